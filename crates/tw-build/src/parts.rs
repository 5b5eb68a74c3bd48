//! Part groups: where a big object's triangle stream passes from one closed part to the next.
//!
//! CAD exports often write a whole assembly as one object (a PLY has no objects at all): tens
//! of thousands of small closed parts, each written whole, one after the other. Redefinition's
//! partition-I would cut such an object by planes through its parts (`crate::redefine`), and
//! every part a plane cuts has seams that the LOD must keep locked up to HLOD (measured on the
//! generated 10 M-triangle assembly: written as one object, 2.28× the input over all LOD levels
//! and 1.09 M triangles in the overview's cut; with one object per part, 2.01× and 0.32 M).
//!
//! [`PartSplitter`] watches an object's triangles as ingest streams them and marks a *group
//! start* where a new part begins: the triangles since the last start are at least
//! [`MIN_GROUP`] and form a closed surface (every directed edge has its reverse: the part is
//! complete). Redefinition then splits the object at those starts instead of by planes
//! (`Route::Parts`), so that no part is cut; groups of up to a few hundred small parts, written
//! together, are also close together in CAD exports, so a group is a compact piece.
//!
//! A surface that never closes (an open scan, pipes without caps, a triangle soup, inconsistent
//! winding) gives no start, and the object is split by planes as before. The same holds from
//! the first open part of an object on: its group never closes again, so the rest of the
//! object is one group (split by partition-II's planes if large); and a group still open after
//! [`GIVE_UP`] triangles stops the watch for the object, which bounds the hashing that big open
//! objects cost (the 10^8 plant's pipe network). Edges are keyed by a
//! 64-bit hash of their two positions (exact `f32` offsets, as the working file has them): a
//! collision can only move a start, never make a store wrong. The first [`MIN_GROUP`]
//! triangles of each group are only buffered and hashed once the group reaches that size, so
//! small objects cost a copy per triangle. Deterministic: a function of the triangle sequence.

use rustc_hash::{FxHashMap, FxHashSet};

/// The fewest triangles of a group: small enough that a group holds a few small parts (cells
/// are 1k–64k triangles), large enough that groups stay few (redefinition keeps O(groups)).
pub const MIN_GROUP: u64 = 512;

/// A group still open after this many triangles is not a run of small parts (a pipe network, a
/// scan): the object's remaining triangles are not watched (its starts so far stay), so that big
/// open objects cost a bounded amount of hashing.
pub const GIVE_UP: u64 = 1 << 15;

/// Finds the group starts of one object at a time (see the module comment).
#[derive(Debug, Default)]
pub struct PartSplitter {
    /// Triangles of the current group not yet hashed (the group is below `MIN_GROUP`).
    pending: Vec<[[f32; 3]; 3]>,
    /// Directed edges of the current group whose reverse has not been seen.
    open: FxHashSet<u64>,
    group_len: u64,
    object_len: u64,
    /// The current group passed [`GIVE_UP`] open: no more starts in this object.
    given_up: bool,
    /// Object-relative indices of the triangles that start a new group (the first group starts
    /// at 0 and is not listed).
    starts: Vec<u64>,
}

impl PartSplitter {
    /// Starts a new object.
    pub fn begin(&mut self) {
        self.pending.clear();
        self.open.clear();
        self.group_len = 0;
        self.object_len = 0;
        self.given_up = false;
        self.starts.clear();
    }

    /// The next triangle of the current object.
    #[inline]
    pub fn add(&mut self, p: [[f32; 3]; 3]) {
        if self.given_up {
            return;
        }
        if self.group_len >= GIVE_UP {
            self.given_up = true;
            self.open.clear();
            return;
        }
        if self.group_len >= MIN_GROUP && self.open.is_empty() {
            self.starts.push(self.object_len);
            self.group_len = 0;
        }
        self.group_len += 1;
        self.object_len += 1;
        if self.group_len < MIN_GROUP {
            self.pending.push(p);
            return;
        }
        for q in std::mem::take(&mut self.pending) {
            self.toggle(q);
        }
        self.toggle(p);
    }

    /// The group starts of the current object (object-relative triangle indices, ascending).
    pub fn starts(&self) -> &[u64] {
        &self.starts
    }

    /// Records the triangle's three directed edges: an edge whose reverse is open closes it.
    fn toggle(&mut self, p: [[f32; 3]; 3]) {
        for (a, b) in [(p[0], p[1]), (p[1], p[2]), (p[2], p[0])] {
            if a == b {
                continue;
            }
            if !self.open.remove(&edge_hash(b, a)) {
                self.open.insert(edge_hash(a, b));
            }
        }
    }
}

/// [`PartSplitter`] over a stream of several objects: the group starts of every object whose
/// triangles came in one run (an object that comes back after another's is left to planes).
#[derive(Debug, Default)]
pub struct ObjectParts {
    splitter: PartSplitter,
    current: Option<u32>,
    starts: FxHashMap<u32, Vec<u64>>,
    broken: FxHashSet<u32>,
}

impl ObjectParts {
    /// The next triangle, of `object`; `seen_before`: the object already has triangles (asked
    /// only when the object changes).
    #[inline]
    pub fn add(&mut self, object: u32, p: [[f32; 3]; 3], seen_before: impl FnOnce() -> bool) {
        if self.current != Some(object) {
            self.close();
            self.current = Some(object);
            if seen_before() {
                self.broken.insert(object);
            }
            self.splitter.begin();
        }
        self.splitter.add(p);
    }

    /// Per object with at least one start, its starts.
    pub fn finish(mut self) -> FxHashMap<u32, Vec<u64>> {
        self.close();
        for o in &self.broken {
            self.starts.remove(o);
        }
        self.starts
    }

    fn close(&mut self) {
        if let Some(o) = self.current.take() {
            if !self.splitter.starts().is_empty() {
                self.starts.insert(o, self.splitter.starts().to_vec());
            }
        }
    }
}

/// A 64-bit hash of the directed edge `a → b` (the positions' bits).
#[inline]
fn edge_hash(a: [f32; 3], b: [f32; 3]) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = rustc_hash::FxHasher::default();
    for x in a.iter().chain(&b) {
        x.to_bits().hash(&mut h);
    }
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A closed box of 12 triangles at `x`, consistently wound.
    fn cube(x: f32) -> Vec<[[f32; 3]; 3]> {
        let c = |i: usize| [x + (i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32];
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        quads.iter().flat_map(|q| [[c(q[0]), c(q[1]), c(q[2])], [c(q[0]), c(q[2]), c(q[3])]]).collect()
    }

    fn starts_of(tris: &[[[f32; 3]; 3]]) -> Vec<u64> {
        let mut s = PartSplitter::default();
        s.begin();
        for &t in tris {
            s.add(t);
        }
        s.starts().to_vec()
    }

    #[test]
    fn groups_start_between_closed_parts_once_big_enough() {
        let tris: Vec<_> = (0..200).flat_map(|i| cube(i as f32 * 3.0)).collect();
        let starts = starts_of(&tris);
        // 2,400 triangles of 12-triangle boxes: a start after the first box that ends at or after
        // MIN_GROUP triangles, and so on.
        let group = MIN_GROUP.div_ceil(12) * 12;
        let expected: Vec<u64> = (1..).map(|k| k * group).take_while(|&s| s < tris.len() as u64).collect();
        assert_eq!(starts, expected);
        assert!(starts.iter().all(|s| s % 12 == 0), "never inside a box");
    }

    #[test]
    fn an_open_surface_or_a_small_object_gives_no_start() {
        // Boxes with one triangle missing never close.
        let open: Vec<_> = (0..200).flat_map(|i| cube(i as f32 * 3.0).into_iter().skip(1)).collect();
        assert!(starts_of(&open).is_empty());
        let small: Vec<_> = (0..20).flat_map(|i| cube(i as f32 * 3.0)).collect();
        assert!(starts_of(&small).is_empty(), "{} triangles", small.len());
    }

    #[test]
    fn a_long_open_group_stops_the_watch_and_keeps_earlier_starts() {
        let mut tris: Vec<_> = (0..100).flat_map(|i| cube(i as f32 * 3.0)).collect();
        let closed_starts = starts_of(&tris);
        // Then a long open strip, then closed boxes again: no start after the strip.
        let strip = (0..GIVE_UP + 10).map(|i| {
            let x = 1000.0 + i as f32;
            [[x, 0.0, 0.0], [x + 1.0, 0.0, 0.0], [x, 1.0, 0.0]]
        });
        tris.extend(strip);
        tris.extend((0..100).flat_map(|i| cube(5000.0 + i as f32 * 3.0)));
        // An open part keeps its group open: no start after it (the object's later parts stay
        // in the last group; see the module comment), and the watch stops at GIVE_UP.
        assert_eq!(starts_of(&tris), closed_starts);
        assert!(!closed_starts.is_empty());
    }

    #[test]
    fn begin_resets_between_objects() {
        let tris: Vec<_> = (0..100).flat_map(|i| cube(i as f32 * 3.0)).collect();
        let mut s = PartSplitter::default();
        s.begin();
        tris.iter().for_each(|&t| s.add(t));
        let first = s.starts().to_vec();
        s.begin();
        tris.iter().for_each(|&t| s.add(t));
        assert_eq!(s.starts(), first);
        assert!(!first.is_empty());
    }
}
