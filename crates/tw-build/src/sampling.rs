//! The centroid samples that redefinition plans its splits from (GigaWalk §4.2: partition-I
//! splits large objects at the median of their triangles' centroids; out of core, a sample of
//! them stands in, see [`crate::redefine`]), taken while ingest streams the triangles so that no
//! pass over the working file is needed for them.
//!
//! # The rule
//!
//! An object of more than `t1` triangles keeps the centroids of its triangles whose index within
//! the object is a multiple of its *stride*: the largest power of two not above
//! `min(r, n / min_samples_per_object)` (at least 1), where `n` is the object's triangle count,
//! `r = ⌈large / max_samples⌉` and `large` the triangles of all objects above `t1`. So the
//! samples number about `max_samples` to twice that, and every sampled object has at least
//! `min_samples_per_object` of them.
//!
//! # Online
//!
//! Neither `n` nor `large` is known before the stream ends, but with power-of-two strides a
//! sample at a finer stride can be thinned to any coarser one. [`OnlineSampler`] keeps each
//! object's samples at stride `min(G, P(seen / min_samples_per_object))` (`P`: the largest power
//! of two not above; `seen`: the object's triangles so far), a stride that only grows and never
//! exceeds the final one, thinning as it grows. The global stride `G` doubles whenever the
//! objects at stride `G` hold more than `T = 2 · max_samples · m / (m − 1)` samples
//! (`m = min_samples_per_object` ≥ 2; `T` ≈ 2.03 `max_samples` for the default 64): each of
//! those has seen at least `m · G` triangles, so it holds at most one sample more than its
//! triangles over `G` and at least `m`, hence `large ≥ T · G · (1 − 1/m) = 2 · max_samples · G`,
//! `r ≥ 2G`, and `G` stays at or below the final `P(r)`. [`OnlineSampler::finish`] thins every
//! object to its final stride: exactly the samples a pass over the file with the rule above
//! takes ([`SampleRule::stride`]), which is what `crate::redefine` falls back to.
//!
//! Objects must come one after the other (each object's triangles contiguous in the stream:
//! every importer does so). An object whose triangles come back after another object's was
//! closed; if it had at most `t1` triangles its samples were dropped, so the sampler gives up
//! (frees everything) and redefinition reads the file instead.
//!
//! # Memory
//!
//! A closed object below stride `G` holds its final samples: its stride `P(n / m)` is below
//! `G` and so below the final `P(r)`, and nothing thins it again. Those samples (up to `2m`
//! per object, which `G` does not bound) are what any way of taking the rule's samples holds,
//! the pass over the file included. The others — the objects at stride `G` and the open
//! object — may still be thinned or dropped: they are about `T` at most, and the sampler gives
//! up if they would exceed its memory cap (a share of the build's budget; only a cap below
//! `12 · T` bytes, or a huge `max_samples`, can be reached). So ingest holds at most the cap
//! more than the final samples (`max_samples` to `2 · max_samples`, plus up to `2m` per sampled
//! object: 23.2 M samples, 278 MB, for the 10^9-triangle generated plant), and 48 bytes per
//! object.

/// The parameters of the rule (from [`crate::redefine::RedefineParams`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SampleRule {
    pub t1: u64,
    pub max_samples: u64,
    pub min_samples_per_object: u64,
}

impl SampleRule {
    /// The stride of an object of `triangles` triangles when the objects above `t1` have `large`
    /// triangles in all (0: the object is not sampled).
    pub fn stride(&self, triangles: u64, large: u64) -> u64 {
        if triangles <= self.t1 {
            return 0;
        }
        let r = large.div_ceil(self.max_samples.max(1)).max(1);
        floor_pow2(r.min(triangles / self.min_samples_per_object.max(1)).max(1))
    }

    /// `large` of [`SampleRule::stride`] for objects of these triangle counts.
    pub fn large(&self, counts: impl IntoIterator<Item = u64>) -> u64 {
        counts.into_iter().filter(|&n| n > self.t1).sum()
    }
}

/// The largest power of two not above `x` (`x` ≥ 1).
fn floor_pow2(x: u64) -> u64 {
    1 << (63 - x.max(1).leading_zeros())
}

/// Samples of every object: object `o`'s centroids are `points[start[o]..start[o + 1]]`, taken
/// every `stride[o]` triangles (0: not sampled).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CentroidSamples {
    pub rule: Option<SampleRule>,
    pub points: Vec<[f32; 3]>,
    pub start: Vec<usize>,
    pub stride: Vec<u64>,
}

/// Takes [`SampleRule`]'s samples from a stream of (object, centroid) in file order.
///
/// The open object's samples grow in one reused buffer; a closed object above `t1` moves its
/// samples to the end of one arena (and one below drops them), so that the many small objects
/// of a scene leave no scattered allocations behind.
pub struct OnlineSampler {
    rule: SampleRule,
    objects: Vec<ObjectSamples>,
    /// The object whose triangles came last, and its samples.
    open: Option<u32>,
    open_points: Vec<[f32; 3]>,
    /// The samples of the closed objects above `t1`, one after the other in closing order
    /// (`closed`).
    arena: Vec<[f32; 3]>,
    closed: Vec<u32>,
    /// `G` of the module comment.
    global: u64,
    /// Samples held by objects at stride `global`, and by the others.
    held_at_global: u64,
    held_below: u64,
    /// The final samples among `held_below`: those of closed objects (module comment, "Memory").
    held_final: u64,
    /// Samples beyond the final ones the sampler may hold (its memory cap over 12 bytes).
    cap: u64,
    gave_up: bool,
}

#[derive(Clone, Copy, Default)]
struct ObjectSamples {
    seen: u64,
    /// 0 until the object's first triangle.
    stride: u64,
    /// Its samples in the arena, once closed.
    start: usize,
    len: usize,
    closed: bool,
}

/// Keeps the samples of `points` (taken every `from` triangles) at multiples of `to` (a power of
/// two ≥ `from`), in place.
fn thin(points: &mut Vec<[f32; 3]>, from: u64, to: u64) {
    let step = (to / from.max(1)) as usize;
    if step <= 1 {
        return;
    }
    let mut k = 0;
    points.retain(|_| {
        k += 1;
        (k - 1) % step == 0
    });
}

impl OnlineSampler {
    /// A sampler that gives up rather than hold more than `memory` bytes of samples.
    pub fn new(rule: SampleRule, memory: u64) -> OnlineSampler {
        OnlineSampler {
            rule,
            objects: Vec::new(),
            open: None,
            open_points: Vec::new(),
            arena: Vec::new(),
            closed: Vec::new(),
            global: 1,
            held_at_global: 0,
            held_below: 0,
            held_final: 0,
            cap: memory / std::mem::size_of::<[f32; 3]>() as u64,
            gave_up: false,
        }
    }

    /// Whether the sampler gave up (the caller may stop feeding it).
    #[cfg(test)]
    pub fn gave_up(&self) -> bool {
        self.gave_up
    }

    /// Adds `n` to the tally of stride `stride` (negative: removes).
    fn tally(&mut self, stride: u64, n: i64) {
        let t = if stride == self.global { &mut self.held_at_global } else { &mut self.held_below };
        *t = t.saturating_add_signed(n);
    }

    /// The next triangle of `object`, whose centroid is `centroid`.
    pub fn add(&mut self, object: u32, centroid: [f32; 3]) {
        self.add_run(object, std::slice::from_ref(&centroid));
    }

    /// The next triangles of `object`, whose centroids are `centroids`. Costs little more than
    /// the samples it keeps: the stride is constant over long stretches, and only its multiples
    /// are visited.
    pub fn add_run(&mut self, object: u32, centroids: &[[f32; 3]]) {
        if self.gave_up || centroids.is_empty() {
            return;
        }
        if self.open != Some(object) && !self.switch_to(Some(object)) {
            return;
        }
        let o = object as usize;
        let min = self.rule.min_samples_per_object.max(1);
        let mut i = 0;
        while i < centroids.len() {
            let seen = self.objects[o].seen;
            // The stride for this triangle (the object's count becomes seen + 1) …
            let (old, want) = (self.objects[o].stride, stride_for(self.global, seen + 1, min));
            if want > old {
                // Below G until now (a stride never exceeds G): its samples move to the tally
                // of their new stride.
                let before = self.open_points.len() as i64;
                thin(&mut self.open_points, old, want);
                self.tally(old, -before);
                self.objects[o].stride = want;
                self.tally(want, self.open_points.len() as i64);
            }
            let stride = self.objects[o].stride;
            // … holds until the count reaches the next power of two times min (or G changes).
            let p = floor_pow2(((seen + 1) / min).max(1));
            let limit = if p >= self.global { u64::MAX } else { min.saturating_mul(2 * p) };
            let n = ((centroids.len() - i) as u64).min(limit.saturating_sub(seen + 1).max(1)) as usize;
            // Its multiples among triangles seen .. seen + n.
            let mut j = seen.next_multiple_of(stride);
            let global = self.global;
            let mut done = n;
            while j < seen + n as u64 {
                self.open_points.push(centroids[i + (j - seen) as usize]);
                self.tally(stride, 1);
                // Doubling G thins this object by its count so far: triangle j is its last.
                self.objects[o].seen = j + 1;
                self.check_memory();
                if self.gave_up {
                    return;
                }
                if self.global != global {
                    // The strides changed: go on after this triangle.
                    done = (j - seen) as usize + 1;
                    break;
                }
                j += stride;
            }
            self.objects[o].seen = seen + done as u64;
            i += done;
        }
    }

    /// Closes the open object (its samples to the arena, or dropped if it has at most `t1`
    /// triangles) and opens `next`; false if the sampler gave up.
    fn switch_to(&mut self, next: Option<u32>) -> bool {
        if let Some(o) = self.open.take() {
            let o = o as usize;
            let s = self.objects[o];
            self.objects[o].closed = true;
            if s.seen > self.rule.t1 {
                self.objects[o].start = self.arena.len();
                self.objects[o].len = self.open_points.len();
                self.arena.extend_from_slice(&self.open_points);
                self.closed.push(o as u32);
                if s.stride < self.global {
                    self.held_final += self.open_points.len() as u64;
                }
            } else {
                self.tally(s.stride, -(self.open_points.len() as i64));
            }
            self.open_points.clear();
        }
        let Some(object) = next else { return true };
        let o = object as usize;
        if o >= self.objects.len() {
            self.objects.resize(o + 1, ObjectSamples::default());
        }
        if self.objects[o].closed {
            self.give_up();
            return false;
        }
        self.objects[o].stride = self.objects[o].stride.max(1);
        self.open = Some(object);
        true
    }

    fn check_memory(&mut self) {
        let max = self.rule.max_samples.max(1);
        let m = self.rule.min_samples_per_object.max(2);
        // held_at_global > 2 · max · m / (m − 1), in integers (module comment).
        while self.held_at_global.saturating_mul(m - 1) > max.saturating_mul(2 * m) {
            self.double_global();
        }
        if self.held_at_global + self.held_below - self.held_final > self.cap {
            self.give_up();
        }
    }

    /// Doubles `G`, thinning the objects at the old `G` (the arena compacted in place).
    fn double_global(&mut self) {
        let old = self.global;
        self.global = old * 2;
        let mut write = 0;
        for &c in &self.closed {
            let c = c as usize;
            let ObjectSamples { seen, stride, start, len, .. } = self.objects[c];
            let to = if stride == old {
                stride_for(self.global, seen, self.rule.min_samples_per_object)
            } else {
                stride
            };
            let step = (to / stride.max(1)).max(1) as usize;
            let kept = len.div_ceil(step);
            for k in 0..kept {
                self.arena[write + k] = self.arena[start + k * step];
            }
            self.objects[c].start = write;
            self.objects[c].len = kept;
            self.objects[c].stride = to;
            write += kept;
        }
        self.arena.truncate(write);
        if let Some(o) = self.open {
            let s = &mut self.objects[o as usize];
            if s.stride == old {
                let to = stride_for(self.global, s.seen, self.rule.min_samples_per_object).max(s.stride);
                thin(&mut self.open_points, s.stride, to);
                s.stride = to;
            }
        }
        let at: u64 = self
            .closed
            .iter()
            .map(|&c| self.objects[c as usize])
            .chain(self.open.map(|o| self.objects[o as usize]))
            .filter(|s| s.stride == self.global)
            .map(|s| if s.closed { s.len as u64 } else { self.open_points.len() as u64 })
            .sum();
        let total = self.arena.len() as u64 + self.open_points.len() as u64;
        (self.held_at_global, self.held_below) = (at, total - at);
        self.held_final = self
            .closed
            .iter()
            .map(|&c| self.objects[c as usize])
            .filter(|s| s.stride < self.global)
            .map(|s| s.len as u64)
            .sum();
    }

    fn give_up(&mut self) {
        self.gave_up = true;
        self.objects = Vec::new();
        self.open = None;
        self.open_points = Vec::new();
        self.arena = Vec::new();
        self.closed = Vec::new();
    }

    /// The samples of the rule for objects of these triangle counts (indexed by object id), or
    /// `None` if the sampler gave up or the counts disagree with what it saw.
    pub fn finish(mut self, counts: &[u64]) -> Option<CentroidSamples> {
        if self.gave_up || !self.switch_to(None) {
            return None;
        }
        let large = self.rule.large(counts.iter().copied());
        let stride: Vec<u64> = counts.iter().map(|&n| self.rule.stride(n, large)).collect();
        for (o, &n) in counts.iter().enumerate() {
            let s = self.objects.get(o).copied().unwrap_or_default();
            // A sampled object must be in the arena at a stride it can be thinned from.
            let usable = s.seen == n && (stride[o] == 0 || (s.closed && s.len > 0 && s.stride <= stride[o]));
            if !usable {
                return None;
            }
        }
        if self.objects.len() > counts.len() {
            return None;
        }
        // Thin every sampled object to its stride, laid out by object id: in place when the
        // objects closed in id order (the usual case), else copied.
        let by_id = self.closed.is_sorted();
        let mut points = if by_id { std::mem::take(&mut self.arena) } else { Vec::new() };
        let mut write = 0;
        let mut start = Vec::with_capacity(counts.len() + 1);
        start.push(0);
        for (o, &to) in stride.iter().enumerate() {
            if to > 0 {
                let s = self.objects[o];
                let step = (to / s.stride) as usize;
                let kept = s.len.div_ceil(step);
                if kept as u64 != counts[o].div_ceil(to) {
                    return None;
                }
                if by_id {
                    for k in 0..kept {
                        points[write + k] = points[s.start + k * step];
                    }
                } else {
                    points.extend(self.arena[s.start..s.start + s.len].iter().step_by(step));
                }
                write += kept;
            }
            start.push(write);
        }
        points.truncate(write);
        points.shrink_to_fit();
        Some(CentroidSamples { rule: Some(self.rule), points, start, stride })
    }
}

/// The stride of an object that has seen `seen` triangles when the global stride is `global`.
fn stride_for(global: u64, seen: u64, min_samples: u64) -> u64 {
    global.min(floor_pow2((seen / min_samples.max(1)).max(1)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rule applied to a whole stream at once.
    fn by_rule(rule: SampleRule, stream: &[(u32, [f32; 3])], objects: usize) -> CentroidSamples {
        let mut counts = vec![0u64; objects];
        for &(o, _) in stream {
            counts[o as usize] += 1;
        }
        let large = rule.large(counts.iter().copied());
        let stride: Vec<u64> = counts.iter().map(|&n| rule.stride(n, large)).collect();
        let mut per: Vec<Vec<[f32; 3]>> = vec![Vec::new(); objects];
        let mut seen = vec![0u64; objects];
        for &(o, c) in stream {
            let o = o as usize;
            if stride[o] > 0 && seen[o].is_multiple_of(stride[o]) {
                per[o].push(c);
            }
            seen[o] += 1;
        }
        let mut out = CentroidSamples { rule: Some(rule), start: vec![0], stride, ..Default::default() };
        for p in per {
            out.points.extend(p);
            out.start.push(out.points.len());
        }
        out
    }

    fn online(rule: SampleRule, stream: &[(u32, [f32; 3])], objects: usize) -> Option<CentroidSamples> {
        let mut s = OnlineSampler::new(rule, u64::MAX);
        let mut counts = vec![0u64; objects];
        for &(o, c) in stream {
            s.add(o, c);
            counts[o as usize] += 1;
        }
        s.finish(&counts)
    }

    /// Objects of these sizes, one after the other; centroids number the triangles.
    fn contiguous(sizes: &[u64]) -> Vec<(u32, [f32; 3])> {
        let mut out = Vec::new();
        for (o, &n) in sizes.iter().enumerate() {
            for _ in 0..n {
                let k = out.len() as f32;
                out.push((o as u32, [k, -k, o as f32]));
            }
        }
        out
    }

    #[test]
    fn strides_are_powers_of_two_within_the_rule() {
        let rule = SampleRule { t1: 1000, max_samples: 2_000_000, min_samples_per_object: 64 };
        assert_eq!(rule.stride(1000, 1 << 40), 0);
        assert_eq!(rule.stride(1001, 1001), 1);
        // r = 45: 32; n / 64 = 15: 8.
        assert_eq!(rule.stride(1_000_000, 90_000_000), 32);
        assert_eq!(rule.stride(1000 * 64 / 64 + 1000, 90_000_000), 16);
        assert_eq!(rule.stride(1001, 90_000_000), 8);
        for n in [1001u64, 5000, 1 << 20, 12_345_678] {
            for large in [n, 3 * n, 1 << 33] {
                let s = rule.stride(n, large);
                assert!(s.is_power_of_two());
                assert!(n / s >= 64 || s == 1, "{n} {large}");
                assert!(s <= large.div_ceil(rule.max_samples).max(1));
            }
        }
    }

    #[test]
    fn online_samples_equal_the_rule_on_contiguous_objects() {
        let sizes = [0, 5, 1000, 1001, 4096, 70_000, 3, 250_000, 1500, 0, 9999];
        for (max_samples, min) in [(2_000_000, 64), (1000, 64), (5000, 16), (100, 2), (1, 8), (1, 2)] {
            let rule = SampleRule { t1: 1000, max_samples, min_samples_per_object: min };
            let stream = contiguous(&sizes);
            let got = online(rule, &stream, sizes.len());
            assert_eq!(got, Some(by_rule(rule, &stream, sizes.len())), "{max_samples} {min}");
        }
    }

    #[test]
    fn runs_of_any_length_give_the_samples_of_one_by_one() {
        let sizes = [0u64, 5, 1000, 1001, 4096, 70_000, 3, 250_000, 1500, 9999];
        let stream = contiguous(&sizes);
        for (max_samples, min) in [(2_000_000, 64), (1000, 64), (300, 2), (5000, 16)] {
            let rule = SampleRule { t1: 1000, max_samples, min_samples_per_object: min };
            let expected = Some(by_rule(rule, &stream, sizes.len()));
            for run in [1usize, 2, 7, 64, 1000, 100_000] {
                let mut s = OnlineSampler::new(rule, u64::MAX);
                let mut at = 0;
                for (o, &n) in sizes.iter().enumerate() {
                    let centroids: Vec<[f32; 3]> = stream[at..at + n as usize].iter().map(|t| t.1).collect();
                    // Runs of varying length, as batches cut them.
                    for (k, chunk) in centroids.chunks(run).enumerate() {
                        let (a, b) = chunk.split_at(chunk.len().min(k % 3));
                        s.add_run(o as u32, a);
                        s.add_run(o as u32, b);
                    }
                    at += n as usize;
                }
                assert!(s.finish(&sizes) == expected, "{max_samples} {min}, runs of {run}");
            }
        }
    }

    #[test]
    fn objects_closed_out_of_id_order_are_laid_out_by_id() {
        let sizes = [3000u64, 20, 7000, 1500];
        let mut stream = Vec::new();
        for o in [2u32, 1, 3, 0] {
            for _ in 0..sizes[o as usize] {
                let k = stream.len() as f32;
                stream.push((o, [k, 0.5 * k, o as f32]));
            }
        }
        let rule = SampleRule { t1: 1000, max_samples: 300, min_samples_per_object: 8 };
        assert_eq!(online(rule, &stream, sizes.len()), Some(by_rule(rule, &stream, sizes.len())));
    }

    #[test]
    fn the_global_stride_bounds_memory_and_stays_exact() {
        // Many large objects and a small sample budget: G must double several times.
        let sizes: Vec<u64> = (0..200).map(|k| 2000 + 37 * k).collect();
        let rule = SampleRule { t1: 1000, max_samples: 500, min_samples_per_object: 2 };
        let stream = contiguous(&sizes);
        let mut s = OnlineSampler::new(rule, u64::MAX);
        let mut peak = 0;
        for &(o, c) in &stream {
            s.add(o, c);
            peak = peak.max(s.held_at_global + s.held_below);
        }
        assert!(s.global > 8, "G = {}", s.global);
        // T = 4 · max_samples for m = 2, and the objects below G hold 2m samples at most.
        assert!(peak <= 4 * rule.max_samples + 1 + 4 * 200, "peak {peak}");
        assert_eq!(s.finish(&sizes), Some(by_rule(rule, &stream, sizes.len())));
    }

    #[test]
    fn the_memory_cap_gives_up() {
        let sizes = [5000, 5000, 5000];
        let rule = SampleRule { t1: 1000, max_samples: 2_000_000, min_samples_per_object: 64 };
        let stream = contiguous(&sizes);
        // Stride 1 until 64 · 2 triangles, then 2, …: thousands of samples held.
        let mut s = OnlineSampler::new(rule, 1000 * 12);
        for &(o, c) in &stream {
            s.add(o, c);
        }
        assert!(s.gave_up());
        assert_eq!(s.finish(&sizes), None);
    }

    #[test]
    fn final_samples_do_not_count_against_the_cap() {
        // 300 objects of 1,100–1,400 triangles with m = 8: each keeps 8–15 samples at a stride
        // below G once G has doubled past 128, about 3,300 final samples in all, far beyond a
        // cap of 4 · max_samples + 2m (T is 16/7 · max_samples).
        let sizes: Vec<u64> = (0..300).map(|k| 1100 + k).collect();
        let rule = SampleRule { t1: 1000, max_samples: 50, min_samples_per_object: 8 };
        let stream = contiguous(&sizes);
        let mut s = OnlineSampler::new(rule, 12 * (4 * 50 + 16));
        for &(o, c) in &stream {
            s.add(o, c);
        }
        assert!(!s.gave_up());
        let expected = by_rule(rule, &stream, sizes.len());
        assert!(expected.points.len() > 3000, "{} samples", expected.points.len());
        assert_eq!(s.finish(&sizes), Some(expected));
    }

    #[test]
    fn interleaved_objects_and_wrong_counts_give_up() {
        let rule = SampleRule { t1: 10, max_samples: 1000, min_samples_per_object: 4 };
        let mut stream = contiguous(&[50, 50]);
        stream.push((0, [0.0; 3]));
        assert_eq!(online(rule, &stream, 2), None);
        let stream = contiguous(&[50, 50]);
        let mut s = OnlineSampler::new(rule, u64::MAX);
        for &(o, c) in &stream {
            s.add(o, c);
        }
        assert_eq!(s.finish(&[50, 51]), None);
    }
}
