//! `terawalk demo`: the README's main job. Generates a power plant (cached), reads it back
//! through the importer, builds the out-of-core store (cached) and verifies it, renders an
//! outside and an inside view, and prints a summary. The runtime issue extends it with the
//! benchmark walkthrough.

use std::time::Instant;

use anyhow::{Context, Result};
use tw_io::generate::{interior_viewpoints, PlantParams};
use tw_io::SceneOptions;
use tw_preview::Camera;

use crate::cli::{Coloring, DemoArgs};
use crate::commands::{generate, preview, stats};
use crate::units::{fmt_bytes, fmt_count};

pub fn run(args: DemoArgs) -> Result<()> {
    let start = Instant::now();
    std::fs::create_dir_all(&args.dir).with_context(|| format!("cannot create {}", args.dir.display()))?;
    let model = args.dir.join(format!("plant-{}-s{}.ply", args.triangles, args.seed));
    println!("terawalk demo: a generated power plant of {} triangles", fmt_count(args.triangles));

    if model.exists() {
        println!("1. plant: cached at {}", model.display());
    } else {
        let g = generate::generate_plant(args.triangles, args.seed, &model)?;
        println!(
            "1. plant: generated {} ({} in {:.1} s, {:.2} M triangles/s)",
            model.display(),
            fmt_bytes(g.file_bytes),
            g.seconds,
            g.summary.triangles as f64 / 1e6 / g.seconds.max(1e-9)
        );
    }

    let options = SceneOptions::default();
    let read = stats::stream_file(&model, &options)?;
    println!(
        "2. read back: {} triangles, {} objects in {:.2} s ({:.0} MB/s)",
        fmt_count(read.summary.triangles),
        fmt_count(read.summary.objects as u64),
        read.seconds,
        read.summary.bytes as f64 / 1e6 / read.seconds.max(1e-9)
    );

    let store = args.dir.join(format!("plant-{}-s{}.tw", args.triangles, args.seed));
    if store.exists() && tw_store::Store::open(&store).is_ok() {
        println!("3. store: cached at {}", store.display());
    } else {
        let scene = tw_io::Scene::open(&[&model], options.clone())?;
        let opts = tw_build::BuildOptions { memory: 1 << 30, ..Default::default() };
        let r = tw_build::build(scene, &store, &opts, &mut tw_build::NoProgress)?;
        println!(
            "3. store: built {} in {:.1} s ({} cells, {} clusters, {:.2}x triangles over all LOD levels, {:.1} bytes per triangle)",
            store.display(),
            r.seconds(),
            fmt_count(r.redefine.cells),
            fmt_count(r.clusters),
            r.stored_triangles as f64 / r.input_triangles.max(1) as f64,
            r.file_bytes as f64 / r.input_triangles.max(1) as f64
        );
    }
    let opened = tw_store::Store::open(&store)?;
    let v = opened.verify(|_, _| {})?;
    println!(
        "   verified: {} pages, {} groups, {} nodes, every checksum and invariant OK",
        v.pages, v.groups, v.nodes
    );

    let files = [model.clone()];
    let outside = args.dir.join("plant-outside.png");
    let cam = Camera::frame_bounds(&read.stats.bounds, [-0.55, -0.75, 0.55], [0.0, 0.0, 1.0], 1280.0 / 720.0);
    preview::render(&files, &options, cam, (1280, 720), Coloring::Material, &outside)?;
    let inside = args.dir.join("plant-inside.png");
    let params = PlantParams { triangles: args.triangles, seed: args.seed };
    let (eye, target) =
        interior_viewpoints(&params, 1).into_iter().next().context("no interior viewpoint")?;
    let cam = Camera { eye, target, up: [0.0, 0.0, 1.0], fovy_deg: 70.0 };
    preview::render(&files, &options, cam, (1280, 720), Coloring::Material, &inside)?;
    println!("4. views (CPU preview of the input): {} and {}", outside.display(), inside.display());

    // One frame through the runtime and the GPU renderer (Mesa's CPU drivers where no GPU).
    let frame = args.dir.join("plant-render-lod.png");
    println!("5. GPU frame of the store at 1 px error, coloured by LOD level:");
    let render = crate::cli::RenderArgs {
        store: store.clone(),
        output: frame,
        size: (1280, 720),
        camera: None,
        error: 1.0,
        color: crate::cli::RenderColoring::Level,
        memory: 1 << 30,
    };
    if let Err(e) = crate::commands::render::run(render) {
        println!("   skipped: {e:#}");
    }

    println!(
        "done in {:.1} s, peak memory {}",
        start.elapsed().as_secs_f64(),
        tw_core::mem::peak_rss_bytes().map(fmt_bytes).unwrap_or_else(|| "unknown".into())
    );
    println!(
        "next: `terawalk info {} --verify`, `terawalk preview {} -o view.png`",
        store.display(),
        model.display()
    );
    Ok(())
}
