//! Times the streamed selection (`Streamer::frame`: the cut and the prefetch views) along a
//! camera path, without a GPU, and fingerprints every frame's cut so that two builds can be
//! checked for identical output.
//!
//! ```text
//! cargo run --release -p tw-runtime --example select_bench -- STORE PATH.json [MEMORY_MIB] [LOADS_PER_FRAME] [OUT.tsv] [LOADER_THREADS]
//! ```
//!
//! Pages are loaded on the caller's thread between frames (`LOADS_PER_FRAME`, default 64;
//! untimed), so the residency, and thus every cut, is the same from run to run. With
//! `LOADER_THREADS` > 0 they are loaded in the background as in a walkthrough instead (the
//! frames are then `LOADS_PER_FRAME` ms apart, and not reproducible).

use std::hash::{Hash, Hasher};
use std::sync::Arc;
use std::time::Instant;

use tw_runtime::{CameraPath, SelectOptions, StreamOptions, Streamer};

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: select_bench STORE PATH.json [MEMORY_MIB] [LOADS_PER_FRAME] [OUT.tsv]");
        std::process::exit(2);
    }
    let store = Arc::new(tw_store::Store::open(std::path::Path::new(&args[1])).expect("store"));
    let path = CameraPath::load(std::path::Path::new(&args[2])).expect("path");
    let mib: u64 = args.get(3).map_or(512, |s| s.parse().expect("MEMORY_MIB"));
    let loads: usize = args.get(4).map_or(64, |s| s.parse().expect("LOADS_PER_FRAME"));
    let threads: usize = args.get(6).map_or(0, |s| s.parse().expect("LOADER_THREADS"));
    let options = StreamOptions { budget_bytes: mib << 20, loader_threads: threads, ..Default::default() };
    let mut streamer = Streamer::new(store.clone(), options).expect("streamer");
    let select = SelectOptions::default();
    let mut rows = Vec::new();
    let mut all = std::collections::hash_map::DefaultHasher::new();
    for (i, f) in path.frames.iter().enumerate() {
        let cam = f.to_scene(store.header()).expect("camera");
        let t = Instant::now();
        let frame = streamer.frame(&cam, &select);
        let total = t.elapsed().as_secs_f64() * 1e3;
        let mut h = std::collections::hash_map::DefaultHasher::new();
        frame.selection.clusters.hash(&mut h);
        let s = &frame.stats;
        (s.pages_requested, s.prefetch_requested, s.stalls_avoided, s.clusters_fallback).hash(&mut h);
        let fp = h.finish();
        fp.hash(&mut all);
        rows.push((
            i,
            f.segment.clone(),
            total,
            frame.times.cut.as_secs_f64() * 1e3,
            frame.times.prefetch.as_secs_f64() * 1e3,
            frame.selection.clusters.len(),
            frame.selection.stats.nodes_visited,
            frame.selection.stats.groups_tested,
            s.pages_requested,
            s.prefetch_requested,
            fp,
        ));
        drop(frame);
        if threads == 0 {
            streamer.load_queued(loads);
        } else {
            std::thread::sleep(std::time::Duration::from_millis(loads as u64));
        }
    }
    if let Some(out) = args.get(5).filter(|o| *o != "-") {
        let mut text = String::from(
            "frame\tsegment\ttotal_ms\tcut_ms\tprefetch_ms\tclusters\tnodes\tgroups\treq\tpref\thash\n",
        );
        for r in &rows {
            text += &format!(
                "{}\t{}\t{:.3}\t{:.3}\t{:.3}\t{}\t{}\t{}\t{}\t{}\t{:016x}\n",
                r.0, r.1, r.2, r.3, r.4, r.5, r.6, r.7, r.8, r.9, r.10
            );
        }
        std::fs::write(out, text).expect("write");
    }
    let mut segments: Vec<String> = rows.iter().map(|r| r.1.clone()).collect();
    segments.dedup();
    for seg in segments {
        let r: Vec<_> = rows.iter().filter(|r| r.1 == seg).collect();
        println!(
            "{seg}: {} frames, median total {:.3} ms, cut {:.3} ms, prefetch {:.3} ms, mean total {:.3} ms, clusters {:.0}",
            r.len(),
            median(r.iter().map(|r| r.2).collect()),
            median(r.iter().map(|r| r.3).collect()),
            median(r.iter().map(|r| r.4).collect()),
            r.iter().map(|r| r.2).sum::<f64>() / r.len() as f64,
            median(r.iter().map(|r| r.5 as f64).collect()),
        );
    }
    println!("fingerprint {:016x}", all.finish());
}
