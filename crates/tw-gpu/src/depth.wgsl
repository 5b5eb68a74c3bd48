// terawalk depth readback: copies the Depth32Float target (bound as an unfilterable
// texture_2d<f32>, the form GL accepts) into a storage buffer of f32, rows from the top.

@group(0) @binding(0) var depth_tex: texture_2d<f32>;
@group(0) @binding(1) var<storage, read_write> out_depth: array<f32>;

@compute @workgroup_size(8, 8)
fn cs_copy(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(depth_tex);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    out_depth[id.y * size.x + id.x] = textureLoad(depth_tex, vec2<i32>(id.xy), 0).x;
}
