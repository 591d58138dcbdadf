//! Skeleton map building on hand-made worlds: corridors, junctions, loops, rooms, height bands,
//! clearance, errors and determinism (`topoloc::skeleton::skeleton_graph`).

#[path = "common/skeleton_worlds.rs"]
mod worlds;

use nalgebra::Point3;
use topoloc::skeleton::SkeletonError;
use topoloc::skeleton::{
    skeleton_graph, skeletonize, NodeKind, OccupancyGrid, SkeletonOptions, TopoGraph,
};
use worlds::World;

/// The graph with the default options, its invariants checked.
fn graph(grid: &OccupancyGrid) -> TopoGraph {
    checked(grid, &SkeletonOptions::default())
}

fn degrees(g: &TopoGraph) -> Vec<usize> {
    let mut d = vec![0; g.places.len()];
    for e in &g.edges {
        d[e.a as usize] += 1;
        d[e.b as usize] += 1;
    }
    d
}

/// Number of connected components of the place graph.
fn components(g: &TopoGraph) -> usize {
    let mut parent: Vec<usize> = (0..g.places.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for e in &g.edges {
        let (a, b) = (
            root(&mut parent, e.a as usize),
            root(&mut parent, e.b as usize),
        );
        parent[a] = b;
    }
    (0..g.places.len())
        .filter(|&i| root(&mut parent, i) == i)
        .count()
}

fn places_of(g: &TopoGraph, kind: NodeKind) -> Vec<Point3<f64>> {
    g.places
        .iter()
        .filter(|p| p.kind == kind)
        .map(|p| p.position)
        .collect()
}

/// What every graph must satisfy: places on free skeleton voxels at their centres, edges sorted,
/// unique, between different places, with their true length, obstacle-free and at most
/// `max_edge_m` long.
fn check_invariants(grid: &OccupancyGrid, g: &TopoGraph, options: &SkeletonOptions) {
    assert!(g
        .skeleton
        .windows(2)
        .all(|w| grid.index(w[0]) < grid.index(w[1])));
    for p in &g.places {
        assert!(grid.is_free(p.voxel), "{p:?}");
        assert_eq!(p.position, grid.center(p.voxel));
        assert!(g
            .skeleton
            .binary_search_by_key(&grid.index(p.voxel), |v| grid.index(*v))
            .is_ok());
    }
    let mut voxels: Vec<_> = g.places.iter().map(|p| p.voxel).collect();
    voxels.sort();
    voxels.dedup();
    assert_eq!(voxels.len(), g.places.len(), "two places on one voxel");
    for w in g.edges.windows(2) {
        assert!(
            (w[0].a, w[0].b) < (w[1].a, w[1].b),
            "edges sorted and unique"
        );
    }
    for e in &g.edges {
        assert!(e.a < e.b && (e.b as usize) < g.places.len(), "{e:?}");
        let (pa, pb) = (
            g.places[e.a as usize].position,
            g.places[e.b as usize].position,
        );
        assert!((e.length_m - (pa - pb).norm()).abs() < 1e-12);
        assert!(
            grid.segment_is_free(&pa, &pb),
            "edge {e:?} crosses an obstacle"
        );
        assert!(
            e.length_m <= options.max_edge_m + 1e-9,
            "edge {e:?} too long"
        );
    }
}

/// Builds the graph and checks the invariants.
fn checked(grid: &OccupancyGrid, options: &SkeletonOptions) -> TopoGraph {
    let g = skeleton_graph(grid, options).unwrap();
    check_invariants(grid, &g, options);
    g
}

fn is_chain(g: &TopoGraph) -> bool {
    let d = degrees(g);
    components(g) == 1
        && g.edges.len() + 1 == g.places.len()
        && d.iter().filter(|&&k| k == 1).count() == 2
        && d.iter().all(|&k| k == 1 || k == 2)
}

#[test]
fn a_straight_corridor_is_a_chain_with_an_end_at_each_end() {
    let grid = worlds::corridor(0.1);
    let g = graph(&grid);
    // Ends and one intermediate place (the ends are ~4 m apart, edges at most 3 m).
    assert_eq!(g.kind_counts(), [2, 0, 0, 1], "{g:?}");
    assert!(is_chain(&g));
    let ends = places_of(&g, NodeKind::End);
    let (west, east) = (ends[0].x.min(ends[1].x), ends[0].x.max(ends[1].x));
    assert!(
        (1.5..2.5).contains(&west) && (5.5..6.5).contains(&east),
        "{ends:?}"
    );
    // On the corridor's axis (y 1.6, z 1.0); a skeleton end may rise towards a corner of the
    // corridor's end face.
    for p in &g.places {
        let (y, z) = (p.position.y, p.position.z);
        assert!((y - 1.6).abs() <= 0.1 && (0.5..1.5).contains(&z), "{p:?}");
    }
    let intermediate = places_of(&g, NodeKind::Intermediate)[0];
    assert!((intermediate.x - 0.5 * (west + east)).abs() <= 0.3, "{g:?}");
    assert!((intermediate.z - 1.0).abs() <= 0.1);

    // Shorter edges: as many intermediate places as it takes, evenly spaced.
    let options = SkeletonOptions {
        max_edge_m: 1.0,
        ..SkeletonOptions::default()
    };
    let g = checked(&grid, &options);
    assert!(is_chain(&g));
    let expected = ((east - west) / 1.0 - 1e-9).ceil() as usize - 1;
    assert_eq!(g.kind_counts(), [2, 0, 0, expected]);
    assert!(expected >= 3);
    for e in &g.edges {
        assert!(e.length_m > 0.8 && e.length_m <= 1.0, "{e:?}");
    }
}

#[test]
fn an_l_corridor_has_one_corner() {
    let grid = worlds::l_corridor(0.1);
    let g = graph(&grid);
    assert!(is_chain(&g));
    let [ends, corners, branches, _] = g.kind_counts();
    assert_eq!((ends, corners, branches), (2, 1, 0), "{g:?}");
    let corner = places_of(&g, NodeKind::Corner)[0];
    assert!(
        (corner - Point3::new(6.4, 1.6, 1.0)).norm() < 0.5,
        "{corner}"
    );
    // The corner is what joins the two legs: its neighbours lie on different legs.
    let c = g
        .places
        .iter()
        .position(|p| p.kind == NodeKind::Corner)
        .unwrap() as u32;
    let n = g.neighbours(c);
    assert_eq!(n.len(), 2);
    let [p, q] = [n[0], n[1]].map(|i| g.places[i as usize].position);
    assert!((p.x - corner.x).abs() > 1.0 || (q.x - corner.x).abs() > 1.0);
    assert!((p.y - corner.y).abs() > 1.0 || (q.y - corner.y).abs() > 1.0);
}

#[test]
fn a_t_junction_has_exactly_one_branch() {
    let grid = worlds::t_junction(0.1);
    let g = graph(&grid);
    let [ends, corners, branches, _] = g.kind_counts();
    assert_eq!((ends, corners, branches), (3, 0, 1), "{g:?}");
    assert_eq!(components(&g), 1);
    assert_eq!(g.edges.len() + 1, g.places.len(), "a tree");
    let b = g
        .places
        .iter()
        .position(|p| p.kind == NodeKind::Branch)
        .unwrap();
    assert_eq!(degrees(&g)[b], 3);
    assert!((g.places[b].position - Point3::new(4.5, 1.6, 1.0)).norm() < 0.5);
}

#[test]
fn a_ring_corridor_is_a_cycle() {
    let grid = worlds::ring(0.1);
    let g = graph(&grid);
    assert_eq!(components(&g), 1);
    assert_eq!(g.edges.len(), g.places.len(), "{g:?}");
    assert!(degrees(&g).iter().all(|&d| d == 2));
    let [ends, corners, branches, _] = g.kind_counts();
    assert_eq!((ends, corners, branches), (0, 4, 0));
    for c in places_of(&g, NodeKind::Corner) {
        let near = [(1.6, 1.6), (7.4, 1.6), (1.6, 5.4), (7.4, 5.4)]
            .iter()
            .any(|&(x, y)| (c.x - x).hypot(c.y - y) < 0.5);
        assert!(near, "corner {c} is not at a corner of the ring");
    }
}

#[test]
fn a_round_loop_without_corners_stays_a_cycle() {
    // An annulus: radius 2.0 m to 3.2 m around (4, 4); it bends by about 20 degrees per 0.5 m,
    // below the corner angle, so the loop has no node of its own.
    let mut grid = World::new([8.0, 8.0, 1.0], 0.1, true).grid();
    for i in 0..grid.len() {
        let v = grid.voxel_of(i);
        let c = grid.center(v);
        let r = (c.x - 4.0).hypot(c.y - 4.0);
        grid.set(v, !(2.0..3.2).contains(&r));
    }
    let options = SkeletonOptions::default();
    let g = checked(&grid, &options);
    assert_eq!(g.kind_counts()[..3], [0, 0, 0], "{g:?}");
    assert!(
        g.places.len() >= 6,
        "circumference ~16 m at edges <= 3 m: {}",
        g.places.len()
    );
    assert_eq!(g.edges.len(), g.places.len());
    assert!(degrees(&g).iter().all(|&d| d == 2));
    assert_eq!(components(&g), 1);
}

#[test]
fn a_loop_around_a_pillar_stays_a_cycle() {
    // A 3 m x 3 m room with a 1 m pillar in the middle: all places are within 3 m of each
    // other, so only the duplicate-edge rule keeps the loop.
    let grid = {
        let mut w = World::new([5.0, 5.0, 2.0], 0.1, true);
        w.carve([1.0, 1.0, 4.0, 4.0])
            .fill([2.0, 2.0, 0.0], [3.0, 3.0, 2.0], true);
        w.grid()
    };
    let options = SkeletonOptions::default();
    let g = checked(&grid, &options);
    assert!(g.places.len() >= 3);
    assert_eq!(g.edges.len(), g.places.len(), "{g:?}");
    assert!(degrees(&g).iter().all(|&d| d == 2));
}

#[test]
fn two_rooms_joined_by_a_door_are_connected() {
    let grid = worlds::two_rooms(0.1);
    let g = graph(&grid);
    assert_eq!(components(&g), 1, "{g:?}");
    let west = g.places.iter().filter(|p| p.position.x < 5.4).count();
    let east = g.places.iter().filter(|p| p.position.x > 5.6).count();
    assert!(west >= 1 && east >= 1);
    // An edge goes through the door (the wall is x in [5.4, 5.6], the door y in [3, 4]).
    let through = g.edges.iter().any(|e| {
        let (a, b) = (
            g.places[e.a as usize].position,
            g.places[e.b as usize].position,
        );
        (a.x - 5.5) * (b.x - 5.5) <= 0.0
    });
    assert!(through);

    // Closing the door splits the graph in two.
    let mut closed = grid.clone();
    for i in 0..closed.len() {
        let v = closed.voxel_of(i);
        let c = closed.center(v);
        if (5.3..5.7).contains(&c.x) {
            closed.set(v, true);
        }
    }
    let g = graph(&closed);
    assert_eq!(components(&g), 2);
}

/// Two storeys: a corridor along x at z 0-2 m and one along y at z 2.4-4.4 m, with a slab
/// between them.
fn two_storeys() -> OccupancyGrid {
    let mut w = World::new([8.0, 8.0, 4.6], 0.1, true);
    w.fill([1.0, 3.4, 0.0], [7.0, 4.6, 2.0], false)
        .fill([3.4, 1.0, 2.4], [4.6, 7.0, 4.4], false);
    w.grid()
}

#[test]
fn a_height_band_limits_the_graph_to_one_storey() {
    let grid = two_storeys();
    let all = graph(&grid);
    assert_eq!(components(&all), 2);
    assert!(all.places.iter().any(|p| p.position.z < 2.0));
    assert!(all.places.iter().any(|p| p.position.z > 2.4));

    for (band, along_x) in [((0.0, 2.2), true), ((2.4, 4.6), false)] {
        let options = SkeletonOptions {
            z_band: Some(band),
            ..SkeletonOptions::default()
        };
        let g = checked(&grid, &options);
        assert!(is_chain(&g), "{band:?}: {g:?}");
        assert!(g.skeleton.iter().all(|v| {
            let z = grid.center(*v).z;
            z >= band.0 && z <= band.1
        }));
        let spread = |k: usize| {
            let c: Vec<f64> = g.places.iter().map(|p| p.position[k]).collect();
            c.iter().cloned().fold(f64::MIN, f64::max) - c.iter().cloned().fold(f64::MAX, f64::min)
        };
        let (along, across) = if along_x { (0, 1) } else { (1, 0) };
        assert!(
            spread(along) > 3.0 && spread(across) < 0.2,
            "{band:?}: {g:?}"
        );
    }
    // The band also bounds the skeleton voxels returned by skeletonize.
    let options = SkeletonOptions {
        z_band: Some((0.0, 2.2)),
        ..SkeletonOptions::default()
    };
    let raw = skeletonize(&grid, &options).unwrap();
    assert!(!raw.is_empty() && raw.iter().all(|v| v[2] < 22));
}

#[test]
fn clearance_closes_passages_too_narrow_to_fly() {
    // Two 4 m rooms joined by a slot 0.4 m wide.
    let grid = worlds::carved(
        [10.0, 5.0],
        2.0,
        0.1,
        &[
            [0.5, 0.5, 4.5, 4.5],
            [5.5, 0.5, 9.5, 4.5],
            [4.4, 2.3, 5.6, 2.7],
        ],
    );
    assert_eq!(components(&graph(&grid)), 1);
    let options = SkeletonOptions {
        min_clearance_m: 0.3,
        ..SkeletonOptions::default()
    };
    let g = checked(&grid, &options);
    assert_eq!(components(&g), 2, "{g:?}");
    // Every skeleton voxel keeps the clearance (to the nearest face of an occupied voxel).
    let occupied: Vec<Point3<f64>> = (0..grid.len())
        .filter(|&i| grid.cells()[i])
        .map(|i| grid.center(grid.voxel_of(i)))
        .collect();
    for v in &g.skeleton {
        let c = grid.center(*v);
        let d = occupied
            .iter()
            .map(|o| (o - c).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(
            d - 0.05 >= 0.3 - 1e-9,
            "{v:?} is {d} m from an obstacle centre"
        );
    }
}

#[test]
fn bad_inputs_are_errors_naming_the_field() {
    let grid = worlds::corridor(0.2);
    let message = |options: SkeletonOptions| match skeleton_graph(&grid, &options) {
        Err(SkeletonError::InvalidArgument(m)) => m,
        other => panic!("expected InvalidArgument, got {other:?}"),
    };
    let d = SkeletonOptions::default;
    let with = |change: fn(&mut SkeletonOptions)| {
        let mut o = d();
        change(&mut o);
        o
    };
    let cases: Vec<(SkeletonOptions, &str)> = vec![
        (with(|o| o.merge_radius_m = -1.0), "merge_radius_m"),
        (with(|o| o.merge_radius_m = f64::NAN), "merge_radius_m"),
        (with(|o| o.max_edge_m = 0.0), "max_edge_m"),
        (with(|o| o.max_edge_m = f64::INFINITY), "max_edge_m"),
        (with(|o| o.max_edge_m = 0.3), "max_edge_m"), // under two 0.2 m voxels
        (with(|o| o.min_clearance_m = -0.1), "min_clearance_m"),
        (with(|o| o.min_spur_m = f64::NAN), "min_spur_m"),
        (with(|o| o.corner_angle_deg = 0.0), "corner_angle_deg"),
        (with(|o| o.corner_angle_deg = 180.0), "corner_angle_deg"),
        (with(|o| o.corner_angle_deg = f64::NAN), "corner_angle_deg"),
        (with(|o| o.corner_scale_m = 0.0), "corner_scale_m"),
        (with(|o| o.z_band = Some((2.0, 1.0))), "z_band"),
        (with(|o| o.z_band = Some((f64::NAN, 1.0))), "z_band"),
        (with(|o| o.z_band = Some((5.0, 6.0))), "z_band"), // above the grid
        (with(|o| o.min_clearance_m = 2.0), "min_clearance_m"), // leaves nothing
    ];
    for (options, field) in cases {
        let m = message(options.clone());
        assert!(
            m.contains(field),
            "{options:?}: '{m}' does not name {field}"
        );
        assert!(matches!(
            skeletonize(&grid, &options),
            Err(SkeletonError::InvalidArgument(_))
        ));
    }
    // The option checks alone.
    assert!(SkeletonOptions::default().validate().is_ok());
    assert!(SkeletonOptions {
        max_edge_m: -1.0,
        ..d()
    }
    .validate()
    .is_err());

    // No free space at all.
    let full = OccupancyGrid::new([4, 3, 2], 0.1, Point3::origin(), vec![true; 24]).unwrap();
    let m = match skeleton_graph(&full, &d()) {
        Err(SkeletonError::InvalidArgument(m)) => m,
        other => panic!("{other:?}"),
    };
    assert!(m.contains("cells") && m.contains("occupied"), "{m}");
    // Free space only outside the band.
    let mut w = World::new([1.0, 1.0, 1.0], 0.1, true);
    w.fill([0.0; 3], [1.0, 1.0, 0.5], false);
    let m = match skeleton_graph(
        &w.grid(),
        &SkeletonOptions {
            z_band: Some((0.6, 1.0)),
            ..d()
        },
    ) {
        Err(SkeletonError::InvalidArgument(m)) => m,
        other => panic!("{other:?}"),
    };
    assert!(m.contains("z_band"), "{m}");
}

#[test]
fn a_single_free_voxel_is_one_end_place() {
    let mut cells = vec![true; 27];
    cells[13] = false;
    let grid = OccupancyGrid::new([3, 3, 3], 0.5, Point3::new(1.0, 2.0, 3.0), cells).unwrap();
    let g = skeleton_graph(&grid, &SkeletonOptions::default()).unwrap();
    assert_eq!(g.skeleton, vec![[1, 1, 1]]);
    assert_eq!(g.places.len(), 1);
    assert_eq!(g.places[0].kind, NodeKind::End);
    assert_eq!(g.places[0].position, Point3::new(1.75, 2.75, 3.75));
    assert!(g.edges.is_empty());
}

#[test]
fn short_spurs_are_removed() {
    // A corridor with a 0.7 m deep alcove on one side.
    let grid = worlds::carved(
        [8.0, 4.0],
        2.0,
        0.1,
        &[[1.0, 1.0, 7.0, 2.2], [3.5, 2.2, 4.7, 2.9]],
    );
    let options = SkeletonOptions::default();
    let g = checked(&grid, &options);
    assert!(is_chain(&g), "{g:?}");
    assert_eq!(g.kind_counts()[NodeKind::Branch as usize], 0);
    let keep = SkeletonOptions {
        min_spur_m: 0.0,
        ..options
    };
    let g = skeleton_graph(&grid, &keep).unwrap();
    assert_eq!(g.kind_counts()[NodeKind::Branch as usize], 1, "{g:?}");
    assert_eq!(
        g.kind_counts()[NodeKind::End as usize],
        2,
        "the spur's end is merged"
    );
}

#[test]
fn the_office_graph_is_connected_and_sound() {
    let grid = worlds::office(0.2);
    let g = graph(&grid);
    assert_eq!(components(&g), 1, "every room is reachable");
    let [ends, corners, branches, intermediates] = g.kind_counts();
    assert!(
        ends >= 16 && corners >= 8 && branches >= 16 && intermediates >= 16,
        "{:?}",
        g.kind_counts()
    );
    // Rooms and corridors have places every few metres, as in the seed's graphs.
    assert!((100..400).contains(&g.places.len()), "{}", g.places.len());
    // Loops: through the doors between rooms and around the corridor pillars.
    assert!(g.edges.len() > g.places.len() + 8);
    // The skeleton is thin: a small fraction of the free space.
    assert!(g.skeleton.len() < grid.free_count() / 50);
}

#[test]
fn the_same_grid_gives_the_same_graph() {
    let grid = worlds::office(0.2);
    let options = SkeletonOptions::default();
    let a = skeleton_graph(&grid, &options).unwrap();
    let b = skeleton_graph(&grid.clone(), &options).unwrap();
    assert_eq!(a, b);
    let bits = |g: &TopoGraph| -> Vec<u64> {
        g.places
            .iter()
            .flat_map(|p| p.position.iter().map(|c| c.to_bits()).collect::<Vec<_>>())
            .chain(g.edges.iter().map(|e| e.length_m.to_bits()))
            .collect()
    };
    assert_eq!(bits(&a), bits(&b));
    assert_eq!(format!("{a:?}"), format!("{b:?}"));
}
