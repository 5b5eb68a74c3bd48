//! Cluster BVHs built at run time against made from the store's shapes (`terawalk build
//! --rt-bvh`; docs/DESIGN.md D8): decodes the pages of a store with trees, then times
//! `ClusterBlas::build` (the SAH) and `ClusterBlas::from_tree` (refit of the stored shape) over
//! every cluster of those pages, alternating, on one thread; prints each round and the medians
//! in nanoseconds per triangle, and checks that both give the same BVH.
//!
//! `cargo run --release -p tw-rt --example stored_bvh_bench -- STORE [PAGES] [ROUNDS]`

use std::time::Instant;

use tw_rt::scene::blas::ClusterBlas;
use tw_store::Store;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let store = Store::open(&args[1]).expect("a store");
    assert!(store.has_rt_trees(), "build the store with --rt-bvh");
    let pages: usize = args.get(2).map_or(400, |a| a.parse().unwrap());
    let rounds: usize = args.get(3).map_or(5, |a| a.parse().unwrap());
    let step = store.header().grid_step;
    let n = store.pages().len();
    let decoded: Vec<_> =
        (0..pages.min(n)).map(|i| store.page_with_trees((i * n / pages.min(n)) as u32).unwrap()).collect();
    let clusters: Vec<_> = decoded.iter().flat_map(|(c, t)| c.iter().zip(t)).collect();
    let triangles: usize = clusters.iter().map(|(c, _)| c.triangle_count()).sum();
    for (c, t) in &clusters {
        let (a, b) = (ClusterBlas::build(c, step), ClusterBlas::from_tree(c, step, t));
        assert_eq!(format!("{:?}", a.bvh), format!("{:?}", b.bvh));
    }
    let (mut built, mut stored) = (Vec::new(), Vec::new());
    for r in 0..rounds {
        let t = Instant::now();
        let mut bytes = 0;
        for (c, _) in &clusters {
            bytes += ClusterBlas::build(c, step).bytes();
        }
        let b = t.elapsed().as_secs_f64() * 1e9 / triangles as f64;
        let t = Instant::now();
        for (c, tree) in &clusters {
            bytes += ClusterBlas::from_tree(c, step, tree).bytes();
        }
        let s = t.elapsed().as_secs_f64() * 1e9 / triangles as f64;
        println!(
            "round {r}: build {b:.1} ns/triangle, from stored shape {s:.1} ns/triangle ({:.2}x) [{bytes}]",
            b / s
        );
        built.push(b);
        stored.push(s);
    }
    built.sort_by(f64::total_cmp);
    stored.sort_by(f64::total_cmp);
    let (b, s) = (built[rounds / 2], stored[rounds / 2]);
    println!(
        "{} clusters, {triangles} triangles from {} pages: medians build {b:.1}, from stored shape {s:.1} ns/triangle ({:.2}x)",
        clusters.len(),
        decoded.len(),
        b / s
    );
}
