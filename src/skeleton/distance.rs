//! Exact Euclidean distance transform of a voxel grid (Felzenszwalb and Huttenlocher, "Distance
//! Transforms of Sampled Functions", Theory of Computing 8, 2012): one lower-envelope pass per
//! axis, linear in the number of voxels. Public as [`squared_distance_transform`]; the skeleton
//! clearance and the `topoloc-sim` path planner both use it.

use super::{out_of_memory, try_vec};
use super::{OccupancyGrid, SkeletonError};

/// Squared distance, in voxels, used for "no obstacle anywhere on this line (yet)": finite, so
/// that the parabola intersections never compute `inf - inf`.
const FAR: f64 = 1e30;

/// Any value at or above this is [`FAR`] plus a few squared voxels: no obstacle was reached
/// (a real squared distance in a grid of at most [`MAX_VOXELS`](crate::skeleton::MAX_VOXELS) voxels
/// is below 1.4e19).
const UNREACHED: f64 = 1e29;

/// What lies outside an [`OccupancyGrid`] for [`squared_distance_transform`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum GridBorder {
    /// Outside the grid is free: only the grid's occupied voxels are obstacles, and a grid
    /// without any gives `f64::INFINITY` everywhere. (Skeleton clearance,
    /// [`SkeletonOptions::min_clearance_m`](crate::skeleton::SkeletonOptions::min_clearance_m).)
    Open,
    /// Outside the grid is occupied, as in [`OccupancyGrid::is_occupied`] (the grid is
    /// closed): the voxels just beyond each face are obstacles too, so a voxel is at most
    /// `min(c + 1, n - c)` voxels from one, for each axis (coordinate `c` of `n` voxels), and
    /// every value is finite.
    Closed,
}

/// Exact squared Euclidean distance transform of `grid`.
///
/// Returns, for every voxel in the grid's order (x fastest, as [`OccupancyGrid::cells`] and
/// [`OccupancyGrid::index`]), the squared distance from its centre to the centre of the nearest
/// obstacle voxel, **in squared voxels** (whole numbers; multiply by `voxel_size()²` for square
/// metres, take the square root for a distance). Obstacles are the occupied voxels of the grid
/// (distance 0), plus, with [`GridBorder::Closed`], the voxels just outside it; with
/// [`GridBorder::Open`] a voxel with no obstacle anywhere gets `f64::INFINITY`.
///
/// The result is exact (not a chamfer approximation): Felzenszwalb and Huttenlocher's separable
/// transform, one lower envelope of parabolas per line along x, then y, then z. Cost: O(voxels)
/// time (three passes over the grid), single-threaded; memory: one `f64` per voxel for the
/// result plus a few lines of scratch.
///
/// Fails with [`SkeletonError::InvalidArgument`] naming `dims` when the memory for the result
/// cannot be reserved.
pub fn squared_distance_transform(
    grid: &OccupancyGrid,
    border: GridBorder,
) -> Result<Vec<f64>, SkeletonError> {
    squared_distance_to(grid.dims(), grid.cells(), border)
        .ok_or_else(|| out_of_memory(grid, "distance transform"))
}

/// [`squared_distance_transform`] of a grid of `dims` (x fastest) whose obstacles are the
/// voxels where `obstacle` is true. `None` when the memory cannot be reserved.
fn squared_distance_to(
    dims: [usize; 3],
    obstacle: &[bool],
    border: GridBorder,
) -> Option<Vec<f64>> {
    let mut d = try_vec(obstacle.len(), FAR)?;
    for (di, &o) in d.iter_mut().zip(obstacle) {
        if o {
            *di = 0.0;
        }
    }
    let closed = border == GridBorder::Closed;
    // A closed grid: each line gets an obstacle site just outside either end.
    let pad = usize::from(closed);
    let longest = dims.iter().max().copied().unwrap_or(0) + 2 * pad;
    let mut line = vec![0.0; longest];
    let mut out = vec![0.0; longest];
    let mut envelope = Envelope::with_capacity(longest);
    let mut stride = 1;
    for n in dims {
        let span = stride * n;
        if n == 1 && !closed {
            stride = span;
            continue; // nothing to propagate along a single voxel
        }
        let padded = n + 2 * pad;
        // The lines along this axis start at the voxels whose coordinate on it is 0.
        for block in (0..d.len()).step_by(span) {
            for start in block..block + stride {
                for (k, slot) in line[pad..pad + n].iter_mut().enumerate() {
                    *slot = d[start + k * stride];
                }
                if closed {
                    (line[0], line[padded - 1]) = (0.0, 0.0);
                }
                envelope.transform(&line[..padded], &mut out[..padded]);
                for (k, &value) in out[pad..pad + n].iter().enumerate() {
                    d[start + k * stride] = value;
                }
            }
        }
        stride = span;
    }
    if !closed {
        for di in d.iter_mut().filter(|di| **di >= UNREACHED) {
            *di = f64::INFINITY;
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
    use nalgebra::Point3;

    fn grid(dims: [usize; 3], occupied: &[[usize; 3]]) -> OccupancyGrid {
        let mut grid = OccupancyGrid::empty(dims, 0.1, Point3::origin()).unwrap();
        for &v in occupied {
            assert!(grid.set(v, true));
        }
        grid
    }

    /// Brute-force squared distance from `v` to the nearest occupied voxel, and with a closed
    /// border to the nearest voxel of the layer just outside the grid.
    fn brute(grid: &OccupancyGrid, v: [usize; 3], border: GridBorder) -> f64 {
        let dims = grid.dims().map(|d| d as i64);
        let outside = i64::from(border == GridBorder::Closed);
        let mut best = f64::INFINITY;
        for z in -outside..dims[2] + outside {
            for y in -outside..dims[1] + outside {
                for x in -outside..dims[0] + outside {
                    let inside = [x, y, z].iter().zip(&dims).all(|(&c, &n)| c >= 0 && c < n);
                    if inside && grid.is_free([x as usize, y as usize, z as usize]) {
                        continue;
                    }
                    let d = [x - v[0] as i64, y - v[1] as i64, z - v[2] as i64];
                    best = best.min((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) as f64);
                }
            }
        }
        best
    }

    #[test]
    fn matches_brute_force() {
        let n = 7 * 5 * 4;
        let scattered: Vec<bool> = (0..n).map(|i| (i * 7919) % 23 == 0).collect();
        let grids = [
            OccupancyGrid::new([7, 5, 4], 0.1, Point3::origin(), scattered).unwrap(),
            grid([9, 7, 5], &[[4, 3, 2], [1, 1, 1], [7, 5, 3], [8, 0, 0]]),
            grid([6, 1, 3], &[[2, 0, 1]]),
            grid([1, 8, 1], &[]),
        ];
        for grid in &grids {
            for border in [GridBorder::Open, GridBorder::Closed] {
                let d = squared_distance_transform(grid, border).unwrap();
                assert_eq!(d.len(), grid.len());
                for (i, &di) in d.iter().enumerate() {
                    let v = grid.voxel_of(i);
                    assert_eq!(
                        di,
                        brute(grid, v, border),
                        "{:?} {border:?} voxel {v:?}",
                        grid.dims()
                    );
                }
            }
        }
    }

    #[test]
    fn known_distances() {
        // One row: an obstacle at x = 1.
        let row = grid([6, 1, 1], &[[1, 0, 0]]);
        let open = squared_distance_transform(&row, GridBorder::Open).unwrap();
        assert_eq!(open, [1.0, 0.0, 1.0, 4.0, 9.0, 16.0]);
        // Closed: the voxels at x = -1 and x = 6 are obstacles too, and so are those just
        // above and below the single layer (y and z), one voxel from every centre.
        let closed = squared_distance_transform(&row, GridBorder::Closed).unwrap();
        assert_eq!(closed, [1.0, 0.0, 1.0, 1.0, 1.0, 1.0]);

        // A 4 x 3 x 2 slab, obstacle at the origin: open distances are x² + y² + z².
        let slab = grid([4, 3, 2], &[[0, 0, 0]]);
        let open = squared_distance_transform(&slab, GridBorder::Open).unwrap();
        for (i, &d) in open.iter().enumerate() {
            let [x, y, z] = slab.voxel_of(i);
            assert_eq!(d, (x * x + y * y + z * z) as f64, "voxel {:?}", [x, y, z]);
        }
        // Closed, in a 5 x 5 x 5 cube without obstacles: one more than the fewest voxels to a
        // face, squared; the centre is 3 voxels from the outside layer.
        let cube = grid([5, 5, 5], &[]);
        let closed = squared_distance_transform(&cube, GridBorder::Closed).unwrap();
        assert_eq!(closed[cube.index([2, 2, 2]).unwrap()], 9.0);
        assert_eq!(closed[cube.index([1, 2, 2]).unwrap()], 4.0);
        assert_eq!(closed[cube.index([0, 4, 2]).unwrap()], 1.0);
    }

    #[test]
    fn no_obstacle_is_infinite_only_when_open() {
        let empty = grid([3, 3, 1], &[]);
        let open = squared_distance_transform(&empty, GridBorder::Open).unwrap();
        assert!(open.iter().all(|&x| x == f64::INFINITY));
        let closed = squared_distance_transform(&empty, GridBorder::Closed).unwrap();
        assert!(closed.iter().all(|&x| x == 1.0), "{closed:?}");
    }
}
