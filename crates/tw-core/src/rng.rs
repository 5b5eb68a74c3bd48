//! A deterministic random number generator: PCG-XSH-RR with 64-bit state and 32-bit output
//! (O'Neill 2014). Small, fast and stable across platforms and dependency versions, which the
//! generator's "same seed, same scene" promise needs.

#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

const MULTIPLIER: u64 = 6364136223846793005;

impl Rng {
    /// A generator for `seed` on the default stream.
    pub fn new(seed: u64) -> Rng {
        Rng::with_stream(seed, 0xda3e_39cb_94b9_5bdb)
    }

    /// A generator for `seed` on stream `stream`: different streams are independent sequences,
    /// so a scene can give each part its own generator (`Rng::with_stream(seed, part_index)`)
    /// and stay deterministic whatever order the parts are made in.
    pub fn with_stream(seed: u64, stream: u64) -> Rng {
        let mut rng = Rng { state: 0, inc: (stream << 1) | 1 };
        rng.next_u32();
        rng.state = rng.state.wrapping_add(seed);
        rng.next_u32();
        rng
    }

    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(MULTIPLIER).wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    pub fn next_u64(&mut self) -> u64 {
        ((self.next_u32() as u64) << 32) | self.next_u32() as u64
    }

    /// Uniform in [0, 1).
    pub fn f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range_f64(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.f64()
    }

    /// Uniform integer in [lo, hi); `hi > lo` is required.
    pub fn range_u32(&mut self, lo: u32, hi: u32) -> u32 {
        assert!(hi > lo, "empty range {lo}..{hi}");
        let span = (hi - lo) as u64;
        lo + ((self.next_u32() as u64 * span) >> 32) as u32
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        self.f64() < p
    }

    /// A uniformly chosen element of a non-empty slice.
    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> &'a T {
        &items[self.range_u32(0, items.len() as u32) as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_sequence_and_streams_differ() {
        let a: Vec<u32> = (0..8).scan(Rng::new(7), |r, _| Some(r.next_u32())).collect();
        let b: Vec<u32> = (0..8).scan(Rng::new(7), |r, _| Some(r.next_u32())).collect();
        let c: Vec<u32> = (0..8).scan(Rng::with_stream(7, 1), |r, _| Some(r.next_u32())).collect();
        assert_eq!(a, b);
        assert_ne!(a, c);
    }

    #[test]
    fn pinned_values_do_not_change_between_versions() {
        // Generated scenes depend on this exact sequence.
        let mut r = Rng::new(42);
        let v: Vec<u32> = (0..3).map(|_| r.next_u32()).collect();
        assert_eq!(v, PINNED);
    }
    const PINNED: [u32; 3] = [1898997482, 1014631766, 4096008554];

    #[test]
    fn ranges_stay_in_bounds() {
        let mut r = Rng::new(1);
        for _ in 0..10_000 {
            let x = r.range_u32(3, 9);
            assert!((3..9).contains(&x));
            let f = r.range_f64(-2.0, 5.0);
            assert!((-2.0..5.0).contains(&f));
        }
    }
}
