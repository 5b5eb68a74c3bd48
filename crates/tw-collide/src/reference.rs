//! The exact CPU reference: every pair of overlapping triangles, between objects and (for
//! objects marked [`Object::self_collide`]) within one object, found by a BVH per object
//! ([`crate::bvh`]) and the exact test ([`crate::tritri`]). Multi-threaded with rayon over the
//! tasks of a split traversal (pairs of subtrees), for all object pairs whose boxes overlap.
//!
//! It is what CULLIDE and FAR are measured against (misses, extra work), and the last stage of
//! both: their surviving triangles go through [`exact_pairs`].

use rayon::prelude::*;

use crate::bvh::{split_tasks, traverse, Bvh, Task};
use crate::tritri::triangles_within;
use crate::{Aabb, Object, Pair, TriRef};

/// Tasks a traversal is split into per thread, so that uneven subtrees still balance.
const TASKS_PER_THREAD: usize = 8;

/// All overlapping triangle pairs of `objects`, sorted.
pub fn all_pairs(objects: &[Object]) -> Vec<Pair> {
    all_pairs_within(objects, 0.0)
}

/// All triangle pairs of `objects` within `distance` of each other (0: overlapping), sorted.
/// Boxes grow by half the distance, so the boxes of a pair within it overlap.
pub fn all_pairs_within(objects: &[Object], distance: f32) -> Vec<Pair> {
    let half = distance.max(0.0) / 2.0;
    let bvhs: Vec<Bvh> = objects
        .par_iter()
        .map(|o| Bvh::build(&o.triangle_boxes().iter().map(|b| b.grow(half)).collect::<Vec<_>>()))
        .collect();
    let bounds: Vec<Aabb> = objects.iter().map(|o| o.bounds().grow(half)).collect();
    let mut jobs: Vec<(usize, usize)> = Vec::new();
    for i in 0..objects.len() {
        if objects[i].self_collide {
            jobs.push((i, i));
        }
        for j in i + 1..objects.len() {
            if bounds[i].overlaps(&bounds[j]) {
                jobs.push((i, j));
            }
        }
    }
    let want = rayon::current_num_threads() * TASKS_PER_THREAD;
    let tasks: Vec<(usize, usize, Task)> = jobs
        .into_iter()
        .flat_map(|(i, j)| split_tasks(&bvhs[i], &bvhs[j], i == j, want).into_iter().map(move |t| (i, j, t)))
        .collect();
    let mut pairs: Vec<Pair> = tasks
        .par_iter()
        .flat_map_iter(|&(i, j, task)| {
            let mut found = Vec::new();
            traverse(&bvhs[i], &bvhs[j], i == j, task, |leaves| {
                let a = bvhs[i].leaf(&bvhs[i].nodes[leaves.a as usize]);
                let b = bvhs[j].leaf(&bvhs[j].nodes[leaves.b as usize]);
                let same_leaf = i == j && leaves.a == leaves.b;
                test_leaves(objects, (i, a), (j, b), same_leaf, distance, &mut found);
            });
            found
        })
        .collect();
    pairs.sort_unstable();
    pairs
}

/// The exact tests between the triangles of two leaves (`within`: the same leaf, each unordered
/// pair once).
fn test_leaves(
    objects: &[Object],
    a: (usize, &[u32]),
    b: (usize, &[u32]),
    same_leaf: bool,
    distance: f32,
    out: &mut Vec<Pair>,
) {
    for (k, &ta) in a.1.iter().enumerate() {
        let rest = if same_leaf { &b.1[k + 1..] } else { b.1 };
        for &tb in rest {
            if let Some(p) = test_pair_within(objects, TriRef::new(a.0, ta), TriRef::new(b.0, tb), distance) {
                out.push(p);
            }
        }
    }
}

/// The exact test of one pair of triangles: `None` when they do not overlap, or when they are
/// neighbours in one object (sharing a vertex: they always touch, and the thesis' self-collision
/// counts only other contacts).
pub fn test_pair(objects: &[Object], a: TriRef, b: TriRef) -> Option<Pair> {
    test_pair_within(objects, a, b, 0.0)
}

/// [`test_pair`] for triangles within `distance` of each other.
pub fn test_pair_within(objects: &[Object], a: TriRef, b: TriRef, distance: f32) -> Option<Pair> {
    let (oa, ob) = (&objects[a.object as usize], &objects[b.object as usize]);
    if a.object == b.object {
        let (ia, ib) = (oa.triangles[a.triangle as usize], ob.triangles[b.triangle as usize]);
        if a.triangle == b.triangle || ia.iter().any(|v| ib.contains(v)) {
            return None;
        }
    }
    let (ta, tb) = (oa.triangle(a.triangle), ob.triangle(b.triangle));
    let half = distance.max(0.0) / 2.0;
    if !Aabb::of_triangle(&ta).grow(half).overlaps(&Aabb::of_triangle(&tb).grow(half))
        || !triangles_within(&ta, &tb, distance)
    {
        return None;
    }
    Some(Pair::new(a, b))
}

/// The exact tests of candidate pairs, in parallel; those within `distance` (0: overlapping),
/// sorted.
pub fn exact_pairs(objects: &[Object], candidates: &[(TriRef, TriRef)], distance: f32) -> Vec<Pair> {
    let mut pairs: Vec<Pair> = candidates
        .par_iter()
        .with_min_len(256)
        .filter_map(|&(a, b)| test_pair_within(objects, a, b, distance))
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square of two triangles at height `z` over [x0, x0 + 1]², tilted by `tilt` along x.
    fn square(x0: f32, z: f32, tilt: f32) -> Object {
        let positions =
            vec![[x0, 0.0, z], [x0 + 1.0, 0.0, z + tilt], [x0 + 1.0, 1.0, z + tilt], [x0, 1.0, z]];
        Object { positions, triangles: vec![[0, 1, 2], [0, 2, 3]], self_collide: false }
    }

    /// Every pair tested without any tree.
    fn brute(objects: &[Object]) -> Vec<Pair> {
        let mut v = Vec::new();
        for i in 0..objects.len() {
            for j in i..objects.len() {
                if i == j && !objects[i].self_collide {
                    continue;
                }
                for a in 0..objects[i].triangles.len() {
                    for b in 0..objects[j].triangles.len() {
                        if i == j && b <= a {
                            continue;
                        }
                        v.extend(test_pair(objects, TriRef::new(i, a as u32), TriRef::new(j, b as u32)));
                    }
                }
            }
        }
        v.sort();
        v
    }

    #[test]
    fn reference_matches_brute_force() {
        for seed in 0..4 {
            let mut objects = crate::scenes::random_soup(8, 40, 0.15, seed);
            objects[3].self_collide = true;
            let found = all_pairs(&objects);
            assert_eq!(found, brute(&objects));
            assert!(found.len() > 10, "the scene should collide: {found:?}");
        }
    }

    #[test]
    fn within_distance_finds_more_and_matches_brute_force() {
        let objects = crate::scenes::random_soup(6, 30, 0.1, 9);
        let near = all_pairs_within(&objects, 0.05);
        let mut brute = Vec::new();
        for i in 0..objects.len() {
            for j in i + 1..objects.len() {
                for a in 0..30 {
                    for b in 0..30 {
                        brute.extend(test_pair_within(&objects, TriRef::new(i, a), TriRef::new(j, b), 0.05));
                    }
                }
            }
        }
        brute.sort();
        assert_eq!(near, brute);
        assert!(near.len() > all_pairs(&objects).len());
    }

    #[test]
    fn neighbours_in_one_object_are_not_self_collisions() {
        let mut o = square(0.0, 0.0, 0.0);
        o.self_collide = true;
        assert!(all_pairs(&[o]).is_empty());
    }
}
