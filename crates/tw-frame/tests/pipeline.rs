//! The parallel pipelines (crates/tw-frame/src/pipeline) stay conservative: with the same LOD
//! cut (pages loaded before drawing), every frame that comes out of `gigawalk`, `switch` or
//! `alternate` is
//! the image of `--occlusion none` for its camera, pixel for pixel, although its occluders are
//! the visible set of two frames before, culled on another device. On a walk through the plant,
//! on teleports (the history is then useless as occluders) and on the approach to an assembly;
//! on Vulkan (lavapipe) and GL (llvmpipe), and with 4× multisampling on Vulkan. Frames come out
//! in order with their tags, culling culls something, and a body that returns with frames in
//! flight or asks for a frame never submitted does not hang.

use std::sync::Arc;

use tw_frame::{FrameSettings, Occlusion, Pipeline, PipelinedFrame};
use tw_gpu::{wgpu, Image};
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};
use tw_runtime::Camera;
use tw_store::Store;

mod common;

use common::gpu_lock;

fn plant() -> Arc<Store> {
    common::plant(200_000, 3)
}

fn cameras(store: &Store, part: PathPart, frames: usize, step: usize) -> Vec<Camera> {
    let options = PathOptions { frames, part, seed: 2, ..Default::default() };
    let path = generate_path(store, &options, &mut |_, _, _| {}).unwrap().path;
    path.frames.iter().step_by(step).map(|f| f.to_scene(store.header()).unwrap()).collect()
}

fn settings(occlusion: Occlusion) -> FrameSettings {
    FrameSettings { tau: 1.0, occlusion, wait_for_pages: true, ..Default::default() }
}

/// Every camera through a `kind` pipeline with `occlusion`, keeping the pipeline full.
fn run(
    w: &mut tw_frame::Walkthrough,
    kind: Pipeline,
    occlusion: Occlusion,
    cameras: &[Camera],
) -> Vec<PipelinedFrame> {
    w.pipelined(kind, &settings(occlusion), |pipe| {
        let mut frames = Vec::new();
        let mut next = 0;
        while frames.len() < cameras.len() {
            while next < cameras.len() && pipe.in_flight() < kind.depth() as u64 {
                assert_eq!(pipe.submit(&cameras[next]).unwrap(), next as u64);
                next += 1;
            }
            frames.push(pipe.receive().unwrap());
        }
        frames
    })
    .unwrap()
}

/// Each pipeline and strategy against `none`'s images of the same cameras.
fn compare(
    store: Arc<Store>,
    cameras: &[Camera],
    backends: wgpu::Backends,
    what: &str,
    samples: u32,
    cull: bool,
) {
    let _lock = gpu_lock();
    let Some(mut w) = common::walkthrough(store, backends, what, 256 << 20) else { return };
    w.renderer_mut().set_samples(samples).unwrap();
    let baseline: Vec<Image> =
        cameras.iter().map(|c| w.frame(c, &settings(Occlusion::None)).unwrap().0).collect();
    let gl = backends == wgpu::Backends::GL;
    let mut runs = vec![
        (Pipeline::Serial, Occlusion::Hzb),
        (Pipeline::SelectAhead, Occlusion::Hzb),
        (Pipeline::SelectAhead, Occlusion::GpuHzb),
        (Pipeline::Gigawalk, Occlusion::Hzb),
        (Pipeline::Switch, Occlusion::Hzb),
        (Pipeline::Switch, Occlusion::Queries),
        (Pipeline::Gigawalk, Occlusion::None),
        (Pipeline::Alternate, Occlusion::Hzb),
        (Pipeline::Alternate, Occlusion::Queries),
        (Pipeline::Alternate, Occlusion::GpuHzb),
    ];
    if gl && samples > 1 {
        runs.retain(|r| r.1 != Occlusion::Queries);
    }
    for (kind, occlusion) in runs {
        let frames = run(&mut w, kind, occlusion, cameras);
        let mut culled = 0;
        for (i, f) in frames.iter().enumerate() {
            assert_eq!(f.frame, i as u64, "{what}: frames out of order");
            let differing = f.image.differing_pixels(&baseline[i]).unwrap();
            assert_eq!(
                differing,
                0,
                "{what}, --pipeline {} --occlusion {}: frame {i} differs from --occlusion none in {differing} pixels",
                kind.name(),
                occlusion.name()
            );
            assert!(f.image.covered_pixels() > 0, "{what}: frame {i} is empty");
            culled += f.info.occlusion.culled;
        }
        eprintln!(
            "{what}, {} {}: {culled} clusters culled over {} frames",
            kind.name(),
            occlusion.name(),
            frames.len()
        );
        if cull && occlusion != Occlusion::None {
            assert!(culled > 0, "{what}, {} {}: culled nothing", kind.name(), occlusion.name());
        }
    }
}

fn walk(backends: wgpu::Backends, what: &str, samples: u32) {
    let cameras = cameras(&plant(), PathPart::Walk, 72, 3);
    compare(plant(), &cameras, backends, what, samples, true);
}

fn teleports(backends: wgpu::Backends, what: &str) {
    let walk = cameras(&plant(), PathPart::Walk, 72, 3);
    let jumps: Vec<Camera> = (0..8).map(|i| walk[(i * 7) % walk.len()]).collect();
    compare(plant(), &jumps, backends, what, 1, false);
}

fn approach(backends: wgpu::Backends, what: &str) {
    let store = common::assembly(300_000, 1);
    let cameras = cameras(&store, PathPart::Approach, 16, 1);
    compare(store, &cameras, backends, what, 1, true);
}

#[test]
fn pipelines_give_the_image_of_none_on_a_walk_vulkan() {
    walk(wgpu::Backends::VULKAN, "Vulkan walk", 1);
}

#[test]
fn pipelines_give_the_image_of_none_on_a_walk_gl() {
    walk(wgpu::Backends::GL, "GL walk", 1);
}

#[test]
fn pipelines_give_the_image_of_none_with_msaa_vulkan() {
    walk(wgpu::Backends::VULKAN, "Vulkan walk, 4 samples", 4);
}

#[test]
fn pipelines_give_the_image_of_none_on_teleports_vulkan() {
    teleports(wgpu::Backends::VULKAN, "Vulkan teleports");
}

#[test]
fn pipelines_give_the_image_of_none_on_teleports_gl() {
    teleports(wgpu::Backends::GL, "GL teleports");
}

#[test]
fn pipelines_give_the_image_of_none_on_an_assembly_approach_vulkan() {
    approach(wgpu::Backends::VULKAN, "Vulkan assembly approach");
}

/// A body that leaves frames in flight returns (the stages finish them and stop), one that asks
/// for a frame it never submitted gets an error, and the walkthrough draws serial frames after.
#[test]
fn pipelines_stop_cleanly_with_frames_in_flight() {
    let _lock = gpu_lock();
    let store = plant();
    let cams = cameras(&store, PathPart::Walk, 12, 1);
    let Some(mut w) = common::walkthrough(store, wgpu::Backends::VULKAN, "stop", 256 << 20) else { return };
    for kind in Pipeline::ALL {
        let got = w
            .pipelined(kind, &settings(Occlusion::Hzb), |pipe| {
                assert!(pipe.receive().is_err(), "a frame came out before any was submitted");
                for c in &cams[..4] {
                    pipe.submit(c).unwrap();
                }
                pipe.receive().unwrap().frame
            })
            .unwrap();
        assert_eq!(got, 0);
    }
    let (image, _) = w.frame(&cams[5], &settings(Occlusion::Hzb)).unwrap();
    assert!(image.covered_pixels() > 0);
}

/// Combinations a pipeline cannot run are refused before anything starts, naming the flags.
#[test]
fn unsupported_combinations_are_refused() {
    assert!(Pipeline::Gigawalk.supports(Occlusion::Queries).unwrap_err().contains("--pipeline switch"));
    assert!(Pipeline::Switch.supports(Occlusion::GpuHzb).unwrap_err().contains("--occlusion gpu-hzb"));
    assert!(Pipeline::Alternate.supports(Occlusion::GpuHzb).is_ok());
    assert!(Pipeline::SelectAhead.supports(Occlusion::Queries).is_ok());
    for p in Pipeline::ALL {
        assert!(p.supports(Occlusion::Hzb).is_ok() && p.supports(Occlusion::None).is_ok());
        assert_eq!(Pipeline::parse(p.name()), Some(p));
    }
    assert_eq!(Pipeline::parse("gigawalk "), Some(Pipeline::Gigawalk));
    assert_eq!(Pipeline::parse("fast"), None);
}
