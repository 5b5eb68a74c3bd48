//! The plan's job graph: which jobs, what each needs first, and what it may take.

use std::ops::Range;

/// What a job does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JobKind {
    /// Phases 1–4 into the plan's `prepared/` folder.
    Prepare,
    /// The LOD of one shard's cells.
    Cells { shard: u32 },
    /// HLOD, pages and the store, from every shard's cells.
    Pack,
}

impl JobKind {
    /// The job's id in the plan (`prepare`, `cells-007`, `pack`).
    pub fn id(&self) -> String {
        match self {
            JobKind::Prepare => "prepare".into(),
            JobKind::Cells { shard } => format!("cells-{shard:03}"),
            JobKind::Pack => "pack".into(),
        }
    }

    /// The job named `id` in a plan of `shards` shards, if there is one.
    pub fn parse(id: &str, shards: u32) -> Option<JobKind> {
        match id {
            "prepare" => Some(JobKind::Prepare),
            "pack" => Some(JobKind::Pack),
            _ => {
                let digits = id.strip_prefix("cells-")?;
                let shard: u32 = digits.parse().ok()?;
                (shard < shards && JobKind::Cells { shard }.id() == id).then_some(JobKind::Cells { shard })
            }
        }
    }
}

/// One job of the plan: what it needs done first and what it may use (for a scheduler).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct JobSpec {
    pub kind: JobKind,
    /// Jobs that must have finished first.
    pub after: Vec<JobKind>,
    /// Peak memory: the build's `--memory`.
    pub memory: u64,
    /// Disk the job's outputs take (an estimate from the input's size).
    pub disk: u64,
    /// Cores it can use.
    pub cpus: u32,
}

/// What the plan's resource figures are estimated from.
#[derive(Clone, Copy, Debug)]
pub struct Estimate {
    /// Input triangles (estimated from the inputs' sizes when not known).
    pub triangles: u64,
    /// The build's memory budget.
    pub memory: u64,
    /// Cores a job may use.
    pub cpus: u32,
}

/// Disk per input triangle, with a margin over what the 10^8 plant measured (docs/SCALE.md):
/// the prepared buckets and seams (33 B), the shards' DAGs and encoded clusters (39 B), the
/// store (10 B).
const PREPARED_BYTES_PER_TRIANGLE: u64 = 40;
const CELLS_BYTES_PER_TRIANGLE: u64 = 60;
const STORE_BYTES_PER_TRIANGLE: u64 = 12;

/// The jobs of a plan with `shards` shards, each after the jobs it needs (a valid run order).
pub fn job_graph(shards: u32, e: &Estimate) -> Vec<JobSpec> {
    let shards = shards.max(1);
    let job = |kind, after, disk, cpus| JobSpec { kind, after, memory: e.memory, disk, cpus };
    let per_shard = e.triangles.div_ceil(shards as u64);
    let mut jobs = vec![job(JobKind::Prepare, vec![], e.triangles * PREPARED_BYTES_PER_TRIANGLE, e.cpus)];
    let cells: Vec<JobKind> = (0..shards).map(|shard| JobKind::Cells { shard }).collect();
    for &c in &cells {
        jobs.push(job(c, vec![JobKind::Prepare], per_shard * CELLS_BYTES_PER_TRIANGLE, e.cpus));
    }
    let mut pack_after = vec![JobKind::Prepare];
    pack_after.extend(cells);
    jobs.push(job(JobKind::Pack, pack_after, e.triangles * STORE_BYTES_PER_TRIANGLE, e.cpus));
    jobs
}

/// The buckets of shard `shard` of `shards`: consecutive buckets, cut where the running
/// triangle count passes each `k / shards` of the total, so shards are about equal in work (a
/// shard may be empty when there are fewer buckets than shards).
pub(crate) fn shard_buckets(bucket_triangles: &[u64], shards: u32, shard: u32) -> Range<usize> {
    let total: u64 = bucket_triangles.iter().sum();
    let shards = shards.max(1) as u128;
    // The first bucket at or after the cumulative share of shard `k`.
    let start_of = |k: u128| -> usize {
        if k == 0 {
            return 0;
        }
        if k >= shards {
            return bucket_triangles.len();
        }
        let target = (total as u128 * k).div_ceil(shards);
        let mut sum = 0u128;
        for (b, &t) in bucket_triangles.iter().enumerate() {
            if sum >= target {
                return b;
            }
            sum += t as u128;
        }
        bucket_triangles.len()
    };
    start_of(shard as u128)..start_of(shard as u128 + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_round_trip_and_foreign_ids_are_refused() {
        for kind in
            [JobKind::Prepare, JobKind::Cells { shard: 0 }, JobKind::Cells { shard: 11 }, JobKind::Pack]
        {
            assert_eq!(JobKind::parse(&kind.id(), 12), Some(kind));
        }
        for bad in ["cells-12", "cells-1", "cells-x", "cells-", "merge", "", "cells-0000"] {
            assert_eq!(JobKind::parse(bad, 12), None, "{bad}");
        }
    }

    #[test]
    fn every_job_comes_after_what_it_needs() {
        let e = Estimate { triangles: 1_000_000, memory: 1 << 30, cpus: 2 };
        let jobs = job_graph(4, &e);
        assert_eq!(jobs.len(), 6);
        for (i, j) in jobs.iter().enumerate() {
            for a in &j.after {
                assert!(jobs[..i].iter().any(|x| x.kind == *a), "{:?} before {:?}", a, j.kind);
            }
        }
        assert_eq!(jobs.last().unwrap().after.len(), 5);
    }

    #[test]
    fn shards_cover_every_bucket_once_and_balance_triangles() {
        let buckets: Vec<u64> = (0..37).map(|i| 1000 + (i * 7919 % 500)).collect();
        for shards in [1, 2, 3, 5, 37, 50] {
            let ranges: Vec<_> = (0..shards).map(|k| shard_buckets(&buckets, shards, k)).collect();
            assert_eq!(ranges[0].start, 0);
            assert_eq!(ranges.last().unwrap().end, buckets.len());
            for w in ranges.windows(2) {
                assert_eq!(w[0].end, w[1].start);
            }
            if shards <= 5 {
                let total: u64 = buckets.iter().sum();
                for r in &ranges {
                    let t: u64 = buckets[r.clone()].iter().sum();
                    assert!(t.abs_diff(total / shards as u64) <= 1500, "{shards}: {t}");
                }
            }
        }
        assert_eq!(shard_buckets(&[], 3, 1), 0..0);
    }
}
