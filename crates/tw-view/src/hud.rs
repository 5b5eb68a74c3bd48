//! The HUD's model, plain data: a ring of recent frame times (fps and the frame-time graph), a
//! disk throughput meter (bytes/s from the cache's cumulative read counter), and [`HudFrame`],
//! the figures of one frame turned into labelled lines. [`crate::ui`] draws them.

use std::collections::VecDeque;
use std::time::Duration;

use tw_frame::ShadowInfo;
use tw_runtime::pathgen::format_length;
use tw_store::units::unit_suffix;

/// Frame times kept for the graph.
pub const HISTORY: usize = 240;

/// Recent frame times (seconds), newest last.
#[derive(Clone, Debug, Default)]
pub struct FrameTimes {
    times: VecDeque<f32>,
}

impl FrameTimes {
    pub fn push(&mut self, dt: f32) {
        if self.times.len() == HISTORY {
            self.times.pop_front();
        }
        self.times.push_back(dt.max(0.0));
    }

    pub fn len(&self) -> usize {
        self.times.len()
    }

    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    pub fn times(&self) -> impl Iterator<Item = f32> + '_ {
        self.times.iter().copied()
    }

    /// Frames per second over the last second of frames (at least one frame).
    pub fn fps(&self) -> f32 {
        let mut total = 0.0;
        let mut n = 0;
        for &t in self.times.iter().rev() {
            total += t;
            n += 1;
            if total >= 1.0 {
                break;
            }
        }
        if total > 0.0 {
            n as f32 / total
        } else {
            0.0
        }
    }

    /// Largest frame time kept (seconds).
    pub fn max(&self) -> f32 {
        self.times.iter().copied().fold(0.0, f32::max)
    }

    /// Points of the frame-time graph in a `w` × `h` box, y down, scaled so that
    /// `max(largest, 1/30 s)` is the top: one point per frame, newest at the right.
    pub fn graph(&self, w: f32, h: f32) -> Vec<[f32; 2]> {
        let top = self.max().max(1.0 / 30.0);
        let n = self.times.len();
        self.times
            .iter()
            .enumerate()
            .map(|(i, &t)| {
                let x = w * (HISTORY - n + i) as f32 / (HISTORY - 1) as f32;
                [x.min(w), h - h * (t / top).min(1.0)]
            })
            .collect()
    }
}

/// Bytes per second from a cumulative counter, averaged over about a second.
#[derive(Clone, Debug, Default)]
pub struct Throughput {
    samples: VecDeque<(f64, u64)>,
}

impl Throughput {
    /// Records the counter `total` at time `t` seconds.
    pub fn push(&mut self, t: f64, total: u64) {
        self.samples.push_back((t, total));
        while self.samples.len() > 2 && self.samples[1].0 <= t - 1.0 {
            self.samples.pop_front();
        }
    }

    pub fn per_second(&self) -> f64 {
        match (self.samples.front(), self.samples.back()) {
            (Some(&(t0, b0)), Some(&(t1, b1))) if t1 > t0 => b1.saturating_sub(b0) as f64 / (t1 - t0),
            _ => 0.0,
        }
    }
}

/// What one frame did, for the HUD.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HudFrame {
    pub fps: f32,
    pub frame_ms: f32,
    pub select_ms: f32,
    pub render_ms: f32,
    pub triangles: u64,
    pub clusters: u64,
    pub nodes_visible: u64,
    pub nodes_frustum_culled: u64,
    pub nodes_lod_culled: u64,
    /// The occlusion strategy, clusters it tested against the occluders' depth, and those it
    /// found hidden (not drawn).
    pub occlusion: String,
    pub occlusion_tested: u64,
    pub occlusion_culled: u64,
    /// Occlusion tests with their read-backs or queries.
    pub cull_ms: f32,
    pub resident_bytes: u64,
    pub memory_budget: u64,
    /// The factor τ is raised by so that the cut's pages fit the budget (1 or 0: not raised;
    /// `tw_runtime::fit`).
    pub tau_scale: f32,
    /// Cluster geometry resident on the GPU.
    pub gpu_bytes: u64,
    /// The GPU pool's budget (0 before the first frame).
    pub gpu_budget: u64,
    pub pages_loading: u64,
    pub pages_failed: u64,
    pub disk_bytes_per_s: f64,
    /// The eye in input coordinates, and the current mode's speed (units per second), in
    /// `units` (the store's; empty when it records none).
    pub position: [f64; 3],
    pub speed: f64,
    pub units: String,
    pub mode: String,
    pub adapter: String,
    /// The renderer (`raster`, `rt` with its threads and light) and, ray traced, the samples
    /// per pixel in the image shown and their most (0 when rasterized).
    pub renderer: String,
    pub samples: u32,
    pub max_samples: u32,
    /// The light casting shadows, in words (empty while shadows are off); rasterized, the
    /// last shadow stage's figures and whether it cross-culled (ray traced: `None`, the
    /// shadows are shadow rays inside the trace).
    pub light: String,
    pub shadow: Option<ShadowInfo>,
    pub cross_culling: bool,
}

impl HudFrame {
    /// Resident bytes of the budget, and the detail lowered to fit it.
    fn memory_text(&self) -> String {
        let held = format!("{} / {}", bytes(self.resident_bytes), bytes(self.memory_budget));
        if self.tau_scale > 1.0 {
            format!("{held} (pixel error ×{:.1} to fit)", self.tau_scale)
        } else {
            held
        }
    }

    /// Labelled lines, in display order.
    pub fn lines(&self) -> Vec<(&'static str, String)> {
        let mut lines = vec![
            ("renderer", self.renderer.clone()),
            ("fps", format!("{:.1} ({:.1} ms)", self.fps, self.frame_ms)),
            (
                "select / cull / draw",
                format!("{:.1} / {:.1} / {:.1} ms", self.select_ms, self.cull_ms, self.render_ms),
            ),
            ("triangles drawn", count(self.triangles)),
            ("clusters drawn", count(self.clusters)),
            ("shadows", self.shadow_summary()),
            ("nodes visible", count(self.nodes_visible)),
            ("frustum-culled", count(self.nodes_frustum_culled)),
            ("LOD-culled", count(self.nodes_lod_culled)),
            (
                "occlusion-culled",
                if self.occlusion.is_empty() || self.occlusion == "none" {
                    "off".to_string()
                } else {
                    format!(
                        "{} of {} clusters tested ({})",
                        count(self.occlusion_culled),
                        count(self.occlusion_tested),
                        self.occlusion
                    )
                },
            ),
            ("resident memory", self.memory_text()),
            (
                "GPU memory",
                if self.gpu_budget > 0 {
                    format!("{} / {}", bytes(self.gpu_bytes), bytes(self.gpu_budget))
                } else if self.max_samples > 0 {
                    "none (the ray tracer runs on the CPU)".to_string()
                } else {
                    format!("{} (no renderer yet)", bytes(self.gpu_bytes))
                },
            ),
            ("pages loading", format!("{} ({} failed)", self.pages_loading, self.pages_failed)),
            ("disk", format!("{}/s", bytes(self.disk_bytes_per_s as u64))),
            ("camera", self.mode.clone()),
            ("position", self.position_text()),
            ("speed", format!("{} {}/s", format_length(self.speed), unit_suffix(&self.units))),
            ("adapter", self.adapter.clone()),
        ];
        if self.max_samples > 0 {
            let still = if self.samples >= self.max_samples { " (complete)" } else { "" };
            lines.insert(1, ("samples", format!("{} / {} per pixel{still}", self.samples, self.max_samples)));
        }
        lines
    }

    /// The HUD's one shadow line, short to keep the HUD narrow: off, or the stage's time and
    /// layers (shadow rays when ray traced). The light is in the "Shadows" section.
    fn shadow_summary(&self) -> String {
        match (&self.shadow, self.light.is_empty()) {
            (_, true) => "off (J)".to_string(),
            (Some(s), false) => format!("{:.1} ms, {} layers", ms(s.total), s.layers),
            (None, false) => "shadow rays".to_string(),
        }
    }

    /// The shadow stage's figures for the "Shadows" section (Govindaraju's thesis ch. 4's set
    /// sizes: light-view sets, casters, receivers by class), empty while shadows are off.
    pub fn shadow_lines(&self) -> Vec<(&'static str, String)> {
        if self.light.is_empty() {
            return Vec::new();
        }
        let Some(s) = &self.shadow else {
            return vec![
                ("light", self.light.clone()),
                ("shadows", "shadow rays of the ray tracer".to_string()),
            ];
        };
        let set = |clusters: u64, triangles: u64| {
            format!("{} clusters, {} triangles", count(clusters), count(triangles))
        };
        let mut lines = vec![
            ("light", self.light.clone()),
            ("stage", format!("{:.1} ms", ms(s.total))),
            ("fit / select / draw", format!("{:.1} / {:.1} / {:.1} ms", ms(s.fit), ms(s.select), ms(s.draw))),
            ("read back / classify", format!("{:.1} / {:.1} ms", ms(s.readback), ms(s.classify))),
            ("layers", format!("{} ({} reused)", s.layers, s.layers_reused)),
            ("light-view sets", set(s.sets.light_cut, s.light_triangles)),
        ];
        if self.cross_culling {
            lines.extend([
                ("light-visible", format!("{} clusters", count(s.sets.light_visible))),
                ("casters", set(s.sets.casters, s.caster_triangles)),
                ("receivers lit", set(s.sets.receivers_lit, s.sets.triangles_lit)),
                ("shadowed", set(s.sets.receivers_shadowed, s.sets.triangles_shadowed)),
                ("partly shadowed", set(s.sets.receivers_partial, s.sets.triangles_partial)),
            ]);
        } else {
            lines.push((
                "receivers",
                format!("{} (all look the map up)", set(s.sets.receivers_partial, s.sets.triangles_partial)),
            ));
        }
        lines
    }

    /// The eye's input coordinates with the store's unit (`"12.5, -3.20, 1.70 m"`), to three
    /// significant digits at any scale.
    fn position_text(&self) -> String {
        let [x, y, z] = self.position.map(format_length);
        format!("{x}, {y}, {z} {}", unit_suffix(&self.units))
    }
}

fn ms(d: Duration) -> f32 {
    d.as_secs_f32() * 1e3
}

/// `1234567` → `"1.23 M"`.
pub fn count(n: u64) -> String {
    match n {
        0..=9_999 => n.to_string(),
        10_000..=999_999 => format!("{:.1} k", n as f64 / 1e3),
        1_000_000..=999_999_999 => format!("{:.2} M", n as f64 / 1e6),
        _ => format!("{:.2} G", n as f64 / 1e9),
    }
}

/// Bytes in binary units.
pub fn bytes(n: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = n as f64;
    let mut u = 0;
    while v >= 1024.0 && u < UNITS.len() - 1 {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{n} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tw_runtime::shadow::ShadowSetStats;

    #[test]
    fn fps_over_the_last_second() {
        let mut f = FrameTimes::default();
        assert_eq!(f.fps(), 0.0);
        for _ in 0..100 {
            f.push(0.02);
        }
        assert!((f.fps() - 50.0).abs() < 0.5);
        for _ in 0..1000 {
            f.push(0.01);
        }
        assert_eq!(f.len(), HISTORY);
        assert!((f.fps() - 100.0).abs() < 1.0);
    }

    #[test]
    fn graph_fits_its_box() {
        let mut f = FrameTimes::default();
        for i in 0..10 {
            f.push(0.01 * i as f32);
        }
        let g = f.graph(200.0, 50.0);
        assert_eq!(g.len(), 10);
        assert!(g.iter().all(|p| (0.0..=200.0).contains(&p[0]) && (0.0..=50.0).contains(&p[1])));
        assert_eq!(g.last().unwrap()[0], 200.0);
        assert_eq!(g.last().unwrap()[1], 0.0, "the largest frame reaches the top");
    }

    #[test]
    fn throughput_is_bytes_per_second() {
        let mut t = Throughput::default();
        assert_eq!(t.per_second(), 0.0);
        for i in 0..=20 {
            t.push(i as f64 * 0.1, i * 1000);
        }
        assert!((t.per_second() - 10_000.0).abs() < 1.0, "{}", t.per_second());
    }

    #[test]
    fn lines_name_every_figure() {
        let h = HudFrame {
            triangles: 1_500_000,
            resident_bytes: 3 << 20,
            memory_budget: 1 << 30,
            ..Default::default()
        };
        let lines = h.lines();
        let get = |k: &str| lines.iter().find(|l| l.0 == k).unwrap().1.clone();
        assert_eq!(get("triangles drawn"), "1.50 M");
        assert_eq!(get("resident memory"), "3.0 MiB / 1.0 GiB");
        let fitted = HudFrame { tau_scale: 1.64, ..h.clone() };
        let fitted = fitted.lines();
        let memory = &fitted.iter().find(|l| l.0 == "resident memory").unwrap().1;
        assert_eq!(memory, "3.0 MiB / 1.0 GiB (pixel error ×1.6 to fit)");
        assert_eq!(get("GPU memory"), "0 B (no renderer yet)");
        assert_eq!(get("occlusion-culled"), "off");
        assert_eq!(get("position"), "0, 0, 0 units");
        let h = HudFrame {
            position: [1250.0, -3.2, 1700.0],
            speed: 1400.0,
            units: "mm".into(),
            ..Default::default()
        };
        let lines = h.lines();
        let get = |k: &str| lines.iter().find(|l| l.0 == k).unwrap().1.clone();
        assert_eq!(get("position"), "1250, -3.20, 1700 mm");
        assert_eq!(get("speed"), "1400 mm/s");
        let h = HudFrame {
            occlusion: "hzb".into(),
            occlusion_tested: 120,
            occlusion_culled: 80,
            gpu_bytes: 1 << 20,
            gpu_budget: 512 << 20,
            ..Default::default()
        };
        let lines = h.lines();
        let get = |k: &str| lines.iter().find(|l| l.0 == k).unwrap().1.clone();
        assert_eq!(get("occlusion-culled"), "80 of 120 clusters tested (hzb)");
        assert_eq!(get("GPU memory"), "1.0 MiB / 512.0 MiB");
        assert!(lines.iter().all(|l| l.0 != "samples"), "no samples line when rasterized");
        let h = HudFrame { renderer: "rt".into(), samples: 5, max_samples: 64, ..Default::default() };
        let lines = h.lines();
        let get = |k: &str| lines.iter().find(|l| l.0 == k).unwrap().1.clone();
        assert_eq!(get("renderer"), "rt");
        assert_eq!(get("samples"), "5 / 64 per pixel");
        assert_eq!(get("GPU memory"), "none (the ray tracer runs on the CPU)");
        let h = HudFrame { samples: 64, max_samples: 64, ..Default::default() };
        assert!(h.lines().contains(&("samples", "64 / 64 per pixel (complete)".to_string())));
        assert!(lines.iter().any(|l| l.0 == "occlusion-culled"));
        assert_eq!(bytes(10), "10 B");
        assert_eq!(count(12_345), "12.3 k");
    }

    #[test]
    fn shadow_lines_show_the_stages_figures() {
        let off = HudFrame::default();
        assert!(off.shadow_lines().is_empty());
        assert!(off.lines().contains(&("shadows", "off (J)".to_string())));
        let sets = ShadowSetStats {
            receivers_lit: 5,
            receivers_shadowed: 6,
            receivers_partial: 7,
            triangles_lit: 500,
            triangles_shadowed: 600,
            triangles_partial: 700,
            light_cut: 40,
            light_visible: 30,
            casters: 12,
        };
        let info = ShadowInfo {
            layers: 3,
            light_triangles: 12_000,
            sets,
            caster_triangles: 3_000,
            total: Duration::from_micros(4_300),
            ..Default::default()
        };
        let h =
            HudFrame { light: "sun".into(), shadow: Some(info), cross_culling: true, ..Default::default() };
        assert!(h.lines().contains(&("shadows", "4.3 ms, 3 layers".to_string())));
        let lines = h.shadow_lines();
        let get = |k: &str| lines.iter().find(|l| l.0 == k).unwrap().1.clone();
        assert_eq!(get("light-view sets"), "40 clusters, 12.0 k triangles");
        assert_eq!(get("casters"), "12 clusters, 3000 triangles");
        assert_eq!(get("receivers lit"), "5 clusters, 500 triangles");
        assert_eq!(get("shadowed"), "6 clusters, 600 triangles");
        assert_eq!(get("partly shadowed"), "7 clusters, 700 triangles");
        assert_eq!(get("stage"), "4.3 ms");
        assert_eq!(get("light"), "sun");
        let h = HudFrame { cross_culling: false, ..h };
        let lines = h.shadow_lines();
        assert!(lines.iter().all(|l| l.0 != "casters"), "no classes without cross-culling");
        assert!(lines.iter().any(|l| l.0 == "receivers"));
        let rt = HudFrame { light: "sun".into(), shadow: None, ..Default::default() };
        assert!(rt.lines().contains(&("shadows", "shadow rays".to_string())));
        assert_eq!(rt.shadow_lines().len(), 2);
    }
}
