//! The camera path a benchmark walks: a path file, or one generated as `terawalk path` does;
//! cut to the frames asked for, as cameras in the store's coordinates.

use anyhow::{bail, Context, Result};
use tw_runtime::pathgen::{generate_path, PathOptions};
use tw_runtime::{Camera, CameraPath};
use tw_store::Store;

use crate::{BenchOptions, Observer};

/// The frames of a benchmark: each one's camera and path segment (the report's captions).
pub struct Frames {
    pub cameras: Vec<Camera>,
    pub segments: Vec<String>,
}

impl Frames {
    /// Loads or generates the path, keeps the first `options.frames`, and places the cameras.
    pub fn of(options: &BenchOptions, store: &Store, observer: &mut dyn Observer) -> Result<Frames> {
        let path = match &options.path {
            Some(p) => CameraPath::load(p)?,
            None => generated(options, store, observer)?,
        };
        let mut frames = path.frames;
        if let Some(n) = options.frames {
            frames.truncate(n);
        }
        if frames.is_empty() {
            bail!("the camera path has no frames");
        }
        let cameras: Vec<Camera> = frames
            .iter()
            .enumerate()
            .map(|(i, f)| f.to_scene(store.header()).with_context(|| format!("path frame {i}")))
            .collect::<Result<_>>()?;
        Ok(Frames { cameras, segments: frames.into_iter().map(|f| f.segment).collect() })
    }
}

/// A path generated for `store` (walk and fly-over, 300 frames unless `options.frames` says),
/// announced with its parts.
fn generated(options: &BenchOptions, store: &Store, observer: &mut dyn Observer) -> Result<CameraPath> {
    let path_options = PathOptions { frames: options.frames.unwrap_or(300).max(2), ..Default::default() };
    let generated = generate_path(store, &path_options, &mut |_, _, _| {})
        .with_context(|| format!("cannot generate a camera path for {}", options.store.display()))?;
    let r = &generated.report;
    observer.line(&format!(
        "path: generated {} frames ({} walking, {} flying){}",
        generated.path.frames.len(),
        r.walk_frames,
        r.fly_frames,
        r.fallback.as_ref().map(|f| format!("; {f}")).unwrap_or_default()
    ));
    Ok(generated.path)
}
