//! A small portable random generator (SplitMix64) and integer hashes.
//!
//! Worlds, textures and sensor noise are defined by seeds, so their draws must not change when a
//! dependency is upgraded or the platform differs: this generator is a few lines of integer
//! arithmetic with a fixed output for every seed, unlike `rand`'s `SmallRng`.

/// SplitMix64 (Steele, Lea and Flood 2014): 64-bit state, passes BigCrush, fast.
#[derive(Clone, Debug)]
pub struct SimRng {
    state: u64,
}

/// The SplitMix64 output function: a bijective 64-bit mix.
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A hash of `seed` and up to three integers, uniform over `u64`.
pub fn hash3(seed: u64, a: i64, b: i64, c: i64) -> u64 {
    let mut h = mix64(seed ^ 0x9e37_79b9_7f4a_7c15);
    for x in [a, b, c] {
        h = mix64(h ^ (x as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    }
    h
}

/// [`hash3`] mapped to `[0, 1)`.
pub fn hash_unit(seed: u64, a: i64, b: i64, c: i64) -> f64 {
    (hash3(seed, a, b, c) >> 11) as f64 / (1u64 << 53) as f64
}

impl SimRng {
    /// A generator whose stream depends only on `seed`.
    pub fn new(seed: u64) -> Self {
        Self {
            state: mix64(seed ^ 0x6a09_e667_f3bc_c909),
        }
    }

    /// An independent generator for the part of a computation named `tag`: drawing more or
    /// fewer numbers in one part does not shift the draws of another.
    pub fn fork(&self, tag: u64) -> Self {
        Self::new(mix64(self.state ^ mix64(tag.wrapping_add(1))))
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9e37_79b9_7f4a_7c15);
        mix64(self.state)
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[lo, hi)` (`lo` when the range is empty).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        if hi > lo {
            lo + (hi - lo) * self.unit()
        } else {
            lo
        }
    }

    /// Uniform integer in `0..n` (0 when `n` is 0).
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            (((self.next_u64() >> 32) * n as u64) >> 32) as usize
        }
    }

    /// Uniform integer in `lo..=hi` (`lo` when `hi < lo`).
    pub fn between(&mut self, lo: usize, hi: usize) -> usize {
        lo + self.below(hi.saturating_sub(lo) + 1)
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }

    /// A uniformly chosen element (`None` for an empty slice).
    pub fn pick<'a, T>(&mut self, items: &'a [T]) -> Option<&'a T> {
        (!items.is_empty()).then(|| &items[self.below(items.len())])
    }

    /// Shuffles `items` in place (Fisher-Yates).
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            items.swap(i, self.below(i + 1));
        }
    }

    /// Approximately standard normal: the sum of four 16-bit uniforms, rescaled (Irwin-Hall);
    /// bounded by +-3.46.
    pub fn normal(&mut self) -> f32 {
        let bits = self.next_u64();
        let sum: u32 = (0..4).map(|i| ((bits >> (16 * i)) & 0xffff) as u32).sum();
        (sum as f32 / 65536.0 - 2.0) * 3f32.sqrt()
    }

    /// Three approximately standard normals from one draw, each the sum of three 7-bit
    /// uniforms (Irwin-Hall, piecewise quadratic), rescaled; bounded by +-3. Cheap enough for
    /// per-pixel, per-channel sensor noise.
    pub fn normal_triple(&mut self) -> [f32; 3] {
        let bits = self.next_u64();
        let one = |h: u64| {
            let sum = (h & 0x7f) + ((h >> 7) & 0x7f) + ((h >> 14) & 0x7f);
            // Each uniform is (k + 0.5) / 128: mean 1.5 and variance 1/4 for the sum.
            ((sum as f32 + 1.5) / 128.0 - 1.5) * 2.0
        };
        [one(bits), one(bits >> 21), one(bits >> 42)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_fixed_and_forks_independent() {
        let mut a = SimRng::new(7);
        let mut b = SimRng::new(7);
        assert_eq!(a.next_u64(), b.next_u64());
        let fa = a.fork(1).next_u64();
        let fb = a.fork(2).next_u64();
        assert_ne!(fa, fb);
        let mut r = SimRng::new(1);
        let n = 20_000;
        let mean: f64 = (0..n).map(|_| r.unit()).sum::<f64>() / n as f64;
        assert!((mean - 0.5).abs() < 0.01, "{mean}");
        let var: f32 = (0..n).map(|_| r.normal().powi(2)).sum::<f32>() / n as f32;
        assert!((var - 1.0).abs() < 0.05, "{var}");
        let triples: Vec<[f32; 3]> = (0..n).map(|_| r.normal_triple()).collect();
        let all = || triples.iter().flatten();
        let mean: f32 = all().sum::<f32>() / (3 * n) as f32;
        let var: f32 = all().map(|x| x * x).sum::<f32>() / (3 * n) as f32;
        assert!(
            mean.abs() < 0.02 && (var - 1.0).abs() < 0.05,
            "{mean} {var}"
        );
        assert!((0..1000).all(|_| r.below(5) < 5));
        assert_eq!(r.below(0), 0);
        assert_eq!(hash3(3, 1, 2, 3), hash3(3, 1, 2, 3));
        assert_ne!(hash3(3, 1, 2, 3), hash3(3, 1, 2, 4));
    }
}
