// Lit opaque meshes (joint axes, arrows) and unlit lines (ground grid, triad).
struct MeshOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) world: vec3<f32>,
    @location(2) color: vec3<f32>,
};

@vertex
fn vs_main(
    @location(0) pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
) -> MeshOut {
    var out: MeshOut;
    out.clip = globals.view_proj * vec4<f32>(pos, 1.0);
    out.normal = normal;
    out.world = pos;
    out.color = color.rgb;
    return out;
}

fn lit(in: MeshOut) -> vec3<f32> {
    let n = normalize(in.normal);
    let l = normalize(globals.eye.xyz - in.world);
    return in.color * (0.4 + 0.6 * abs(dot(n, l)));
}

@fragment
fn fs_lit(in: MeshOut) -> @location(0) vec4<f32> {
    return vec4<f32>(encode_output(lit(in)), 1.0);
}

// Where an axis is hidden behind the object it still shows, faintly.
@fragment
fn fs_xray(in: MeshOut) -> @location(0) vec4<f32> {
    return vec4<f32>(encode_output(lit(in)), 0.35);
}

@fragment
fn fs_unlit(in: MeshOut) -> @location(0) vec4<f32> {
    return vec4<f32>(encode_output(in.color), 1.0);
}
