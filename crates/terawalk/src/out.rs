//! Standard output, where the commands print their results, and what a closed pipe means.
//!
//! `terawalk info s.tw | head -1`: the reader of standard output may go away before a command
//! has said everything. The command's work is done by then (results are printed after the files
//! are written), so that is not a failure: as ripgrep does, a write that fails with
//! `BrokenPipe` ends the program quietly with exit status 0. Rust ignores SIGPIPE, so the write
//! returns EPIPE instead of killing the process; `println!` would panic on it (exit 101), hence
//! `outln!`. Any other failure to write (a full disk behind `> file`) is an
//! error with exit status 1, never a panic.
//!
//! Either way the temporary files a command may have registered (`tw_store::cleanup`) are
//! removed before the process exits, as on an interrupt.

use std::io::Write;

/// Prints a line on standard output; a closed pipe ends the program with exit status 0, any
/// other write error with 1 (see the module).
macro_rules! outln {
    () => {
        $crate::out::line(format_args!(""))
    };
    ($($arg:tt)*) => {
        $crate::out::line(format_args!($($arg)*))
    };
}

/// Writes `args` and a newline on standard output, or ends the program (see the module).
pub fn line(args: std::fmt::Arguments<'_>) {
    let mut stdout = std::io::stdout().lock();
    let written = stdout.write_fmt(args).and_then(|_| stdout.write_all(b"\n"));
    if let Err(e) = written {
        drop(stdout);
        end_on_write_error(&e);
    }
}

/// Whether an error, or any error in its chain of causes, is a write to a pipe that nobody reads.
pub fn is_closed_pipe(e: &anyhow::Error) -> bool {
    e.chain().any(|c| {
        c.downcast_ref::<std::io::Error>().is_some_and(|io| io.kind() == std::io::ErrorKind::BrokenPipe)
    })
}

/// Removes the registered temporaries and exits: 0 for a closed pipe, 1 otherwise.
fn end_on_write_error(e: &std::io::Error) -> ! {
    tw_store::cleanup::remove_registered();
    if e.kind() == std::io::ErrorKind::BrokenPipe {
        std::process::exit(0);
    }
    eprintln!("error: cannot write to standard output: {e}");
    std::process::exit(1);
}

/// For code that still prints with `println!`: its panic on a closed standard output ends the
/// program as `outln!` does, with exit status 0 and no panic message. Every
/// other panic goes to the hook installed before (the message and exit status 101).
///
/// `println!` reports only a message, "failed printing to stdout: …", not the I/O error; the
/// pipe itself says whether its reader is gone ([`stdout_reader_gone`]), so the message is
/// only a first filter.
pub fn end_quietly_when_println_hits_a_closed_pipe() {
    let previous = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or("");
        if message.starts_with("failed printing to stdout") && stdout_reader_gone() {
            tw_store::cleanup::remove_registered();
            std::process::exit(0);
        }
        previous(info);
    }));
}

/// Whether standard output is a pipe whose reading end is closed: `poll` reports POLLERR for
/// the writing end of such a pipe (and POLLHUP on some systems).
#[cfg(unix)]
fn stdout_reader_gone() -> bool {
    let mut fd = libc::pollfd { fd: libc::STDOUT_FILENO, events: libc::POLLOUT, revents: 0 };
    // SAFETY: one valid pollfd, no timeout.
    let ready = unsafe { libc::poll(&mut fd, 1, 0) };
    ready > 0 && fd.revents & (libc::POLLERR | libc::POLLHUP) != 0
}

#[cfg(not(unix))]
fn stdout_reader_gone() -> bool {
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_broken_pipe_is_found_in_the_chain() {
        let pipe = std::io::Error::from(std::io::ErrorKind::BrokenPipe);
        assert!(is_closed_pipe(&anyhow::Error::new(pipe).context("writing the summary")));
        let missing = std::io::Error::from(std::io::ErrorKind::NotFound);
        assert!(!is_closed_pipe(&anyhow::Error::new(missing)));
        assert!(!is_closed_pipe(&anyhow::anyhow!("no I/O at all")));
    }
}
