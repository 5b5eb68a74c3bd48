//! `terawalk generate`: procedural scenes written to a model file.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, Result};
use tw_io::generate::{AssemblyObjects, AssemblyParams, AssemblySource, PlantParams, PlantSource};
use tw_io::{Scene, SceneSummary, TriangleSource};

use crate::cli::{GenerateArgs, SceneKind};
use crate::progress;
use crate::units::{fmt_bytes, fmt_count, fmt_count_rate};

/// What one generation wrote.
pub struct Generated {
    pub summary: SceneSummary,
    pub file_bytes: u64,
    pub seconds: f64,
}

/// Generates a plant of `triangles` for `seed` into `output` (format by extension), atomically.
pub fn generate_plant(triangles: u64, seed: u64, output: &Path) -> Result<Generated> {
    let source = PlantSource::new(PlantParams { triangles, seed })?;
    write_scene(Box::new(source), output)
}

/// Generates a CAD assembly (millimetres) of `triangles` (rounded down to even) for `seed`
/// into `output`, one object per part or, with `one_object`, a single object.
pub fn generate_assembly(triangles: u64, seed: u64, one_object: bool, output: &Path) -> Result<Generated> {
    let objects = if one_object { AssemblyObjects::One } else { AssemblyObjects::PerPart };
    let source = AssemblySource::new(AssemblyParams { triangles, seed, objects })?;
    write_scene(Box::new(source), output)
}

/// Streams `source` into `output` (format by extension) with a progress bar.
fn write_scene(source: Box<dyn TriangleSource>, output: &Path) -> Result<Generated> {
    let start = Instant::now();
    let total = source.progress_total().unwrap_or(0);
    let mut writer =
        tw_io::write::create_writer(output).with_context(|| format!("cannot write {}", output.display()))?;
    let pb = progress::count(total, "generating");
    pb.set_message(output.display().to_string());
    let summary = Scene::from_sources(vec![source])
        .stream_with_progress(writer.as_mut(), &mut |p| pb.set_position(p.done))?;
    pb.set_message("finishing file");
    writer.finish()?;
    pb.finish_and_clear();
    let file_bytes = std::fs::metadata(output).map(|m| m.len()).unwrap_or(0);
    Ok(Generated { summary, file_bytes, seconds: start.elapsed().as_secs_f64() })
}

/// Prints what one generation wrote.
fn report(output: &Path, g: &Generated) {
    outln!(
        "wrote {}: {} triangles in {} objects, {} in {:.1} s ({})",
        output.display(),
        fmt_count(g.summary.triangles),
        fmt_count(g.summary.objects as u64),
        fmt_bytes(g.file_bytes),
        g.seconds,
        fmt_count_rate(g.summary.triangles, g.seconds, "triangles")
    );
}

pub fn run(args: GenerateArgs) -> Result<()> {
    match args.kind {
        SceneKind::Plant => {
            if args.one_object {
                anyhow::bail!("--one-object applies to `generate assembly` only");
            }
            let g = generate_plant(args.triangles, args.seed, &args.output)?;
            report(&args.output, &g);
        }
        SceneKind::Assembly => {
            let g = generate_assembly(args.triangles, args.seed, args.one_object, &args.output)?;
            report(&args.output, &g);
            // Model files carry no units; the store records them at build time.
            outln!("units: millimetres (build with --units mm)");
        }
    }
    Ok(())
}
