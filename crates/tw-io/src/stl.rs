//! STL importer: streams the triangles of binary and ASCII STL files.
//!
//! Follows the STL format of 3D Systems' "StereoLithography Interface Specification" (1989) as
//! exporters write it today:
//! - binary: an 80-byte header, a little-endian `u32` triangle count, then 50 bytes per triangle
//!   (facet normal, three vertices, all `f32`, and a 2-byte attribute, which is ignored: its
//!   colour conventions disagree between vendors). One object, named after the file.
//! - ASCII: `solid name` … `facet normal nx ny nz` / `outer loop` / three `vertex x y z` /
//!   `endloop` / `endfacet` … `endsolid`, keywords case-insensitive, one statement per line.
//!   Every `solid` block is an object with its name; a file may hold several.
//!
//! Detection: a file that does not start with `solid` is binary. One that does may still be
//! binary (many exporters write "solid" into the binary header): it is binary when its size is
//! exactly `84 + 50 n` for the count `n` in its header (known for uncompressed files), or when
//! the line after `solid` does not start with `facet` or `endsolid` (the only test for gzip'ed
//! files, whose size is unknown until the end).
//!
//! Facet normals: a finite, non-zero facet normal becomes the normal of all three vertices of
//! its triangle; a zero or non-finite one (common: many exporters write zeros) gives no normals.
//! Non-finite vertex coordinates are errors. A binary file shorter than its count says is an
//! error at the byte where it ends; bytes after the last triangle are ignored with a warning.

use std::path::PathBuf;

use crate::error::{ImportError, Position};
use crate::format::ImportOptions;
use crate::input::{DiskCounter, Input};
use crate::ply::{object_name, parse_f64, show, ByteReader, Line, Tokens};
use crate::{ObjectInfo, SourceSummary, Triangle, TriangleSink, TriangleSource};

/// Bytes looked at to tell ASCII from binary.
const SNIFF: usize = 1024;
const HEADER: usize = 84;
const RECORD: usize = 50;
/// Longest line of an ASCII file.
const MAX_LINE: usize = 1 << 20;

/// Opens an STL file for streaming: tells binary from ASCII and checks a binary file's size.
pub fn open(input: Input, _options: &ImportOptions) -> Result<Box<dyn TriangleSource>, ImportError> {
    let path = input.path.clone();
    let (gzip, file_len, counter) = (input.gzip, input.file_len, input.disk_counter());
    let mut rd = ByteReader::new(input);
    rd.ensure(SNIFF).map_err(|e| ImportError::io(&path, Position::Byte(0), e))?;
    let head = &rd.available()[..rd.available().len().min(SNIFF)];
    if head.is_empty() {
        return Err(ImportError::parse(&path, Position::File, "empty file"));
    }
    let size = (!gzip).then_some(file_len);
    if is_ascii(head, size) {
        return Ok(Box::new(AsciiStl { path, rd, counter, file_len }));
    }
    let looks_like_text = head.iter().all(|&b| b.is_ascii_graphic() || b.is_ascii_whitespace());
    let hint = if looks_like_text { " (the file is text but does not start with \"solid\")" } else { "" };
    if head.len() < HEADER {
        return Err(ImportError::parse(
            &path,
            Position::Byte(head.len() as u64),
            format!("not a binary STL file: shorter than the 84-byte header{hint}"),
        ));
    }
    let count = u32::from_le_bytes([head[80], head[81], head[82], head[83]]);
    let need = HEADER as u64 + RECORD as u64 * count as u64;
    if let Some(size) = size {
        if size < need {
            return Err(ImportError::parse(
                &path,
                Position::Byte(size),
                format!(
                    "the file is truncated: the binary STL header declares {count} triangles \
                     ({need} bytes) but the file has {size} bytes{hint}"
                ),
            ));
        }
    }
    Ok(Box::new(BinaryStl { path, rd, counter, file_len, count }))
}

/// True when `head` (the first bytes) is the start of an ASCII STL; see the module docs.
fn is_ascii(head: &[u8], size: Option<u64>) -> bool {
    let text = head.trim_ascii_start();
    if !starts_with_keyword(text, b"solid") {
        return false;
    }
    if let (Some(size), Some(n)) = (size, head.get(80..84)) {
        let n = u32::from_le_bytes([n[0], n[1], n[2], n[3]]);
        if size == HEADER as u64 + RECORD as u64 * n as u64 {
            return false;
        }
    }
    let whole_file = head.len() < SNIFF;
    let Some(nl) = text.iter().position(|&b| b == b'\n') else {
        // One line only: an unfinished ASCII file when that is the whole file and it is text.
        return whole_file && !text.iter().any(|&b| b.is_ascii_control() && !b.is_ascii_whitespace());
    };
    let next = text[nl + 1..].trim_ascii_start();
    starts_with_keyword(next, b"facet")
        || starts_with_keyword(next, b"endsolid")
        || (next.is_empty() && whole_file)
}

fn starts_with_keyword(text: &[u8], keyword: &[u8]) -> bool {
    text.len() >= keyword.len()
        && text[..keyword.len()].eq_ignore_ascii_case(keyword)
        && text.get(keyword.len()).is_none_or(|b| b.is_ascii_whitespace())
}

/// A facet normal as per-vertex normals when it is finite and non-zero.
#[inline]
fn facet_normals(n: [f32; 3]) -> Option<[[f32; 3]; 3]> {
    (n.iter().all(|c| c.is_finite()) && n != [0.0; 3]).then_some([n; 3])
}

// ---------------------------------------------------------------------------------------------
// Binary

/// A binary STL: header checked, triangles streamed straight from the read buffer.
pub struct BinaryStl {
    path: PathBuf,
    rd: ByteReader,
    counter: DiskCounter,
    file_len: u64,
    count: u32,
}

impl TriangleSource for BinaryStl {
    fn name(&self) -> String {
        self.path.display().to_string()
    }

    fn progress_total(&self) -> Option<u64> {
        Some(self.file_len)
    }

    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        let BinaryStl { path, mut rd, counter, count, .. } = *self;
        let io_err = |rd: &ByteReader, e| ImportError::io(&path, Position::Byte(rd.position()), e);
        // `open` saw the whole header in the buffer.
        rd.consume(HEADER);
        sink.object(0, &ObjectInfo { name: object_name(&path), color: None })?;
        let count = count as u64;
        let mut index = 0u64;
        while index < count {
            let start = rd.position();
            let avail = rd.available();
            let n = ((count - index) as usize).min(avail.len() / RECORD);
            for (k, rec) in avail[..n * RECORD].chunks_exact(RECORD).enumerate() {
                let f = |i: usize| {
                    f32::from_le_bytes([rec[4 * i], rec[4 * i + 1], rec[4 * i + 2], rec[4 * i + 3]])
                };
                let v = |i: usize| [f(3 + 3 * i) as f64, f(4 + 3 * i) as f64, f(5 + 3 * i) as f64];
                let positions = [v(0), v(1), v(2)];
                if !positions.iter().flatten().all(|c| c.is_finite()) {
                    return Err(ImportError::parse(
                        &path,
                        Position::Byte(start + (k * RECORD) as u64),
                        format!("triangle {}: non-finite coordinate {positions:?}", index + k as u64),
                    ));
                }
                let normals = facet_normals([f(0), f(1), f(2)]);
                sink.triangle(&Triangle { positions, normals, colors: None, object: 0 })?;
            }
            rd.consume(n * RECORD);
            index += n as u64;
            if index < count && rd.fill_more().map_err(|e| io_err(&rd, e))? == 0 {
                let end = rd.position() + rd.available().len() as u64;
                return Err(ImportError::parse(
                    &path,
                    Position::Byte(end),
                    format!("the file is truncated: it ends in triangle {index} of {count}"),
                ));
            }
            if rd.take_refilled() {
                sink.progress(counter.get());
            }
        }
        if rd.ensure(1).map_err(|e| io_err(&rd, e))? {
            tracing::warn!(
                "{}: data after the {count} triangles the header declares ignored (from byte {})",
                path.display(),
                rd.position()
            );
        }
        sink.progress(counter.get());
        Ok(SourceSummary { objects: 1, vertices: 3 * count, bytes: counter.get() })
    }
}

// ---------------------------------------------------------------------------------------------
// ASCII

/// An ASCII STL: one object per `solid` block.
pub struct AsciiStl {
    path: PathBuf,
    rd: ByteReader,
    counter: DiskCounter,
    file_len: u64,
}

/// Where the parser is in the `solid` grammar.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// Between solids: `solid` or the end.
    Outside,
    /// In a solid: `facet` or `endsolid`.
    Solid,
    /// After `facet`: `outer loop`.
    Facet,
    /// In a loop with this many vertices: `vertex` or `endloop`.
    Loop(usize),
    /// After `endloop`: `endfacet`.
    EndLoop,
}

impl State {
    fn expected(self) -> &'static str {
        match self {
            State::Outside => "\"solid\"",
            State::Solid => "\"facet\" or \"endsolid\"",
            State::Facet => "\"outer loop\"",
            State::Loop(n) if n < 3 => "\"vertex\"",
            State::Loop(_) => "\"endloop\"",
            State::EndLoop => "\"endfacet\"",
        }
    }
}

fn keyword(t: &[u8], k: &str) -> bool {
    t.eq_ignore_ascii_case(k.as_bytes())
}

/// Exactly three numbers from `tokens`.
fn three(tokens: &mut Tokens, what: &str) -> Result<[f64; 3], String> {
    let mut v = [0.0; 3];
    let mut n = 0;
    for t in tokens {
        if n == 3 {
            return Err(format!("{what} has more than 3 coordinates"));
        }
        v[n] = parse_f64(t).ok_or_else(|| format!("invalid number \"{}\" in {what}", show(t)))?;
        n += 1;
    }
    if n < 3 {
        return Err(format!("{what} needs 3 coordinates, found {n}"));
    }
    Ok(v)
}

impl TriangleSource for AsciiStl {
    fn name(&self) -> String {
        self.path.display().to_string()
    }

    fn progress_total(&self) -> Option<u64> {
        Some(self.file_len)
    }

    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        let AsciiStl { path, mut rd, counter, .. } = *self;
        let mut line_no = 0u64;
        let mut p = AsciiParse {
            state: State::Outside,
            objects: 0,
            triangles: 0,
            normals: None,
            corners: [[0.0; 3]; 3],
        };
        loop {
            line_no += 1;
            let err = |msg: String| ImportError::parse(&path, Position::Line(line_no), msg);
            let range = match rd
                .read_line(MAX_LINE)
                .map_err(|e| ImportError::io(&path, Position::Line(line_no), e))?
            {
                Line::Text(r) => r,
                Line::Eof => break,
                Line::TooLong => return Err(err(format!("line longer than {MAX_LINE} bytes"))),
            };
            let line = rd.bytes(range);
            let mut tokens = Tokens::new(line);
            let Some(word) = tokens.next() else { continue };
            if !p.line(line, word, &mut tokens, sink, &err)? {
                continue;
            }
            if let Some(t) = tokens.next() {
                return Err(err(format!("unexpected \"{}\" at the end of the line", show(t))));
            }
            if rd.take_refilled() {
                sink.progress(counter.get());
            }
        }
        if p.state != State::Outside {
            return Err(ImportError::parse(
                &path,
                Position::Line(line_no),
                format!("the file is truncated: it ends where {} was expected", p.state.expected()),
            ));
        }
        if p.objects == 0 {
            return Err(ImportError::parse(&path, Position::File, "empty file: no \"solid\""));
        }
        sink.progress(counter.get());
        Ok(SourceSummary { objects: p.objects, vertices: 3 * p.triangles, bytes: counter.get() })
    }
}

/// The ASCII reader's state between lines: where it is in the grammar, the solids and
/// triangles so far, and the facet being read.
struct AsciiParse {
    state: State,
    objects: u32,
    triangles: u64,
    normals: Option<[[f32; 3]; 3]>,
    corners: [[f64; 3]; 3],
}

impl AsciiParse {
    /// Takes one non-empty line (`line`, its first word `word`, the rest in `tokens`): a
    /// solid starts or ends, a facet's parts are read, a finished facet goes to `sink`. Returns
    /// whether the caller checks that nothing follows on the line and reports progress (not
    /// after `solid`, `endsolid` and `vertex`, which read the line themselves). `err` makes an
    /// error at this line.
    fn line(
        &mut self,
        line: &[u8],
        word: &[u8],
        tokens: &mut Tokens,
        sink: &mut dyn TriangleSink,
        err: &dyn Fn(String) -> ImportError,
    ) -> Result<bool, ImportError> {
        match self.state {
            State::Outside if keyword(word, "solid") => {
                let name = line.trim_ascii_start()[5..].trim_ascii();
                let info = ObjectInfo { name: String::from_utf8_lossy(name).into_owned(), color: None };
                sink.object(self.objects, &info)?;
                self.objects += 1;
                self.state = State::Solid;
                return Ok(false);
            }
            State::Solid if keyword(word, "endsolid") => {
                self.state = State::Outside;
                return Ok(false);
            }
            State::Solid if keyword(word, "facet") => {
                self.normals = facet_normal(tokens, err)?;
                self.state = State::Facet;
            }
            State::Facet if keyword(word, "outer") => {
                match tokens.next() {
                    Some(t) if keyword(t, "loop") => {}
                    _ => return Err(err("expected \"outer loop\"".into())),
                }
                self.state = State::Loop(0);
            }
            State::Loop(n) if keyword(word, "vertex") => {
                let v = vertex(n, tokens, err)?;
                self.corners[n] = v;
                self.state = State::Loop(n + 1);
                return Ok(false);
            }
            State::Loop(n) if keyword(word, "endloop") => {
                if n != 3 {
                    return Err(err(format!("a facet with {n} vertices (STL facets are triangles)")));
                }
                self.state = State::EndLoop;
            }
            State::EndLoop if keyword(word, "endfacet") => {
                let t = Triangle {
                    positions: self.corners,
                    normals: self.normals,
                    colors: None,
                    object: self.objects - 1,
                };
                sink.triangle(&t)?;
                self.triangles += 1;
                self.state = State::Solid;
            }
            _ => return Err(err(format!("expected {}, found \"{}\"", self.state.expected(), show(word)))),
        }
        Ok(true)
    }
}

/// The rest of a `facet` line: nothing, or `normal` and three numbers (the facet's normal for
/// each corner, when usable).
fn facet_normal(
    tokens: &mut Tokens,
    err: &dyn Fn(String) -> ImportError,
) -> Result<Option<[[f32; 3]; 3]>, ImportError> {
    match tokens.next() {
        None => Ok(None),
        Some(t) if keyword(t, "normal") => {
            let n = three(tokens, "the facet normal").map_err(err)?;
            Ok(facet_normals(n.map(|c| c as f32)))
        }
        Some(t) => Err(err(format!("expected \"normal\" after \"facet\", found \"{}\"", show(t)))),
    }
}

/// The rest of the line of a facet's vertex `n` (counting from 0): three finite numbers, and
/// no fourth vertex.
fn vertex(
    n: usize,
    tokens: &mut Tokens,
    err: &dyn Fn(String) -> ImportError,
) -> Result<[f64; 3], ImportError> {
    if n == 3 {
        return Err(err("a facet with more than 3 vertices (STL facets are triangles)".into()));
    }
    let v = three(tokens, "the vertex").map_err(err)?;
    if !v.iter().all(|c| c.is_finite()) {
        return Err(err(format!("non-finite coordinate {v:?}")));
    }
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[derive(Default)]
    struct Collect {
        objects: Vec<(u32, String)>,
        tris: Vec<Triangle>,
    }

    impl TriangleSink for Collect {
        fn object(&mut self, id: u32, info: &ObjectInfo) -> Result<(), ImportError> {
            self.objects.push((id, info.name.clone()));
            Ok(())
        }
        fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
            assert!(t.object < self.objects.len() as u32, "triangle before its object");
            self.tris.push(*t);
            Ok(())
        }
    }

    fn gz(bytes: &[u8]) -> Vec<u8> {
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(bytes).unwrap();
        enc.finish().unwrap()
    }

    fn run(name: &str, bytes: &[u8]) -> Result<(Collect, SourceSummary), ImportError> {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let source = open(Input::open(&p)?, &ImportOptions::default())?;
        let mut sink = Collect::default();
        let summary = source.stream(&mut sink)?;
        Ok((sink, summary))
    }

    fn err(name: &str, bytes: &[u8]) -> ImportError {
        match run(name, bytes) {
            Ok((c, _)) => panic!("expected an error, got {} triangles", c.tris.len()),
            Err(e) => e,
        }
    }

    fn assert_err(e: &ImportError, pos: Position, text: &str) {
        assert_eq!(e.position(), Some(pos), "{e}");
        assert!(e.to_string().contains(text), "{e:?} does not contain {text:?}");
    }

    const T0: [[f32; 3]; 3] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
    const T1: [[f32; 3]; 3] = [[0.5, -2.0, 3.25], [1e6, 2.0, 0.0], [-7.0, 1.0, 0.125]];

    fn f64s(t: [[f32; 3]; 3]) -> [[f64; 3]; 3] {
        t.map(|v| v.map(|c| c as f64))
    }

    /// A binary STL with the given header text, triangles and normals.
    fn binary(header: &[u8], tris: &[([f32; 3], [[f32; 3]; 3])], count: u32) -> Vec<u8> {
        let mut out = vec![b' '; 80];
        out[..header.len()].copy_from_slice(header);
        out.extend_from_slice(&count.to_le_bytes());
        for (n, t) in tris {
            for c in n.iter().chain(t.iter().flatten()) {
                out.extend_from_slice(&c.to_le_bytes());
            }
            out.extend_from_slice(&[0x12, 0x34]);
        }
        out
    }

    fn two() -> Vec<u8> {
        binary(b"exported by CAD", &[([0.0, 0.0, 1.0], T0), ([0.0; 3], T1)], 2)
    }

    const ASCII: &str = "solid pump casing\n  facet normal 0 0 1\n    outer loop\n      vertex 0 0 0\n\
                         vertex 1 0 0\n      vertex 0 1 0\n    endloop\n  endfacet\nendsolid pump casing\n\
                         SOLID Valve\nFACET NORMAL 0 0 0\nOUTER LOOP\nVERTEX 0.5 -2 3.25\nVERTEX 1e6 2.0 0\n\
                         VERTEX -7 1 0.125\nENDLOOP\nENDFACET\nENDSOLID\n";

    #[test]
    fn binary_triangles_normals_and_summary() {
        for zipped in [false, true] {
            let bytes = if zipped { gz(&two()) } else { two() };
            let (c, s) = run("part.stl", &bytes).unwrap();
            assert_eq!(c.objects, vec![(0, "part".to_string())]);
            assert_eq!(c.tris.iter().map(|t| t.positions).collect::<Vec<_>>(), vec![f64s(T0), f64s(T1)]);
            assert_eq!(c.tris[0].normals, Some([[0.0, 0.0, 1.0]; 3]));
            assert_eq!(c.tris[1].normals, None, "a zero facet normal gives no normals");
            assert_eq!(s, SourceSummary { objects: 1, vertices: 6, bytes: bytes.len() as u64 });
        }
    }

    #[test]
    fn binary_with_solid_header_is_binary_by_size_and_by_content() {
        let bytes = binary(b"solid part", &[([0.0; 3], T0), ([0.0; 3], T1)], 2);
        let (c, _) = run("s.stl", &bytes).unwrap();
        assert_eq!(c.tris.len(), 2);
        // Compressed: size unknown, the content decides.
        let (c, _) = run("s.stl.gz", &gz(&bytes)).unwrap();
        assert_eq!(c.tris.len(), 2);
        // Even with a newline in the header, what follows is not "facet".
        let bytes = binary(b"solid part\nmade by X", &[([0.0; 3], T0)], 1);
        let (c, _) = run("s.stl.gz", &gz(&bytes)).unwrap();
        assert_eq!(c.tris.len(), 1);
    }

    #[test]
    fn binary_with_zero_triangles() {
        let (c, s) = run("z.stl", &binary(b"solid empty", &[], 0)).unwrap();
        assert_eq!((c.objects.len(), c.tris.len(), s.objects), (1, 0, 1));
    }

    #[test]
    fn ascii_solids_are_objects() {
        for zipped in [false, true] {
            let bytes = if zipped { gz(ASCII.as_bytes()) } else { ASCII.as_bytes().to_vec() };
            let (c, s) = run("a.stl", &bytes).unwrap();
            assert_eq!(c.objects, vec![(0, "pump casing".to_string()), (1, "Valve".to_string())]);
            assert_eq!(
                c.tris.iter().map(|t| (t.positions, t.object)).collect::<Vec<_>>(),
                vec![(f64s(T0), 0), (f64s(T1), 1)]
            );
            assert_eq!(c.tris[0].normals, Some([[0.0, 0.0, 1.0]; 3]));
            assert_eq!(c.tris[1].normals, None);
            assert_eq!(s.objects, 2);
            assert_eq!(s.vertices, 6);
        }
    }

    #[test]
    fn ascii_crlf_blank_lines_and_empty_solid() {
        let text = "solid\r\n\r\nendsolid\r\nsolid b\r\nfacet normal 0 0 1\r\nouter loop\r\nvertex 0 0 0\r\n\
                    vertex 1 0 0\r\nvertex 0 1 0\r\nendloop\r\nendfacet\r\nendsolid b\r\n\r\n";
        let (c, _) = run("crlf.stl", text.as_bytes()).unwrap();
        assert_eq!(c.objects, vec![(0, String::new()), (1, "b".to_string())]);
        assert_eq!(c.tris.len(), 1);
        assert_eq!(c.tris[0].object, 1);
    }

    #[test]
    fn binary_truncated_plain_and_gzip() {
        let mut bytes = two();
        bytes.truncate(bytes.len() - 7);
        assert_err(&err("t.stl", &bytes), Position::Byte(bytes.len() as u64), "declares 2 triangles");
        assert_err(&err("t.stl", &gz(&bytes)), Position::Byte(bytes.len() as u64), "ends in triangle 1 of 2");
        assert_err(&err("t.stl", &bytes[..50]), Position::Byte(50), "shorter than the 84-byte header");
    }

    #[test]
    fn binary_absurd_count() {
        let bytes = binary(b"x", &[([0.0; 3], T0)], u32::MAX);
        assert_err(
            &err("a.stl", &bytes),
            Position::Byte(bytes.len() as u64),
            "declares 4294967295 triangles",
        );
        assert_err(
            &err("a.stl", &gz(&bytes)),
            Position::Byte(bytes.len() as u64),
            "ends in triangle 1 of 4294967295",
        );
    }

    #[test]
    fn binary_trailing_bytes_are_ignored() {
        let mut bytes = two();
        bytes.extend_from_slice(&[0; 30]);
        let (c, _) = run("t.stl", &bytes).unwrap();
        assert_eq!(c.tris.len(), 2);
    }

    #[test]
    fn binary_nan() {
        let mut t = T1;
        t[2][1] = f32::NAN;
        let bytes = binary(b"x", &[([0.0; 3], T0), ([0.0; 3], t)], 2);
        assert_err(&err("n.stl", &bytes), Position::Byte(134), "triangle 1: non-finite coordinate");
        let bytes = binary(b"x", &[([f32::NAN, 0.0, 1.0], T0)], 1);
        assert_eq!(run("n.stl", &bytes).unwrap().0.tris[0].normals, None, "a NaN normal is dropped");
    }

    #[test]
    fn ascii_truncated() {
        let cut = &ASCII[..ASCII.find("ENDLOOP").unwrap()];
        assert_err(&err("t.stl", cut.as_bytes()), Position::Line(16), "truncated: it ends where \"endloop\"");
        let cut = &ASCII[..ASCII.find("ENDSOLID").unwrap()];
        assert_err(&err("t.stl", cut.as_bytes()), Position::Line(18), "\"facet\" or \"endsolid\"");
        assert_err(&err("t.stl", b"solid lonely"), Position::Line(2), "truncated");
    }

    #[test]
    fn ascii_bad_number_and_nan() {
        let text = ASCII.replace("vertex 1 0 0", "vertex 1 0x 0");
        assert_err(&err("b.stl", text.as_bytes()), Position::Line(5), "invalid number \"0x\" in the vertex");
        let text = ASCII.replace("vertex 1 0 0", "vertex 1 nan 0");
        assert_err(&err("b.stl", text.as_bytes()), Position::Line(5), "non-finite");
        let text = ASCII.replace("vertex 1 0 0", "vertex 1 -inf 0");
        assert_err(&err("b.stl", text.as_bytes()), Position::Line(5), "non-finite");
        let text = ASCII.replace("facet normal 0 0 1", "facet normal 0 zero 1");
        assert_err(
            &err("b.stl", text.as_bytes()),
            Position::Line(2),
            "invalid number \"zero\" in the facet normal",
        );
    }

    #[test]
    fn ascii_vertex_with_two_or_four_coordinates() {
        let text = ASCII.replace("vertex 1 0 0", "vertex 1 0");
        assert_err(&err("v.stl", text.as_bytes()), Position::Line(5), "needs 3 coordinates, found 2");
        let text = ASCII.replace("vertex 1 0 0", "vertex 1 0 0 1");
        assert_err(&err("v.stl", text.as_bytes()), Position::Line(5), "more than 3 coordinates");
    }

    #[test]
    fn ascii_facet_with_four_or_two_vertices() {
        let text = ASCII.replace("vertex 0 1 0\n", "vertex 0 1 0\nvertex 1 1 0\n");
        assert_err(&err("f.stl", text.as_bytes()), Position::Line(7), "more than 3 vertices");
        let text = ASCII.replace("vertex 0 1 0\n", "");
        assert_err(&err("f.stl", text.as_bytes()), Position::Line(6), "a facet with 2 vertices");
    }

    #[test]
    fn ascii_grammar_errors() {
        let text = ASCII.replace("endfacet\nendsolid pump", "endfacet\nendfacet\nendsolid pump");
        assert_err(&err("g.stl", text.as_bytes()), Position::Line(9), "expected \"facet\" or \"endsolid\"");
        let text = ASCII.replace("outer loop", "outer space");
        assert_err(&err("g.stl", text.as_bytes()), Position::Line(3), "expected \"outer loop\"");
        let text = ASCII.replace("endloop", "endloop now");
        assert_err(&err("g.stl", text.as_bytes()), Position::Line(7), "unexpected \"now\"");
        let text = ASCII.to_string() + "garbage\n";
        assert_err(
            &err("g.stl", text.as_bytes()),
            Position::Line(19),
            "expected \"solid\", found \"garbage\"",
        );
    }

    #[test]
    fn empty_file() {
        assert_err(&err("e.stl", b""), Position::File, "empty file");
        assert_err(&err("e.stl.gz", &gz(b"")), Position::File, "empty file");
    }

    #[test]
    fn garbage() {
        // Binary STL has no magic: short garbage is too short, long garbage has a wrong count.
        assert_err(&err("g.stl", b"\x07\x00garbage"), Position::Byte(9), "shorter than the 84-byte header");
        let text = "v 1 2 3\n".repeat(20);
        let e = err("g.stl", text.as_bytes());
        assert_err(&e, Position::Byte(text.len() as u64), "text but does not start with \"solid\"");
        let noise: Vec<u8> = (0..1000u32).map(|i| (i.wrapping_mul(2654435761) >> 13) as u8).collect();
        assert!(run("g.stl", &noise).is_err());
    }

    #[test]
    fn detection_rules() {
        let facet = b"solid x\n facet normal 0 0 1\n";
        assert!(is_ascii(facet, None));
        assert!(is_ascii(b"  solid\nendsolid\n", None));
        assert!(!is_ascii(b"solidity\nfacet", None));
        assert!(!is_ascii(b"\x00\x01solid", None));
        let mut bin = binary(b"solid x\n facet", &[([0.0; 3], T0)], 1);
        assert!(!is_ascii(&bin, Some(bin.len() as u64)), "size decides when known");
        bin.truncate(100);
        assert!(is_ascii(&bin, None), "content only: looks like ASCII");
    }
}
