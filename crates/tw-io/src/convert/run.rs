//! Running a converter program: its output goes to files (a pipe nobody drains would stall a
//! chatty tool), it is killed when it runs past its time limit, and when terawalk itself dies
//! (Linux: `PR_SET_PDEATHSIG`), so that an interrupted build leaves no tool running on.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// How a run ended.
#[derive(Debug)]
pub enum Outcome {
    /// The program exited (successfully or not) within the limit.
    Exited { status: ExitStatus, elapsed: Duration },
    /// The program ran past the limit and was killed.
    TimedOut,
}

/// How often a running program is checked on: short against its run time, long enough to cost
/// nothing.
const POLL: Duration = Duration::from_millis(50);

/// Runs `command` with its standard output and error in `stdout` and `stderr` (created or
/// truncated), killing it after `limit`. An error is a failure to start it (a missing program
/// gives `ErrorKind::NotFound`) or to create the files.
pub fn run(command: &mut Command, stdout: &Path, stderr: &Path, limit: Duration) -> std::io::Result<Outcome> {
    command.stdin(Stdio::null()).stdout(File::create(stdout)?).stderr(File::create(stderr)?);
    die_with_parent(command);
    let start = Instant::now();
    let mut child = command.spawn()?;
    loop {
        if let Some(status) = child.try_wait()? {
            return Ok(Outcome::Exited { status, elapsed: start.elapsed() });
        }
        if start.elapsed() >= limit {
            // Already gone (it exited just now) is fine either way.
            drop(child.kill());
            drop(child.wait());
            return Ok(Outcome::TimedOut);
        }
        std::thread::sleep(POLL);
    }
}

/// Asks the kernel to kill the child when the thread that started it ends: a signal that ends
/// terawalk (its handler removes the working directory and exits) also ends the converter.
#[cfg(target_os = "linux")]
fn die_with_parent(command: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: prctl is async-signal-safe and touches no memory of the parent.
    #[allow(unsafe_code)]
    unsafe {
        command.pre_exec(|| {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL as libc::c_ulong) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

#[cfg(not(target_os = "linux"))]
fn die_with_parent(_command: &mut Command) {}

/// The last `max_lines` lines of the text file `path` (at most its last 64 KiB), trimmed; empty
/// when it cannot be read.
pub fn tail(path: &Path, max_lines: usize) -> String {
    const MAX_BYTES: u64 = 64 << 10;
    let Ok(mut f) = File::open(path) else { return String::new() };
    let len = f.metadata().map(|m| m.len()).unwrap_or(0);
    let mut bytes = Vec::new();
    if f.seek(SeekFrom::Start(len.saturating_sub(MAX_BYTES))).is_err() || f.read_to_end(&mut bytes).is_err() {
        return String::new();
    }
    let text = String::from_utf8_lossy(&bytes);
    let lines: Vec<&str> = text.lines().map(str::trim_end).filter(|l| !l.is_empty()).collect();
    lines[lines.len().saturating_sub(max_lines)..].join("\n")
}

/// Where `program` would be run from: a path with a directory part as it is, a bare name
/// looked up in the `PATH` directories; made absolute (the program runs in another directory)
/// but symbolic links kept (a virtual environment's `bin/python` is one, and Python finds its
/// environment by that path). `None` when no such executable file exists.
pub fn find_program(program: &Path) -> Option<PathBuf> {
    find_program_in(program, std::env::var_os("PATH"))
}

/// [`find_program`] with `path` as the `PATH` value (`None`: no folders to look in).
pub fn find_program_in(program: &Path, path: Option<std::ffi::OsString>) -> Option<PathBuf> {
    let found = if program.components().count() > 1 {
        is_executable(program).then(|| program.to_path_buf())
    } else {
        std::env::split_paths(&path?).map(|dir| dir.join(program)).find(|p| is_executable(p))
    }?;
    std::path::absolute(found).ok()
}

#[cfg(unix)]
fn is_executable(p: &Path) -> bool {
    use std::os::unix::fs::PermissionsExt;
    std::fs::metadata(p).is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
}

#[cfg(not(unix))]
fn is_executable(p: &Path) -> bool {
    p.is_file()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_program_past_its_limit_is_killed() {
        let dir = tempfile::tempdir().unwrap();
        let (out, err) = (dir.path().join("out"), dir.path().join("err"));
        let start = Instant::now();
        let mut sleep = Command::new("sleep");
        sleep.arg("30");
        let r = run(&mut sleep, &out, &err, Duration::from_millis(300)).unwrap();
        assert!(matches!(r, Outcome::TimedOut), "{r:?}");
        assert!(start.elapsed() < Duration::from_secs(10));
    }

    #[test]
    fn exit_status_and_stderr_tail_are_kept() {
        let dir = tempfile::tempdir().unwrap();
        let (out, err) = (dir.path().join("out"), dir.path().join("err"));
        let mut sh = Command::new("sh");
        sh.args(["-c", "echo hello; for i in 1 2 3 4 5; do echo line $i >&2; done; exit 7"]);
        let Outcome::Exited { status, .. } = run(&mut sh, &out, &err, Duration::from_secs(60)).unwrap()
        else {
            panic!("timed out")
        };
        assert_eq!(status.code(), Some(7));
        assert_eq!(tail(&err, 2), "line 4\nline 5");
        assert_eq!(std::fs::read_to_string(&out).unwrap(), "hello\n");
    }

    #[test]
    fn a_missing_program_is_not_found() {
        assert_eq!(find_program(Path::new("no-such-program-terawalk")), None);
        assert!(find_program(Path::new("sh")).is_some());
        let dir = tempfile::tempdir().unwrap();
        let mut c = Command::new(dir.path().join("absent"));
        let e =
            run(&mut c, &dir.path().join("o"), &dir.path().join("e"), Duration::from_secs(1)).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::NotFound);
    }
}
