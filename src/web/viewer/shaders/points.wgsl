// Points as screen-space disks: one triangle (3 vertices sharing the centre)
// around the unit disk per point, round by discard,
// shaded as a tiny sphere lit from the viewer (the centre keeps the exact colour).
struct PointOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) color: vec3<f32>,
};

@vertex
fn vs_main(
    @builtin(vertex_index) vi: u32,
    @location(0) center: vec3<f32>,
    @location(1) color: vec4<f32>,
) -> PointOut {
    // Equilateral triangle with the unit circle as its incircle.
    let k = vi % 3u;
    var corner = vec2<f32>(0.0, 2.0);
    if (k == 1u) {
        corner = vec2<f32>(-1.7320508, -1.0);
    } else if (k == 2u) {
        corner = vec2<f32>(1.7320508, -1.0);
    }
    var out: PointOut;
    var clip = globals.view_proj * vec4<f32>(center, 1.0);
    // Half a diameter in NDC is size / viewport.
    let offset = corner * globals.params.z / globals.params.xy;
    clip = vec4<f32>(clip.xy + offset * clip.w, clip.z, clip.w);
    out.clip = clip;
    out.uv = corner;
    out.color = color.rgb;
    return out;
}

@fragment
fn fs_main(in: PointOut) -> @location(0) vec4<f32> {
    let r2 = dot(in.uv, in.uv);
    if (r2 > 1.0) {
        discard;
    }
    let nz = sqrt(1.0 - r2);
    let shade = 0.55 + 0.45 * nz;
    return vec4<f32>(encode_output(in.color * shade), 1.0);
}
