//! The render client's side: a background thread that keeps a connection to the cull server,
//! sends the newest camera, rebuilds the visible set from the deltas, and hands each frame's set
//! back; on any failure it drops the connection and reconnects, while the caller culls locally
//! (its frames never wait for a server that is gone).
//!
//! The camera goes through a one-slot buffer, as in the occlusion switch (Govindaraju's thesis,
//! Alg. 3.4.2: the newest camera from a one-slot buffer): a camera not yet sent is replaced by a
//! newer one, so a slow server culls the newest view rather than a queue of old ones.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::protocol::{
    CameraRequest, EndOfFrame, FrameStats, Hello, HelloReply, Message, StoreId, PROTOCOL_VERSION,
};
use crate::server::unexpected;
use crate::set::VisibleSet;
use crate::transport::Connection;
use crate::{NetError, WireError};

/// Where and who the client is.
#[derive(Clone, Debug)]
pub struct ClientOptions {
    /// The server, host:port.
    pub addr: String,
    /// The store this client opened (the server refuses another).
    pub store: StoreId,
    /// Free text for the server's log.
    pub name: String,
    /// Longest wait for a connection, a read or a write.
    pub timeout: Duration,
    /// Pause between reconnection attempts.
    pub retry: Duration,
}

/// One frame's visible set as the server sent it, and what it cost.
#[derive(Clone, Debug, Default)]
pub struct RemoteSet {
    pub frame: u64,
    pub set: VisibleSet,
    pub stats: FrameStats,
    /// Bytes this frame's exchange wrote (the camera) and read (the deltas and the sentinel).
    pub bytes_sent: u64,
    pub bytes_received: u64,
    /// Ids the deltas carried (added + dropped); `set.len()` is what the full set would take.
    pub ids_received: u64,
    /// From sending the camera to receiving the sentinel.
    pub round_trip: Duration,
}

enum Event {
    Connected(String),
    Reply(Box<RemoteSet>),
    Lost(String),
}

/// The one-slot camera buffer between the caller and the worker.
#[derive(Default)]
struct Slot {
    camera: Mutex<Option<CameraRequest>>,
    ready: Condvar,
}

/// A connection to a cull server, kept by a background thread (see the module).
pub struct CullClient {
    slot: Arc<Slot>,
    events: Receiver<Event>,
    stop: Arc<AtomicBool>,
    worker: Option<JoinHandle<()>>,
    /// Why the server is not used now (logged once per outage); `None` while it answers.
    down: Option<String>,
    /// The newest set received.
    latest: Option<RemoteSet>,
    /// Frames for which no set came in time.
    pub fallbacks: u64,
}

impl CullClient {
    /// Starts the worker, which connects at once (and keeps trying).
    pub fn start(options: ClientOptions) -> CullClient {
        let slot = Arc::new(Slot::default());
        let stop = Arc::new(AtomicBool::new(false));
        let (tx, events) = channel();
        let worker = {
            let (slot, stop) = (slot.clone(), stop.clone());
            std::thread::Builder::new()
                .name("cull-client".into())
                .spawn(move || worker(options, &slot, &stop, &tx))
                .ok()
        };
        let down = worker.is_none().then(|| "cannot start the client thread".to_string());
        CullClient { slot, events, stop, worker, down, latest: None, fallbacks: 0 }
    }

    /// Hands `camera` to the worker, replacing one not yet sent.
    pub fn request(&self, camera: CameraRequest) {
        if let Ok(mut slot) = self.slot.camera.lock() {
            *slot = Some(camera);
            self.slot.ready.notify_one();
        }
    }

    /// The newest set of frame `frame` or a later one, waiting at most `wait` for it while
    /// the server answers; while it does not (down, refused, late), only what has already
    /// arrived, so the caller's frame does not stall. A set already returned is returned again
    /// while it is the newest (frame n − 1's set serves frame n even when n − 1 itself was drawn
    /// with it). `None`: cull locally this frame.
    pub fn set_for(&mut self, frame: u64, wait: Duration) -> Option<RemoteSet> {
        while let Ok(event) = self.events.try_recv() {
            self.handle(event);
        }
        if self.latest.as_ref().is_some_and(|r| r.frame >= frame) {
            return self.latest.clone();
        }
        let deadline = Instant::now() + if self.down.is_some() { Duration::ZERO } else { wait };
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.events.recv_timeout(left) {
                Ok(event) => {
                    if !self.handle(event) {
                        break;
                    }
                    if self.latest.as_ref().is_some_and(|r| r.frame >= frame) {
                        return self.latest.clone();
                    }
                }
                Err(RecvTimeoutError::Timeout) => {
                    self.mark_down(format!("no visible set for frame {frame} within {wait:?}"));
                    break;
                }
                Err(RecvTimeoutError::Disconnected) => {
                    self.mark_down("the client thread has stopped".to_string());
                    break;
                }
            }
        }
        self.fallbacks += 1;
        None
    }

    /// Takes in one event from the worker; false when it says the server is lost.
    fn handle(&mut self, event: Event) -> bool {
        match event {
            Event::Reply(r) => {
                if self.down.take().is_some() {
                    tracing::info!("cull server: answering again from frame {}", r.frame);
                }
                if self.latest.as_ref().is_none_or(|l| l.frame < r.frame) {
                    self.latest = Some(*r);
                }
                true
            }
            Event::Connected(peer) => {
                tracing::debug!("cull server {peer}: connected");
                true
            }
            Event::Lost(reason) => {
                self.mark_down(reason);
                false
            }
        }
    }

    fn mark_down(&mut self, reason: String) {
        if self.down.is_none() {
            tracing::warn!("cull server: {reason}; culling locally until it answers again");
            self.down = Some(reason);
        }
    }
}

impl Drop for CullClient {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.slot.ready.notify_all();
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}

/// The worker thread: connect, exchange frames, reconnect after any failure.
fn worker(options: ClientOptions, slot: &Slot, stop: &AtomicBool, events: &Sender<Event>) {
    let mut conn: Option<Connection> = None;
    let mut set = VisibleSet::default();
    while !stop.load(Ordering::Relaxed) {
        let Some(c) = conn.as_mut() else {
            match connect(&options) {
                Ok(c) => {
                    let _ = events.send(Event::Connected(c.peer().to_string()));
                    conn = Some(c);
                    // A new session starts from the empty set on both ends.
                    set = VisibleSet::default();
                }
                Err(e) => {
                    let _ = events.send(Event::Lost(e.to_string()));
                    sleep_unless_stopped(options.retry, stop);
                }
            }
            continue;
        };
        let Some(camera) = next_camera(slot, stop) else { continue };
        match exchange(c, &mut set, &camera) {
            Ok(reply) => {
                let _ = events.send(Event::Reply(Box::new(reply)));
            }
            Err(e) => {
                let _ = events.send(Event::Lost(e.to_string()));
                conn = None;
            }
        }
    }
    if let Some(c) = conn.as_mut() {
        let _ = c.send(&[Message::Bye]);
    }
}

/// Connects and greets; a refusal is an error naming the server's reason.
fn connect(options: &ClientOptions) -> Result<Connection, NetError> {
    let mut conn = Connection::connect(&options.addr, options.timeout)?;
    let hello = Hello { version: PROTOCOL_VERSION, store: options.store, client: options.name.clone() };
    conn.send(&[Message::Hello(hello)])?;
    match conn.receive()? {
        Message::HelloReply(HelloReply::Accept { .. }) => Ok(conn),
        Message::HelloReply(HelloReply::Refuse { reason }) => {
            Err(NetError::Refused { peer: conn.peer().to_string(), reason })
        }
        other => Err(unexpected(&conn, "HelloReply", &other)),
    }
}

/// The newest camera, waiting for one (`None` when stopped or after a short wait, so the loop
/// looks at the stop flag).
fn next_camera(slot: &Slot, stop: &AtomicBool) -> Option<CameraRequest> {
    let mut camera = slot.camera.lock().ok()?;
    if camera.is_none() && !stop.load(Ordering::Relaxed) {
        camera = slot.ready.wait_timeout(camera, Duration::from_millis(50)).ok()?.0;
    }
    camera.take()
}

/// Sends one camera and rebuilds the set from the deltas up to the frame's sentinel.
fn exchange(
    conn: &mut Connection,
    set: &mut VisibleSet,
    camera: &CameraRequest,
) -> Result<RemoteSet, NetError> {
    let (sent0, received0) = (conn.bytes_sent(), conn.bytes_received());
    let start = Instant::now();
    conn.send(&[Message::Camera(*camera)])?;
    let (mut added, mut dropped) = (Vec::new(), Vec::new());
    let end: EndOfFrame = loop {
        match conn.receive()? {
            Message::VisibleDelta(d) if d.frame == camera.frame => {
                added.extend(d.added);
                dropped.extend(d.dropped);
            }
            Message::EndOfFrame(e) if e.frame == camera.frame => break e,
            Message::Bye => return Err(NetError::Closed { peer: conn.peer().to_string() }),
            other => {
                let expected = format!("VisibleDelta or EndOfFrame of frame {}", camera.frame);
                return Err(unexpected(conn, &expected, &other));
            }
        }
    };
    let round_trip = start.elapsed();
    let ids_received = (added.len() + dropped.len()) as u64;
    let wire =
        |source| NetError::Wire { peer: conn.peer().to_string(), offset: conn.bytes_received(), source };
    set.apply(added, dropped).map_err(wire)?;
    if set.len() != end.stats.visible as usize {
        let what = format!(
            "frame {}: {} ids after the delta, the server has {}",
            end.frame,
            set.len(),
            end.stats.visible
        );
        return Err(wire(WireError::Desync(what)));
    }
    Ok(RemoteSet {
        frame: camera.frame,
        set: set.clone(),
        stats: end.stats,
        bytes_sent: conn.bytes_sent() - sent0,
        bytes_received: conn.bytes_received() - received0,
        ids_received,
        round_trip,
    })
}

fn sleep_unless_stopped(total: Duration, stop: &AtomicBool) {
    let end = Instant::now() + total;
    while !stop.load(Ordering::Relaxed) {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        std::thread::sleep(left.min(Duration::from_millis(20)));
    }
}
