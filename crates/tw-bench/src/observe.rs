//! What the method hands to its caller while it works, and what it asks of it: the running
//! account and progress (an [`Observer`]: `terawalk bench` prints it, a test may ignore it),
//! and culling done elsewhere ([`RemoteCulling`]: the method knows no transport; terawalk's
//! is tw-net's client).

use anyhow::Result;
use tw_frame::{FrameInfo, FrameSettings, Walkthrough};
use tw_gpu::Image;
use tw_report::{BenchReport, Run};
use tw_runtime::Camera;

/// Receives the benchmark's account as it happens, in order: lines, phases of frames, each run
/// when it is complete, the report before it is written.
pub trait Observer {
    /// A line of the running account (the adapter, a generated path, the cold start, …).
    fn line(&mut self, text: &str);
    /// `total` frames named `name` begin: the references, or a run.
    fn phase(&mut self, name: &str, total: u64);
    /// Frame `frame` of the phase is done (`measured`: of a run, not of the references).
    fn frame_done(&mut self, name: &str, frame: usize, measured: bool);
    /// The phase is over.
    fn end_phase(&mut self);
    /// A run is complete, with its network figures (`--cull-server`: (key, value) lines).
    fn run_done(&mut self, run: &Run, network: &[(String, String)]);
    /// The runs are complete; the report is written next.
    fn report_done(&mut self, report: &BenchReport);
}

/// An observer that ignores everything (tests, library use).
pub struct Silent;

impl Observer for Silent {
    fn line(&mut self, _: &str) {}
    fn phase(&mut self, _: &str, _: u64) {}
    fn frame_done(&mut self, _: &str, _: usize, _: bool) {}
    fn end_phase(&mut self) {}
    fn run_done(&mut self, _: &Run, _: &[(String, String)]) {}
    fn report_done(&mut self, _: &BenchReport) {}
}

/// Frames culled elsewhere (the occlusion switch's cull server): each frame drawn with a
/// visible set that came from outside, or culled locally when none came in time.
pub trait RemoteCulling {
    /// One frame: its image and statistics (the frame time includes the wait for the set).
    fn frame(
        &mut self,
        walk: &mut Walkthrough,
        camera: &Camera,
        settings: &FrameSettings,
    ) -> Result<(Image, FrameInfo)>;
    /// The network figures since the last call as (key, value) lines for run `run`, and a
    /// fresh count.
    fn take_lines(&mut self, run: &str) -> Vec<(String, String)>;
}

/// Starts the remote culling of a store once its walkthrough exists (the connection is made
/// in the background while the method goes on).
pub type StartRemote<'a> = &'a dyn Fn(&tw_store::Store) -> Box<dyn RemoteCulling>;
