// terawalk shadow-map readback on GL (shadow.rs `LayerCopy`): copies one layer of the
// Depth32Float shadow map (bound as an unfilterable texture_2d_array<f32>, the form GL accepts;
// GL can neither copy a depth texture to a buffer nor bind one layer of an array on its own)
// into a storage buffer of f32, rows from the top.

@group(0) @binding(0) var shadow_map: texture_2d_array<f32>;
@group(0) @binding(1) var<storage, read_write> out_depth: array<f32>;
// x: the layer to copy.
@group(0) @binding(2) var<uniform> layer: vec4<u32>;

@compute @workgroup_size(8, 8)
fn cs_copy_layer(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(shadow_map);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    out_depth[id.y * size.x + id.x] = textureLoad(shadow_map, vec2<i32>(id.xy), i32(layer.x), 0).x;
}
