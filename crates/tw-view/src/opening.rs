//! Opening another model while the viewer runs (the open dialog, drag and drop, the script's
//! `open` and `drop` steps): the file is handed to an [`Opener`] on a background thread, so that
//! the window keeps drawing (and shows the build's progress) while a model is built into the
//! cache; the store it gives is opened on that thread too, and the app swaps it in at its next
//! frame ([`Opening::poll`]).
//!
//! tw-view cannot build stores itself (the builder and its cache are the `terawalk` binary's:
//! `commands/open.rs`), so the program that starts the viewer passes the opener in
//! [`crate::ViewOptions::opener`]; without one only stores are opened.
//!
//! Cancel: a build cannot be stopped cleanly halfway (`tw_build::build` has no cancellation
//! point), so Cancel stops waiting for it: the viewer keeps its scene and the build finishes
//! in the background into the cache (its store appears atomically, and a later open of the
//! same file finds it at once). The progress window says so.

use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use tw_store::Store;

/// Where a build is: the phase, and how far through it (`total` 0: of unknown size).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Progress {
    pub phase: String,
    pub done: u64,
    pub total: u64,
    /// The unit of `done` and `total` ("bytes", "triangles", …; empty: none).
    pub unit: String,
}

/// Turns a file into the path of a store to open, reporting progress while it builds one.
pub type OpenFn = dyn Fn(&Path, &dyn Fn(Progress)) -> Result<PathBuf, String> + Send + Sync;

/// Which files the open dialog lists (besides folders).
pub type AcceptsFn = dyn Fn(&Path) -> bool + Send + Sync;

/// How the viewer opens files: a model is built into a store by `open`, a store is returned
/// as it is; `accepts` says which files the dialog lists.
#[derive(Clone)]
pub struct Opener {
    open: Arc<OpenFn>,
    accepts: Arc<AcceptsFn>,
}

impl std::fmt::Debug for Opener {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Opener")
    }
}

impl Opener {
    pub fn new(open: Arc<OpenFn>, accepts: Arc<AcceptsFn>) -> Opener {
        Opener { open, accepts }
    }

    /// Opens stores only (what tw-view can do without a builder).
    pub fn stores_only() -> Opener {
        Opener::new(
            Arc::new(|p: &Path, _: &dyn Fn(Progress)| Ok(p.to_path_buf())),
            Arc::new(|p: &Path| is_store(p)),
        )
    }

    pub fn accepts(&self, path: &Path) -> bool {
        (self.accepts)(path)
    }
}

/// Whether `path` starts with a store's magic bytes (`TERAWALK`), whatever its name.
pub fn is_store(path: &Path) -> bool {
    let mut magic = [0u8; 8];
    std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut magic))
        .is_ok_and(|_| &magic == b"TERAWALK")
}

/// A store opened in the background: the file asked for, and the store (the same file, or the
/// one built from it in the cache).
pub struct Opened {
    pub requested: PathBuf,
    pub store: Store,
}

/// An open that did not give a store: the file and why, in words.
#[derive(Clone, Debug, PartialEq)]
pub struct OpenFailure {
    pub path: PathBuf,
    pub error: String,
}

/// The progress of the running job and when its phase began (for the phase's ETA).
#[derive(Clone, Debug)]
struct Shared {
    progress: Progress,
    phase_started: Instant,
}

/// The open being run in the background.
struct Job {
    requested: PathBuf,
    started: Instant,
    shared: Arc<Mutex<Shared>>,
    result: Receiver<Result<Opened, String>>,
}

/// What the progress window shows of a running open.
#[derive(Clone, Debug)]
pub struct JobView {
    pub file: PathBuf,
    pub progress: Progress,
    pub elapsed: Duration,
    /// The phase's remaining time at its rate so far (none until it has one).
    pub phase_eta: Option<Duration>,
}

/// The viewer's opening state: the job, the last failure, the file hovered over the window,
/// and the open dialog while it is shown.
pub struct Opening {
    opener: Opener,
    job: Option<Job>,
    pub failure: Option<OpenFailure>,
    /// A file dragged over the window (winit's `HoveredFile`), for the "drop to open" overlay.
    pub hovered: Option<PathBuf>,
    pub browser: Option<crate::browser::FileBrowser>,
}

impl Opening {
    pub fn new(opener: Option<Opener>) -> Opening {
        Opening {
            opener: opener.unwrap_or_else(Opener::stores_only),
            job: None,
            failure: None,
            hovered: None,
            browser: None,
        }
    }

    pub fn opener(&self) -> &Opener {
        &self.opener
    }

    /// Whether an open runs.
    pub fn busy(&self) -> bool {
        self.job.is_some()
    }

    /// Starts opening `path` in the background; refused (in words) while another open runs.
    pub fn start(&mut self, path: &Path) -> Result<(), String> {
        if let Some(j) = &self.job {
            return Err(format!("still opening {} (wait for it or cancel it)", j.requested.display()));
        }
        self.failure = None;
        self.browser = None;
        let shared =
            Arc::new(Mutex::new(Shared { progress: Progress::default(), phase_started: Instant::now() }));
        let (tx, rx) = mpsc::channel();
        let (open, requested, report) = (self.opener.open.clone(), path.to_path_buf(), shared.clone());
        let spawned = std::thread::Builder::new().name("terawalk open".into()).spawn(move || {
            let progress = move |p: Progress| report_progress(&report, p);
            let result = open(&requested, &progress).and_then(|store| open_store(&store, requested));
            // The receiver is gone when the open was cancelled: nobody waits for the result.
            let _ = tx.send(result);
        });
        spawned.map_err(|e| format!("cannot start opening {}: {e}", path.display()))?;
        self.job = Some(Job { requested: path.to_path_buf(), started: Instant::now(), shared, result: rx });
        Ok(())
    }

    /// Stops waiting for the running open (see the module documentation: a build goes on into
    /// the cache); returns the file it was opening.
    pub fn cancel(&mut self) -> Option<PathBuf> {
        self.job.take().map(|j| j.requested)
    }

    /// The finished open, once: the store, or why there is none (also kept in `failure` for
    /// the error window).
    pub fn poll(&mut self) -> Option<Result<Opened, OpenFailure>> {
        let job = self.job.as_ref()?;
        let result = match job.result.try_recv() {
            Ok(r) => r,
            Err(TryRecvError::Empty) => return None,
            Err(TryRecvError::Disconnected) => Err("the open stopped without a result".into()),
        };
        let job = self.job.take().expect("polled above");
        Some(result.map_err(|error| {
            let f = OpenFailure { path: job.requested, error };
            self.failure = Some(f.clone());
            f
        }))
    }

    /// What the progress window shows (none while nothing opens).
    pub fn job_view(&self) -> Option<JobView> {
        let j = self.job.as_ref()?;
        let s = j.shared.lock().map(|s| s.clone()).ok()?;
        Some(JobView {
            file: j.requested.clone(),
            phase_eta: phase_eta(&s.progress, s.phase_started.elapsed()),
            progress: s.progress,
            elapsed: j.started.elapsed(),
        })
    }
}

/// Records a progress report; a new phase restarts the phase's clock.
fn report_progress(shared: &Mutex<Shared>, p: Progress) {
    if let Ok(mut s) = shared.lock() {
        if s.progress.phase != p.phase {
            s.phase_started = Instant::now();
        }
        s.progress = p;
    }
}

/// Opens the store the opener gave for `requested`, with the error in words.
fn open_store(store: &Path, requested: PathBuf) -> Result<Opened, String> {
    match Store::open(store) {
        Ok(store) => Ok(Opened { requested, store }),
        Err(e) if store == requested => {
            Err(format!("{e} (terawalk opens its stores and the model formats `terawalk build` reads)"))
        }
        Err(e) => Err(format!("cannot open the store {} built from it: {e}", store.display())),
    }
}

/// The phase's remaining time at the rate of its `elapsed` so far: none for a phase of unknown
/// size or before anything is done.
pub fn phase_eta(p: &Progress, elapsed: Duration) -> Option<Duration> {
    if p.total == 0 || p.done == 0 || p.done >= p.total {
        return None;
    }
    let left = (p.total - p.done) as f64 / p.done as f64;
    Some(Duration::from_secs_f64(elapsed.as_secs_f64() * left))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wait(o: &mut Opening) -> Result<Opened, OpenFailure> {
        let start = Instant::now();
        loop {
            if let Some(r) = o.poll() {
                return r;
            }
            assert!(start.elapsed() < Duration::from_secs(20), "the open did not finish");
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    #[test]
    fn a_file_that_is_no_store_fails_in_words_and_is_kept_for_the_error_window() {
        let dir = tempfile::tempdir().unwrap();
        let bad = dir.path().join("notes.tw");
        std::fs::write(&bad, "not a store").unwrap();
        let mut o = Opening::new(None);
        o.start(&bad).unwrap();
        assert!(o.busy());
        let Err(f) = wait(&mut o) else { panic!("opened a text file") };
        assert_eq!(f.path, bad);
        assert!(!f.error.is_empty(), "{f:?}");
        assert_eq!(o.failure.as_ref(), Some(&f));
        assert!(!o.busy() && o.poll().is_none());
        let Err(f) = ({
            o.start(&dir.path().join("missing.tw")).unwrap();
            wait(&mut o)
        }) else {
            panic!("opened a missing file")
        };
        assert!(f.error.contains("No such file") || f.error.contains("not found"), "{}", f.error);
    }

    #[test]
    fn the_opener_error_is_returned_and_a_second_open_waits_for_the_first() {
        let (tx, rx) = mpsc::channel::<()>();
        let rx = Mutex::new(rx);
        let open: Arc<OpenFn> = Arc::new(move |p: &Path, progress: &dyn Fn(Progress)| {
            progress(Progress { phase: "build".into(), done: 1, total: 4, unit: "triangles".into() });
            rx.lock().unwrap().recv().ok();
            Err(format!("cannot build {}", p.display()))
        });
        let mut o = Opening::new(Some(Opener::new(open, Arc::new(|_: &Path| true))));
        o.start(Path::new("a.ply")).unwrap();
        assert!(o.start(Path::new("b.ply")).unwrap_err().contains("still opening a.ply"));
        let start = Instant::now();
        while o.job_view().unwrap().progress.phase.is_empty() {
            assert!(start.elapsed() < Duration::from_secs(20));
            std::thread::sleep(Duration::from_millis(2));
        }
        let v = o.job_view().unwrap();
        assert_eq!((v.progress.done, v.progress.total), (1, 4));
        tx.send(()).unwrap();
        let Err(f) = wait(&mut o) else { panic!() };
        assert_eq!(f.error, "cannot build a.ply");
    }

    #[test]
    fn cancel_forgets_the_job() {
        let open: Arc<OpenFn> = Arc::new(|_: &Path, _: &dyn Fn(Progress)| {
            std::thread::sleep(Duration::from_millis(50));
            Err("late".into())
        });
        let mut o = Opening::new(Some(Opener::new(open, Arc::new(|_: &Path| true))));
        o.start(Path::new("a.ply")).unwrap();
        assert_eq!(o.cancel(), Some(PathBuf::from("a.ply")));
        assert!(!o.busy() && o.poll().is_none());
        o.start(Path::new("b.ply")).unwrap();
    }

    #[test]
    fn the_phase_eta_follows_its_rate() {
        let p = |done, total| Progress { phase: "x".into(), done, total, unit: String::new() };
        assert_eq!(phase_eta(&p(1, 4), Duration::from_secs(2)), Some(Duration::from_secs(6)));
        assert_eq!(phase_eta(&p(0, 4), Duration::from_secs(2)), None);
        assert_eq!(phase_eta(&p(5, 0), Duration::from_secs(2)), None);
        assert_eq!(phase_eta(&p(4, 4), Duration::from_secs(2)), None);
    }
}
