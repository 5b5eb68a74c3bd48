//! Small handmade glTF documents, one per feature and per broken-input case.

use std::io::Write;
use std::path::{Path, PathBuf};

use serde_json::{json, Value};

use crate::format::{open_input, open_source, ImportOptions};
use crate::input::Input;
use crate::{ImportError, ObjectInfo, Position, SourceSummary, Triangle, TriangleSink};
use tw_core::Rgba8;

const FLOAT: u32 = 5126;
const BYTE: u32 = 5120;
const UBYTE: u32 = 5121;
const SHORT: u32 = 5122;
const USHORT: u32 = 5123;
const UINT: u32 = 5125;

const SQUARE: [[f32; 3]; 4] = [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];

/// Binary data, buffer views and accessors of a test document (buffer 0).
#[derive(Default)]
struct Bin {
    bytes: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Bin {
    fn view(&mut self, data: &[u8], stride: Option<usize>) -> usize {
        while !self.bytes.len().is_multiple_of(4) {
            self.bytes.push(0);
        }
        let mut v = json!({"buffer": 0, "byteOffset": self.bytes.len(), "byteLength": data.len()});
        if let Some(s) = stride {
            v["byteStride"] = json!(s);
        }
        self.bytes.extend_from_slice(data);
        self.views.push(v);
        self.views.len() - 1
    }

    fn accessor(&mut self, a: Value) -> usize {
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    fn positions(&mut self, p: &[[f32; 3]]) -> usize {
        let v = self.view(&f32_bytes(p), None);
        self.accessor(json!({"bufferView": v, "componentType": FLOAT, "type": "VEC3", "count": p.len(),
            "min": [0, 0, 0], "max": [1, 1, 1]}))
    }

    fn vec3(&mut self, p: &[[f32; 3]]) -> usize {
        let v = self.view(&f32_bytes(p), None);
        self.accessor(json!({"bufferView": v, "componentType": FLOAT, "type": "VEC3", "count": p.len()}))
    }

    fn indices(&mut self, ix: &[u32], component_type: u32) -> usize {
        let bytes: Vec<u8> = match component_type {
            UBYTE => ix.iter().map(|&i| i as u8).collect(),
            USHORT => ix.iter().flat_map(|&i| (i as u16).to_le_bytes()).collect(),
            _ => ix.iter().flat_map(|&i| i.to_le_bytes()).collect(),
        };
        let v = self.view(&bytes, None);
        self.accessor(
            json!({"bufferView": v, "componentType": component_type, "type": "SCALAR", "count": ix.len()}),
        )
    }

    /// The document: `rest` (meshes, nodes, ...) plus asset, buffer 0 (with `uri` if given),
    /// views and accessors.
    fn doc(&self, rest: Value, uri: Option<&str>) -> Value {
        let mut d =
            json!({"asset": {"version": "2.0"}, "bufferViews": self.views, "accessors": self.accessors});
        let mut buffer = json!({"byteLength": self.bytes.len()});
        if let Some(u) = uri {
            buffer["uri"] = json!(u);
        }
        d["buffers"] = json!([buffer]);
        for (k, v) in rest.as_object().unwrap() {
            d[k] = v.clone();
        }
        d
    }
}

fn f32_bytes(p: &[[f32; 3]]) -> Vec<u8> {
    p.iter().flatten().flat_map(|c| c.to_le_bytes()).collect()
}

/// A GLB from a JSON document and BIN chunk content.
fn glb(doc: &Value, bin: &[u8]) -> Vec<u8> {
    let mut j = serde_json::to_vec(doc).unwrap();
    while !j.len().is_multiple_of(4) {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while !b.len().is_multiple_of(4) {
        b.push(0);
    }
    let total = 12 + 8 + j.len() + if b.is_empty() { 0 } else { 8 + b.len() };
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    if !b.is_empty() {
        out.extend_from_slice(&(b.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&b);
    }
    out
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(bytes).unwrap();
    enc.finish().unwrap()
}

#[derive(Default, Debug)]
struct Collect {
    objects: Vec<(u32, ObjectInfo)>,
    tris: Vec<Triangle>,
    progress: Vec<u64>,
    total: Option<u64>,
    summary: SourceSummary,
}

impl TriangleSink for Collect {
    fn object(&mut self, id: u32, info: &ObjectInfo) -> Result<(), ImportError> {
        assert_eq!(id as usize, self.objects.len(), "ids are dense and in order");
        self.objects.push((id, info.clone()));
        Ok(())
    }
    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        assert!((t.object as usize) < self.objects.len(), "object announced before its triangles");
        self.tris.push(*t);
        Ok(())
    }
    fn progress(&mut self, done: u64) {
        self.progress.push(done);
    }
}

fn import_path(path: &Path) -> Result<Collect, ImportError> {
    let opts = ImportOptions { spill_dir: path.parent().map(Path::to_path_buf), ..Default::default() };
    let src = open_source(path, &opts)?;
    let mut c = Collect { total: src.progress_total(), ..Default::default() };
    c.summary = src.stream(&mut c)?;
    Ok(c)
}

/// Writes `files` into a temporary directory and imports the first.
fn import_files(files: &[(&str, &[u8])]) -> Result<Collect, ImportError> {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in files {
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    import_path(&dir.path().join(files[0].0))
}

fn import_glb(doc: &Value, bin: &[u8]) -> Result<Collect, ImportError> {
    import_files(&[("m.glb", &glb(doc, bin))])
}

fn import_gltf(doc: &Value, bin: &[u8]) -> Result<Collect, ImportError> {
    import_files(&[("m.gltf", &serde_json::to_vec_pretty(doc).unwrap()), ("m.bin", bin)])
}

fn one_mesh(primitive: Value) -> Value {
    json!({"meshes": [{"name": "m", "primitives": [primitive]}], "nodes": [{"name": "n", "mesh": 0}],
        "scenes": [{"nodes": [0]}]})
}

fn square(index_type: u32) -> (Bin, Value) {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let i = b.indices(&[0, 1, 2, 0, 2, 3], index_type);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": p}, "indices": i})), None);
    (b, d)
}

fn positions(c: &Collect) -> Vec<[[f64; 3]; 3]> {
    c.tris.iter().map(|t| t.positions).collect()
}

fn sq(a: usize, b: usize, c: usize) -> [[f64; 3]; 3] {
    [a, b, c].map(|i| SQUARE[i].map(f64::from))
}

fn err_text(r: Result<Collect, ImportError>) -> (String, Option<Position>) {
    let e = r.expect_err("the import should fail");
    (e.to_string(), e.position())
}

// ---- geometry ----

#[test]
fn indexed_u16_glb() {
    let (b, d) = square(USHORT);
    let c = import_glb(&d, &b.bytes).unwrap();
    assert_eq!(positions(&c), vec![sq(0, 1, 2), sq(0, 2, 3)]);
    assert_eq!(c.objects, vec![(0, ObjectInfo { name: "n".into(), color: None })]);
    assert_eq!((c.summary.objects, c.summary.vertices), (1, 4));
    assert!(c.summary.bytes > 0);
    assert_eq!(c.total, Some(2));
    assert_eq!(c.progress.last(), Some(&2));
}

#[test]
fn u8_and_u32_indices() {
    for t in [UBYTE, UINT] {
        let (b, d) = square(t);
        assert_eq!(positions(&import_glb(&d, &b.bytes).unwrap()), vec![sq(0, 1, 2), sq(0, 2, 3)]);
    }
}

#[test]
fn signed_indices_are_an_error() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let i = b.indices(&[0, 1, 2], SHORT);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": p}, "indices": i})), None);
    assert!(err_text(import_glb(&d, &b.bytes)).0.contains("must be unsigned"));
}

#[test]
fn non_indexed_triangles() {
    let mut b = Bin::default();
    let p = b.positions(&[SQUARE[0], SQUARE[1], SQUARE[2], SQUARE[0], SQUARE[2], SQUARE[3], SQUARE[1]]);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": p}})), None);
    // 7 vertices: two triangles, the stray vertex ignored with a warning.
    let c = import_glb(&d, &b.bytes).unwrap();
    assert_eq!(positions(&c), vec![sq(0, 1, 2), sq(0, 2, 3)]);
    assert_eq!(c.summary.vertices, 7);
}

#[test]
fn triangle_strip_alternates_winding() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let i = b.indices(&[0, 1, 3, 2], USHORT);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": p}, "indices": i, "mode": 5})), None);
    // Strip v0 v1 v3 v2: (v0 v1 v3), then odd (v1 v2 v3) per the spec's {i, i+2, i+1}.
    assert_eq!(positions(&import_glb(&d, &b.bytes).unwrap()), vec![sq(0, 1, 3), sq(1, 2, 3)]);
}

#[test]
fn triangle_fan_pivots_on_first_vertex() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": p}, "mode": 6})), None);
    // Spec: {v(i+1), v(i+2), v0}.
    assert_eq!(positions(&import_glb(&d, &b.bytes).unwrap()), vec![sq(1, 2, 0), sq(2, 3, 0)]);
}

#[test]
fn points_and_lines_are_skipped() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let mesh = json!({"primitives": [
        {"attributes": {"POSITION": p}, "mode": 0},
        {"attributes": {"POSITION": p}, "mode": 1},
        {"attributes": {"POSITION": p}, "mode": 6}]});
    let d = b.doc(json!({"meshes": [mesh], "nodes": [{"mesh": 0}]}), None);
    let c = import_glb(&d, &b.bytes).unwrap();
    assert_eq!(c.tris.len(), 2);
    assert_eq!(c.summary.vertices, 4);
}

#[test]
fn node_transforms_compose_exactly() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let i = b.indices(&[0, 1, 2], USHORT);
    let mesh = json!({"primitives": [{"attributes": {"POSITION": p}, "indices": i}]});
    // Parent: translate (10, 20, 30). Child: scale 2 then rotate 90 degrees about z.
    // Grandchild: matrix translating by (0, 0, 1).
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let nodes = json!([
        {"name": "parent", "translation": [10, 20, 30], "children": [1]},
        {"name": "child", "rotation": [0, 0, s, s], "scale": [2, 2, 2], "mesh": 0, "children": [2]},
        {"name": "grandchild", "matrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,1,1], "mesh": 0}
    ]);
    let d = b.doc(json!({"meshes": [mesh], "nodes": nodes, "scene": 0, "scenes": [{"nodes": [0]}]}), None);
    let c = import_glb(&d, &b.bytes).unwrap();
    assert_eq!(c.objects.iter().map(|o| o.1.name.as_str()).collect::<Vec<_>>(), ["child", "grandchild"]);
    let near = |a: [f64; 3], e: [f64; 3]| a.iter().zip(e).all(|(x, y)| (x - y).abs() < 1e-6);
    let t = c.tris[0].positions;
    assert!(
        near(t[0], [10., 20., 30.]) && near(t[1], [10., 22., 30.]) && near(t[2], [8., 22., 30.]),
        "{t:?}"
    );
    // The grandchild's (0, 0, 1) offset is in the child's frame: scaled by 2.
    let t = c.tris[1].positions;
    assert!(
        near(t[0], [10., 20., 32.]) && near(t[1], [10., 22., 32.]) && near(t[2], [8., 22., 32.]),
        "{t:?}"
    );
    // Exact in f64: a pure translation adds exactly.
    let mut b2 = Bin::default();
    let p = b2.positions(&SQUARE);
    let d = b2.doc(
        json!({"meshes": [{"primitives": [{"attributes": {"POSITION": p}}]}],
            "nodes": [{"translation": [1e6, 0.5, -3], "mesh": 0}]}),
        None,
    );
    let c = import_glb(&d, &b2.bytes).unwrap();
    assert_eq!(c.tris[0].positions, [[1e6, 0.5, -3.], [1e6 + 1., 0.5, -3.], [1e6 + 1., 1.5, -3.]]);
}

#[test]
fn two_instances_are_two_objects() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let i = b.indices(&[0, 1, 2, 0, 2, 3], UBYTE);
    let d = b.doc(
        json!({"meshes": [{"name": "shared", "primitives": [{"attributes": {"POSITION": p}, "indices": i, "material": 0}]}],
            "materials": [{"pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 1]}}],
            "nodes": [{"mesh": 0}, {"mesh": 0, "translation": [5, 0, 0]}], "scenes": [{"nodes": [0, 1]}]}),
        None,
    );
    let c = import_glb(&d, &b.bytes).unwrap();
    let red = Some(Rgba8([255, 0, 0, 255]));
    assert_eq!(
        c.objects,
        vec![
            (0, ObjectInfo { name: "shared".into(), color: red }),
            (1, ObjectInfo { name: "shared".into(), color: red })
        ]
    );
    assert_eq!(c.tris.iter().map(|t| t.object).collect::<Vec<_>>(), [0, 0, 1, 1]);
    assert_eq!(c.tris[2].positions[0], [5., 0., 0.]);
    assert_eq!(c.summary.vertices, 8);
    assert_eq!(c.total, Some(4));
}

#[test]
fn primitives_with_different_materials_split_the_object() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let i = b.indices(&[0, 1, 2], UBYTE);
    let j = b.indices(&[0, 2, 3], UBYTE);
    let mesh = json!({"name": "m", "primitives": [
        {"attributes": {"POSITION": p}, "indices": i, "material": 0},
        {"attributes": {"POSITION": p}, "indices": j, "material": 1},
        {"attributes": {"POSITION": p}, "indices": i, "material": 0}]});
    let materials = json!([
        {"name": "paint", "pbrMetallicRoughness": {"baseColorFactor": [0.214, 0.214, 0.214, 0.5]}},
        {"name": "glossy", "extensions": {"KHR_materials_pbrSpecularGlossiness": {"diffuseFactor": [0, 0, 1, 1]}}}
    ]);
    let d =
        b.doc(json!({"meshes": [mesh], "materials": materials, "nodes": [{"name": "n", "mesh": 0}]}), None);
    let c = import_glb(&d, &b.bytes).unwrap();
    // Linear 0.214 is sRGB 0.4999 (127).
    assert_eq!(
        c.objects,
        vec![
            (0, ObjectInfo { name: "n [paint]".into(), color: Some(Rgba8([127, 127, 127, 128])) }),
            (1, ObjectInfo { name: "n [glossy]".into(), color: Some(Rgba8([0, 0, 255, 255])) }),
        ]
    );
    assert_eq!(c.tris.iter().map(|t| t.object).collect::<Vec<_>>(), [0, 1, 0]);
}

#[test]
fn mirrored_transform_flips_winding() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let n = b.vec3(&[[0., 0., 1.]; 4]);
    let d = b.doc(
        json!({"meshes": [{"primitives": [{"attributes": {"POSITION": p, "NORMAL": n}}]}],
            "nodes": [{"scale": [-1, 1, 1], "mesh": 0}]}),
        None,
    );
    let c = import_glb(&d, &b.bytes).unwrap();
    let t = c.tris[0];
    assert_eq!(t.positions, [[0., 0., 0.], [-1., 1., 0.], [-1., 0., 0.]]);
    // Counter-clockwise seen from +z, as the original was: the normal (+z) agrees with the winding.
    let [a, bb, cc] = t.positions;
    let z = (bb[0] - a[0]) * (cc[1] - a[1]) - (bb[1] - a[1]) * (cc[0] - a[0]);
    assert!(z > 0.0);
    assert_eq!(t.normals, Some([[0., 0., 1.]; 3]));
}

#[test]
fn normals_use_the_inverse_transpose() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE[..3]);
    let n = b.vec3(&[[1., 1., 0.]; 3]);
    let d = b.doc(
        json!({"meshes": [{"primitives": [{"attributes": {"POSITION": p, "NORMAL": n}}]}],
            "nodes": [{"scale": [2, 1, 1], "mesh": 0}]}),
        None,
    );
    let c = import_glb(&d, &b.bytes).unwrap();
    let nn = c.tris[0].normals.unwrap()[0];
    let l = 1.25f32.sqrt();
    assert!((nn[0] - 0.5 / l).abs() < 1e-6 && (nn[1] - 1.0 / l).abs() < 1e-6, "{nn:?}");
}

#[test]
fn interleaved_byte_stride() {
    // position (12 bytes) + normal (12 bytes) interleaved, stride 24.
    let mut b = Bin::default();
    let mut data = Vec::new();
    for p in SQUARE {
        data.extend(f32_bytes(&[p]));
        data.extend(f32_bytes(&[[0., 0., 1.]]));
    }
    let v = b.view(&data, Some(24));
    let p = b.accessor(json!({"bufferView": v, "componentType": FLOAT, "type": "VEC3", "count": 4}));
    let n = b.accessor(
        json!({"bufferView": v, "byteOffset": 12, "componentType": FLOAT, "type": "VEC3", "count": 4}),
    );
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": p, "NORMAL": n}, "mode": 6})), None);
    let c = import_glb(&d, &b.bytes).unwrap();
    assert_eq!(positions(&c), vec![sq(1, 2, 0), sq(2, 3, 0)]);
    assert_eq!(c.tris[0].normals, Some([[0., 0., 1.]; 3]));
}

#[test]
fn sparse_accessor_substitutes_values() {
    let mut b = Bin::default();
    let base = [[0., 0., 0.], [1., 0., 0.], [9., 9., 9.]];
    let p = b.positions(&base);
    let idx = b.view(&[2u8, 0, 0, 0], None);
    let val = b.view(&f32_bytes(&[[1., 1., 0.]]), None);
    b.accessors[p]["sparse"] = json!({"count": 1, "indices": {"bufferView": idx, "componentType": UBYTE}, "values": {"bufferView": val}});
    // Sparse over zeros (no bufferView): only vertex 1 and 2 are set.
    let val2 = b.view(&f32_bytes(&[[1., 0., 0.], [1., 1., 0.]]), None);
    let idx2 = b.view(&[1u8, 0, 2, 0], None);
    let q = b.accessor(json!({"componentType": FLOAT, "type": "VEC3", "count": 3, "sparse":
        {"count": 2, "indices": {"bufferView": idx2, "componentType": USHORT}, "values": {"bufferView": val2}}}));
    let mesh = json!({"primitives": [{"attributes": {"POSITION": p}}, {"attributes": {"POSITION": q}}]});
    let d = b.doc(json!({"meshes": [mesh], "nodes": [{"mesh": 0}]}), None);
    let c = import_glb(&d, &b.bytes).unwrap();
    assert_eq!(positions(&c), vec![sq(0, 1, 2), sq(0, 1, 2)]);
}

#[test]
fn sparse_index_out_of_range_is_an_error() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE[..3]);
    let idx = b.view(&[7u8], None);
    let val = b.view(&f32_bytes(&[[1., 1., 0.]]), None);
    b.accessors[p]["sparse"] = json!({"count": 1, "indices": {"bufferView": idx, "componentType": UBYTE}, "values": {"bufferView": val}});
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": p}})), None);
    let (m, pos) = err_text(import_glb(&d, &b.bytes));
    assert!(m.contains("sparse index 7") && m.contains("accessors[0]"), "{m}");
    assert_eq!(pos, Some(Position::File));
}

#[test]
fn quantized_positions_and_normals() {
    // KHR_mesh_quantization: positions as normalized u16 and as plain i16, normals as normalized i8.
    let mut b = Bin::default();
    let q: Vec<u8> = [[0u16, 0, 0], [65535, 0, 0], [65535, 65535, 0]]
        .iter()
        .flatten()
        .flat_map(|c| c.to_le_bytes())
        .collect();
    // u16 x3 = 6 bytes; vertex attributes must be 4-aligned: stride 8.
    let mut padded = Vec::new();
    for v in q.chunks(6) {
        padded.extend_from_slice(v);
        padded.extend_from_slice(&[0, 0]);
    }
    let v = b.view(&padded, Some(8));
    let p = b.accessor(
        json!({"bufferView": v, "componentType": USHORT, "normalized": true, "type": "VEC3", "count": 3}),
    );
    let s: Vec<u8> = [[0i16, 0, 0, 0], [100, 0, 0, 0], [100, -50, 0, 0]]
        .iter()
        .flatten()
        .flat_map(|c| c.to_le_bytes())
        .collect();
    let v = b.view(&s, Some(8));
    let p2 = b.accessor(json!({"bufferView": v, "componentType": SHORT, "type": "VEC3", "count": 3}));
    let n = b.view(&[0u8, 0, 127, 0, 0, 0, 0x81, 0, 0, 0x80, 0, 0], Some(4));
    let n = b.accessor(
        json!({"bufferView": n, "componentType": BYTE, "normalized": true, "type": "VEC3", "count": 3}),
    );
    let mesh = json!({"primitives": [{"attributes": {"POSITION": p, "NORMAL": n}}, {"attributes": {"POSITION": p2}}]});
    let mut d = b.doc(json!({"meshes": [mesh], "nodes": [{"mesh": 0}]}), None);
    d["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
    d["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
    let c = import_glb(&d, &b.bytes).unwrap();
    assert_eq!(c.tris[0].positions, [[0., 0., 0.], [1., 0., 0.], [1., 1., 0.]]);
    // -127 and -128 both map to -1.
    assert_eq!(c.tris[0].normals, Some([[0., 0., 1.], [0., 0., -1.], [0., -1., 0.]]));
    assert_eq!(c.tris[1].positions, [[0., 0., 0.], [100., 0., 0.], [100., -50., 0.]]);
}

#[test]
fn vertex_colors_float_and_normalized_u8() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE[..3]);
    let c3 = b.vec3(&[[1., 0., 0.], [0., 1., 0.], [0.214, 0.214, 0.214]]);
    let c4 = b.view(&[255, 0, 0, 255, 0, 255, 0, 128, 0, 0, 255, 0], None);
    let c4 = b.accessor(
        json!({"bufferView": c4, "componentType": UBYTE, "normalized": true, "type": "VEC4", "count": 3}),
    );
    let mesh = json!({"primitives": [{"attributes": {"POSITION": p, "COLOR_0": c3}}, {"attributes": {"POSITION": p, "COLOR_0": c4}}]});
    let d = b.doc(json!({"meshes": [mesh], "nodes": [{"mesh": 0}]}), None);
    let c = import_glb(&d, &b.bytes).unwrap();
    assert_eq!(
        c.tris[0].colors,
        Some([Rgba8([255, 0, 0, 255]), Rgba8([0, 255, 0, 255]), Rgba8([127, 127, 127, 255])])
    );
    assert_eq!(
        c.tris[1].colors,
        Some([Rgba8([255, 0, 0, 255]), Rgba8([0, 255, 0, 128]), Rgba8([0, 0, 255, 0])])
    );
}

#[test]
fn gpu_instancing_makes_one_object_per_instance() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE[..3]);
    let t = b.vec3(&[[0., 0., 0.], [10., 0., 0.]]);
    let mut d = b.doc(
        json!({"meshes": [{"primitives": [{"attributes": {"POSITION": p}}]}],
            "nodes": [{"name": "tree", "mesh": 0, "translation": [0, 0, 5],
                "extensions": {"EXT_mesh_gpu_instancing": {"attributes": {"TRANSLATION": t}}}}]}),
        None,
    );
    d["extensionsRequired"] = json!(["EXT_mesh_gpu_instancing"]);
    let c = import_glb(&d, &b.bytes).unwrap();
    assert_eq!(c.objects.iter().map(|o| o.1.name.as_str()).collect::<Vec<_>>(), ["tree[0]", "tree[1]"]);
    assert_eq!(c.tris[1].positions[1], [11., 0., 5.]);
    assert_eq!(c.total, Some(2));
}

// ---- containers and buffers ----

#[test]
fn gltf_with_external_bin() {
    let (b, _) = square(USHORT);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": 0}, "indices": 1})), Some("my%20data.bin"));
    let c = import_files(&[("m.gltf", &serde_json::to_vec(&d).unwrap()), ("my data.bin", &b.bytes)]).unwrap();
    assert_eq!(positions(&c), vec![sq(0, 1, 2), sq(0, 2, 3)]);
}

#[test]
fn gltf_with_data_uri() {
    let (b, _) = square(UINT);
    let uri = format!("data:application/octet-stream;base64,{}", base64(&b.bytes));
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": 0}, "indices": 1})), Some(&uri));
    let c = import_files(&[("m.gltf", &serde_json::to_vec(&d).unwrap())]).unwrap();
    assert_eq!(positions(&c), vec![sq(0, 1, 2), sq(0, 2, 3)]);
    // Also in a GLB, and through Input::from_bytes (no file on disk).
    let bytes = glb(&d, &[]);
    let src =
        open_input(Input::from_bytes(Path::new("/nonexistent/m.glb"), bytes), &ImportOptions::default());
    let mut c = Collect::default();
    src.unwrap().stream(&mut c).unwrap();
    assert_eq!(positions(&c), vec![sq(0, 1, 2), sq(0, 2, 3)]);
}

fn base64(data: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in data.chunks(3) {
        let v = (c[0] as u32) << 16 | (*c.get(1).unwrap_or(&0) as u32) << 8 | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            s.push(if k <= c.len() { A[(v >> (18 - 6 * k) & 63) as usize] as char } else { '=' });
        }
    }
    s
}

#[test]
fn gzipped_glb_and_gltf() {
    let (b, d) = square(USHORT);
    let c = import_files(&[("m.glb.gz", &gzip(&glb(&d, &b.bytes)))]).unwrap();
    assert_eq!(positions(&c), vec![sq(0, 1, 2), sq(0, 2, 3)]);
    // Progress: the compressed bytes first, then triangles on top.
    let total = c.total.unwrap();
    assert_eq!(c.progress.last(), Some(&total));
    assert!(total > 2);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": 0}, "indices": 1})), Some("m.bin"));
    let c =
        import_files(&[("m.gltf.gz", &gzip(&serde_json::to_vec(&d).unwrap())), ("m.bin", &b.bytes)]).unwrap();
    assert_eq!(c.tris.len(), 2);
    // In memory, gzip'ed.
    let src = open_input(
        Input::from_bytes(Path::new("mem.glb.gz"), gzip(&glb(&d_without_uri(&b), &b.bytes))),
        &ImportOptions::default(),
    );
    let mut c = Collect::default();
    src.unwrap().stream(&mut c).unwrap();
    assert_eq!(c.tris.len(), 2);
}

fn d_without_uri(b: &Bin) -> Value {
    b.doc(one_mesh(json!({"attributes": {"POSITION": 0}, "indices": 1})), None)
}

#[test]
fn scene_selection() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE[..3]);
    let meshes = json!([{"name": "a", "primitives": [{"attributes": {"POSITION": p}}]},
        {"name": "b", "primitives": [{"attributes": {"POSITION": p}}]}]);
    let nodes = json!([{"mesh": 0, "children": [2]}, {"mesh": 1}, {"mesh": 1}]);
    let names = |d: Value| {
        let c = import_glb(&d, &b.bytes).unwrap();
        c.objects.into_iter().map(|o| o.1.name).collect::<Vec<_>>()
    };
    // Default scene 1.
    assert_eq!(
        names(b.doc(
            json!({"meshes": meshes, "nodes": nodes, "scene": 1, "scenes": [{"nodes": [0]}, {"nodes": [1]}]}),
            None
        )),
        ["b"]
    );
    // No default: scene 0.
    assert_eq!(
        names(b.doc(
            json!({"meshes": meshes, "nodes": nodes, "scenes": [{"nodes": [0]}, {"nodes": [1]}]}),
            None
        )),
        ["a", "b"]
    );
    // No scenes: the parentless nodes 0 and 1 (node 2 is a child of 0).
    assert_eq!(names(b.doc(json!({"meshes": meshes, "nodes": nodes}), None)), ["a", "b", "b"]);
    // No nodes: every mesh once.
    assert_eq!(names(b.doc(json!({"meshes": meshes}), None)), ["a", "b"]);
}

#[test]
fn deep_hierarchy_does_not_recurse() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE[..3]);
    let n = 20_000;
    let mut nodes: Vec<Value> =
        (0..n - 1).map(|i| json!({"translation": [1, 0, 0], "children": [i + 1]})).collect();
    nodes.push(json!({"translation": [1, 0, 0], "mesh": 0}));
    let d = b.doc(json!({"meshes": [{"primitives": [{"attributes": {"POSITION": p}}]}], "nodes": nodes, "scenes": [{"nodes": [0]}]}), None);
    let c = import_glb(&d, &b.bytes).unwrap();
    assert_eq!(c.tris[0].positions[0], [n as f64, 0., 0.]);
}

// ---- meshopt ----

/// A document whose POSITION, NORMAL and index views are EXT_meshopt_compression streams in
/// buffer 0, with buffer 1 the data-less fallback.
fn meshopt_doc(mode_indices: &str, filter_positions: bool) -> (Value, Vec<u8>) {
    let pos: Vec<[f32; 3]> = vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.], [0.5, 0.5, 1.]];
    let ix: Vec<u32> = vec![0, 1, 2, 0, 2, 3, 2, 4, 3];
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let mut push = |data: Vec<u8>, stride: usize, count: usize, mode: &str, filter: Option<&str>| {
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let mut ext = json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": data.len(), "byteStride": stride,
            "count": count, "mode": mode});
        if let Some(f) = filter {
            ext["filter"] = json!(f);
        }
        bin.extend_from_slice(&data);
        let mut v = json!({"buffer": 1, "byteLength": stride * count, "extensions": {"EXT_meshopt_compression": ext}});
        if mode == "ATTRIBUTES" {
            v["byteStride"] = json!(stride);
        }
        views.push(v);
    };
    if filter_positions {
        let e = meshopt::encode_filter_exp::<3>(&pos, 20, meshopt::EncodeExpMode::Separate);
        push(meshopt::encode_vertex_buffer(&e).unwrap(), 12, pos.len(), "ATTRIBUTES", Some("EXPONENTIAL"));
    } else {
        push(meshopt::encode_vertex_buffer(&pos).unwrap(), 12, pos.len(), "ATTRIBUTES", None);
    }
    let normals: Vec<[f32; 4]> = vec![[0., 0., 1., 0.]; pos.len()];
    let oct: Vec<[i8; 4]> = meshopt::encode_filter_oct(&normals, 8);
    push(meshopt::encode_vertex_buffer(&oct).unwrap(), 4, pos.len(), "ATTRIBUTES", Some("OCTAHEDRAL"));
    let ix16: Vec<u16> = ix.iter().map(|&i| i as u16).collect();
    let enc = if mode_indices == "TRIANGLES" {
        meshopt::encode_index_buffer(&ix, pos.len()).unwrap()
    } else {
        meshopt::encode_index_sequence(&ix, pos.len()).unwrap()
    };
    let _ = ix16;
    push(enc, 2, ix.len(), mode_indices, None);
    let d = json!({
        "asset": {"version": "2.0"},
        "extensionsUsed": ["EXT_meshopt_compression", "KHR_mesh_quantization"],
        "extensionsRequired": ["EXT_meshopt_compression", "KHR_mesh_quantization"],
        "buffers": [{"byteLength": bin.len()},
            {"byteLength": 1000, "extensions": {"EXT_meshopt_compression": {"fallback": true}}}],
        "bufferViews": views,
        "accessors": [
            {"bufferView": 0, "componentType": FLOAT, "type": "VEC3", "count": pos.len()},
            {"bufferView": 1, "componentType": BYTE, "normalized": true, "type": "VEC3", "count": pos.len()},
            {"bufferView": 2, "componentType": USHORT, "type": "SCALAR", "count": ix.len()}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "NORMAL": 1}, "indices": 2}]}],
        "nodes": [{"mesh": 0}]
    });
    (d, bin)
}

#[test]
fn meshopt_triangles_and_attributes() {
    for (mode, filter) in [("TRIANGLES", false), ("INDICES", false), ("TRIANGLES", true)] {
        let (d, bin) = meshopt_doc(mode, filter);
        let c = import_glb(&d, &bin).unwrap();
        assert_eq!(c.tris.len(), 3, "{mode}");
        // The triangle codec may rotate a triangle's vertices; compare as rotation-free sets.
        let mut got: Vec<Vec<[i64; 3]>> = c
            .tris
            .iter()
            .map(|t| {
                let mut v: Vec<[i64; 3]> =
                    t.positions.iter().map(|p| p.map(|c| (c * 1e4).round() as i64)).collect();
                let k = (0..3).min_by_key(|&k| v[k]).unwrap();
                v.rotate_left(k);
                v
            })
            .collect();
        got.sort();
        assert_eq!(got.len(), 3);
        assert!(got.contains(&vec![[0, 0, 0], [10000, 0, 0], [10000, 10000, 0]]), "{mode}: {got:?}");
        assert!(
            got.contains(&vec![[0, 10000, 0], [10000, 10000, 0], [5000, 5000, 10000]]),
            "{mode}: {got:?}"
        );
        assert_eq!(c.tris[0].normals.unwrap()[0], [0., 0., 1.], "{mode}");
    }
}

#[test]
fn meshopt_corrupt_stream_is_an_error() {
    let (d, mut bin) = meshopt_doc("TRIANGLES", false);
    for b in bin.iter_mut().take(40) {
        *b = 0xff;
    }
    let (m, _) = err_text(import_glb(&d, &bin));
    assert!(m.contains("EXT_meshopt_compression") && m.contains("decoding failed"), "{m}");
}

#[test]
fn meshopt_bad_parameters_are_errors() {
    let cases: [(&str, Value, &str); 4] = [
        ("byteStride", json!(6), "multiple of 4"),
        ("count", json!(1u64 << 40), "cannot come from"),
        ("mode", json!("BOGUS"), "unknown"),
        ("filter", json!("QUATERNION"), "cannot be used"),
    ];
    for (key, value, expect) in cases {
        let (mut d, bin) = meshopt_doc("TRIANGLES", false);
        d["bufferViews"][0]["extensions"]["EXT_meshopt_compression"][key] = value;
        let (m, _) = err_text(import_glb(&d, &bin));
        assert!(m.contains(expect), "{key}: {m}");
    }
    // TRIANGLES with a count that is not a multiple of 3 must not reach the decoder's assert.
    let (mut d, bin) = meshopt_doc("TRIANGLES", false);
    d["bufferViews"][2]["extensions"]["EXT_meshopt_compression"]["count"] = json!(8);
    assert!(err_text(import_glb(&d, &bin)).0.contains("multiple of 3"));
}

// ---- broken files ----

#[test]
fn truncated_glb_header() {
    let (m, p) = err_text(import_files(&[("m.glb", b"glTF\x02\0\0")]));
    assert!(m.contains("truncated GLB header"), "{m}");
    assert_eq!(p, Some(Position::Byte(7)));
}

#[test]
fn glb_shorter_than_its_header_says() {
    let (b, d) = square(USHORT);
    let mut g = glb(&d, &b.bytes);
    g.truncate(g.len() - 10);
    let (m, p) = err_text(import_files(&[("m.glb", &g)]));
    assert!(m.contains("truncated GLB"), "{m}");
    assert_eq!(p, Some(Position::Byte(g.len() as u64)));
    // The same truncated file gzip'ed: found after decompression.
    let (m, _) = err_text(import_files(&[("m.glb.gz", &gzip(&g))]));
    assert!(m.contains("truncated GLB"), "{m}");
}

#[test]
fn bad_chunk_lengths_and_types() {
    let (b, d) = square(USHORT);
    let good = glb(&d, &b.bytes);
    let json_len = u32::from_le_bytes(good[12..16].try_into().unwrap()) as usize;
    // JSON chunk longer than the file says.
    let mut g = good.clone();
    g[12..16].copy_from_slice(&(good.len() as u32).to_le_bytes());
    let (m, p) = err_text(import_files(&[("m.glb", &g)]));
    assert!(m.contains("JSON chunk length"), "{m}");
    assert_eq!(p, Some(Position::Byte(12)));
    // First chunk not JSON.
    let mut g = good.clone();
    g[16..20].copy_from_slice(b"BIN\0");
    assert_eq!(err_text(import_files(&[("m.glb", &g)])).1, Some(Position::Byte(16)));
    // BIN chunk longer than the file.
    let mut g = good.clone();
    let at = 20 + json_len;
    g[at..at + 4].copy_from_slice(&1_000_000u32.to_le_bytes());
    let (m, p) = err_text(import_files(&[("m.glb", &g)]));
    assert!(m.contains("BIN chunk length"), "{m}");
    assert_eq!(p, Some(Position::Byte(at as u64)));
    // BIN chunk shorter than buffers[0].byteLength.
    let mut d2 = d.clone();
    d2["buffers"][0]["byteLength"] = json!(b.bytes.len() + 100);
    let (m, _) = err_text(import_glb(&d2, &b.bytes));
    assert!(m.contains("buffers[0].byteLength"), "{m}");
    // Version 1 and an unknown version.
    let mut g = good.clone();
    g[4] = 1;
    assert!(matches!(import_files(&[("m.glb", &g)]), Err(ImportError::Unsupported { .. })));
    g[4] = 3;
    assert_eq!(err_text(import_files(&[("m.glb", &g)])).1, Some(Position::Byte(4)));
    // Declared length shorter than the header.
    let mut g = good.clone();
    g[8..12].copy_from_slice(&4u32.to_le_bytes());
    assert_eq!(err_text(import_files(&[("m.glb", &g)])).1, Some(Position::Byte(8)));
}

#[test]
fn json_errors_name_line_or_byte() {
    let (m, p) = err_text(import_files(&[(
        "m.gltf",
        b"{\n  \"asset\": {\"version\": \"2.0\"},\n  \"nodes\": [ {\"mesh\": -1} ]\n}",
    )]));
    assert_eq!(p, Some(Position::Line(3)), "{m}");
    assert!(m.contains("invalid glTF JSON"), "{m}");
    let (m, p) = err_text(import_files(&[("m.gltf", b"{\"asset\": {\"version\": \"2.0\"}, ")]));
    assert_eq!(p, Some(Position::Line(1)), "{m}");
    // In a GLB: a byte offset inside the JSON chunk.
    let mut g = glb(&json!({"asset": {"version": "2.0"}, "nodes": "x"}), &[]);
    let (m, p) = err_text(import_files(&[("m.glb", &g)]));
    assert!(matches!(p, Some(Position::Byte(b)) if b > 20 && b < g.len() as u64), "{m} {p:?}");
    g[20] = b'[';
    assert!(err_text(import_files(&[("m.glb", &g)])).0.contains("invalid glTF JSON"));
    // A missing required field.
    let (m, _) = err_text(import_files(&[("m.gltf", b"{\"nodes\": []}")]));
    assert!(m.contains("asset"), "{m}");
}

#[test]
fn gltf_1_is_unsupported() {
    let d = br#"{"asset": {"version": "1.0"}, "meshes": {"m": {"primitives": []}}}"#;
    let e = import_files(&[("m.gltf", d)]).unwrap_err();
    assert!(matches!(e, ImportError::Unsupported { .. }) && e.to_string().contains("1.0"), "{e}");
}

#[test]
fn required_extensions() {
    let (b, mut d) = square(USHORT);
    d["extensionsRequired"] = json!(["KHR_draco_mesh_compression"]);
    let e = import_glb(&d, &b.bytes).unwrap_err();
    assert!(matches!(e, ImportError::Unsupported { .. }) && e.to_string().contains("Draco"), "{e}");
    d["extensionsRequired"] = json!(["EXT_something_new"]);
    assert!(import_glb(&d, &b.bytes).unwrap_err().to_string().contains("EXT_something_new"));
    d["extensionsRequired"] = json!(["KHR_materials_emissive_strength", "KHR_texture_transform"]);
    assert!(import_glb(&d, &b.bytes).is_ok());
}

#[test]
fn draco_without_fallback_is_unsupported() {
    let mut b = Bin::default();
    let p = b.accessor(json!({"componentType": FLOAT, "type": "VEC3", "count": 3}));
    let prim = json!({"attributes": {"POSITION": p},
        "extensions": {"KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0}}}});
    let d = b.doc(one_mesh(prim), None);
    let e = import_glb(&d, &[0; 4]).unwrap_err();
    assert!(matches!(e, ImportError::Unsupported { .. }) && e.to_string().contains("Draco"), "{e}");
}

#[test]
fn accessor_outside_its_view_or_buffer() {
    let (b, mut d) = square(USHORT);
    d["accessors"][0]["byteOffset"] = json!(4);
    let (m, p) = err_text(import_glb(&d, &b.bytes));
    assert!(m.contains("accessors[0]") && m.contains("bufferViews[0] has 48"), "{m}");
    assert_eq!(p, Some(Position::File));
    let (b, mut d) = square(USHORT);
    d["bufferViews"][1]["byteLength"] = json!(1000);
    d["accessors"][1]["count"] = json!(400);
    let (m, _) = err_text(import_glb(&d, &b.bytes));
    assert!(m.contains("bufferViews[1]") && m.contains("outside buffers[0]"), "{m}");
    // byteStride smaller than an element.
    let (b, mut d) = square(USHORT);
    d["bufferViews"][0]["byteStride"] = json!(4);
    assert!(err_text(import_glb(&d, &b.bytes)).0.contains("smaller than an element"));
}

#[test]
fn absurd_counts_fail_before_allocating() {
    let (b, mut d) = square(USHORT);
    d["accessors"][0]["count"] = json!(1u64 << 60);
    let (m, _) = err_text(import_glb(&d, &b.bytes));
    assert!(m.contains("too large") || m.contains("need"), "{m}");
    let (b, mut d) = square(USHORT);
    d["accessors"][0]["count"] = json!(u64::MAX);
    assert!(err_text(import_glb(&d, &b.bytes)).0.contains("accessors[0]"));
    // Sparse over zeros with a huge count.
    let (b, mut d) = square(USHORT);
    d["accessors"][0] = json!({"componentType": FLOAT, "type": "VEC3", "count": 1u64 << 40, "sparse":
        {"count": 1, "indices": {"bufferView": 1, "componentType": USHORT}, "values": {"bufferView": 0}}});
    assert!(err_text(import_glb(&d, &b.bytes)).0.contains("implausibly large"));
}

#[test]
fn index_out_of_range() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let i = b.indices(&[0, 1, 4], USHORT);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": p}, "indices": i})), None);
    let (m, _) = err_text(import_glb(&d, &b.bytes));
    assert!(
        m.contains("element 2 = 4 is out of range (4 vertices)") && m.contains("meshes[0].primitives[0]"),
        "{m}"
    );
}

#[test]
fn missing_buffer_file() {
    let (b, _) = square(USHORT);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": 0}, "indices": 1})), Some("gone.bin"));
    let (m, _) = err_text(import_files(&[("m.gltf", &serde_json::to_vec(&d).unwrap())]));
    assert!(m.contains("buffers[0]") && m.contains("gone.bin"), "{m}");
    // A .bin shorter than byteLength.
    let (m, _) =
        err_text(import_files(&[("m.gltf", &serde_json::to_vec(&d).unwrap()), ("gone.bin", &b.bytes[..8])]));
    assert!(m.contains("has 8 bytes but byteLength is"), "{m}");
    // No uri in a .gltf.
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": 0}, "indices": 1})), None);
    assert!(err_text(import_gltf(&d, &b.bytes)).0.contains("buffers[0] has no uri"));
    // A remote URI.
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": 0}})), Some("https://example.com/a.bin"));
    let e = import_gltf(&d, &b.bytes).unwrap_err();
    assert!(matches!(e, ImportError::Unsupported { .. }), "{e}");
}

#[test]
fn bad_data_uris() {
    let (b, _) = square(USHORT);
    let bad = |uri: &str| {
        let d = b.doc(one_mesh(json!({"attributes": {"POSITION": 0}, "indices": 1})), Some(uri));
        err_text(import_files(&[("m.gltf", &serde_json::to_vec(&d).unwrap())])).0
    };
    let mut enc = base64(&b.bytes);
    assert!(bad(&format!("data:application/octet-stream;base64,{}", &enc[..8])).contains("holds 6 bytes"));
    enc.replace_range(4..5, "*");
    assert!(bad(&format!("data:application/octet-stream;base64,{enc}")).contains("invalid base64"));
    assert!(bad("data:application/octet-stream,abc").contains("only base64"));
}

#[test]
fn nan_positions_and_transforms() {
    let mut b = Bin::default();
    let p = b.positions(&[[0., 0., 0.], [f32::NAN, 0., 0.], [1., 1., 0.]]);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": p}})), None);
    let (m, _) = err_text(import_glb(&d, &b.bytes));
    assert!(m.contains("vertex 1 is not finite"), "{m}");
    // A NaN in a node matrix.
    let (b, mut d) = square(USHORT);
    d["nodes"][0]["matrix"] = json!([1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1e39]);
    let (m, _) = err_text(import_glb(&d, &b.bytes));
    assert!(m.contains("nodes[0].matrix is not finite"), "{m}");
    // Finite in the file, infinite in the world: ten nested scales of 1e38 overflow f64.
    let mut b = Bin::default();
    let p = b.positions(&[[0., 0., 0.], [3e38, 0., 0.], [1., 1., 0.]]);
    let mut nodes: Vec<Value> =
        (0..10).map(|i| json!({"scale": [1e38, 1, 1], "children": [i + 1]})).collect();
    nodes.push(json!({"mesh": 0}));
    let d = b.doc(
        json!({"meshes": [{"primitives": [{"attributes": {"POSITION": p}}]}], "nodes": nodes, "scenes": [{"nodes": [0]}]}),
        None,
    );
    let (m, _) = err_text(import_glb(&d, &b.bytes));
    assert!(m.contains("not finite in world space"), "{m}");
}

#[test]
fn node_cycles_and_shared_children() {
    let (b, mut d) = square(USHORT);
    d["nodes"] = json!([{"mesh": 0, "children": [1]}, {"children": [0]}]);
    let (m, _) = err_text(import_glb(&d, &b.bytes));
    assert!(m.contains("reached twice"), "{m}");
    // No scenes and every node has a parent: nothing to draw, but no loop either.
    d.as_object_mut().unwrap().remove("scenes");
    assert_eq!(import_glb(&d, &b.bytes).unwrap().tris.len(), 0);
    d["nodes"] = json!([{"children": [2]}, {"children": [2]}, {"mesh": 0}]);
    d["scenes"] = json!([{"nodes": [0, 1]}]);
    assert!(err_text(import_glb(&d, &b.bytes)).0.contains("nodes[1].children[0]: nodes[2] is reached twice"));
    d["nodes"] = json!([{"mesh": 0, "children": [0]}]);
    assert!(err_text(import_glb(&d, &b.bytes)).0.contains("reached twice"));
}

#[test]
fn dangling_references() {
    let (b, d) = square(USHORT);
    let cases: [(&str, Value, &str); 6] = [
        ("nodes", json!([{"mesh": 3}]), "meshes[3] does not exist"),
        ("scene", json!(5), "scene 5 does not exist"),
        ("scenes", json!([{"nodes": [9]}]), "nodes[9] does not exist"),
        ("meshes", json!([{"primitives": [{"attributes": {"POSITION": 9}}]}]), "accessors[9] does not exist"),
        ("meshes", json!([{"primitives": [{"attributes": {"NORMAL": 0}}]}]), "no POSITION"),
        ("meshes", json!([{"primitives": [{"attributes": {"POSITION": 0}, "mode": 9}]}]), "mode is invalid"),
    ];
    for (key, value, expect) in cases {
        let mut d = d.clone();
        d[key] = value;
        let (m, _) = err_text(import_glb(&d, &b.bytes));
        assert!(m.contains(expect), "{key}: {m}");
    }
    let mut d2 = d.clone();
    d2["accessors"][0]["bufferView"] = json!(7);
    assert!(err_text(import_glb(&d2, &b.bytes)).0.contains("bufferViews[7] does not exist"));
}

#[test]
fn attribute_count_mismatch() {
    let mut b = Bin::default();
    let p = b.positions(&SQUARE);
    let n = b.vec3(&[[0., 0., 1.]; 3]);
    let d = b.doc(one_mesh(json!({"attributes": {"POSITION": p, "NORMAL": n}})), None);
    assert!(err_text(import_glb(&d, &b.bytes))
        .0
        .contains("NORMAL (accessors[1]) has 3 elements but POSITION has 4"));
}

#[test]
fn paths_in_messages_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path: PathBuf = dir.path().join("broken.glb");
    std::fs::write(&path, b"glTF\x02\0\0\0\x10\0\0\0").unwrap();
    let e = import_path(&path).unwrap_err();
    assert!(e.to_string().contains("broken.glb"), "{e}");
}

#[test]
fn scenes_without_nodes_and_a_dangling_default_scene_are_empty_not_errors() {
    // As in assimp's TestNoRootNode models: `scenes[0].nodes` is optional in glTF 2.0.
    let c =
        import_files(&[("m.gltf", br#"{"asset": {"version": "2.0"}, "scene": 0, "scenes": [{}]}"#)]).unwrap();
    assert_eq!((c.tris.len(), c.objects.len()), (0, 0));
    let c = import_files(&[("m.gltf", br#"{"asset": {"version": "2.0"}, "scene": 0}"#)]).unwrap();
    assert_eq!(c.tris.len(), 0);
    // With scenes present, a bad default scene stays an error.
    let e = import_files(&[("m.gltf", br#"{"asset": {"version": "2.0"}, "scene": 1, "scenes": [{}]}"#)]);
    assert!(err_text(e).0.contains("scene 1 does not exist"));
}

#[test]
fn gltf_1_with_numeric_version_is_unsupported() {
    let d = br#"{"asset": {"version": 1}, "accessors": {"a": {}}}"#;
    let e = import_files(&[("m.gltf", d)]).unwrap_err();
    assert!(matches!(e, ImportError::Unsupported { .. }) && e.to_string().contains("version 1"), "{e}");
}

#[test]
fn every_corrupted_byte_is_an_error_or_a_result_never_a_panic() {
    let (b, d) = square(USHORT);
    let (md, mbin) = meshopt_doc("TRIANGLES", true);
    for (name, good) in [("plain.glb", glb(&d, &b.bytes)), ("meshopt.glb", glb(&md, &mbin))] {
        for at in 0..good.len() {
            for value in [0x00, 0xff, good[at] ^ 0x01, b'9'] {
                let mut bytes = good.clone();
                bytes[at] = value;
                let path = PathBuf::from(format!("/nonexistent/{name}"));
                if let Ok(src) = open_input(Input::from_bytes(&path, bytes), &ImportOptions::default()) {
                    let _ = src.stream(&mut Collect::default());
                }
            }
        }
    }
}

/// Regression: `"uri": "/etc/passwd"` was read as vertex data. A buffer URI must name a file
/// inside the glTF file's folder; absolute paths, `..` that climbs out (also percent-encoded)
/// and other schemes are refused with the file and the URI named.
#[test]
fn buffer_uris_outside_the_folder_are_refused() {
    let (b, _) = square(USHORT);
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("models");
    std::fs::create_dir_all(root.join("sub")).unwrap();
    std::fs::write(dir.path().join("x.bin"), &b.bytes).unwrap();
    std::fs::write(root.join("sub/m.bin"), &b.bytes).unwrap();
    let import = |uri: &str| {
        let d = b.doc(one_mesh(json!({"attributes": {"POSITION": 0}, "indices": 1})), Some(uri));
        let path = root.join("m.gltf");
        std::fs::write(&path, serde_json::to_vec(&d).unwrap()).unwrap();
        import_path(&path)
    };
    for (uri, why) in [
        ("/etc/passwd", "is an absolute path"),
        ("../x.bin", "climbs out of the glTF file's folder"),
        ("a/../../x.bin", "climbs out of the glTF file's folder"),
        ("sub/../../x.bin", "climbs out of the glTF file's folder"),
        ("%2e%2e/x.bin", "climbs out of the glTF file's folder"),
        ("..\\x.bin", "climbs out of the glTF file's folder"),
        ("C:/Windows/x.bin", "is an absolute path"),
    ] {
        let e = import(uri).unwrap_err().to_string();
        assert!(e.contains("m.gltf") && e.contains(&format!("uri \"{uri}\"")), "{uri}: {e}");
        assert!(e.contains(why), "{uri}: {e}");
    }
    let e = import("file:///etc/passwd").unwrap_err();
    assert!(matches!(e, ImportError::Unsupported { .. }), "{e}");
    assert!(e.to_string().contains("m.gltf") && e.to_string().contains("file:///etc/passwd"), "{e}");
    // Relative names inside the folder still work, also through a `..` that stays inside.
    for uri in ["sub/m.bin", "./sub/m.bin", "sub/../sub/m.bin", "sub%2Fm.bin"] {
        let c = import(uri).unwrap_or_else(|e| panic!("{uri}: {e}"));
        assert_eq!(c.tris.len(), 2, "{uri}");
    }
}

/// Regression: `extras` that were arrays or strings made the file unreadable ("invalid type");
/// glTF 2.0 allows any JSON value there. Object extras keep working, and names are unchanged.
#[test]
fn extras_of_any_json_type_are_accepted() {
    let (b, _) = square(USHORT);
    let extras = [json!([1, 2, 3]), json!("a string"), json!(42), json!(null), json!(true), json!({"id": 7})];
    for e in extras {
        let mut d = b.doc(one_mesh(json!({"attributes": {"POSITION": 0}, "indices": 1, "extras": e})), None);
        d["nodes"][0]["extras"] = e.clone();
        d["meshes"][0]["extras"] = e.clone();
        d["asset"]["extras"] = e.clone();
        d["extras"] = e.clone();
        d["buffers"][0]["extras"] = e.clone();
        let c = import_glb(&d, &b.bytes).unwrap_or_else(|err| panic!("extras {e}: {err}"));
        assert_eq!(c.tris.len(), 2, "extras {e}");
        assert_eq!(c.objects[0].1.name, "n", "extras {e}");
    }
}
