//! The cull server's side of a session: accept clients (a thread each), check the handshake,
//! then for every camera ask the caller's [`Culler`] for the visible set and send its delta
//! against the set last sent to that client, closed by the end-of-frame sentinel.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use crate::protocol::{
    CameraRequest, ClusterId, EndOfFrame, FrameStats, Hello, HelloReply, Message, StoreId, PROTOCOL_VERSION,
};
use crate::set::{chunks, VisibleSet};
use crate::transport::{Connection, Listener};
use crate::NetError;

/// How often an idle session and the accept loop look at the stop flag.
const POLL: Duration = Duration::from_millis(100);

/// The culling a server does for one client: made per client by the factory given to
/// [`serve`], in the client's own thread (so it need not be `Send`).
pub trait Culler {
    /// The visible set of `request`'s camera. An error ends the session (the client falls back
    /// to culling locally and reconnects).
    fn cull(&mut self, request: &CameraRequest) -> Result<Culled, String>;
}

/// A visible set as a [`Culler`] finds it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Culled {
    pub ids: Vec<ClusterId>,
    /// Triangles of those clusters (for the client's statistics).
    pub triangles: u64,
}

/// Who the server is.
#[derive(Clone, Debug)]
pub struct ServerOptions {
    /// The store served; a client that opened another is refused.
    pub store: StoreId,
    /// Free text sent in the accept (the server's log name).
    pub name: String,
}

/// What a [`serve`] did, for its caller's log.
#[derive(Debug, Default)]
pub struct ServeSummary {
    pub clients: AtomicU64,
    pub refused: AtomicU64,
    pub frames: AtomicU64,
    pub bytes_sent: AtomicU64,
}

/// Serves clients from `listener` until `stop` is set: one thread per client, each with the
/// culler `make` returns for its [`Hello`] (an `Err` refuses the client with that reason).
/// Returns when every session has ended (within `POLL` of `stop` for idle ones).
pub fn serve<F, C>(
    listener: &Listener,
    options: &ServerOptions,
    stop: &AtomicBool,
    summary: &ServeSummary,
    make: F,
) -> Result<(), NetError>
where
    F: Fn(&Hello) -> Result<C, String> + Sync,
    C: Culler,
{
    std::thread::scope(|scope| {
        while !stop.load(Ordering::Relaxed) {
            let Some(conn) = listener.accept_within(POLL)? else { continue };
            let make = &make;
            scope.spawn(move || {
                let peer = conn.peer().to_string();
                tracing::info!("{peer}: connected");
                match session(conn, options, stop, summary, make) {
                    Ok(frames) => tracing::info!("{peer}: session ended after {frames} frames"),
                    Err(NetError::Refused { reason, .. }) => tracing::warn!("{peer}: refused: {reason}"),
                    Err(e) => tracing::warn!("session ended: {e}"),
                }
            });
        }
        Ok(())
    })
}

/// One client's session; returns its frame count.
fn session<F, C>(
    mut conn: Connection,
    options: &ServerOptions,
    stop: &AtomicBool,
    summary: &ServeSummary,
    make: &F,
) -> Result<u64, NetError>
where
    F: Fn(&Hello) -> Result<C, String>,
    C: Culler,
{
    let mut culler = handshake(&mut conn, options, summary, make)?;
    summary.clients.fetch_add(1, Ordering::Relaxed);
    let mut sent = VisibleSet::default();
    let mut frames = 0;
    let result = loop {
        if stop.load(Ordering::Relaxed) {
            let _ = conn.send(&[Message::Bye]);
            break Ok(frames);
        }
        if !conn.readable_within(POLL)? {
            continue;
        }
        let request = match conn.receive()? {
            Message::Camera(request) => request,
            Message::Bye => break Ok(frames),
            other => break Err(unexpected(&conn, "Camera or Bye", &other)),
        };
        let before = conn.bytes_sent();
        if let Err(e) = answer(&mut conn, &mut culler, &mut sent, &request) {
            break Err(e);
        }
        frames += 1;
        summary.frames.fetch_add(1, Ordering::Relaxed);
        summary.bytes_sent.fetch_add(conn.bytes_sent() - before, Ordering::Relaxed);
    };
    conn.shutdown();
    result
}

/// Reads the client's [`Hello`] and accepts it (returning its culler) or refuses it, saying why
/// (counted in `summary` before the refusal is sent).
fn handshake<F, C>(
    conn: &mut Connection,
    options: &ServerOptions,
    summary: &ServeSummary,
    make: &F,
) -> Result<C, NetError>
where
    F: Fn(&Hello) -> Result<C, String>,
{
    let hello = match conn.receive()? {
        Message::Hello(h) => h,
        other => return Err(unexpected(conn, "Hello", &other)),
    };
    let refusal = if hello.version != PROTOCOL_VERSION {
        Some(format!(
            "protocol version {} (client {:?}), this server speaks version {PROTOCOL_VERSION}",
            hello.version, hello.client
        ))
    } else if hello.store != options.store {
        Some(format!(
            "the client {:?} opened {}, this server serves {}: another store or another build of it",
            hello.client, hello.store, options.store
        ))
    } else {
        None
    };
    let culler = match refusal {
        Some(reason) => Err(reason),
        None => make(&hello),
    };
    match culler {
        Ok(c) => {
            conn.send(&[Message::HelloReply(HelloReply::Accept { server: options.name.clone() })])?;
            tracing::info!("{}: accepted {:?}", conn.peer(), hello.client);
            Ok(c)
        }
        Err(reason) => {
            summary.refused.fetch_add(1, Ordering::Relaxed);
            let _ = conn.send(&[Message::HelloReply(HelloReply::Refuse { reason: reason.clone() })]);
            conn.shutdown();
            Err(NetError::Refused { peer: conn.peer().to_string(), reason })
        }
    }
}

/// Culls one camera and sends the delta against `sent`, then the sentinel; `sent` becomes the
/// new set once it is on its way.
fn answer<C: Culler>(
    conn: &mut Connection,
    culler: &mut C,
    sent: &mut VisibleSet,
    request: &CameraRequest,
) -> Result<(), NetError> {
    let start = Instant::now();
    let culled = culler.cull(request).map_err(|reason| {
        let _ = conn.send(&[Message::Bye]);
        NetError::Refused {
            peer: conn.peer().to_string(),
            reason: format!("frame {}: {reason}", request.frame),
        }
    })?;
    let cull_us = start.elapsed().as_micros() as u64;
    let next = VisibleSet::from_ids(culled.ids);
    let (added, dropped) = sent.delta_to(&next);
    let parts = chunks(request.frame, &added, &dropped);
    let stats = FrameStats {
        visible: next.len() as u32,
        chunks: parts.len() as u32,
        cull_us,
        triangles: culled.triangles,
    };
    let mut messages: Vec<Message> = parts.into_iter().map(Message::VisibleDelta).collect();
    messages.push(Message::EndOfFrame(EndOfFrame { frame: request.frame, stats }));
    conn.send(&messages)?;
    *sent = next;
    Ok(())
}

pub(crate) fn unexpected(conn: &Connection, expected: &str, got: &Message) -> NetError {
    NetError::Unexpected {
        peer: conn.peer().to_string(),
        expected: expected.to_string(),
        got: got.name().to_string(),
    }
}
