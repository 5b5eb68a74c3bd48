//! Occlusion culling strategies behind one interface (docs/DESIGN.md, D6), applied to a frame's
//! LOD cut. All of them are two-pass and conservative:
//!
//! 1. **occluders**: the clusters of this frame's cut that were visible last frame
//!    ([`OcclusionHistory::split`]) — taken from *this* frame's cut, so they are drawn at the
//!    frame's own LOD, the condition under which GigaWalk's test gives the same image as no
//!    culling (Baxter et al. 2002 §4, "same LOD for occluders and display");
//! 2. the occluders are drawn (colour and depth);
//! 3. the other clusters of the cut (the candidates) are tested against that depth:
//!    - [`Occlusion::Hzb`] (GigaWalk §4.2): the depth is read back, a hierarchical Z pyramid is
//!      built on the CPU ([`tw_runtime::Hzb`]) and the candidates are tested there top-down
//!      ([`tw_runtime::occlusion::test_clusters_hierarchically`]): the skeleton nodes holding
//!      them breadth-first by level (thesis Alg. 3.4.1, as the queries below), then a box per
//!      group, then the boxes of the candidates under no hidden node or group, each round's
//!      boxes in parallel — a hidden node culls its subtree with one test, where a flat test
//!      ([`tw_runtime::occlusion::HierarchyOptions::FLAT`]) tests every candidate;
//!    - [`Occlusion::Queries`] (Yoon et al. 2003 §5.3; Govindaraju's occlusion switch):
//!      hardware occlusion queries against the depth buffer (sample counts on Vulkan, booleans
//!      on GL), first of the skeleton nodes holding candidates, breadth-first by level in one
//!      batch a level (thesis Alg. 3.4.1, [`tw_runtime::node_test`]; a hidden node culls its
//!      subtree's candidates), then one batch of the remaining candidates' boxes. Node tests
//!      run only while they pay: a probe frame measures their time against the cluster
//!      queries they save, and they are left out for 15 frames when they did not
//!      ([`tw_runtime::NodeTestSwitch`]);
//!    - [`Occlusion::GpuHzb`] (Greene et al. 1993, two-pass as in GPU-driven renderers): the
//!      pyramid is built and the boxes tested in compute shaders that write the second pass's
//!      indirect draws, with no CPU round trip in between (the crate's `gpu_hzb` module);
//! 4. the visible candidates are drawn on top in the same frame (nothing is missing when
//!    visibility changes: the papers' one-frame-late artefacts do not occur);
//! 5. the history becomes the candidates drawn plus the occluders still visible (the HZB tests
//!    the occluders too; with queries every occluder stays), so it follows visibility.
//!
//! Candidates are clusters, the finest unit the cut has; a cluster's box is its vertex grid box.
//! `hzb` goes one level finer ([`crate::FrameSettings::triangle_culling`], on by default): the
//! triangles of every cluster that passed its box test are tested against the same pyramid
//! ([`tw_runtime::triangle_test`]), the second pass draws the visible candidates' triangles
//! and the occluders' visible triangles their first pass left out, and the history keeps each
//! cluster's visible triangles, which are all the next first pass draws. The triangles an
//! occluder drew in its first pass are tested only every `RETEST_PERIOD`-th frame (they are
//! in the image either way; only the history learns from their test).

use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use tw_gpu::{wgpu, Renderer, Target};
use tw_runtime::frustum::grid_box;
use tw_runtime::node_test::parents;
use tw_runtime::occlusion::{test_boxes, test_clusters_hierarchically, HierarchyOptions, Skeleton};
use tw_runtime::{
    test_hierarchy, test_triangles, Camera, ClusterRef, Hzb, HzbResult, NodeTestOptions, NodeTestResult,
    NodeTestSwitch, OcclusionHistory, OcclusionSplit, OcclusionTest, TriangleMask,
};
use tw_store::{PageCluster, Store};

use crate::FrameError;

/// The occlusion culling strategy (`--occlusion`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Occlusion {
    /// No occlusion culling: the whole LOD cut is drawn.
    #[default]
    None,
    /// Two-pass culling against a CPU hierarchical Z-buffer of last frame's visible set.
    Hzb,
    /// Two-pass culling with hardware occlusion queries of the candidates' boxes.
    Queries,
    /// Two-pass culling against a hierarchical Z-buffer built and tested in compute shaders,
    /// feeding indirect draws.
    GpuHzb,
}

impl Occlusion {
    pub const ALL: [Occlusion; 4] = [Occlusion::None, Occlusion::Hzb, Occlusion::Queries, Occlusion::GpuHzb];

    pub fn name(self) -> &'static str {
        match self {
            Occlusion::None => "none",
            Occlusion::Hzb => "hzb",
            Occlusion::Queries => "queries",
            Occlusion::GpuHzb => "gpu-hzb",
        }
    }

    /// The strategy named `name` (as `--occlusion` spells it).
    pub fn parse(name: &str) -> Option<Occlusion> {
        Occlusion::ALL.into_iter().find(|o| o.name() == name.trim())
    }

    /// The fastest conservative strategy for a device (`--occlusion auto`, the default). All
    /// four give the image of `none`; what differs is speed. Measured (docs/benchmarks-log.md) on
    /// Mesa's CPU drivers, lavapipe and llvmpipe: `hzb` is the fastest (8.2–8.6× `none` over the
    /// 10^8-triangle plant's walk and fly-over, `gpu-hzb` 4.2–4.3×: building the pyramid in
    /// compute costs more than on the CPU there; "after the shader fix"). On a real GPU, `gpu-hzb`
    /// (no depth read-back, the culling feeding indirect draws on the GPU) where compute and
    /// indirect draws exist, else `hzb`.
    /// Measured once, on an NVIDIA H200 (docs/benchmarks-log.md, "On a real GPU"): the frames there
    /// are CPU-bound and the strategies close — gpu-hzb 1.04× none at 10^7 (hzb 0.79×), 1.00× at
    /// 10^8 (hzb 1.27×) — while gpu-hzb draws 6–87× fewer triangles than none; so it stays.
    pub fn fastest_conservative(device: wgpu::DeviceType, gpu_cull_supported: bool) -> Occlusion {
        match device {
            wgpu::DeviceType::Cpu => Occlusion::Hzb,
            _ if gpu_cull_supported => Occlusion::GpuHzb,
            _ => Occlusion::Hzb,
        }
    }

    /// [`fastest_conservative`](Self::fastest_conservative) for `renderer`'s device.
    pub fn fastest_for(renderer: &Renderer) -> Occlusion {
        Occlusion::fastest_conservative(renderer.info().device_type, renderer.gpu_cull_supported().is_ok())
    }

    pub fn description(self) -> &'static str {
        match self {
            Occlusion::None => "no occlusion culling",
            Occlusion::Hzb => "two-pass, CPU hierarchical Z-buffer (GigaWalk)",
            Occlusion::Queries => "two-pass, hardware occlusion queries (Yoon 2003, occlusion switch)",
            Occlusion::GpuHzb => "two-pass, hierarchical Z-buffer in compute shaders, indirect draws",
        }
    }
}

/// What occlusion culling did in one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct OcclusionStats {
    /// Clusters drawn in the first pass (visible last frame).
    pub occluders: u64,
    /// Clusters tested against the occluders' depth.
    pub tested: u64,
    /// Tested clusters hidden behind the occluders (not drawn).
    pub culled: u64,
    /// Tested clusters covering no pixel centre (not drawn; HZB only).
    pub no_pixels: u64,
    /// Hardware occlusion queries issued (node boxes and cluster boxes).
    pub queries: u64,
    /// Skeleton node boxes tested before the clusters (`queries` and `hzb`; Alg. 3.4.1), and of
    /// those found hidden (each culls the candidates under it).
    pub node_tests: u64,
    pub nodes_hidden: u64,
    /// `hzb`: group boxes (the union of a group's candidates) tested between the nodes and the
    /// clusters, and of those found hidden.
    #[serde(default)]
    pub group_tests: u64,
    #[serde(default)]
    pub groups_hidden: u64,
}

/// Frame-to-frame state of the strategies.
#[derive(Debug, Default)]
pub struct OcclusionState {
    pub(crate) history: OcclusionHistory,
    /// The queries' visible-pixel cut-off ([`crate::FrameSettings::visible_pixels`]).
    pub visible_pixels: u32,
    /// The store skeleton's parent links (for the node tests), made on first use.
    pub(crate) parents: Vec<u32>,
    /// Whether the queries' node tests pay here (measured frame by frame).
    pub(crate) node_switch: NodeTestSwitch,
    /// `hzb` only: also test the triangles of visible clusters
    /// ([`crate::FrameSettings::triangle_culling`]).
    pub triangle_culling: bool,
    /// Frames drawn with occlusion culling (staggers the occluders' triangle re-tests).
    pub(crate) frames: u64,
    /// `hzb` only: which boxes above the clusters are tested first (nodes and groups by
    /// default; [`HierarchyOptions::FLAT`]: every candidate's own box, as GigaWalk).
    pub hierarchy: HierarchyOptions,
    /// `hzb` only: whether those tests pay here, measured frame by frame as the queries' are
    /// (their time against the cluster tests they save). Measured on the CPU drivers they did
    /// not always: on a fly-over of a 2·10^6-triangle assembly no node box was ever hidden, and
    /// ~5,000 node tests over 40 frames made the box tests 0.8 ms a frame instead of 0.6.
    pub(crate) hzb_switch: NodeTestSwitch,
    /// `hzb` only: test `hierarchy` in every frame, whether it pays or not (to measure it).
    pub hierarchy_forced: bool,
}

impl OcclusionState {
    /// The clusters last frame found visible (next frame's occluders).
    pub(crate) fn history(&self) -> &OcclusionHistory {
        &self.history
    }
}

/// Every how many frames an occluder's triangles drawn in the first pass are tested again
/// (see [`draw_culled`]); the others only keep them in the history.
const RETEST_PERIOD: u64 = 4;

/// Whether `cluster`'s first-pass triangles are tested again in frame `frame`: every
/// [`RETEST_PERIOD`]-th frame, at a phase set by the cluster, so the re-tests spread evenly.
fn retest(cluster: &ClusterRef, frame: u64) -> bool {
    let phase = (cluster.page as u64).wrapping_mul(0x9E37_79B9).wrapping_add(cluster.index_in_page as u64);
    phase.wrapping_add(frame).is_multiple_of(RETEST_PERIOD)
}

impl OcclusionState {
    pub fn reset(&mut self) {
        self.history.clear();
        self.node_switch = NodeTestSwitch::default();
        self.hzb_switch = NodeTestSwitch::default();
    }
}

/// What [`draw_culled`] did: the occlusion statistics and which clusters were drawn or hidden.
#[derive(Clone, Debug, Default)]
pub struct Culled {
    pub stats: OcclusionStats,
    pub cull_time: Duration,
    /// Of `cull_time`, `hzb` only: the box tests (nodes, groups, candidates, occluders).
    pub box_test_time: Duration,
    /// Of `cull_time`, `hzb` with triangle tests only: the triangle tests.
    pub triangle_test_time: Duration,
    /// Of `cull_time`, `hzb` only: reading the first pass's depth back, which waits for that
    /// pass to be drawn (on a CPU driver, the first pass's rasterization).
    pub readback_time: Duration,
    /// The clusters drawn (both passes; with [`Occlusion::None`] the whole cut).
    pub drawn: Vec<ClusterRef>,
    /// Tested clusters hidden behind the occluders (HZB: not those covering no pixel centre,
    /// unless a hidden node or group box culled them with the rest under it).
    pub occluded: Vec<ClusterRef>,
}

/// Draws a frame's cut with the strategy, without reading the image back (`Walkthrough::frame`
/// reads it after): the frame stays in the renderer's own colour target
/// ([`Renderer::color_texture`]), for a viewer that shows it without waiting (only the
/// strategies' own read-backs wait: the depth for `hzb`, the query results for `queries`).
/// Also returns the clusters drawn and those found occluded (the debug view's boxes).
pub fn draw_culled(
    strategy: Occlusion,
    state: &mut OcclusionState,
    renderer: &mut Renderer,
    store: &Store,
    camera: &Camera,
    clusters: &[(ClusterRef, &PageCluster)],
    bounds: impl Fn(&ClusterRef) -> Option<([u32; 3], [u32; 3])> + Sync,
) -> Result<Culled, FrameError> {
    let grid_step = store.header().grid_step;
    renderer.begin_frame();
    if strategy == Occlusion::None {
        renderer.draw(Target::Own, camera, grid_step, clusters, true)?;
        return Ok(Culled { drawn: clusters.iter().map(|c| c.0).collect(), ..Default::default() });
    }
    if strategy == Occlusion::GpuHzb {
        return crate::gpu_hzb::draw_gpu_hzb(state, renderer, grid_step, camera, clusters, bounds);
    }
    let (cull, mut tested) = cull_on(strategy, state, renderer, store, camera, clusters, &bounds, false)?;
    cull.draw_second(renderer, camera, grid_step, &tested.visible_set)?;
    state.finish(&mut tested);
    Ok(tested.culled)
}

/// The steps of `hzb` and `queries` up to the second pass, all on `renderer` (whose frame the
/// caller has begun): the cut split by `state`'s history, the occluders drawn (with
/// `depth_only`, the depth alone), the candidates tested against them. The history is not
/// updated yet ([`OcclusionState::finish`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn cull_on<'a, B>(
    strategy: Occlusion,
    state: &mut OcclusionState,
    renderer: &mut Renderer,
    store: &Store,
    camera: &Camera,
    clusters: &[(ClusterRef, &'a PageCluster)],
    bounds: &B,
    depth_only: bool,
) -> Result<(CullPlan<'a>, CullOutcome), FrameError>
where
    B: Fn(&ClusterRef) -> Option<([u32; 3], [u32; 3])> + Sync,
{
    let plan = CullPlan::new(state, clusters);
    plan.draw_first(strategy, state, renderer, camera, store.header().grid_step, depth_only)?;
    let tester = match strategy {
        Occlusion::Hzb => Tester::Depth(DepthFrame::read(renderer)?),
        _ => Tester::Queries(renderer),
    };
    let outcome = plan.test(strategy, state, tester, store, camera, bounds)?;
    Ok((plan, outcome))
}

/// What a frame draws after occlusion culling, pass by pass: the first pass (the occluders,
/// each with the triangles it draws there: all, `None`, or those of the history) and the
/// second (the visible candidates and, with triangle tests, the occluders' visible triangles
/// their first pass left out). Drawn in this order on any renderer, it gives the frame's image
/// ([`crate::pipeline`]'s render stage draws a set culled on another renderer).
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct VisibleSet {
    first: Vec<ClusterRef>,
    /// Per cluster of `first`, the triangles drawn; `None`: all of them.
    first_masks: Option<Vec<TriangleMask>>,
    second: Vec<ClusterRef>,
    second_masks: Vec<TriangleMask>,
}

impl VisibleSet {
    /// The whole cut in one pass (no occlusion culling).
    pub(crate) fn whole(clusters: Vec<ClusterRef>) -> VisibleSet {
        VisibleSet { first: clusters, ..Default::default() }
    }

    /// Draws both passes of the set with `camera` into `renderer`'s own target (cleared first);
    /// `clusters` are the frame's decoded clusters, in which every cluster of the set is.
    pub(crate) fn draw(
        &self,
        renderer: &mut Renderer,
        camera: &Camera,
        grid_step: f64,
        clusters: &[(ClusterRef, &PageCluster)],
    ) -> Result<(), FrameError> {
        let by_key = ClusterIndex::new(clusters);
        renderer.begin_frame();
        renderer.draw_masked(
            Target::Own,
            camera,
            grid_step,
            &by_key.decoded(&self.first),
            self.first_masks.as_deref(),
            true,
        )?;
        if !self.second.is_empty() {
            renderer.draw_masked(
                Target::Own,
                camera,
                grid_step,
                &by_key.decoded(&self.second),
                Some(&self.second_masks),
                false,
            )?;
        }
        Ok(())
    }
}

/// How a frame's candidates are tested once its occluders are drawn: against the depth read
/// back from the renderer that drew them (`hzb`), or with occlusion queries on that renderer
/// (`queries`).
pub(crate) enum Tester<'r> {
    Depth(DepthFrame),
    Queries(&'r mut Renderer),
}

/// The first pass's depth, read back, and what the HZB tests need to know of the renderer
/// that drew it.
pub(crate) struct DepthFrame {
    depth: tw_gpu::DepthImage,
    sample_positions: &'static [[f32; 2]],
    depth_rounding: f32,
    size: (u32, u32),
    /// Waiting for the first pass and reading its depth.
    readback: Duration,
}

impl DepthFrame {
    /// Reads `renderer`'s depth back (waiting for its first pass to be drawn).
    pub(crate) fn read(renderer: &mut Renderer) -> Result<DepthFrame, FrameError> {
        let start = Instant::now();
        let depth = renderer.read_depth()?;
        Ok(DepthFrame {
            depth,
            sample_positions: renderer.sample_positions(),
            depth_rounding: renderer.depth_rounding(),
            size: renderer.size(),
            readback: start.elapsed(),
        })
    }
}

/// One frame's occlusion culling of a cut, step by step, so that the steps can run on
/// different renderers and threads ([`crate::pipeline`]): the split of the cut by the history
/// ([`CullPlan::new`]), the occluders' pass ([`CullPlan::draw_first`]), the tests
/// ([`CullPlan::test`]) and the second pass ([`CullPlan::draw_second`]); the history is
/// updated last ([`OcclusionState::finish`]). [`draw_culled`] runs them in order on one
/// renderer.
pub(crate) struct CullPlan<'a> {
    split: OcclusionSplit,
    by_key: ClusterIndex<'a>,
}

/// What [`CullPlan::test`] found: the set to draw, next frame's history and the figures.
pub(crate) struct CullOutcome {
    pub(crate) visible_set: VisibleSet,
    history: Vec<(ClusterRef, TriangleMask)>,
    pub(crate) culled: Culled,
}

impl<'a> CullPlan<'a> {
    /// Splits the frame's decoded cut into occluders (in `state`'s history) and candidates.
    pub(crate) fn new(state: &OcclusionState, clusters: &[(ClusterRef, &'a PageCluster)]) -> CullPlan<'a> {
        let refs: Vec<ClusterRef> = clusters.iter().map(|c| c.0).collect();
        CullPlan::from_split(state.history.split(&refs), clusters)
    }

    /// A plan of `split`, made from another copy of the same cut (the split travels between
    /// the pipeline's stages, the decoded clusters are looked up again by each).
    pub(crate) fn from_split(
        split: OcclusionSplit,
        clusters: &[(ClusterRef, &'a PageCluster)],
    ) -> CullPlan<'a> {
        CullPlan { split, by_key: ClusterIndex::new(clusters) }
    }

    pub(crate) fn into_split(self) -> OcclusionSplit {
        self.split
    }

    /// Whether the first pass draws only the occluders' triangles of the history: `hzb` with
    /// triangle tests (its second pass draws the rest that is visible); the others, and `hzb`
    /// after its triangle tests were turned off, draw their occluders whole whatever masks the
    /// history holds.
    fn partial_occluders(strategy: Occlusion, state: &OcclusionState) -> bool {
        strategy == Occlusion::Hzb && state.triangle_culling
    }

    /// Draws the occluders into `renderer`'s own target, cleared first (colour and depth, or
    /// with `depth_only` the depth alone: an occlusion context whose colour nobody reads); the
    /// caller has begun the renderer's frame.
    pub(crate) fn draw_first(
        &self,
        strategy: Occlusion,
        state: &OcclusionState,
        renderer: &mut Renderer,
        camera: &Camera,
        grid_step: f64,
        depth_only: bool,
    ) -> Result<(), FrameError> {
        let masks = Self::partial_occluders(strategy, state).then_some(&self.split.occluder_masks[..]);
        let occluders = self.by_key.decoded(&self.split.occluders);
        if depth_only {
            renderer.draw_depth_masked(camera, grid_step, &occluders, masks, true)?;
        } else {
            renderer.draw_masked(Target::Own, camera, grid_step, &occluders, masks, true)?;
        }
        Ok(())
    }

    /// Tests the candidates (and, for `hzb`, the occluders) with `tester` against the drawn
    /// occluders: the visible set, next frame's history and the frame's figures.
    pub(crate) fn test<B>(
        &self,
        strategy: Occlusion,
        state: &mut OcclusionState,
        tester: Tester<'_>,
        store: &Store,
        camera: &Camera,
        bounds: &B,
    ) -> Result<CullOutcome, FrameError>
    where
        B: Fn(&ClusterRef) -> Option<([u32; 3], [u32; 3])> + Sync,
    {
        let grid_step = store.header().grid_step;
        let cluster_box = |k: &ClusterRef| -> Option<(Vec3, Vec3)> {
            bounds(k).map(|(lo, hi)| grid_box(lo, hi, grid_step))
        };
        let f = CullFrame {
            store,
            camera,
            grid_step,
            split: &self.split,
            by_key: &self.by_key,
            cluster_box: &cluster_box,
        };
        let mut stats = OcclusionStats {
            occluders: self.split.occluders.len() as u64,
            tested: self.split.candidates.len() as u64,
            ..Default::default()
        };
        let cull_start = Instant::now();
        let mut times = TestTimes::default();
        let tested = match (strategy, tester) {
            (Occlusion::Hzb, Tester::Depth(depth)) => hzb_tests(&f, state, depth, &mut stats, &mut times)?,
            (Occlusion::Queries, Tester::Queries(renderer)) => query_tests(&f, state, renderer, &mut stats)?,
            (s, _) => unreachable!("{} is not tested by a CullPlan, or with another tester", s.name()),
        };
        // The depth was read before this step; its time counts as culling, as in one frame.
        let cull_time = cull_start.elapsed() + times.readback;
        let (second, second_masks): (Vec<ClusterRef>, Vec<TriangleMask>) = tested.second.into_iter().unzip();
        let first_masks = Self::partial_occluders(strategy, state).then(|| self.split.occluder_masks.clone());
        let mut drawn = self.split.occluders.clone();
        drawn.extend_from_slice(&tested.visible);
        Ok(CullOutcome {
            visible_set: VisibleSet {
                first: self.split.occluders.clone(),
                first_masks,
                second,
                second_masks,
            },
            history: tested.history,
            culled: Culled {
                stats,
                cull_time,
                box_test_time: times.box_tests,
                triangle_test_time: times.triangle_tests,
                readback_time: times.readback,
                drawn,
                occluded: tested.occluded,
            },
        })
    }

    /// Draws the second pass of `set` on top of the first (same target, not cleared).
    pub(crate) fn draw_second(
        &self,
        renderer: &mut Renderer,
        camera: &Camera,
        grid_step: f64,
        set: &VisibleSet,
    ) -> Result<(), FrameError> {
        renderer.draw_masked(
            Target::Own,
            camera,
            grid_step,
            &self.by_key.decoded(&set.second),
            Some(&set.second_masks),
            false,
        )?;
        Ok(())
    }
}

impl OcclusionState {
    /// Takes a tested frame's visible set as the history that chooses the next frame's
    /// occluders (its time counts as culling).
    pub(crate) fn finish(&mut self, outcome: &mut CullOutcome) {
        let start = Instant::now();
        self.history.update_masked(std::mem::take(&mut outcome.history));
        self.frames = self.frames.wrapping_add(1);
        outcome.culled.cull_time += start.elapsed();
    }
}

/// What [`draw_culled`]'s tests read: the frame's store, camera, first and second pass split,
/// decoded clusters and each cluster's scene-space box.
struct CullFrame<'a, B> {
    store: &'a Store,
    camera: &'a Camera,
    grid_step: f64,
    split: &'a OcclusionSplit,
    by_key: &'a ClusterIndex<'a>,
    cluster_box: &'a B,
}

/// What a strategy's tests found: the visible candidates; what the second pass draws
/// (cluster, triangles; `u128::MAX`: all): the visible candidates and, with triangle tests,
/// the occluders' visible triangles their first pass left out; next frame's history (cluster,
/// visible triangles); and the candidates found hidden.
struct Tested {
    visible: Vec<ClusterRef>,
    second: Vec<(ClusterRef, TriangleMask)>,
    history: Vec<(ClusterRef, TriangleMask)>,
    occluded: Vec<ClusterRef>,
}

/// The parts of the `hzb` strategy's time that [`Culled`] reports.
#[derive(Default)]
struct TestTimes {
    readback: Duration,
    box_tests: Duration,
    triangle_tests: Duration,
}

/// The `hzb` strategy: the first pass's depth read back into a pyramid, the candidates tested
/// against it top-down and the occluders flat, then, with triangle tests, the visible clusters'
/// triangles.
fn hzb_tests<B>(
    f: &CullFrame<B>,
    state: &mut OcclusionState,
    frame: DepthFrame,
    stats: &mut OcclusionStats,
    times: &mut TestTimes,
) -> Result<Tested, FrameError>
where
    B: Fn(&ClusterRef) -> Option<(Vec3, Vec3)> + Sync,
{
    times.readback = frame.readback;
    let depth = &frame.depth;
    // With multisampling the depth is each pixel's farthest sample, and a pixel is its
    // samples to the tests (tw_gpu::msaa).
    let hzb = Hzb::build(&depth.depth, depth.width, depth.height)
        .map_err(|e| tw_gpu::GpuError::Gpu(format!("HZB: {e}")))?
        .with_samples(frame.sample_positions);
    let (w, h) = frame.size;
    let view_proj = f.camera.projection_reverse_z(w as f32 / h as f32) * f.camera.view();
    let box_tests_start = Instant::now();
    let t = hzb_candidates(f, state, &hzb, &view_proj, stats);
    // The occluders flat: they were visible last frame, so nodes above them mostly are.
    let o_results = test_boxes(&f.split.occluders, &hzb, &view_proj, f.cluster_box);
    let o_still: Vec<usize> = (0..o_results.len()).filter(|&i| o_results[i] == HzbResult::Visible).collect();
    let o_visible: Vec<ClusterRef> = o_still.iter().map(|&i| f.split.occluders[i]).collect();
    times.box_tests = box_tests_start.elapsed();
    stats.culled = t.occluded.len() as u64;
    stats.no_pixels = t.no_pixels.len() as u64;
    if state.triangle_culling {
        let hzb_view = (&hzb, &view_proj);
        Ok(hzb_triangle_tests(f, state.frames, frame.depth_rounding, hzb_view, t, &o_still, o_visible, times))
    } else {
        let second = t.visible.iter().map(|k| (*k, u128::MAX)).collect();
        let history = t.visible.iter().chain(&o_visible).map(|k| (*k, u128::MAX)).collect();
        Ok(Tested { visible: t.visible, second, history, occluded: t.occluded })
    }
}

/// The candidates against the pyramid top-down (skeleton nodes, groups, clusters): a hidden
/// node culls its subtree's candidates with one test. Probe frames and frames where they paid
/// test nodes; the others go flat. Counts the node and group tests in `stats`.
fn hzb_candidates<B>(
    f: &CullFrame<B>,
    state: &mut OcclusionState,
    hzb: &Hzb,
    view_proj: &glam::Mat4,
    stats: &mut OcclusionStats,
) -> OcclusionTest
where
    B: Fn(&ClusterRef) -> Option<(Vec3, Vec3)> + Sync,
{
    let store = f.store;
    if state.parents.len() != store.nodes().len() {
        state.parents = parents(store.nodes().iter().map(|n| (n.first_child, n.child_count)));
    }
    let skeleton = Skeleton {
        parents: &state.parents,
        nodes: store.nodes(),
        groups: store.groups(),
        grid_step: f.grid_step,
    };
    let test_nodes = (state.hierarchy_forced || state.hzb_switch.test_nodes())
        && state.hierarchy != HierarchyOptions::FLAT;
    let hierarchy = if test_nodes { state.hierarchy } else { HierarchyOptions::FLAT };
    let tested = test_clusters_hierarchically(
        &f.split.candidates,
        &skeleton,
        hzb,
        view_proj,
        f.cluster_box,
        &hierarchy,
    );
    let by_nodes = f.split.candidates.len() as u64 - tested.clusters_tested;
    state.hzb_switch.update(
        tested.clusters_tested,
        tested.clusters_time,
        test_nodes.then_some((tested.hierarchy_time, by_nodes)),
    );
    (stats.node_tests, stats.nodes_hidden) = (tested.nodes_tested, tested.nodes_hidden);
    (stats.group_tests, stats.groups_hidden) = (tested.groups_tested, tested.groups_hidden);
    tested.clusters
}

/// The visible clusters' triangles against the same pyramid (`hzb_view`: the pyramid and the
/// view-projection): the candidates (`t`) draw theirs, the still visible occluders
/// (`o_visible`, at `o_still` in the split) the ones their first pass left out.
#[allow(clippy::too_many_arguments)]
fn hzb_triangle_tests<B>(
    f: &CullFrame<B>,
    frame: u64,
    depth_rounding: f32,
    (hzb, view_proj): (&Hzb, &glam::Mat4),
    t: OcclusionTest,
    o_still: &[usize],
    o_visible: Vec<ClusterRef>,
    times: &mut TestTimes,
) -> Tested {
    let triangles = |list: &[ClusterRef], assumed: Option<&[TriangleMask]>| {
        let clusters: Vec<&PageCluster> = f.by_key.decoded(list).into_iter().map(|(_, c)| c).collect();
        let rounding = depth_rounding as f64;
        test_triangles(&clusters, assumed, f.grid_step, hzb, view_proj, rounding)
    };
    // What each still visible occluder drew in the first pass.
    let drawn: Vec<TriangleMask> = o_still.iter().map(|&i| f.split.occluder_masks[i]).collect();
    // The triangles an occluder drew in the first pass are in the image whatever their test
    // says, so only the history would learn from it (which of them to draw first next frame):
    // they are assumed visible, and tested again only every RETEST_PERIOD-th frame per cluster
    // (staggered), which drops those that became hidden from the history.
    let assumed: Vec<TriangleMask> =
        o_visible.iter().zip(&drawn).map(|(k, &d)| if retest(k, frame) { 0 } else { d }).collect();
    let triangles_start = Instant::now();
    let (t_masks, o_masks) = (triangles(&t.visible, None), triangles(&o_visible, Some(&assumed)));
    times.triangle_tests = triangles_start.elapsed();
    let candidates = t.visible.iter().copied().zip(t_masks);
    let occluders = o_visible.iter().copied().zip(o_masks);
    let rest = occluders
        .clone()
        .zip(&drawn)
        .filter_map(|((k, m), &drawn)| (m & !drawn != 0).then_some((k, m & !drawn)));
    let second: Vec<(ClusterRef, TriangleMask)> = candidates.clone().chain(rest).collect();
    let history: Vec<(ClusterRef, TriangleMask)> = candidates.chain(occluders).collect();
    Tested { visible: t.visible, second, history, occluded: t.occluded }
}

/// The `queries` strategy: node boxes first, breadth-first by level (Alg. 3.4.1), where they
/// paid; a hidden node culls the candidates under it without a query each; then a query per
/// remaining candidate's box. GL's queries are booleans (1 = some sample passed): no cut-off
/// there.
fn query_tests<B>(
    f: &CullFrame<B>,
    state: &mut OcclusionState,
    renderer: &mut Renderer,
    stats: &mut OcclusionStats,
) -> Result<Tested, FrameError>
where
    B: Fn(&ClusterRef) -> Option<(Vec3, Vec3)> + Sync,
{
    let cutoff = if renderer.queries_count_samples() { state.visible_pixels as u64 } else { 0 };
    let store = f.store;
    if state.parents.len() != store.nodes().len() {
        state.parents = parents(store.nodes().iter().map(|n| (n.first_child, n.child_count)));
    }
    let test_nodes = state.node_switch.test_nodes();
    let node_start = Instant::now();
    let tree = query_nodes(f, state, renderer, cutoff, test_nodes)?;
    let node_time = node_start.elapsed();
    stats.node_tests = tree.nodes_tested;
    stats.nodes_hidden = tree.nodes_hidden;
    let (survivors, by_nodes): (Vec<_>, Vec<_>) =
        f.split.candidates.iter().zip(&tree.culled).partition(|(_, &culled)| !culled);
    let survivors: Vec<ClusterRef> = survivors.into_iter().map(|(k, _)| *k).collect();
    let mut occluded: Vec<ClusterRef> = by_nodes.into_iter().map(|(k, _)| *k).collect();
    let boxes: Vec<(Vec3, Vec3)> = survivors
        .iter()
        .map(|k| (f.cluster_box)(k).unwrap_or((Vec3::splat(f32::MIN), Vec3::splat(f32::MAX))))
        .collect();
    let query_start = Instant::now();
    let samples = renderer.query_boxes(f.camera, &boxes)?;
    // `occluded` holds, so far, the candidates the node tests culled.
    state.node_switch.update(
        boxes.len() as u64,
        query_start.elapsed(),
        test_nodes.then_some((node_time, occluded.len() as u64)),
    );
    stats.queries = tree.nodes_tested + boxes.len() as u64;
    let (visible, hidden): (Vec<_>, Vec<_>) = survivors.iter().zip(&samples).partition(|(_, &s)| s > cutoff);
    let visible: Vec<ClusterRef> = visible.into_iter().map(|(k, _)| *k).collect();
    occluded.extend(hidden.into_iter().map(|(k, _)| *k));
    stats.culled = occluded.len() as u64;
    let second = visible.iter().map(|k| (*k, u128::MAX)).collect();
    let history = f.split.occluders.iter().chain(&visible).map(|k| (*k, u128::MAX)).collect();
    Ok(Tested { visible, second, history, occluded })
}

/// The `queries` strategy's node tests (when `test_nodes`): the candidates' skeleton nodes
/// (`state.parents` made for the store) queried level by level, visible with more than
/// `cutoff` samples; else nothing culled.
fn query_nodes<B>(
    f: &CullFrame<B>,
    state: &OcclusionState,
    renderer: &mut Renderer,
    cutoff: u64,
    test_nodes: bool,
) -> Result<NodeTestResult, FrameError> {
    if !test_nodes {
        return Ok(NodeTestResult { culled: vec![false; f.split.candidates.len()], ..Default::default() });
    }
    let (nodes, groups) = (f.store.nodes(), f.store.groups());
    let candidate_nodes: Vec<u32> = f
        .split
        .candidates
        .iter()
        .map(|k| groups.get(k.group as usize).map_or(u32::MAX, |g| g.node))
        .collect();
    test_hierarchy(&state.parents, &candidate_nodes, &NodeTestOptions::default(), |batch| {
        let boxes: Vec<(Vec3, Vec3)> = batch
            .iter()
            .map(|&n| grid_box(nodes[n as usize].min, nodes[n as usize].max, f.grid_step))
            .collect();
        let samples = renderer.query_boxes(f.camera, &boxes)?;
        Ok::<_, FrameError>(samples.iter().map(|&s| s > cutoff).collect())
    })
}

/// The decoded clusters of a frame by (page, index in page): sorted in parallel and searched,
/// so the look-ups of [`draw_culled`]'s lists run in parallel too.
struct ClusterIndex<'a> {
    sorted: Vec<((u32, u32), &'a PageCluster)>,
}

impl<'a> ClusterIndex<'a> {
    fn new(clusters: &[(ClusterRef, &'a PageCluster)]) -> ClusterIndex<'a> {
        let mut sorted: Vec<((u32, u32), &PageCluster)> =
            clusters.iter().map(|(k, c)| ((k.page, k.index_in_page), *c)).collect();
        sorted.par_sort_by_key(|e| e.0);
        ClusterIndex { sorted }
    }

    fn get(&self, k: &ClusterRef) -> Option<&'a PageCluster> {
        let i = self.sorted.binary_search_by_key(&(k.page, k.index_in_page), |e| e.0).ok()?;
        Some(self.sorted[i].1)
    }

    /// The decoded clusters of `list`, in order. Every reference [`draw_culled`] looks up comes
    /// from the frame's clusters, so none is left out (and per-cluster masks stay aligned with
    /// the list they were made for).
    fn decoded(&self, list: &[ClusterRef]) -> Vec<(ClusterRef, &'a PageCluster)> {
        list.par_iter().with_min_len(1024).filter_map(|k| self.get(k).map(|c| (*k, c))).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every cluster's first-pass triangles are re-tested exactly once in any
    /// [`RETEST_PERIOD`] consecutive frames, and the clusters of a frame are spread over the
    /// phases rather than all re-tested together.
    #[test]
    fn retests_come_once_a_period_and_are_staggered() {
        let clusters: Vec<ClusterRef> = (0..64u32)
            .flat_map(|page| (0..8u32).map(move |i| ClusterRef { page, index_in_page: i, group: 0 }))
            .collect();
        for start in [0u64, 5, u64::MAX - 2] {
            for c in &clusters {
                let n = (0..RETEST_PERIOD).filter(|&f| retest(c, start.wrapping_add(f))).count();
                assert_eq!(n, 1, "{c:?} from frame {start}");
            }
        }
        let in_frame = clusters.iter().filter(|c| retest(c, 7)).count();
        let even = clusters.len() / RETEST_PERIOD as usize;
        assert!(in_frame > even / 2 && in_frame < even * 2, "{in_frame} of {} re-tested", clusters.len());
    }
}
