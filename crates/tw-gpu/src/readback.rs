//! Reading textures and buffers back to the CPU: one reusable MAP_READ buffer, rows padded to
//! 256 bytes (wgpu's `COPY_BYTES_PER_ROW_ALIGNMENT`), waiting with `PollType::wait_indefinitely`.

use crate::error::GpuError;

/// A growable readback buffer.
#[derive(Default)]
pub(crate) struct Readback {
    buffer: Option<wgpu::Buffer>,
}

/// Row pitch (bytes) of a copy of `width` texels of `bytes_per_texel`.
pub(crate) fn padded_row(width: u32, bytes_per_texel: u32) -> u32 {
    (width * bytes_per_texel).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
        * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT
}

impl Readback {
    /// The buffer, at least `size` bytes.
    pub(crate) fn buffer(&mut self, device: &wgpu::Device, size: u64) -> &wgpu::Buffer {
        if self.buffer.as_ref().is_none_or(|b| b.size() < size) {
            self.buffer = Some(device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("readback"),
                size: size.next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT),
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }));
        }
        self.buffer.as_ref().expect("just created")
    }

    /// Records a copy of `texture` (`width` × `height`, `bytes_per_texel`) into the buffer.
    pub(crate) fn copy_texture(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        texture: &wgpu::Texture,
        bytes_per_texel: u32,
    ) {
        let (width, height) = (texture.width(), texture.height());
        let row = padded_row(width, bytes_per_texel);
        let buffer = self.buffer(device, row as u64 * height as u64);
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row),
                    rows_per_image: Some(height),
                },
            },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        );
    }

    /// Submits `encoder`, waits, and returns `rows` rows of `row_bytes` (dropping the padding
    /// of a pitch of `pitch` bytes).
    pub(crate) fn finish(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: wgpu::CommandEncoder,
        pitch: usize,
        row_bytes: usize,
        rows: usize,
    ) -> Result<Vec<u8>, GpuError> {
        queue.submit([encoder.finish()]);
        let buffer = self.buffer.as_ref().ok_or_else(|| GpuError::Gpu("nothing to read back".into()))?;
        let (tx, rx) = std::sync::mpsc::channel();
        buffer.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Gpu(format!("waiting for the GPU: {e}")))?;
        rx.recv()
            .map_err(|_| GpuError::Gpu("the readback was never mapped".into()))?
            .map_err(|e| GpuError::Gpu(format!("mapping the readback buffer: {e}")))?;
        let mut out = Vec::with_capacity(row_bytes * rows);
        {
            let view = buffer
                .get_mapped_range(..)
                .map_err(|e| GpuError::Gpu(format!("reading the readback buffer: {e}")))?;
            for r in view.chunks(pitch).take(rows) {
                out.extend_from_slice(&r[..row_bytes]);
            }
        }
        buffer.unmap();
        Ok(out)
    }
}
