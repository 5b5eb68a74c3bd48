// terawalk GPU HZB build (gpu_cull.rs): the farthest-depth pyramid of tw_runtime::Hzb::build, in
// one storage buffer of f32, level after level (offsets in the uniform). Reverse-Z: larger is
// nearer, so "farthest" is the minimum. cs_copy2 writes levels 0 and 1 from the Depth32Float
// target (bound as an unfilterable texture_2d<f32>, as depth.wgsl does; cs_copy for a 1×1
// target); cs_reduce writes level k + 1 from level k, one dispatch per level.

struct Level {
    src_offset: u32,
    src_width: u32,
    src_height: u32,
    dst_offset: u32,
    dst_width: u32,
    dst_height: u32,
    _pad0: u32,
    _pad1: u32,
};

@group(0) @binding(0) var<uniform> level: Level;
@group(0) @binding(1) var<storage, read_write> pyramid: array<f32>;
@group(0) @binding(2) var depth_tex: texture_2d<f32>;

// Hzb::build treats non-finite depths as far (0): they never occlude. Tested on the bits, which
// no fast-math setting folds away.
fn finite_or_far(d: f32) -> f32 {
    if ((bitcast<u32>(d) & 0x7f800000u) == 0x7f800000u) {
        return 0.0;
    }
    return d;
}

@compute @workgroup_size(8, 8)
fn cs_copy(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= level.dst_width || id.y >= level.dst_height) {
        return;
    }
    let d = textureLoad(depth_tex, vec2<i32>(id.xy), 0).x;
    pyramid[level.dst_offset + id.y * level.dst_width + id.x] = finite_or_far(d);
}

// Levels 0 and 1 at once (src = level 0, dst = level 1): each invocation loads the 2×2 depth
// texels under its level-1 texel (clamped at odd edges, as cs_reduce), stores them into level 0
// and their minimum into level 1 — a quarter of the invocations of cs_copy then cs_reduce.
@compute @workgroup_size(8, 8)
fn cs_copy2(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= level.dst_width || id.y >= level.dst_height) {
        return;
    }
    let x0 = 2u * id.x;
    let x1 = min(2u * id.x + 1u, level.src_width - 1u);
    let y0 = 2u * id.y;
    let y1 = min(2u * id.y + 1u, level.src_height - 1u);
    let d00 = finite_or_far(textureLoad(depth_tex, vec2<i32>(vec2<u32>(x0, y0)), 0).x);
    let d10 = finite_or_far(textureLoad(depth_tex, vec2<i32>(vec2<u32>(x1, y0)), 0).x);
    let d01 = finite_or_far(textureLoad(depth_tex, vec2<i32>(vec2<u32>(x0, y1)), 0).x);
    let d11 = finite_or_far(textureLoad(depth_tex, vec2<i32>(vec2<u32>(x1, y1)), 0).x);
    let w = level.src_width;
    pyramid[level.src_offset + y0 * w + x0] = d00;
    pyramid[level.src_offset + y0 * w + x1] = d10;
    pyramid[level.src_offset + y1 * w + x0] = d01;
    pyramid[level.src_offset + y1 * w + x1] = d11;
    pyramid[level.dst_offset + id.y * level.dst_width + id.x] = min(min(d00, d10), min(d01, d11));
}

// Texel (x, y) covers the existing texels 2x..=2x+1 × 2y..=2y+1 of the level below (clamped at
// the last row and column of odd sizes), as in Hzb::build.
@compute @workgroup_size(8, 8)
fn cs_reduce(@builtin(global_invocation_id) id: vec3<u32>) {
    if (id.x >= level.dst_width || id.y >= level.dst_height) {
        return;
    }
    let x0 = 2u * id.x;
    let x1 = min(2u * id.x + 1u, level.src_width - 1u);
    let row0 = level.src_offset + (2u * id.y) * level.src_width;
    let row1 = level.src_offset + min(2u * id.y + 1u, level.src_height - 1u) * level.src_width;
    let d = min(min(pyramid[row0 + x0], pyramid[row0 + x1]), min(pyramid[row1 + x0], pyramid[row1 + x1]));
    pyramid[level.dst_offset + id.y * level.dst_width + id.x] = d;
}
