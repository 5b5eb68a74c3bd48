//! Sweep-and-prune (the broad phase of I-COLLIDE, used by the thesis between the visibility
//! culling and the exact tests): sorts boxes by their lower x and sweeps once, keeping the boxes
//! whose x interval is still open, and reports the pairs whose boxes overlap on all three axes.

use crate::Aabb;

/// The pairs `(i, j)`, `i < j`, of `boxes` that overlap and that `keep(i, j)` accepts.
pub fn overlapping_pairs(boxes: &[Aabb], mut keep: impl FnMut(usize, usize) -> bool) -> Vec<(usize, usize)> {
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_unstable_by(|&a, &b| boxes[a].lo[0].total_cmp(&boxes[b].lo[0]));
    let mut active: Vec<usize> = Vec::new();
    let mut out = Vec::new();
    for &i in &order {
        let b = &boxes[i];
        active.retain(|&j| boxes[j].hi[0] >= b.lo[0]);
        for &j in &active {
            if boxes[j].overlaps(b) && keep(i.min(j), i.max(j)) {
                out.push((i.min(j), i.max(j)));
            }
        }
        active.push(i);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_exactly_the_overlapping_pairs() {
        let boxes: Vec<Aabb> = (0..40)
            .map(|i| {
                let (x, y) = ((i * 7 % 13) as f32 * 0.4, (i * 5 % 11) as f32 * 0.3);
                Aabb { lo: [x, y, 0.0], hi: [x + 0.5, y + 0.5, 1.0] }
            })
            .collect();
        let mut found = overlapping_pairs(&boxes, |_, _| true);
        found.sort();
        let mut want = Vec::new();
        for i in 0..boxes.len() {
            for j in i + 1..boxes.len() {
                if boxes[i].overlaps(&boxes[j]) {
                    want.push((i, j));
                }
            }
        }
        assert_eq!(found, want);
        assert!(!want.is_empty());
    }
}
