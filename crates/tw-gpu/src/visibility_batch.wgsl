// terawalk full-visibility tests without a draw call per query (visibility_batch.rs): every op of
// a run is a range of triangles; a batch of consecutive ops is one draw whose vertex stage pulls
// its triangle from the uploaded vertices, and whose fragment stage (query batches) tests the
// fragment against the stored depth and counts it for its op.

struct Params {
    view_proj: mat4x4<f32>,
    // 1: a fragment counts only strictly behind the stored depth (S-CULLIDE); 0: at or behind.
    strict: u32,
    // Ops in the run (`first_triangle` has one more entry: the end).
    ops: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// The uploaded vertices, three floats each.
@group(0) @binding(1) var<storage, read> positions: array<f32>;
// Per op: its first triangle in the run's numbering (non-decreasing), then the total.
@group(0) @binding(2) var<storage, read> first_triangle: array<u32>;
// Per op: its first vertex in the uploaded vertices.
@group(0) @binding(3) var<storage, read> first_vertex: array<u32>;

// Query batches only: fragments passed per op, and the depth drawn so far (bound read-only).
@group(1) @binding(0) var<storage, read_write> passed: array<atomic<u32>>;
@group(1) @binding(1) var depth: texture_depth_2d;

struct Pulled {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) op: u32,
}

// The op holding triangle `t` of the run: the last op whose first triangle is at or before it
// (empty ops share their first triangle with the next one, so they are never chosen).
fn op_of(t: u32) -> u32 {
    var lo = 0u;
    var hi = params.ops;
    while (hi - lo > 1u) {
        let mid = (lo + hi) / 2u;
        if (first_triangle[mid] <= t) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}

@vertex
fn vs_pull(@builtin(vertex_index) v: u32) -> Pulled {
    let t = v / 3u;
    let op = op_of(t);
    let source = first_vertex[op] + (t - first_triangle[op]) * 3u + v % 3u;
    let p = vec3<f32>(positions[3u * source], positions[3u * source + 1u], positions[3u * source + 2u]);
    var out: Pulled;
    out.position = params.view_proj * vec4<f32>(p, 1.0);
    out.op = op;
    return out;
}

// The occlusion query's test, done by hand: the pass holds the depth read-only.
@fragment
fn fs_query(in: Pulled) {
    let stored = textureLoad(depth, vec2<i32>(in.position.xy), 0);
    var behind = in.position.z >= stored;
    if (params.strict != 0u) {
        behind = in.position.z > stored;
    }
    if (behind) {
        atomicAdd(&passed[in.op], 1u);
    }
}
