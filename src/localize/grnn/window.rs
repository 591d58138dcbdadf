//! The micro-node graph of a map and the window of it the network runs on each frame, as
//! `python/train/window.py` chooses it (the model was trained on exactly these windows).
//!
//! Micro nodes are the map's views. Micro edges join every two views of one place, and the views
//! of the same slot (index among the place's views, in id order) of two places joined by an edge.
//! A frame's window holds the [`APPEARANCE`] places whose best view is most similar to the
//! frame, the [`CARRIED`] most probable places of the previous frame and the graph neighbours of
//! the previous most probable place; its nodes are those places' views in ascending id order,
//! its edges the micro edges between them.

use crate::map::Map;

/// Places chosen by appearance per frame.
pub(crate) const APPEARANCE: usize = 24;
/// Most probable places of the previous frame kept in the window.
pub(crate) const CARRIED: usize = 8;

/// The directed micro edges of a map, grouped by source view (compressed rows).
pub(super) struct MicroGraph {
    /// `targets[offsets[v]..offsets[v + 1]]` are the views view `v` sends messages to.
    offsets: Vec<u32>,
    targets: Vec<u32>,
}

impl MicroGraph {
    /// The micro graph of `map` (the rule in the module's doc).
    pub fn new(map: &Map) -> Self {
        let mut lists: Vec<Vec<u32>> = vec![Vec::new(); map.view_count()];
        let views_of = |place: usize| map.place_views_unchecked(place);
        for place in 0..map.place_count() {
            let views = views_of(place);
            for &v in views.iter() {
                lists[v as usize].extend(views.iter().copied().filter(|&w| w != v));
            }
        }
        for edge in map.edges() {
            let (a, b) = (views_of(edge.a as usize), views_of(edge.b as usize));
            for (&v, &w) in a.iter().zip(b.iter()) {
                lists[v as usize].push(w);
                lists[w as usize].push(v);
            }
        }
        let mut offsets = Vec::with_capacity(lists.len() + 1);
        offsets.push(0u32);
        let mut targets = Vec::with_capacity(lists.iter().map(Vec::len).sum());
        for list in lists {
            targets.extend(list);
            offsets.push(targets.len() as u32);
        }
        Self { offsets, targets }
    }

    /// The views `view` sends messages to.
    pub fn targets(&self, view: u32) -> &[u32] {
        let v = view as usize;
        &self.targets[self.offsets[v] as usize..self.offsets[v + 1] as usize]
    }
}

/// The most nodes a window of `map` can hold: the views of the `APPEARANCE + CARRIED + the
/// largest degree + 1` places with the most views.
pub(super) fn largest_window(map: &Map) -> usize {
    let degree = (0..map.place_count())
        .map(|p| map.neighbours_unchecked(p).len())
        .max()
        .unwrap_or(0);
    let mut counts: Vec<usize> = (0..map.place_count())
        .map(|p| map.place_views_unchecked(p).len())
        .collect();
    counts.sort_unstable_by(|a, b| b.cmp(a));
    counts.iter().take(APPEARANCE + CARRIED + degree + 1).sum()
}

/// Buffers of the window choice, sized once for the map.
pub(super) struct WindowScratch {
    /// Place ids, partially sorted by similarity or probability.
    order: Vec<u32>,
    /// Whether each place is in the window being chosen (cleared after each choice).
    chosen: Vec<bool>,
    /// Window-local index of each view, `u32::MAX` outside the window (cleared after use).
    local: Vec<u32>,
    /// The chosen places.
    pub places: Vec<u32>,
    /// The window's views, ascending.
    pub views: Vec<u32>,
    /// Edge sources then targets, window-local (the `(2, M)` tensor's rows).
    pub edges: Vec<i64>,
    /// The previous window's places, sorted by probability.
    ranked: Vec<u32>,
    /// Edge targets, before they are appended to `edges`.
    targets: Vec<i64>,
}

impl WindowScratch {
    /// Buffers for `map`.
    pub fn new(map: &Map) -> Self {
        Self {
            order: (0..map.place_count() as u32).collect(),
            chosen: vec![false; map.place_count()],
            local: vec![u32::MAX; map.view_count()],
            places: Vec::new(),
            views: Vec::new(),
            edges: Vec::new(),
            ranked: Vec::new(),
            targets: Vec::new(),
        }
    }

    /// Chooses the window of a frame whose places' best similarities are `place_scores`, after
    /// a frame whose window held `previous_places` with posterior `previous` (over all places;
    /// `None` at a sequence's start). Fills `places`, `views` and `edges`.
    pub fn choose(
        &mut self,
        map: &Map,
        graph: &MicroGraph,
        place_scores: &[f32],
        previous: Option<(&[u32], &[f64])>,
    ) {
        self.places.clear();
        let by_score = |a: &u32, b: &u32| {
            place_scores[*b as usize]
                .total_cmp(&place_scores[*a as usize])
                .then(a.cmp(b))
        };
        let k = APPEARANCE.min(self.order.len());
        if k < self.order.len() {
            self.order.select_nth_unstable_by(k, by_score);
        }
        for i in 0..k {
            let place = self.order[i];
            self.add(place);
        }
        if let Some((window, posterior)) = previous.filter(|(w, _)| !w.is_empty()) {
            let mut ranked = std::mem::take(&mut self.ranked);
            ranked.clear();
            ranked.extend_from_slice(window);
            ranked.sort_unstable_by(|a, b| {
                posterior[*b as usize]
                    .total_cmp(&posterior[*a as usize])
                    .then(a.cmp(b))
            });
            for &place in ranked.iter().take(CARRIED) {
                self.add(place);
            }
            for &place in map.neighbours_unchecked(ranked[0] as usize) {
                self.add(place);
            }
            self.ranked = ranked;
        }
        self.views.clear();
        for &place in &self.places {
            self.chosen[place as usize] = false;
            self.views
                .extend_from_slice(map.place_views_unchecked(place as usize));
        }
        self.views.sort_unstable();
        for (i, &v) in self.views.iter().enumerate() {
            self.local[v as usize] = i as u32;
        }
        self.edges.clear();
        self.targets.clear();
        for (i, &v) in self.views.iter().enumerate() {
            for &w in graph.targets(v) {
                let j = self.local[w as usize];
                if j != u32::MAX {
                    self.edges.push(i as i64);
                    self.targets.push(i64::from(j));
                }
            }
        }
        self.edges.extend_from_slice(&self.targets);
        for &v in &self.views {
            self.local[v as usize] = u32::MAX;
        }
    }

    fn add(&mut self, place: u32) {
        if !std::mem::replace(&mut self.chosen[place as usize], true) {
            self.places.push(place);
        }
    }
}
