// terawalk item buffer (appended to common.wgsl; ids.rs prepends `enable primitive_index;` and
// defines PRIM where the adapter has Features::PRIMITIVE_INDEX): per pixel the object id, 1 + the
// cluster's position in the drawn list (0 = nothing drawn) and the triangle's index in its
// cluster (0xffffffff when primitive indices are unavailable).

@fragment
fn fs_items(in: VertexOut PRIM_ARG) -> @location(0) vec4<u32> {
    // With a section, a removed point is no item (the CPU pick ignores it too, tw-view pick.rs).
    if (SECTION && section_removes(in.world)) {
        discard;
    }
    return vec4<u32>(in.object, slots[in.slot].item, PRIM_VALUE, 1u);
}
