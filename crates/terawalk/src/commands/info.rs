//! `terawalk info`: what a store holds, and with `--verify` whether every byte of it is sound.

use anyhow::{Context, Result};

use crate::cli::InfoArgs;
use crate::progress;
use crate::units::{fmt_bytes, fmt_count};

pub fn run(args: InfoArgs) -> Result<()> {
    let store = crate::commands::open_store(&args.store)?;
    let h = store.header();
    let input = h.input_triangles.max(1);
    outln!("{}", args.store.display());
    outln!("  format version {}, {}", h.version, fmt_bytes(store.file_len()));
    outln!(
        "  bounds: ({:.4}, {:.4}, {:.4}) .. ({:.4}, {:.4}, {:.4}), up axis {}, units {:?}",
        h.bounds_min[0],
        h.bounds_min[1],
        h.bounds_min[2],
        h.bounds_max[0],
        h.bounds_max[1],
        h.bounds_max[2],
        ["x", "y", "z"].get(h.up_axis as usize).unwrap_or(&"?"),
        store.units()
    );
    outln!("  grid: step {:.3e}", h.grid_step);
    outln!(
        "  {} input triangles, {} objects, {} nodes, {} groups ({} links to the groups they were \
         simplified from), {} pages",
        fmt_count(h.input_triangles),
        fmt_count(store.objects().len() as u64),
        fmt_count(store.nodes().len() as u64),
        fmt_count(store.groups().len() as u64),
        fmt_count(store.group_links().link_count() as u64),
        fmt_count(store.pages().len() as u64)
    );
    // Counts per level, from the group table.
    let mut levels: Vec<(u64, u64, u64)> = Vec::new(); // groups, clusters, triangles
    for g in store.groups() {
        let l = g.level as usize;
        if levels.len() <= l {
            levels.resize(l + 1, (0, 0, 0));
        }
        levels[l].0 += 1;
        levels[l].1 += g.cluster_count as u64;
        levels[l].2 += g.triangles as u64;
    }
    let total: u64 = levels.iter().map(|l| l.2).sum();
    outln!("  level     groups   clusters      triangles");
    for (l, (g, c, t)) in levels.iter().enumerate() {
        outln!("  {l:>5} {:>10} {:>10} {:>14}", fmt_count(*g), fmt_count(*c), fmt_count(*t));
    }
    outln!("  all levels: {} triangles ({:.2}x input)", fmt_count(total), total as f64 / input as f64);
    let page_bytes: u64 = store.pages().iter().map(|p| p.compressed_len as u64).sum();
    let root_bytes: u64 = store.pages().iter().filter(|p| p.is_root()).map(|p| p.compressed_len as u64).sum();
    outln!(
        "  pages: {} ({} resident root pages, {}); {:.2} bytes per input triangle in all",
        fmt_bytes(page_bytes),
        store.pages().iter().filter(|p| p.is_root()).count(),
        fmt_bytes(root_bytes),
        store.file_len() as f64 / input as f64
    );
    if !store.build_options().is_empty() {
        outln!("  build options: {}", store.build_options().trim().replace('\n', ", "));
    }
    if args.verify {
        let pb = progress::count(store.pages().len() as u64, "verifying");
        let report = store.verify(|done, _| pb.set_position(done as u64));
        pb.finish_and_clear();
        let report = report.with_context(|| format!("{} failed verification", args.store.display()))?;
        outln!("verify: OK ({report:?})");
    }
    Ok(())
}
