//! From skeleton voxels to a graph of places (steps 3-6 of the module documentation).
//!
//! Rules, in order:
//! - **Spurs**: a chain of 2-neighbour voxels from an end voxel to a junction voxel, shorter than
//!   `min_spur_m`, is removed; the skeleton is then thinned again (a junction left with two
//!   branches can hold a redundant voxel) and this repeats until no spur is left.
//! - **Nodes**: ends (at most one neighbour), junctions (connected groups of voxels with three or
//!   more neighbours) and corners (see [`corners`]). The voxels between nodes form *segments*.
//!   A loop of the skeleton without ends or junctions starts at its sharpest corner, or, with no
//!   corner either, at an `Intermediate` node on its first voxel in grid order.
//! - **Merging**: nodes are visited by kind (branch, end, corner, intermediate) and then grid
//!   order; each node not yet in a place starts one, placed at its voxel (a junction: its voxel
//!   nearest the junction's centroid) and of its kind, and takes in every node not yet in a
//!   place within `merge_radius_m` along the skeleton whose voxel it sees in a straight line.
//! - **Edges**: every segment is walked from its first place to its last (the path also runs
//!   through the places' own voxels); a segment that leaves a place and comes back to it without
//!   going farther than `merge_radius_m` from it is dropped. Splitting a path at a skeleton voxel inserts an
//!   `Intermediate` place there. A path (or part of one) is split while one of these holds,
//!   checked in this order: its two places are the same place (a loop: split at the voxel
//!   farthest from the place); the straight segment between its places is not obstacle-free in
//!   the grid (split at the voxel farthest from that segment); its places are more than
//!   `max_edge_m` apart (split evenly along the path into as few parts as keep each under
//!   `max_edge_m`); its places are already joined by another path (split in the middle, so that
//!   a loop of the skeleton stays a cycle of the graph). Otherwise the two places are joined.
//!   A part with no segment voxel left to split at joins its places (they are neighbours along
//!   the skeleton; such an edge is at most about `merge_radius_m` long).

use super::thinning::Volume;
use super::{try_vec, GraphEdge, GraphPlace, NodeKind, SkeletonOptions, TopoGraph};
use super::{OccupancyGrid, Voxel};
use nalgebra::Point3;
use std::cmp::Ordering;
use std::collections::{BTreeSet, BinaryHeap};

/// The skeleton as a graph of voxels: ids are positions in grid order, with their 26-neighbours.
struct Skeleton<'g> {
    grid: &'g OccupancyGrid,
    voxels: Vec<Voxel>,
    /// Neighbours of voxel `i`: `neighbours[offsets[i]..offsets[i + 1]]`, increasing.
    offsets: Vec<usize>,
    neighbours: Vec<u32>,
}

impl<'g> Skeleton<'g> {
    /// `voxels` must be in grid order.
    fn new(grid: &'g OccupancyGrid, voxels: Vec<Voxel>) -> Self {
        let linear: Vec<usize> = voxels
            .iter()
            .map(|&v| grid.index(v).expect("skeleton voxels are inside the grid"))
            .collect();
        debug_assert!(linear.windows(2).all(|w| w[0] < w[1]));
        let mut offsets = Vec::with_capacity(voxels.len() + 1);
        let mut neighbours = Vec::new();
        offsets.push(0);
        for v in &voxels {
            let first = neighbours.len();
            for dz in -1i64..=1 {
                for dy in -1i64..=1 {
                    for dx in -1i64..=1 {
                        if (dx, dy, dz) == (0, 0, 0) {
                            continue;
                        }
                        let w = [v[0] as i64 + dx, v[1] as i64 + dy, v[2] as i64 + dz];
                        if w.iter().any(|&c| c < 0) {
                            continue;
                        }
                        let w = [w[0] as usize, w[1] as usize, w[2] as usize];
                        if let Some(j) = grid.index(w).and_then(|l| linear.binary_search(&l).ok()) {
                            neighbours.push(j as u32);
                        }
                    }
                }
            }
            // The loops above run in grid order (x fastest), so the ids are increasing.
            debug_assert!(neighbours[first..].windows(2).all(|w| w[0] < w[1]));
            offsets.push(neighbours.len());
        }
        Self {
            grid,
            voxels,
            offsets,
            neighbours,
        }
    }

    fn len(&self) -> usize {
        self.voxels.len()
    }

    fn neighbours(&self, i: u32) -> &[u32] {
        &self.neighbours[self.offsets[i as usize]..self.offsets[i as usize + 1]]
    }

    fn degree(&self, i: u32) -> usize {
        self.neighbours(i).len()
    }

    fn position(&self, i: u32) -> Point3<f64> {
        self.grid.center(self.voxels[i as usize])
    }

    fn distance(&self, i: u32, j: u32) -> f64 {
        (self.position(i) - self.position(j)).norm()
    }

    /// The neighbour of 2-neighbour voxel `i` that is not `from`.
    fn other_neighbour(&self, i: u32, from: u32) -> u32 {
        let n = self.neighbours(i);
        if n[0] == from {
            n[1]
        } else {
            n[0]
        }
    }
}

/// Builds the graph from the thinned skeleton (grid order).
pub(super) fn build(
    grid: &OccupancyGrid,
    options: &SkeletonOptions,
    voxels: Vec<Voxel>,
) -> TopoGraph {
    let skeleton = remove_spurs(grid, voxels, options);
    let nodes = Nodes::find(&skeleton, options);
    let places = merge(&skeleton, &nodes, options);
    let mut edges = EdgeBuilder {
        skeleton: &skeleton,
        options,
        places,
        edges: BTreeSet::new(),
    };
    for segment in &nodes.segments {
        edges.add_segment(&nodes, segment);
    }
    let places: Vec<GraphPlace> = edges
        .places
        .places
        .iter()
        .map(|&(voxel, kind)| GraphPlace {
            position: skeleton.position(voxel),
            voxel: skeleton.voxels[voxel as usize],
            kind,
        })
        .collect();
    let edges = edges
        .edges
        .iter()
        .map(|&(a, b)| GraphEdge {
            a,
            b,
            length_m: (places[a as usize].position - places[b as usize].position).norm(),
        })
        .collect();
    TopoGraph {
        places,
        edges,
        skeleton: skeleton.voxels,
    }
}

/// Removes short spurs (see the module documentation), thinning again after each pass.
fn remove_spurs<'g>(
    grid: &'g OccupancyGrid,
    mut voxels: Vec<Voxel>,
    options: &SkeletonOptions,
) -> Skeleton<'g> {
    loop {
        let skeleton = Skeleton::new(grid, voxels);
        if options.min_spur_m <= 0.0 {
            return skeleton;
        }
        let mut remove = vec![false; skeleton.len()];
        let mut removed = false;
        for end in 0..skeleton.len() as u32 {
            if skeleton.degree(end) != 1 {
                continue;
            }
            let mut chain = vec![end];
            let (mut prev, mut cur) = (end, skeleton.neighbours(end)[0]);
            let mut length = skeleton.distance(prev, cur);
            while skeleton.degree(cur) == 2 && length < options.min_spur_m {
                chain.push(cur);
                let next = skeleton.other_neighbour(cur, prev);
                length += skeleton.distance(cur, next);
                (prev, cur) = (cur, next);
            }
            if skeleton.degree(cur) >= 3 && length < options.min_spur_m {
                for &i in &chain {
                    remove[i as usize] = true;
                }
                removed = true;
            }
        }
        if !removed {
            return skeleton;
        }
        let kept: Vec<Voxel> = (0..skeleton.len())
            .filter(|&i| !remove[i])
            .map(|i| skeleton.voxels[i])
            .collect();
        voxels = rethin(kept);
    }
}

/// Thins a set of skeleton voxels (grid order) again, removing voxels made redundant by spur
/// removal. Should its memory not be available, the voxels are kept as they are (a former
/// junction may then keep a redundant voxel).
fn rethin(voxels: Vec<Voxel>) -> Vec<Voxel> {
    if voxels.is_empty() {
        return voxels;
    }
    // Thin inside the bounding box of the voxels only.
    let mut lo = [usize::MAX; 3];
    let mut hi = [0usize; 3];
    for v in &voxels {
        for k in 0..3 {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
        }
    }
    let dims = [hi[0] - lo[0] + 1, hi[1] - lo[1] + 1, hi[2] - lo[2] + 1];
    let Some(mut inside) = try_vec(dims[0] * dims[1] * dims[2], false) else {
        return voxels;
    };
    for v in &voxels {
        inside[v[0] - lo[0] + dims[0] * (v[1] - lo[1] + dims[1] * (v[2] - lo[2]))] = true;
    }
    // A single-layer box is thinned in the plane only: fine, the voxels are in one layer.
    let Some(mut volume) = Volume::new(dims, |x, y, z| inside[x + dims[0] * (y + dims[1] * z)])
    else {
        return voxels;
    };
    let Some(thinned) = volume.thin() else {
        return voxels;
    };
    thinned
        .into_iter()
        .map(|i| {
            let v = volume.inner_voxel(i);
            [v[0] + lo[0], v[1] + lo[1], v[2] + lo[2]]
        })
        .collect()
}

/// A run of skeleton voxels between two node voxels.
struct Segment {
    /// First and last node voxel (equal for a loop).
    ends: [u32; 2],
    /// The 2-neighbour voxels in between, in order.
    interior: Vec<u32>,
}

/// A node: one end or corner voxel, or one junction (its voxels), or a loop's anchor.
struct Node {
    kind: NodeKind,
    /// The node's voxel (a junction: its voxel nearest the junction's centroid).
    voxel: u32,
}

/// The nodes of a skeleton and the segments between them.
struct Nodes {
    nodes: Vec<Node>,
    /// Node of each node voxel (`u32::MAX` for the others).
    node_of: Vec<u32>,
    segments: Vec<Segment>,
}

impl Nodes {
    fn find(skeleton: &Skeleton, options: &SkeletonOptions) -> Self {
        let n = skeleton.len();
        let mut node_of = vec![u32::MAX; n];
        let mut nodes = Vec::new();
        // Junctions: connected groups of voxels with three or more neighbours.
        for start in 0..n as u32 {
            if skeleton.degree(start) < 3 || node_of[start as usize] != u32::MAX {
                continue;
            }
            let id = nodes.len() as u32;
            let mut members = vec![start];
            node_of[start as usize] = id;
            let mut k = 0;
            while k < members.len() {
                for &w in skeleton.neighbours(members[k]) {
                    if skeleton.degree(w) >= 3 && node_of[w as usize] == u32::MAX {
                        node_of[w as usize] = id;
                        members.push(w);
                    }
                }
                k += 1;
            }
            nodes.push(Node {
                kind: NodeKind::Branch,
                voxel: nearest_to_centroid(skeleton, &members),
            });
        }
        for i in 0..n as u32 {
            if skeleton.degree(i) <= 1 {
                node_of[i as usize] = nodes.len() as u32;
                nodes.push(Node {
                    kind: NodeKind::End,
                    voxel: i,
                });
            }
        }
        let mut found = Self {
            nodes,
            node_of,
            segments: Vec::new(),
        };
        let (runs, loops) = runs_between_nodes(skeleton, &found.node_of);
        let scale = corner_scale(skeleton.grid, options);
        for run in runs {
            let corners = corners(skeleton, &run, false, scale, options.corner_angle_deg);
            found.split_run(run, &corners, NodeKind::Corner);
        }
        for cycle in loops {
            let corners = corners(skeleton, &cycle, true, scale, options.corner_angle_deg);
            // Start the loop at a corner if it has one, else at its first voxel in grid order.
            let (start, kind) = match corners.first() {
                Some(&c) => (c, NodeKind::Corner),
                None => {
                    let first = (0..cycle.len()).min_by_key(|&k| cycle[k]).unwrap_or(0);
                    (first, NodeKind::Intermediate)
                }
            };
            let mut run: Vec<u32> = cycle[start..]
                .iter()
                .chain(&cycle[..start])
                .copied()
                .collect();
            run.push(run[0]);
            let shifted: Vec<usize> = corners
                .iter()
                .map(|&c| (c + cycle.len() - start) % cycle.len())
                .filter(|&c| c != 0)
                .collect();
            found.add_node(run[0], kind);
            found.split_run(run, &shifted, NodeKind::Corner);
        }
        found
    }

    fn add_node(&mut self, voxel: u32, kind: NodeKind) {
        self.node_of[voxel as usize] = self.nodes.len() as u32;
        self.nodes.push(Node { kind, voxel });
    }

    /// Splits `run` (node voxel, 2-neighbour voxels..., node voxel) at the positions `at`
    /// (interior, any order), which become nodes of `kind`, and records the segments.
    fn split_run(&mut self, run: Vec<u32>, at: &[usize], kind: NodeKind) {
        let mut cuts: Vec<usize> = at.to_vec();
        cuts.sort_unstable();
        for &c in &cuts {
            self.add_node(run[c], kind);
        }
        let mut start = 0;
        for end in cuts.into_iter().chain([run.len() - 1]) {
            self.segments.push(Segment {
                ends: [run[start], run[end]],
                interior: run[start + 1..end].to_vec(),
            });
            start = end;
        }
    }
}

/// The voxel of `members` nearest their centroid (the first in grid order on a tie).
fn nearest_to_centroid(skeleton: &Skeleton, members: &[u32]) -> u32 {
    let sum = members.iter().fold(Point3::origin().coords, |s, &m| {
        s + skeleton.position(m).coords
    });
    let centroid = Point3::from(sum / members.len() as f64);
    let mut best = members[0];
    let mut best_d = f64::INFINITY;
    let mut sorted = members.to_vec();
    sorted.sort_unstable();
    for m in sorted {
        let d = (skeleton.position(m) - centroid).norm();
        if d < best_d {
            (best, best_d) = (m, d);
        }
    }
    best
}

/// The runs of 2-neighbour voxels between node voxels, each with its two node voxels
/// (`[node, voxels..., node]`; two adjacent node voxels of different nodes give a run of two),
/// and the loops of 2-neighbour voxels that touch no node.
fn runs_between_nodes(skeleton: &Skeleton, node_of: &[u32]) -> (Vec<Vec<u32>>, Vec<Vec<u32>>) {
    let is_node = |i: u32| node_of[i as usize] != u32::MAX;
    let mut visited = vec![false; skeleton.len()];
    let mut runs = Vec::new();
    for start in 0..skeleton.len() as u32 {
        if !is_node(start) {
            continue;
        }
        for &first in skeleton.neighbours(start) {
            if is_node(first) {
                // Two node voxels side by side: a link unless they are the same junction.
                if start < first && node_of[start as usize] != node_of[first as usize] {
                    runs.push(vec![start, first]);
                }
                continue;
            }
            if visited[first as usize] {
                continue; // traced from its other end
            }
            let mut run = vec![start];
            let (mut prev, mut cur) = (start, first);
            while !is_node(cur) {
                visited[cur as usize] = true;
                run.push(cur);
                let next = skeleton.other_neighbour(cur, prev);
                (prev, cur) = (cur, next);
            }
            run.push(cur);
            runs.push(run);
        }
    }
    let mut loops = Vec::new();
    for start in 0..skeleton.len() as u32 {
        if is_node(start) || visited[start as usize] {
            continue;
        }
        let mut cycle = vec![start];
        visited[start as usize] = true;
        let (mut prev, mut cur) = (start, skeleton.neighbours(start)[0]);
        while cur != start {
            visited[cur as usize] = true;
            cycle.push(cur);
            let next = skeleton.other_neighbour(cur, prev);
            (prev, cur) = (cur, next);
        }
        loops.push(cycle);
    }
    (runs, loops)
}

/// Steps along the skeleton over which bends are measured: `corner_scale_m`, at least 4 voxels.
fn corner_scale(grid: &OccupancyGrid, options: &SkeletonOptions) -> usize {
    ((options.corner_scale_m / grid.voxel_size()).ceil() as usize).max(4)
}

/// Positions of the corners of `run` (a node-to-node run, or a closed `cycle` of voxels): the
/// voxels where the angle between the directions to the voxels `scale` steps before and after
/// (clamped to the run's ends) is at most `180 - min_bend_deg` degrees, keeping only the
/// sharpest voxel within `scale` steps. Sorted by sharpness (sharpest first), then position.
fn corners(
    skeleton: &Skeleton,
    run: &[u32],
    cycle: bool,
    scale: usize,
    min_bend_deg: f64,
) -> Vec<usize> {
    let n = run.len();
    if cycle && n < 2 * scale + 1 {
        return Vec::new(); // too small a loop to speak of corners
    }
    let positions: Vec<usize> = if cycle {
        (0..n).collect()
    } else {
        (1..n.saturating_sub(1)).collect()
    };
    let mut bends: Vec<(f64, usize)> = positions
        .into_iter()
        .filter_map(|k| {
            let (before, after) = if cycle {
                ((k + n - scale) % n, (k + scale) % n)
            } else {
                (k.saturating_sub(scale), (k + scale).min(n - 1))
            };
            let here = skeleton.position(run[k]);
            let a = skeleton.position(run[before]) - here;
            let b = skeleton.position(run[after]) - here;
            let cos = (a.dot(&b) / (a.norm() * b.norm())).clamp(-1.0, 1.0);
            let bend = 180.0 - cos.acos().to_degrees();
            (bend >= min_bend_deg).then_some((bend, k))
        })
        .collect();
    bends.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
    let mut kept: Vec<usize> = Vec::new();
    for (_, k) in bends {
        let far = |c: &usize| {
            let d = k.abs_diff(*c);
            let d = if cycle { d.min(n - d) } else { d };
            d > scale
        };
        if kept.iter().all(far) {
            kept.push(k);
        }
    }
    kept
}

/// The places being built: `(voxel, kind)`, and the place of each node.
struct Places {
    places: Vec<(u32, NodeKind)>,
    place_of_node: Vec<u32>,
}

/// Merges nodes into places (see the module documentation).
fn merge(skeleton: &Skeleton, nodes: &Nodes, options: &SkeletonOptions) -> Places {
    // The node graph: segments as weighted links between nodes.
    let mut links: Vec<Vec<(u32, f64)>> = vec![Vec::new(); nodes.nodes.len()];
    for s in &nodes.segments {
        let [a, b] = s.ends;
        let mut length = 0.0;
        let mut prev = a;
        for &v in s.interior.iter().chain([&b]) {
            length += skeleton.distance(prev, v);
            prev = v;
        }
        let (na, nb) = (nodes.node_of[a as usize], nodes.node_of[b as usize]);
        if na != nb {
            links[na as usize].push((nb, length));
            links[nb as usize].push((na, length));
        }
    }
    let priority = |k: NodeKind| match k {
        NodeKind::Branch => 0,
        NodeKind::End => 1,
        NodeKind::Corner => 2,
        NodeKind::Intermediate => 3,
    };
    let mut order: Vec<u32> = (0..nodes.nodes.len() as u32).collect();
    order.sort_by_key(|&i| {
        let node = &nodes.nodes[i as usize];
        (priority(node.kind), node.voxel)
    });
    let mut place_of_node = vec![u32::MAX; nodes.nodes.len()];
    let mut places = Vec::new();
    let mut dist = vec![f64::INFINITY; nodes.nodes.len()];
    let mut touched = Vec::new();
    for seed in order {
        if place_of_node[seed as usize] != u32::MAX {
            continue;
        }
        let place = places.len() as u32;
        let origin = nodes.nodes[seed as usize].voxel;
        places.push((origin, nodes.nodes[seed as usize].kind));
        place_of_node[seed as usize] = place;
        // Dijkstra along the node graph, up to merge_radius_m.
        for &t in &touched {
            dist[t as usize] = f64::INFINITY;
        }
        touched.clear();
        let mut heap = BinaryHeap::new();
        dist[seed as usize] = 0.0;
        touched.push(seed);
        heap.push(Visit(0.0, seed));
        while let Some(Visit(d, u)) = heap.pop() {
            if d > dist[u as usize] {
                continue;
            }
            if place_of_node[u as usize] == u32::MAX {
                let voxel = nodes.nodes[u as usize].voxel;
                if skeleton
                    .grid
                    .segment_is_free(&skeleton.position(origin), &skeleton.position(voxel))
                {
                    place_of_node[u as usize] = place;
                }
            }
            for &(w, length) in &links[u as usize] {
                let dw = d + length;
                if dw <= options.merge_radius_m && dw < dist[w as usize] {
                    dist[w as usize] = dw;
                    touched.push(w);
                    heap.push(Visit(dw, w));
                }
            }
        }
    }
    Places {
        places,
        place_of_node,
    }
}

/// A Dijkstra queue entry, smallest distance first (then smallest node).
struct Visit(f64, u32);

impl PartialEq for Visit {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Visit {}
impl PartialOrd for Visit {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Visit {
    fn cmp(&self, other: &Self) -> Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

/// Walks segments into edges, inserting intermediate places (see the module documentation).
struct EdgeBuilder<'s, 'g> {
    skeleton: &'s Skeleton<'g>,
    options: &'s SkeletonOptions,
    places: Places,
    edges: BTreeSet<(u32, u32)>,
}

impl EdgeBuilder<'_, '_> {
    fn position(&self, place: u32) -> Point3<f64> {
        self.skeleton.position(self.places.places[place as usize].0)
    }

    fn add_segment(&mut self, nodes: &Nodes, segment: &Segment) {
        let [a, b] = segment.ends;
        let place_a = self.places.place_of_node[nodes.node_of[a as usize] as usize];
        let place_b = self.places.place_of_node[nodes.node_of[b as usize] as usize];
        if place_a == place_b {
            // A loop back into one place: ignore it when it stays near the place.
            let centre = self.position(place_a);
            let reach = self
                .options
                .merge_radius_m
                .max(self.skeleton.grid.voxel_size());
            let near = segment
                .interior
                .iter()
                .all(|&v| (self.skeleton.position(v) - centre).norm() <= reach);
            if near {
                return;
            }
        }
        // The path: place voxel, segment (node voxel, interior..., node voxel), place voxel.
        let mut path: Vec<u32> = Vec::with_capacity(segment.interior.len() + 4);
        let mut push = |v: u32| {
            if path.last() != Some(&v) {
                path.push(v);
            }
        };
        push(self.places.places[place_a as usize].0);
        push(a);
        for &v in &segment.interior {
            push(v);
        }
        push(b);
        push(self.places.places[place_b as usize].0);
        let interior: BTreeSet<u32> = segment.interior.iter().copied().collect();
        let splittable: Vec<bool> = path.iter().map(|v| interior.contains(v)).collect();
        let mut arc = vec![0.0; path.len()];
        for k in 1..path.len() {
            arc[k] = arc[k - 1] + self.skeleton.distance(path[k - 1], path[k]);
        }
        let mut place_at: Vec<u32> = vec![u32::MAX; path.len()];
        place_at[0] = place_a;
        place_at[path.len() - 1] = place_b;
        let walk = Walk {
            path: &path,
            splittable: &splittable,
            arc: &arc,
        };
        // Parts of the path still to join, leftmost first.
        let mut todo = vec![(0usize, path.len() - 1)];
        while let Some((i, j)) = todo.pop() {
            let (p, q) = (place_at[i], place_at[j]);
            let cuts = self.cuts(&walk, i, j, p, q);
            if cuts.is_empty() {
                if p != q {
                    self.edges.insert((p.min(q), p.max(q)));
                }
                continue;
            }
            let mut bounds = vec![i];
            for c in cuts {
                place_at[c] = self.places.places.len() as u32;
                self.places.places.push((path[c], NodeKind::Intermediate));
                bounds.push(c);
            }
            bounds.push(j);
            for w in bounds.windows(2).rev() {
                todo.push((w[0], w[1]));
            }
        }
    }

    /// Where to split the part `i..=j` of a path between places `p` and `q` (increasing
    /// positions strictly inside), or nothing to join `p` and `q` directly.
    fn cuts(&self, walk: &Walk, i: usize, j: usize, p: u32, q: u32) -> Vec<usize> {
        let candidates: Vec<usize> = (i + 1..j).filter(|&k| walk.splittable[k]).collect();
        if candidates.is_empty() {
            return Vec::new();
        }
        let (pp, pq) = (self.position(p), self.position(q));
        let at = |k: usize| self.skeleton.position(walk.path[k]);
        let farthest = |distance: &dyn Fn(Point3<f64>) -> f64| {
            let mut best = (f64::NEG_INFINITY, candidates[0]);
            for &k in &candidates {
                let d = distance(at(k));
                if d > best.0 {
                    best = (d, k);
                }
            }
            best
        };
        if p == q {
            return vec![farthest(&|x| (x - pp).norm()).1];
        }
        let middle = || walk.nearest(&candidates, 0.5 * (walk.arc[i] + walk.arc[j]));
        if !self.skeleton.grid.segment_is_free(&pp, &pq) {
            let (d, k) = farthest(&|x| distance_to_segment(&x, &pp, &pq));
            // A straight path blocked only by a grazed voxel edge: split it in the middle.
            return vec![if d < 0.5 * self.skeleton.grid.voxel_size() {
                middle()
            } else {
                k
            }];
        }
        if (pq - pp).norm() > self.options.max_edge_m {
            let length = walk.arc[j] - walk.arc[i];
            let parts = (length / self.options.max_edge_m).ceil().max(2.0) as usize;
            let mut cuts: Vec<usize> = (1..parts)
                .map(|m| walk.nearest(&candidates, walk.arc[i] + length * m as f64 / parts as f64))
                .collect();
            cuts.dedup();
            return cuts;
        }
        if self.edges.contains(&(p.min(q), p.max(q))) {
            return vec![middle()];
        }
        Vec::new()
    }
}

/// A path being split into edges.
struct Walk<'a> {
    path: &'a [u32],
    splittable: &'a [bool],
    /// Length along the path from its start to each voxel, metres.
    arc: &'a [f64],
}

impl Walk<'_> {
    /// The candidate position whose arc length is nearest `target` (the first on a tie).
    fn nearest(&self, candidates: &[usize], target: f64) -> usize {
        let mut best = (f64::INFINITY, candidates[0]);
        for &k in candidates {
            let d = (self.arc[k] - target).abs();
            if d < best.0 {
                best = (d, k);
            }
        }
        best.1
    }
}

/// Distance from `x` to the segment `a`-`b`.
fn distance_to_segment(x: &Point3<f64>, a: &Point3<f64>, b: &Point3<f64>) -> f64 {
    let ab = b - a;
    let t = ((x - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
    (x - (a + ab * t)).norm()
}

#[cfg(test)]
pub(super) mod tests_support {
    //! Entry points for the unit tests in `tests.rs`.

    use super::*;

    /// The skeleton of `voxels` (any order, no duplicates).
    fn skeleton_of<'g>(grid: &'g OccupancyGrid, voxels: &[Voxel]) -> (Skeleton<'g>, Vec<u32>) {
        let mut sorted = voxels.to_vec();
        sorted.sort_by_key(|&v| grid.index(v));
        let skeleton = Skeleton::new(grid, sorted.clone());
        let ids = voxels
            .iter()
            .map(|v| sorted.iter().position(|w| w == v).unwrap() as u32)
            .collect();
        (skeleton, ids)
    }

    /// Corner positions along the run of voxels `run`, in run order.
    pub fn corner_positions(
        grid: &OccupancyGrid,
        run: &[Voxel],
        options: &SkeletonOptions,
    ) -> Vec<usize> {
        let (skeleton, ids) = skeleton_of(grid, run);
        let scale = corner_scale(grid, options);
        let mut at = corners(&skeleton, &ids, false, scale, options.corner_angle_deg);
        at.sort_unstable();
        at
    }

    /// The kinds of the nodes of a skeleton and its number of segments (without corners).
    pub fn nodes_of(grid: &OccupancyGrid, voxels: Vec<Voxel>) -> (Vec<NodeKind>, usize) {
        let (skeleton, _) = skeleton_of(grid, &voxels);
        let options = SkeletonOptions {
            corner_angle_deg: 179.0,
            ..SkeletonOptions::default()
        };
        let nodes = Nodes::find(&skeleton, &options);
        (
            nodes.nodes.iter().map(|n| n.kind).collect(),
            nodes.segments.len(),
        )
    }
}
