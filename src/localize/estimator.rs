//! The state a localizer estimates, stated once per mode: the graph filter alone; or the
//! particle cloud of metric mode, or the learned network's posterior (whose place posterior
//! wins), beside the graph filter, which still decides on-map vs off-map there.

use super::filter::{Belief, FilterParams};
use super::grnn::{Grnn, GrnnOptions};
use super::options::Mode;
use super::particles::{MetricOptions, Particles};
use super::LocalizeError;
use crate::map::Map;
use nalgebra::{Isometry3, Point3};

/// The belief of one localizer.
#[derive(Clone)]
pub(super) enum Estimator {
    /// [`Mode::Filter`] and [`Mode::SingleFrame`]: the graph filter gives the place posterior
    /// and the off-map probability.
    Graph(Belief),
    /// [`Mode::Metric`]: the particles give the place posterior; the graph filter runs beside
    /// them for the off-map probability only.
    Metric {
        /// The cloud over camera poses (boxed: far larger than the graph filter's handles).
        particles: Box<Particles>,
        /// The graph filter, read for `off_map` only.
        graph: Belief,
    },
    /// [`Mode::Grnn`]: the learned network gives the place posterior; the graph filter runs
    /// beside it for the off-map probability only.
    Learned {
        /// The network's state (boxed: its buffers are far larger than the filter's handles).
        grnn: Box<Grnn>,
        /// The graph filter, read for `off_map` only.
        graph: Belief,
    },
}

impl Estimator {
    /// The estimator `mode` asks for, at its initial state.
    pub fn new(
        map: &Map,
        mode: Mode,
        params: &FilterParams,
        metric: &MetricOptions,
        learned: &GrnnOptions,
    ) -> Result<Self, LocalizeError> {
        let mut graph = Belief::new(map, params);
        graph.set_initial(params);
        Ok(match mode {
            Mode::Filter | Mode::SingleFrame => Estimator::Graph(graph),
            Mode::Metric => Estimator::Metric {
                particles: Box::new(Particles::new(map, metric).map_err(LocalizeError::Metric)?),
                graph,
            },
            Mode::Grnn => Estimator::Learned {
                grnn: Box::new(Grnn::new(map, learned)?),
                graph,
            },
        })
    }

    fn graph(&self) -> &Belief {
        match self {
            Estimator::Graph(graph)
            | Estimator::Metric { graph, .. }
            | Estimator::Learned { graph, .. } => graph,
        }
    }

    /// The posterior over places given that the robot is on the map.
    pub fn places(&self) -> &[f64] {
        match self {
            Estimator::Graph(graph) => &graph.places,
            Estimator::Metric { particles, .. } => &particles.places,
            Estimator::Learned { grnn, .. } => &grnn.places,
        }
    }

    /// The posterior probability that the robot is off the map (from the graph filter).
    pub fn off_map(&self) -> f64 {
        self.graph().off_map
    }

    /// Back to the state before the first frame.
    pub fn set_initial(&mut self, params: &FilterParams) {
        match self {
            Estimator::Graph(graph) => graph.set_initial(params),
            Estimator::Metric { particles, graph } => {
                graph.set_initial(params);
                particles.set_initial();
            }
            Estimator::Learned { grnn, graph } => {
                graph.set_initial(params);
                grnn.set_initial();
            }
        }
    }

    /// One frame's prediction and appearance update. `continued` is false for the first frame
    /// (or every frame in single-frame mode), which starts from the initial state instead of
    /// moving the previous one; `travelled` is the odometry distance, `odometry` the full motion.
    /// `query` is the frame's unit descriptor. Only the learned network can fail, and it runs
    /// first, so an error leaves every part of the state unchanged.
    pub fn step(
        &mut self,
        map: &Map,
        params: &FilterParams,
        continued: bool,
        odometry: Option<&Isometry3<f64>>,
        scores: Scores<'_>,
    ) -> Result<(), LocalizeError> {
        let travelled = odometry.map(|pose| pose.translation.vector.norm());
        let (graph, particles) = match self {
            Estimator::Graph(graph) => (graph, None),
            Estimator::Metric { particles, graph } => (graph, Some(particles)),
            Estimator::Learned { grnn, graph } => {
                grnn.step(map, continued, scores.query, scores.views, scores.places)?;
                (graph, None)
            }
        };
        if continued {
            graph.predict(params, travelled);
        } else {
            graph.set_initial(params);
        }
        graph.update(params, scores.places);
        if let Some(particles) = particles {
            if continued {
                particles.predict(odometry);
            } else {
                particles.set_initial();
            }
            particles.update(scores.views);
        }
        Ok(())
    }

    /// Multiplies the belief of every place by `factor(place)` (verification); in metric mode
    /// the particles are weighed, the graph filter is left as it is.
    pub fn weigh_places(&mut self, params: &FilterParams, factor: impl Fn(usize) -> f64) {
        match self {
            Estimator::Graph(graph) => graph.weigh_places(params, factor),
            Estimator::Metric { particles, .. } => particles.weigh_places(factor),
            Estimator::Learned { grnn, .. } => grnn.weigh_places(factor),
        }
    }

    /// Redoes the current frame's off-map update with the likelihood ratio `off_over_on` (see
    /// [`Belief::replace_off_map_evidence`]); every mode's off-map state is the graph filter's.
    pub fn replace_off_map_evidence(&mut self, off_over_on: f64) {
        match self {
            Estimator::Graph(graph)
            | Estimator::Metric { graph, .. }
            | Estimator::Learned { graph, .. } => graph.replace_off_map_evidence(off_over_on),
        }
    }

    /// Weighs the particles by a metric position of the camera (a pose fix); the graph filter
    /// has no positions to weigh.
    pub fn weigh_by_position(&mut self, position: &Point3<f64>) {
        if let Estimator::Metric { particles, .. } = self {
            particles.weigh_by_position(position);
        }
    }

    /// Copies the state into `backup` (of the same mode) without allocating.
    pub fn save(&self, backup: &mut Estimator) {
        match (self, backup) {
            (Estimator::Graph(graph), Estimator::Graph(to)) => graph.save(to),
            (
                Estimator::Metric { particles, graph },
                Estimator::Metric {
                    particles: to_particles,
                    graph: to_graph,
                },
            ) => {
                graph.save(to_graph);
                particles.save(to_particles);
            }
            (
                Estimator::Learned { grnn, graph },
                Estimator::Learned {
                    grnn: to_grnn,
                    graph: to_graph,
                },
            ) => {
                graph.save(to_graph);
                grnn.save(to_grnn);
            }
            (_, backup) => *backup = self.clone(),
        }
    }

    /// Restores the state saved by [`Estimator::save`].
    pub fn restore(&mut self, backup: &Estimator) {
        backup.save(self);
    }
}

/// One frame's similarities, as the estimators read them.
#[derive(Clone, Copy)]
pub(super) struct Scores<'a> {
    /// The frame's unit-norm descriptor.
    pub query: &'a [f32],
    /// Its cosine to every view.
    pub views: &'a [f32],
    /// Each place's best view's cosine.
    pub places: &'a [f32],
}
