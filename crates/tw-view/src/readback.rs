//! Reading a texture back to the CPU as a [`tw_gpu::Image`] (screenshots of the scene texture
//! and of the whole window).

use tw_gpu::Image;

use crate::error::ViewError;

/// Copies a 4-byte RGBA or BGRA texture into an [`Image`] (RGBA; waits for the GPU).
pub fn read_texture(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
    size: [u32; 2],
) -> Result<Image, ViewError> {
    let [w, h] = size;
    let padded = (w * 4).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("screenshot"),
        size: padded as u64 * h as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder =
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("screenshot") });
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(h),
            },
        },
        wgpu::Extent3d { width: w, height: h, depth_or_array_layers: 1 },
    );
    queue.submit([encoder.finish()]);
    let row = w as usize * 4;
    let mut rgba = Vec::with_capacity(row * h as usize);
    tw_gpu::map_read(device, &buffer, padded as usize, h as usize, |r| rgba.extend_from_slice(&r[..row]))
        .map_err(|e| ViewError::Gpu(format!("reading the screenshot: {e}")))?;
    if matches!(texture.format(), wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb) {
        for p in rgba.chunks_exact_mut(4) {
            p.swap(0, 2);
        }
    }
    Ok(Image { width: w, height: h, rgba })
}
