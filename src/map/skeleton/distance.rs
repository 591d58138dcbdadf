//! Exact Euclidean distance transform of a voxel grid (Felzenszwalb and Huttenlocher, "Distance
//! Transforms of Sampled Functions", Theory of Computing 8, 2012): one lower-envelope pass per
//! axis, linear in the number of voxels.

use super::try_vec;

/// Squared distance, in voxels, used for "no obstacle anywhere on this line (yet)".
const FAR: f64 = 1e30;

/// For every voxel of a grid of `dims` (x fastest), the squared distance in voxel units from its
/// centre to the centre of the nearest voxel for which `obstacle` is true; `FAR`-ish (>= 1e29)
/// when there is none. `None` when the memory cannot be reserved.
pub(super) fn squared_distance_to(dims: [usize; 3], obstacle: &[bool]) -> Option<Vec<f64>> {
    let mut d = try_vec(obstacle.len(), FAR)?;
    for (di, &o) in d.iter_mut().zip(obstacle) {
        if o {
            *di = 0.0;
        }
    }
    let [nx, ny, nz] = dims;
    let longest = nx.max(ny).max(nz);
    let mut line = vec![0.0; longest];
    let mut out = vec![0.0; longest];
    let mut scratch = Envelope::with_capacity(longest);
    let strides = [1, nx, nx * ny];
    for axis in 0..3 {
        let n = dims[axis];
        if n == 1 && axis > 0 {
            continue; // nothing to propagate along a single voxel
        }
        let stride = strides[axis];
        // Every line along `axis` starts at a voxel whose `axis` coordinate is 0.
        for start in 0..d.len() {
            let coordinate = (start / stride) % n;
            if coordinate != 0 {
                continue;
            }
            for (k, slot) in line[..n].iter_mut().enumerate() {
                *slot = d[start + k * stride];
            }
            scratch.transform(&line[..n], &mut out[..n]);
            for (k, &value) in out[..n].iter().enumerate() {
                d[start + k * stride] = value;
            }
        }
    }
    Some(d)
}

/// Buffers of the one-dimensional transform.
struct Envelope {
    /// Positions of the parabolas of the lower envelope.
    v: Vec<usize>,
    /// Boundaries between consecutive parabolas.
    z: Vec<f64>,
}

impl Envelope {
    fn with_capacity(n: usize) -> Self {
        Self {
            v: vec![0; n],
            z: vec![0.0; n + 1],
        }
    }

    /// `out[q] = min_p (q - p)^2 + f[p]`.
    fn transform(&mut self, f: &[f64], out: &mut [f64]) {
        let n = f.len();
        let (v, z) = (&mut self.v, &mut self.z);
        let mut k = 0usize;
        v[0] = 0;
        z[0] = f64::NEG_INFINITY;
        z[1] = f64::INFINITY;
        for q in 1..n {
            let fq = f[q] + (q * q) as f64;
            let intersection = |p: usize| (fq - (f[p] + (p * p) as f64)) / (2.0 * (q - p) as f64);
            let mut s = intersection(v[k]);
            // z[0] is -inf, so this stops at k = 0.
            while s <= z[k] {
                k -= 1;
                s = intersection(v[k]);
            }
            k += 1;
            v[k] = q;
            z[k] = s;
            z[k + 1] = f64::INFINITY;
        }
        k = 0;
        for (q, slot) in out.iter_mut().enumerate() {
            while z[k + 1] < q as f64 {
                k += 1;
            }
            let p = v[k];
            let dq = q as f64 - p as f64;
            *slot = dq * dq + f[p];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_brute_force() {
        let dims = [7, 5, 4];
        let n = dims[0] * dims[1] * dims[2];
        let obstacle: Vec<bool> = (0..n).map(|i| (i * 7919) % 23 == 0).collect();
        let d = squared_distance_to(dims, &obstacle).unwrap();
        let at = |i: usize| [i % 7, (i / 7) % 5, i / 35];
        for (i, &di) in d.iter().enumerate() {
            let a = at(i);
            let best = (0..n)
                .filter(|&j| obstacle[j])
                .map(|j| {
                    let b = at(j);
                    (0..3)
                        .map(|k| (a[k] as f64 - b[k] as f64).powi(2))
                        .sum::<f64>()
                })
                .fold(f64::INFINITY, f64::min);
            assert_eq!(di, best, "voxel {a:?}");
        }
    }

    #[test]
    fn no_obstacle_is_far() {
        let d = squared_distance_to([3, 3, 1], &[false; 9]).unwrap();
        assert!(d.iter().all(|&x| x >= 1e29));
    }
}
