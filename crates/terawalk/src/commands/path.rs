//! `terawalk path`: generate a camera path through a store (tw-runtime's `pathgen`: an interior
//! walk at eye height, a fly-over, or a fly-around when there is nothing to walk on; or an
//! approach from the overview to a close view) and write it as JSON for `bench` and the viewer.

use std::time::Instant;

use anyhow::Result;
use tw_runtime::pathgen::{
    format_length as len, generate_path, PathOptions, PathPart, PathReport, RegionKind,
};

use crate::cli::{PathArgs, PathPartArg};
use crate::progress;
use crate::units::fmt_count;

pub fn run(args: PathArgs, quiet: bool) -> Result<()> {
    let start = Instant::now();
    tw_core::output::check_output(&args.output, &[&args.store])?;
    let store = crate::commands::open_store(&args.store)?;
    let options = path_options(&args);
    let units = store.units().to_string();
    let unit_name = if units.is_empty() { "units".to_string() } else { units.clone() };
    // Only the walk needs an eye height (the approach and the fly-over scale with the model).
    let walks = matches!(options.part, PathPart::Walk | PathPart::Both);
    if units.is_empty() && options.eye_height.is_none() && walks {
        tracing::info!("the store has no units: assuming metres (eye height 1.7)");
    } else if walks && options.eye_height.is_none() && store.metres_per_unit().is_none() {
        eprintln!("note: unknown units {units:?}; assuming metres (give --eye-height in the model's units)");
    }
    let pb = progress::count(0, "voxelizing");
    if quiet || options.part == PathPart::Approach {
        pb.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    pb.set_message("coarse pages");
    let generated = generate_path(&store, &options, &mut |_stage, done, total| {
        pb.set_length(total);
        pb.set_position(done);
    })?;
    pb.finish_and_clear();
    let path = &generated.path;
    path.save(&args.output)?;
    let r = &generated.report;
    if let Some(why) = &r.fallback {
        outln!("no walk: {why}; the path is a fly-around instead");
    }
    if r.walk_frames > 0 {
        print_walk(r, args.fps, &unit_name);
    }
    if r.fly_frames > 0 {
        outln!("fly: {} frames, {} {unit_name}", r.fly_frames, len(r.fly_length));
    }
    if r.approach_frames > 0 {
        print_approach(r, &unit_name);
    }
    let heights = path.frames.iter().filter_map(|f| f.ortho_height);
    if let Some((lo, hi)) = heights
        .fold(None, |m: Option<(f64, f64)>, h| Some(m.map_or((h, h), |(lo, hi)| (lo.min(h), hi.max(h)))))
    {
        let range = if lo == hi { len(lo) } else { format!("{} to {}", len(lo), len(hi)) };
        outln!("orthographic: views {range} {unit_name} high");
    }
    let parts = if r.approach_frames > 0 {
        format!("approach {}", r.approach_frames)
    } else {
        format!("walk {} / fly {}", r.walk_frames, r.fly_frames)
    };
    outln!(
        "wrote {}: {} frames ({:.1} s at {} fps; {parts}), {} {unit_name} in {:.2} s",
        args.output.display(),
        path.frames.len(),
        path.duration_s(),
        args.fps,
        len(r.walk_length + r.fly_length + r.approach_length),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// The generator's options, from the command's.
fn path_options(args: &PathArgs) -> PathOptions {
    PathOptions {
        frames: args.frames,
        fps: args.fps,
        part: match args.part {
            PathPartArg::Walk => PathPart::Walk,
            PathPartArg::Fly => PathPart::Fly,
            PathPartArg::Both => PathPart::Both,
            PathPartArg::Approach => PathPart::Approach,
        },
        walk_share: args.walk_share,
        eye_height: args.eye_height,
        speed: args.speed,
        fovy_deg: args.fovy,
        ortho: args.ortho,
        seed: args.seed,
        voxel_size: args.voxel,
        max_voxels: args.max_voxels,
    }
}

/// The walk's summary: its length and speed, the region walked, and the voxelization behind it.
fn print_walk(r: &PathReport, fps: f64, unit_name: &str) {
    outln!(
        "walk: {} frames, {} {unit_name} at {} {unit_name}/s, eye height {} {unit_name}, {} region of {} \
         walkable spans ({} in all), {} waypoints",
        r.walk_frames,
        len(r.walk_length),
        len(r.walk_length / (r.walk_frames.max(2) - 1) as f64 * fps),
        len(r.eye_height),
        match r.region {
            Some(RegionKind::Interior) => "interior",
            Some(RegionKind::Outdoor) => "outdoor",
            None => "no",
        },
        fmt_count(r.region_spans as u64),
        fmt_count(r.walkable_spans as u64),
        r.waypoints
    );
    outln!(
        "  voxels: {} {unit_name}, grid {} x {} x {}{}; {} coarse triangles from {} pages{}",
        len(r.voxel_size),
        r.grid[0],
        r.grid[1],
        r.grid[2],
        if r.windowed {
            " (a window around the centre: the scene is too large for the voxel cap)"
        } else {
            ""
        },
        fmt_count(r.triangles_voxelized),
        fmt_count(r.pages_read),
        if r.pages_failed > 0 { format!(", {} pages failed", r.pages_failed) } else { String::new() }
    );
}

/// The approach's summary: from how far to how close, and its length.
fn print_approach(r: &PathReport, unit_name: &str) {
    let (from, to) = r.approach_distances;
    outln!(
        "approach: {} frames from the overview ({} {unit_name} from the model's centre) to a close \
         view of its top ({} {unit_name} away, {:.1}x closer), {} {unit_name}",
        r.approach_frames,
        len(from),
        len(to),
        from / to,
        len(r.approach_length)
    );
}
