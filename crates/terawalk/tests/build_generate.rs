//! `terawalk build --generate SPEC`: a generated scene built without a model file gives the
//! store that generating the file and building it gives; bad specs are refused clearly.

mod common;

use std::path::Path;

use common::{stderr, stdout, terawalk};
use tw_io::generate::{PlantParams, PlantSource};
use tw_io::{ImportError, ObjectId, ObjectInfo, SourceSummary, Triangle, TriangleSink, TriangleSource};

/// The streamed plant and the plant written to PLY and read back are the same scene, but not
/// the same bytes: PLY stores positions as f32 (the generator makes f64) and keeps no object
/// names or colours. So the store `--generate` builds has the PLY store's triangles, objects and
/// bounds (to f32 rounding), and the generator with exactly those two losses applied
/// ([`AsWrittenToPly`]) builds the PLY store byte for byte.
#[test]
fn generated_plant_builds_the_store_its_ply_file_builds() {
    let dir = tempfile::tempdir().unwrap();
    let common = ["--memory", "256M", "--threads", "2"];
    let o = terawalk(&["generate", "plant", "--triangles", "200k", "-o", "p.ply"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let o =
        terawalk(&[&["build", "p.ply", "-o", "file.tw", "--units", "m"][..], &common].concat(), dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let o =
        terawalk(&[&["build", "--generate", "plant:200k", "-o", "gen.tw"][..], &common].concat(), dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&o).contains("200,000 triangles"), "{}", stdout(&o));
    let o = terawalk(&["info", "gen.tw", "--verify"], dir.path());
    assert!(o.status.success() && stdout(&o).contains("verify: OK"), "{}", stdout(&o));
    assert!(stdout(&o).contains("units \"m\""), "{}", stdout(&o));
    same_scene(&dir.path().join("file.tw"), &dir.path().join("gen.tw"));

    let rounded = dir.path().join("rounded.tw");
    build_as_written_to_ply(&rounded);
    let (file, rounded) = (read(dir.path(), "file.tw"), std::fs::read(rounded).unwrap());
    assert!(file == rounded, "the stores differ ({} and {} bytes)", file.len(), rounded.len());
}

/// The two stores hold the same input: triangles, objects with their triangle counts, and
/// bounds within f32 rounding.
fn same_scene(a: &Path, b: &Path) {
    let (a, b) = (tw_store::Store::open(a).unwrap(), tw_store::Store::open(b).unwrap());
    let (ha, hb) = (a.header(), b.header());
    assert_eq!(ha.input_triangles, hb.input_triangles);
    assert_eq!(a.units(), b.units());
    let counts = |s: &tw_store::Store| s.objects().iter().map(|o| o.triangles).collect::<Vec<_>>();
    assert_eq!(counts(&a), counts(&b));
    for k in 0..3 {
        let extent = (ha.bounds_max[k] - ha.bounds_min[k]).max(1.0);
        assert!((ha.bounds_min[k] - hb.bounds_min[k]).abs() < 1e-6 * extent, "{ha:?} {hb:?}");
        assert!((ha.bounds_max[k] - hb.bounds_max[k]).abs() < 1e-6 * extent, "{ha:?} {hb:?}");
    }
}

/// Builds the 200k plant through the library with `build`'s options for `--memory 256M
/// --threads 2 --units m`, its positions rounded to f32 and its objects named and coloured as
/// the PLY reader names them (`p/ID`, no colour).
fn build_as_written_to_ply(output: &Path) {
    let plant = PlantSource::new(PlantParams { triangles: 200_000, seed: 1 }).unwrap();
    let scene = tw_io::Scene::from_sources(vec![Box::new(AsWrittenToPly(Box::new(plant)))]);
    let mut options = tw_build::BuildOptions { memory: 256 << 20, threads: Some(2), ..Default::default() };
    options.units = "m".into();
    options.lod.max_triangles = 128;
    options.hlod.max_triangles = 128;
    tw_build::build(scene, output, &options, &mut tw_build::NoProgress).unwrap();
}

/// A source as it reads back from terawalk's PLY file: f32 positions, no names or colours.
struct AsWrittenToPly(Box<dyn TriangleSource>);

impl TriangleSource for AsWrittenToPly {
    fn name(&self) -> String {
        self.0.name()
    }
    fn progress_total(&self) -> Option<u64> {
        self.0.progress_total()
    }
    fn stream(self: Box<Self>, sink: &mut dyn TriangleSink) -> Result<SourceSummary, ImportError> {
        self.0.stream(&mut Rounded(sink))
    }
}

struct Rounded<'a>(&'a mut dyn TriangleSink);

impl TriangleSink for Rounded<'_> {
    fn object(&mut self, id: ObjectId, _: &ObjectInfo) -> Result<(), ImportError> {
        self.0.object(id, &ObjectInfo { name: format!("p/{id}"), color: None })
    }
    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        let mut t = *t;
        t.positions = t.positions.map(|p| p.map(|v| v as f32 as f64));
        self.0.triangle(&t)
    }
}

#[test]
fn generated_assembly_is_in_millimetres_unless_told() {
    let dir = tempfile::tempdir().unwrap();
    let o = terawalk(&["build", "--generate", "assembly:30k,seed=3,one-object", "-o", "a.tw"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    let o = terawalk(&["info", "a.tw"], dir.path());
    assert!(
        stdout(&o).contains("units \"mm\"") && stdout(&o).contains("30,000 input triangles"),
        "{}",
        stdout(&o)
    );
    let o = terawalk(&["build", "--generate", "assembly:30k", "--units", "cm", "-o", "b.tw"], dir.path());
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stdout(&terawalk(&["info", "b.tw"], dir.path())).contains("units \"cm\""));
}

#[test]
fn bad_generate_arguments_are_refused_clearly() {
    let dir = tempfile::tempdir().unwrap();
    let refused = |args: &[&str], says: &str| {
        let o = terawalk(args, dir.path());
        assert!(!o.status.success() && stderr(&o).contains(says), "{args:?}: {}", stderr(&o));
    };
    refused(&["build", "--generate", "plant:200k"], "--generate needs -o");
    refused(&["build", "x.ply", "--generate", "plant:200k", "-o", "x.tw"], "cannot be used with");
    refused(&["build", "--generate", "tree:1M", "-o", "x.tw"], "unknown generator `tree`");
    refused(&["build", "--generate", "plant:1M,one-object", "-o", "x.tw"], "assembly only");
    refused(&["build", "--generate", "plant:100", "-o", "x.tw"], "100 triangles requested");
    refused(&["build", "--generate", "plant:1M,seed=x", "-o", "x.tw"], "seed must be");
    refused(&["build", "-o", "x.tw"], "required");
    assert!(!dir.path().join("x.tw").exists());
}

fn read(dir: &Path, name: &str) -> Vec<u8> {
    std::fs::read(dir.join(name)).unwrap()
}
