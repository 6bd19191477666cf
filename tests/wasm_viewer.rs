//! Browser tests of the wgpu viewer (headless Chromium through
//! wasm-bindgen-test-runner; flags in `webdriver.json`): on WebGPU and on
//! forced WebGL2, draw points, Gaussians and an axis offscreen, read the pixels
//! back and check what is on screen.
//!
//! Run: `CHROMEDRIVER=/usr/bin/chromedriver cargo test --target wasm32-unknown-unknown --test wasm_viewer`
#![cfg(target_arch = "wasm32")]

use gsart::web::viewer::{palette_color, palette_css, palette_size, Viewer};
use wasm_bindgen::JsCast;
use wasm_bindgen_test::*;

wasm_bindgen_test_configure!(run_in_browser);

const W: u32 = 160;
const H: u32 = 120;
const BACKGROUND: [u8; 3] = [242, 242, 240];

fn canvas(w: u32, h: u32) -> web_sys::HtmlCanvasElement {
    let doc = web_sys::window().unwrap().document().unwrap();
    let c: web_sys::HtmlCanvasElement = doc.create_element("canvas").unwrap().unchecked_into();
    c.set_width(w);
    c.set_height(h);
    c
}

/// Two clusters of points: label 0 at x < 0, label 1 at x > 0, `n` points
/// each on a grid in the x-y plane (z up, slightly jittered in height).
fn two_clusters(n: usize, shift: f32) -> (Vec<f32>, Vec<u32>) {
    let mut pos = Vec::new();
    let mut labels = Vec::new();
    let side = (n as f32).sqrt().ceil() as usize;
    for label in 0..2u32 {
        for i in 0..n {
            let (u, v) = (
                (i % side) as f32 / side as f32,
                (i / side) as f32 / side as f32,
            );
            let x = if label == 0 {
                -0.5 + 0.4 * u
            } else {
                0.1 + 0.4 * u
            } + shift;
            pos.extend_from_slice(&[x, -0.3 + 0.6 * v, 0.05 * ((i * 7) % 5) as f32 / 5.0]);
            labels.push(label);
        }
    }
    (pos, labels)
}

fn near(p: &[u8], c: &[u8], tol: i32) -> bool {
    (0..3).all(|k| (p[k] as i32 - c[k] as i32).abs() <= tol)
}

fn count_near(img: &[u8], c: &[u8], tol: i32) -> usize {
    img.chunks_exact(4).filter(|p| near(p, c, tol)).count()
}

fn diff_pixels(a: &[u8], b: &[u8]) -> usize {
    a.chunks_exact(4)
        .zip(b.chunks_exact(4))
        .filter(|(p, q)| (0..3).any(|k| (p[k] as i32 - q[k] as i32).abs() > 8))
        .count()
}

async fn suite(force_webgl: bool, msaa: bool) {
    let v = Viewer::create(canvas(W, H), force_webgl)
        .await
        .unwrap_or_else(|e| panic!("viewer creation failed (force_webgl={force_webgl}): {e:?}"));
    let expected = if force_webgl { "webgl2" } else { "webgpu" };
    assert_eq!(v.backend(), expected);
    assert_eq!(
        v.set_msaa(msaa),
        msaa,
        "{expected}: MSAA should be available"
    );
    assert_eq!(v.sample_count(), if msaa { 4 } else { 1 });
    let (pos, labels) = two_clusters(150, 0.0);
    v.set_points(&pos, &labels).unwrap();
    v.set_point_size(7.0);
    v.reset_view();
    v.set_grid_visible(false);

    let img = v.offscreen_rgba(W, H).await.unwrap();
    assert_eq!(img.len(), (W * H * 4) as usize);
    let total = (W * H) as usize;
    let bg = count_near(&img, &BACKGROUND, 2);
    assert!(
        bg > total / 4,
        "{expected}: background should dominate, got {bg}/{total}"
    );
    assert!(
        bg < total - 500,
        "{expected}: points missing, {bg}/{total} background"
    );
    let c0 = palette_color(0);
    let c1 = palette_color(1);
    let n0 = count_near(&img, &c0, 3);
    let n1 = count_near(&img, &c1, 3);
    assert!(
        n0 > 20 && n1 > 20,
        "{expected}: palette colours 0/1 seen {n0}/{n1} times"
    );

    // The clusters land on opposite halves of the image.
    let side = |c: &[u8], left: bool| {
        img.chunks_exact(4)
            .enumerate()
            .filter(|(i, p)| ((i % W as usize) < W as usize / 2) == left && near(p, c, 3))
            .count()
    };
    let (l0, r0, l1, r1) = (
        side(&c0, true),
        side(&c0, false),
        side(&c1, true),
        side(&c1, false),
    );
    assert!(
        (l0 > r0) != (l1 > r1),
        "{expected}: clusters should sit on opposite sides: {l0} {r0} {l1} {r1}"
    );

    // The grid draws something of its own.
    v.set_grid_visible(true);
    let with_grid = v.offscreen_rgba(W, H).await.unwrap();
    assert!(
        diff_pixels(&img, &with_grid) > 50,
        "{expected}: grid not visible"
    );
    v.set_grid_visible(false);

    // Moving the camera changes the picture; restoring the state restores it.
    let state = v.camera_state();
    v.orbit(60.0, 20.0);
    let turned = v.offscreen_rgba(W, H).await.unwrap();
    assert!(
        diff_pixels(&img, &turned) > 200,
        "{expected}: orbit changed nothing"
    );
    v.set_camera_state(&state).unwrap();
    let back = v.offscreen_rgba(W, H).await.unwrap();
    assert!(
        diff_pixels(&img, &back) < 20,
        "{expected}: camera state did not restore the view"
    );
    v.zoom(0.5);
    let zoomed = v.offscreen_rgba(W, H).await.unwrap();
    let bg_zoomed = count_near(&zoomed, &BACKGROUND, 2);
    assert!(
        bg_zoomed < bg,
        "{expected}: zooming in should fill more of the view ({bg_zoomed} vs {bg})"
    );
    v.set_camera_state(&state).unwrap();
    assert!(v.set_camera_state("d=banana").is_err());

    // Changing the points changes the picture.
    let (pos2, labels2) = two_clusters(150, 0.25);
    v.set_points(&pos2, &labels2).unwrap();
    let moved = v.offscreen_rgba(W, H).await.unwrap();
    assert!(
        diff_pixels(&img, &moved) > 200,
        "{expected}: new points changed nothing"
    );
    v.set_points(&pos, &labels).unwrap();

    // Override colours replace the palette (mode 0), mode 1 ignores them, mode
    // 2 is plain, and new points drop the override.
    let red = [255u8, 0, 0, 255].repeat(300);
    v.set_point_colors(&red).unwrap();
    let custom = v.offscreen_rgba(W, H).await.unwrap();
    assert!(
        count_near(&custom, &[255, 0, 0], 3) > 40,
        "{expected}: override colours not drawn"
    );
    assert_eq!(count_near(&custom, &c0, 3), 0);
    v.set_color_mode(1).unwrap();
    let by_label = v.offscreen_rgba(W, H).await.unwrap();
    assert_eq!(count_near(&by_label, &[255, 0, 0], 3), 0);
    assert!(count_near(&by_label, &c0, 3) > 20);
    v.set_color_mode(2).unwrap();
    let plain = v.offscreen_rgba(W, H).await.unwrap();
    assert_eq!(count_near(&plain, &c0, 3) + count_near(&plain, &c1, 3), 0);
    v.set_color_mode(0).unwrap();
    v.set_points(&pos, &labels).unwrap();
    let dropped = v.offscreen_rgba(W, H).await.unwrap();
    assert_eq!(count_near(&dropped, &[255, 0, 0], 3), 0);
    assert!(v.set_color_mode(7).is_err());
    assert!(v.set_point_colors(&[1, 2, 3, 4]).is_err());

    // Gaussians: two translucent ellipsoids over the clusters change the
    // picture, hiding them restores it.
    v.set_gaussians(
        &[-0.3, 0.0, 0.0, 0.3, 0.0, 0.0],
        &[
            1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, //
            0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0,
        ],
        &[0.1, 0.05, 0.15, 0.08, 0.08, 0.08],
        &[2, 3],
    )
    .unwrap();
    let gauss = v.offscreen_rgba(W, H).await.unwrap();
    assert!(
        diff_pixels(&img, &gauss) > 300,
        "{expected}: Gaussians not visible"
    );
    v.set_gaussians_visible(false);
    let hidden = v.offscreen_rgba(W, H).await.unwrap();
    assert!(
        diff_pixels(&img, &hidden) < 20,
        "{expected}: hiding Gaussians did not restore"
    );
    assert!(v
        .set_gaussians(&[0.0; 3], &[0.0; 8], &[0.1; 3], &[])
        .is_err());

    // Translucent Gaussians blend back to front whatever their input order:
    // two spheres on the line of sight, given in both orders, look the same.
    let state = v.camera_state();
    v.set_camera_state("t=0,0,0;d=3;y=0;p=0;u=2").unwrap();
    v.set_points(&[], &[]).unwrap();
    v.set_gaussians_visible(true);
    let eye = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let rots = [eye, eye].concat();
    let scales = [0.2f32; 6];
    let centre = |img: &[u8]| {
        let i = 4 * ((H / 2) * W + W / 2) as usize;
        [img[i], img[i + 1], img[i + 2]]
    };
    v.set_gaussians(&[0.5, 0.0, 0.0, -0.5, 0.0, 0.0], &rots, &scales, &[0, 1])
        .unwrap();
    let near_first = centre(&v.offscreen_rgba(W, H).await.unwrap());
    v.set_gaussians(&[-0.5, 0.0, 0.0, 0.5, 0.0, 0.0], &rots, &scales, &[1, 0])
        .unwrap();
    let far_first = centre(&v.offscreen_rgba(W, H).await.unwrap());
    assert!(
        near(&near_first, &far_first, 2),
        "{expected}: blend depends on input order: {near_first:?} vs {far_first:?}"
    );
    // Exactly "near over (far over background)" at alpha 0.35, fully lit at the centre.
    let (cn, cf) = (palette_color(0), palette_color(1));
    let want: Vec<u8> = (0..3)
        .map(|k| {
            let far_over = 0.35 * cf[k] as f32 + 0.65 * BACKGROUND[k] as f32;
            (0.35 * cn[k] as f32 + 0.65 * far_over).round() as u8
        })
        .collect();
    assert!(
        near(&near_first, &want, 4),
        "{expected}: blend {near_first:?}, want near-over-far {want:?}"
    );
    v.set_gaussians(&[], &[], &[], &[]).unwrap();
    v.set_points(&pos, &labels).unwrap();
    v.set_camera_state(&state).unwrap();

    // A joint axis above the cloud is drawn; a highlighted prismatic arrow differs.
    v.set_axes(&[0.0, 0.0, 0.3], &[1.0, 0.0, 0.0], &[0], -1)
        .unwrap();
    let axis = v.offscreen_rgba(W, H).await.unwrap();
    assert!(diff_pixels(&img, &axis) > 30, "{expected}: axis not drawn");
    v.set_axes(&[0.0, 0.0, 0.3], &[0.0, 0.0, 1.0], &[1], 0)
        .unwrap();
    let arrow = v.offscreen_rgba(W, H).await.unwrap();
    assert!(
        diff_pixels(&axis, &arrow) > 30,
        "{expected}: prismatic highlighted arrow not drawn"
    );
    assert!(v.set_axes(&[0.0; 3], &[1.0, 0.0, 0.0], &[5], -1).is_err());

    // Input validation.
    assert!(v.set_points(&[0.0; 4], &[]).is_err());
    assert!(v.set_points(&[0.0; 6], &[1]).is_err());

    // On-screen draws must not raise GPU errors either.
    v.resize(200.0, 100.0, 2.0);
    v.render().unwrap();
    v.render().unwrap();
    let errors = v.gpu_errors();
    assert!(errors.is_empty(), "{expected}: GPU errors: {errors}");
}

#[wasm_bindgen_test]
async fn webgpu_draws_points_gaussians_axes() {
    suite(false, false).await;
}

#[wasm_bindgen_test]
async fn webgpu_msaa_draws_points_gaussians_axes() {
    suite(false, true).await;
}

#[wasm_bindgen_test]
async fn webgl2_draws_points_gaussians_axes() {
    suite(true, false).await;
}

#[wasm_bindgen_test]
async fn webgl2_msaa_draws_points_gaussians_axes() {
    suite(true, true).await;
}

#[wasm_bindgen_test]
fn palette_is_shared_and_distinct() {
    let n = palette_size();
    assert!(n >= 10);
    assert_eq!(palette_color(0), palette_color(n));
    let table = gsart::web::viewer::part_palette(n + 1);
    assert_eq!(table.len() as u32, 3 * (n + 1));
    assert_eq!(&table[3 * n as usize..], palette_color(0).as_slice());
    let c = palette_color(0);
    assert_eq!(
        palette_css(0),
        format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
    );
    for i in 0..n {
        for j in 0..i {
            let (a, b) = (palette_color(i), palette_color(j));
            let d: i32 = (0..3).map(|k| (a[k] as i32 - b[k] as i32).abs()).sum();
            assert!(d > 40, "palette colours {i} and {j} are too close");
        }
    }
}

/// Frame time for 40k points + 15 Gaussians (printed; only sanity-checked):
/// on-screen frames at 800×600, with a read-back every few frames so the GPU
/// work is inside the measurement.
async fn frame_time(force_webgl: bool, msaa: bool) -> f64 {
    let v = Viewer::create(canvas(800, 600), force_webgl).await.unwrap();
    v.set_msaa(msaa);
    v.resize(800.0, 600.0, 1.0);
    let n = 40_000usize;
    let mut pos = Vec::with_capacity(3 * n);
    let mut labels = Vec::with_capacity(n);
    for i in 0..n {
        let t = i as f32 * 0.618_034 * std::f32::consts::TAU;
        let z = (i as f32 / n as f32) * 2.0 - 1.0;
        let r = (1.0 - z * z).sqrt() * 0.5;
        pos.extend_from_slice(&[r * t.cos(), r * t.sin(), z * 0.5]);
        labels.push((i * 15 / n) as u32);
    }
    v.set_points(&pos, &labels).unwrap();
    let m = 15;
    let centers: Vec<f32> = (0..m)
        .flat_map(|k| [0.0, 0.0, k as f32 / m as f32 - 0.5])
        .collect();
    let rot: Vec<f32> = (0..m)
        .flat_map(|_| [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0])
        .collect();
    let scales: Vec<f32> = (0..m).flat_map(|_| [0.2, 0.15, 0.05]).collect();
    let parts: Vec<u32> = (0..m as u32).collect();
    v.set_gaussians(&centers, &rot, &scales, &parts).unwrap();
    v.set_axes(&[0.0, 0.0, 0.0], &[0.0, 0.0, 1.0], &[0], 0)
        .unwrap();
    v.reset_view();
    v.render().unwrap();
    v.offscreen_rgba(4, 4).await.unwrap();
    let perf = web_sys::window().unwrap().performance().unwrap();
    let frames = 10;
    let t0 = perf.now();
    for i in 0..frames {
        v.orbit(3.0, 0.0);
        v.render().unwrap();
        if i % 5 == 4 {
            v.offscreen_rgba(4, 4).await.unwrap();
        }
    }
    v.offscreen_rgba(4, 4).await.unwrap();
    let ms = (perf.now() - t0) / frames as f64;
    assert!(v.gpu_errors().is_empty(), "{}", v.gpu_errors());
    console_log!(
        "frame time {} [{}] (800x600, 40k points, 15 Gaussians, MSAA x{}): {ms:.2} ms",
        v.backend(),
        v.adapter_info(),
        v.sample_count()
    );
    ms
}

// Benchmarks (slow on SwiftShader under load): `... --test wasm_viewer -- --include-ignored --nocapture`.
#[wasm_bindgen_test]
#[ignore = "benchmark"]
async fn frame_time_40k_points_webgpu() {
    assert!(frame_time(false, false).await > 0.0);
    assert!(frame_time(false, true).await > 0.0);
}

#[wasm_bindgen_test]
#[ignore = "benchmark"]
async fn frame_time_40k_points_webgl2() {
    assert!(frame_time(true, false).await > 0.0);
    assert!(frame_time(true, true).await > 0.0);
}

/// A canvas that already has a 2D context cannot give WebGL2 (or WebGPU): the
/// viewer must reject with a readable message, not panic.
#[wasm_bindgen_test]
async fn unusable_canvas_gives_a_clear_error() {
    for force_webgl in [true, false] {
        let c = canvas(64, 64);
        assert!(c.get_context("2d").unwrap().is_some());
        let err = match Viewer::create(c, force_webgl).await {
            Ok(v) => panic!("created a {} viewer on a 2D canvas", v.backend()),
            Err(e) => e,
        };
        let text = js_sys::Error::from(err)
            .message()
            .as_string()
            .unwrap_or_default();
        assert!(
            text.contains("3D view cannot start"),
            "force_webgl={force_webgl}: unclear error: {text}"
        );
    }
}

/// Pointer and wheel input move the camera (and report it so the page redraws).
#[wasm_bindgen_test]
async fn pointer_and_wheel_input_move_the_camera() {
    let v = Viewer::create(canvas(W, H), true).await.unwrap();
    let (pos, labels) = two_clusters(50, 0.0);
    v.set_points(&pos, &labels).unwrap();
    v.reset_view();
    let s0 = v.camera_state();
    v.pointer_down(1, 50.0, 50.0, 0, false);
    assert!(v.pointer_move(1, 80.0, 60.0));
    v.pointer_up(1);
    assert!(!v.pointer_move(1, 90.0, 60.0), "no drag after pointer up");
    let s1 = v.camera_state();
    assert_ne!(s0, s1);
    // Two fingers spreading apart zoom in (the distance field shrinks).
    let dist = |s: &str| -> f32 {
        s.split(';')
            .find_map(|f| f.strip_prefix("d="))
            .unwrap()
            .parse()
            .unwrap()
    };
    v.pointer_down(2, 40.0, 60.0, 0, false);
    v.pointer_down(3, 80.0, 60.0, 0, false);
    v.pointer_move(3, 120.0, 60.0);
    v.pointer_cancel();
    let s2 = v.camera_state();
    assert!(dist(&s2) < dist(&s1), "{s1} -> {s2}");
    v.wheel(200.0);
    assert!(dist(&v.camera_state()) > dist(&s2));
    v.frame_object();
    v.pan(10.0, 0.0);
    assert_ne!(v.camera_state(), s2);
}

/// The on-screen canvas shows the same colours as the offscreen image (the
/// canvas format and sRGB handling are right), read back through a 2D canvas
/// in the same task as the draw.
async fn on_screen_matches(force_webgl: bool) {
    let c = canvas(W, H);
    let v = Viewer::create(c.clone(), force_webgl).await.unwrap();
    let (pos, labels) = two_clusters(150, 0.0);
    v.set_points(&pos, &labels).unwrap();
    v.set_point_size(7.0);
    v.reset_view();
    v.resize(W as f32, H as f32, 1.0);
    v.render().unwrap();
    let copy = canvas(W, H);
    let ctx: web_sys::CanvasRenderingContext2d =
        copy.get_context("2d").unwrap().unwrap().unchecked_into();
    ctx.draw_image_with_html_canvas_element(&c, 0.0, 0.0)
        .unwrap();
    let shown = ctx
        .get_image_data(0.0, 0.0, W as f64, H as f64)
        .unwrap()
        .data()
        .0;
    let backend = v.backend();
    assert!(
        count_near(&shown, &BACKGROUND, 3) > (W * H / 4) as usize,
        "{backend}: canvas background wrong"
    );
    for i in 0..2 {
        let n = count_near(&shown, &palette_color(i), 4);
        assert!(
            n > 20,
            "{backend}: palette colour {i} on the canvas {n} times"
        );
    }
    let offscreen = v.offscreen_rgba(W, H).await.unwrap();
    assert!(
        diff_pixels(&shown, &offscreen) < (W * H / 20) as usize,
        "{backend}: canvas and offscreen image differ"
    );
}

#[wasm_bindgen_test]
async fn on_screen_colours_webgpu() {
    on_screen_matches(false).await;
}

#[wasm_bindgen_test]
async fn on_screen_colours_webgl2() {
    on_screen_matches(true).await;
}
