//! Test-only: a small z-buffer rasterizer that renders the generated plant to PNG, to look at
//! the layout and to measure how much of the plant a viewpoint sees.
//!
//! `cargo test -p tw-io --release generate::preview -- --ignored --nocapture` writes
//! `plant-*.png` into `$PREVIEW_DIR` (default: the system temp dir).

use std::io::Write;

use tw_core::Rgba8;

use super::shapes::{cross, dot, normalize, sub, V3};
use super::{interior_viewpoints, plant_bounds, PlantParams, PlantSource};
use crate::{ImportError, MeshChunk, ObjectId, ObjectInfo, Triangle, TriangleSink, TriangleSource};

struct Raster {
    w: usize,
    h: usize,
    eye: V3,
    right: V3,
    up: V3,
    fwd: V3,
    focal: f64,
    depth: Vec<f64>,
    color: Vec<[u8; 3]>,
    id: Vec<u32>,
    colors: Vec<Rgba8>,
    triangles: u64,
}

const NEAR: f64 = 0.05;

impl Raster {
    fn new(w: usize, h: usize, eye: V3, target: V3, fov_deg: f64) -> Raster {
        let fwd = normalize(sub(target, eye));
        let right = normalize(cross(fwd, [0.0, 0.0, 1.0]));
        let up = cross(right, fwd);
        let focal = (w as f64 / 2.0) / (fov_deg.to_radians() / 2.0).tan();
        Raster {
            w,
            h,
            eye,
            right,
            up,
            fwd,
            focal,
            depth: vec![f64::INFINITY; w * h],
            color: vec![[150, 180, 220]; w * h],
            id: vec![u32::MAX; w * h],
            colors: Vec::new(),
            triangles: 0,
        }
    }

    fn cam(&self, p: V3) -> V3 {
        let d = sub(p, self.eye);
        [dot(d, self.right), dot(d, self.up), dot(d, self.fwd)]
    }

    fn draw(&mut self, p: [V3; 3], object: u32) {
        let n = normalize(cross(sub(p[1], p[0]), sub(p[2], p[0])));
        let light = normalize([0.4, 0.3, 0.85]);
        let shade = 0.35 + 0.65 * dot(n, light).abs();
        let c = self.colors.get(object as usize).copied().unwrap_or(Rgba8::GREY).0;
        let rgb = [(c[0] as f64 * shade) as u8, (c[1] as f64 * shade) as u8, (c[2] as f64 * shade) as u8];
        let v = p.map(|q| self.cam(q));
        // Clip against the near plane (Sutherland-Hodgman on one plane).
        let mut poly: Vec<V3> = Vec::with_capacity(4);
        for i in 0..3 {
            let (a, b) = (v[i], v[(i + 1) % 3]);
            let (ia, ib) = (a[2] >= NEAR, b[2] >= NEAR);
            if ia {
                poly.push(a);
            }
            if ia != ib {
                let t = (NEAR - a[2]) / (b[2] - a[2]);
                poly.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), NEAR]);
            }
        }
        for k in 1..poly.len().saturating_sub(1) {
            self.fill([poly[0], poly[k], poly[k + 1]], rgb, object);
        }
    }

    fn fill(&mut self, v: [V3; 3], rgb: [u8; 3], object: u32) {
        let (cx, cy) = (self.w as f64 / 2.0, self.h as f64 / 2.0);
        let s = v.map(|q| [cx + self.focal * q[0] / q[2], cy - self.focal * q[1] / q[2], 1.0 / q[2]]);
        let area = (s[1][0] - s[0][0]) * (s[2][1] - s[0][1]) - (s[2][0] - s[0][0]) * (s[1][1] - s[0][1]);
        if area.abs() < 1e-12 {
            return;
        }
        let minx = s.iter().map(|q| q[0]).fold(f64::INFINITY, f64::min).floor().max(0.0) as usize;
        let maxx = s.iter().map(|q| q[0]).fold(f64::NEG_INFINITY, f64::max).ceil().min(self.w as f64 - 1.0);
        let miny = s.iter().map(|q| q[1]).fold(f64::INFINITY, f64::min).floor().max(0.0) as usize;
        let maxy = s.iter().map(|q| q[1]).fold(f64::NEG_INFINITY, f64::max).ceil().min(self.h as f64 - 1.0);
        if maxx < 0.0 || maxy < 0.0 {
            return;
        }
        for y in miny..=maxy as usize {
            for x in minx..=maxx as usize {
                let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
                let e = |a: [f64; 3], b: [f64; 3]| (b[0] - a[0]) * (py - a[1]) - (b[1] - a[1]) * (px - a[0]);
                let (w0, w1, w2) = (e(s[1], s[2]) / area, e(s[2], s[0]) / area, e(s[0], s[1]) / area);
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let inv_z = w0 * s[0][2] + w1 * s[1][2] + w2 * s[2][2];
                let z = 1.0 / inv_z;
                let i = y * self.w + x;
                if z < self.depth[i] {
                    self.depth[i] = z;
                    self.color[i] = rgb;
                    self.id[i] = object;
                }
            }
        }
    }

    fn write_png(&self, path: &std::path::Path) -> std::io::Result<()> {
        let mut raw = Vec::with_capacity(self.h * (1 + 3 * self.w));
        for y in 0..self.h {
            raw.push(0);
            for x in 0..self.w {
                raw.extend_from_slice(&self.color[y * self.w + x]);
            }
        }
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&raw)?;
        let idat = z.finish()?;
        let mut f = std::fs::File::create(path)?;
        f.write_all(b"\x89PNG\r\n\x1a\n")?;
        let mut ihdr = Vec::new();
        ihdr.extend_from_slice(&(self.w as u32).to_be_bytes());
        ihdr.extend_from_slice(&(self.h as u32).to_be_bytes());
        ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
        for (kind, data) in [(b"IHDR", &ihdr[..]), (b"IDAT", &idat[..]), (b"IEND", &[][..])] {
            f.write_all(&(data.len() as u32).to_be_bytes())?;
            let mut chunk = kind.to_vec();
            chunk.extend_from_slice(data);
            f.write_all(&chunk)?;
            f.write_all(&crc32(&chunk).to_be_bytes())?;
        }
        Ok(())
    }
}

fn crc32(data: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &b in data {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 { 0xedb8_8320 ^ (c >> 1) } else { c >> 1 };
        }
    }
    !c
}

impl TriangleSink for Raster {
    fn object(&mut self, _id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        self.colors.push(info.color.unwrap_or(Rgba8::GREY));
        Ok(())
    }
    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        self.triangles += 1;
        self.draw(t.positions, t.object);
        Ok(())
    }
    fn mesh(&mut self, c: &MeshChunk<'_>) -> Result<(), ImportError> {
        for t in c.indices.chunks_exact(3) {
            let p = |i: u32| c.positions[i as usize];
            self.triangles += 1;
            self.draw([p(t[0]), p(t[1]), p(t[2])], c.object);
        }
        Ok(())
    }
}

fn render(p: PlantParams, eye: V3, target: V3, fov: f64, name: &str) -> (usize, usize) {
    let mut r = Raster::new(800, 600, eye, target, fov);
    Box::new(PlantSource::new(p).unwrap()).stream(&mut r).unwrap();
    let dir =
        std::env::var_os("PREVIEW_DIR").map(std::path::PathBuf::from).unwrap_or_else(std::env::temp_dir);
    let path = dir.join(format!("plant-{name}.png"));
    r.write_png(&path).unwrap();
    let mut seen: Vec<u32> = r.id.iter().copied().filter(|&i| i != u32::MAX).collect();
    seen.sort_unstable();
    seen.dedup();
    println!("{}: {} of {} objects visible", path.display(), seen.len(), r.colors.len());
    (seen.len(), r.colors.len())
}

#[test]
#[ignore]
fn previews() {
    let p = PlantParams { triangles: 2_000_000, seed: 1 };
    let b = plant_bounds(&p);
    let c = b.center();
    render(p, [b.min[0] - 60.0, b.min[1] - 80.0, 120.0], [c[0], c[1], 0.0], 60.0, "aerial");
    let o = [20.0, 20.0, 0.0];
    render(p, [o[0] - 15.0, o[1] - 25.0, 25.0], [o[0] + 40.0, o[1] + 30.0, 5.0], 60.0, "block");
    let lay = super::plant::Layout::new(&super::plant::SitePlan::new(&p), 0);
    let (bx, by) = (lay.shape.bx, lay.shape.by);
    render(p, [bx + 12.6, by + 0.6, 2.2], [bx + 20.0, by + 8.0, 0.3], 75.0, "room");
    for (i, (eye, target)) in interior_viewpoints(&p, 4).into_iter().enumerate() {
        let (seen, total) = render(p, eye, target, 75.0, &format!("inside-{i}"));
        assert!(seen * 10 < total, "inside view {i} sees {seen} of {total} objects");
    }
}
