//! Pass C: the exact count and box of every cell partition-II planned.

use super::assign::{walk, Assigner, Route};
use super::geometry::FBox;
use super::pieces::Pieces;
use super::scan::{joined_spans, map_records, LaneStats, LANES};
use super::CellInfo;
use crate::error::BuildError;
use crate::ingest::{Ingested, WorkTri, RECORD_BYTES};
use crate::types::GridBox;
use crate::workio::for_each_lane;

/// Pass C: the count and box of every cell. A piece placed whole in a cell (`Route::Fixed`)
/// adds its pass-B count and box; only the triangles of pieces that a partition-II plan cuts
/// are read again, from the file spans of their objects ([`crate::types::ObjectRecord::span`]), decoded and
/// accumulated in lanes as in pass B. Counts are sums and boxes minima and maxima, so the result
/// does not depend on the order (a −0 and a +0 bound quantize to the same grid point).
pub(super) fn cell_stats(
    ing: &Ingested,
    assign: &Assigner,
    pieces: &Pieces,
    piece_object: &[u32],
    n: u32,
) -> Result<Vec<CellInfo>, BuildError> {
    let n = n as usize;
    let mut count = vec![0u64; n];
    let mut bounds = vec![FBox::EMPTY; n];
    let mut bad = None;
    let mut cut_objects = Vec::new();
    for (q, &tris) in pieces.count.iter().enumerate() {
        if tris == 0 {
            continue;
        }
        match assign.piece_cell[q] {
            Route::Fixed(c) => match count.get_mut(c as usize) {
                Some(cnt) => {
                    *cnt += tris;
                    bounds[c as usize].union(&pieces.bounds[q]);
                }
                None => bad = Some(ing.objects[piece_object[q] as usize].span.start),
            },
            Route::Plan(_) => cut_objects.push(piece_object[q]),
        }
    }
    cut_objects.dedup();
    let joined = joined_spans(&cut_objects, |o| ing.objects[o as usize].span.clone());
    let read: u64 = joined.iter().map(|r| r.end - r.start).sum();
    tracing::debug!(spans = joined.len(), triangles = read, of = ing.work.triangles, "pass C reads");
    // Triangles of whole pieces in the spans are skipped (`u32::MAX`); a plan that gives no
    // cell is a bug, reported (`n`) rather than left to panic.
    let mut lanes = LaneStats::lanes(n, false);
    let mut ids = Vec::new();
    ing.work.scan_ranges_raw(&joined, |first, bytes| {
        map_records(first, bytes, &mut ids, |t, i| match assign.piece_cell[assign.piece(t, i) as usize] {
            Route::Fixed(_) => u32::MAX,
            Route::Plan(root) => {
                let c = walk(&assign.plan2, root, t.centroid());
                if (c as usize) < n {
                    c
                } else {
                    n as u32
                }
            }
        });
        if let Some(k) = ids.iter().rposition(|&c| c != u32::MAX && c as usize >= n) {
            bad = Some(first + k as u64);
        }
        for_each_lane(&mut lanes, &ids, |lane, k, c| {
            let j = c as usize / LANES;
            let Some(cnt) = lane.count.get_mut(j) else { return };
            *cnt += 1;
            let t = WorkTri::decode(&bytes[k * RECORD_BYTES..(k + 1) * RECORD_BYTES]);
            for v in t.p {
                lane.bounds[j].grow(v);
            }
        });
        Ok(())
    })?;
    for c in 0..n {
        let (cnt, b, _) = LaneStats::get(&lanes, c);
        if cnt > 0 {
            count[c] += cnt;
            bounds[c].union(&b);
        }
    }
    if let Some(t) = bad {
        // Only reachable through a bug in the plans; say so rather than panic later.
        return Err(BuildError::Corrupt {
            path: ing.work.path().to_path_buf(),
            message: format!("triangle {t} was assigned no cell"),
        });
    }
    Ok(count
        .iter()
        .zip(&bounds)
        .map(|(&triangles, b)| CellInfo {
            triangles,
            bounds: if triangles > 0 { b.to_grid(&ing.work, &ing.grid) } else { GridBox::EMPTY },
        })
        .collect())
}
