//! GLB writer: the binary container of glTF 2.0 (Khronos glTF 2.0 specification, section 4.4
//! "GLB File Format Specification"; JSON schema of section 5).
//!
//! Scene structure: one node per object (named after it), and for every object with triangles
//! one mesh with one primitive per *run* — a maximal sequence of consecutive triangles of that
//! object in the stream (usually one run per object). Each run has its own POSITION accessor
//! (f32 VEC3, with the `min`/`max` the specification requires), NORMAL accessor (f32 VEC3, unit
//! length) and index accessor (u32). Normals make viewers shade the model (CesiumJS draws a
//! primitive without them unlit, flat-coloured): a lone triangle gets its face normal, a mesh
//! chunk's vertices the area-weighted sum of their triangles' normals within the chunk
//! (`chunk_normals`), so memory stays bounded by the chunk; surfaces are smooth inside a chunk
//! and may show a crease where two chunks meet. One
//! material per distinct object colour: `baseColorFactor` is the sRGB colour converted to linear
//! as glTF requires, metallic 0, double-sided (models are not consistently wound); objects
//! without a colour share a grey default.
//!
//! Up axis: the scenes written here are z-up (terawalk's generators; PLY, OBJ and STL have no
//! convention and terawalk takes z for them), while glTF 2.0 says +Y is up (section
//! "Coordinate System and Units"). So the object nodes hang under one root node whose `matrix`
//! turns +Z into +Y (a −90° turn about X: (x, y, z) → (x, z, −y)), and the positions stay as
//! given: glTF viewers, and terawalk's own importer with its glTF default `--up y`, show the
//! model upright. A writer whose scene has another up axis says so
//! ([`GlbWriter::set_up_axis`]: `terawalk export` writes a store's recorded axis), and may scale
//! the scene at the same node ([`GlbWriter::set_scale`]: 3D Tiles content in metres); the
//! positions still stay as given.
//!
//! Layout of the file, assembled in [`SceneWriter::finish`]:
//! ```text
//! header (12)  | JSON chunk: length, "JSON", text padded with spaces to 4 bytes
//!              | BIN chunk: length, "BIN\0", all positions (bufferView 0, stride 12),
//!              |            all normals (bufferView 1, stride 12), all indices (bufferView 2)
//! ```
//! The JSON must precede BIN but is known only at the end, so positions, normals and indices
//! stream into three unnamed temporary files; the JSON is serialised twice (once to measure its length), never held in
//! memory. GLB lengths are u32: a binary chunk that would pass 4 GiB is an error as soon as a
//! triangle would cross it.

use std::collections::HashMap;
use std::io::{self, Write};
use std::path::Path;

use tw_core::Rgba8;

use crate::error::ImportError;
use crate::{MeshChunk, ObjectId, ObjectInfo, Triangle, TriangleSink};

use super::{check_chunk, io_err, to_f32, Objects, Output, SceneWriter, Spill, WriteSummary};

const MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
/// GLB header plus the two chunk headers.
const OVERHEAD: u64 = 12 + 8 + 8;
/// More runs than this means the objects' triangles are interleaved almost one by one; the JSON
/// (and the per-run records in memory) would grow without bound.
const MAX_RUNS: usize = 1 << 22;

/// The root node's matrix for each up axis of the written scene (column-major, as glTF stores
/// it), turning that axis to glTF's +Y. z: a −90° turn about X, (x, y, z) → (x, z, −y);
/// y: the identity; x: a +90° turn about Z, (x, y, z) → (−y, x, z).
pub const UP_TO_Y_UP: [[f64; 16]; 3] = [
    [0., 1., 0., 0., -1., 0., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.],
    [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.],
    [1., 0., 0., 0., 0., 0., -1., 0., 0., 1., 0., 0., 0., 0., 0., 1.],
];

/// A maximal sequence of consecutive triangles of one object: one primitive.
#[derive(Clone, Debug)]
struct Run {
    /// Dense object index (announcement order).
    object: u32,
    /// First vertex in bufferView 0 and number of vertices.
    first_vertex: u64,
    vertices: u64,
    /// First index in bufferView 1 and number of indices.
    first_index: u64,
    indices: u64,
    min: [f32; 3],
    max: [f32; 3],
}

/// Writes GLB; see the module documentation.
pub struct GlbWriter {
    out: Output,
    positions: Spill,
    normals: Spill,
    indices: Spill,
    objects: Objects,
    runs: Vec<Run>,
    vertices: u64,
    index_count: u64,
    triangles: u64,
    /// Limits (fields so tests can lower them).
    max_bin: u64,
    max_runs: usize,
    scratch: Vec<u8>,
    /// Up axis of the written scene (0 x, 1 y, 2 z) and a uniform scale, both applied by the
    /// root node (module docs).
    up_axis: u8,
    scale: f64,
}

impl GlbWriter {
    /// Starts writing `path`. Nothing appears before [`SceneWriter::finish`].
    pub fn create(path: &Path) -> Result<GlbWriter, ImportError> {
        Ok(GlbWriter {
            out: Output::create(path, false)?,
            positions: Spill::create(path)?,
            normals: Spill::create(path)?,
            indices: Spill::create(path)?,
            objects: Objects::default(),
            runs: Vec::new(),
            vertices: 0,
            index_count: 0,
            triangles: 0,
            max_bin: u32::MAX as u64 - OVERHEAD,
            max_runs: MAX_RUNS,
            scratch: Vec::new(),
            up_axis: 2,
            scale: 1.0,
        })
    }

    /// The up axis of the scene to be written (0 x, 1 y, 2 z; default z): the root node turns
    /// it to glTF's +Y. Another value is an error.
    pub fn set_up_axis(&mut self, axis: u8) -> Result<(), ImportError> {
        if axis > 2 {
            return Err(ImportError::Sink(format!(
                "{}: up axis {axis} is not 0 (x), 1 (y) or 2 (z)",
                self.out.target().display()
            )));
        }
        self.up_axis = axis;
        Ok(())
    }

    /// A uniform scale the root node applies after the turn (default 1): metres per unit for
    /// content that must be in metres. It must be finite and positive.
    pub fn set_scale(&mut self, scale: f64) -> Result<(), ImportError> {
        if !(scale.is_finite() && scale > 0.0) {
            return Err(ImportError::Sink(format!(
                "{}: scale {scale} is not a finite positive number",
                self.out.target().display()
            )));
        }
        self.scale = scale;
        Ok(())
    }

    /// Makes room for `vertices` and `indices` more in the current run of `object` (starting a
    /// run if the object changed); returns the index within the run of the first new vertex.
    fn reserve(&mut self, object: u32, vertices: u64, indices: u64) -> Result<u32, ImportError> {
        let bin = (self.vertices + vertices) * 24 + (self.index_count + indices) * 4;
        if bin > self.max_bin {
            return Err(ImportError::Sink(format!(
                "{}: the GLB binary chunk would pass {} bytes (GLB lengths are 32-bit, 4 GiB at most); \
                 write PLY for scenes this large",
                self.out.target().display(),
                self.max_bin
            )));
        }
        let same = self.runs.last().is_some_and(|r| r.object == object);
        if !same {
            if self.runs.len() >= self.max_runs {
                return Err(ImportError::Sink(format!(
                    "{}: more than {} runs of triangles: the objects' triangles are too finely \
                     interleaved for GLB (each run becomes a primitive)",
                    self.out.target().display(),
                    self.max_runs
                )));
            }
            self.runs.push(Run {
                object,
                first_vertex: self.vertices,
                vertices: 0,
                first_index: self.index_count,
                indices: 0,
                min: [f32::INFINITY; 3],
                max: [f32::NEG_INFINITY; 3],
            });
        }
        let Some(run) = self.runs.last_mut() else {
            return Err(ImportError::Sink("internal: GLB run missing".into()));
        };
        // The BIN limit keeps a run's vertex count far below u32::MAX (the primitive restart
        // value, which indices must not use).
        let base = run.vertices as u32;
        run.vertices += vertices;
        run.indices += indices;
        self.vertices += vertices;
        self.index_count += indices;
        Ok(base)
    }

    fn grow_bounds(&mut self, p: [f32; 3]) {
        if let Some(run) = self.runs.last_mut() {
            run.min = [run.min[0].min(p[0]), run.min[1].min(p[1]), run.min[2].min(p[2])];
            run.max = [run.max[0].max(p[0]), run.max[1].max(p[1]), run.max[2].max(p[2])];
        }
    }
}

/// What the JSON describes.
struct Layout<'a> {
    objects: &'a Objects,
    runs: &'a [Run],
    vertices: u64,
    index_count: u64,
    up_axis: u8,
    scale: f64,
}

impl Layout<'_> {
    /// The root node's name and matrix (JSON array text), for the scene's up axis and scale.
    fn root_matrix(&self) -> (String, String) {
        let axis = self.up_axis.min(2) as usize;
        let name = format!("{}-up to y-up", ["x", "y", "z"][axis]);
        let mut m = UP_TO_Y_UP[axis];
        for v in &mut m[..12] {
            *v *= self.scale;
        }
        let text: Vec<String> = m.iter().map(|v| format!("{}", v + 0.0)).collect();
        (name, format!("[{}]", text.join(",")))
    }

    /// Serialises the JSON chunk's text (unpadded).
    fn write_json(&self, w: &mut impl Write) -> io::Result<()> {
        let infos = &self.objects.infos;
        let runs = self.runs_by_object();
        let (materials, material_list) = self.materials(&runs);

        w.write_all(br#"{"asset":{"version":"2.0","generator":"terawalk"}"#)?;
        // Arrays must not be empty in glTF: without objects there is no scene at all. The
        // scene's one root node, after the objects' nodes, holds them upright (module docs).
        if !infos.is_empty() {
            write!(w, r#","scene":0,"scenes":[{{"nodes":[{}]}}]"#, infos.len())?;
        }
        if !infos.is_empty() {
            self.write_nodes(w, &runs)?;
        }
        if !self.runs.is_empty() {
            self.write_meshes(w, &runs, &materials)?;
            write_materials(w, &material_list)?;
            self.write_accessors_and_buffers(w)?;
        }
        w.write_all(b"}")
    }

    /// The runs grouped by object, in stream order within each object.
    fn runs_by_object(&self) -> RunsByObject {
        let objects = self.objects.infos.len();
        let mut order: Vec<u32> = (0..self.runs.len() as u32).collect();
        order.sort_by_key(|&r| self.runs[r as usize].object);
        let mut first_run = vec![0u32; objects + 1];
        for r in self.runs {
            first_run[r.object as usize + 1] += 1;
        }
        for i in 0..objects {
            first_run[i + 1] += first_run[i];
        }
        RunsByObject { order, first_run }
    }

    /// The materials, one per colour, in order of first use by an object with triangles, and
    /// each colour's material index.
    fn materials(&self, runs: &RunsByObject) -> (HashMap<Option<Rgba8>, u32>, Vec<Option<Rgba8>>) {
        let mut materials: HashMap<Option<Rgba8>, u32> = HashMap::new();
        let mut material_list: Vec<Option<Rgba8>> = Vec::new();
        for (o, (_, info)) in self.objects.infos.iter().enumerate() {
            if !runs.of(o).is_empty() && !materials.contains_key(&info.color) {
                materials.insert(info.color, material_list.len() as u32);
                material_list.push(info.color);
            }
        }
        (materials, material_list)
    }

    /// The `nodes` array: a node per object (named; with a mesh when it has triangles), then
    /// the root node that holds them all upright.
    fn write_nodes(&self, w: &mut impl Write, runs: &RunsByObject) -> io::Result<()> {
        let infos = &self.objects.infos;
        w.write_all(br#","nodes":["#)?;
        let mut mesh = 0u32;
        for (o, (_, info)) in infos.iter().enumerate() {
            w.write_all(if o > 0 { b",{" } else { b"{" })?;
            let mut sep = "";
            if !info.name.is_empty() {
                w.write_all(br#""name":"#)?;
                serde_json::to_writer(&mut *w, &info.name)?;
                sep = ",";
            }
            if !runs.of(o).is_empty() {
                write!(w, r#"{sep}"mesh":{mesh}"#)?;
                mesh += 1;
            }
            w.write_all(b"}")?;
        }
        let (name, matrix) = self.root_matrix();
        write!(w, r#",{{"name":"{name}","matrix":{matrix},"children":["#)?;
        for o in 0..infos.len() {
            write!(w, "{}{o}", if o > 0 { "," } else { "" })?;
        }
        w.write_all(b"]}]")
    }

    /// The `meshes` array: a mesh per object with triangles, a primitive per run (each run's
    /// accessors are `3 r`, `3 r + 1` and `3 r + 2`).
    fn write_meshes(
        &self,
        w: &mut impl Write,
        runs: &RunsByObject,
        materials: &HashMap<Option<Rgba8>, u32>,
    ) -> io::Result<()> {
        w.write_all(br#","meshes":["#)?;
        let mut first = true;
        for (o, (_, info)) in self.objects.infos.iter().enumerate() {
            let runs = runs.of(o);
            if runs.is_empty() {
                continue;
            }
            w.write_all(if first { b"{" } else { b",{" })?;
            first = false;
            if !info.name.is_empty() {
                w.write_all(br#""name":"#)?;
                serde_json::to_writer(&mut *w, &info.name)?;
                w.write_all(b",")?;
            }
            w.write_all(br#""primitives":["#)?;
            let material = materials[&info.color];
            for (k, &r) in runs.iter().enumerate() {
                write!(
                    w,
                    r#"{}{{"attributes":{{"POSITION":{},"NORMAL":{}}},"indices":{},"material":{material}}}"#,
                    if k > 0 { "," } else { "" },
                    3 * r,
                    3 * r + 1,
                    3 * r + 2
                )?;
            }
            w.write_all(b"]}")?;
        }
        w.write_all(b"]")
    }

    /// The `accessors` array (each run's positions, normals and indices), the three buffer views
    /// (all positions, all normals, all indices) and the one buffer.
    fn write_accessors_and_buffers(&self, w: &mut impl Write) -> io::Result<()> {
        w.write_all(br#","accessors":["#)?;
        for (k, r) in self.runs.iter().enumerate() {
            write!(
                w,
                r#"{}{{"bufferView":0,"byteOffset":{},"componentType":5126,"count":{},"type":"VEC3","min":[{},{},{}],"max":[{},{},{}]}},"#,
                if k > 0 { "," } else { "" },
                r.first_vertex * 12,
                r.vertices,
                r.min[0],
                r.min[1],
                r.min[2],
                r.max[0],
                r.max[1],
                r.max[2]
            )?;
            write!(
                w,
                r#"{{"bufferView":1,"byteOffset":{},"componentType":5126,"count":{},"type":"VEC3"}},"#,
                r.first_vertex * 12,
                r.vertices
            )?;
            write!(
                w,
                r#"{{"bufferView":2,"byteOffset":{},"componentType":5125,"count":{},"type":"SCALAR"}}"#,
                r.first_index * 4,
                r.indices
            )?;
        }
        let p = self.vertices * 12;
        let i = self.index_count * 4;
        write!(
            w,
            r#"],"bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":{p},"byteStride":12,"target":34962}},{{"buffer":0,"byteOffset":{p},"byteLength":{p},"byteStride":12,"target":34962}},{{"buffer":0,"byteOffset":{},"byteLength":{i},"target":34963}}],"buffers":[{{"byteLength":{}}}]"#,
            2 * p,
            2 * p + i
        )
    }
}

/// The runs grouped by object: object `o`'s runs are `order[first_run[o]..first_run[o + 1]]`.
struct RunsByObject {
    order: Vec<u32>,
    first_run: Vec<u32>,
}

impl RunsByObject {
    /// Object `o`'s runs, in stream order.
    fn of(&self, o: usize) -> &[u32] {
        &self.order[self.first_run[o] as usize..self.first_run[o + 1] as usize]
    }
}

/// The `materials` array: one per colour (grey without one), its base colour in linear RGB,
/// blended when translucent.
fn write_materials(w: &mut impl Write, material_list: &[Option<Rgba8>]) -> io::Result<()> {
    w.write_all(br#","materials":["#)?;
    for (k, color) in material_list.iter().enumerate() {
        let c = color.unwrap_or(Rgba8::GREY);
        let l = c.0.map(|v| srgb_to_linear(v as f32 / 255.0));
        let alpha = c.0[3] as f32 / 255.0;
        write!(
            w,
            r#"{}{{"name":"{}","pbrMetallicRoughness":{{"baseColorFactor":[{},{},{},{alpha}],"metallicFactor":0,"roughnessFactor":0.8}},"doubleSided":true{}}}"#,
            if k > 0 { "," } else { "" },
            super::obj::material_name(*color),
            l[0],
            l[1],
            l[2],
            if c.0[3] < 255 { r#","alphaMode":"BLEND""# } else { "" }
        )?;
    }
    w.write_all(b"]")
}

/// The sRGB transfer function inverted (IEC 61966-2-1), as glTF's linear colour factors need.
fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// A triangle's normal, its length twice the triangle's area (right-handed winding).
fn face_normal(p: &[[f32; 3]; 3]) -> [f32; 3] {
    let (a, b) = (sub(p[1], p[0]), sub(p[2], p[0]));
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `n` scaled to unit length; +Z where it has none (a degenerate triangle, or normals that
/// cancel): glTF requires every normal to be of unit length.
fn unit_or_up(n: [f32; 3]) -> [f32; 3] {
    let len = (n[0] as f64).hypot(n[1] as f64).hypot(n[2] as f64);
    if len.is_finite() && len > 1e-30 {
        n.map(|x| (x as f64 / len) as f32)
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// Per vertex of a mesh chunk: the unit sum of its triangles' normals weighted by their areas
/// (the cross products' lengths), so large faces dominate and slivers barely count. A vertex
/// on no triangle, or whose triangles cancel (a fold), gets +Z.
fn chunk_normals(points: &[[f32; 3]], indices: &[u32]) -> Vec<[f32; 3]> {
    let mut sum = vec![[0.0f64; 3]; points.len()];
    for t in indices.chunks_exact(3) {
        let n = face_normal(&[points[t[0] as usize], points[t[1] as usize], points[t[2] as usize]]);
        for &v in t {
            for i in 0..3 {
                sum[v as usize][i] += n[i] as f64;
            }
        }
    }
    sum.iter().map(|s| unit_or_up([s[0] as f32, s[1] as f32, s[2] as f32])).collect()
}

/// Counts bytes, to measure the JSON before writing it.
struct Counter<W> {
    inner: W,
    n: u64,
}

impl<W: Write> Write for Counter<W> {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.n += n as u64;
        Ok(n)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.inner.flush()
    }
}

impl TriangleSink for GlbWriter {
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        self.objects.announce(self.out.target(), id, info)?;
        Ok(())
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        let target = self.out.target();
        let object = self.objects.get(target, t.object)?;
        let mut pos = [[0f32; 3]; 3];
        for (q, p) in pos.iter_mut().zip(&t.positions) {
            *q = to_f32(target, *p)?;
        }
        let base = self.reserve(object, 3, 3)?;
        let mut v = [0u8; 36];
        for (k, p) in pos.iter().enumerate() {
            for i in 0..3 {
                v[12 * k + 4 * i..12 * k + 4 * i + 4].copy_from_slice(&p[i].to_le_bytes());
            }
            self.grow_bounds(*p);
        }
        let mut idx = [0u8; 12];
        for k in 0..3 {
            idx[4 * k..4 * k + 4].copy_from_slice(&(base + k as u32).to_le_bytes());
        }
        let normal = unit_or_up(face_normal(&pos));
        let mut n = [0u8; 36];
        for k in 0..3 {
            for i in 0..3 {
                n[12 * k + 4 * i..12 * k + 4 * i + 4].copy_from_slice(&normal[i].to_le_bytes());
            }
        }
        let err = io_err(self.out.target());
        self.positions.write_all(&v).map_err(&err)?;
        self.normals.write_all(&n).map_err(&err)?;
        self.indices.write_all(&idx).map_err(&err)?;
        self.triangles += 1;
        Ok(())
    }

    fn mesh(&mut self, chunk: &MeshChunk<'_>) -> Result<(), ImportError> {
        let target = self.out.target().to_path_buf();
        let object = self.objects.get(&target, chunk.object)?;
        check_chunk(&target, chunk)?;
        if chunk.indices.is_empty() {
            return Ok(());
        }
        let points = chunk.positions.iter().map(|p| to_f32(&target, *p)).collect::<Result<Vec<_>, _>>()?;
        let base = self.reserve(object, chunk.positions.len() as u64, chunk.indices.len() as u64)?;
        for &p in &points {
            self.grow_bounds(p);
        }
        let err = io_err(&target);
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        scratch.extend(points.iter().flatten().flat_map(|x| x.to_le_bytes()));
        self.positions.write_all(&scratch).map_err(&err)?;
        scratch.clear();
        scratch.extend(chunk_normals(&points, chunk.indices).iter().flatten().flat_map(|x| x.to_le_bytes()));
        self.normals.write_all(&scratch).map_err(&err)?;
        scratch.clear();
        for &i in chunk.indices {
            scratch.extend_from_slice(&(base + i).to_le_bytes());
        }
        self.indices.write_all(&scratch).map_err(&err)?;
        self.triangles += (chunk.indices.len() / 3) as u64;
        self.scratch = scratch;
        Ok(())
    }
}

impl SceneWriter for GlbWriter {
    fn finish(self: Box<Self>) -> Result<WriteSummary, ImportError> {
        let GlbWriter {
            out,
            positions,
            normals,
            indices,
            objects,
            runs,
            vertices,
            index_count,
            triangles,
            up_axis,
            scale,
            ..
        } = *self;
        let layout = Layout { objects: &objects, runs: &runs, vertices, index_count, up_axis, scale };
        let target = out.target().to_path_buf();
        let err = io_err(&target);
        let mut counter = Counter { inner: io::sink(), n: 0 };
        layout.write_json(&mut counter).map_err(&err)?;
        let json_len = counter.n;
        let json_padded = json_len.next_multiple_of(4);
        let bin_len = positions.len() + normals.len() + indices.len();
        debug_assert_eq!(bin_len, vertices * 24 + index_count * 4);
        let total = 12 + 8 + json_padded + if bin_len > 0 { 8 + bin_len } else { 0 };
        if total > u32::MAX as u64 {
            return Err(ImportError::Sink(format!(
                "{}: the GLB file would be {total} bytes, more than GLB's 32-bit length allows; \
                 write PLY for scenes this large",
                target.display()
            )));
        }
        let mut out = Counter { inner: out, n: 0 };
        let mut head = Vec::with_capacity(20);
        head.extend_from_slice(MAGIC);
        head.extend_from_slice(&2u32.to_le_bytes());
        head.extend_from_slice(&(total as u32).to_le_bytes());
        head.extend_from_slice(&(json_padded as u32).to_le_bytes());
        head.extend_from_slice(&CHUNK_JSON.to_le_bytes());
        out.write_all(&head).map_err(&err)?;
        layout.write_json(&mut out).map_err(&err)?;
        if out.n != 20 + json_len {
            return Err(ImportError::Sink(format!("{}: internal: JSON length changed", target.display())));
        }
        out.write_all(&b"   "[..(json_padded - json_len) as usize]).map_err(&err)?;
        if bin_len > 0 {
            out.write_all(&(bin_len as u32).to_le_bytes()).map_err(&err)?;
            out.write_all(&CHUNK_BIN.to_le_bytes()).map_err(&err)?;
            positions.copy_into(&mut out).map_err(&err)?;
            normals.copy_into(&mut out).map_err(&err)?;
            indices.copy_into(&mut out).map_err(&err)?;
        }
        if out.n != total {
            return Err(ImportError::Sink(format!("{}: internal: GLB length mismatch", target.display())));
        }
        let bytes = out.inner.commit()?;
        Ok(WriteSummary { objects: objects.len(), triangles, vertices, bytes })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::write::{create_writer, test_scene};

    fn write(scene: impl FnOnce(&mut dyn TriangleSink)) -> Vec<u8> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.glb");
        let mut w = create_writer(&p).unwrap();
        scene(&mut *w);
        let s = w.finish().unwrap();
        let b = std::fs::read(&p).unwrap();
        assert_eq!(s.bytes, b.len() as u64);
        b
    }

    fn u32_at(b: &[u8], o: usize) -> u32 {
        u32::from_le_bytes(b[o..o + 4].try_into().unwrap())
    }

    /// Splits a GLB into its JSON and BIN chunks, checking the container rules.
    fn chunks(b: &[u8]) -> (serde_json::Value, Vec<u8>) {
        assert_eq!(&b[0..4], b"glTF");
        assert_eq!(u32_at(b, 4), 2);
        assert_eq!(u32_at(b, 8) as usize, b.len());
        let jl = u32_at(b, 12) as usize;
        assert_eq!(jl % 4, 0);
        assert_eq!(u32_at(b, 16), CHUNK_JSON);
        let json = serde_json::from_slice(&b[20..20 + jl]).unwrap();
        let rest = &b[20 + jl..];
        if rest.is_empty() {
            return (json, Vec::new());
        }
        let bl = u32_at(rest, 0) as usize;
        assert_eq!(bl % 4, 0);
        assert_eq!(u32_at(rest, 4), CHUNK_BIN);
        assert_eq!(rest.len(), 8 + bl);
        (json, rest[8..].to_vec())
    }

    fn floats(v: &serde_json::Value) -> Vec<f64> {
        v.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect()
    }

    fn sample() -> Vec<u8> {
        write(|s| test_scene::stream(s).unwrap())
    }

    #[test]
    fn container_and_chunks_are_well_formed() {
        let (json, bin) = chunks(&sample());
        assert_eq!(json["asset"]["version"], "2.0");
        assert_eq!(bin.len(), 13 * 24 + 15 * 4);
        assert_eq!(json["buffers"][0]["byteLength"], bin.len());
    }

    #[test]
    fn one_node_per_object_and_one_primitive_per_run() {
        let (json, _) = chunks(&sample());
        let nodes = json["nodes"].as_array().unwrap();
        assert_eq!(nodes.len(), 4);
        assert_eq!(nodes[0]["name"], "red part");
        assert_eq!(nodes[0]["mesh"], 0);
        assert!(nodes[1].get("name").is_none());
        assert_eq!(nodes[1]["mesh"], 1);
        assert_eq!(nodes[2]["name"], "empty\nline");
        assert!(nodes[2].get("mesh").is_none());
        let meshes = json["meshes"].as_array().unwrap();
        assert_eq!(meshes.len(), 2);
        // Object 0 has two runs: the chunk, and the triangle after object 1's.
        let p0 = meshes[0]["primitives"].as_array().unwrap();
        assert_eq!(p0.len(), 2);
        assert_eq!(p0[0]["attributes"]["POSITION"], 0);
        assert_eq!(p0[0]["attributes"]["NORMAL"], 1);
        assert_eq!(p0[0]["indices"], 2);
        assert_eq!(p0[1]["attributes"]["POSITION"], 6);
        assert_eq!(meshes[1]["primitives"][0]["indices"], 5);
        // One root node holds the objects' nodes, turning the z-up scene to glTF's y-up.
        assert_eq!(json["scenes"][0]["nodes"], serde_json::json!([3]));
        assert_eq!(nodes[3]["children"], serde_json::json!([0, 1, 2]));
        assert_eq!(
            floats(&nodes[3]["matrix"]),
            [1., 0., 0., 0., 0., 0., -1., 0., 0., 1., 0., 0., 0., 0., 0., 1.]
        );
    }

    #[test]
    fn accessors_have_min_max_and_point_into_the_views() {
        let (json, bin) = chunks(&sample());
        let acc = json["accessors"].as_array().unwrap();
        assert_eq!(acc.len(), 9);
        assert_eq!(acc[0]["count"], 4);
        assert_eq!(floats(&acc[0]["min"]), [0.0, 0.0, 0.0]);
        assert_eq!(floats(&acc[0]["max"]), [1.0, 1.0, 0.0]);
        assert_eq!(
            (&acc[1]["bufferView"], &acc[1]["count"], &acc[1]["type"]),
            (&1.into(), &4.into(), &"VEC3".into())
        );
        assert_eq!(acc[3]["byteOffset"], 48);
        assert_eq!(floats(&acc[3]["min"]), [2.0, 0.0, -1.5]);
        assert_eq!(floats(&acc[3]["max"]), [3.0, 2.0, 1.0]);
        assert_eq!(acc[4]["byteOffset"], 48);
        assert_eq!(acc[8]["byteOffset"], 12 * 4);
        assert_eq!(acc[8]["count"], 3);
        let views = json["bufferViews"].as_array().unwrap();
        assert_eq!(views[0]["byteStride"], 12);
        assert_eq!((&views[1]["byteOffset"], &views[1]["byteStride"]), (&(13 * 12).into(), &12.into()));
        assert_eq!(views[2]["byteOffset"], 13 * 24);
        // Indices are relative to their run: the chunk's, then 0 1 2 3 4 5, then 0 1 2.
        let idx: Vec<u32> =
            bin[13 * 24..].chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap())).collect();
        assert_eq!(idx, [0, 1, 2, 0, 2, 3, 0, 1, 2, 3, 4, 5, 0, 1, 2]);
    }

    #[test]
    fn materials_are_linear_and_per_colour() {
        let (json, _) = chunks(&sample());
        let m = json["materials"].as_array().unwrap();
        // Red, and the default for object 1; object 2's colour is unused (no triangles).
        assert_eq!(m.len(), 2);
        assert_eq!(floats(&m[0]["pbrMetallicRoughness"]["baseColorFactor"]), [1.0, 0.0, 0.0, 1.0]);
        let grey = m[1]["pbrMetallicRoughness"]["baseColorFactor"][0].as_f64().unwrap();
        assert!((grey - 0.4564).abs() < 1e-3, "{grey}");
        assert_eq!(json["meshes"][1]["primitives"][0]["material"], 1);
    }

    #[test]
    fn gltf_crate_accepts_and_reads_it() {
        let b = sample();
        let (doc, buffers, _) = gltf::import_slice(&b).unwrap();
        let mut tris = 0;
        for mesh in doc.meshes() {
            for prim in mesh.primitives() {
                let r = prim.reader(|buf| Some(&buffers[buf.index()]));
                let pos: Vec<[f32; 3]> = r.read_positions().unwrap().collect();
                let idx: Vec<u32> = r.read_indices().unwrap().into_u32().collect();
                assert!(idx.iter().all(|&i| (i as usize) < pos.len()));
                tris += idx.len() / 3;
            }
        }
        assert_eq!(tris, 5);
        let first = doc.meshes().next().unwrap().primitives().next().unwrap();
        let r = first.reader(|buf| Some(&buffers[buf.index()]));
        assert_eq!(r.read_positions().unwrap().nth(2), Some([1.0, 1.0, 0.0]));
    }

    /// Every normal is of unit length (glTF requires it); a lone triangle's vertices carry its face
    /// normal, a chunk's vertices the area-weighted mean of their triangles', and a degenerate
    /// triangle +Z.
    #[test]
    fn normals_are_unit_face_or_area_weighted() {
        let b = sample();
        let (doc, buffers, _) = gltf::import_slice(&b).unwrap();
        let mut normals = 0;
        for prim in doc.meshes().flat_map(|m| m.primitives().collect::<Vec<_>>()) {
            let r = prim.reader(|buf| Some(&buffers[buf.index()]));
            let pos: Vec<[f32; 3]> = r.read_positions().unwrap().collect();
            let nrm: Vec<[f32; 3]> = r.read_normals().unwrap().collect();
            assert_eq!(pos.len(), nrm.len());
            for n in &nrm {
                let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
                assert!((len - 1.0).abs() < 1e-5, "{n:?}");
            }
            normals += nrm.len();
        }
        assert_eq!(normals, 13);
        // Area weighting: a unit square in z = 0 and a tiny triangle standing up at one corner.
        let points = [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.], [0., 0., 1e-3], [1e-3, 0., 0.]];
        let n = chunk_normals(&points, &[0, 1, 2, 0, 2, 3, 0, 5, 4]);
        assert_eq!(n[2], [0.0, 0.0, 1.0]);
        assert!(n[0][2] > 0.999 && n[0][1] < 0.0, "the big faces dominate: {:?}", n[0]);
        assert_eq!(n[4], [0.0, -1.0, 0.0]);
        assert_eq!(unit_or_up(face_normal(&[[1.0; 3]; 3])), [0.0, 0.0, 1.0]);
    }

    #[test]
    fn empty_scene_has_no_bin_chunk() {
        let b = write(|_| {});
        let (json, bin) = chunks(&b);
        assert!(bin.is_empty());
        assert!(json.get("buffers").is_none());
        assert!(json.get("scenes").is_none());
        gltf::Gltf::from_slice(&b).unwrap();
        let b = write(|s| s.object(0, &ObjectInfo::default()).unwrap());
        let (json, _) = chunks(&b);
        assert_eq!(json["nodes"][0], serde_json::json!({}));
        assert_eq!(json["nodes"][1]["children"], serde_json::json!([0]));
        gltf::Gltf::from_slice(&b).unwrap();
    }

    /// A scene with another up axis gets the root matrix that turns that axis to +Y, scaled;
    /// bad axes and scales are errors naming the file.
    #[test]
    fn root_node_follows_the_up_axis_and_scale() {
        let dir = tempfile::tempdir().unwrap();
        let root_of = |axis: u8, scale: f64| {
            let p = dir.path().join("a.glb");
            let mut w = GlbWriter::create(&p).unwrap();
            w.set_up_axis(axis).unwrap();
            w.set_scale(scale).unwrap();
            let mut w: Box<dyn SceneWriter> = Box::new(w);
            test_scene::stream(&mut *w).unwrap();
            w.finish().unwrap();
            let (json, _) = chunks(&std::fs::read(&p).unwrap());
            (json["nodes"][3]["name"].clone(), floats(&json["nodes"][3]["matrix"]))
        };
        let (name, m) = root_of(1, 1.0);
        assert_eq!(name, "y-up to y-up");
        assert_eq!(m, [1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.]);
        // x up: +X goes to +Y, +Y to −X; the scale multiplies the turn, not the w row.
        let (name, m) = root_of(0, 0.001);
        assert_eq!(name, "x-up to y-up");
        assert_eq!(m, [0., 0.001, 0., 0., -0.001, 0., 0., 0., 0., 0., 0.001, 0., 0., 0., 0., 1.]);
        let (_, m) = root_of(2, 2.0);
        assert_eq!(m, [2., 0., 0., 0., 0., 0., -2., 0., 0., 2., 0., 0., 0., 0., 0., 1.]);
        let mut w = GlbWriter::create(&dir.path().join("b.glb")).unwrap();
        assert!(w.set_up_axis(3).unwrap_err().to_string().contains("b.glb"));
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY] {
            assert!(w.set_scale(bad).unwrap_err().to_string().contains("b.glb"), "{bad}");
        }
    }

    #[test]
    fn binary_chunk_limit_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = GlbWriter::create(&dir.path().join("a.glb")).unwrap();
        w.object(0, &ObjectInfo::default()).unwrap();
        w.max_bin = 170;
        w.triangle(&Triangle::new(test_scene::T1, 0)).unwrap(); // 84 bytes: positions, normals, indices
        w.triangle(&Triangle::new(test_scene::T2, 0)).unwrap(); // 168 bytes
        let e = w.triangle(&Triangle::new(test_scene::T3, 0)).unwrap_err();
        assert!(e.to_string().contains("4 GiB"), "{e}");
    }

    #[test]
    fn too_many_runs_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = GlbWriter::create(&dir.path().join("a.glb")).unwrap();
        w.max_runs = 2;
        w.object(0, &ObjectInfo::default()).unwrap();
        w.object(1, &ObjectInfo::default()).unwrap();
        w.triangle(&Triangle::new(test_scene::T1, 0)).unwrap();
        w.triangle(&Triangle::new(test_scene::T2, 1)).unwrap();
        let e = w.triangle(&Triangle::new(test_scene::T3, 0)).unwrap_err();
        assert!(e.to_string().contains("interleaved"), "{e}");
    }
}
