//! The wgpu skeleton renderer: instanced low-polygon cylinders and spheres and a ground grid,
//! drawn into any render pass (the window's egui pass through a paint callback, or an
//! offscreen texture for tests and screenshots).
//!
//! Each viewport has a *slot* (uniforms + instance buffer): `prepare` uploads a viewport's
//! camera (the view at the shapes' presentation time, so it follows the figure) and shapes,
//! `paint` records up to four draw calls (ground, shadow, bones, joints). The shadow is
//! alpha-blended over the ground and writes no depth. It knows nothing of trials.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use anyhow::Context as _;
use egui_wgpu::wgpu;
use wgpu::util::DeviceExt as _;

use super::scene::{FrameShapes, Instance, View};

/// Background behind the skeletons (the ground fades into it), gamma-space RGB.
pub const BACKGROUND: [f32; 3] = [0.20, 0.21, 0.24];

const GLOBALS_BYTES: u64 = 112;

/// First slot of the window's calibration load (two skeletons drawn while the refresh period
/// is measured); viewports in slots below it are the screens' own and are counted.
pub const LOAD_SLOT: usize = 16;
const VERTEX_BYTES: u64 = 24;

/// Formats of the pass the renderer draws into.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Targets {
    /// Colour target format.
    pub color: wgpu::TextureFormat,
    /// Depth format, if the pass has a depth attachment.
    pub depth: Option<wgpu::TextureFormat>,
    /// MSAA sample count (1 = off).
    pub samples: u32,
}

struct Mesh {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    count: u32,
}

struct Slot {
    globals: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    instances: wgpu::Buffer,
    capacity: usize,
    bones: u32,
    joints: u32,
    shadows: u32,
}

/// Pipelines, meshes and per-viewport slots.
pub struct SkeletonRenderer {
    mesh_pipeline: wgpu::RenderPipeline,
    ground_pipeline: wgpu::RenderPipeline,
    shadow_pipeline: wgpu::RenderPipeline,
    drawn: Arc<AtomicUsize>,
    layout: wgpu::BindGroupLayout,
    cylinder: Mesh,
    sphere: Mesh,
    slots: Vec<Slot>,
    bytes: Vec<u8>,
}

fn floats(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|f| f.to_le_bytes()).collect()
}

fn mesh(device: &wgpu::Device, label: &str, vertices: &[f32], indices: &[u16]) -> Mesh {
    Mesh {
        vertices: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: &floats(vertices),
            usage: wgpu::BufferUsages::VERTEX,
        }),
        indices: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: &indices
                .iter()
                .flat_map(|i| i.to_le_bytes())
                .collect::<Vec<u8>>(),
            usage: wgpu::BufferUsages::INDEX,
        }),
        count: indices.len() as u32,
    }
}

/// A unit cylinder along +y from 0 to 1, radius 1, open ends (joint spheres cover them).
fn cylinder_mesh(segments: u16) -> (Vec<f32>, Vec<u16>) {
    let mut v = Vec::new();
    let mut idx = Vec::new();
    for s in 0..=segments {
        let a = f32::from(s) / f32::from(segments) * std::f32::consts::TAU;
        let (x, z) = (a.cos(), a.sin());
        for y in [0.0, 1.0] {
            v.extend_from_slice(&[x, y, z, x, 0.0, z]);
        }
    }
    for s in 0..segments {
        let b = s * 2;
        // Counter-clockwise seen from outside (wgpu's default front face).
        idx.extend_from_slice(&[b, b + 1, b + 2, b + 1, b + 3, b + 2]);
    }
    (v, idx)
}

/// A unit sphere of `rings` × `sectors` quads.
fn sphere_mesh(rings: u16, sectors: u16) -> (Vec<f32>, Vec<u16>) {
    let mut v = Vec::new();
    let mut idx = Vec::new();
    for r in 0..=rings {
        let phi = f32::from(r) / f32::from(rings) * std::f32::consts::PI;
        for s in 0..=sectors {
            let th = f32::from(s) / f32::from(sectors) * std::f32::consts::TAU;
            let p = [phi.sin() * th.cos(), phi.cos(), phi.sin() * th.sin()];
            v.extend_from_slice(&[p[0], p[1], p[2], p[0], p[1], p[2]]);
        }
    }
    let w = sectors + 1;
    for r in 0..rings {
        for s in 0..sectors {
            let a = r * w + s;
            idx.extend_from_slice(&[a, a + 1, a + w, a + 1, a + w + 1, a + w]);
        }
    }
    (v, idx)
}

/// What the skeleton's two render pipelines share: shader, layout, depth, samples, target.
struct Stage<'a> {
    device: &'a wgpu::Device,
    layout: &'a wgpu::PipelineLayout,
    shader: &'a wgpu::ShaderModule,
    depth_stencil: Option<wgpu::DepthStencilState>,
    multisample: wgpu::MultisampleState,
    color: &'a [Option<wgpu::ColorTargetState>],
}

impl Stage<'_> {
    /// A pipeline of the shader's `(vertex, fragment)` entry points over `buffers`.
    fn pipeline(
        &self,
        label: &str,
        (vs, fs): (&str, &str),
        buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
        primitive: wgpu::PrimitiveState,
    ) -> wgpu::RenderPipeline {
        self.device
            .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(self.layout),
                vertex: wgpu::VertexState {
                    module: self.shader,
                    entry_point: Some(vs),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    buffers,
                },
                primitive,
                depth_stencil: self.depth_stencil.clone(),
                multisample: self.multisample,
                fragment: Some(wgpu::FragmentState {
                    module: self.shader,
                    entry_point: Some(fs),
                    compilation_options: wgpu::PipelineCompilationOptions::default(),
                    targets: self.color,
                }),
                multiview_mask: None,
                cache: None,
            })
    }
}

/// The shadow's pipeline: the mesh vertex stage with `fs_shadow`, blended over the ground,
/// tested against it, writing no depth (overlapping discs darken each other; the figure is
/// drawn after them).
fn shadow_pipeline(
    stage: &Stage<'_>,
    color: wgpu::TextureFormat,
    buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
) -> wgpu::RenderPipeline {
    let blended = [Some(wgpu::ColorTargetState {
        format: color,
        blend: Some(wgpu::BlendState::ALPHA_BLENDING),
        write_mask: wgpu::ColorWrites::ALL,
    })];
    let shadow_stage = Stage {
        device: stage.device,
        layout: stage.layout,
        shader: stage.shader,
        depth_stencil: stage
            .depth_stencil
            .clone()
            .map(|d| wgpu::DepthStencilState {
                depth_write_enabled: Some(false),
                ..d
            }),
        multisample: stage.multisample,
        color: &blended,
    };
    shadow_stage.pipeline(
        "ground shadow",
        ("vs_mesh", "fs_shadow"),
        buffers,
        wgpu::PrimitiveState {
            cull_mode: Some(wgpu::Face::Back),
            ..wgpu::PrimitiveState::default()
        },
    )
}

impl SkeletonRenderer {
    /// Builds the pipelines for passes with `targets`.
    pub fn new(device: &wgpu::Device, targets: Targets) -> SkeletonRenderer {
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("skeleton"),
            source: wgpu::ShaderSource::Wgsl(include_str!("skeleton.wgsl").into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("skeleton globals"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: wgpu::BufferSize::new(GLOBALS_BYTES),
                },
                count: None,
            }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("skeleton"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let depth_stencil = targets.depth.map(|format| wgpu::DepthStencilState {
            format,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: wgpu::StencilState::default(),
            bias: wgpu::DepthBiasState::default(),
        });
        let multisample = wgpu::MultisampleState {
            count: targets.samples.max(1),
            ..wgpu::MultisampleState::default()
        };
        let color = [Some(wgpu::ColorTargetState {
            format: targets.color,
            blend: None,
            write_mask: wgpu::ColorWrites::ALL,
        })];
        let vertex_attrs = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];
        let instance_attrs = wgpu::vertex_attr_array![
            2 => Float32x3, 3 => Float32x4, 4 => Float32x3, 5 => Float32x4
        ];
        let buffers = [
            Some(wgpu::VertexBufferLayout {
                array_stride: VERTEX_BYTES,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &vertex_attrs,
            }),
            Some(wgpu::VertexBufferLayout {
                array_stride: Instance::BYTES as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &instance_attrs,
            }),
        ];
        let stage = Stage {
            device,
            layout: &pipeline_layout,
            shader: &shader,
            depth_stencil,
            multisample,
            color: &color,
        };
        let mesh_pipeline = stage.pipeline(
            "skeleton meshes",
            ("vs_mesh", "fs_mesh"),
            &buffers,
            wgpu::PrimitiveState {
                cull_mode: Some(wgpu::Face::Back),
                ..wgpu::PrimitiveState::default()
            },
        );
        let ground_pipeline = stage.pipeline(
            "ground",
            ("vs_ground", "fs_ground"),
            &[],
            wgpu::PrimitiveState::default(),
        );
        let shadow_pipeline = shadow_pipeline(&stage, targets.color, &buffers);
        let (cv, ci) = cylinder_mesh(10);
        let (sv, si) = sphere_mesh(6, 10);
        SkeletonRenderer {
            mesh_pipeline,
            ground_pipeline,
            shadow_pipeline,
            drawn: Arc::new(AtomicUsize::new(0)),
            layout,
            cylinder: mesh(device, "cylinder", &cv, &ci),
            sphere: mesh(device, "sphere", &sv, &si),
            slots: Vec::new(),
            bytes: Vec::new(),
        }
    }

    /// A counter of the viewports prepared in slots below [`LOAD_SLOT`]; the window reads and
    /// resets it each frame.
    pub fn drawn_counter(&self) -> Arc<AtomicUsize> {
        Arc::clone(&self.drawn)
    }

    /// Uploads viewport `slot`'s camera (`view` at the shapes' presentation time, for a
    /// viewport of aspect `aspect`) and shapes.
    pub fn prepare(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        slot: usize,
        view: &View,
        aspect: f32,
        shapes: &FrameShapes,
    ) {
        while self.slots.len() <= slot {
            let globals = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("skeleton globals"),
                size: GLOBALS_BYTES,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("skeleton globals"),
                layout: &self.layout,
                entries: &[wgpu::BindGroupEntry {
                    binding: 0,
                    resource: globals.as_entire_binding(),
                }],
            });
            self.slots.push(Slot {
                globals,
                bind_group,
                instances: instance_buffer(device, 64),
                capacity: 64,
                bones: 0,
                joints: 0,
                shadows: 0,
            });
        }
        if slot < LOAD_SLOT {
            self.drawn.fetch_add(1, Ordering::Relaxed);
        }
        let view = view.at(shapes.time_s);
        let vp = view.view_proj(aspect);
        let mut g: Vec<f32> = vp.iter().flatten().copied().collect();
        let l = view.light;
        let n = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt().max(1e-6);
        g.extend_from_slice(&[l[0] / n, l[1] / n, l[2] / n, l[3]]);
        // Shader layout: x, z = ground centre, y = half side, w = height.
        g.extend_from_slice(&[
            view.target[0],
            view.ground_half,
            view.target[2],
            view.ground_y,
        ]);
        g.extend_from_slice(&[view.grid, 0.0, 0.0, 0.0]);
        let count = shapes.bones.len() + shapes.joints.len() + shapes.shadows.len();
        let Some(s) = self.slots.get_mut(slot) else {
            return;
        };
        queue.write_buffer(&s.globals, 0, &floats(&g));
        if count > s.capacity {
            s.capacity = count.next_power_of_two();
            s.instances = instance_buffer(device, s.capacity);
        }
        self.bytes.clear();
        for i in shapes
            .bones
            .iter()
            .chain(&shapes.joints)
            .chain(&shapes.shadows)
        {
            i.write(&mut self.bytes);
        }
        if !self.bytes.is_empty() {
            queue.write_buffer(&s.instances, 0, &self.bytes);
        }
        s.bones = shapes.bones.len() as u32;
        s.joints = shapes.joints.len() as u32;
        s.shadows = shapes.shadows.len() as u32;
    }

    /// Records slot `slot`'s draw calls into `pass` (viewport already set by the caller).
    pub fn paint(&self, pass: &mut wgpu::RenderPass<'_>, slot: usize) {
        let Some(s) = self.slots.get(slot) else {
            return;
        };
        pass.set_bind_group(0, &s.bind_group, &[]);
        pass.set_pipeline(&self.ground_pipeline);
        pass.draw(0..6, 0..1);
        pass.set_vertex_buffer(1, s.instances.slice(..));
        let figure = s.bones + s.joints;
        for (pipeline, mesh, range) in [
            (
                &self.shadow_pipeline,
                &self.sphere,
                figure..figure + s.shadows,
            ),
            (&self.mesh_pipeline, &self.cylinder, 0..s.bones),
            (&self.mesh_pipeline, &self.sphere, s.bones..figure),
        ] {
            if range.is_empty() {
                continue;
            }
            pass.set_pipeline(pipeline);
            pass.set_vertex_buffer(0, mesh.vertices.slice(..));
            pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint16);
            pass.draw_indexed(0..mesh.count, 0, range);
        }
    }
}

fn instance_buffer(device: &wgpu::Device, capacity: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("skeleton instances"),
        size: (capacity * Instance::BYTES) as u64,
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

/// What one egui viewport draws: a camera and the shapes of one frame.
pub struct SkeletonCallback {
    /// Renderer slot (0 = left / single viewport, 1 = right).
    pub slot: usize,
    /// The clip's camera.
    pub view: View,
    /// Viewport aspect ratio.
    pub aspect: f32,
    /// Shapes at this frame's presentation time.
    pub shapes: Arc<FrameShapes>,
}

impl egui_wgpu::CallbackTrait for SkeletonCallback {
    fn prepare(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        _screen: &egui_wgpu::ScreenDescriptor,
        _encoder: &mut wgpu::CommandEncoder,
        resources: &mut egui_wgpu::CallbackResources,
    ) -> Vec<wgpu::CommandBuffer> {
        if let Some(r) = resources.get_mut::<SkeletonRenderer>() {
            r.prepare(
                device,
                queue,
                self.slot,
                &self.view,
                self.aspect,
                &self.shapes,
            );
        }
        Vec::new()
    }

    fn paint(
        &self,
        _info: egui::PaintCallbackInfo,
        pass: &mut wgpu::RenderPass<'static>,
        resources: &egui_wgpu::CallbackResources,
    ) {
        if let Some(r) = resources.get::<SkeletonRenderer>() {
            r.paint(pass, self.slot);
        }
    }
}

/// An RGBA8 image read back from the GPU, rows top to bottom.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width × height × 4` bytes.
    pub rgba: Vec<u8>,
}

impl Image {
    /// The pixel at (x, y).
    #[cfg(test)]
    pub fn pixel(&self, x: u32, y: u32) -> [u8; 4] {
        let i = ((y * self.width + x) * 4) as usize;
        let mut p = [0; 4];
        if let Some(s) = self.rgba.get(i..i + 4) {
            p.copy_from_slice(s);
        }
        p
    }

    /// The image encoded as PNG.
    ///
    /// # Errors
    /// Encoder errors.
    pub fn png_bytes(&self) -> anyhow::Result<Vec<u8>> {
        let mut out = Vec::new();
        let mut enc = png::Encoder::new(&mut out, self.width, self.height);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc.write_header().context("encoding a PNG")?;
        w.write_image_data(&self.rgba).context("encoding a PNG")?;
        w.finish().context("encoding a PNG")?;
        Ok(out)
    }

    /// Writes the image as PNG, whole or not at all ([`files::AtomicFile`]); an existing file
    /// is replaced only with [`files::Mode::Replace`].
    ///
    /// # Errors
    /// I/O or encoder errors, or an existing file under [`files::Mode::New`], naming the file.
    pub fn write_png(&self, path: &std::path::Path, mode: files::Mode) -> anyhow::Result<()> {
        let mut file = files::AtomicFile::create(path, mode)?;
        let mut enc = png::Encoder::new(&mut file, self.width, self.height);
        enc.set_color(png::ColorType::Rgba);
        enc.set_depth(png::BitDepth::Eight);
        let mut w = enc
            .write_header()
            .with_context(|| format!("writing {}", path.display()))?;
        w.write_image_data(&self.rgba)
            .with_context(|| format!("writing {}", path.display()))?;
        w.finish()
            .with_context(|| format!("writing {}", path.display()))?;
        file.commit()?;
        Ok(())
    }

    /// Reads an RGBA8 PNG.
    ///
    /// # Errors
    /// The file cannot be read or is not an 8-bit RGBA PNG, naming the file.
    #[cfg(test)]
    pub fn read_png(path: &std::path::Path) -> anyhow::Result<Image> {
        let file =
            std::fs::File::open(path).with_context(|| format!("opening {}", path.display()))?;
        let mut dec = png::Decoder::new(std::io::BufReader::new(file))
            .read_info()
            .with_context(|| format!("{}: not a PNG", path.display()))?;
        let info = dec.info();
        if info.color_type != png::ColorType::Rgba || info.bit_depth != png::BitDepth::Eight {
            anyhow::bail!("{}: expected an 8-bit RGBA PNG", path.display());
        }
        let (width, height) = (info.width, info.height);
        if u64::from(width) * u64::from(height) > 1 << 26 {
            anyhow::bail!("{}: {width}×{height} is too large", path.display());
        }
        let mut rgba = vec![0; (width * height * 4) as usize];
        dec.next_frame(&mut rgba)
            .with_context(|| format!("{}: corrupt PNG data", path.display()))?;
        Ok(Image {
            width,
            height,
            rgba,
        })
    }
}

/// The shapes of every stage (a row of panes) at clip time `t_s`, appended to `shapes`.
pub fn shapes_at(stages: &mut [crate::scene::Stage], t_s: f64, shapes: &mut Vec<FrameShapes>) {
    for stage in stages {
        let mut s = FrameShapes::default();
        stage.shapes_at(t_s, &mut s);
        shapes.push(s);
    }
}

/// `shapes` as panes of `width` × `height` pixels, `cols` to a row, seen through `view`.
pub fn panes_of<'a>(
    shapes: &'a [FrameShapes],
    view: &'a View,
    cols: u32,
    width: u32,
    height: u32,
) -> Vec<Pane<'a>> {
    shapes
        .iter()
        .enumerate()
        .map(|(k, s)| Pane {
            x: (k as u32 % cols) * width,
            y: (k as u32 / cols) * height,
            width,
            height,
            view,
            shapes: s,
        })
        .collect()
}

/// An SVG of `image` (embedded as PNG) with each pane's name and time written over it as
/// text, so a paper's figure keeps its labels sharp and editable.
///
/// `names` label the columns and `times` (seconds) the rows of panes `width` × `pane` pixels.
///
/// # Errors
/// The image does not encode as PNG.
pub fn labelled_svg(
    image: &Image,
    names: &[String],
    times: &[f64],
    (width, pane): (u32, u32),
) -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let png = image.png_bytes()?;
    let (w, h) = (image.width, image.height);
    let size = (f64::from(pane) / 16.0).clamp(10.0, 32.0);
    let mut s = String::new();
    let _ = writeln!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" xmlns:xlink="http://www.w3.org/1999/xlink" width="{w}" height="{h}" viewBox="0 0 {w} {h}">"#
    );
    let _ = writeln!(
        s,
        r#"<image x="0" y="0" width="{w}" height="{h}" xlink:href="data:image/png;base64,{}"/>"#,
        base64::Engine::encode(&base64::engine::general_purpose::STANDARD, &png)
    );
    let _ = writeln!(
        s,
        r##"<g font-family="Helvetica, Arial, sans-serif" font-size="{size:.0}" fill="#f2f2f2">"##
    );
    for (row, t) in times.iter().enumerate() {
        for (col, name) in names.iter().enumerate() {
            let (x, y) = (col as u32 * width, row as u32 * pane);
            let pad = size * 0.6;
            let _ = writeln!(
                s,
                r#"<text class="pane" x="{:.1}" y="{:.1}">{}</text>"#,
                f64::from(x) + pad,
                f64::from(y) + pad + size,
                xml_escape(name)
            );
            let _ = writeln!(
                s,
                r#"<text class="time" x="{:.1}" y="{:.1}" text-anchor="end">t = {t:.2} s</text>"#,
                f64::from(x + width) - pad,
                f64::from(y) + pad + size
            );
        }
    }
    s.push_str("</g>\n</svg>\n");
    Ok(s)
}

/// `text` for XML text and attributes (control characters as spaces).
fn xml_escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c if c.is_control() => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

/// One viewport of an offscreen frame.
pub struct Pane<'a> {
    /// Left edge, pixels.
    pub x: u32,
    /// Top edge, pixels.
    pub y: u32,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Camera.
    pub view: &'a View,
    /// Shapes.
    pub shapes: &'a FrameShapes,
}

/// A headless device rendering into textures: the display-free core of the renderer.
pub struct Offscreen {
    device: wgpu::Device,
    queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    renderer: SkeletonRenderer,
    samples: u32,
    /// egui's renderer for [`Offscreen::render_ui`], made on first use, with its own
    /// skeleton renderer for the frames' paint callbacks.
    ui: Option<egui_wgpu::Renderer>,
}

/// Colour format of offscreen frames.
const OFFSCREEN_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const OFFSCREEN_DEPTH: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;

impl Offscreen {
    /// Opens the first adapter wgpu finds (Mesa's lavapipe on a machine without a GPU) with
    /// `samples`-times MSAA.
    ///
    /// # Errors
    /// No adapter (no Vulkan driver installed) or no device.
    pub fn new(samples: u32) -> anyhow::Result<Offscreen> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter =
            pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
                .context(
                "no graphics adapter (on Debian: apt-get install mesa-vulkan-drivers libvulkan1)",
            )?;
        let (device, queue) =
            pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))
                .context("opening the graphics device")?;
        let samples = samples.max(1);
        let renderer = SkeletonRenderer::new(
            &device,
            Targets {
                color: OFFSCREEN_FORMAT,
                depth: Some(OFFSCREEN_DEPTH),
                samples,
            },
        );
        Ok(Offscreen {
            device,
            queue,
            info: adapter.get_info(),
            renderer,
            samples,
            ui: None,
        })
    }

    /// Renders one egui frame, `output` of `ctx`'s [`egui::Context::run_ui`], into a
    /// `width × height` image, as the study window's egui pass draws it: its paint callbacks
    /// ([`SkeletonCallback`]) find a skeleton renderer in the callback resources.
    ///
    /// # Errors
    /// The frame cannot be read back.
    pub fn render_ui(
        &mut self,
        ctx: &egui::Context,
        output: egui::FullOutput,
        width: u32,
        height: u32,
    ) -> anyhow::Result<Image> {
        let targets = self.targets(width, height);
        let samples = self.samples;
        let mut ui = self.ui.take().unwrap_or_else(|| {
            let mut r = egui_wgpu::Renderer::new(
                &self.device,
                OFFSCREEN_FORMAT,
                egui_wgpu::RendererOptions {
                    msaa_samples: samples,
                    depth_stencil_format: Some(OFFSCREEN_DEPTH),
                    dithering: false,
                    predictable_texture_filtering: false,
                },
            );
            r.callback_resources.insert(SkeletonRenderer::new(
                &self.device,
                Targets {
                    color: OFFSCREEN_FORMAT,
                    depth: Some(OFFSCREEN_DEPTH),
                    samples,
                },
            ));
            r
        });
        let egui::FullOutput {
            shapes,
            mut textures_delta,
            pixels_per_point: ppp,
            ..
        } = output;
        for (id, deltas) in &textures_delta.set {
            for delta in deltas {
                ui.update_texture(&self.device, &self.queue, *id, delta);
            }
        }
        let jobs = ctx.tessellate(shapes, ppp);
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [width, height],
            pixels_per_point: ppp,
        };
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        let commands = ui.update_buffers(&self.device, &self.queue, &mut encoder, &jobs, &screen);
        {
            let pass = targets.pass(&mut encoder, "offscreen egui", wgpu::Color::BLACK);
            ui.render(&mut pass.forget_lifetime(), &jobs, &screen);
        }
        self.queue.submit(commands);
        for id in &textures_delta.free {
            ui.free_texture(id);
        }
        // Applied: egui checks that no delta is dropped unapplied.
        textures_delta.clear();
        self.ui = Some(ui);
        let rgba = self.read_back(encoder, &targets.resolved, width, height)?;
        Ok(Image {
            width,
            height,
            rgba,
        })
    }

    /// The adapter in use.
    pub fn adapter(&self) -> &wgpu::AdapterInfo {
        &self.info
    }

    /// Renders `panes` into a `width × height` frame cleared to [`BACKGROUND`].
    ///
    /// # Errors
    /// The frame cannot be read back.
    pub fn render(&mut self, width: u32, height: u32, panes: &[Pane<'_>]) -> anyhow::Result<Image> {
        let targets = self.targets(width, height);
        for (k, p) in panes.iter().enumerate() {
            let aspect = p.width as f32 / p.height.max(1) as f32;
            self.renderer
                .prepare(&self.device, &self.queue, k, p.view, aspect, p.shapes);
        }
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor::default());
        self.draw_panes(&mut encoder, &targets, panes);
        let rgba = self.read_back(encoder, &targets.resolved, width, height)?;
        Ok(Image {
            width,
            height,
            rgba,
        })
    }

    /// The frame's textures: the resolved colour target (read back), the multisampled one
    /// when MSAA is on, and the depth buffer.
    fn targets(&self, width: u32, height: u32) -> FrameTargets {
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let texture = |format, samples, usage| {
            self.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("offscreen"),
                size,
                mip_level_count: 1,
                sample_count: samples,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let view = |t: &wgpu::Texture| t.create_view(&wgpu::TextureViewDescriptor::default());
        let resolved = texture(
            OFFSCREEN_FORMAT,
            1,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        );
        let msaa = (self.samples > 1).then(|| {
            view(&texture(
                OFFSCREEN_FORMAT,
                self.samples,
                wgpu::TextureUsages::RENDER_ATTACHMENT,
            ))
        });
        let depth = view(&texture(
            OFFSCREEN_DEPTH,
            self.samples,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        ));
        FrameTargets {
            resolved_view: view(&resolved),
            resolved,
            msaa,
            depth,
        }
    }

    /// One render pass: cleared to [`BACKGROUND`], each pane in its viewport.
    fn draw_panes(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        targets: &FrameTargets,
        panes: &[Pane<'_>],
    ) {
        let background = wgpu::Color {
            r: f64::from(BACKGROUND[0]),
            g: f64::from(BACKGROUND[1]),
            b: f64::from(BACKGROUND[2]),
            a: 1.0,
        };
        let mut pass = targets.pass(encoder, "offscreen", background);
        for (k, p) in panes.iter().enumerate() {
            pass.set_viewport(
                p.x as f32,
                p.y as f32,
                p.width as f32,
                p.height as f32,
                0.0,
                1.0,
            );
            self.renderer.paint(&mut pass, k);
        }
    }

    /// Submits `encoder` with a copy of `resolved` into a mapped buffer and returns its
    /// pixels, RGBA rows without the copy's row padding.
    fn read_back(
        &self,
        mut encoder: wgpu::CommandEncoder,
        resolved: &wgpu::Texture,
        width: u32,
        height: u32,
    ) -> anyhow::Result<Vec<u8>> {
        let row = (width * 4).div_ceil(256) * 256;
        let readback = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("readback"),
            size: u64::from(row) * u64::from(height),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        encoder.copy_texture_to_buffer(
            resolved.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &readback,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(height),
                },
            },
            resolved.size(),
        );
        self.queue.submit([encoder.finish()]);
        let slice = readback.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .context("waiting for the frame")?;
        rx.recv()
            .context("the frame was never mapped")?
            .context("mapping the frame")?;
        let data = slice
            .get_mapped_range()
            .map_err(|e| anyhow::anyhow!("{e:?}"))
            .context("reading the frame")?;
        let mut rgba = Vec::with_capacity((width * height * 4) as usize);
        for y in 0..height {
            let start = (y * row) as usize;
            rgba.extend_from_slice(&data[start..start + (width * 4) as usize]);
        }
        drop(data);
        readback.unmap();
        Ok(rgba)
    }
}

/// The textures one offscreen frame is drawn into.
struct FrameTargets {
    /// Single-sampled colour target, copied to the readback buffer.
    resolved: wgpu::Texture,
    resolved_view: wgpu::TextureView,
    /// Multisampled colour target resolved into `resolved`, when MSAA is on.
    msaa: Option<wgpu::TextureView>,
    depth: wgpu::TextureView,
}

impl FrameTargets {
    /// A render pass into these targets (through the MSAA target when there is one),
    /// cleared to `clear` and a depth of 1, the depth not kept.
    fn pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        label: &str,
        clear: wgpu::Color,
    ) -> wgpu::RenderPass<'e> {
        let (view, resolve_target) = match &self.msaa {
            Some(m) => (m, Some(&self.resolved_view)),
            None => (&self.resolved_view, None),
        };
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some(label),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(clear),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.depth,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            ..wgpu::RenderPassDescriptor::default()
        })
    }
}

/// Paints pane `k` of an egui frame: its background, and when `gpu` its skeletons posed at
/// time `t_s` through [`SkeletonCallback`] (the study window's trials and the preview alike).
#[allow(
    clippy::too_many_arguments,
    reason = "one pane's parts, as the frame holds them"
)]
pub(crate) fn paint_pane(
    painter: &egui::Painter,
    gpu: bool,
    k: usize,
    rect: egui::Rect,
    view: &crate::scene::View,
    stage: &mut crate::scene::Stage,
    shapes: &mut Arc<crate::scene::FrameShapes>,
    t_s: f64,
) {
    let bg = egui::Color32::from_rgb(
        (BACKGROUND[0] * 255.0) as u8,
        (BACKGROUND[1] * 255.0) as u8,
        (BACKGROUND[2] * 255.0) as u8,
    );
    painter.rect_filled(rect, 0.0, bg);
    let mut frame = crate::scene::FrameShapes::default();
    stage.shapes_at(t_s, &mut frame);
    *shapes = Arc::new(frame);
    if gpu {
        painter.add(egui_wgpu::Callback::new_paint_callback(
            rect,
            SkeletonCallback {
                slot: k,
                view: *view,
                aspect: rect.width() / rect.height().max(1.0),
                shapes: Arc::clone(shapes),
            },
        ));
    }
}

#[cfg(test)]
mod svg_tests {
    use super::xml_escape;

    #[test]
    fn labels_are_escaped_for_xml() {
        assert_eq!(xml_escape("a<b>&\"c'"), "a&lt;b&gt;&amp;&quot;c&apos;");
    }
}
