//! A small axis-aligned bounding-box tree over one object's triangles, and the traversal of two
//! trees (or one tree against itself) that yields the pairs of leaves whose boxes overlap — the
//! broad phase of the exact reference ([`crate::reference`]).
//!
//! Built top-down by median split of the triangles' centroids along the longest axis of their
//! bounds, [`LEAF_SIZE`] triangles a leaf at most: a build is O(n log n) and fast enough to redo
//! every step of a deforming scene, which is what the thesis' scenes need (no refitting).

use crate::Aabb;

/// Triangles in a leaf at most.
pub const LEAF_SIZE: usize = 4;

/// One node: its box and either its two children (`count == 0`: `first` and `first + 1`) or
/// its triangles (`order[first..first + count]`).
#[derive(Clone, Copy, Debug)]
pub struct Node {
    pub bounds: Aabb,
    pub first: u32,
    pub count: u32,
}

impl Node {
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

/// The tree; node 0 is the root (absent for an object without triangles).
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    pub nodes: Vec<Node>,
    /// Triangle indices in leaf order.
    pub order: Vec<u32>,
}

impl Bvh {
    /// The tree over triangles with the given boxes.
    pub fn build(boxes: &[Aabb]) -> Bvh {
        let mut bvh =
            Bvh { nodes: Vec::with_capacity(boxes.len() / 2 + 1), order: (0..boxes.len() as u32).collect() };
        if boxes.is_empty() {
            return bvh;
        }
        let centroids: Vec<[f32; 3]> = boxes.iter().map(Aabb::center).collect();
        bvh.nodes.push(Node { bounds: Aabb::EMPTY, first: 0, count: 0 });
        let mut stack = vec![(0usize, 0usize, boxes.len())];
        while let Some((node, start, end)) = stack.pop() {
            let items = &mut bvh.order[start..end];
            let bounds = items.iter().fold(Aabb::EMPTY, |b, &t| b.union(&boxes[t as usize]));
            if items.len() <= LEAF_SIZE {
                bvh.nodes[node] = Node { bounds, first: start as u32, count: items.len() as u32 };
                continue;
            }
            let spread = items.iter().fold(Aabb::EMPTY, |b, &t| b.include(centroids[t as usize]));
            let axis = spread.longest_axis();
            let mid = items.len() / 2;
            items.select_nth_unstable_by(mid, |&a, &b| {
                centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis])
            });
            let left = bvh.nodes.len();
            bvh.nodes.push(Node { bounds: Aabb::EMPTY, first: 0, count: 0 });
            bvh.nodes.push(Node { bounds: Aabb::EMPTY, first: 0, count: 0 });
            bvh.nodes[node] = Node { bounds, first: left as u32, count: 0 };
            stack.push((left, start, start + mid));
            stack.push((left + 1, start + mid, end));
        }
        bvh
    }

    /// The triangles of leaf `node`.
    pub fn leaf(&self, node: &Node) -> &[u32] {
        &self.order[node.first as usize..(node.first + node.count) as usize]
    }
}

/// A pair of nodes still to be traversed: in two trees, or (`same`) twice the same tree, where
/// `(n, n)` stands for the pairs inside node `n`.
#[derive(Clone, Copy, Debug)]
pub struct Task {
    pub a: u32,
    pub b: u32,
}

/// Expands the traversal of `a` against `b` breadth-first until there are at least `want` tasks
/// (or nothing left to expand), so that the tasks can be traversed in parallel. `same`: `a` and
/// `b` are the same tree (self-collision).
pub fn split_tasks(a: &Bvh, b: &Bvh, same: bool, want: usize) -> Vec<Task> {
    if a.nodes.is_empty() || b.nodes.is_empty() {
        return Vec::new();
    }
    let mut tasks = vec![Task { a: 0, b: 0 }];
    loop {
        if tasks.len() >= want {
            return tasks;
        }
        let mut next = Vec::with_capacity(tasks.len() * 4);
        let mut grew = false;
        for t in tasks {
            let before = next.len();
            expand(a, b, same, t, &mut |x| next.push(x), &mut |_| {});
            // A pair of leaves stays a task of its own.
            if next.len() == before && leaves_overlap(a, b, same, t) {
                next.push(t);
            } else {
                grew = true;
            }
        }
        tasks = next;
        if !grew {
            return tasks;
        }
    }
}

fn leaves_overlap(a: &Bvh, b: &Bvh, same: bool, t: Task) -> bool {
    let (na, nb) = (&a.nodes[t.a as usize], &b.nodes[t.b as usize]);
    na.is_leaf() && nb.is_leaf() && (same && t.a == t.b || na.bounds.overlaps(&nb.bounds))
}

/// One step of the traversal of task `t`: pushes the child tasks whose boxes overlap, or hands
/// a pair of overlapping leaves to `leaves`.
fn expand(a: &Bvh, b: &Bvh, same: bool, t: Task, push: &mut impl FnMut(Task), leaves: &mut impl FnMut(Task)) {
    let (na, nb) = (&a.nodes[t.a as usize], &b.nodes[t.b as usize]);
    if same && t.a == t.b {
        if na.is_leaf() {
            leaves(t);
        } else {
            let (l, r) = (na.first, na.first + 1);
            push(Task { a: l, b: l });
            push(Task { a: r, b: r });
            if a.nodes[l as usize].bounds.overlaps(&a.nodes[r as usize].bounds) {
                push(Task { a: l, b: r });
            }
        }
        return;
    }
    if !na.bounds.overlaps(&nb.bounds) {
        return;
    }
    match (na.is_leaf(), nb.is_leaf()) {
        (true, true) => leaves(t),
        // Descend the larger box (or the inner node).
        (false, false) if na.bounds.volume() >= nb.bounds.volume() => {
            push(Task { a: na.first, b: t.b });
            push(Task { a: na.first + 1, b: t.b });
        }
        (false, true) => {
            push(Task { a: na.first, b: t.b });
            push(Task { a: na.first + 1, b: t.b });
        }
        _ => {
            push(Task { a: t.a, b: nb.first });
            push(Task { a: t.a, b: nb.first + 1 });
        }
    }
}

/// Traverses `task` to the end, calling `leaves` for every pair of overlapping leaves (for
/// `(n, n)` in the same tree: leaf `n` against itself).
pub fn traverse(a: &Bvh, b: &Bvh, same: bool, task: Task, mut leaves: impl FnMut(Task)) {
    let mut stack = vec![task];
    while let Some(t) = stack.pop() {
        expand(a, b, same, t, &mut |x| stack.push(x), &mut leaves);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(x: f32) -> Aabb {
        Aabb { lo: [x, 0.0, 0.0], hi: [x + 1.0, 1.0, 1.0] }
    }

    #[test]
    fn every_triangle_is_in_one_leaf_under_its_ancestors() {
        let boxes: Vec<Aabb> = (0..37).map(|i| unit(i as f32 * 0.7)).collect();
        let bvh = Bvh::build(&boxes);
        let mut seen = vec![0; boxes.len()];
        for n in bvh.nodes.iter().filter(|n| n.is_leaf()) {
            assert!(n.count as usize <= LEAF_SIZE);
            for &t in bvh.leaf(n) {
                seen[t as usize] += 1;
                assert!(n.bounds.contains(&boxes[t as usize]));
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
    }

    #[test]
    fn split_tasks_find_the_same_leaf_pairs_as_one_traversal() {
        let boxes: Vec<Aabb> = (0..100).map(|i| unit(i as f32 * 0.5)).collect();
        let bvh = Bvh::build(&boxes);
        let collect = |tasks: &[Task]| {
            let mut v = Vec::new();
            for &t in tasks {
                traverse(&bvh, &bvh, true, t, |l| v.push((l.a, l.b)));
            }
            v.sort();
            v
        };
        let whole = collect(&[Task { a: 0, b: 0 }]);
        let split = collect(&split_tasks(&bvh, &bvh, true, 16));
        assert_eq!(whole, split);
        assert!(!whole.is_empty());
    }
}
