//! `terawalk`: the command-line program. Glue only: it parses arguments and wires the library
//! crates together (tw-io for input and generation, tw-preview for images, tw-runtime and tw-gpu
//! for GPU frames). Exit codes: 0 success, 1 failure (bad input, I/O), 2 bad usage (clap).

#[macro_use]
mod out;
mod cli;
mod commands;
mod generate_spec;
mod progress;
mod units;

use clap::Parser;

fn main() {
    // Memory budgets are promises about the resident set: one heap for every thread, so memory
    // that one phase, worker or driver thread freed serves the next allocation instead of staying
    // resident in an arena of its own (the 10^8 build at --memory 256M: 445-514 -> 245-251 MB;
    // a 10^8 bench with reference frames at --memory 512M: 2,510 -> 1,730 MB).
    tw_core::mem::use_one_heap_arena();
    out::end_quietly_when_println_hits_a_closed_pipe();
    // Before any thread starts: it may set an environment variable (see the module).
    tw_gpu::headless::quiet_device_select();
    let cli = cli::Cli::parse();
    init_logging(cli.verbose, cli.quiet);
    // The cull server stops on Ctrl-C by itself (it says goodbye to its clients first).
    if !matches!(cli.command, cli::Command::CullServer(_)) {
        on_interrupt_remove_temporaries();
    }
    let result = match cli.command {
        cli::Command::Stats(a) => commands::stats::run(a),
        cli::Command::Generate(a) => commands::generate::run(a),
        cli::Command::Preview(a) => commands::preview::run(a),
        cli::Command::Build(a) => commands::build::run(a, cli.quiet),
        cli::Command::BuildJob(a) => commands::build_job::run(a, cli.quiet),
        cli::Command::Info(a) => commands::info::run(a),
        cli::Command::Render(a) => commands::render::run(a, cli.quiet),
        cli::Command::Bench(a) => commands::bench::run(a).map(|_| ()),
        cli::Command::View(a) => commands::view::run(a, cli.quiet),
        cli::Command::Demo(a) => commands::demo::run(a),
        cli::Command::Path(a) => commands::path::run(a, cli.quiet),
        cli::Command::Export(a) => commands::export::run(a),
        cli::Command::CullServer(a) => commands::cull_server::run(a),
        cli::Command::Collide(a) => commands::collide::run(a),
    };
    if let Err(e) = result {
        if out::is_closed_pipe(&e) {
            // The reader of our output has gone: not a failure (see the `out` module).
            std::process::exit(0);
        }
        eprintln!("error: {}", error_text(&e));
        std::process::exit(1);
    }
}

/// The error and its causes, "outer: inner", each said once: many errors carry their cause's
/// text in their own (an I/O error named with its path), and the chain would repeat it.
fn error_text(e: &anyhow::Error) -> String {
    let mut text = String::new();
    for cause in e.chain() {
        let s = cause.to_string();
        let Some(new) = unsaid_part(&text, &s) else { continue };
        if !text.is_empty() {
            text.push_str(": ");
        }
        text.push_str(new);
    }
    text
}

/// What `cause` adds to `said`: nothing when `said` holds all of it, else `cause` less the
/// leading "NAME: " parts that `said` has already named ("cannot write a/x.ply" followed by
/// "a/x.ply: No such file or directory" adds only "No such file or directory"). A name counts
/// as said when it is one of `said`'s words or ends it (a path with spaces).
fn unsaid_part<'a>(said: &str, cause: &'a str) -> Option<&'a str> {
    let mut rest = cause.trim();
    while let Some((head, tail)) = rest.split_once(": ") {
        let named = !head.is_empty()
            && (said.split_whitespace().any(|w| w.trim_end_matches(':') == head) || said.ends_with(head));
        if !named {
            break;
        }
        rest = tail.trim_start();
    }
    (!rest.is_empty() && !said.contains(rest)).then_some(rest)
}

/// Ctrl-C, SIGTERM or SIGHUP: remove the temporary store file and working directory of a build
/// in progress (`tw_store::cleanup`), then exit with 130 as a shell does for an interrupt.
fn on_interrupt_remove_temporaries() {
    let installed = ctrlc::set_handler(|| {
        let removed = tw_store::cleanup::remove_registered();
        eprintln!("\ninterrupted: {removed} temporary path(s) removed");
        std::process::exit(130);
    });
    if let Err(e) = installed {
        tracing::warn!("no interrupt handler ({e}): an interrupted build may leave temporary files");
    }
}

fn init_logging(verbose: u8, quiet: bool) {
    let level = match (quiet, verbose) {
        (true, _) => "error",
        (false, 0) => "warn",
        (false, 1) => "info",
        (false, 2) => "debug",
        _ => "trace",
    };
    // wgpu-hal logs failed driver probes (e.g. EGL's hardware DRI2 driver on a machine without a
    // GPU) as errors even when another adapter serves: only shown from -v on.
    let default = if verbose == 0 { format!("{level},wgpu_hal=off") } else { level.to_string() };
    let filter = tracing_subscriber::EnvFilter::try_from_env("TERAWALK_LOG")
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).with_target(false).init();
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_cause_and_each_path_is_said_once() {
        let io = std::io::Error::from(std::io::ErrorKind::NotFound);
        let io_text = io.to_string();
        let e = anyhow::Error::new(io).context(format!("m.obj: {io_text}")).context("cannot read m.obj");
        assert_eq!(error_text(&e), format!("cannot read m.obj: {io_text}"));
        let e = anyhow::anyhow!("a dir/x.ply: disk full").context("cannot write a dir/x.ply");
        assert_eq!(error_text(&e), "cannot write a dir/x.ply: disk full");
        // A name the outer text does not hold stays: it says which path failed.
        let e = anyhow::anyhow!("/nonexist: not found").context("building /nonexist/x.tw");
        assert_eq!(error_text(&e), "building /nonexist/x.tw: /nonexist: not found");
    }
}
