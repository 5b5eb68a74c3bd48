//! Line plots as inline SVG, written by hand (no scripts, no fonts to fetch): one plot per
//! per-frame series, every run overlaid in its own colour with a legend, axes with "nice" ticks
//! (1, 2, 5 × 10^k) and units, light grid lines, and the camera path's segments ("walk",
//! "fly") as shaded bands. Long runs are decimated to a min/max envelope per pixel column, so
//! spikes stay visible and the file stays small.

use std::fmt::Write;

use crate::{FrameRecord, Run, RunKind};

/// One per-frame figure: its JSON key, title, unit and how to read it from a frame.
pub struct Series {
    pub key: &'static str,
    pub title: &'static str,
    pub unit: &'static str,
    pub value: fn(&FrameRecord) -> Option<f64>,
}

macro_rules! series {
    ($key:ident, $title:expr, $unit:expr) => {
        Series { key: stringify!($key), title: $title, unit: $unit, value: |f| Some(f.$key as f64) }
    };
    ($key:ident?, $title:expr, $unit:expr) => {
        Series { key: stringify!($key), title: $title, unit: $unit, value: |f| f.$key.map(|v| v as f64) }
    };
}

/// Every per-frame series of a [`FrameRecord`], in the order the page shows them.
pub const SERIES: &[Series] = &[
    series!(frame_ms, "Frame time", "ms"),
    // Frustum culling has no time of its own: the cut's traversal tests each node's box as it
    // reaches it (tw-runtime's select.rs), so its time is in the selection's.
    series!(select_ms, "LOD selection and frustum culling time", "ms"),
    series!(culling_ms, "Occlusion culling time", "ms"),
    series!(upload_ms, "Upload time", "ms"),
    series!(render_ms, "Render time (GPU + readback)", "ms"),
    series!(triangles, "Triangles drawn", "triangles"),
    series!(cut_triangles, "Triangles in the LOD cut", "triangles"),
    series!(needed_triangles?, "Triangles a screen needs at ε (2 · covered px ÷ ε²)", "triangles"),
    series!(lod_efficiency?, "LOD efficiency (cut ÷ needed)", "ratio"),
    series!(covered_pixels?, "Pixels covered by the model", "pixels"),
    series!(clusters, "Clusters drawn", "clusters"),
    series!(nodes_visited, "Nodes visited", "nodes"),
    series!(nodes_culled_frustum, "Nodes culled by the frustum", "nodes"),
    series!(nodes_culled_lod, "Nodes culled by LOD", "nodes"),
    series!(nodes_culled_occlusion, "Nodes culled by occlusion", "nodes"),
    series!(occlusion_queries, "Occlusion queries", "queries"),
    series!(resident_mb, "Resident pages", "MB"),
    series!(gpu_resident_mb, "GPU resident", "MB"),
    series!(disk_read_mb, "Read from disk", "MB"),
    series!(pages_requested, "Pages requested", "pages"),
    series!(pages_loaded, "Pages loaded", "pages"),
    series!(pages_evicted, "Pages evicted", "pages"),
    series!(stalls_avoided, "Stalls avoided (coarser ancestor drawn)", "groups"),
    series!(tau_scale, "Pixel error raised to fit the memory budget", "× τ"),
    series!(psnr_db?, "PSNR against the reference", "dB"),
    series!(differing_pixels?, "Differing pixels", "share"),
    series!(supersampled_psnr_db?, "PSNR against the supersampled reference", "dB"),
    series!(brute_force_psnr_db?, "Brute-force frame's PSNR against the supersampled reference", "dB"),
    series!(psnr_gap_db?, "PSNR gap: LOD − brute force (supersampled reference)", "dB"),
    series!(popping_changed_pixels?, "Popping: pixels the LOD alone changes", "share"),
    series!(popping_psnr_db?, "Popping: PSNR of the LOD-only change (changed frames)", "dB"),
    series!(exact_visible_triangles?, "Exactly visible triangles", "triangles"),
    series!(exact_visible_objects?, "Exactly visible objects", "objects"),
    series!(culling_efficiency?, "Culling efficiency (drawn ÷ visible)", "ratio"),
];

/// Colours of runs (Tableau 10), in order.
pub const PALETTE: [&str; 10] = [
    "#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f", "#edc948", "#b07aa1", "#ff9da7", "#9c755f",
    "#bab0ac",
];

/// The series worth a plot: some plotted run ([`plotted_runs`]) has a non-zero value.
pub fn plotted(runs: &[Run]) -> Vec<&'static Series> {
    SERIES
        .iter()
        .filter(|s| {
            plotted_runs(runs).any(|(_, r)| r.frames.iter().any(|f| (s.value)(f).is_some_and(|v| v != 0.0)))
        })
        .collect()
}

/// The runs the per-frame plots show, with their index in `runs` (their colour): the
/// walkthroughs. Reference renderings ([`RunKind::Reference`]) are left out: they are no
/// walkthrough frames (drawn once each, at full detail, before the runs), and one of them can
/// take seconds where a walkthrough frame takes milliseconds, which would squeeze every
/// walkthrough into the bottom pixel row of the frame-time plot. A log axis would keep both
/// visible, but would compare a walkthrough with a rendering it never has to match in time;
/// the reference's times are in the summary table, and its speed-up ratio with them.
pub fn plotted_runs(runs: &[Run]) -> impl Iterator<Item = (usize, &Run)> {
    runs.iter().enumerate().filter(|(_, r)| r.kind == RunKind::Walkthrough)
}

/// The points of `series` in `run`: (frame number, value), frames without a (finite) value
/// left out. The frame number, not the position in the run: runs that hold only some frames
/// (the compared frames of `--compare K`) line up with those that hold all.
pub fn points(series: &Series, run: &Run) -> Vec<(f64, f64)> {
    run.frames
        .iter()
        .filter_map(|f| (series.value)(f).filter(|v| v.is_finite()).map(|v| (f64::from(f.frame), v)))
        .collect()
}

/// Escapes text for HTML and SVG.
pub fn escape(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            _ => o.push(c),
        }
    }
    o
}

/// Ranges narrower than this share of their magnitude are flat: their nice step would be a
/// rounding error of the values, labelled with as many digits.
const FLAT: f64 = 1e-6;

/// Tick positions of one axis and the step between them.
#[derive(Clone, Debug, PartialEq)]
pub struct Ticks {
    pub values: Vec<f64>,
    pub step: f64,
}

impl Ticks {
    /// "Nice" ticks (1, 2, 2.5, 5 × 10^k apart) covering `lo..=hi` with about `target` steps of
    /// at least `min_step` (1 for frame numbers: no tick between two frames). A flat range
    /// (every value the same, to a millionth of its magnitude) is widened by half the value on
    /// either side (±0.5 around 0), so that it still gets several distinct ticks, the value in
    /// the middle and a positive value's axis positive.
    pub fn new(lo: f64, hi: f64, target: usize, min_step: f64) -> Ticks {
        let (lo, hi) = if hi - lo > FLAT * lo.abs().max(hi.abs()) {
            (lo, hi)
        } else {
            let mid = 0.5 * (lo + hi);
            let half = if mid == 0.0 { 0.5 } else { 0.5 * mid.abs() };
            (mid - half, mid + half)
        };
        let raw = ((hi - lo) / target.max(1) as f64).max(min_step);
        let mag = 10f64.powf(raw.log10().floor());
        let step =
            [1.0, 2.0, 2.5, 5.0, 10.0].iter().map(|m| m * mag).find(|s| *s >= raw).unwrap_or(10.0 * mag);
        let first = (lo / step).floor() * step;
        let mut values = Vec::new();
        let mut k = 0;
        while values.len() < 64 {
            let t = first + k as f64 * step;
            values.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
            if t >= hi - step * 1e-9 {
                break;
            }
            k += 1;
        }
        Ticks { values, step }
    }

    /// One label per tick, each with the digits the step needs ([`tick_label`]): distinct
    /// values get distinct labels.
    pub fn labels(&self) -> Vec<String> {
        self.values.iter().map(|&v| tick_label(v, self.step)).collect()
    }
}

/// "Nice" tick positions covering `lo..=hi` with about `target` steps ([`Ticks::new`]).
pub fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    Ticks::new(lo, hi, target, 0.0).values
}

/// The SI scale of a label for `v`: from 10^4 on, thousands (k), millions (M), billions (G).
fn si(v: f64) -> (f64, &'static str) {
    match v.abs() {
        a if a >= 1e9 => (1e9, "G"),
        a if a >= 1e6 => (1e6, "M"),
        a if a >= 1e4 => (1e3, "k"),
        _ => (1.0, ""),
    }
}

/// A tick label for `v` on an axis whose ticks are `step` apart: SI suffixes from 10^4 on, and
/// as many decimals as the step has in the label's unit (2.5 × 10^k needs one more than 10^k),
/// trailing zeros dropped. Rounding to those decimals moves a tick by less than half a step, so
/// two ticks never share a label.
pub fn tick_label(v: f64, step: f64) -> String {
    let (scale, suffix) = si(v);
    let (x, step) = (v / scale, step / scale);
    let decimals = if step > 0.0 && step.is_finite() {
        let d = (-step.log10().floor()).max(0.0);
        // In units of the last decimal the step is whole, or 2.5 × 10^k: one digit more.
        let units = step * 10f64.powf(d);
        if (units - units.round()).abs() > 1e-6 * units {
            d + 1.0
        } else {
            d
        }
    } else {
        0.0
    };
    format!("{}{suffix}", trim_zeros(format!("{x:.*}", decimals.min(12.0) as usize)))
}

/// "1.50" → "1.5", "2.00" → "2", "-0" → "0".
fn trim_zeros(s: String) -> String {
    let t = if s.contains('.') { s.trim_end_matches('0').trim_end_matches('.') } else { &s };
    if t == "-0" {
        "0".into()
    } else {
        t.into()
    }
}

/// A label for a value on its own: SI suffixes from 10^4 on, few digits.
pub fn label(v: f64) -> String {
    let (scale, suffix) = si(v);
    let x = v / scale;
    let s = if x == x.round() {
        format!("{x:.0}")
    } else if (x * 10.0 - (x * 10.0).round()).abs() < 1e-9 {
        format!("{x:.1}")
    } else if x.abs() >= 1.0 {
        format!("{x:.2}")
    } else {
        format!("{x:.3}")
    };
    format!("{}{suffix}", s.trim_end_matches(".000"))
}

const W: f64 = 760.0;
const H: f64 = 250.0;
const ML: f64 = 62.0;
const MR: f64 = 14.0;
const MT: f64 = 34.0;
const MB: f64 = 38.0;
/// The plotting area's width and height, inside the margins.
const PW: f64 = W - ML - MR;
const PH: f64 = H - MT - MB;

/// The plot of `series` over the plotted runs of `runs` ([`plotted_runs`]) as one `<svg>`
/// element: x the frame number, y the value. Drawn back to front: the path's segments, the
/// grid, the axes, the runs' lines, the legend.
pub fn plot(series: &Series, runs: &[Run]) -> String {
    let shown: Vec<(usize, &Run)> = plotted_runs(runs).collect();
    let data: Vec<(usize, Vec<(f64, f64)>)> = shown.iter().map(|&(ri, r)| (ri, points(series, r))).collect();
    let last_frame = shown.iter().flat_map(|(_, r)| r.frames.iter().map(|f| f.frame)).max().unwrap_or(0);
    let axes = Axes::new(last_frame, y_range(&data));
    let mut s = String::new();
    open_svg(&mut s, series);
    // Segment bands from the first plotted run's frames.
    if let Some(&(_, r)) = shown.first() {
        segment_bands(&mut s, r, &axes);
    }
    grid_and_ticks(&mut s, &axes);
    axes_and_titles(&mut s, series);
    lines(&mut s, &data, &axes);
    legend(&mut s, &shown);
    s.push_str("</svg>");
    s
}

/// The y range the plot must show: every value, from 0 unless the values are far from it
/// (PSNR); 0..1 when there is none.
fn y_range(data: &[(usize, Vec<(f64, f64)>)]) -> (f64, f64) {
    let (mut ymin, mut ymax) = (f64::INFINITY, f64::NEG_INFINITY);
    for &(_, y) in data.iter().flat_map(|(_, pts)| pts) {
        ymin = ymin.min(y);
        ymax = ymax.max(y);
    }
    if !ymin.is_finite() {
        (ymin, ymax) = (0.0, 1.0);
    }
    // Start at 0 unless the values are far from it (PSNR).
    if ymin >= 0.0 && ymin < 0.5 * ymax {
        ymin = 0.0;
    }
    (ymin, ymax)
}

/// A plot's two axes: their ticks, and the ranges (first to last tick) that span the
/// plotting area.
struct Axes {
    x: Ticks,
    y: Ticks,
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
}

impl Axes {
    /// Frames 0..=`last_frame` across (whole frames only), `y` up.
    fn new(last_frame: u32, (ymin, ymax): (f64, f64)) -> Axes {
        let y = Ticks::new(ymin, ymax, 5, 0.0);
        let (y0, y1) = (y.values[0], *y.values.last().unwrap_or(&1.0));
        let x = Ticks::new(0.0, f64::from(last_frame.max(1)), 8, 1.0);
        let (x0, x1) = (x.values[0], *x.values.last().unwrap_or(&1.0));
        Axes { x, y, x0, x1, y0, y1 }
    }

    /// The SVG x of frame `x`.
    fn sx(&self, x: f64) -> f64 {
        ML + (x - self.x0) / (self.x1 - self.x0).max(1e-300) * PW
    }

    /// The SVG y of value `y` (SVG's y grows downwards).
    fn sy(&self, y: f64) -> f64 {
        MT + PH - (y - self.y0) / (self.y1 - self.y0).max(1e-300) * PH
    }
}

/// The `<svg>` element's opening (its title and series key for readers and tests) and the
/// white background.
fn open_svg(s: &mut String, series: &Series) {
    let _ = write!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"plot\" viewBox=\"0 0 {W} {H}\" role=\"img\" \
         aria-label=\"{t}\" data-series=\"{k}\"><title>{t}</title>",
        t = escape(series.title),
        k = series.key
    );
    let _ = write!(s, "<rect x=\"0\" y=\"0\" width=\"{W}\" height=\"{H}\" fill=\"#fff\"/>");
}

/// The camera path's segments ("walk", "fly") of run `r` as alternately shaded, labelled
/// bands; none when the whole run is one segment or the frames name none.
fn segment_bands(s: &mut String, r: &Run, axes: &Axes) {
    let mut start = 0;
    let mut band = 0;
    for i in 1..=r.frames.len() {
        if i == r.frames.len() || r.frames[i].segment != r.frames[start].segment {
            let seg = &r.frames[start].segment;
            if !(seg.is_empty() || start == 0 && i == r.frames.len()) {
                let (a, b) =
                    (axes.sx(f64::from(r.frames[start].frame)), axes.sx(f64::from(r.frames[i - 1].frame)));
                let fill = if band % 2 == 0 { "#f3f6fa" } else { "#fbf7f0" };
                let _ = write!(
                    s,
                    "<rect x=\"{a:.1}\" y=\"{MT}\" width=\"{:.1}\" height=\"{PH}\" fill=\"{fill}\"/>\
                     <text x=\"{:.1}\" y=\"{:.1}\" class=\"seg\">{}</text>",
                    (b - a).max(0.5),
                    a + 4.0,
                    MT + 12.0,
                    escape(seg)
                );
                band += 1;
            }
            start = i;
        }
    }
}

/// Horizontal grid lines with the y ticks' labels, and the x ticks with theirs.
fn grid_and_ticks(s: &mut String, axes: &Axes) {
    for (&t, text) in axes.y.values.iter().zip(axes.y.labels()) {
        let y = axes.sy(t);
        let _ = write!(
            s,
            "<line x1=\"{ML}\" x2=\"{:.1}\" y1=\"{y:.1}\" y2=\"{y:.1}\" class=\"grid\"/>\
             <text x=\"{:.1}\" y=\"{:.1}\" class=\"tick\" text-anchor=\"end\">{text}</text>",
            ML + PW,
            ML - 6.0,
            y + 4.0,
        );
    }
    for (&t, text) in axes.x.values.iter().zip(axes.x.labels()) {
        let x = axes.sx(t);
        let _ = write!(
            s,
            "<line x1=\"{x:.1}\" x2=\"{x:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" class=\"axis\"/>\
             <text x=\"{x:.1}\" y=\"{:.1}\" class=\"tick\" text-anchor=\"middle\">{text}</text>",
            MT + PH,
            MT + PH + 5.0,
            MT + PH + 18.0,
        );
    }
}

/// The two axis lines, their labels (frame; the series' unit) and the plot's title.
fn axes_and_titles(s: &mut String, series: &Series) {
    let _ = write!(
        s,
        "<line x1=\"{ML}\" x2=\"{ML}\" y1=\"{MT}\" y2=\"{:.1}\" class=\"axis\"/>\
         <line x1=\"{ML}\" x2=\"{:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" class=\"axis\"/>",
        MT + PH,
        ML + PW,
        MT + PH,
        MT + PH
    );
    let _ = write!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" class=\"axislabel\" text-anchor=\"middle\">frame</text>\
         <text x=\"14\" y=\"{:.1}\" class=\"axislabel\" text-anchor=\"middle\" \
         transform=\"rotate(-90 14 {:.1})\">{}</text>",
        ML + PW / 2.0,
        H - 6.0,
        MT + PH / 2.0,
        MT + PH / 2.0,
        escape(series.unit)
    );
    let _ = write!(s, "<text x=\"{ML}\" y=\"20\" class=\"ptitle\">{}</text>", escape(series.title));
}

/// Each run's points in its colour: a polyline through them ([`decimate`]d to the plot's
/// width), or a dot for a single point.
fn lines(s: &mut String, data: &[(usize, Vec<(f64, f64)>)], axes: &Axes) {
    for (ri, pts) in data {
        if pts.is_empty() {
            continue;
        }
        let colour = PALETTE[ri % PALETTE.len()];
        let pts = decimate(pts, PW as usize);
        let mut d = String::with_capacity(pts.len() * 14);
        for (i, &(x, y)) in pts.iter().enumerate() {
            let _ = write!(d, "{}{:.1},{:.1}", if i == 0 { "" } else { " " }, axes.sx(x), axes.sy(y));
        }
        if pts.len() == 1 {
            let _ = write!(
                s,
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"2.5\" fill=\"{colour}\"/>",
                axes.sx(pts[0].0),
                axes.sy(pts[0].1)
            );
        } else {
            let _ = write!(s, "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.4\" stroke-linejoin=\"round\" points=\"{d}\"/>");
        }
    }
}

/// The legend, right-aligned in the title row: the plotted runs, each in its summary colour.
fn legend(s: &mut String, shown: &[(usize, &Run)]) {
    let mut x = W - MR;
    for &(ri, r) in shown.iter().rev() {
        let name = escape(&r.name);
        let w = 7.0 * r.name.chars().count() as f64 + 22.0;
        x -= w;
        let _ = write!(
            s,
            "<rect x=\"{x:.1}\" y=\"11\" width=\"12\" height=\"4\" rx=\"1\" fill=\"{}\"/>\
             <text x=\"{:.1}\" y=\"17\" class=\"legend\">{name}</text>",
            PALETTE[ri % PALETTE.len()],
            x + 16.0
        );
    }
}

/// At most about `2 × columns` points: the first, minimum, maximum and last of each bucket.
fn decimate(pts: &[(f64, f64)], columns: usize) -> Vec<(f64, f64)> {
    if pts.len() <= 2 * columns.max(1) {
        return pts.to_vec();
    }
    let per = pts.len().div_ceil(columns.max(1));
    let mut out = Vec::with_capacity(4 * columns);
    for chunk in pts.chunks(per) {
        let (mut lo, mut hi) = (chunk[0], chunk[0]);
        for &p in chunk {
            if p.1 < lo.1 {
                lo = p;
            }
            if p.1 > hi.1 {
                hi = p;
            }
        }
        let (a, b) = if lo.0 <= hi.0 { (lo, hi) } else { (hi, lo) };
        for p in [chunk[0], a, b, chunk[chunk.len() - 1]] {
            if out.last() != Some(&p) {
                out.push(p);
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_nice_and_cover_the_range() {
        assert_eq!(ticks(0.0, 10.0, 5), vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        let t = ticks(0.0, 37.0, 5);
        assert_eq!(t.first(), Some(&0.0));
        assert!(*t.last().unwrap() >= 37.0 && t.len() <= 8, "{t:?}");
        let t = ticks(5.0, 5.0, 5);
        assert!(t.first().unwrap() <= &5.0 && t.last().unwrap() >= &5.0);
    }

    /// The y tick labels of a plot, top to bottom order as written.
    fn y_labels(svg: &str) -> Vec<String> {
        svg.split("class=\"tick\" text-anchor=\"end\">")
            .skip(1)
            .map(|t| t.split('<').next().unwrap_or("").to_string())
            .collect()
    }

    /// The x coordinates of a plot's polylines, one list per line.
    fn line_xs(svg: &str) -> Vec<Vec<f64>> {
        svg.split("points=\"")
            .skip(1)
            .map(|p| {
                let pts = p.split('"').next().unwrap_or("");
                pts.split(' ').map(|xy| xy.split(',').next().unwrap().parse().unwrap()).collect()
            })
            .collect()
    }

    fn run(name: &str, frames: impl IntoIterator<Item = (u32, f64)>) -> Run {
        let frames =
            frames.into_iter().map(|(frame, frame_ms)| FrameRecord { frame, frame_ms, ..Default::default() });
        Run::new(name, "", frames.collect(), None)
    }

    fn frame_time() -> &'static Series {
        SERIES.iter().find(|s| s.key == "frame_ms").unwrap()
    }

    #[test]
    fn flat_and_nearly_flat_series_get_distinct_tick_labels() {
        // Flat (one value), nearly flat (a change in the fourth digit, which labels of two
        // decimals or a "k" of two decimals showed as "1.00 1.00 1.00"), at several magnitudes.
        let cases: &[(f64, f64)] = &[
            (1.0, 1.0),
            (16.7, 16.7),
            (0.003, 0.003),
            (1.0, 1.002),
            (50.0, 50.04),
            (25_000.0, 25_010.0),
            (3_500_000.0, 3_500_004.0),
            (1.0, 1.0 + 1e-12),
            (-2.0, -2.0),
        ];
        for &(a, b) in cases {
            let r = run("hzb", (0..20).map(|i| (i, if i % 2 == 0 { a } else { b })));
            let labels = y_labels(&plot(frame_time(), &[r]));
            let mut distinct = labels.clone();
            distinct.sort();
            distinct.dedup();
            assert!(labels.len() >= 3, "{a}..{b}: {labels:?}");
            assert_eq!(distinct.len(), labels.len(), "{a}..{b}: {labels:?}");
            // The ticks still cover the values.
            let t = Ticks::new(a.min(b), a.max(b), 5, 0.0);
            assert!(t.values[0] <= a.min(b) && *t.values.last().unwrap() >= a.max(b), "{a}..{b}: {t:?}");
            // A positive value keeps a positive axis (a flat 0.003 is not drawn on -0.6..0.6).
            if a > 0.0 {
                assert!(t.values[0] >= 0.0, "{a}..{b}: {t:?}");
            }
        }
    }

    #[test]
    fn tick_labels_have_the_digits_of_the_step() {
        assert_eq!(tick_label(0.6000000000000001, 0.2), "0.6");
        assert_eq!(tick_label(1.0005, 0.0005), "1.0005");
        assert_eq!(tick_label(2.5, 2.5), "2.5");
        assert_eq!(tick_label(0.25, 0.25), "0.25");
        assert_eq!(tick_label(7500.0, 2500.0), "7500");
        assert_eq!(tick_label(12_500.0, 2500.0), "12.5k");
        assert_eq!(tick_label(25_002.0, 2.0), "25.002k");
        assert_eq!(tick_label(-0.0, 1.0), "0");
        assert_eq!(tick_label(40.0, 10.0), "40");
    }

    #[test]
    fn frame_axis_ticks_are_whole_frames() {
        assert_eq!(Ticks::new(0.0, 1.0, 8, 1.0).values, vec![0.0, 1.0]);
        let t = Ticks::new(0.0, 3.0, 8, 1.0);
        assert!(t.values.iter().all(|v| v.fract() == 0.0), "{t:?}");
    }

    #[test]
    fn points_are_at_frame_numbers() {
        // The compared frames of --compare 10: a run that holds only frames 0, 10, 20, 30.
        let sparse = run("reference-like", [0, 10, 20, 30].map(|i| (i, 5.0)));
        assert_eq!(
            points(frame_time(), &sparse).iter().map(|p| p.0).collect::<Vec<_>>(),
            vec![0.0, 10.0, 20.0, 30.0]
        );
        // Plotted beside a run of every frame, both span the same x range.
        let full = run("hzb", (0..=30).map(|i| (i, 4.0)));
        let xs = line_xs(&plot(frame_time(), &[full, sparse]));
        assert_eq!(xs.len(), 2);
        assert_eq!(xs[0].first(), xs[1].first());
        assert_eq!(xs[0].last(), xs[1].last());
    }

    #[test]
    fn psnr_points_carry_frame_numbers() {
        let psnr = SERIES.iter().find(|s| s.key == "psnr_db").unwrap();
        let frames = (0..25)
            .map(|i| FrameRecord {
                frame: i,
                psnr_db: (i % 8 == 0).then_some(40.0 + i as f64),
                ..Default::default()
            })
            .collect();
        let r = Run::new("hzb", "", frames, None);
        assert_eq!(points(psnr, &r), vec![(0.0, 40.0), (8.0, 48.0), (16.0, 56.0), (24.0, 64.0)]);
    }

    #[test]
    fn reference_renderings_are_left_out_of_the_plots() {
        let walk = run("hzb", (0..10).map(|i| (i, 10.0 + i as f64)));
        let reference = run("reference", [0, 5].map(|i| (i, 10_000.0))).with_kind(RunKind::Reference);
        let svg = plot(frame_time(), &[walk, reference.clone()]);
        // The y axis is the walkthrough's (tens of ms), not the reference's 10 s.
        let top: f64 = y_labels(&svg).last().unwrap().parse().unwrap();
        assert!(top < 100.0, "{svg}");
        assert_eq!(line_xs(&svg).len(), 1);
        assert!(!svg.contains(">reference</text>"), "no legend entry");
        // A series only the reference has is not plotted at all.
        assert!(plotted(&[reference]).is_empty());
    }

    #[test]
    fn no_time_plot_repeats_another() {
        // A frame as the bench records it: `cull_ms` is the old name of `culling_ms` and equal
        // to it (the "Frustum culling time" plot once showed it, the occlusion time again).
        let f = FrameRecord {
            frame_ms: 1.0,
            select_ms: 2.0,
            cut_ms: 3.0,
            prefetch_ms: 4.0,
            cull_ms: 5.0,
            culling_ms: 5.0,
            upload_ms: 6.0,
            render_ms: 7.0,
            ..Default::default()
        };
        let times: Vec<f64> =
            SERIES.iter().filter(|s| s.unit == "ms").filter_map(|s| (s.value)(&f)).collect();
        let mut distinct = times.clone();
        distinct.sort_by(f64::total_cmp);
        distinct.dedup();
        assert_eq!(distinct.len(), times.len(), "two time plots show the same figure: {times:?}");
        // Frustum culling is timed with the selection, the only series that names it.
        let frustum: Vec<&str> = SERIES
            .iter()
            .filter(|s| s.title.to_lowercase().contains("frustum culling"))
            .map(|s| s.key)
            .collect();
        assert_eq!(frustum, vec!["select_ms"]);
    }

    #[test]
    fn labels_are_short() {
        assert_eq!(label(0.0), "0");
        assert_eq!(label(2.5), "2.5");
        assert_eq!(label(25_000.0), "25k");
        assert_eq!(label(3_500_000.0), "3.5M");
        assert_eq!(label(0.125), "0.125");
    }

    #[test]
    fn decimation_keeps_spikes() {
        let pts: Vec<(f64, f64)> =
            (0..10_000).map(|i| (i as f64, if i == 5000 { 99.0 } else { 1.0 })).collect();
        let d = decimate(&pts, 100);
        assert!(d.len() <= 400);
        assert!(d.iter().any(|p| p.1 == 99.0));
    }

    #[test]
    fn text_is_escaped() {
        assert_eq!(escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
    }
}
