// terawalk cluster shader: flat shading from screen-space derivatives, a headlight plus a fixed
// sun, colour per vertex (sRGB bytes, decoded here; the target is an sRGB format).

struct Uniforms {
    view_proj: mat4x4<f32>,
    // xyz: eye in scene space.
    eye: vec4<f32>,
    // xyz: unit direction towards the sun; w: 1 when the target needs sRGB encoding here.
    sun: vec4<f32>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) color: vec4<f32>,
};

@vertex
fn vs_main(@location(0) position: vec3<f32>, @location(1) color: vec4<f32>) -> VertexOut {
    var out: VertexOut;
    out.clip = u.view_proj * vec4<f32>(position, 1.0);
    out.world = position;
    out.color = color;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let to_eye = normalize(u.eye.xyz - in.world);
    let c = cross(dpdx(in.world), dpdy(in.world));
    let len = length(c);
    var n = to_eye;
    if (len > 0.0) {
        n = c / len;
    }
    // Both sides are drawn (inputs are not consistently wound): face the viewer.
    if (dot(n, to_eye) < 0.0) {
        n = -n;
    }
    let head = max(dot(n, to_eye), 0.0);
    let sun = max(dot(n, u.sun.xyz), 0.0);
    let base = pow(in.color.rgb, vec3<f32>(2.2));
    let lit = base * (0.18 + 0.62 * head + 0.35 * sun);
    var rgb = min(lit, vec3<f32>(1.0));
    if (u.sun.w > 0.5) {
        // A non-sRGB target (e.g. a Bgra8Unorm surface): encode here.
        rgb = pow(rgb, vec3<f32>(1.0 / 2.2));
    }
    return vec4<f32>(rgb, 1.0);
}
