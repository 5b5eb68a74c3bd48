//! terawalk collision detection (Govindaraju 2004, ch. 5; docs/DESIGN.md "Where the new
//! capabilities go"): which triangles of a set of moving, deforming objects overlap.
//!
//! Modules, one algorithm each:
//! - [`tritri`]: the exact triangle–triangle test (Guigue–Devillers 2003, coplanar cases too).
//! - [`bvh`]: an AABB tree per object and the traversal of tree pairs.
//! - [`reference`](mod@reference): the exact CPU answer, every overlapping pair (rayon over subtree pairs).
//! - [`cullide`]: CULLIDE (two-pass potentially colliding sets from full-visibility queries on
//!   the GPU along x, y and z, object → sub-object → triangle), S-CULLIDE (strict test, for
//!   self-collision) and FAR (fattened primitives: nothing is missed at any resolution).
//! - [`fatten`]: FAR's oriented box around a triangle.
//! - [`sap`]: sweep-and-prune over boxes, between the culling and the exact tests.
//! - [`scenes`]: the thesis' scenes with generated motion.
//! - [`closest`]: exact closest points of a segment and a triangle.
//! - [`capsule`]: the walker's capsule moved through triangles (collide and slide, step up,
//!   land): the viewer's walk mode.
//! - [`nearby`]: the triangles of a store's resident clusters within a box, for [`capsule`].
//!
//! The GPU side is `tw_gpu::visibility` (plain draws and occlusion queries).

pub mod bvh;
pub mod capsule;
pub mod closest;
pub mod cullide;
pub mod fatten;
pub mod nearby;
pub mod reference;
pub mod sap;
pub mod scenes;
pub mod tritri;

pub use cullide::{Collider, Method, StepStats};
pub use reference::all_pairs;
pub use scenes::{Scene, SceneKind, SceneOptions};

/// An axis-aligned box (closed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub lo: [f32; 3],
    pub hi: [f32; 3],
}

impl Aabb {
    /// The empty box (the identity of [`Aabb::union`]).
    pub const EMPTY: Aabb = Aabb { lo: [f32::INFINITY; 3], hi: [f32::NEG_INFINITY; 3] };

    pub fn of_triangle(t: &[[f32; 3]; 3]) -> Aabb {
        t.iter().fold(Aabb::EMPTY, |b, &p| b.include(p))
    }

    pub fn include(self, p: [f32; 3]) -> Aabb {
        Aabb {
            lo: std::array::from_fn(|i| self.lo[i].min(p[i])),
            hi: std::array::from_fn(|i| self.hi[i].max(p[i])),
        }
    }

    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb {
            lo: std::array::from_fn(|i| self.lo[i].min(o.lo[i])),
            hi: std::array::from_fn(|i| self.hi[i].max(o.hi[i])),
        }
    }

    /// Whether the closed boxes share a point.
    pub fn overlaps(&self, o: &Aabb) -> bool {
        (0..3).all(|i| self.lo[i] <= o.hi[i] && o.lo[i] <= self.hi[i])
    }

    pub fn contains(&self, o: &Aabb) -> bool {
        (0..3).all(|i| self.lo[i] <= o.lo[i] && o.hi[i] <= self.hi[i])
    }

    pub fn center(&self) -> [f32; 3] {
        std::array::from_fn(|i| 0.5 * (self.lo[i] + self.hi[i]))
    }

    pub fn extent(&self) -> [f32; 3] {
        std::array::from_fn(|i| (self.hi[i] - self.lo[i]).max(0.0))
    }

    pub fn volume(&self) -> f32 {
        let e = self.extent();
        e[0] * e[1] * e[2]
    }

    pub fn longest_axis(&self) -> usize {
        let e = self.extent();
        if e[0] >= e[1] && e[0] >= e[2] {
            0
        } else if e[1] >= e[2] {
            1
        } else {
            2
        }
    }

    /// The box grown by `r` on every side.
    pub fn grow(&self, r: f32) -> Aabb {
        Aabb { lo: self.lo.map(|v| v - r), hi: self.hi.map(|v| v + r) }
    }
}

/// One object: an indexed triangle mesh. Triangles that share a vertex index are neighbours
/// (never a self-collision).
#[derive(Clone, Debug, Default)]
pub struct Object {
    pub positions: Vec<[f32; 3]>,
    pub triangles: Vec<[u32; 3]>,
    /// Whether pairs within this object count (cloth).
    pub self_collide: bool,
}

impl Object {
    /// The positions of triangle `t`.
    pub fn triangle(&self, t: u32) -> [[f32; 3]; 3] {
        self.triangles[t as usize].map(|i| self.positions[i as usize])
    }

    pub fn triangle_boxes(&self) -> Vec<Aabb> {
        (0..self.triangles.len() as u32).map(|t| Aabb::of_triangle(&self.triangle(t))).collect()
    }

    pub fn bounds(&self) -> Aabb {
        self.triangles.iter().flatten().fold(Aabb::EMPTY, |b, &i| b.include(self.positions[i as usize]))
    }
}

/// A triangle of a scene: its object and its index there.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct TriRef {
    pub object: u32,
    pub triangle: u32,
}

impl TriRef {
    pub fn new(object: usize, triangle: u32) -> TriRef {
        TriRef { object: object as u32, triangle }
    }
}

/// An overlapping pair of triangles, the smaller first.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Pair(pub TriRef, pub TriRef);

impl Pair {
    pub fn new(a: TriRef, b: TriRef) -> Pair {
        if a <= b {
            Pair(a, b)
        } else {
            Pair(b, a)
        }
    }
}

/// The triangles of all objects in a scene.
pub fn triangle_count(objects: &[Object]) -> usize {
    objects.iter().map(|o| o.triangles.len()).sum()
}
