// terawalk shading (appended to common.wgsl): flat normals from screen-space derivatives, a
// headlight plus a fixed sun, colour by material (the store's object colours), object, LOD
// level or cluster (ColorMode).

fn unpack_srgb(c: u32) -> vec3<f32> {
    return vec3<f32>(f32(c & 255u), f32((c >> 8u) & 255u), f32((c >> 16u) & 255u)) / 255.0;
}

// hash_color in color.rs (MurmurHash3's finaliser, then HSV), in f32.
fn hash_color(id: u32) -> vec3<f32> {
    var h = id + 0x9e3779b9u;
    h = h ^ (h >> 16u);
    h = h * 0x85ebca6bu;
    h = h ^ (h >> 13u);
    h = h * 0xc2b2ae35u;
    h = h ^ (h >> 16u);
    let hue = f32(h & 0xffffu) / 65536.0 * 6.0;
    let sat = 0.45 + 0.35 * f32((h >> 16u) & 255u) / 255.0;
    let val = 0.75 + 0.25 * f32(h >> 24u) / 255.0;
    let f = fract(hue);
    let p = val * (1.0 - sat);
    let q = val * (1.0 - sat * f);
    let t = val * (1.0 - sat * (1.0 - f));
    let sector = u32(hue);
    if (sector == 0u) { return vec3<f32>(val, t, p); }
    if (sector == 1u) { return vec3<f32>(q, val, p); }
    if (sector == 2u) { return vec3<f32>(p, val, t); }
    if (sector == 3u) { return vec3<f32>(p, q, val); }
    if (sector == 4u) { return vec3<f32>(t, p, val); }
    return vec3<f32>(val, p, q);
}

// What the shaded pipeline draws, fixed when the pipeline is made (draw.rs `Pipelines::shaded`),
// not read from the uniforms: Mesa 22.3's lavapipe compiles a new copy of a shader whose branches
// depend on uniform-buffer values alone (it "inlines" those values) every time the pipeline is
// bound, and never frees the copies — ~0.3 MB of process memory a render pass (docs/RUNTIME.md,
// "Memory"). So no branch here may test a uniform alone.
// The colour mode (ColorMode::code): 0 material, 1 object, 2 level, 3 cluster, 4 shadow mask
// (SHADOW_LIT / SHADOW_BLOCKED / SHADOW_AWAY, constants generated from tw_core::color by
// draw.rs `Pipelines::new`).
override COLOR_MODE: u32 = 0u;
// Whether the target needs sRGB encoding here (a non-sRGB target format).
override ENCODE_SRGB: bool = false;

// level_color in color.rs.
fn level_color(level: u32) -> vec3<f32> {
    var palette = array<vec3<f32>, 8>(
        vec3<f32>(80.0, 200.0, 90.0), vec3<f32>(220.0, 210.0, 70.0),
        vec3<f32>(240.0, 150.0, 50.0), vec3<f32>(225.0, 70.0, 60.0),
        vec3<f32>(200.0, 80.0, 200.0), vec3<f32>(90.0, 110.0, 230.0),
        vec3<f32>(70.0, 200.0, 220.0), vec3<f32>(240.0, 240.0, 240.0));
    return palette[level % 8u] / 255.0;
}

// The object's colour in the colour mode, the highlighted object's (u.params.w) half-way to
// HIGHLIGHT (tw_core::color::highlight): a select on the object, not a branch on the uniform.
fn base_color(object: u32, slot: u32) -> vec3<f32> {
    let c = mode_color(object, slot);
    return select(c, 0.5 * (c + HIGHLIGHT), object == u.params.w);
}

fn mode_color(object: u32, slot: u32) -> vec3<f32> {
    let mode = COLOR_MODE;
    if (mode == 1u) {
        return hash_color(object);
    }
    if (mode == 2u) {
        return level_color(slots[slot].level);
    }
    if (mode == 3u) {
        let s = slots[slot];
        return hash_color((s.page * 0x9e3779b9u) ^ s.index_in_page);
    }
    if (object < u.params.y) {
        return unpack_srgb(object_colors[object]);
    }
    return unpack_srgb(u.params.z);
}

// The shaded pipeline: flat shading, all of it in the vertex stage. The first (provoking)
// vertex of every triangle carries the triangle's normal (pool.rs), so the colour computed there
// (base colour, a headlight along the view direction, sun) is the triangle's, and coplanar
// triangles get one colour; the fragment stage only writes it. On CPU rasterizers (llvmpipe)
// per-fragment lighting from screen-space derivatives was ~40% of an interior frame at
// 1280x720 (78 -> 48 ms measured), and interior views shade each pixel several times.
struct ShadeOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) color: vec3<f32>,
    // Scene space, for the section's clip test (read only where SECTION).
    @location(1) world: vec3<f32>,
    // The cluster's fade word (read only where DITHER).
    @location(2) @interpolate(flat) fade: u32,
};

// The sRGB transfer function (IEC 61966-2-1), linear to encoded.
fn srgb_encode(c: vec3<f32>) -> vec3<f32> {
    let lo = c * 12.92;
    let hi = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(hi, lo, c <= vec3<f32>(0.0031308));
}

// The sRGB transfer function's inverse (IEC 61966-2-1), encoded to linear.
fn srgb_decode(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

// An sRGB-encoded colour (ColorMode::Shadow's flat mask colours) as the target must receive it:
// as it is where this shader encodes (ENCODE_SRGB), decoded where the target's format encodes.
fn flat_srgb(c: vec3<f32>) -> vec3<f32> {
    if (ENCODE_SRGB) {
        return c;
    }
    return srgb_decode(c);
}

fn unpack_normal(p: u32) -> vec3<f32> {
    let q = bitcast<vec3<i32>>(vec3<u32>(p << 22u, p << 12u, p << 2u)) >> vec3<u32>(22u);
    return vec3<f32>(q) / 511.0;
}

// The triangle's unit normal (`normal` packed as pool.rs writes it), turned towards the viewer
// (Camera::to_viewer: the eye in perspective, the headlight's direction in orthographic): both
// sides are drawn and lit (inputs are not consistently wound). A degenerate normal faces the
// viewer.
fn viewer_normal(normal: u32, position: vec3<f32>) -> vec3<f32> {
    // Arithmetic, not an `if` on the uniform (docs/RUNTIME.md, "Memory": lavapipe compiles a
    // shader anew per pass when a branch tests uniforms alone): w = 1 gives eye − position
    // exactly, w = 0 the headlight.
    let w = u.eye.w;
    let to_eye = normalize((u.eye.xyz - position) * w + u.headlight.xyz * (1.0 - w));
    var n = unpack_normal(normal);
    let len = length(n);
    if (len > 0.0) {
        n = n / len;
    } else {
        n = to_eye;
    }
    if (dot(n, to_eye) < 0.0) {
        n = -n;
    }
    return n;
}

@vertex
fn vs_shade(
    @location(0) position: vec3<f32>,
    @location(1) object: u32,
    @location(2) slot: u32,
    @location(3) normal: u32,
) -> ShadeOut {
    var out: ShadeOut;
    out.clip = u.view_proj * vec4<f32>(position, 1.0);
    out.world = position;
    out.fade = slots[slot].fade;
    let n = viewer_normal(normal, position);
    let head = abs(dot(n, u.headlight.xyz));
    let sun = max(dot(n, u.sun.xyz), 0.0);
    if (COLOR_MODE == 4u) {
        // The shadow mask without shadows (Renderer::set_shadows(None)): the fixed sun reaches
        // every surface facing it.
        out.color = flat_srgb(select(SHADOW_AWAY, SHADOW_LIT, sun > 0.0));
        return out;
    }
    let base = pow(base_color(object, slot), vec3<f32>(2.2));
    var rgb = min(base * (0.18 + 0.62 * head + 0.35 * sun), vec3<f32>(1.0));
    if (ENCODE_SRGB) {
        // A non-sRGB target (the renderer's own Rgba8Unorm target, a Bgra8Unorm surface): encode
        // here, once per vertex, instead of per fragment in the rasterizer (on llvmpipe the sRGB
        // write was a quarter of an interior frame's fill cost).
        rgb = srgb_encode(rgb);
    }
    out.color = rgb;
    return out;
}

// With a section: a fragment on a removed side is discarded, and a back face (the inside of a
// cut solid, seen through the cut) is drawn in the flat SECTION_COLOR so that the cut reads.
// Inputs that are not consistently wound show some back faces anyway; they get the colour too.
fn section_color(color: vec3<f32>, world: vec3<f32>, front: bool) -> vec3<f32> {
    if (section_removes(world)) {
        discard;
    }
    return select(flat_srgb(SECTION_COLOR), color, front);
}

@fragment
fn fs_main(in: ShadeOut, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    if (DITHER) {
        if (!dither_keeps(in.clip.xy, in.fade)) {
            discard;
        }
    }
    if (SECTION) {
        return vec4<f32>(section_color(in.color, in.world, front), 1.0);
    }
    return vec4<f32>(in.color, 1.0);
}
