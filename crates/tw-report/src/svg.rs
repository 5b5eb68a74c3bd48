//! Line plots as inline SVG, written by hand (no scripts, no fonts to fetch): one plot per
//! per-frame series, every run overlaid in its own colour with a legend, axes with "nice" ticks
//! (1, 2, 5 × 10^k) and units, light grid lines, and the camera path's segments ("walk",
//! "fly") as shaded bands. Long runs are decimated to a min/max envelope per pixel column, so
//! spikes stay visible and the file stays small.

use std::fmt::Write;

use crate::{FrameRecord, Run};

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
    series!(select_ms, "LOD selection time", "ms"),
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
    series!(psnr_db?, "PSNR against the reference", "dB"),
    series!(differing_pixels?, "Differing pixels", "share"),
    series!(exact_visible_triangles?, "Exactly visible triangles", "triangles"),
    series!(exact_visible_objects?, "Exactly visible objects", "objects"),
    series!(culling_efficiency?, "Culling efficiency (drawn ÷ visible)", "ratio"),
];

/// Colours of runs (Tableau 10), in order.
pub const PALETTE: [&str; 10] = [
    "#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f", "#edc948", "#b07aa1", "#ff9da7", "#9c755f",
    "#bab0ac",
];

/// The series worth a plot: some run has a non-zero value.
pub fn plotted(runs: &[Run]) -> Vec<&'static Series> {
    SERIES
        .iter()
        .filter(|s| runs.iter().any(|r| r.frames.iter().any(|f| (s.value)(f).is_some_and(|v| v != 0.0))))
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

/// "Nice" tick positions covering `lo..=hi` with about `target` steps.
pub fn ticks(lo: f64, hi: f64, target: usize) -> Vec<f64> {
    let (lo, hi) =
        if hi > lo { (lo, hi) } else { (lo - 0.5 * lo.abs().max(1.0), hi + 0.5 * hi.abs().max(1.0)) };
    let raw = (hi - lo) / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0].iter().map(|m| m * mag).find(|s| *s >= raw).unwrap_or(10.0 * mag);
    let first = (lo / step).floor() * step;
    let mut out = Vec::new();
    let mut k = 0;
    while out.len() < 64 {
        let t = first + k as f64 * step;
        out.push(if t.abs() < step * 1e-9 { 0.0 } else { t });
        if t >= hi - step * 1e-9 {
            break;
        }
        k += 1;
    }
    out
}

/// A tick label: SI suffixes from 10^4 on, few digits.
pub fn label(v: f64) -> String {
    let a = v.abs();
    let (x, suffix) = if a >= 1e9 {
        (v / 1e9, "G")
    } else if a >= 1e6 {
        (v / 1e6, "M")
    } else if a >= 1e4 {
        (v / 1e3, "k")
    } else {
        (v, "")
    };
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

/// The plot of `series` over `runs` as one `<svg>` element.
pub fn plot(series: &Series, runs: &[Run]) -> String {
    let data: Vec<Vec<(f64, f64)>> = runs
        .iter()
        .map(|r| {
            r.frames
                .iter()
                .enumerate()
                .filter_map(|(i, f)| (series.value)(f).filter(|v| v.is_finite()).map(|v| (i as f64, v)))
                .collect()
        })
        .collect();
    let n = runs.iter().map(|r| r.frames.len()).max().unwrap_or(0).max(2);
    let (mut ymin, mut ymax) = (f64::INFINITY, f64::NEG_INFINITY);
    for &(_, y) in data.iter().flatten() {
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
    let yt = ticks(ymin, ymax, 5);
    let (y0, y1) = (yt[0], *yt.last().unwrap_or(&1.0));
    let xt = ticks(0.0, (n - 1) as f64, 8);
    let x1 = *xt.last().unwrap_or(&1.0);
    let (pw, ph) = (W - ML - MR, H - MT - MB);
    let sx = |x: f64| ML + x / x1.max(1e-300) * pw;
    let sy = |y: f64| MT + ph - (y - y0) / (y1 - y0).max(1e-300) * ph;
    let mut s = String::new();
    let _ = write!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"plot\" viewBox=\"0 0 {W} {H}\" role=\"img\" \
         aria-label=\"{t}\" data-series=\"{k}\"><title>{t}</title>",
        t = escape(series.title),
        k = series.key
    );
    let _ = write!(s, "<rect x=\"0\" y=\"0\" width=\"{W}\" height=\"{H}\" fill=\"#fff\"/>");
    // Segment bands from the first run's frames.
    if let Some(r) = runs.first() {
        let mut start = 0;
        let mut band = 0;
        for i in 1..=r.frames.len() {
            if i == r.frames.len() || r.frames[i].segment != r.frames[start].segment {
                let seg = &r.frames[start].segment;
                if !(seg.is_empty() || start == 0 && i == r.frames.len()) {
                    let (a, b) = (sx(start as f64), sx((i - 1) as f64));
                    let fill = if band % 2 == 0 { "#f3f6fa" } else { "#fbf7f0" };
                    let _ = write!(
                        s,
                        "<rect x=\"{a:.1}\" y=\"{MT}\" width=\"{:.1}\" height=\"{ph}\" fill=\"{fill}\"/>\
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
    // Grid and ticks.
    for &t in &yt {
        let y = sy(t);
        let _ = write!(
            s,
            "<line x1=\"{ML}\" x2=\"{:.1}\" y1=\"{y:.1}\" y2=\"{y:.1}\" class=\"grid\"/>\
             <text x=\"{:.1}\" y=\"{:.1}\" class=\"tick\" text-anchor=\"end\">{}</text>",
            ML + pw,
            ML - 6.0,
            y + 4.0,
            label(t)
        );
    }
    for &t in &xt {
        let x = sx(t);
        let _ = write!(
            s,
            "<line x1=\"{x:.1}\" x2=\"{x:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" class=\"axis\"/>\
             <text x=\"{x:.1}\" y=\"{:.1}\" class=\"tick\" text-anchor=\"middle\">{}</text>",
            MT + ph,
            MT + ph + 5.0,
            MT + ph + 18.0,
            label(t)
        );
    }
    let _ = write!(
        s,
        "<line x1=\"{ML}\" x2=\"{ML}\" y1=\"{MT}\" y2=\"{:.1}\" class=\"axis\"/>\
         <line x1=\"{ML}\" x2=\"{:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" class=\"axis\"/>",
        MT + ph,
        ML + pw,
        MT + ph,
        MT + ph
    );
    let _ = write!(
        s,
        "<text x=\"{:.1}\" y=\"{:.1}\" class=\"axislabel\" text-anchor=\"middle\">frame</text>\
         <text x=\"14\" y=\"{:.1}\" class=\"axislabel\" text-anchor=\"middle\" \
         transform=\"rotate(-90 14 {:.1})\">{}</text>",
        ML + pw / 2.0,
        H - 6.0,
        MT + ph / 2.0,
        MT + ph / 2.0,
        escape(series.unit)
    );
    let _ = write!(s, "<text x=\"{ML}\" y=\"20\" class=\"ptitle\">{}</text>", escape(series.title));
    // Lines.
    for (ri, pts) in data.iter().enumerate() {
        if pts.is_empty() {
            continue;
        }
        let colour = PALETTE[ri % PALETTE.len()];
        let pts = decimate(pts, pw as usize);
        let mut d = String::with_capacity(pts.len() * 14);
        for (i, &(x, y)) in pts.iter().enumerate() {
            let _ = write!(d, "{}{:.1},{:.1}", if i == 0 { "" } else { " " }, sx(x), sy(y));
        }
        if pts.len() == 1 {
            let _ = write!(
                s,
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"2.5\" fill=\"{colour}\"/>",
                sx(pts[0].0),
                sy(pts[0].1)
            );
        } else {
            let _ = write!(s, "<polyline fill=\"none\" stroke=\"{colour}\" stroke-width=\"1.4\" stroke-linejoin=\"round\" points=\"{d}\"/>");
        }
    }
    // Legend, right-aligned in the title row.
    let mut x = W - MR;
    for (ri, r) in runs.iter().enumerate().rev() {
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
    s.push_str("</svg>");
    s
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
