//! Geometry helpers of object redefinition: the scene-relative thresholds ([`Scale`]), box
//! extents and aspect ratios, and boxes of working-file offsets ([`FBox`]).

use super::RedefineParams;
use crate::ingest::{Ingested, WorkFile};
use crate::types::{Grid, GridBox};

/// The scene-relative thresholds in input units.
pub(super) struct Scale {
    pub(super) step: f64,
    pub(super) s1: f64,
    pub(super) s2: f64,
    pub(super) d: f64,
    pub(super) v: f64,
    /// Smallest extent used for volumes.
    pub(super) floor: f64,
}

impl Scale {
    pub(super) fn new(ing: &Ingested, p: &RedefineParams) -> Scale {
        let ext: Vec<f64> = (0..3).map(|i| ing.max[i] - ing.min[i]).collect();
        let largest = ext.iter().copied().fold(0.0, f64::max);
        let largest = if largest > 0.0 { largest } else { 1.0 };
        let floor = 1e-3 * largest;
        let volume: f64 = ext.iter().map(|e| e.max(floor)).product();
        Scale {
            step: ing.grid.step,
            s1: p.s1 * largest,
            s2: p.s2 * largest,
            d: p.d * largest,
            v: p.v * volume,
            floor,
        }
    }

    pub(super) fn grid_ext(&self, b: &GridBox) -> [f64; 3] {
        let e = |i: usize| b.max[i].saturating_sub(b.min[i]) as f64 * self.step;
        [e(0), e(1), e(2)]
    }

    pub(super) fn volume(&self, b: &GridBox) -> f64 {
        self.grid_ext(b).iter().map(|e| e.max(self.floor)).product()
    }
}

pub(super) fn diag(e: [f64; 3]) -> f64 {
    (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
}

/// Longest extent over the second longest.
pub(super) fn aspect(e: [f64; 3]) -> f64 {
    let mut s = e;
    s.sort_by(|a, b| b.total_cmp(a));
    if s[0] <= 0.0 {
        1.0
    } else if s[1] <= 0.0 {
        f64::INFINITY
    } else {
        s[0] / s[1]
    }
}

/// Axes by decreasing extent (ties: lower axis first).
pub(super) fn axes_by_extent(e: [f64; 3]) -> [usize; 3] {
    let mut a = [0, 1, 2];
    a.sort_by(|&x, &y| e[y].total_cmp(&e[x]));
    a
}

/// The smallest f32 above `v` (finite, non-NaN `v`).
pub(super) fn next_up(v: f32) -> f32 {
    if v == 0.0 {
        return f32::from_bits(1);
    }
    let b = v.to_bits();
    f32::from_bits(if v > 0.0 { b + 1 } else { b - 1 })
}

/// A box in working-file coordinates (f32 offsets, input units).
#[derive(Clone, Copy, Debug)]
pub(super) struct FBox {
    pub(super) min: [f32; 3],
    pub(super) max: [f32; 3],
}

impl FBox {
    pub(super) const EMPTY: FBox = FBox { min: [f32::INFINITY; 3], max: [f32::NEG_INFINITY; 3] };

    #[inline]
    pub(super) fn grow(&mut self, p: [f32; 3]) {
        for (i, x) in p.into_iter().enumerate() {
            self.min[i] = self.min[i].min(x);
            self.max[i] = self.max[i].max(x);
        }
    }

    /// Grows to contain `o`, which must not be empty (an empty box's +∞ minimum would become
    /// this box's maximum).
    pub(super) fn union(&mut self, o: &FBox) {
        self.grow(o.min);
        self.grow(o.max);
    }

    pub(super) fn ext(&self) -> [f64; 3] {
        let e = |i: usize| (self.max[i] as f64 - self.min[i] as f64).max(0.0);
        [e(0), e(1), e(2)]
    }

    pub(super) fn to_grid(self, work: &WorkFile, grid: &Grid) -> GridBox {
        GridBox { min: work.quantize(grid, self.min), max: work.quantize(grid, self.max) }
    }
}

/// Moves the elements satisfying `pred` to the front; returns how many there are.
pub(super) fn partition_in_place<T>(v: &mut [T], pred: impl Fn(&T) -> bool) -> usize {
    let mut n = 0;
    for i in 0..v.len() {
        if pred(&v[i]) {
            v.swap(n, i);
            n += 1;
        }
    }
    n
}
