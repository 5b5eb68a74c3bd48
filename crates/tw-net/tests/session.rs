//! Sessions over loopback TCP with a fake culler: handshake refusals, deltas, several clients
//! at once, and a server that dies in the middle of a frame.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use tw_net::client::{ClientOptions, CullClient};
use tw_net::server::{serve, Culled, Culler, ServeSummary, ServerOptions};
use tw_net::transport::Listener;
use tw_net::{CameraRequest, Message, StoreId, VisibleDelta};

const STORE: StoreId = StoreId([7; 16]);

/// The visible set of frame f: ids f..f+100 (so consecutive frames share 99 of 100).
struct Sliding;

impl Culler for Sliding {
    fn cull(&mut self, r: &CameraRequest) -> Result<Culled, String> {
        let f = r.frame as u32;
        Ok(Culled { ids: (f..f + 100).collect(), triangles: 100 })
    }
}

fn camera(frame: u64) -> CameraRequest {
    CameraRequest {
        frame,
        eye: [0.0; 3],
        target: [1.0, 0.0, 0.0],
        up: [0.0, 0.0, 1.0],
        fovy: 1.0,
        near: 0.1,
        far: 10.0,
        viewport: [64, 48],
        tau: 1.0,
        occlusion: 0,
        flags: CameraRequest::FRUSTUM_CULLING,
        visible_pixels: 0,
    }
}

fn options(addr: &str, store: StoreId) -> ClientOptions {
    ClientOptions {
        addr: addr.to_string(),
        store,
        name: "test".into(),
        timeout: Duration::from_secs(2),
        retry: Duration::from_millis(50),
    }
}

/// Runs `body` against a server of `Sliding` on a free port, then stops the server.
fn with_server(body: impl FnOnce(&str, &ServeSummary)) {
    let listener = Listener::bind("127.0.0.1:0", Duration::from_secs(2)).unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let stop = AtomicBool::new(false);
    let summary = ServeSummary::default();
    let server = ServerOptions { store: STORE, name: "test server".into() };
    std::thread::scope(|s| {
        s.spawn(|| serve(&listener, &server, &stop, &summary, |_| Ok(Sliding)).unwrap());
        let _stop = StopOnDrop(&stop);
        body(&addr, &summary);
    });
}

/// Stops a server when dropped, also when a test's assertion unwinds (else the scope would
/// wait for the server forever and the failure would show as a hang).
struct StopOnDrop<'a>(&'a AtomicBool);

impl Drop for StopOnDrop<'_> {
    fn drop(&mut self) {
        self.0.store(true, Ordering::Relaxed);
    }
}

/// Frame by frame: request, then wait for that frame's set (long enough for a loaded test host).
fn frames(client: &mut CullClient, range: std::ops::Range<u64>) -> Vec<tw_net::client::RemoteSet> {
    range
        .map(|f| {
            client.request(camera(f));
            client.set_for(f, Duration::from_secs(5)).unwrap_or_else(|| panic!("no set for frame {f}"))
        })
        .collect()
}

#[test]
fn deltas_rebuild_each_frames_set_and_save_ids() {
    with_server(|addr, summary| {
        let mut client = CullClient::start(options(addr, STORE));
        let sets = frames(&mut client, 0..10);
        for (f, r) in sets.iter().enumerate() {
            let f = f as u32;
            assert_eq!(r.set.ids(), (f..f + 100).collect::<Vec<_>>().as_slice());
            assert_eq!(r.stats.visible, 100);
            // Frame 0 sends the full set, later frames one added and one dropped id.
            assert_eq!(r.ids_received, if f == 0 { 100 } else { 2 });
            assert!(r.bytes_received > 0 && r.bytes_sent > 0);
        }
        drop(client);
        assert_eq!(summary.frames.load(Ordering::Relaxed), 10);
    });
}

/// Frame n is drawn with frame n − 1's set (one frame of latency): asking for it after
/// sending n's camera returns at once, without waiting for n.
#[test]
fn the_previous_frames_set_serves_without_waiting() {
    with_server(|addr, _| {
        let mut client = CullClient::start(options(addr, STORE));
        client.request(camera(0));
        assert_eq!(client.set_for(0, Duration::from_secs(5)).unwrap().frame, 0);
        for f in 1..20 {
            client.request(camera(f));
            let r = client.set_for(f - 1, Duration::from_secs(5)).unwrap();
            assert!(r.frame == f - 1 || r.frame == f, "frame {f} got the set of {}", r.frame);
            assert_eq!(r.set.ids().first(), Some(&(r.frame as u32)));
        }
    });
}

#[test]
fn several_clients_at_once_each_get_their_own_deltas() {
    with_server(|addr, summary| {
        std::thread::scope(|s| {
            for k in 0..4u64 {
                s.spawn(move || {
                    let mut client = CullClient::start(options(addr, STORE));
                    // Each client walks its own frames: its deltas are against its own last set.
                    let sets = frames(&mut client, k * 50..k * 50 + 5);
                    assert_eq!(sets[0].ids_received, 100);
                    assert!(sets[1..].iter().all(|r| r.ids_received == 2));
                });
            }
        });
        assert_eq!(summary.clients.load(Ordering::Relaxed), 4);
    });
}

#[test]
fn a_client_of_another_store_is_refused_naming_both() {
    with_server(|addr, summary| {
        let other = StoreId::new(1, 2, 3);
        let mut client = CullClient::start(options(addr, other));
        client.request(camera(0));
        assert!(client.set_for(0, Duration::from_millis(500)).is_none());
        assert!(summary.refused.load(Ordering::Relaxed) >= 1);
        // The refusal's text, as the client receives it.
        let mut conn = tw_net::transport::Connection::connect(addr, Duration::from_secs(2)).unwrap();
        let hello = tw_net::Hello { version: tw_net::PROTOCOL_VERSION, store: other, client: "c".into() };
        conn.send(&[Message::Hello(hello)]).unwrap();
        let Message::HelloReply(tw_net::HelloReply::Refuse { reason }) = conn.receive().unwrap() else {
            panic!("not refused")
        };
        assert!(reason.contains(&other.to_string()) && reason.contains(&STORE.to_string()), "{reason}");
        // And another protocol version.
        let mut conn = tw_net::transport::Connection::connect(addr, Duration::from_secs(2)).unwrap();
        let hello = tw_net::Hello { version: 99, store: STORE, client: "c".into() };
        conn.send(&[Message::Hello(hello)]).unwrap();
        let Message::HelloReply(tw_net::HelloReply::Refuse { reason }) = conn.receive().unwrap() else {
            panic!("not refused")
        };
        assert!(reason.contains("version 99"), "{reason}");
    });
}

/// A server that accepts, sends half a frame and dies: the client falls back at once (no wait
/// for its timeout on later frames), and reconnects when a server answers again. The listening
/// socket stays open throughout (a port given up could be taken by another test's server).
#[test]
fn a_server_dying_mid_frame_means_local_frames_then_a_reconnect() {
    let listener = Listener::bind("127.0.0.1:0", Duration::from_secs(2)).unwrap();
    let addr = listener.local_addr().unwrap().to_string();
    let mut client = CullClient::start(options(&addr, STORE));
    {
        let mut conn = listener.accept_within(Duration::from_secs(5)).unwrap().unwrap();
        assert!(matches!(conn.receive().unwrap(), Message::Hello(_)));
        let accept = Message::HelloReply(tw_net::HelloReply::Accept { server: "dying".into() });
        conn.send(&[accept]).unwrap();
        client.request(camera(0));
        assert!(matches!(conn.receive().unwrap(), Message::Camera(_)));
        conn.send(&[Message::VisibleDelta(VisibleDelta { frame: 0, added: vec![1, 2], dropped: vec![] })])
            .unwrap();
        conn.shutdown();
    }
    assert!(client.set_for(0, Duration::from_secs(5)).is_none(), "half a frame gave a set");
    // While no server answers (the client's new connections wait in the backlog, unanswered),
    // frames fall back at once.
    let start = std::time::Instant::now();
    for f in 1..5 {
        client.request(camera(f));
        assert!(client.set_for(f, Duration::from_secs(5)).is_none());
    }
    assert!(start.elapsed() < Duration::from_secs(1), "fallback frames waited {:?}", start.elapsed());
    assert!(client.fallbacks >= 5);
    // A server answering again: the client reconnects and gets full sets again.
    let stop = AtomicBool::new(false);
    let summary = ServeSummary::default();
    let server = ServerOptions { store: STORE, name: "back".into() };
    std::thread::scope(|s| {
        s.spawn(|| serve(&listener, &server, &stop, &summary, |_| Ok(Sliding)).unwrap());
        let _stop = StopOnDrop(&stop);
        let deadline = std::time::Instant::now() + Duration::from_secs(20);
        let mut f = 5;
        let got = loop {
            // As a render client does: the set of frame f is asked for a frame later.
            client.request(camera(f));
            std::thread::sleep(Duration::from_millis(50));
            if let Some(r) = client.set_for(f, Duration::from_millis(200)) {
                break r;
            }
            assert!(std::time::Instant::now() < deadline, "no reconnection");
            f += 1;
        };
        assert_eq!(got.set.len(), 100);
        assert_eq!(got.ids_received, 100, "a new session starts from the full set");
        drop(client);
    });
}
