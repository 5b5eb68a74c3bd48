//! `render --video`: frames piped into ffmpeg as raw RGBA, encoded into a video file.
//!
//! Raw frames (not PNGs) go through the pipe: nothing is compressed twice, and ffmpeg needs no
//! guessing about the input (`-f rawvideo` with the size, pixel format and frame rate given).
//! ffmpeg writes a temporary file beside the video (same extension, so it picks the same
//! container) that is renamed over it once ffmpeg has succeeded: a failed or interrupted
//! encoding leaves no truncated video under the asked name.

use std::ffi::OsString;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};

use anyhow::{bail, Context, Result};

/// Finds `ffmpeg` on PATH, or says how to install it.
pub fn find_ffmpeg() -> Result<PathBuf> {
    tw_io::convert::find_program(Path::new("ffmpeg")).ok_or_else(|| {
        anyhow::anyhow!(
            "--video needs ffmpeg, which is not on PATH. Install it:\n    \
             sudo apt install ffmpeg      (Debian, Ubuntu)\n    \
             sudo dnf install ffmpeg      (Fedora)\n    \
             brew install ffmpeg          (macOS)\n  \
             or write the frames with --frames-dir DIR and encode them later:\n    \
             ffmpeg -framerate 30 -i DIR/frame-%05d.png -pix_fmt yuv420p video.mp4"
        )
    })
}

/// ffmpeg's arguments: raw RGBA frames of `size` at `fps` on standard input, encoded into
/// `output`, whose extension picks the container and its default encoder. Video players want
/// 4:2:0 chroma (yuv420p) in mp4/mkv/mov/webm, which needs even sides: odd ones are padded by a
/// pixel. A GIF keeps its own palette format.
pub fn ffmpeg_args(size: (u32, u32), fps: f64, output: &Path) -> Vec<OsString> {
    let mut args: Vec<OsString> = [
        "-hide_banner",
        "-loglevel",
        "error",
        "-y",
        "-f",
        "rawvideo",
        "-pixel_format",
        "rgba",
        "-video_size",
    ]
    .iter()
    .map(OsString::from)
    .collect();
    args.push(format!("{}x{}", size.0, size.1).into());
    args.push("-framerate".into());
    args.push(format!("{fps}").into());
    args.extend(["-i", "-"].map(OsString::from));
    let gif = output.extension().is_some_and(|e| e.eq_ignore_ascii_case("gif"));
    if !gif {
        args.extend(["-vf", "pad=ceil(iw/2)*2:ceil(ih/2)*2", "-pix_fmt", "yuv420p"].map(OsString::from));
    }
    args.push(output.into());
    args
}

/// A running ffmpeg that frames are written to.
pub struct Encoder {
    child: Child,
    stdin: Option<ChildStdin>,
    partial: PathBuf,
    output: PathBuf,
    _guard: tw_core::cleanup::TempGuard,
}

impl Encoder {
    /// Starts `ffmpeg` writing `output` (through a temporary file beside it).
    pub fn start(ffmpeg: &Path, size: (u32, u32), fps: f64, output: &Path) -> Result<Encoder> {
        if !(fps.is_finite() && fps > 0.0) {
            bail!("--fps must be a number > 0, got {fps}");
        }
        let partial = partial_name(output);
        let guard = tw_core::cleanup::register(&partial);
        let mut child = Command::new(ffmpeg)
            .args(ffmpeg_args(size, fps, &partial))
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .spawn()
            .with_context(|| format!("cannot start {}", ffmpeg.display()))?;
        let stdin = child.stdin.take();
        Ok(Encoder { child, stdin, partial, output: output.to_path_buf(), _guard: guard })
    }

    /// Sends one frame (`width × height × 4` bytes of opaque RGBA).
    pub fn frame(&mut self, rgba: &[u8]) -> Result<()> {
        let Some(stdin) = self.stdin.as_mut() else { bail!("ffmpeg's input is closed") };
        if stdin.write_all(rgba).is_err() {
            // ffmpeg has quit (its message is on stderr): report its exit status.
            self.stdin = None;
            let status = self.child.wait().context("waiting for ffmpeg")?;
            let _ = std::fs::remove_file(&self.partial);
            bail!(
                "ffmpeg stopped reading frames ({status}) while encoding {}: see its message above",
                self.output.display()
            );
        }
        Ok(())
    }

    /// Closes the input, waits for ffmpeg and moves the video into place.
    pub fn finish(mut self) -> Result<()> {
        drop(self.stdin.take());
        let status = self.child.wait().context("waiting for ffmpeg")?;
        if !status.success() {
            let _ = std::fs::remove_file(&self.partial);
            bail!("ffmpeg failed ({status}) encoding {}: see its message above", self.output.display());
        }
        std::fs::rename(&self.partial, &self.output)
            .with_context(|| format!("cannot move {} to {}", self.partial.display(), self.output.display()))
    }
}

impl Drop for Encoder {
    /// An encoder dropped before [`Encoder::finish`] (a frame failed to render): ffmpeg is told
    /// the input has ended, and its partial file is removed.
    fn drop(&mut self) {
        if self.stdin.take().is_some() {
            let _ = self.child.wait();
            let _ = std::fs::remove_file(&self.partial);
        }
    }
}

/// `walk.mp4` → `.walk.partial.mp4`: hidden, and with the extension ffmpeg picks the container by.
fn partial_name(output: &Path) -> PathBuf {
    let stem = output.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let name = match output.extension() {
        Some(ext) => format!(".{stem}.partial.{}", ext.to_string_lossy()),
        None => format!(".{stem}.partial"),
    };
    output.with_file_name(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn strings(args: &[OsString]) -> Vec<String> {
        args.iter().map(|a| a.to_string_lossy().into_owned()).collect()
    }

    #[test]
    fn ffmpeg_reads_raw_rgba_of_the_frame_size_and_rate_from_stdin() {
        let args = strings(&ffmpeg_args((64, 36), 30.0, Path::new("out/walk.mp4")));
        let after = |flag: &str| args[args.iter().position(|a| a == flag).expect(flag) + 1].clone();
        assert_eq!(after("-f"), "rawvideo");
        assert_eq!(after("-pixel_format"), "rgba");
        assert_eq!(after("-video_size"), "64x36");
        assert_eq!(after("-framerate"), "30");
        assert_eq!(after("-i"), "-");
        assert_eq!(after("-pix_fmt"), "yuv420p");
        assert!(after("-vf").starts_with("pad="), "odd sizes are padded to even ones");
        assert!(args.contains(&"-y".to_string()), "the partial file may be left from a killed run");
        // Input options come before the input, the output last.
        assert!(args.iter().position(|a| a == "-framerate") < args.iter().position(|a| a == "-i"));
        assert_eq!(args.last().map(String::as_str), Some("out/walk.mp4"));
        let gif = strings(&ffmpeg_args((65, 37), 12.5, Path::new("a.gif")));
        assert!(!gif.contains(&"-pix_fmt".to_string()), "{gif:?}");
        assert!(gif.contains(&"12.5".to_string()) && gif.contains(&"65x37".to_string()));
    }

    #[test]
    fn the_partial_file_keeps_the_extension_beside_the_video() {
        assert_eq!(partial_name(Path::new("d/walk.mp4")), PathBuf::from("d/.walk.partial.mp4"));
        assert_eq!(partial_name(Path::new("v")), PathBuf::from(".v.partial"));
    }

    /// Where ffmpeg would be found with `path` as the `PATH` value.
    fn find_on_path(path: Option<std::ffi::OsString>) -> Option<PathBuf> {
        tw_io::convert::find_program_in(Path::new("ffmpeg"), path)
    }

    #[cfg(unix)]
    #[test]
    fn ffmpeg_is_found_only_as_an_executable_on_path() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let (plain, exe) = (dir.path().join("a"), dir.path().join("b"));
        std::fs::create_dir_all(&plain).unwrap();
        std::fs::create_dir_all(&exe).unwrap();
        std::fs::write(plain.join("ffmpeg"), "").unwrap();
        std::fs::write(exe.join("ffmpeg"), "#!/bin/sh\n").unwrap();
        std::fs::set_permissions(exe.join("ffmpeg"), std::fs::Permissions::from_mode(0o755)).unwrap();
        let path = std::env::join_paths([&plain, &exe]).unwrap();
        assert_eq!(find_on_path(Some(path)), Some(exe.join("ffmpeg")));
        let path = std::env::join_paths([&plain]).unwrap();
        assert_eq!(find_on_path(Some(path)), None);
        assert_eq!(find_on_path(None), None);
    }
}
