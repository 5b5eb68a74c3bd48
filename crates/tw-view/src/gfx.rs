//! The window's GPU side: a wgpu instance (with winit's display handle, which GL on X11
//! needs), the window surface, the device it presents with, and egui-wgpu's renderer. One
//! [`Gfx::present`] call draws egui's output (the scene image is an egui texture drawn in the
//! background layer) into the next surface texture. Resizing reconfigures the surface; a zero
//! size (minimised) skips frames.

use std::sync::Arc;

use winit::window::Window;

use crate::error::ViewError;

pub struct Gfx {
    pub instance: wgpu::Instance,
    pub surface: wgpu::Surface<'static>,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub config: wgpu::SurfaceConfiguration,
    pub egui: egui_wgpu::Renderer,
    /// Whether the surface can be copied from (window screenshots).
    pub can_capture: bool,
}

impl Gfx {
    /// Opens an adapter that can present to `window` (backends from `WGPU_BACKEND`).
    pub fn new(
        window: Arc<Window>,
        display: winit::event_loop::OwnedDisplayHandle,
    ) -> Result<Gfx, ViewError> {
        let mut desc = wgpu::InstanceDescriptor::new_with_display_handle(Box::new(display));
        desc.backends = wgpu::Backends::all().with_env();
        desc.flags = wgpu::InstanceFlags::default().with_env();
        let instance = wgpu::Instance::new(desc);
        let size = window.inner_size();
        let surface = instance
            .create_surface(window)
            .map_err(|e| ViewError::Adapter(format!("creating the window surface: {e}")))?;
        let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: Some(&surface),
            ..Default::default()
        }))
        .map_err(|e| ViewError::Adapter(e.to_string()))?;
        let info = adapter.get_info();
        tracing::info!("window adapter: {} ({:?}, {:?})", info.name, info.backend, info.device_type);
        tw_gpu::Renderer::check_adapter(&adapter).map_err(|e| ViewError::Gpu(e.to_string()))?;
        let limits = tw_gpu::Renderer::device_limits(&adapter);
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("terawalk view"),
            required_features: wgpu::Features::empty(),
            required_limits: limits,
            memory_hints: tw_gpu::Renderer::memory_hints(),
            ..Default::default()
        }))
        .map_err(|e| ViewError::Gpu(format!("creating a device on {}: {e}", info.name)))?;
        let caps = surface.get_capabilities(&adapter);
        let format = egui_wgpu::preferred_framebuffer_format(&caps.formats)
            .map_err(|e| ViewError::Gpu(format!("no usable surface format: {e}")))?;
        let mut config = surface
            .get_default_config(&adapter, size.width.max(1), size.height.max(1))
            .ok_or_else(|| ViewError::Gpu(format!("{} cannot present to this window", info.name)))?;
        config.format = format;
        let can_capture = caps.usages.contains(wgpu::TextureUsages::COPY_SRC);
        config.usage = wgpu::TextureUsages::RENDER_ATTACHMENT;
        if can_capture {
            config.usage |= wgpu::TextureUsages::COPY_SRC;
        }
        config.present_mode = wgpu::PresentMode::AutoVsync;
        config.view_formats = vec![];
        if size.width > 0 && size.height > 0 {
            surface.configure(&device, &config);
        }
        let egui = egui_wgpu::Renderer::new(&device, format, egui_wgpu::RendererOptions::default());
        Ok(Gfx { instance, surface, adapter, device, queue, config, egui, can_capture })
    }

    /// "name (backend, device type)" of the window's adapter.
    pub fn adapter_summary(&self) -> String {
        let i = self.adapter.get_info();
        format!("{} ({:?}, {:?})", i.name, i.backend, i.device_type)
    }

    /// [`tw_gpu::BACKGROUND`] as the clear colour of the surface (where the scene drew
    /// nothing, the window shows the same colour as a screenshot).
    fn background(&self) -> wgpu::Color {
        let [r, g, b] = tw_gpu::BACKGROUND.map(|c| {
            let v = c as f64 / 255.0;
            if self.config.format.is_srgb() {
                if v <= 0.04045 {
                    v / 12.92
                } else {
                    ((v + 0.055) / 1.055).powf(2.4)
                }
            } else {
                v
            }
        });
        wgpu::Color { r, g, b, a: 1.0 }
    }

    /// Reconfigures the surface; a zero size (minimised) is remembered and skipped.
    pub fn resize(&mut self, width: u32, height: u32) {
        if width > 0 && height > 0 {
            self.config.width = width;
            self.config.height = height;
            self.surface.configure(&self.device, &self.config);
        }
    }

    /// Draws egui's output into the next surface texture and presents it. Returns false when
    /// the frame was skipped (minimised, occluded, timeout, outdated surface). With `capture`
    /// (and a surface that allows it) the finished window image is read back into `captured`.
    pub fn present(
        &mut self,
        window: &Window,
        jobs: &[egui::ClippedPrimitive],
        textures: &mut egui::TexturesDelta,
        pixels_per_point: f32,
        captured: Option<&mut Option<tw_gpu::Image>>,
    ) -> Result<bool, ViewError> {
        let r = self.present_inner(window, jobs, textures, pixels_per_point, captured);
        for id in &textures.free {
            self.egui.free_texture(id);
        }
        // egui insists that every delta is marked handled.
        textures.clear();
        r
    }

    fn present_inner(
        &mut self,
        window: &Window,
        jobs: &[egui::ClippedPrimitive],
        textures: &egui::TexturesDelta,
        pixels_per_point: f32,
        captured: Option<&mut Option<tw_gpu::Image>>,
    ) -> Result<bool, ViewError> {
        let size = window.inner_size();
        for (id, deltas) in &textures.set {
            for delta in deltas {
                self.egui.update_texture(&self.device, &self.queue, *id, delta);
            }
        }
        if size.width == 0 || size.height == 0 {
            return Ok(false);
        }
        if size.width != self.config.width || size.height != self.config.height {
            self.resize(size.width, size.height);
        }
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(false),
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Validation => {
                self.surface.configure(&self.device, &self.config);
                return Ok(false);
            }
            wgpu::CurrentSurfaceTexture::Lost => {
                return Err(ViewError::Gpu("the window surface was lost".into()));
            }
        };
        let view = frame.texture.create_view(&wgpu::TextureViewDescriptor::default());
        let screen = egui_wgpu::ScreenDescriptor {
            size_in_pixels: [self.config.width, self.config.height],
            pixels_per_point,
        };
        let mut encoder =
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("egui") });
        let extra = self.egui.update_buffers(&self.device, &self.queue, &mut encoder, jobs, &screen);
        {
            let pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("egui"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(self.background()),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            let mut pass = pass.forget_lifetime();
            self.egui.render(&mut pass, jobs, &screen);
        }
        self.queue.submit(extra.into_iter().chain([encoder.finish()]));
        if let (Some(out), true) = (captured, self.can_capture) {
            *out = Some(crate::readback::read_texture(
                &self.device,
                &self.queue,
                &frame.texture,
                [self.config.width, self.config.height],
            )?);
        }
        window.pre_present_notify();
        self.queue.present(frame);
        Ok(true)
    }
}
