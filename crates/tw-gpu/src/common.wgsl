// terawalk: what the cluster shaders share — uniforms, the pool's slot table and vertex stage.
// Pooled vertices (pool.rs): scene-space position, object id, pool slot. Every vertex of a
// triangle carries the triangle's object and slot, so the flat varyings do not depend on the
// backend's provoking vertex.

struct Uniforms {
    view_proj: mat4x4<f32>,
    // xyz: eye in scene space; w: 1 for a perspective camera, 0 for an orthographic one (whose
    // viewer is along `headlight` from every point, Camera::to_viewer).
    eye: vec4<f32>,
    // xyz: unit direction towards the sun; w: unused (0).
    sun: vec4<f32>,
    // x: unused (0: the colour mode is the pipeline constant COLOR_MODE, draw.wgsl); y: object
    // colours in the table; z: default colour (RGBA8); w: the highlighted object (0xffffffff:
    // none; Renderer::set_highlight).
    params: vec4<u32>,
    // xyz: unit direction from the view's target towards the eye (the headlight).
    headlight: vec4<f32>,
    // The section's half-spaces (tw_runtime::Section::clip_planes): a point p is kept when
    // dot(xyz, p) + w >= 0 for all twelve; unused ones are (0, 0, 0, 1).
    clip: array<vec4<f32>, 12>,
};

// Whether the pipeline clips by the section (a pipeline constant, draw.rs `Pipelines`: a
// branch on the uniforms alone would make lavapipe recompile the shader at every bind,
// docs/RUNTIME.md "Memory"). Without a section no fragment stage discards, so the depth
// test stays early.
override SECTION: bool = false;

// Whether the section removes scene-space point p: all twelve planes tested arithmetically.
fn section_removes(p: vec3<f32>) -> bool {
    var m = 1.0;
    for (var i = 0; i < 12; i = i + 1) {
        m = min(m, dot(u.clip[i].xyz, p) + u.clip[i].w);
    }
    return m < 0.0;
}

// One resident cluster (pool.rs SlotInfo).
struct Slot {
    page: u32,
    index_in_page: u32,
    level: u32,
    item: u32,
};

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var<storage, read> slots: array<Slot>;
@group(0) @binding(2) var<storage, read> object_colors: array<u32>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) @interpolate(flat) object: u32,
    @location(2) @interpolate(flat) slot: u32,
};

// The depth-only passes with a section (draw.rs `depth_only`): the point for the fragment
// stage's clip test.
struct DepthOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
};

@vertex
fn vs_depth_world(@location(0) position: vec3<f32>) -> DepthOut {
    var out: DepthOut;
    out.clip = u.view_proj * vec4<f32>(position, 1.0);
    out.world = position;
    return out;
}

@fragment
fn fs_depth_clip(in: DepthOut) {
    if (section_removes(in.world)) {
        discard;
    }
}

@vertex
fn vs_main(
    @location(0) position: vec3<f32>,
    @location(1) object: u32,
    @location(2) slot: u32,
) -> VertexOut {
    var out: VertexOut;
    out.clip = u.view_proj * vec4<f32>(position, 1.0);
    out.world = position;
    out.object = object;
    out.slot = slot;
    return out;
}
