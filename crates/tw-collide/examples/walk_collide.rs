//! Times walk mode's collision step along a store's walk path, as the viewer runs it: per frame
//! the cut at the walker's eye (1280 × 720, τ = 1, frustum culled; pages loaded and waited for
//! here, which is not timed), then the timed step — gather the triangles within the capsule's
//! reach ([`Nearby::gather`]) and move the capsule by the path's horizontal motion and a
//! frame's fall ([`Capsule::move_by`]). Prints the median, p99 and maximum, and the clearance
//! the capsule kept from the full-detail geometry (never below −radius/1000 if it never went
//! into a wall or a floor).
//!
//! ```text
//! cargo run --release -p tw-collide --example walk_collide -- STORE.tw PATH.json [FRAMES] [swerve]
//! ```
//!
//! `swerve`: the walker also swerves left and right of the path (1.5 × its speed, turning every
//! 40 frames), into the walls and equipment beside the walkway.

use std::time::Instant;

use glam::Vec3;
use tw_collide::capsule::Capsule;
use tw_collide::nearby::Nearby;
use tw_runtime::{Camera, CameraPath, PageCache, SelectOptions, Selector};
use tw_store::Store;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(store), Some(path)) = (args.get(1), args.get(2)) else {
        return Err("usage: walk_collide STORE.tw PATH.json [FRAMES] [swerve]".into());
    };
    let limit: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(usize::MAX);
    let swerve = args.get(4).is_some_and(|s| s == "swerve");
    let store = Store::open(store)?;
    let path = CameraPath::load(std::path::Path::new(path))?;
    let cameras: Vec<Camera> = path
        .frames
        .iter()
        .filter(|f| f.segment.is_empty() || f.segment == "walk")
        .take(limit)
        .map(|f| f.to_scene(store.header()))
        .collect::<Result<_, _>>()?;
    if cameras.len() < 2 {
        return Err(format!("{}: fewer than two walk frames", args[2]).into());
    }
    let up = [Vec3::X, Vec3::Y, Vec3::Z][store.header().up_axis.min(2) as usize];
    let unit = store.metres_per_unit().unwrap_or(1.0);
    let capsule = Capsule::walker(unit, up);
    let eye_height = (tw_store::units::EYE_HEIGHT_M / unit) as f32;
    let fall = (tw_store::units::GRAVITY_M_S2 / unit) as f32 / (path.fps as f32).powi(2);
    let cache = PageCache::new(&store, 4 << 30);
    cache.load_root_pages(&store);
    let selector = Selector::new(&store);
    let select =
        SelectOptions { tau: 1.0, viewport: [1280, 720], frustum_culling: true, ..Default::default() };
    let (mut near, mut truth) = (Nearby::default(), Nearby::default());
    let mut scratch = Vec::new();
    let mut feet = cameras[0].eye - up * eye_height;
    let mut times = Vec::with_capacity(cameras.len());
    let mut gather_ms = Vec::with_capacity(cameras.len());
    let mut cut_clusters = 0usize;
    let mut short = 0usize;
    let (mut worst, mut blocked, mut triangles) = (f64::INFINITY, 0usize, 0usize);
    let mut vertical = 0.0f32;
    for (i, pair) in cameras.windows(2).enumerate() {
        let eye = feet + up * eye_height;
        let view = Camera { eye, target: eye + pair[1].direction(), ..pair[1] };
        let cut = selector.select(&store, &cache, &view, &select);
        let step = pair[1].eye - pair[0].eye;
        vertical -= fall;
        let along = step - up * step.dot(up);
        let side =
            if swerve { along.cross(up) * if (i / 40) % 2 == 0 { 1.5 } else { -1.5 } } else { Vec3::ZERO };
        let motion = along + side + up * vertical;
        let t = Instant::now();
        let reach = capsule.reach(feet, motion);
        near.gather(&store, &reach, &cut.clusters, |p| cache.try_get(p));
        gather_ms.push(t.elapsed().as_secs_f64() * 1e3);
        let moved = capsule.move_by(feet, motion, &near.triangles, &mut scratch);
        times.push(t.elapsed().as_secs_f64() * 1e3);
        if std::env::var_os("WALK_COLLIDE_TRACE").is_some() {
            eprintln!("move {i}: motion {motion} ({}) tests {} {moved:?}", motion.length(), moved.tests);
        }
        if moved.grounded {
            vertical = 0.0;
        }
        feet = moved.feet;
        blocked += moved.blocked as usize;
        triangles += near.triangles.len();
        cut_clusters += cut.clusters.len();
        short += (near.missing > 0) as usize;
        // The reference: every full-detail triangle around the capsule (pages loaded).
        let full: Vec<_> = Vec::new();
        truth.gather(&store, &capsule.reach(feet, Vec3::ZERO), &full, |p| cache.get(&store, p).ok());
        worst = worst.min(capsule.clearance(feet, &truth.triangles));
    }
    if std::env::var_os("WALK_COLLIDE_TRACE").is_some() {
        for (i, (t, g)) in times.iter().zip(&gather_ms).enumerate() {
            eprintln!("frame {i}: {t:.3} ms ({g:.3} gathering)");
        }
    }
    gather_ms.sort_by(f64::total_cmp);
    println!(
        "gathering: median {:.3} ms; {:.0} clusters in the cut on average; {short} frames with a \
         full-detail page not resident (the cut filled in)",
        gather_ms[gather_ms.len() / 2],
        cut_clusters as f64 / times.len() as f64
    );
    times.sort_by(f64::total_cmp);
    let q = |f: f64| times[((times.len() - 1) as f64 * f).round() as usize];
    println!(
        "{} frames: collision step median {:.3} ms, p99 {:.3} ms, max {:.3} ms; {:.0} triangles near on average; \
         {blocked} frames blocked; worst clearance to the full-detail geometry {:.5} (radius {}); ended {:.3} from the path's end",
        times.len(),
        q(0.5),
        q(0.99),
        q(1.0),
        triangles as f64 / times.len() as f64,
        worst,
        capsule.radius,
        (feet + up * eye_height - cameras.last().map_or(Vec3::ZERO, |c| c.eye)).length()
    );
    Ok(())
}
