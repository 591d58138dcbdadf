//! Hop distances on the undirected place graph.

use super::EvalError;
use crate::map::{Map, PlaceId};
use std::collections::VecDeque;
use std::sync::OnceLock;

/// Marks a place that a BFS did not reach.
const UNREACHABLE: u32 = u32::MAX;

/// Hop distances (number of edges on a shortest path) between places of an undirected graph.
///
/// The BFS from a source place runs on first use and is cached (one `u32` per place per
/// source), so evaluating many frames costs at most one BFS per distinct place. Queries take
/// `&self` and may run from several threads.
#[derive(Debug)]
pub struct HopDistances {
    /// CSR adjacency: neighbours of p are `neighbours[offsets[p]..offsets[p + 1]]`.
    offsets: Vec<usize>,
    neighbours: Vec<PlaceId>,
    /// Hop counts from each source place, computed on demand.
    from_source: Vec<OnceLock<Box<[u32]>>>,
}

impl HopDistances {
    /// Uses the places and edges of `map` (edge weights are ignored).
    pub fn from_map(map: &Map) -> Self {
        Self::from_edges(map.place_count(), map.edges().iter().map(|e| (e.a, e.b)))
    }

    /// Uses a plain adjacency list: `adjacency[p]` holds neighbours of place `p`. Each listed
    /// edge is taken as undirected, so listing it from one end is enough; duplicates and
    /// self-loops are ignored. Fails when a neighbour id is `>= adjacency.len()`.
    pub fn from_adjacency(adjacency: &[Vec<PlaceId>]) -> Result<Self, EvalError> {
        let places = adjacency.len();
        let mut edges = Vec::new();
        for (place, list) in (0..).zip(adjacency) {
            for &neighbour in list {
                if neighbour as usize >= places {
                    return Err(EvalError::UnknownNeighbour {
                        place,
                        neighbour,
                        places,
                    });
                }
                edges.push((place, neighbour));
            }
        }
        Ok(Self::from_edges(places, edges))
    }

    /// Builds the symmetric CSR adjacency. Edge endpoints must be `< places`.
    fn from_edges(places: usize, edges: impl IntoIterator<Item = (PlaceId, PlaceId)>) -> Self {
        let mut pairs: Vec<(PlaceId, PlaceId)> = edges
            .into_iter()
            .filter(|(a, b)| a != b)
            .map(|(a, b)| (a.min(b), a.max(b)))
            .collect();
        pairs.sort_unstable();
        pairs.dedup();

        let mut offsets = vec![0usize; places + 1];
        for &(a, b) in &pairs {
            offsets[a as usize + 1] += 1;
            offsets[b as usize + 1] += 1;
        }
        for p in 0..places {
            offsets[p + 1] += offsets[p];
        }
        let mut fill = offsets[..places].to_vec();
        let mut neighbours = vec![0; pairs.len() * 2];
        for &(a, b) in &pairs {
            for (from, to) in [(a, b), (b, a)] {
                let slot = &mut fill[from as usize];
                neighbours[*slot] = to;
                *slot += 1;
            }
        }
        Self {
            offsets,
            neighbours,
            from_source: (0..places).map(|_| OnceLock::new()).collect(),
        }
    }

    /// Number of places in the graph.
    pub fn place_count(&self) -> usize {
        self.from_source.len()
    }

    /// Hops between places `a` and `b` (0 when `a == b`); `None` when no path joins them or
    /// either id is not a place of the graph.
    pub fn hops(&self, a: PlaceId, b: PlaceId) -> Option<u32> {
        let (a, b) = (a as usize, b as usize);
        if a >= self.place_count() || b >= self.place_count() {
            return None;
        }
        // The graph is undirected: reuse a BFS from `b` if only that one is cached.
        let (source, target) =
            if self.from_source[a].get().is_none() && self.from_source[b].get().is_some() {
                (b, a)
            } else {
                (a, b)
            };
        let hops = self.from_source[source].get_or_init(|| self.bfs(source))[target];
        (hops != UNREACHABLE).then_some(hops)
    }

    /// Hop counts from `source` to every place, [`UNREACHABLE`] where no path exists.
    fn bfs(&self, source: usize) -> Box<[u32]> {
        let mut hops = vec![UNREACHABLE; self.place_count()];
        let mut queue = VecDeque::from([source]);
        hops[source] = 0;
        while let Some(place) = queue.pop_front() {
            for &next in &self.neighbours[self.offsets[place]..self.offsets[place + 1]] {
                let next = next as usize;
                if hops[next] == UNREACHABLE {
                    hops[next] = hops[place] + 1;
                    queue.push_back(next);
                }
            }
        }
        hops.into_boxed_slice()
    }

    /// Number of source places whose BFS is cached.
    #[cfg(test)]
    fn cached_sources(&self) -> usize {
        self.from_source
            .iter()
            .filter(|cell| cell.get().is_some())
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::descriptor::DescriptorIdentity;
    use crate::map::MapBuilder;

    fn graph(adjacency: &[&[PlaceId]]) -> HopDistances {
        let lists: Vec<Vec<PlaceId>> = adjacency.iter().map(|l| l.to_vec()).collect();
        HopDistances::from_adjacency(&lists).unwrap()
    }

    #[test]
    fn chain_hops_are_index_differences() {
        let chain = graph(&[&[1], &[0, 2], &[1, 3], &[2, 4], &[3]]);
        assert_eq!(chain.place_count(), 5);
        assert_eq!(chain.hops(0, 4), Some(4));
        assert_eq!(chain.hops(4, 0), Some(4));
        assert_eq!(chain.hops(1, 3), Some(2));
        assert_eq!(chain.hops(2, 2), Some(0));
    }

    #[test]
    fn ring_takes_the_shorter_way_round() {
        let ring = graph(&[&[1], &[2], &[3], &[4], &[5], &[0]]);
        assert_eq!(ring.hops(0, 3), Some(3));
        assert_eq!(ring.hops(0, 4), Some(2));
        assert_eq!(ring.hops(1, 5), Some(2));
        assert_eq!(ring.hops(5, 0), Some(1));
    }

    #[test]
    fn disconnected_places_and_unknown_ids_have_no_distance() {
        let two_parts = graph(&[&[1], &[0], &[3], &[2], &[]]);
        assert_eq!(two_parts.hops(0, 1), Some(1));
        assert_eq!(two_parts.hops(0, 2), None);
        assert_eq!(two_parts.hops(3, 4), None);
        assert_eq!(two_parts.hops(4, 4), Some(0));
        assert_eq!(two_parts.hops(0, 9), None);
    }

    #[test]
    fn star_listed_from_the_centre_only_is_undirected() {
        let star = graph(&[&[1, 2, 3, 4, 1], &[], &[], &[], &[]]);
        assert_eq!(star.hops(3, 0), Some(1));
        assert_eq!(star.hops(1, 4), Some(2));
        assert_eq!(star.hops(2, 3), Some(2));
    }

    #[test]
    fn bad_neighbour_is_rejected() {
        let err = HopDistances::from_adjacency(&[vec![1], vec![5]]).unwrap_err();
        assert_eq!(
            err,
            EvalError::UnknownNeighbour {
                place: 1,
                neighbour: 5,
                places: 2
            }
        );
    }

    #[test]
    fn one_bfs_serves_both_directions() {
        let chain = graph(&[&[1], &[2], &[3], &[]]);
        assert_eq!(chain.cached_sources(), 0);
        assert_eq!(chain.hops(0, 3), Some(3));
        assert_eq!(chain.hops(3, 0), Some(3));
        assert_eq!(chain.hops(2, 0), Some(2));
        assert_eq!(chain.cached_sources(), 1);
    }

    #[test]
    fn from_map_uses_the_map_edges() {
        let mut builder = MapBuilder::new(DescriptorIdentity::new("test", "", 4).unwrap());
        for _ in 0..6 {
            let place = builder.add_place(None).unwrap();
            builder
                .add_view(place, &[1.0, 0.0, 0.0, 0.0], Default::default())
                .unwrap();
        }
        // Ring 0-1-2-3-4-0; place 5 has no edge.
        for (a, b) in [(0, 1), (1, 2), (2, 3), (3, 4), (4, 0)] {
            builder.add_edge(a, b, 1.0).unwrap();
        }
        let hops = HopDistances::from_map(&builder.build().unwrap());
        assert_eq!(hops.place_count(), 6);
        assert_eq!(hops.hops(0, 3), Some(2));
        assert_eq!(hops.hops(1, 3), Some(2));
        assert_eq!(hops.hops(4, 0), Some(1));
        assert_eq!(hops.hops(0, 5), None);
    }
}
