//! What a localizer is asked to do: its [`Mode`] and [`LocalizerOptions`], validated into the
//! graph filter's parameters.

use super::filter::FilterParams;
use super::grnn::GrnnOptions;
use super::particles::MetricOptions;
use super::LocalizeError;
use crate::bounds::Bounds;
use crate::descriptor::ExpectedDescriptor;
use crate::verify::VerificationOptions;

/// Whether frames are filtered over time or judged one by one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Mode {
    /// Forward filter over the graph (default).
    #[default]
    Filter,
    /// Every frame on its own, from the same prior; for comparison and for unordered queries.
    SingleFrame,
    /// Monte Carlo localization of the camera pose in the map frame, moved by the full
    /// odometry and weighed by appearance (see `particles.rs`); the place is the one nearest
    /// to the particles. Needs a map with place positions and view poses.
    Metric,
    /// The seed's learned graph recurrent network (GRNN), run through ONNX Runtime on a window
    /// of the map's views each frame (see `grnn/`); the place posterior is the network's.
    /// Needs ONNX Runtime (`scripts/setup-models.sh`) and a map with edges; the model is
    /// [`LocalizerOptions::grnn`]'s. Odometry is not used.
    Grnn,
}

/// Localizer parameters. `temperature` and `off_map_margin` were chosen with `topoloc sweep`
/// on generated worlds held out from the demo (table in BENCHMARKS.md); the same temperature
/// serves MobileNetV2 multi-level and VLAD descriptors on real images (BENCHMARKS.md).
#[derive(Clone, Debug, PartialEq)]
pub struct LocalizerOptions {
    /// Filter or single-frame.
    pub mode: Mode,
    /// Softmax temperature turning similarities into likelihoods for the motion belief; smaller
    /// trusts each frame's appearance more, larger lets evidence accumulate along the route.
    /// Default 0.2 (best OHA, then R@100P, on held-out generated worlds; BENCHMARKS.md).
    /// Scaling it with the map's similarity spread was measured and is worse on real images.
    pub temperature: f32,
    /// Probability that the off-map state persists from one frame to the next. Default 0.7.
    pub stay_probability: f32,
    /// Probability of a jump to any place (kidnapping, relocalization). Default 0.01.
    pub jump_probability: f32,
    /// Probability of entering the off-map state per frame. Default 0.01; 0 disables off-map.
    pub off_map_probability: f32,
    /// Absolute floor of the off-map hypothesis' score: frames whose best place scores below it
    /// (for long enough) are reported off-map. Default 0.2. This and the next two shape the
    /// appearance evidence, which verification's inliers replace when it runs with an off-map
    /// threshold ([`crate::verify::VerificationOptions::off_map_inliers`]).
    pub off_map_similarity: f32,
    /// How many standard deviations above the expected best background score a place must
    /// score to beat the off-map hypothesis (see `filter.rs`; negative values lower the bar,
    /// since neighbouring places make the background scores correlated). Default -1.0.
    pub off_map_margin: f32,
    /// Temperature of the on-map vs off-map decision (see `filter.rs`). Default 0.03.
    pub off_map_temperature: f32,
    /// Candidates reported per frame. Default 5.
    pub top_k: usize,
    /// Refuse maps built with another descriptor than this one.
    pub expected: ExpectedDescriptor,
    /// Speed classes of the motion model: the chance of advancing one edge per frame, each in
    /// [0, 1], at most [`MAX_SPEED_CLASSES`]. Default 1, 0.5, 0.2, 0.05, 0 (from a camera that
    /// advances a place every frame to a standing one). Odometry, when given, sets the advance.
    pub speeds: Vec<f32>,
    /// Per-frame probability of moving to a neighbouring speed class. Default 0.05.
    pub speed_change_probability: f32,
    /// Per-frame probability of turning to another heading at the same place. Default 0.02.
    pub turn_probability: f32,
    /// Geometric verification of the most probable places against the query image (off by
    /// default; needs frames with images and a map storing keypoints).
    pub verification: VerificationOptions,
    /// Parameters of [`Mode::Metric`] (ignored in the other modes).
    pub metric: MetricOptions,
    /// The network of [`Mode::Grnn`] (ignored in the other modes).
    pub grnn: GrnnOptions,
}

/// Most speed classes the motion model accepts.
pub const MAX_SPEED_CLASSES: usize = 8;

impl Default for LocalizerOptions {
    fn default() -> Self {
        Self {
            mode: Mode::Filter,
            temperature: 0.2,
            stay_probability: 0.7,
            jump_probability: 0.01,
            off_map_probability: 0.01,
            off_map_similarity: 0.2,
            off_map_margin: -1.0,
            off_map_temperature: 0.03,
            top_k: 5,
            expected: ExpectedDescriptor::default(),
            speeds: vec![1.0, 0.5, 0.2, 0.05, 0.0],
            speed_change_probability: 0.05,
            turn_probability: 0.02,
            verification: VerificationOptions::default(),
            metric: MetricOptions::default(),
            grnn: GrnnOptions::default(),
        }
    }
}

impl LocalizerOptions {
    /// Accepted values of [`Self::temperature`] and [`Self::off_map_temperature`].
    pub const TEMPERATURE_RANGE: Bounds = Bounds::above(0.0);
    /// Accepted values of every probability: [`Self::stay_probability`],
    /// [`Self::jump_probability`], [`Self::off_map_probability`], the [`Self::speeds`],
    /// [`Self::speed_change_probability`] and [`Self::turn_probability`].
    pub const PROBABILITY_RANGE: Bounds = Bounds::closed(0.0, 1.0);
    /// Accepted values of [`Self::off_map_similarity`] (a cosine).
    pub const OFF_MAP_SIMILARITY_RANGE: Bounds = Bounds::closed(-1.0, 1.0);
    /// Accepted values of [`Self::off_map_margin`].
    pub const OFF_MAP_MARGIN_RANGE: Bounds = Bounds::finite();
    /// Accepted values of [`Self::top_k`].
    pub const TOP_K_RANGE: Bounds = Bounds::whole_at_least(1);

    /// Checks every field's own range, then the rules that join fields.
    fn check_ranges(&self) -> Result<(), String> {
        Self::TEMPERATURE_RANGE.check("temperature", self.temperature)?;
        Self::TEMPERATURE_RANGE.check("off_map_temperature", self.off_map_temperature)?;
        for (name, p) in [
            ("stay_probability", self.stay_probability),
            ("jump_probability", self.jump_probability),
            ("off_map_probability", self.off_map_probability),
            ("speed_change_probability", self.speed_change_probability),
            ("turn_probability", self.turn_probability),
        ] {
            Self::PROBABILITY_RANGE.check(name, p)?;
        }
        if self.jump_probability + self.off_map_probability >= 1.0 {
            return Err("jump_probability + off_map_probability must be below 1".into());
        }
        Self::OFF_MAP_SIMILARITY_RANGE.check("off_map_similarity", self.off_map_similarity)?;
        Self::OFF_MAP_MARGIN_RANGE.check("off_map_margin", self.off_map_margin)?;
        if self.speeds.is_empty() || self.speeds.len() > MAX_SPEED_CLASSES {
            return Err(format!(
                "speeds holds {} values, must hold 1 to {MAX_SPEED_CLASSES}",
                self.speeds.len()
            ));
        }
        for &speed in &self.speeds {
            Self::PROBABILITY_RANGE.check("speeds value", speed)?;
        }
        Self::TOP_K_RANGE.check("top_k", self.top_k)
    }

    pub(super) fn filter_params(&self) -> Result<FilterParams, LocalizeError> {
        self.check_ranges().map_err(LocalizeError::InvalidOption)?;
        self.verification
            .validate()
            .map_err(LocalizeError::InvalidOption)?;
        self.metric
            .validate()
            .map_err(LocalizeError::InvalidOption)?;
        Ok(FilterParams {
            temperature: f64::from(self.temperature),
            stay_probability: f64::from(self.stay_probability),
            jump_probability: f64::from(self.jump_probability),
            off_map_probability: f64::from(self.off_map_probability),
            off_map_similarity: f64::from(self.off_map_similarity),
            off_map_margin: f64::from(self.off_map_margin),
            off_map_temperature: f64::from(self.off_map_temperature),
            speeds: self.speeds.iter().map(|&v| f64::from(v)).collect(),
            speed_change_probability: f64::from(self.speed_change_probability),
            turn_probability: f64::from(self.turn_probability),
        })
    }
}
