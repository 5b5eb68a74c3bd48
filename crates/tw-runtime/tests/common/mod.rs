//! Stores shared by the selection, streaming and coherence tests, built once per test binary with
//! tw-build: a 50 k-triangle plant (default pages and small ones) and a closed scene of
//! icospheres.
#![allow(dead_code)] // each test binary uses some of them

use std::path::Path;

use tw_io::{ImportError, ObjectInfo, SourceSummary, Triangle, TriangleSink, TriangleSource};

/// The 50 k-triangle plant (seed 1), built once per process (tw-testkit).
pub fn plant_path() -> &'static Path {
    tw_testkit::plant(50_000, 1, tw_build::BuildOptions { memory: 256 << 20, ..Default::default() }).path()
}

/// The plant with small pages (1024 triangles) and only the top two levels in root pages:
/// many pages, so that a walk keeps needing new ones.
pub fn small_pages_plant_path() -> &'static Path {
    let mut options = tw_build::BuildOptions { memory: 256 << 20, root_depth: 2, ..Default::default() };
    options.pages.page_triangles = 1024;
    tw_testkit::plant(50_000, 1, options).path()
}

/// Whole icospheres (closed, manifold), one object each.
pub struct Spheres(pub Vec<([f64; 3], f64, u32)>);

impl TriangleSource for Spheres {
    fn name(&self) -> String {
        "spheres".into()
    }
    fn progress_total(&self) -> Option<u64> {
        None
    }
    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        for (o, &(c, r, level)) in self.0.iter().enumerate() {
            sink.object(o as u32, &ObjectInfo::default())?;
            let (v, f) = tw_io::generate::icosphere(c, r, level);
            for t in f {
                sink.triangle(&Triangle::new(t.map(|i| v[i as usize]), o as u32))?;
            }
        }
        Ok(SourceSummary { objects: self.0.len() as u32, ..Default::default() })
    }
}

/// A big sphere split over several cells (small `max_cell_triangles`), beside a row of small
/// ones that HLOD merges: closed input, so no cut may have a boundary edge.
pub fn spheres_path() -> &'static Path {
    tw_testkit::once("tw-runtime spheres".into(), || {
        let mut list = vec![([0.0, 0.0, 0.0], 10.0, 6)];
        for i in 0..6 {
            list.push(([15.0 + 3.0 * i as f64, 0.0, 0.0], 1.0, 3));
        }
        let mut options = tw_build::BuildOptions { memory: 256 << 20, ..Default::default() };
        options.redefine.max_cell_triangles = 8192;
        tw_testkit::build(Box::new(Spheres(list)), &options)
    })
    .path()
}
