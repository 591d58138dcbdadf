//! The learned estimator of [`Mode::Grnn`](super::Mode::Grnn): the seed's graph recurrent
//! network (thesis §4.4.2.2-3), trained by `python/train/` and run per frame through ONNX
//! Runtime on a window of the map's micro graph (`window.rs`). The recurrent state of each
//! window node is kept between frames; a node entering the window starts from zeros. The place
//! posterior is the softmax over the window's nodes summed per place (zero outside the window).

mod model;
mod window;

use crate::errors::VisionError;
use crate::map::Map;
use model::{Network, StepInput, StepOutput};
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use window::{largest_window, MicroGraph, WindowScratch};

/// Where [`Mode::Grnn`](super::Mode::Grnn) finds its network.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GrnnOptions {
    /// The ONNX model (written by `python/train/export.py`); `None` = the model built into the
    /// library.
    pub model: Option<PathBuf>,
    /// The ONNX Runtime library; `None` = `TOPOLOC_ORT_LIBRARY`, `ORT_DYLIB_PATH`, then the
    /// cache `scripts/setup-models.sh` fills.
    pub runtime: Option<PathBuf>,
    /// The seed's ablation "GRNN without temporal module": every frame starts the window's
    /// recurrent state from zeros instead of carrying it (the window's choice still follows the
    /// last posterior). `false` (the default) carries it; for benchmarks, not for hosts.
    pub forget_state: bool,
}

/// Why the learned estimator cannot be created or run.
#[derive(Debug, thiserror::Error)]
pub enum GrnnError {
    /// The runtime library or the model file is missing (the paths tried and a hint).
    #[error(transparent)]
    Unavailable(VisionError),
    /// The model file is not an ONNX model ONNX Runtime can load.
    #[error("the GRNN model is not a loadable ONNX model: {0}")]
    NotOnnx(String),
    /// The model's inputs, outputs or metadata do not match the contract (`model.rs`).
    #[error("the GRNN model does not match topoloc's contract: {0}")]
    Contract(String),
    /// The map's largest window has more nodes than the model accepts.
    #[error("the map's windows reach {nodes} micro nodes, the GRNN model accepts at most {limit}")]
    GraphTooLarge {
        /// Nodes of the map's largest possible window.
        nodes: usize,
        /// The model's limit.
        limit: usize,
    },
    /// The map has no edges between places: the network's messages need a graph.
    #[error("the map has no graph: {0}")]
    NoGraph(String),
    /// ONNX Runtime failed on a frame.
    #[error("running the GRNN model failed: {0}")]
    Run(String),
}

/// The session, the map's micro graph and the per-frame buffers: shared by the clones of one
/// estimator (the localizer's state and verification's backup), used by one frame at a time.
struct Shared {
    network: Network,
    graph: MicroGraph,
    window: WindowScratch,
    nodes: Vec<f32>,
    input_state: Vec<f32>,
    output: StepOutput,
}

/// The learned estimator's state: the window of the last frame, its nodes' recurrent state and
/// the place posterior.
#[derive(Clone)]
pub(super) struct Grnn {
    shared: Arc<Mutex<Shared>>,
    /// [`GrnnOptions::forget_state`].
    forget_state: bool,
    /// The last window's views, ascending.
    views: Vec<u32>,
    /// The last window's places.
    window_places: Vec<u32>,
    /// The recurrent state, `views.len() x S` row-major.
    state: Vec<f32>,
    /// Posterior over every place (zero outside the last window; uniform before a frame).
    pub places: Vec<f64>,
}

impl Grnn {
    /// Loads the network and prepares `map`'s micro graph. Fails on a map without edges, a
    /// model that does not match the contract, or a map whose windows exceed the model's limit.
    pub fn new(map: &Map, options: &GrnnOptions) -> Result<Self, GrnnError> {
        if map.edge_count() == 0 {
            return Err(GrnnError::NoGraph(format!(
                "{} places and no edges; build the map with a graph (the skeleton, or edges added by the builder)",
                map.place_count()
            )));
        }
        let network = Network::load(
            options.model.as_deref(),
            options.runtime.as_deref(),
            map.dim(),
        )?;
        let nodes = largest_window(map);
        if let Some(limit) = network.max_nodes.filter(|&limit| nodes > limit) {
            return Err(GrnnError::GraphTooLarge { nodes, limit });
        }
        let shared = Shared {
            network,
            graph: MicroGraph::new(map),
            window: WindowScratch::new(map),
            nodes: Vec::new(),
            input_state: Vec::new(),
            output: StepOutput::default(),
        };
        let mut grnn = Self {
            shared: Arc::new(Mutex::new(shared)),
            forget_state: options.forget_state,
            views: Vec::new(),
            window_places: Vec::new(),
            state: Vec::new(),
            places: vec![0.0; map.place_count()],
        };
        grnn.set_initial();
        Ok(grnn)
    }

    /// Back to the state before a sequence's first frame.
    pub fn set_initial(&mut self) {
        self.views.clear();
        self.window_places.clear();
        self.state.clear();
        let uniform = 1.0 / self.places.len().max(1) as f64;
        self.places.fill(uniform);
    }

    /// One frame: `query` its unit descriptor, `view_scores` / `place_scores` its similarity to
    /// every view / each place's best view; `continued` false starts a new sequence. On error
    /// the state is unchanged.
    pub fn step(
        &mut self,
        map: &Map,
        continued: bool,
        query: &[f32],
        view_scores: &[f32],
        place_scores: &[f32],
    ) -> Result<(), GrnnError> {
        let mut guard = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        let shared = &mut *guard;
        let continued = continued && !self.views.is_empty();
        let previous = continued.then_some((self.window_places.as_slice(), self.places.as_slice()));
        shared
            .window
            .choose(map, &shared.graph, place_scores, previous);
        let window = &shared.window;
        let (d, s) = (map.dim(), shared.network.state_width);
        shared.nodes.clear();
        for &v in &window.views {
            shared
                .nodes
                .extend_from_slice(map.view_descriptor_unchecked(v as usize));
        }
        carry_state(
            &self.views,
            &self.state,
            &window.views,
            s,
            continued && !self.forget_state,
            &mut shared.input_state,
        );
        debug_assert_eq!(query.len(), d);
        let input = StepInput {
            nodes: &shared.nodes,
            edges: &window.edges,
            frame: query,
            state: &shared.input_state,
            stats: &statistics(view_scores),
        };
        shared.network.run(&input, &mut shared.output)?;
        let logits = &shared.output.logits;
        if logits.iter().any(|l| !l.is_finite()) {
            return Err(GrnnError::Run(
                "the model returned a non-finite logit".into(),
            ));
        }
        if self.views.is_empty() {
            self.places.fill(0.0);
        }
        for &place in &self.window_places {
            self.places[place as usize] = 0.0;
        }
        let top = logits.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        let total: f64 = logits.iter().map(|&l| f64::from(l - top).exp()).sum();
        for (&v, &l) in window.views.iter().zip(logits) {
            self.places[map.view_place_unchecked(v as usize)] += f64::from(l - top).exp() / total;
        }
        self.views.clone_from(&window.views);
        self.window_places.clone_from(&window.places);
        std::mem::swap(&mut self.state, &mut shared.output.new_state);
        Ok(())
    }

    /// Multiplies every place's probability by `factor(place)` (the geometric re-ranking) and
    /// renormalises; a factor that zeroes every place leaves the posterior as it was.
    pub fn weigh_places(&mut self, factor: impl Fn(usize) -> f64) {
        let mut total = 0.0;
        for &place in &self.window_places {
            let p = &mut self.places[place as usize];
            *p *= factor(place as usize);
            total += *p;
        }
        if total > 0.0 && total.is_finite() {
            for &place in &self.window_places {
                self.places[place as usize] /= total;
            }
        }
    }

    /// Copies the state into `backup` (an estimator on the same network) without allocating
    /// once the buffers have grown.
    pub fn save(&self, backup: &mut Grnn) {
        backup.shared = Arc::clone(&self.shared);
        backup.views.clone_from(&self.views);
        backup.window_places.clone_from(&self.window_places);
        backup.state.clone_from(&self.state);
        backup.places.clone_from(&self.places);
    }
}

/// The input state of the new window `views` (`views.len() x width`): rows of views that were in
/// the previous window `previous` (state `state`) copied, zeros elsewhere and at a sequence's
/// start. Both view lists are ascending.
fn carry_state(
    previous: &[u32],
    state: &[f32],
    views: &[u32],
    width: usize,
    continued: bool,
    out: &mut Vec<f32>,
) {
    out.clear();
    out.resize(views.len() * width, 0.0);
    if !continued {
        return;
    }
    let mut j = 0;
    for (i, &v) in views.iter().enumerate() {
        while j < previous.len() && previous[j] < v {
            j += 1;
        }
        if j < previous.len() && previous[j] == v {
            out[i * width..(i + 1) * width].copy_from_slice(&state[j * width..(j + 1) * width]);
        }
    }
}

/// `[max, mean, standard deviation]` of the frame's similarity to every view (the population
/// deviation, as `python/train/model.py::map_statistics`).
fn statistics(view_scores: &[f32]) -> [f32; 3] {
    let n = view_scores.len().max(1) as f64;
    let top = view_scores
        .iter()
        .copied()
        .fold(f32::NEG_INFINITY, f32::max);
    let mean = view_scores.iter().map(|&s| f64::from(s)).sum::<f64>() / n;
    let variance = view_scores
        .iter()
        .map(|&s| (f64::from(s) - mean).powi(2))
        .sum::<f64>()
        / n;
    [top, mean as f32, variance.sqrt() as f32]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn carried_state_keeps_rows_of_views_that_stay() {
        let mut out = Vec::new();
        let state = [1.0, 1.5, 2.0, 2.5, 3.0, 3.5];
        carry_state(&[2, 5, 9], &state, &[1, 5, 9, 12], 2, true, &mut out);
        assert_eq!(out, [0.0, 0.0, 2.0, 2.5, 3.0, 3.5, 0.0, 0.0]);
        carry_state(&[2, 5, 9], &state, &[1, 5, 9, 12], 2, false, &mut out);
        assert_eq!(out, [0.0; 8]);
    }

    #[test]
    fn statistics_match_the_population_formula() {
        let [top, mean, std] = statistics(&[0.1, 0.5, 0.3, -0.1]);
        assert!((top - 0.5).abs() < 1e-7);
        assert!((mean - 0.2).abs() < 1e-7);
        assert!((std - 0.05f32.sqrt()).abs() < 1e-6);
    }
}
