//! Camera trajectories through a voxel world: 3D A* with clearance inside a flight band, path
//! smoothing, a speed profile, and frames sampled at a fixed rate with the heading following
//! the motion (rate-limited, plus correlated noise).
//!
//! Build one [`Planner`] per world (it computes an exact 3D Euclidean distance transform of the
//! grid and the connected clear space once), then ask it for paths ([`Planner::plan`]), for a
//! trajectory through given waypoints ([`Planner::trajectory_through`]) or for a random one
//! with loops ([`Planner::random_trajectory`]). Everything is deterministic from the seed.
//!
//! Frames are `world_T_body` poses in the crate's convention (x forward, z up, yaw about world
//! z), timestamps in seconds from 0.

mod motion;
mod planner;

pub(crate) use motion::wrap_angle;
pub use motion::MotionOptions;

use motion::Knot;
use nalgebra::{Point3, Vector3};
use planner::ClearSpace;
use rand::rngs::SmallRng;
use rand::seq::IndexedRandom;
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;
use topoloc::build::TimedPose;
use topoloc::skeleton::OccupancyGrid;

/// A bad option, point or request; messages name the field or the point.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TrajectoryError {
    /// An option is out of its range.
    #[error("{field} is {value}: {expected}")]
    InvalidOption {
        /// Option path, e.g. `motion.rate_hz`.
        field: &'static str,
        /// Value given.
        value: String,
        /// What is allowed.
        expected: String,
    },
    /// The start point is not in clear space.
    #[error("start point {point} is blocked: {why}")]
    StartBlocked {
        /// Start given, world metres.
        point: Point3<f64>,
        /// Outside the grid, outside the flight band, or too close to an obstacle.
        why: &'static str,
    },
    /// A goal point is not in clear space.
    #[error("goal point {point} is blocked: {why}")]
    GoalBlocked {
        /// Goal given, world metres.
        point: Point3<f64>,
        /// Outside the grid, outside the flight band, or too close to an obstacle.
        why: &'static str,
    },
    /// No clear path joins start and goal (they lie in different connected parts of the clear
    /// space).
    #[error("goal {goal} is unreachable from start {start} with this clearance and flight band")]
    Unreachable {
        /// Start, world metres.
        start: Point3<f64>,
        /// Goal, world metres.
        goal: Point3<f64>,
    },
    /// No voxel of the flight band is far enough from obstacles.
    #[error("no clear space: no voxel in the flight band is planner.clearance_m from obstacles")]
    NoClearSpace,
    /// Random goal sampling found no clear point far enough from the previous one.
    #[error(
        "no reachable goal at least spec.min_goal_distance_m = {min_goal_distance_m} m from {from}"
    )]
    NoGoal {
        /// Point the goal was to be sampled from.
        from: Point3<f64>,
        /// The distance asked for.
        min_goal_distance_m: f64,
    },
    /// A trajectory needs a start and at least one goal.
    #[error("waypoints: {count} given, a trajectory needs at least 2 (start and goal)")]
    TooFewWaypoints {
        /// Waypoints given.
        count: usize,
    },
}

/// Checks `ok` on option `field`, otherwise an [`TrajectoryError::InvalidOption`].
fn check(
    field: &'static str,
    value: impl std::fmt::Display,
    ok: bool,
    expected: &str,
) -> Result<(), TrajectoryError> {
    if ok {
        Ok(())
    } else {
        Err(TrajectoryError::InvalidOption {
            field,
            value: value.to_string(),
            expected: expected.to_string(),
        })
    }
}

/// Checks that `value` is finite and lies in `[min, max]`.
fn check_range(field: &'static str, value: f64, min: f64, max: f64) -> Result<(), TrajectoryError> {
    let expected = format!("must lie in [{min}, {max}]");
    check(
        field,
        value,
        value.is_finite() && (min..=max).contains(&value),
        &expected,
    )
}

/// Checks the interval option `field`: both bounds finite and `ok(lo, hi)`.
fn check_interval(
    field: &'static str,
    (lo, hi): (f64, f64),
    ok: impl FnOnce(f64, f64) -> bool,
    expected: &str,
) -> Result<(), TrajectoryError> {
    let finite = lo.is_finite() && hi.is_finite();
    check(
        field,
        format!("({lo}, {hi})"),
        finite && ok(lo, hi),
        expected,
    )
}

/// Where paths may go.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PlannerOptions {
    /// Least distance from a path voxel to the nearest obstacle surface, metres (0..=5).
    /// Default 0.3: a small drone passes 0.8 m doors.
    pub clearance_m: f64,
    /// Flight height band `(z_min, z_max)`, world metres: paths use voxels whose centres lie
    /// in it. Default `(0.8, 2.0)`.
    pub band: (f64, f64),
}

impl Default for PlannerOptions {
    fn default() -> Self {
        Self {
            clearance_m: 0.3,
            band: (0.8, 2.0),
        }
    }
}

impl PlannerOptions {
    /// Checks ranges; the error names the field.
    pub fn validate(&self) -> Result<(), TrajectoryError> {
        check_range("planner.clearance_m", self.clearance_m, 0.0, 5.0)?;
        check_interval(
            "planner.band",
            self.band,
            |lo, hi| lo <= hi,
            "must be finite with z_min <= z_max",
        )
    }
}

// Checked here, with the other options' checks (the motion module does not import this one).
impl MotionOptions {
    /// Checks ranges; the error names the field.
    pub fn validate(&self) -> Result<(), TrajectoryError> {
        check_range("motion.rate_hz", self.rate_hz, 1.0, 100.0)?;
        check_interval(
            "motion.speed_range_mps",
            self.speed_range_mps,
            |lo, hi| 0.0 < lo && lo <= hi && hi <= 5.0,
            "must satisfy 0 < min <= max <= 5",
        )?;
        check_range("motion.accel_mps2", self.accel_mps2, 0.05, 10.0)?;
        check_range(
            "motion.lateral_accel_mps2",
            self.lateral_accel_mps2,
            0.05,
            20.0,
        )?;
        check_range(
            "motion.max_yaw_rate_rad_s",
            self.max_yaw_rate_rad_s,
            0.1,
            2.0 * PI,
        )?;
        check_range("motion.corner_radius_m", self.corner_radius_m, 0.0, 10.0)?;
        check_range(
            "motion.yaw_noise_std_rad",
            self.yaw_noise_std_rad,
            0.0,
            PI / 4.0,
        )?;
        check_range(
            "motion.tilt_noise_std_rad",
            self.tilt_noise_std_rad,
            0.0,
            0.5,
        )?;
        check_range("motion.noise_tau_s", self.noise_tau_s, 0.01, 60.0)?;
        check_range("motion.goal_pause_s", self.goal_pause_s, 0.0, 60.0)
    }
}

/// A random trajectory: a start and `goals` goals sampled in clear space, `revisits` of the
/// legs returning to an earlier waypoint (loops), so that places are seen again.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct TrajectorySpec {
    /// Seed of the sampling and of the motion noise.
    pub seed: u64,
    /// Number of legs (goals after the start), 1..=1000. Default 4.
    pub goals: usize,
    /// How many legs go back to an earlier waypoint instead of a new one
    /// (0..=goals - 1). Default 1.
    pub revisits: usize,
    /// Least straight-line distance between consecutive waypoints, metres (0..=1000).
    /// Default 5.
    pub min_goal_distance_m: f64,
    /// Motion along the path.
    pub motion: MotionOptions,
}

impl Default for TrajectorySpec {
    fn default() -> Self {
        Self {
            seed: 0,
            goals: 4,
            revisits: 1,
            min_goal_distance_m: 5.0,
            motion: MotionOptions::default(),
        }
    }
}

impl TrajectorySpec {
    /// Checks ranges (the motion's too); the error names the field.
    pub fn validate(&self) -> Result<(), TrajectoryError> {
        check(
            "spec.goals",
            self.goals,
            (1..=1000).contains(&self.goals),
            "must lie in 1..=1000",
        )?;
        check(
            "spec.revisits",
            self.revisits,
            self.revisits < self.goals,
            "must be less than spec.goals (the first leg cannot revisit)",
        )?;
        check_range(
            "spec.min_goal_distance_m",
            self.min_goal_distance_m,
            0.0,
            1000.0,
        )?;
        self.motion.validate()
    }
}

/// A sampled camera trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// Start and goals in the order visited, world metres (a revisit repeats an earlier one).
    pub waypoints: Vec<Point3<f64>>,
    /// For each waypoint, the first frame at or after the vehicle reaches it.
    pub waypoint_frames: Vec<usize>,
    /// The smoothed path, densely sampled (a few centimetres apart), world metres.
    pub path: Vec<Point3<f64>>,
    /// One `world_T_body` pose per frame, at `1 / rate_hz` second intervals from 0.
    pub frames: Vec<TimedPose>,
    /// Path length, metres.
    pub length_m: f64,
}

impl Trajectory {
    /// Time of the last frame, seconds.
    pub fn duration_s(&self) -> f64 {
        self.frames.last().map_or(0.0, |f| f.timestamp)
    }
}

/// Plans collision-free paths in one grid (see the module documentation).
///
/// Building costs one exact distance transform of the whole grid and a connected-component
/// pass over the flight band: 0.9 s for a 40 x 30 x 3 m grid at 0.1 m (3.6 M voxels), 0.14 s
/// at 0.2 m, in a release build. An A* query allocates 9 bytes per band voxel and took 0.46 s
/// (0.03 s at 0.2 m) corner to corner through six doors of that grid.
pub struct Planner {
    options: PlannerOptions,
    space: ClearSpace,
    /// The grid with every voxel that is not clear marked occupied (line-of-sight tests).
    inflated: OccupancyGrid,
}

impl std::fmt::Debug for Planner {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Planner")
            .field("options", &self.options)
            .field("band_dims", &self.space.dims)
            .field("components", &(self.space.component_sizes.len() - 1))
            .finish()
    }
}

impl Planner {
    /// Prepares planning in `grid`. Fails on a bad option or a band that holds no voxel centre
    /// of the grid (naming `planner.band`), or with [`TrajectoryError::NoClearSpace`].
    pub fn new(grid: &OccupancyGrid, options: PlannerOptions) -> Result<Self, TrajectoryError> {
        options.validate()?;
        let size = grid.voxel_size();
        let nz = grid.dims()[2];
        let oz = grid.origin().z;
        // Voxel z layer k has its centre at oz + (k + 0.5) size.
        let first = ((options.band.0 - oz) / size - 0.5).ceil().max(0.0);
        let last = ((options.band.1 - oz) / size - 0.5)
            .floor()
            .min(nz as f64 - 1.0);
        check(
            "planner.band",
            format!("({}, {})", options.band.0, options.band.1),
            first <= last,
            &format!(
                "must hold a voxel centre of the grid (z from {} to {})",
                oz + size / 2.0,
                oz + (nz as f64 - 0.5) * size
            ),
        )?;
        let threshold = options.clearance_m / size + 0.5;
        let space = ClearSpace::new(grid, (first as usize, last as usize), threshold * threshold);
        if space.component_sizes.len() < 2 {
            return Err(TrajectoryError::NoClearSpace);
        }
        let mut blocked = vec![true; grid.len()];
        let [nx, ny, _] = grid.dims();
        let offset = nx * ny * space.z0;
        for (cell, &clear) in blocked[offset..offset + space.clear.len()]
            .iter_mut()
            .zip(&space.clear)
        {
            *cell = !clear;
        }
        let inflated = OccupancyGrid::new(grid.dims(), size, grid.origin(), blocked)
            .expect("same layout as a valid grid");
        Ok(Self {
            options,
            space,
            inflated,
        })
    }

    /// The options the planner was built with.
    pub fn options(&self) -> &PlannerOptions {
        &self.options
    }

    /// The grid with every voxel a path may not use (too close to obstacles, outside the band)
    /// marked occupied: paths are free in it, checked with
    /// [`OccupancyGrid::segment_is_free`].
    pub fn inflated(&self) -> &OccupancyGrid {
        &self.inflated
    }

    /// Whether a path may pass through `p` (world metres).
    pub fn is_clear(&self, p: &Point3<f64>) -> bool {
        self.locate(p).is_ok()
    }

    /// Band index of the clear voxel holding `p`, or why `p` is blocked.
    fn locate(&self, p: &Point3<f64>) -> Result<usize, &'static str> {
        let v = self.inflated.voxel_at(p).ok_or("outside the grid")?;
        let i = self
            .space
            .slab_index(v)
            .ok_or("outside the flight band planner.band")?;
        if self.space.clear[i] {
            Ok(i)
        } else {
            Err("closer than planner.clearance_m to an obstacle")
        }
    }

    /// World centre of band voxel `i`.
    fn center(&self, i: usize) -> Point3<f64> {
        let [x, y, z] = self.space.voxel(i);
        self.inflated.center([x, y, z + self.space.z0])
    }

    /// The shortest 26-connected voxel path from `start` to `goal` (world metres): voxel
    /// centres, with the exact start and goal as its ends. A* with the octile heuristic over
    /// clear voxels; a diagonal step needs its whole bounding box clear.
    pub fn plan(
        &self,
        start: Point3<f64>,
        goal: Point3<f64>,
    ) -> Result<Vec<Point3<f64>>, TrajectoryError> {
        let from = self
            .locate(&start)
            .map_err(|why| TrajectoryError::StartBlocked { point: start, why })?;
        let to = self
            .locate(&goal)
            .map_err(|why| TrajectoryError::GoalBlocked { point: goal, why })?;
        let unreachable = TrajectoryError::Unreachable { start, goal };
        if self.space.component[from] != self.space.component[to] {
            return Err(unreachable);
        }
        let voxels = self.space.astar(from, to).ok_or(unreachable)?;
        let mut path: Vec<Point3<f64>> = voxels.iter().map(|&i| self.center(i)).collect();
        path[0] = start;
        if path.len() == 1 {
            path.push(goal);
        } else {
            *path.last_mut().expect("non-empty") = goal;
        }
        Ok(path)
    }

    /// Smooths a free path (as from [`plan`](Self::plan)): line-of-sight shortcutting in the
    /// inflated grid, then corners rounded with arcs of about `corner_radius_m` where they stay
    /// clear. Returns the curve sampled every few centimetres (at most half a voxel).
    pub fn smooth(&self, path: &[Point3<f64>], corner_radius_m: f64) -> Vec<Point3<f64>> {
        let visible = |a: &Point3<f64>, b: &Point3<f64>| self.inflated.segment_is_free(a, b);
        let vertices = planner::shortcut(path, visible);
        let size = self.inflated.voxel_size();
        let step = (size / 2.0).min(0.05);
        planner::round_corners(&vertices, corner_radius_m, step, size / 2.0, visible)
    }

    /// A trajectory visiting `waypoints` in order (start first), stopping at each goal, with
    /// motion noise drawn from `seed`. Fails when fewer than two waypoints are given, on a bad
    /// option, or when a leg cannot be planned (the error names its points).
    pub fn trajectory_through(
        &self,
        waypoints: &[Point3<f64>],
        motion: &MotionOptions,
        seed: u64,
    ) -> Result<Trajectory, TrajectoryError> {
        motion.validate()?;
        if waypoints.len() < 2 {
            return Err(TrajectoryError::TooFewWaypoints {
                count: waypoints.len(),
            });
        }
        let mut rng = SmallRng::seed_from_u64(seed);
        let mut knots: Vec<Knot> = Vec::new();
        let mut waypoint_knots = vec![0];
        for leg in waypoints.windows(2) {
            let raw = self.plan(leg[0], leg[1])?;
            let curve = self.smooth(&raw, motion.corner_radius_m);
            let (lo, hi) = motion.speed_range_mps;
            let cruise_mps = if hi > lo {
                rng.random_range(lo..=hi)
            } else {
                lo
            };
            if let Some(last) = knots.last_mut() {
                last.stop = true;
                last.pause_s = motion.goal_pause_s;
                last.cruise_mps = cruise_mps;
            }
            let skip = usize::from(!knots.is_empty());
            knots.extend(curve.iter().skip(skip).map(|&position| Knot {
                position,
                stop: false,
                pause_s: 0.0,
                cruise_mps,
            }));
            // Drop zero-length steps (a goal equal to its start).
            knots.dedup_by(|b, a| (b.position - a.position).norm() < 1e-9);
            waypoint_knots.push(knots.len() - 1);
        }
        let sampled = motion::sample(&knots, motion, &mut rng);
        let waypoint_frames = waypoint_knots
            .iter()
            .map(|&k| {
                let t = sampled.arrival_s[k];
                ((t * motion.rate_hz - 1e-9).ceil().max(0.0) as usize).min(sampled.frames.len() - 1)
            })
            .collect();
        let path: Vec<Point3<f64>> = knots.iter().map(|k| k.position).collect();
        let length_m = path.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        Ok(Trajectory {
            waypoints: waypoints.to_vec(),
            waypoint_frames,
            path,
            frames: sampled.frames,
            length_m,
        })
    }

    /// A random trajectory as `spec` describes: the start is a clear point of the largest
    /// connected part of the clear space, each new goal a clear point of the same part at
    /// least `spec.min_goal_distance_m` from the previous waypoint, and `spec.revisits`
    /// randomly chosen legs (never the first) go back to an earlier waypoint at least that far
    /// away (a new goal when there is none).
    pub fn random_trajectory(&self, spec: &TrajectorySpec) -> Result<Trajectory, TrajectoryError> {
        spec.validate()?;
        let mut rng = SmallRng::seed_from_u64(spec.seed);
        let largest = (1..self.space.component_sizes.len())
            .max_by_key(|&c| (self.space.component_sizes[c], std::cmp::Reverse(c)))
            .expect("a planner has clear space") as u32;
        let pool: Vec<u32> = (0..self.space.component.len() as u32)
            .filter(|&i| self.space.component[i as usize] == largest)
            .collect();
        let size = self.inflated.voxel_size();
        let sample = |rng: &mut SmallRng| {
            let i = *pool.choose(rng).expect("components are non-empty") as usize;
            let jitter = Vector3::from_fn(|_, _| rng.random_range(-0.45..=0.45) * size);
            self.center(i) + jitter
        };
        let mut revisit_legs = vec![false; spec.goals + 1];
        for leg in rand::seq::index::sample(&mut rng, spec.goals - 1, spec.revisits) {
            revisit_legs[leg + 2] = true;
        }
        let mut waypoints = vec![sample(&mut rng)];
        for &revisit in &revisit_legs[1..] {
            let here = *waypoints.last().expect("the start");
            let far_enough = |p: &Point3<f64>| (p - here).norm() >= spec.min_goal_distance_m;
            // A revisit goes back to an earlier waypoint far enough away; when there is none,
            // the leg draws a new goal instead.
            let earlier: Vec<Point3<f64>> = waypoints
                .iter()
                .copied()
                .filter(|p| revisit && *p != here && far_enough(p))
                .collect();
            let next = match earlier.choose(&mut rng) {
                Some(&p) => p,
                None => (0..1000).map(|_| sample(&mut rng)).find(far_enough).ok_or(
                    TrajectoryError::NoGoal {
                        from: here,
                        min_goal_distance_m: spec.min_goal_distance_m,
                    },
                )?,
            };
            waypoints.push(next);
        }
        let motion_seed = rng.random();
        self.trajectory_through(&waypoints, &spec.motion, motion_seed)
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// [`two_rooms`] and its planner with the default options.
    pub(crate) fn two_rooms_planner() -> (OccupancyGrid, Planner) {
        let grid = two_rooms();
        let planner = Planner::new(&grid, PlannerOptions::default()).unwrap();
        (grid, planner)
    }

    /// Two 6 x 6 m rooms joined by a 4 m corridor 1.2 m wide, 3 m high, 0.1 m voxels, floor
    /// and ceiling slabs; the rooms span x 0-6 and 10-16, y 0-6, the corridor y 2.4-3.6.
    pub(crate) fn two_rooms() -> OccupancyGrid {
        let size = 0.1;
        let mut grid =
            OccupancyGrid::empty([170, 70, 30], size, Point3::new(-0.5, -0.5, 0.0)).unwrap();
        for i in 0..grid.len() {
            let v = grid.voxel_of(i);
            let c = grid.center(v);
            let in_room = (0.0..6.0).contains(&c.y)
                && ((0.0..6.0).contains(&c.x) || (10.0..16.0).contains(&c.x));
            let in_corridor = (6.0..10.0).contains(&c.x) && (2.4..3.6).contains(&c.y);
            let open = (in_room || in_corridor) && (0.1..2.9).contains(&c.z);
            grid.set(v, !open);
        }
        grid
    }

    #[test]
    fn plans_through_the_corridor_with_clearance() {
        let (_, planner) = two_rooms_planner();
        let (start, goal) = (Point3::new(1.0, 1.0, 1.2), Point3::new(15.0, 5.0, 1.5));
        let path = planner.plan(start, goal).unwrap();
        assert_eq!((path[0], *path.last().unwrap()), (start, goal));
        let smooth = planner.smooth(&path, 0.8);
        assert!(smooth
            .windows(2)
            .all(|w| planner.inflated().segment_is_free(&w[0], &w[1])));
        for p in &smooth {
            assert!(
                (0.8 - 0.05..=2.0 + 0.05).contains(&p.z),
                "inside the band: {p}"
            );
            if (6.0..10.0).contains(&p.x) {
                assert!(
                    (2.4 + 0.25..3.6 - 0.25).contains(&p.y),
                    "clear of the corridor walls: {p}"
                );
            }
        }
        let raw_len: f64 = path.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        let smooth_len: f64 = smooth.windows(2).map(|w| (w[1] - w[0]).norm()).sum();
        assert!(smooth_len < raw_len, "{smooth_len} < {raw_len}");
    }

    #[test]
    fn blocked_and_unreachable_points_are_named() {
        let mut grid = two_rooms();
        let planner = Planner::new(&grid, PlannerOptions::default()).unwrap();
        let start = Point3::new(1.0, 1.0, 1.2);
        let msg = |e: TrajectoryError| e.to_string();
        let wall = Point3::new(8.0, 1.0, 1.2);
        let err = msg(planner.plan(wall, start).unwrap_err());
        assert!(
            err.contains("start point {8, 1, 1.2}") && err.contains("obstacle"),
            "{err}"
        );
        let high = Point3::new(1.0, 1.0, 2.5);
        let err = msg(planner.plan(start, high).unwrap_err());
        assert!(err.contains("goal point") && err.contains("band"), "{err}");
        let outside = Point3::new(100.0, 1.0, 1.2);
        assert!(msg(planner.plan(start, outside).unwrap_err()).contains("outside the grid"));
        // Close the corridor: the far room is unreachable.
        for y in 0..70 {
            for z in 0..30 {
                grid.set([85, y, z], true);
            }
        }
        let closed = Planner::new(&grid, PlannerOptions::default()).unwrap();
        let goal = Point3::new(15.0, 5.0, 1.5);
        assert_eq!(
            closed.plan(start, goal).unwrap_err(),
            TrajectoryError::Unreachable { start, goal }
        );
    }

    #[test]
    fn options_out_of_range_name_the_field() {
        let grid = two_rooms();
        let bad = |options: PlannerOptions| Planner::new(&grid, options).unwrap_err().to_string();
        let base = PlannerOptions::default();
        assert!(bad(PlannerOptions {
            clearance_m: -1.0,
            ..base
        })
        .contains("planner.clearance_m"));
        assert!(bad(PlannerOptions {
            band: (2.0, 1.0),
            ..base
        })
        .contains("planner.band"));
        assert!(bad(PlannerOptions {
            band: (5.0, 6.0),
            ..base
        })
        .contains("planner.band"));
        assert_eq!(
            Planner::new(
                &grid,
                PlannerOptions {
                    clearance_m: 4.0,
                    ..base
                }
            )
            .unwrap_err(),
            TrajectoryError::NoClearSpace
        );
        let motion = MotionOptions::default();
        for (field, options) in [
            (
                "motion.rate_hz",
                MotionOptions {
                    rate_hz: 0.0,
                    ..motion
                },
            ),
            (
                "motion.speed_range_mps",
                MotionOptions {
                    speed_range_mps: (1.0, 0.5),
                    ..motion
                },
            ),
            (
                "motion.max_yaw_rate_rad_s",
                MotionOptions {
                    max_yaw_rate_rad_s: f64::NAN,
                    ..motion
                },
            ),
            (
                "motion.noise_tau_s",
                MotionOptions {
                    noise_tau_s: 0.0,
                    ..motion
                },
            ),
        ] {
            assert!(
                options.validate().unwrap_err().to_string().contains(field),
                "{field}"
            );
        }
        let spec = TrajectorySpec::default();
        assert!(TrajectorySpec { goals: 0, ..spec }
            .validate()
            .unwrap_err()
            .to_string()
            .contains("spec.goals"));
        assert!(TrajectorySpec {
            revisits: 4,
            ..spec
        }
        .validate()
        .unwrap_err()
        .to_string()
        .contains("spec.revisits"));
    }

    #[test]
    fn frames_follow_the_path_at_the_rate_with_the_heading() {
        let (_, planner) = two_rooms_planner();
        let waypoints = [Point3::new(1.0, 3.0, 1.2), Point3::new(15.0, 3.0, 1.2)];
        let motion = MotionOptions {
            yaw_noise_std_rad: 0.0,
            ..MotionOptions::default()
        };
        let t = planner.trajectory_through(&waypoints, &motion, 7).unwrap();
        assert!((t.length_m - 14.0).abs() < 0.05, "straight: {}", t.length_m);
        let dt = 1.0 / motion.rate_hz;
        for (k, pair) in t.frames.windows(2).enumerate() {
            assert!(
                (pair[1].timestamp - pair[0].timestamp - dt).abs() < 1e-9,
                "frame {k}"
            );
            let step = (pair[1].world_t_camera.translation.vector
                - pair[0].world_t_camera.translation.vector)
                .norm();
            assert!(step <= 1.5 * dt + 1e-6, "speed at frame {k}: {}", step / dt);
            let yaw = crate::camera::yaw_of(&pair[1].world_t_camera);
            assert!(yaw.abs() < 1e-9, "heading along +x: {yaw}");
        }
        let first = t.frames[0].world_t_camera.translation.vector;
        let last = t.frames.last().unwrap().world_t_camera.translation.vector;
        assert!((first - waypoints[0].coords).norm() < 1e-12);
        assert!(
            (last - waypoints[1].coords).norm() < 0.05,
            "ends at the goal: {last}"
        );
        // Accelerate from rest, cruise between 0.5 and 1.5 m/s, brake to rest.
        let speed = |k: usize| {
            (t.frames[k + 1].world_t_camera.translation.vector
                - t.frames[k].world_t_camera.translation.vector)
                .norm()
                / dt
        };
        assert!(speed(0) < 0.1 && speed(t.frames.len() / 2) >= 0.5 - 1e-6);
        assert_eq!(t.waypoint_frames[0], 0);
        assert_eq!(t.waypoint_frames[1], t.frames.len() - 1);
    }

    #[test]
    fn heading_turns_at_a_limited_rate_and_noise_is_seeded() {
        let (_, planner) = two_rooms_planner();
        let waypoints = [
            Point3::new(1.0, 1.0, 1.2),
            Point3::new(5.0, 5.0, 1.2),
            Point3::new(1.0, 1.0, 1.2),
            Point3::new(14.0, 2.0, 1.5),
        ];
        let motion = MotionOptions {
            tilt_noise_std_rad: 0.02,
            ..MotionOptions::default()
        };
        let t = planner.trajectory_through(&waypoints, &motion, 3).unwrap();
        let step_limit = motion.max_yaw_rate_rad_s / motion.rate_hz;
        let yaws: Vec<f64> = t
            .frames
            .iter()
            .map(|f| crate::camera::yaw_of(&f.world_t_camera))
            .collect();
        for (k, pair) in yaws.windows(2).enumerate() {
            // Rate limit plus the change of the correlated noise over one frame.
            let turn = wrap_angle(pair[1] - pair[0]).abs();
            assert!(turn < step_limit + 0.05, "frame {k}: {turn}");
        }
        for f in &t.frames {
            assert!(planner.is_clear(&f.world_t_camera.translation.vector.into()));
        }
        assert_eq!(
            t,
            planner.trajectory_through(&waypoints, &motion, 3).unwrap()
        );
        assert_ne!(
            t.frames,
            planner
                .trajectory_through(&waypoints, &motion, 4)
                .unwrap()
                .frames
        );
        assert_eq!(t.waypoint_frames.len(), 4);
        assert!(t.waypoint_frames.windows(2).all(|w| w[0] < w[1]));
    }

    #[test]
    fn random_trajectories_loop_back_and_are_deterministic() {
        let (_, planner) = two_rooms_planner();
        let spec = TrajectorySpec {
            seed: 11,
            goals: 4,
            revisits: 2,
            min_goal_distance_m: 4.0,
            ..TrajectorySpec::default()
        };
        let t = planner.random_trajectory(&spec).unwrap();
        assert_eq!(t.waypoints.len(), 5);
        let repeated = (1..5)
            .filter(|&i| t.waypoints[..i - 1].contains(&t.waypoints[i]))
            .count();
        assert_eq!(repeated, 2, "{:?}", t.waypoints);
        for w in t.waypoints.windows(2) {
            assert!((w[1] - w[0]).norm() >= 4.0, "{w:?}");
        }
        assert_eq!(t, planner.random_trajectory(&spec).unwrap());
        let far = TrajectorySpec {
            min_goal_distance_m: 100.0,
            ..spec
        };
        assert!(matches!(
            planner.random_trajectory(&far),
            Err(TrajectoryError::NoGoal { .. })
        ));
    }
}
