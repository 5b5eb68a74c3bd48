//! The GLB container (glTF 2.0 specification, section 4.4 "Binary glTF Layout"): a 12-byte header
//! (`glTF`, version 2, total length), a JSON chunk, and an optional BIN chunk, all little-endian.
//!
//! The header and the JSON chunk are read sequentially from the [`Input`](crate::input::Input)
//! when the file is opened. The BIN chunk is never read whole: accessors read their ranges with
//! positioned reads from a [`RandomFile`], which is the GLB itself for a plain file on disk, or a
//! temporary copy of the decompressed stream for a gzip'ed (or in-memory) input.

use std::fs::File;
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};

use crate::error::{ImportError, Position};
use crate::input::read_up_to;

const MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;
/// Bytes of the GLB header plus the JSON chunk header: where the JSON text starts.
pub(super) const JSON_START: u64 = 20;

/// What [`read_head`] found: the JSON text and where the next chunk would start.
pub(super) struct GlbHead {
    /// The total length the header declares.
    pub total_len: u64,
    /// The JSON chunk's content (with its padding).
    pub json: Vec<u8>,
    /// Offset of the first byte after the JSON chunk: the BIN chunk header, if any.
    pub json_end: u64,
    /// The first 20 bytes (header and JSON chunk header), to recognise the file on disk.
    pub header: Vec<u8>,
}

fn le32(b: &[u8]) -> u32 {
    u32::from_le_bytes([b[0], b[1], b[2], b[3]])
}

/// Reads the GLB header and the JSON chunk from the start of `reader`. `file_len` is the size of
/// the content when it is known (a plain file), to reject a truncated file before streaming.
pub(super) fn read_head(
    reader: &mut impl Read,
    path: &Path,
    file_len: Option<u64>,
) -> Result<GlbHead, ImportError> {
    let io_err = |at: u64| move |e: io::Error| ImportError::io(path, Position::Byte(at), e);
    let mut head = [0u8; 20];
    let got = read_up_to(reader, &mut head[..12]).map_err(io_err(0))?;
    if got < 12 {
        return Err(ImportError::parse(
            path,
            Position::Byte(got as u64),
            format!("truncated GLB header: the file ends after {got} of 12 bytes"),
        ));
    }
    if &head[..4] != MAGIC {
        return Err(ImportError::parse(path, Position::Byte(0), "not a GLB file: the magic is not \"glTF\""));
    }
    let version = le32(&head[4..8]);
    if version == 1 {
        return Err(ImportError::unsupported(path, "GLB version 1 (glTF 1.0); only glTF 2.0 is read"));
    }
    if version != 2 {
        return Err(ImportError::parse(path, Position::Byte(4), format!("unknown GLB version {version}")));
    }
    let total_len = le32(&head[8..12]) as u64;
    if total_len < JSON_START {
        return Err(ImportError::parse(
            path,
            Position::Byte(8),
            format!("GLB length {total_len} is too short for the header and a JSON chunk"),
        ));
    }
    if let Some(len) = file_len {
        if total_len > len {
            return Err(ImportError::parse(
                path,
                Position::Byte(len),
                format!("truncated GLB: the header declares {total_len} bytes but the file has {len}"),
            ));
        }
    }
    let got = read_up_to(reader, &mut head[12..20]).map_err(io_err(12))?;
    if got < 8 {
        return Err(ImportError::parse(
            path,
            Position::Byte(12 + got as u64),
            "truncated GLB: the file ends inside the JSON chunk header",
        ));
    }
    let json_len = le32(&head[12..16]) as u64;
    let kind = le32(&head[16..20]);
    if kind != CHUNK_JSON {
        return Err(ImportError::parse(
            path,
            Position::Byte(16),
            format!("the first GLB chunk must be JSON (type 0x4E4F534A), found type 0x{kind:08X}"),
        ));
    }
    if json_len > total_len - JSON_START {
        return Err(ImportError::parse(
            path,
            Position::Byte(12),
            format!("JSON chunk length {json_len} runs past the declared GLB length {total_len}"),
        ));
    }
    // Grows with the data actually read, so a lying length cannot force a large allocation.
    let mut json = Vec::new();
    reader.take(json_len).read_to_end(&mut json).map_err(io_err(JSON_START))?;
    if (json.len() as u64) < json_len {
        return Err(ImportError::parse(
            path,
            Position::Byte(JSON_START + json.len() as u64),
            format!("truncated GLB: the file ends inside the JSON chunk of {json_len} bytes"),
        ));
    }
    Ok(GlbHead { total_len, json, json_end: JSON_START + json_len, header: head.to_vec() })
}

/// A file read with positioned reads. Its byte 0 is byte `base` of the logical (decompressed)
/// input, so that error positions name offsets in the file the user has.
pub(super) struct RandomFile {
    file: File,
    base: u64,
    /// Logical offset one past the last byte.
    end: u64,
    /// Path for messages.
    path: PathBuf,
}

impl RandomFile {
    /// Opens `path` for positioned reads, logical offset 0 at file offset 0. Only a regular
    /// file: a FIFO would block the open and cannot be read at offsets, a device has no length.
    pub fn open(path: &Path, message_path: &Path) -> Result<RandomFile, ImportError> {
        let io_err = |e| ImportError::io(message_path, Position::File, e);
        let (file, meta) = tw_core::regular_file::open_regular(path).map_err(io_err)?;
        let end = meta.len();
        Ok(RandomFile { file, base: 0, end, path: message_path.to_path_buf() })
    }

    /// Copies at most `limit` bytes of `reader` into an anonymous temporary file in `dir` (the
    /// system temp dir when `None`); the copy starts at logical offset `base`. `progress` is
    /// called after every megabyte.
    pub fn spill(
        reader: &mut impl Read,
        limit: u64,
        base: u64,
        dir: Option<&Path>,
        message_path: &Path,
        progress: &mut dyn FnMut(),
    ) -> Result<RandomFile, ImportError> {
        let tmp_err = |e| ImportError::io(message_path, Position::Byte(base), e);
        let file = match dir {
            Some(d) => tempfile::tempfile_in(d),
            None => tempfile::tempfile(),
        }
        .map_err(tmp_err)?;
        let mut out = io::BufWriter::with_capacity(1 << 20, file);
        let mut buf = vec![0u8; 1 << 20];
        let mut copied = 0u64;
        let mut reader = reader.take(limit);
        loop {
            let n = match reader.read(&mut buf) {
                Ok(0) => break,
                Ok(n) => n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                Err(e) => return Err(ImportError::io(message_path, Position::Byte(base + copied), e)),
            };
            out.write_all(&buf[..n]).map_err(tmp_err)?;
            copied += n as u64;
            progress();
        }
        let file = out.into_inner().map_err(|e| tmp_err(e.into_error()))?;
        Ok(RandomFile { file, base, end: base + copied, path: message_path.to_path_buf() })
    }

    /// Logical offset one past the last byte.
    pub fn end(&self) -> u64 {
        self.end
    }

    /// Reads `len` bytes at logical offset `at`; the caller has checked that they lie in the file.
    pub fn read_at(&self, at: u64, len: usize) -> Result<Vec<u8>, ImportError> {
        if at < self.base || at.saturating_add(len as u64) > self.end {
            return Err(ImportError::parse(
                &self.path,
                Position::Byte(at.min(self.end)),
                format!("{len} bytes at byte {at} lie outside the file (it ends at byte {})", self.end),
            ));
        }
        let mut buf = vec![0u8; len];
        tw_core::direct_io::read_exact_at(&self.file, &mut buf, at - self.base)
            .map_err(|e| ImportError::io(&self.path, Position::Byte(at), e))?;
        Ok(buf)
    }
}

/// Where the BIN chunk's content lies: logical offset and length.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct BinChunk {
    pub offset: u64,
    pub len: u64,
}

/// Finds the BIN chunk after the JSON chunk, if the file has one. `file` must cover the logical
/// range from `head.json_end` on.
pub(super) fn find_bin(
    file: &RandomFile,
    total_len: u64,
    json_end: u64,
    path: &Path,
) -> Result<Option<BinChunk>, ImportError> {
    if json_end >= total_len {
        return Ok(None);
    }
    if file.end() < total_len {
        return Err(ImportError::parse(
            path,
            Position::Byte(file.end()),
            format!(
                "truncated GLB: the header declares {total_len} bytes but the content ends at byte {}",
                file.end()
            ),
        ));
    }
    if total_len - json_end < 8 {
        return Err(ImportError::parse(
            path,
            Position::Byte(json_end),
            format!(
                "{} stray bytes after the JSON chunk: too short for a chunk header",
                total_len - json_end
            ),
        ));
    }
    let h = file.read_at(json_end, 8)?;
    let len = le32(&h[0..4]) as u64;
    let kind = le32(&h[4..8]);
    if kind != CHUNK_BIN {
        // The BIN chunk, when present, must be the second; later chunks are extensions' to read.
        return Ok(None);
    }
    let offset = json_end + 8;
    if len > total_len - offset {
        return Err(ImportError::parse(
            path,
            Position::Byte(json_end),
            format!("BIN chunk length {len} runs past the declared GLB length {total_len}"),
        ));
    }
    Ok(Some(BinChunk { offset, len }))
}
