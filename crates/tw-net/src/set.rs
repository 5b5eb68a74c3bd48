//! The visible set as the two ends of a connection hold it, and its frame-to-frame delta: the
//! occlusion switch's incremental transmission (Govindaraju's thesis §3.5): the server sends
//! δ(i, i−1) = Vi − Vi−1 (added) and δ(i−1, i) = Vi−1 − Vi (dropped), and the client rebuilds
//! Vi = (Vi−1 − dropped) ∪ added. A set is a sorted list of distinct ids, so both the delta and
//! its application are one merge, O(|V| + |δ|).

use crate::protocol::{ClusterId, VisibleDelta, MAX_IDS_PER_CHUNK};
use crate::WireError;

/// A visible set: sorted, distinct cluster ids.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct VisibleSet {
    ids: Vec<ClusterId>,
}

impl VisibleSet {
    /// The set of `ids` (any order, repeats allowed).
    pub fn from_ids(mut ids: Vec<ClusterId>) -> VisibleSet {
        ids.sort_unstable();
        ids.dedup();
        VisibleSet { ids }
    }

    /// The ids, ascending.
    pub fn ids(&self) -> &[ClusterId] {
        &self.ids
    }

    pub fn len(&self) -> usize {
        self.ids.len()
    }

    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }

    /// What turns `self` into `next`: (added, dropped), each ascending.
    pub fn delta_to(&self, next: &VisibleSet) -> (Vec<ClusterId>, Vec<ClusterId>) {
        let (mut added, mut dropped) = (Vec::new(), Vec::new());
        let (a, b) = (&self.ids, &next.ids);
        let (mut i, mut j) = (0, 0);
        while i < a.len() || j < b.len() {
            match (a.get(i), b.get(j)) {
                (Some(x), Some(y)) if x == y => (i, j) = (i + 1, j + 1),
                (Some(x), Some(y)) if x < y => {
                    dropped.push(*x);
                    i += 1;
                }
                (Some(_), Some(y)) | (None, Some(y)) => {
                    added.push(*y);
                    j += 1;
                }
                (Some(x), None) => {
                    dropped.push(*x);
                    i += 1;
                }
                (None, None) => break,
            }
        }
        (added, dropped)
    }

    /// Applies a frame's delta (all its chunks' ids gathered): (self − dropped) ∪ added. An id
    /// dropped that is not in the set, or added that already is, means the two ends no longer
    /// agree on the set: an error, and the set is left as it was.
    pub fn apply(&mut self, mut added: Vec<ClusterId>, mut dropped: Vec<ClusterId>) -> Result<(), WireError> {
        added.sort_unstable();
        dropped.sort_unstable();
        let mut kept = Vec::with_capacity(self.ids.len() + added.len());
        let mut d = 0;
        for &id in &self.ids {
            if let Some(x) = dropped.get(d).filter(|&&x| x < id) {
                return Err(WireError::Desync(format!("id {x} dropped but not in the set")));
            }
            if dropped.get(d) == Some(&id) {
                d += 1;
            } else {
                kept.push(id);
            }
        }
        if let Some(id) = dropped.get(d) {
            return Err(WireError::Desync(format!("id {id} dropped but not in the set")));
        }
        let mut out = Vec::with_capacity(kept.len() + added.len());
        let (mut i, mut j) = (0, 0);
        while i < kept.len() || j < added.len() {
            match (kept.get(i), added.get(j)) {
                (Some(x), Some(y)) if x == y => {
                    return Err(WireError::Desync(format!("id {y} added but already in the set")));
                }
                (Some(x), Some(y)) if x < y => {
                    out.push(*x);
                    i += 1;
                }
                (Some(x), None) => {
                    out.push(*x);
                    i += 1;
                }
                (_, Some(y)) => {
                    if out.last() == Some(y) {
                        return Err(WireError::Desync(format!("id {y} added twice")));
                    }
                    out.push(*y);
                    j += 1;
                }
                (None, None) => break,
            }
        }
        self.ids = out;
        Ok(())
    }
}

/// A frame's delta cut into chunks of at most [`MAX_IDS_PER_CHUNK`] ids (added first, then
/// dropped); none for an empty delta.
pub fn chunks(frame: u64, added: &[ClusterId], dropped: &[ClusterId]) -> Vec<VisibleDelta> {
    let mut out = Vec::new();
    let (mut a, mut d) = (added, dropped);
    while !a.is_empty() || !d.is_empty() {
        let na = a.len().min(MAX_IDS_PER_CHUNK);
        let nd = d.len().min(MAX_IDS_PER_CHUNK - na);
        out.push(VisibleDelta { frame, added: a[..na].to_vec(), dropped: d[..nd].to_vec() });
        (a, d) = (&a[na..], &d[nd..]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use tw_core::rng::Rng;

    fn random_set(rng: &mut Rng, n: u32, universe: u32) -> VisibleSet {
        VisibleSet::from_ids((0..n).map(|_| rng.range_u32(0, universe)).collect())
    }

    #[test]
    fn applying_the_delta_rebuilds_the_next_set() {
        let mut rng = Rng::new(3);
        for _ in 0..500 {
            let universe = rng.range_u32(1, 300);
            let (na, nb) = (rng.range_u32(0, 200), rng.range_u32(0, 200));
            let a = random_set(&mut rng, na, universe);
            let b = random_set(&mut rng, nb, universe);
            let (added, dropped) = a.delta_to(&b);
            let mut c = a.clone();
            c.apply(added.clone(), dropped.clone()).unwrap();
            assert_eq!(c, b);
            // Through the chunks, reversed and gathered: the same.
            let mut c = a.clone();
            let parts = chunks(9, &added, &dropped);
            let gather =
                |f: fn(&VisibleDelta) -> &Vec<u32>| parts.iter().rev().flat_map(f).copied().collect();
            c.apply(gather(|p| &p.added), gather(|p| &p.dropped)).unwrap();
            assert_eq!(c, b);
        }
    }

    #[test]
    fn a_delta_that_does_not_fit_the_set_is_a_desync() {
        let mut s = VisibleSet::from_ids(vec![1, 5, 9]);
        assert!(s.apply(vec![5], vec![]).is_err());
        assert!(s.apply(vec![], vec![4]).is_err());
        assert!(s.apply(vec![], vec![10]).is_err());
        assert!(s.apply(vec![2, 2], vec![]).is_err());
        assert_eq!(s.ids(), &[1, 5, 9], "a failed delta leaves the set");
        s.apply(vec![2], vec![1, 9]).unwrap();
        assert_eq!(s.ids(), &[2, 5]);
    }

    #[test]
    fn chunks_hold_at_most_the_bound() {
        let added: Vec<u32> = (0..MAX_IDS_PER_CHUNK as u32 + 5).collect();
        let dropped: Vec<u32> = (0..MAX_IDS_PER_CHUNK as u32).map(|i| i + 1_000_000).collect();
        let parts = chunks(1, &added, &dropped);
        assert_eq!(parts.len(), 3);
        assert!(parts.iter().all(|p| p.added.len() + p.dropped.len() <= MAX_IDS_PER_CHUNK));
        assert_eq!(parts.iter().map(|p| p.added.len()).sum::<usize>(), added.len());
        assert_eq!(parts.iter().map(|p| p.dropped.len()).sum::<usize>(), dropped.len());
        assert!(chunks(1, &[], &[]).is_empty());
    }
}
