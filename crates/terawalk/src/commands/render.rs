//! `terawalk render`: one frame of a store on the GPU, headless (tw-runtime selects the LOD cut
//! with frustum culling, tw-gpu draws it and reads it back), written as PNG.

use std::time::Instant;

use anyhow::Result;
use tw_core::Aabb;
use tw_gpu::{ColorMode, Renderer};
use tw_runtime::{Camera, InputCamera, PageCache, SelectOptions, Selector};
use tw_store::Header;

use crate::cli::{RenderArgs, RenderColoring, View};
use crate::commands::preview::preset_direction;
use crate::units::{fmt_bytes, fmt_count};

/// The up axis the camera uses: `--up` when given (overriding the store's at run time, no
/// rebuild), else the one the store records.
pub fn up_axis(header: &Header, over: Option<u8>) -> usize {
    over.unwrap_or(header.up_axis).min(2) as usize
}

/// The default camera: the store's bounds framed from the `--view iso` direction of `preview`,
/// upright along `up` (see [`up_axis`]).
pub fn default_camera(header: &Header, size: (u32, u32), up: usize) -> Result<Camera> {
    let bounds = Aabb { min: header.bounds_min, max: header.bounds_max };
    let (dir, up) = preset_direction(View::Iso, up);
    let c = tw_preview::Camera::frame_bounds(&bounds, dir, up, size.0 as f64 / size.1 as f64);
    Ok(Camera::from_input_coordinates(c.eye, c.target, c.up, c.fovy_deg, header)?)
}

pub fn run(args: RenderArgs) -> Result<()> {
    if !(args.error.is_finite() && args.error >= 0.0) {
        anyhow::bail!("--error must be a finite number ≥ 0, got {}", args.error);
    }
    tw_core::output::check_output(&args.output, &[&args.store])?;
    let store = crate::commands::open_store(&args.store)?;
    let header = store.header();
    let camera = match &args.camera {
        Some(s) => InputCamera::parse(s)?.to_scene(header)?,
        None => default_camera(header, args.size, up_axis(header, args.up))?,
    };
    let mut renderer = Renderer::new_headless(args.size.0, args.size.1)?;
    outln!("adapter: {}", renderer.adapter_summary());
    renderer.set_samples(args.samples.resolve(&renderer))?;
    renderer.set_store_colors(&store);
    renderer.set_color_mode(match args.color {
        RenderColoring::Material => ColorMode::Material,
        RenderColoring::Object => ColorMode::Object,
        RenderColoring::Level => ColorMode::Level,
        RenderColoring::Cluster => ColorMode::Cluster,
    });

    let cache = PageCache::new(&store, args.memory);
    cache.load_root_pages(&store);
    let t = Instant::now();
    let selector = Selector::new(&store);
    let options =
        SelectOptions { tau: args.error, viewport: [args.size.0, args.size.1], frustum_culling: true };
    let selection = selector.select(&store, &cache, &camera, &options);
    let select_time = t.elapsed();
    let image = renderer.render_selection(&store, &cache, &camera, &selection)?;
    let stats = renderer.stats();
    image.save_png(&args.output)?;
    let cs = cache.stats();
    outln!(
        "selection: {} clusters, {} triangles (τ = {} px) in {:.1} ms; {} pages touched, {} resident \
         ({}), {} culled by frustum",
        fmt_count(selection.stats.clusters_selected),
        fmt_count(selection.triangles),
        args.error,
        select_time.as_secs_f64() * 1e3,
        selection.stats.pages_touched,
        cs.resident_pages,
        fmt_bytes(cs.resident_bytes),
        fmt_count(selection.stats.nodes_culled_frustum + selection.stats.groups_culled_frustum),
    );
    outln!(
        "render: {} triangles drawn, {} clusters; upload {:.1} ms, GPU + readback {:.1} ms",
        fmt_count(stats.triangles),
        fmt_count(stats.clusters),
        stats.upload.as_secs_f64() * 1e3,
        stats.render.as_secs_f64() * 1e3,
    );
    outln!(
        "GPU pool: {} clusters uploaded ({}), {} resident, {} batch(es), {} draw call(s) ({:?})",
        fmt_count(stats.pool.uploaded_clusters),
        fmt_bytes(stats.pool.uploaded_bytes),
        fmt_bytes(stats.pool.resident_bytes),
        stats.pool.batches,
        fmt_count(stats.draw_calls),
        renderer.draw_mode(),
    );
    outln!("wrote {} ({}x{})", args.output.display(), args.size.0, args.size.1);
    crate::commands::damage::check(&args.store, &cache.failed_pages(), args.allow_damaged)
}
