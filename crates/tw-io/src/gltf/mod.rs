//! glTF 2.0 importer: `.gltf` (JSON with external or base64 data-URI buffers) and `.glb`, either
//! possibly gzip'ed. Follows the Khronos glTF 2.0 specification (2.0.1), plus the extensions
//! `KHR_mesh_quantization`, `EXT_meshopt_compression`, `EXT_mesh_gpu_instancing` and (for colour)
//! `KHR_materials_pbrSpecularGlossiness`.
//!
//! Stages (see [`open`] and [`GltfSource::stream`]):
//! 1. Header: for a GLB, the 12-byte header and the JSON chunk are read from the input stream
//!    (`container::read_head`); a `.gltf` is read whole (it is the JSON). The document is parsed
//!    with the `gltf` crate's JSON types (not `gltf::import`, which loads every buffer and image),
//!    without its validation (which panics on some bad indices): every index is checked where it
//!    is used, and errors name the JSON path ("meshes\[2\].primitives\[0\]: ...").
//! 2. Scene: the default scene (else scene 0, else every parentless node, else every mesh once;
//!    a default scene index in a file without scenes is ignored with a warning) is
//!    walked depth-first with an explicit stack, composing node transforms in f64
//!    (`scene::instances`). A node reached twice (cycle, two parents) is an error.
//! 3. Binary access: a plain `.glb` on disk is read with positioned reads; a gzip'ed (or
//!    in-memory) `.glb` is first decompressed into a temporary file in
//!    [`ImportOptions::spill_dir`](crate::format::ImportOptions) (`container::RandomFile`).
//!    External buffers are opened on first use, relative to the `.gltf`'s directory.
//! 4. Per mesh instance, per primitive: the accessors it needs (POSITION, NORMAL, COLOR_0,
//!    indices) are read, only their byte ranges (`data::Store::read_accessor`); positions go to
//!    world space in f64, normals through the inverse transpose; triangle lists, strips and fans
//!    become triangles; a mirroring transform (negative determinant) has its winding flipped so
//!    faces stay front-facing. One primitive's data is in memory at a time (instanced meshes keep
//!    theirs under the vertex memory budget so that repeated instances are not re-read).
//!
//! Objects: each mesh instance is one object, named after its node (else its mesh). Its colour is
//! its primitives' material colour (`baseColorFactor`, or the `diffuseFactor` of
//! `KHR_materials_pbrSpecularGlossiness`), converted from linear to sRGB. When the primitives of
//! a mesh have different colours, the instance becomes one object per colour, named
//! "name \[material\]". With `EXT_mesh_gpu_instancing` each instance of a node is an object.
//! Per-vertex colours (`COLOR_0`) are converted to sRGB and sent with the triangles, as is.
//!
//! Not read: POINTS and LINES primitives (skipped with a warning), skins and morph targets (the
//! bind pose and base geometry are used, with the node transform), Draco compression
//! (`KHR_draco_mesh_compression`: unsupported when required, otherwise the uncompressed fallback
//! is read), textures. glTF 1.0 is unsupported.
//!
//! Progress counts triangles (estimated from accessor counts at open), preceded for a
//! decompressed GLB by the compressed bytes read into the temporary copy.

mod container;
mod data;
mod scene;
#[cfg(test)]
mod tests;

use std::collections::{HashMap, HashSet};
use std::io::Read;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use ::gltf::json;
use json::accessor::Type;
use json::mesh::{Mode, Semantic};
use json::validation::Checked;
use tw_core::Rgba8;

use crate::error::{ImportError, Position};
use crate::format::{Format, ImportOptions};
use crate::input::{DiskCounter, Input};
use crate::{ObjectInfo, SourceSummary, Triangle, TriangleSink, TriangleSource};
use container::RandomFile;
use data::Store;
use scene::{Instance, Mat4};

/// Required extensions that do not change geometry, or that this importer implements.
const KNOWN_EXTENSIONS: &[&str] = &[
    "KHR_mesh_quantization",
    "EXT_meshopt_compression",
    "EXT_mesh_gpu_instancing",
    "KHR_lights_punctual",
    "KHR_xmp_json_ld",
    "KHR_technique_webgl",
    "MSFT_texture_dds",
];
const KNOWN_PREFIXES: &[&str] = &["KHR_materials_", "KHR_texture_", "EXT_texture_"];

/// Opens a glTF or GLB file for streaming: reads the JSON document and walks the scene, so that
/// structural errors surface before any triangle is streamed.
pub fn open(
    mut input: Input,
    _format: Format,
    options: &ImportOptions,
) -> Result<Box<dyn TriangleSource>, ImportError> {
    let path = input.path.clone();
    let is_glb = input.peek(4)?.starts_with(b"glTF");
    let plain =
        !input.gzip && std::fs::metadata(&path).is_ok_and(|m| m.is_file() && m.len() == input.file_len);
    let (root, glb) = if is_glb {
        let known_len = plain.then_some(input.file_len);
        let head = container::read_head(input.reader(), &path, known_len)?;
        let root = parse_json(&head.json, &path, true)?;
        // A plain file is read in place, once its first bytes are seen to be the stream's.
        let file = if plain {
            let f = RandomFile::open(&path, &path)?;
            let same = f.end() >= container::JSON_START
                && f.read_at(0, container::JSON_START as usize)? == head.header;
            same.then_some(f)
        } else {
            None
        };
        (root, Some(Glb { total_len: head.total_len, json_end: head.json_end, file }))
    } else {
        let mut text = Vec::new();
        input.reader().read_to_end(&mut text).map_err(|e| ImportError::io(&path, Position::File, e))?;
        (parse_json(&text, &path, false)?, None)
    };
    check_extensions(&root, &path)?;
    let instances = scene::instances(&root, &path)?;
    let plan = plan(&root, &instances, &path)?;
    let spill = glb.as_ref().is_some_and(|g| g.file.is_none());
    let progress_total = plan.triangles + if spill { input.file_len } else { 0 };
    Ok(Box::new(GltfSource {
        dir: path.parent().map(Path::to_path_buf).unwrap_or_default(),
        path,
        root,
        glb,
        instances,
        plan,
        progress_total,
        file_len: input.file_len,
        disk: input.disk_counter(),
        input: spill.then_some(input),
        options: options.clone(),
    }))
}

struct Glb {
    total_len: u64,
    json_end: u64,
    /// The GLB itself, when it is a plain file on disk.
    file: Option<RandomFile>,
}

/// A glTF document ready to stream.
pub struct GltfSource {
    path: PathBuf,
    dir: PathBuf,
    root: json::Root,
    glb: Option<Glb>,
    instances: Vec<Instance>,
    plan: Plan,
    progress_total: u64,
    file_len: u64,
    disk: DiskCounter,
    /// The rest of a GLB stream that must be copied to a temporary file first.
    input: Option<Input>,
    options: ImportOptions,
}

/// What [`plan`] learns from the JSON alone.
struct Plan {
    /// Estimated triangles over all instances, for progress.
    triangles: u64,
    /// How many times each mesh is drawn: meshes drawn more than once keep their data cached.
    uses: Vec<u64>,
    /// Per instance, the `EXT_mesh_gpu_instancing` attributes of its node.
    gpu: Vec<Option<GpuInstancing>>,
}

#[derive(Clone, Debug)]
struct GpuInstancing {
    translation: Option<usize>,
    rotation: Option<usize>,
    scale: Option<usize>,
    count: u64,
}

fn parse_json(bytes: &[u8], path: &Path, glb: bool) -> Result<json::Root, ImportError> {
    // GLB JSON chunks are padded with spaces; some writers pad with zeros.
    let end = bytes.iter().rposition(|&b| b != 0 && !b.is_ascii_whitespace()).map_or(0, |p| p + 1);
    let bytes = &bytes[..end];
    let root: json::Root = match serde_json::from_slice(bytes) {
        Ok(root) => root,
        Err(e) => match lenient_parse(bytes) {
            Some(root) => root,
            None => {
                if let Some(v) = gltf_version(bytes).filter(|v| !v.starts_with('2')) {
                    return Err(ImportError::unsupported(
                        path,
                        format!("glTF version {v}; only glTF 2.0 is read"),
                    ));
                }
                let text = e.to_string();
                let message = text.rsplit_once(" at line ").map_or(text.as_str(), |(m, _)| m);
                return Err(if glb {
                    let at = line_column_offset(bytes, e.line(), e.column());
                    ImportError::parse(
                        path,
                        Position::Byte(container::JSON_START + at),
                        format!("invalid glTF JSON: {message}"),
                    )
                } else {
                    ImportError::parse(
                        path,
                        Position::Line(e.line() as u64),
                        format!("column {}: invalid glTF JSON: {message}", e.column()),
                    )
                });
            }
        },
    };
    if !root.asset.version.starts_with("2.") {
        return Err(ImportError::unsupported(
            path,
            format!("glTF version {}; only glTF 2.0 is read", root.asset.version),
        ));
    }
    Ok(root)
}

/// Parses a document that the `gltf` crate's types reject for a reason the specification does
/// not give: a scene without `nodes` (optional in glTF 2.0, required by gltf-json 1.4), or
/// `extras` that are not objects (glTF 2.0 allows any JSON value there; gltf-json, built without
/// its `extras` feature, takes only objects). Only tried after a failure, so valid files are
/// parsed once.
fn lenient_parse(bytes: &[u8]) -> Option<json::Root> {
    let mut v: serde_json::Value = serde_json::from_slice(bytes).ok()?;
    let fixed = add_missing_scene_nodes(&mut v) | drop_non_object_extras(&mut v);
    if !fixed {
        return None;
    }
    serde_json::from_value(v).ok()
}

/// Gives every scene without `nodes` an empty list; true if one was missing.
fn add_missing_scene_nodes(doc: &mut serde_json::Value) -> bool {
    let mut fixed = false;
    let scenes = doc.get_mut("scenes").and_then(|s| s.as_array_mut());
    for scene in scenes.into_iter().flatten() {
        if let Some(s) = scene.as_object_mut() {
            if !s.contains_key("nodes") {
                s.insert("nodes".into(), serde_json::Value::Array(Vec::new()));
                fixed = true;
            }
        }
    }
    fixed
}

/// Removes every `extras` member whose value is not an object (an array, a string, a number...),
/// at any depth; true if one was removed. terawalk reads nothing from `extras` (names come from
/// `name`), so nothing is lost; objects are left as they are. The depth is bounded by
/// serde_json's recursion limit.
fn drop_non_object_extras(v: &mut serde_json::Value) -> bool {
    match v {
        serde_json::Value::Object(map) => {
            let mut fixed = false;
            if map.get("extras").is_some_and(|e| !e.is_object()) {
                map.remove("extras");
                fixed = true;
            }
            for child in map.values_mut() {
                fixed |= drop_non_object_extras(child);
            }
            fixed
        }
        serde_json::Value::Array(items) => items.iter_mut().fold(false, |f, c| drop_non_object_extras(c) | f),
        _ => false,
    }
}

/// `asset.version` of a document that the glTF 2.0 types could not parse.
fn gltf_version(bytes: &[u8]) -> Option<String> {
    let v: serde_json::Value = serde_json::from_slice(bytes).ok()?;
    match v.get("asset")?.get("version")? {
        serde_json::Value::String(s) => Some(s.clone()),
        other => Some(other.to_string()),
    }
}

/// Byte offset of 1-based `line` and `column` in `text`.
fn line_column_offset(text: &[u8], line: usize, column: usize) -> u64 {
    let mut start = 0;
    for _ in 1..line {
        match text[start..].iter().position(|&b| b == b'\n') {
            Some(p) => start += p + 1,
            None => break,
        }
    }
    (start + column.saturating_sub(1)).min(text.len()) as u64
}

fn check_extensions(root: &json::Root, path: &Path) -> Result<(), ImportError> {
    for ext in &root.extensions_required {
        if ext == "KHR_draco_mesh_compression" {
            return Err(ImportError::unsupported(
                path,
                "the file requires KHR_draco_mesh_compression (Draco-compressed meshes); convert it, e.g. \
                 with `gltf-transform copy` or `gltfpack`, to uncompressed or meshopt-compressed geometry",
            ));
        }
        let known =
            KNOWN_EXTENSIONS.contains(&ext.as_str()) || KNOWN_PREFIXES.iter().any(|p| ext.starts_with(p));
        if !known {
            return Err(ImportError::unsupported(path, format!("the file requires the extension {ext}")));
        }
    }
    Ok(())
}

/// Counts triangles for progress, finds `EXT_mesh_gpu_instancing`, checks primitive modes, and
/// warns (once per primitive) about primitives that are not triangles.
fn plan(root: &json::Root, instances: &[Instance], path: &Path) -> Result<Plan, ImportError> {
    let err = |m: String| ImportError::parse(path, Position::File, m);
    let mut uses = vec![0u64; root.meshes.len()];
    let mut per_mesh: Vec<Option<u64>> = vec![None; root.meshes.len()];
    let mut triangles = 0u64;
    let mut gpu = Vec::with_capacity(instances.len());
    for inst in instances {
        let g = match inst.node {
            Some(n) => gpu_instancing(root, n, path)?,
            None => None,
        };
        let copies = g.as_ref().map_or(1, |g| g.count);
        uses[inst.mesh] += copies;
        gpu.push(g);
        let tris = match per_mesh[inst.mesh] {
            Some(t) => t,
            None => {
                let mesh = &root.meshes[inst.mesh];
                let mut t = 0u64;
                for (p, prim) in mesh.primitives.iter().enumerate() {
                    let at = format!("meshes[{}].primitives[{p}]", inst.mesh);
                    let mode = match prim.mode {
                        Checked::Valid(m) => m,
                        Checked::Invalid => return Err(err(format!("{at}.mode is invalid"))),
                    };
                    if !is_triangles(mode) {
                        tracing::warn!("{}: {at}: {mode:?} primitive skipped", path.display());
                        continue;
                    }
                    let count = |a: usize| root.accessors.get(a).map_or(0, |a| a.count.0);
                    let n = match prim.indices {
                        Some(i) => count(i.value()),
                        None => prim
                            .attributes
                            .get(&Checked::Valid(Semantic::Positions))
                            .map_or(0, |a| count(a.value())),
                    };
                    t = t.saturating_add(if mode == Mode::Triangles { n / 3 } else { n.saturating_sub(2) });
                }
                per_mesh[inst.mesh] = Some(t);
                t
            }
        };
        triangles = triangles.saturating_add(tris.saturating_mul(copies));
    }
    Ok(Plan { triangles, uses, gpu })
}

fn is_triangles(mode: Mode) -> bool {
    matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan)
}

/// The `EXT_mesh_gpu_instancing` attributes of node `n`, if it has the extension.
fn gpu_instancing(root: &json::Root, n: usize, path: &Path) -> Result<Option<GpuInstancing>, ImportError> {
    let Some(ext) = root.nodes[n].extensions.as_ref().and_then(|e| e.others.get("EXT_mesh_gpu_instancing"))
    else {
        return Ok(None);
    };
    let at = format!("nodes[{n}].extensions.EXT_mesh_gpu_instancing");
    let err = |m: String| ImportError::parse(path, Position::File, format!("{at}: {m}"));
    let attrs =
        ext.get("attributes").and_then(|a| a.as_object()).ok_or_else(|| err("no attributes".into()))?;
    let mut g = GpuInstancing { translation: None, rotation: None, scale: None, count: 0 };
    let mut counts = HashSet::new();
    for (key, slot) in
        [("TRANSLATION", &mut g.translation), ("ROTATION", &mut g.rotation), ("SCALE", &mut g.scale)]
    {
        if let Some(v) = attrs.get(key) {
            let a = v.as_u64().ok_or_else(|| err(format!("attributes.{key} is not an accessor index")))?;
            let acc = root
                .accessors
                .get(a as usize)
                .ok_or_else(|| err(format!("attributes.{key}: accessors[{a}] does not exist")))?;
            counts.insert(acc.count.0);
            *slot = Some(a as usize);
        }
    }
    if counts.len() > 1 {
        return Err(err(format!("the attributes have different counts {counts:?}")));
    }
    g.count = counts.into_iter().next().unwrap_or(0);
    Ok(Some(g))
}

impl TriangleSource for GltfSource {
    fn name(&self) -> String {
        self.path.display().to_string()
    }

    fn progress_total(&self) -> Option<u64> {
        Some(self.progress_total)
    }

    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        let GltfSource { path, dir, mut root, glb, instances, plan, file_len, disk, input, options, .. } =
            *self;
        let mut progress_base = 0;
        let bin = match glb {
            None => None,
            Some(g) => {
                let file = match (g.file, input) {
                    (Some(f), _) => f,
                    (None, Some(mut input)) => {
                        let counter = disk.clone();
                        let f = RandomFile::spill(
                            input.reader(),
                            g.total_len - g.json_end,
                            g.json_end,
                            options.spill_dir.as_deref(),
                            &path,
                            &mut || sink.progress(counter.get()),
                        )?;
                        progress_base = file_len;
                        f
                    }
                    (None, None) => {
                        return Err(ImportError::parse(&path, Position::File, "GLB content lost"))
                    }
                };
                let chunk = container::find_bin(&file, g.total_len, g.json_end, &path)?;
                Some((Rc::new(file), chunk, progress_base == 0))
            }
        };
        let source_len = match &bin {
            Some((f, _, _)) => f.end(),
            None => file_len,
        };
        let budget = options.vertex_memory;
        let mut store = Store::new(&mut root, &path, &dir, bin, budget / 2, source_len)?;
        let mut e = Emitter {
            path: &path,
            root: &root,
            sink,
            objects: 0,
            vertices: 0,
            done: progress_base,
            cache: HashMap::new(),
            cache_bytes: 0,
            cache_budget: budget / 2,
        };
        for (inst, gpu) in instances.iter().zip(&plan.gpu) {
            let cache = plan.uses[inst.mesh] > 1;
            match gpu {
                None => e.instance(&mut store, inst, &inst.matrix, None, cache)?,
                Some(g) => {
                    let transforms = gpu_transforms(&mut store, &root, g, &path)?;
                    for (k, local) in transforms.iter().enumerate() {
                        e.instance(&mut store, inst, &scene::mul(&inst.matrix, local), Some(k), cache)?;
                    }
                }
            }
        }
        Ok(SourceSummary { objects: e.objects, vertices: e.vertices, bytes: disk.get() + store.bytes_read })
    }
}

/// The per-instance transforms of `EXT_mesh_gpu_instancing`: translation * rotation * scale.
fn gpu_transforms(
    store: &mut Store,
    root: &json::Root,
    g: &GpuInstancing,
    path: &Path,
) -> Result<Vec<Mat4>, ImportError> {
    let mut read = |a: Option<usize>, t: Type, what: &str| -> Result<Option<Vec<f32>>, ImportError> {
        a.map(|a| store.read_accessor(root, a, &[t], what).map(|r| r.to_f32())).transpose()
    };
    let t = read(g.translation, Type::Vec3, "EXT_mesh_gpu_instancing TRANSLATION")?;
    let r = read(g.rotation, Type::Vec4, "EXT_mesh_gpu_instancing ROTATION")?;
    let s = read(g.scale, Type::Vec3, "EXT_mesh_gpu_instancing SCALE")?;
    let n = g.count as usize;
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let node = json::Node {
            translation: t.as_ref().map(|v| [v[3 * k], v[3 * k + 1], v[3 * k + 2]]),
            rotation: r
                .as_ref()
                .map(|v| json::scene::UnitQuaternion([v[4 * k], v[4 * k + 1], v[4 * k + 2], v[4 * k + 3]])),
            scale: s.as_ref().map(|v| [v[3 * k], v[3 * k + 1], v[3 * k + 2]]),
            ..Default::default()
        };
        out.push(scene::local_matrix(&node, k, path).map_err(|e| {
            ImportError::parse(path, Position::File, format!("EXT_mesh_gpu_instancing instance {k}: {e}"))
        })?);
    }
    Ok(out)
}

/// One primitive's data in its mesh's space.
struct Loaded {
    positions: Vec<f32>,
    normals: Option<Vec<f32>>,
    colors: Option<Vec<Rgba8>>,
    indices: Option<Vec<u32>>,
    mode: Mode,
}

impl Loaded {
    fn vertex_count(&self) -> usize {
        self.positions.len() / 3
    }

    fn bytes(&self) -> usize {
        self.positions.len() * 4
            + self.normals.as_ref().map_or(0, |n| n.len() * 4)
            + self.colors.as_ref().map_or(0, |c| c.len() * 4)
            + self.indices.as_ref().map_or(0, |i| i.len() * 4)
    }
}

struct Emitter<'a> {
    path: &'a Path,
    root: &'a json::Root,
    sink: &'a mut dyn TriangleSink,
    objects: u32,
    vertices: u64,
    /// Progress reported so far.
    done: u64,
    /// Primitives of meshes drawn more than once, by (mesh, primitive).
    cache: HashMap<(usize, usize), Rc<Loaded>>,
    cache_bytes: usize,
    cache_budget: usize,
}

impl Emitter<'_> {
    fn err(&self, m: String) -> ImportError {
        ImportError::parse(self.path, Position::File, m)
    }

    /// Streams one drawn mesh with world transform `matrix`.
    fn instance(
        &mut self,
        store: &mut Store,
        inst: &Instance,
        matrix: &Mat4,
        copy: Option<usize>,
        cache: bool,
    ) -> Result<(), ImportError> {
        let root = self.root;
        let mesh = &root.meshes[inst.mesh];
        let node = inst.node.and_then(|n| root.nodes.get(n));
        let mut base = node.and_then(|n| n.name.clone()).or_else(|| mesh.name.clone()).unwrap_or_default();
        if let Some(k) = copy {
            base = format!("{base}[{k}]");
        }
        // One object per distinct colour among the triangle primitives, in order of appearance.
        let colors: Vec<Option<(Option<Rgba8>, Option<usize>)>> = mesh
            .primitives
            .iter()
            .map(|p| {
                let tri = matches!(p.mode, Checked::Valid(m) if is_triangles(m));
                tri.then(|| {
                    let m = p.material.map(|m| m.value());
                    (m.and_then(|m| material_color(root, m)), m)
                })
            })
            .collect();
        let mut groups: Vec<Option<Rgba8>> = Vec::new();
        for (c, _) in colors.iter().flatten() {
            if !groups.contains(c) {
                groups.push(*c);
            }
        }
        let mut ids: Vec<Option<u32>> = vec![None; groups.len()];
        let normal_matrix = scene::normal_matrix(matrix);
        let flip = scene::det3(matrix) < 0.0;
        for (p, c) in colors.iter().enumerate() {
            let Some((color, material)) = c else { continue };
            let g = groups.iter().position(|x| x == color).unwrap_or(0);
            let loaded = self.load(store, inst.mesh, p, cache)?;
            self.vertices += loaded.vertex_count() as u64;
            let id = match ids[g] {
                Some(id) => id,
                None => {
                    let name = if groups.len() == 1 {
                        base.clone()
                    } else {
                        let m = material.and_then(|m| root.materials.get(m)).and_then(|m| m.name.clone());
                        format!("{base} [{}]", m.unwrap_or_else(|| format!("primitive {p}")))
                    };
                    let id = self.objects;
                    self.sink.object(id, &ObjectInfo { name, color: *color })?;
                    self.objects += 1;
                    ids[g] = Some(id);
                    id
                }
            };
            let at = format!("meshes[{}].primitives[{p}]", inst.mesh);
            self.emit(&loaded, matrix, normal_matrix.as_ref(), flip, id, &at)?;
        }
        Ok(())
    }

    /// Reads one primitive's accessors, or takes them from the cache.
    fn load(
        &mut self,
        store: &mut Store,
        mesh: usize,
        p: usize,
        cache: bool,
    ) -> Result<Rc<Loaded>, ImportError> {
        if let Some(l) = self.cache.get(&(mesh, p)) {
            return Ok(l.clone());
        }
        let root = self.root;
        let prim = &root.meshes[mesh].primitives[p];
        let at = format!("meshes[{mesh}].primitives[{p}]");
        let mode = match prim.mode {
            Checked::Valid(m) => m,
            Checked::Invalid => return Err(self.err(format!("{at}.mode is invalid"))),
        };
        let attr = |s: Semantic| prim.attributes.get(&Checked::Valid(s)).map(|a| a.value());
        let pos =
            attr(Semantic::Positions).ok_or_else(|| self.err(format!("{at}: no POSITION attribute")))?;
        self.refuse_draco_only(prim, pos, &at)?;
        let positions = self.read_positions(store, pos, &at)?;
        let n = positions.len() / 3;
        let normals = match attr(Semantic::Normals) {
            None => None,
            Some(a) => self.read_normals(store, a, n, &at)?,
        };
        let colors = match attr(Semantic::Colors(0)) {
            None => None,
            Some(a) => Some(self.read_colors(store, a, n, &at)?),
        };
        let indices = match prim.indices {
            None => None,
            Some(a) => Some(self.read_indices(store, a.value(), n, &at)?),
        };
        let loaded = Rc::new(Loaded { positions, normals, colors, indices, mode });
        if cache {
            self.remember((mesh, p), &loaded);
        }
        Ok(loaded)
    }

    /// Refuses a Draco-compressed primitive whose POSITION accessor (`pos`) has no data of its
    /// own: there is no uncompressed fallback to read.
    fn refuse_draco_only(
        &self,
        prim: &json::mesh::Primitive,
        pos: usize,
        at: &str,
    ) -> Result<(), ImportError> {
        let draco =
            prim.extensions.as_ref().is_some_and(|e| e.others.contains_key("KHR_draco_mesh_compression"));
        if draco
            && self.root.accessors.get(pos).is_some_and(|a| a.buffer_view.is_none() && a.sparse.is_none())
        {
            return Err(ImportError::unsupported(
                self.path,
                format!(
                    "{at} is Draco-compressed (KHR_draco_mesh_compression) without an uncompressed fallback"
                ),
            ));
        }
        Ok(())
    }

    /// The POSITION accessor `pos` as floats, every one finite.
    fn read_positions(&self, store: &mut Store, pos: usize, at: &str) -> Result<Vec<f32>, ImportError> {
        let raw = store.read_accessor(self.root, pos, &[Type::Vec3], &format!("{at} POSITION"))?;
        let positions = raw.to_f32();
        drop(raw);
        if let Some(k) = positions.iter().position(|v| !v.is_finite()) {
            let v = k / 3;
            return Err(self.err(format!(
                "{at}: POSITION (accessors[{pos}]) vertex {v} is not finite: {:?}",
                &positions[v * 3..v * 3 + 3]
            )));
        }
        Ok(positions)
    }

    /// The NORMAL accessor `a`, one per vertex of the `n`; `None` (with a warning) if some
    /// value is not finite.
    fn read_normals(
        &self,
        store: &mut Store,
        a: usize,
        n: usize,
        at: &str,
    ) -> Result<Option<Vec<f32>>, ImportError> {
        let raw = store.read_accessor(self.root, a, &[Type::Vec3], &format!("{at} NORMAL"))?;
        if raw.count != n {
            return Err(self.err(format!(
                "{at}: NORMAL (accessors[{a}]) has {} elements but POSITION has {n}",
                raw.count
            )));
        }
        let v = raw.to_f32();
        if v.iter().all(|c| c.is_finite()) {
            Ok(Some(v))
        } else {
            tracing::warn!("{}: {at}: NORMAL has non-finite values; normals ignored", self.path.display());
            Ok(None)
        }
    }

    /// The COLOR_0 accessor `a` (RGB or RGBA, linear), one per vertex of the `n`, as sRGB
    /// 8-bit colours.
    fn read_colors(
        &self,
        store: &mut Store,
        a: usize,
        n: usize,
        at: &str,
    ) -> Result<Vec<Rgba8>, ImportError> {
        let raw = store.read_accessor(self.root, a, &[Type::Vec3, Type::Vec4], &format!("{at} COLOR_0"))?;
        if raw.count != n {
            return Err(self.err(format!(
                "{at}: COLOR_0 (accessors[{a}]) has {} elements but POSITION has {n}",
                raw.count
            )));
        }
        let c = raw.components;
        let v = raw.to_f32();
        Ok(v.chunks_exact(c).map(|x| srgb8([x[0], x[1], x[2], if c == 4 { x[3] } else { 1.0 }])).collect())
    }

    /// The indices accessor `a`: unsigned integers, each below the vertex count `n`.
    fn read_indices(&self, store: &mut Store, a: usize, n: usize, at: &str) -> Result<Vec<u32>, ImportError> {
        let raw = store.read_accessor(self.root, a, &[Type::Scalar], &format!("{at} indices"))?;
        let ix = raw
            .to_u32()
            .ok_or_else(|| self.err(format!("{at}: indices (accessors[{a}]) must be unsigned integers")))?;
        if let Some(k) = ix.iter().position(|&i| i as usize >= n) {
            return Err(self.err(format!(
                "{at}: indices (accessors[{a}]) element {k} = {} is out of range ({n} vertices)",
                ix[k]
            )));
        }
        Ok(ix)
    }

    /// Caches a loaded primitive of a mesh drawn more than once, within the cache's budget
    /// (emptied when the next one would not fit; one larger than the whole budget is not kept).
    fn remember(&mut self, key: (usize, usize), loaded: &Rc<Loaded>) {
        let b = loaded.bytes();
        if self.cache_bytes + b > self.cache_budget {
            self.cache.clear();
            self.cache_bytes = 0;
        }
        if b <= self.cache_budget {
            self.cache_bytes += b;
            self.cache.insert(key, loaded.clone());
        }
    }

    /// Sends the triangles of one loaded primitive.
    fn emit(
        &mut self,
        l: &Loaded,
        m: &Mat4,
        nm: Option<&[[f64; 3]; 3]>,
        flip: bool,
        object: u32,
        at: &str,
    ) -> Result<(), ImportError> {
        let mut world = Vec::with_capacity(l.vertex_count());
        for (v, p) in l.positions.chunks_exact(3).enumerate() {
            let w = scene::transform_point(m, [p[0], p[1], p[2]]);
            if !w.iter().all(|c| c.is_finite()) {
                return Err(self.err(format!("{at}: vertex {v} {p:?} is not finite in world space: {w:?}")));
            }
            world.push(w);
        }
        let normals: Option<Vec<[f32; 3]>> = match (&l.normals, nm) {
            (Some(n), Some(nm)) => {
                Some(n.chunks_exact(3).map(|v| scene::transform_normal(nm, [v[0], v[1], v[2]])).collect())
            }
            _ => None,
        };
        let count = l.indices.as_ref().map_or(l.vertex_count(), Vec::len);
        if l.mode == Mode::Triangles && !count.is_multiple_of(3) {
            tracing::warn!(
                "{}: {at}: {count} vertices is not a multiple of 3; the last {} are ignored",
                self.path.display(),
                count % 3
            );
        }
        let triangles = match l.mode {
            Mode::Triangles => count / 3,
            _ => count.saturating_sub(2),
        };
        let vertex = |k: usize| l.indices.as_ref().map_or(k, |ix| ix[k] as usize);
        let mut t = Triangle::new([[0.0; 3]; 3], object);
        for i in 0..triangles {
            // Section 3.7.2.1 "Topology types": the vertex order of each primitive mode.
            let mut c = match l.mode {
                Mode::TriangleStrip if i % 2 == 1 => [i, i + 2, i + 1],
                Mode::TriangleStrip => [i, i + 1, i + 2],
                Mode::TriangleFan => [i + 1, i + 2, 0],
                _ => [3 * i, 3 * i + 1, 3 * i + 2],
            }
            .map(vertex);
            if flip {
                c.swap(1, 2);
            }
            t.positions = c.map(|v| world[v]);
            t.normals = normals.as_ref().map(|n| c.map(|v| n[v]));
            t.colors = l.colors.as_ref().map(|col| c.map(|v| col[v]));
            self.sink.triangle(&t)?;
            if i % (1 << 20) == (1 << 20) - 1 {
                self.sink.progress(self.done + i as u64);
            }
        }
        self.done += triangles as u64;
        self.sink.progress(self.done);
        Ok(())
    }
}

/// The display colour of material `m`: its base colour factor (or `KHR_materials_pbrSpecularGlossiness`
/// diffuse factor), from linear to sRGB.
fn material_color(root: &json::Root, m: usize) -> Option<Rgba8> {
    let mat = root.materials.get(m)?;
    let sg = mat.extensions.as_ref().and_then(|e| e.pbr_specular_glossiness.as_ref());
    let c = match sg {
        Some(sg) => sg.diffuse_factor.0,
        None => mat.pbr_metallic_roughness.base_color_factor.0,
    };
    Some(srgb8(c))
}

/// Linear RGBA in [0, 1] to 8-bit sRGB (alpha stays linear). NaN maps to 0.
fn srgb8(c: [f32; 4]) -> Rgba8 {
    let clamp = |v: f32| if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    let enc = |v: f32| {
        let v = clamp(v);
        let s = if v <= 0.003_130_8 { 12.92 * v } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 };
        (s * 255.0 + 0.5) as u8
    };
    Rgba8([enc(c[0]), enc(c[1]), enc(c[2]), (clamp(c[3]) * 255.0 + 0.5) as u8])
}
