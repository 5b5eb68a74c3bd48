//! Coordinate frames of an export.
//!
//! - *Input coordinates*: what the model file had, `grid_origin + g · grid_step` for a grid
//!   point `g` (docs/FORMAT.md, "Model"). Exported positions are these, in the input's units.
//! - *glTF*: +Y up (glTF 2.0, "Coordinate System and Units"). The GLB writer's root node turns
//!   the store's recorded up axis to +Y ([`tw_io::write::glb::UP_TO_Y_UP`]).
//! - *3D Tiles*: +Z up. glTF content is y-up and a 3D Tiles client turns it to z-up when it
//!   loads it (3D Tiles 1.1, "glTF transforms": a +90° turn about X, (x, y, z) → (x, −z, y)),
//!   so the tileset's bounding volumes are in that z-up frame: [`to_tileset`].

use tw_io::write::glb::UP_TO_Y_UP;
use tw_store::Header;

/// The input coordinates of grid point `g`.
#[inline]
pub fn grid_to_input(header: &Header, g: [u32; 3]) -> [f64; 3] {
    let o = header.grid_origin;
    let s = header.grid_step;
    [o[0] + g[0] as f64 * s, o[1] + g[1] as f64 * s, o[2] + g[2] as f64 * s]
}

/// The 3×3 part of a column-major glTF matrix applied to `p`.
fn apply(m: &[f64; 16], p: [f64; 3]) -> [f64; 3] {
    [
        m[0] * p[0] + m[4] * p[1] + m[8] * p[2],
        m[1] * p[0] + m[5] * p[1] + m[9] * p[2],
        m[2] * p[0] + m[6] * p[1] + m[10] * p[2],
    ]
}

/// Input coordinates to the 3D Tiles frame: scaled by `scale` (metres per unit), turned from
/// the store's up axis to glTF's +Y (what the GLB root node does), then from +Y to +Z (what the
/// 3D Tiles client does with glTF content). The store's up axis ends up along +Z.
pub fn to_tileset(up_axis: u8, scale: f64, p: [f64; 3]) -> [f64; 3] {
    let [x, y, z] = apply(&UP_TO_Y_UP[up_axis.min(2) as usize], p).map(|v| v * scale);
    [x, -z, y]
}

/// The axis-aligned box, in the 3D Tiles frame, of the input-coordinate box `min..max` (the
/// turns only permute and negate axes, so the box stays tight).
pub fn box_to_tileset(up_axis: u8, scale: f64, min: [f64; 3], max: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let a = to_tileset(up_axis, scale, min);
    let b = to_tileset(up_axis, scale, max);
    let lo = [a[0].min(b[0]), a[1].min(b[1]), a[2].min(b[2])];
    let hi = [a[0].max(b[0]), a[1].max(b[1]), a[2].max(b[2])];
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whatever the store's up axis, it comes out along the tileset's +Z, and the frame stays
    /// right-handed (x × y = z).
    #[test]
    fn store_up_becomes_tileset_z() {
        for axis in 0..3u8 {
            let mut up = [0.0; 3];
            up[axis as usize] = 1.0;
            assert_eq!(to_tileset(axis, 1.0, up), [0.0, 0.0, 1.0], "axis {axis}");
            let x = to_tileset(axis, 1.0, [1.0, 0.0, 0.0]);
            let y = to_tileset(axis, 1.0, [0.0, 1.0, 0.0]);
            let z = to_tileset(axis, 1.0, [0.0, 0.0, 1.0]);
            let cross = [x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]];
            assert_eq!(cross, z, "axis {axis}");
        }
        assert_eq!(to_tileset(2, 0.001, [1000.0, 2000.0, 3000.0]), [1.0, 2.0, 3.0]);
        let (lo, hi) = box_to_tileset(1, 1.0, [0.0, 0.0, 0.0], [1.0, 2.0, 3.0]);
        assert_eq!((lo, hi), ([0.0, -3.0, 0.0], [1.0, 0.0, 2.0]));
    }
}
