//! `terawalk preview`: a CPU-rasterized image of any input, streaming (memory = image size).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use tw_core::Aabb;
use tw_io::{Scene, SceneOptions, SceneStats};
use tw_preview::{Camera, ColorMode, Preview};

use crate::cli::{Coloring, PreviewArgs, View};
use crate::progress;
use crate::units::fmt_count;

/// Parses "x,y,z;x,y,z;x,y,z;fovy" (eye; target; up; vertical field of view in degrees), or an
/// orthographic camera ("…;ortho:HEIGHT").
pub fn parse_camera(s: &str) -> Result<Camera> {
    // One parser of camera strings for every command (tw-runtime's), here into the preview's type.
    let c = tw_runtime::InputCamera::parse(s)?;
    Ok(Camera { eye: c.eye, target: c.target, up: c.up, fovy_deg: c.fovy_deg, ortho_height: c.ortho_height })
}

/// The view direction (from the model towards the eye) of a preset, for a model with `up` axis.
pub(crate) fn preset_direction(view: View, up: usize) -> ([f64; 3], [f64; 3]) {
    // Directions in a Z-up frame, then the axes permuted so that Z becomes `up`.
    let (dir, upv) = match view {
        View::Iso => ([-0.55, -0.75, 0.55], [0.0, 0.0, 1.0]),
        View::Top => ([0.0, 0.0, 1.0], [0.0, 1.0, 0.0]),
        View::Front => ([0.0, -1.0, 0.08], [0.0, 0.0, 1.0]),
    };
    let permute = |v: [f64; 3]| match up {
        0 => [v[2], v[0], v[1]],
        1 => [v[0], v[2], -v[1]],
        _ => v,
    };
    (permute(dir), permute(upv))
}

/// Streams `files` once to find their bounds (needed to frame a preset view), and the up axis
/// of their formats' convention (glTF: y; otherwise z; `tw_io::up::format_default`).
pub fn scene_bounds(files: &[PathBuf], options: &SceneOptions) -> Result<(Aabb, u8)> {
    let mut stats = SceneStats::default();
    let scene = Scene::open(files, options.clone())?;
    let up = tw_io::up::format_default(scene.formats()).axis;
    scene.stream(&mut stats)?;
    if stats.bounds.is_empty() {
        bail!("the input holds no triangles");
    }
    Ok((stats.bounds, up))
}

/// Renders `files` from `camera` into `output`; returns the triangles streamed.
pub fn render(
    files: &[PathBuf],
    options: &SceneOptions,
    camera: Camera,
    size: (u32, u32),
    coloring: Coloring,
    output: &Path,
) -> Result<u64> {
    let mode = match coloring {
        Coloring::Material => ColorMode::Object,
        Coloring::Object => ColorMode::HashObject,
    };
    let mut preview = Preview::new(size.0, size.1, camera)?.with_color_mode(mode);
    let scene = Scene::open(files, options.clone())?;
    let pb = progress::bytes(0, "rendering");
    let summary = scene.stream_with_progress(&mut preview, &mut |p| {
        if let Some(t) = p.total {
            pb.set_length(t);
        }
        pb.set_position(p.done)
    })?;
    pb.finish_and_clear();
    preview.write_png(output).with_context(|| format!("cannot write {}", output.display()))?;
    Ok(summary.triangles)
}

pub fn run(args: PreviewArgs) -> Result<()> {
    let start = Instant::now();
    tw_core::output::check_output(&args.output, &args.files)?;
    let options = SceneOptions { import: args.import.options() };
    let camera = match &args.camera {
        Some(c) => parse_camera(c)?,
        None => {
            let (bounds, format_up) = scene_bounds(&args.files, &options)?;
            let up = args.up.unwrap_or(format_up) as usize;
            let (dir, upv) = preset_direction(args.view, up);
            Camera::frame_bounds(&bounds, dir, upv, args.size.0 as f64 / args.size.1 as f64)
        }
    };
    let n = render(&args.files, &options, camera, args.size, args.color, &args.output)?;
    outln!(
        "wrote {} ({}x{}): {} triangles in {:.1} s",
        args.output.display(),
        args.size.0,
        args.size.1,
        fmt_count(n),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_strings() {
        let c = parse_camera("1,2,3; 4,5,6; 0,0,1; 60").unwrap();
        assert_eq!(c.eye, [1.0, 2.0, 3.0]);
        assert_eq!(c.target, [4.0, 5.0, 6.0]);
        assert_eq!(c.fovy_deg, 60.0);
        assert!(parse_camera("1,2,3;4,5,6;0,0,1").is_err());
        assert!(parse_camera("1,2;4,5,6;0,0,1;60").is_err());
        assert!(parse_camera("1,2,3;4,5,6;0,0,1;0").is_err());
        assert!(parse_camera("1,2,3;1,2,3;0,0,1;60").is_err());
        assert!(parse_camera("nan,2,3;4,5,6;0,0,1;60").is_err());
        let ortho = parse_camera("1,2,3;4,5,6;0,0,1;ortho:12.5").unwrap();
        assert_eq!((ortho.ortho_height, ortho.eye), (Some(12.5), [1.0, 2.0, 3.0]));
        assert_eq!(parse_camera("1,2,3;4,5,6;0,0,1;60").unwrap().ortho_height, None);
        assert!(parse_camera("1,2,3;4,5,6;0,0,1;ortho:0").is_err());
    }

    /// The presets frame a glTF input y-up and a PLY input z-up, as `build` records them.
    #[test]
    fn preset_up_follows_the_format() {
        let dir = tempfile::tempdir().unwrap();
        for (name, up) in [("t.glb", 1), ("t.ply", 2)] {
            let path = dir.path().join(name);
            let mut w = tw_io::write::create_writer(&path).unwrap();
            w.object(0, &tw_io::ObjectInfo::default()).unwrap();
            let tri = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 3.0]];
            w.triangle(&tw_io::Triangle::new(tri, 0)).unwrap();
            w.finish().unwrap();
            let (bounds, got) = scene_bounds(&[path], &SceneOptions::default()).unwrap();
            assert_eq!(got, up, "{name}");
            // Upright either way: the triangle's height (3 along z as written) is along `up`.
            assert_eq!(bounds.max[up as usize] - bounds.min[up as usize], 3.0, "{name}");
        }
    }
}
