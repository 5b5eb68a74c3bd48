//! OBJ import throughput: writes a grid mesh OBJ (positions with six decimals, normals, faces
//! alternating between `f a b c` and `f a//a b//b c//c` rows) and streams it three times into a
//! counting sink through [`tw_io::format::open_source`], printing MB/s for each run and the median.
//!
//! ```text
//! cargo run --release -p tw-io --example bench_obj -- /tmp/grid.obj [size_mb]
//! ```
//!
//! The file is only written when it does not exist yet (delete it to regenerate).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::Instant;

use tw_io::format::{open_source, ImportOptions};
use tw_io::{ImportError, ObjectId, ObjectInfo, Triangle, TriangleSink};

/// Counts what arrives, and sums coordinates so that nothing can be optimised away.
#[derive(Default)]
struct Count {
    objects: u64,
    triangles: u64,
    with_normals: u64,
    sum: f64,
}

impl TriangleSink for Count {
    fn object(&mut self, _id: ObjectId, _info: &ObjectInfo) -> Result<(), ImportError> {
        self.objects += 1;
        Ok(())
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        self.triangles += 1;
        self.with_normals += t.normals.is_some() as u64;
        self.sum += t.positions[0][0] + t.positions[1][1] + t.positions[2][2];
        Ok(())
    }
}

/// Writes a height-field grid `WIDTH` vertices wide, row by row (each row's vertices and normals,
/// then the faces joining it to the previous row), until the file reaches `target` bytes.
fn generate(path: &Path, target: u64) -> std::io::Result<()> {
    const WIDTH: u64 = 1000;
    let mut out = BufWriter::with_capacity(1 << 20, File::create(path)?);
    writeln!(out, "# terawalk bench_obj grid\no grid")?;
    let mut written = 0u64;
    let mut row = 0u64;
    let mut line = String::new();
    while written < target {
        line.clear();
        use std::fmt::Write as _;
        for c in 0..WIDTH {
            let (x, z) = (c as f64 * 0.01 - 5.0, row as f64 * 0.01 - 5.0);
            let y = (x * 1.3).sin() * (z * 0.7).cos() * 2.345678;
            writeln!(line, "v {x:.6} {y:.6} {z:.6}").unwrap();
        }
        for c in 0..WIDTH {
            let a = c as f64 * 0.001;
            writeln!(line, "vn {:.6} {:.6} {:.6}", a.sin() * 0.3, 0.9, a.cos() * 0.3).unwrap();
        }
        if row > 0 {
            for c in 0..WIDTH - 1 {
                // 1-based indices of the quad's corners in the previous and this row.
                let a = (row - 1) * WIDTH + c + 1;
                let (b, d, e) = (a + 1, a + WIDTH, a + WIDTH + 1);
                if row.is_multiple_of(2) {
                    writeln!(line, "f {a} {b} {e}\nf {a} {e} {d}").unwrap();
                } else {
                    writeln!(line, "f {a}//{a} {b}//{b} {e}//{e}\nf {a}//{a} {e}//{e} {d}//{d}").unwrap();
                }
            }
        }
        out.write_all(line.as_bytes())?;
        written += line.len() as u64;
        row += 1;
    }
    out.flush()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: bench_obj PATH [SIZE_MB]")?;
    let size_mb: u64 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(300);
    let path = Path::new(&path);
    if !path.exists() {
        let t = Instant::now();
        generate(path, size_mb << 20)?;
        eprintln!("wrote {} in {:.1} s", path.display(), t.elapsed().as_secs_f64());
    }
    let bytes = std::fs::metadata(path)?.len();
    let mut rates = Vec::new();
    for run in 1..=3 {
        let t = Instant::now();
        let mut sink = Count::default();
        let summary = open_source(path, &ImportOptions::default())?.stream(&mut sink)?;
        let secs = t.elapsed().as_secs_f64();
        let rate = bytes as f64 / 1e6 / secs;
        println!(
            "run {run}: {:.1} MB in {secs:.2} s = {rate:.1} MB/s ({} vertices, {} triangles, {} with normals, \
             {} objects, checksum {:.3})",
            bytes as f64 / 1e6,
            summary.vertices,
            sink.triangles,
            sink.with_normals,
            sink.objects,
            sink.sum
        );
        rates.push(rate);
    }
    rates.sort_by(f64::total_cmp);
    println!("median: {:.1} MB/s", rates[1]);
    Ok(())
}
