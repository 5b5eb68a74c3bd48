//! `terawalk export`: a store's scene back out (tw-export). `-o FILE.glb` writes the LOD cut
//! `render` would draw for a camera and pixel error (the same selection and default camera), or
//! with `--region` the full-detail triangles inside a box; `--tiles DIR` writes the store's LOD
//! hierarchy as an OGC 3D Tiles 1.1 tileset.

use std::time::Instant;

use anyhow::{Context, Result};
use tw_export::cut::Region;
use tw_export::{export_glb, export_tiles, GlbSelection, TilesOptions};
use tw_runtime::{InputCamera, PageCache};
use tw_store::Header;

use crate::cli::ExportArgs;
use crate::commands::render::{default_camera, up_axis};
use crate::units::{fmt_bytes, fmt_count};

pub fn run(args: ExportArgs) -> Result<()> {
    if !(args.error.is_finite() && args.error >= 0.0) {
        anyhow::bail!("--error must be a finite number ≥ 0, got {}", args.error);
    }
    let region = args.region.as_deref().map(Region::parse).transpose()?;
    if let Some(output) = &args.output {
        tw_core::output::check_output(output, &[&args.store])?;
    }
    let store = crate::commands::open_store(&args.store)?;
    let cache = PageCache::new(&store, args.memory);
    cache.load_root_pages(&store);
    let t = Instant::now();
    match (&args.output, &args.tiles) {
        (Some(output), None) => {
            let selection = match region {
                Some(r) => GlbSelection::Region(r),
                None => {
                    let header = store.header();
                    let camera = match &args.camera {
                        Some(s) => parse_camera(s, header)?.to_scene(header)?,
                        None => default_camera(header, args.size, up_axis(header, None))?,
                    };
                    GlbSelection::Camera { camera, tau: args.error, viewport: [args.size.0, args.size.1] }
                }
            };
            let e = export_glb(&store, &cache, &selection, output)
                .with_context(|| format!("cannot export {}", args.store.display()))?;
            let what = match &selection {
                GlbSelection::Region(_) => format!(
                    "full detail in the region ({} triangles reaching outside left out)",
                    fmt_count(e.outside)
                ),
                GlbSelection::Camera { tau, .. } => format!("the LOD cut at τ = {tau} px"),
            };
            outln!(
                "wrote {} ({}): {} triangles, {} objects, {} clusters, {what} in {:.2} s",
                output.display(),
                fmt_bytes(e.file.bytes),
                fmt_count(e.file.triangles),
                fmt_count(e.file.objects as u64),
                fmt_count(e.clusters),
                t.elapsed().as_secs_f64()
            );
        }
        (None, Some(dir)) => {
            let options = TilesOptions { tile_triangles: args.tile_triangles };
            let s = export_tiles(&store, &cache, dir, &options)
                .with_context(|| format!("cannot export {}", args.store.display()))?;
            // 3D Tiles errors are metres; a store without known units is taken as metres.
            let unit = if store.metres_per_unit().is_some() { "m" } else { "units (taken as metres)" };
            outln!(
                "wrote {}: {} tiles ({} in all), depth {}, {} triangles over all levels, at most {} per \
                 tile; root error {:.4} {unit}, in {:.2} s",
                dir.join("tileset.json").display(),
                fmt_count(s.tiles as u64),
                fmt_bytes(s.bytes),
                s.depth,
                fmt_count(s.triangles),
                fmt_count(s.max_tile_triangles),
                s.root_error,
                t.elapsed().as_secs_f64()
            );
        }
        _ => anyhow::bail!("give -o FILE.glb or --tiles DIR"),
    }
    crate::commands::damage::check(&args.store, &cache.failed_pages(), args.allow_damaged)
}

/// `--camera`: `render`'s "eye;target;up;fovy", or just "eye;target", looking up along the
/// store's up axis with the field of view of `render`'s default camera.
fn parse_camera(s: &str, header: &Header) -> Result<InputCamera> {
    if s.split(';').count() != 2 {
        return Ok(InputCamera::parse(s)?);
    }
    let mut up = ["0"; 3];
    up[up_axis(header, None)] = "1";
    let fovy = tw_preview::camera::FRAMING_FOVY_DEG;
    Ok(InputCamera::parse(&format!("{s};{};{fovy}", up.join(",")))?)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The short form "eye;target" gets the store's up axis and the default field of view; the
    /// full form is `render`'s.
    #[test]
    fn short_camera_looks_up_the_stores_axis() {
        let mut header = Header::empty([0.0; 3], [1.0; 3], [0.0; 3], 1.0);
        header.up_axis = 1;
        let c = parse_camera("1,2,3;4,5,6", &header).unwrap();
        assert_eq!((c.eye, c.target, c.up), ([1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [0.0, 1.0, 0.0]));
        assert_eq!(c.fovy_deg, tw_preview::camera::FRAMING_FOVY_DEG);
        let c = parse_camera("1,2,3;4,5,6;0,0,1;30", &header).unwrap();
        assert_eq!((c.up, c.fovy_deg), ([0.0, 0.0, 1.0], 30.0));
        assert!(parse_camera("1,2,3", &header).unwrap_err().to_string().contains("part"));
    }
}
