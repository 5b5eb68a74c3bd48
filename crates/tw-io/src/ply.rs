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
//!   warning); other face properties are skipped;
//! - any other element (`edge`, `material`, `tristrips`…), before, between or after these, is
//!   skipped.
//!
//! The file is one object (id 0) named after the file. Stages:
//! 1. [`open`] reads the header ([`read_header`]) and checks that a binary file is long enough
//!    for its declared counts, so that a broken file fails before any work.
//! 2. [`PlySource::stream`] walks the elements in file order: vertex records go into
//!    [`VertexStore`]s (positions, and normals and colours when present) under the memory budget
//!    of [`ImportOptions::vertex_memory`], spilling to disk beyond it; face records are resolved
//!    through the stores and streamed as triangles; other elements are skipped.
//!
//! Binary records are decoded straight out of the read buffer ([`ByteReader`]): a record of a
//! fixed layout is a constant set of offsets, a record with lists is measured once and decoded in
//! place; no per-record allocation or virtual call. ASCII records are one line each.
//!
//! Limits and choices: faces must come after vertices (the usual order; the other order would
//! need the faces held until the vertices arrive); lists in vertex and face records hold at most
//! [`MAX_LIST`] items; a file without faces (a point cloud) yields no triangles and its vertex
//! data is skipped unread; a non-finite position is an error, a non-finite normal becomes zero.

use std::io::{self, Read};
use std::ops::Range;
use std::path::{Path, PathBuf};

use tw_core::Rgba8;

use crate::error::{ImportError, Position};
use crate::format::ImportOptions;
use crate::input::{DiskCounter, Input};
use crate::vertex_store::VertexStore;
use crate::{ObjectInfo, SourceSummary, Triangle, TriangleSink, TriangleSource};

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
        let need: u128 = header.elements.iter().map(|e| e.count as u128 * min_record_size(&e.props) as u128).sum();
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
    let name = if name.to_ascii_lowercase().ends_with(".gz") { name[..name.len() - 3].to_string() } else { name };
    match name.rfind('.') {
        Some(i) if i > 0 => name[..i].to_string(),
        _ => name,
    }
}

// ---------------------------------------------------------------------------------------------
// Reading bytes

/// Bytes at the start of the remaining stream: the largest buffer a [`ByteReader`] may grow to.
const MAX_BUFFER: usize = 64 << 20;
const CHUNK: usize = 1 << 20;

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
                return Err(io::Error::new(io::ErrorKind::InvalidData, "a record or line is larger than 64 MiB"));
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

/// Where a face keeps its indices: property index and the list's types.
#[derive(Clone, Copy, Debug)]
struct FaceLayout {
    prop: usize,
    count: Scalar,
    item: Scalar,
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
        let range = match rd.read_line(MAX_HEADER_LINE).map_err(|e| ImportError::io(path, Position::Line(line_no), e))? {
            Line::Text(r) => r,
            Line::Eof if line_no == 1 => return Err(ImportError::parse(path, Position::File, "empty file")),
            Line::Eof => return Err(err("the file ends inside the header (no \"end_header\" line)".into())),
            Line::TooLong => return Err(err(format!("header line longer than {MAX_HEADER_LINE} bytes"))),
        };
        header_bytes += range.len() + 1;
        if header_bytes > MAX_HEADER_BYTES {
            return Err(err(format!("the header is longer than {MAX_HEADER_BYTES} bytes")));
        }
        let Ok(text) = std::str::from_utf8(rd.bytes(range)) else {
            return Err(err("the header line is not text (binary data inside the header?)".into()));
        };
        if line_no == 1 {
            if text.trim_end() != "ply" {
                return Err(err("not a PLY file: the first line must be \"ply\"".into()));
            }
            continue;
        }
        let mut words = text.split_ascii_whitespace();
        let Some(keyword) = words.next() else { continue };
        match keyword {
            "comment" | "obj_info" => continue,
            "format" => {
                let (Some(name), Some(version), None) = (words.next(), words.next(), words.next()) else {
                    return Err(err("expected \"format <ascii|binary_little_endian|binary_big_endian> 1.0\"".into()));
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
            _ => return Err(err(format!("unknown header line \"{}\"", show(keyword.as_bytes())))),
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
                        return Err(at(p.line, format!("vertex property {} must be a scalar, not a list", p.name)));
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
                let partial_colors = !colors && (has(Role::R) || has(Role::G) || has(Role::B) || has(Role::A));
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
                let Some((prop, p)) =
                    el.props.iter().enumerate().find(|(_, p)| p.name == "vertex_indices" || p.name == "vertex_index")
                else {
                    return Err(at(el.line, "the face element has no list \"vertex_indices\"".into()));
                };
                let PropKind::List { count, item } = p.kind else {
                    return Err(at(p.line, format!("{} must be a list", p.name)));
                };
                if !item.is_integer() {
                    return Err(at(p.line, format!("{} must be a list of integers", p.name)));
                }
                el.role = ElementRole::Face(FaceLayout { prop, count, item });
            }
            _ => {
                if el.name == "tristrips" && el.count > 0 {
                    tracing::warn!("{}: element \"tristrips\" is not read; its triangles are skipped", path.display());
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

/// The vertex stores.
struct Vertices {
    pos: VertexStore<[f64; 3]>,
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

impl Vertices {
    /// Stores sharing `budget` bytes in proportion to their record sizes.
    fn new(normals: bool, colors: bool, options: &ImportOptions) -> Vertices {
        let weight = 24 + if normals { 12 } else { 0 } + if colors { 4 } else { 0 };
        let share = |w: usize| options.vertex_memory / weight * w;
        let dir = || options.spill_dir.clone();
        Vertices {
            pos: VertexStore::new(share(24), dir()),
            normals: normals.then(|| VertexStore::new(share(12), dir())),
            colors: colors.then(|| VertexStore::new(share(4), dir())),
        }
    }

    #[inline]
    fn push(&mut self, v: &VertexValues) -> io::Result<()> {
        self.pos.push(v.pos)?;
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
            pos: self.pos.get(i)?,
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

    fn len(&self) -> u64 {
        self.pos.len()
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
    fn emit(&mut self, v: &mut Vertices, sink: &mut dyn TriangleSink) -> Result<(), RecordError> {
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
            let normals = match (a.normal, b.normal, c.normal) {
                (Some(x), Some(y), Some(z)) => Some([x, y, z]),
                _ => None,
            };
            let colors = match (a.color, b.color, c.color) {
                (Some(x), Some(y), Some(z)) => Some([x, y, z]),
                _ => None,
            };
            sink.triangle(&Triangle { positions: [a.pos, b.pos, c.pos], normals, colors, object: 0 })?;
            b = c;
        }
        Ok(())
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
        sink.object(0, &ObjectInfo { name: object_name(&path), color: None })?;
        let faces_declared = header.count_of(|r| matches!(r, ElementRole::Face(_)));
        let vertices_declared = header.count_of(|r| matches!(r, ElementRole::Vertex(_)));
        let mut body = Body {
            path: &path,
            counter: &counter,
            big: header.encoding == Encoding::BinaryBe,
            line: header.lines,
            vertices: None,
            faces: Faces { indices: Vec::new(), short: 0 },
        };
        for el in &header.elements {
            match (&el.role, header.encoding) {
                (ElementRole::Vertex(layout), _) if faces_declared > 0 => {
                    let mut v = Vertices::new(layout.normals, layout.colors, &options);
                    if header.encoding == Encoding::Ascii {
                        body.ascii_vertices(&mut rd, el, layout, &mut v, sink)?;
                    } else {
                        body.binary_vertices(&mut rd, el, layout, &mut v, sink)?;
                    }
                    body.vertices = Some(v);
                }
                (ElementRole::Face(layout), _) if el.count > 0 => {
                    let mut v = body.vertices.take().unwrap_or_else(|| Vertices::new(false, false, &options));
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
            let st = v.pos.stats();
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
        Ok(SourceSummary { objects: 1, vertices: vertices_declared, bytes: counter.get() })
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
                let got = rd.fill_more().map_err(|e| ImportError::io(path, Position::Byte(rd.position()), e))?;
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
            faces.emit(v, sink)
        });
        self.faces = faces;
        result
    }

    fn binary_skip(&mut self, rd: &mut ByteReader, el: &Element, sink: &mut dyn TriangleSink) -> Result<(), ImportError> {
        let mut offsets = vec![0usize; el.props.len()];
        if let Some(size) = fixed_layout(&el.props, &mut offsets) {
            let bytes = el.count.saturating_mul(size as u64);
            let skipped = rd.skip(bytes).map_err(|e| ImportError::io(self.path, Position::Byte(rd.position()), e))?;
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
                        return Err(ImportError::parse(path, pos, format!("line longer than {MAX_ASCII_LINE} bytes")))
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
        let result = self.ascii_records(rd, el, sink, |tokens, _, sink| {
            faces.indices.clear();
            for (pi, p) in el.props.iter().enumerate() {
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
            faces.emit(v, sink)
        });
        self.faces = faces;
        result
    }

    fn ascii_skip(&mut self, rd: &mut ByteReader, el: &Element, sink: &mut dyn TriangleSink) -> Result<(), ImportError> {
        self.ascii_records(rd, el, sink, |tokens, _, _| {
            for p in &el.props {
                skip_ascii_property(tokens, p, MAX_SKIPPED_LIST)?;
            }
            Ok(())
        })
    }
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
    tokens.next().ok_or_else(|| RecordError::Bad(format!("fewer values than the header declares (no {})", p.name)))
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
