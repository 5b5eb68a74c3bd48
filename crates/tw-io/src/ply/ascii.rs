//! ASCII bodies: one record per non-blank line, its values read token by token.

use super::faces::Faces;
use super::header::{Element, FaceLayout, PropKind, Property, VertexLayout};
use super::reader::{parse_f64, parse_i64, show, ByteReader, Line, Tokens};
use super::vertices::{VertexValues, Vertices};
use super::{Body, RecordError, MAX_LIST, MAX_SKIPPED_LIST};
use crate::error::{ImportError, Position};
use crate::TriangleSink;

/// Longest line of an ASCII body (a face of [`MAX_LIST`] indices fits easily).
const MAX_ASCII_LINE: usize = 4 << 20;

impl Body<'_> {
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

    /// Reads the vertex element into `out`, one record per line.
    pub(super) fn ascii_vertices(
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

    /// Reads the face element and streams its triangles, one record per line.
    pub(super) fn ascii_faces(
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

    /// Reads past an element we do not use, still checking that each line holds its values.
    pub(super) fn ascii_skip(
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
    use crate::error::Position;

    use super::super::test_util::*;

    #[test]
    fn crlf_header_and_blank_body_lines() {
        let text =
            String::from_utf8(square("ascii")).unwrap().replace('\n', "\r\n").replace("4 0 1", "\r\n4 0 1");
        let (c, _) = run("crlf.ply", text.as_bytes()).unwrap();
        assert_eq!(positions(&c), square_triangles());
    }

    #[test]
    fn truncated_ascii_body() {
        let text = String::from_utf8(square("ascii")).unwrap();
        let cut = &text[..text.len() - "3 3 2 1\n".len()];
        assert_err(&err("t.ply", cut.as_bytes()), Position::Line(17), "ends before face 1 of 2");
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
}
