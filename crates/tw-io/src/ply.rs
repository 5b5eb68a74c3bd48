//! PLY importer: streams the triangles of ASCII and binary (little- and big-endian) PLY 1.0 files.
//!
//! Follows Greg Turk's "The PLY Polygon File Format" (1994) and the conventions of its common
//! writers (Stanford scans, MeshLab, Blender, Open3D, PCL):
//! - header: `comment`/`obj_info` lines, any elements with scalar properties of the types
//!   `char uchar short ushort int uint float double` (and `int8 … float64`) and list properties
//!   with any integer count type and any item type;
//! - element `vertex`: `x y z` (any numeric type), optional `nx ny nz` (or `normal_x …`) and
//!   `red green blue [alpha]` (or `diffuse_red …`; integers are 0..255, `ushort` 0..65535,
//!   floats 0..1); other properties are skipped;
//! - element `face`: the list `vertex_indices` (or `vertex_index`) of any integer types; polygons
//!   are fan-triangulated, faces of fewer than three vertices are skipped (and counted in a
//!   warning); a scalar integer property `object` (or `object_id`), as terawalk's PLY writer
//!   writes it, gives each face's object (see below); other face properties are skipped;
//! - any other element (`edge`, `material`, `tristrips`…), before, between or after these, is
//!   skipped.
//!
//! Objects: without a per-face `object` property (or without faces) the file is one object (id 0)
//! named after the file. With it, the file's ids are arbitrary integers: each new one, in order of
//! first appearance, becomes the next dense id (0, 1, 2, …), announced as `<file name>/<id in the
//! file>` just before its first triangle (memory grows with the number of objects, not of faces).
//!
//! Stages:
//! 1. [`open`] reads the header (`read_header`) and checks that a binary file is long enough
//!    for its declared counts, so that a broken file fails before any work.
//! 2. [`PlySource::stream`] walks the elements in file order: vertex records go into
//!    [`VertexStore`]s (positions, and normals and colours when present) under the memory budget
//!    of [`ImportOptions::vertex_memory`], spilling to disk beyond it; positions are kept as `f32`
//!    when the file's coordinate types convert to `f32` exactly (the usual `float x y z`), which
//!    halves memory and spilling, and as `f64` otherwise. Face records are resolved
//!    through the stores and streamed as triangles; other elements are skipped.
//! 3. Binary faces whose records are triangles of one size (every property a scalar but the
//!    index list, its count 3: what terawalk writes and most large scans are) go in runs
//!    (`Body::binary_triangles`): `scan_run` checks a run's counts and indices in order,
//!    makes the vertex blocks it uses resident and resolves its objects, and the run goes to
//!    the sink as one [`TriangleBatch`], which the sink may resolve on several threads (the
//!    build does). Any other record (a polygon, a short face) is read the general way in
//!    between; triangles, order, objects and errors are the same either way.
//!
//! Binary records are decoded straight out of the read buffer (`ByteReader`): a record of a
//! fixed layout is a constant set of offsets, a record with lists is measured once and decoded in
//! place, with no per-record allocation and no reads through a trait object. ASCII records are
//! one line each.
//!
//! Limits and choices: faces must come after vertices (the usual order; the other order would
//! need the faces held until the vertices arrive); lists in vertex and face records hold at most
//! [`MAX_LIST`] items; a file without faces (a point cloud) yields no triangles and its vertex
//! data is skipped unread; a non-finite position is an error, a non-finite normal becomes zero.

use std::collections::HashMap;
use std::io::{self, Read};
use std::ops::Range;
use std::path::{Path, PathBuf};

use tw_core::Rgba8;

use crate::error::{ImportError, Position};
use crate::format::ImportOptions;
use crate::input::{DiskCounter, Input};
use crate::vertex_store::{VertexStore, BLOCK_SHIFT};
use crate::{
    NewObject, ObjectId, ObjectInfo, SourceSummary, Triangle, TriangleBatch, TriangleSink, TriangleSource,
};

/// Most items a list in a vertex or face record may hold (so a face has at most this many
/// vertices); a longer list is an error, not an allocation.
pub const MAX_LIST: i64 = 1 << 16;
/// Most items a list in a skipped element may hold.
const MAX_SKIPPED_LIST: i64 = 1 << 20;
/// Longest header line, and the most bytes a header may take.
const MAX_HEADER_LINE: usize = 64 << 10;
const MAX_HEADER_BYTES: usize = 16 << 20;
/// Most elements, and properties over all elements, a header may declare.
const MAX_ELEMENTS: usize = 4096;
const MAX_PROPERTIES: usize = 4096;
/// Longest line of an ASCII body (a face of [`MAX_LIST`] indices fits easily).
const MAX_ASCII_LINE: usize = 4 << 20;

/// Opens a PLY file for streaming: reads and checks the header.
pub fn open(input: Input, options: &ImportOptions) -> Result<Box<dyn TriangleSource>, ImportError> {
    let path = input.path.clone();
    let (gzip, file_len, counter) = (input.gzip, input.file_len, input.disk_counter());
    let mut rd = ByteReader::new(input);
    let header = read_header(&mut rd, &path)?;
    if header.encoding != Encoding::Ascii && !gzip {
        // Every record takes at least its scalars and list counts: a file too short for the
        // declared counts is truncated, and we say so now rather than after hours of work.
        let need: u128 =
            header.elements.iter().map(|e| e.count as u128 * min_record_size(&e.props) as u128).sum();
        let have = file_len.saturating_sub(rd.position()) as u128;
        if need > have {
            return Err(ImportError::parse(
                &path,
                Position::Byte(file_len),
                format!(
                    "the file is truncated: the header declares {} needing at least {need} bytes of data, \
                     but only {have} follow the header",
                    header.describe_counts()
                ),
            ));
        }
    }
    Ok(Box::new(PlySource { path, rd, header, options: options.clone(), counter, file_len }))
}

/// The object name of a file: its name without `.gz` and without its extension.
pub(crate) fn object_name(path: &Path) -> String {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let name =
        if name.to_ascii_lowercase().ends_with(".gz") { name[..name.len() - 3].to_string() } else { name };
    match name.rfind('.') {
        Some(i) if i > 0 => name[..i].to_string(),
        _ => name,
    }
}

// ---------------------------------------------------------------------------------------------
// Reading bytes

/// Bytes at the start of the remaining stream: the largest buffer a [`ByteReader`] may grow to.
const MAX_BUFFER: usize = 64 << 20;
/// The first size of a [`ByteReader`]'s buffer: larger than [`crate::input::READ_BUFFER`], so
/// that reads go straight from the file's reader into it rather than through the `BufReader`.
const CHUNK: usize = 4 * crate::input::READ_BUFFER;
/// Most faces in one [`TriangleRun`] (its memory, and the sink's for the batch, are bounded
/// by it whatever the buffer holds).
const MAX_RUN: usize = 1 << 17;

/// A read buffer under the parsers (shared by the PLY and STL importers): records and lines are
/// parsed in place from [`ByteReader::available`]; [`ByteReader::fill_more`] moves the unread
/// tail to the front and reads more behind it, so a record or line that straddles two reads is
/// still contiguous.
pub(crate) struct ByteReader {
    inner: Box<dyn Read + Send>,
    buf: Vec<u8>,
    pos: usize,
    end: usize,
    /// Stream offset of `buf[0]`.
    base: u64,
    eof: bool,
    /// Set by every read; parsers clear it to report progress about once per [`CHUNK`].
    refilled: bool,
}

/// A line found by [`ByteReader::read_line`]: a range valid until the reader moves on.
pub(crate) enum Line {
    Text(Range<usize>),
    Eof,
    TooLong,
}

impl ByteReader {
    pub(crate) fn new(input: Input) -> ByteReader {
        ByteReader {
            inner: Box::new(input.into_reader()),
            buf: vec![0; CHUNK],
            pos: 0,
            end: 0,
            base: 0,
            eof: false,
            refilled: false,
        }
    }

    /// The buffered bytes not consumed yet.
    #[inline]
    pub(crate) fn available(&self) -> &[u8] {
        &self.buf[self.pos..self.end]
    }

    /// Bytes of a range [`ByteReader::read_line`] returned.
    #[inline]
    pub(crate) fn bytes(&self, r: Range<usize>) -> &[u8] {
        &self.buf[r]
    }

    /// Marks `n` available bytes as used; `n <= available().len()`.
    #[inline]
    pub(crate) fn consume(&mut self, n: usize) {
        debug_assert!(n <= self.end - self.pos);
        self.pos += n;
    }

    /// Stream offset of the first available byte: bytes consumed so far.
    #[inline]
    pub(crate) fn position(&self) -> u64 {
        self.base + self.pos as u64
    }

    /// True once after each read from the stream: time to report progress.
    #[inline]
    pub(crate) fn take_refilled(&mut self) -> bool {
        std::mem::take(&mut self.refilled)
    }

    /// Reads more bytes behind the available ones; returns how many (0 at the end of the stream).
    /// Grows the buffer when the available bytes fill it, up to 64 MiB.
    pub(crate) fn fill_more(&mut self) -> io::Result<usize> {
        if self.eof {
            return Ok(0);
        }
        if self.pos > 0 {
            self.buf.copy_within(self.pos..self.end, 0);
            self.base += self.pos as u64;
            self.end -= self.pos;
            self.pos = 0;
        }
        if self.end == self.buf.len() {
            if self.buf.len() >= MAX_BUFFER {
                return Err(io::Error::new(
                    io::ErrorKind::InvalidData,
                    "a record or line is larger than 64 MiB",
                ));
            }
            self.buf.resize(self.buf.len() * 2, 0);
        }
        loop {
            match self.inner.read(&mut self.buf[self.end..]) {
                Ok(0) => {
                    self.eof = true;
                    return Ok(0);
                }
                Ok(n) => {
                    self.end += n;
                    self.refilled = true;
                    return Ok(n);
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
    }

    /// Makes at least `n` bytes available; false when the stream ends first.
    pub(crate) fn ensure(&mut self, n: usize) -> io::Result<bool> {
        while self.end - self.pos < n {
            if self.fill_more()? == 0 {
                return Ok(false);
            }
        }
        Ok(true)
    }

    /// Skips `n` bytes; returns how many were there to skip.
    pub(crate) fn skip(&mut self, n: u64) -> io::Result<u64> {
        let mut left = n;
        loop {
            let take = ((self.end - self.pos) as u64).min(left);
            self.pos += take as usize;
            left -= take;
            if left == 0 || self.fill_more()? == 0 {
                return Ok(n - left);
            }
        }
    }

    /// The next line without its `\n` or `\r\n`; the last line may lack the terminator.
    pub(crate) fn read_line(&mut self, max: usize) -> io::Result<Line> {
        let mut scanned = 0;
        loop {
            let avail = &self.buf[self.pos..self.end];
            if let Some(i) = avail[scanned..].iter().position(|&b| b == b'\n') {
                let start = self.pos;
                let mut end = start + scanned + i;
                self.pos = end + 1;
                if end > start && self.buf[end - 1] == b'\r' {
                    end -= 1;
                }
                return Ok(if end - start > max { Line::TooLong } else { Line::Text(start..end) });
            }
            scanned = avail.len();
            if scanned > max {
                return Ok(Line::TooLong);
            }
            if self.fill_more()? == 0 {
                if self.pos == self.end {
                    return Ok(Line::Eof);
                }
                let start = self.pos;
                let mut end = self.end;
                self.pos = end;
                if self.buf[end - 1] == b'\r' {
                    end -= 1;
                }
                return Ok(Line::Text(start..end));
            }
        }
    }

    /// True when nothing but ASCII whitespace is left in the stream (reads to find out).
    pub(crate) fn only_whitespace_left(&mut self) -> io::Result<bool> {
        loop {
            if !self.available().iter().all(u8::is_ascii_whitespace) {
                return Ok(false);
            }
            let n = self.end - self.pos;
            self.consume(n);
            if self.fill_more()? == 0 {
                return Ok(true);
            }
        }
    }
}

/// Whitespace-separated tokens of a line.
pub(crate) struct Tokens<'a> {
    rest: &'a [u8],
}

impl<'a> Tokens<'a> {
    pub(crate) fn new(line: &'a [u8]) -> Self {
        Tokens { rest: line }
    }
}

impl<'a> Iterator for Tokens<'a> {
    type Item = &'a [u8];
    #[inline]
    fn next(&mut self) -> Option<&'a [u8]> {
        let start = self.rest.iter().position(|b| !b.is_ascii_whitespace())?;
        let rest = &self.rest[start..];
        let len = rest.iter().position(|b| b.is_ascii_whitespace()).unwrap_or(rest.len());
        self.rest = &rest[len..];
        Some(&rest[..len])
    }
}

/// A decimal number (as `str::parse` reads it; `inf`/`nan` parse and are rejected by callers).
#[inline]
pub(crate) fn parse_f64(t: &[u8]) -> Option<f64> {
    std::str::from_utf8(t).ok()?.parse().ok()
}

#[inline]
fn parse_i64(t: &[u8]) -> Option<i64> {
    std::str::from_utf8(t).ok()?.parse().ok()
}

/// A token for messages, shortened and made printable.
pub(crate) fn show(t: &[u8]) -> String {
    let s = String::from_utf8_lossy(&t[..t.len().min(40)]).into_owned();
    if t.len() > 40 {
        s + "…"
    } else {
        s
    }
}

// ---------------------------------------------------------------------------------------------
// Header

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Encoding {
    Ascii,
    BinaryLe,
    BinaryBe,
}

/// A scalar type of the PLY header.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &str) -> Option<Scalar> {
        Some(match name {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    #[inline]
    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// The value at the start of `b` (which holds at least `size()` bytes).
    #[inline(always)]
    fn f64(self, b: &[u8], big: bool) -> f64 {
        match self {
            Scalar::F32 => f32::from_bits(u32_at(b, big)) as f64,
            Scalar::F64 => f64::from_bits(u64_at(b, big)),
            _ => self.i64(b, big) as f64,
        }
    }

    /// The integer at the start of `b` (floats are truncated; the header allows only integer
    /// types where this is used).
    #[inline(always)]
    fn i64(self, b: &[u8], big: bool) -> i64 {
        match self {
            Scalar::I8 => b[0] as i8 as i64,
            Scalar::U8 => b[0] as i64,
            Scalar::I16 => u16_at(b, big) as i16 as i64,
            Scalar::U16 => u16_at(b, big) as i64,
            Scalar::I32 => u32_at(b, big) as i32 as i64,
            Scalar::U32 => u32_at(b, big) as i64,
            Scalar::F32 | Scalar::F64 => self.f64(b, big) as i64,
        }
    }
}

#[inline(always)]
fn u16_at(b: &[u8], big: bool) -> u16 {
    let a = [b[0], b[1]];
    if big {
        u16::from_be_bytes(a)
    } else {
        u16::from_le_bytes(a)
    }
}

#[inline(always)]
fn u32_at(b: &[u8], big: bool) -> u32 {
    let a: [u8; 4] = b[..4].try_into().expect("4 bytes");
    if big {
        u32::from_be_bytes(a)
    } else {
        u32::from_le_bytes(a)
    }
}

#[inline(always)]
fn u64_at(b: &[u8], big: bool) -> u64 {
    let a: [u8; 8] = b[..8].try_into().expect("8 bytes");
    if big {
        u64::from_be_bytes(a)
    } else {
        u64::from_le_bytes(a)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    kind: PropKind,
    line: u64,
}

/// What a vertex property means to us.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Role {
    X,
    Y,
    Z,
    Nx,
    Ny,
    Nz,
    R,
    G,
    B,
    A,
}

impl Role {
    fn of(name: &str) -> Option<Role> {
        Some(match name {
            "x" => Role::X,
            "y" => Role::Y,
            "z" => Role::Z,
            "nx" | "normal_x" => Role::Nx,
            "ny" | "normal_y" => Role::Ny,
            "nz" | "normal_z" => Role::Nz,
            "red" | "diffuse_red" => Role::R,
            "green" | "diffuse_green" => Role::G,
            "blue" | "diffuse_blue" => Role::B,
            "alpha" | "diffuse_alpha" => Role::A,
            _ => return None,
        })
    }
}

/// The vertex properties we read: (property index, role, type), and which attributes exist.
#[derive(Clone, Debug)]
struct VertexLayout {
    fields: Vec<(usize, Role, Scalar)>,
    /// `roles[p]` is the role of property `p`, if we read it.
    roles: Vec<Option<Role>>,
    normals: bool,
    colors: bool,
}

/// Where a face keeps its indices: property index and the list's types; and its object id,
/// when it has one: property index and type.
#[derive(Clone, Copy, Debug)]
struct FaceLayout {
    prop: usize,
    count: Scalar,
    item: Scalar,
    object: Option<(usize, Scalar)>,
}

#[derive(Clone, Debug)]
enum ElementRole {
    Vertex(VertexLayout),
    Face(FaceLayout),
    Other,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: u64,
    props: Vec<Property>,
    line: u64,
    role: ElementRole,
}

#[derive(Clone, Debug)]
struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Lines in the header, `end_header` included.
    lines: u64,
}

impl Header {
    fn count_of(&self, f: impl Fn(&ElementRole) -> bool) -> u64 {
        self.elements.iter().find(|e| f(&e.role)).map_or(0, |e| e.count)
    }

    fn describe_counts(&self) -> String {
        let v: Vec<String> = self.elements.iter().map(|e| format!("{} {}", e.count, e.name)).collect();
        v.join(", ")
    }
}

/// Smallest possible size of a binary record: its scalars and list counts.
fn min_record_size(props: &[Property]) -> usize {
    props
        .iter()
        .map(|p| match p.kind {
            PropKind::Scalar(t) => t.size(),
            PropKind::List { count, .. } => count.size(),
        })
        .sum()
}

/// Reads the header, up to and including the `end_header` line, and works out the layouts of
/// the vertex and face elements.
fn read_header(rd: &mut ByteReader, path: &Path) -> Result<Header, ImportError> {
    let mut line_no = 0u64;
    let mut header_bytes = 0usize;
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut properties = 0usize;
    loop {
        line_no += 1;
        let err = |msg: String| ImportError::parse(path, Position::Line(line_no), msg);
        let range = match rd
            .read_line(MAX_HEADER_LINE)
            .map_err(|e| ImportError::io(path, Position::Line(line_no), e))?
        {
            Line::Text(r) => r,
            Line::Eof if line_no == 1 => return Err(ImportError::parse(path, Position::File, "empty file")),
            Line::Eof => return Err(err("the file ends inside the header (no \"end_header\" line)".into())),
            Line::TooLong => return Err(err(format!("header line longer than {MAX_HEADER_LINE} bytes"))),
        };
        header_bytes += range.len() + 1;
        if header_bytes > MAX_HEADER_BYTES {
            return Err(err(format!("the header is longer than {MAX_HEADER_BYTES} bytes")));
        }
        let bytes = rd.bytes(range);
        if line_no == 1 {
            if bytes.trim_ascii_end() != b"ply" {
                return Err(err("not a PLY file: the first line must be \"ply\"".into()));
            }
            continue;
        }
        let Ok(text) = std::str::from_utf8(bytes) else {
            return Err(err("the header line is not text (binary data inside the header?)".into()));
        };
        let mut words = text.split_ascii_whitespace();
        let Some(keyword) = words.next() else { continue };
        match keyword {
            "comment" | "obj_info" => continue,
            "format" => {
                let (Some(name), Some(version), None) = (words.next(), words.next(), words.next()) else {
                    return Err(err(
                        "expected \"format <ascii|binary_little_endian|binary_big_endian> 1.0\"".into(),
                    ));
                };
                if encoding.is_some() {
                    return Err(err("a second \"format\" line".into()));
                }
                encoding = Some(match name {
                    "ascii" => Encoding::Ascii,
                    "binary_little_endian" => Encoding::BinaryLe,
                    "binary_big_endian" => Encoding::BinaryBe,
                    _ => {
                        return Err(err(format!(
                            "unknown format \"{name}\" (expected ascii, binary_little_endian or binary_big_endian)"
                        )))
                    }
                });
                if version != "1.0" && version != "1" {
                    return Err(err(format!("unsupported PLY version {version} (only 1.0 is defined)")));
                }
            }
            "element" => {
                let (Some(name), Some(count), None) = (words.next(), words.next(), words.next()) else {
                    return Err(err("expected \"element <name> <count>\"".into()));
                };
                let Ok(count) = count.parse::<u64>() else {
                    return Err(err(format!("invalid count \"{count}\" for element {name}")));
                };
                if elements.len() >= MAX_ELEMENTS {
                    return Err(err(format!("more than {MAX_ELEMENTS} elements")));
                }
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                    line: line_no,
                    role: ElementRole::Other,
                });
            }
            "property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(err("a property before any element".into()));
                };
                let words: Vec<&str> = words.collect();
                let ty = |name: &str| {
                    Scalar::parse(name).ok_or_else(|| err(format!("unknown property type \"{name}\"")))
                };
                let (kind, name) = match words.as_slice() {
                    ["list", count, item, name] => {
                        let count = ty(count)?;
                        if !count.is_integer() {
                            return Err(err(format!("the count type of list {name} must be an integer type")));
                        }
                        (PropKind::List { count, item: ty(item)? }, name)
                    }
                    [t, name] if *t != "list" => (PropKind::Scalar(ty(t)?), name),
                    _ => {
                        return Err(err(
                            "expected \"property <type> <name>\" or \"property list <count type> <item type> <name>\""
                                .into(),
                        ))
                    }
                };
                properties += 1;
                if properties > MAX_PROPERTIES {
                    return Err(err(format!("more than {MAX_PROPERTIES} properties")));
                }
                element.props.push(Property { name: name.to_string(), kind, line: line_no });
            }
            "end_header" => break,
            // Real exporters write stray lines (Blender 2.47: "Created by Blender3D ..." without
            // "comment"); readers such as trimesh and assimp skip them, and so do we.
            _ => {
                tracing::warn!("{}: line {line_no}: skipping unknown header line", path.display());
            }
        }
    }
    let Some(encoding) = encoding else {
        return Err(ImportError::parse(path, Position::Line(line_no), "the header has no \"format\" line"));
    };
    assign_roles(&mut elements, path)?;
    Ok(Header { encoding, elements, lines: line_no })
}

/// Finds the vertex and face elements and the properties we read from them.
fn assign_roles(elements: &mut [Element], path: &Path) -> Result<(), ImportError> {
    let at = |line: u64, msg: String| ImportError::parse(path, Position::Line(line), msg);
    let mut vertex_at: Option<usize> = None;
    let mut face_at: Option<usize> = None;
    for (ei, el) in elements.iter_mut().enumerate() {
        match el.name.as_str() {
            "vertex" => {
                if vertex_at.is_some() {
                    return Err(at(el.line, "a second \"vertex\" element is not supported".into()));
                }
                vertex_at = Some(ei);
                let mut roles = vec![None; el.props.len()];
                let mut fields: Vec<(usize, Role, Scalar)> = Vec::new();
                for (pi, p) in el.props.iter().enumerate() {
                    let Some(role) = Role::of(&p.name) else { continue };
                    let PropKind::Scalar(t) = p.kind else {
                        return Err(at(
                            p.line,
                            format!("vertex property {} must be a scalar, not a list", p.name),
                        ));
                    };
                    if fields.iter().any(|f| f.1 == role) {
                        return Err(at(p.line, format!("vertex property {} given twice", p.name)));
                    }
                    roles[pi] = Some(role);
                    fields.push((pi, role, t));
                }
                let has = |r: Role| fields.iter().any(|f| f.1 == r);
                for (r, name) in [(Role::X, "x"), (Role::Y, "y"), (Role::Z, "z")] {
                    if !has(r) {
                        return Err(at(el.line, format!("the vertex element has no property \"{name}\"")));
                    }
                }
                let normals = has(Role::Nx) && has(Role::Ny) && has(Role::Nz);
                let colors = has(Role::R) && has(Role::G) && has(Role::B);
                let partial_normals = !normals && (has(Role::Nx) || has(Role::Ny) || has(Role::Nz));
                let partial_colors =
                    !colors && (has(Role::R) || has(Role::G) || has(Role::B) || has(Role::A));
                if partial_normals || partial_colors {
                    tracing::warn!(
                        "{}: vertex normals or colours are incomplete (need nx ny nz, red green blue); ignored",
                        path.display()
                    );
                }
                let used = |r: Role| match r {
                    Role::X | Role::Y | Role::Z => true,
                    Role::Nx | Role::Ny | Role::Nz => normals,
                    Role::R | Role::G | Role::B | Role::A => colors,
                };
                fields.retain(|f| used(f.1));
                for r in roles.iter_mut() {
                    if r.is_some_and(|r| !used(r)) {
                        *r = None;
                    }
                }
                el.role = ElementRole::Vertex(VertexLayout { fields, roles, normals, colors });
            }
            "face" => {
                if face_at.is_some() {
                    return Err(at(el.line, "a second \"face\" element is not supported".into()));
                }
                face_at = Some(ei);
                let Some((prop, p)) = el
                    .props
                    .iter()
                    .enumerate()
                    .find(|(_, p)| p.name == "vertex_indices" || p.name == "vertex_index")
                else {
                    return Err(at(el.line, "the face element has no list \"vertex_indices\"".into()));
                };
                let PropKind::List { count, item } = p.kind else {
                    return Err(at(p.line, format!("{} must be a list", p.name)));
                };
                if !item.is_integer() {
                    return Err(at(p.line, format!("{} must be a list of integers", p.name)));
                }
                el.role =
                    ElementRole::Face(FaceLayout { prop, count, item, object: object_property(el, path) });
            }
            _ => {
                if el.name == "tristrips" && el.count > 0 {
                    tracing::warn!(
                        "{}: element \"tristrips\" is not read; its triangles are skipped",
                        path.display()
                    );
                }
            }
        }
    }
    if let Some(f) = face_at {
        let face = &elements[f];
        match vertex_at {
            _ if face.count == 0 => {}
            None => return Err(at(face.line, "faces but no vertex element".into())),
            Some(v) if v > f => {
                return Err(ImportError::unsupported(
                    path,
                    format!(
                        "faces before vertices are not supported (element face on line {} precedes \
                         element vertex on line {})",
                        face.line, elements[v].line
                    ),
                ))
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// The face property that gives each face's object: a scalar integer named `object`, else one
/// named `object_id`. One of another type is skipped, with a warning.
fn object_property(el: &Element, path: &Path) -> Option<(usize, Scalar)> {
    let find = |name: &str| el.props.iter().position(|p| p.name == name);
    let pi = find("object").or_else(|| find("object_id"))?;
    let p = &el.props[pi];
    match p.kind {
        PropKind::Scalar(t) if t.is_integer() => Some((pi, t)),
        _ => {
            tracing::warn!(
                "{}: line {}: face property {} is not a scalar integer; faces keep the file's single object",
                path.display(),
                p.line,
                p.name
            );
            None
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Body

/// The PLY source: the header is read, the body streams on [`TriangleSource::stream`].
pub struct PlySource {
    path: PathBuf,
    rd: ByteReader,
    header: Header,
    options: ImportOptions,
    counter: DiskCounter,
    file_len: u64,
}

/// Why a record could not be used; it becomes an [`ImportError`] with the record's position.
enum RecordError {
    Bad(String),
    Io(io::Error),
    Sink(ImportError),
}

impl From<io::Error> for RecordError {
    fn from(e: io::Error) -> Self {
        RecordError::Io(e)
    }
}

impl From<ImportError> for RecordError {
    fn from(e: ImportError) -> Self {
        RecordError::Sink(e)
    }
}

impl RecordError {
    fn at(self, path: &Path, pos: Position, element: &str, index: u64) -> ImportError {
        match self {
            RecordError::Bad(msg) => ImportError::parse(path, pos, format!("{element} {index}: {msg}")),
            RecordError::Io(e) => ImportError::io(path, pos, e),
            RecordError::Sink(e) => e,
        }
    }
}

/// One vertex's values.
#[derive(Clone, Copy)]
struct VertexValues {
    pos: [f64; 3],
    normal: [f32; 3],
    color: [u8; 4],
}

impl VertexValues {
    const NEW: VertexValues = VertexValues { pos: [0.0; 3], normal: [0.0; 3], color: [0, 0, 0, 255] };

    #[inline(always)]
    fn set(&mut self, role: Role, ty: Scalar, v: f64) {
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
    fn check(&mut self) -> Result<(), RecordError> {
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
struct Vertices {
    pos: Positions,
    normals: Option<VertexStore<[f32; 3]>>,
    colors: Option<VertexStore<Rgba8>>,
}

/// One corner of a triangle, fetched from the stores.
#[derive(Clone, Copy)]
struct Corner {
    pos: [f64; 3],
    normal: Option<[f32; 3]>,
    color: Option<Rgba8>,
}

impl Corner {
    /// The triangle of three corners: normals and colours only where all three have them.
    fn triangle([a, b, c]: [&Corner; 3], object: ObjectId) -> Triangle {
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
    fn new(layout: Option<&VertexLayout>, options: &ImportOptions) -> Vertices {
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
    fn push(&mut self, v: &VertexValues) -> io::Result<()> {
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
    fn corner(&mut self, i: u64) -> io::Result<Corner> {
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
    fn touch(&mut self, b: usize) -> io::Result<()> {
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
    fn touchable_blocks(&self) -> usize {
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
    fn corner_resident(&self, i: u64) -> Corner {
        Corner {
            pos: match &self.pos {
                Positions::F32(s) => s.get_resident(i).map(|c| c as f64),
                Positions::F64(s) => s.get_resident(i),
            },
            normal: self.normals.as_ref().map(|s| s.get_resident(i)),
            color: self.colors.as_ref().map(|s| s.get_resident(i)),
        }
    }

    fn len(&self) -> u64 {
        match &self.pos {
            Positions::F32(s) => s.len(),
            Positions::F64(s) => s.len(),
        }
    }

    fn stats(&self) -> crate::vertex_store::StoreStats {
        match &self.pos {
            Positions::F32(s) => s.stats(),
            Positions::F64(s) => s.stats(),
        }
    }
}

/// Reused state for faces.
struct Faces {
    indices: Vec<u64>,
    /// Faces of fewer than three vertices, skipped.
    short: u64,
}

impl Faces {
    /// Checks and keeps one index.
    #[inline(always)]
    fn add(&mut self, i: i64, vertices: u64) -> Result<(), RecordError> {
        if i < 0 || i as u64 >= vertices {
            return Err(RecordError::Bad(format!(
                "vertex index {i} out of range (the file has {vertices} vertices)"
            )));
        }
        self.indices.push(i as u64);
        Ok(())
    }

    /// Fan-triangulates the collected polygon into `sink`.
    #[inline]
    fn emit(
        &mut self,
        v: &mut Vertices,
        object: ObjectId,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), RecordError> {
        let [first, second, rest @ ..] = self.indices.as_slice() else {
            self.short += 1;
            return Ok(());
        };
        if rest.is_empty() {
            self.short += 1;
            return Ok(());
        }
        let a = v.corner(*first)?;
        let mut b = v.corner(*second)?;
        for &i in rest {
            let c = v.corner(i)?;
            sink.triangle(&Corner::triangle([&a, &b, &c], object))?;
            b = c;
        }
        Ok(())
    }
}

/// Per-face object ids: the file's ids, mapped to dense ids in order of first appearance.
struct Objects {
    /// Object name prefix: the file's name.
    stem: String,
    ids: HashMap<i64, ObjectId>,
    /// The last face's file id and dense id: consecutive faces mostly share their object.
    last: Option<(i64, ObjectId)>,
}

impl Objects {
    fn new(stem: String) -> Objects {
        Objects { stem, ids: HashMap::new(), last: None }
    }

    /// Objects announced.
    fn len(&self) -> u32 {
        self.ids.len() as u32
    }

    /// The dense id of file id `raw`, announcing it to `sink` when it is new.
    #[inline(always)]
    fn id(&mut self, raw: i64, sink: &mut dyn TriangleSink) -> Result<ObjectId, RecordError> {
        match self.last {
            Some((r, id)) if r == raw => Ok(id),
            _ => self.lookup(raw, sink),
        }
    }

    #[cold]
    #[inline(never)]
    fn lookup(&mut self, raw: i64, sink: &mut dyn TriangleSink) -> Result<ObjectId, RecordError> {
        let (id, new) = self.resolve_new(raw)?;
        if let Some(info) = new {
            sink.object(id, &info)?;
        }
        Ok(id)
    }

    /// The dense id of file id `raw`, and the object's description when it is new (for the
    /// caller to announce before the object's first triangle).
    #[inline(always)]
    fn resolve(&mut self, raw: i64) -> Result<(ObjectId, Option<ObjectInfo>), RecordError> {
        match self.last {
            Some((r, id)) if r == raw => Ok((id, None)),
            _ => self.resolve_new(raw),
        }
    }

    #[cold]
    #[inline(never)]
    fn resolve_new(&mut self, raw: i64) -> Result<(ObjectId, Option<ObjectInfo>), RecordError> {
        let (id, new) = match self.ids.get(&raw) {
            Some(&id) => (id, None),
            None => {
                let id = u32::try_from(self.ids.len())
                    .map_err(|_| RecordError::Bad("more than 2^32 objects".into()))?;
                self.ids.insert(raw, id);
                (id, Some(ObjectInfo { name: format!("{}/{raw}", self.stem), color: None }))
            }
        };
        self.last = Some((raw, id));
        Ok((id, new))
    }
}

/// Offsets of the properties of a record made of scalars only, and its size; `None` when the
/// element has lists.
fn fixed_layout(props: &[Property], offsets: &mut [usize]) -> Option<usize> {
    let mut at = 0;
    for (p, o) in props.iter().zip(offsets.iter_mut()) {
        let PropKind::Scalar(t) = p.kind else { return None };
        *o = at;
        at += t.size();
    }
    Some(at)
}

/// The layout of a binary face record that holds one triangle: every property a scalar except
/// the index list, whose count is 3. Such records all have the same size, so a run of them can
/// be delimited without reading them one by one (see [`Body::binary_triangles`]).
#[derive(Clone, Copy, Debug)]
struct TriangleRecord {
    size: usize,
    /// Offset of the index list's count, and of the three indices that follow it.
    count_at: usize,
    items_at: usize,
    /// Offset and type of the object id, when the faces have one.
    object: Option<(usize, Scalar)>,
}

impl TriangleRecord {
    /// The layout, when the face element has no list besides the indices.
    fn of(el: &Element, layout: &FaceLayout) -> Option<TriangleRecord> {
        let (mut at, mut count_at, mut items_at, mut object) = (0, None, 0, None);
        for (pi, p) in el.props.iter().enumerate() {
            match p.kind {
                PropKind::Scalar(t) => {
                    if layout.object.is_some_and(|(op, _)| op == pi) {
                        object = Some((at, t));
                    }
                    at += t.size();
                }
                PropKind::List { count, item } if pi == layout.prop => {
                    count_at = Some(at);
                    items_at = at + count.size();
                    at = items_at + 3 * item.size();
                }
                PropKind::List { .. } => return None,
            }
        }
        Some(TriangleRecord { size: at, count_at: count_at?, items_at, object })
    }
}

/// A run of triangle records being handed to the sink as one [`TriangleBatch`]: the faces'
/// vertex indices (checked) and objects, and the objects they announce. Reused across runs.
#[derive(Default)]
struct TriangleRun {
    corners: Vec<[u64; 3]>,
    /// Dense object ids, one per face; empty when the file is one object (id 0).
    objects: Vec<ObjectId>,
    new_objects: Vec<NewObject>,
    /// Vertex blocks touched by the run: `stamp[b] == run` for those.
    stamp: Vec<u32>,
    run: u32,
    touched: usize,
}

/// Why [`Body::scan_run`] stopped.
enum RunEnd {
    /// At the end of the buffered records (or of the element).
    Window,
    /// The next record would touch more vertex blocks than stay resident together.
    Full,
    /// The next record is not a triangle (its count is not 3).
    NotTriangle,
    /// The next record is broken.
    Bad(RecordError),
}

/// The batch of a [`TriangleRun`]: triangles resolved from the touched vertex blocks, through
/// shared references, on whichever threads the sink uses.
struct RunBatch<'a> {
    run: &'a TriangleRun,
    vertices: &'a Vertices,
}

impl TriangleBatch for RunBatch<'_> {
    fn len(&self) -> usize {
        self.run.corners.len()
    }

    fn triangles(&self, range: Range<usize>, out: &mut Vec<Triangle>) -> Result<(), ImportError> {
        let objects = self.run.objects.get(range.clone());
        for (k, corners) in self.run.corners[range].iter().enumerate() {
            let [a, b, c] = corners.map(|v| self.vertices.corner_resident(v));
            out.push(Corner::triangle([&a, &b, &c], objects.map_or(0, |o| o[k])));
        }
        Ok(())
    }

    fn new_objects(&self) -> &[NewObject] {
        &self.run.new_objects
    }
}

/// Walks the binary record at the start of `bytes`: fills `offsets` with each property's offset
/// (a list's is that of its count) and returns the record's length, or `None` when `bytes` does
/// not hold all of it.
#[inline]
fn measure(
    props: &[Property],
    bytes: &[u8],
    big: bool,
    list_cap: i64,
    offsets: &mut [usize],
) -> Result<Option<usize>, String> {
    let mut at = 0usize;
    for (p, o) in props.iter().zip(offsets.iter_mut()) {
        *o = at;
        match p.kind {
            PropKind::Scalar(t) => at += t.size(),
            PropKind::List { count, item } => {
                if bytes.len() < at + count.size() {
                    return Ok(None);
                }
                let n = count.i64(&bytes[at..], big);
                if n < 0 {
                    return Err(format!("list {} has a negative length {n}", p.name));
                }
                if n > list_cap {
                    return Err(format!("list {} has {n} items (at most {list_cap} are supported)", p.name));
                }
                at += count.size() + n as usize * item.size();
            }
        }
    }
    Ok((bytes.len() >= at).then_some(at))
}

impl TriangleSource for PlySource {
    fn name(&self) -> String {
        self.path.display().to_string()
    }

    fn progress_total(&self) -> Option<u64> {
        Some(self.file_len)
    }

    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        let PlySource { path, mut rd, header, options, counter, .. } = *self;
        // Per-face objects when the faces have them; otherwise the file is one object.
        let per_face_objects = header
            .elements
            .iter()
            .any(|e| e.count > 0 && matches!(e.role, ElementRole::Face(FaceLayout { object: Some(_), .. })));
        let objects = if per_face_objects {
            Some(Objects::new(object_name(&path)))
        } else {
            sink.object(0, &ObjectInfo { name: object_name(&path), color: None })?;
            None
        };
        let faces_declared = header.count_of(|r| matches!(r, ElementRole::Face(_)));
        let vertices_declared = header.count_of(|r| matches!(r, ElementRole::Vertex(_)));
        let mut body = Body {
            path: &path,
            counter: &counter,
            big: header.encoding == Encoding::BinaryBe,
            line: header.lines,
            vertices: None,
            faces: Faces { indices: Vec::new(), short: 0 },
            objects,
        };
        for el in &header.elements {
            match (&el.role, header.encoding) {
                (ElementRole::Vertex(layout), _) if faces_declared > 0 => {
                    let mut v = Vertices::new(Some(layout), &options);
                    if header.encoding == Encoding::Ascii {
                        body.ascii_vertices(&mut rd, el, layout, &mut v, sink)?;
                    } else {
                        body.binary_vertices(&mut rd, el, layout, &mut v, sink)?;
                    }
                    body.vertices = Some(v);
                }
                (ElementRole::Face(layout), _) if el.count > 0 => {
                    let mut v = body.vertices.take().unwrap_or_else(|| Vertices::new(None, &options));
                    let result = if header.encoding == Encoding::Ascii {
                        body.ascii_faces(&mut rd, el, layout, &mut v, sink)
                    } else {
                        body.binary_faces(&mut rd, el, layout, &mut v, sink)
                    };
                    body.vertices = Some(v);
                    result?;
                }
                (_, Encoding::Ascii) => body.ascii_skip(&mut rd, el, sink)?,
                _ => body.binary_skip(&mut rd, el, sink)?,
            }
        }
        let trailing = if header.encoding == Encoding::Ascii {
            rd.only_whitespace_left().map(|w| !w)
        } else {
            rd.ensure(1)
        }
        .map_err(|e| ImportError::io(&path, Position::Byte(rd.position()), e))?;
        if trailing {
            tracing::warn!("{}: data after the last element ignored", path.display());
        }
        if body.faces.short > 0 {
            tracing::warn!("{}: {} faces of fewer than 3 vertices skipped", path.display(), body.faces.short);
        }
        if let Some(v) = &body.vertices {
            let st = v.stats();
            if st.blocks_spilled > 0 {
                tracing::debug!(
                    "{}: vertex store spilled {} blocks, loaded {}",
                    path.display(),
                    st.blocks_spilled,
                    st.blocks_loaded
                );
            }
        }
        sink.progress(counter.get());
        let objects = body.objects.as_ref().map_or(1, Objects::len);
        Ok(SourceSummary { objects, vertices: vertices_declared, bytes: counter.get() })
    }
}

/// Body-reading state shared by the element readers.
struct Body<'a> {
    path: &'a Path,
    counter: &'a DiskCounter,
    big: bool,
    /// Last line read (ASCII).
    line: u64,
    vertices: Option<Vertices>,
    faces: Faces,
    /// Per-face objects, when the faces have an object property.
    objects: Option<Objects>,
}

impl Body<'_> {
    /// Calls `each` with every record of a binary element, decoded in place from the buffer.
    #[inline]
    fn binary_records(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        list_cap: i64,
        sink: &mut dyn TriangleSink,
        mut each: impl FnMut(&[u8], &[usize], u64, &mut dyn TriangleSink) -> Result<(), RecordError>,
    ) -> Result<(), ImportError> {
        let path = self.path;
        let mut offsets = vec![0usize; el.props.len()];
        let fixed = fixed_layout(&el.props, &mut offsets);
        let mut index = 0u64;
        while index < el.count {
            let start = rd.position();
            let avail = rd.available();
            let mut used = 0usize;
            while index < el.count {
                let rest = &avail[used..];
                let len = match fixed {
                    Some(size) if rest.len() >= size => size,
                    Some(_) => break,
                    None => match measure(&el.props, rest, self.big, list_cap, &mut offsets) {
                        Ok(Some(len)) => len,
                        Ok(None) => break,
                        Err(msg) => {
                            let pos = Position::Byte(start + used as u64);
                            return Err(RecordError::Bad(msg).at(path, pos, &el.name, index));
                        }
                    },
                };
                if let Err(e) = each(&rest[..len], &offsets, index, sink) {
                    return Err(e.at(path, Position::Byte(start + used as u64), &el.name, index));
                }
                used += len;
                index += 1;
            }
            rd.consume(used);
            if index < el.count {
                let got =
                    rd.fill_more().map_err(|e| ImportError::io(path, Position::Byte(rd.position()), e))?;
                if got == 0 {
                    return Err(truncated(path, rd, el, index));
                }
            }
            if rd.take_refilled() {
                sink.progress(self.counter.get());
            }
        }
        Ok(())
    }

    fn binary_vertices(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        layout: &VertexLayout,
        out: &mut Vertices,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        let big = self.big;
        // The usual layout, `float x y z` (little endian) and nothing else read: without the
        // dispatch on roles and types.
        if let ([(px, Role::X, Scalar::F32), (py, Role::Y, Scalar::F32), (pz, Role::Z, Scalar::F32)], false) =
            (layout.fields.as_slice(), big)
        {
            let (px, py, pz) = (*px, *py, *pz);
            let f = |b: &[u8]| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64;
            return self.binary_records(rd, el, MAX_LIST, sink, |rec, offsets, _, _| {
                let pos = [f(&rec[offsets[px]..]), f(&rec[offsets[py]..]), f(&rec[offsets[pz]..])];
                let mut v = VertexValues { pos, ..VertexValues::NEW };
                v.check()?;
                out.push(&v)?;
                Ok(())
            });
        }
        self.binary_records(rd, el, MAX_LIST, sink, |rec, offsets, _, _| {
            let mut v = VertexValues::NEW;
            for &(p, role, ty) in &layout.fields {
                v.set(role, ty, ty.f64(&rec[offsets[p]..], big));
            }
            v.check()?;
            out.push(&v)?;
            Ok(())
        })
    }

    fn binary_faces(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        layout: &FaceLayout,
        v: &mut Vertices,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        if let Some(rec) = TriangleRecord::of(el, layout) {
            return self.binary_triangles(rd, el, layout, rec, v, sink);
        }
        let big = self.big;
        let mut objects = self.objects.take();
        // Two instances of the record loop, so that files without objects pay nothing for them.
        // `measure` delimited the record, so the scalar at `offsets[p]` lies within it.
        let result = match (&mut objects, layout.object) {
            // As terawalk writes it: a loop without a dispatch on the type.
            (Some(objects), Some((p, Scalar::U32))) if !big => {
                self.binary_faces_with(rd, el, layout, v, sink, |rec, offsets, sink| {
                    objects.id(u32_at(&rec[offsets[p]..], false) as i64, sink)
                })
            }
            (Some(objects), Some((p, ty))) => {
                self.binary_faces_with(rd, el, layout, v, sink, |rec, offsets, sink| {
                    objects.id(ty.i64(&rec[offsets[p]..], big), sink)
                })
            }
            _ => self.binary_faces_with(rd, el, layout, v, sink, |_, _, _| Ok(0)),
        };
        self.objects = objects;
        result
    }

    /// Reads binary faces; `object_of` gives the object of a face that has triangles.
    #[inline]
    fn binary_faces_with(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        layout: &FaceLayout,
        v: &mut Vertices,
        sink: &mut dyn TriangleSink,
        mut object_of: impl FnMut(&[u8], &[usize], &mut dyn TriangleSink) -> Result<ObjectId, RecordError>,
    ) -> Result<(), ImportError> {
        let big = self.big;
        let mut faces = std::mem::replace(&mut self.faces, Faces { indices: Vec::new(), short: 0 });
        let n_vertices = v.len();
        let (csize, isize_) = (layout.count.size(), layout.item.size());
        let result = self.binary_records(rd, el, MAX_LIST, sink, |rec, offsets, _, sink| {
            let at = offsets[layout.prop];
            // `measure` checked the count and that the items are in `rec`.
            let n = layout.count.i64(&rec[at..], big) as usize;
            let items = &rec[at + csize..at + csize + n * isize_];
            faces.indices.clear();
            for item in items.chunks_exact(isize_) {
                faces.add(layout.item.i64(item, big), n_vertices)?;
            }
            let object = if faces.indices.len() >= 3 { object_of(rec, offsets, sink)? } else { 0 };
            faces.emit(v, object, sink)
        });
        self.faces = faces;
        result
    }

    /// Reads binary faces whose records are triangles of one size ([`TriangleRecord`]): runs of
    /// them are checked here, in order, and handed to the sink as [`TriangleBatch`]es, which
    /// it may resolve on several threads; any other record (a polygon, a short face, one that
    /// needs more vertex blocks than stay resident together) is read the general way. The
    /// triangles, their order, the objects and the errors are those of the general path.
    fn binary_triangles(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        layout: &FaceLayout,
        rec: TriangleRecord,
        v: &mut Vertices,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        let (path, big) = (self.path, self.big);
        let mut faces = std::mem::replace(&mut self.faces, Faces { indices: Vec::new(), short: 0 });
        let mut objects = self.objects.take();
        let mut run =
            TriangleRun { stamp: vec![0; v.len().div_ceil(1 << BLOCK_SHIFT) as usize], ..Default::default() };
        let mut offsets = vec![0usize; el.props.len()];
        let mut index = 0u64;
        let result = (|| -> Result<(), ImportError> {
            while index < el.count {
                let start = rd.position();
                let records =
                    ((rd.available().len() / rec.size).min(MAX_RUN) as u64).min(el.count - index) as usize;
                let end = scan_run(
                    &rd.available()[..records * rec.size],
                    rec,
                    layout,
                    big,
                    &mut run,
                    v,
                    &mut objects,
                );
                let n = run.corners.len();
                if n > 0 {
                    sink.batch(&RunBatch { run: &run, vertices: v })?;
                    rd.consume(n * rec.size);
                    index += n as u64;
                }
                let one_record = match end {
                    RunEnd::Window if index < el.count => {
                        // At the end of the file the bytes left are fewer than a triangle's
                        // record, but may still hold a shorter record (a face of fewer than 3
                        // vertices, skipped like in ASCII): the general way reads it, or says
                        // the file is truncated.
                        rd.fill_more().map_err(|e| ImportError::io(path, Position::Byte(rd.position()), e))?
                            == 0
                    }
                    RunEnd::Window => false,
                    RunEnd::Full if n > 0 => false,
                    RunEnd::Full | RunEnd::NotTriangle => true,
                    RunEnd::Bad(e) => {
                        return Err(e.at(
                            path,
                            Position::Byte(start + (n * rec.size) as u64),
                            &el.name,
                            index,
                        ))
                    }
                };
                if one_record {
                    // One record the general way.
                    let at = rd.position();
                    let len = loop {
                        match measure(&el.props, rd.available(), big, MAX_LIST, &mut offsets) {
                            Ok(Some(len)) => break len,
                            Ok(None) => {
                                let got = rd
                                    .fill_more()
                                    .map_err(|e| ImportError::io(path, Position::Byte(rd.position()), e))?;
                                if got == 0 {
                                    return Err(truncated(path, rd, el, index));
                                }
                            }
                            Err(msg) => {
                                return Err(RecordError::Bad(msg).at(
                                    path,
                                    Position::Byte(at),
                                    &el.name,
                                    index,
                                ))
                            }
                        }
                    };
                    let record = &rd.available()[..len];
                    let r = face_record(record, &offsets, layout, big, &mut faces, v, &mut objects, sink);
                    if let Err(e) = r {
                        return Err(e.at(path, Position::Byte(at), &el.name, index));
                    }
                    rd.consume(len);
                    index += 1;
                }
                if rd.take_refilled() {
                    sink.progress(self.counter.get());
                }
            }
            Ok(())
        })();
        self.faces = faces;
        self.objects = objects;
        result
    }

    fn binary_skip(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        let mut offsets = vec![0usize; el.props.len()];
        if let Some(size) = fixed_layout(&el.props, &mut offsets) {
            let bytes = el.count.saturating_mul(size as u64);
            let skipped =
                rd.skip(bytes).map_err(|e| ImportError::io(self.path, Position::Byte(rd.position()), e))?;
            if skipped < bytes {
                return Err(truncated(self.path, rd, el, skipped / size as u64));
            }
            sink.progress(self.counter.get());
            return Ok(());
        }
        self.binary_records(rd, el, MAX_SKIPPED_LIST, sink, |_, _, _, _| Ok(()))
    }

    /// Calls `each` with the tokens of every record (one non-blank line each) of an ASCII
    /// element; a line with values left over is an error.
    fn ascii_records(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        sink: &mut dyn TriangleSink,
        mut each: impl FnMut(&mut Tokens, u64, &mut dyn TriangleSink) -> Result<(), RecordError>,
    ) -> Result<(), ImportError> {
        if el.props.is_empty() {
            return Ok(());
        }
        let path = self.path;
        for index in 0..el.count {
            let range = loop {
                self.line += 1;
                let pos = Position::Line(self.line);
                match rd.read_line(MAX_ASCII_LINE).map_err(|e| ImportError::io(path, pos, e))? {
                    Line::Text(r) if rd.bytes(r.clone()).iter().all(u8::is_ascii_whitespace) => continue,
                    Line::Text(r) => break r,
                    Line::Eof => {
                        return Err(ImportError::parse(
                            path,
                            pos,
                            format!(
                                "the file is truncated: it ends before {} {index} of {}",
                                el.name, el.count
                            ),
                        ))
                    }
                    Line::TooLong => {
                        return Err(ImportError::parse(
                            path,
                            pos,
                            format!("line longer than {MAX_ASCII_LINE} bytes"),
                        ))
                    }
                }
            };
            let pos = Position::Line(self.line);
            let mut tokens = Tokens::new(rd.bytes(range));
            if let Err(e) = each(&mut tokens, index, sink) {
                return Err(e.at(path, pos, &el.name, index));
            }
            if let Some(t) = tokens.next() {
                let msg = format!("more values than the header declares (\"{}\")", show(t));
                return Err(RecordError::Bad(msg).at(path, pos, &el.name, index));
            }
            if rd.take_refilled() {
                sink.progress(self.counter.get());
            }
        }
        Ok(())
    }

    fn ascii_vertices(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        layout: &VertexLayout,
        out: &mut Vertices,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        self.ascii_records(rd, el, sink, |tokens, _, _| {
            let mut v = VertexValues::NEW;
            for (p, role) in el.props.iter().zip(&layout.roles) {
                match (p.kind, role) {
                    (PropKind::Scalar(ty), Some(role)) => {
                        let t = next_token(tokens, p)?;
                        let x = parse_f64(t).ok_or_else(|| bad_number(t, p))?;
                        v.set(*role, ty, x);
                    }
                    _ => skip_ascii_property(tokens, p, MAX_SKIPPED_LIST)?,
                }
            }
            v.check()?;
            out.push(&v)?;
            Ok(())
        })
    }

    fn ascii_faces(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        layout: &FaceLayout,
        v: &mut Vertices,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        let mut faces = std::mem::replace(&mut self.faces, Faces { indices: Vec::new(), short: 0 });
        let n_vertices = v.len();
        let mut objects = self.objects.take();
        let object_prop = layout.object.map(|(p, _)| p);
        let result = self.ascii_records(rd, el, sink, |tokens, _, sink| {
            faces.indices.clear();
            let mut raw = 0i64;
            for (pi, p) in el.props.iter().enumerate() {
                if Some(pi) == object_prop {
                    let t = next_token(tokens, p)?;
                    raw = parse_i64(t).ok_or_else(|| bad_number(t, p))?;
                    continue;
                }
                if pi != layout.prop {
                    skip_ascii_property(tokens, p, MAX_SKIPPED_LIST)?;
                    continue;
                }
                let n = list_count(tokens, p, MAX_LIST)?;
                for _ in 0..n {
                    let t = next_token(tokens, p)?;
                    let i = parse_i64(t).ok_or_else(|| bad_number(t, p))?;
                    faces.add(i, n_vertices)?;
                }
            }
            let object = match &mut objects {
                Some(objects) if faces.indices.len() >= 3 => objects.id(raw, sink)?,
                _ => 0,
            };
            faces.emit(v, object, sink)
        });
        self.faces = faces;
        self.objects = objects;
        result
    }

    fn ascii_skip(
        &mut self,
        rd: &mut ByteReader,
        el: &Element,
        sink: &mut dyn TriangleSink,
    ) -> Result<(), ImportError> {
        self.ascii_records(rd, el, sink, |tokens, _, _| {
            for p in &el.props {
                skip_ascii_property(tokens, p, MAX_SKIPPED_LIST)?;
            }
            Ok(())
        })
    }
}

/// Collects into `run` the triangle records at the start of `bytes` (whole records) that can go
/// to the sink as one batch: checks their counts and indices, touches the vertex blocks they
/// use, resolves their objects. Stops at the first record that cannot join the run, and says why.
#[allow(clippy::too_many_arguments)]
fn scan_run(
    bytes: &[u8],
    rec: TriangleRecord,
    layout: &FaceLayout,
    big: bool,
    run: &mut TriangleRun,
    v: &mut Vertices,
    objects: &mut Option<Objects>,
) -> RunEnd {
    let le32 = |b: &[u8]| u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    // The usual layout (terawalk's, and most scanners'), without a dispatch on the types.
    match (layout.count, layout.item, big) {
        (Scalar::U8, Scalar::U32, false) => {
            scan_run_with(bytes, rec, big, run, v, objects, |b| b[0] as i64, 4, |b| le32(b) as i64)
        }
        (Scalar::U8, Scalar::I32, false) => {
            scan_run_with(bytes, rec, big, run, v, objects, |b| b[0] as i64, 4, |b| le32(b) as i32 as i64)
        }
        (count, item, _) => scan_run_with(
            bytes,
            rec,
            big,
            run,
            v,
            objects,
            |b| count.i64(b, big),
            item.size(),
            |b| item.i64(b, big),
        ),
    }
}

/// [`scan_run`] with the readers of the list count and of an index (`isz` bytes).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn scan_run_with(
    bytes: &[u8],
    rec: TriangleRecord,
    big: bool,
    run: &mut TriangleRun,
    v: &mut Vertices,
    objects: &mut Option<Objects>,
    count: impl Fn(&[u8]) -> i64,
    isz: usize,
    item: impl Fn(&[u8]) -> i64,
) -> RunEnd {
    run.corners.clear();
    run.objects.clear();
    run.new_objects.clear();
    run.run = run.run.wrapping_add(1);
    if run.run == 0 {
        run.stamp.fill(0);
        run.run = 1;
    }
    run.touched = 0;
    let touchable = v.touchable_blocks();
    let n_vertices = v.len();
    for r in bytes.chunks_exact(rec.size) {
        if count(&r[rec.count_at..]) != 3 {
            return RunEnd::NotTriangle;
        }
        let mut corner = [0u64; 3];
        for (k, c) in corner.iter_mut().enumerate() {
            let i = item(&r[rec.items_at + k * isz..]);
            if i < 0 || i as u64 >= n_vertices {
                return RunEnd::Bad(RecordError::Bad(format!(
                    "vertex index {i} out of range (the file has {n_vertices} vertices)"
                )));
            }
            *c = i as u64;
        }
        // The blocks this face adds to the run, all of them or none.
        let blocks = corner.map(|c| (c >> BLOCK_SHIFT) as usize);
        let mut new = 0;
        for (k, &b) in blocks.iter().enumerate() {
            if run.stamp[b] != run.run && !blocks[..k].contains(&b) {
                new += 1;
            }
        }
        if new > 0 {
            if run.touched + new > touchable {
                return RunEnd::Full;
            }
            for b in blocks {
                if run.stamp[b] != run.run {
                    if let Err(e) = v.touch(b) {
                        return RunEnd::Bad(RecordError::Io(e));
                    }
                    run.stamp[b] = run.run;
                    run.touched += 1;
                }
            }
        }
        if let (Some(objects), Some((at, ty))) = (objects.as_mut(), rec.object) {
            match objects.resolve(ty.i64(&r[at..], big)) {
                Ok((id, new)) => {
                    if let Some(info) = new {
                        run.new_objects.push(NewObject { first: run.corners.len(), id, info });
                    }
                    run.objects.push(id);
                }
                Err(e) => return RunEnd::Bad(e),
            }
        }
        run.corners.push(corner);
    }
    RunEnd::Window
}

/// Reads one binary face record the general way (any list length) and streams its triangles.
#[allow(clippy::too_many_arguments)]
fn face_record(
    rec: &[u8],
    offsets: &[usize],
    layout: &FaceLayout,
    big: bool,
    faces: &mut Faces,
    v: &mut Vertices,
    objects: &mut Option<Objects>,
    sink: &mut dyn TriangleSink,
) -> Result<(), RecordError> {
    let at = offsets[layout.prop];
    // `measure` checked the count and that the items are in `rec`.
    let n = layout.count.i64(&rec[at..], big) as usize;
    let (csize, isize_) = (layout.count.size(), layout.item.size());
    let items = &rec[at + csize..at + csize + n * isize_];
    faces.indices.clear();
    let n_vertices = v.len();
    for item in items.chunks_exact(isize_) {
        faces.add(layout.item.i64(item, big), n_vertices)?;
    }
    let object = match (objects.as_mut(), layout.object) {
        (Some(objects), Some((p, ty))) if faces.indices.len() >= 3 => {
            objects.id(ty.i64(&rec[offsets[p]..], big), sink)?
        }
        _ => 0,
    };
    faces.emit(v, object, sink)
}

fn truncated(path: &Path, rd: &ByteReader, el: &Element, index: u64) -> ImportError {
    let end = rd.position() + rd.available().len() as u64;
    ImportError::parse(
        path,
        Position::Byte(end),
        format!("the file is truncated: it ends in {} {index} of {}", el.name, el.count),
    )
}

#[inline]
fn next_token<'a>(tokens: &mut Tokens<'a>, p: &Property) -> Result<&'a [u8], RecordError> {
    tokens
        .next()
        .ok_or_else(|| RecordError::Bad(format!("fewer values than the header declares (no {})", p.name)))
}

fn bad_number(t: &[u8], p: &Property) -> RecordError {
    RecordError::Bad(format!("invalid number \"{}\" for {}", show(t), p.name))
}

fn list_count(tokens: &mut Tokens, p: &Property, cap: i64) -> Result<i64, RecordError> {
    let t = next_token(tokens, p)?;
    let n = parse_i64(t).ok_or_else(|| bad_number(t, p))?;
    if n < 0 {
        return Err(RecordError::Bad(format!("list {} has a negative length {n}", p.name)));
    }
    if n > cap {
        return Err(RecordError::Bad(format!("list {} has {n} items (at most {cap} are supported)", p.name)));
    }
    Ok(n)
}

fn skip_ascii_property(tokens: &mut Tokens, p: &Property, cap: i64) -> Result<(), RecordError> {
    match p.kind {
        PropKind::Scalar(_) => {
            next_token(tokens, p)?;
        }
        PropKind::List { .. } => {
            for _ in 0..list_count(tokens, p, cap)? {
                next_token(tokens, p)?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// A sink that keeps everything.
    #[derive(Default)]
    struct Collect {
        objects: Vec<(u32, ObjectInfo)>,
        tris: Vec<Triangle>,
        progress_calls: u64,
    }

    impl TriangleSink for Collect {
        fn object(&mut self, id: u32, info: &ObjectInfo) -> Result<(), ImportError> {
            self.objects.push((id, info.clone()));
            Ok(())
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            assert!(!self.objects.is_empty(), "triangle before object");
            self.tris.push(*t);
            Ok(())
        }
        fn progress(&mut self, _done: u64) {
            self.progress_calls += 1;
        }
    }

    fn gz(bytes: &[u8]) -> Vec<u8> {
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(bytes).unwrap();
        enc.finish().unwrap()
    }

    fn run_opts(
        name: &str,
        bytes: &[u8],
        options: &ImportOptions,
    ) -> Result<(Collect, SourceSummary), ImportError> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let source = open(Input::open(&p)?, options)?;
        let mut sink = Collect::default();
        let summary = source.stream(&mut sink)?;
        Ok((sink, summary))
    }

    fn run(name: &str, bytes: &[u8]) -> Result<(Collect, SourceSummary), ImportError> {
        run_opts(name, bytes, &ImportOptions::default())
    }

    fn err(name: &str, bytes: &[u8]) -> ImportError {
        match run(name, bytes) {
            Ok((c, _)) => panic!("expected an error, got {} triangles", c.tris.len()),
            Err(e) => e,
        }
    }

    fn positions(c: &Collect) -> Vec<[[f64; 3]; 3]> {
        c.tris.iter().map(|t| t.positions).collect()
    }

    /// Binary writer for fixtures.
    struct W {
        big: bool,
        out: Vec<u8>,
    }

    impl W {
        fn new(header: &str, big: bool) -> W {
            W { big, out: header.as_bytes().to_vec() }
        }
        fn put(&mut self, le: &[u8], be: &[u8]) -> &mut Self {
            self.out.extend_from_slice(if self.big { be } else { le });
            self
        }
        fn f32(&mut self, v: f32) -> &mut Self {
            self.put(&v.to_le_bytes(), &v.to_be_bytes())
        }
        fn f64(&mut self, v: f64) -> &mut Self {
            self.put(&v.to_le_bytes(), &v.to_be_bytes())
        }
        fn i32(&mut self, v: i32) -> &mut Self {
            self.put(&v.to_le_bytes(), &v.to_be_bytes())
        }
        fn u32(&mut self, v: u32) -> &mut Self {
            self.put(&v.to_le_bytes(), &v.to_be_bytes())
        }
        fn i16(&mut self, v: i16) -> &mut Self {
            self.put(&v.to_le_bytes(), &v.to_be_bytes())
        }
        fn u16(&mut self, v: u16) -> &mut Self {
            self.put(&v.to_le_bytes(), &v.to_be_bytes())
        }
        fn u8(&mut self, v: u8) -> &mut Self {
            self.out.push(v);
            self
        }
    }

    const SQUARE: [[f32; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.5, -2.25]];

    /// A quad (fanned into two triangles) and a triangle, in the three encodings.
    fn square(encoding: &str) -> Vec<u8> {
        let header = format!(
            "ply\nformat {encoding} 1.0\ncomment made by hand\nobj_info test\nelement vertex 4\n\
             property float x\nproperty float y\nproperty float z\nelement face 2\n\
             property list uchar int vertex_indices\nend_header\n"
        );
        if encoding == "ascii" {
            let mut s = header;
            for v in SQUARE {
                s += &format!("{} {} {}\n", v[0], v[1], v[2]);
            }
            s += "4 0 1 2 3\n3 3 2 1\n";
            return s.into_bytes();
        }
        let mut w = W::new(&header, encoding == "binary_big_endian");
        for v in SQUARE {
            w.f32(v[0]).f32(v[1]).f32(v[2]);
        }
        w.u8(4).i32(0).i32(1).i32(2).i32(3);
        w.u8(3).i32(3).i32(2).i32(1);
        w.out
    }

    fn square_triangles() -> Vec<[[f64; 3]; 3]> {
        let v = |i: usize| SQUARE[i].map(|c| c as f64);
        vec![[v(0), v(1), v(2)], [v(0), v(2), v(3)], [v(3), v(2), v(1)]]
    }

    #[test]
    fn all_encodings_plain_and_gzip_give_the_same_triangles() {
        for enc in ["ascii", "binary_little_endian", "binary_big_endian"] {
            for zipped in [false, true] {
                let bytes = if zipped { gz(&square(enc)) } else { square(enc) };
                let (c, s) = run("square.ply", &bytes).unwrap_or_else(|e| panic!("{enc} {zipped}: {e}"));
                assert_eq!(positions(&c), square_triangles(), "{enc} gzip={zipped}");
                assert_eq!(c.objects, vec![(0, ObjectInfo { name: "square".into(), color: None })]);
                assert_eq!(s.objects, 1);
                assert_eq!(s.vertices, 4);
                assert_eq!(s.bytes, bytes.len() as u64);
                assert!(c.tris.iter().all(|t| t.normals.is_none() && t.colors.is_none() && t.object == 0));
                assert!(c.progress_calls > 0);
            }
        }
    }

    #[test]
    fn object_name_is_the_file_stem() {
        let (c, _) = run("Pump House.ply.gz", &gz(&square("ascii"))).unwrap();
        assert_eq!(c.objects[0].1.name, "Pump House");
        assert_eq!(object_name(Path::new("/a/b.c.PLY.GZ")), "b.c");
        assert_eq!(object_name(Path::new(".hidden")), ".hidden");
    }

    #[test]
    fn crlf_header_and_blank_body_lines() {
        let text =
            String::from_utf8(square("ascii")).unwrap().replace('\n', "\r\n").replace("4 0 1", "\r\n4 0 1");
        let (c, _) = run("crlf.ply", text.as_bytes()).unwrap();
        assert_eq!(positions(&c), square_triangles());
    }

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

    /// Extra elements before, between and after, with lists, and extra vertex and face properties.
    fn cluttered(encoding: &str) -> Vec<u8> {
        let header = format!(
            "ply\nformat {encoding} 1.0\nelement material 2\nproperty list uchar uchar name\nproperty float shine\n\
             element vertex 3\nproperty float confidence\nproperty float x\nproperty list uchar short tags\n\
             property float y\nproperty float z\nproperty uchar flags\n\
             element edge 1\nproperty int vertex1\nproperty int vertex2\n\
             element face 2\nproperty uchar kind\nproperty list uchar int vertex_indices\n\
             property list uchar float texcoord\nelement extra 1\nproperty list int double values\nend_header\n"
        );
        if encoding == "ascii" {
            return (header
                + "3 65 66 67 0.5\n0 1\n\
                   0.9 0 2 5 6 0 0 7\n0.8 1 0 0 0 0\n0.7 0 1 1 1 0 0\n\
                   0 1\n\
                   9 3 0 1 2 6 0 0 1 0 0 1\n1 4 2 1 0 2 0\n\
                   2 1.5 2.5\n")
                .into_bytes();
        }
        let mut w = W::new(&header, encoding == "binary_big_endian");
        w.u8(3).u8(65).u8(66).u8(67).f32(0.5);
        w.u8(0).f32(1.0);
        w.f32(0.9).f32(0.0).u8(2).i16(5).i16(6).f32(0.0).f32(0.0).u8(7);
        w.f32(0.8).f32(1.0).u8(0).f32(0.0).f32(0.0).u8(0);
        w.f32(0.7).f32(0.0).u8(1).i16(1).f32(1.0).f32(0.0).u8(0);
        w.i32(0).i32(1);
        w.u8(9).u8(3).i32(0).i32(1).i32(2).u8(6).f32(0.0).f32(0.0).f32(1.0).f32(0.0).f32(0.0).f32(1.0);
        w.u8(1).u8(4).i32(2).i32(1).i32(0).i32(2).u8(0);
        w.i32(2).f64(1.5).f64(2.5);
        w.out
    }

    #[test]
    fn extra_elements_and_properties_are_skipped_in_every_encoding() {
        let a = [0.0, 0.0, 0.0];
        let b = [1.0, 0.0, 0.0];
        let c = [0.0, 1.0, 0.0];
        for enc in ["ascii", "binary_little_endian", "binary_big_endian"] {
            let (got, s) = run("x.ply", &cluttered(enc)).unwrap_or_else(|e| panic!("{enc}: {e}"));
            // The quad 2 1 0 2 fans into (2 1 0) and (2 0 2).
            assert_eq!(positions(&got), vec![[a, b, c], [c, b, a], [c, a, c]], "{enc}");
            assert_eq!(s.vertices, 3);
        }
    }

    #[test]
    fn polygons_are_fanned_and_short_faces_skipped() {
        let text =
            "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 4\nproperty list uchar int vertex_indices\nend_header\n\
                    0 0 0\n1 0 0\n2 1 0\n1 2 0\n0 1 0\n5 0 1 2 3 4\n2 0 1\n0\n1 4\n";
        let (c, _) = run("fan.ply", text.as_bytes()).unwrap();
        let v = |i: usize| {
            [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 1.0, 0.0]][i]
        };
        assert_eq!(positions(&c), vec![[v(0), v(1), v(2)], [v(0), v(2), v(3)], [v(0), v(3), v(4)]]);
    }

    /// Regression: a binary file whose last face has fewer than 3 vertices was called truncated
    /// (its record is shorter than a triangle's), while ASCII skips such a face. Every encoding
    /// now gives the same triangles; a record that really is cut short is still an error.
    #[test]
    fn short_last_face_is_skipped_in_every_encoding() {
        for k in 0..3u8 {
            let header = |enc: &str| {
                format!(
                    "ply\nformat {enc} 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                     property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
                )
            };
            let mut text = header("ascii");
            for v in SQUARE {
                text += &format!("{} {} {}\n", v[0], v[1], v[2]);
            }
            text += "3 0 1 2\n";
            text += &format!("{k}{}\n", (0..k).map(|i| format!(" {i}")).collect::<String>());
            let (ascii, _) = run("short.ply", text.as_bytes()).unwrap();
            assert_eq!(ascii.tris.len(), 1);
            for enc in ["binary_little_endian", "binary_big_endian"] {
                let mut w = W::new(&header(enc), enc == "binary_big_endian");
                for v in SQUARE {
                    w.f32(v[0]).f32(v[1]).f32(v[2]);
                }
                w.u8(3).i32(0).i32(1).i32(2);
                w.u8(k);
                for i in 0..k {
                    w.i32(i as i32);
                }
                let (c, _) = run("short.ply", &w.out).unwrap_or_else(|e| panic!("{enc}, {k} vertices: {e}"));
                assert_eq!(positions(&c), positions(&ascii), "{enc}, {k} vertices");
                // The same face cut short (its count says 3) is truncated.
                let mut cut = W::new(&header(enc), enc == "binary_big_endian");
                for v in SQUARE {
                    cut.f32(v[0]).f32(v[1]).f32(v[2]);
                }
                cut.u8(3).i32(0).i32(1).i32(2);
                cut.u8(3).i32(0).i32(1);
                let e = run("cut.ply", &cut.out).err().unwrap().to_string();
                assert!(e.contains("truncated"), "{enc}: {e}");
            }
        }
    }

    #[test]
    fn point_cloud_without_faces_announces_the_object() {
        let text =
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
                    end_header\n1 2 3\nnan 0 0\n";
        let (c, s) = run("cloud.ply", text.as_bytes()).unwrap();
        assert_eq!(c.objects.len(), 1);
        assert!(c.tris.is_empty());
        assert_eq!(s, SourceSummary { objects: 1, vertices: 2, bytes: text.len() as u64 });
    }

    #[test]
    fn zero_faces_declared() {
        let text =
            "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
                    property float z\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n";
        let (c, s) = run("empty.ply", text.as_bytes()).unwrap();
        assert_eq!((c.objects.len(), c.tris.len(), s.objects), (1, 0, 1));
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

    // ---- per-face objects ----

    /// Four vertices and four triangles with the file object ids 7, 3, 7, 100, in `property uint
    /// object` after the indices (as terawalk's writer lays it out).
    fn with_objects(encoding: &str) -> Vec<u8> {
        let header = format!(
            "ply\nformat {encoding} 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
             property float z\nelement face 4\nproperty list uchar uint vertex_indices\n\
             property uint object\nend_header\n"
        );
        let faces = [([0u32, 1, 2], 7u32), ([0, 2, 3], 3), ([3, 2, 1], 7), ([1, 3, 0], 100)];
        if encoding == "ascii" {
            let mut s = header;
            for v in SQUARE {
                s += &format!("{} {} {}\n", v[0], v[1], v[2]);
            }
            for ([a, b, c], o) in faces {
                s += &format!("3 {a} {b} {c} {o}\n");
            }
            return s.into_bytes();
        }
        let mut w = W::new(&header, encoding == "binary_big_endian");
        for v in SQUARE {
            w.f32(v[0]).f32(v[1]).f32(v[2]);
        }
        for ([a, b, c], o) in faces {
            w.u8(3).u32(a).u32(b).u32(c).u32(o);
        }
        w.out
    }

    fn object_names(c: &Collect) -> Vec<(u32, String)> {
        c.objects.iter().map(|(id, info)| (*id, info.name.clone())).collect()
    }

    fn tri_objects(c: &Collect) -> Vec<u32> {
        c.tris.iter().map(|t| t.object).collect()
    }

    #[test]
    fn per_face_object_ids_become_dense_in_order_of_first_appearance() {
        for enc in ["ascii", "binary_little_endian", "binary_big_endian"] {
            for zipped in [false, true] {
                let bytes = if zipped { gz(&with_objects(enc)) } else { with_objects(enc) };
                let (c, s) = run("obj.ply", &bytes).unwrap_or_else(|e| panic!("{enc}: {e}"));
                let names =
                    vec![(0, "obj/7".to_string()), (1, "obj/3".to_string()), (2, "obj/100".to_string())];
                assert_eq!(object_names(&c), names, "{enc} gzip={zipped}");
                assert!(c.objects.iter().all(|(_, i)| i.color.is_none()));
                assert_eq!(tri_objects(&c), vec![0, 1, 0, 2], "{enc} gzip={zipped}");
                assert_eq!(s.objects, 3, "{enc} gzip={zipped}");
                let v = |i: usize| SQUARE[i].map(|c| c as f64);
                assert_eq!(c.tris[3].positions, [v(1), v(3), v(0)], "{enc}");
            }
        }
    }

    /// A sink that records the order of announcements and triangles.
    #[derive(Default)]
    struct Events(Vec<String>);

    impl TriangleSink for Events {
        fn object(&mut self, id: u32, _: &ObjectInfo) -> Result<(), ImportError> {
            self.0.push(format!("object {id}"));
            Ok(())
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            self.0.push(format!("triangle {}", t.object));
            Ok(())
        }
    }

    #[test]
    fn each_object_is_announced_just_before_its_first_triangle() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("o.ply");
        std::fs::write(&p, with_objects("binary_little_endian")).unwrap();
        let mut events = Events::default();
        open(Input::open(&p).unwrap(), &ImportOptions::default()).unwrap().stream(&mut events).unwrap();
        let want =
            ["object 0", "triangle 0", "object 1", "triangle 1", "triangle 0", "object 2", "triangle 2"];
        assert_eq!(events.0, want);
    }

    #[test]
    fn object_id_property_signed_and_before_the_indices() {
        // `object_id`, a signed type, before the list; a quad's two triangles share its object.
        let header =
            "ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                      property float z\nelement face 3\nproperty short object_id\n\
                      property list uchar int vertex_indices\nend_header\n";
        let mut w = W::new(header, true);
        for v in SQUARE {
            w.f32(v[0]).f32(v[1]).f32(v[2]);
        }
        w.i16(-1).u8(4).i32(0).i32(1).i32(2).i32(3);
        w.i16(5).u8(3).i32(3).i32(2).i32(1);
        w.i16(-1).u8(3).i32(0).i32(1).i32(3);
        let (c, s) = run("s.ply", &w.out).unwrap();
        assert_eq!(object_names(&c), vec![(0, "s/-1".to_string()), (1, "s/5".to_string())]);
        assert_eq!(tri_objects(&c), vec![0, 0, 1, 0]);
        assert_eq!(s.objects, 2);
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 2\nproperty int object_id\nproperty list uchar int vertex_indices\nend_header\n\
                    0 0 0\n1 0 0\n0 1 0\n-1 3 0 1 2\n42 3 2 1 0\n";
        let (c, _) = run("s.ply", text.as_bytes()).unwrap();
        assert_eq!(object_names(&c), vec![(0, "s/-1".to_string()), (1, "s/42".to_string())]);
        assert_eq!(tri_objects(&c), vec![0, 1]);
    }

    #[test]
    fn object_is_preferred_over_object_id() {
        let text =
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 1\nproperty int object_id\nproperty list uchar int vertex_indices\n\
                    property uchar object\nend_header\n0 0 0\n1 0 0\n0 1 0\n9 3 0 1 2 4\n";
        let (c, _) = run("p.ply", text.as_bytes()).unwrap();
        assert_eq!(object_names(&c), vec![(0, "p/4".to_string())]);
    }

    #[test]
    fn non_integer_object_property_is_ignored() {
        for (decl, a, b) in [("float object", "1.5", "2"), ("list uchar int object", "1 7", "2 8 9")] {
            let text = format!(
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                 element face 2\nproperty list uchar int vertex_indices\nproperty {decl}\nend_header\n\
                 0 0 0\n1 0 0\n0 1 0\n3 0 1 2 {a}\n3 2 1 0 {b}\n"
            );
            let (c, s) = run("f.ply", text.as_bytes()).unwrap();
            assert_eq!(object_names(&c), vec![(0, "f".to_string())], "{decl}");
            assert_eq!(tri_objects(&c), vec![0, 0]);
            assert_eq!(s.objects, 1);
        }
    }

    #[test]
    fn object_property_without_faces_keeps_the_file_object() {
        let text =
            "ply\nformat binary_little_endian 1.0\nelement vertex 0\nproperty float x\nproperty float y\n\
                    property float z\nelement face 0\nproperty list uchar int vertex_indices\n\
                    property uint object\nend_header\n";
        let (c, s) = run("e.ply", text.as_bytes()).unwrap();
        assert_eq!(object_names(&c), vec![(0, "e".to_string())]);
        assert_eq!(s.objects, 1);
    }

    #[test]
    fn short_faces_announce_no_object() {
        let text = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 3\nproperty list uchar int vertex_indices\nproperty uint object\nend_header\n\
                    0 0 0\n1 0 0\n0 1 0\n2 0 1 5\n3 0 1 2 9\n0 6\n";
        let (c, s) = run("s.ply", text.as_bytes()).unwrap();
        assert_eq!(object_names(&c), vec![(0, "s/9".to_string())]);
        assert_eq!(tri_objects(&c), vec![0]);
        assert_eq!(s.objects, 1);
    }

    #[test]
    fn many_objects_in_a_large_binary_file() {
        // Runs of faces per object, ids revisited out of order: the last-id cache and the map
        // must agree.
        let n = 50_000u32;
        let header = format!(
            "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nelement face {n}\nproperty list uchar int vertex_indices\n\
             property uint object\nend_header\n"
        );
        let mut w = W::new(&header, false);
        w.f32(0.0).f32(0.0).f32(0.0).f32(1.0).f32(0.0).f32(0.0).f32(0.0).f32(1.0).f32(0.0);
        let raw = |i: u32| ((i / 3) % 1000).wrapping_mul(2_654_435_761);
        for i in 0..n {
            w.u8(3).i32(0).i32(1).i32(2).u32(raw(i));
        }
        let (c, s) = run("m.ply", &w.out).unwrap();
        assert_eq!(s.objects, 1000);
        assert_eq!(c.objects.len(), 1000);
        for (i, t) in c.tris.iter().enumerate() {
            let name = &c.objects[t.object as usize].1.name;
            assert_eq!(*name, format!("m/{}", raw(i as u32)), "triangle {i}");
        }
    }

    #[test]
    fn bad_ascii_object_value() {
        let text = String::from_utf8(with_objects("ascii")).unwrap();
        let e = err("b.ply", text.replace("3 3 2 1 7", "3 3 2 1 seven").as_bytes());
        assert_err(&e, Position::Line(17), "face 2: invalid number \"seven\" for object");
        let e = err("b.ply", text.replace("3 3 2 1 7", "3 3 2 1").as_bytes());
        assert_err(&e, Position::Line(17), "fewer values than the header declares (no object)");
    }

    // ---- errors ----

    fn assert_err(e: &ImportError, pos: Position, text: &str) {
        assert_eq!(e.position(), Some(pos), "{e}");
        assert!(e.to_string().contains(text), "{e:?} does not contain {text:?}");
    }

    #[test]
    fn empty_file() {
        assert_err(&err("e.ply", b""), Position::File, "empty file");
    }

    #[test]
    fn garbage_bytes() {
        assert_err(&err("g.ply", b"\x00\x9f\x13garbage\n\x01"), Position::Line(1), "not a PLY file");
        assert_err(&err("g.ply", b"ply\n\xff\xfe\xfd\n"), Position::Line(2), "not text");
    }

    #[test]
    fn stray_header_lines_are_skipped() {
        // As Blender 2.47 writes them (assimp's Wuson.ply).
        let (c, _) = run(
            "w.ply",
            b"ply\nformat ascii 1.0\nCreated by Blender3D 247\nelement vertex 3\nproperty float x\n\
              property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
              end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
        )
        .unwrap();
        assert_eq!(c.tris.len(), 1);
    }

    #[test]
    fn truncated_header() {
        let e = err("t.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n");
        assert_err(&e, Position::Line(5), "ends inside the header");
    }

    #[test]
    fn unknown_format_and_version() {
        assert_err(
            &err("f.ply", b"ply\nformat binary_middle_endian 1.0\nend_header\n"),
            Position::Line(2),
            "unknown format",
        );
        assert_err(&err("f.ply", b"ply\nformat ascii 2.0\nend_header\n"), Position::Line(2), "version 2.0");
        assert_err(&err("f.ply", b"ply\nend_header\n"), Position::Line(2), "no \"format\" line");
    }

    #[test]
    fn unknown_property_type() {
        let text = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n";
        assert_err(&err("p.ply", text), Position::Line(4), "unknown property type \"float128\"");
        let text = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty list float int x\nend_header\n";
        assert_err(&err("p.ply", text), Position::Line(4), "must be an integer type");
    }

    #[test]
    fn missing_z() {
        let text =
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n";
        assert_err(&err("z.ply", text), Position::Line(3), "no property \"z\"");
    }

    #[test]
    fn face_without_vertex_indices() {
        let text = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
                     element face 1\nproperty list uchar int corners\nend_header\n";
        assert_err(&err("f.ply", text), Position::Line(7), "no list \"vertex_indices\"");
        let text = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
                     element face 1\nproperty list uchar float vertex_indices\nend_header\n";
        assert_err(&err("f.ply", text), Position::Line(8), "list of integers");
    }

    #[test]
    fn faces_before_vertices() {
        let text = b"ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
                     element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
        let e = err("o.ply", text);
        assert!(matches!(e, ImportError::Unsupported { .. }), "{e:?}");
        assert!(e.to_string().contains("faces before vertices are not supported"), "{e}");
    }

    #[test]
    fn truncated_binary_body_plain_is_found_at_open() {
        let mut bytes = square("binary_little_endian");
        bytes.truncate(bytes.len() - 3);
        assert_err(&err("t.ply", &bytes), Position::Byte(bytes.len() as u64), "truncated");
    }

    #[test]
    fn truncated_binary_body_gzip_is_found_while_streaming() {
        for cut in [3, 20, 60] {
            let mut bytes = square("binary_big_endian");
            bytes.truncate(bytes.len() - cut);
            let e = err("t.ply.gz", &gz(&bytes));
            assert_err(&e, Position::Byte(bytes.len() as u64), "the file is truncated");
        }
    }

    #[test]
    fn truncated_ascii_body() {
        let text = String::from_utf8(square("ascii")).unwrap();
        let cut = &text[..text.len() - "3 3 2 1\n".len()];
        assert_err(&err("t.ply", cut.as_bytes()), Position::Line(17), "ends before face 1 of 2");
    }

    #[test]
    fn absurd_vertex_count_does_not_allocate() {
        let header = "ply\nformat binary_little_endian 1.0\nelement vertex 99999999999\nproperty float x\n\
                      property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n\
                      end_header\n";
        let mut bytes = header.as_bytes().to_vec();
        bytes.extend_from_slice(&[0; 100]);
        assert_err(&err("a.ply", &bytes), Position::Byte(bytes.len() as u64), "truncated");
        // Compressed: the size is unknown, found lazily.
        let e = err("a.ply.gz", &gz(&bytes));
        assert_err(&e, Position::Byte(bytes.len() as u64), "ends in vertex 8 of 99999999999");
        let text = "ply\nformat ascii 1.0\nelement vertex 99999999999\nproperty float x\nproperty float y\n\
                    property float z\nend_header\n1 2 3\n";
        assert_err(&err("a.ply", text.as_bytes()), Position::Line(9), "ends before vertex 1");
        let text = "ply\nformat ascii 1.0\nelement vertex -5\nend_header\n";
        assert_err(&err("a.ply", text.as_bytes()), Position::Line(3), "invalid count");
    }

    #[test]
    fn absurd_list_count() {
        let header =
            "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                      property float z\nelement face 1\nproperty list uint int vertex_indices\nend_header\n";
        let mut w = W::new(header, false);
        for _ in 0..9 {
            w.f32(0.0);
        }
        let face_at = w.out.len() as u64;
        w.u32(4_000_000_000).i32(0).i32(1).i32(2);
        assert_err(&err("l.ply", &w.out), Position::Byte(face_at), "4000000000 items (at most 65536");
        let text = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
                    element face 1\nproperty list uint int vertex_indices\nend_header\n0 0 0\n4000000000 0 0 0\n";
        assert_err(&err("l.ply", text.as_bytes()), Position::Line(11), "at most 65536");
        let text = text.replace("4000000000", "-3");
        assert_err(&err("l.ply", text.as_bytes()), Position::Line(11), "negative length");
    }

    #[test]
    fn index_out_of_range_or_negative() {
        for (bad, what) in [(4i32, "index 4 out of range"), (-1, "index -1 out of range")] {
            let mut bytes = square("binary_little_endian");
            let n = bytes.len();
            bytes[n - 4..].copy_from_slice(&bad.to_le_bytes());
            let face1 = (n - 13) as u64;
            assert_err(&err("r.ply", &bytes), Position::Byte(face1), &format!("face 1: vertex {what}"));
            let text =
                String::from_utf8(square("ascii")).unwrap().replace("3 3 2 1", &format!("3 3 2 {bad}"));
            assert_err(&err("r.ply", text.as_bytes()), Position::Line(17), what);
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

    #[test]
    fn ascii_value_count_and_number_errors() {
        let text = String::from_utf8(square("ascii")).unwrap();
        assert_err(
            &err("v.ply", text.replace("1 1 0", "1 1").as_bytes()),
            Position::Line(14),
            "fewer values",
        );
        assert_err(
            &err("v.ply", text.replace("1 1 0", "1 1 0 9").as_bytes()),
            Position::Line(14),
            "more values",
        );
        assert_err(
            &err("v.ply", text.replace("1 1 0", "1 1x 0").as_bytes()),
            Position::Line(14),
            "invalid number \"1x\"",
        );
        assert_err(
            &err("v.ply", text.replace("3 3 2 1", "3 3 2").as_bytes()),
            Position::Line(17),
            "fewer values",
        );
        assert_err(
            &err("v.ply", text.replace("3 3 2 1", "3 3 2 1.5").as_bytes()),
            Position::Line(17),
            "invalid number",
        );
    }

    #[test]
    fn trailing_data_is_tolerated() {
        let mut bytes = square("binary_little_endian");
        bytes.extend_from_slice(b"trailing junk");
        let (c, _) = run("t.ply", &bytes).unwrap();
        assert_eq!(c.tris.len(), 3);
    }

    // ---- runs of triangle records (Body::binary_triangles) ----

    /// A mesh of `n` vertices and mostly triangular faces in `encoding`, with a scalar before
    /// the index list and the object after it: a quad, short faces, far references and object
    /// changes sprinkled in. Face `bad_at` (if any) gets the list `bad_list` instead.
    fn mixed(encoding: &str, n: u32, faces: u32, count_ty: &str, bad: Option<(u32, &[i64])>) -> Vec<u8> {
        let header = format!(
            "ply\nformat {encoding} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n\
             property float z\nelement face {faces}\nproperty uchar flags\n\
             property list {count_ty} int vertex_indices\nproperty int object\nend_header\n"
        );
        let list = |f: u32| -> Vec<i64> {
            if let Some((at, l)) = bad {
                if f == at {
                    return l.to_vec();
                }
            }
            let a = |k: u32| ((f + k) % n) as i64;
            match f % 997 {
                500 => vec![a(0), a(1), a(2), a(3)],
                600 => vec![a(0), a(1)],
                700 => vec![],
                // A vertex far behind: its spilled block is read back.
                _ if f.is_multiple_of(211) => vec![a(0), ((f * 7919) % n) as i64, a(2)],
                _ => vec![a(0), a(1), a(2)],
            }
        };
        let object = |f: u32| ((f / 37) % 5) as i32 - 2;
        if encoding == "ascii" {
            let mut t = header;
            for i in 0..n {
                t += &format!("{} {} {}\n", i, i % 13, (i * i) % 101);
            }
            for f in 0..faces {
                let l = list(f);
                let items: Vec<String> = l.iter().map(|i| i.to_string()).collect();
                t += &format!("9 {} {} {}\n", l.len(), items.join(" "), object(f));
            }
            return t.into_bytes();
        }
        let mut w = W::new(&header, encoding == "binary_big_endian");
        for i in 0..n {
            w.f32(i as f32).f32((i % 13) as f32).f32(((i * i) % 101) as f32);
        }
        for f in 0..faces {
            let l = list(f);
            w.u8(9);
            match count_ty {
                "uchar" => w.u8(l.len() as u8),
                _ => w.i32(l.len() as i32),
            };
            for i in l {
                w.i32(i as i32);
            }
            w.i32(object(f));
        }
        w.out
    }

    /// Objects and triangles in the order a sink saw them.
    #[derive(Default)]
    struct Seen(Vec<(Option<ObjectInfo>, Option<Triangle>)>);

    impl TriangleSink for Seen {
        fn object(&mut self, id: u32, info: &ObjectInfo) -> Result<(), ImportError> {
            assert_eq!(id as usize, self.0.iter().filter(|e| e.0.is_some()).count());
            self.0.push((Some(info.clone()), None));
            Ok(())
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            self.0.push((None, Some(*t)));
            Ok(())
        }
    }

    /// Streams `bytes` into a [`Seen`] and returns it with the result.
    fn seen(bytes: &[u8], vertex_memory: usize) -> (Seen, Result<SourceSummary, ImportError>) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ply");
        std::fs::write(&p, bytes).unwrap();
        let options = ImportOptions { vertex_memory, spill_dir: None };
        let mut sink = Seen::default();
        let r = open(Input::open(&p).unwrap(), &options).and_then(|s| s.stream(&mut sink));
        (sink, r)
    }

    #[test]
    fn triangle_runs_give_what_the_general_path_gives() {
        // ASCII goes the general way, record by record; binary in runs, with polygons, short
        // faces and (with no vertex memory) faces whose blocks are not resident in between.
        let (n, faces) = (30_000, 50_000);
        let (want, r) = seen(&mixed("ascii", n, faces, "uchar", None), 192 << 20);
        r.unwrap();
        assert_eq!(want.0.iter().filter(|e| e.1.is_some()).count(), 50_000 - 2 * 50 + 50);
        assert_eq!(want.0.iter().filter(|e| e.0.is_some()).count(), 5);
        for encoding in ["binary_little_endian", "binary_big_endian"] {
            for count_ty in ["uchar", "int"] {
                for memory in [0, 1 << 16, 192 << 20] {
                    let (got, r) = seen(&mixed(encoding, n, faces, count_ty, None), memory);
                    r.unwrap();
                    assert!(got.0 == want.0, "{encoding} {count_ty} {memory}");
                }
            }
        }
    }

    #[test]
    fn bad_index_in_a_run_names_its_face_after_streaming_the_ones_before() {
        let (n, faces) = (20_000, 30_000);
        for (at, list, text) in [
            (12_345u32, &[1i64, 20_000, 2][..], "face 12345: vertex index 20000 out of range"),
            (29_999, &[-1, 0, 1][..], "face 29999: vertex index -1 out of range"),
        ] {
            let bytes = mixed("binary_little_endian", n, faces, "uchar", Some((at, list)));
            let (sink, r) = seen(&bytes, 1 << 16);
            // Every face record before `at` is the same size but for the polygons and short ones.
            let ascii = mixed("ascii", n, at, "uchar", None);
            let (before, _) = seen(&ascii, 1 << 16);
            let header = bytes.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
            let record = |f: u32| {
                1 + 1
                    + 4 * (if f % 997 == 500 {
                        4
                    } else if f % 997 == 600 {
                        2
                    } else if f % 997 == 700 {
                        0
                    } else {
                        3
                    })
                    + 4
            };
            let offset = header as u64 + 12 * n as u64 + (0..at).map(|f| record(f) as u64).sum::<u64>();
            assert_err(&r.unwrap_err(), Position::Byte(offset), text);
            assert!(sink.0 == before.0, "the triangles before face {at} are streamed");
        }
    }

    #[test]
    fn bad_list_counts_mid_file_are_errors_at_their_face() {
        let (n, faces) = (5_000, 9_000);
        let header_and_vertices = |bytes: &[u8]| {
            bytes.windows(11).position(|w| w == b"end_header\n").unwrap() as u64 + 11 + 12 * n as u64
        };
        // `int` counts: a negative one and one beyond MAX_LIST, after a long run of triangles.
        let record = |f: u32| {
            1 + 4
                + 4 * (if f % 997 == 500 {
                    4
                } else if f % 997 == 600 {
                    2
                } else if f % 997 == 700 {
                    0
                } else {
                    3
                })
                + 4
        };
        for (count, text) in [(-1i64, "a negative length -1"), (70_000, "70000 items")] {
            let mut bytes = mixed("binary_little_endian", n, faces, "int", Some((8_000, &[0, 1, 2])));
            let at = header_and_vertices(&bytes) + (0..8_000).map(|f| record(f) as u64).sum::<u64>();
            bytes[at as usize + 1..at as usize + 5].copy_from_slice(&(count as i32).to_le_bytes());
            let (_, r) = seen(&bytes, 192 << 20);
            assert_err(
                &r.unwrap_err(),
                Position::Byte(at),
                &format!("face 8000: list vertex_indices has {text}"),
            );
        }
        // A count that runs past the end of the file in the last face.
        let mut bytes = mixed("binary_little_endian", n, faces, "uchar", None);
        let last = header_and_vertices(&bytes) + (0..faces - 1).map(|f| record(f) as u64 - 3).sum::<u64>();
        bytes[last as usize + 1] = 200;
        let (sink, r) = seen(&gz(&bytes), 192 << 20);
        let e = r.unwrap_err();
        assert!(e.to_string().contains("truncated: it ends in face 8999 of 9000"), "{e}");
        assert_eq!(sink.0.iter().filter(|e| e.1.is_some()).count(), 8_999 - 2 * 9 + 9);
    }

    /// A sink that fetches each batch's triangles backwards, in ranges of 7: the order of
    /// fetching must not matter.
    #[derive(Default)]
    struct Backwards(Seen);

    impl TriangleSink for Backwards {
        fn object(&mut self, id: u32, info: &ObjectInfo) -> Result<(), ImportError> {
            self.0.object(id, info)
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            self.0.triangle(t)
        }
        fn batch(&mut self, batch: &dyn TriangleBatch) -> Result<(), ImportError> {
            let mut parts = Vec::new();
            for end in (0..batch.len()).rev().step_by(7) {
                let mut out = Vec::new();
                batch.triangles(end.saturating_sub(6)..end + 1, &mut out)?;
                parts.push(out);
            }
            let tris: Vec<Triangle> = parts.into_iter().rev().flatten().collect();
            let mut new = batch.new_objects().iter().peekable();
            for (i, t) in tris.iter().enumerate() {
                while let Some(o) = new.next_if(|o| o.first == i) {
                    self.0.object(o.id, &o.info)?;
                }
                self.0.triangle(t)?;
            }
            Ok(())
        }
    }

    #[test]
    fn batches_can_be_fetched_in_any_order() {
        let bytes = mixed("binary_little_endian", 10_000, 20_000, "uchar", None);
        let (want, _) = seen(&bytes, 192 << 20);
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ply");
        std::fs::write(&p, &bytes).unwrap();
        let mut sink = Backwards::default();
        open(Input::open(&p).unwrap(), &ImportOptions::default()).unwrap().stream(&mut sink).unwrap();
        assert!(sink.0 .0 == want.0);
    }
}
