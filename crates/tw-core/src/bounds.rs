//! Axis-aligned bounding boxes in f64.

/// An axis-aligned box. [`Aabb::EMPTY`] has `min > max` and grows to the first point added.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: [f64; 3],
    pub max: [f64; 3],
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The empty box: contains nothing, and `grow` of any point gives that point.
    pub const EMPTY: Aabb = Aabb { min: [f64::INFINITY; 3], max: [f64::NEG_INFINITY; 3] };

    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a [f64; 3]>) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in points {
            b.grow(*p);
        }
        b
    }

    pub fn is_empty(&self) -> bool {
        (0..3).any(|i| self.min[i] > self.max[i])
    }

    pub fn grow(&mut self, p: [f64; 3]) {
        for (i, v) in p.into_iter().enumerate() {
            self.min[i] = self.min[i].min(v);
            self.max[i] = self.max[i].max(v);
        }
    }

    pub fn union(&self, other: &Aabb) -> Aabb {
        let mut b = *self;
        for i in 0..3 {
            b.min[i] = b.min[i].min(other.min[i]);
            b.max[i] = b.max[i].max(other.max[i]);
        }
        b
    }

    /// Size along each axis; zero for an empty box.
    pub fn extent(&self) -> [f64; 3] {
        if self.is_empty() {
            return [0.0; 3];
        }
        [self.max[0] - self.min[0], self.max[1] - self.min[1], self.max[2] - self.min[2]]
    }

    pub fn center(&self) -> [f64; 3] {
        [
            0.5 * (self.min[0] + self.max[0]),
            0.5 * (self.min[1] + self.max[1]),
            0.5 * (self.min[2] + self.max[2]),
        ]
    }

    /// Length of the diagonal; zero for an empty box.
    pub fn diagonal(&self) -> f64 {
        let e = self.extent();
        (e[0] * e[0] + e[1] * e[1] + e[2] * e[2]).sqrt()
    }

    pub fn contains_point(&self, p: [f64; 3]) -> bool {
        (0..3).all(|i| p[i] >= self.min[i] && p[i] <= self.max[i])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_box_has_no_extent_and_grows_to_a_point() {
        let mut b = Aabb::EMPTY;
        assert!(b.is_empty());
        assert_eq!(b.extent(), [0.0; 3]);
        b.grow([1.0, 2.0, 3.0]);
        assert!(!b.is_empty());
        assert_eq!(b.min, [1.0, 2.0, 3.0]);
        assert_eq!(b.max, [1.0, 2.0, 3.0]);
    }

    #[test]
    fn union_contains_both() {
        let a = Aabb::from_points(&[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0]]);
        let b = Aabb::from_points(&[[2.0, -1.0, 0.5]]);
        let u = a.union(&b);
        assert!(u.contains_point([2.0, -1.0, 0.5]));
        assert!(u.contains_point([0.0, 1.0, 1.0]));
        assert_eq!(u.extent(), [2.0, 2.0, 1.0]);
        assert_eq!(Aabb::EMPTY.union(&a), a);
    }
}
