//! terawalk's network cull server, the wire side: the occlusion switch of Govindaraju's thesis
//! (ch. 3; Manocha §4.4–4.5) over TCP. A cull server culls each camera a render client sends and
//! answers with the visible set's delta against the set it last sent to that client, as 4-byte
//! cluster ids closed by an end-of-frame sentinel (docs/DESIGN.md, D7).
//!
//! This crate holds only what travels and how (docs/DESIGN.md, "Where the new capabilities
//! go"): the messages ([`protocol`]), the visible set and its delta ([`set`]), the TCP transport
//! ([`transport`]), and the two ends' session logic — handshake, frames, reconnection — behind a
//! [`server::Culler`] that the caller implements with the frame pipeline (`tw-frame`) and a
//! [`client::CullClient`] that hands back visible sets; the culling itself stays in `tw-frame` /
//! `tw-runtime`.
//!
//! **Threads, not an async runtime.** One std thread per connected client on the server, one
//! background thread on the client. A cull server has a handful of clients (the thesis: one
//! render PC per culling pair), each of whose frames is blocking GPU work (a depth read-back,
//! occlusion query results) that would have to leave an async executor for a blocking pool
//! anyway; a thread per client keeps each frame a plain sequence of blocking calls with socket
//! timeouts, adds no dependency, and costs nothing measurable at this client count. Every
//! socket has `TCP_NODELAY`: a frame is a few small messages whose latency matters more than
//! their packet count (the thesis saw up to 50 ms of TCP buffering latency per frame).

pub mod client;
pub mod protocol;
pub mod server;
pub mod set;
pub mod transport;

pub use protocol::{
    CameraRequest, ClusterId, EndOfFrame, FrameStats, Hello, HelloReply, Message, StoreId, VisibleDelta,
    MAX_IDS_PER_CHUNK, MAX_MESSAGE_LEN, PROTOCOL_VERSION,
};
pub use set::VisibleSet;

/// Bytes that are not a valid message; `at` is the byte offset within the message body.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    #[error("truncated {what} at byte {at}")]
    Truncated { at: u64, what: &'static str },
    #[error("message length {len} outside 1..={max}")]
    BadLength { len: u32, max: u32 },
    #[error("unknown message tag {0}")]
    UnknownTag(u8),
    #[error("{ids} ids in one delta chunk, at most {max}")]
    TooManyIds { ids: usize, max: usize },
    #[error("{what} of {len} bytes, at most {max}")]
    TextTooLong { what: &'static str, len: usize, max: usize },
    #[error("at byte {at}: {what}")]
    BadValue { at: u64, what: String },
    /// A delta that does not fit the set it is applied to.
    #[error("visible sets out of step: {0}")]
    Desync(String),
}

/// A failed exchange with a peer; every variant names the peer. After any error the
/// connection is unusable (a timeout may have left half a message unread): drop it.
#[derive(Debug, thiserror::Error)]
pub enum NetError {
    #[error("{peer}: bad message at stream byte {offset}: {source}")]
    Wire { peer: String, offset: u64, source: WireError },
    #[error("{peer}: cannot {op}: {source}")]
    Io { peer: String, op: &'static str, source: std::io::Error },
    #[error("{peer}: no answer within {after:?} ({op})")]
    Timeout { peer: String, op: &'static str, after: std::time::Duration },
    #[error("{peer}: connection closed")]
    Closed { peer: String },
    #[error("{peer}: refused: {reason}")]
    Refused { peer: String, reason: String },
    #[error("{peer}: expected {expected}, got {got}")]
    Unexpected { peer: String, expected: String, got: String },
}

/// Entry point of the `net` fuzz target (fuzz/fuzz_targets/net.rs): decodes every message of
/// `data` in turn, as a receiver would, and applies the deltas to a visible set; any error is
/// allowed, a panic or an unbounded allocation is not. Returns the messages decoded.
pub fn fuzz_decode(data: &[u8]) -> usize {
    let mut rest = data;
    let mut set = VisibleSet::default();
    let mut n = 0;
    while let Ok((message, used)) = Message::decode(rest) {
        if let Message::VisibleDelta(d) = message {
            let _ = set.apply(d.added, d.dropped);
        }
        rest = &rest[used..];
        n += 1;
    }
    n
}

#[cfg(test)]
mod tests {
    /// The committed corpus and every crasher found so far (fuzz/corpus/net,
    /// fuzz/regressions/net) through the fuzz target's entry point.
    #[test]
    fn net_corpus_replays() {
        let fuzz = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
        let mut files = Vec::new();
        for dir in ["corpus", "regressions"] {
            if let Ok(entries) = std::fs::read_dir(fuzz.join(dir).join("net")) {
                files.extend(entries.filter_map(|e| e.ok()).map(|e| e.path()));
            }
        }
        assert!(!files.is_empty(), "no corpus for the net fuzz target in {}", fuzz.display());
        for f in files {
            let data = std::fs::read(&f).unwrap();
            let n = super::fuzz_decode(&data);
            if f.to_string_lossy().contains("corpus") {
                assert!(n > 0, "{}: a seed that decodes nothing", f.display());
            }
            if f.ends_with("server.bin") {
                // Both deltas apply: a seed that reaches the set code.
                assert_eq!(n, 6, "{}", f.display());
            }
        }
    }
}
