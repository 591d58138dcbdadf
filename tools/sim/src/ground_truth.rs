//! Ground truth per frame: the closest place the camera can see and the view of it that best
//! matches the camera's heading, plus the place graph those indices refer to.
//!
//! Places are the seed's macro nodes; each holds views (micro nodes) taken at fixed yaws,
//! numbered globally place by place: with four views per place at yaws 0, 90, 180 and 270
//! degrees, view `j` of place `i` is global view `4 i + j`.

use crate::trajectory::wrap_angle;
use nalgebra::Point3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::f64::consts::FRAC_PI_2;
use std::ops::Range;
use topoloc::build::TimedPose;
use topoloc::eval::HopDistances;
use topoloc::map::{PlaceId, ViewId};
use topoloc::skeleton::OccupancyGrid;

/// One place of the graph.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Place {
    /// Position `[x, y, z]`, world metres.
    pub position: [f64; 3],
    /// What the place is, free text: e.g. `"end"`, `"corner"`, `"branch"`, `"room"`.
    pub kind: String,
    /// Yaw of each view, radians about world z (0 = world +x).
    pub view_yaws: Vec<f64>,
}

impl Place {
    /// The position as a point.
    pub fn point(&self) -> Point3<f64> {
        Point3::from(self.position)
    }
}

/// The place graph: places, their views and undirected edges between places.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlaceGraph {
    /// Places, indexed by [`PlaceId`].
    pub places: Vec<Place>,
    /// Undirected edges `(a, b)` between places.
    pub edges: Vec<(PlaceId, PlaceId)>,
}

/// Yaws of the four standard views: 0, 90, 180 and 270 degrees.
pub const FOUR_VIEW_YAWS: [f64; 4] = [0.0, FRAC_PI_2, 2.0 * FRAC_PI_2, 3.0 * FRAC_PI_2];

impl PlaceGraph {
    /// Places at `positions` with the four standard views each and kind `"place"`; set
    /// [`Place::kind`] afterwards where known.
    pub fn with_four_views(positions: &[Point3<f64>], edges: &[(PlaceId, PlaceId)]) -> Self {
        Self::with_views(positions, edges, FOUR_VIEW_YAWS.len())
    }

    /// Places at `positions` with `views_per_place` views each, at the yaws of
    /// [`crate::capture::view_yaw`] (evenly spaced from 0), and kind `"place"`.
    pub fn with_views(
        positions: &[Point3<f64>],
        edges: &[(PlaceId, PlaceId)],
        views_per_place: usize,
    ) -> Self {
        let yaws: Vec<f64> = (0..views_per_place)
            .map(|j| crate::capture::view_yaw(j, views_per_place))
            .collect();
        Self {
            places: positions
                .iter()
                .map(|p| Place {
                    position: [p.x, p.y, p.z],
                    kind: "place".into(),
                    view_yaws: yaws.clone(),
                })
                .collect(),
            edges: edges.to_vec(),
        }
    }

    /// Checks the graph: at least one place, finite positions, at least one finite view yaw
    /// per place, edges between distinct existing places. The message names the item.
    pub fn validate(&self) -> Result<(), String> {
        if self.places.is_empty() {
            return Err("places: the graph has no places".into());
        }
        for (i, place) in self.places.iter().enumerate() {
            if !place.position.iter().all(|c| c.is_finite()) {
                return Err(format!(
                    "places[{i}].position {:?} is not finite",
                    place.position
                ));
            }
            if place.view_yaws.is_empty() || !place.view_yaws.iter().all(|y| y.is_finite()) {
                return Err(format!(
                    "places[{i}].view_yaws {:?}: need at least one finite yaw",
                    place.view_yaws
                ));
            }
        }
        let n = self.places.len();
        for (e, &(a, b)) in self.edges.iter().enumerate() {
            if a as usize >= n || b as usize >= n || a == b {
                return Err(format!(
                    "edges[{e}] ({a}, {b}) must join two distinct places of the {n}"
                ));
            }
        }
        Ok(())
    }

    /// Global index of each place's first view (one more entry at the end: the view count).
    pub fn view_offsets(&self) -> Vec<ViewId> {
        let mut offsets = Vec::with_capacity(self.places.len() + 1);
        let mut next = 0;
        offsets.push(0);
        for place in &self.places {
            next += place.view_yaws.len() as ViewId;
            offsets.push(next);
        }
        offsets
    }

    /// Number of views of all places.
    pub fn view_count(&self) -> usize {
        self.places.iter().map(|p| p.view_yaws.len()).sum()
    }

    /// Neighbours of each place.
    pub fn adjacency(&self) -> Vec<Vec<PlaceId>> {
        let mut adjacency = vec![Vec::new(); self.places.len()];
        for &(a, b) in &self.edges {
            adjacency[a as usize].push(b);
            adjacency[b as usize].push(a);
        }
        adjacency
    }

    /// Hop distances for the graph metrics of `topoloc::eval` (MNA, OHA, R@N). Fails with the
    /// reason of [`validate`](Self::validate) when an edge names a missing place.
    pub fn hop_distances(&self) -> Result<HopDistances, String> {
        HopDistances::from_adjacency(&self.adjacency()).map_err(|e| e.to_string())
    }
}

/// The ground truth of one frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FrameTruth {
    /// Frame index.
    pub frame: usize,
    /// The closest place in line of sight of the camera (the closest place at all when none is
    /// in sight: then `visible` is false).
    pub place: PlaceId,
    /// Global index of that place's view whose yaw is closest to the camera's heading.
    pub view: ViewId,
    /// Whether the straight segment from the camera to the place crosses only free voxels.
    pub visible: bool,
}

/// Ground truth of every frame of `frames` (camera poses `world_T_body`) against `graph` in
/// `grid`: for each, the closest place whose segment to the camera is free
/// ([`OccupancyGrid::segment_is_free`]), else the closest place flagged not visible; then the
/// view of it with the smallest absolute yaw difference (the first on ties). Fails with the
/// reason of [`PlaceGraph::validate`]. Runs frames in parallel; each costs at most one
/// line-of-sight walk per place.
pub fn ground_truth(
    grid: &OccupancyGrid,
    graph: &PlaceGraph,
    frames: &[TimedPose],
) -> Result<Vec<FrameTruth>, String> {
    graph.validate()?;
    let offsets = graph.view_offsets();
    let points: Vec<Point3<f64>> = graph.places.iter().map(Place::point).collect();
    Ok(frames
        .par_iter()
        .enumerate()
        .map(|(frame, pose)| {
            let camera = Point3::from(pose.world_t_camera.translation.vector);
            let mut order: Vec<(f64, usize)> = points
                .iter()
                .enumerate()
                .map(|(i, p)| ((p - camera).norm_squared(), i))
                .collect();
            order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let seen = order
                .iter()
                .find(|&&(_, i)| grid.segment_is_free(&camera, &points[i]));
            let (place, visible) = match seen {
                Some(&(_, i)) => (i, true),
                None => (order[0].1, false),
            };
            let yaw = crate::camera::yaw_of(&pose.world_t_camera);
            let best = closest_yaw(&graph.places[place].view_yaws, yaw);
            FrameTruth {
                frame,
                place: place as PlaceId,
                view: offsets[place] + best as ViewId,
                visible,
            }
        })
        .collect())
}

/// Index of the yaw in `yaws` closest to `yaw` (smallest absolute wrapped difference; the first
/// on ties).
pub fn closest_yaw(yaws: &[f64], yaw: f64) -> usize {
    let mut best = (f64::INFINITY, 0);
    for (j, &y) in yaws.iter().enumerate() {
        let d = wrap_angle(yaw - y).abs();
        if d < best.0 - 1e-12 {
            best = (d, j);
        }
    }
    best.1
}

/// Frames of each place: `table[p]` lists, in order, the frames whose true place is `p`
/// (`place_count` places; frames naming a larger place are skipped).
pub fn frames_by_place(truth: &[FrameTruth], place_count: usize) -> Vec<Vec<usize>> {
    let mut table = vec![Vec::new(); place_count];
    for t in truth {
        if let Some(list) = table.get_mut(t.place as usize) {
            list.push(t.frame);
        }
    }
    table
}

/// A run of consecutive frames at one place.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Visit {
    /// The place.
    pub place: PlaceId,
    /// Its frames (indices into the truth slice).
    pub frames: Range<usize>,
}

/// The trajectory as a sequence of visits; a place appearing in two visits is a revisit (a loop
/// closure opportunity).
pub fn visits(truth: &[FrameTruth]) -> Vec<Visit> {
    let mut out: Vec<Visit> = Vec::new();
    for (k, t) in truth.iter().enumerate() {
        match out.last_mut() {
            Some(last) if last.place == t.place => last.frames.end = k + 1,
            _ => out.push(Visit {
                place: t.place,
                frames: k..k + 1,
            }),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::pose;
    use crate::trajectory::tests::{two_rooms, two_rooms_planner};
    use crate::trajectory::MotionOptions;

    fn at(x: f64, y: f64, yaw: f64) -> TimedPose {
        TimedPose {
            timestamp: 0.0,
            world_t_camera: pose(Point3::new(x, y, 1.5), yaw, 0.0),
        }
    }

    /// Places: room A centre, corridor middle, room B centre, and one just behind room A's
    /// east wall (closer to the corridor mouth but hidden).
    fn graph() -> PlaceGraph {
        let positions = [
            Point3::new(3.0, 3.0, 1.5),
            Point3::new(8.0, 3.0, 1.5),
            Point3::new(13.0, 3.0, 1.5),
            Point3::new(6.5, 1.0, 1.5),
        ];
        PlaceGraph::with_four_views(&positions, &[(0, 1), (1, 2), (1, 3)])
    }

    #[test]
    fn the_closest_visible_place_wins_over_a_hidden_closer_one() {
        let grid = two_rooms();
        let truth = ground_truth(&grid, &graph(), &[at(5.5, 1.0, 0.0), at(3.2, 3.0, 3.0)]).unwrap();
        // From (5.5, 1): place 3 (1 m, behind the wall) is hidden; place 0 is visible.
        assert_eq!((truth[0].place, truth[0].visible), (0, true));
        assert_eq!(truth[0].view, 0, "heading 0 -> view 0");
        // Heading 3 rad is closest to 180 degrees: view 2 of place 0.
        assert_eq!((truth[1].place, truth[1].view), (0, 2));
    }

    #[test]
    fn views_follow_the_heading_and_hidden_frames_are_flagged() {
        let grid = two_rooms();
        let g = graph();
        let frames: Vec<TimedPose> = [0.2, 1.4, 2.8, -1.0]
            .iter()
            .map(|&yaw| at(12.5, 3.5, yaw))
            .collect();
        let truth = ground_truth(&grid, &g, &frames).unwrap();
        let views: Vec<ViewId> = truth.iter().map(|t| t.view).collect();
        assert_eq!(views, vec![8, 9, 10, 11]);
        assert!(truth.iter().all(|t| t.place == 2 && t.visible));
        // A camera inside a wall sees nothing: the closest place, flagged.
        let hidden = ground_truth(&grid, &g, &[at(8.0, 1.0, 0.0)]).unwrap();
        assert_eq!((hidden[0].place, hidden[0].visible), (3, false));
        assert_eq!(
            closest_yaw(&FOUR_VIEW_YAWS, FRAC_PI_2 / 2.0),
            0,
            "ties go to the first"
        );
        assert_eq!(closest_yaw(&FOUR_VIEW_YAWS, -3.0), 2);
    }

    #[test]
    fn bad_graphs_are_named() {
        let grid = two_rooms();
        let mut g = graph();
        g.edges.push((2, 9));
        let err = ground_truth(&grid, &g, &[]).unwrap_err();
        assert!(err.contains("edges[3]"), "{err}");
        let mut g = graph();
        g.places[1].position[2] = f64::NAN;
        assert!(g.validate().unwrap_err().contains("places[1].position"));
        g.places.clear();
        assert!(g.validate().unwrap_err().contains("no places"));
    }

    #[test]
    fn a_loop_revisits_places() {
        let (grid, planner) = two_rooms_planner();
        let waypoints = [
            Point3::new(2.0, 2.0, 1.5),
            Point3::new(14.0, 4.0, 1.5),
            Point3::new(2.0, 4.0, 1.5),
        ];
        let t = planner
            .trajectory_through(&waypoints, &MotionOptions::default(), 1)
            .unwrap();
        let g = graph();
        let truth = ground_truth(&grid, &g, &t.frames).unwrap();
        let runs = visits(&truth);
        let order: Vec<PlaceId> = runs.iter().map(|v| v.place).collect();
        assert_eq!(order, vec![0, 1, 2, 1, 0], "there and back: {runs:?}");
        let table = frames_by_place(&truth, g.places.len());
        assert_eq!(table.iter().map(Vec::len).sum::<usize>(), truth.len());
        assert!(table[3].is_empty(), "the hidden place is never the truth");
        let hops = g.hop_distances().unwrap();
        assert_eq!(hops.place_count(), 4);
        assert_eq!(g.view_offsets(), vec![0, 4, 8, 12, 16]);
    }
}
