//! Where the triangles of one frame's LOD cut come from: a diagnostic for the DAG (how the cut of
//! an overview was found to sit on groups whose next step was 8–16 times coarser; see
//! docs/benchmarks-log.md, "Assemblies", session 26).
//!
//! ```text
//! cargo run --release -p tw-runtime --example cut_profile -- STORE PATH.json [FRAME] [TAU] [nofrustum]
//! ```
//!
//! Selects the cut of frame `FRAME` (default 0) of the camera path at τ = `TAU` (default 1) on a
//! 1280×720 screen, every page loaded, with frustum culling (unless `nofrustum`), and prints its
//! triangles by whether their next step is an HLOD step (a subtree's roots) or one inside their
//! node, by level,
//! by the cluster's own error and by its group's error (in pixels, half-octave buckets), by
//! the ratio of the two (the size of the step the cut stands on), by the radius of the connected
//! parts inside each cluster (in pixels), how many are exact duplicates (the same three
//! vertices as another triangle of their cluster), and how much of the pages the cut needs it
//! draws (decoded bytes of the drawn clusters against those of the pages it draws from and of
//! every page the traversal looked up).

use std::collections::BTreeMap;
use std::sync::Arc;

use tw_runtime::{CameraPath, LodMetric, PageCache, SelectOptions, Selector};
use tw_store::{PageCluster, Store};

/// Half-octave bucket of a positive value (`2·log2`, rounded down); `i32::MIN` for zero.
fn bucket(v: f64) -> i32 {
    if v > 0.0 {
        (v.log2() * 2.0).floor() as i32
    } else {
        i32::MIN
    }
}

fn print_buckets(title: &str, unit: &str, map: &BTreeMap<i32, u64>) {
    println!("{title}:");
    let mut total = 0;
    for (&k, &v) in map {
        total += v;
        let from = if k == i32::MIN { 0.0 } else { 2f64.powf(k as f64 / 2.0) };
        println!("  ≥ {from:>9.3} {unit}: {v:>10}  (cumulative {total})");
    }
}

/// The connected parts of a cluster (triangles sharing a vertex): per part, its triangles and
/// half its box diagonal in grid units.
fn cluster_parts(c: &PageCluster) -> Vec<(u64, f64)> {
    let n = c.positions.len();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    for t in c.indices.chunks_exact(3) {
        for &v in &t[1..] {
            let (a, b) = (find(&mut parent, t[0] as usize), find(&mut parent, v as usize));
            parent[a.max(b)] = a.min(b);
        }
    }
    let mut lo = vec![[u32::MAX; 3]; n];
    let mut hi = vec![[0u32; 3]; n];
    let mut count = vec![0u64; n];
    for t in c.indices.chunks_exact(3) {
        let r = find(&mut parent, t[0] as usize);
        count[r] += 1;
        for &v in t {
            let q = c.positions[v as usize];
            for i in 0..3 {
                lo[r][i] = lo[r][i].min(q[i]);
                hi[r][i] = hi[r][i].max(q[i]);
            }
        }
    }
    (0..n)
        .filter(|&r| count[r] > 0)
        .map(|r| {
            let d2: f64 = (0..3).map(|i| ((hi[r][i] - lo[r][i]) as f64).powi(2)).sum();
            (count[r], d2.sqrt() * 0.5)
        })
        .collect()
}

/// Triangles of `c` with the same three vertices as an earlier one.
fn duplicates(c: &PageCluster) -> u64 {
    let mut seen = std::collections::HashSet::new();
    c.indices
        .chunks_exact(3)
        .filter(|t| {
            let mut k = [t[0], t[1], t[2]];
            k.sort_unstable();
            !seen.insert(k)
        })
        .count() as u64
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: cut_profile STORE PATH.json [FRAME] [TAU] [nofrustum]");
        std::process::exit(2);
    }
    let store = Arc::new(Store::open(std::path::Path::new(&args[1])).expect("store"));
    let path = CameraPath::load(std::path::Path::new(&args[2])).expect("path");
    let frame: usize = args.get(3).map_or(0, |s| s.parse().expect("FRAME"));
    let tau: f32 = args.get(4).map_or(1.0, |s| s.parse().expect("TAU"));
    let camera = path.frames.get(frame).expect("no such frame").to_scene(store.header()).expect("camera");
    let cache = PageCache::new(&store, u64::MAX / 4);
    let frustum_culling = args.get(5).is_none_or(|s| s != "nofrustum");
    let options = SelectOptions { tau, frustum_culling, ..SelectOptions::default() };
    let selection = Selector::new(&store).select(&store, &cache, &camera, &options);
    let metric = LodMetric::new(&camera, options.viewport[1] as f32);
    let step = store.header().grid_step;

    let mut by_level: BTreeMap<i32, u64> = BTreeMap::new();
    let (mut own, mut group, mut ratio, mut parts) =
        (BTreeMap::new(), BTreeMap::new(), BTreeMap::new(), BTreeMap::new());
    let mut duplicate = 0;
    // Triangles whose group is replaced by a group of another node (a subtree's root, replaced
    // by HLOD) against those replaced inside their own node.
    let (mut replaced_by_hlod, mut replaced_inside) = (0u64, 0u64);
    // Groups of leaf nodes (cells) and of inner nodes (HLOD), and the step ratios of each.
    let nodes = store.nodes();
    let (mut cell_ratio, mut hlod_ratio) = (BTreeMap::new(), BTreeMap::new());
    let mut spread = BTreeMap::new();
    let mut object_ratio = BTreeMap::new();
    // Triangles whose group's error, seen from the cluster's own sphere rather than the group's,
    // would be within τ: what the size of the group's sphere alone keeps in the cut.
    let (mut sphere_bound, mut sphere_bound_leaf) = (0u64, 0u64);
    let touched = cache.stats().resident_bytes;
    let mut drawn_pages: BTreeMap<u32, u64> = BTreeMap::new();
    let mut drawn_bytes = 0u64;
    // Per page level: (decoded bytes of the pages drawn from, bytes of the clusters drawn).
    let mut page_use: BTreeMap<u8, (u64, u64)> = BTreeMap::new();
    for c in &selection.clusters {
        let page = cache.get(&store, c.page).expect("page");
        let info = page.info()[c.index_in_page as usize];
        let cluster = &page.clusters[c.index_in_page as usize];
        let (error, sphere) = page.steps()[info.step as usize];
        let g = &store.groups()[c.group as usize];
        let t = info.triangles as u64;
        let level = store.pages()[c.page as usize].level_max;
        if drawn_pages.insert(c.page, page.bytes() as u64).is_none() {
            page_use.entry(level).or_default().0 += page.bytes() as u64;
        }
        let bytes = 12 * cluster.positions.len() as u64 + 7 * t;
        drawn_bytes += bytes;
        page_use.entry(level).or_default().1 += bytes;
        let own_px = metric.sphere(error, sphere);
        let group_px = metric.sphere(g.error, g.sphere);
        *by_level.entry(cluster.level as i32).or_default() += t;
        let parents = store.group_parents(c.group);
        if parents.iter().any(|&p| store.groups()[p as usize].node != g.node) {
            replaced_by_hlod += t;
        } else {
            replaced_inside += t;
        }
        *own.entry(bucket(own_px)).or_default() += t;
        *group.entry(bucket(group_px)).or_default() += t;
        if own_px > 0.0 {
            *ratio.entry(bucket(group_px / own_px)).or_default() += t;
            let leaf = nodes.get(g.node as usize).is_some_and(|n| n.child_count == 0);
            let by_kind = if leaf { &mut cell_ratio } else { &mut hlod_ratio };
            *by_kind.entry(bucket(group_px / own_px)).or_default() += t;
        }
        // The largest own error among the group's members: a cluster far below it waits for
        // its siblings (a group has one error).
        let members = page.info()[g.first_cluster as usize..(g.first_cluster + g.cluster_count) as usize]
            .iter()
            .map(|i| page.steps()[i.step as usize].0)
            .fold(0.0f32, f32::max);
        if metric.sphere(g.error, sphere) <= tau as f64 {
            sphere_bound += t;
            if nodes.get(g.node as usize).is_some_and(|n| n.child_count == 0) {
                sphere_bound_leaf += t;
            }
        }
        if error > 0.0 {
            *object_ratio.entry(bucket((g.error / error) as f64)).or_default() += t;
            *spread.entry(bucket((members / error) as f64)).or_default() += t;
        }
        for (count, radius) in cluster_parts(cluster) {
            let px = metric.sphere((radius * step) as f32, sphere);
            *parts.entry(bucket(px)).or_default() += count;
        }
        duplicate += duplicates(cluster);
    }
    println!("cut at τ = {tau}: {} clusters, {} triangles", selection.clusters.len(), selection.triangles);
    println!(
        "by the next step: {replaced_by_hlod} triangles in a subtree's roots (replaced by HLOD), \
         {replaced_inside} in groups replaced inside their node"
    );
    println!("by level:");
    for (k, v) in &by_level {
        println!("  L{k}: {v}");
    }
    print_buckets("by the cluster's own error", "px", &own);
    print_buckets("by its group's error (the next step)", "px", &group);
    print_buckets("by group error ÷ own error", "×", &ratio);
    print_buckets("the same, groups of cells (leaf nodes)", "×", &cell_ratio);
    print_buckets("the same, groups of HLOD (inner nodes)", "×", &hlod_ratio);
    print_buckets("by group error ÷ own error, object space", "×", &object_ratio);
    print_buckets("by the group's largest member own error ÷ own error", "×", &spread);
    print_buckets("by the radius of connected parts inside clusters", "px", &parts);
    println!(
        "held by the group's sphere alone (its error within τ from the cluster's own sphere): {sphere_bound} \
         triangles, {sphere_bound_leaf} of them in groups of cells"
    );
    println!("exact duplicate triangles (same vertices in one cluster): {duplicate}");
    let from: u64 = drawn_pages.values().sum();
    let mb = |b: u64| b as f64 / 1e6;
    println!(
        "pages: {:.1} MB decoded looked up by the traversal, {:.1} MB in the {} pages drawn from; \
         the drawn clusters {:.1} MB ({:.1} % of the pages drawn from)",
        mb(touched),
        mb(from),
        drawn_pages.len(),
        mb(drawn_bytes),
        100.0 * drawn_bytes as f64 / from.max(1) as f64
    );
    for (level, (pages, drawn)) in &page_use {
        println!(
            "  pages of level {level}: {:.1} MB drawn from, {:.1} MB drawn ({:.1} %)",
            mb(*pages),
            mb(*drawn),
            100.0 * *drawn as f64 / (*pages).max(1) as f64
        );
    }
}
