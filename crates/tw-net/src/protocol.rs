//! The wire format: length-prefixed, frame-tagged binary messages (docs/DESIGN.md, D7).
//!
//! Every message is `[length: u32 LE][tag: u8][payload]`, where `length` counts the tag and the
//! payload and is at most [`MAX_MESSAGE_LEN`]. All integers and floats are little-endian. A
//! session is:
//!
//! ```text
//! client                                  server
//! Hello { version, store, client }   →
//!                                    ←    HelloReply::Accept | HelloReply::Refuse
//! Camera { frame n, … }              →
//!                                    ←    VisibleDelta { frame n, added, dropped } (0 or more chunks)
//!                                    ←    EndOfFrame { frame n, stats }
//! …
//! Bye                                →    (either side may send Bye before closing)
//! ```
//!
//! Cluster ids are [`ClusterId`]s, 4 bytes each, as the occlusion switch sends node ids
//! (Govindaraju's thesis §3.5: ids identical on every machine, the scene replicated, so 4 bytes
//! per visible node instead of its geometry). A frame's visible set is sent as the delta against
//! the set the server last sent to that client, in chunks of at most [`MAX_IDS_PER_CHUNK`] ids,
//! and closed by an [`EndOfFrame`] sentinel (GigaWalk §5: frame-tagged hand-offs with
//! end-of-frame markers), which also carries the size the set must have after the delta, so a
//! client that lost track notices at once.
//!
//! The decoder is total: any bytes give a message or a [`WireError`], never a panic, and no
//! allocation exceeds the message's own (bounded) length.

use crate::WireError;

/// The protocol version a [`Hello`] carries; a server refuses any other.
pub const PROTOCOL_VERSION: u32 = 1;

/// The longest message (tag and payload) either side accepts: a full chunk of ids with room to
/// spare. A length prefix above it is refused before anything is allocated.
pub const MAX_MESSAGE_LEN: u32 = 1 << 20;

/// Most ids (added and dropped together) in one [`VisibleDelta`] chunk: 4 × 65,536 = 256 KiB.
pub const MAX_IDS_PER_CHUNK: usize = 1 << 16;

/// Longest client name or refusal reason, in bytes of UTF-8.
pub const MAX_TEXT_LEN: usize = 1024;

/// Bytes of the length prefix.
pub const PREFIX_LEN: usize = 4;

/// One cluster's id on the wire: its position in the store's page order (the clusters of page
/// 0 first, in their order within the page, then page 1's, …). Both ends open the same store
/// (checked by the [`StoreId`] of the handshake), so the id means the same cluster on both.
pub type ClusterId = u32;

/// A store's identity, compared in the handshake: the header's CRC-32C, the page count and the
/// cluster count. The header CRC covers the section directory, whose CRCs cover every table,
/// and the page table holds each page's CRC, so the header CRC changes with any byte of the
/// store's content; the counts make the identity readable in a refusal and a chance collision
/// of two 32-bit CRCs harmless unless the stores also have the same shape.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct StoreId(pub [u8; 16]);

impl StoreId {
    pub fn new(header_crc: u32, pages: u32, clusters: u64) -> StoreId {
        let mut b = [0u8; 16];
        b[..4].copy_from_slice(&header_crc.to_le_bytes());
        b[4..8].copy_from_slice(&pages.to_le_bytes());
        b[8..].copy_from_slice(&clusters.to_le_bytes());
        StoreId(b)
    }

    /// The identity of `store` (see the type).
    pub fn of(store: &tw_store::Store) -> StoreId {
        let header = store.header();
        let bytes = header.to_bytes();
        let crc = u32::from_le_bytes(bytes[bytes.len() - 4..].try_into().unwrap_or_default());
        StoreId::new(crc, header.page_count, header.cluster_count)
    }
}

impl std::fmt::Display for StoreId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let crc = u32::from_le_bytes([self.0[0], self.0[1], self.0[2], self.0[3]]);
        let pages = u32::from_le_bytes([self.0[4], self.0[5], self.0[6], self.0[7]]);
        let mut c = [0u8; 8];
        c.copy_from_slice(&self.0[8..]);
        write!(f, "store {crc:08x} ({pages} pages, {} clusters)", u64::from_le_bytes(c))
    }
}

/// The client's greeting.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Hello {
    pub version: u32,
    pub store: StoreId,
    /// Free text for the server's log (host, process).
    pub client: String,
}

/// The server's answer to a [`Hello`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum HelloReply {
    /// `server`: free text for the client's log.
    Accept { server: String },
    /// Why not, naming both identities or versions.
    Refuse { reason: String },
}

/// One frame's camera and culling settings, in the store's scene space (the runtime's
/// `tw_runtime::Camera`). 79 bytes on the wire: the camera's 48 (the thesis counts 72 bytes of
/// "view parameters"), the frame tag, the viewport, the settings, tag and length prefix.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraRequest {
    pub frame: u64,
    pub eye: [f32; 3],
    pub target: [f32; 3],
    pub up: [f32; 3],
    /// Vertical field of view, radians; with the [`ORTHOGRAPHIC`](Self::ORTHOGRAPHIC) flag the
    /// orthographic view's height in scene units instead.
    pub fovy: f32,
    pub near: f32,
    pub far: f32,
    /// Width and height in pixels: the pixel error's scale and the frustum's aspect.
    pub viewport: [u32; 2],
    /// Pixel error threshold τ.
    pub tau: f32,
    /// Occlusion strategy by its `--occlusion` name index (0 none, 1 hzb, 2 queries, 3
    /// gpu-hzb; the receiver checks it).
    pub occlusion: u8,
    /// Bit 0: frustum culling; bit 1: triangle culling (`hzb`); bit 2: load every page of the
    /// cut before culling (the same cut whatever the timing); bit 3: an orthographic camera.
    pub flags: u8,
    /// `queries`' visible-pixel cut-off.
    pub visible_pixels: u32,
}

impl CameraRequest {
    pub const FRUSTUM_CULLING: u8 = 1;
    pub const TRIANGLE_CULLING: u8 = 2;
    pub const WAIT_FOR_PAGES: u8 = 4;
    /// The camera is orthographic, [`fovy`](Self::fovy) its view height.
    pub const ORTHOGRAPHIC: u8 = 8;
    /// [`occlusion`](Self::occlusion): the server's own choice.
    pub const SERVER_OCCLUSION: u8 = 255;
}

/// One chunk of a frame's visible-set delta.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VisibleDelta {
    pub frame: u64,
    /// Ids visible now and not in the previous set.
    pub added: Vec<ClusterId>,
    /// Ids of the previous set no longer visible.
    pub dropped: Vec<ClusterId>,
}

/// What the server measured for one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameStats {
    /// Size of the visible set after this frame's delta (the client checks its own).
    pub visible: u32,
    /// Chunks of delta sent for the frame.
    pub chunks: u32,
    /// The server's culling time (select, stream, occlude), microseconds.
    pub cull_us: u64,
    /// Triangles of the visible set.
    pub triangles: u64,
}

/// The end-of-frame sentinel: every delta chunk of `frame` has been sent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EndOfFrame {
    pub frame: u64,
    pub stats: FrameStats,
}

/// Every message of the protocol.
#[derive(Clone, Debug, PartialEq)]
pub enum Message {
    Hello(Hello),
    HelloReply(HelloReply),
    Camera(CameraRequest),
    VisibleDelta(VisibleDelta),
    EndOfFrame(EndOfFrame),
    Bye,
}

const TAG_HELLO: u8 = 1;
const TAG_ACCEPT: u8 = 2;
const TAG_REFUSE: u8 = 3;
const TAG_CAMERA: u8 = 4;
const TAG_DELTA: u8 = 5;
const TAG_END: u8 = 6;
const TAG_BYE: u8 = 7;

/// Magic at the start of a [`Hello`]'s payload: a stray connection from another program is
/// refused as such, not as a version mismatch.
const HELLO_MAGIC: [u8; 4] = *b"TWNC";

impl Message {
    /// The message's name, for logs and errors.
    pub fn name(&self) -> &'static str {
        match self {
            Message::Hello(_) => "Hello",
            Message::HelloReply(_) => "HelloReply",
            Message::Camera(_) => "Camera",
            Message::VisibleDelta(_) => "VisibleDelta",
            Message::EndOfFrame(_) => "EndOfFrame",
            Message::Bye => "Bye",
        }
    }

    /// The message framed for the wire (length prefix included). Fails where a field is over
    /// its bound (a chunk of too many ids, a text too long), so the sender learns it, not the
    /// receiver.
    pub fn encode(&self) -> Result<Vec<u8>, WireError> {
        let mut w = vec![0u8; PREFIX_LEN];
        match self {
            Message::Hello(h) => {
                w.push(TAG_HELLO);
                w.extend_from_slice(&HELLO_MAGIC);
                put_u32(&mut w, h.version);
                w.extend_from_slice(&h.store.0);
                put_text(&mut w, &h.client, "client name")?;
            }
            Message::HelloReply(HelloReply::Accept { server }) => {
                w.push(TAG_ACCEPT);
                put_text(&mut w, server, "server name")?;
            }
            Message::HelloReply(HelloReply::Refuse { reason }) => {
                w.push(TAG_REFUSE);
                put_text(&mut w, reason, "refusal reason")?;
            }
            Message::Camera(c) => {
                w.push(TAG_CAMERA);
                put_u64(&mut w, c.frame);
                for v in c.eye.iter().chain(&c.target).chain(&c.up).chain(&[c.fovy, c.near, c.far]) {
                    put_f32(&mut w, *v);
                }
                put_u32(&mut w, c.viewport[0]);
                put_u32(&mut w, c.viewport[1]);
                put_f32(&mut w, c.tau);
                w.push(c.occlusion);
                w.push(c.flags);
                put_u32(&mut w, c.visible_pixels);
            }
            Message::VisibleDelta(d) => {
                let ids = d.added.len() + d.dropped.len();
                if ids > MAX_IDS_PER_CHUNK {
                    return Err(WireError::TooManyIds { ids, max: MAX_IDS_PER_CHUNK });
                }
                w.push(TAG_DELTA);
                put_u64(&mut w, d.frame);
                put_u32(&mut w, d.added.len() as u32);
                put_u32(&mut w, d.dropped.len() as u32);
                for id in d.added.iter().chain(&d.dropped) {
                    put_u32(&mut w, *id);
                }
            }
            Message::EndOfFrame(e) => {
                w.push(TAG_END);
                put_u64(&mut w, e.frame);
                put_u32(&mut w, e.stats.visible);
                put_u32(&mut w, e.stats.chunks);
                put_u64(&mut w, e.stats.cull_us);
                put_u64(&mut w, e.stats.triangles);
            }
            Message::Bye => w.push(TAG_BYE),
        }
        let len = (w.len() - PREFIX_LEN) as u32;
        w[..PREFIX_LEN].copy_from_slice(&len.to_le_bytes());
        Ok(w)
    }

    /// The body length a length prefix announces, checked against [`MAX_MESSAGE_LEN`] (an
    /// empty body has no tag: refused too).
    pub fn body_len(prefix: [u8; PREFIX_LEN]) -> Result<usize, WireError> {
        let len = u32::from_le_bytes(prefix);
        if len == 0 || len > MAX_MESSAGE_LEN {
            return Err(WireError::BadLength { len, max: MAX_MESSAGE_LEN });
        }
        Ok(len as usize)
    }

    /// Decodes one framed message from the front of `bytes`; returns it and the bytes it took.
    pub fn decode(bytes: &[u8]) -> Result<(Message, usize), WireError> {
        let prefix: [u8; PREFIX_LEN] = match bytes.get(..PREFIX_LEN) {
            Some(p) => [p[0], p[1], p[2], p[3]],
            None => return Err(WireError::Truncated { at: bytes.len() as u64, what: "length prefix" }),
        };
        let len = Message::body_len(prefix)?;
        let body = bytes
            .get(PREFIX_LEN..PREFIX_LEN + len)
            .ok_or(WireError::Truncated { at: bytes.len() as u64, what: "message body" })?;
        Ok((Message::decode_body(body)?, PREFIX_LEN + len))
    }

    /// Decodes a message body (tag and payload, without the prefix). Every byte must be used.
    pub fn decode_body(body: &[u8]) -> Result<Message, WireError> {
        let mut r = Reader { bytes: body, at: 0 };
        let tag = r.u8("tag")?;
        let message = match tag {
            TAG_HELLO => {
                let magic = r.take(4, "hello magic")?;
                if magic != HELLO_MAGIC {
                    return Err(WireError::BadValue {
                        at: 1,
                        what: format!("hello magic {magic:02x?}, expected \"TWNC\" (not a terawalk client)"),
                    });
                }
                let version = r.u32("protocol version")?;
                let mut store = [0u8; 16];
                store.copy_from_slice(r.take(16, "store identity")?);
                let client = r.text("client name")?;
                Message::Hello(Hello { version, store: StoreId(store), client })
            }
            TAG_ACCEPT => Message::HelloReply(HelloReply::Accept { server: r.text("server name")? }),
            TAG_REFUSE => Message::HelloReply(HelloReply::Refuse { reason: r.text("refusal reason")? }),
            TAG_CAMERA => {
                let frame = r.u64("frame")?;
                let mut f = [0f32; 12];
                for v in &mut f {
                    *v = r.f32("camera")?;
                }
                let viewport = [r.u32("viewport width")?, r.u32("viewport height")?];
                let tau = r.f32("tau")?;
                let occlusion = r.u8("occlusion")?;
                let flags = r.u8("flags")?;
                let visible_pixels = r.u32("visible pixels")?;
                Message::Camera(CameraRequest {
                    frame,
                    eye: [f[0], f[1], f[2]],
                    target: [f[3], f[4], f[5]],
                    up: [f[6], f[7], f[8]],
                    fovy: f[9],
                    near: f[10],
                    far: f[11],
                    viewport,
                    tau,
                    occlusion,
                    flags,
                    visible_pixels,
                })
            }
            TAG_DELTA => {
                let frame = r.u64("frame")?;
                let added = r.u32("added count")? as usize;
                let dropped = r.u32("dropped count")? as usize;
                let ids = added.saturating_add(dropped);
                if ids > MAX_IDS_PER_CHUNK {
                    return Err(WireError::TooManyIds { ids, max: MAX_IDS_PER_CHUNK });
                }
                // The counts are checked against the bytes there before anything is allocated.
                if r.remaining() != ids * 4 {
                    return Err(WireError::BadValue {
                        at: r.at as u64,
                        what: format!("{ids} ids announced, {} bytes follow", r.remaining()),
                    });
                }
                let added = r.ids(added)?;
                let dropped = r.ids(dropped)?;
                Message::VisibleDelta(VisibleDelta { frame, added, dropped })
            }
            TAG_END => Message::EndOfFrame(EndOfFrame {
                frame: r.u64("frame")?,
                stats: FrameStats {
                    visible: r.u32("visible")?,
                    chunks: r.u32("chunks")?,
                    cull_us: r.u64("cull time")?,
                    triangles: r.u64("triangles")?,
                },
            }),
            TAG_BYE => Message::Bye,
            other => return Err(WireError::UnknownTag(other)),
        };
        if r.remaining() != 0 {
            return Err(WireError::BadValue {
                at: r.at as u64,
                what: format!("{} bytes after the end of a {} message", r.remaining(), message.name()),
            });
        }
        Ok(message)
    }
}

fn put_u32(w: &mut Vec<u8>, v: u32) {
    w.extend_from_slice(&v.to_le_bytes());
}

fn put_u64(w: &mut Vec<u8>, v: u64) {
    w.extend_from_slice(&v.to_le_bytes());
}

fn put_f32(w: &mut Vec<u8>, v: f32) {
    w.extend_from_slice(&v.to_le_bytes());
}

fn put_text(w: &mut Vec<u8>, text: &str, what: &'static str) -> Result<(), WireError> {
    if text.len() > MAX_TEXT_LEN {
        return Err(WireError::TextTooLong { what, len: text.len(), max: MAX_TEXT_LEN });
    }
    put_u32(w, text.len() as u32);
    w.extend_from_slice(text.as_bytes());
    Ok(())
}

/// A cursor over a message body; every read is bounds-checked and names the field it wanted.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn remaining(&self) -> usize {
        self.bytes.len() - self.at
    }

    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], WireError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let end = end.ok_or(WireError::Truncated { at: self.at as u64, what })?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u8(&mut self, what: &'static str) -> Result<u8, WireError> {
        Ok(self.take(1, what)?[0])
    }

    fn u32(&mut self, what: &'static str) -> Result<u32, WireError> {
        let b = self.take(4, what)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u64(&mut self, what: &'static str) -> Result<u64, WireError> {
        let b = self.take(8, what)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }

    fn f32(&mut self, what: &'static str) -> Result<f32, WireError> {
        Ok(f32::from_bits(self.u32(what)?))
    }

    fn text(&mut self, what: &'static str) -> Result<String, WireError> {
        let len = self.u32(what)? as usize;
        if len > MAX_TEXT_LEN {
            return Err(WireError::TextTooLong { what, len, max: MAX_TEXT_LEN });
        }
        let at = self.at as u64;
        let bytes = self.take(len, what)?;
        String::from_utf8(bytes.to_vec())
            .map_err(|_| WireError::BadValue { at, what: format!("{what} is not UTF-8") })
    }

    /// `n` ids; the caller has checked that their bytes are there.
    fn ids(&mut self, n: usize) -> Result<Vec<ClusterId>, WireError> {
        let bytes = self.take(n * 4, "ids")?;
        Ok(bytes.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tw_core::rng::Rng;

    fn samples() -> Vec<Message> {
        vec![
            Message::Hello(Hello {
                version: PROTOCOL_VERSION,
                store: StoreId::new(0xdead_beef, 12, 3456),
                client: "bench@host".into(),
            }),
            Message::HelloReply(HelloReply::Accept { server: "cull-server".into() }),
            Message::HelloReply(HelloReply::Refuse { reason: "another store: é".into() }),
            Message::Camera(CameraRequest {
                frame: u64::MAX - 1,
                eye: [1.0, -2.5, 3.0],
                target: [0.0, 0.0, f32::MIN_POSITIVE],
                up: [0.0, 0.0, 1.0],
                fovy: 1.2,
                near: 1e-5,
                far: 1e5,
                viewport: [1280, 720],
                tau: 1.5,
                occlusion: 1,
                flags: CameraRequest::FRUSTUM_CULLING | CameraRequest::TRIANGLE_CULLING,
                visible_pixels: 7,
            }),
            Message::VisibleDelta(VisibleDelta { frame: 3, added: vec![1, 2, u32::MAX], dropped: vec![9] }),
            Message::VisibleDelta(VisibleDelta { frame: 4, added: vec![], dropped: vec![] }),
            Message::VisibleDelta(VisibleDelta {
                frame: 5,
                added: (0..MAX_IDS_PER_CHUNK as u32 - 1).collect(),
                dropped: vec![7],
            }),
            Message::EndOfFrame(EndOfFrame {
                frame: 3,
                stats: FrameStats { visible: 10, chunks: 1, cull_us: 1234, triangles: 1 << 40 },
            }),
            Message::Bye,
        ]
    }

    #[test]
    fn every_message_round_trips() {
        for m in samples() {
            let bytes = m.encode().unwrap();
            assert!(bytes.len() - PREFIX_LEN <= MAX_MESSAGE_LEN as usize, "{}", m.name());
            let (back, used) = Message::decode(&bytes).unwrap();
            assert_eq!(back, m);
            assert_eq!(used, bytes.len());
        }
    }

    #[test]
    fn a_camera_message_is_79_bytes() {
        let Message::Camera(c) = samples()[3].clone() else { unreachable!() };
        let len = Message::Camera(c).encode().unwrap().len();
        // prefix + tag + frame + 12 floats + viewport + tau + occlusion + flags + cut-off
        assert_eq!(len, 4 + 1 + 8 + 48 + 8 + 4 + 1 + 1 + 4);
    }

    #[test]
    fn oversized_fields_are_refused_when_encoding() {
        let big = VisibleDelta { frame: 0, added: vec![0; MAX_IDS_PER_CHUNK], dropped: vec![1] };
        assert!(matches!(Message::VisibleDelta(big).encode(), Err(WireError::TooManyIds { .. })));
        let long = "x".repeat(MAX_TEXT_LEN + 1);
        let refuse = Message::HelloReply(HelloReply::Refuse { reason: long });
        assert!(matches!(refuse.encode(), Err(WireError::TextTooLong { .. })));
    }

    #[test]
    fn every_truncation_is_an_error() {
        for m in samples() {
            let bytes = m.encode().unwrap();
            for len in 0..bytes.len() {
                assert!(Message::decode(&bytes[..len]).is_err(), "{} cut to {len} bytes decoded", m.name());
            }
        }
    }

    #[test]
    fn bad_lengths_tags_and_trailing_bytes_are_errors() {
        assert!(matches!(Message::decode(&[0, 0, 0, 0, 1]), Err(WireError::BadLength { .. })));
        let huge = (MAX_MESSAGE_LEN + 1).to_le_bytes();
        assert!(matches!(Message::decode(&huge), Err(WireError::BadLength { .. })));
        assert!(matches!(Message::decode(&[1, 0, 0, 0, 99]), Err(WireError::UnknownTag(99))));
        let mut bye = Message::Bye.encode().unwrap();
        bye[0] = 2;
        bye.push(0);
        assert!(Message::decode(&bye).unwrap_err().to_string().contains("after the end of a Bye"));
        // A delta announcing more ids than it carries is refused before allocating them.
        let mut delta = Message::VisibleDelta(VisibleDelta { frame: 1, added: vec![5], dropped: vec![] })
            .encode()
            .unwrap();
        delta[PREFIX_LEN + 9..PREFIX_LEN + 13].copy_from_slice(&2u32.to_le_bytes());
        assert!(Message::decode(&delta).unwrap_err().to_string().contains("2 ids announced"));
        let mut hello = samples()[0].encode().unwrap();
        hello[PREFIX_LEN + 1] = b'X';
        assert!(Message::decode(&hello).unwrap_err().to_string().contains("not a terawalk client"));
    }

    /// Random mutations of valid messages and random bytes: decoding gives a message or an
    /// error, never a panic, and what decodes encodes back to the same bytes.
    #[test]
    fn garbage_never_panics() {
        let mut rng = Rng::new(7);
        let valid: Vec<Vec<u8>> = samples().iter().map(|m| m.encode().unwrap()).collect();
        for _ in 0..20_000 {
            let mut bytes = rng.pick(&valid).clone();
            match rng.range_u32(0, 3) {
                0 => {
                    for _ in 0..rng.range_u32(1, 4) {
                        let len = bytes.len() as u32;
                        let i = rng.range_u32(0, len) as usize;
                        bytes[i] = rng.next_u32() as u8;
                    }
                }
                1 => {
                    let len = bytes.len() as u32;
                    bytes.truncate(rng.range_u32(0, len) as usize);
                }
                _ => {
                    let len = rng.range_u32(0, 64) as usize;
                    bytes = (0..len).map(|_| rng.next_u32() as u8).collect();
                }
            }
            if let Ok((m, used)) = Message::decode(&bytes) {
                assert_eq!(m.encode().unwrap(), bytes[..used], "{}", m.name());
            }
        }
    }
}
