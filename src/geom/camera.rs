//! Orbit camera for the 3D viewer: orbit / pan / zoom, view and projection
//! matrices, framing a bounding box, a compact text form for sharing a view in
//! the URL hash, and the pointer/touch gesture state machine that drives it.
//!
//! Pure math (no browser types) so it is unit-tested natively; `web::viewer`
//! only forwards DOM events here.

use crate::error::{Error, Result};
use crate::math::Libm;
use glam::{Mat4, Vec3};

/// Which world axis points up on screen (URDF robots are z-up, many meshes y-up).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UpAxis {
    X,
    Y,
    Z,
}

impl UpAxis {
    /// 0 = x, 1 = y, anything else = z (the default for robots).
    pub fn from_index(i: u32) -> Self {
        match i {
            0 => UpAxis::X,
            1 => UpAxis::Y,
            _ => UpAxis::Z,
        }
    }

    pub fn index(self) -> u32 {
        match self {
            UpAxis::X => 0,
            UpAxis::Y => 1,
            UpAxis::Z => 2,
        }
    }

    /// Right-handed basis (a, b, up): yaw turns in the a–b plane.
    pub fn basis(self) -> (Vec3, Vec3, Vec3) {
        match self {
            UpAxis::Z => (Vec3::X, Vec3::Y, Vec3::Z),
            UpAxis::Y => (Vec3::Z, Vec3::X, Vec3::Y),
            UpAxis::X => (Vec3::Y, Vec3::Z, Vec3::X),
        }
    }
}

/// Radians per CSS pixel of drag when orbiting.
const ORBIT_SPEED: f32 = 0.008;
/// Keep the camera off the poles so `look_at` stays well defined.
const MAX_PITCH: f32 = std::f32::consts::FRAC_PI_2 - 0.01;
const MIN_DISTANCE: f32 = 1e-4;
const MAX_DISTANCE: f32 = 1e6;
const DEFAULT_YAW: f32 = -1.0;
const DEFAULT_PITCH: f32 = 0.35;

/// A camera orbiting `target` at `distance`, direction given by yaw/pitch around
/// the up axis. The viewport size (CSS pixels) is kept so pixel drags map to
/// world motion.
#[derive(Debug, Clone, PartialEq)]
pub struct OrbitCamera {
    pub target: Vec3,
    pub distance: f32,
    pub yaw: f32,
    pub pitch: f32,
    /// Vertical field of view in radians.
    pub fov_y: f32,
    pub up: UpAxis,
    pub viewport: [f32; 2],
}

impl Default for OrbitCamera {
    fn default() -> Self {
        OrbitCamera {
            target: Vec3::ZERO,
            distance: 2.0,
            yaw: DEFAULT_YAW,
            pitch: DEFAULT_PITCH,
            fov_y: 45f32.to_radians(),
            up: UpAxis::Z,
            viewport: [800.0, 600.0],
        }
    }
}

impl OrbitCamera {
    /// Unit vector from target to eye.
    pub fn eye_direction(&self) -> Vec3 {
        let (a, b, up) = self.up.basis();
        let (sy, cy) = self.yaw.lsin_cos();
        let (sp, cp) = self.pitch.lsin_cos();
        a * (cp * cy) + b * (cp * sy) + up * sp
    }

    pub fn eye(&self) -> Vec3 {
        self.target + self.eye_direction() * self.distance
    }

    pub fn aspect(&self) -> f32 {
        let [w, h] = self.viewport;
        if w > 0.0 && h > 0.0 {
            w / h
        } else {
            1.0
        }
    }

    pub fn set_viewport(&mut self, width: f32, height: f32) {
        if width.is_finite() && height.is_finite() && width > 0.0 && height > 0.0 {
            self.viewport = [width, height];
        }
    }

    pub fn view_matrix(&self) -> Mat4 {
        Mat4::look_at_rh(self.eye(), self.target, self.up.basis().2)
    }

    /// Perspective with WebGPU depth range [0, 1]; near/far follow the distance
    /// so any scene scale keeps depth precision.
    pub fn projection_matrix(&self) -> Mat4 {
        let near = self.distance * 0.01;
        let far = self.distance * 100.0;
        Mat4::perspective_rh(self.fov_y, self.aspect(), near, far)
    }

    pub fn view_projection(&self) -> Mat4 {
        self.projection_matrix() * self.view_matrix()
    }

    /// Camera right and up vectors in world space.
    pub fn screen_axes(&self) -> (Vec3, Vec3) {
        let forward = -self.eye_direction();
        let world_up = self.up.basis().2;
        let right = forward.cross(world_up).normalize_or(Vec3::X);
        let up = right.cross(forward);
        (right, up)
    }

    /// Drag by (dx, dy) CSS pixels: dragging right turns the object right,
    /// dragging down tilts it towards the viewer.
    pub fn orbit(&mut self, dx: f32, dy: f32) {
        if !(dx.is_finite() && dy.is_finite()) {
            return;
        }
        self.yaw = (self.yaw - dx * ORBIT_SPEED).rem_euclid(std::f32::consts::TAU);
        self.pitch = (self.pitch + dy * ORBIT_SPEED).clamp(-MAX_PITCH, MAX_PITCH);
    }

    /// Turn the camera about the up axis by `radians` (a turntable; the video export
    /// turns it once around in equal steps).
    pub fn turn(&mut self, radians: f32) {
        if radians.is_finite() {
            self.yaw = (self.yaw + radians).rem_euclid(std::f32::consts::TAU);
        }
    }

    /// World units per CSS pixel at the target's depth.
    pub fn world_per_pixel(&self) -> f32 {
        2.0 * self.distance * (self.fov_y * 0.5).ltan() / self.viewport[1].max(1.0)
    }

    /// Move the target so the scene follows the pointer by (dx, dy) CSS pixels.
    pub fn pan(&mut self, dx: f32, dy: f32) {
        if !(dx.is_finite() && dy.is_finite()) {
            return;
        }
        let (right, up) = self.screen_axes();
        let s = self.world_per_pixel();
        self.target += (-right * dx + up * dy) * s;
    }

    /// Multiply the distance by `factor` (< 1 zooms in).
    pub fn zoom(&mut self, factor: f32) {
        if factor.is_finite() && factor > 0.0 {
            self.distance = (self.distance * factor).clamp(MIN_DISTANCE, MAX_DISTANCE);
        }
    }

    /// Wheel delta (pixels, as `WheelEvent.deltaY` in pixel mode) to a zoom.
    pub fn wheel(&mut self, delta_y: f32) {
        if delta_y.is_finite() {
            self.zoom((delta_y.clamp(-500.0, 500.0) * 0.0015).lexp());
        }
    }

    /// Centre on the box and back off until its bounding sphere fits both the
    /// vertical and the horizontal field of view. Keeps yaw and pitch.
    pub fn frame_box(&mut self, min: Vec3, max: Vec3) {
        if !(min.is_finite() && max.is_finite()) || min.cmpgt(max).any() {
            return;
        }
        self.target = (min + max) * 0.5;
        let radius = ((max - min).length() * 0.5).max(1e-3);
        let half_v = self.fov_y * 0.5;
        let half_h = (half_v.ltan() * self.aspect()).latan();
        let half = half_v.min(half_h);
        self.distance = (radius / half.lsin() * 1.05).clamp(MIN_DISTANCE, MAX_DISTANCE);
    }

    /// Default orientation, then frame the box.
    pub fn reset(&mut self, min: Vec3, max: Vec3) {
        self.yaw = DEFAULT_YAW;
        self.pitch = DEFAULT_PITCH;
        self.frame_box(min, max);
    }

    /// Compact text for the URL hash, e.g. `t=0.1,0,-0.2;d=1.5;y=0.7;p=0.35;u=2`.
    pub fn to_state_string(&self) -> String {
        format!(
            "t={},{},{};d={};y={};p={};u={}",
            round5(self.target.x),
            round5(self.target.y),
            round5(self.target.z),
            round5(self.distance),
            round5(self.yaw),
            round5(self.pitch),
            self.up.index()
        )
    }

    /// Parse [`Self::to_state_string`]; fields may come in any order, missing
    /// fields keep their current values. Bad text is an error naming the field.
    pub fn apply_state_string(&mut self, text: &str) -> Result<()> {
        let mut next = self.clone();
        for field in text.split(';').map(str::trim).filter(|f| !f.is_empty()) {
            let (key, value) = field
                .split_once('=')
                .ok_or_else(|| bad_state(format!("field `{field}` has no `=`")))?;
            match key {
                "t" => {
                    let parts: Vec<&str> = value.split(',').collect();
                    if parts.len() != 3 {
                        return Err(bad_state(format!(
                            "target `{value}` needs 3 comma-separated numbers"
                        )));
                    }
                    next.target = Vec3::new(
                        parse_num("t", parts[0])?,
                        parse_num("t", parts[1])?,
                        parse_num("t", parts[2])?,
                    );
                }
                "d" => {
                    let d = parse_num("d", value)?;
                    if d <= 0.0 {
                        return Err(bad_state(format!("distance `{value}` must be positive")));
                    }
                    next.distance = d.clamp(MIN_DISTANCE, MAX_DISTANCE);
                }
                "y" => next.yaw = parse_num("y", value)?,
                "p" => next.pitch = parse_num("p", value)?.clamp(-MAX_PITCH, MAX_PITCH),
                "u" => {
                    next.up = match value {
                        "0" => UpAxis::X,
                        "1" => UpAxis::Y,
                        "2" => UpAxis::Z,
                        _ => return Err(bad_state(format!("up axis `{value}` is not 0, 1 or 2"))),
                    }
                }
                _ => return Err(bad_state(format!("unknown field `{key}`"))),
            }
        }
        *self = next;
        Ok(())
    }
}

fn round5(v: f32) -> f32 {
    (v * 1e5).round() / 1e5
}

fn bad_state(problem: String) -> Error {
    Error::input("camera state", problem)
}

fn parse_num(key: &str, s: &str) -> Result<f32> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() => Ok(v),
        _ => Err(bad_state(format!(
            "`{key}` value `{s}` is not a finite number"
        ))),
    }
}

/// What a pointer drag does.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DragMode {
    Orbit,
    Pan,
}

#[derive(Debug, Clone, Copy)]
struct ActivePointer {
    id: i32,
    x: f32,
    y: f32,
}

/// Turns pointer events (mouse, pen and touch alike, as DOM `PointerEvent`s)
/// into camera moves: one pointer orbits (pans with the right/middle button or
/// shift), two pointers pinch-zoom and pan. Extra fingers are ignored.
#[derive(Debug, Clone, Default)]
pub struct Gestures {
    pointers: [Option<ActivePointer>; 2],
    mode: Option<DragMode>,
}

impl Gestures {
    /// `button` follows `PointerEvent.button` (0 left, 1 middle, 2 right).
    pub fn pointer_down(&mut self, id: i32, x: f32, y: f32, button: i32, shift: bool) {
        if !(x.is_finite() && y.is_finite()) || self.index_of(id).is_some() {
            return;
        }
        let Some(slot) = self.pointers.iter().position(Option::is_none) else {
            return;
        };
        self.pointers[slot] = Some(ActivePointer { id, x, y });
        if self.count() == 1 {
            self.mode = Some(if button == 0 && !shift {
                DragMode::Orbit
            } else {
                DragMode::Pan
            });
        }
    }

    /// Returns whether the camera changed (so the caller can redraw).
    pub fn pointer_move(&mut self, cam: &mut OrbitCamera, id: i32, x: f32, y: f32) -> bool {
        if !(x.is_finite() && y.is_finite()) {
            return false;
        }
        let Some(i) = self.index_of(id) else {
            return false;
        };
        if self.count() == 2 {
            let j = 1 - i;
            let (Some(p), Some(q)) = (self.pointers[i], self.pointers[j]) else {
                return false;
            };
            let old_gap = ((p.x - q.x).powi(2) + (p.y - q.y).powi(2)).sqrt();
            let new_gap = ((x - q.x).powi(2) + (y - q.y).powi(2)).sqrt();
            if old_gap > 1.0 && new_gap > 1.0 {
                cam.zoom(old_gap / new_gap);
            }
            // The midpoint moves by half of this pointer's motion.
            cam.pan((x - p.x) * 0.5, (y - p.y) * 0.5);
        } else if let Some(p) = self.pointers[i] {
            match self.mode {
                Some(DragMode::Orbit) => cam.orbit(x - p.x, y - p.y),
                Some(DragMode::Pan) => cam.pan(x - p.x, y - p.y),
                None => return false,
            }
        }
        self.pointers[i] = Some(ActivePointer { id, x, y });
        true
    }

    pub fn pointer_up(&mut self, id: i32) {
        if let Some(i) = self.index_of(id) {
            self.pointers[i] = None;
        }
        match self.count() {
            0 => self.mode = None,
            // Lifting one finger of a pinch continues as a one-finger orbit.
            _ => self.mode = Some(DragMode::Orbit),
        }
    }

    /// Forget all pointers (e.g. on `pointercancel` or losing focus).
    pub fn cancel(&mut self) {
        *self = Gestures::default();
    }

    fn count(&self) -> usize {
        self.pointers.iter().filter(|p| p.is_some()).count()
    }

    fn index_of(&self, id: i32) -> Option<usize> {
        self.pointers
            .iter()
            .position(|p| p.map(|p| p.id == id).unwrap_or(false))
    }
}

/// Axis-aligned bounds of an xyz-interleaved f32 slice, skipping non-finite
/// points; `None` when there is no finite point.
pub fn bounds_of(xyz: &[f32]) -> Option<(Vec3, Vec3)> {
    let mut min = Vec3::splat(f32::INFINITY);
    let mut max = Vec3::splat(f32::NEG_INFINITY);
    let mut any = false;
    for p in xyz.chunks_exact(3) {
        let v = Vec3::new(p[0], p[1], p[2]);
        if v.is_finite() {
            min = min.min(v);
            max = max.max(v);
            any = true;
        }
    }
    any.then_some((min, max))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn project(cam: &OrbitCamera, p: Vec3) -> Vec3 {
        cam.view_projection().project_point3(p)
    }

    #[test]
    fn target_projects_to_centre_and_eye_sits_at_distance() {
        for up in [UpAxis::X, UpAxis::Y, UpAxis::Z] {
            let cam = OrbitCamera {
                target: Vec3::new(0.3, -0.2, 1.0),
                distance: 3.0,
                up,
                ..Default::default()
            };
            let c = project(&cam, cam.target);
            assert!(c.x.abs() < 1e-5 && c.y.abs() < 1e-5, "{c:?}");
            assert!(c.z > 0.0 && c.z < 1.0);
            assert!(((cam.eye() - cam.target).length() - 3.0).abs() < 1e-5);
        }
    }

    #[test]
    fn up_axis_points_up_on_screen() {
        for up in [UpAxis::X, UpAxis::Y, UpAxis::Z] {
            let cam = OrbitCamera {
                up,
                ..Default::default()
            };
            let above = project(&cam, up.basis().2 * 0.1);
            assert!(above.y > 0.01, "{up:?}: {above:?}");
        }
    }

    #[test]
    fn frame_box_fits_every_corner() {
        let mut cam = OrbitCamera::default();
        cam.set_viewport(400.0, 900.0); // narrow viewport: horizontal fov limits
        let (min, max) = (Vec3::new(-1.0, 2.0, 0.0), Vec3::new(3.0, 4.0, 0.5));
        for yaw in [0.0f32, 0.7, 2.0, 4.0] {
            cam.yaw = yaw;
            cam.frame_box(min, max);
            for i in 0..8 {
                let corner = Vec3::new(
                    if i & 1 == 0 { min.x } else { max.x },
                    if i & 2 == 0 { min.y } else { max.y },
                    if i & 4 == 0 { min.z } else { max.z },
                );
                let p = project(&cam, corner);
                assert!(p.x.abs() <= 1.0 && p.y.abs() <= 1.0, "{corner:?} -> {p:?}");
                assert!(p.z > 0.0 && p.z < 1.0);
            }
        }
        // Tight: the box is not tiny on screen.
        let p = project(&cam, max);
        let q = project(&cam, min);
        assert!((p - q).truncate().length() > 0.5);
    }

    #[test]
    fn orbit_pan_zoom_move_the_camera_sensibly() {
        let mut cam = OrbitCamera::default();
        let eye0 = cam.eye();
        cam.orbit(50.0, 0.0);
        assert!((cam.eye() - eye0).length() > 0.1);
        assert!(
            (cam.eye().length() - 2.0).abs() < 1e-4,
            "orbit keeps distance"
        );
        let before = (cam.eye(), cam.target);
        cam.turn(0.7);
        cam.turn(std::f32::consts::TAU - 0.7);
        assert!(
            (cam.eye() - before.0).length() < 1e-4,
            "a whole turn comes back"
        );
        cam.turn(std::f32::consts::FRAC_PI_2);
        assert!((cam.eye() - before.0).length() > 1.0 && cam.target == before.1);
        cam.turn(f32::NAN);
        assert!(cam.eye().is_finite());
        cam.orbit(0.0, 1e6);
        assert!(cam.pitch <= MAX_PITCH);

        // Pan by 100 px right: the target point moves right on screen by ~100 px.
        let mut cam = OrbitCamera::default();
        let p0 = Vec3::ZERO;
        cam.pan(100.0, 0.0);
        let ndc = project(&cam, p0);
        let px = ndc.x * cam.viewport[0] * 0.5;
        assert!((px - 100.0).abs() < 1.0, "{px}");
        cam.pan(0.0, 50.0);
        let ndc = project(&cam, p0);
        let py = -ndc.y * cam.viewport[1] * 0.5;
        assert!((py - 50.0).abs() < 1.0, "{py}");

        let mut cam = OrbitCamera::default();
        cam.zoom(0.5);
        assert!((cam.distance - 1.0).abs() < 1e-6);
        cam.zoom(0.0);
        cam.zoom(f32::NAN);
        assert!((cam.distance - 1.0).abs() < 1e-6);
        cam.wheel(100.0);
        assert!(cam.distance > 1.0, "wheel down zooms out");
    }

    #[test]
    fn state_string_round_trips_and_rejects_garbage() {
        let mut cam = OrbitCamera {
            target: Vec3::new(0.125, -3.5, 2.0),
            distance: 4.25,
            yaw: 1.25,
            pitch: -0.5,
            up: UpAxis::Y,
            ..Default::default()
        };
        let s = cam.to_state_string();
        let mut other = OrbitCamera::default();
        other.apply_state_string(&s).unwrap();
        assert_eq!(other.target, cam.target);
        assert_eq!(other.distance, cam.distance);
        assert_eq!(other.yaw, cam.yaw);
        assert_eq!(other.pitch, cam.pitch);
        assert_eq!(other.up, UpAxis::Y);

        let before = cam.clone();
        for bad in [
            "t=1,2",
            "d=-1",
            "d=abc",
            "x=3",
            "p",
            "y=inf",
            "u=7",
            "t=1,2,NaN",
        ] {
            let err = cam.apply_state_string(bad).unwrap_err().to_string();
            assert!(err.starts_with("camera state:"), "{err}");
            assert_eq!(cam, before, "failed parse must not change the camera");
        }
        cam.apply_state_string("d=2").unwrap();
        assert_eq!(cam.distance, 2.0);
        assert_eq!(cam.target, before.target);
    }

    #[test]
    fn one_pointer_orbits_right_button_pans_two_pointers_pinch() {
        let mut cam = OrbitCamera::default();
        let mut g = Gestures::default();
        g.pointer_down(1, 100.0, 100.0, 0, false);
        assert!(g.pointer_move(&mut cam, 1, 140.0, 100.0));
        assert!(cam.yaw != DEFAULT_YAW && cam.target == Vec3::ZERO);
        g.pointer_up(1);
        assert!(!g.pointer_move(&mut cam, 1, 150.0, 100.0));

        let mut cam = OrbitCamera::default();
        g.pointer_down(2, 10.0, 10.0, 2, false);
        g.pointer_move(&mut cam, 2, 30.0, 10.0);
        assert_eq!(cam.yaw, DEFAULT_YAW);
        assert!(cam.target != Vec3::ZERO);
        g.pointer_up(2);

        let mut cam = OrbitCamera::default();
        g.pointer_down(3, 100.0, 100.0, 0, false);
        g.pointer_down(4, 200.0, 100.0, 0, false);
        g.pointer_down(5, 300.0, 100.0, 0, false); // third finger ignored
        g.pointer_move(&mut cam, 4, 300.0, 100.0); // spread: zoom in
        assert!(cam.distance < 2.0, "{}", cam.distance);
        assert_eq!(cam.yaw, DEFAULT_YAW);
        g.pointer_up(4);
        g.pointer_move(&mut cam, 3, 120.0, 100.0);
        assert!(cam.yaw != DEFAULT_YAW, "remaining finger orbits");
        g.cancel();
        assert!(!g.pointer_move(&mut cam, 3, 0.0, 0.0));
    }

    #[test]
    fn bounds_skip_non_finite_points() {
        assert!(bounds_of(&[]).is_none());
        assert!(bounds_of(&[f32::NAN, 0.0, 0.0]).is_none());
        let (min, max) = bounds_of(&[1.0, 2.0, 3.0, f32::NAN, 0.0, 0.0, -1.0, 5.0, 0.0]).unwrap();
        assert_eq!(min, Vec3::new(-1.0, 2.0, 0.0));
        assert_eq!(max, Vec3::new(1.0, 5.0, 3.0));
    }
}
