//! The draws of a partly shadowed cluster whose triangles cross-culling refined
//! (`tw_runtime::shadow::subobjects`): its lit and shadowed triangles drawn by the pipeline
//! without lookups, the others by the lookup pipeline, in the cluster's triangle order.
//!
//! The pipeline without lookups reads a cluster's class from its pool slot (shadow.wgsl
//! `slot_classes`); a part of a cluster carries its own in the draw's first instance (1 + the
//! class code; 0 = the slot's class), so lit and shadowed parts share that pipeline and a batch
//! switches pipelines only between lookups and none. That needs indirect draws with a first
//! instance (`wgpu::Features::INDIRECT_FIRST_INSTANCE`); without it clusters are drawn whole
//! by their class.
//!
//! Order: the triangles are cut into maximal ranges of one kind and the ranges drawn in order,
//! so where depths tie the image is the one drawing the cluster whole would give. A cluster is
//! cut into at most [`MAX_PARTS`] ranges: beyond, the shortest ranges that need no lookup are
//! looked up too (a lookup draws any triangle correctly; each draw and each pipeline switch has
//! a fixed cost on a CPU driver).

use tw_runtime::{full_mask, TriangleClasses, TriangleMask};
use tw_store::PageCluster;

use super::passes::push_runs;
use crate::pool::DrawArgs;

/// At most this many ranges of one kind per refined cluster.
pub const MAX_PARTS: usize = 4;

/// How a range of a cluster's triangles is shaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Part {
    /// Looked up per fragment (the lookup pipeline).
    Lookup,
    /// Drawn without lookups with this class code (shadow.rs `CLASS_*`).
    Classified(u32),
}

/// Appends the draws of `mask`'s triangles of a resident cluster drawn whole by `args`, each
/// range of `classes` with its pipeline, and marks in `runs` (first draw, whether it looks up)
/// where the pipeline changes. Returns the triangles drawn and those in the mask, as
/// [`push_runs`] does.
pub(crate) fn push_classified(
    draws: &mut Vec<DrawArgs>,
    runs: &mut Vec<(usize, bool)>,
    args: DrawArgs,
    cluster: &PageCluster,
    mask: TriangleMask,
    classes: TriangleClasses,
    codes: (u32, u32),
) -> (u64, u64) {
    let triangles = (args.index_count / 3) as usize;
    let (mut drawn, mut masked) = (0, 0);
    for (start, end, part) in parts(triangles, classes, codes) {
        let range = full_mask(end) & !full_mask(start);
        let lookups = part == Part::Lookup;
        let first_instance = match part {
            Part::Lookup => 0,
            Part::Classified(code) => 1 + code,
        };
        let before = draws.len();
        let (d, m) = push_runs(draws, DrawArgs { first_instance, ..args }, cluster, mask & range);
        drawn += d;
        masked += m;
        if draws.len() > before && runs.last().is_none_or(|r| r.1 != lookups) {
            runs.push((before, lookups));
        }
    }
    (drawn, masked)
}

/// The maximal ranges `[start, end)` of one part of a cluster of `triangles`, in order, at most
/// [`MAX_PARTS`] of them; `codes` are the lit and shadowed class codes.
fn parts(
    triangles: usize,
    classes: TriangleClasses,
    (lit, shadowed): (u32, u32),
) -> Vec<(usize, usize, Part)> {
    let part_of = |t: usize| {
        let bit = 1u128 << t;
        if classes.lit & bit != 0 {
            Part::Classified(lit)
        } else if classes.shadowed & bit != 0 {
            Part::Classified(shadowed)
        } else {
            Part::Lookup
        }
    };
    let mut ranges: Vec<(usize, usize, Part)> = Vec::new();
    for t in 0..triangles.min(128) {
        let part = part_of(t);
        match ranges.last_mut() {
            Some(last) if last.2 == part => last.1 = t + 1,
            _ => ranges.push((t, t + 1, part)),
        }
    }
    while ranges.len() > MAX_PARTS {
        let shortest = (0..ranges.len())
            .filter(|&i| ranges[i].2 != Part::Lookup)
            .min_by_key(|&i| ranges[i].1 - ranges[i].0)
            .expect("more ranges than MAX_PARTS alternate, so some need no lookup");
        ranges[shortest].2 = Part::Lookup;
        ranges = coalesce(ranges);
    }
    ranges
}

/// Joins neighbouring ranges of the same part.
fn coalesce(ranges: Vec<(usize, usize, Part)>) -> Vec<(usize, usize, Part)> {
    let mut out: Vec<(usize, usize, Part)> = Vec::with_capacity(ranges.len());
    for r in ranges {
        match out.last_mut() {
            Some(last) if last.2 == r.2 => last.1 = r.1,
            _ => out.push(r),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const CODES: (u32, u32) = (1, 2);

    fn cluster(triangles: usize) -> PageCluster {
        PageCluster {
            positions: vec![[0, 0, 0]; 3],
            indices: (0..triangles).flat_map(|_| [0u8, 1, 2]).collect(),
            objects: vec![0; triangles],
            self_error: 0.0,
            self_sphere: [0.0; 4],
            group: 0,
            level: 0,
        }
    }

    fn args(triangles: u32) -> DrawArgs {
        DrawArgs {
            index_count: 3 * triangles,
            instance_count: 1,
            first_index: 300,
            base_vertex: 40,
            first_instance: 0,
        }
    }

    #[test]
    fn ranges_follow_the_classes_in_order() {
        let classes = TriangleClasses { lit: 0xff, shadowed: 0xff << 16 };
        let got = parts(32, classes, CODES);
        assert_eq!(
            got,
            vec![
                (0, 8, Part::Classified(1)),
                (8, 16, Part::Lookup),
                (16, 24, Part::Classified(2)),
                (24, 32, Part::Lookup)
            ]
        );
    }

    #[test]
    fn too_many_ranges_look_the_shortest_up() {
        // lit 0..8, lookup 8..16, shadowed 16..20, lookup 20..24, lit 24..40, lookup 40..48.
        let classes = TriangleClasses { lit: 0xff | (0xffff << 24), shadowed: 0xf << 16 };
        let got = parts(48, classes, CODES);
        assert_eq!(got.len(), MAX_PARTS);
        assert_eq!(
            got,
            vec![
                (0, 8, Part::Classified(1)),
                (8, 24, Part::Lookup),
                (24, 40, Part::Classified(1)),
                (40, 48, Part::Lookup)
            ]
        );
    }

    #[test]
    fn draws_carry_the_class_and_runs_mark_the_pipeline_changes() {
        let c = cluster(24);
        let classes = TriangleClasses { lit: 0xff, shadowed: 0 };
        let (mut draws, mut runs) = (Vec::new(), vec![(0, true)]);
        let (drawn, masked) =
            push_classified(&mut draws, &mut runs, args(24), &c, full_mask(24), classes, CODES);
        assert_eq!((drawn, masked), (24, 24));
        assert_eq!(draws.len(), 2);
        assert_eq!((draws[0].first_index, draws[0].index_count, draws[0].first_instance), (300, 24, 2));
        assert_eq!((draws[1].first_index, draws[1].index_count, draws[1].first_instance), (324, 48, 0));
        assert_eq!(runs, vec![(0, true), (0, false), (1, true)]);
    }

    #[test]
    fn hidden_triangles_are_not_drawn_and_gaps_stay_inside_a_range() {
        let c = cluster(16);
        let classes = TriangleClasses { lit: 0xff, shadowed: 0 };
        // Visible: triangles 0 and 7 (lit range), 8 (lookup range).
        let mask = 0b1_1000_0001;
        let (mut draws, mut runs) = (Vec::new(), Vec::new());
        let (drawn, masked) = push_classified(&mut draws, &mut runs, args(16), &c, mask, classes, CODES);
        assert_eq!(masked, 3);
        assert_eq!(drawn, 3);
        assert!(draws.iter().all(|d| (d.first_instance == 2) == (d.first_index < 300 + 24)));
    }
}
