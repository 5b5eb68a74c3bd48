//! `terawalk generate`: procedural scenes written to a model file.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use tw_io::generate::{PlantParams, PlantSource};
use tw_io::{Scene, SceneSummary};

use crate::cli::{GenerateArgs, SceneKind};
use crate::progress;
use crate::units::{fmt_bytes, fmt_count};

/// What one generation wrote.
pub struct Generated {
    pub summary: SceneSummary,
    pub file_bytes: u64,
    pub seconds: f64,
}

/// Generates a plant of `triangles` for `seed` into `output` (format by extension), atomically.
pub fn generate_plant(triangles: u64, seed: u64, output: &Path) -> Result<Generated> {
    let start = Instant::now();
    let source = PlantSource::new(PlantParams { triangles, seed })?;
    let mut writer =
        tw_io::write::create_writer(output).with_context(|| format!("cannot write {}", output.display()))?;
    let pb = progress::count(triangles, "generating");
    pb.set_message(output.display().to_string());
    let summary = Scene::from_sources(vec![Box::new(source)])
        .stream_with_progress(writer.as_mut(), &mut |p| pb.set_position(p.done))?;
    pb.set_message("finishing file");
    writer.finish()?;
    pb.finish_and_clear();
    let file_bytes = std::fs::metadata(output).map(|m| m.len()).unwrap_or(0);
    Ok(Generated { summary, file_bytes, seconds: start.elapsed().as_secs_f64() })
}

pub fn run(args: GenerateArgs) -> Result<()> {
    match args.kind {
        SceneKind::Plant => {
            let g = generate_plant(args.triangles, args.seed, &args.output)?;
            println!(
                "wrote {}: {} triangles in {} objects, {} in {:.1} s ({:.2} M triangles/s)",
                args.output.display(),
                fmt_count(g.summary.triangles),
                fmt_count(g.summary.objects as u64),
                fmt_bytes(g.file_bytes),
                g.seconds,
                g.summary.triangles as f64 / 1e6 / g.seconds.max(1e-9)
            );
        }
    }
    Ok(())
}
