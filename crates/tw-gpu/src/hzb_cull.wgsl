// terawalk GPU HZB cull (gpu_cull.rs): per candidate, the conservative box test of
// tw_runtime::Hzb::test_box (ported rule for rule; the constants come in the uniform) and its
// flag (0 visible, 1 occluded, 2 no pixel centre, read back for the CPU's history), then the
// candidates' indirect draw arguments: in place with instance_count 0 for a culled candidate
// (cs_cull), or, where the device draws with an indirect count, compacted in candidate order
// behind the count (cs_compact, a second dispatch).

struct Cull {
    // Reverse-Z view-projection of the depth the pyramid was built from.
    view_proj: mat4x4<f32>,
    // x, y: level 0 size (pixels); z: pyramid levels; w: candidates.
    size: vec4<u32>,
    // x: rectangle slack (px, RECT_SLACK_PX + the GPU guard); y: DEPTH_MARGIN; z: the GPU's
    // relative depth guard.
    params: vec4<f32>,
    // Per level: offset in the pyramid buffer, width, height.
    levels: array<vec4<u32>, 16>,
};

struct DrawArgs {
    index_count: u32,
    instance_count: u32,
    first_index: u32,
    base_vertex: i32,
    first_instance: u32,
};

struct Candidate {
    lo: vec4<f32>,
    hi: vec4<f32>,
    args: DrawArgs,
};

struct State {
    // Draws written (compacted mode); the count buffer of multi_draw_indexed_indirect_count.
    count: u32,
    flags: array<u32>,
};

@group(0) @binding(0) var<uniform> u: Cull;

// Whether cs_cull writes the draw arguments in place (instance_count 0 when culled): a pipeline
// constant (gpu_cull.rs `cull` / `cull_flags`), not a uniform, as no branch may test a uniform
// alone (draw.wgsl: lavapipe would compile a new copy of the shader at every dispatch).
override WRITE_ARGS: bool = true;
@group(0) @binding(1) var<storage, read> pyramid: array<f32>;
@group(0) @binding(2) var<storage, read> candidates: array<Candidate>;
@group(0) @binding(3) var<storage, read_write> out_args: array<DrawArgs>;
@group(0) @binding(4) var<storage, read_write> state: State;

const VISIBLE: u32 = 0u;
const OCCLUDED: u32 = 1u;
const NO_PIXELS: u32 = 2u;
const BIG: f32 = 3.0e38;

fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

fn all_finite(v: vec4<f32>) -> bool {
    return is_finite(v.x) && is_finite(v.y) && is_finite(v.z) && is_finite(v.w);
}

// Hzb::test_rect: the pixels whose centres lie in the widened rectangle, read at the finest
// level where they span at most 2×2 texels.
fn test_rect(x_lo: f32, y_lo: f32, x_hi: f32, y_hi: f32, nearest: f32) -> u32 {
    if (!(is_finite(x_lo) && is_finite(y_lo) && is_finite(x_hi) && is_finite(y_hi))) {
        return VISIBLE;
    }
    let w = f32(u.size.x);
    let h = f32(u.size.y);
    let slack = u.params.x;
    let px0 = max(ceil(x_lo - slack - 0.5), 0.0);
    let py0 = max(ceil(y_lo - slack - 0.5), 0.0);
    let px1 = min(floor(x_hi + slack - 0.5), w - 1.0);
    let py1 = min(floor(y_hi + slack - 0.5), h - 1.0);
    if (px0 > px1 || py0 > py1) {
        return NO_PIXELS;
    }
    let x0 = u32(px0);
    let y0 = u32(py0);
    let x1 = u32(px1);
    let y1 = u32(py1);
    var k = 0u;
    while (k + 1u < u.size.z && ((x1 >> k) - (x0 >> k) > 1u || (y1 >> k) - (y0 >> k) > 1u)) {
        k = k + 1u;
    }
    let level = u.levels[k];
    var farthest = BIG;
    for (var ty = y0 >> k; ty <= (y1 >> k); ty = ty + 1u) {
        for (var tx = x0 >> k; tx <= (x1 >> k); tx = tx + 1u) {
            farthest = min(farthest, pyramid[level.x + ty * level.y + tx]);
        }
    }
    // The guard makes the GPU's answer occluded only where the CPU's is too, whatever the
    // shader compiler fuses or reorders.
    if (nearest * (1.0 + u.params.z) < farthest * (1.0 - u.params.y)) {
        return OCCLUDED;
    }
    return VISIBLE;
}

// Hzb::test_box: the bounding rectangle of the 8 projected corners and their nearest depth; a
// corner behind the eye, at or before the near plane, or not finite makes the box visible.
fn test_box(lo: vec3<f32>, hi: vec3<f32>) -> u32 {
    let w = f32(u.size.x);
    let h = f32(u.size.y);
    var x_lo = BIG;
    var y_lo = BIG;
    var x_hi = -BIG;
    var y_hi = -BIG;
    var nearest = 0.0;
    for (var i = 0u; i < 8u; i = i + 1u) {
        let p = vec3<f32>(
            select(hi.x, lo.x, (i & 1u) == 0u),
            select(hi.y, lo.y, (i & 2u) == 0u),
            select(hi.z, lo.z, (i & 4u) == 0u),
        );
        let c = u.view_proj * vec4<f32>(p, 1.0);
        if (!all_finite(c) || c.w <= 0.0) {
            return VISIBLE;
        }
        let depth = c.z / c.w;
        if (depth >= 1.0) {
            return VISIBLE;
        }
        nearest = max(nearest, depth);
        let sx = (c.x / c.w * 0.5 + 0.5) * w;
        let sy = (0.5 - c.y / c.w * 0.5) * h;
        x_lo = min(x_lo, sx);
        x_hi = max(x_hi, sx);
        y_lo = min(y_lo, sy);
        y_hi = max(y_hi, sy);
    }
    return test_rect(x_lo, y_lo, x_hi, y_hi, nearest);
}

@compute @workgroup_size(64)
fn cs_cull(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x;
    if (i >= u.size.w) {
        return;
    }
    let c = candidates[i];
    let flag = test_box(c.lo.xyz, c.hi.xyz);
    state.flags[i] = flag;
    if (WRITE_ARGS) {
        var a = c.args;
        a.instance_count = select(0u, 1u, flag == VISIBLE && c.args.index_count > 0u);
        out_args[i] = a;
    }
}

// Compaction in candidate order (so the draws, and the image, do not depend on thread timing):
// one workgroup; each thread counts the drawn candidates of a contiguous chunk, a scan over the
// workgroup gives each chunk its first output slot, then each thread writes its chunk.
const COMPACT_THREADS: u32 = 256u;
var<workgroup> chunk_counts: array<u32, 256>;

fn drawn(i: u32) -> bool {
    return state.flags[i] == VISIBLE && candidates[i].args.index_count > 0u;
}

@compute @workgroup_size(256)
fn cs_compact(@builtin(local_invocation_index) t: u32) {
    let n = u.size.w;
    let per = (n + COMPACT_THREADS - 1u) / COMPACT_THREADS;
    let first = min(t * per, n);
    let end = min(first + per, n);
    var count = 0u;
    for (var i = first; i < end; i = i + 1u) {
        if (drawn(i)) {
            count = count + 1u;
        }
    }
    chunk_counts[t] = count;
    workgroupBarrier();
    if (t == 0u) {
        var total = 0u;
        for (var j = 0u; j < COMPACT_THREADS; j = j + 1u) {
            let c = chunk_counts[j];
            chunk_counts[j] = total;
            total = total + c;
        }
        state.count = total;
    }
    workgroupBarrier();
    var slot = chunk_counts[t];
    for (var i = first; i < end; i = i + 1u) {
        if (drawn(i)) {
            out_args[slot] = candidates[i].args;
            slot = slot + 1u;
        }
    }
}
