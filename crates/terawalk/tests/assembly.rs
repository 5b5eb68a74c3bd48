//! `terawalk generate assembly` end to end: generate a small CAD assembly in both object modes,
//! read it back, and build it into a store that verifies.

mod common;

use common::{stderr, stdout, terawalk};

#[test]
fn generate_assembly_then_stats_build_and_verify() {
    let dir = tempfile::tempdir().unwrap();
    let o =
        terawalk(&["generate", "assembly", "--triangles", "40001", "--seed", "3", "-o", "a.ply"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    // Closed parts have an even number of triangles: an odd request is rounded down.
    assert!(out.contains("40,000 triangles") && out.contains("millimetres"), "{out}");

    let o = terawalk(&["stats", "a.ply", "--json"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["files"][0]["triangles"], 40_000, "{v}");
    assert_eq!(v["files"][0]["degenerate_dropped"], 0, "{v}");
    let objects = v["files"][0]["objects"].as_u64().unwrap();
    assert!(objects > 500, "{objects} objects");

    let o = terawalk(
        &["build", "a.ply", "-o", "a.tw", "--memory", "256M", "--threads", "2", "--units", "mm"],
        dir.path(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["info", "a.tw", "--verify"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("40,000 input triangles") && out.contains("verify: OK"), "{out}");
    assert!(out.contains("units \"mm\""), "{out}");
}

#[test]
fn one_object_assembly_is_one_object_and_builds() {
    let dir = tempfile::tempdir().unwrap();
    let args = ["generate", "assembly", "--triangles", "30k", "--one-object", "-o", "one.ply"];
    let o = terawalk(&args, dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("30,000 triangles in 1 objects"), "{}", stdout(&o));
    let o = terawalk(&["stats", "one.ply", "--json"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["files"][0]["objects"], 1, "{v}");
    let o = terawalk(&["build", "one.ply", "-o", "one.tw", "--memory", "256M", "--threads", "2"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["info", "one.tw", "--verify"], dir.path());
    assert!(o.status.success() && stdout(&o).contains("verify: OK"), "{}", stdout(&o));
}

#[test]
fn one_object_is_refused_for_the_plant_and_sizes_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let o = terawalk(&["generate", "plant", "--triangles", "20k", "--one-object", "-o", "p.ply"], dir.path());
    assert!(!o.status.success() && stderr(&o).contains("--one-object"), "{}", stderr(&o));
    let o = terawalk(&["generate", "assembly", "--triangles", "2e9", "-o", "a.ply"], dir.path());
    assert!(!o.status.success() && stderr(&o).contains("2000000000 triangles requested"), "{}", stderr(&o));
    assert!(!dir.path().join("a.ply").exists());
    let o = terawalk(&["generate", "--help"], dir.path());
    assert!(stdout(&o).contains("generate assembly --triangles 24M --one-object"), "{}", stdout(&o));
}
