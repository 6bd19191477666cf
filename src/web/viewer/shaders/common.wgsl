// Shared by every viewer pipeline (prepended to each shader's source).
struct Globals {
    view_proj: mat4x4<f32>,
    eye: vec4<f32>,
    // x, y: viewport in physical pixels; z: point diameter in physical pixels;
    // w: 1 when the target is an sRGB format (colours must be linearised).
    params: vec4<f32>,
};

@group(0) @binding(0) var<uniform> globals: Globals;

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + vec3<f32>(0.055)) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

// Colours are authored in sRGB; only an sRGB target needs them linear.
fn encode_output(c: vec3<f32>) -> vec3<f32> {
    if (globals.params.w > 0.5) {
        return srgb_to_linear(c);
    }
    return c;
}
