//! Dev-only: the shared test helpers. A generated scene (the procedural plant or a CAD
//! assembly of tw-io::generate) built by tw-build into a store in a temporary directory, once
//! per test process: every test of a binary that asks for the same scene with the same
//! `BuildOptions` gets the same store, which lives until the process ends.
//!
//! Tests use it as `[dev-dependencies] tw-testkit = { path = "../tw-testkit" }`; no library
//! crate depends on it.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

use tw_build::BuildOptions;
use tw_io::generate::{AssemblyObjects, AssemblyParams, AssemblySource, PlantParams, PlantSource};
use tw_io::TriangleSource;
use tw_store::Store;

/// A generated scene: what tw-io::generate makes, with its parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Generated {
    Plant(PlantParams),
    Assembly(AssemblyParams),
}

impl Generated {
    /// The generator as a triangle source.
    pub fn source(self) -> Box<dyn TriangleSource> {
        match self {
            Generated::Plant(p) => Box::new(PlantSource::new(p).unwrap()),
            Generated::Assembly(p) => Box::new(AssemblySource::new(p).unwrap()),
        }
    }
}

/// A built store; the temporary directory lives as long as this value.
pub struct Built {
    _dir: tempfile::TempDir,
    /// The store file.
    pub path: PathBuf,
    store: OnceLock<Arc<Store>>,
}

impl Built {
    /// The store file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The store, opened the first time it is asked for and shared after that.
    pub fn store(&self) -> Arc<Store> {
        self.store.get_or_init(|| Arc::new(Store::open(&self.path).unwrap())).clone()
    }
}

/// Builds `source` with `options` into `scene.tw` in a new temporary directory (not cached).
pub fn build(source: Box<dyn TriangleSource>, options: &BuildOptions) -> Built {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.tw");
    let scene = tw_io::Scene::from_sources(vec![source]);
    tw_build::build(scene, &path, options, &mut tw_build::NoProgress).unwrap();
    Built { _dir: dir, path, store: OnceLock::new() }
}

/// `make()`'s store, made once per process for `key`: the first caller with a key runs `make`,
/// the others wait for it and share its result. Different keys build in parallel.
pub fn once(key: String, make: impl FnOnce() -> Built) -> &'static Built {
    type Cells = HashMap<String, &'static OnceLock<Built>>;
    static CELLS: Mutex<Option<Cells>> = Mutex::new(None);
    let cell: &'static OnceLock<Built> = {
        let mut cells = CELLS.lock().unwrap_or_else(|e| e.into_inner());
        cells.get_or_insert_with(HashMap::new).entry(key).or_insert_with(|| Box::leak(Box::default()))
    };
    cell.get_or_init(make)
}

/// `scene` built with `options`, once per process for each scene and options.
pub fn built(scene: Generated, options: BuildOptions) -> &'static Built {
    once(format!("{scene:?} {options:?}"), || build(scene.source(), &options))
}

/// The plant of `triangles` with `seed`, built with `options` once per process.
pub fn plant(triangles: u64, seed: u64, options: BuildOptions) -> &'static Built {
    built(Generated::Plant(PlantParams { triangles, seed }), options)
}

/// The CAD assembly of `triangles` with `seed`, its parts grouped as `objects`, built with
/// `options` once per process.
pub fn assembly(
    triangles: u64,
    seed: u64,
    objects: AssemblyObjects,
    options: BuildOptions,
) -> &'static Built {
    built(Generated::Assembly(AssemblyParams { triangles, seed, objects }), options)
}
