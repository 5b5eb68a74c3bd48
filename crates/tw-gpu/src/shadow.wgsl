// terawalk shadow maps (appended to common.wgsl and draw.wgsl; shadow.rs): the depth-only pass
// from the light, and the shaded pipeline with shadows, which follows the lookup rule of
// crates/tw-runtime/src/shadow/mod.rs (`Shadows::lit`) exactly, so that the CPU's
// cross-culling classes (Lit, Shadowed) give the image a lookup would.

// One layer (shadow.rs LayerUniform): scene space to the light's clip space, and the eye depths
// [split.x, split.y) it serves (infinite ends stored as ±f32::MAX).
struct ShadowLayer {
    view_proj: mat4x4<f32>,
    split: vec4<f32>,
};

// shadow.rs ShadowUniforms.
struct ShadowUniforms {
    // xyz: unit direction towards the sun (w = 0) or the point light's position (w = 1).
    light: vec4<f32>,
    // xyz: the eye's unit view direction (Camera::direction), for the eye depth of rule 1.
    view_dir: vec4<f32>,
    // x: texels per side of a layer; y: the bias of rule 2.
    params: vec4<f32>,
    layers: array<ShadowLayer, 6>,
};

@group(1) @binding(0) var<uniform> su: ShadowUniforms;
// Per pool slot: the cross-culling class of the cluster in it (shadow.rs CLASS_*).
@group(1) @binding(1) var<storage, read> slot_classes: array<u32>;
// The shadow map (Depth32Float bound as unfilterable floats: the form GL accepts too).
@group(1) @binding(2) var shadow_map: texture_2d_array<f32>;

// Layers in use, a pipeline constant: a loop bound read from the uniforms would be a branch on
// a uniform alone, which lavapipe recompiles at every bind (draw.wgsl, COLOR_MODE).
override SHADOW_LAYERS: u32 = 1u;

const CLASS_PARTIAL: u32 = 0u;
const CLASS_LIT: u32 = 1u;
const CLASS_SHADOWED: u32 = 2u;

// The depth-only pass into a shadow-map layer: `u.view_proj` is the layer's.
@vertex
fn vs_depth(@location(0) position: vec3<f32>) -> @builtin(position) vec4<f32> {
    return u.view_proj * vec4<f32>(position, 1.0);
}

struct ShadowedOut {
    @builtin(position) clip: vec4<f32>,
    // The scene-space point, for the lookup.
    @location(0) world: vec3<f32>,
    // The triangle's colour with the light's term and without it.
    @location(1) @interpolate(flat) lit: vec3<f32>,
    @location(2) @interpolate(flat) dark: vec3<f32>,
    @location(3) @interpolate(flat) shadow_class: u32,
};

// Light::towards_from: the unit direction from `p` towards the light. Selects, not branches,
// between the sun and a point light (the kind is a uniform).
fn towards_light(p: vec3<f32>) -> vec3<f32> {
    let d = su.light.xyz - su.light.w * p;
    let len = length(d);
    let point = select(vec3<f32>(0.0, 0.0, 1.0), d * (1.0 / len), len > 0.0);
    return select(point, su.light.xyz, su.light.w == 0.0);
}

// vs_shade (draw.wgsl) with the light of the shadows instead of the fixed sun: the same flat
// per-vertex shading, done twice — with the light's term and without — so that the fragment
// stage only picks one (one lookup a fragment, no shading).
@vertex
fn vs_shadowed(
    @location(0) position: vec3<f32>,
    @location(1) object: u32,
    @location(2) slot: u32,
    @location(3) normal: u32,
) -> ShadowedOut {
    var out: ShadowedOut;
    out.clip = u.view_proj * vec4<f32>(position, 1.0);
    out.world = position;
    let n = viewer_normal(normal, position);
    let head = abs(dot(n, u.headlight.xyz));
    let facing = max(dot(n, towards_light(position)), 0.0);
    // Facing away, the light's term is 0 either way: no lookup.
    out.shadow_class = select(slot_classes[slot], CLASS_LIT, facing <= 0.0);
    if (COLOR_MODE == 4u) {
        out.lit = flat_srgb(select(SHADOW_AWAY, SHADOW_LIT, facing > 0.0));
        out.dark = flat_srgb(select(SHADOW_AWAY, SHADOW_BLOCKED, facing > 0.0));
        return out;
    }
    let base = pow(base_color(object, slot), vec3<f32>(2.2));
    let ambient = 0.18 + 0.62 * head;
    var lit = min(base * (ambient + 0.35 * facing), vec3<f32>(1.0));
    var dark = min(base * ambient, vec3<f32>(1.0));
    if (ENCODE_SRGB) {
        lit = srgb_encode(lit);
        dark = srgb_encode(dark);
    }
    out.lit = lit;
    out.dark = dark;
    return out;
}

// The lookup rule (tw-runtime shadow/mod.rs, Shadows::lit): rule 1 picks the first layer whose
// eye-depth split holds p and whose clip space holds p; rule 2 compares p's light depth with the
// texel's. A point in no layer is lit.
fn light_reaches(p: vec3<f32>) -> bool {
    let depth = dot(p - u.eye.xyz, su.view_dir.xyz);
    let s = su.params.x;
    for (var i = 0u; i < SHADOW_LAYERS; i = i + 1u) {
        let layer = su.layers[i];
        if (!(depth >= layer.split.x && depth < layer.split.y)) {
            continue;
        }
        let c = layer.view_proj * vec4<f32>(p, 1.0);
        if (c.w <= 0.0) {
            continue;
        }
        let d = c.xyz / c.w;
        if (!(abs(d.x) <= 1.0 && abs(d.y) <= 1.0 && d.z >= 0.0 && d.z <= 1.0)) {
            continue;
        }
        let x = clamp(floor((d.x + 1.0) * 0.5 * s), 0.0, s - 1.0);
        let y = clamp(floor((1.0 - d.y) * 0.5 * s), 0.0, s - 1.0);
        let stored = textureLoad(shadow_map, vec2<i32>(i32(x), i32(y)), i32(i), 0).x;
        return d.z <= stored + su.params.y;
    }
    return true;
}

// Clusters the cross-culling classified (Lit, Shadowed): no lookup code at all (draw.rs,
// `Shading::Classified`).
@fragment
fn fs_classified(in: ShadowedOut) -> @location(0) vec4<f32> {
    return vec4<f32>(select(in.dark, in.lit, in.shadow_class == CLASS_LIT), 1.0);
}

@fragment
fn fs_shadowed(in: ShadowedOut) -> @location(0) vec4<f32> {
    var lit = in.shadow_class == CLASS_LIT;
    if (in.shadow_class == CLASS_PARTIAL) {
        lit = light_reaches(in.world);
    }
    return vec4<f32>(select(in.dark, in.lit, lit), 1.0);
}
