//! The shape of a connected part, as the LOD charges its removal (docs/BUILD.md, phase 6):
//! how far its points lie from a set with no area — its centre (the radius) or, when nearer,
//! its principal axis — and whether it is a *rod*, far longer than it is thick. One
//! definition for the cells' DAG (`crate::clusterlod`, rules 2 and 4), HLOD
//! (`crate::hlod`, `prune_components`) and the cut checks (`crate::cut::ThinPieces`).

/// How much longer than thick a part must be to count as a rod: its half-length along its
/// axis at least this many times its largest distance from the axis. A rod may be removed
/// where it continues across a border (a cell seam, a group border): what opens there is its
/// own section, and the rest of the rod ends as if it were shorter. A piece of a wide surface
/// (a patch of a shell, a floor) is never one, so a closed surface never opens (measured: the
/// generated plant's pipe and beam pieces are 15–50 times longer than thick; a tenth of a
/// sphere is about as long as it is thick).
pub(crate) const ROD_ELONGATION: f64 = 4.0;

/// How far from an end of a rod, in multiples of its thickness (its largest distance from the
/// axis), a held point may lie: a section cut at 45° to the axis spans twice the thickness
/// along it. On the Stanford dragon, HLOD found long thin components in its simplified surface,
/// held along their length by seams with finer cells: removing them opened the shell.
pub(crate) const END_REACH: f64 = 2.0;

/// What [`part_shapes`] finds of one part (in the units of its points).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct PartShape {
    /// Half the box diagonal: every point lies within it of the box's centre.
    pub radius: f64,
    /// The largest distance of a point from the principal axis.
    pub off_axis: f64,
    /// Half the extent of the points along the principal axis.
    pub half_length: f64,
    /// The largest distance, along the axis, of a *held* point (one the caller marks: on a
    /// seam) from the nearer end of the part (0 when none is held).
    pub held_inside: f64,
}

impl PartShape {
    /// What removing the part costs: it collapses onto its centre or its axis, whichever is
    /// nearer (a triangle's points are convex combinations of its corners, and distances to a
    /// point or a line are convex, so the corners' bound holds for the whole surface).
    pub(crate) fn bound(&self) -> f64 {
        self.radius.min(self.off_axis)
    }

    /// Whether the part is a rod ([`ROD_ELONGATION`]).
    pub(crate) fn is_rod(&self) -> bool {
        self.half_length >= ROD_ELONGATION * self.off_axis
    }

    /// Whether the part is a rod held only at its ends: every held point within
    /// [`END_REACH`] times the rod's thickness of an end. A rod cut across by a seam is held
    /// at its section; a strip of a wide surface that simplification left long and thin is held
    /// along its length (where the rest of the surface goes on) and must stay.
    pub(crate) fn is_rod_held_at_ends(&self) -> bool {
        self.is_rod() && self.held_inside <= END_REACH * self.off_axis
    }
}

/// The shapes of `parts` parts from their points: `points()` yields `(part, point, held)`
/// (`part < parts`; repeats allowed) and is walked three times: for the boxes and moments, for
/// the distances from the axes and the extents along them, and for the held points.
pub(crate) fn part_shapes<I>(parts: usize, points: impl Fn() -> I) -> Vec<PartShape>
where
    I: Iterator<Item = (usize, [f32; 3], bool)>,
{
    let mut boxes = vec![([f32::MAX; 3], [f32::MIN; 3]); parts];
    let mut moments = vec![Moments::default(); parts];
    for (p, q, _) in points() {
        let (lo, hi) = &mut boxes[p];
        *lo = std::array::from_fn(|i| lo[i].min(q[i]));
        *hi = std::array::from_fn(|i| hi[i].max(q[i]));
        moments[p].add(q);
    }
    let axes: Vec<Axis> = moments.iter().map(Moments::axis).collect();
    let mut off_axis = vec![0.0f64; parts];
    let mut along = vec![(f64::MAX, f64::MIN); parts];
    for (p, q, _) in points() {
        let (t, d) = axes[p].coordinates(q);
        off_axis[p] = off_axis[p].max(d);
        along[p] = (along[p].0.min(t), along[p].1.max(t));
    }
    let mut held_inside = vec![0.0f64; parts];
    for (p, q, _) in points().filter(|x| x.2) {
        let t = axes[p].coordinates(q).0;
        held_inside[p] = held_inside[p].max((t - along[p].0).min(along[p].1 - t));
    }
    (0..parts)
        .map(|p| {
            let (lo, hi) = boxes[p];
            let d2: f64 = (0..3).map(|i| (hi[i] as f64 - lo[i] as f64).powi(2)).sum();
            let (t0, t1) = along[p];
            PartShape {
                radius: d2.max(0.0).sqrt() * 0.5,
                off_axis: off_axis[p],
                half_length: if t1 >= t0 { (t1 - t0) * 0.5 } else { 0.0 },
                held_inside: held_inside[p],
            }
        })
        .collect()
}

/// Sums of a point set's coordinates and their products: its centroid and covariance. The
/// coordinates are taken relative to the first point, so that the covariance (a difference of
/// two sums) keeps its digits far from the origin.
#[derive(Clone, Copy, Debug, Default)]
struct Moments {
    n: f64,
    first: [f64; 3],
    sum: [f64; 3],
    products: [[f64; 3]; 3],
}

impl Moments {
    fn add(&mut self, q: [f32; 3]) {
        let q = q.map(f64::from);
        if self.n == 0.0 {
            self.first = q;
        }
        let q: [f64; 3] = std::array::from_fn(|i| q[i] - self.first[i]);
        self.n += 1.0;
        for i in 0..3 {
            self.sum[i] += q[i];
            for j in 0..3 {
                self.products[i][j] += q[i] * q[j];
            }
        }
    }

    /// The line through the centroid along the principal direction (power iteration on the
    /// covariance, started from the coordinate axis of largest variance). Any line gives a
    /// valid bound ([`PartShape::bound`]); this one makes it small for long thin parts.
    fn axis(&self) -> Axis {
        let n = self.n.max(1.0);
        let c = self.sum.map(|s| s / n);
        let cov: [[f64; 3]; 3] =
            std::array::from_fn(|i| std::array::from_fn(|j| self.products[i][j] / n - c[i] * c[j]));
        let widest = (0..3).max_by(|&a, &b| cov[a][a].total_cmp(&cov[b][b])).unwrap_or(0);
        let mut d = [0.0f64; 3];
        d[widest] = 1.0;
        for _ in 0..24 {
            let next: [f64; 3] = std::array::from_fn(|i| (0..3).map(|j| cov[i][j] * d[j]).sum());
            let len = next.iter().map(|x| x * x).sum::<f64>().sqrt();
            if !(len > 0.0 && len.is_finite()) {
                break;
            }
            d = next.map(|x| x / len);
        }
        Axis { origin: std::array::from_fn(|i| c[i] + self.first[i]), direction: d }
    }
}

/// A line: a point and a unit direction.
#[derive(Clone, Copy, Debug)]
struct Axis {
    origin: [f64; 3],
    direction: [f64; 3],
}

impl Axis {
    /// `q`'s position along the line (from its origin) and its distance from it.
    fn coordinates(&self, q: [f32; 3]) -> (f64, f64) {
        let v: [f64; 3] = std::array::from_fn(|i| q[i] as f64 - self.origin[i]);
        let along: f64 = (0..3).map(|i| v[i] * self.direction[i]).sum();
        let d2: f64 = (0..3).map(|i| (v[i] - along * self.direction[i]).powi(2)).sum();
        (along, d2.max(0.0).sqrt())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The corners of a 1×1 square section at `x`, as points of part 0, `held` or not.
    fn ring(x: f32, held: bool) -> Vec<(usize, [f32; 3], bool)> {
        [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]].iter().map(|&[y, z]| (0, [x, y, z], held)).collect()
    }

    #[test]
    fn a_rod_held_at_its_ends_may_go_and_one_held_along_its_length_may_not() {
        // A bar 20 long, 1×1 across: √½ from its axis, half-length 10, a rod.
        let held_at_ends: Vec<_> = (0..=20).flat_map(|x| ring(x as f32, x == 0 || x == 20)).collect();
        let s = part_shapes(1, || held_at_ends.iter().copied())[0];
        assert!((s.off_axis - 0.5f64.sqrt()).abs() < 1e-6 && (s.half_length - 10.0).abs() < 1e-6, "{s:?}");
        assert!(s.is_rod() && s.is_rod_held_at_ends(), "{s:?}");
        assert!((s.bound() - 0.5f64.sqrt()).abs() < 1e-6, "its thickness, not its length");
        // The same bar held in its middle (a seam along it): a rod, but it stays.
        let held_inside: Vec<_> = (0..=20).flat_map(|x| ring(x as f32, x == 10)).collect();
        let s = part_shapes(1, || held_inside.iter().copied())[0];
        assert!(s.is_rod() && !s.is_rod_held_at_ends(), "{s:?}");
        // A cube is no rod.
        let cube: Vec<_> = (0..=1).flat_map(|x| ring(x as f32, false)).collect();
        assert!(!part_shapes(1, || cube.iter().copied())[0].is_rod());
    }
}
