//! The graph as the motion model sees it: *headings*, i.e. directed edges. Heading h means
//! "at place `from[h]`, facing neighbour `to[h]`"; a place without neighbours has one heading
//! facing itself. Advancing along h arrives at `to[h]` and continues on one of its headings that
//! does not turn back (a U-turn only at a dead end).

use crate::map::Map;

/// Directed edges of a map with their continuations, in compressed-row form.
#[derive(Clone)]
pub(crate) struct Headings {
    /// Place the heading starts from.
    pub from: Vec<u32>,
    /// Place the heading faces (== `from` for an isolated place).
    pub to: Vec<u32>,
    /// Edge length in metres, when both places have positions.
    pub length: Vec<Option<f64>>,
    /// Headings of place p are `place_offsets[p]..place_offsets[p + 1]`.
    pub place_offsets: Vec<u32>,
    /// Continuations of heading h are `next_ids[next_offsets[h]..next_offsets[h + 1]]`, with the
    /// share of advancing belief each receives in `next_shares` (edge weights, normalised).
    pub next_offsets: Vec<u32>,
    pub next_ids: Vec<u32>,
    pub next_shares: Vec<f64>,
}

impl Headings {
    pub fn new(map: &Map) -> Self {
        let m = map.place_count();
        let positions = map.place_positions();
        let (mut from, mut to, mut length, mut weight) =
            (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut place_offsets = Vec::with_capacity(m + 1);
        place_offsets.push(0u32);
        for p in 0..m as u32 {
            let (ids, weights) = map.neighbours(p).expect("place in range");
            let targets: Vec<(u32, f32)> = if ids.is_empty() {
                vec![(p, 1.0)]
            } else {
                ids.iter().copied().zip(weights.iter().copied()).collect()
            };
            for (q, w) in targets {
                from.push(p);
                to.push(q);
                weight.push(f64::from(w));
                length.push(match (positions[p as usize], positions[q as usize]) {
                    (Some(a), Some(b)) if p != q => Some((b - a).norm()),
                    _ => None,
                });
            }
            place_offsets.push(from.len() as u32);
        }
        let heading_of = |p: u32, q: u32| -> u32 {
            let range = place_offsets[p as usize]..place_offsets[p as usize + 1];
            range
                .clone()
                .find(|&h| to[h as usize] == q)
                .expect("heading exists for every neighbour")
        };
        let mut next_offsets = Vec::with_capacity(from.len() + 1);
        let (mut next_ids, mut next_shares) = (Vec::new(), Vec::new());
        next_offsets.push(0u32);
        for h in 0..from.len() {
            let (a, b) = (from[h], to[h]);
            let start = next_ids.len();
            if a == b {
                next_ids.push(h as u32);
            } else {
                let range = place_offsets[b as usize]..place_offsets[b as usize + 1];
                next_ids.extend(range.filter(|&g| to[g as usize] != a));
                if next_ids.len() == start {
                    next_ids.push(heading_of(b, a)); // dead end: turn back
                }
            }
            let total: f64 = next_ids[start..].iter().map(|&g| weight[g as usize]).sum();
            next_shares.extend(
                next_ids[start..]
                    .iter()
                    .map(|&g| weight[g as usize] / total),
            );
            next_offsets.push(next_ids.len() as u32);
        }
        Self {
            from,
            to,
            length,
            place_offsets,
            next_offsets,
            next_ids,
            next_shares,
        }
    }

    /// Number of headings.
    pub fn len(&self) -> usize {
        self.from.len()
    }

    /// Number of headings of place p.
    pub fn degree(&self, p: usize) -> usize {
        (self.place_offsets[p + 1] - self.place_offsets[p]) as usize
    }

    /// Continuations of heading h and their shares.
    pub fn next(&self, h: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let range = self.next_offsets[h] as usize..self.next_offsets[h + 1] as usize;
        self.next_ids[range.clone()]
            .iter()
            .map(|&g| g as usize)
            .zip(self.next_shares[range].iter().copied())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::descriptor::DescriptorIdentity;
    use crate::map::MapBuilder;

    /// T-junction: 0 - 1 - 2, and 1 - 3; plus an isolated place 4.
    fn t_junction() -> Map {
        let mut b = MapBuilder::new(DescriptorIdentity::new("t", "", 2).unwrap());
        for _ in 0..5 {
            let p = b.add_place(None).unwrap();
            b.add_view(p, &[1.0, 0.0], Default::default()).unwrap();
        }
        b.add_edge(0, 1, 1.0).unwrap();
        b.add_edge(1, 2, 1.0).unwrap();
        b.add_edge(1, 3, 3.0).unwrap();
        b.build().unwrap()
    }

    #[test]
    fn continuations_go_on_without_turning_back() {
        let headings = Headings::new(&t_junction());
        assert_eq!(headings.len(), 7); // 0->1, 1->0, 1->2, 1->3, 2->1, 3->1, 4->4
        let find = |a: u32, b: u32| {
            (0..headings.len())
                .find(|&h| headings.from[h] == a && headings.to[h] == b)
                .unwrap()
        };
        let next = |a, b| -> Vec<(u32, u32, f64)> {
            headings
                .next(find(a, b))
                .map(|(g, share)| (headings.from[g], headings.to[g], share))
                .collect()
        };
        // Arriving at the junction from 0: on to 2 or 3, by edge weight (1 : 3).
        assert_eq!(next(0, 1), vec![(1, 2, 0.25), (1, 3, 0.75)]);
        // Dead end at 2: the only way on is back.
        assert_eq!(next(1, 2), vec![(2, 1, 1.0)]);
        // Isolated place: stays.
        assert_eq!(next(4, 4), vec![(4, 4, 1.0)]);
        assert_eq!((headings.degree(1), headings.degree(4)), (3, 1));
    }
}
