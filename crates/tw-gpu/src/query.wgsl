// terawalk occlusion-query proxies: bounding boxes drawn against the frame's depth, no colour
// and no depth writes; only the vertex stage runs (the pass has no colour attachment).

@group(0) @binding(0) var<uniform> view_proj: mat4x4<f32>;

@vertex
fn vs_box(@location(0) position: vec3<f32>) -> @builtin(position) vec4<f32> {
    return view_proj * vec4<f32>(position, 1.0);
}
