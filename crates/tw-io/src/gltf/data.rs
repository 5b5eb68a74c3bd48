//! Binary data behind a glTF document (glTF 2.0 specification, sections 3.6 "Binary Data Storage"
//! and 5.1 "Accessor"): buffers (the GLB BIN chunk, external files, base64 data URIs), buffer
//! views (with `EXT_meshopt_compression`), and accessors (with `byteStride`, sparse substitution
//! and normalized integer components, as `KHR_mesh_quantization` allows).
//!
//! Nothing is loaded whole: an accessor reads the byte range it covers, with a positioned read
//! from a file or by decoding only the base64 groups it needs. Every range is checked against the
//! declared lengths, and those against the real size of the data, before anything is allocated.
//! The one exception is a meshopt-compressed buffer view, which must be decoded as a whole; its
//! decoded size is checked against what the codec can produce from its compressed size, and
//! decoded views are cached under a memory budget.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

use ::gltf::json;
use json::accessor::{ComponentType, Type};
use json::validation::Checked;

use super::container::{BinChunk, RandomFile};
use crate::error::{ImportError, Position};

/// An accessor's elements, tightly packed, sparse values applied.
pub(super) struct RawAccessor {
    pub bytes: Vec<u8>,
    pub count: usize,
    pub components: usize,
    pub component_type: ComponentType,
    pub normalized: bool,
}

impl RawAccessor {
    /// The components as floats: normalized integers mapped to [0, 1] or [-1, 1] (glTF 2.0,
    /// section 3.11 "Animations", the normalization equations), other integers as their values.
    pub fn to_f32(&self) -> Vec<f32> {
        let b = &self.bytes;
        let n = self.normalized;
        match self.component_type {
            ComponentType::F32 => {
                b.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
            }
            ComponentType::I8 => b
                .iter()
                .map(|&c| if n { (c as i8 as f32 / 127.0).max(-1.0) } else { c as i8 as f32 })
                .collect(),
            ComponentType::U8 => b.iter().map(|&c| if n { c as f32 / 255.0 } else { c as f32 }).collect(),
            ComponentType::I16 => b
                .chunks_exact(2)
                .map(|c| {
                    let v = i16::from_le_bytes([c[0], c[1]]) as f32;
                    if n {
                        (v / 32767.0).max(-1.0)
                    } else {
                        v
                    }
                })
                .collect(),
            ComponentType::U16 => b
                .chunks_exact(2)
                .map(|c| {
                    let v = u16::from_le_bytes([c[0], c[1]]) as f32;
                    if n {
                        v / 65535.0
                    } else {
                        v
                    }
                })
                .collect(),
            ComponentType::U32 => b
                .chunks_exact(4)
                .map(|c| {
                    let v = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                    if n {
                        (v as f64 / u32::MAX as f64) as f32
                    } else {
                        v as f32
                    }
                })
                .collect(),
        }
    }

    /// Unsigned integer components as u32 (indices); `None` for signed or float components.
    pub fn to_u32(&self) -> Option<Vec<u32>> {
        let b = &self.bytes;
        Some(match self.component_type {
            ComponentType::U8 => b.iter().map(|&c| c as u32).collect(),
            ComponentType::U16 => {
                b.chunks_exact(2).map(|c| u16::from_le_bytes([c[0], c[1]]) as u32).collect()
            }
            ComponentType::U32 => {
                b.chunks_exact(4).map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
            }
            _ => return None,
        })
    }
}

/// Where a buffer's bytes are.
enum BufferData {
    /// In the GLB BIN chunk.
    Bin(BinChunk),
    /// An external file, opened on first use.
    External { path: PathBuf, file: Option<RandomFile> },
    /// A base64 data URI's payload (its decoded size was checked against byteLength).
    DataUri { payload: String },
    /// No data: the message says why, for the error raised when an accessor needs it.
    Missing(String),
}

/// Reads accessors of one document.
pub(super) struct Store {
    path: PathBuf,
    bin_file: Option<Rc<RandomFile>>,
    buffers: Vec<BufferData>,
    /// Decoded meshopt buffer views, by view index, and their total size.
    decoded: HashMap<usize, Rc<Vec<u8>>>,
    decoded_bytes: usize,
    decoded_budget: usize,
    /// Cap on an accessor without a buffer view (all zeros plus sparse values), in bytes.
    zero_cap: u64,
    /// Whether reads from `bin_file` are reads of the user's file (not of a temporary copy).
    count_bin: bool,
    /// Bytes read from the user's files so far.
    pub bytes_read: u64,
}

fn json_err(path: &Path, message: String) -> ImportError {
    ImportError::parse(path, Position::File, message)
}

impl Store {
    /// Takes the buffers' URIs out of `root` (data URIs can be large; they move, not copy).
    /// `dir` resolves relative URIs; `bin` is the GLB BIN chunk and the file it is in.
    pub fn new(
        root: &mut json::Root,
        path: &Path,
        dir: &Path,
        bin: Option<(Rc<RandomFile>, Option<BinChunk>, bool)>,
        memory_budget: usize,
        source_len: u64,
    ) -> Result<Store, ImportError> {
        let (bin_file, bin_chunk, count_bin) = match bin {
            Some((f, c, count)) => (Some(f), c, count),
            None => (None, None, false),
        };
        let mut buffers = Vec::with_capacity(root.buffers.len());
        for (i, b) in root.buffers.iter_mut().enumerate() {
            let declared = b.byte_length.0;
            let data = match b.uri.take() {
                None if i == 0 && bin_chunk.is_some() => {
                    let chunk = bin_chunk.unwrap_or(BinChunk { offset: 0, len: 0 });
                    if chunk.len < declared {
                        return Err(ImportError::parse(
                            path,
                            Position::Byte(chunk.offset.saturating_sub(8)),
                            format!(
                                "the BIN chunk has {} bytes but buffers[0].byteLength is {declared}",
                                chunk.len
                            ),
                        ));
                    }
                    BufferData::Bin(chunk)
                }
                None if is_meshopt_fallback(b) => BufferData::Missing(format!(
                    "buffers[{i}] is an EXT_meshopt_compression fallback buffer without data"
                )),
                None if bin_file.is_some() => BufferData::Missing(format!(
                    "buffers[{i}] has no uri and {}",
                    if i == 0 { "the GLB has no BIN chunk" } else { "only buffers[0] can be the BIN chunk" }
                )),
                None => BufferData::Missing(format!("buffers[{i}] has no uri")),
                Some(uri) if uri.starts_with("data:") => {
                    let (payload, len) = parse_data_uri(uri)
                        .map_err(|m| json_err(path, format!("buffers[{i}]: bad data URI: {m}")))?;
                    if len < declared {
                        return Err(json_err(
                            path,
                            format!(
                                "buffers[{i}]: the data URI holds {len} bytes but byteLength is {declared}"
                            ),
                        ));
                    }
                    BufferData::DataUri { payload }
                }
                Some(uri) => {
                    if let Some(scheme) = uri_scheme(&uri) {
                        return Err(ImportError::unsupported(
                            path,
                            format!(
                                "buffers[{i}]: uri \"{uri}\": URI scheme \"{scheme}:\" (only relative file \
                                 names inside the glTF file's folder and data URIs are read)"
                            ),
                        ));
                    }
                    let rel = percent_decode(&uri).ok_or_else(|| {
                        json_err(path, format!("buffers[{i}]: bad percent-encoding in uri \"{uri}\""))
                    })?;
                    if let Err(why) = check_inside_folder(&rel) {
                        return Err(json_err(
                            path,
                            format!(
                                "buffers[{i}]: uri \"{uri}\" {why}: only relative file names inside the glTF \
                                 file's folder (and data URIs) are read"
                            ),
                        ));
                    }
                    BufferData::External { path: dir.join(rel), file: None }
                }
            };
            buffers.push(data);
        }
        Ok(Store {
            path: path.to_path_buf(),
            bin_file,
            buffers,
            decoded: HashMap::new(),
            decoded_bytes: 0,
            decoded_budget: memory_budget,
            zero_cap: (1u64 << 26).max(source_len.saturating_mul(16)),
            count_bin,
            bytes_read: 0,
        })
    }

    fn err(&self, message: String) -> ImportError {
        json_err(&self.path, message)
    }

    /// Reads `len` bytes at `offset` of buffer `index`; `offset + len` must be within the
    /// buffer's declared byteLength, which [`Store::new`] or the first opening checked against
    /// the real data.
    fn read_buffer(
        &mut self,
        root: &json::Root,
        index: usize,
        offset: u64,
        len: usize,
        what: &str,
    ) -> Result<Vec<u8>, ImportError> {
        let declared = match root.buffers.get(index) {
            Some(b) => b.byte_length.0,
            None => return Err(self.err(format!("{what}: buffers[{index}] does not exist"))),
        };
        let end = offset.checked_add(len as u64);
        if end.is_none_or(|e| e > declared) {
            return Err(self.err(format!(
                "{what}: bytes {offset}..{} lie outside buffers[{index}] (byteLength {declared})",
                offset as u128 + len as u128
            )));
        }
        let path = self.path.clone();
        match self.buffers.get_mut(index) {
            Some(BufferData::Bin(chunk)) => {
                let at = chunk.offset + offset;
                let file = self.bin_file.as_ref().ok_or_else(|| json_err(&path, "no GLB file".into()))?;
                if self.count_bin {
                    self.bytes_read += len as u64;
                }
                file.read_at(at, len)
            }
            Some(BufferData::External { path: file_path, file }) => {
                if file.is_none() {
                    let f = RandomFile::open(file_path, file_path).map_err(|e| {
                        let why = match e {
                            ImportError::Io { source, .. } => source.to_string(),
                            other => other.to_string(),
                        };
                        json_err(
                            &path,
                            format!("buffers[{index}]: cannot read \"{}\": {why}", file_path.display()),
                        )
                    })?;
                    if f.end() < declared {
                        return Err(json_err(
                            &path,
                            format!(
                                "buffers[{index}]: \"{}\" has {} bytes but byteLength is {declared}",
                                file_path.display(),
                                f.end()
                            ),
                        ));
                    }
                    *file = Some(f);
                }
                self.bytes_read += len as u64;
                match file {
                    Some(f) => f.read_at(offset, len),
                    None => Err(json_err(&path, format!("buffers[{index}] is not open"))),
                }
            }
            Some(BufferData::DataUri { payload }) => decode_base64_range(payload.as_bytes(), offset, len)
                .map_err(|m| json_err(&path, format!("buffers[{index}]: bad data URI: {m}"))),
            Some(BufferData::Missing(why)) => Err(json_err(&path, format!("{what}: {why}"))),
            None => Err(json_err(&path, format!("{what}: buffers[{index}] does not exist"))),
        }
    }

    /// The usable length of buffer view `index` (its decoded length for meshopt).
    fn view_len(&mut self, root: &json::Root, index: usize, what: &str) -> Result<u64, ImportError> {
        let view = root
            .buffer_views
            .get(index)
            .ok_or_else(|| self.err(format!("{what}: bufferViews[{index}] does not exist")))?;
        match meshopt_ext(view, index).map_err(|m| self.err(m))? {
            Some(ext) => {
                ext.check_plausible().map_err(|m| {
                    self.err(format!("bufferViews[{index}].extensions.EXT_meshopt_compression: {m}"))
                })?;
                Ok(ext.count * ext.stride)
            }
            None => Ok(view.byte_length.0),
        }
    }

    /// Reads `len` bytes at `offset` in buffer view `index`.
    fn read_view(
        &mut self,
        root: &json::Root,
        index: usize,
        offset: u64,
        len: usize,
        what: &str,
    ) -> Result<Vec<u8>, ImportError> {
        let view = root
            .buffer_views
            .get(index)
            .ok_or_else(|| self.err(format!("{what}: bufferViews[{index}] does not exist")))?;
        if let Some(ext) = meshopt_ext(view, index).map_err(|m| self.err(m))? {
            let data = self.decoded_view(root, index, &ext)?;
            let end = offset.checked_add(len as u64).filter(|&e| e <= data.len() as u64);
            return match end {
                Some(e) => Ok(data[offset as usize..e as usize].to_vec()),
                None => Err(self.err(format!(
                    "{what}: bytes {offset}..{} lie outside bufferViews[{index}] (decoded length {})",
                    offset as u128 + len as u128,
                    data.len()
                ))),
            };
        }
        let vlen = view.byte_length.0;
        if offset.checked_add(len as u64).is_none_or(|e| e > vlen) {
            return Err(self.err(format!(
                "{what}: bytes {offset}..{} lie outside bufferViews[{index}] (byteLength {vlen})",
                offset as u128 + len as u128
            )));
        }
        let voff = view.byte_offset.map_or(0, |o| o.0);
        let buffer = view.buffer.value();
        let declared = root.buffers.get(buffer).map_or(0, |b| b.byte_length.0);
        if voff.checked_add(vlen).is_none_or(|e| e > declared) {
            return Err(self.err(format!(
                "bufferViews[{index}]: bytes {voff}..{} lie outside buffers[{buffer}] (byteLength {declared})",
                voff as u128 + vlen as u128
            )));
        }
        self.read_buffer(root, buffer, voff + offset, len, &format!("bufferViews[{index}]"))
    }

    /// Decodes a whole `EXT_meshopt_compression` buffer view, or takes it from the cache.
    fn decoded_view(
        &mut self,
        root: &json::Root,
        index: usize,
        ext: &MeshoptView,
    ) -> Result<Rc<Vec<u8>>, ImportError> {
        if let Some(d) = self.decoded.get(&index) {
            return Ok(d.clone());
        }
        let what = format!("bufferViews[{index}].extensions.EXT_meshopt_compression");
        let compressed_len = usize::try_from(ext.byte_length)
            .map_err(|_| self.err(format!("{what}: byteLength {} is too large", ext.byte_length)))?;
        ext.check_plausible().map_err(|m| self.err(format!("{what}: {m}")))?;
        let compressed = self.read_buffer(root, ext.buffer, ext.byte_offset, compressed_len, &what)?;
        let decoded = ext.decode(&compressed).map_err(|m| self.err(format!("{what}: {m}")))?;
        let decoded = Rc::new(decoded);
        if self.decoded_bytes + decoded.len() > self.decoded_budget {
            self.decoded.clear();
            self.decoded_bytes = 0;
        }
        self.decoded_bytes += decoded.len();
        self.decoded.insert(index, decoded.clone());
        Ok(decoded)
    }

    /// Reads accessor `index`: checks its type against `types`, reads the range it covers,
    /// drops the stride, applies sparse values.
    pub fn read_accessor(
        &mut self,
        root: &json::Root,
        index: usize,
        types: &[Type],
        what: &str,
    ) -> Result<RawAccessor, ImportError> {
        let name = format!("accessors[{index}] ({what})");
        let acc = root
            .accessors
            .get(index)
            .ok_or_else(|| self.err(format!("{what}: accessors[{index}] does not exist")))?;
        let component_type = match acc.component_type {
            Checked::Valid(t) => t.0,
            Checked::Invalid => return Err(self.err(format!("{name}: invalid componentType"))),
        };
        let ty = match acc.type_ {
            Checked::Valid(t) => t,
            Checked::Invalid => return Err(self.err(format!("{name}: invalid type"))),
        };
        if !types.contains(&ty) {
            return Err(self.err(format!("{name}: type {ty:?} where {types:?} is expected")));
        }
        let components = ty.multiplicity();
        let elem = components * component_type.size();
        let count = acc.count.0;
        let packed = count
            .checked_mul(elem as u64)
            .ok_or_else(|| self.err(format!("{name}: count {count} is too large")))?;
        let mut bytes = match acc.buffer_view {
            Some(v) => {
                let v = v.value();
                let view_len = self.view_len(root, v, &name)?;
                let stride =
                    root.buffer_views.get(v).and_then(|w| w.byte_stride).map_or(elem as u64, |s| s.0 as u64);
                if stride < elem as u64 {
                    return Err(self.err(format!(
                        "{name}: bufferViews[{v}].byteStride {stride} is smaller than an element ({elem} bytes)"
                    )));
                }
                let offset = acc.byte_offset.map_or(0, |o| o.0);
                let span = match count {
                    0 => Some(0),
                    c => (c - 1).checked_mul(stride).and_then(|s| s.checked_add(elem as u64)),
                };
                let end = span.and_then(|s| s.checked_add(offset));
                let (Some(span), Some(end)) = (span, end) else {
                    return Err(self.err(format!("{name}: count {count} is too large")));
                };
                if end > view_len {
                    return Err(self.err(format!(
                        "{name}: {count} elements of {elem} bytes, stride {stride}, at byteOffset {offset} need \
                         {end} bytes but bufferViews[{v}] has {view_len}"
                    )));
                }
                let mut raw = self.read_view(root, v, offset, span as usize, &name)?;
                if stride != elem as u64 {
                    let stride = stride as usize;
                    for i in 1..count as usize {
                        raw.copy_within(i * stride..i * stride + elem, i * elem);
                    }
                    raw.truncate(packed as usize);
                }
                raw
            }
            None if acc.sparse.is_some() => {
                if packed > self.zero_cap {
                    return Err(self.err(format!(
                        "{name}: {count} elements without a bufferView ({packed} bytes) is implausibly large"
                    )));
                }
                vec![0u8; packed as usize]
            }
            None => return Err(self.err(format!("{name}: neither bufferView nor sparse is given"))),
        };
        if let Some(sparse) = &acc.sparse {
            self.apply_sparse(root, sparse, &mut bytes, count, elem, &name)?;
        }
        Ok(RawAccessor {
            bytes,
            count: count as usize,
            components,
            component_type,
            normalized: acc.normalized,
        })
    }

    fn apply_sparse(
        &mut self,
        root: &json::Root,
        sparse: &json::accessor::sparse::Sparse,
        bytes: &mut [u8],
        count: u64,
        elem: usize,
        name: &str,
    ) -> Result<(), ImportError> {
        let n = sparse.count.0;
        if n > count {
            return Err(self.err(format!("{name}: sparse.count {n} exceeds count {count}")));
        }
        let n = n as usize;
        let index_type = match sparse.indices.component_type {
            Checked::Valid(t)
                if matches!(t.0, ComponentType::U8 | ComponentType::U16 | ComponentType::U32) =>
            {
                t.0
            }
            _ => {
                return Err(
                    self.err(format!("{name}: sparse.indices.componentType must be an unsigned integer"))
                )
            }
        };
        let isize = index_type.size();
        let idx = self.read_view(
            root,
            sparse.indices.buffer_view.value(),
            sparse.indices.byte_offset.0,
            n * isize,
            &format!("{name}.sparse.indices"),
        )?;
        let values = self.read_view(
            root,
            sparse.values.buffer_view.value(),
            sparse.values.byte_offset.0,
            n * elem,
            &format!("{name}.sparse.values"),
        )?;
        for (j, value) in values.chunks_exact(elem).enumerate() {
            let c = &idx[j * isize..(j + 1) * isize];
            let k = match isize {
                1 => c[0] as u64,
                2 => u16::from_le_bytes([c[0], c[1]]) as u64,
                _ => u32::from_le_bytes([c[0], c[1], c[2], c[3]]) as u64,
            };
            if k >= count {
                return Err(
                    self.err(format!("{name}: sparse index {k} (entry {j}) is out of range (count {count})"))
                );
            }
            let k = k as usize;
            bytes[k * elem..(k + 1) * elem].copy_from_slice(value);
        }
        Ok(())
    }
}

fn is_meshopt_fallback(b: &json::Buffer) -> bool {
    b.extensions
        .as_ref()
        .and_then(|e| e.others.get("EXT_meshopt_compression"))
        .and_then(|v| v.get("fallback"))
        .and_then(|v| v.as_bool())
        .unwrap_or(false)
}

/// The scheme of an absolute URI ("http" in "http://x"), if it has one. A Windows drive letter
/// is not a scheme, and relative file names have none.
fn uri_scheme(uri: &str) -> Option<&str> {
    let (scheme, _) = uri.split_once(':')?;
    let ok = scheme.len() > 1
        && scheme.starts_with(|c: char| c.is_ascii_alphabetic())
        && scheme.chars().all(|c| c.is_ascii_alphanumeric() || "+-.".contains(c));
    ok.then_some(scheme)
}

/// Checks that a decoded relative URI names a file inside the glTF file's folder: not an
/// absolute path (`/x`, `\\server\x`, `C:x`), and no `..` that climbs above the folder (`a/../b`
/// stays inside and is accepted). A file may only read what lies beside it: a model from
/// elsewhere must not make terawalk read `/etc/passwd` or `../../secret` as vertex data. The
/// check is on the name, component by component, as both `/` and `\` separate them.
fn check_inside_folder(rel: &str) -> Result<(), &'static str> {
    if rel.starts_with(['/', '\\']) {
        return Err("is an absolute path");
    }
    let b = rel.as_bytes();
    if b.len() >= 2 && b[0].is_ascii_alphabetic() && b[1] == b':' {
        return Err("is an absolute path (a drive letter)");
    }
    let mut depth = 0usize;
    for part in rel.split(['/', '\\']) {
        match part {
            "" | "." => {}
            ".." if depth == 0 => return Err("climbs out of the glTF file's folder"),
            ".." => depth -= 1,
            _ => depth += 1,
        }
    }
    Ok(())
}

/// Decodes %XX escapes of a relative URI (RFC 3986); `None` for a bad escape or non-UTF-8.
fn percent_decode(uri: &str) -> Option<String> {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = b.get(i + 1..i + 3)?;
            let s = std::str::from_utf8(hex).ok()?;
            out.push(u8::from_str_radix(s, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

/// Splits a `data:[<mediatype>];base64,<payload>` URI; returns the payload and its decoded size.
fn parse_data_uri(mut uri: String) -> Result<(String, u64), String> {
    let comma = uri.find(',').ok_or("no ',' before the data")?;
    if !uri[..comma].ends_with(";base64") {
        return Err("only base64 data URIs are supported".into());
    }
    uri.drain(..=comma);
    let p = uri.as_bytes();
    let pad = p.iter().rev().take_while(|&&c| c == b'=').count();
    if pad > 2 {
        return Err("too much '=' padding".into());
    }
    let body = p.len() - pad;
    if pad > 0 && !p.len().is_multiple_of(4) {
        return Err(format!("padded base64 length {} is not a multiple of 4", p.len()));
    }
    let len = match body % 4 {
        1 => return Err(format!("base64 length {body} is impossible")),
        r => (body / 4 * 3 + r.saturating_sub(1)) as u64,
    };
    Ok((uri, len))
}

fn base64_value(c: u8) -> Option<u32> {
    Some(match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' | b'-' => 62,
        b'/' | b'_' => 63,
        _ => return None,
    } as u32)
}

/// Decodes bytes `offset..offset + len` of base64 `payload` (standard or URL-safe alphabet,
/// padding optional), decoding only the 4-character groups that cover them.
fn decode_base64_range(payload: &[u8], offset: u64, len: usize) -> Result<Vec<u8>, String> {
    let first_group = (offset / 3) as usize;
    let skip = (offset % 3) as usize;
    let groups = (skip + len).div_ceil(3);
    let mut out = Vec::with_capacity(groups * 3);
    for g in first_group..first_group + groups {
        let chars = payload.get(g * 4..(g * 4 + 4).min(payload.len())).unwrap_or(&[]);
        let mut acc = 0u32;
        let mut n = 0;
        for (k, &c) in chars.iter().enumerate() {
            if c == b'=' {
                break;
            }
            let v = base64_value(c).ok_or_else(|| {
                format!("invalid base64 character {:?} at payload offset {}", c as char, g * 4 + k)
            })?;
            acc |= v << (18 - 6 * k);
            n += 1;
        }
        let bytes = [(acc >> 16) as u8, (acc >> 8) as u8, acc as u8];
        let have = if n >= 2 { n - 1 } else { 0 };
        out.extend_from_slice(&bytes[..have]);
        if have < 3 {
            break;
        }
    }
    if out.len() < skip + len {
        return Err(format!("the payload ends before byte {}", offset + len as u64));
    }
    out.drain(..skip);
    out.truncate(len);
    Ok(out)
}

/// The parsed `EXT_meshopt_compression` object of a buffer view.
#[derive(Debug)]
pub(super) struct MeshoptView {
    buffer: usize,
    byte_offset: u64,
    byte_length: u64,
    stride: u64,
    count: u64,
    mode: MeshoptMode,
    filter: MeshoptFilter,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum MeshoptMode {
    Attributes,
    Triangles,
    Indices,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum MeshoptFilter {
    None,
    Octahedral,
    Quaternion,
    Exponential,
    Color,
}

/// Parses the extension object of buffer view `index`, if it has one.
fn meshopt_ext(view: &json::buffer::View, index: usize) -> Result<Option<MeshoptView>, String> {
    let Some(v) = view.extensions.as_ref().and_then(|e| e.others.get("EXT_meshopt_compression")) else {
        return Ok(None);
    };
    let what = format!("bufferViews[{index}].extensions.EXT_meshopt_compression");
    let num = |key: &str, default: Option<u64>| match v.get(key) {
        Some(x) => x.as_u64().ok_or_else(|| format!("{what}.{key} is not a non-negative integer")),
        None => default.ok_or_else(|| format!("{what}.{key} is missing")),
    };
    let mode = match v.get("mode").and_then(|m| m.as_str()) {
        Some("ATTRIBUTES") => MeshoptMode::Attributes,
        Some("TRIANGLES") => MeshoptMode::Triangles,
        Some("INDICES") => MeshoptMode::Indices,
        Some(m) => return Err(format!("{what}.mode \"{m}\" is unknown")),
        None => return Err(format!("{what}.mode is missing")),
    };
    let filter = match v.get("filter").map(|f| f.as_str()) {
        None | Some(Some("NONE")) => MeshoptFilter::None,
        Some(Some("OCTAHEDRAL")) => MeshoptFilter::Octahedral,
        Some(Some("QUATERNION")) => MeshoptFilter::Quaternion,
        Some(Some("EXPONENTIAL")) => MeshoptFilter::Exponential,
        Some(Some("COLOR")) => MeshoptFilter::Color,
        Some(f) => return Err(format!("{what}.filter {f:?} is unknown")),
    };
    let buffer = num("buffer", None)?;
    Ok(Some(MeshoptView {
        buffer: usize::try_from(buffer).map_err(|_| format!("{what}.buffer {buffer} does not exist"))?,
        byte_offset: num("byteOffset", Some(0))?,
        byte_length: num("byteLength", None)?,
        stride: num("byteStride", None)?,
        count: num("count", None)?,
        mode,
        filter,
    }))
}

impl MeshoptView {
    /// Checks the parameters the meshoptimizer decoders assert on (they must never see bad ones),
    /// and that the decoded size is one the compressed size can produce, before allocating it.
    fn check_plausible(&self) -> Result<(), String> {
        let s = self.stride;
        match self.mode {
            MeshoptMode::Attributes if s == 0 || !s.is_multiple_of(4) || s > 256 => {
                return Err(format!("byteStride {s} must be a multiple of 4 up to 256 for ATTRIBUTES"))
            }
            MeshoptMode::Triangles | MeshoptMode::Indices if s != 2 && s != 4 => {
                return Err(format!("byteStride {s} must be 2 or 4 for {:?}", self.mode))
            }
            MeshoptMode::Triangles if !self.count.is_multiple_of(3) => {
                return Err(format!("count {} is not a multiple of 3 for TRIANGLES", self.count))
            }
            _ => {}
        }
        let ok = match (self.filter, self.mode) {
            (MeshoptFilter::None, _) => true,
            (_, MeshoptMode::Triangles | MeshoptMode::Indices) => false,
            (MeshoptFilter::Octahedral | MeshoptFilter::Color, _) => s == 4 || s == 8,
            (MeshoptFilter::Quaternion, _) => s == 8,
            (MeshoptFilter::Exponential, _) => s.is_multiple_of(4),
        };
        if !ok {
            return Err(format!(
                "filter {:?} cannot be used with mode {:?} and byteStride {s}",
                self.filter, self.mode
            ));
        }
        // Upper bounds of the codecs' compression ratios: the index codecs spend at least one byte
        // per triangle or per index; the vertex codec at least a header per 16 bytes of a byte
        // channel, and its version 1 a 2-bit control per channel per block of up to 256 vertices.
        let decoded = self.count.checked_mul(s).ok_or("count times byteStride overflows")?;
        let max = match self.mode {
            MeshoptMode::Triangles => self.byte_length.saturating_mul(12),
            MeshoptMode::Indices => self.byte_length.saturating_mul(4),
            MeshoptMode::Attributes => self.byte_length.saturating_mul(1024).saturating_add(1 << 16),
        };
        if decoded > max || decoded > isize::MAX as u64 / 2 {
            return Err(format!(
                "{} elements of {s} bytes cannot come from {} compressed bytes",
                self.count, self.byte_length
            ));
        }
        Ok(())
    }

    /// Decodes `compressed` into `count * stride` bytes and applies the filter.
    fn decode(&self, compressed: &[u8]) -> Result<Vec<u8>, String> {
        use meshopt::ffi;
        let count = self.count as usize;
        let stride = self.stride as usize;
        let mut out = vec![0u8; count * stride];
        // SAFETY: `out` holds exactly count * stride bytes, `compressed` is a valid slice, and
        // check_plausible has enforced every precondition the decoders assert (stride values,
        // index count divisible by 3, filter strides).
        let code = unsafe {
            match self.mode {
                MeshoptMode::Attributes => ffi::meshopt_decodeVertexBuffer(
                    out.as_mut_ptr().cast(),
                    count,
                    stride,
                    compressed.as_ptr(),
                    compressed.len(),
                ),
                MeshoptMode::Triangles => ffi::meshopt_decodeIndexBuffer(
                    out.as_mut_ptr().cast(),
                    count,
                    stride,
                    compressed.as_ptr(),
                    compressed.len(),
                ),
                MeshoptMode::Indices => ffi::meshopt_decodeIndexSequence(
                    out.as_mut_ptr().cast(),
                    count,
                    stride,
                    compressed.as_ptr(),
                    compressed.len(),
                ),
            }
        };
        if code != 0 {
            return Err(format!("meshopt {:?} decoding failed (code {code}): corrupt data", self.mode));
        }
        if count > 0 {
            // SAFETY: as above; the filters work in place on count elements of `stride` bytes.
            unsafe {
                let p = out.as_mut_ptr().cast();
                match self.filter {
                    MeshoptFilter::None => {}
                    MeshoptFilter::Octahedral => ffi::meshopt_decodeFilterOct(p, count, stride),
                    MeshoptFilter::Quaternion => ffi::meshopt_decodeFilterQuat(p, count, stride),
                    MeshoptFilter::Exponential => ffi::meshopt_decodeFilterExp(p, count, stride),
                    MeshoptFilter::Color => ffi::meshopt_decodeFilterColor(p, count, stride),
                }
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn base64_ranges_decode_like_the_whole() {
        let data: Vec<u8> = (0..=255u8).collect();
        let enc = "AAECAwQFBgcICQoLDA0ODxAREhMUFRYXGBkaGxwdHh8gISIjJCUmJygpKissLS4vMDEyMzQ1Njc4OTo7PD0+P0BBQkNERUZHSElKS0xNTk9QUVJTVFVWV1hZWltcXV5fYGFiY2RlZmdoaWprbG1ub3BxcnN0dXZ3eHl6e3x9fn+AgYKDhIWGh4iJiouMjY6PkJGSk5SVlpeYmZqbnJ2en6ChoqOkpaanqKmqq6ytrq+wsbKztLW2t7i5uru8vb6/wMHCw8TFxsfIycrLzM3Oz9DR0tPU1dbX2Nna29zd3t/g4eLj5OXm5+jp6uvs7e7v8PHy8/T19vf4+fr7/P3+/w==";
        let (payload, len) = parse_data_uri(format!("data:application/octet-stream;base64,{enc}")).unwrap();
        assert_eq!(len, 256);
        for (off, n) in [(0, 256), (1, 10), (2, 1), (3, 3), (250, 6), (255, 1), (100, 0)] {
            assert_eq!(decode_base64_range(payload.as_bytes(), off, n).unwrap(), &data[off as usize..][..n]);
        }
        assert!(decode_base64_range(payload.as_bytes(), 255, 2).is_err());
    }

    #[test]
    fn base64_without_padding_and_bad_characters() {
        let (p, len) = parse_data_uri("data:;base64,AQID".into()).unwrap();
        assert_eq!((decode_base64_range(p.as_bytes(), 0, 3).unwrap(), len), (vec![1, 2, 3], 3));
        let (p, len) = parse_data_uri("data:;base64,AQ".into()).unwrap();
        assert_eq!((decode_base64_range(p.as_bytes(), 0, 1).unwrap(), len), (vec![1], 1));
        let (p, _) = parse_data_uri("data:;base64,A*ID".into()).unwrap();
        assert!(decode_base64_range(p.as_bytes(), 0, 3).unwrap_err().contains("invalid base64"));
        assert!(parse_data_uri("data:text/plain,hello".into()).is_err());
        assert!(parse_data_uri("data:;base64,A".into()).is_err());
        assert!(parse_data_uri("data:;base64".into()).is_err());
    }

    #[test]
    fn uri_schemes_and_percent_escapes() {
        assert_eq!(uri_scheme("http://x/a.bin"), Some("http"));
        assert_eq!(uri_scheme("a.bin"), None);
        assert_eq!(uri_scheme("C:/models/a.bin"), None);
        assert_eq!(percent_decode("my%20model.bin").as_deref(), Some("my model.bin"));
        assert_eq!(percent_decode("bad%2"), None);
        assert_eq!(percent_decode("bad%zz"), None);
    }

    #[test]
    fn meshopt_attribute_ratio_bound_holds_for_constant_data() {
        // All-zero vertices compress best; the plausibility bound must still admit them.
        let zeros = vec![[0u32; 4]; 100_000];
        for level in 0..=3 {
            let enc = meshopt::encode_vertex_buffer_level(&zeros, level, Some(1)).unwrap();
            let ratio = (zeros.len() * 16) as f64 / enc.len() as f64;
            assert!(ratio < 1024.0, "level {level}: ratio {ratio}");
        }
        let enc = meshopt::encode_vertex_buffer_level(&zeros, 2, Some(0)).unwrap();
        assert!(((zeros.len() * 16) as f64 / enc.len() as f64) < 1024.0);
    }
}
