//! `terawalk demo`: the README's main job. Generates a power plant (cached), reads it back
//! through the importer, builds the out-of-core store (cached) and verifies it, generates a
//! walkthrough path (cached), renders it headless with every occlusion strategy (`bench`, with
//! the full-detail reference every 30th frame) and prints where the report is.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use tw_io::SceneOptions;

use crate::cli::DemoArgs;
use crate::commands::{generate, stats};
use crate::units::{fmt_byte_rate, fmt_bytes, fmt_count, fmt_count_rate};

pub fn run(args: DemoArgs) -> Result<()> {
    let start = Instant::now();
    std::fs::create_dir_all(&args.dir).with_context(|| format!("cannot create {}", args.dir.display()))?;
    let model = args.dir.join(format!("plant-{}-s{}.ply", args.triangles, args.seed));
    outln!("terawalk demo: a generated power plant of {} triangles", fmt_count(args.triangles));
    plant(&args, &model)?;
    let options = SceneOptions::default();
    read_back(&model, &options)?;
    let store = args.dir.join(format!("plant-{}-s{}.tw", args.triangles, args.seed));
    let opened = build_store(&model, &options, &store)?;
    let path_file =
        args.dir.join(format!("plant-{}-s{}-path{}.json", args.triangles, args.seed, args.frames));
    walkthrough_path(&opened, args.frames, &path_file)?;
    drop(opened);

    // The benchmark walkthrough on the GPU (Mesa's CPU drivers where there is no GPU): each
    // occlusion strategy, and the full-detail reference every 30th frame for PSNR.
    let out = args.dir.join("bench-report");
    outln!("5. bench: rendering the path headless at 1280x720, 1 px error:");
    let outcome = crate::commands::bench::run(bench_args(&store, &path_file, &out))?;

    outln!(
        "done in {:.1} s, peak memory {}",
        start.elapsed().as_secs_f64(),
        tw_core::mem::peak_rss_bytes().map(fmt_bytes).unwrap_or_else(|| "unknown".into())
    );
    outln!("report: open {} in a browser", outcome.html.display());
    outln!(
        "next: `terawalk view {}` (a window; fly with WASD and the mouse), `terawalk bench {} --path {} --exact`",
        store.display(),
        store.display(),
        path_file.display()
    );
    Ok(())
}

/// Step 1: the plant at `model`, generated unless it is there already.
fn plant(args: &DemoArgs, model: &Path) -> Result<()> {
    if model.exists() {
        outln!("1. plant: cached at {}", model.display());
    } else {
        let g = generate::generate_plant(args.triangles, args.seed, model)?;
        outln!(
            "1. plant: generated {} ({} in {:.1} s, {})",
            model.display(),
            fmt_bytes(g.file_bytes),
            g.seconds,
            fmt_count_rate(g.summary.triangles, g.seconds, "triangles")
        );
    }
    Ok(())
}

/// Step 2: the plant read back through the importer, with its read speed.
fn read_back(model: &Path, options: &SceneOptions) -> Result<()> {
    let read = stats::stream_file(model, options)?;
    outln!(
        "2. read back: {} triangles, {} objects in {:.2} s ({})",
        fmt_count(read.summary.triangles),
        fmt_count(read.summary.objects as u64),
        read.seconds,
        fmt_byte_rate(read.summary.bytes, read.seconds)
    );
    Ok(())
}

/// Step 3: the store at `store`, built unless a readable one is there already, then opened
/// and verified (every checksum and invariant).
fn build_store(model: &Path, options: &SceneOptions, store: &Path) -> Result<tw_store::Store> {
    if store.exists() && tw_store::Store::open(store).is_ok() {
        outln!("3. store: cached at {}", store.display());
    } else {
        let scene = tw_io::Scene::open(&[model], options.clone())?;
        let opts = tw_build::BuildOptions { memory: 1 << 30, ..Default::default() };
        let r = tw_build::build(scene, store, &opts, &mut tw_build::NoProgress)?;
        outln!(
            "3. store: built {} in {:.1} s ({} cells, {} clusters, {:.2}x triangles over all LOD levels, {:.1} bytes per triangle)",
            store.display(),
            r.seconds(),
            fmt_count(r.redefine.cells),
            fmt_count(r.clusters),
            r.stored_triangles as f64 / r.input_triangles.max(1) as f64,
            r.file_bytes as f64 / r.input_triangles.max(1) as f64
        );
    }
    let opened = tw_store::Store::open(store)?;
    let v = opened.verify(|_, _| {})?;
    outln!(
        "   verified: {} pages, {} groups, {} nodes, every checksum and invariant OK",
        v.pages,
        v.groups,
        v.nodes
    );
    Ok(opened)
}

/// Step 4: an automatic walkthrough path of `frames` frames (cached at `path_file`): a walk
/// at eye height inside, then a fly-over.
fn walkthrough_path(opened: &tw_store::Store, frames: usize, path_file: &Path) -> Result<()> {
    if path_file.exists() && tw_runtime::CameraPath::load(path_file).is_ok() {
        outln!("4. path: cached at {}", path_file.display());
    } else {
        let t = Instant::now();
        let options = tw_runtime::pathgen::PathOptions { frames, ..Default::default() };
        let g = tw_runtime::pathgen::generate_path(opened, &options, &mut |_, _, _| {})?;
        g.path.save(path_file)?;
        outln!(
            "4. path: {} frames ({} walking inside at eye height, {} flying over) in {:.1} s -> {}",
            g.path.frames.len(),
            g.report.walk_frames,
            g.report.fly_frames,
            t.elapsed().as_secs_f64(),
            path_file.display()
        );
    }
    Ok(())
}

/// Step 5's benchmark: the path at 1280x720 and 1 px error with every occlusion strategy, the
/// full-detail reference every 30th frame, into `out`.
fn bench_args(store: &Path, path_file: &Path, out: &Path) -> crate::cli::BenchArgs {
    crate::cli::BenchArgs {
        store: store.to_path_buf(),
        path: Some(path_file.to_path_buf()),
        frames: None,
        out: out.to_path_buf(),
        frame: crate::cli::FrameArgs {
            size: (1280, 720),
            samples: crate::cli::SamplesChoice::Auto,
            transition: Default::default(),
        },
        error: 1.0,
        memory: 1 << 30,
        occlusion: tw_frame::Occlusion::ALL.iter().map(|&o| crate::cli::OcclusionChoice::Is(o)).collect(),
        pipeline: vec![tw_frame::Pipeline::Serial],
        reference: false,
        compare: Some(30),
        reference_samples: 1,
        exact: false,
        wait: false,
        fit_memory: true,
        visible_pixels: 0,
        whole_clusters: false,
        gpu_memory: 512 << 20,
        warmup: 3,
        images: 4,
        color: crate::cli::ColorArgs { color: crate::cli::RenderColoring::Material },
        allow_damaged: false,
        cull_server: None,
        cull_timeout_ms: 250,
        renderer: crate::cli::RendererChoice::Raster,
        flashlight: false,
        popping: false,
        shadows: crate::cli::ShadowArgs::default(),
        section: crate::cli::SectionArgs::default(),
    }
}
