//! Tracing whole images: the [`Trace`] trait and a tiled, parallel primary-ray loop.

use rayon::prelude::*;

use crate::camera::{Camera, PixelRays};
use crate::ray::{Hit, Ray};
use crate::simd::Simd;

/// Anything rays can be traced against: a [`crate::TriangleBvh`], or a two-level scene.
pub trait Trace: Sync {
    /// The nearest hit along `ray` in `[t_min, t_max)`.
    fn intersect(&self, ray: &Ray) -> Option<Hit>;

    /// Nearest hits of many rays, index by index; consecutive rays are coherent (pixels of a
    /// tile). The default traces them one by one.
    fn intersect_packet(&self, rays: &[Ray], hits: &mut [Option<Hit>]) {
        for (r, h) in rays.iter().zip(hits.iter_mut()) {
            *h = self.intersect(r);
        }
    }
}

/// How [`trace_image_with`] hands rays to the target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TraceMode {
    /// [`Trace::intersect`] per ray.
    Single,
    /// [`Trace::intersect_packet`] per tile, rays ordered in 4x2 pixel blocks.
    Packet,
}

/// Square tiles of this many pixels a side; a tile is one rayon task's unit of work.
const TILE: u32 = 8;
/// A packet's pixel block: 4 wide, 2 high (8 rays).
const BLOCK_W: u32 = 4;
const BLOCK_H: u32 = 2;

/// One primary ray per pixel centre of a `width x height` image, traced in packets on the current
/// rayon pool. Returns the id of the primitive hit per pixel (`u32::MAX` for a miss) and the hit
/// distance along the unit-length ray (`f32::INFINITY` for a miss), both row-major from the top.
pub fn trace_image(target: &impl Trace, camera: &Camera, width: u32, height: u32) -> (Vec<u32>, Vec<f32>) {
    trace_image_with(target, camera, width, height, TraceMode::Packet)
}

/// [`trace_image`] with a chosen [`TraceMode`].
pub fn trace_image_with(
    target: &impl Trace,
    camera: &Camera,
    width: u32,
    height: u32,
    mode: TraceMode,
) -> (Vec<u32>, Vec<f32>) {
    let (w, h) = (width as usize, height as usize);
    let mut ids = vec![u32::MAX; w * h];
    let mut depth = vec![f32::INFINITY; w * h];
    if w == 0 || h == 0 {
        return (ids, depth);
    }
    let strip = w * TILE as usize;
    let gen = PixelRays::new(camera, width, height);
    let simd = Simd::detect();
    ids.par_chunks_mut(strip).zip(depth.par_chunks_mut(strip)).enumerate().for_each(|(row, (ids, depth))| {
        let y0 = row as u32 * TILE;
        let mut rays = Vec::with_capacity((TILE * TILE) as usize);
        let mut pixels = Vec::with_capacity((TILE * TILE) as usize);
        let mut hits = vec![None; (TILE * TILE) as usize];
        for x0 in (0..width).step_by(TILE as usize) {
            tile_rays(simd, &gen, x0, y0, width, height, &mut rays, &mut pixels);
            let hits = &mut hits[..rays.len()];
            match mode {
                TraceMode::Single => {
                    for (r, hit) in rays.iter().zip(hits.iter_mut()) {
                        *hit = target.intersect(r);
                    }
                }
                TraceMode::Packet => target.intersect_packet(&rays, hits),
            }
            for (&(x, y), hit) in pixels.iter().zip(hits.iter()) {
                let i = (y - y0) as usize * w + x as usize;
                if let Some(hit) = hit {
                    ids[i] = hit.prim;
                    depth[i] = hit.t;
                }
            }
        }
    });
    (ids, depth)
}

/// The rays of the tile at `(x0, y0)`, ordered block by block (4x2 pixels, row by row: one
/// packet), with the pixel of each; pixels outside the image are left out. On AVX2 a block's
/// rays come from [`PixelRays::block_avx2`].
#[allow(clippy::too_many_arguments)]
fn tile_rays(
    simd: Simd,
    gen: &PixelRays,
    x0: u32,
    y0: u32,
    width: u32,
    height: u32,
    rays: &mut Vec<Ray>,
    pixels: &mut Vec<(u32, u32)>,
) {
    #[cfg(target_arch = "x86_64")]
    if simd == Simd::Avx2 {
        // SAFETY: `Simd::detect` found AVX2 and FMA on this CPU.
        return unsafe { tile_rays_avx2(gen, x0, y0, width, height, rays, pixels) };
    }
    let _ = simd;
    tile_rays_impl(gen, x0, y0, width, height, rays, pixels, |x, y| gen.block(x, y))
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn tile_rays_avx2(
    gen: &PixelRays,
    x0: u32,
    y0: u32,
    width: u32,
    height: u32,
    rays: &mut Vec<Ray>,
    pixels: &mut Vec<(u32, u32)>,
) {
    tile_rays_impl(gen, x0, y0, width, height, rays, pixels, |x, y| gen.block_avx2(x, y))
}

#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn tile_rays_impl(
    gen: &PixelRays,
    x0: u32,
    y0: u32,
    width: u32,
    height: u32,
    rays: &mut Vec<Ray>,
    pixels: &mut Vec<(u32, u32)>,
    block: impl Fn(u32, u32) -> [Ray; 8],
) {
    rays.clear();
    pixels.clear();
    for by in (y0..y0 + TILE).step_by(BLOCK_H as usize) {
        for bx in (x0..x0 + TILE).step_by(BLOCK_W as usize) {
            if bx + BLOCK_W <= width && by + BLOCK_H <= height {
                rays.extend_from_slice(&block(bx, by));
                pixels.extend((0..BLOCK_W * BLOCK_H).map(|k| (bx + k % BLOCK_W, by + k / BLOCK_W)));
                continue;
            }
            for y in by..(by + BLOCK_H).min(height) {
                for x in bx..(bx + BLOCK_W).min(width) {
                    rays.push(gen.ray(x, y));
                    pixels.push((x, y));
                }
            }
        }
    }
}
