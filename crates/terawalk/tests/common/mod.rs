//! Helpers shared by the program's end-to-end tests.

use std::path::Path;
use std::process::{Command, Output};

/// Runs the program with `args` in `dir`.
pub fn terawalk(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_terawalk")).args(args).current_dir(dir).output().expect("runs")
}

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Whether a GPU command failed only for want of an adapter (then the test is skipped, unless
/// `TERAWALK_REQUIRE_GPU=1` makes that a failure).
#[allow(dead_code)] // Not every test binary uses every helper.
pub fn no_gpu(o: &Output) -> bool {
    let skip = !o.status.success()
        && stderr(o).contains("no GPU adapter")
        && std::env::var("TERAWALK_REQUIRE_GPU").as_deref() != Ok("1");
    if skip {
        eprintln!("SKIPPED: {} (set TERAWALK_REQUIRE_GPU=1 to make this a failure)", stderr(o));
    }
    skip
}

/// An OBJ of unit cubes, one object per `(name, x0)` at x `x0..x0+1`, y and z `0..1`, every
/// face wound counter-clockwise seen from outside (glTF's convention, which the section colour
/// of back faces relies on: tw-gpu draw.wgsl `section_color`).
#[allow(dead_code)] // Not every test binary uses every helper.
pub fn wound_cubes_obj(cubes: &[(&str, f64)]) -> String {
    let mut obj = String::new();
    for (k, (name, x0)) in cubes.iter().enumerate() {
        obj += &format!("o {name}\n");
        for i in 0..8 {
            obj += &format!("v {} {} {}\n", x0 + (i & 1) as f64, (i >> 1) & 1, (i >> 2) & 1);
        }
        for axis in 0..3 {
            let (b, c) = ((axis + 1) % 3, (axis + 2) % 3);
            for side in 0..2 {
                // Corners (0,0) (1,0) (1,1) (0,1) in the (b, c) plane turn around +axis.
                let mut q: Vec<usize> = [(0, 0), (1, 0), (1, 1), (0, 1)]
                    .iter()
                    .map(|&(u, v)| k * 8 + 1 + (side << axis) + (u << b) + (v << c))
                    .collect();
                if side == 0 {
                    q.reverse();
                }
                obj += &format!("f {} {} {}\nf {} {} {}\n", q[0], q[1], q[2], q[0], q[2], q[3]);
            }
        }
    }
    obj
}
