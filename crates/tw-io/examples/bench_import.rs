//! Import throughput: streams files into a counting sink and prints MB/s (median of 3 runs).
//!
//! ```text
//! cargo run --release -p tw-io --example bench_import -- FILE...          # through tw_io::Scene
//! cargo run --release -p tw-io --example bench_import -- --raw FILE...    # the importer alone
//! cargo run --release -p tw-io --example bench_import -- gen-ply OUT.ply TRIANGLES
//! cargo run --release -p tw-io --example bench_import -- gen-stl OUT.stl TRIANGLES
//! ```
//! The generated files are a height-field grid: binary little-endian PLY (`float x y z`,
//! `list uchar int vertex_indices`) and binary STL (with a header starting "solid", as many
//! exporters write it). MB/s counts bytes on disk; for .gz inputs that is compressed bytes.

use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::Instant;

use tw_io::format::ImportOptions;
use tw_io::{ImportError, ObjectInfo, Scene, SceneOptions, SceneStats, Triangle, TriangleSink};

/// Counts triangles and sums a coordinate so that the work cannot be optimised away.
#[derive(Default)]
struct Count {
    triangles: u64,
    checksum: f64,
}

impl TriangleSink for Count {
    fn object(&mut self, _id: u32, _info: &ObjectInfo) -> Result<(), ImportError> {
        Ok(())
    }
    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        self.triangles += 1;
        self.checksum += t.positions[2][0];
        Ok(())
    }
}

fn grid(triangles: u64) -> (u64, impl Fn(u64, u64) -> [f32; 3]) {
    let k = (((triangles / 2) as f64).sqrt().ceil() as u64).max(1);
    (k, move |i: u64, j: u64| [i as f32 * 0.01, j as f32 * 0.01, ((i * 31 + j * 17) % 101) as f32 * 0.001])
}

fn gen_ply(path: &Path, triangles: u64) -> std::io::Result<()> {
    let (k, v) = grid(triangles);
    let quads = triangles.div_ceil(2);
    let mut w = BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    write!(
        w,
        "ply\nformat binary_little_endian 1.0\ncomment terawalk bench grid\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nelement face {}\n\
         property list uchar int vertex_indices\nend_header\n",
        (k + 1) * (k + 1),
        quads * 2
    )?;
    for j in 0..=k {
        for i in 0..=k {
            for c in v(i, j) {
                w.write_all(&c.to_le_bytes())?;
            }
        }
    }
    for q in 0..quads {
        let (i, j) = (q % k, q / k);
        let a = (j * (k + 1) + i) as i32;
        let (b, c, d) = (a + 1, a + 1 + (k as i32 + 1), a + (k as i32 + 1));
        for t in [[a, b, c], [a, c, d]] {
            w.write_all(&[3])?;
            for x in t {
                w.write_all(&x.to_le_bytes())?;
            }
        }
    }
    w.flush()
}

fn gen_stl(path: &Path, triangles: u64) -> std::io::Result<()> {
    let (k, v) = grid(triangles);
    let mut w = BufWriter::with_capacity(1 << 20, std::fs::File::create(path)?);
    let mut header = [b' '; 80];
    header[..23].copy_from_slice(b"solid terawalk bench   ");
    w.write_all(&header)?;
    w.write_all(&(triangles as u32).to_le_bytes())?;
    for t in 0..triangles {
        let q = t / 2;
        let (i, j) = (q % k, q / k);
        let corners = if t % 2 == 0 {
            [v(i, j), v(i + 1, j), v(i + 1, j + 1)]
        } else {
            [v(i, j), v(i + 1, j + 1), v(i, j + 1)]
        };
        for c in [0f32, 0.0, 1.0] {
            w.write_all(&c.to_le_bytes())?;
        }
        for p in corners {
            for c in p {
                w.write_all(&c.to_le_bytes())?;
            }
        }
        w.write_all(&[0, 0])?;
    }
    w.flush()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("gen-ply") | Some("gen-stl") if args.len() == 3 => {
            let n: u64 = args[2].parse()?;
            if args[0] == "gen-ply" {
                gen_ply(Path::new(&args[1]), n)?;
            } else {
                gen_stl(Path::new(&args[1]), n)?;
            }
            println!("wrote {} ({} bytes)", args[1], std::fs::metadata(&args[1])?.len());
            return Ok(());
        }
        None => {
            eprintln!("usage: bench_import [--raw] FILE... | gen-ply OUT N | gen-stl OUT N");
            std::process::exit(2);
        }
        _ => {}
    }
    let raw = args[0] == "--raw";
    for file in args.iter().skip(raw as usize) {
        let bytes = std::fs::metadata(file)?.len();
        let mut times = Vec::new();
        let mut triangles = 0;
        for _ in 0..3 {
            let start = Instant::now();
            if raw {
                let source = tw_io::open_source(Path::new(file), &ImportOptions::default())?;
                let mut count = Count::default();
                source.stream(&mut count)?;
                triangles = count.triangles;
                std::hint::black_box(count.checksum);
            } else {
                let scene = Scene::open(&[file], SceneOptions::default())?;
                let mut stats = SceneStats::default();
                scene.stream(&mut stats)?;
                triangles = stats.triangles;
            }
            times.push(start.elapsed().as_secs_f64());
        }
        times.sort_by(f64::total_cmp);
        let t = times[1];
        println!(
            "{file}: {triangles} triangles, {:.1} MB in {t:.3} s (median of 3{}): {:.0} MB/s, {:.1} M triangles/s",
            bytes as f64 / 1e6,
            if raw { ", importer alone" } else { ", through Scene" },
            bytes as f64 / 1e6 / t,
            triangles as f64 / 1e6 / t
        );
    }
    Ok(())
}
