//! Flat against hierarchical `hzb` culling on this machine: the same camera path drawn with
//! each candidate's own box tested (GigaWalk's flat test), with skeleton node boxes tested
//! first (thesis Alg. 3.4.1), and with node then group boxes (the default). Prints per
//! variant the median and mean of the frames' box tests (`FrameTimes::cull_box_tests`), the
//! median culling time (`FrameTimes::cull`: with the depth read-back, which waits for the
//! first pass, the pyramid and the triangle tests), the median frame time, the boxes tested, and the
//! pixels that differ from the flat run's images (0: the same image); the last variant is the
//! default, nodes and groups tested only while they pay. The variants run in
//! turn over the whole path, twice in opposite orders, and each keeps its faster pass.
//! A measuring tool for docs/benchmarks-log.md; `terawalk bench` measures the pipeline.
//!
//! `cargo run --release -p tw-frame --example hzb_hierarchy -- STORE PATH.json [FRAMES] [WxH]`

use std::sync::Arc;

use tw_frame::{FrameSettings, Occlusion, Walkthrough};
use tw_gpu::{Image, Renderer};
use tw_runtime::occlusion::HierarchyOptions;
use tw_runtime::{CameraPath, StreamOptions};
use tw_store::Store;

/// What one variant did over the path.
#[derive(Default)]
struct Pass {
    cull_ms: Vec<f64>,
    box_tests_ms: Vec<f64>,
    triangle_tests_ms: Vec<f64>,
    frame_ms: Vec<f64>,
    /// Candidates, node boxes tested and hidden, group boxes tested and hidden, candidates
    /// culled.
    candidates: u64,
    node_tests: u64,
    nodes_hidden: u64,
    group_tests: u64,
    groups_hidden: u64,
    culled: u64,
    images: Vec<Image>,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: hzb_hierarchy STORE PATH.json [FRAMES] [WxH]");
        std::process::exit(2);
    }
    let store = Arc::new(Store::open(&args[1])?);
    let path = CameraPath::load(std::path::Path::new(&args[2]))?;
    let frames: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(60);
    let (w, h) = match args.get(4).and_then(|s| s.split_once('x')) {
        Some((a, b)) => (a.parse()?, b.parse()?),
        None => (1280u32, 720u32),
    };
    let renderer = Renderer::new_headless(w, h)?;
    println!("{} at {w}×{h}, {} threads", renderer.adapter_summary(), rayon::current_num_threads());
    let options = StreamOptions { budget_bytes: 1 << 30, ..Default::default() };
    let mut walk = Walkthrough::new(store.clone(), renderer, options)?;
    let settings = FrameSettings { occlusion: Occlusion::Hzb, wait_for_pages: true, ..Default::default() };
    let cameras =
        path.frames.iter().take(frames).map(|f| f.to_scene(store.header())).collect::<Result<Vec<_>, _>>()?;
    let variants = [
        ("flat", HierarchyOptions::FLAT, true),
        ("nodes", HierarchyOptions { groups: false, ..Default::default() }, true),
        ("nodes+groups", HierarchyOptions::default(), true),
        ("switched", HierarchyOptions::default(), false),
    ];
    let mut best: Vec<Option<Pass>> = variants.iter().map(|_| None).collect();
    let orders: [Vec<usize>; 2] = [(0..variants.len()).collect(), (0..variants.len()).rev().collect()];
    for order in orders {
        for v in order {
            walk.set_hzb_hierarchy(variants[v].1, variants[v].2);
            walk.reset();
            let mut pass = Pass::default();
            for camera in &cameras {
                let (image, info) = walk.frame(camera, &settings)?;
                pass.cull_ms.push(info.times.cull.as_secs_f64() * 1e3);
                pass.box_tests_ms.push(info.times.cull_box_tests.as_secs_f64() * 1e3);
                pass.triangle_tests_ms.push(info.times.cull_triangle_tests.as_secs_f64() * 1e3);
                pass.frame_ms.push(info.times.total.as_secs_f64() * 1e3);
                pass.candidates += info.occlusion.tested;
                pass.node_tests += info.occlusion.node_tests;
                pass.nodes_hidden += info.occlusion.nodes_hidden;
                pass.group_tests += info.occlusion.group_tests;
                pass.groups_hidden += info.occlusion.groups_hidden;
                pass.culled += info.occlusion.culled;
                pass.images.push(image);
            }
            if best[v].as_ref().is_none_or(|b| mean(&pass.box_tests_ms) < mean(&b.box_tests_ms)) {
                best[v] = Some(pass);
            }
        }
    }
    let flat_images = best[0].as_ref().map(|p| p.images.clone()).unwrap_or_default();
    for ((name, _, _), pass) in variants.iter().zip(best.iter().flatten()) {
        let differing: usize = pass
            .images
            .iter()
            .zip(&flat_images)
            .map(|(a, b)| a.differing_pixels(b).unwrap_or(usize::MAX))
            .sum();
        println!(
            "{name:>13}: box tests median {:.2} ms, mean {:.2} ms; triangle tests median {:.1} ms; cull median {:.1} \
             ms; frame median {:.1} ms; \
             {} candidates, {} node boxes tested ({} hidden), {} group boxes ({} hidden), {} culled; {differing} \
             pixels differ from flat",
            median(&pass.box_tests_ms),
            mean(&pass.box_tests_ms),
            median(&pass.triangle_tests_ms),
            median(&pass.cull_ms),
            median(&pass.frame_ms),
            pass.candidates,
            pass.node_tests,
            pass.nodes_hidden,
            pass.group_tests,
            pass.groups_hidden,
            pass.culled,
        );
    }
    Ok(())
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s.get(s.len() / 2).copied().unwrap_or(0.0)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}
