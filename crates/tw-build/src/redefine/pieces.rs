//! Pass B: the exact count, box and centre of mass of every piece partition-I planned.

use super::assign::{Assigner, ObjectRoute};
use super::geometry::FBox;
use super::scan::{joined_spans, map_records, LaneStats, LANES};
use crate::error::BuildError;
use crate::ingest::{Ingested, WorkTri, RECORD_BYTES};
use crate::types::GridBox;
use crate::workio::for_each_lane;

/// Every piece's exact triangle count, box (working-file offsets and grid) and centre of mass.
pub(super) struct Pieces {
    pub(super) count: Vec<u64>,
    pub(super) bounds: Vec<FBox>,
    pub(super) grid: Vec<GridBox>,
    /// Centre of mass (mean centroid).
    pub(super) centre: Vec<[f32; 3]>,
}

/// Pass B. A piece that is a whole object takes its ingest figures; only the file spans of the
/// objects partition-I cuts ([`crate::types::ObjectRecord::span`]) are read. Parallel: the pool decodes each chunk
/// and finds the pieces ([`map_records`]), then accumulates them in [`LANES`] lanes by piece,
/// so that each piece's centroid sum adds its triangles in file order, as a serial loop would.
pub(super) fn piece_stats(ing: &Ingested, assign: &Assigner, n: usize) -> Result<Pieces, BuildError> {
    let mut lanes = LaneStats::lanes(n, true);
    // A whole object is one piece, and ingest summed exactly what a scan of its triangles
    // would (count, box, centroids in file order): only the objects partition-I cut are read.
    let cut: Vec<u32> = (0..ing.objects.len() as u32)
        .filter(|&o| !matches!(assign.object_piece[o as usize], ObjectRoute::Fixed(_)))
        .collect();
    let joined = joined_spans(&cut, |o| ing.objects[o as usize].span.clone());
    let read: u64 = joined.iter().map(|r| r.end - r.start).sum();
    tracing::debug!(spans = joined.len(), triangles = read, of = ing.work.triangles, "pass B reads");
    let mut ids = Vec::new();
    ing.work.scan_ranges_raw(&joined, |first, bytes| {
        map_records(first, bytes, &mut ids, |t, i| match assign.object_piece[t.object as usize] {
            ObjectRoute::Fixed(_) => u32::MAX,
            ObjectRoute::Plan(_) | ObjectRoute::Parts(_) => assign.piece(t, i),
        });
        for_each_lane(&mut lanes, &ids, |lane, k, p| {
            let t = WorkTri::decode(&bytes[k * RECORD_BYTES..(k + 1) * RECORD_BYTES]);
            let j = p as usize / LANES;
            lane.count[j] += 1;
            let b = &mut lane.bounds[j];
            for v in t.p {
                b.grow(v);
            }
            let c = t.centroid();
            let sum = &mut lane.sum[j];
            for i in 0..3 {
                sum[i] += c[i] as f64;
            }
        });
        Ok(())
    })?;
    for (o, route) in assign.object_piece.iter().enumerate() {
        if let (ObjectRoute::Fixed(p), Some(rec)) = (route, ing.objects.get(o)) {
            let (l, j) = (&mut lanes[*p as usize % LANES], *p as usize / LANES);
            l.count[j] = rec.triangles;
            l.bounds[j] = FBox { min: rec.offset_min, max: rec.offset_max };
            l.sum[j] = rec.centroid_sum;
        }
    }
    let (mut count, mut bounds, mut sum) =
        (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    for p in 0..n {
        let (c, b, s) = LaneStats::get(&lanes, p);
        count.push(c);
        bounds.push(b);
        sum.push(s);
    }
    drop(lanes);
    let grid = bounds
        .iter()
        .zip(&count)
        .map(|(b, &c)| if c > 0 { b.to_grid(&ing.work, &ing.grid) } else { GridBox::EMPTY })
        .collect();
    let centre = sum
        .iter()
        .zip(&count)
        .map(|(s, &c)| {
            let c = c.max(1) as f64;
            [(s[0] / c) as f32, (s[1] / c) as f32, (s[2] / c) as f32]
        })
        .collect();
    Ok(Pieces { count, bounds, grid, centre })
}
