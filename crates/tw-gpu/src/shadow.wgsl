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

// The lookup's inputs are affine in the scene-space point — its eye depth and its light clip
// position in each layer (homogeneous: a point light's perspective divides per fragment) — so
// the vertex stage computes them and the rasterizer interpolates them, instead of a matrix
// product per layer and fragment: on a CPU driver the fragments are the frame's cost.
struct ShadowedOut {
    @builtin(position) clip: vec4<f32>,
    // Rule 1's eye depth, (p − eye) · view direction.
    @location(0) eye_depth: f32,
    // The triangle's colour with the light's term and without it.
    @location(1) @interpolate(flat) lit: vec3<f32>,
    @location(2) @interpolate(flat) dark: vec3<f32>,
    @location(3) @interpolate(flat) shadow_class: u32,
    // The point in the light clip space of layers 0..5 (those past SHADOW_LAYERS unused).
    @location(4) l0: vec4<f32>,
    @location(5) l1: vec4<f32>,
    @location(6) l2: vec4<f32>,
    @location(7) l3: vec4<f32>,
    @location(8) l4: vec4<f32>,
    @location(9) l5: vec4<f32>,
    // Scene space, for the section's clip test (draw.wgsl `section_color`).
    @location(10) world: vec3<f32>,
    // The cluster's fade word (read only where DITHER; common.wgsl `dither_keeps`).
    @location(11) @interpolate(flat) fade: u32,
};

// The light clip position of `p` in layer `i` (zero past SHADOW_LAYERS).
fn layer_clip_of(i: u32, p: vec3<f32>) -> vec4<f32> {
    if (i >= SHADOW_LAYERS) {
        return vec4<f32>(0.0);
    }
    return su.layers[i].view_proj * vec4<f32>(p, 1.0);
}

// The interpolated light clip position of layer `i` (selects, no branches: fragments of one
// block may be in different layers).
// The guards are pipeline constants: the layers past SHADOW_LAYERS are not even interpolated.
fn layer_clip(in: ShadowedOut, i: u32) -> vec4<f32> {
    var c = in.l0;
    if (SHADOW_LAYERS > 1u) {
        c = select(c, in.l1, i == 1u);
    }
    if (SHADOW_LAYERS > 2u) {
        c = select(c, in.l2, i == 2u);
    }
    if (SHADOW_LAYERS > 3u) {
        c = select(c, in.l3, i == 3u);
    }
    if (SHADOW_LAYERS > 4u) {
        c = select(c, in.l4, i == 4u);
    }
    if (SHADOW_LAYERS > 5u) {
        c = select(c, in.l5, i == 5u);
    }
    return c;
}

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
    @builtin(instance_index) instance: u32,
) -> ShadowedOut {
    var out: ShadowedOut;
    out.clip = u.view_proj * vec4<f32>(position, 1.0);
    out.eye_depth = dot(position - u.eye.xyz, su.view_dir.xyz);
    out.world = position;
    out.fade = slots[slot].fade;
    out.l0 = layer_clip_of(0u, position);
    out.l1 = layer_clip_of(1u, position);
    out.l2 = layer_clip_of(2u, position);
    out.l3 = layer_clip_of(3u, position);
    out.l4 = layer_clip_of(4u, position);
    out.l5 = layer_clip_of(5u, position);
    let n = viewer_normal(normal, position);
    let head = abs(dot(n, u.headlight.xyz));
    let facing = max(dot(n, towards_light(position)), 0.0);
    // A part of a refined cluster carries its class in the draw's first instance (1 + the
    // code; renderer/classified.rs), a whole cluster in its slot's entry.
    let drawn_class = select(slot_classes[slot], instance - 1u, instance > 0u);
    // Facing away, the light's term is 0 either way: no lookup.
    out.shadow_class = select(drawn_class, CLASS_LIT, facing <= 0.0);
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

// Whether the splits of the layers are ascending and disjoint (sun cascades), a pipeline
// constant: then at most one layer's split holds a depth, found without a loop over the layers.
override SHADOW_DISJOINT: bool = false;

// Whether every layer is orthographic (sun cascades: the last row of each matrix is 0, 0, 0, 1),
// a pipeline constant: then w = 1 and the perspective divide is skipped (the rule divides by an
// exact 1; the interpolated w is 1 within rounding).
override SHADOW_ORTHO: bool = false;

// Rule 2 for a point whose light clip position in layer `i` is `c`, the eye-depth split of the
// layer holding it: 0 if the layer's clip space does not hold it, 1 if the light reaches it, 2
// if not. Without branches: a CPU driver runs both sides of a branch for a block of fragments
// whenever they disagree, and the fetch is made either way.
fn lookup_clip(c: vec4<f32>, i: u32) -> u32 {
    var d = c.xyz;
    var ahead = true;
    if (!SHADOW_ORTHO) {
        d = c.xyz / c.w;
        ahead = c.w > 0.0;
    }
    let inside = ahead && abs(d.x) <= 1.0 && abs(d.y) <= 1.0 && d.z >= 0.0 && d.z <= 1.0;
    let s = su.params.x;
    let x = clamp(floor((d.x + 1.0) * 0.5 * s), 0.0, s - 1.0);
    let y = clamp(floor((1.0 - d.y) * 0.5 * s), 0.0, s - 1.0);
    let stored = textureLoad(shadow_map, vec2<i32>(i32(x), i32(y)), i32(i), 0).x;
    return select(0u, select(2u, 1u, d.z <= stored + su.params.y), inside);
}

// Rule 2 in layer `i` for a point whose eye depth the layer's split holds.
fn lookup_in(in: ShadowedOut, i: u32) -> u32 {
    return lookup_clip(layer_clip(in, i), i);
}

// With disjoint splits, the only candidate layer for eye depth `depth`: the last whose split
// starts at or before it, with its clip position and split, picked by selects over the layers
// the pipeline constants allow (an index varying per fragment into the uniforms would be a
// gather).
struct Candidate {
    i: u32,
    clip: vec4<f32>,
    split: vec4<f32>,
};

fn candidate_layer(in: ShadowedOut, depth: f32) -> Candidate {
    var k = Candidate(0u, in.l0, su.layers[0].split);
    if (SHADOW_LAYERS > 1u) {
        let s = su.layers[1].split;
        let on = depth >= s.x;
        k = Candidate(select(k.i, 1u, on), select(k.clip, in.l1, on), select(k.split, s, on));
    }
    if (SHADOW_LAYERS > 2u) {
        let s = su.layers[2].split;
        let on = depth >= s.x;
        k = Candidate(select(k.i, 2u, on), select(k.clip, in.l2, on), select(k.split, s, on));
    }
    if (SHADOW_LAYERS > 3u) {
        let s = su.layers[3].split;
        let on = depth >= s.x;
        k = Candidate(select(k.i, 3u, on), select(k.clip, in.l3, on), select(k.split, s, on));
    }
    if (SHADOW_LAYERS > 4u) {
        let s = su.layers[4].split;
        let on = depth >= s.x;
        k = Candidate(select(k.i, 4u, on), select(k.clip, in.l4, on), select(k.split, s, on));
    }
    if (SHADOW_LAYERS > 5u) {
        let s = su.layers[5].split;
        let on = depth >= s.x;
        k = Candidate(select(k.i, 5u, on), select(k.clip, in.l5, on), select(k.split, s, on));
    }
    return k;
}

// The lookup rule (tw-runtime shadow/mod.rs, Shadows::lit): rule 1 picks the first layer whose
// eye-depth split holds p and whose clip space holds p; rule 2 compares p's light depth with the
// texel's. A point in no layer is lit. With disjoint splits the only candidate is the last layer
// whose split starts at or before the depth: one lookup a fragment instead of one a layer, which
// is what a CPU driver pays for (it runs the loop's iterations for the whole block of fragments).
fn light_reaches(in: ShadowedOut) -> bool {
    let depth = in.eye_depth;
    if (SHADOW_DISJOINT) {
        let k = candidate_layer(in, depth);
        let held = depth >= k.split.x && depth < k.split.y;
        return !held || lookup_clip(k.clip, k.i) != 2u;
    }
    for (var i = 0u; i < SHADOW_LAYERS; i = i + 1u) {
        let split = su.layers[i].split;
        if (!(depth >= split.x && depth < split.y)) {
            continue;
        }
        let r = lookup_in(in, i);
        if (r != 0u) {
            return r == 1u;
        }
    }
    return true;
}

// Clusters the cross-culling classified (Lit, Shadowed): no lookup code at all (draw.rs,
// `Shading::Classified`).
@fragment
fn fs_classified(in: ShadowedOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    if (DITHER) {
        if (!dither_keeps(in.clip.xy, in.fade)) {
            discard;
        }
    }
    let c = select(in.dark, in.lit, in.shadow_class == CLASS_LIT);
    if (SECTION) {
        return vec4<f32>(section_color(c, in.world, front), 1.0);
    }
    return vec4<f32>(c, 1.0);
}

@fragment
fn fs_shadowed(in: ShadowedOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    if (DITHER) {
        if (!dither_keeps(in.clip.xy, in.fade)) {
            discard;
        }
    }
    if (SECTION && section_removes(in.world)) {
        discard;
    }
    if (SECTION && !front) {
        return vec4<f32>(flat_srgb(SECTION_COLOR), 1.0);
    }
    var lit = in.shadow_class == CLASS_LIT;
    if (in.shadow_class == CLASS_PARTIAL) {
        lit = light_reaches(in);
    }
    return vec4<f32>(select(in.dark, in.lit, lit), 1.0);
}
