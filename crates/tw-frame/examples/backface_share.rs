//! How much back-face culling could remove: on every 5th frame of one segment of a camera path,
//! the share of the frame's triangles that face away from the eye (what the rasterizer's
//! per-triangle back-face culling would drop on closed, outward-wound geometry), and the share
//! in clusters whose normal cone (axis = mean normal, half-angle = widest normal; apex-free test
//! against the cluster's bounding sphere) proves every triangle back-facing (what cluster-level
//! cone culling, as in meshoptimizer's `meshopt_computeClusterBounds`, could skip). Counted over
//! the frame's whole cut (`none`) and over what `hzb` drew. An analysis tool for
//! docs/benchmarks-log.md.
//!
//! `cargo run --release -p tw-frame --example backface_share -- STORE PATH.json [walk|fly]`

use std::sync::Arc;

use glam::DVec3;
use tw_frame::{FrameSettings, Occlusion, Walkthrough};
use tw_gpu::Renderer;
use tw_runtime::{CameraPath, StreamOptions};
use tw_store::{PageCluster, Store};

/// A cluster's normal cone and bounding sphere, all in scene space.
struct Cone {
    axis: DVec3,
    /// cos of the half-angle: every normal `n` has `n·axis ≥ cos`.
    cos: f64,
    centre: DVec3,
    radius: f64,
}

fn scene_positions(c: &PageCluster, step: f64) -> Vec<DVec3> {
    c.positions.iter().map(|g| DVec3::new(g[0] as f64, g[1] as f64, g[2] as f64) * step).collect()
}

fn triangles<'a>(c: &'a PageCluster, p: &'a [DVec3]) -> impl Iterator<Item = [DVec3; 3]> + 'a {
    c.indices.chunks_exact(3).map(move |t| [p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]])
}

/// `None` when the normals span a half-space or more (no cone can prove anything).
fn cone(c: &PageCluster, p: &[DVec3]) -> Option<Cone> {
    let normals: Vec<DVec3> =
        triangles(c, p).filter_map(|[a, b, d]| (b - a).cross(d - a).try_normalize()).collect();
    let axis = normals.iter().sum::<DVec3>().try_normalize()?;
    let cos = normals.iter().map(|n| n.dot(axis)).fold(1.0f64, f64::min);
    let (lo, hi) = p.iter().fold((DVec3::MAX, DVec3::MIN), |(lo, hi), q| (lo.min(*q), hi.max(*q)));
    let centre = (lo + hi) * 0.5;
    let radius = p.iter().map(|q| q.distance(centre)).fold(0.0, f64::max);
    (cos > 0.0).then_some(Cone { axis, cos, centre, radius })
}

/// Every triangle faces away from `eye`: for `v = eye − centre` at angle φ to the axis, the
/// largest `n·v` over the cone is `|v|·cos(φ − θ)`, and a point of a triangle is within `radius`
/// of the centre, so `|v|·cos(φ − θ) < −radius` proves `n·(eye − p) < 0` for all of them.
fn all_back_facing(k: &Cone, eye: DVec3) -> bool {
    let v = eye - k.centre;
    let along = v.dot(k.axis);
    let across = (v.length_squared() - along * along).max(0.0).sqrt();
    let sin = (1.0 - k.cos * k.cos).max(0.0).sqrt();
    along * k.cos + across * sin < -k.radius * 1.0001 - 1e-6
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        eprintln!("usage: backface_share STORE PATH.json [walk|fly]");
        std::process::exit(2);
    }
    let store = Arc::new(Store::open(&args[1])?);
    let path = CameraPath::load(std::path::Path::new(&args[2]))?;
    let segment = args.get(3).map_or("walk", |s| s.as_str());
    let renderer = Renderer::new_headless(1280, 720)?;
    let options = StreamOptions { budget_bytes: 512 << 20, ..Default::default() };
    let mut walk = Walkthrough::new(store.clone(), renderer, options)?;
    let step = store.header().grid_step;
    let settings = FrameSettings { occlusion: Occlusion::Hzb, wait_for_pages: true, ..Default::default() };
    let share = |part: u64, whole: u64| 100.0 * part as f64 / whole.max(1) as f64;
    // Per set (cut, drawn): triangles, back-facing triangles, triangles in cone-culled clusters.
    let mut total = [[0u64; 3]; 2];
    let frames = path.frames.iter().enumerate().filter(|(_, f)| f.segment == segment).step_by(5);
    for (i, f) in frames {
        let camera = f.to_scene(store.header())?;
        let drawn = walk.draw_frame(&camera, &settings)?.drawn;
        let eye = camera.eye.as_dvec3();
        let cut = walk.selection().clusters.clone();
        let cache = walk.streamer().cache().clone();
        let mut row = [[0u64; 3]; 2];
        for (set, counts) in [&cut, &drawn].into_iter().zip(&mut row) {
            for c in set {
                let page = cache.get(&store, c.page)?;
                let cluster = &page.clusters[c.index_in_page as usize];
                let p = scene_positions(cluster, step);
                let n = cluster.triangle_count() as u64;
                counts[0] += n;
                counts[1] += triangles(cluster, &p)
                    .filter(|[a, b, d]| (b - a).cross(d - a).dot(eye - a) < 0.0)
                    .count() as u64;
                if cone(cluster, &p).is_some_and(|k| all_back_facing(&k, eye)) {
                    counts[2] += n;
                }
            }
        }
        let [c, d] = row;
        println!(
            "frame {i}: cut {} triangles, {:.1}% back-facing, {:.1}% cone-culled | hzb drew {}, {:.1}%, {:.1}%",
            c[0], share(c[1], c[0]), share(c[2], c[0]), d[0], share(d[1], d[0]), share(d[2], d[0])
        );
        for (t, r) in total.iter_mut().zip(row) {
            for k in 0..3 {
                t[k] += r[k];
            }
        }
    }
    let [c, d] = total;
    println!(
        "{segment}: cut {:.1}% back-facing, {:.1}% cone-culled | hzb drew {:.1}% back-facing, {:.1}% cone-culled",
        share(c[1], c[0]), share(c[2], c[0]), share(d[1], d[0]), share(d[2], d[0])
    );
    Ok(())
}
