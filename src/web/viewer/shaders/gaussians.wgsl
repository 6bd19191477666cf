// Gaussians as translucent ellipsoids: a unit sphere mesh scaled by k·sigma,
// rotated by R and moved to the centre (one instance per Gaussian).
const SIGMA_SCALE: f32 = 1.5;
const ALPHA: f32 = 0.35;

struct GaussOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) world: vec3<f32>,
    @location(2) color: vec3<f32>,
};

@vertex
fn vs_main(
    @location(0) unit: vec3<f32>,
    @location(1) center: vec3<f32>,
    @location(2) r0: vec3<f32>,
    @location(3) r1: vec3<f32>,
    @location(4) r2: vec3<f32>,
    @location(5) scale: vec3<f32>,
    @location(6) color: vec4<f32>,
) -> GaussOut {
    // r0, r1, r2 are the columns of R.
    let s = max(scale, vec3<f32>(1e-6)) * SIGMA_SCALE;
    let local = unit * s;
    let world = center + r0 * local.x + r1 * local.y + r2 * local.z;
    // Ellipsoid normal: inverse-transpose of R·S is R·S⁻¹.
    let ln = unit / s;
    let n = r0 * ln.x + r1 * ln.y + r2 * ln.z;
    var out: GaussOut;
    out.clip = globals.view_proj * vec4<f32>(world, 1.0);
    out.normal = n;
    out.world = world;
    out.color = color.rgb;
    return out;
}

@fragment
fn fs_main(in: GaussOut) -> @location(0) vec4<f32> {
    let n = normalize(in.normal);
    let l = normalize(globals.eye.xyz - in.world);
    let shade = 0.45 + 0.55 * abs(dot(n, l));
    return vec4<f32>(encode_output(in.color * shade), ALPHA);
}
