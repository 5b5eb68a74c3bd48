//! F11: fullscreen that works with or without a window manager.
//!
//! winit's borderless fullscreen asks the window manager (on X11 the EWMH
//! `_NET_WM_STATE_FULLSCREEN` message); with none running — a bare X server such as Xvfb, a kiosk
//! session — nobody answers and the window stays as it was. So the viewer asks, and if the
//! window has not grown to its monitor's size [`GRACE_FRAMES`] frames and [`GRACE`] later, it
//! does what a window manager would: it removes the decorations and moves and sizes the window
//! over the monitor itself ([`Fullscreen::check`] says when). The second F11 leaves either way:
//! the fullscreen request is withdrawn and, after the fallback, the decorations, size and
//! position from before are restored.

use std::time::{Duration, Instant};

use winit::dpi::{PhysicalPosition, PhysicalSize};
use winit::window::Window;

/// Frames to wait for a window manager to make the window fullscreen before doing it ourselves.
pub const GRACE_FRAMES: u64 = 3;
/// Time to wait likewise (a window manager may take a few frames of a fast GPU to answer).
/// Scripted runs, which count frames, wait only [`GRACE_FRAMES`].
pub const GRACE: Duration = Duration::from_millis(250);

/// A fullscreen window: what to restore and whether the fallback was needed.
#[derive(Clone, Debug, PartialEq)]
pub struct Fullscreen {
    /// The window's outer position and inner size before (position: `None` where the window
    /// system does not tell it).
    restore_position: Option<PhysicalPosition<i32>>,
    restore_size: PhysicalSize<u32>,
    /// The monitor covered: its position and size.
    monitor_position: PhysicalPosition<i32>,
    monitor_size: PhysicalSize<u32>,
    /// When it was asked for: the frame count and the time.
    asked_frame: u64,
    asked_at: Instant,
    /// Whether the viewer placed the window itself (no window manager answered).
    placed: bool,
    /// Whether the window reached the monitor's size without the fallback (a window manager
    /// answered).
    settled: bool,
}

impl Fullscreen {
    /// Asks for borderless fullscreen on the window's monitor; `None` when the window system
    /// tells no monitor (then nothing is asked).
    pub fn enter(window: &Window, frame: u64) -> Option<Fullscreen> {
        let monitor = window.current_monitor().or_else(|| window.primary_monitor())?;
        let state = Fullscreen {
            restore_position: window.outer_position().ok(),
            restore_size: window.inner_size(),
            monitor_position: monitor.position(),
            monitor_size: monitor.size(),
            asked_frame: frame,
            asked_at: Instant::now(),
            placed: false,
            settled: false,
        };
        window.set_fullscreen(Some(winit::window::Fullscreen::Borderless(Some(monitor))));
        Some(state)
    }

    /// Whether the fallback is due at frame `frame` for a window of inner size `size`: not yet
    /// placed, the grace over (`scripted`: frames only), and the window not the monitor's size.
    pub fn due(&self, frame: u64, now: Instant, size: PhysicalSize<u32>, scripted: bool) -> bool {
        let waited = frame >= self.asked_frame + GRACE_FRAMES
            && (scripted || now.saturating_duration_since(self.asked_at) >= GRACE);
        !self.placed && waited && size != self.monitor_size
    }

    /// Once a frame while fullscreen: when [`due`](Self::due), covers the monitor with the
    /// undecorated window. Returns whether it did (the caller says so).
    pub fn check(&mut self, window: &Window, frame: u64, scripted: bool) -> bool {
        let size = window.inner_size();
        if size == self.monitor_size {
            self.settled = true;
        }
        if !self.due(frame, Instant::now(), size, scripted) {
            return false;
        }
        self.placed = true;
        window.set_decorations(false);
        window.set_outer_position(self.monitor_position);
        // Without a window manager the X server grants the size at once; the Resized event
        // that follows resizes the surface.
        let _ = window.request_inner_size(self.monitor_size);
        true
    }

    /// Whether the frames must go on until [`check`](Self::check) has decided (an idle viewer
    /// draws no frame, and the fallback would wait for the next input).
    pub fn pending(&self) -> bool {
        !self.placed && !self.settled
    }

    /// Whether the viewer placed the window itself.
    pub fn placed(&self) -> bool {
        self.placed
    }

    /// Leaves fullscreen: withdraws the request and, after the fallback, restores the
    /// decorations, size and position.
    pub fn leave(self, window: &Window) {
        window.set_fullscreen(None);
        if self.placed {
            window.set_decorations(true);
            let _ = window.request_inner_size(self.restore_size);
            if let Some(p) = self.restore_position {
                window.set_outer_position(p);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn asked(frame: u64, at: Instant) -> Fullscreen {
        Fullscreen {
            restore_position: Some(PhysicalPosition::new(10, 20)),
            restore_size: PhysicalSize::new(480, 320),
            monitor_position: PhysicalPosition::new(0, 0),
            monitor_size: PhysicalSize::new(1024, 768),
            asked_frame: frame,
            asked_at: at,
            placed: false,
            settled: false,
        }
    }

    #[test]
    fn the_fallback_waits_for_a_window_manager_and_only_when_none_answered() {
        let t0 = Instant::now();
        let f = asked(10, t0);
        let small = PhysicalSize::new(480, 320);
        let full = PhysicalSize::new(1024, 768);
        // Not before GRACE_FRAMES frames, nor (interactive) before GRACE.
        assert!(!f.due(10 + GRACE_FRAMES - 1, t0 + GRACE * 2, small, false));
        assert!(!f.due(10 + GRACE_FRAMES, t0 + GRACE / 2, small, false));
        assert!(f.due(10 + GRACE_FRAMES, t0 + GRACE, small, false));
        // Scripted runs count frames only.
        assert!(f.due(10 + GRACE_FRAMES, t0, small, true));
        // A window manager made it fullscreen: nothing to do.
        assert!(!f.due(100, t0 + GRACE * 10, full, false));
        // Placed once, never again.
        let placed = Fullscreen { placed: true, ..f.clone() };
        assert!(!placed.due(100, t0 + GRACE * 10, small, false) && !placed.pending());
        assert!(f.pending() && !Fullscreen { settled: true, ..f }.pending());
    }
}
