//! Imports each file given on the command line and prints its triangles, objects and import
//! time, or the error. Exits with status 1 if any import failed.
//!
//! ```text
//! cargo run -p tw-io --example import_stats -- model.glb other.gltf.gz
//! ```

use std::time::Instant;

use tw_io::{open_source, ImportError, ObjectInfo, Triangle, TriangleSink};

#[derive(Default)]
struct Count {
    triangles: u64,
    degenerate: u64,
}

impl TriangleSink for Count {
    fn object(&mut self, _id: u32, _info: &ObjectInfo) -> Result<(), ImportError> {
        Ok(())
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        self.triangles += 1;
        self.degenerate += t.is_degenerate() as u64;
        Ok(())
    }
}

fn main() {
    let mut failed = false;
    for arg in std::env::args().skip(1) {
        let start = Instant::now();
        let mut count = Count::default();
        let result = open_source(arg.as_ref(), &Default::default()).and_then(|s| s.stream(&mut count));
        let ms = start.elapsed().as_secs_f64() * 1e3;
        match result {
            Ok(summary) => println!(
                "ok\t{arg}\t{} triangles ({} degenerate)\t{} objects\t{} vertices\t{ms:.1} ms",
                count.triangles, count.degenerate, summary.objects, summary.vertices
            ),
            Err(e) => {
                failed = true;
                println!("FAIL\t{arg}\t{e}\t{ms:.1} ms");
            }
        }
    }
    std::process::exit(failed as i32);
}
