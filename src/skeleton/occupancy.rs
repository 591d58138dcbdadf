//! 3D occupancy voxel grids: the input of skeleton map building, and what `topoloc-sim` worlds
//! are made of.
//!
//! Voxel `(x, y, z)` covers the box `origin + voxel_size * [x, x+1) x [y, y+1) x [z, z+1)` in
//! world metres (z up). Voxels are stored x fastest, then y, then z:
//! `index = x + nx * (y + ny * z)`. A voxel is occupied (an obstacle) or free.

use super::SkeletonError;
use nalgebra::{Point3, Vector3};

/// Most voxels a grid may hold (2^31): 2 GiB of cells, far beyond any indoor map at 0.1 m.
pub const MAX_VOXELS: usize = 1 << 31;

/// A voxel index `[x, y, z]`.
pub type Voxel = [usize; 3];

/// An occupancy voxel grid (see the module documentation for its layout).
#[derive(Clone, Debug, PartialEq)]
pub struct OccupancyGrid {
    dims: [usize; 3],
    voxel_size: f64,
    origin: Point3<f64>,
    occupied: Vec<bool>,
}

impl OccupancyGrid {
    /// A grid of `dims` voxels of `voxel_size` metres whose corner voxel starts at `origin`,
    /// with cells `occupied` in the module's order. Fails with [`SkeletonError::InvalidArgument`]
    /// naming the field for a zero or oversized dimension, a non-positive or non-finite voxel
    /// size, a non-finite origin, or a cell count other than `nx * ny * nz`.
    pub fn new(
        dims: [usize; 3],
        voxel_size: f64,
        origin: Point3<f64>,
        occupied: Vec<bool>,
    ) -> Result<Self, SkeletonError> {
        let invalid = |msg: String| Err(SkeletonError::InvalidArgument(msg));
        if dims.contains(&0) {
            return invalid(format!("dims {dims:?}: every dimension must be at least 1"));
        }
        let Some(count) = dims[0]
            .checked_mul(dims[1])
            .and_then(|n| n.checked_mul(dims[2]))
            .filter(|&n| n <= MAX_VOXELS)
        else {
            return invalid(format!("dims {dims:?}: more than {MAX_VOXELS} voxels"));
        };
        if !(voxel_size.is_finite() && voxel_size > 0.0) {
            return invalid(format!(
                "voxel_size {voxel_size}: must be finite and positive"
            ));
        }
        if !origin.iter().all(|c| c.is_finite()) {
            return invalid(format!("origin {origin}: must be finite"));
        }
        if occupied.len() != count {
            return invalid(format!(
                "occupied holds {} cells, dims {dims:?} need {count}",
                occupied.len()
            ));
        }
        Ok(Self {
            dims,
            voxel_size,
            origin,
            occupied,
        })
    }

    /// A grid with every voxel free (errors as [`OccupancyGrid::new`]).
    pub fn empty(
        dims: [usize; 3],
        voxel_size: f64,
        origin: Point3<f64>,
    ) -> Result<Self, SkeletonError> {
        let count = dims
            .iter()
            .try_fold(1usize, |n, &d| n.checked_mul(d))
            .filter(|&n| n <= MAX_VOXELS)
            .unwrap_or(0); // a bad count fails in `new`, naming `dims`
        Self::new(dims, voxel_size, origin, vec![false; count])
    }

    /// Voxels along x, y and z.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }

    /// Edge length of a voxel, metres.
    pub fn voxel_size(&self) -> f64 {
        self.voxel_size
    }

    /// World position of the outer corner of voxel `[0, 0, 0]`.
    pub fn origin(&self) -> Point3<f64> {
        self.origin
    }

    /// The cells, x fastest (see the module documentation).
    pub fn cells(&self) -> &[bool] {
        &self.occupied
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.occupied.len()
    }

    /// Always false: a grid has at least one voxel.
    pub fn is_empty(&self) -> bool {
        self.occupied.is_empty()
    }

    /// Linear index of `v`, or `None` outside the grid.
    pub fn index(&self, v: Voxel) -> Option<usize> {
        let [nx, ny, nz] = self.dims;
        (v[0] < nx && v[1] < ny && v[2] < nz).then(|| v[0] + nx * (v[1] + ny * v[2]))
    }

    /// The voxel at linear index `i` (`i < len()`).
    pub fn voxel_of(&self, i: usize) -> Voxel {
        let [nx, ny, _] = self.dims;
        [i % nx, (i / nx) % ny, i / (nx * ny)]
    }

    /// Whether `v` is occupied; voxels outside the grid count as occupied (the grid is closed).
    pub fn is_occupied(&self, v: Voxel) -> bool {
        self.index(v).is_none_or(|i| self.occupied[i])
    }

    /// Whether `v` is inside the grid and free.
    pub fn is_free(&self, v: Voxel) -> bool {
        !self.is_occupied(v)
    }

    /// Marks `v` occupied or free; returns false (and changes nothing) outside the grid.
    pub fn set(&mut self, v: Voxel, occupied: bool) -> bool {
        match self.index(v) {
            Some(i) => {
                self.occupied[i] = occupied;
                true
            }
            None => false,
        }
    }

    /// Number of free voxels.
    pub fn free_count(&self) -> usize {
        self.occupied.iter().filter(|&&o| !o).count()
    }

    /// World position of the centre of voxel `v`.
    pub fn center(&self, v: Voxel) -> Point3<f64> {
        self.origin
            + Vector3::new(v[0] as f64 + 0.5, v[1] as f64 + 0.5, v[2] as f64 + 0.5)
                * self.voxel_size
    }

    /// The voxel containing world point `p`, or `None` outside the grid.
    pub fn voxel_at(&self, p: &Point3<f64>) -> Option<Voxel> {
        let local = (p - self.origin) / self.voxel_size;
        let mut v = [0usize; 3];
        for k in 0..3 {
            let c = local[k].floor();
            if !(c >= 0.0 && c < self.dims[k] as f64) {
                return None;
            }
            v[k] = c as usize;
        }
        Some(v)
    }

    /// Whether the straight segment from `a` to `b` (world metres) crosses only free voxels,
    /// both ends included. Walks every voxel the segment touches (Amanatides-Woo traversal).
    pub fn segment_is_free(&self, a: &Point3<f64>, b: &Point3<f64>) -> bool {
        self.segment_voxels(a, b, |v| self.is_free(v))
    }

    /// Visits the voxels the segment `a`-`b` passes through, in order, while `visit` returns
    /// true; returns false when `visit` stopped it or the segment leaves the grid.
    pub fn segment_voxels(
        &self,
        a: &Point3<f64>,
        b: &Point3<f64>,
        mut visit: impl FnMut(Voxel) -> bool,
    ) -> bool {
        let (Some(start), Some(end)) = (self.voxel_at(a), self.voxel_at(b)) else {
            return false;
        };
        let dir = (b - a) / self.voxel_size;
        let mut v = [start[0] as i64, start[1] as i64, start[2] as i64];
        let local = (a - self.origin) / self.voxel_size;
        let mut step = [0i64; 3];
        let mut t_max = [f64::INFINITY; 3];
        let mut t_delta = [f64::INFINITY; 3];
        for k in 0..3 {
            if dir[k] > 0.0 {
                step[k] = 1;
                t_max[k] = ((v[k] + 1) as f64 - local[k]) / dir[k];
                t_delta[k] = 1.0 / dir[k];
            } else if dir[k] < 0.0 {
                step[k] = -1;
                t_max[k] = (v[k] as f64 - local[k]) / dir[k];
                t_delta[k] = -1.0 / dir[k];
            }
        }
        let end = [end[0] as i64, end[1] as i64, end[2] as i64];
        // At most one step per voxel boundary crossed, plus the start.
        let budget = (end[0] - v[0]).abs() + (end[1] - v[1]).abs() + (end[2] - v[2]).abs() + 1;
        for _ in 0..budget {
            if !visit([v[0] as usize, v[1] as usize, v[2] as usize]) {
                return false;
            }
            if v == end {
                return true;
            }
            let k = if t_max[0] <= t_max[1] && t_max[0] <= t_max[2] {
                0
            } else if t_max[1] <= t_max[2] {
                1
            } else {
                2
            };
            v[k] += step[k];
            t_max[k] += t_delta[k];
            if v[k] < 0 || v[k] >= self.dims[k] as i64 {
                return false;
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(dims: [usize; 3]) -> OccupancyGrid {
        OccupancyGrid::empty(dims, 0.5, Point3::new(-1.0, 0.0, 0.0)).unwrap()
    }

    #[test]
    fn indices_and_positions_round_trip() {
        let g = grid([4, 3, 2]);
        assert_eq!(g.len(), 24);
        for i in 0..g.len() {
            let v = g.voxel_of(i);
            assert_eq!(g.index(v), Some(i));
            assert_eq!(g.voxel_at(&g.center(v)), Some(v));
        }
        assert_eq!(g.index([4, 0, 0]), None);
        assert!(g.is_occupied([0, 3, 0]), "outside counts as occupied");
        assert_eq!(g.center([0, 0, 0]), Point3::new(-0.75, 0.25, 0.25));
        assert_eq!(g.voxel_at(&Point3::new(-1.01, 0.1, 0.1)), None);
    }

    #[test]
    fn bad_parameters_name_the_field() {
        let o = Point3::origin();
        let msg = |r: Result<OccupancyGrid, SkeletonError>| r.unwrap_err().to_string();
        assert!(msg(OccupancyGrid::new([0, 1, 1], 0.1, o, vec![])).contains("dims"));
        assert!(msg(OccupancyGrid::new([1, 1, 1], 0.0, o, vec![false])).contains("voxel_size"));
        assert!(msg(OccupancyGrid::new([1, 1, 1], f64::NAN, o, vec![false])).contains("voxel_size"));
        assert!(msg(OccupancyGrid::new([2, 1, 1], 0.1, o, vec![false])).contains("occupied"));
        let far = Point3::new(f64::INFINITY, 0.0, 0.0);
        assert!(msg(OccupancyGrid::new([1, 1, 1], 0.1, far, vec![false])).contains("origin"));
        assert!(msg(OccupancyGrid::empty([1 << 20, 1 << 20, 1], 0.1, o)).contains("dims"));
        assert!(msg(OccupancyGrid::empty([0, 1, 1], 0.1, o)).contains("dims"));
    }

    #[test]
    fn segments_see_walls() {
        let mut g = grid([10, 10, 1]);
        for y in 0..10 {
            if y != 7 {
                g.set([5, y, 0], true);
            }
        }
        let at = |x: usize, y: usize| g.center([x, y, 0]);
        assert!(g.segment_is_free(&at(1, 1), &at(4, 9)));
        assert!(!g.segment_is_free(&at(1, 1), &at(8, 1)), "through the wall");
        assert!(g.segment_is_free(&at(1, 7), &at(8, 7)), "through the door");
        assert!(!g.segment_is_free(&at(5, 1), &at(5, 1)), "an occupied end");
        let mut visited = Vec::new();
        g.segment_voxels(&at(0, 0), &at(3, 0), |v| {
            visited.push(v[0]);
            true
        });
        assert_eq!(visited, vec![0, 1, 2, 3]);
        let outside = Point3::new(100.0, 0.0, 0.0);
        assert!(!g.segment_is_free(&at(0, 0), &outside));
    }
}
