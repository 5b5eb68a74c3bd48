//! MTL material libraries, as far as terawalk needs them: the diffuse colour `Kd` and the
//! dissolve `d` of each `newmtl`, which become an object's [`crate::ObjectInfo::color`].
//!
//! Follows the MTL part of the Wavefront OBJ specification (Appendix B1, "Material Library File
//! (.mtl)"). A material library only decorates the geometry, so nothing in it is fatal: a missing
//! file, an unreadable one or a malformed statement is a `tracing::warn` naming the file and line,
//! and the statement is ignored. Everything else (textures, specular terms, illumination models)
//! is skipped silently.

use std::collections::HashMap;
use std::fs::File;
use std::io::{self, BufRead, BufReader, Read};
use std::path::Path;

use tw_core::Rgba8;

use super::{is_space, parse_f64, tokens, trim};

/// Material libraries larger than this are not read: real ones are kilobytes, and a bigger file is
/// almost certainly not a material library.
const MAX_MTL_BYTES: u64 = 64 << 20;

/// Material name → its colour (`None` when the material has no usable `Kd`).
pub(crate) type Materials = HashMap<Vec<u8>, Option<Rgba8>>;

/// One material while its statements are read.
struct Pending {
    name: Vec<u8>,
    kd: Option<[f32; 3]>,
    dissolve: f32,
}

impl Pending {
    fn finish(self, into: &mut Materials) {
        let color = self.kd.map(|[r, g, b]| Rgba8::from_f32([r, g, b, self.dissolve]));
        into.insert(self.name, color);
    }
}

/// Reads the material library at `path` into `into` (later definitions of a name win).
/// Returns an error only when the file cannot be opened or read; the caller warns about it.
pub(crate) fn load(path: &Path, into: &mut Materials) -> io::Result<()> {
    let file = File::open(path)?;
    let len = file.metadata()?.len();
    if len > MAX_MTL_BYTES {
        return Err(io::Error::other(format!(
            "{len} bytes is too large for a material library (the limit is {MAX_MTL_BYTES})"
        )));
    }
    read(BufReader::new(file.take(MAX_MTL_BYTES)), path, into)
}

/// Parses material library text from `reader`; `path` is only used in warnings.
pub(crate) fn read(mut reader: impl BufRead, path: &Path, into: &mut Materials) -> io::Result<()> {
    let mut line = Vec::new();
    let mut line_no = 0u64;
    let mut current: Option<Pending> = None;
    let warn = |line_no: u64, msg: &str| {
        tracing::warn!("{}: line {line_no}: {msg}; statement ignored", path.display());
    };
    loop {
        line.clear();
        if reader.read_until(b'\n', &mut line)? == 0 {
            break;
        }
        line_no += 1;
        let text = trim(line.strip_suffix(b"\n").unwrap_or(&line));
        let (keyword, rest) = match text.iter().position(|&b| is_space(b)) {
            Some(i) => (&text[..i], trim(&text[i..])),
            None => (text, &text[text.len()..]),
        };
        match keyword {
            b"newmtl" => {
                if let Some(done) = current.take() {
                    done.finish(into);
                }
                if rest.is_empty() {
                    warn(line_no, "newmtl without a name");
                } else {
                    current = Some(Pending { name: rest.to_vec(), kd: None, dissolve: 1.0 });
                }
            }
            b"Kd" => {
                let Some(m) = current.as_mut() else {
                    warn(line_no, "Kd before any newmtl");
                    continue;
                };
                if rest.starts_with(b"spectral") || rest.starts_with(b"xyz") {
                    warn(line_no, "only RGB diffuse colours are supported");
                    continue;
                }
                match numbers::<3>(rest) {
                    Some((1, [r, ..])) => m.kd = Some([r; 3]),
                    Some((3, rgb)) => m.kd = Some(rgb),
                    _ => warn(line_no, "Kd needs one or three numbers"),
                }
            }
            b"d" => {
                let Some(m) = current.as_mut() else {
                    warn(line_no, "d before any newmtl");
                    continue;
                };
                let value = rest.strip_prefix(b"-halo").map(trim).unwrap_or(rest);
                match numbers::<1>(value) {
                    Some((1, [d])) => m.dissolve = d,
                    _ => warn(line_no, "d needs one number"),
                }
            }
            _ => {}
        }
    }
    if let Some(done) = current.take() {
        done.finish(into);
    }
    Ok(())
}

/// Up to `N` finite numbers from `text`, and how many there were; `None` when a token is not a
/// finite number or there are more than `N`.
fn numbers<const N: usize>(text: &[u8]) -> Option<(usize, [f32; N])> {
    let mut out = [0.0f32; N];
    let mut n = 0;
    for token in tokens(text) {
        let v = parse_f64(token).filter(|v| v.is_finite())?;
        *out.get_mut(n)? = v as f32;
        n += 1;
    }
    Some((n, out))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Materials {
        let mut m = Materials::new();
        read(text.as_bytes(), Path::new("t.mtl"), &mut m).unwrap();
        m
    }

    #[test]
    fn diffuse_colour_and_dissolve() {
        let m = parse("newmtl red\nKa 0 0 0\nKd 1 0 0\n\nnewmtl glass\r\nKd 0.5\r\nd 0.5\r\n");
        assert_eq!(m[&b"red".to_vec()], Some(Rgba8([255, 0, 0, 255])));
        assert_eq!(m[&b"glass".to_vec()], Some(Rgba8([128, 128, 128, 128])));
    }

    #[test]
    fn material_without_kd_has_no_colour() {
        let m = parse("newmtl plain\nNs 10\n");
        assert_eq!(m[&b"plain".to_vec()], None);
    }

    #[test]
    fn names_with_spaces_and_tabs() {
        let m = parse("newmtl\tmy metal \nKd 0 1 0\n");
        assert_eq!(m[&b"my metal".to_vec()], Some(Rgba8([0, 255, 0, 255])));
    }

    #[test]
    fn malformed_statements_are_ignored() {
        let m = parse("Kd 1 1 1\nnewmtl a\nKd 1 x 1\nKd nan 0 0\nKd 1 2\nKd spectral f.rfl\nd\nnewmtl\n");
        assert_eq!(m.len(), 1);
        assert_eq!(m[&b"a".to_vec()], None);
    }

    #[test]
    fn halo_dissolve() {
        let m = parse("newmtl a\nKd 0 0 1\nd -halo 0\n");
        assert_eq!(m[&b"a".to_vec()], Some(Rgba8([0, 0, 255, 0])));
    }

    #[test]
    fn missing_file_is_an_io_error() {
        let mut m = Materials::new();
        assert!(load(Path::new("/nonexistent/x.mtl"), &mut m).is_err());
    }
}
