//! The renderer's targets: its own colour and depth targets and their readback, the depth
//! targets for caller views of other sizes, the item buffer's target, and the multisampled
//! targets of [`crate::msaa`] with their colour and depth resolves.

use std::time::Instant;

use super::{Attachments, Pass, Renderer};
use crate::draw::{DEPTH_FORMAT, ITEM_FORMAT};
use crate::{depth, msaa, readback, DepthImage, GpuError, Image, COLOR_FORMAT, SUPPORTED_SAMPLES};

impl Renderer {
    /// Sets the samples per pixel of the shaded passes: 1, or 4 for 4× multisampling
    /// ([`msaa`]; its targets take 8 bytes × samples a pixel more GPU memory). The item buffer
    /// stays single-sample. Call between frames. Not on GL: wgpu's GL backend on llvmpipe
    /// resolved multisampled frames to nothing or to one sample (tests/frame.rs `msaa_gl`).
    pub fn set_samples(&mut self, samples: u32) -> Result<(), GpuError> {
        if !SUPPORTED_SAMPLES.contains(&samples) {
            return Err(GpuError::Gpu(format!(
                "{samples} samples per pixel are not supported (use one of {SUPPORTED_SAMPLES:?})"
            )));
        }
        if samples > 1 && !self.multisampling_supported() {
            return Err(GpuError::Gpu(format!(
                "multisampling is not supported on the {:?} backend (use Vulkan: WGPU_BACKEND=vulkan)",
                self.info.backend
            )));
        }
        if samples != self.samples {
            self.samples = samples;
            self.msaa_own = None;
            self.msaa_view = None;
            self.depth_resolve = None;
            self.box_queries = None;
            self.depth_stale = false;
            self.color_stale = false;
        }
        Ok(())
    }

    /// Whether [`Renderer::set_samples`] accepts more than one sample (every backend but GL).
    pub fn multisampling_supported(&self) -> bool {
        self.info.backend != wgpu::Backend::Gl
    }

    /// The samples per pixel `--samples auto` picks: 4 on a real GPU that can multisample (the
    /// fidelity goal's setting; it cost 17–26 % of the frame on an NVIDIA H200 against 2–3× on
    /// lavapipe, docs/benchmarks-log.md "On a real GPU"), 1 on CPU drivers and on GL.
    pub fn default_samples(&self) -> u32 {
        if self.multisampling_supported() && self.info.device_type != wgpu::DeviceType::Cpu {
            4
        } else {
            1
        }
    }

    /// Samples per pixel of the shaded passes ([`Renderer::set_samples`]).
    pub fn samples(&self) -> u32 {
        self.samples
    }

    /// Where those samples lie in a pixel (x, y from its top-left corner): what the CPU
    /// occlusion tests take ([`tw_runtime::hzb::Hzb::with_samples`]) to stay conservative.
    pub fn sample_positions(&self) -> &'static [[f32; 2]] {
        tw_runtime::hzb::sample_positions(self.samples).expect("set_samples accepts only these")
    }

    /// The own colour target (`Rgba8Unorm` holding sRGB-encoded bytes, usage
    /// `RENDER_ATTACHMENT | COPY_SRC`): a viewer copies it into the (`Rgba8UnormSrgb`) texture
    /// it shows after drawing to [`Target::Own`](crate::Target::Own) (no readback, no wait). With multisampling the
    /// frame's colour is resolved into it first (submitted, not waited for).
    pub fn color_texture(&mut self) -> &wgpu::Texture {
        self.resolve_color();
        &self.color
    }

    /// Reads the own colour target back (after [`draw`](Self::draw) to [`Target::Own`](crate::Target::Own));
    /// waits for the GPU.
    pub fn read_color(&mut self) -> Result<Image, GpuError> {
        if !self.last_own {
            return Err(GpuError::NotOwnTarget { what: "read_color" });
        }
        self.resolve_color();
        let color = self.color.clone();
        let rgba = self.read_texture(&color, 4)?;
        Ok(Image { width: self.width, height: self.height, rgba })
    }

    /// Copies an own-size `texture` of `bytes_per_pixel` to the CPU (rows from the top, no
    /// padding); waits for the GPU. The time counts as rendering.
    pub(super) fn read_texture(
        &mut self,
        texture: &wgpu::Texture,
        bytes_per_pixel: u32,
    ) -> Result<Vec<u8>, GpuError> {
        let start = Instant::now();
        let mut encoder = self.device.create_command_encoder(&Default::default());
        self.readback.copy_texture(&self.device, &mut encoder, texture, bytes_per_pixel);
        let pitch = readback::padded_row(self.width, bytes_per_pixel) as usize;
        let bytes = self.readback.finish(
            &self.device,
            &self.queue,
            encoder,
            pitch,
            self.width as usize * bytes_per_pixel as usize,
            self.height as usize,
        )?;
        self.stats.render += start.elapsed();
        Ok(bytes)
    }

    /// Reads the own depth target back as reverse-Z f32 (see [`depth`]); waits for the GPU.
    pub fn read_depth(&mut self) -> Result<DepthImage, GpuError> {
        if !self.last_own {
            return Err(GpuError::NotOwnTarget { what: "read_depth" });
        }
        let start = Instant::now();
        self.resolve_depth();
        let d = if self.info.backend == wgpu::Backend::Gl {
            let copy = self.depth_copy.get_or_insert_with(|| depth::DepthCopy::new(&self.device));
            copy.read(&self.device, &self.queue, &mut self.readback, &self.depth)?
        } else {
            depth::read_direct(&self.device, &self.queue, &mut self.readback, &self.depth)?
        };
        self.stats.render += start.elapsed();
        Ok(d)
    }

    /// The multisampled target of `size` and `format`: the own one (`own`) or the one for
    /// callers' views, made again when its size or format differs.
    fn msaa_target(&mut self, own: bool, size: (u32, u32), format: wgpu::TextureFormat) -> &msaa::MsaaTarget {
        let (device, samples) = (&self.device, self.samples);
        let slot = if own { &mut self.msaa_own } else { &mut self.msaa_view };
        if slot.as_ref().is_none_or(|t| t.size != size || t.format != format) {
            *slot = Some(msaa::MsaaTarget::new(device, size, format, samples));
        }
        slot.as_ref().expect("made above")
    }

    /// The attachments of `pass` into a target of `size` whose single-sample depth is
    /// `depth_view`: with multisampling, a shaded pass draws into the multisampled targets of
    /// that size and format (made on first use) and resolves into the pass's view.
    pub(crate) fn attachments(
        &mut self,
        pass: &Pass<'_>,
        size: (u32, u32),
        depth_view: wgpu::TextureView,
    ) -> Attachments {
        match *pass {
            Pass::ShadowMap { .. } => {
                Attachments { color: None, resolve: None, depth: depth_view, samples: 1 }
            }
            Pass::Items => Attachments {
                color: Some(self.items.as_ref().expect("made before").1.clone()),
                resolve: None,
                depth: depth_view,
                samples: 1,
            },
            Pass::EyeDepth if self.samples == 1 => {
                Attachments { color: None, resolve: None, depth: depth_view, samples: 1 }
            }
            Pass::EyeDepth => {
                // The own multisampled depth, which read_depth resolves and queries test.
                let own = (self.width, self.height);
                let t = self.msaa_target(true, own, COLOR_FORMAT);
                Attachments { color: None, resolve: None, depth: t.depth.clone(), samples: self.samples }
            }
            Pass::Shade { view, .. } if self.samples == 1 => {
                Attachments { color: Some(view.clone()), resolve: None, depth: depth_view, samples: 1 }
            }
            Pass::Shade { view, format, own } => {
                let own_size = size == (self.width, self.height) && format == COLOR_FORMAT;
                if own_size && !own {
                    // The caller's view reuses the own multisampled target: keep its frame.
                    self.resolve_color();
                }
                let t = self.msaa_target(own_size, size, format);
                let (color, depth) = (t.color.clone(), t.depth.clone());
                let att = Attachments {
                    color: Some(color),
                    resolve: (!own).then(|| view.clone()),
                    depth,
                    samples: self.samples,
                };
                self.color_stale |= own;
                att
            }
        }
    }

    /// Brings the own single-sample depth up to date with the multisampled one (the farthest
    /// sample of each pixel, [`msaa`]) when a shaded pass drew since; submits without waiting.
    pub(crate) fn resolve_depth(&mut self) {
        if !self.depth_stale {
            return;
        }
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("depth resolve") });
        self.encode_depth_resolve(&mut encoder);
        self.queue.submit([encoder.finish()]);
    }

    /// Resolves the own multisampled colour into the own colour target when a pass drew into
    /// it since the last resolve (see `color_stale`); submits without waiting.
    pub(super) fn resolve_color(&mut self) {
        if !self.color_stale {
            return;
        }
        self.color_stale = false;
        let Some(target) = self.msaa_own.as_ref() else { return };
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("colour resolve") });
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("colour resolve"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &target.color,
                depth_slice: None,
                resolve_target: Some(&self.color_view),
                ops: wgpu::Operations { load: wgpu::LoadOp::Load, store: wgpu::StoreOp::Store },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        self.queue.submit([encoder.finish()]);
    }

    /// Records [`resolve_depth`](Self::resolve_depth)'s pass into `encoder` (when needed).
    pub(crate) fn encode_depth_resolve(&mut self, encoder: &mut wgpu::CommandEncoder) {
        let Some(target) = self.msaa_own.as_ref().filter(|_| self.depth_stale) else { return };
        if self.depth_resolve.as_ref().is_none_or(|r| r.samples() != self.samples) {
            self.depth_resolve = Some(msaa::DepthResolve::new(&self.device, self.samples));
        }
        let resolve = self.depth_resolve.as_ref().expect("made above");
        resolve.encode(&self.device, encoder, &target.depth_only, &self.depth_view);
        self.depth_stale = false;
    }

    /// The depth view for a target of `size`.
    pub(super) fn depth_view_for(&mut self, size: (u32, u32)) -> wgpu::TextureView {
        if size == (self.width, self.height) {
            return self.depth_view.clone();
        }
        match &self.extra_depth {
            Some((s, v)) if *s == size => v.clone(),
            _ => {
                let v = depth_texture(&self.device, size.0, size.1).create_view(&Default::default());
                self.extra_depth = Some((size, v.clone()));
                v
            }
        }
    }
    /// Makes the item buffer's target (own size, single-sample) on first use.
    pub(super) fn make_item_target(&mut self) {
        if self.items.is_some() {
            return;
        }
        let t = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("item buffer"),
            size: wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: ITEM_FORMAT,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let v = t.create_view(&Default::default());
        self.items = Some((t, v));
    }
}

/// A single-sample reverse-Z depth target of `width` × `height`.
pub(super) fn depth_texture(device: &wgpu::Device, width: u32, height: u32) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("depth target"),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: DEPTH_FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}
