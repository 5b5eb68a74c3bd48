//! `bench --cull-server`: frames whose visible set comes from a `terawalk cull-server`. Each
//! frame sends its camera, then draws the set the server sent for the frame before — one frame
//! of latency, as GigaWalk's pipeline and the occlusion switch have (GigaWalk §5; Govindaraju's
//! thesis §3.4): frame n is drawn with the set of frame n − 1 while n is being culled. When no
//! set has come within the timeout (a server gone, refusing, late, or sending garbage) the frame
//! is culled locally, logged once per outage, while the client reconnects in the background
//! (tw-net's `CullClient`). A set drawn one frame late may miss what frame n newly shows at the
//! frustum's edges or behind moving occluders; that is the latency the pipelines accept.

use std::time::Duration;

use anyhow::Result;
use tw_frame::remote::ClusterIds;
use tw_frame::{FrameInfo, FrameSettings, Walkthrough};
use tw_gpu::Image;
use tw_net::client::{ClientOptions, CullClient};
use tw_net::StoreId;
use tw_runtime::{Camera, ClusterRef};
use tw_store::Store;

use crate::commands::cull_server::request_of;

/// A bench run's frames through a cull server, and what they cost on the wire.
pub struct RemoteCulling {
    client: CullClient,
    ids: ClusterIds,
    wait: Duration,
    next_frame: u64,
    /// The newest server frame whose figures are in `totals` (a set serves several frames
    /// when the server lags; its bytes count once).
    counted: Option<u64>,
    totals: NetTotals,
}

/// Network figures of a run.
#[derive(Clone, Debug, Default)]
pub struct NetTotals {
    pub frames: u64,
    /// Frames drawn from a server's set, and the distinct server frames among them.
    pub remote_frames: u64,
    pub replies: u64,
    /// Frames culled locally (no set in time).
    pub fallbacks: u64,
    /// Over the distinct server frames drawn: bytes written (cameras) and read (deltas and
    /// sentinels), ids the deltas carried, ids full sets would have carried, visible clusters.
    pub bytes_sent: u64,
    pub bytes_received: u64,
    pub ids_sent: u64,
    pub ids_full: u64,
    /// Round trips (camera sent to sentinel received) and the server's culling times, ms.
    pub round_trip_ms: Vec<f64>,
    pub server_cull_ms: Vec<f64>,
}

impl NetTotals {
    /// The summary lines of a run (printed, and kept in the report's header).
    pub fn lines(&self, run: &str) -> Vec<(String, String)> {
        let n = self.replies.max(1) as f64;
        let median = |v: &[f64]| tw_report::stats::median(v).unwrap_or(0.0);
        let saved = 1.0 - self.ids_sent as f64 / self.ids_full.max(1) as f64;
        let visible = self.ids_full as f64 / n;
        let delta = self.ids_sent as f64 / n;
        vec![
            (
                format!("{run}: cull server frames"),
                format!(
                    "{} of {} ({} culled locally; {} server frames)",
                    self.remote_frames, self.frames, self.fallbacks, self.replies
                ),
            ),
            (
                format!("{run}: bytes per frame"),
                format!(
                    "sent {:.0}, received {:.0} (visible set {visible:.0} ids, delta {delta:.0} ids)",
                    self.bytes_sent as f64 / n,
                    self.bytes_received as f64 / n
                ),
            ),
            (
                format!("{run}: delta savings"),
                format!("{:.1} % of the ids a full set per frame would send", saved * 100.0),
            ),
            (
                format!("{run}: round trip"),
                format!(
                    "median {:.2} ms (server culling median {:.2} ms)",
                    median(&self.round_trip_ms),
                    median(&self.server_cull_ms)
                ),
            ),
        ]
    }
}

impl RemoteCulling {
    /// Starts a client of the server at `addr` for `store` (it connects in the background).
    pub fn start(addr: &str, store: &Store, wait: Duration) -> RemoteCulling {
        let options = ClientOptions {
            addr: addr.to_string(),
            store: StoreId::of(store),
            name: format!("terawalk bench (pid {})", std::process::id()),
            // The worker's own waits: a slow first frame (pages loaded with `--wait`) must not
            // count as a dead server; the frames meanwhile fall back after `wait`.
            timeout: wait.max(Duration::from_secs(10)),
            retry: Duration::from_millis(500),
        };
        RemoteCulling {
            client: CullClient::start(options),
            ids: ClusterIds::new(store),
            wait,
            next_frame: 0,
            counted: None,
            totals: NetTotals::default(),
        }
    }

    /// One frame (see the module): its image and statistics.
    pub fn frame(
        &mut self,
        walk: &mut Walkthrough,
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Result<(Image, FrameInfo)> {
        // The frame time includes the wait for the server's set.
        let start = std::time::Instant::now();
        let frame = self.next_frame;
        self.next_frame += 1;
        self.totals.frames += 1;
        self.client.request(request_of(frame, camera, settings, walk.renderer().size()));
        let Some(remote) = self.client.set_for(frame.saturating_sub(1), self.wait) else {
            self.totals.fallbacks += 1;
            let (image, mut info) = walk.frame(camera, settings)?;
            info.times.total = start.elapsed();
            return Ok((image, info));
        };
        let clusters: Vec<ClusterRef> =
            remote.set.ids().iter().filter_map(|&id| self.ids.cluster(id)).collect();
        if clusters.len() != remote.set.len() {
            tracing::warn!(
                "cull server frame {}: {} of {} ids are not clusters of this store",
                remote.frame,
                remote.set.len() - clusters.len(),
                remote.set.len()
            );
        }
        let t = &mut self.totals;
        t.remote_frames += 1;
        if self.counted.is_none_or(|c| c < remote.frame) {
            self.counted = Some(remote.frame);
            t.replies += 1;
            t.bytes_sent += remote.bytes_sent;
            t.bytes_received += remote.bytes_received;
            t.ids_sent += remote.ids_received;
            t.ids_full += remote.set.len() as u64;
            t.round_trip_ms.push(remote.round_trip.as_secs_f64() * 1e3);
            t.server_cull_ms.push(remote.stats.cull_us as f64 / 1e3);
        }
        let (image, mut info) = walk.frame_of_clusters(camera, &clusters)?;
        info.times.total = start.elapsed();
        Ok((image, info))
    }

    /// The figures since the last call (a run's), and a fresh count.
    pub fn take_totals(&mut self) -> NetTotals {
        std::mem::take(&mut self.totals)
    }
}
