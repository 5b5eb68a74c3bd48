//! Embeds the git commit terawalk is built from as `TERAWALK_COMMIT` (`terawalk bench` records it
//! in its report, so that a figure can be traced to the code that measured it).
//!
//! Where it comes from, first found wins: the `TERAWALK_COMMIT` environment variable (for
//! packagers building from a source tarball who know the commit), `git rev-parse --short HEAD`
//! in a git checkout, else "unknown". No dependency, and no failure: a tarball without `.git`, a
//! machine without `git` or a repository git refuses to read all build, with "unknown".
//!
//! A checkout whose tracked sources differ from HEAD (`crates/`, `Cargo.toml`, `Cargo.lock`)
//! is stamped `HASH-dirty`: a binary built from an uncommitted experiment must not pass for the
//! commit (a stale release binary carrying a dropped experiment once produced "committed"
//! figures; docs/benchmarks-log.md, session 36). The sources are watched, so an edit reruns
//! this script and the stamp follows the tree the binary is built from.

use std::path::Path;
use std::process::Command;

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=TERAWALK_COMMIT");
    let given = std::env::var("TERAWALK_COMMIT").ok().and_then(|c| one_line(&c));
    let commit = given.or_else(git_commit).unwrap_or_else(|| "unknown".into());
    println!("cargo:rustc-env=TERAWALK_COMMIT={commit}");
}

/// The short hash of HEAD, and the files that change when HEAD moves watched, so that the next
/// build after a checkout or a commit embeds the new hash.
fn git_commit() -> Option<String> {
    // A source tarball unpacked inside some other repository is not that repository's code:
    // the commit counts only if this crate is tracked in it.
    git(&["ls-files", "--full-name", "--error-unmatch", "Cargo.toml"])?;
    let commit = git(&["rev-parse", "--short", "HEAD"])?;
    let top = git(&["rev-parse", "--show-toplevel"])?;
    let sources = ["crates", "Cargo.toml", "Cargo.lock"];
    for source in sources {
        let path = Path::new(&top).join(source);
        if path.exists() {
            // A directory is watched with everything in it (cargo compares every file's mtime).
            println!("cargo:rerun-if-changed={}", path.display());
        }
    }
    let mut status = vec!["-C", &top, "status", "--porcelain", "--untracked-files=no", "--"];
    status.extend(sources);
    let changed = Command::new("git").args(&status).output().ok().filter(|o| o.status.success());
    let commit = match changed {
        Some(out) if !out.stdout.is_empty() => format!("{commit}-dirty"),
        _ => commit,
    };
    let mut watched =
        vec![git(&["rev-parse", "--git-path", "HEAD"]), git(&["rev-parse", "--git-path", "packed-refs"])];
    // On a branch, a commit moves the branch's ref, not HEAD.
    if let Some(branch) = git(&["symbolic-ref", "-q", "HEAD"]) {
        watched.push(git(&["rev-parse", "--git-path", &branch]));
    }
    let dir = std::env::var_os("CARGO_MANIFEST_DIR")?;
    for file in watched.into_iter().flatten() {
        let path = Path::new(&dir).join(file);
        // A path that does not exist (refs all packed) would rerun this script on every build.
        if path.exists() {
            println!("cargo:rerun-if-changed={}", path.display());
        }
    }
    Some(commit)
}

/// `git ARGS` run in this crate's folder: its output's one line, or `None` if git is missing,
/// fails (no repository) or prints nothing usable.
fn git(args: &[&str]) -> Option<String> {
    let dir = std::env::var_os("CARGO_MANIFEST_DIR")?;
    let out = Command::new("git").args(args).current_dir(dir).output().ok()?;
    if !out.status.success() {
        return None;
    }
    one_line(&String::from_utf8(out.stdout).ok()?)
}

/// `text` trimmed if it is one non-empty line (a newline would end the `cargo:` instruction).
fn one_line(text: &str) -> Option<String> {
    let t = text.trim();
    (!t.is_empty() && !t.contains(['\n', '\r'])).then(|| t.to_string())
}
