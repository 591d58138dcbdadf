//! Planning cost on an office-sized grid (40 x 30 x 3 m): a 4 x 3 array of 10 x 10 m rooms with
//! 0.2 m walls and 1 m doors, at 0.1 and 0.2 m voxels. Ignored by default (slow in debug):
//! `cargo test --release -p topoloc-sim --test planning_time -- --ignored --nocapture`.

use nalgebra::Point3;
use std::time::Instant;
use topoloc::skeleton::OccupancyGrid;
use topoloc_sim::trajectory::{Planner, PlannerOptions, TrajectorySpec};

fn office(voxel: f64) -> OccupancyGrid {
    let dims = [
        (40.0 / voxel) as usize,
        (30.0 / voxel) as usize,
        (3.0 / voxel) as usize,
    ];
    let mut grid = OccupancyGrid::empty(dims, voxel, Point3::origin()).unwrap();
    let wall = |c: f64| (c.rem_euclid(10.0)) < 0.2;
    // Doors: 1 m gaps in the middle of every wall between rooms.
    let door = |c: f64| (c.rem_euclid(10.0) - 5.0).abs() < 0.5;
    for i in 0..grid.len() {
        let v = grid.voxel_of(i);
        let p = grid.center(v);
        let floor_or_ceiling = p.z < 0.1 || p.z > 2.9;
        let x_wall = wall(p.x) && !(door(p.y) && p.x > 1.0 && p.z < 2.1);
        let y_wall = wall(p.y) && !(door(p.x) && p.y > 1.0 && p.z < 2.1);
        grid.set(v, floor_or_ceiling || x_wall || y_wall);
    }
    grid
}

#[test]
#[ignore = "timing; run in release"]
fn plan_across_an_office() {
    for voxel in [0.2, 0.1] {
        let grid = office(voxel);
        let t = Instant::now();
        let planner = Planner::new(&grid, PlannerOptions::default()).unwrap();
        let build = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let path = planner
            .plan(Point3::new(1.0, 1.0, 1.2), Point3::new(39.0, 29.0, 1.5))
            .unwrap();
        let plan = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let smooth = planner.smooth(&path, 0.8);
        let smoothing = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let spec = TrajectorySpec {
            seed: 1,
            goals: 6,
            revisits: 2,
            min_goal_distance_m: 10.0,
            ..TrajectorySpec::default()
        };
        let trajectory = planner.random_trajectory(&spec).unwrap();
        let random = t.elapsed().as_secs_f64();
        let length: f64 = smooth.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        println!(
            "voxel {voxel} m, {} voxels: planner {build:.3} s, corner-to-corner A* {plan:.3} s ({} voxels), \
             smoothing {smoothing:.3} s ({length:.1} m), 6-leg random trajectory {random:.3} s \
             ({:.0} m, {} frames)",
            grid.len(),
            path.len(),
            trajectory.length_m,
            trajectory.frames.len()
        );
    }
}
