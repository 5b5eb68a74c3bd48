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
        self.copy_texture_aspect(device, encoder, texture, wgpu::TextureAspect::All, bytes_per_texel);
    }

    /// [`copy_texture`](Self::copy_texture) of one aspect (a depth texture's depth).
    pub(crate) fn copy_texture_aspect(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        texture: &wgpu::Texture,
        aspect: wgpu::TextureAspect,
        bytes_per_texel: u32,
    ) {
        let (width, height) = (texture.width(), texture.height());
        let row = padded_row(width, bytes_per_texel);
        let buffer = self.buffer(device, row as u64 * height as u64);
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo { aspect, ..texture.as_image_copy() },
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
        let mut out = Vec::with_capacity(row_bytes * rows);
        self.finish_with(device, queue, encoder, pitch, rows, |row| {
            out.extend_from_slice(&row[..row_bytes])
        })?;
        Ok(out)
    }

    /// [`finish`](Self::finish) for rows of `row_values` little-endian f32 (depth), converted
    /// in the one pass over the mapped buffer.
    pub(crate) fn finish_f32(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: wgpu::CommandEncoder,
        pitch: usize,
        row_values: usize,
        rows: usize,
    ) -> Result<Vec<f32>, GpuError> {
        let mut out = Vec::with_capacity(row_values * rows);
        self.finish_with(device, queue, encoder, pitch, rows, |row| {
            out.extend(
                row[..row_values * 4].chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
            )
        })?;
        Ok(out)
    }

    /// Submits `encoder`, waits, and hands each of the first `rows` rows (`pitch` bytes, the
    /// last maybe shorter) of the mapped buffer to `row`.
    fn finish_with(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: wgpu::CommandEncoder,
        pitch: usize,
        rows: usize,
        row: impl FnMut(&[u8]),
    ) -> Result<(), GpuError> {
        queue.submit([encoder.finish()]);
        let buffer = self.buffer.as_ref().ok_or_else(|| GpuError::Gpu("nothing to read back".into()))?;
        map_read(device, buffer, pitch, rows, row)
    }
}

/// Waits for the GPU, maps `buffer` and hands each of its first `rows` rows (`pitch` bytes, the
/// last maybe shorter) to `row`, then unmaps it: the end of every read-back, the renderer's and
/// its users' (tw-frame's supersampled reference reads its strips so).
pub fn map_read(
    device: &wgpu::Device,
    buffer: &wgpu::Buffer,
    pitch: usize,
    rows: usize,
    mut row: impl FnMut(&[u8]),
) -> Result<(), GpuError> {
    let (tx, rx) = std::sync::mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| GpuError::Gpu(format!("waiting for the GPU: {e}")))?;
    rx.recv()
        .map_err(|_| GpuError::Gpu("the read-back buffer was never mapped".into()))?
        .map_err(|e| GpuError::Gpu(format!("mapping the read-back buffer: {e}")))?;
    {
        let view = buffer
            .get_mapped_range(..)
            .map_err(|e| GpuError::Gpu(format!("reading the read-back buffer: {e}")))?;
        for r in view.chunks(pitch).take(rows) {
            row(r);
        }
    }
    buffer.unmap();
    Ok(())
}
