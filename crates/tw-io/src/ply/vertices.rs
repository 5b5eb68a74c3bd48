//! Vertex records as the body reads them ([`VertexValues`]) and the stores that keep them for the
//! faces ([`Vertices`]), under the memory budget of the import.

use std::io;

use tw_core::Rgba8;

use super::header::{Role, VertexLayout};
use super::scalar::Scalar;
use super::RecordError;
use crate::format::ImportOptions;
use crate::vertex_store::VertexStore;
use crate::{ObjectId, Triangle};

/// One vertex's values.
#[derive(Clone, Copy)]
pub(super) struct VertexValues {
    pub(super) pos: [f64; 3],
    pub(super) normal: [f32; 3],
    pub(super) color: [u8; 4],
}

impl VertexValues {
    pub(super) const NEW: VertexValues =
        VertexValues { pos: [0.0; 3], normal: [0.0; 3], color: [0, 0, 0, 255] };

    #[inline(always)]
    pub(super) fn set(&mut self, role: Role, ty: Scalar, v: f64) {
        match role {
            Role::X => self.pos[0] = v,
            Role::Y => self.pos[1] = v,
            Role::Z => self.pos[2] = v,
            Role::Nx => self.normal[0] = v as f32,
            Role::Ny => self.normal[1] = v as f32,
            Role::Nz => self.normal[2] = v as f32,
            Role::R => self.color[0] = color_byte(ty, v),
            Role::G => self.color[1] = color_byte(ty, v),
            Role::B => self.color[2] = color_byte(ty, v),
            Role::A => self.color[3] = color_byte(ty, v),
        }
    }

    /// Checks the position; a non-finite normal becomes zero (no normal).
    #[inline(always)]
    pub(super) fn check(&mut self) -> Result<(), RecordError> {
        if !self.pos.iter().all(|v| v.is_finite()) {
            let [x, y, z] = self.pos;
            return Err(RecordError::Bad(format!("non-finite coordinate ({x}, {y}, {z})")));
        }
        if !self.normal.iter().all(|v| v.is_finite()) {
            self.normal = [0.0; 3];
        }
        Ok(())
    }
}

/// A colour channel from a value of type `ty`: floats are 0..1, `ushort` 0..65535, other
/// integers 0..255.
#[inline]
fn color_byte(ty: Scalar, v: f64) -> u8 {
    match ty {
        Scalar::F32 | Scalar::F64 => (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8,
        Scalar::U16 => (v / 257.0 + 0.5).clamp(0.0, 255.0) as u8,
        _ => v.clamp(0.0, 255.0) as u8,
    }
}

/// Positions as the file gives them: `f32` when every coordinate type converts to `f32`
/// exactly (the common `float x y z`), which halves the memory and the spilling; else `f64`.
enum Positions {
    F32(VertexStore<[f32; 3]>),
    F64(VertexStore<[f64; 3]>),
}

/// The vertex stores.
pub(super) struct Vertices {
    pos: Positions,
    normals: Option<VertexStore<[f32; 3]>>,
    colors: Option<VertexStore<Rgba8>>,
}

/// One corner of a triangle, fetched from the stores.
#[derive(Clone, Copy)]
pub(super) struct Corner {
    pos: [f64; 3],
    normal: Option<[f32; 3]>,
    color: Option<Rgba8>,
}

impl Corner {
    /// The triangle of three corners: normals and colours only where all three have them.
    pub(super) fn triangle([a, b, c]: [&Corner; 3], object: ObjectId) -> Triangle {
        let normals = match (a.normal, b.normal, c.normal) {
            (Some(x), Some(y), Some(z)) => Some([x, y, z]),
            _ => None,
        };
        let colors = match (a.color, b.color, c.color) {
            (Some(x), Some(y), Some(z)) => Some([x, y, z]),
            _ => None,
        };
        Triangle { positions: [a.pos, b.pos, c.pos], normals, colors, object }
    }
}

impl Vertices {
    /// Stores sharing [`ImportOptions::vertex_memory`] in proportion to their record sizes.
    pub(super) fn new(layout: Option<&VertexLayout>, options: &ImportOptions) -> Vertices {
        let (normals, colors) = layout.map_or((false, false), |l| (l.normals, l.colors));
        let exact_f32 = layout.is_some_and(|l| {
            l.fields.iter().all(|&(_, role, ty)| {
                !matches!(role, Role::X | Role::Y | Role::Z)
                    || matches!(ty, Scalar::F32 | Scalar::I8 | Scalar::U8 | Scalar::I16 | Scalar::U16)
            })
        });
        let pos_size = if exact_f32 { 12 } else { 24 };
        let weight = pos_size + if normals { 12 } else { 0 } + if colors { 4 } else { 0 };
        let share = |w: usize| options.vertex_memory / weight * w;
        let dir = || options.spill_dir.clone();
        Vertices {
            pos: if exact_f32 {
                Positions::F32(VertexStore::new(share(12), dir()))
            } else {
                Positions::F64(VertexStore::new(share(24), dir()))
            },
            normals: normals.then(|| VertexStore::new(share(12), dir())),
            colors: colors.then(|| VertexStore::new(share(4), dir())),
        }
    }

    #[inline]
    pub(super) fn push(&mut self, v: &VertexValues) -> io::Result<()> {
        match &mut self.pos {
            Positions::F32(s) => s.push(v.pos.map(|c| c as f32))?,
            Positions::F64(s) => s.push(v.pos)?,
        }
        if let Some(n) = &mut self.normals {
            n.push(v.normal)?;
        }
        if let Some(c) = &mut self.colors {
            c.push(Rgba8(v.color))?;
        }
        Ok(())
    }

    /// The corner of vertex `i`; `i < len()` is checked by the caller.
    #[inline]
    pub(super) fn corner(&mut self, i: u64) -> io::Result<Corner> {
        Ok(Corner {
            pos: match &mut self.pos {
                Positions::F32(s) => s.get(i)?.map(|c| c as f64),
                Positions::F64(s) => s.get(i)?,
            },
            normal: match &mut self.normals {
                Some(s) => Some(s.get(i)?),
                None => None,
            },
            color: match &mut self.colors {
                Some(s) => Some(s.get(i)?),
                None => None,
            },
        })
    }

    /// Makes block `b` of every store resident (see [`VertexStore::touch`]).
    pub(super) fn touch(&mut self, b: usize) -> io::Result<()> {
        match &mut self.pos {
            Positions::F32(s) => s.touch(b)?,
            Positions::F64(s) => s.touch(b)?,
        }
        if let Some(n) = &mut self.normals {
            n.touch(b)?;
        }
        if let Some(c) = &mut self.colors {
            c.touch(b)?;
        }
        Ok(())
    }

    /// How many blocks may be touched and stay resident together: one fewer than the smallest
    /// store keeps (at least 1).
    pub(super) fn touchable_blocks(&self) -> usize {
        let pos = match &self.pos {
            Positions::F32(s) => s.max_resident_blocks(),
            Positions::F64(s) => s.max_resident_blocks(),
        };
        let normals = self.normals.as_ref().map_or(usize::MAX, VertexStore::max_resident_blocks);
        let colors = self.colors.as_ref().map_or(usize::MAX, VertexStore::max_resident_blocks);
        pos.min(normals).min(colors) - 1
    }

    /// The corner of vertex `i < len()`, whose block was touched since the last push; from a
    /// shared reference, so that several threads can resolve faces at once.
    #[inline]
    pub(super) fn corner_resident(&self, i: u64) -> Corner {
        Corner {
            pos: match &self.pos {
                Positions::F32(s) => s.get_resident(i).map(|c| c as f64),
                Positions::F64(s) => s.get_resident(i),
            },
            normal: self.normals.as_ref().map(|s| s.get_resident(i)),
            color: self.colors.as_ref().map(|s| s.get_resident(i)),
        }
    }

    pub(super) fn len(&self) -> u64 {
        match &self.pos {
            Positions::F32(s) => s.len(),
            Positions::F64(s) => s.len(),
        }
    }

    pub(super) fn stats(&self) -> crate::vertex_store::StoreStats {
        match &self.pos {
            Positions::F32(s) => s.stats(),
            Positions::F64(s) => s.stats(),
        }
    }
}

#[cfg(test)]
mod tests {
    use tw_core::Rgba8;

    use crate::error::Position;
    use crate::format::ImportOptions;

    use super::super::test_util::*;

    #[test]
    fn normals_and_uchar_colours_per_vertex() {
        let header =
            "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                      property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
                      property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar alpha\n\
                      element face 1\nproperty list uchar uint vertex_indices\nend_header\n";
        let mut w = W::new(header, false);
        for i in 0..3u8 {
            w.f32(i as f32).f32(0.0).f32(i as f32 * 0.5);
            w.f32(0.0).f32(0.0).f32(if i == 2 { f32::NAN } else { 1.0 });
            w.u8(10 * i).u8(20).u8(30).u8(255 - i);
        }
        w.u8(3).u32(0).u32(1).u32(2);
        let (c, _) = run("n.ply", &w.out).unwrap();
        let t = c.tris[0];
        assert_eq!(t.positions, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [2.0, 0.0, 1.0]]);
        // A NaN normal becomes zero rather than an error.
        assert_eq!(t.normals, Some([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]]));
        assert_eq!(
            t.colors,
            Some([Rgba8([0, 20, 30, 255]), Rgba8([10, 20, 30, 254]), Rgba8([20, 20, 30, 253])])
        );
    }

    #[test]
    fn float_colours_and_double_coordinates_in_ascii() {
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\n\
                    property float red\nproperty float green\nproperty float blue\nelement face 1\n\
                    property list uchar int vertex_indices\nend_header\n\
                    1000000.125 2 3 1 0 0.5\n4 5 6 0 1 0\n7 8 9e1 0 0 1\n3 0 1 2\n";
        let (c, _) = run("c.ply", text.as_bytes()).unwrap();
        let t = c.tris[0];
        assert_eq!(t.positions, [[1000000.125, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 90.0]]);
        assert_eq!(
            t.colors,
            Some([Rgba8([255, 0, 128, 255]), Rgba8([0, 255, 0, 255]), Rgba8([0, 0, 255, 255])])
        );
        assert_eq!(t.normals, None);
    }

    #[test]
    fn integer_coordinates_type_aliases_and_vertex_index() {
        let header = "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty int16 x\nproperty int8 y\n\
                      property float64 z\nelement face 1\nproperty list uint16 uint8 vertex_index\nend_header\n";
        let mut w = W::new(header, true);
        w.i16(-300).u8(0xff).f64(0.25);
        w.i16(7).u8(1).f64(-1.0);
        w.i16(0).u8(2).f64(0.0);
        w.u16(3).u8(2).u8(0).u8(1);
        let (c, _) = run("i.ply", &w.out).unwrap();
        assert_eq!(c.tris[0].positions, [[0.0, 2.0, 0.0], [-300.0, -1.0, 0.25], [7.0, 1.0, -1.0]]);
    }

    /// Many vertices: records straddle read buffers, and with no vertex memory the store spills.
    #[test]
    fn large_binary_file_spills_and_streams_exactly() {
        let n = 120_000u32; // 1.4 MB of vertices: more than one read buffer
        let header = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n\
             property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            n - 2
        );
        let mut w = W::new(&header, false);
        for i in 0..n {
            w.f32(i as f32).f32((i % 7) as f32).f32(-(i as f32)).u8(i as u8).u8(1).u8(2);
        }
        // Every 1024th face refers to a far-away vertex, so that spilled blocks are read back.
        let far = |i: u32| if i.is_multiple_of(1024) { (i * 7919) % n } else { i };
        for i in 0..n - 2 {
            w.u8(3).i32(far(i) as i32).i32(far(i + 1) as i32).i32(far(i + 2) as i32);
        }
        let options = ImportOptions { vertex_memory: 0, spill_dir: None };
        let (c, s) = run_opts("big.ply", &gz(&w.out), &options).unwrap();
        assert_eq!(c.tris.len(), n as usize - 2);
        assert_eq!(s.vertices, n as u64);
        for (i, t) in c.tris.iter().enumerate() {
            for (k, p) in t.positions.iter().enumerate() {
                let v = far(i as u32 + k as u32);
                assert_eq!(*p, [v as f64, (v % 7) as f64, -(v as f64)]);
                assert_eq!(t.colors.unwrap()[k], Rgba8([v as u8, 1, 2, 255]));
            }
        }
    }

    #[test]
    fn non_finite_coordinates() {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let mut bytes = square("binary_little_endian");
            let header_len = bytes.len() - 4 * 12 - 17 - 13;
            let at = header_len + 2 * 12 + 4; // vertex 2, y
            bytes[at..at + 4].copy_from_slice(&bad.to_le_bytes());
            let e = err("n.ply", &bytes);
            assert_err(&e, Position::Byte((header_len + 24) as u64), "vertex 2: non-finite coordinate");
        }
        for bad in ["nan", "inf", "-infinity"] {
            let text = String::from_utf8(square("ascii")).unwrap().replace("1 1 0", &format!("1 {bad} 0"));
            assert_err(&err("n.ply", text.as_bytes()), Position::Line(14), "vertex 2: non-finite");
        }
    }
}
