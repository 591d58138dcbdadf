//! Unit tests of the skeleton module's parts (the hand-made worlds are in tests/skeleton.rs).

use super::graph::tests_support::{corner_positions, nodes_of};
use super::*;

fn grid_with(dims: [usize; 3], voxel: f64, occupied: impl Fn(Voxel) -> bool) -> OccupancyGrid {
    let mut g = OccupancyGrid::empty(dims, voxel, Point3::origin()).unwrap();
    for i in 0..g.len() {
        let v = g.voxel_of(i);
        g.set(v, occupied(v));
    }
    g
}

#[test]
fn the_height_band_keeps_the_layers_whose_centres_are_in_it() {
    // Layer centres at z = 0.25, 0.75, 1.25, 1.75.
    let grid = grid_with([3, 3, 4], 0.5, |_| false);
    let band = |lo, hi| SkeletonOptions {
        z_band: Some((lo, hi)),
        ..SkeletonOptions::default()
    };
    let space = free_space(&grid, &band(0.5, 1.3)).unwrap();
    assert_eq!((space.z0, space.dims), (1, [3, 3, 2]));
    let space = free_space(&grid, &band(0.75, 0.75)).unwrap();
    assert_eq!((space.z0, space.dims), (1, [3, 3, 1]));
    let space = free_space(&grid, &SkeletonOptions::default()).unwrap();
    assert_eq!((space.z0, space.dims), (0, [3, 3, 4]));
    for (lo, hi) in [(0.8, 1.0), (-5.0, 0.2), (1.8, 9.0)] {
        match free_space(&grid, &band(lo, hi)) {
            Err(SkeletonError::InvalidArgument(m)) => assert!(m.contains("z_band"), "{m}"),
            _ => panic!("band [{lo}, {hi}] holds no layer"),
        }
    }
}

#[test]
fn clearance_is_measured_to_the_nearest_obstacle_face() {
    // A wall at x = 0; voxel x = 3 has its centre 0.3 m from the wall voxel's centre, 0.25 m
    // from its face.
    let grid = grid_with([8, 1, 1], 0.1, |v| v[0] == 0);
    let free = |clearance: f64| {
        let options = SkeletonOptions {
            min_clearance_m: clearance,
            ..SkeletonOptions::default()
        };
        let space = free_space(&grid, &options).unwrap();
        (0..8).filter(|&x| space.free[x]).collect::<Vec<_>>()
    };
    assert_eq!(free(0.0), (1..8).collect::<Vec<_>>());
    assert_eq!(free(0.25 - 1e-9), (3..8).collect::<Vec<_>>());
    assert_eq!(free(0.25 + 1e-9), (4..8).collect::<Vec<_>>());
    // The grid's outer boundary is not an obstacle: x = 7 is free at any clearance up to 0.65.
    assert_eq!(free(0.65 - 1e-9), vec![7]);
    match free_space(
        &grid,
        &SkeletonOptions {
            min_clearance_m: 0.7,
            ..SkeletonOptions::default()
        },
    ) {
        Err(SkeletonError::InvalidArgument(m)) => assert!(m.contains("min_clearance_m"), "{m}"),
        _ => panic!("no voxel keeps 0.7 m"),
    }
}

#[test]
fn the_defaults_are_valid_and_documented_values() {
    let d = SkeletonOptions::default();
    assert!(d.validate().is_ok());
    assert_eq!(d.z_band, None);
    assert_eq!(
        (d.min_clearance_m, d.merge_radius_m, d.max_edge_m),
        (0.0, 1.0, 3.0)
    );
    assert_eq!(
        (d.corner_angle_deg, d.corner_scale_m, d.min_spur_m),
        (40.0, 0.5, 1.0)
    );
}

/// Voxels of a polyline through `points` (x, y) in layer 0, 4-connected steps.
fn polyline(points: &[(usize, usize)]) -> Vec<Voxel> {
    let mut out = vec![[points[0].0, points[0].1, 0]];
    for w in points.windows(2) {
        let (mut x, mut y) = w[0];
        while (x, y) != w[1] {
            if x != w[1].0 {
                x = if x < w[1].0 { x + 1 } else { x - 1 };
            } else {
                y = if y < w[1].1 { y + 1 } else { y - 1 };
            }
            out.push([x, y, 0]);
        }
    }
    out
}

#[test]
fn corners_are_bends_of_at_least_the_corner_angle() {
    let grid = OccupancyGrid::empty([40, 40, 1], 0.1, Point3::origin()).unwrap();
    let options = SkeletonOptions::default();
    // A right angle: one corner, at the apex.
    let l = polyline(&[(2, 2), (20, 2), (20, 20)]);
    let at: Vec<Voxel> = corner_positions(&grid, &l, &options)
        .iter()
        .map(|&k| l[k])
        .collect();
    assert_eq!(at, vec![[20, 2, 0]]);
    // A straight line at a slope of 1/3 (a voxel staircase): no corner.
    let stairs: Vec<Voxel> = (2..35).map(|x| [x, 2 + x / 3, 0]).collect();
    assert!(corner_positions(&grid, &stairs, &options).is_empty());
    // A 45 degree bend is a corner at the default 40 degrees, not at 50.
    let mut bend = polyline(&[(2, 2), (20, 2)]);
    bend.extend((1..15).map(|k| [20 + k, 2 + k, 0]));
    assert_eq!(corner_positions(&grid, &bend, &options).len(), 1);
    let strict = SkeletonOptions {
        corner_angle_deg: 50.0,
        ..options
    };
    assert!(corner_positions(&grid, &bend, &strict).is_empty());
}

#[test]
fn junction_voxels_form_one_branch_node() {
    // A plus sign: the centre and the first voxel of each arm (which touch diagonally) all have
    // three or more neighbours; together they are one junction, with four arms.
    let grid = OccupancyGrid::empty([21, 21, 1], 0.1, Point3::origin()).unwrap();
    let mut voxels = polyline(&[(10, 1), (10, 19)]);
    voxels.extend(polyline(&[(1, 10), (19, 10)]));
    voxels.sort_by_key(|v| (v[2], v[1], v[0]));
    voxels.dedup();
    let (kinds, segments) = nodes_of(&grid, voxels);
    let count = |k| kinds.iter().filter(|&&x| x == k).count();
    assert_eq!((count(NodeKind::Branch), count(NodeKind::End)), (1, 4));
    assert_eq!(segments, 4);
}
