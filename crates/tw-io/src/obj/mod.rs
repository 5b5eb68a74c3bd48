//! Streaming Wavefront OBJ importer.
//!
//! Follows the polygonal part of the Wavefront OBJ specification (Appendix B, "Object Files
//! (.obj)", of the Advanced Visualizer manual, version 3.0), with the common extension of vertex
//! colours (`v x y z r g b`, floats in 0..=1, clamped). Materials come from `mtllib` files (see
//! `obj::mtl`).
//!
//! Stages, all in one pass over the file:
//! 1. Lines are cut straight out of the [`BufRead`] buffer (see `ObjSource::stream`); only a
//!    line that straddles two buffer fills, or is continued with a trailing backslash, is copied.
//!    Lines are bytes: non-UTF-8 text is fine wherever it is not part of a number or keyword.
//! 2. Each statement is dispatched on its keyword (`Parser::statement`). Numbers use a decimal
//!    fast path that is exact (Clinger's fast path: at most 19 digits, mantissa below 2^53, no
//!    exponent) and falls back to `str::parse` otherwise (`parse_f64`).
//! 3. `v`, `vn` go into [`VertexStore`]s, which spill to disk beyond
//!    [`ImportOptions::vertex_memory`], so files larger than memory work; `vt` are only counted,
//!    so that face indices can be checked.
//! 4. `f` (and the old `fo`) resolves every corner (`i`, `i/t`, `i//n`, `i/t/n`, negative indices
//!    counting back from the latest element) and fan-triangulates polygons (`Parser::face`).
//!    A face has normals when every corner names one.
//! 5. Objects: see `Parser::object_for_face`. `o` and `g` both begin a new object, but an object
//!    is announced to the sink only with its first face, so consecutive `o`/`g` lines without faces
//!    between them make one object, named by the last of them. Faces before any `o`/`g` belong to
//!    an object named after the file stem, and so do faces after a bare `o` or `g` (no name). Each object has one colour: when `usemtl` changes the
//!    material within an `o`/`g`, the following faces go to an object named `group/material`
//!    (switching back to a material already used in the same `o`/`g` reuses its object).
//!
//! Skipped: `s`, `l`, `p` and the display attributes (`mg`, `lod`, `usemap`, …) silently;
//! free-form geometry (`vp`, `cstype`, `curv`, `surf`, …) and `call`/`csh` with one warning each;
//! unknown keywords with one warning per keyword. Comment lines (`#`) are never continued by a
//! trailing backslash, so that a path like `# C:\dir\` cannot swallow the next statement.
//!
//! Errors name the file and line (the first line of a continued statement): index 0, an index
//! out of range, a malformed or non-finite number, a vertex with fewer than 3 coordinates, a face
//! with fewer than 3 or more than [`MAX_FACE_VERTICES`] corners, a line longer than [`MAX_LINE`],
//! and a keyword that is not printable ASCII (binary data).

pub(crate) mod mtl;

use std::collections::{HashMap, HashSet};
use std::io::{self, BufRead};
use std::path::{Path, PathBuf};

use tw_core::Rgba8;

use crate::error::{ImportError, Position};
use crate::format::ImportOptions;
use crate::input::Input;
use crate::vertex_store::VertexStore;
use crate::{ObjectId, ObjectInfo, SourceSummary, Triangle, TriangleSink, TriangleSource};

/// Most corners a face may have. Real polygons have a handful; more is a broken file.
pub const MAX_FACE_VERTICES: usize = 1 << 16;

/// Longest line (or continued statement) accepted, in bytes. A face of [`MAX_FACE_VERTICES`]
/// corners in `i/t/n` form with 10-digit indices fits comfortably.
pub const MAX_LINE: usize = 16 << 20;

/// Distinct warnings remembered (unknown keywords, unknown materials); beyond that, further ones
/// are not reported, so that a garbage file cannot grow the set without bound.
const MAX_WARNINGS: usize = 64;

/// Opens an OBJ file for streaming. Nothing is read until [`TriangleSource::stream`].
pub fn open(input: Input, options: &ImportOptions) -> Result<Box<dyn TriangleSource>, ImportError> {
    Ok(Box::new(ObjSource { input, options: options.clone() }))
}

struct ObjSource {
    input: Input,
    options: ImportOptions,
}

impl TriangleSource for ObjSource {
    fn name(&self) -> String {
        self.input.path.display().to_string()
    }

    fn progress_total(&self) -> Option<u64> {
        Some(self.input.file_len)
    }

    /// Stage 1: cuts lines out of the reader's buffer and feeds them to the [`Parser`].
    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        let ObjSource { input, options } = *self;
        let disk = input.disk_counter();
        let path = input.path.clone();
        let mut reader = input.into_reader();
        let mut p = Parser::new(path, &options, sink);
        // A line that straddles two buffer fills.
        let mut partial: Vec<u8> = Vec::new();
        loop {
            let buf = match reader.fill_buf() {
                Ok(buf) => buf,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(ImportError::io(&p.path, Position::Line(p.line + 1), e)),
            };
            if buf.is_empty() {
                break;
            }
            let len = buf.len();
            let mut rest = buf;
            if !partial.is_empty() {
                let Some(i) = find_newline(rest) else {
                    if partial.len() + len > MAX_LINE {
                        return Err(p.err(p.line + 1, format!("line longer than {MAX_LINE} bytes")));
                    }
                    partial.extend_from_slice(rest);
                    reader.consume(len);
                    continue;
                };
                partial.extend_from_slice(&rest[..i]);
                p.physical_line(&partial)?;
                partial.clear();
                rest = &rest[i + 1..];
            }
            while let Some(i) = find_newline(rest) {
                p.physical_line(&rest[..i])?;
                rest = &rest[i + 1..];
            }
            partial.extend_from_slice(rest);
            reader.consume(len);
            p.sink.progress(disk.get());
        }
        if !partial.is_empty() {
            p.physical_line(&partial)?;
        }
        p.finish()?;
        let bytes = disk.get();
        p.sink.progress(bytes);
        Ok(SourceSummary { objects: p.objects, vertices: p.positions.len(), bytes })
    }
}

/// One face corner, resolved to 0-based indices.
#[derive(Clone, Copy, Debug)]
struct Corner {
    vertex: u64,
    normal: Option<u64>,
}

/// A corner's data, fetched from the stores.
#[derive(Clone, Copy, Debug)]
struct Fetched {
    position: [f64; 3],
    normal: Option<[f32; 3]>,
    color: Option<Rgba8>,
}

/// Colour stored for a vertex without one, once some vertex had a colour. Real colours always
/// have alpha 255.
const NO_COLOR: Rgba8 = Rgba8([0, 0, 0, 0]);

/// The parsing state; stages 2 to 5.
struct Parser<'s> {
    path: PathBuf,
    /// Directory that `mtllib` names are relative to.
    dir: PathBuf,
    sink: &'s mut dyn TriangleSink,
    /// Physical lines read so far (the current line's 1-based number once counted).
    line: u64,
    /// A statement continued with a trailing backslash, and the line it started on.
    cont: Vec<u8>,
    cont_start: u64,

    positions: VertexStore<[f64; 3]>,
    normals: VertexStore<[f32; 3]>,
    /// Vertex colours, from the first coloured vertex on (vertex `first_colored` is entry 0).
    colors: Option<VertexStore<Rgba8>>,
    first_colored: u64,
    color_budget: usize,
    spill_dir: Option<PathBuf>,
    texcoords: u64,
    corners: Vec<Corner>,
    fetched: Vec<Fetched>,

    /// Name of the current `o`/`g` (the file stem before any).
    group: String,
    /// Objects announced in the current `o`/`g`, by material.
    group_objects: HashMap<Option<Vec<u8>>, ObjectId>,
    /// The object faces go to now; `None` until the next face announces or finds it.
    current: Option<ObjectId>,
    /// The current `usemtl` name, if any.
    material: Option<Vec<u8>>,
    materials: mtl::Materials,
    objects: u32,
    warned: HashSet<Vec<u8>>,
}

impl<'s> Parser<'s> {
    fn new(path: PathBuf, options: &ImportOptions, sink: &'s mut dyn TriangleSink) -> Self {
        let budget = options.vertex_memory;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let group = file_stem(&path);
        Parser {
            dir,
            sink,
            line: 0,
            cont: Vec::new(),
            cont_start: 0,
            positions: VertexStore::new(budget / 5 * 3, options.spill_dir.clone()),
            normals: VertexStore::new(budget / 10 * 3, options.spill_dir.clone()),
            colors: None,
            first_colored: 0,
            color_budget: budget / 10,
            spill_dir: options.spill_dir.clone(),
            texcoords: 0,
            corners: Vec::new(),
            fetched: Vec::new(),
            group,
            group_objects: HashMap::new(),
            current: None,
            material: None,
            materials: mtl::Materials::new(),
            objects: 0,
            warned: HashSet::new(),
            path,
        }
    }

    fn err(&self, line: u64, message: impl Into<String>) -> ImportError {
        ImportError::parse(&self.path, Position::Line(line), message)
    }

    /// Logs `message` the first time `key` is seen (up to [`MAX_WARNINGS`] keys).
    fn warn_once(&mut self, key: &[u8], line: u64, message: impl FnOnce() -> String) {
        if self.warned.len() >= MAX_WARNINGS || self.warned.contains(key) {
            return;
        }
        self.warned.insert(key.to_vec());
        tracing::warn!("{}: line {line}: {}", self.path.display(), message());
        if self.warned.len() == MAX_WARNINGS {
            tracing::warn!("{}: further warnings are not reported", self.path.display());
        }
    }

    /// One line of the file, without its `\n`. Joins continued lines, then parses.
    fn physical_line(&mut self, raw: &[u8]) -> Result<(), ImportError> {
        self.line += 1;
        let mut line = raw;
        if self.line == 1 {
            line = line.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(line);
        }
        let end = trim_end(line);
        let continued =
            end.last() == Some(&b'\\') && (!self.cont.is_empty() || trim_start(line).first() != Some(&b'#'));
        if !continued && self.cont.is_empty() {
            return self.statement(line, self.line);
        }
        if self.cont.is_empty() {
            self.cont_start = self.line;
        }
        if self.cont.len() + line.len() > MAX_LINE {
            return Err(self.err(self.cont_start, format!("statement longer than {MAX_LINE} bytes")));
        }
        if continued {
            self.cont.extend_from_slice(&end[..end.len() - 1]);
            self.cont.push(b' ');
            return Ok(());
        }
        self.cont.extend_from_slice(line);
        let statement = std::mem::take(&mut self.cont);
        let result = self.statement(&statement, self.cont_start);
        self.cont = statement;
        self.cont.clear();
        result
    }

    /// End of file: a statement still waiting for its continuation is parsed as it is.
    fn finish(&mut self) -> Result<(), ImportError> {
        if self.cont.is_empty() {
            return Ok(());
        }
        let statement = std::mem::take(&mut self.cont);
        self.statement(&statement, self.cont_start)
    }

    /// Stage 2: one statement, starting on line `at`.
    fn statement(&mut self, line: &[u8], at: u64) -> Result<(), ImportError> {
        let line = trim_start(line);
        let split = line.iter().position(|&b| is_space(b)).unwrap_or(line.len());
        let (keyword, rest) = line.split_at(split);
        match keyword {
            b"v" => self.vertex(rest, at),
            b"f" | b"fo" => self.face(rest, at),
            b"vn" => self.normal(rest, at),
            b"vt" => self.texcoord(rest, at),
            b"" => Ok(()),
            [b'#', ..] => Ok(()),
            b"o" | b"g" => {
                let name = trim(rest);
                self.group = if name.is_empty() {
                    file_stem(&self.path)
                } else {
                    String::from_utf8_lossy(name).into()
                };
                self.group_objects.clear();
                self.current = None;
                Ok(())
            }
            b"usemtl" => {
                let name = trim(rest);
                self.material = (!name.is_empty()).then(|| name.to_vec());
                self.current = None;
                Ok(())
            }
            b"mtllib" => {
                self.mtllib(rest, at);
                Ok(())
            }
            // Smoothing groups, points, lines and display attributes: nothing to triangulate.
            b"s" | b"l" | b"p" | b"mg" | b"lod" | b"bevel" | b"c_interp" | b"d_interp" | b"usemap"
            | b"maplib" | b"shadow_obj" | b"trace_obj" | b"ctech" | b"stech" => Ok(()),
            b"vp" | b"cstype" | b"deg" | b"bmat" | b"step" | b"curv" | b"curv2" | b"surf" | b"parm"
            | b"trim" | b"hole" | b"scrv" | b"sp" | b"end" | b"con" => {
                self.warn_once(b"free-form", at, || "free-form curves and surfaces are not imported".into());
                Ok(())
            }
            b"call" | b"csh" => {
                self.warn_once(keyword, at, || {
                    format!("\"{}\" statements are not executed", String::from_utf8_lossy(keyword))
                });
                Ok(())
            }
            _ if keyword.iter().all(u8::is_ascii_graphic) => {
                self.warn_once(keyword, at, || {
                    format!("unknown statement \"{}\" skipped", String::from_utf8_lossy(keyword))
                });
                Ok(())
            }
            _ => Err(self.err(at, format!("\"{}\" is not an OBJ statement (binary data?)", show(keyword)))),
        }
    }

    /// Stage 3: `v x y z [w]` or `v x y z r g b`.
    fn vertex(&mut self, rest: &[u8], at: u64) -> Result<(), ImportError> {
        let mut values = [0.0f64; 6];
        let mut n = 0;
        for token in tokens(rest) {
            let v = self.finite(token, "vertex", at)?;
            if let Some(slot) = values.get_mut(n) {
                *slot = v;
            }
            n += 1;
        }
        if n < 3 {
            return Err(self.err(at, format!("a vertex needs 3 coordinates, found {n}")));
        }
        let index = self.positions.len();
        let [x, y, z, r, g, b] = values;
        self.positions.push([x, y, z]).map_err(io_err(&self.path, at))?;
        if n >= 6 {
            let color = Rgba8::from_f32([r as f32, g as f32, b as f32, 1.0]);
            if self.colors.is_none() {
                self.colors = Some(VertexStore::new(self.color_budget, self.spill_dir.clone()));
                self.first_colored = index;
            }
            if let Some(store) = self.colors.as_mut() {
                store.push(color).map_err(io_err(&self.path, at))?;
            }
        } else if let Some(store) = self.colors.as_mut() {
            store.push(NO_COLOR).map_err(io_err(&self.path, at))?;
        }
        Ok(())
    }

    /// `vn i j k`.
    fn normal(&mut self, rest: &[u8], at: u64) -> Result<(), ImportError> {
        let mut values = [0.0f32; 3];
        let mut n = 0;
        for token in tokens(rest) {
            let v = self.finite(token, "normal", at)?;
            if let Some(slot) = values.get_mut(n) {
                *slot = v as f32;
            }
            n += 1;
        }
        if n < 3 {
            return Err(self.err(at, format!("a normal needs 3 components, found {n}")));
        }
        self.normals.push(values).map_err(io_err(&self.path, at))
    }

    /// `vt u [v [w]]`: checked and counted, not kept.
    fn texcoord(&mut self, rest: &[u8], at: u64) -> Result<(), ImportError> {
        let mut n = 0;
        for token in tokens(rest) {
            self.finite(token, "texture coordinate", at)?;
            n += 1;
        }
        if n == 0 {
            return Err(self.err(at, "a texture coordinate needs at least 1 number"));
        }
        self.texcoords += 1;
        Ok(())
    }

    /// A finite number, or an error naming `what` it belongs to.
    fn finite(&self, token: &[u8], what: &str, at: u64) -> Result<f64, ImportError> {
        match parse_f64(token) {
            Some(v) if v.is_finite() => Ok(v),
            Some(_) => Err(self.err(at, format!("{what} has a non-finite number \"{}\"", show(token)))),
            None => Err(self.err(at, format!("malformed number \"{}\" in a {what}", show(token)))),
        }
    }

    /// Stage 4: `f v1 v2 v3 …` with corners `i`, `i/t`, `i//n` or `i/t/n`.
    fn face(&mut self, rest: &[u8], at: u64) -> Result<(), ImportError> {
        self.corners.clear();
        for token in tokens(rest) {
            if self.corners.len() == MAX_FACE_VERTICES {
                return Err(self.err(at, format!("a face has more than {MAX_FACE_VERTICES} vertices")));
            }
            let corner = self.corner(token, at)?;
            self.corners.push(corner);
        }
        let n = self.corners.len();
        if n < 3 {
            return Err(self.err(at, format!("a face needs at least 3 vertices, found {n}")));
        }
        let object = self.object_for_face(at)?;

        let with_normals = self.corners.iter().all(|c| c.normal.is_some());
        self.fetched.clear();
        for k in 0..n {
            let corner = self.corners[k];
            let position = self.positions.get(corner.vertex).map_err(io_err(&self.path, at))?;
            let normal = match corner.normal {
                Some(i) if with_normals => Some(self.normals.get(i).map_err(io_err(&self.path, at))?),
                _ => None,
            };
            let color = match self.colors.as_mut() {
                Some(store) if corner.vertex >= self.first_colored => {
                    let c = store.get(corner.vertex - self.first_colored).map_err(io_err(&self.path, at))?;
                    (c != NO_COLOR).then_some(c)
                }
                _ => None,
            };
            self.fetched.push(Fetched { position, normal, color });
        }

        let a = self.fetched[0];
        for k in 1..n - 1 {
            let (b, c) = (self.fetched[k], self.fetched[k + 1]);
            let normals = match (a.normal, b.normal, c.normal) {
                (Some(x), Some(y), Some(z)) => Some([x, y, z]),
                _ => None,
            };
            let colors = match (a.color, b.color, c.color) {
                (Some(x), Some(y), Some(z)) => Some([x, y, z]),
                _ => None,
            };
            let triangle =
                Triangle { positions: [a.position, b.position, c.position], normals, colors, object };
            self.sink.triangle(&triangle)?;
        }
        Ok(())
    }

    /// One face corner `v[/[t][/n]]`, checked against the elements defined so far.
    fn corner(&self, token: &[u8], at: u64) -> Result<Corner, ImportError> {
        let (v, rest) = split_slash(token);
        let vertex = self.resolve(v, self.positions.len(), "vertex", "vertices", at)?;
        let mut normal = None;
        if let Some(rest) = rest {
            let (t, n) = split_slash(rest);
            if !t.is_empty() {
                self.resolve(t, self.texcoords, "texture coordinate", "texture coordinates", at)?;
            }
            if let Some(n) = n.filter(|n| !n.is_empty()) {
                normal = Some(self.resolve(n, self.normals.len(), "normal", "normals", at)?);
            }
        }
        Ok(Corner { vertex, normal })
    }

    /// A 1-based (or negative, relative) index into `count` elements, as a 0-based index.
    fn resolve(
        &self,
        token: &[u8],
        count: u64,
        what: &str,
        plural: &str,
        at: u64,
    ) -> Result<u64, ImportError> {
        let Some(i) = parse_index(token) else {
            return Err(self.err(at, format!("malformed {what} index \"{}\"", show(token))));
        };
        if i > 0 && i.unsigned_abs() <= count {
            return Ok(i.unsigned_abs() - 1);
        }
        if i < 0 && i.unsigned_abs() <= count {
            return Ok(count - i.unsigned_abs());
        }
        if i == 0 {
            return Err(self.err(at, format!("{what} index 0 is invalid (OBJ indices start at 1)")));
        }
        Err(self.err(at, format!("{what} index {i} is out of range: {count} {plural} are defined so far")))
    }

    /// Stage 5: the object the current face belongs to, announcing it to the sink if it is new.
    fn object_for_face(&mut self, at: u64) -> Result<ObjectId, ImportError> {
        if let Some(id) = self.current {
            return Ok(id);
        }
        if let Some(&id) = self.group_objects.get(&self.material) {
            self.current = Some(id);
            return Ok(id);
        }
        let name = match &self.material {
            Some(m) if !self.group_objects.is_empty() => {
                format!("{}/{}", self.group, String::from_utf8_lossy(m))
            }
            _ => self.group.clone(),
        };
        let color = match self.material.clone() {
            None => None,
            Some(m) => match self.materials.get(&m) {
                Some(color) => *color,
                None => {
                    let mut key = b"usemtl ".to_vec();
                    key.extend_from_slice(&m);
                    self.warn_once(&key, at, || {
                        format!("material \"{}\" is not defined in any mtllib", String::from_utf8_lossy(&m))
                    });
                    None
                }
            },
        };
        let id = self.objects;
        self.objects = id.checked_add(1).ok_or_else(|| self.err(at, "more than 2^32 objects"))?;
        self.sink.object(id, &ObjectInfo { name, color })?;
        self.group_objects.insert(self.material.clone(), id);
        self.current = Some(id);
        Ok(id)
    }

    /// `mtllib a.mtl [b.mtl …]`: reads the libraries now. A name with spaces works when the whole
    /// rest of the line names an existing file.
    fn mtllib(&mut self, rest: &[u8], at: u64) {
        let whole = trim(rest);
        if whole.is_empty() {
            tracing::warn!("{}: line {at}: mtllib without a file name", self.path.display());
            return;
        }
        let path = self.mtl_path(whole);
        if path.is_file() {
            self.load_mtl(&path, at);
            return;
        }
        for name in tokens(whole) {
            let path = self.mtl_path(name);
            self.load_mtl(&path, at);
        }
    }

    /// Resolves a material library name relative to the OBJ's directory; a Windows path
    /// (backslashes) that does not exist as written is tried with slashes.
    fn mtl_path(&self, name: &[u8]) -> PathBuf {
        let path = self.dir.join(path_from_bytes(name));
        if !path.is_file() && name.contains(&b'\\') {
            let slashed: Vec<u8> = name.iter().map(|&b| if b == b'\\' { b'/' } else { b }).collect();
            return self.dir.join(path_from_bytes(&slashed));
        }
        path
    }

    fn load_mtl(&mut self, path: &Path, at: u64) {
        if let Err(e) = mtl::load(path, &mut self.materials) {
            tracing::warn!(
                "{}: line {at}: material library {} cannot be read ({e}); its materials get no colour",
                self.path.display(),
                path.display()
            );
        }
    }
}

/// Turns a vertex store's I/O error (spilling to disk) into an import error at `line`.
fn io_err(path: &Path, line: u64) -> impl FnOnce(io::Error) -> ImportError + '_ {
    move |e| ImportError::io(path, Position::Line(line), e)
}

/// The file name without `.gz` and its extension: "/a/Pump.obj.gz" gives "Pump".
fn file_stem(path: &Path) -> String {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let name = name.strip_suffix(".gz").or_else(|| name.strip_suffix(".GZ")).unwrap_or(&name);
    match name.rsplit_once('.') {
        Some((stem, _)) if !stem.is_empty() => stem.to_string(),
        _ => name.to_string(),
    }
}

/// A token for an error message: lossy UTF-8, at most 40 characters.
fn show(token: &[u8]) -> String {
    let s = String::from_utf8_lossy(&token[..token.len().min(40)]);
    if token.len() > 40 {
        format!("{s}…")
    } else {
        s.into_owned()
    }
}

/// Whitespace between tokens: space, tab, CR, vertical tab, form feed.
#[inline]
pub(crate) fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r' | 0x0b | 0x0c)
}

fn trim_start(s: &[u8]) -> &[u8] {
    let start = s.iter().position(|&b| !is_space(b)).unwrap_or(s.len());
    &s[start..]
}

fn trim_end(s: &[u8]) -> &[u8] {
    let end = s.iter().rposition(|&b| !is_space(b)).map_or(0, |i| i + 1);
    &s[..end]
}

pub(crate) fn trim(s: &[u8]) -> &[u8] {
    trim_end(trim_start(s))
}

/// The whitespace-separated tokens of `s`.
pub(crate) fn tokens(s: &[u8]) -> Tokens<'_> {
    Tokens { rest: s }
}

pub(crate) struct Tokens<'a> {
    rest: &'a [u8],
}

impl<'a> Iterator for Tokens<'a> {
    type Item = &'a [u8];

    #[inline]
    fn next(&mut self) -> Option<&'a [u8]> {
        let mut s = self.rest;
        while let [first, tail @ ..] = s {
            if !is_space(*first) {
                break;
            }
            s = tail;
        }
        if s.is_empty() {
            self.rest = s;
            return None;
        }
        let end = s.iter().position(|&b| is_space(b)).unwrap_or(s.len());
        let (token, rest) = s.split_at(end);
        self.rest = rest;
        Some(token)
    }
}

/// The index of the first `\n`, eight bytes at a time.
#[inline]
fn find_newline(s: &[u8]) -> Option<usize> {
    const LO: u64 = 0x0101_0101_0101_0101;
    const HI: u64 = 0x8080_8080_8080_8080;
    const NL: u64 = LO * b'\n' as u64;
    let mut i = 0;
    while i + 8 <= s.len() {
        let word = u64::from_le_bytes(s[i..i + 8].try_into().expect("8 bytes"));
        let x = word ^ NL;
        let found = x.wrapping_sub(LO) & !x & HI;
        if found != 0 {
            return Some(i + (found.trailing_zeros() / 8) as usize);
        }
        i += 8;
    }
    s[i..].iter().position(|&b| b == b'\n').map(|k| i + k)
}

/// `a/b/c` → (`a`, Some(`b/c`)); `a` → (`a`, None).
#[inline]
fn split_slash(s: &[u8]) -> (&[u8], Option<&[u8]>) {
    match s.iter().position(|&b| b == b'/') {
        Some(i) => (&s[..i], Some(&s[i + 1..])),
        None => (s, None),
    }
}

/// An OBJ index: an optional sign and 1 to 18 digits (larger values cannot be in range).
#[inline]
fn parse_index(s: &[u8]) -> Option<i64> {
    let (negative, digits) = match s {
        [b'-', rest @ ..] => (true, rest),
        [b'+', rest @ ..] => (false, rest),
        _ => (false, s),
    };
    if digits.is_empty() || digits.len() > 18 {
        return None;
    }
    let mut value: i64 = 0;
    for &c in digits {
        let d = c.wrapping_sub(b'0');
        if d > 9 {
            return None;
        }
        value = value * 10 + d as i64;
    }
    Some(if negative { -value } else { value })
}

/// Exact powers of ten representable in an f64.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18,
    1e19, 1e20, 1e21, 1e22,
];

/// Parses a number as `str::parse::<f64>` would (same result, bit for bit), or `None`.
///
/// Fast path for plain decimals (`-12.345`): with at most 19 digits the mantissa is an exact
/// integer; when it is below 2^53 and there are at most 22 fraction digits, both it and the power
/// of ten are exact f64s and one division rounds correctly (Clinger 1990). Everything else
/// (exponents, long mantissas, `inf`, `nan`, non-ASCII) goes to `str::parse`.
#[inline]
pub(crate) fn parse_f64(s: &[u8]) -> Option<f64> {
    let (negative, body) = match s {
        [b'-', rest @ ..] => (true, rest),
        [b'+', rest @ ..] => (false, rest),
        _ => (false, s),
    };
    let mut mantissa: u64 = 0;
    let mut i = 0;
    while let Some(&c) = body.get(i) {
        let d = c.wrapping_sub(b'0');
        if d > 9 {
            break;
        }
        mantissa = mantissa.wrapping_mul(10).wrapping_add(d as u64);
        i += 1;
    }
    let int_digits = i;
    let mut frac_digits = 0;
    if body.get(i) == Some(&b'.') {
        i += 1;
        let start = i;
        while let Some(&c) = body.get(i) {
            let d = c.wrapping_sub(b'0');
            if d > 9 {
                break;
            }
            mantissa = mantissa.wrapping_mul(10).wrapping_add(d as u64);
            i += 1;
        }
        frac_digits = i - start;
    }
    let digits = int_digits + frac_digits;
    if i == body.len() && digits > 0 && digits <= 19 && mantissa < (1 << 53) && frac_digits < POW10.len() {
        let v = mantissa as f64 / POW10[frac_digits];
        return Some(if negative { -v } else { v });
    }
    std::str::from_utf8(s).ok()?.parse().ok()
}

/// A file name as an OBJ file spells it. On Unix a path is bytes, so any name is kept exactly;
/// elsewhere paths are Unicode and a name that is not UTF-8 is read with replacement characters
/// (such a file then is not found, which is reported like any missing material library).
#[cfg(unix)]
fn path_from_bytes(name: &[u8]) -> PathBuf {
    PathBuf::from(<std::ffi::OsStr as std::os::unix::ffi::OsStrExt>::from_bytes(name))
}

/// A file name as an OBJ file spells it (see the Unix version).
#[cfg(not(unix))]
fn path_from_bytes(name: &[u8]) -> PathBuf {
    PathBuf::from(String::from_utf8_lossy(name).into_owned())
}

#[cfg(test)]
mod tests;
