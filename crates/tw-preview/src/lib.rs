//! terawalk preview images: a streaming CPU software rasterizer.
//!
//! [`Preview`] is a [`TriangleSink`]: each triangle is drawn into a z-buffer and a colour buffer
//! the moment it arrives, so memory is the image (8 bytes a pixel, plus a memo of at most
//! 65,536 large triangles that skips exact repeats) whatever the size of the scene, and a
//! preview of a billion-triangle file costs one streaming pass. Meant for
//! thumbnails, documentation images and checking an import, not for walking (that is the GPU
//! renderer's job).
//!
//! Per triangle (the stages are listed in `src/raster.rs`): transform to camera space in f64, reject it if
//! it lies outside the view frustum, clip it against the near plane when it crosses it, project,
//! and scan-convert with edge functions and the top-left fill rule; depth is 1/z, interpolated
//! perspective-correctly. Orthographic cameras ([`Camera::ortho_height`]) project in parallel
//! along the view, with a box for a frustum. Both sides are drawn (models are not consistently wound) and flat
//! shaded by a headlight plus a fixed sun from above; colours come from the object (or per-vertex
//! colours), or from a hash of the object id with [`ColorMode::HashObject`]. Pixels no triangle
//! covers show a sky gradient by the elevation of their view ray.
//!
//! ```
//! use tw_io::{ObjectInfo, Triangle, TriangleSink};
//! use tw_preview::{Camera, Preview};
//! let bounds = tw_core::Aabb::from_points(&[[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]]);
//! let mut preview = Preview::new(64, 48, Camera::look_at_bounds(&bounds, [0.3, -1.0, 0.8])).unwrap();
//! preview.object(0, &ObjectInfo::default()).unwrap();
//! preview.triangle(&Triangle::new([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], 0)).unwrap();
//! assert!(preview.stats().pixels > 0);
//! assert_eq!(preview.image().len(), 64 * 48 * 4);
//! // preview.write_png("preview.png".as_ref()).unwrap();
//! ```

pub mod camera;
mod raster;

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::DVec3;
use tw_core::Rgba8;
use tw_io::write::AtomicFile;
use tw_io::{ImportError, MeshChunk, ObjectId, ObjectInfo, Triangle, TriangleSink};

use camera::least_aligned_axis;
pub use camera::{Basis, Camera};
use raster::{Class, Projector};

/// The largest image side [`Preview::new`] accepts.
pub const MAX_SIDE: u32 = 16384;

/// Triangles whose projected bounding box covers at least this many pixels are remembered in
/// the repeat memo ([`Preview`]'s `drawn`); smaller ones cost less to draw than to look up.
const MEMO_MIN_AREA: f64 = 1024.0;
/// The repeat memo holds at most this many triangles (about 6 MB); when full it starts over.
const MEMO_CAP: usize = 1 << 16;

/// Errors of this crate.
#[derive(Debug, thiserror::Error)]
pub enum PreviewError {
    #[error("image size {width}×{height} is invalid: each side must be 1 to {MAX_SIDE} pixels")]
    Size { width: u32, height: u32 },
    /// Creating, writing or renaming the output file failed.
    #[error(transparent)]
    Write(#[from] ImportError),
    #[error("{}: PNG encoding failed: {source}", path.display())]
    Png {
        path: PathBuf,
        #[source]
        source: png::EncodingError,
    },
}

/// Where a triangle's colour comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ColorMode {
    /// The average of the triangle's vertex colours if it has them, else its object's colour,
    /// else grey.
    #[default]
    Object,
    /// A colour made from a hash of the object id: tells objects apart.
    HashObject,
}

/// Counts of what the preview has drawn.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PreviewStats {
    /// Triangles received.
    pub triangles: u64,
    /// Rejected without drawing: outside the view, behind the near plane, or not finite.
    pub culled: u64,
    /// Triangles that had to be clipped (near plane or guard band).
    pub clipped: u64,
    /// Pixels covered, before the depth test (a pixel counts once per triangle covering it).
    pub fragments: u64,
    /// Pixel writes that passed the depth test (a pixel may count more than once).
    pub pixels: u64,
}

/// A streaming rasterizer into an RGBA image; see the crate documentation.
pub struct Preview {
    camera: Camera,
    basis: Basis,
    proj: Projector,
    /// Fixed sun direction in camera space (unit, towards the light).
    sun: DVec3,
    mode: ColorMode,
    /// RGBA, row-major from the top row.
    color: Vec<[u8; 4]>,
    /// 1/z per pixel (z along the view axis), 0 where nothing is drawn: larger is nearer.
    depth: Vec<f32>,
    colors: HashMap<ObjectId, Rgba8>,
    last_color: Option<(ObjectId, Rgba8)>,
    stats: PreviewStats,
    /// Camera-space positions of the current mesh chunk.
    scratch: Vec<[f64; 3]>,
    /// The repeat memo: large triangles drawn so far (their camera-space vertices, bit for bit,
    /// in order) and the fragments each covered. A triangle drawn again exactly changes no pixel
    /// (see [`Preview::draw`]), so a repeat only adds its fragments to the statistics. Without
    /// it, a model with many copies of one large triangle (duplicated parts of CAD exports) cost
    /// a full scan conversion per copy: 100,000 copies of a triangle covering a third of the
    /// image took over 40 s.
    drawn: HashMap<[u64; 9], u64>,
}

impl Preview {
    /// An image of `width` × `height` pixels (each 1..=[`MAX_SIDE`]) seen by `camera`, filled
    /// with the sky gradient. The near plane is at 1/10000 of the eye–target distance (see
    /// [`Preview::with_near`]).
    pub fn new(width: u32, height: u32, camera: Camera) -> Result<Preview, PreviewError> {
        if width == 0 || height == 0 || width > MAX_SIDE || height > MAX_SIDE {
            return Err(PreviewError::Size { width, height });
        }
        let basis = camera.basis();
        let d = camera.target_distance();
        let near = if d > 0.0 { d * 1e-4 } else { 1e-4 };
        let proj = match camera.orthographic_height() {
            Some(view_height) => Projector::orthographic(width, height, view_height, near),
            None => Projector::new(width, height, camera.fovy(), near),
        };
        // The sun: from above (the camera's up, which is the scene's up), tilted towards a
        // horizontal direction fixed in the scene.
        let world_up = DVec3::from(camera.up).try_normalize().unwrap_or(basis.up);
        let axis = least_aligned_axis(world_up);
        let h1 = (axis - world_up * axis.dot(world_up)).try_normalize().unwrap_or(basis.right);
        let h2 = world_up.cross(h1);
        let sun_world = (world_up * 0.8 + h1 * 0.45 + h2 * 0.3).try_normalize().unwrap_or(world_up);
        let sun = basis.to_camera(sun_world);
        let n = width as usize * height as usize;
        let mut p = Preview {
            camera,
            basis,
            proj,
            sun,
            mode: ColorMode::Object,
            color: vec![[0; 4]; n],
            depth: vec![0.0; n],
            colors: HashMap::new(),
            last_color: None,
            stats: PreviewStats::default(),
            scratch: Vec::new(),
            drawn: HashMap::new(),
        };
        p.fill_sky(world_up);
        Ok(p)
    }

    /// Sets the near plane distance (scene units, > 0). Geometry nearer than this is cut away.
    pub fn with_near(mut self, near: f64) -> Preview {
        if near > 0.0 && near.is_finite() {
            self.proj.near = near;
        }
        self
    }

    pub fn with_color_mode(mut self, mode: ColorMode) -> Preview {
        self.mode = mode;
        self
    }

    pub fn camera(&self) -> &Camera {
        &self.camera
    }

    pub fn width(&self) -> u32 {
        self.proj.width
    }

    pub fn height(&self) -> u32 {
        self.proj.height
    }

    /// The image: RGBA, 8 bits a channel, row-major from the top row, `width × height × 4` bytes.
    pub fn image(&self) -> &[u8] {
        self.color.as_flattened()
    }

    /// The depth buffer: 1/z per pixel, z the distance along the view axis; 0 where the sky
    /// shows. Row-major from the top row.
    pub fn depth(&self) -> &[f32] {
        &self.depth
    }

    pub fn stats(&self) -> PreviewStats {
        self.stats
    }

    /// Where a scene point lands in the image (pixel coordinates, y down), or `None` when it is
    /// behind the near plane. The result may lie outside the image.
    pub fn project(&self, p: [f64; 3]) -> Option<[f64; 2]> {
        let c = self.to_camera(p);
        (c[2] >= self.proj.near).then(|| {
            let s = self.proj.project(c);
            [s.x, s.y]
        })
    }

    /// Writes the image as an 8-bit RGBA PNG, atomically (temporary file, fsync, rename).
    pub fn write_png(&self, path: &Path) -> Result<(), PreviewError> {
        let png_err = |source| PreviewError::Png { path: path.to_path_buf(), source };
        let mut file = AtomicFile::create(path)?;
        {
            let mut enc = png::Encoder::new(&mut file, self.proj.width, self.proj.height);
            enc.set_color(png::ColorType::Rgba);
            enc.set_depth(png::BitDepth::Eight);
            let mut w = enc.write_header().map_err(png_err)?;
            w.write_image_data(self.image()).map_err(png_err)?;
            w.finish().map_err(png_err)?;
        }
        file.commit()?;
        Ok(())
    }

    #[inline]
    fn to_camera(&self, p: [f64; 3]) -> [f64; 3] {
        self.basis.to_camera(DVec3::from(p) - DVec3::from(self.camera.eye)).to_array()
    }

    /// Sky above the horizon, ground below, by the elevation of each pixel's view ray.
    fn fill_sky(&mut self, world_up: DVec3) {
        let (w, h) = (self.proj.width as usize, self.proj.height as usize);
        // Elevation of a camera-space direction: its dot product with up, in camera space.
        let up = self.basis.to_camera(world_up);
        let lerp = |a: [f64; 3], c: [f64; 3], t: f64| [0, 1, 2].map(|i| a[i] + (c[i] - a[i]) * t);
        const ZENITH: [f64; 3] = [0.33, 0.52, 0.80];
        const HORIZON: [f64; 3] = [0.86, 0.90, 0.95];
        // Below the horizon a blue-grey haze rather than a ground colour: previews mostly look
        // down on a model, and grey models must stand out from it.
        const GROUND_NEAR: [f64; 3] = [0.78, 0.81, 0.86];
        const NADIR: [f64; 3] = [0.42, 0.46, 0.54];
        for j in 0..h {
            // Orthographic: every view ray is parallel to the view axis (one sky colour).
            let ortho = if self.proj.orthographic { 0.0 } else { 1.0 };
            let y = -((j as f64 + 0.5) - 0.5 * h as f64) / self.proj.focal * ortho;
            for i in 0..w {
                let x = ((i as f64 + 0.5) - 0.5 * w as f64) / self.proj.focal * ortho;
                let len = (x * x + y * y + 1.0).sqrt();
                let e = (x * up.x + y * up.y + up.z) / len;
                let c = if e >= 0.0 {
                    lerp(HORIZON, ZENITH, e.sqrt())
                } else {
                    lerp(GROUND_NEAR, NADIR, (-e).sqrt())
                };
                self.color[j * w + i] = [to_u8(c[0]), to_u8(c[1]), to_u8(c[2]), 255];
            }
        }
    }

    fn base_color(&mut self, t: &Triangle) -> [f64; 3] {
        if self.mode == ColorMode::HashObject {
            return hash_color(t.object);
        }
        if let Some(c) = t.colors {
            let avg = |k: usize| (c[0].0[k] as f64 + c[1].0[k] as f64 + c[2].0[k] as f64) / (3.0 * 255.0);
            return [avg(0), avg(1), avg(2)];
        }
        let c = match self.last_color {
            Some((id, c)) if id == t.object => c,
            _ => {
                let c = self.colors.get(&t.object).copied().unwrap_or(Rgba8::GREY);
                self.last_color = Some((t.object, c));
                c
            }
        };
        [c.0[0] as f64 / 255.0, c.0[1] as f64 / 255.0, c.0[2] as f64 / 255.0]
    }

    /// Draws a triangle given in camera space.
    ///
    /// Depths only grow (a pixel is written when the new 1/z is strictly larger) and scan
    /// conversion is a deterministic function of the camera-space vertices, so a triangle equal
    /// to one drawn before, vertex for vertex, finds every pixel it covers at its own depth or
    /// nearer and writes none: such repeats of large triangles are skipped through the memo.
    #[inline]
    fn draw(&mut self, c: [[f64; 3]; 3], t: &Triangle) {
        self.stats.triangles += 1;
        let class = self.proj.classify(&c);
        if class == Class::Outside || !c.iter().flatten().all(|v| v.is_finite()) {
            self.stats.culled += 1;
            return;
        }
        let projected = (class == Class::Inside)
            .then(|| [self.proj.project(c[0]), self.proj.project(c[1]), self.proj.project(c[2])]);
        // Clipped triangles reach past the image: treat them as large.
        let key = projected.is_none_or(|s| bounding_area(&s) >= MEMO_MIN_AREA).then(|| memo_key(&c));
        if let Some(fragments) = key.as_ref().and_then(|k| self.drawn.get(k)) {
            self.stats.fragments += fragments;
            if class == Class::Clip {
                self.stats.clipped += 1;
            }
            return;
        }
        let base = self.base_color(t);
        let sun = self.sun;
        let (w, h, ortho) = (self.proj.width, self.proj.height, self.proj.orthographic);
        let depth = &mut self.depth;
        let image = &mut self.color;
        let (mut pixels, mut fragments) = (0u64, 0u64);
        // Shaded on the first pixel drawn: most small triangles of a big scene cover none.
        let mut color = None;
        let mut plot = |i: usize, z: f32| {
            fragments += 1;
            if z > depth[i] {
                depth[i] = z;
                image[i] = *color.get_or_insert_with(|| shade(&c, base, sun, ortho));
                pixels += 1;
            }
        };
        if let Some(s) = projected {
            raster::rasterize(s, w, h, ortho, &mut plot);
        } else {
            self.stats.clipped += 1;
            let poly = raster::clip(&self.proj, &c);
            if poly.len >= 3 {
                let s0 = self.proj.project(poly.v[0]);
                for k in 1..poly.len - 1 {
                    let tri = [s0, self.proj.project(poly.v[k]), self.proj.project(poly.v[k + 1])];
                    raster::rasterize(tri, w, h, ortho, &mut plot);
                }
            }
        }
        self.stats.pixels += pixels;
        self.stats.fragments += fragments;
        if let Some(k) = key {
            if self.drawn.len() >= MEMO_CAP {
                self.drawn.clear();
            }
            self.drawn.insert(k, fragments);
        }
    }
}

/// Area in pixels of the bounding box of a projected triangle.
fn bounding_area(s: &[raster::ScreenVertex; 3]) -> f64 {
    let (x0, x1) = (s[0].x.min(s[1].x).min(s[2].x), s[0].x.max(s[1].x).max(s[2].x));
    let (y0, y1) = (s[0].y.min(s[1].y).min(s[2].y), s[0].y.max(s[1].y).max(s[2].y));
    (x1 - x0) * (y1 - y0)
}

/// The repeat memo's key of a camera-space triangle: its coordinates, bit for bit, in order.
fn memo_key(c: &[[f64; 3]; 3]) -> [u64; 9] {
    let mut k = [0u64; 9];
    for (slot, v) in k.iter_mut().zip(c.iter().flatten()) {
        *slot = v.to_bits();
    }
    k
}

/// Flat shading of a camera-space triangle: ambient + headlight + sun (`sun`: unit, camera
/// space), both sides lit alike.
fn shade(c: &[[f64; 3]; 3], base: [f64; 3], sun: DVec3, orthographic: bool) -> [u8; 4] {
    let c = c.map(DVec3::from);
    let n = (c[1] - c[0]).cross(c[2] - c[0]);
    // The view ray to the triangle: from the eye, or along the view axis in orthographic.
    let ray = if orthographic { DVec3::Z } else { (c[0] + c[1] + c[2]) / 3.0 };
    let light = match n.try_normalize() {
        Some(mut n) => {
            // Face the eye: the side we see is the side we light.
            if n.dot(ray) > 0.0 {
                n = -n;
            }
            // The headlight shines along the view axis (not towards each triangle), so that
            // coplanar triangles get the same shade.
            let head = n.z.abs();
            let sun = n.dot(sun).max(0.0);
            0.18 + 0.55 * head + 0.35 * sun
        }
        None => 0.6,
    };
    [to_u8(base[0] * light), to_u8(base[1] * light), to_u8(base[2] * light), 255]
}

impl TriangleSink for Preview {
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        if let Some(c) = info.color {
            self.colors.insert(id, c);
        } else {
            self.colors.remove(&id);
        }
        if self.last_color.is_some_and(|(last, _)| last == id) {
            self.last_color = None;
        }
        Ok(())
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        let c = t.positions.map(|p| self.to_camera(p));
        self.draw(c, t);
        Ok(())
    }

    fn mesh(&mut self, chunk: &MeshChunk<'_>) -> Result<(), ImportError> {
        let n = chunk.positions.len();
        if let Some(&bad) = chunk.indices.iter().find(|&&i| i as usize >= n) {
            return Err(ImportError::Sink(format!(
                "preview: mesh chunk index {bad} out of range ({n} positions)"
            )));
        }
        let mut cam = std::mem::take(&mut self.scratch);
        cam.clear();
        cam.extend(chunk.positions.iter().map(|p| self.to_camera(*p)));
        // Shading reads only the object (and vertex colours, which chunks do not have).
        let t = Triangle::new([[0.0; 3]; 3], chunk.object);
        for idx in chunk.indices.chunks_exact(3) {
            let c = [cam[idx[0] as usize], cam[idx[1] as usize], cam[idx[2] as usize]];
            self.draw(c, &t);
        }
        self.scratch = cam;
        Ok(())
    }
}

fn to_u8(v: f64) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// A distinct, fairly saturated colour for an object id (a fixed hash, the same on every run and
/// in every renderer: `tw_core::color::hash_color_f64`).
pub fn hash_color(id: ObjectId) -> [f64; 3] {
    tw_core::color::hash_color_f64(id)
}

#[cfg(test)]
mod tests;
