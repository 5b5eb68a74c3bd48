//! Pass A: the centroid samples that the split plans are made from ([`crate::sampling`]).

use super::RedefineParams;
use crate::error::BuildError;
use crate::ingest::{record_object, Ingested, WorkTri, RECORD_BYTES};
use crate::sampling::SampleRule;

/// The samples of every object, and the stride each was taken at.
pub(super) struct Samples {
    /// Centroids, grouped by object: object `o`'s are `start[o]..start[o + 1]`.
    pub(super) points: Vec<[f32; 3]>,
    pub(super) start: Vec<usize>,
    /// Triangles per sample of each object (0: not sampled).
    pub(super) stride: Vec<u64>,
}

/// Pass A: the samples of [`SampleRule`]. Ingest takes them while streaming
/// ([`crate::sampling::OnlineSampler`]); only when it could not (no rule, another rule,
/// interleaved objects) is the working file read for them. Both give the same samples.
pub(super) fn sample_objects(ing: &Ingested, p: &RedefineParams) -> Result<Samples, BuildError> {
    let rule = p.sample_rule();
    let online = ing.samples.lock().map(|mut s| s.take()).unwrap_or(None);
    match online {
        Some(s) if s.rule == Some(rule) && s.stride.len() == ing.objects.len() => {
            tracing::debug!(samples = s.points.len(), "pass A: samples taken by ingest");
            return Ok(Samples { points: s.points, start: s.start, stride: s.stride });
        }
        _ => tracing::debug!("pass A: reading the working file for samples"),
    }
    sample_file(ing, &rule)
}

/// Pass A over the working file: [`SampleRule`]'s samples.
fn sample_file(ing: &Ingested, rule: &SampleRule) -> Result<Samples, BuildError> {
    let objects = &ing.objects;
    let large = rule.large(objects.iter().map(|o| o.triangles));
    let stride: Vec<u64> = objects.iter().map(|o| rule.stride(o.triangles, large)).collect();
    let mut start = Vec::with_capacity(objects.len() + 1);
    start.push(0usize);
    for (o, &s) in objects.iter().zip(&stride) {
        let n = if s > 0 { o.triangles.div_ceil(s) as usize } else { 0 };
        start.push(start.last().copied().unwrap_or(0) + n);
    }
    let mut points = vec![[0f32; 3]; start.last().copied().unwrap_or(0)];
    let mut seen = vec![0u64; objects.len()];
    // The next sampled triangle of each object (counted within the object): the multiples of
    // its stride, so that only sampled triangles are decoded (none for unsampled objects).
    let mut next: Vec<u64> = stride.iter().map(|&s| if s > 0 { 0 } else { u64::MAX }).collect();
    let corrupt = |message: String| BuildError::Corrupt { path: ing.work.path().to_path_buf(), message };
    // Serial, but it reads only the object ids: the reader thread only reads.
    ing.work.scan_raw(|first, bytes| {
        for k in 0..bytes.len() / RECORD_BYTES {
            let o = record_object(bytes, k) as usize;
            let Some(n) = seen.get_mut(o) else {
                return Err(corrupt(format!(
                    "triangle {} has object {o} of {}",
                    first + k as u64,
                    objects.len()
                )));
            };
            if *n == next[o] {
                let s = stride[o];
                let i = start[o] + (*n / s) as usize;
                if i >= start[o + 1] {
                    return Err(corrupt(format!("object {o} has more triangles than ingest counted")));
                }
                points[i] = WorkTri::decode(&bytes[k * RECORD_BYTES..(k + 1) * RECORD_BYTES]).centroid();
                next[o] += s;
            }
            *n += 1;
        }
        Ok(())
    })?;
    if let Some(o) = (0..objects.len()).find(|&o| seen[o] != objects[o].triangles) {
        return Err(corrupt(format!(
            "object {o} has {} triangles, ingest counted {}",
            seen[o], objects[o].triangles
        )));
    }
    Ok(Samples { points, start, stride })
}
