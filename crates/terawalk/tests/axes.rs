//! Up axes end to end: `build`'s default follows the input format (glTF is y-up), `--up auto`
//! estimates it from the triangles, and the build says which axis it chose and why.

mod common;

use std::path::Path;

use common::{stderr, stdout, terawalk};
use tw_io::{ObjectInfo, Triangle};

/// The 12 triangles of the box `lo`..`hi`.
fn boxed(lo: [f64; 3], hi: [f64; 3]) -> Vec<[[f64; 3]; 3]> {
    let c = |i: usize| {
        [
            if i & 1 == 0 { lo[0] } else { hi[0] },
            if i & 2 == 0 { lo[1] } else { hi[1] },
            if i & 4 == 0 { lo[2] } else { hi[2] },
        ]
    };
    let faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
    faces.iter().flat_map(|f| [[c(f[0]), c(f[1]), c(f[2])], [c(f[0]), c(f[2]), c(f[3])]]).collect()
}

/// Writes `triangles` as one object to `path` (format by extension) with tw-io's writers.
fn write(path: &Path, triangles: &[[[f64; 3]; 3]]) {
    let mut w = tw_io::write::create_writer(path).unwrap();
    w.object(0, &ObjectInfo { name: "part".into(), color: None }).unwrap();
    for t in triangles {
        w.triangle(&Triangle::new(*t, 0)).unwrap();
    }
    w.finish().unwrap();
}

/// The store's up axis and its extent along each axis.
fn up_and_extent(store: &Path) -> (u8, [f64; 3]) {
    let s = tw_store::Store::open(store).unwrap();
    let h = s.header();
    (h.up_axis, std::array::from_fn(|i| h.bounds_max[i] - h.bounds_min[i]))
}

/// A tower 2 × 2 wide and 10 tall along z (terawalk's writers take their scenes as z-up): as
/// GLB it is written y-up (glTF's convention) and built y-up by default; as PLY it stays z-up.
/// Either way the store stands upright: its tallest extent is along its up axis.
#[test]
fn gltf_builds_y_up_and_ply_z_up_by_default() {
    let dir = tempfile::tempdir().unwrap();
    let tower = boxed([0.0, 0.0, 0.0], [2.0, 2.0, 10.0]);
    for (name, up, why) in [
        ("t.glb", 1, "up: y (glTF convention)"),
        ("t.ply", 2, "up: z (default for PLY; use --up to override)"),
    ] {
        write(&dir.path().join(name), &tower);
        let o = terawalk(&["build", name, "-o", "t.tw", "--memory", "256M"], dir.path());
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        assert!(stdout(&o).contains(why), "{name}: {}", stdout(&o));
        let (axis, extent) = up_and_extent(&dir.path().join("t.tw"));
        assert_eq!(axis, up, "{name}");
        assert!((extent[up as usize] - 10.0).abs() < 1e-3, "{name}: not upright, extent {extent:?}");
        std::fs::remove_file(dir.path().join("t.tw")).unwrap();
    }
    // An explicit --up wins over the convention.
    let o = terawalk(&["build", "t.glb", "-o", "t.tw", "--memory", "256M", "--up", "z"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("up: z (--up)"), "{}", stdout(&o));
    assert_eq!(up_and_extent(&dir.path().join("t.tw")).0, 2);
}

/// A y-up building as PLY (three 20 × 20 floor slabs facing y, thin walls): `--up auto` finds y
/// and says why; a lone cube gives no evidence, so auto falls back to PLY's default.
#[test]
fn auto_up_finds_the_floors_or_abstains() {
    let dir = tempfile::tempdir().unwrap();
    let mut building = Vec::new();
    for floor in 0..3 {
        let y = 3.0 * floor as f64;
        building.extend(boxed([0.0, y, 0.0], [20.0, y + 0.2, 20.0]));
        building.extend(boxed([0.0, y, 0.0], [0.2, y + 3.0, 20.0]));
        building.extend(boxed([0.0, y, 0.0], [20.0, y + 3.0, 0.2]));
    }
    write(&dir.path().join("b.ply"), &building);
    let o = terawalk(&["build", "b.ply", "-o", "b.tw", "--memory", "256M", "--up", "auto"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("up: y (auto: "), "{}", stdout(&o));
    assert_eq!(up_and_extent(&dir.path().join("b.tw")).0, 1);

    write(&dir.path().join("c.ply"), &boxed([0.0; 3], [1.0; 3]));
    let o = terawalk(&["build", "c.ply", "-o", "c.tw", "--memory", "256M", "--up", "auto"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("up: z (auto abstained: ") && out.contains("default for PLY"), "{out}");
}
