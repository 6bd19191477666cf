//! The page's 3D view (wgpu; WebGPU when the browser has it, WebGL2 otherwise):
//! points as screen-space disks coloured by part, by frame or plain, Gaussians
//! as translucent ellipsoids, joint axes, a ground grid; an orbit camera driven
//! by pointer/wheel events the page forwards. Exported to JS as `Viewer`.
//!
//! JS usage:
//! ```js
//! const v = await Viewer.create(canvas, false);   // true forces WebGL2
//! v.resize(canvas.clientWidth, canvas.clientHeight, devicePixelRatio);
//! v.set_points(xyzFloat32, labelsUint32); v.frame_object(); v.render();
//! canvas.onpointerdown = e => v.pointer_down(e.pointerId, e.offsetX, e.offsetY, e.button, e.shiftKey);
//! ```

mod mesh;
mod palette;
mod renderer;

use crate::geom::camera::UpAxis;
use renderer::Renderer;
use std::cell::RefCell;
use std::future::Future;
use std::rc::Rc;
use wasm_bindgen::prelude::*;
use web_sys::HtmlCanvasElement;

/// The 3D viewer bound to one canvas.
#[wasm_bindgen]
pub struct Viewer {
    inner: Rc<RefCell<Renderer>>,
}

fn js_err(e: String) -> JsValue {
    JsValue::from(js_sys::Error::new(&e))
}

#[wasm_bindgen]
impl Viewer {
    /// Open WebGPU (or WebGL2 when WebGPU is missing or `force_webgl`) on `canvas`.
    /// Rejects with a readable message when the browser has neither.
    pub async fn create(canvas: HtmlCanvasElement, force_webgl: bool) -> Result<Viewer, JsValue> {
        console_error_panic_hook::set_once();
        let r = Renderer::create(canvas, force_webgl)
            .await
            .map_err(js_err)?;
        Ok(Viewer {
            inner: Rc::new(RefCell::new(r)),
        })
    }

    /// "webgpu" or "webgl2".
    pub fn backend(&self) -> String {
        self.inner.borrow().backend().to_string()
    }

    /// Graphics adapter as the browser reports it (name, device type, driver).
    pub fn adapter_info(&self) -> String {
        self.inner.borrow().adapter_info().to_string()
    }

    /// MSAA sample count in use (4, or 1 where multisampling is unavailable).
    pub fn sample_count(&self) -> u32 {
        self.inner.borrow().sample_count()
    }

    /// Turn 4× multisampling on or off; returns whether it is on (it stays off
    /// where unsupported). Default: on, except on software renderers.
    pub fn set_msaa(&self, on: bool) -> bool {
        self.inner.borrow_mut().set_msaa(on)
    }

    /// GPU validation errors so far, newline-separated ("" when none).
    pub fn gpu_errors(&self) -> String {
        self.inner.borrow().errors().join("\n")
    }

    /// Size of the canvas in CSS pixels and the device pixel ratio; sets the
    /// canvas's backing size.
    pub fn resize(&self, width: f32, height: f32, dpr: f32) {
        self.inner.borrow_mut().resize(width, height, dpr);
    }

    /// `positions`: N×3 xyz; `labels`: N part labels or empty (0xffffffff = unlabelled).
    pub fn set_points(&self, positions: &[f32], labels: &[u32]) -> Result<(), JsValue> {
        self.inner
            .borrow_mut()
            .set_points(positions, labels)
            .map_err(js_err)
    }

    /// Override colours for the current points (RGBA8, 4 bytes per point; e.g.
    /// colour by frame); shown until the next `set_points`. Empty clears them.
    pub fn set_point_colors(&self, rgba: &[u8]) -> Result<(), JsValue> {
        self.inner
            .borrow_mut()
            .set_point_colors(rgba)
            .map_err(js_err)
    }

    /// 0 = override colours if given, else by part label (default);
    /// 1 = always by part label; 2 = plain grey.
    pub fn set_color_mode(&self, mode: u32) -> Result<(), JsValue> {
        self.inner.borrow_mut().set_color_mode(mode).map_err(js_err)
    }

    /// Point diameter in CSS pixels.
    pub fn set_point_size(&self, px: f32) {
        self.inner.borrow_mut().set_point_size(px);
    }

    /// `centers` m×3, `rotations` m×9 (row-major R), `scales` m×3 (σ per axis),
    /// `parts` m part labels (or empty). Drawn at 1.5σ.
    pub fn set_gaussians(
        &self,
        centers: &[f32],
        rotations: &[f32],
        scales: &[f32],
        parts: &[u32],
    ) -> Result<(), JsValue> {
        self.inner
            .borrow_mut()
            .set_gaussians(centers, rotations, scales, parts)
            .map_err(js_err)
    }

    pub fn set_gaussians_visible(&self, visible: bool) {
        self.inner.borrow_mut().set_gaussians_visible(visible);
    }

    pub fn set_grid_visible(&self, visible: bool) {
        self.inner.borrow_mut().set_grid_visible(visible);
    }

    /// Joint axes: `origins`, `dirs` k×3, `kinds` k (0 revolute, 1 prismatic);
    /// `highlight` = index of the selected joint or -1.
    pub fn set_axes(
        &self,
        origins: &[f32],
        dirs: &[f32],
        kinds: &[u32],
        highlight: i32,
    ) -> Result<(), JsValue> {
        self.inner
            .borrow_mut()
            .set_axes(origins, dirs, kinds, highlight)
            .map_err(js_err)
    }

    /// 0 = x, 1 = y, 2 = z up (default z, as URDF robots).
    pub fn set_up_axis(&self, axis: u32) {
        self.inner
            .borrow_mut()
            .set_up_axis(UpAxis::from_index(axis));
    }

    /// Draw one frame to the canvas (call from requestAnimationFrame when something changed).
    pub fn render(&self) -> Result<(), JsValue> {
        self.inner.borrow_mut().render().map_err(js_err)
    }

    /// Render the current scene into a `width`×`height` image and resolve to its
    /// RGBA8 bytes (rows top to bottom, not sRGB-encoded): tests and PNG export.
    pub fn render_offscreen_rgba(&self, width: u32, height: u32) -> js_sys::Promise {
        let fut = self.offscreen_rgba(width, height);
        wasm_bindgen_futures::future_to_promise(async move {
            let bytes = fut.await?;
            Ok(js_sys::Uint8Array::from(bytes.as_slice()).into())
        })
    }

    // ----------------------------------------------------------- camera

    /// Default orientation, framing the current points.
    pub fn reset_view(&self) {
        self.inner.borrow_mut().reset_view();
    }

    /// Fit the current points in view, keeping the orientation.
    pub fn frame_object(&self) {
        self.inner.borrow_mut().frame_object();
    }

    /// Orbit as if dragged by (dx, dy) CSS pixels.
    pub fn orbit(&self, dx: f32, dy: f32) {
        self.inner.borrow_mut().camera.orbit(dx, dy);
    }

    /// Turn the camera about the up axis by `radians` (turntable).
    pub fn turn(&self, radians: f32) {
        self.inner.borrow_mut().camera.turn(radians);
    }

    /// Pan as if dragged by (dx, dy) CSS pixels.
    pub fn pan(&self, dx: f32, dy: f32) {
        self.inner.borrow_mut().camera.pan(dx, dy);
    }

    /// Multiply the camera distance by `factor` (< 1 zooms in).
    pub fn zoom(&self, factor: f32) {
        self.inner.borrow_mut().camera.zoom(factor);
    }

    /// `WheelEvent.deltaY` in pixels (multiply line-mode deltas by ~16).
    pub fn wheel(&self, delta_y: f32) {
        self.inner.borrow_mut().camera.wheel(delta_y);
    }

    /// Forward `pointerdown` (offsetX/Y in CSS pixels, `button`, `shiftKey`).
    pub fn pointer_down(&self, id: i32, x: f32, y: f32, button: i32, shift: bool) {
        self.inner
            .borrow_mut()
            .gestures
            .pointer_down(id, x, y, button, shift);
    }

    /// Forward `pointermove`; true when the camera moved (redraw).
    pub fn pointer_move(&self, id: i32, x: f32, y: f32) -> bool {
        let mut r = self.inner.borrow_mut();
        let r = &mut *r;
        r.gestures.pointer_move(&mut r.camera, id, x, y)
    }

    /// Forward `pointerup`.
    pub fn pointer_up(&self, id: i32) {
        self.inner.borrow_mut().gestures.pointer_up(id);
    }

    /// Forward `pointercancel` / blur: forget every active pointer.
    pub fn pointer_cancel(&self) {
        self.inner.borrow_mut().gestures.cancel();
    }

    /// The view as text for the URL hash (`t=x,y,z;d=..;y=..;p=..;u=..`).
    pub fn camera_state(&self) -> String {
        self.inner.borrow().camera.to_state_string()
    }

    /// Restore a view from [`Viewer::camera_state`] text; bad text is an error
    /// and leaves the view unchanged.
    pub fn set_camera_state(&self, state: &str) -> Result<(), JsValue> {
        let mut r = self.inner.borrow_mut();
        r.camera
            .apply_state_string(state)
            .map_err(|e| js_err(e.to_string()))?;
        r.refresh_after_camera_state();
        Ok(())
    }
}

impl Viewer {
    /// Rust-side form of [`Viewer::render_offscreen_rgba`]; the future does not
    /// borrow the viewer while it waits.
    pub fn offscreen_rgba(
        &self,
        width: u32,
        height: u32,
    ) -> impl Future<Output = Result<Vec<u8>, JsValue>> + 'static {
        let pending = self.inner.borrow_mut().encode_offscreen(width, height);
        async move {
            let readback = pending.map_err(js_err)?;
            readback.read().await.map_err(js_err)
        }
    }
}

/// sRGB colour `[r, g, b]` of part label `i` in the viewer's palette (cycles).
#[wasm_bindgen]
pub fn palette_color(i: u32) -> Vec<u8> {
    palette::color(i).to_vec()
}

/// Same colour as a CSS `#rrggbb` string, for legends and the tree diagram.
#[wasm_bindgen]
pub fn palette_css(i: u32) -> String {
    let [r, g, b] = palette::color(i);
    format!("#{r:02x}{g:02x}{b:02x}")
}

/// The first `n` palette colours as `[r0, g0, b0, r1, ...]` (n ≤ 4096), for
/// the page's legend and tree diagram.
#[wasm_bindgen]
pub fn part_palette(n: u32) -> Vec<u8> {
    (0..n.min(4096)).flat_map(palette::color).collect()
}

/// Number of distinct palette colours before it repeats.
#[wasm_bindgen]
pub fn palette_size() -> u32 {
    palette::PALETTE.len() as u32
}

/// Resolve after `ms` milliseconds via the global `setTimeout` (window or worker).
async fn sleep_ms(ms: i32) {
    let promise = js_sys::Promise::new(&mut |resolve, _reject| {
        let global = js_sys::global();
        let set_timeout = js_sys::Reflect::get(&global, &JsValue::from_str("setTimeout"))
            .ok()
            .and_then(|f| f.dyn_into::<js_sys::Function>().ok());
        match set_timeout {
            Some(f) => {
                if f.call2(&global, &resolve, &JsValue::from(ms)).is_err() {
                    let _ = resolve.call0(&JsValue::NULL);
                }
            }
            None => {
                let _ = resolve.call0(&JsValue::NULL);
            }
        }
    });
    let _ = wasm_bindgen_futures::JsFuture::from(promise).await;
}
