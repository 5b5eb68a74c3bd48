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
