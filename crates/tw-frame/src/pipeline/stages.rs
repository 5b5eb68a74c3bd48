//! The stages of the parallel pipelines (see the module above): each a loop on a scoped thread
//! that takes a frame from the channel before it, does its step and hands the frame on.
//!
//! - [`select`] (S): the cut of each camera and the pages it holds.
//! - [`occluders_stage`] (GigaWalk's OR): the cut split by the visible set of two frames before, the
//!   occluders drawn on the OR device, its depth read back.
//! - [`cull`] (GigaWalk's STC): the HZB of that depth and the tests; the visible set goes to
//!   RVG and, as the history, back to OR.
//! - [`context`] (one of the switch's two occlusion contexts): occluders, then the tests, on
//!   one device that keeps its own history.
//! - [`render`] (RVG): the visible set drawn on the walkthrough's renderer, the image read back.
//! - [`whole`] (`select-ahead`'s one context, or one of `alternate`'s two): the serial frame's
//!   culling and drawing on one device, the image read back; [`in_order`] puts the contexts'
//!   frames back in order.

use std::sync::mpsc::{channel, sync_channel, Receiver, Sender, SyncSender};
use std::sync::Arc;
use std::thread::Scope;
use std::time::{Duration, Instant};

use tw_gpu::Renderer;
use tw_runtime::{
    Camera, ClusterRef, OcclusionHistory, OcclusionSplit, ResidentPage, SelectStats, Selection, StreamStats,
    Streamer,
};
use tw_store::{PageCluster, Store};

use super::{Pipe, Pipeline, PipelinedFrame, Submitted};
use crate::occlude::{cull_on, CullPlan, DepthFrame, OcclusionState, Tester, VisibleSet};
use crate::{
    lookup, page_bounds, select_and_stream, selection_times, triangles, Culled, FrameError, FrameInfo,
    FrameSettings, FrameTimes, Occlusion, Streamed, Walkthrough,
};

/// The frames' output: drawn frames, or the error of the stage that failed.
type Output = Sender<Result<PipelinedFrame, FrameError>>;

/// A frame's cut, as S hands it on: shared by the stages after it, holding its pages.
struct Cut {
    frame: u64,
    camera: Camera,
    submitted: Instant,
    pages: Vec<(u32, Arc<ResidentPage>)>,
    clusters: Vec<ClusterRef>,
    select: SelectStats,
    stream: StreamStats,
    times: FrameTimes,
}

impl Cut {
    fn decoded(&self) -> Vec<(ClusterRef, &PageCluster)> {
        lookup(&self.pages, &self.clusters)
    }

    fn bounds(&self) -> impl Fn(&ClusterRef) -> Option<([u32; 3], [u32; 3])> + Sync + '_ {
        |c| page_bounds(&self.pages, c)
    }
}

/// A frame whose occluders OR has drawn: the split it drew and the depth it read back
/// (`None` without occlusion culling), with the time the read-back waited.
struct Occluded {
    cut: Arc<Cut>,
    split: OcclusionSplit,
    depth: Option<DepthFrame>,
}

/// A culled frame, on its way to the render stage.
struct Tested {
    cut: Arc<Cut>,
    set: VisibleSet,
    culled: Culled,
}

/// Runs `kind` over `walk` (see [`Walkthrough::pipelined`]): the stages on scoped threads, the
/// body on this one.
pub(super) fn run<R>(
    walk: &mut Walkthrough,
    kind: Pipeline,
    settings: &FrameSettings,
    occluders: Vec<Renderer>,
    body: impl FnOnce(&mut Pipe) -> R,
) -> Result<R, FrameError> {
    let store = walk.streamer.store().clone();
    let settings = *settings;
    let size = walk.renderer.size();
    let (cameras_tx, cameras) = sync_channel::<Submitted>(0);
    let (out, frames) = channel();
    let pipe = Pipe { cameras: Some(cameras_tx), frames, submitted: 0, received: 0, kind, failed: None };
    if kind == Pipeline::Serial {
        // The serial frame behind the same pipe: one stage does everything.
        return std::thread::scope(|s| {
            spawn(s, "frames", out.clone(), move || serial(walk, &settings, cameras, out))?;
            Ok(drive(pipe, body))
        });
    }
    let Walkthrough { streamer, renderer, selection, .. } = walk;
    let pacer = Pacer::new(2);
    std::thread::scope(|s| {
        let store = &store;
        let mut occluders = occluders.into_iter();
        let mut next_device =
            || occluders.next().ok_or_else(|| FrameError::Pipeline("an occlusion device is missing".into()));
        match kind {
            Pipeline::Serial => unreachable!("run_serial runs it"),
            Pipeline::Gigawalk => {
                let (cut_tx, cut_rx) = sync_channel(0);
                let (occluded_tx, occluded_rx) = sync_channel(0);
                let (tested_tx, tested_rx) = sync_channel(0);
                let (history_tx, history_rx) = channel();
                let mut device = next_device()?;
                let o = out.clone();
                spawn(s, "select", o.clone(), move || {
                    select(streamer, selection, &settings, size, cameras, vec![cut_tx], None)
                })?;
                spawn(s, "occluders", o.clone(), move || {
                    occluders_stage(&mut device, store, &settings, cut_rx, history_rx, occluded_tx)
                })?;
                spawn(s, "cull", o, move || cull(store, &settings, occluded_rx, history_tx, tested_tx))?;
                let o = out.clone();
                spawn(s, "render", out, move || render(renderer, store, vec![tested_rx], o))?;
            }
            Pipeline::Switch => {
                let (mut cut_txs, mut tested_rxs) = (Vec::new(), Vec::new());
                for name in ["context-a", "context-b"] {
                    let (cut_tx, cut_rx) = sync_channel(0);
                    let (tested_tx, tested_rx) = sync_channel(0);
                    let mut device = next_device()?;
                    spawn(s, name, out.clone(), move || {
                        context(&mut device, store, &settings, cut_rx, tested_tx)
                    })?;
                    cut_txs.push(cut_tx);
                    tested_rxs.push(tested_rx);
                }
                spawn(s, "select", out.clone(), move || {
                    select(streamer, selection, &settings, size, cameras, cut_txs, None)
                })?;
                let o = out.clone();
                spawn(s, "render", out, move || render(renderer, store, tested_rxs, o))?;
            }
            Pipeline::SelectAhead | Pipeline::Alternate => {
                let (mut cut_txs, mut done_rxs) = (Vec::new(), Vec::new());
                let mut devices = vec![("frames-a", Device::Borrowed(renderer))];
                if kind == Pipeline::Alternate {
                    devices.push(("frames-b", Device::Owned(Box::new(next_device()?))));
                }
                // Only contexts that take turns need their hand-outs spaced.
                let pacer = (devices.len() > 1).then_some(&pacer);
                for (name, device) in devices {
                    let (cut_tx, cut_rx) = sync_channel(0);
                    // One finished frame may wait for its turn while the context goes on.
                    let (done_tx, done_rx) = sync_channel(1);
                    spawn(s, name, out.clone(), move || {
                        whole(device, store, &settings, cut_rx, done_tx, pacer)
                    })?;
                    cut_txs.push(cut_tx);
                    done_rxs.push(done_rx);
                }
                spawn(s, "select", out.clone(), move || {
                    select(streamer, selection, &settings, size, cameras, cut_txs, pacer)
                })?;
                let o = out.clone();
                spawn(s, "in-order", out, move || in_order(done_rxs, o))?;
            }
        }
        Ok(drive(pipe, body))
    })
}

/// Runs the caller's `body` on the pipe, then closes it: closing the cameras' channel stops the
/// first stage, then every stage after it in turn, and the scope joins them.
fn drive<R>(mut pipe: Pipe, body: impl FnOnce(&mut Pipe) -> R) -> R {
    let result = body(&mut pipe);
    drop(pipe);
    result
}

/// Starts stage `name` on a scoped thread: `work` runs until its input closes; an error it
/// returns, or a panic, is sent to `out` before the stage's channels close, so the caller sees
/// it before the end of the output.
fn spawn<'scope>(
    s: &'scope Scope<'scope, '_>,
    name: &str,
    out: Output,
    work: impl FnOnce() -> Result<(), FrameError> + Send + 'scope,
) -> Result<(), FrameError> {
    let stage = name.to_string();
    std::thread::Builder::new()
        .name(format!("tw-{name}"))
        .spawn_scoped(s, move || {
            // A panic is sent on as an error too: the stage before this one may be waiting for
            // a camera and keep the output open, so the caller would otherwise wait forever.
            let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(work))
                .unwrap_or_else(|_| Err(FrameError::Pipeline(format!("the {stage} stage panicked"))));
            if let Err(e) = result {
                let _ = out.send(Err(e));
            }
        })
        .map(|_| ())
        .map_err(|e| FrameError::Pipeline(format!("could not start the {name} stage: {e}")))
}

/// The serial frame as a stage: each camera's frame drawn with [`Walkthrough::draw_frame`] and
/// read back, on one thread.
fn serial(
    walk: &mut Walkthrough,
    settings: &FrameSettings,
    cameras: Receiver<Submitted>,
    out: Output,
) -> Result<(), FrameError> {
    for Submitted { frame, camera, at } in cameras {
        let mut drawn = walk.draw_frame(&camera, settings)?;
        let image = walk.renderer_mut().read_color()?;
        drawn.info.times.total = at.elapsed();
        if out.send(Ok(PipelinedFrame { frame, image, info: drawn.info, drawn: drawn.drawn })).is_err() {
            break;
        }
    }
    Ok(())
}

/// S: the cut of each camera and its pages (streamed: the frame never waits for the disk, or
/// with `wait_for_pages` loaded on the spot), handed to `next` in turn (frame i to
/// `next[i % len]`).
fn select(
    streamer: &mut Streamer,
    selection: &mut Selection,
    settings: &FrameSettings,
    viewport: (u32, u32),
    cameras: Receiver<Submitted>,
    next: Vec<SyncSender<Arc<Cut>>>,
    pacer: Option<&Pacer>,
) -> Result<(), FrameError> {
    let mut last_dispatch: Option<Instant> = None;
    for Submitted { frame, camera, at } in cameras {
        let start = Instant::now();
        let Streamed { pages, stats, times } =
            select_and_stream(streamer, selection, &camera, settings, viewport);
        let select = start.elapsed();
        let cut = Cut {
            frame,
            camera,
            submitted: at,
            pages,
            clusters: selection.clusters.clone(),
            select: selection.stats,
            stream: stats,
            times: selection_times(select, times),
        };
        if let Some(pacer) = pacer {
            pacer.wait_after(last_dispatch);
        }
        if next[(frame % next.len() as u64) as usize].send(Arc::new(cut)).is_err() {
            break;
        }
        last_dispatch = Some(Instant::now());
    }
    Ok(())
}

/// Frame pacing for contexts that take turns (`alternate`; the micro-stutter of alternate-frame
/// rendering): two contexts handed frames back to back finish them back to back, and the
/// frames come out in pairs, 1 ms then 90 ms apart (measured on the 10^8 walk). S therefore
/// hands a context its frame no sooner than a share of a context's frame time after the frame
/// before: with two contexts, half of it, so their frames come out evenly spaced.
pub(super) struct Pacer {
    contexts: u32,
    /// A context's time for one frame, cut in to image out, averaged (ns; 0: none yet).
    frame_ns: std::sync::atomic::AtomicU64,
}

impl Pacer {
    fn new(contexts: u32) -> Pacer {
        Pacer { contexts, frame_ns: std::sync::atomic::AtomicU64::new(0) }
    }

    /// A context took `busy` for a frame: into the running average (an eighth of the new one).
    fn record(&self, busy: Duration) {
        use std::sync::atomic::Ordering::Relaxed;
        let new = busy.as_nanos().min(u64::MAX as u128) as u64;
        let old = self.frame_ns.load(Relaxed);
        let avg = if old == 0 { new } else { old - old / 8 + new / 8 };
        self.frame_ns.store(avg, Relaxed);
    }

    /// The interval between two frames handed out.
    fn spacing(&self) -> Duration {
        Duration::from_nanos(self.frame_ns.load(std::sync::atomic::Ordering::Relaxed) / self.contexts as u64)
    }

    /// Waits until the spacing has passed since `last` (the previous frame handed out).
    fn wait_after(&self, last: Option<Instant>) {
        if let Some(due) = last.map(|l| l + self.spacing()) {
            if let Some(left) = due.checked_duration_since(Instant::now()) {
                std::thread::sleep(left);
            }
        }
    }
}

/// OR: frame i's cut split by the visible set of frame i−2 (`histories` brings one a frame,
/// from frame 0 on; frames 0 and 1 have none: no occluders, every cluster a candidate), the
/// occluders drawn on `device` with frame i's camera and its depth read back for STC.
fn occluders_stage(
    device: &mut Renderer,
    store: &Store,
    settings: &FrameSettings,
    cuts: Receiver<Arc<Cut>>,
    histories: Receiver<OcclusionHistory>,
    next: SyncSender<Occluded>,
) -> Result<(), FrameError> {
    let mut state = OcclusionState { triangle_culling: settings.triangle_culling, ..Default::default() };
    let grid_step = store.header().grid_step;
    for cut in cuts {
        if cut.frame >= 2 {
            match histories.recv() {
                Ok(h) => state.history = h,
                Err(_) => break,
            }
        }
        let decoded = cut.decoded();
        let plan = CullPlan::new(&state, &decoded);
        let depth = if settings.occlusion == Occlusion::None {
            None
        } else {
            device.begin_frame();
            plan.draw_first(settings.occlusion, &state, device, &cut.camera, grid_step, true)?;
            Some(DepthFrame::read(device)?)
        };
        let split = plan.into_split();
        drop(decoded);
        if next.send(Occluded { cut, split, depth }).is_err() {
            break;
        }
    }
    Ok(())
}

/// STC: the HZB of OR's depth and the tests of the frame's candidates and occluders (on the
/// rayon pool: every core left); the visible set goes to `next` and, as the history of a
/// later frame's occluders, to `histories`.
fn cull(
    store: &Store,
    settings: &FrameSettings,
    occluded: Receiver<Occluded>,
    histories: Sender<OcclusionHistory>,
    next: SyncSender<Tested>,
) -> Result<(), FrameError> {
    let mut state = OcclusionState { triangle_culling: settings.triangle_culling, ..Default::default() };
    for Occluded { cut, split, depth } in occluded {
        let tested = {
            let decoded = cut.decoded();
            match depth {
                None => Tested::whole(cut.clone()),
                Some(depth) => {
                    let plan = CullPlan::from_split(split, &decoded);
                    let bounds = cut.bounds();
                    let mut outcome = plan.test(
                        settings.occlusion,
                        &mut state,
                        Tester::Depth(depth),
                        store,
                        &cut.camera,
                        &bounds,
                    )?;
                    state.finish(&mut outcome);
                    Tested { cut: cut.clone(), set: outcome.visible_set, culled: outcome.culled }
                }
            }
        };
        // OR waits for this history two frames on; a closed OR is seen at the next send.
        let _ = histories.send(state.history.clone());
        if next.send(tested).is_err() {
            break;
        }
    }
    Ok(())
}

/// One occlusion context of the switch: it takes every other frame, splits the cut by the
/// visible set it found for its previous frame (two frames before), draws the occluders on its
/// own `device` and tests the candidates there (queries) or against its depth read back
/// (`hzb`).
fn context(
    device: &mut Renderer,
    store: &Store,
    settings: &FrameSettings,
    cuts: Receiver<Arc<Cut>>,
    next: SyncSender<Tested>,
) -> Result<(), FrameError> {
    let mut state = OcclusionState {
        triangle_culling: settings.triangle_culling,
        visible_pixels: settings.visible_pixels,
        ..Default::default()
    };
    for cut in cuts {
        let tested = if settings.occlusion == Occlusion::None {
            Tested::whole(cut)
        } else {
            let decoded = cut.decoded();
            device.begin_frame();
            let bounds = cut.bounds();
            let (_, mut outcome) =
                cull_on(settings.occlusion, &mut state, device, store, &cut.camera, &decoded, &bounds, true)?;
            state.finish(&mut outcome);
            drop(decoded);
            Tested { cut: cut.clone(), set: outcome.visible_set, culled: outcome.culled }
        };
        if next.send(tested).is_err() {
            break;
        }
    }
    Ok(())
}

impl Tested {
    /// A frame drawn without occlusion culling: the whole cut in one pass.
    fn whole(cut: Arc<Cut>) -> Tested {
        let set = VisibleSet::whole(cut.clusters.clone());
        let culled = Culled { drawn: cut.clusters.clone(), ..Default::default() };
        Tested { cut, set, culled }
    }
}

/// RVG: the frames' visible sets drawn on the walkthrough's `renderer` in submission order
/// (frame i from `tested[i % len]`, its tag checked), each image read back and sent to `out`
/// with the frame's figures.
fn render(
    renderer: &mut Renderer,
    store: &Store,
    tested: Vec<Receiver<Tested>>,
    out: Output,
) -> Result<(), FrameError> {
    let grid_step = store.header().grid_step;
    for expected in 0u64.. {
        let Ok(Tested { cut, set, culled }) = tested[(expected % tested.len() as u64) as usize].recv() else {
            break;
        };
        if cut.frame != expected {
            return Err(FrameError::Pipeline(format!(
                "frame {} reached the render stage where frame {expected} was due",
                cut.frame
            )));
        }
        let decoded = cut.decoded();
        set.draw(renderer, &cut.camera, grid_step, &decoded)?;
        let image = renderer.read_color()?;
        let info = frame_info(&cut, &culled, renderer, &decoded);
        drop(decoded);
        let frame = PipelinedFrame { frame: cut.frame, image, info, drawn: culled.drawn };
        if out.send(Ok(frame)).is_err() {
            break;
        }
    }
    Ok(())
}

/// A renderer a stage draws with: the walkthrough's own, or one the pipeline opened.
enum Device<'a> {
    Borrowed(&'a mut Renderer),
    Owned(Box<Renderer>),
}

impl Device<'_> {
    fn get(&mut self) -> &mut Renderer {
        match self {
            Device::Borrowed(r) => r,
            Device::Owned(r) => r,
        }
    }
}

/// A context of `select-ahead` (every frame) or `alternate` (every other frame): frames culled
/// and drawn whole on its `device`
/// ([`crate::occlude::draw_culled`], the serial frame's steps, with this context's own
/// history), its image read back and handed to [`in_order`].
fn whole(
    mut device: Device<'_>,
    store: &Store,
    settings: &FrameSettings,
    cuts: Receiver<Arc<Cut>>,
    next: SyncSender<PipelinedFrame>,
    pacer: Option<&Pacer>,
) -> Result<(), FrameError> {
    let renderer = device.get();
    let mut state = OcclusionState {
        triangle_culling: settings.triangle_culling,
        visible_pixels: settings.visible_pixels,
        ..Default::default()
    };
    for cut in cuts {
        let start = Instant::now();
        let decoded = cut.decoded();
        let culled = crate::occlude::draw_culled(
            settings.occlusion,
            &mut state,
            renderer,
            store,
            &cut.camera,
            &decoded,
            cut.bounds(),
        )?;
        let image = renderer.read_color()?;
        if let Some(pacer) = pacer {
            pacer.record(start.elapsed());
        }
        let info = frame_info(&cut, &culled, renderer, &decoded);
        drop(decoded);
        if next.send(PipelinedFrame { frame: cut.frame, image, info, drawn: culled.drawn }).is_err() {
            break;
        }
    }
    Ok(())
}

/// `select-ahead`'s or `alternate`'s frames back in submission order (frame i from `done[i % len]`, its tag
/// checked), to the output.
fn in_order(done: Vec<Receiver<PipelinedFrame>>, out: Output) -> Result<(), FrameError> {
    for expected in 0u64.. {
        let Ok(frame) = done[(expected % done.len() as u64) as usize].recv() else { break };
        if frame.frame != expected {
            return Err(FrameError::Pipeline(format!(
                "frame {} came out where frame {expected} was due",
                frame.frame
            )));
        }
        if out.send(Ok(frame)).is_err() {
            break;
        }
    }
    Ok(())
}

/// A pipelined frame's figures: S's selection and streaming, the culling's, the drawing
/// renderer's; `times.total` is the latency so far (submitted to now).
fn frame_info(
    cut: &Cut,
    culled: &Culled,
    renderer: &Renderer,
    decoded: &[(ClusterRef, &PageCluster)],
) -> FrameInfo {
    let cut_triangles = triangles(decoded);
    let figures = (cut.select, cut.stream, cut_triangles);
    FrameInfo::culled(cut.times, figures, culled, &renderer.stats(), cut.submitted.elapsed())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three stages wired as the pipelines wire theirs (rendezvous channels, [`spawn`], one
    /// output): the one at `failing` fails (or panics) at frame 3. The body gets frames 0–2, then that
    /// stage's error, further submits fail with it too, and the scope ends: no stage waits
    /// forever, whichever fails.
    fn chain_with_failure(failing: usize) {
        let (cameras_tx, cameras) = sync_channel::<Submitted>(0);
        let (out, frames) = channel();
        let mut pipe = Pipe {
            cameras: Some(cameras_tx),
            frames,
            submitted: 0,
            received: 0,
            kind: Pipeline::Gigawalk,
            failed: None,
        };
        let fail = |stage: usize, frame: u64| -> Result<(), FrameError> {
            if stage == failing && frame == 3 {
                return Err(FrameError::Pipeline(format!("stage {stage} failed at frame {frame}")));
            }
            if stage + 3 == failing && frame == 3 {
                panic!("stage {stage} panicked at frame {frame}");
            }
            Ok(())
        };
        let expected = if failing < 3 {
            format!("stage {failing} failed")
        } else {
            format!("the {} stage panicked", ["first", "second", "third"][failing - 3])
        };
        std::thread::scope(|s| {
            let (a_tx, a_rx) = sync_channel::<u64>(0);
            let (b_tx, b_rx) = sync_channel::<u64>(0);
            spawn(s, "first", out.clone(), move || {
                for c in cameras {
                    fail(0, c.frame)?;
                    if a_tx.send(c.frame).is_err() {
                        break;
                    }
                }
                Ok(())
            })
            .unwrap();
            spawn(s, "second", out.clone(), move || {
                for f in a_rx {
                    fail(1, f)?;
                    if b_tx.send(f).is_err() {
                        break;
                    }
                }
                Ok(())
            })
            .unwrap();
            let o = out.clone();
            spawn(s, "third", out, move || {
                for frame in b_rx {
                    fail(2, frame)?;
                    let image = tw_gpu::Image { width: 1, height: 1, rgba: vec![0; 4] };
                    let done = PipelinedFrame { frame, image, info: FrameInfo::default(), drawn: Vec::new() };
                    if o.send(Ok(done)).is_err() {
                        break;
                    }
                }
                Ok(())
            })
            .unwrap();
            let camera =
                Camera::new(glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Z, 1.0, 0.1, 100.0).unwrap();
            for expected in 0..3u64 {
                pipe.submit(&camera).unwrap();
                assert_eq!(pipe.receive().unwrap().frame, expected);
            }
            // Frame 3 fails somewhere; the error comes out of receive, or of the submits
            // that follow once the first stage has stopped.
            let error = match pipe.submit(&camera) {
                Err(e) => e,
                Ok(_) => match pipe.receive() {
                    Err(e) => e,
                    Ok(f) => panic!("frame {} came out of a failed stage", f.frame),
                },
            };
            assert!(error.to_string().contains(&expected), "{error}");
            // Later calls fail at once, naming the error, and never wait.
            for _ in 0..3 {
                let again = pipe.submit(&camera).unwrap_err().to_string();
                assert!(again.contains(&expected), "{again}");
                assert!(pipe.receive().is_err());
            }
            drop(pipe);
        });
    }

    #[test]
    fn a_failing_stage_stops_every_stage_and_its_error_comes_out() {
        // 0–2: stage k returns an error; 3–5: stage k − 3 panics.
        for failing in 0..6 {
            chain_with_failure(failing);
        }
    }
}
