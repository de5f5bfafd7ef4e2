//! The headless wgpu renderer: a frame's triangles drawn twice side by side (the fixed camera on
//! the left, the follow camera on the right) into an RGBA8 texture with a depth buffer, lit by an
//! ambient and a two-sided directional light, and read back to the CPU. Runs on any adapter,
//! lavapipe included; every wgpu call's error comes back as an `Err` (`GpuContext::scoped`).

use std::sync::mpsc;

use anyhow::{Result, anyhow, ensure};
use glam::{Mat4, Vec3};

use super::triangles::Vertex;
use crate::gpu::context::GpuContext;

/// The shader: world-space vertices through a view's P·V; colour × (ambient + diffuse·|n·l|).
const SHADER: &str = r#"
struct View {
    view_proj: mat4x4<f32>,
    // xyz: unit direction toward the light (world); w: ambient share
    light: vec4<f32>,
}
@group(0) @binding(0) var<uniform> view: View;

struct VsIn {
    @location(0) pos: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec4<f32>,
}
struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) color: vec4<f32>,
}

@vertex
fn vs_main(v: VsIn) -> VsOut {
    var o: VsOut;
    o.clip = view.view_proj * vec4<f32>(v.pos, 1.0);
    o.normal = v.normal;
    o.color = v.color;
    return o;
}

@fragment
fn fs_main(i: VsOut) -> @location(0) vec4<f32> {
    // two-sided: hull triangles come in either winding
    let n = normalize(i.normal + vec3<f32>(0.0, 0.0, 1e-6));
    let shade = view.light.w + (1.0 - view.light.w) * abs(dot(n, view.light.xyz));
    return vec4<f32>(i.color.rgb * shade, i.color.a);
}
"#;

/// The colour format of the frame (no sRGB encoding: the bytes are the shader's values × 255).
const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// The background (sky), RGB 0..1.
pub const BACKGROUND: [f64; 3] = [0.86, 0.9, 0.95];
/// Direction toward the light (world; normalised when used): from the cameras' side, above.
const LIGHT_DIR: Vec3 = Vec3::new(0.4, -0.6, 1.0);
/// Share of the colour that the ambient light gives.
const AMBIENT: f32 = 0.45;
/// Bytes of a view's uniform: P·V (64) and the light (16).
const UNIFORM_BYTES: u64 = 80;

/// A renderer of two `view_width` × `view_height` views side by side.
pub struct SceneRenderer {
    ctx: GpuContext,
    view_width: u32,
    view_height: u32,
    opaque: wgpu::RenderPipeline,
    ghost: wgpu::RenderPipeline,
    uniforms: [wgpu::Buffer; 2],
    bind_groups: [wgpu::BindGroup; 2],
    color: wgpu::Texture,
    depth: wgpu::Texture,
    staging: wgpu::Buffer,
    /// Bytes per row of the staging buffer: 4·width rounded up to 256.
    padded_row: u32,
    vertices: Option<wgpu::Buffer>,
}

impl SceneRenderer {
    /// A renderer on `ctx`'s device for views of `view_width` × `view_height` pixels.
    pub fn new(ctx: GpuContext, view_width: u32, view_height: u32) -> Result<SceneRenderer> {
        ensure!(view_width > 0 && view_height > 0, "video view size {view_width}x{view_height}: expected both > 0");
        let width = 2 * view_width;
        let max = ctx.device.limits().max_texture_dimension_2d;
        ensure!(width <= max && view_height <= max, "video frame {width}x{view_height} exceeds adapter {}'s largest texture ({max})", ctx.info.name);
        let padded_row = (4 * width).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let device = ctx.device.clone();
        let built = ctx.scoped(
            || "building the video renderer".into(),
            || {
                let module = device.create_shader_module(wgpu::ShaderModuleDescriptor { label: Some("video"), source: wgpu::ShaderSource::Wgsl(SHADER.into()) });
                let bgl = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some("video view"),
                    entries: &[wgpu::BindGroupLayoutEntry {
                        binding: 0,
                        visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                        ty: wgpu::BindingType::Buffer { ty: wgpu::BufferBindingType::Uniform, has_dynamic_offset: false, min_binding_size: wgpu::BufferSize::new(UNIFORM_BYTES) },
                        count: None,
                    }],
                });
                let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor { label: Some("video"), bind_group_layouts: &[Some(&bgl)], immediate_size: 0 });
                let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x4];
                let pipeline = |blend: Option<wgpu::BlendState>, depth_write: bool| {
                    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                        label: Some("video"),
                        layout: Some(&layout),
                        vertex: wgpu::VertexState {
                            module: &module,
                            entry_point: Some("vs_main"),
                            compilation_options: Default::default(),
                            buffers: &[Some(wgpu::VertexBufferLayout { array_stride: std::mem::size_of::<Vertex>() as u64, step_mode: wgpu::VertexStepMode::Vertex, attributes: &attributes })],
                        },
                        primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
                        depth_stencil: Some(wgpu::DepthStencilState {
                            format: DEPTH_FORMAT,
                            depth_write_enabled: Some(depth_write),
                            depth_compare: Some(wgpu::CompareFunction::Less),
                            stencil: Default::default(),
                            bias: Default::default(),
                        }),
                        multisample: Default::default(),
                        fragment: Some(wgpu::FragmentState {
                            module: &module,
                            entry_point: Some("fs_main"),
                            compilation_options: Default::default(),
                            targets: &[Some(wgpu::ColorTargetState { format: COLOR_FORMAT, blend, write_mask: wgpu::ColorWrites::ALL })],
                        }),
                        multiview_mask: None,
                        cache: None,
                    })
                };
                // the ghost: blended over what is drawn, behind nothing it does not hide
                let opaque = pipeline(None, true);
                let ghost = pipeline(Some(wgpu::BlendState::ALPHA_BLENDING), false);
                let uniform = || device.create_buffer(&wgpu::BufferDescriptor { label: Some("video view"), size: UNIFORM_BYTES, usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST, mapped_at_creation: false });
                let uniforms = [uniform(), uniform()];
                let bind_groups = [0, 1].map(|k| {
                    device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some("video view"), layout: &bgl, entries: &[wgpu::BindGroupEntry { binding: 0, resource: uniforms[k].as_entire_binding() }] })
                });
                let texture = |format, usage| {
                    device.create_texture(&wgpu::TextureDescriptor {
                        label: Some("video frame"),
                        size: wgpu::Extent3d { width, height: view_height, depth_or_array_layers: 1 },
                        mip_level_count: 1,
                        sample_count: 1,
                        dimension: wgpu::TextureDimension::D2,
                        format,
                        usage,
                        view_formats: &[],
                    })
                };
                let color = texture(COLOR_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC);
                let depth = texture(DEPTH_FORMAT, wgpu::TextureUsages::RENDER_ATTACHMENT);
                let staging = device.create_buffer(&wgpu::BufferDescriptor { label: Some("video readback"), size: padded_row as u64 * view_height as u64, usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ, mapped_at_creation: false });
                (opaque, ghost, uniforms, bind_groups, color, depth, staging)
            },
        )?;
        let (opaque, ghost, uniforms, bind_groups, color, depth, staging) = built;
        Ok(SceneRenderer { ctx, view_width, view_height, opaque, ghost, uniforms, bind_groups, color, depth, staging, padded_row, vertices: None })
    }

    /// The size of a rendered image: (2·view width, view height).
    pub fn size(&self) -> (u32, u32) {
        (2 * self.view_width, self.view_height)
    }

    /// The adapter it renders on.
    pub fn adapter(&self) -> String {
        self.ctx.describe()
    }

    /// Draws `opaque` then the translucent `ghost` triangles (world space) through `view_projs`
    /// (left view, right view) and returns the image: RGBA8 rows, top first, tightly packed
    /// ([2·view width · view height · 4] bytes).
    pub fn render(&mut self, opaque: &[Vertex], ghost: &[Vertex], view_projs: [Mat4; 2]) -> Result<Vec<u8>> {
        let (width, height) = self.size();
        let bytes = std::mem::size_of_val(opaque) + std::mem::size_of_val(ghost);
        // the vertex buffer grows to the largest frame (at least 4 bytes: wgpu's smallest copy)
        if self.vertices.as_ref().is_none_or(|b| (b.size() as usize) < bytes) {
            let size = (bytes.max(4) as u64).next_power_of_two();
            // a vertex buffer is bounded by max_buffer_size only, as a staging buffer is
            self.ctx.check_buffer_size("video vertices", size, crate::gpu::context::BufferRole::Staging)?;
            let device = &self.ctx.device;
            self.vertices = Some(self.ctx.scoped(
                || format!("allocating {size} bytes of video vertices"),
                || device.create_buffer(&wgpu::BufferDescriptor { label: Some("video vertices"), size, usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST, mapped_at_creation: false }),
            )?);
        }
        let vertices = self.vertices.as_ref().expect("allocated above");
        let light = LIGHT_DIR.normalize();
        let (n_opaque, n_ghost) = (opaque.len() as u32, ghost.len() as u32);
        let receiver = self.ctx.scoped(
            || "rendering a video frame".into(),
            || {
                let queue = &self.ctx.queue;
                queue.write_buffer(vertices, 0, bytemuck::cast_slice(opaque));
                queue.write_buffer(vertices, std::mem::size_of_val(opaque) as u64, bytemuck::cast_slice(ghost));
                for (k, vp) in view_projs.iter().enumerate() {
                    let mut u = [0.0f32; 20];
                    u[..16].copy_from_slice(&vp.to_cols_array());
                    u[16..].copy_from_slice(&[light.x, light.y, light.z, AMBIENT]);
                    queue.write_buffer(&self.uniforms[k], 0, bytemuck::cast_slice(&u));
                }
                let color_view = self.color.create_view(&wgpu::TextureViewDescriptor::default());
                let depth_view = self.depth.create_view(&wgpu::TextureViewDescriptor::default());
                let mut enc = self.ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("video frame") });
                {
                    let [r, g, b] = BACKGROUND;
                    let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                        label: Some("video frame"),
                        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                            view: &color_view,
                            depth_slice: None,
                            resolve_target: None,
                            ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color { r, g, b, a: 1.0 }), store: wgpu::StoreOp::Store },
                        })],
                        depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                            view: &depth_view,
                            depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
                            stencil_ops: None,
                        }),
                        timestamp_writes: None,
                        occlusion_query_set: None,
                        multiview_mask: None,
                    });
                    pass.set_vertex_buffer(0, vertices.slice(..));
                    for k in 0..2u32 {
                        // view k: the k-th half of the texture
                        pass.set_viewport((k * self.view_width) as f32, 0.0, self.view_width as f32, self.view_height as f32, 0.0, 1.0);
                        pass.set_bind_group(0, &self.bind_groups[k as usize], &[]);
                        if n_opaque > 0 {
                            pass.set_pipeline(&self.opaque);
                            pass.draw(0..n_opaque, 0..1);
                        }
                        if n_ghost > 0 {
                            pass.set_pipeline(&self.ghost);
                            pass.draw(n_opaque..n_opaque + n_ghost, 0..1);
                        }
                    }
                }
                enc.copy_texture_to_buffer(
                    wgpu::TexelCopyTextureInfo { texture: &self.color, mip_level: 0, origin: wgpu::Origin3d::ZERO, aspect: wgpu::TextureAspect::All },
                    wgpu::TexelCopyBufferInfo { buffer: &self.staging, layout: wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(self.padded_row), rows_per_image: Some(height) } },
                    wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                );
                queue.submit([enc.finish()]);
                let (tx, rx) = mpsc::channel();
                self.staging.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                    let _ = tx.send(r);
                });
                rx
            },
        )?;
        let waited = self.ctx.device.poll(wgpu::PollType::wait_indefinitely());
        let mapped = match receiver.recv() {
            Ok(r) => r.map_err(|e| anyhow!("reading a video frame back: mapping failed: {e}")),
            Err(_) => Err(anyhow!("reading a video frame back: the map never completed")),
        };
        waited.map_err(|e| anyhow!("rendering a video frame: waiting for adapter {}: {e}", self.ctx.info.name))?;
        mapped?;
        // rows of 4·width bytes out of rows of `padded_row` bytes
        let row = 4 * width as usize;
        let mut image = Vec::with_capacity(row * height as usize);
        let read = self.staging.slice(..).get_mapped_range().map_err(|e| anyhow!("reading a video frame back: {e:?}")).map(|data| {
            for y in 0..height as usize {
                image.extend_from_slice(&data[y * self.padded_row as usize..][..row]);
            }
        });
        self.staging.unmap();
        read?;
        self.ctx.check_uncaptured("rendering a video frame")?;
        Ok(image)
    }
}
