//! Skeleton graphs: a topological graph of places from an occupancy voxel grid, for users
//! with a 3D map from their own mapping stack (and for `topoloc-sim` worlds).
//!
//! Method (after the seed thesis, §4.4.2.1):
//! 1. **Free space.** A voxel is free space for the skeleton when it is free in the grid, its
//!    centre lies in the optional height band [`SkeletonOptions::z_band`], and it is at least
//!    [`SkeletonOptions::min_clearance_m`] from every occupied voxel.
//! 2. **Thinning** ([`skeletonize`]): the free space is thinned to a one-voxel-thin 3D curve
//!    skeleton with the medial-axis thinning of Lee, Kashyap and Chu (1994), ported from
//!    scikit-image (see `thinning.rs`). The skeleton keeps the topology of the free space: one
//!    loop per loop of corridors, one piece per connected region.
//! 3. **Spurs.** Branches that end within [`SkeletonOptions::min_spur_m`] of a junction
//!    (thinning artefacts pointing into room corners) are removed.
//! 4. **Nodes.** Skeleton voxels are classified by their number of skeleton neighbours (26-
//!    connectivity): *end* (0 or 1), *branch* (3 or more; touching branch voxels form one
//!    junction), or, with 2, *corner* where the skeleton bends by at least
//!    [`SkeletonOptions::corner_angle_deg`] (measured over [`SkeletonOptions::corner_scale_m`]
//!    on either side; the sharpest voxel of a bend is kept). Straight voxels are not nodes.
//! 5. **Places.** Nodes closer than [`SkeletonOptions::merge_radius_m`] along the skeleton, and
//!    in line of sight, are merged into one place (see `graph.rs` for the rule).
//! 6. **Edges.** Places are joined when the skeleton links them and the straight segment between
//!    them is obstacle-free ([`OccupancyGrid::segment_is_free`]); where it is not, an
//!    intermediate place is inserted on the skeleton path (so curved corridors stay connected),
//!    and long paths get intermediate places so that no edge is longer than
//!    [`SkeletonOptions::max_edge_m`].
//!
//! The result is deterministic: the same grid and options give the same graph, place for place.

mod distance;
mod graph;
mod occupancy;
mod thinning;

pub use distance::{squared_distance_transform, GridBorder};

use crate::bounds::Bounds;
use nalgebra::Point3;
pub use occupancy::{OccupancyGrid, Voxel, MAX_VOXELS};

/// What can go wrong while building a grid or a skeleton graph.
#[derive(Debug, thiserror::Error)]
pub enum SkeletonError {
    /// An argument or option is out of range, or the grid is too large for memory; the message
    /// names the field.
    #[error("invalid argument: {0}")]
    InvalidArgument(String),
}

/// Parameters of skeleton map building. `Default` gives the documented defaults, chosen for
/// indoor MAV maps at 0.05-0.2 m voxels (places every ~1-3 m, as in the seed's graphs).
#[derive(Clone, Debug, PartialEq)]
pub struct SkeletonOptions {
    /// Height band `(z_min, z_max)` in world metres: only voxels whose centre z lies in it
    /// (inclusive) are free space for the skeleton. `None` (default): the whole grid.
    pub z_band: Option<(f64, f64)>,
    /// Free voxels closer than this to an occupied voxel are treated as occupied before
    /// thinning (a MAV needs room). Distance from the voxel centre to the nearest face of an
    /// occupied voxel (centre-to-centre distance minus half a voxel); the grid's outer boundary
    /// is not an obstacle. Metres, >= 0; default 0 (off).
    pub min_clearance_m: f64,
    /// Nodes closer than this along the skeleton become one place. Metres, >= 0; default 1.0.
    pub merge_radius_m: f64,
    /// Longest edge: longer skeleton paths get intermediate places. Metres, at least two voxels;
    /// default 3.0.
    pub max_edge_m: f64,
    /// Smallest bend, in degrees (0 < angle < 180), that makes a 2-neighbour skeleton voxel a
    /// corner; default 40: the seed's 90 and 135 degree curves (bends of 90 and 45 degrees) are
    /// corners, while the zig-zag of a voxelised straight line (at most 2 atan(1/4) = 28 degrees
    /// over four voxels) is not.
    pub corner_angle_deg: f64,
    /// Distance along the skeleton, on either side of a voxel, over which its bend is measured:
    /// metres, > 0, and never less than 4 voxels; default 0.5.
    pub corner_scale_m: f64,
    /// Branches shorter than this from a junction to a dead end are removed before nodes are
    /// classified (thinning leaves such spurs pointing into room corners). Metres, >= 0;
    /// default 1.0; 0 keeps every branch.
    pub min_spur_m: f64,
}

impl Default for SkeletonOptions {
    fn default() -> Self {
        Self {
            z_band: None,
            min_clearance_m: 0.0,
            merge_radius_m: 1.0,
            max_edge_m: 3.0,
            corner_angle_deg: 40.0,
            corner_scale_m: 0.5,
            min_spur_m: 1.0,
        }
    }
}

impl SkeletonOptions {
    /// Checks every option on its own; fails with [`SkeletonError::InvalidArgument`] naming the
    /// field. ([`skeleton_graph`] also checks `max_edge_m` against the grid's voxel size.)
    pub fn validate(&self) -> Result<(), SkeletonError> {
        self.check_ranges().map_err(SkeletonError::InvalidArgument)
    }

    /// Accepted values of each end of [`Self::z_band`], metres (z_min must not exceed z_max).
    pub const Z_RANGE: Bounds = Bounds::finite();
    /// Accepted values of [`Self::min_clearance_m`], [`Self::merge_radius_m`] and
    /// [`Self::min_spur_m`], metres.
    pub const DISTANCE_RANGE: Bounds = Bounds::at_least(0.0);
    /// Accepted values of [`Self::max_edge_m`] and [`Self::corner_scale_m`], metres (the
    /// skeleton also needs them at least two and four voxels long).
    pub const LENGTH_RANGE: Bounds = Bounds::above(0.0);
    /// Accepted values of [`Self::corner_angle_deg`], degrees.
    pub const CORNER_ANGLE_DEG_RANGE: Bounds = Bounds::open(0.0, 180.0);

    fn check_ranges(&self) -> Result<(), String> {
        if let Some((lo, hi)) = self.z_band {
            Self::Z_RANGE.check("z_band z_min", lo)?;
            Self::Z_RANGE.check("z_band z_max", hi)?;
            if lo > hi {
                return Err(format!("z_band [{lo}, {hi}]: z_min must not exceed z_max"));
            }
        }
        for (field, value) in [
            ("min_clearance_m", self.min_clearance_m),
            ("merge_radius_m", self.merge_radius_m),
            ("min_spur_m", self.min_spur_m),
        ] {
            Self::DISTANCE_RANGE.check(field, value)?;
        }
        Self::LENGTH_RANGE.check("max_edge_m", self.max_edge_m)?;
        Self::LENGTH_RANGE.check("corner_scale_m", self.corner_scale_m)?;
        Self::CORNER_ANGLE_DEG_RANGE.check("corner_angle_deg", self.corner_angle_deg)
    }

    /// [`validate`](Self::validate) plus the checks that need the grid.
    fn validate_for(&self, grid: &OccupancyGrid) -> Result<(), SkeletonError> {
        self.validate()?;
        let least = 2.0 * grid.voxel_size();
        if self.max_edge_m < least {
            return Err(SkeletonError::InvalidArgument(format!(
                "max_edge_m {}: must be at least two voxels ({least} m at voxel_size {})",
                self.max_edge_m,
                grid.voxel_size()
            )));
        }
        Ok(())
    }
}

/// What a place of a skeleton graph is.
#[repr(u32)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum NodeKind {
    /// A dead end of the skeleton (a voxel with at most one skeleton neighbour).
    End = 0,
    /// A bend of the skeleton.
    Corner = 1,
    /// A junction: three or more skeleton branches meet.
    Branch = 2,
    /// Inserted on a skeleton path to keep edges straight, obstacle-free and short.
    Intermediate = 3,
}

/// A place of a skeleton graph.
#[derive(Clone, Debug, PartialEq)]
pub struct GraphPlace {
    /// World position in metres: the centre of [`voxel`](Self::voxel).
    pub position: Point3<f64>,
    /// The skeleton voxel the place sits on.
    pub voxel: Voxel,
    /// What the place is.
    pub kind: NodeKind,
}

/// An undirected edge of a skeleton graph.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GraphEdge {
    /// The place with the smaller index.
    pub a: u32,
    /// The place with the larger index.
    pub b: u32,
    /// Straight-line distance between the two places, metres.
    pub length_m: f64,
}

/// A topological graph built from an occupancy grid by [`skeleton_graph`].
#[derive(Clone, Debug, PartialEq)]
pub struct TopoGraph {
    /// The places: first the merged nodes (branches, then ends, then corners, each group in
    /// grid order), then the intermediate places (loops without any other node first, then the
    /// places inserted on paths, in the order they were inserted).
    pub places: Vec<GraphPlace>,
    /// The edges, sorted by `(a, b)`, each pair at most once.
    pub edges: Vec<GraphEdge>,
    /// The skeleton the graph was built on (after spur removal), in grid order (x fastest).
    pub skeleton: Vec<Voxel>,
}

impl TopoGraph {
    /// Number of places of each kind, indexed by `NodeKind as usize`.
    pub fn kind_counts(&self) -> [usize; 4] {
        let mut counts = [0; 4];
        for p in &self.places {
            counts[p.kind as usize] += 1;
        }
        counts
    }

    /// Neighbours of place `p`, increasing.
    pub fn neighbours(&self, p: u32) -> Vec<u32> {
        let mut out: Vec<u32> = self
            .edges
            .iter()
            .filter_map(|e| match (e.a == p, e.b == p) {
                (true, _) => Some(e.b),
                (_, true) => Some(e.a),
                _ => None,
            })
            .collect();
        out.sort_unstable();
        out
    }
}

/// A vector of `n` copies of `value`, or `None` when the memory cannot be reserved (a grid too
/// large for this machine is an error, not an abort).
fn try_vec<T: Clone>(n: usize, value: T) -> Option<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).ok()?;
    v.resize(n, value);
    Some(v)
}

/// The error for a grid whose working memory cannot be reserved.
fn out_of_memory(grid: &OccupancyGrid, what: &str) -> SkeletonError {
    SkeletonError::InvalidArgument(format!(
        "dims {:?}: not enough memory for the {what} of {} voxels",
        grid.dims(),
        grid.len()
    ))
}

/// The free space the skeleton is built in: grid voxels `z0..z0 + dims[2]` of the band, with
/// the clearance applied.
struct FreeSpace {
    z0: usize,
    dims: [usize; 3],
    free: Vec<bool>,
}

fn free_space(grid: &OccupancyGrid, options: &SkeletonOptions) -> Result<FreeSpace, SkeletonError> {
    if grid.free_count() == 0 {
        return Err(SkeletonError::InvalidArgument(format!(
            "cells: all {} voxels of the grid are occupied; a skeleton needs free space",
            grid.len()
        )));
    }
    let [nx, ny, nz] = grid.dims();
    let (z0, z1) = match options.z_band {
        None => (0, nz),
        Some((lo, hi)) => {
            // Layers whose centre z = origin.z + (k + 0.5) voxel lies in [lo, hi].
            let centre = |k: usize| grid.origin().z + (k as f64 + 0.5) * grid.voxel_size();
            let first = (0..nz).find(|&k| centre(k) >= lo);
            let layers = first.map(|f| (f, (f..nz).take_while(|&k| centre(k) <= hi).count()));
            match layers {
                Some((f, n)) if n > 0 => (f, f + n),
                _ => {
                    return Err(SkeletonError::InvalidArgument(format!(
                        "z_band [{lo}, {hi}]: no voxel layer of the grid has its centre in the \
                         band (layer centres run from {} to {} m)",
                        centre(0),
                        centre(nz - 1)
                    )))
                }
            }
        }
    };
    let layer = nx * ny;
    let cells = &grid.cells()[z0 * layer..z1 * layer];
    let mut free = try_vec(cells.len(), false).ok_or_else(|| out_of_memory(grid, "free space"))?;
    for (f, &o) in free.iter_mut().zip(cells) {
        *f = !o;
    }
    if !free.contains(&true) {
        let (lo, hi) = options.z_band.unwrap_or_default();
        return Err(SkeletonError::InvalidArgument(format!(
            "z_band [{lo}, {hi}]: every voxel in the band is occupied"
        )));
    }
    if options.min_clearance_m > 0.0 {
        // The clearance is measured to occupied voxels only: the grid's border is no obstacle.
        let d2 = squared_distance_transform(grid, GridBorder::Open)?;
        let need = (options.min_clearance_m / grid.voxel_size() + 0.5).powi(2);
        for (f, &d) in free.iter_mut().zip(&d2[z0 * layer..z1 * layer]) {
            *f = *f && d >= need;
        }
        if !free.contains(&true) {
            return Err(SkeletonError::InvalidArgument(format!(
                "min_clearance_m {}: no free voxel{} is that far from every obstacle",
                options.min_clearance_m,
                if options.z_band.is_some() {
                    " in z_band"
                } else {
                    ""
                }
            )));
        }
    }
    Ok(FreeSpace {
        z0,
        dims: [nx, ny, z1 - z0],
        free,
    })
}

/// Thins the free space of `grid` (see the module documentation, steps 1-2) and returns the
/// skeleton voxels in grid order (x fastest), before spur removal. Errors as [`skeleton_graph`].
///
/// Cost: one pass over the free voxels per border direction and thinning iteration (about half
/// the widest free region, in voxels), single-threaded; the graph stage after it costs far
/// less. Timings: `cargo bench --bench skeleton`.
pub fn skeletonize(
    grid: &OccupancyGrid,
    options: &SkeletonOptions,
) -> Result<Vec<Voxel>, SkeletonError> {
    options.validate_for(grid)?;
    let space = free_space(grid, options)?;
    let [nx, ny, _] = space.dims;
    let mut volume = thinning::Volume::new(space.dims, |x, y, z| space.free[x + nx * (y + ny * z)])
        .ok_or_else(|| out_of_memory(grid, "thinning volume"))?;
    let thinned = volume
        .thin()
        .ok_or_else(|| out_of_memory(grid, "thinning"))?;
    Ok(thinned
        .into_iter()
        .map(|i| {
            let [x, y, z] = volume.inner_voxel(i);
            [x, y, z + space.z0]
        })
        .collect())
}

/// Builds the topological graph of the free space of `grid` (see the module documentation).
///
/// Errors ([`SkeletonError::InvalidArgument`], the message naming the field): an option out of
/// range, `max_edge_m` under two voxels, a grid with no free voxel (`cells`), a height band
/// without free voxels (`z_band`), or a clearance that leaves none (`min_clearance_m`).
pub fn skeleton_graph(
    grid: &OccupancyGrid,
    options: &SkeletonOptions,
) -> Result<TopoGraph, SkeletonError> {
    let skeleton = skeletonize(grid, options)?;
    Ok(graph::build(grid, options, skeleton))
}

#[cfg(test)]
mod tests;
