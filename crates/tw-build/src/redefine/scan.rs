//! How the passes over the working file (B, C and D) read and accumulate: the pool maps each
//! chunk's triangles to keys in fixed sub-chunks ([`map_records`]), per-key statistics are
//! accumulated in fixed lanes ([`LaneStats`]) so that floating-point sums add in file order for
//! any number of threads, and only the file spans of the objects concerned are read, joined
//! across small gaps ([`joined_spans`]).

use rayon::prelude::*;

use super::geometry::FBox;
use crate::ingest::{records, WorkTri, RECORD_BYTES};
use crate::workio::SUB_CHUNK;

/// Decodes and maps every triangle of a chunk of raw working-file records in parallel (fixed
/// sub-chunks: the result does not depend on the number of threads).
pub(super) fn map_records(
    first: u64,
    bytes: &[u8],
    out: &mut Vec<u32>,
    f: impl Fn(&WorkTri, u64) -> u32 + Sync,
) {
    out.clear();
    out.resize(bytes.len() / RECORD_BYTES, 0);
    out.par_chunks_mut(SUB_CHUNK).zip(bytes.par_chunks(SUB_CHUNK * RECORD_BYTES)).enumerate().for_each(
        |(k, (o, b))| {
            let base = first + (k * SUB_CHUNK) as u64;
            for (j, (o, t)) in o.iter_mut().zip(records(b)).enumerate() {
                *o = f(&t, base + j as u64);
            }
        },
    );
}

/// Lanes of the per-piece and per-cell statistics
/// ([`for_each_lane`](crate::workio::for_each_lane)): fixed, so that the floating-point sums
/// happen in the same order for any number of threads.
pub(super) const LANES: usize = 4;

/// Per-key statistics of the keys one lane owns (key `k` at `k / LANES`).
pub(super) struct LaneStats {
    pub(super) count: Vec<u64>,
    pub(super) bounds: Vec<FBox>,
    /// Sum of centroids (pieces only; empty for cells).
    pub(super) sum: Vec<[f64; 3]>,
}

impl LaneStats {
    /// The lanes for keys `0..n`, with centroid sums if `sums`.
    pub(super) fn lanes(n: usize, sums: bool) -> Vec<LaneStats> {
        (0..LANES)
            .map(|l| {
                let len = (n + LANES - 1 - l) / LANES;
                LaneStats {
                    count: vec![0; len],
                    bounds: vec![FBox::EMPTY; len],
                    sum: if sums { vec![[0.0; 3]; len] } else { Vec::new() },
                }
            })
            .collect()
    }

    /// Key `k`'s figures back out of the lanes: (count, bounds, sum).
    pub(super) fn get(lanes: &[LaneStats], k: usize) -> (u64, FBox, [f64; 3]) {
        let (l, j) = (&lanes[k % LANES], k / LANES);
        (l.count[j], l.bounds[j], l.sum.get(j).copied().unwrap_or_default())
    }
}

/// Gaps (in triangles) between the file spans of pass B's and C's objects that are read through
/// rather than skipped (160 KB: about one device round trip's worth of transfer). The spans are
/// read by one reader, each on its own ([`crate::ingest::WorkFile::scan_ranges_raw`]). At 10^8
/// triangles pass C reads 2,491 spans, 55 % of the file (joined across 10 MB gaps: 2 spans,
/// 99.6 %): 3.5 → 2.1 s.
pub(super) const SPAN_GAP: u64 = 1 << 12;

/// The working-file ranges to read for `objects` (their spans, sorted, joined across gaps of at
/// most [`SPAN_GAP`] triangles).
pub(super) fn joined_spans(
    objects: &[u32],
    span: impl Fn(u32) -> std::ops::Range<u64>,
) -> Vec<std::ops::Range<u64>> {
    let mut spans: Vec<std::ops::Range<u64>> =
        objects.iter().map(|&o| span(o)).filter(|r| !r.is_empty()).collect();
    spans.sort_unstable_by_key(|r| (r.start, r.end));
    let mut joined: Vec<std::ops::Range<u64>> = Vec::new();
    for r in spans {
        match joined.last_mut() {
            Some(last) if r.start <= last.end + SPAN_GAP => last.end = last.end.max(r.end),
            _ => joined.push(r),
        }
    }
    joined
}
