//! Union-find over dense ids, for the connected parts of a mesh (`crate::clusterlod`,
//! `crate::hlod`). Path halving; of two roots the smaller id wins, so a part's root is its
//! smallest id whatever the order of the unions.

/// A forest of `n` ids, each its own set at first.
pub(crate) struct UnionFind {
    parent: Vec<u32>,
}

impl UnionFind {
    pub fn new(n: usize) -> UnionFind {
        UnionFind { parent: (0..n as u32).collect() }
    }

    /// The root of `v`'s set.
    pub fn find(&mut self, mut v: u32) -> u32 {
        while self.parent[v as usize] != v {
            let g = self.parent[self.parent[v as usize] as usize];
            self.parent[v as usize] = g;
            v = g;
        }
        v
    }

    /// Joins the sets of `a` and `b`.
    pub fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.parent[ra.max(rb) as usize] = ra.min(rb);
        }
    }

    /// Joins the three corners of every triangle of `indices` (ids mapped by `id`).
    pub fn union_triangles(&mut self, indices: &[u32], id: impl Fn(u32) -> u32) {
        for t in indices.chunks_exact(3) {
            self.union(id(t[0]), id(t[1]));
            self.union(id(t[0]), id(t[2]));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_triangle_joining_three_sets_makes_one() {
        // Roots 5, 3 and 1: joining 5 with 3, then 5 with 1, must keep 3 in the set (a union that
        // reuses 5 as if it were still a root would lose it).
        let mut u = UnionFind::new(6);
        u.union_triangles(&[5, 3, 1], |v| v);
        assert_eq!((u.find(5), u.find(3), u.find(1)), (1, 1, 1));
        assert_eq!(u.find(0), 0);
    }
}
