//! Parallel frame pipelines (docs/RUNTIME.md "Pipelines"): the stages of a frame on threads of
//! their own and, for the occlusion stages, on GPU devices of their own, so that frame n is drawn
//! while frame n+1 is culled and frame n+2's occluders are rendered.
//!
//! - [`Pipeline::Serial`]: [`Walkthrough::frame`], one stage after the other on one thread.
//! - [`Pipeline::Gigawalk`] (GigaWalk §5): **S** selects and streams the cut of each camera;
//!   **OR** renders the frame's occluders, depth only, on a device of its own and reads its
//!   depth back;
//!   **STC** builds the HZB from it and tests the cut's candidates (on every core left);
//!   **RVG** draws the visible set on the walkthrough's renderer and reads the image. The
//!   occluders of frame i are the visible set of frame i−2 at frame i's LOD (the paper's
//!   choice: OR works on frame i while STC is still on frame i−1), so OR, STC and RVG work on
//!   three frames at once. Culls with `hzb` (or passes the cut through with `none`).
//! - [`Pipeline::Switch`] (the occlusion switch, Govindaraju's thesis §3.4, Fig. 3.2): two
//!   occlusion contexts, each on a device of its own with its own depth buffer, take the frames
//!   in turn; while one culls frame i (its hardware queries, or its depth read back into an
//!   HZB), the other renders frame i+1's occluders. Each context's occluders are the visible
//!   set it found two frames before, which it keeps (a depth buffer never leaves its device
//!   for `queries`). **S** and **RVG** are as above. Culls with `queries`, `hzb` or `none`.
//! - [`Pipeline::SelectAhead`]: **S** selects and streams frame i+1 while one context culls and
//!   draws frame i whole (the serial frame's steps) on the walkthrough's renderer: nothing is
//!   drawn twice, and the selection's single-threaded traversal overlaps the rasterization.
//!   Culls with every strategy.
//! - [`Pipeline::Alternate`]: the switch without its render context, for machines where every
//!   device shares the same cores (Mesa's CPU drivers): the two contexts each draw their frame
//!   whole, the serial two-pass frame on their own device with their own history (the
//!   walkthrough's renderer and one more), and the frames are put back in order. No geometry
//!   is drawn twice; two frames are culled and rasterized at once. Culls with every strategy.
//!
//! All stay conservative: every occluder is geometry of the frame's own cut drawn with the
//! frame's camera, so frame i's image is that of `--occlusion none` (the tests in
//! crates/tw-frame/tests/pipeline.rs compare them pixel for pixel on Vulkan and GL).
//!
//! The stages hand whole frames on over rendezvous channels (a frame's message is its
//! end-of-frame marker; its tag is checked in order where the frames meet again), so at most
//! one frame is in each stage: the frames in flight, and the decoded pages they hold beyond the
//! page cache's budget, are bounded by the number of stages. A stage that fails or panics sends
//! its error to the output and stops; the others then find their channels closed and stop too,
//! so no stage waits forever ([`Pipe::receive`] returns the error, and every later call too).

mod stages;

use std::sync::mpsc;
use std::time::Instant;

use serde::{Deserialize, Serialize};
use tw_gpu::Image;
use tw_runtime::{Camera, ClusterRef};

use crate::{FrameError, FrameInfo, FrameSettings, Occlusion, Walkthrough};

/// How a frame's stages run (`--pipeline`). Through [`Walkthrough::pipelined`], `Serial` is
/// [`Walkthrough::draw_frame`] and the read-back on one thread behind the same [`Pipe`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Pipeline {
    /// One stage after the other, on one thread.
    #[default]
    Serial,
    /// GigaWalk's occluder rendering, culling and rendering of the visible set as concurrent
    /// stages, one frame of latency.
    Gigawalk,
    /// Two occlusion contexts swapping roles every frame, plus the render context.
    Switch,
    /// Two contexts taking turns, each drawing its frames whole.
    Alternate,
    /// Selection on a thread of its own, one frame ahead of culling and drawing.
    SelectAhead,
}

impl Pipeline {
    pub const ALL: [Pipeline; 5] =
        [Pipeline::Serial, Pipeline::SelectAhead, Pipeline::Gigawalk, Pipeline::Switch, Pipeline::Alternate];

    pub fn name(self) -> &'static str {
        match self {
            Pipeline::Serial => "serial",
            Pipeline::Gigawalk => "gigawalk",
            Pipeline::Switch => "switch",
            Pipeline::Alternate => "alternate",
            Pipeline::SelectAhead => "select-ahead",
        }
    }

    /// The pipeline named `name` (as `--pipeline` spells it).
    pub fn parse(name: &str) -> Option<Pipeline> {
        Pipeline::ALL.into_iter().find(|p| p.name() == name.trim())
    }

    pub fn description(self) -> &'static str {
        match self {
            Pipeline::Serial => "serial stages",
            Pipeline::Gigawalk => "GigaWalk pipeline: select, occluders, culling and drawing on four threads, two devices",
            Pipeline::Switch => "occlusion switch: two occlusion contexts taking turns, select and drawing on threads of their own",
            Pipeline::Alternate => "alternate frames: two contexts on devices of their own each drawing every other frame whole, select on a thread of its own",
            Pipeline::SelectAhead => "select ahead: the next frame's selection and streaming on a thread of its own while this one is culled and drawn",
        }
    }

    /// Whether this pipeline can cull with `occlusion`, and why not: gigawalk culls on the CPU
    /// from the depth it reads back (`hzb`); the switch also with hardware queries on its own
    /// contexts; neither runs `gpu-hzb`, whose tests feed the same device's indirect draws.
    pub fn supports(self, occlusion: Occlusion) -> Result<(), String> {
        match (self, occlusion) {
            (Pipeline::Serial | Pipeline::SelectAhead | Pipeline::Alternate, _)
            | (_, Occlusion::None | Occlusion::Hzb) => Ok(()),
            (Pipeline::Switch, Occlusion::Queries) => Ok(()),
            (p, o) => Err(format!(
                "--pipeline {} cannot cull with --occlusion {}: {}",
                p.name(),
                o.name(),
                match o {
                    Occlusion::Queries =>
                        "its culling stage reads a depth buffer back (use --pipeline switch for queries)",
                    _ => "the GPU's tests feed the same device's indirect draws (use --pipeline serial)",
                }
            )),
        }
    }

    /// Frames to submit ahead so that every stage has one: the stages after the caller.
    pub fn depth(self) -> usize {
        match self {
            Pipeline::Serial => 1,
            Pipeline::Gigawalk => 4,
            Pipeline::Switch => 4,
            Pipeline::Alternate => 3,
            Pipeline::SelectAhead => 2,
        }
    }
}

/// A frame that came out of a pipeline.
#[derive(Debug)]
pub struct PipelinedFrame {
    /// Which camera it is: 0 for the first submitted to the pipe, then 1, 2, …
    pub frame: u64,
    pub image: Image,
    /// Its statistics; `times.total` is its latency (from [`Pipe::submit`] to the image read
    /// back); `times.select` is S's, `times.cull` the culling's (the depth read back included),
    /// `times.upload` and `times.render` the render stage's.
    pub info: FrameInfo,
    /// The clusters drawn (both passes).
    pub drawn: Vec<ClusterRef>,
}

/// A camera on its way in: its tag and when it was submitted.
struct Submitted {
    frame: u64,
    camera: Camera,
    at: Instant,
}

/// The caller's end of a running pipeline: cameras in, frames out, in order.
pub struct Pipe {
    cameras: Option<mpsc::SyncSender<Submitted>>,
    frames: mpsc::Receiver<Result<PipelinedFrame, FrameError>>,
    submitted: u64,
    received: u64,
    kind: Pipeline,
    /// The error the pipeline stopped on, once it came out: later calls return it at once
    /// rather than wait on stages that may wait for cameras.
    failed: Option<String>,
}

impl Pipe {
    /// Hands the next camera to the pipeline; blocks while its first stage is busy. Returns the
    /// frame's tag. Fails when the pipeline has stopped on an error (that error).
    pub fn submit(&mut self, camera: &Camera) -> Result<u64, FrameError> {
        self.check_failed()?;
        let frame = self.submitted;
        let sent = match &self.cameras {
            Some(tx) => tx.send(Submitted { frame, camera: *camera, at: Instant::now() }).is_ok(),
            None => false,
        };
        if !sent {
            self.cameras = None;
            return Err(self.stopped_error());
        }
        self.submitted += 1;
        Ok(frame)
    }

    /// The next frame, in submission order; blocks until it is drawn. Fails when a stage
    /// failed, or when no frame is in flight.
    pub fn receive(&mut self) -> Result<PipelinedFrame, FrameError> {
        self.check_failed()?;
        if self.received == self.submitted {
            return Err(FrameError::Pipeline("no frame in flight: submit a camera first".into()));
        }
        match self.frames.recv() {
            Ok(Ok(frame)) => {
                self.received += 1;
                Ok(frame)
            }
            Ok(Err(e)) => Err(self.fail(e)),
            Err(_) => Err(self.fail(FrameError::Pipeline("the pipeline stopped".into()))),
        }
    }

    /// The error the pipeline stopped on, if it has.
    fn check_failed(&self) -> Result<(), FrameError> {
        match &self.failed {
            Some(e) => Err(FrameError::Pipeline(format!("stopped earlier: {e}"))),
            None => Ok(()),
        }
    }

    /// Remembers that the pipeline stopped on `e`, and returns it.
    fn fail(&mut self, e: FrameError) -> FrameError {
        self.failed = Some(e.to_string());
        self.cameras = None;
        e
    }

    /// Frames submitted and not yet received.
    pub fn in_flight(&self) -> u64 {
        self.submitted - self.received
    }

    pub fn kind(&self) -> Pipeline {
        self.kind
    }

    /// The error a stage sent before the pipeline stopped (the stages stop in a cascade once
    /// one has failed, so it comes before the output closes).
    fn stopped_error(&mut self) -> FrameError {
        while let Ok(item) = self.frames.recv() {
            if let Err(e) = item {
                return self.fail(e);
            }
        }
        self.fail(FrameError::Pipeline("the pipeline stopped".into()))
    }
}

impl Walkthrough {
    /// Runs `body` with a [`Pipe`] into a `kind` pipeline over this walkthrough: its streamer
    /// serves the select stage, its renderer the render stage, and the occlusion stages open
    /// devices of their own ([`tw_gpu::Renderer::sibling`]). Every frame uses `settings`.
    /// When `body` returns, the frames still in flight are finished and dropped and the
    /// stages stop; the walkthrough then holds the last frame's selection, and its occlusion
    /// history is forgotten (the pipeline's was its own).
    pub fn pipelined<R>(
        &mut self,
        kind: Pipeline,
        settings: &FrameSettings,
        body: impl FnOnce(&mut Pipe) -> R,
    ) -> Result<R, FrameError> {
        kind.supports(settings.occlusion).map_err(FrameError::Pipeline)?;
        if settings.transition != crate::Transition::Pop && kind != Pipeline::Serial {
            return Err(FrameError::Pipeline(format!(
                "--pipeline {} does not cross-fade LOD switches yet (use --pipeline serial with --transition {})",
                kind.name(),
                settings.transition.name()
            )));
        }
        if settings.shadows.is_some() {
            return Err(FrameError::Pipeline(format!(
                "--pipeline {} does not draw shadows yet (use --pipeline serial with --light)",
                kind.name()
            )));
        }
        let contexts = match kind {
            Pipeline::Serial | Pipeline::SelectAhead => 0,
            Pipeline::Gigawalk | Pipeline::Alternate => 1,
            Pipeline::Switch => 2,
        };
        let mut occluders = Vec::with_capacity(contexts);
        for _ in 0..contexts {
            let mut device = self.renderer.sibling()?;
            device.set_store_colors(self.streamer.store());
            occluders.push(device);
        }
        self.occlusion.reset();
        let result = stages::run(self, kind, settings, occluders, body);
        self.occlusion.reset();
        result
    }
}
