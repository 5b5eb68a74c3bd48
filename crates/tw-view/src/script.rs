//! Scripted viewer sessions (`terawalk view --script FILE`): a text file of steps that drive
//! the viewer as a person would — keys held for some frames, key presses, mouse look, window
//! resizes, minimising and restoring, screenshots — one frame at a time, so that a run is
//! reproducible (tests under Xvfb, demos, bug reports). The viewer quits after the last step.
//!
//! One step per line; `#` starts a comment; blank lines are ignored:
//!
//! ```text
//! wait 10              # draw 10 frames (the controller or --path moves the camera)
//! hold W 20            # hold a key for 20 frames (W A S D Q E, Up Down Left Right, Shift…)
//! press F1             # press and release a key (any key the viewer knows: F1, L, C, 2, …)
//! press Shift+H        # … with Shift held (show all objects)
//! press Ctrl+O         # … with Ctrl held (the open dialog)
//! press ]              # the sun keys: ] [ turn it, Shift+] Shift+[ raise and lower it
//! look 120 -40         # move the mouse-look by (dx, dy) pixels
//! scroll 3             # the wheel: +3 lines (speed; zoom in orbit and orthographic views)
//! click 240 160        # left click at window pixel (x, y): pick (or measure, after `press M`)
//! view +x              # a preset view: +x -x +y -y +z -z iso (as keys 4…9, 0)
//! save-view door       # save the camera as viewpoint `door` (STORE.views.json)
//! load-view door       # go to the saved viewpoint `door`
//! resize 640x360       # ask for a new window size (applied when the window system agrees)
//! minimize             # minimise: frames are skipped until `restore`
//! restore
//! screenshot a.png     # the scene image of the last frame drawn (as F12)
//! screenshot-window b.png   # the whole window, HUD included (as Shift+F12)
//! open model.ply       # open a file, as the open dialog's Enter (built in the background)
//! drop scene.tw        # open a file as if dropped on the window (winit's DroppedFile)
//! wait-open 600        # draw frames until the open finished, at most 600
//! measure plane        # clicks measure: `point` (as M), `plane` (as Shift+M) or `off`
//! tree                 # open / close the model tree (as Shift+T)
//! tree-search pump 2   # search the object names (the rest of the line; none: the whole tree)
//! tree-select middle   # select (pick) an object by name, `id=3` by id, `row=1` by row shown
//! tree-isolate         # the tree's buttons: tree-hide, tree-isolate, tree-show-all, tree-frame
//! section-plane x 0.5  # a section plane across x at half the scene box, keeping +x (y, z too)
//! section-plane picked # a plane through the last clicked surface, removing the eye's side
//! section-flip 1       # plane 1 keeps its other side
//! section-move 1 0.1   # plane 1 moves along its normal by 0.1 × the scene's diagonal
//! section-remove 1     # plane 1 goes
//! section-box 0 0 0 0.5 0.5 1   # a section box at these fractions of the scene box (min, max)
//! section-box picked   # a section box around the picked object
//! section-toggle       # the section off / on
//! section-clear        # every plane and the box gone
//! ```
//!
//! `open` and `drop` start the open and go on at once (the build runs in the background while
//! frames are drawn, as for a person); `wait-open N` waits for its end: the frame after the open
//! ended draws the new scene (or the old one, with the error shown, when the open failed), and
//! the steps after `wait-open` come in the frame after that one.
//!
//! Before any scene is open (`terawalk view` with no file, or a model still building): `open`,
//! `drop`, `press` (Ctrl+O, Esc), `resize`, `screenshot-window` and the waits act; `screenshot`
//! is said not to be taken (there is no scene image), and the steps that need a scene
//! (`click`, `view`, `look`, …) are said to do nothing.
//!
//! The `tree-` steps open the model tree's window when it is closed.
//!
//! Minimising: a window system minimises a window asynchronously and differently (Windows sends
//! a zero size; X11 without a window manager ignores the request), so `minimize` both asks the
//! window system and takes the viewer through its zero-size path, the one a zero-sized
//! `Resized` event takes; `restore` configures the surface for the window's size again.

use std::path::{Path, PathBuf};

use winit::keyboard::KeyCode;

use crate::review::MeasureKind;
use crate::viewpoints::Preset;

/// One step of a script.
#[derive(Clone, Debug, PartialEq)]
pub enum Step {
    Wait(u32),
    Hold(KeyCode, u32),
    Press(KeyCode),
    /// A key pressed with Shift held.
    PressShifted(KeyCode),
    Look(f32, f32),
    Click(f32, f32),
    View(Preset),
    SaveView(String),
    LoadView(String),
    Scroll(f32),
    Resize(u32, u32),
    Minimize,
    Restore,
    Screenshot(PathBuf),
    WindowScreenshot(PathBuf),
    /// Open a file as the open dialog's Enter does.
    Open(PathBuf),
    /// Open a file as a drop on the window does.
    Drop(PathBuf),
    /// Draw frames until the open running finished, at most this many.
    WaitOpen(u32),
    /// A key pressed with Ctrl held (Ctrl+O: the open dialog).
    PressCtrl(KeyCode),
    /// Measuring of a kind from a new measurement, or off (`None`).
    Measure(Option<MeasureKind>),
    /// The model tree's window, search, rows and buttons.
    Tree(TreeStep),
    /// `section-…`: a section step (crate::section_tool::parse_step).
    Section(crate::section_tool::SectionStep),
}

/// A model tree step (`tree`, `tree-search`, `tree-select`, `tree-hide`…).
#[derive(Clone, Debug, PartialEq)]
pub enum TreeStep {
    Toggle,
    Search(String),
    Select(TreeTarget),
    Hide,
    Isolate,
    ShowAll,
    Frame,
}

/// The object a `tree-select` names.
#[derive(Clone, Debug, PartialEq)]
pub enum TreeTarget {
    /// Its whole name (case-insensitive).
    Name(String),
    /// `id=N`: its id in the object table.
    Id(u32),
    /// `row=N`: the N-th row shown (from 1; after `tree-search`, the N-th match).
    Row(usize),
}

impl Step {
    /// Frames the step takes (0: it happens at the start of the next frame with the steps
    /// after it, up to the next one that takes frames).
    pub fn frames(&self) -> u32 {
        match self {
            Step::Wait(n) | Step::Hold(_, n) | Step::WaitOpen(n) => *n,
            _ => 0,
        }
    }
}

/// A parsed script.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Script {
    pub steps: Vec<Step>,
}

/// A script that cannot be read, with the file and line.
#[derive(Debug, thiserror::Error)]
pub enum ScriptError {
    #[error("cannot read the script {path}: {source}")]
    Io { path: PathBuf, source: std::io::Error },
    #[error("{path}:{line}: {msg}")]
    Syntax { path: PathBuf, line: usize, msg: String },
}

/// The key names a script may use (winit's `KeyCode` without the prefix, case-insensitive:
/// `W`, `F1`, `Up`, `Shift`, `Escape`, `Home`, `2`, `[`, `]`).
pub fn parse_key(name: &str) -> Option<KeyCode> {
    let n = name.to_ascii_lowercase();
    let letter = |c: char| -> Option<KeyCode> {
        use KeyCode::*;
        const LETTERS: [KeyCode; 26] = [
            KeyA, KeyB, KeyC, KeyD, KeyE, KeyF, KeyG, KeyH, KeyI, KeyJ, KeyK, KeyL, KeyM, KeyN, KeyO, KeyP,
            KeyQ, KeyR, KeyS, KeyT, KeyU, KeyV, KeyW, KeyX, KeyY, KeyZ,
        ];
        c.is_ascii_lowercase().then(|| LETTERS[(c as u8 - b'a') as usize])
    };
    use KeyCode::*;
    const DIGITS: [KeyCode; 10] =
        [Digit0, Digit1, Digit2, Digit3, Digit4, Digit5, Digit6, Digit7, Digit8, Digit9];
    const FKEYS: [KeyCode; 12] = [F1, F2, F3, F4, F5, F6, F7, F8, F9, F10, F11, F12];
    let mut chars = n.chars();
    match (chars.next(), chars.next()) {
        (Some(c), None) if c.is_ascii_lowercase() => return letter(c),
        (Some(c), None) if c.is_ascii_digit() => return Some(DIGITS[(c as u8 - b'0') as usize]),
        _ => {}
    }
    if let Some(k) = n.strip_prefix('f').and_then(|d| d.parse::<usize>().ok()) {
        return FKEYS.get(k.wrapping_sub(1)).copied();
    }
    Some(match n.as_str() {
        "up" => ArrowUp,
        "down" => ArrowDown,
        "left" => ArrowLeft,
        "right" => ArrowRight,
        "shift" | "lshift" => ShiftLeft,
        "rshift" => ShiftRight,
        "space" => Space,
        "escape" | "esc" => Escape,
        "home" => Home,
        "tab" => Tab,
        "[" | "bracketleft" => BracketLeft,
        "]" | "bracketright" => BracketRight,
        _ => return None,
    })
}

impl Script {
    /// Reads and parses the script at `path`.
    pub fn load(path: &Path) -> Result<Script, ScriptError> {
        let text = std::fs::read_to_string(path)
            .map_err(|source| ScriptError::Io { path: path.to_path_buf(), source })?;
        Script::parse(&text, path)
    }

    /// Parses `text`; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<Script, ScriptError> {
        let mut steps = Vec::new();
        for (i, raw) in text.lines().enumerate() {
            let line = raw.split('#').next().unwrap_or_default().trim();
            if line.is_empty() {
                continue;
            }
            let words: Vec<&str> = line.split_whitespace().collect();
            let line = StepLine { path, line: i + 1, cmd: words[0].to_ascii_lowercase(), args: &words[1..] };
            steps.push(line.step()?);
        }
        Ok(Script { steps })
    }

    /// Frames a run of the script takes: those of its waits and holds, then the last one, in
    /// which the steps after them happen and the viewer quits.
    pub fn frames(&self) -> u64 {
        self.steps.iter().map(|s| s.frames() as u64).sum::<u64>() + 1
    }
}

/// One step's line of a script: its command (lower case) and arguments, and where it is for
/// errors.
struct StepLine<'a> {
    path: &'a Path,
    line: usize,
    cmd: String,
    args: &'a [&'a str],
}

impl StepLine<'_> {
    /// The step the line says.
    fn step(&self) -> Result<Step, ScriptError> {
        let args = self.args;
        Ok(match self.cmd.as_str() {
            "wait" => {
                self.want(1)?;
                Step::Wait(self.count(args[0])?)
            }
            "hold" => {
                self.want(2)?;
                Step::Hold(self.key(args[0])?, self.count(args[1])?)
            }
            "press" => {
                self.want(1)?;
                let lower = args[0].to_ascii_lowercase();
                match (lower.strip_prefix("shift+"), lower.strip_prefix("ctrl+")) {
                    (Some(k), _) => Step::PressShifted(self.key(k)?),
                    (_, Some(k)) => Step::PressCtrl(self.key(k)?),
                    _ => Step::Press(self.key(args[0])?),
                }
            }
            "click" => {
                self.want(2)?;
                Step::Click(self.pixel(args[0])?, self.pixel(args[1])?)
            }
            "view" => {
                self.want(1)?;
                Step::View(self.preset(args[0])?)
            }
            "save-view" => {
                self.want(1)?;
                Step::SaveView(args[0].to_string())
            }
            "load-view" => {
                self.want(1)?;
                Step::LoadView(args[0].to_string())
            }
            "look" => {
                self.want(2)?;
                Step::Look(self.number(args[0])?, self.number(args[1])?)
            }
            "scroll" => {
                self.want(1)?;
                Step::Scroll(self.number(args[0])?)
            }
            "resize" => {
                self.want(1)?;
                let (w, h) = self.size(args[0])?;
                Step::Resize(w, h)
            }
            "minimize" | "minimise" => {
                self.want(0)?;
                Step::Minimize
            }
            "restore" => {
                self.want(0)?;
                Step::Restore
            }
            "screenshot" => {
                self.want(1)?;
                Step::Screenshot(PathBuf::from(args[0]))
            }
            "screenshot-window" => {
                self.want(1)?;
                Step::WindowScreenshot(PathBuf::from(args[0]))
            }
            "open" | "drop" => {
                // A path may hold spaces: the rest of the line.
                if args.is_empty() {
                    return Err(self.err(format!("`{}` takes a file path", self.cmd)));
                }
                let path = PathBuf::from(args.join(" "));
                if self.cmd == "open" {
                    Step::Open(path)
                } else {
                    Step::Drop(path)
                }
            }
            "wait-open" => {
                self.want(1)?;
                Step::WaitOpen(self.count(args[0])?)
            }
            "measure" => {
                self.want(1)?;
                Step::Measure(self.measure_kind(args[0])?)
            }
            "tree" | "tree-hide" | "tree-isolate" | "tree-show-all" | "tree-frame" => {
                self.want(0)?;
                Step::Tree(match self.cmd.as_str() {
                    "tree" => TreeStep::Toggle,
                    "tree-hide" => TreeStep::Hide,
                    "tree-isolate" => TreeStep::Isolate,
                    "tree-show-all" => TreeStep::ShowAll,
                    _ => TreeStep::Frame,
                })
            }
            "tree-search" => Step::Tree(TreeStep::Search(args.join(" "))),
            "tree-select" => {
                if args.is_empty() {
                    return Err(self.err("`tree-select` takes a name, id=N or row=N".into()));
                }
                Step::Tree(TreeStep::Select(self.tree_target(&args.join(" "))?))
            }
            cmd if cmd.starts_with("section") => {
                Step::Section(crate::section_tool::parse_step(cmd, args).map_err(|m| self.err(m))?)
            }
            other => {
                return Err(self.err(format!(
                    "unknown step `{other}` (wait, hold, press, look, scroll, click, view, \
                     save-view, load-view, resize, minimize, restore, screenshot, \
                     screenshot-window, open, drop, wait-open, measure, tree, tree-search, tree-select, \
                     tree-hide, tree-isolate, tree-show-all, tree-frame, section-plane, section-flip, \
                     section-move, section-remove, section-box, section-toggle, section-clear)"
                )))
            }
        })
    }

    fn err(&self, msg: String) -> ScriptError {
        ScriptError::Syntax { path: self.path.to_path_buf(), line: self.line, msg }
    }

    /// Exactly `n` arguments.
    fn want(&self, n: usize) -> Result<(), ScriptError> {
        if self.args.len() == n {
            Ok(())
        } else {
            Err(self.err(format!("`{}` takes {n} argument(s), found {}", self.cmd, self.args.len())))
        }
    }

    /// A frame count, 0..=1000000.
    fn count(&self, s: &str) -> Result<u32, ScriptError> {
        s.parse::<u32>()
            .ok()
            .filter(|&n| n <= 1_000_000)
            .ok_or_else(|| self.err(format!("`{s}` is not a frame count (0..=1000000)")))
    }

    /// A finite number of magnitude at most 10^6.
    fn number(&self, s: &str) -> Result<f32, ScriptError> {
        s.parse::<f32>()
            .ok()
            .filter(|v| v.is_finite() && v.abs() <= 1e6)
            .ok_or_else(|| self.err(format!("`{s}` is not a number")))
    }

    fn key(&self, s: &str) -> Result<KeyCode, ScriptError> {
        parse_key(s).ok_or_else(|| self.err(format!("unknown key `{s}`")))
    }

    /// A number (see [`Self::number`]) that is not negative.
    fn pixel(&self, s: &str) -> Result<f32, ScriptError> {
        self.number(s)?;
        s.parse::<f32>()
            .ok()
            .filter(|v| *v >= 0.0)
            .ok_or_else(|| self.err(format!("`{s}` is not a pixel coordinate (>= 0)")))
    }

    fn preset(&self, s: &str) -> Result<Preset, ScriptError> {
        Preset::parse(s).ok_or_else(|| self.err(format!("unknown view `{s}` (+x -x +y -y +z -z iso)")))
    }

    /// `point`, `plane` or `off` (`None`).
    fn measure_kind(&self, s: &str) -> Result<Option<MeasureKind>, ScriptError> {
        if s.eq_ignore_ascii_case("off") {
            return Ok(None);
        }
        MeasureKind::parse(s)
            .map(Some)
            .ok_or_else(|| self.err(format!("unknown measurement `{s}` (point, plane, off)")))
    }

    /// `id=N`, `row=N` (N from 1) or a name.
    fn tree_target(&self, s: &str) -> Result<TreeTarget, ScriptError> {
        let bad = |what: &str| self.err(format!("`{s}` is not {what}"));
        if let Some(id) = s.strip_prefix("id=") {
            return id.parse().map(TreeTarget::Id).map_err(|_| bad("an object id (id=N)"));
        }
        if let Some(row) = s.strip_prefix("row=") {
            return row
                .parse()
                .ok()
                .filter(|&r| r >= 1)
                .map(TreeTarget::Row)
                .ok_or_else(|| bad("a row (row=N, N ≥ 1)"));
        }
        Ok(TreeTarget::Name(s.to_string()))
    }

    /// A window size `WIDTHxHEIGHT`, each 1..=16384.
    fn size(&self, s: &str) -> Result<(u32, u32), ScriptError> {
        s.split_once(['x', 'X'])
            .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
            .filter(|&(w, h)| (1..=16384).contains(&w) && (1..=16384).contains(&h))
            .ok_or_else(|| self.err(format!("`{s}` is not a size WIDTHxHEIGHT (1..=16384)")))
    }
}

/// Where a running script is.
#[derive(Clone, Debug, Default)]
pub struct ScriptRunner {
    steps: std::collections::VecDeque<Step>,
    /// Frames left of the step being run (a wait or a held key), and the key held.
    left: u32,
    held: Option<KeyCode>,
    /// The frames being waited are a `wait-open`'s: they end when the open does.
    waiting_open: bool,
}

/// What to do at the start of a frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameSteps {
    /// Instant steps, in order (presses, looks, resizes, screenshots…).
    pub instant: Vec<Step>,
    /// A key to release before them (its hold ended).
    pub release: Option<KeyCode>,
    /// A key to press and keep down (a hold starts).
    pub hold: Option<KeyCode>,
    /// The script ended: this frame is the last.
    pub last: bool,
}

impl ScriptRunner {
    pub fn new(script: Script) -> ScriptRunner {
        ScriptRunner { steps: script.steps.into(), left: 0, held: None, waiting_open: false }
    }

    /// The steps of the next frame.
    pub fn next_frame(&mut self) -> FrameSteps {
        let mut out = FrameSteps::default();
        if self.left > 0 {
            self.left -= 1;
            if self.left > 0 {
                return out;
            }
        }
        out.release = self.held.take();
        // A step's frames are counted from this frame on.
        while let Some(step) = self.steps.pop_front() {
            match step {
                Step::Wait(0) | Step::Hold(_, 0) | Step::WaitOpen(0) => {}
                Step::WaitOpen(n) => {
                    self.left = n;
                    self.waiting_open = true;
                    break;
                }
                Step::Wait(n) => {
                    self.left = n;
                    break;
                }
                Step::Hold(k, n) => {
                    self.left = n;
                    self.held = Some(k);
                    out.hold = Some(k);
                    break;
                }
                s => out.instant.push(s),
            }
        }
        out.last = self.left == 0 && self.steps.is_empty();
        out
    }

    /// No open runs: a `wait-open` being waited ends with the next frame.
    pub fn open_finished(&mut self) {
        if std::mem::take(&mut self.waiting_open) {
            self.left = self.left.min(2);
        }
    }

    pub fn finished(&self) -> bool {
        self.left == 0 && self.steps.is_empty()
    }
}

/// Frames [`fuzz_bytes`] runs a script for at most (a script may ask for 10^6 per step).
pub const FUZZ_MAX_FRAMES: u64 = 100_000;

/// The entry point of the `script` fuzz target: parses `data` as [`Script::load`] reads a file
/// (UTF-8 required), then steps a [`ScriptRunner`] through it frame by frame, up to
/// [`FUZZ_MAX_FRAMES`]. Returns the frames run.
pub fn fuzz_bytes(data: &[u8]) -> Result<u64, ScriptError> {
    let path = Path::new("fuzz.txt");
    let text = std::str::from_utf8(data).map_err(|e| ScriptError::Io {
        path: path.to_path_buf(),
        source: std::io::Error::new(std::io::ErrorKind::InvalidData, e),
    })?;
    let script = Script::parse(text, path)?;
    let expected = script.frames();
    let mut runner = ScriptRunner::new(script);
    let mut frames = 0;
    while frames < FUZZ_MAX_FRAMES.min(expected) {
        frames += 1;
        if runner.next_frame().last {
            break;
        }
    }
    Ok(frames)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Script, ScriptError> {
        Script::parse(text, Path::new("s.txt"))
    }

    /// Replays the committed corpus and every crasher of the `script` fuzz target
    /// (fuzz/corpus/script, fuzz/regressions/script) through [`fuzz_bytes`]: no panic.
    #[test]
    fn fuzz_corpus_replays() {
        let fuzz = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
        let mut files = Vec::new();
        for dir in ["corpus", "regressions"] {
            if let Ok(entries) = std::fs::read_dir(fuzz.join(dir).join("script")) {
                files.extend(entries.filter_map(|e| e.ok()).map(|e| e.path()));
            }
        }
        assert!(!files.is_empty(), "no corpus for the script fuzz target");
        let panicked: Vec<_> = files
            .iter()
            .filter(|f| {
                let data = std::fs::read(f).unwrap();
                std::panic::catch_unwind(|| fuzz_bytes(&data)).is_err()
            })
            .collect();
        assert!(panicked.is_empty(), "these inputs panic: {panicked:?}");
        // The seed is a valid script: 3 + 2 + 1 waiting frames, then the last one.
        let seed = std::fs::read(fuzz.join("corpus/script/steps.txt")).unwrap();
        assert_eq!(fuzz_bytes(&seed).unwrap(), 7);
    }

    #[test]
    fn parses_every_step_and_comments() {
        let s = parse(
            "# a walk\nwait 3\nhold w 2  # forward\npress F1\nlook 10 -5\nscroll 2\nresize 320x200\n\
             minimize\nrestore\nscreenshot a.png\nscreenshot-window b.png\n\npress shift+H\n\
             click 12 30.5\nview -Z\nview iso\nsave-view door\nload-view door\nmeasure plane\n\
             measure OFF\ntree\ntree-search pump  2\ntree-select Left Cube\ntree-select id=2\n\
             tree-select row=1\ntree-isolate\ntree-hide\ntree-show-all\ntree-frame\ntree-search\n",
        )
        .unwrap();
        assert_eq!(
            s.steps,
            vec![
                Step::Wait(3),
                Step::Hold(KeyCode::KeyW, 2),
                Step::Press(KeyCode::F1),
                Step::Look(10.0, -5.0),
                Step::Scroll(2.0),
                Step::Resize(320, 200),
                Step::Minimize,
                Step::Restore,
                Step::Screenshot("a.png".into()),
                Step::WindowScreenshot("b.png".into()),
                Step::PressShifted(KeyCode::KeyH),
                Step::Click(12.0, 30.5),
                Step::View(Preset::NegZ),
                Step::View(Preset::Iso),
                Step::SaveView("door".into()),
                Step::LoadView("door".into()),
                Step::Measure(Some(MeasureKind::Plane)),
                Step::Measure(None),
                Step::Tree(TreeStep::Toggle),
                Step::Tree(TreeStep::Search("pump 2".into())),
                Step::Tree(TreeStep::Select(TreeTarget::Name("Left Cube".into()))),
                Step::Tree(TreeStep::Select(TreeTarget::Id(2))),
                Step::Tree(TreeStep::Select(TreeTarget::Row(1))),
                Step::Tree(TreeStep::Isolate),
                Step::Tree(TreeStep::Hide),
                Step::Tree(TreeStep::ShowAll),
                Step::Tree(TreeStep::Frame),
                Step::Tree(TreeStep::Search(String::new())),
            ]
        );
        assert_eq!(s.frames(), 6);
    }

    #[test]
    fn open_steps_parse_and_wait_open_ends_with_the_open() {
        let s =
            parse("press ctrl+O\nopen my models/a.ply\nwait-open 50\nscreenshot s.png\ndrop b.tw\n").unwrap();
        assert_eq!(
            s.steps,
            vec![
                Step::PressCtrl(KeyCode::KeyO),
                Step::Open("my models/a.ply".into()),
                Step::WaitOpen(50),
                Step::Screenshot("s.png".into()),
                Step::Drop("b.tw".into()),
            ]
        );
        assert!(parse("open\n").unwrap_err().to_string().contains("takes a file path"));
        let mut r = ScriptRunner::new(s);
        assert_eq!(r.next_frame().instant.len(), 2, "the press and the open, then the wait");
        for _ in 0..5 {
            // The open runs: the wait goes on.
            assert!(r.next_frame().instant.is_empty());
        }
        r.open_finished();
        // The frame that saw the open end draws the new scene; the steps come in the next.
        assert!(r.next_frame().instant.is_empty());
        let f = r.next_frame();
        assert_eq!(f.instant, vec![Step::Screenshot("s.png".into()), Step::Drop("b.tw".into())]);
        assert!(f.last);
    }

    #[test]
    fn errors_name_the_file_and_line() {
        for (text, line, needle) in [
            ("wait 2\njump 3", 2, "unknown step `jump`"),
            ("hold W", 1, "takes 2 argument"),
            ("\n\nhold Foo 2", 3, "unknown key `Foo`"),
            ("resize 0x10", 1, "not a size"),
            ("wait -1", 1, "not a frame count"),
            ("look 1 nan", 1, "not a number"),
            ("click 1 -2", 1, "not a pixel coordinate"),
            ("view front", 1, "unknown view `front`"),
            ("press shift+nope", 1, "unknown key `nope`"),
            ("save-view", 1, "takes 1 argument"),
            ("measure line", 1, "unknown measurement `line`"),
            ("tree-select", 1, "takes a name, id=N or row=N"),
            ("tree-select row=0", 1, "not a row"),
            ("tree-select id=x", 1, "not an object id"),
            ("tree x", 1, "takes 0 argument"),
        ] {
            let e = parse(text).unwrap_err().to_string();
            assert!(e.starts_with(&format!("s.txt:{line}: ")) && e.contains(needle), "{e}");
        }
    }

    #[test]
    fn keys_by_name() {
        assert_eq!(parse_key("w"), Some(KeyCode::KeyW));
        assert_eq!(parse_key("F12"), Some(KeyCode::F12));
        assert_eq!(parse_key("f13"), None);
        assert_eq!(parse_key("f0"), None);
        assert_eq!(parse_key("Up"), Some(KeyCode::ArrowUp));
        assert_eq!(parse_key("3"), Some(KeyCode::Digit3));
        assert_eq!(parse_key("shift"), Some(KeyCode::ShiftLeft));
        assert_eq!(parse_key("["), Some(KeyCode::BracketLeft));
        assert_eq!(parse_key("BracketRight"), Some(KeyCode::BracketRight));
        assert_eq!(parse_key("xyz"), None);
    }

    #[test]
    fn the_runner_spreads_steps_over_frames() {
        let s = parse("press F1\nhold W 2\nresize 10x10\nwait 2\nscreenshot a.png").unwrap();
        assert_eq!(s.frames(), 5);
        let mut r = ScriptRunner::new(s);
        let f1 = r.next_frame();
        assert_eq!(f1.instant, vec![Step::Press(KeyCode::F1)]);
        assert_eq!((f1.hold, f1.release, f1.last), (Some(KeyCode::KeyW), None, false));
        assert_eq!(r.next_frame(), FrameSteps::default(), "second frame of the hold");
        let f3 = r.next_frame();
        assert_eq!(f3.release, Some(KeyCode::KeyW));
        assert_eq!(f3.instant, vec![Step::Resize(10, 10)]);
        assert!(!f3.last);
        assert_eq!(r.next_frame(), FrameSteps::default());
        let f5 = r.next_frame();
        assert_eq!(f5.instant, vec![Step::Screenshot("a.png".into())]);
        assert!(f5.last && r.finished());
    }
}
