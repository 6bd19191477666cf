//! GPU side of the viewer: device and surface setup (WebGPU or WebGL2), the
//! pipelines, grow-only scene buffers and the draw of one frame, on screen or
//! into an offscreen RGBA8 texture for read-back.

use super::mesh::{self, MeshVertex};
use super::palette;
use crate::geom::camera::{bounds_of, Gestures, OrbitCamera};
use glam::Vec3;
use std::sync::{Arc, Mutex};
use web_sys::HtmlCanvasElement;

const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth24Plus;
/// Offscreen read-back format: exact bytes, no sRGB encoding.
pub const OFFSCREEN_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
/// Points are drawn as one plain (non-instanced) triangle each that circumscribes
/// the disk: SwiftShader and some mobile GPUs run one tiny instance at a time
/// (measured in headless Chromium, 40k points: ~1 s per frame instanced,
/// ~0.3–0.6 s as indexed quads, less as triangles — vertex work dominates).
const CORNERS: usize = 3;
const POINT_STRIDE: u64 = 12;
const COLOR_STRIDE: u64 = 4;
/// centre(3) + rotation columns(9) + scale(3) + packed colour(1), as u32 words.
const GAUSS_WORDS: usize = 16;
/// Colour modes of `set_color_mode`.
/// Override colours when the page gave some for the current points, else by label.
pub const COLOR_AUTO: u32 = 0;
/// Always by label, ignoring override colours.
pub const COLOR_BY_LABEL: u32 = 1;
/// One neutral grey.
pub const COLOR_PLAIN: u32 = 2;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Globals {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    params: [f32; 4],
}

/// A GPU buffer that only grows (to the next power of two), so steady-state
/// updates (a snapshot per progress message, a frame per slider move) reuse it.
struct GrowBuffer {
    buf: wgpu::Buffer,
    label: &'static str,
    usage: wgpu::BufferUsages,
}

impl GrowBuffer {
    fn new(device: &wgpu::Device, label: &'static str, usage: wgpu::BufferUsages) -> Self {
        let usage = usage | wgpu::BufferUsages::COPY_DST;
        GrowBuffer {
            buf: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 256,
                usage,
                mapped_at_creation: false,
            }),
            label,
            usage,
        }
    }

    fn write(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, data: &[u8]) {
        if data.is_empty() {
            return;
        }
        let needed = data.len() as u64;
        if needed > self.buf.size() {
            self.buf.destroy();
            self.buf = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(self.label),
                size: needed.next_power_of_two().max(256),
                usage: self.usage,
                mapped_at_creation: false,
            });
        }
        queue.write_buffer(&self.buf, 0, data);
    }
}

struct Pipelines {
    format: wgpu::TextureFormat,
    points: wgpu::RenderPipeline,
    gaussians: wgpu::RenderPipeline,
    mesh: wgpu::RenderPipeline,
    mesh_xray: wgpu::RenderPipeline,
    lines: wgpu::RenderPipeline,
}

/// Colour and depth attachments of one target size (screen or offscreen).
struct Targets {
    size: (u32, u32),
    msaa: Option<wgpu::TextureView>,
    depth: wgpu::TextureView,
}

pub struct Renderer {
    canvas: HtmlCanvasElement,
    device: wgpu::Device,
    queue: wgpu::Queue,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    backend: &'static str,
    adapter_info: String,
    sample_count: u32,
    msaa_supported: bool,
    layout: wgpu::PipelineLayout,
    globals_buf: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    shader_points: wgpu::ShaderModule,
    shader_gauss: wgpu::ShaderModule,
    shader_mesh: wgpu::ShaderModule,
    pipelines: Vec<Pipelines>,
    screen: Option<Targets>,

    positions: GrowBuffer,
    pos_scratch: Vec<f32>,
    colors: GrowBuffer,
    n_points: u32,
    labels: Vec<u32>,
    custom_colors: Vec<u8>,
    color_scratch: Vec<u8>,
    color_mode: u32,
    point_size: f32,
    dpr: f32,

    sphere_vb: wgpu::Buffer,
    sphere_ib: wgpu::Buffer,
    sphere_index_count: u32,
    small_sphere: (Vec<[f32; 3]>, Vec<u16>),
    gauss: GrowBuffer,
    n_gauss: u32,
    gauss_scratch: Vec<u32>,
    /// (depth key, index) and the instance words in back-to-front order.
    gauss_order: Vec<(f32, u32)>,
    gauss_sorted: Vec<u32>,
    gauss_visible: bool,

    axes: GrowBuffer,
    n_axes_verts: u32,
    axes_scratch: Vec<MeshVertex>,
    axes_src: (Vec<f32>, Vec<f32>, Vec<u32>, i32),

    grid: GrowBuffer,
    n_grid_verts: u32,
    grid_scratch: Vec<MeshVertex>,
    grid_visible: bool,

    pub camera: OrbitCamera,
    pub gestures: Gestures,
    /// Bounds of the current points (what "frame object" fits).
    point_bounds: Option<(Vec3, Vec3)>,
    /// Bounds the grid and the axis sizes follow; only updated on framing so
    /// playing frames does not make the floor jump.
    scene_bounds: Option<(Vec3, Vec3)>,
    errors: Arc<Mutex<Vec<String>>>,
}

fn srgb_to_linear(c: u8) -> f64 {
    let c = c as f64 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

fn shader(device: &wgpu::Device, label: &str, body: &str) -> wgpu::ShaderModule {
    let source = format!("{}\n{}", include_str!("shaders/common.wgsl"), body);
    device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    })
}

fn msaa_ok(adapter: &wgpu::Adapter, format: wgpu::TextureFormat) -> bool {
    let f = adapter.get_texture_format_features(format).flags;
    f.sample_count_supported(4)
        && (format.is_depth_stencil_format()
            || f.contains(wgpu::TextureFormatFeatureFlags::MULTISAMPLE_RESOLVE))
}

impl Renderer {
    pub async fn create(canvas: HtmlCanvasElement, force_webgl: bool) -> Result<Self, String> {
        let width = canvas.width().max(1);
        let height = canvas.height().max(1);
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        let instance = if force_webgl {
            desc.backends = wgpu::Backends::GL;
            wgpu::Instance::new(desc)
        } else {
            desc.backends = wgpu::Backends::BROWSER_WEBGPU | wgpu::Backends::GL;
            wgpu::util::new_instance_with_webgpu_detection(desc).await
        };
        let surface = instance
            .create_surface(wgpu::SurfaceTarget::Canvas(canvas.clone()))
            .map_err(|e| {
                format!(
                    "This browser offers neither WebGPU nor WebGL2, so the 3D view cannot start \
                     (creating the drawing surface failed: {e})."
                )
            })?;
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                compatible_surface: Some(&surface),
                apply_limit_buckets: false,
            })
            .await
            .map_err(|e| {
                format!(
                    "No usable WebGPU or WebGL2 graphics adapter, so the 3D view cannot start ({e})."
                )
            })?;
        let info = adapter.get_info();
        let backend = match info.backend {
            wgpu::Backend::BrowserWebGpu => "webgpu",
            wgpu::Backend::Gl => "webgl2",
            _ => "other",
        };
        let base = if backend == "webgl2" {
            wgpu::Limits::downlevel_webgl2_defaults()
        } else {
            wgpu::Limits::downlevel_defaults()
        };
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("gsart viewer"),
                required_features: wgpu::Features::empty(),
                required_limits: base.using_resolution(adapter.limits()),
                ..Default::default()
            })
            .await
            .map_err(|e| format!("The graphics device could not be opened ({backend}): {e}"))?;

        let errors: Arc<Mutex<Vec<String>>> = Arc::default();
        let sink = errors.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            let text = e.to_string();
            web_sys::console::error_1(&format!("gsart viewer: {text}").into());
            if let Ok(mut v) = sink.lock() {
                if v.len() < 32 {
                    v.push(text);
                }
            }
        }));

        let caps = surface.get_capabilities(&adapter);
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| !f.is_srgb())
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| format!("The {backend} canvas offers no colour format."))?;
        let alpha_mode = if caps.alpha_modes.contains(&wgpu::CompositeAlphaMode::Opaque) {
            wgpu::CompositeAlphaMode::Opaque
        } else {
            caps.alpha_modes
                .first()
                .copied()
                .unwrap_or(wgpu::CompositeAlphaMode::Auto)
        };
        let config = wgpu::SurfaceConfiguration {
            // COPY_SRC lets the page's PNG export read the canvas back on WebGPU.
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
            format,
            color_space: wgpu::SurfaceColorSpace::Auto,
            width,
            height,
            present_mode: wgpu::PresentMode::Fifo,
            desired_maximum_frame_latency: 2,
            alpha_mode,
            view_formats: vec![],
        };
        surface.configure(&device, &config);

        let msaa_supported = msaa_ok(&adapter, format)
            && msaa_ok(&adapter, OFFSCREEN_FORMAT)
            && msaa_ok(&adapter, DEPTH_FORMAT);
        // Software rasterisers (SwiftShader) pay dearly for MSAA: off there by default.
        let sample_count = if msaa_supported && info.device_type != wgpu::DeviceType::Cpu {
            4
        } else {
            1
        };

        let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("globals"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("viewer"),
            bind_group_layouts: &[Some(&bgl)],
            immediate_size: 0,
        });
        let globals_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("globals"),
            size: std::mem::size_of::<Globals>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("globals"),
            layout: &bgl,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: globals_buf.as_entire_binding(),
            }],
        });

        let (sphere_verts, sphere_idx) = mesh::icosphere(2);
        let sphere_vb = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("unit sphere"),
            size: (sphere_verts.len() * 12) as u64,
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        queue.write_buffer(&sphere_vb, 0, bytemuck::cast_slice(&sphere_verts));
        let mut idx_bytes: Vec<u8> = bytemuck::cast_slice(&sphere_idx).to_vec();
        idx_bytes.resize(idx_bytes.len().next_multiple_of(4), 0);
        let sphere_ib = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("unit sphere indices"),
            size: idx_bytes.len() as u64,
            usage: wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        queue.write_buffer(&sphere_ib, 0, &idx_bytes);

        let vertex = wgpu::BufferUsages::VERTEX;
        let mut r = Renderer {
            canvas,
            shader_points: shader(&device, "points", include_str!("shaders/points.wgsl")),
            shader_gauss: shader(&device, "gaussians", include_str!("shaders/gaussians.wgsl")),
            shader_mesh: shader(&device, "mesh", include_str!("shaders/mesh.wgsl")),
            positions: GrowBuffer::new(&device, "point positions", vertex),
            pos_scratch: Vec::new(),
            colors: GrowBuffer::new(&device, "point colours", vertex),
            gauss: GrowBuffer::new(&device, "gaussians", vertex),
            axes: GrowBuffer::new(&device, "axes", vertex),
            grid: GrowBuffer::new(&device, "grid", vertex),
            device,
            queue,
            surface,
            config,
            backend,
            adapter_info: format!("{} ({:?}, {})", info.name, info.device_type, info.driver),
            sample_count,
            msaa_supported,
            layout,
            globals_buf,
            bind_group,
            pipelines: Vec::new(),
            screen: None,
            n_points: 0,
            labels: Vec::new(),
            custom_colors: Vec::new(),
            color_scratch: Vec::new(),
            color_mode: COLOR_AUTO,
            point_size: 4.0,
            dpr: 1.0,
            sphere_vb,
            sphere_ib,
            sphere_index_count: sphere_idx.len() as u32,
            small_sphere: mesh::icosphere(1),
            n_gauss: 0,
            gauss_scratch: Vec::new(),
            gauss_order: Vec::new(),
            gauss_sorted: Vec::new(),
            gauss_visible: true,
            n_axes_verts: 0,
            axes_scratch: Vec::new(),
            axes_src: (Vec::new(), Vec::new(), Vec::new(), -1),
            n_grid_verts: 0,
            grid_scratch: Vec::new(),
            grid_visible: true,
            camera: OrbitCamera::default(),
            gestures: Gestures::default(),
            point_bounds: None,
            scene_bounds: None,
            errors,
        };
        r.camera.set_viewport(width as f32, height as f32);
        r.pipelines_for(format);
        Ok(r)
    }

    pub fn backend(&self) -> &'static str {
        self.backend
    }

    pub fn adapter_info(&self) -> &str {
        &self.adapter_info
    }

    pub fn sample_count(&self) -> u32 {
        self.sample_count
    }

    /// Turn 4× MSAA on or off (where supported); returns whether it is on.
    pub fn set_msaa(&mut self, on: bool) -> bool {
        let count = if on && self.msaa_supported { 4 } else { 1 };
        if count != self.sample_count {
            self.sample_count = count;
            // Pipelines and attachments are built for one sample count.
            self.pipelines.clear();
            self.screen = None;
        }
        self.sample_count > 1
    }

    /// GPU validation errors seen so far (empty when all is well).
    pub fn errors(&self) -> Vec<String> {
        self.errors.lock().map(|v| v.clone()).unwrap_or_default()
    }

    /// `width`/`height` in CSS pixels, `dpr` = devicePixelRatio.
    pub fn resize(&mut self, width: f32, height: f32, dpr: f32) {
        let dpr = if dpr.is_finite() && dpr > 0.0 {
            dpr.min(4.0)
        } else {
            1.0
        };
        if !(width.is_finite() && height.is_finite()) || width < 1.0 || height < 1.0 {
            return;
        }
        let max = self.device.limits().max_texture_dimension_2d;
        let pw = ((width * dpr).round() as u32).clamp(1, max);
        let ph = ((height * dpr).round() as u32).clamp(1, max);
        self.dpr = dpr;
        self.camera.set_viewport(width, height);
        if pw != self.config.width || ph != self.config.height {
            self.canvas.set_width(pw);
            self.canvas.set_height(ph);
            self.config.width = pw;
            self.config.height = ph;
            self.surface.configure(&self.device, &self.config);
            self.screen = None;
        }
    }

    fn pipelines_for(&mut self, format: wgpu::TextureFormat) -> usize {
        if let Some(i) = self.pipelines.iter().position(|p| p.format == format) {
            return i;
        }
        let d = &self.device;
        let ms = wgpu::MultisampleState {
            count: self.sample_count,
            mask: !0,
            alpha_to_coverage_enabled: false,
        };
        let depth = |write: bool, compare: wgpu::CompareFunction| {
            Some(wgpu::DepthStencilState {
                format: DEPTH_FORMAT,
                depth_write_enabled: Some(write),
                depth_compare: Some(compare),
                stencil: wgpu::StencilState::default(),
                bias: wgpu::DepthBiasState::default(),
            })
        };
        let opaque = [Some(wgpu::ColorTargetState {
            format,
            blend: None,
            write_mask: wgpu::ColorWrites::ALL,
        })];
        let blended = [Some(wgpu::ColorTargetState {
            format,
            blend: Some(wgpu::BlendState::ALPHA_BLENDING),
            write_mask: wgpu::ColorWrites::ALL,
        })];
        let mesh_attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Unorm8x4];
        let mesh_layout = [Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<MeshVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &mesh_attrs,
        })];
        let pos_attr = wgpu::vertex_attr_array![0 => Float32x3];
        let col_attr = wgpu::vertex_attr_array![1 => Unorm8x4];
        let point_layout = [
            Some(wgpu::VertexBufferLayout {
                array_stride: POINT_STRIDE,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &pos_attr,
            }),
            Some(wgpu::VertexBufferLayout {
                array_stride: COLOR_STRIDE,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &col_attr,
            }),
        ];
        let unit_attr = wgpu::vertex_attr_array![0 => Float32x3];
        let gauss_attr = wgpu::vertex_attr_array![
            1 => Float32x3, 2 => Float32x3, 3 => Float32x3, 4 => Float32x3, 5 => Float32x3,
            6 => Unorm8x4
        ];
        let gauss_layout = [
            Some(wgpu::VertexBufferLayout {
                array_stride: 12,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &unit_attr,
            }),
            Some(wgpu::VertexBufferLayout {
                array_stride: (GAUSS_WORDS * 4) as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &gauss_attr,
            }),
        ];
        let make = |label: &str,
                    module: &wgpu::ShaderModule,
                    buffers: &[Option<wgpu::VertexBufferLayout>],
                    fs: &str,
                    targets: &[Option<wgpu::ColorTargetState>],
                    topology: wgpu::PrimitiveTopology,
                    cull: Option<wgpu::Face>,
                    depth_stencil: Option<wgpu::DepthStencilState>| {
            d.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&self.layout),
                vertex: wgpu::VertexState {
                    module,
                    entry_point: Some("vs_main"),
                    compilation_options: Default::default(),
                    buffers,
                },
                primitive: wgpu::PrimitiveState {
                    topology,
                    cull_mode: cull,
                    ..Default::default()
                },
                depth_stencil,
                multisample: ms,
                fragment: Some(wgpu::FragmentState {
                    module,
                    entry_point: Some(fs),
                    compilation_options: Default::default(),
                    targets,
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        use wgpu::CompareFunction::{Greater, Less};
        use wgpu::PrimitiveTopology::{LineList, TriangleList};
        let p = Pipelines {
            format,
            points: make(
                "points",
                &self.shader_points,
                &point_layout,
                "fs_main",
                &opaque,
                TriangleList,
                None,
                depth(true, Less),
            ),
            gaussians: make(
                "gaussians",
                &self.shader_gauss,
                &gauss_layout,
                "fs_main",
                &blended,
                TriangleList,
                Some(wgpu::Face::Back),
                depth(false, Less),
            ),
            mesh: make(
                "axes",
                &self.shader_mesh,
                &mesh_layout,
                "fs_lit",
                &opaque,
                TriangleList,
                Some(wgpu::Face::Back),
                depth(true, Less),
            ),
            mesh_xray: make(
                "axes x-ray",
                &self.shader_mesh,
                &mesh_layout,
                "fs_xray",
                &blended,
                TriangleList,
                Some(wgpu::Face::Back),
                depth(false, Greater),
            ),
            lines: make(
                "grid",
                &self.shader_mesh,
                &mesh_layout,
                "fs_unlit",
                &opaque,
                LineList,
                None,
                depth(true, Less),
            ),
        };
        self.pipelines.push(p);
        self.pipelines.len() - 1
    }

    fn make_targets(&self, width: u32, height: u32, format: wgpu::TextureFormat) -> Targets {
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let tex = |label: &str, format: wgpu::TextureFormat| {
            self.device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size,
                    mip_level_count: 1,
                    sample_count: self.sample_count,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                    view_formats: &[],
                })
                .create_view(&wgpu::TextureViewDescriptor::default())
        };
        Targets {
            size: (width, height),
            msaa: (self.sample_count > 1).then(|| tex("msaa colour", format)),
            depth: tex("depth", DEPTH_FORMAT),
        }
    }

    // ---------------------------------------------------------------- scene

    /// `positions` is N×3 xyz; `labels` is empty or N part labels (`u32::MAX` = none).
    pub fn set_points(&mut self, positions: &[f32], labels: &[u32]) -> Result<(), String> {
        if !positions.len().is_multiple_of(3) {
            return Err(format!(
                "set_points: {} position values is not a multiple of 3",
                positions.len()
            ));
        }
        let n = positions.len() / 3;
        if !labels.is_empty() && labels.len() != n {
            return Err(format!(
                "set_points: {} labels for {n} points (give one per point or none)",
                labels.len()
            ));
        }
        let max_points = (self.device.limits().max_buffer_size / (CORNERS as u64 * POINT_STRIDE))
            .min(u32::MAX as u64 / 8) as usize;
        if n > max_points {
            return Err(format!(
                "set_points: {n} points exceed what this GPU can draw at once ({max_points}); downsample first"
            ));
        }
        // Every corner of a quad carries the point's centre; the vertex shader
        // pushes it out by the corner's offset in pixels.
        self.pos_scratch.clear();
        for p in positions.chunks_exact(3) {
            for _ in 0..CORNERS {
                self.pos_scratch.extend_from_slice(p);
            }
        }
        self.positions.write(
            &self.device,
            &self.queue,
            bytemuck::cast_slice(&self.pos_scratch),
        );
        self.n_points = n as u32;
        self.labels.clear();
        self.labels.extend_from_slice(labels);
        // Override colours belong to the points they were given for.
        self.custom_colors.clear();
        self.point_bounds = bounds_of(positions);
        if self.scene_bounds.is_none() && self.point_bounds.is_some() {
            self.scene_bounds = self.point_bounds;
            self.rebuild_grid();
            self.rebuild_axes();
        }
        self.upload_colors();
        Ok(())
    }

    /// Override colours (RGBA8, one per current point) shown instead of the
    /// label colours in [`COLOR_AUTO`] mode until the next `set_points`; empty
    /// clears the override.
    pub fn set_point_colors(&mut self, rgba: &[u8]) -> Result<(), String> {
        if !rgba.is_empty() && rgba.len() != 4 * self.n_points as usize {
            return Err(format!(
                "set_point_colors: {} bytes for {} points (need 4 RGBA bytes per point)",
                rgba.len(),
                self.n_points
            ));
        }
        self.custom_colors.clear();
        self.custom_colors.extend_from_slice(rgba);
        self.upload_colors();
        Ok(())
    }

    pub fn set_color_mode(&mut self, mode: u32) -> Result<(), String> {
        if !matches!(mode, COLOR_AUTO | COLOR_BY_LABEL | COLOR_PLAIN) {
            return Err(format!(
                "set_color_mode: unknown mode {mode} (0 = override colours or part, 1 = part, 2 = plain)"
            ));
        }
        self.color_mode = mode;
        self.upload_colors();
        Ok(())
    }

    fn upload_colors(&mut self) {
        let n = self.n_points as usize;
        self.color_scratch.clear();
        for i in 0..n {
            let label = self.labels.get(i).copied().unwrap_or(u32::MAX);
            let rgba = match self.color_mode {
                COLOR_AUTO if 4 * i + 4 <= self.custom_colors.len() => {
                    let c = &self.custom_colors[4 * i..4 * i + 4];
                    [c[0], c[1], c[2], 255]
                }
                COLOR_PLAIN => {
                    let c = palette::UNLABELED;
                    [c[0], c[1], c[2], 255]
                }
                _ => {
                    let c = palette::color(label);
                    [c[0], c[1], c[2], 255]
                }
            };
            for _ in 0..CORNERS {
                self.color_scratch.extend_from_slice(&rgba);
            }
        }
        self.colors
            .write(&self.device, &self.queue, &self.color_scratch);
    }

    pub fn set_point_size(&mut self, px: f32) {
        if px.is_finite() && px > 0.0 {
            self.point_size = px.clamp(0.5, 64.0);
        }
    }

    /// `centers` m×3, `rotations` m×9 row-major, `scales` m×3 (sigmas), `parts` m
    /// (empty = colour by index).
    pub fn set_gaussians(
        &mut self,
        centers: &[f32],
        rotations: &[f32],
        scales: &[f32],
        parts: &[u32],
    ) -> Result<(), String> {
        if !centers.len().is_multiple_of(3) {
            return Err(format!(
                "set_gaussians: {} centre values is not a multiple of 3",
                centers.len()
            ));
        }
        let m = centers.len() / 3;
        if rotations.len() != 9 * m || scales.len() != 3 * m {
            return Err(format!(
                "set_gaussians: {m} centres need {} rotation and {} scale values, got {} and {}",
                9 * m,
                3 * m,
                rotations.len(),
                scales.len()
            ));
        }
        if !parts.is_empty() && parts.len() != m {
            return Err(format!(
                "set_gaussians: {} parts for {m} Gaussians (give one per Gaussian or none)",
                parts.len()
            ));
        }
        self.gauss_scratch.clear();
        for k in 0..m {
            let c = &centers[3 * k..3 * k + 3];
            let r = &rotations[9 * k..9 * k + 9];
            let s = &scales[3 * k..3 * k + 3];
            let words = [
                c[0],
                c[1],
                c[2], // centre
                r[0],
                r[3],
                r[6], // column 0 of row-major R
                r[1],
                r[4],
                r[7], // column 1
                r[2],
                r[5],
                r[8], // column 2
                s[0].abs(),
                s[1].abs(),
                s[2].abs(),
            ];
            if words.iter().any(|v| !v.is_finite()) {
                return Err(format!(
                    "set_gaussians: Gaussian {k} has a non-finite value"
                ));
            }
            self.gauss_scratch.extend(words.iter().map(|v| v.to_bits()));
            let part = parts.get(k).copied().unwrap_or(k as u32);
            self.gauss_scratch.push(palette::pack(palette::color(part)));
        }
        self.n_gauss = m as u32;
        self.sort_gaussians();
        Ok(())
    }

    /// Upload the Gaussians farthest-first for the current camera, so the
    /// translucent ellipsoids blend in the right order (no per-frame allocation).
    fn sort_gaussians(&mut self) {
        let m = self.n_gauss as usize;
        if m == 0 {
            return;
        }
        let eye = self.camera.eye();
        self.gauss_order.clear();
        for k in 0..m {
            let w = &self.gauss_scratch[k * GAUSS_WORDS..k * GAUSS_WORDS + 3];
            let c = Vec3::new(
                f32::from_bits(w[0]),
                f32::from_bits(w[1]),
                f32::from_bits(w[2]),
            );
            self.gauss_order
                .push((-(c - eye).length_squared(), k as u32));
        }
        self.gauss_order
            .sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        self.gauss_sorted.clear();
        for &(_, k) in &self.gauss_order {
            let k = k as usize;
            self.gauss_sorted
                .extend_from_slice(&self.gauss_scratch[k * GAUSS_WORDS..(k + 1) * GAUSS_WORDS]);
        }
        self.gauss.write(
            &self.device,
            &self.queue,
            bytemuck::cast_slice(&self.gauss_sorted),
        );
    }

    pub fn set_gaussians_visible(&mut self, visible: bool) {
        self.gauss_visible = visible;
    }

    pub fn set_grid_visible(&mut self, visible: bool) {
        self.grid_visible = visible;
    }

    /// `origins`, `dirs` k×3; `kinds` k (0 revolute, 1 prismatic); `highlight`
    /// is the index drawn thicker in the highlight colour, or -1.
    pub fn set_axes(
        &mut self,
        origins: &[f32],
        dirs: &[f32],
        kinds: &[u32],
        highlight: i32,
    ) -> Result<(), String> {
        let k = kinds.len();
        if origins.len() != 3 * k || dirs.len() != 3 * k {
            return Err(format!(
                "set_axes: {k} kinds need {} origin and direction values, got {} and {}",
                3 * k,
                origins.len(),
                dirs.len()
            ));
        }
        if let Some(bad) = kinds.iter().find(|&&t| t > 1) {
            return Err(format!(
                "set_axes: joint kind {bad} is neither 0 (revolute) nor 1 (prismatic)"
            ));
        }
        let src = &mut self.axes_src;
        src.0.clear();
        src.0.extend_from_slice(origins);
        src.1.clear();
        src.1.extend_from_slice(dirs);
        src.2.clear();
        src.2.extend_from_slice(kinds);
        src.3 = highlight;
        self.rebuild_axes();
        Ok(())
    }

    fn scene_size(&self) -> f32 {
        self.scene_bounds
            .map(|(a, b)| (b - a).length())
            .filter(|d| *d > 1e-6)
            .unwrap_or(1.0)
    }

    fn rebuild_axes(&mut self) {
        let size = self.scene_size();
        let (origins, dirs, kinds, highlight) = &self.axes_src;
        let out = &mut self.axes_scratch;
        out.clear();
        for (i, &kind) in kinds.iter().enumerate() {
            let o = Vec3::from_slice(&origins[3 * i..3 * i + 3]);
            let d = Vec3::from_slice(&dirs[3 * i..3 * i + 3]);
            let (Some(d), true) = (d.try_normalize(), o.is_finite()) else {
                continue;
            };
            let hl = i as i32 == *highlight;
            let color = palette::pack(if hl {
                palette::AXIS_HIGHLIGHT
            } else {
                palette::AXIS_COLOR
            });
            let r = size * if hl { 0.007 } else { 0.0045 };
            if kind == 0 {
                // Revolute: a line through the pivot, with a ball at the pivot.
                let half = size * 0.22;
                mesh::cylinder(out, o - d * half, o + d * half, r, color);
                mesh::sphere(out, &self.small_sphere, o, r * 2.5, color);
            } else {
                // Prismatic: an arrow from the origin along the sliding direction.
                let len = size * 0.25;
                let shaft_end = o + d * (len * 0.8);
                mesh::cylinder(out, o, shaft_end, r, color);
                mesh::cone(out, shaft_end, o + d * len, r * 3.0, color);
            }
        }
        self.n_axes_verts = out.len() as u32;
        self.axes
            .write(&self.device, &self.queue, bytemuck::cast_slice(out));
    }

    fn rebuild_grid(&mut self) {
        let size = self.scene_size();
        let out = &mut self.grid_scratch;
        out.clear();
        if let Some((min, max)) = self.scene_bounds {
            let (a, b, up) = self.camera.up.basis();
            let center = (min + max) * 0.5;
            let extent = (max - min).dot(a).abs().max((max - min).dot(b).abs()) * 1.4;
            let extent = extent.max(size * 0.5);
            let floor = up * (min.dot(up) - size * 0.01);
            let c = center - up * center.dot(up) + floor;
            let cells = 10;
            let step = extent / cells as f32;
            let color = palette::pack([212, 212, 208]);
            let half = extent * 0.5;
            for i in 0..=cells {
                let t = -half + i as f32 * step;
                mesh::line(out, c + a * t - b * half, c + a * t + b * half, color);
                mesh::line(out, c + b * t - a * half, c + b * t + a * half, color);
            }
            // Axis triad at the grid corner: x red, y green, z blue.
            let corner = c - a * half - b * half;
            let len = extent * 0.12;
            mesh::line(
                out,
                corner,
                corner + Vec3::X * len,
                palette::pack([214, 60, 60]),
            );
            mesh::line(
                out,
                corner,
                corner + Vec3::Y * len,
                palette::pack([60, 160, 60]),
            );
            mesh::line(
                out,
                corner,
                corner + Vec3::Z * len,
                palette::pack([60, 90, 210]),
            );
        }
        self.n_grid_verts = out.len() as u32;
        self.grid
            .write(&self.device, &self.queue, bytemuck::cast_slice(out));
    }

    // --------------------------------------------------------------- camera

    /// Fit the camera to the current points; also re-anchors grid and axis sizes.
    pub fn frame_object(&mut self) {
        if let Some((min, max)) = self.point_bounds {
            self.camera.frame_box(min, max);
            self.scene_bounds = self.point_bounds;
            self.rebuild_grid();
            self.rebuild_axes();
        }
    }

    pub fn reset_view(&mut self) {
        let (min, max) = self
            .point_bounds
            .unwrap_or((Vec3::splat(-0.5), Vec3::splat(0.5)));
        self.camera.reset(min, max);
        if self.point_bounds.is_some() {
            self.scene_bounds = self.point_bounds;
            self.rebuild_grid();
            self.rebuild_axes();
        }
    }

    pub fn set_up_axis(&mut self, up: crate::geom::camera::UpAxis) {
        self.camera.up = up;
        self.rebuild_grid();
    }

    pub fn refresh_after_camera_state(&mut self) {
        self.rebuild_grid();
    }

    // ---------------------------------------------------------------- draw

    fn write_globals(&self, viewport_px: (u32, u32), srgb: bool, point_px: f32) {
        let g = Globals {
            view_proj: self.camera.view_projection().to_cols_array_2d(),
            eye: self.camera.eye().extend(1.0).to_array(),
            params: [
                viewport_px.0 as f32,
                viewport_px.1 as f32,
                point_px,
                if srgb { 1.0 } else { 0.0 },
            ],
        };
        self.queue
            .write_buffer(&self.globals_buf, 0, bytemuck::bytes_of(&g));
    }

    fn encode_scene(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        pipes: &Pipelines,
        targets: &Targets,
        final_view: &wgpu::TextureView,
    ) {
        let srgb = pipes.format.is_srgb();
        let bg = palette::BACKGROUND.map(|c| {
            if srgb {
                srgb_to_linear(c)
            } else {
                c as f64 / 255.0
            }
        });
        let (view, resolve) = match &targets.msaa {
            Some(msaa) => (msaa, Some(final_view)),
            None => (final_view, None),
        };
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("scene"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: resolve,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color {
                        r: bg[0],
                        g: bg[1],
                        b: bg[2],
                        a: 1.0,
                    }),
                    store: if resolve.is_some() {
                        wgpu::StoreOp::Discard
                    } else {
                        wgpu::StoreOp::Store
                    },
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &targets.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_bind_group(0, &self.bind_group, &[]);
        if self.grid_visible && self.n_grid_verts > 0 {
            pass.set_pipeline(&pipes.lines);
            pass.set_vertex_buffer(0, self.grid.buf.slice(..));
            pass.draw(0..self.n_grid_verts, 0..1);
        }
        if self.n_points > 0 {
            let verts = self.n_points as u64 * CORNERS as u64;
            pass.set_pipeline(&pipes.points);
            pass.set_vertex_buffer(0, self.positions.buf.slice(..verts * POINT_STRIDE));
            pass.set_vertex_buffer(1, self.colors.buf.slice(..verts * COLOR_STRIDE));
            pass.draw(0..self.n_points * CORNERS as u32, 0..1);
        }
        if self.n_axes_verts > 0 {
            pass.set_pipeline(&pipes.mesh);
            pass.set_vertex_buffer(0, self.axes.buf.slice(..));
            pass.draw(0..self.n_axes_verts, 0..1);
        }
        if self.gauss_visible && self.n_gauss > 0 {
            pass.set_pipeline(&pipes.gaussians);
            pass.set_vertex_buffer(0, self.sphere_vb.slice(..));
            pass.set_vertex_buffer(1, self.gauss.buf.slice(..));
            pass.set_index_buffer(self.sphere_ib.slice(..), wgpu::IndexFormat::Uint16);
            pass.draw_indexed(0..self.sphere_index_count, 0, 0..self.n_gauss);
        }
        if self.n_axes_verts > 0 {
            pass.set_pipeline(&pipes.mesh_xray);
            pass.set_vertex_buffer(0, self.axes.buf.slice(..));
            pass.draw(0..self.n_axes_verts, 0..1);
        }
    }

    /// Draw one frame to the canvas.
    pub fn render(&mut self) -> Result<(), String> {
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                // Resize or context loss: reconfigure and draw on the next call.
                self.surface.configure(&self.device, &self.config);
                return Ok(());
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => {
                return Ok(())
            }
            other => return Err(format!("the canvas cannot be drawn to: {other:?}")),
        };
        let (w, h) = (self.config.width, self.config.height);
        if self.screen.as_ref().map(|t| t.size) != Some((w, h)) {
            self.screen = Some(self.make_targets(w, h, self.config.format));
        }
        let idx = self.pipelines_for(self.config.format);
        if self.gauss_visible {
            self.sort_gaussians();
        }
        self.write_globals(
            (w, h),
            self.config.format.is_srgb(),
            self.point_size * self.dpr,
        );
        let view = frame
            .texture
            .create_view(&wgpu::TextureViewDescriptor::default());
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        if let Some(targets) = &self.screen {
            self.encode_scene(&mut encoder, &self.pipelines[idx], targets, &view);
        }
        self.queue.submit(Some(encoder.finish()));
        self.queue.present(frame);
        Ok(())
    }

    /// Draw into a fresh `width`×`height` RGBA8 texture and queue its copy into
    /// a mappable buffer. Returns what [`read_back`] needs. The camera's aspect
    /// follows the requested size for this draw only.
    pub fn encode_offscreen(&mut self, width: u32, height: u32) -> Result<Readback, String> {
        let max = self.device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 || width > max || height > max {
            return Err(format!(
                "offscreen size {width}×{height} is outside 1..={max} pixels"
            ));
        }
        let idx = self.pipelines_for(OFFSCREEN_FORMAT);
        if self.gauss_visible {
            self.sort_gaussians();
        }
        let saved = self.camera.viewport;
        self.camera.set_viewport(width as f32, height as f32);
        // Same look as the canvas, scaled to the image: a 2× screenshot gets 2× points.
        let scale = height as f32 / self.camera.viewport[1].max(1.0);
        self.write_globals((width, height), false, self.point_size * scale);
        self.camera.viewport = saved;

        let texture = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("offscreen"),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: OFFSCREEN_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        let targets = self.make_targets(width, height, OFFSCREEN_FORMAT);
        let padded_row = (width * 4).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("read-back"),
            size: padded_row as u64 * height as u64,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("offscreen"),
            });
        self.encode_scene(&mut encoder, &self.pipelines[idx], &targets, &view);
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded_row),
                    rows_per_image: Some(height),
                },
            },
            wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
        );
        self.queue.submit(Some(encoder.finish()));
        Ok(Readback {
            device: self.device.clone(),
            buffer,
            width,
            height,
            padded_row,
        })
    }
}

/// A submitted offscreen draw whose pixels are on their way to `buffer`.
pub struct Readback {
    device: wgpu::Device,
    buffer: wgpu::Buffer,
    width: u32,
    height: u32,
    padded_row: u32,
}

impl Readback {
    /// Wait for the copy (polling with short sleeps: WebGPU resolves the map
    /// from the browser's event loop, WebGL on `poll`) and return tight RGBA rows.
    pub async fn read(self) -> Result<Vec<u8>, String> {
        let state: std::rc::Rc<std::cell::Cell<Option<Result<(), String>>>> = Default::default();
        let sink = state.clone();
        self.buffer
            .slice(..)
            .map_async(wgpu::MapMode::Read, move |r| {
                sink.set(Some(r.map_err(|e| e.to_string())));
            });
        let mut waited = 0;
        loop {
            let _ = self.device.poll(wgpu::PollType::Poll);
            if let Some(r) = state.take() {
                r.map_err(|e| format!("reading the offscreen image failed: {e}"))?;
                break;
            }
            if waited > 20_000 {
                return Err("reading the offscreen image timed out after 20 s".into());
            }
            super::sleep_ms(2).await;
            waited += 2;
        }
        let mut out = Vec::with_capacity((self.width * self.height * 4) as usize);
        {
            let data = self
                .buffer
                .get_mapped_range(..)
                .map_err(|e| format!("reading the offscreen image failed: {e}"))?;
            for row in data.chunks_exact(self.padded_row as usize) {
                out.extend_from_slice(&row[..(self.width * 4) as usize]);
            }
        }
        self.buffer.unmap();
        self.buffer.destroy();
        Ok(out)
    }
}
