//! The clearance map (the library's exact 3D Euclidean distance transform,
//! [`squared_distance_transform`]), connected components, 3D A* and path smoothing behind
//! [`Planner`](super::Planner).

use nalgebra::{Point3, Vector3};
use std::cmp::Ordering;
use std::collections::BinaryHeap;
use topoloc::skeleton::{squared_distance_transform, GridBorder, OccupancyGrid};

/// One of the 26 moves of the voxel neighbourhood.
struct Move {
    delta: [i64; 3],
    /// Step length in voxels: 1, sqrt 2 or sqrt 3.
    cost: f32,
    /// The voxels of the move's bounding box other than its start, as offsets; all of them
    /// must be clear, so a diagonal move never cuts an obstacle's corner.
    swept: Vec<[i64; 3]>,
}

fn moves() -> Vec<Move> {
    let mut moves = Vec::with_capacity(26);
    for dz in -1i64..=1 {
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                let delta = [dx, dy, dz];
                if delta == [0, 0, 0] {
                    continue;
                }
                let axes = delta.iter().filter(|&&d| d != 0).count();
                let mut swept = Vec::new();
                for mask in 1u32..8 {
                    let offset = [0, 1, 2].map(|k| if mask & (1 << k) != 0 { delta[k] } else { 0 });
                    if offset != [0, 0, 0] && !swept.contains(&offset) {
                        swept.push(offset);
                    }
                }
                moves.push(Move {
                    delta,
                    cost: (axes as f32).sqrt(),
                    swept,
                });
            }
        }
    }
    moves
}

/// The voxels a vehicle may occupy: free voxels at least the clearance away from obstacles,
/// with centres inside the flight band, as a slab of the grid's z layers `z0..z0 + nz`.
pub(super) struct ClearSpace {
    /// Slab size in voxels.
    pub dims: [usize; 3],
    /// First grid z layer of the slab.
    pub z0: usize,
    pub clear: Vec<bool>,
    /// Connected component of each clear voxel (1-based; 0 for voxels that are not clear).
    pub component: Vec<u32>,
    /// Voxels per component, indexed by component label (entry 0 unused).
    pub component_sizes: Vec<usize>,
    moves: Vec<Move>,
}

impl ClearSpace {
    /// `threshold_sq`: least squared centre distance (voxels) to an occupied voxel, voxels
    /// outside the grid counting as occupied (a vehicle keeps its clearance from the grid's
    /// border too). Panics when the memory for the distance transform cannot be reserved.
    pub fn new(grid: &OccupancyGrid, z_layers: (usize, usize), threshold_sq: f64) -> Self {
        let [nx, ny, _] = grid.dims();
        let (z0, z1) = z_layers;
        let dist = squared_distance_transform(grid, GridBorder::Closed)
            .expect("memory for the distance transform of the grid");
        let slab = &dist[nx * ny * z0..nx * ny * (z1 + 1)];
        let clear = slab.iter().map(|&d| d >= threshold_sq).collect();
        let mut space = Self {
            dims: [nx, ny, z1 + 1 - z0],
            z0,
            clear,
            component: Vec::new(),
            component_sizes: vec![0],
            moves: moves(),
        };
        space.label_components();
        space
    }

    pub fn voxel(&self, i: usize) -> [usize; 3] {
        let [nx, ny, _] = self.dims;
        [i % nx, (i / nx) % ny, i / (nx * ny)]
    }

    pub fn index(&self, v: [usize; 3]) -> usize {
        v[0] + self.dims[0] * (v[1] + self.dims[1] * v[2])
    }

    /// Slab index of grid voxel `v`, if `v` lies in the slab.
    pub fn slab_index(&self, v: [usize; 3]) -> Option<usize> {
        let z = v[2].checked_sub(self.z0).filter(|&z| z < self.dims[2])?;
        Some(self.index([v[0], v[1], z]))
    }

    /// Calls `visit(neighbour, step_cost)` for every clear voxel one legal move from `i`.
    fn neighbours(&self, i: usize, mut visit: impl FnMut(usize, f32)) {
        let v = self.voxel(i).map(|c| c as i64);
        let dims = self.dims.map(|d| d as i64);
        let inside = |p: [i64; 3]| (0..3).all(|k| p[k] >= 0 && p[k] < dims[k]);
        let at = |p: [i64; 3]| (p[0] + dims[0] * (p[1] + dims[1] * p[2])) as usize;
        for m in &self.moves {
            let to = [0, 1, 2].map(|k| v[k] + m.delta[k]);
            if !inside(to) {
                continue;
            }
            let swept_clear = m
                .swept
                .iter()
                .all(|o| self.clear[at([0, 1, 2].map(|k| v[k] + o[k]))]);
            if swept_clear {
                visit(at(to), m.cost);
            }
        }
    }

    fn label_components(&mut self) {
        let mut component = vec![0u32; self.clear.len()];
        let mut stack = Vec::new();
        for seed in 0..self.clear.len() {
            if !self.clear[seed] || component[seed] != 0 {
                continue;
            }
            let label = self.component_sizes.len() as u32;
            let mut size = 0;
            component[seed] = label;
            stack.push(seed);
            while let Some(i) = stack.pop() {
                size += 1;
                self.neighbours(i, |j, _| {
                    if component[j] == 0 {
                        component[j] = label;
                        stack.push(j);
                    }
                });
            }
            self.component_sizes.push(size);
        }
        self.component = component;
    }

    /// Shortest 26-connected path of clear voxels from `start` to `goal` (slab indices in one
    /// component), A* with the exact octile heuristic; `None` if there is none.
    pub fn astar(&self, start: usize, goal: usize) -> Option<Vec<usize>> {
        let g_voxel = self.voxel(goal);
        let heuristic = |i: usize| {
            let v = self.voxel(i);
            let mut d = [0, 1, 2].map(|k| v[k].abs_diff(g_voxel[k]) as f32);
            d.sort_unstable_by(|a, b| b.total_cmp(a));
            d[0] + (2f32.sqrt() - 1.0) * d[1] + (3f32.sqrt() - 2f32.sqrt()) * d[2]
        };
        let mut g = vec![f32::INFINITY; self.clear.len()];
        let mut parent = vec![u32::MAX; self.clear.len()];
        let mut closed = vec![false; self.clear.len()];
        let mut open = BinaryHeap::new();
        g[start] = 0.0;
        open.push(Open {
            f: heuristic(start),
            g: 0.0,
            index: start as u32,
        });
        while let Some(Open {
            g: g_here, index, ..
        }) = open.pop()
        {
            let i = index as usize;
            if closed[i] {
                continue;
            }
            closed[i] = true;
            if i == goal {
                let mut path = vec![goal];
                let mut at = goal;
                while parent[at] != u32::MAX {
                    at = parent[at] as usize;
                    path.push(at);
                }
                path.reverse();
                return Some(path);
            }
            self.neighbours(i, |j, cost| {
                let candidate = g_here + cost;
                if !closed[j] && candidate < g[j] {
                    g[j] = candidate;
                    parent[j] = index;
                    open.push(Open {
                        f: candidate + heuristic(j),
                        g: candidate,
                        index: j as u32,
                    });
                }
            });
        }
        None
    }
}

/// An open-list entry: lowest `f` first, ties to the deepest (largest `g`).
struct Open {
    f: f32,
    g: f32,
    index: u32,
}

impl PartialEq for Open {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Open {}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Open {
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .f
            .total_cmp(&self.f)
            .then(self.g.total_cmp(&other.g))
            .then(other.index.cmp(&self.index))
    }
}

/// Greedy line-of-sight shortcutting: from each kept vertex, jump to the farthest later vertex
/// that `visible` connects to it.
pub(super) fn shortcut(
    path: &[Point3<f64>],
    visible: impl Fn(&Point3<f64>, &Point3<f64>) -> bool,
) -> Vec<Point3<f64>> {
    let Some(&first) = path.first() else {
        return Vec::new();
    };
    let mut kept = vec![first];
    let mut anchor = 0;
    while anchor + 1 < path.len() {
        let mut next = anchor + 1;
        for j in anchor + 2..path.len() {
            if visible(&path[anchor], &path[j]) {
                next = j;
            } else {
                break;
            }
        }
        kept.push(path[next]);
        anchor = next;
    }
    kept
}

/// Rounds the corners of polyline `vertices` with quadratic Bezier arcs whose tangent length
/// follows `radius_m` (half of each adjacent segment at most), shrinking an arc until
/// `visible` accepts every chord of it (a corner stays sharp when none fits). Returns the dense
/// curve sampled every `step_m` metres or less.
pub(super) fn round_corners(
    vertices: &[Point3<f64>],
    radius_m: f64,
    step_m: f64,
    min_cut_m: f64,
    visible: impl Fn(&Point3<f64>, &Point3<f64>) -> bool,
) -> Vec<Point3<f64>> {
    let mut out: Vec<Point3<f64>> = Vec::new();
    let Some(&first) = vertices.first() else {
        return out;
    };
    out.push(first);
    let line_to = |out: &mut Vec<Point3<f64>>, to: Point3<f64>| {
        let from = *out.last().expect("curve starts with a point");
        let pieces = ((to - from).norm() / step_m).ceil().max(1.0) as usize;
        for k in 1..=pieces {
            out.push(from + (to - from) * (k as f64 / pieces as f64));
        }
    };
    for i in 1..vertices.len().saturating_sub(1) {
        let (prev, corner, next) = (vertices[i - 1], vertices[i], vertices[i + 1]);
        let (a_len, b_len) = ((corner - prev).norm(), (next - corner).norm());
        let (u, v): (Vector3<f64>, Vector3<f64>) =
            ((corner - prev) / a_len, (next - corner) / b_len);
        let turn = u.dot(&v).clamp(-1.0, 1.0).acos();
        let mut cut = (radius_m * (turn / 2.0).tan())
            .min(a_len / 2.0)
            .min(b_len / 2.0);
        let mut arc = Vec::new();
        while cut >= min_cut_m && turn > 1e-6 {
            let (a, b) = (corner - u * cut, corner + v * cut);
            let pieces = ((2.0 * cut / step_m).ceil() as usize).max(4);
            arc.clear();
            arc.extend((0..=pieces).map(|k| {
                let t = k as f64 / pieces as f64;
                let w = [(1.0 - t) * (1.0 - t), 2.0 * t * (1.0 - t), t * t];
                Point3::from(a.coords * w[0] + corner.coords * w[1] + b.coords * w[2])
            }));
            if arc.windows(2).all(|pair| visible(&pair[0], &pair[1])) {
                break;
            }
            arc.clear();
            cut /= 2.0;
        }
        if arc.is_empty() {
            line_to(&mut out, corner);
        } else {
            line_to(&mut out, arc[0]);
            out.extend_from_slice(&arc[1..]);
        }
    }
    if vertices.len() > 1 {
        line_to(&mut out, vertices[vertices.len() - 1]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn astar_finds_the_octile_shortest_path() {
        let grid = OccupancyGrid::empty([12, 12, 3], 0.1, Point3::origin()).unwrap();
        let space = ClearSpace::new(&grid, (1, 1), 0.25);
        assert_eq!(space.component_sizes.len(), 2, "one component");
        let start = space.index([0, 0, 0]);
        let goal = space.index([11, 5, 0]);
        let path = space.astar(start, goal).unwrap();
        // 5 diagonal steps and 6 straight ones: 11 moves, 12 voxels.
        assert_eq!(path.len(), 12);
        assert_eq!((path[0], path[11]), (start, goal));
    }

    #[test]
    fn corners_are_rounded_only_where_free() {
        let square = [
            Point3::new(0.0, 0.0, 1.0),
            Point3::new(2.0, 0.0, 1.0),
            Point3::new(2.0, 2.0, 1.0),
        ];
        let rounded = round_corners(&square, 0.5, 0.05, 0.02, |_, _| true);
        let closest = rounded
            .iter()
            .map(|p| (p - square[1]).norm())
            .fold(f64::INFINITY, f64::min);
        assert!(closest > 0.1, "the corner is cut: {closest}");
        assert!(rounded
            .windows(2)
            .all(|w| (w[1] - w[0]).norm() <= 0.05 + 1e-9));
        let sharp = round_corners(&square, 0.5, 0.05, 0.02, |_, _| false);
        assert!(
            sharp.iter().any(|p| (p - square[1]).norm() < 1e-12),
            "kept sharp"
        );
    }
}
