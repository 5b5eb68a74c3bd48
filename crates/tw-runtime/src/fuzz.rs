//! Entry points of the fuzz targets in fuzz/ that reach the runtime: bytes in, any error
//! allowed, no panic, no unbounded allocation. The tests below feed every file of their corpus
//! and of fuzz/regressions through the same functions in the ordinary test run.
//!
//! - [`camera_path`]: the camera path JSON (`bench --path`, `view --path`).
//! - [`store_geometry`]: a store written by [`StoreWriter`] from fuzzed geometry (grid
//!   coordinates anywhere in the u32 grid, degenerate and repeated triangles, extreme grid steps
//!   and origins, non-finite spheres and errors), optionally with bytes of the written file
//!   flipped; opened, verified, every page decoded into a [`ResidentPage`], and cuts selected
//!   from it for cameras derived from its header — what `render`, `bench` and the viewer do
//!   with a store before drawing it.
//! - [`store_bytes`]: arbitrary bytes as a store, through both readers and the runtime.

use tw_store::{Group, Node, Object, PageCluster, Store, StoreInfo, StoreWriter};

use crate::cache::{PageCache, ResidentPage};
use crate::camera::Camera;
use crate::path::CameraPath;
use crate::select::{SelectOptions, Selector};

/// Parses `data` as a camera path file, then derives every frame's camera for a store of unit
/// bounds (as `bench` does before rendering).
pub fn camera_path(data: &[u8]) -> Result<usize, String> {
    let path = CameraPath::parse(data)?;
    let header = tw_store::Header::empty([0.0; 3], [1.0; 3], [0.0; 3], 1.0 / 16_777_215.0);
    for frame in &path.frames {
        let _ = frame.to_scene(&header);
    }
    Ok(path.frames.len())
}

/// The `store` target: `data` as a `scene.tw`, written to a temporary file and opened
/// (memory-mapped), verified, every page decoded and every group's links read; the same through
/// the in-memory reader ([`tw_store::fuzz_bytes`]); then [`store_in_runtime`].
///
/// # Panics
/// When the memory-mapped and the in-memory reader disagree on whether the bytes are a store
/// (a reader bug for the fuzzer to find).
pub fn store_bytes(data: &[u8]) {
    use std::io::Write;
    let Ok(mut file) = tempfile::NamedTempFile::new() else { return };
    if file.write_all(data).is_err() {
        return;
    }
    let from_file = Store::open(file.path());
    if let Ok(store) = &from_file {
        let _ = store.verify(|_, _| {});
        for i in 0..store.pages().len() as u32 {
            let _ = store.page(i);
        }
        // The group links (one index past the table too).
        for g in 0..=store.groups().len() as u32 {
            let _ = (store.group_sources(g), store.group_parents(g));
        }
    }
    let from_bytes = Store::from_bytes(data.to_vec());
    assert_eq!(from_file.is_ok(), from_bytes.is_ok(), "the file and the in-memory reader disagree");
    tw_store::fuzz_bytes(data);
    if let Ok(store) = &from_bytes {
        store_in_runtime(store);
    }
}

/// The runtime's use of an opened store: every page decoded as a [`ResidentPage`], and a cut
/// selected for a few cameras derived from the header (page loads through a [`PageCache`]).
pub fn store_in_runtime(store: &Store) {
    for i in 0..store.pages().len() as u32 {
        if let Ok((clusters, trees)) = store.page_with_trees(i) {
            let page = ResidentPage::with_trees(clusters, trees);
            let _ = (page.info().len(), page.steps().len(), page.bytes());
        }
    }
    let selector = Selector::new(store);
    let cache = PageCache::new(store, 64 << 20);
    for camera in cameras(store.header()) {
        for tau in [1.0, 0.01] {
            let options = SelectOptions { tau, ..Default::default() };
            let _ = selector.select(store, &cache, &camera, &options);
        }
    }
}

/// Cameras that see the store's bounds: from outside a corner, from the centre, from above.
fn cameras(h: &tw_store::Header) -> Vec<Camera> {
    let (lo, hi) = (h.bounds_min, h.bounds_max);
    let centre: [f64; 3] = std::array::from_fn(|a| (lo[a] + hi[a]) / 2.0);
    let outside: [f64; 3] = std::array::from_fn(|a| hi[a] + (hi[a] - lo[a]));
    let ahead: [f64; 3] = std::array::from_fn(|a| centre[a] + if a == 0 { 1.0 } else { 0.0 });
    let above: [f64; 3] = std::array::from_fn(|a| if a == 2 { hi[a] + 1.0 } else { centre[a] });
    [(outside, centre, [0.0, 0.0, 1.0]), (centre, ahead, [0.0, 0.0, 1.0]), (above, centre, [0.0, 1.0, 0.0])]
        .into_iter()
        .filter_map(|(eye, target, up)| Camera::from_input_coordinates(eye, target, up, 60.0, h).ok())
        .collect()
}

/// Builds a store from `data` (the layout is `Geometry::read`'s), then runs it through the
/// reader and the runtime. Bytes the writer refuses (a non-finite sphere, a table invariant)
/// end the run: refusing them is the writer's validation at work.
pub fn store_geometry(data: &[u8]) {
    let mut bytes = Bytes(data);
    let geometry = Geometry::read(&mut bytes);
    let Ok(dir) = tempfile::tempdir() else { return };
    let path = dir.path().join("scene.tw");
    if geometry.write(&path).is_err() {
        return;
    }
    if let Ok(store) = Store::open(&path) {
        let _ = store.verify(|_, _| {});
        store_in_runtime(&store);
    }
    // The rest of the input: (offset, xor) pairs flipped in the written file, which the
    // reader must refuse or survive (its checksums are off under `cfg(fuzzing)`).
    let Ok(mut file) = std::fs::read(&path) else { return };
    let mut flipped = false;
    while let (Some(hi), Some(lo), Some(x)) = (bytes.u8(), bytes.u8(), bytes.u8()) {
        if let Some(b) = file.get_mut(usize::from(u16::from_le_bytes([lo, hi]))) {
            *b ^= x;
            flipped = true;
        }
    }
    if flipped {
        if let Ok(store) = Store::from_bytes(file) {
            let _ = store.verify(|_, _| {});
            store_in_runtime(&store);
        }
    }
}

/// Little-endian fields from the front of the fuzz input; `None` once it is used up.
struct Bytes<'a>(&'a [u8]);

impl Bytes<'_> {
    fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let (head, rest) = self.0.split_first_chunk::<N>()?;
        self.0 = rest;
        Some(*head)
    }
    fn u8(&mut self) -> Option<u8> {
        self.take::<1>().map(|[b]| b)
    }
    fn u32(&mut self) -> u32 {
        self.take().map_or(0, u32::from_le_bytes)
    }
    fn f32(&mut self) -> f32 {
        self.take().map_or(0.0, f32::from_le_bytes)
    }
    fn f64(&mut self) -> f64 {
        self.take().map_or(0.0, f64::from_le_bytes)
    }
    fn vec3(&mut self) -> [f64; 3] {
        [self.f64(), self.f64(), self.f64()]
    }
}

/// A fuzzed scene: one root node holding one group per page, every group a root group.
struct Geometry {
    info: StoreInfo,
    pages: Vec<(Vec<PageCluster>, [f32; 4])>,
    /// Write a ray-tracing tree after every cluster (`RtTree::halving`).
    rt_trees: bool,
}

impl Geometry {
    /// Layout: grid step (f64), grid origin, bounds min, bounds max (3 × f64 each), the page
    /// count − 1 (u8, mod 4; bit 7: ray-tracing trees); per page the group sphere (4 × f32), the cluster count − 1 (u8,
    /// mod 4); per cluster the triangle count − 1 (u8, mod 128), vertex count − 1 (u8), level
    /// (u8), self error and self sphere (5 × f32), the positions (3 × u32 each), three indices
    /// per triangle (u8, reduced modulo the vertex count) and an object id per triangle (u8,
    /// mod 4). Missing bytes read as zeros.
    fn read(r: &mut Bytes<'_>) -> Geometry {
        let grid_step = r.f64();
        let info = StoreInfo {
            grid_step,
            grid_origin: r.vec3(),
            bounds_min: r.vec3(),
            bounds_max: r.vec3(),
            units: "m".into(),
            up_axis: 2,
            build_options: String::new(),
            input_triangles: 0,
        };
        let count_byte = r.u8().unwrap_or(0);
        let (page_count, rt_trees) = (count_byte % 4 + 1, count_byte & 0x80 != 0);
        let mut pages = Vec::new();
        for _ in 0..page_count {
            let sphere = [r.f32(), r.f32(), r.f32(), r.f32()];
            let cluster_count = r.u8().unwrap_or(0) % 4 + 1;
            let clusters = (0..cluster_count).map(|_| Self::cluster(r, pages.len() as u32)).collect();
            pages.push((clusters, sphere));
        }
        let mut g = Geometry { info, pages, rt_trees };
        g.info.input_triangles = g.pages.iter().flat_map(|p| &p.0).map(|c| c.triangle_count() as u64).sum();
        g
    }

    fn cluster(r: &mut Bytes<'_>, group: u32) -> PageCluster {
        let t = usize::from(r.u8().unwrap_or(0) % 128) + 1;
        let v = usize::from(r.u8().unwrap_or(0)) % tw_store::MAX_VERTICES + 1;
        let level = r.u8().unwrap_or(0);
        let self_error = r.f32();
        let self_sphere = [r.f32(), r.f32(), r.f32(), r.f32()];
        let positions = (0..v).map(|_| [r.u32(), r.u32(), r.u32()]).collect();
        let indices = (0..3 * t).map(|_| (usize::from(r.u8().unwrap_or(0)) % v) as u8).collect();
        let objects = (0..t).map(|_| u32::from(r.u8().unwrap_or(0) % 4)).collect();
        PageCluster { positions, indices, objects, self_error, self_sphere, group, level }
    }

    /// Writes the store: page `i` holds group `i`, attached to the single node, whose box is the
    /// grid box of every position.
    fn write(&self, path: &std::path::Path) -> Result<(), tw_store::StoreError> {
        let mut w = StoreWriter::create(path)?;
        let (mut min, mut max) = ([u32::MAX; 3], [0u32; 3]);
        let mut groups = Vec::new();
        for (i, (clusters, sphere)) in self.pages.iter().enumerate() {
            for p in clusters.iter().flat_map(|c| &c.positions) {
                for a in 0..3 {
                    min[a] = min[a].min(p[a]);
                    max[a] = max[a].max(p[a]);
                }
            }
            let page = if self.rt_trees {
                let mut encoded = Vec::new();
                for c in clusters {
                    let mut e = tw_store::EncodedCluster::new(c).map_err(tw_store::StoreError::Invalid)?;
                    tw_store::RtTree::halving(c.triangle_count())
                        .encode(c.triangle_count(), &mut e.bytes)
                        .map_err(tw_store::StoreError::Invalid)?;
                    encoded.push(e);
                }
                w.set_rt_trees(true);
                w.add_encoded_page(&encoded, true)?
            } else {
                w.add_page(clusters, true)?
            };
            groups.push(Group {
                sphere: *sphere,
                error: f32::INFINITY,
                node: 0,
                level: clusters.iter().map(|c| c.level).max().unwrap_or(0),
                page,
                first_cluster: 0,
                cluster_count: clusters.len() as u32,
                triangles: clusters.iter().map(|c| c.triangle_count() as u32).sum(),
                source_count: 0,
            });
            debug_assert_eq!(page as usize, i);
        }
        let node = Node {
            min,
            max,
            first_child: 0,
            child_count: 0,
            first_group: 0,
            group_count: groups.len() as u32,
            max_error: f32::INFINITY,
        };
        let objects = vec![Object::default(); 4];
        w.finish(&self.info, &objects, &[node], &groups, &[])?;
        Ok(())
    }
}

/// The committed corpus and every crasher found so far, through the entry points above.
#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use tw_io::fuzz::replay_corpus as replay;

    #[test]
    fn path_corpus_replays() {
        replay("path", |d| drop(super::camera_path(d)));
    }

    #[test]
    fn store_corpus_replays() {
        replay("store", super::store_bytes);
    }

    #[test]
    fn store_geometry_corpus_replays() {
        replay("store_geometry", super::store_geometry);
    }

    /// The seeds are valid: the path parses, the geometry seeds write a store that opens and
    /// verifies (a seed that stopped being valid would leave the fuzzer starting from nothing).
    #[test]
    fn seeds_are_valid() {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus");
        let path = std::fs::read(dir.join("path/walk.json")).unwrap();
        assert_eq!(super::camera_path(&path), Ok(3));
        for name in ["quad.bin", "extreme.bin", "quad-rt.bin"] {
            let data = std::fs::read(dir.join("store_geometry").join(name)).unwrap();
            let geometry = super::Geometry::read(&mut super::Bytes(&data));
            let tmp = tempfile::tempdir().unwrap();
            let file = tmp.path().join("scene.tw");
            geometry.write(&file).unwrap_or_else(|e| panic!("{name}: {e}"));
            let store = tw_store::Store::open(&file).unwrap();
            store.verify(|_, _| {}).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(store.has_rt_trees(), name == "quad-rt.bin", "{name}");
        }
    }
}
