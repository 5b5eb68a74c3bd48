// terawalk depth resolve: the farthest (reverse-Z: smallest) of a multisampled Depth32Float
// target's samples per pixel, written as the depth of a single-sample target. SAMPLES is
// replaced by the sample count when the module is made.

@group(0) @binding(0) var depth_ms: texture_multisampled_2d<f32>;

@vertex
fn vs_full(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    // One triangle over the whole target.
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}

@fragment
fn fs_resolve(@builtin(position) p: vec4<f32>) -> @builtin(frag_depth) f32 {
    let c = vec2<i32>(p.xy);
    var d = textureLoad(depth_ms, c, 0).x;
    for (var s = 1; s < SAMPLES; s++) {
        d = min(d, textureLoad(depth_ms, c, s).x);
    }
    return d;
}
