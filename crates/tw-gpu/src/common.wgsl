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
    // The cross-fade word (dither.rs): 0 every pixel; bits 30-31 the side (1 entering, 2
    // leaving), bits 0-16 the threshold t (65536 = 1).
    fade: u32,
};

// Whether the pipeline tests each fragment against its cluster's fade word (a pipeline
// constant, draw.rs `Pipelines`, like SECTION: without it no fragment stage discards).
override DITHER: bool = false;

// The rank of pixel p in the 8 x 8 Bayer matrix on the threshold's scale, the centre of its
// cell (dither.rs `pixel_rank`).
fn pixel_rank(p: vec2<u32>) -> u32 {
    var rank = 0u;
    for (var bit = 0u; bit < 3u; bit = bit + 1u) {
        let bx = (p.x >> bit) & 1u;
        let by = (p.y >> bit) & 1u;
        rank = rank * 4u + (((bx ^ by) << 1u) | by);
    }
    return rank * 1024u + 512u;
}

// Whether a fragment at `frag` (framebuffer coordinates) of a cluster with fade word `fade` is
// kept (dither.rs `keeps`): arithmetic on the word, which comes from the slot table, not the
// uniforms.
fn dither_keeps(frag: vec2<f32>, fade: u32) -> bool {
    let side = fade >> 30u;
    let t = fade & 0x1ffffu;
    let h = pixel_rank(vec2<u32>(frag) & vec2<u32>(7u));
    return side == 0u || (side == 1u && h < t) || (side == 2u && h >= t);
}

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

// The depth-only passes of a frame with cross-fades (draw.rs `depth_only`): the cluster's fade
// word for the fragment stage's dither test, and the point for the section's.
struct FadeDepthOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) @interpolate(flat) fade: u32,
};

@vertex
fn vs_depth_fade(@location(0) position: vec3<f32>, @location(2) slot: u32) -> FadeDepthOut {
    var out: FadeDepthOut;
    out.clip = u.view_proj * vec4<f32>(position, 1.0);
    out.world = position;
    out.fade = slots[slot].fade;
    return out;
}

@fragment
fn fs_depth_fade(in: FadeDepthOut) {
    if (!dither_keeps(in.clip.xy, in.fade)) {
        discard;
    }
    if (SECTION) {
        if (section_removes(in.world)) {
            discard;
        }
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
