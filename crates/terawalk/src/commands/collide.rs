//! `terawalk collide`: runs one of the thesis' collision scenes (`tw_collide::scenes`) for a
//! number of steps with CULLIDE, FAR and/or the exact CPU reference, and prints a table: the
//! median milliseconds a step, the pairs found, and the pairs missed against the reference.

use std::path::PathBuf;

use anyhow::{bail, Context};
use clap::Args;
use tw_collide::cullide::Options;
use tw_collide::reference::all_pairs_within;
use tw_collide::{Collider, Method, Pair, Scene, SceneKind, SceneOptions};

/// Arguments of `terawalk collide`.
#[derive(Args, Debug)]
pub struct CollideArgs {
    /// The scene: cylinders (100 × 200 triangles), tori (6 × 20K), breaking (the bunny falls
    /// through the dragon's pieces), cloth (20K on a sphere, self-collision) or bunnies (two
    /// interpenetrating bunnies).
    pub scene: String,
    /// Steps of the scene's motion to run.
    #[arg(long, default_value_t = 10)]
    pub steps: usize,
    /// The first step.
    #[arg(long, default_value_t = 0)]
    pub first: usize,
    /// Methods, comma-separated: cullide, far, reference.
    #[arg(long, value_delimiter = ',', default_value = "far")]
    pub method: Vec<String>,
    /// Side of the query viewport in pixels, comma-separated for several.
    #[arg(long, value_delimiter = ',', default_value = "512")]
    pub resolution: Vec<u32>,
    /// Triangle counts relative to the thesis' scenes (0 < scale ≤ 1).
    #[arg(long, default_value_t = 1.0)]
    pub scale: f32,
    /// The sub-object culling stages after the object boxes, coarse to fine: triangles per
    /// sub-object, comma-separated (the thesis: k, then single triangles). Ending at k > 1
    /// leaves more to the CPU's exact tests and issues fewer queries.
    #[arg(long, value_delimiter = ',', default_value = "32,1")]
    pub groups: Vec<usize>,
    /// Report the pairs of triangles within this distance (scene units) instead of overlapping
    /// ones (FAR's within-distance variant; far and reference only).
    #[arg(long, default_value_t = 0.0)]
    pub within: f32,
    /// How the GPU methods query, comma-separated for a row each: batched (a pass's queries in
    /// a few draws, the test in the fragment stage; where the device cannot, GL, it falls back)
    /// or occlusion (one occlusion query a draw, as the thesis). The answers are the same.
    #[arg(long, value_delimiter = ',', default_value = "batched")]
    pub queries: Vec<String>,
    /// Where the models are (dragon_vrip.ply.gz, bunny.obj; scripts/fetch-data.sh).
    #[arg(long, default_value = "data")]
    pub data: PathBuf,
}

/// One row of the summary.
struct Row {
    method: Method,
    resolution: Option<u32>,
    /// How its queries ran (`Collider::batched`).
    batched: Option<bool>,
    times: Vec<f64>,
    gpu: Vec<f64>,
    cpu: Vec<f64>,
    pairs: usize,
    missed: usize,
    extra: usize,
    pcs: usize,
    queries: usize,
}

pub fn run(a: CollideArgs) -> anyhow::Result<()> {
    let (kind, methods, queries) = check_args(&a)?;
    let scene = Scene::new(kind, &SceneOptions { scale: a.scale, data_dir: a.data.clone() })?;
    let mut rows = colliders(&a, &methods, &queries)?;
    if let Some(adapter) = rows.iter().find_map(|(_, c)| c.adapter()) {
        println!("GPU: {adapter}");
    }
    for t in a.first..a.first + a.steps {
        let objects = scene.step(t);
        if t == a.first {
            println!(
                "scene {}: {} objects, {} triangles, steps {}..{}",
                kind.name(),
                objects.len(),
                tw_collide::triangle_count(&objects),
                a.first,
                a.first + a.steps
            );
        }
        let reference: Vec<Pair> = all_pairs_within(&objects, a.within);
        for (row, collider) in &mut rows {
            let s = collider.step(&objects)?;
            row.times.push(s.total_ms);
            row.gpu.push(s.gpu_ms);
            row.cpu.push(s.cpu_ms);
            row.pairs += s.pairs.len();
            row.pcs += s.pcs_triangles + s.pcs_self_triangles;
            row.queries += s.queries;
            row.missed += reference.iter().filter(|p| s.pairs.binary_search(p).is_err()).count();
            row.extra += s.pairs.iter().filter(|p| reference.binary_search(p).is_err()).count();
        }
    }
    print_table(&rows, a.steps);
    if let Some((r, _)) = rows.iter().find(|(r, _)| r.extra > 0) {
        bail!("{} reported {} pairs the exact reference does not have", r.method.name(), r.extra);
    }
    if let Some((r, _)) = rows.iter().find(|(r, _)| r.method != Method::Cullide && r.missed > 0) {
        bail!("{} missed {} pairs; only cullide may miss", r.method.name(), r.missed);
    }
    Ok(())
}

/// The scene, the methods and the query modes (batched or not) named by the arguments, once
/// the other arguments are checked.
fn check_args(a: &CollideArgs) -> anyhow::Result<(SceneKind, Vec<Method>, Vec<bool>)> {
    let kind = SceneKind::from_name(&a.scene).with_context(|| {
        let names: Vec<&str> = SceneKind::ALL.iter().map(|k| k.name()).collect();
        format!("unknown scene {:?}: one of {}", a.scene, names.join(", "))
    })?;
    if a.steps == 0 {
        bail!("--steps must be at least 1");
    }
    if a.resolution.iter().any(|&r| !(8..=8192).contains(&r)) {
        bail!("--resolution must be 8 to 8192 pixels");
    }
    if a.groups.contains(&0) {
        bail!("--groups: a sub-object has at least 1 triangle");
    }
    let methods = a
        .method
        .iter()
        .map(|m| match m.as_str() {
            "cullide" => Ok(Method::Cullide),
            "far" => Ok(Method::Far),
            "reference" => Ok(Method::Reference),
            other => bail!("unknown method {other:?}: cullide, far or reference"),
        })
        .collect::<anyhow::Result<Vec<Method>>>()?;
    let queries = a
        .queries
        .iter()
        .map(|q| match q.trim() {
            "batched" => Ok(true),
            "occlusion" => Ok(false),
            other => bail!("unknown --queries {other:?}: batched or occlusion"),
        })
        .collect::<anyhow::Result<Vec<bool>>>()?;
    Ok((kind, methods, queries))
}

/// A collider and an empty row per method, resolution and query mode (the reference has
/// neither resolution nor queries).
fn colliders(a: &CollideArgs, methods: &[Method], queries: &[bool]) -> anyhow::Result<Vec<(Row, Collider)>> {
    let mut rows: Vec<(Row, Collider)> = Vec::new();
    for &method in methods {
        let settings: Vec<(Option<u32>, bool)> = match method {
            Method::Reference => vec![(None, true)],
            _ => a.resolution.iter().flat_map(|&r| queries.iter().map(move |&q| (Some(r), q))).collect(),
        };
        for (resolution, batched) in settings {
            let options = Options {
                method,
                resolution: resolution.unwrap_or(512),
                groups: a.groups.clone(),
                within: a.within,
                batched,
                ..Default::default()
            };
            let collider = Collider::new(options)?;
            let row = Row {
                method,
                resolution,
                batched: collider.batched(),
                times: Vec::new(),
                gpu: Vec::new(),
                cpu: Vec::new(),
                pairs: 0,
                missed: 0,
                extra: 0,
                pcs: 0,
                queries: 0,
            };
            rows.push((row, collider));
        }
    }
    Ok(rows)
}

/// Prints the summary: a row per method and resolution over `steps` steps, and what the
/// columns mean.
fn print_table(rows: &[(Row, Collider)], steps: usize) {
    println!();
    println!(
        "{:<10} {:>10} {:>9} {:>10} {:>9} {:>9} {:>11} {:>8} {:>11} {:>13}",
        "method",
        "resolution",
        "queries",
        "median ms",
        "gpu ms",
        "cpu ms",
        "pairs/step",
        "missed",
        "PCS tris",
        "queries/step"
    );
    for (r, _) in rows {
        let per = |v: usize| v as f64 / steps as f64;
        let gpu = r.method != Method::Reference;
        println!(
            "{:<10} {:>10} {:>9} {:>10.1} {:>9} {:>9} {:>11.1} {:>8} {:>11} {:>13}",
            r.method.name(),
            r.resolution.map_or("-".to_string(), |x| x.to_string()),
            match r.batched {
                Some(true) => "batched",
                Some(false) => "occlusion",
                None => "-",
            },
            median(&r.times),
            if gpu { format!("{:.1}", median(&r.gpu)) } else { "-".into() },
            if gpu { format!("{:.1}", median(&r.cpu)) } else { "-".into() },
            per(r.pairs),
            r.missed,
            if gpu { format!("{:.0}", per(r.pcs)) } else { "-".into() },
            if gpu { format!("{:.0}", per(r.queries)) } else { "-".into() },
        );
    }
    println!(
        "(gpu ms: the visibility passes, with building their geometry; cpu ms: sweep-and-prune and \
         exact tests; missed: reference pairs not found, over all steps; PCS tris: triangles left \
         for the exact tests per step)"
    );
}

fn median(v: &[f64]) -> f64 {
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    s.get(s.len() / 2).copied().unwrap_or(0.0)
}
