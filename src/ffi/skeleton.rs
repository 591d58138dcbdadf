//! C functions of skeleton map building: a topological graph of places from an occupancy voxel
//! grid (see `topoloc::skeleton::skeleton_graph`).

use super::boundary::{check_out, fill_out, run, slice, write_array, write_out};
use super::error::FfiError;
use super::handles::{castable, free_box, handle_value, new_box, run_on, Opaque};
use super::map::write_edge;
use super::topoloc_status;
use super::versioned::{init_versioned, read_optional, versioned};
use crate::map::MapError;
use crate::skeleton::{skeleton_graph, GraphEdge, OccupancyGrid, SkeletonOptions, TopoGraph};
use nalgebra::Point3;

/// Kind of a graph place: one of the `TOPOLOC_NODE_*` values.
pub type topoloc_node_kind = u32;

/// Place kind: a dead end of the skeleton.
pub const TOPOLOC_NODE_END: topoloc_node_kind = 0;
/// Place kind: a bend of the skeleton.
pub const TOPOLOC_NODE_CORNER: topoloc_node_kind = 1;
/// Place kind: a junction of three or more skeleton branches.
pub const TOPOLOC_NODE_BRANCH: topoloc_node_kind = 2;
/// Place kind: inserted on a skeleton path to keep edges straight, obstacle-free and short.
pub const TOPOLOC_NODE_INTERMEDIATE: topoloc_node_kind = 3;

/// Parameters of `topoloc_graph_from_occupancy`. Initialise with
/// `topoloc_skeleton_options_default`. Lengths are metres.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_skeleton_options {
    /// `sizeof(topoloc_skeleton_options)`, set by the `_default` function.
    pub struct_size: usize,
    /// Whether to use only the height band `[z_min_m, z_max_m]` (voxel centres, world z).
    /// Default false (the whole grid).
    pub use_z_band: bool,
    /// Lower bound of the height band.
    pub z_min_m: f64,
    /// Upper bound of the height band (not below `z_min_m`).
    pub z_max_m: f64,
    /// Free voxels closer than this to an obstacle count as occupied.
    pub min_clearance_m: f64,
    /// Nodes closer than this along the skeleton become one place.
    pub merge_radius_m: f64,
    /// Longest edge (at least two voxels); longer paths get intermediate places.
    pub max_edge_m: f64,
    /// Smallest bend, degrees, that makes a corner.
    pub corner_angle_deg: f64,
    /// Distance along the skeleton over which bends are measured.
    pub corner_scale_m: f64,
    /// Dead-end branches shorter than this are removed.
    pub min_spur_m: f64,
}

versioned! {
    topoloc_skeleton_options {
        let d = SkeletonOptions::default();
        let (z_min_m, z_max_m) = d.z_band.unwrap_or_default();
        Self {
            use_z_band: d.z_band.is_some(),
            z_min_m: z_min_m,
            z_max_m: z_max_m,
            min_clearance_m: d.min_clearance_m,
            merge_radius_m: d.merge_radius_m,
            max_edge_m: d.max_edge_m,
            corner_angle_deg: d.corner_angle_deg,
            corner_scale_m: d.corner_scale_m,
            min_spur_m: d.min_spur_m,
        }
    }
}

impl From<&topoloc_skeleton_options> for SkeletonOptions {
    fn from(o: &topoloc_skeleton_options) -> Self {
        Self {
            z_band: o.use_z_band.then_some((o.z_min_m, o.z_max_m)),
            min_clearance_m: o.min_clearance_m,
            merge_radius_m: o.merge_radius_m,
            max_edge_m: o.max_edge_m,
            corner_angle_deg: o.corner_angle_deg,
            corner_scale_m: o.corner_scale_m,
            min_spur_m: o.min_spur_m,
        }
    }
}

/// Fills the first `size` bytes of `*options` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_skeleton_options_default(options)`, which passes
/// `sizeof *(options)`. Thread-safe.
#[no_mangle]
pub extern "C" fn topoloc_skeleton_options_init(
    options: *mut topoloc_skeleton_options,
    size: usize,
) -> topoloc_status {
    init_versioned(options, size, "options")
}

/// A topological graph built from an occupancy grid: places (position, kind) and undirected
/// edges (place pairs with their length), plus the skeleton it was built on. Created by
/// `topoloc_graph_from_occupancy`, released by `topoloc_graph_free`. Immutable: a
/// `const topoloc_graph*` may be used from many threads at once.
pub struct topoloc_graph(Opaque);

castable!(topoloc_graph: OwnedBox => TopoGraph);

/// Builds the topological graph of the free space of an occupancy voxel grid: the free space
/// (optionally limited to a height band, minus a clearance) is thinned to a one-voxel-thin 3D
/// skeleton, whose ends, corners and junctions become places (merged when close), joined where
/// the skeleton links them by an obstacle-free straight segment (intermediate places are
/// inserted where it is not, and to keep edges under `max_edge_m`).
///
/// The grid: `dims` (3 values: voxels along x, y, z), `voxel_size` (metres, > 0), `origin`
/// (3 doubles: world position of the outer corner of voxel (0, 0, 0); z is up), and `cells_len`
/// bytes at `cells`, x fastest (`cells[x + nx * (y + ny * z)]`), non-zero = occupied. The
/// inputs are read during the call only. `options` may be NULL (defaults).
///
/// On success `*out` owns a new graph (free it with `topoloc_graph_free`); the same inputs give
/// the same graph. Thread-safe (no shared state); single-threaded, seconds for an office floor
/// at 0.1 m (BENCHMARKS.md). Errors: `_INVALID_ARGUMENT` (the message names the field: `dims`,
/// `voxel_size`, `origin`, `cells_len`, `cells` when every voxel is occupied, `z_band` when the
/// band holds no free voxel, `min_clearance_m` when the clearance leaves none, or another option
/// out of range).
#[no_mangle]
pub extern "C" fn topoloc_graph_from_occupancy(
    dims: *const usize,
    voxel_size: f64,
    origin: *const f64,
    cells: *const u8,
    cells_len: usize,
    options: *const topoloc_skeleton_options,
    out: *mut *mut topoloc_graph,
) -> topoloc_status {
    run(|| {
        let d = slice(dims, 3, "dims")?;
        let dims = [d[0], d[1], d[2]];
        let o = slice(origin, 3, "origin")?;
        let cells = slice(cells, cells_len, "cells")?;
        fill_out(out, "out", || {
            let options = SkeletonOptions::from(&read_optional(options, "options")?);
            let count = dims.iter().try_fold(1usize, |n, &k| n.checked_mul(k));
            if count.is_some_and(|n| n != cells_len && !dims.contains(&0)) {
                return Err(FfiError::invalid(format!(
                    "cells_len {cells_len}: dims {dims:?} need {} cells",
                    count.unwrap_or(0)
                )));
            }
            let mut occupied = Vec::new();
            occupied.try_reserve_exact(cells.len()).map_err(|_| {
                FfiError::invalid(format!(
                    "cells_len {cells_len}: not enough memory to copy the grid"
                ))
            })?;
            occupied.extend(cells.iter().map(|&c| c != 0));
            let grid =
                OccupancyGrid::new(dims, voxel_size, Point3::new(o[0], o[1], o[2]), occupied)?;
            Ok(new_box::<topoloc_graph>(skeleton_graph(&grid, &options)?))
        })
    })
}

/// Releases a graph. `NULL` is a no-op.
#[no_mangle]
pub extern "C" fn topoloc_graph_free(graph: *mut topoloc_graph) {
    free_box(graph)
}

/// Number of places (`*out`).
#[no_mangle]
pub extern "C" fn topoloc_graph_place_count(
    graph: *const topoloc_graph,
    out: *mut usize,
) -> topoloc_status {
    handle_value(graph, "graph", out, "out", |g| g.places.len())
}

/// Number of undirected edges (`*out`).
#[no_mangle]
pub extern "C" fn topoloc_graph_edge_count(
    graph: *const topoloc_graph,
    out: *mut usize,
) -> topoloc_status {
    handle_value(graph, "graph", out, "out", |g| g.edges.len())
}

/// Place `place` (0..place_count): `xyz` (3 doubles) receives its world position in metres (the
/// centre of its skeleton voxel), `*kind` its `TOPOLOC_NODE_*` kind. Places come in this order:
/// branches, ends, corners, then intermediate places. Errors: `_UNKNOWN_PLACE`.
#[no_mangle]
pub extern "C" fn topoloc_graph_place(
    graph: *const topoloc_graph,
    place: u32,
    xyz: *mut f64,
    kind: *mut topoloc_node_kind,
) -> topoloc_status {
    run_on(graph, "graph", |graph| {
        let p = graph
            .places
            .get(place as usize)
            .ok_or(MapError::UnknownPlace {
                place,
                places: graph.places.len(),
            })?;
        check_out(xyz, "xyz")?;
        check_out(kind, "kind")?;
        write_array(
            &[p.position.x, p.position.y, p.position.z],
            xyz,
            3,
            std::ptr::null_mut(),
        )?;
        write_out(kind, p.kind as u32);
        Ok(())
    })
}

/// Edge number `index` (0..edge_count, sorted by (a, b)): places `*a < *b` and the straight
/// distance between them, `*length_m`. Errors: `_INVALID_ARGUMENT` (index out of range).
#[no_mangle]
pub extern "C" fn topoloc_graph_edge(
    graph: *const topoloc_graph,
    index: usize,
    a: *mut u32,
    b: *mut u32,
    length_m: *mut f64,
) -> topoloc_status {
    run_on(graph, "graph", |graph| {
        let parts = |e: GraphEdge| (e.a, e.b, e.length_m);
        write_edge(
            &graph.edges,
            index,
            "graph",
            parts,
            (a, b, length_m),
            "length_m",
        )
    })
}

/// Copies the skeleton the graph was built on, as voxel indices `x0, y0, z0, x1, y1, z1, ...`
/// in grid order, into `xyz` of capacity `len` values. `*count` (if not NULL) receives the
/// number of values (3 per voxel), also on `TOPOLOC_ERR_BUFFER_TOO_SMALL`; call with `len` 0
/// to ask. Errors: `_BUFFER_TOO_SMALL`.
#[no_mangle]
pub extern "C" fn topoloc_graph_skeleton(
    graph: *const topoloc_graph,
    xyz: *mut u32,
    len: usize,
    count: *mut usize,
) -> topoloc_status {
    run_on(graph, "graph", |graph| {
        // Voxel indices fit in 32 bits: a grid holds at most 2^31 voxels.
        let values: Vec<u32> = graph
            .skeleton
            .iter()
            .flat_map(|v| v.map(|c| c as u32))
            .collect();
        write_array(&values, xyz, len, count)
    })
}

#[cfg(test)]
mod tests {
    use super::super::boundary::copy_last_error;
    use super::*;
    use std::ptr::{null, null_mut};
    use topoloc_status::*;

    fn message() -> String {
        let mut buf = vec![0u8; 1024];
        let status = copy_last_error(buf.as_mut_ptr().cast(), buf.len(), null_mut());
        assert_eq!(status, TOPOLOC_OK);
        let end = buf.iter().position(|&b| b == 0).unwrap();
        String::from_utf8(buf[..end].to_vec()).unwrap()
    }

    /// A T junction 0.2 m voxels: a corridor along x and a stem along y, 2 m high.
    fn t_cells() -> ([usize; 3], Vec<u8>) {
        let dims = [45, 35, 10];
        let mut cells = vec![1u8; dims[0] * dims[1] * dims[2]];
        for z in 0..dims[2] {
            for y in 0..dims[1] {
                for x in 0..dims[0] {
                    let along = (5..40).contains(&x) && (5..11).contains(&y);
                    let stem = (19..25).contains(&x) && (5..30).contains(&y);
                    if along || stem {
                        cells[x + dims[0] * (y + dims[1] * z)] = 0;
                    }
                }
            }
        }
        (dims, cells)
    }

    fn build(
        dims: &[usize; 3],
        cells: &[u8],
        options: *const topoloc_skeleton_options,
    ) -> (topoloc_status, *mut topoloc_graph) {
        let mut out = null_mut();
        let origin = [0.0; 3];
        let status = topoloc_graph_from_occupancy(
            dims.as_ptr(),
            0.2,
            origin.as_ptr(),
            cells.as_ptr(),
            cells.len(),
            options,
            &mut out,
        );
        (status, out)
    }

    #[test]
    fn a_t_junction_through_the_c_functions() {
        let (dims, cells) = t_cells();
        let (status, graph) = build(&dims, &cells, null());
        assert_eq!(status, TOPOLOC_OK, "{}", message());
        let (mut places, mut edges) = (0usize, 0usize);
        assert_eq!(topoloc_graph_place_count(graph, &mut places), TOPOLOC_OK);
        assert_eq!(topoloc_graph_edge_count(graph, &mut edges), TOPOLOC_OK);
        assert_eq!(edges + 1, places, "a tree");
        let mut kinds = [0usize; 4];
        for p in 0..places as u32 {
            let (mut xyz, mut kind) = ([0.0; 3], u32::MAX);
            assert_eq!(
                topoloc_graph_place(graph, p, xyz.as_mut_ptr(), &mut kind),
                TOPOLOC_OK
            );
            kinds[kind as usize] += 1;
            assert!(xyz[2] > 0.0 && xyz[2] < 2.0);
        }
        assert_eq!(kinds[TOPOLOC_NODE_BRANCH as usize], 1);
        assert_eq!(kinds[TOPOLOC_NODE_END as usize], 3);
        let (mut a, mut b, mut length) = (0u32, 0u32, 0.0f64);
        for e in 0..edges {
            assert_eq!(
                topoloc_graph_edge(graph, e, &mut a, &mut b, &mut length),
                TOPOLOC_OK
            );
            assert!(a < b && (b as usize) < places && length > 0.0 && length <= 3.0);
        }
        // Out of range: UNKNOWN_PLACE for a place, INVALID_ARGUMENT for an edge; outputs untouched.
        let (mut xyz, mut kind) = ([7.0; 3], 7u32);
        assert_eq!(
            topoloc_graph_place(graph, places as u32, xyz.as_mut_ptr(), &mut kind),
            TOPOLOC_ERR_UNKNOWN_PLACE
        );
        assert_eq!((xyz, kind), ([7.0; 3], 7));
        a = 99;
        assert_eq!(
            topoloc_graph_edge(graph, edges, &mut a, &mut b, &mut length),
            TOPOLOC_ERR_INVALID_ARGUMENT
        );
        assert_eq!(a, 99);
        // The skeleton: ask for the size, then copy.
        let mut count = 0usize;
        assert_eq!(
            topoloc_graph_skeleton(graph, null_mut(), 0, &mut count),
            TOPOLOC_ERR_BUFFER_TOO_SMALL
        );
        assert!(count > 0 && count.is_multiple_of(3));
        let mut xyz = vec![0u32; count];
        assert_eq!(
            topoloc_graph_skeleton(graph, xyz.as_mut_ptr(), count, &mut count),
            TOPOLOC_OK
        );
        assert!(xyz
            .chunks(3)
            .all(|v| cells[v[0] as usize + 45 * (v[1] as usize + 35 * v[2] as usize)] == 0));
        topoloc_graph_free(graph);
        topoloc_graph_free(null_mut());
    }

    #[test]
    fn bad_arguments_are_refused_naming_them() {
        let (dims, cells) = t_cells();
        let origin = [0.0; 3];
        let mut out = null_mut();
        let call = |dims: *const usize, voxel: f64, origin: *const f64, cells: &[u8], out| {
            topoloc_graph_from_occupancy(
                dims,
                voxel,
                origin,
                cells.as_ptr(),
                cells.len(),
                null(),
                out,
            )
        };
        let expect = |status: topoloc_status, want: topoloc_status, field: &str| {
            assert_eq!(status, want, "{field}");
            assert!(message().contains(field), "{field}: {}", message());
        };
        let (null_arg, invalid) = (TOPOLOC_ERR_NULL_ARGUMENT, TOPOLOC_ERR_INVALID_ARGUMENT);
        let (d, o) = (dims.as_ptr(), origin.as_ptr());
        expect(call(null(), 0.2, o, &cells, &mut out), null_arg, "dims");
        expect(call(d, 0.2, null(), &cells, &mut out), null_arg, "origin");
        expect(call(d, 0.2, o, &cells, null_mut()), null_arg, "out");
        expect(
            call(d, f64::NAN, o, &cells, &mut out),
            invalid,
            "voxel_size",
        );
        expect(call(d, 0.2, o, &cells[1..], &mut out), invalid, "cells_len");
        expect(
            call([0, 3, 3].as_ptr(), 0.2, o, &[], &mut out),
            invalid,
            "dims",
        );
        let full = vec![1u8; cells.len()];
        expect(call(d, 0.2, o, &full, &mut out), invalid, "cells");
        assert!(out.is_null(), "out is written only on success");

        // Options: a bad field, a bad struct_size.
        let mut options = topoloc_skeleton_options::default();
        let size = std::mem::size_of_val(&options);
        assert_eq!(
            topoloc_skeleton_options_init(&mut options, size),
            TOPOLOC_OK
        );
        options.merge_radius_m = -1.0;
        expect(build(&dims, &cells, &options).0, invalid, "merge_radius_m");
        options.merge_radius_m = 1.0;
        options.use_z_band = true;
        (options.z_min_m, options.z_max_m) = (5.0, 6.0);
        expect(build(&dims, &cells, &options).0, invalid, "z_band");
        options.struct_size = 8;
        assert_eq!(build(&dims, &cells, &options).0, TOPOLOC_ERR_STRUCT_SIZE);
        assert_eq!(
            topoloc_skeleton_options_init(null_mut(), 64),
            TOPOLOC_ERR_NULL_ARGUMENT
        );
        // Accessors on NULL.
        let mut n = 0usize;
        assert_eq!(
            topoloc_graph_place_count(null(), &mut n),
            TOPOLOC_ERR_NULL_ARGUMENT
        );
        assert_eq!(
            topoloc_graph_skeleton(null(), null_mut(), 0, &mut n),
            TOPOLOC_ERR_NULL_ARGUMENT
        );
    }

    #[test]
    fn the_c_defaults_are_the_rust_defaults() {
        let c = topoloc_skeleton_options::default();
        assert_eq!(SkeletonOptions::from(&c), SkeletonOptions::default());
        let banded = topoloc_skeleton_options {
            use_z_band: true,
            z_min_m: 0.5,
            z_max_m: 1.5,
            ..c
        };
        assert_eq!(SkeletonOptions::from(&banded).z_band, Some((0.5, 1.5)));
    }
}
