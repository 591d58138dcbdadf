//! Per-frame localization against a map: similarity of the query descriptor to every view,
//! place scores, and a forward filter over the graph (see [`filter`](self) docs in
//! `filter.rs`), giving the most probable place, a confidence, top-k candidates and an
//! off-map flag. [`Mode::Metric`] replaces the graph filter's place belief by a particle
//! filter over camera poses (`particles.rs`), on maps with positions and view poses; the
//! off-map state comes from the graph filter in every mode. Optionally the most probable places
//! are verified geometrically against the query image ([`crate::verify`]) and their belief
//! weighed by the inliers found; with the camera's intrinsics and a map storing keypoint scene
//! points, the best-verified view also gives a metric pose of the camera
//! ([`Localization::pose_fix`]), which metric mode uses to weigh its particles.

mod error;
mod filter;
mod motion;
mod particles;
mod similarity;

pub use error::{LocalizeError, TimestampError};
pub use particles::{MetricOptions, MAX_PARTICLES};

use crate::describe::{Describer, DescriberOptions};
use crate::descriptor::{normalize_descriptor_into, ExpectedDescriptor};
use crate::errors::VisionError;
use crate::image::ImageView;
use crate::map::{Map, MapError, PlaceId, ViewId};
use crate::verify::{check_pair, locate, KeypointDetector, Keypoints, VerificationOptions};
use filter::{Belief, FilterParams};
use nalgebra::{Isometry3, Point3};
use particles::Particles;
use std::sync::Arc;

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
    /// (for long enough) are reported off-map. Default 0.2.
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
        }
    }
}

impl LocalizerOptions {
    fn filter_params(&self) -> Result<FilterParams, LocalizeError> {
        let bad = |msg: &str| Err(LocalizeError::InvalidOption(msg.to_string()));
        let prob = |x: f32| x.is_finite() && (0.0..=1.0).contains(&x);
        if !(self.temperature.is_finite() && self.temperature > 0.0) {
            return bad("temperature must be finite and > 0");
        }
        if !(self.off_map_temperature.is_finite() && self.off_map_temperature > 0.0) {
            return bad("off_map_temperature must be finite and > 0");
        }
        if !prob(self.stay_probability) {
            return bad("stay_probability must lie in [0, 1]");
        }
        if !prob(self.jump_probability) || !prob(self.off_map_probability) {
            return bad("jump_probability and off_map_probability must lie in [0, 1]");
        }
        if self.jump_probability + self.off_map_probability >= 1.0 {
            return bad("jump_probability + off_map_probability must be below 1");
        }
        if !(self.off_map_similarity.is_finite() && (-1.0..=1.0).contains(&self.off_map_similarity))
        {
            return bad("off_map_similarity must lie in [-1, 1]");
        }
        if !self.off_map_margin.is_finite() {
            return bad("off_map_margin must be finite");
        }
        if self.speeds.is_empty()
            || self.speeds.len() > MAX_SPEED_CLASSES
            || !self.speeds.iter().all(|&v| prob(v))
        {
            return bad("speeds must hold 1 to 8 values in [0, 1]");
        }
        if !prob(self.speed_change_probability) || !prob(self.turn_probability) {
            return bad("speed_change_probability and turn_probability must lie in [0, 1]");
        }
        if self.top_k == 0 {
            return bad("top_k must be at least 1");
        }
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

/// One camera frame: a descriptor computed by the host, or an image the localizer describes.
#[derive(Clone, Debug, Default)]
pub struct Frame<'a> {
    /// Time in seconds; must not decrease in filter mode.
    pub timestamp: f64,
    /// Global descriptor of the frame (D values; normalised internally). When empty, `image` is
    /// described with the map's own backend; when given, it is used and `image` is not described.
    pub descriptor: &'a [f32],
    /// The camera image, described when `descriptor` is empty (needs a localizer made with
    /// [`Localizer::with_describer`]).
    pub image: Option<ImageView<'a>>,
    /// Motion since the previous frame, `previous_T_current`, from the host's odometry.
    pub odometry: Option<Isometry3<f64>>,
}

/// One ranked hypothesis.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Candidate {
    /// Place.
    pub place: PlaceId,
    /// Best-matching view of the place.
    pub view: ViewId,
    /// Posterior probability of the place.
    pub probability: f32,
    /// Cosine similarity of the query to `view`.
    pub similarity: f32,
    /// Whether the place was verified geometrically in this frame.
    pub verified: bool,
    /// Geometric inliers between the query and `view` (0 unless `verified`).
    pub inliers: u32,
}

/// A metric pose of the camera found against one map view (see [`crate::verify::locate`]):
/// what a pose graph adds as a loop-closure constraint.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoseFix {
    /// The view the camera was placed against.
    pub view: ViewId,
    /// The camera in the map frame, `world_T_optical` (optical axes: z forward, x right, y
    /// down).
    pub world_t_optical: Isometry3<f64>,
    /// Keypoint pairs consistent with the pose.
    pub inliers: u32,
}

/// The answer for one frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Localization {
    /// 0-based count of frames processed since creation or reset.
    pub frame_index: u64,
    /// Most probable place.
    pub place: PlaceId,
    /// Best-matching view of that place.
    pub view: ViewId,
    /// Posterior probability that the robot is at `place` (0..1): the place belief times the
    /// probability of being on the map.
    pub confidence: f32,
    /// Cosine similarity of the query to `view`.
    pub similarity: f32,
    /// True when the robot is more likely off the map than on it.
    pub off_map: bool,
    /// Posterior probability that the robot is off the map.
    pub off_map_probability: f32,
    /// Top-k places by posterior, best first; `candidates[0]` is `place`.
    pub candidates: Vec<Candidate>,
    /// The camera's metric pose against the best-verified view, when verification has a camera
    /// ([`VerificationOptions::camera`]), the map stores keypoint scene points and enough
    /// keypoints agree on one pose.
    pub pose_fix: Option<PoseFix>,
}

/// Localizes a stream of frames against one map.
///
/// Holds the filter state, so one localizer follows one camera; it is `Send` but not meant to
/// be shared between threads without a lock. Many localizers may share one `Arc<Map>`.
/// After construction, `process` allocates nothing.
pub struct Localizer {
    map: Arc<Map>,
    options: LocalizerOptions,
    params: FilterParams,
    belief: Belief,
    /// The particle cloud of [`Mode::Metric`].
    particles: Option<Particles>,
    initialized: bool,
    frames: u64,
    last_timestamp: Option<f64>,
    query: Vec<f32>,
    view_scores: Vec<f32>,
    place_scores: Vec<f32>,
    best_views: Vec<u32>,
    order: Vec<u32>,
    describer: Option<Describer>,
    described: Vec<f32>,
    verifier: Option<Verifier>,
}

/// State of geometric verification: the query detector, the per-place results of the current
/// frame, and a copy of the belief to restore if a check fails half-way.
struct Verifier {
    detector: KeypointDetector,
    query: Keypoints,
    /// Places checked in the current frame with their best inlier count and view.
    checked: Vec<(PlaceId, u32, ViewId)>,
    views: Vec<ViewId>,
    /// The pose fix of the current frame.
    fix: Option<PoseFix>,
    backup: Belief,
    particles_backup: Option<Particles>,
}

impl Localizer {
    /// Creates a localizer; fails on invalid options or when the map was built with another
    /// descriptor than `options.expected`.
    pub fn new(map: Arc<Map>, options: LocalizerOptions) -> Result<Self, LocalizeError> {
        let params = options.filter_params()?;
        map.descriptor()
            .check_compatible(&options.expected)
            .map_err(MapError::from)?;
        let (n, m) = (map.view_count(), map.place_count());
        let mut belief = Belief::new(&map, &params);
        belief.set_initial(&params);
        let particles = match options.mode {
            Mode::Metric => {
                Some(Particles::new(&map, &options.metric).map_err(LocalizeError::Metric)?)
            }
            _ => None,
        };
        let verifier = if options.verification.enabled() {
            if map.keypoints().is_none() {
                return Err(LocalizeError::Verification(
                    "verification is on but the map stores no keypoints (build it from images with keypoints > 0, or set verification.candidates to 0)".into(),
                ));
            }
            if options.verification.camera.is_some()
                && map.keypoints().and_then(|k| k.world_points()).is_none()
            {
                return Err(LocalizeError::Verification(
                    "verification.camera is set but the map stores no keypoint scene points (attach them with ViewKeypoints::with_world_points, or leave the camera unset)".into(),
                ));
            }
            Some(Verifier {
                detector: KeypointDetector::new(options.verification.query_keypoints)?,
                query: Keypoints::default(),
                checked: Vec::with_capacity(options.verification.candidates),
                views: Vec::new(),
                fix: None,
                backup: Belief::new(&map, &params),
                particles_backup: particles.clone(),
            })
        } else {
            None
        };
        Ok(Self {
            verifier,
            belief,
            particles,
            params,
            initialized: false,
            frames: 0,
            last_timestamp: None,
            query: Vec::with_capacity(map.dim()),
            view_scores: vec![0.0; n],
            place_scores: vec![0.0; m],
            best_views: vec![0; m],
            order: (0..m as u32).collect(),
            describer: None,
            described: Vec::with_capacity(map.dim()),
            options,
            map,
        })
    }

    /// Creates a localizer that also describes images, with the describer model stored in the
    /// map (maps built from images have one). Loads the backend now, so a missing runtime or
    /// model, or a backend or model file other than the map's, fails here with a typed error
    /// (`VisionError::BackendUnavailable`, `VisionError::Mismatch`).
    pub fn with_describer(
        map: Arc<Map>,
        options: LocalizerOptions,
        describer: &DescriberOptions,
    ) -> Result<Self, LocalizeError> {
        let model = map.describer().cloned().ok_or_else(|| {
            LocalizeError::NoDescriber(format!(
                "the map ({}) stores no describer; it was built from descriptors, not images",
                map.descriptor()
            ))
        })?;
        let describer = Describer::new(model, describer)?;
        let mut localizer = Self::new(map, options)?;
        localizer.describer = Some(describer);
        Ok(localizer)
    }

    /// True when the localizer can describe images.
    pub fn describes_images(&self) -> bool {
        self.describer.is_some()
    }

    /// The map this localizer reads.
    pub fn map(&self) -> &Arc<Map> {
        &self.map
    }

    /// The options it was created with.
    pub fn options(&self) -> &LocalizerOptions {
        &self.options
    }

    /// Similarity of the last processed frame to every view (empty before the first frame).
    pub fn last_view_similarities(&self) -> &[f32] {
        if self.frames == 0 {
            &[]
        } else {
            &self.view_scores
        }
    }

    /// Forgets all history: the next frame is treated as the first.
    pub fn reset(&mut self) {
        self.belief.set_initial(&self.params);
        if let Some(particles) = &mut self.particles {
            particles.set_initial();
        }
        self.initialized = false;
        self.frames = 0;
        self.last_timestamp = None;
    }

    /// Processes one frame and returns the result.
    pub fn localize(&mut self, frame: &Frame<'_>) -> Result<Localization, LocalizeError> {
        let mut out = Localization::default();
        self.process(frame, &mut out)?;
        Ok(out)
    }

    /// Processes one frame, writing into `out` (reusing its candidate buffer). Validates the
    /// whole frame before touching any state, so an error leaves the localizer unchanged.
    /// Cost: one pass over the descriptor matrix plus O(places + edges); in metric mode also
    /// O(particles x places) for the particles' nearest places; with verification on,
    /// also keypoint detection in the frame's image and one match + RANSAC per checked view,
    /// and with a camera one PnP fit (these allocate). Verification needs `frame.image` even when a descriptor is given.
    pub fn process(
        &mut self,
        frame: &Frame<'_>,
        out: &mut Localization,
    ) -> Result<(), LocalizeError> {
        let filtering = self.options.mode != Mode::SingleFrame;
        if !frame.timestamp.is_finite() {
            return Err(LocalizeError::Timestamp(TimestampError::NonFinite(
                frame.timestamp,
            )));
        }
        if let (true, Some(last)) = (filtering, self.last_timestamp) {
            if frame.timestamp < last {
                return Err(LocalizeError::Timestamp(TimestampError::Backwards {
                    timestamp: frame.timestamp,
                    previous: last,
                }));
            }
        }
        let travelled = match &frame.odometry {
            Some(pose) => {
                let t = pose.translation.vector;
                if !(t
                    .iter()
                    .chain(pose.rotation.coords.iter())
                    .all(|x| x.is_finite()))
                {
                    return Err(LocalizeError::Odometry(
                        "odometry has a non-finite value".into(),
                    ));
                }
                Some(t.norm())
            }
            None => None,
        };
        let descriptor: &[f32] = match (frame.descriptor.is_empty(), &frame.image) {
            (true, Some(image)) => {
                let describer = self.describer.as_mut().ok_or_else(|| {
                    LocalizeError::NoDescriber(
                        "the frame has an image but no descriptor, and this localizer has no describer (Rust: Localizer::with_describer; C: image_backend TOPOLOC_BACKEND_AUTO on a map built from images)".into(),
                    )
                })?;
                describer.describe(image, &mut self.described)?;
                &self.described
            }
            _ => frame.descriptor,
        };
        normalize_descriptor_into(descriptor, self.map.dim(), &mut self.query)?;
        if let Some(verifier) = &mut self.verifier {
            let image = frame.image.as_ref().ok_or_else(|| {
                VisionError::InvalidImage(
                    "verification is on: the frame needs its image (beside or instead of a descriptor)".into(),
                )
            })?;
            verifier.query = verifier.detector.detect(image)?;
        }

        similarity::view_similarities(&self.map, &self.query, &mut self.view_scores);
        similarity::pool_places(
            &self.map,
            &self.view_scores,
            &mut self.place_scores,
            &mut self.best_views,
        );
        if let Some(verifier) = &mut self.verifier {
            self.belief.save(&mut verifier.backup);
            if let (Some(particles), Some(backup)) =
                (&self.particles, &mut verifier.particles_backup)
            {
                particles.save(backup);
            }
        }
        if filtering && self.initialized {
            self.belief.predict(&self.params, travelled);
        } else {
            self.belief.set_initial(&self.params);
        }
        self.belief.update(&self.params, &self.place_scores);
        if let Some(particles) = &mut self.particles {
            if self.initialized {
                particles.predict(frame.odometry.as_ref());
            } else {
                particles.set_initial();
            }
            particles.update(&self.view_scores);
        }
        if let Err(e) = self.verify() {
            if let Some(verifier) = &self.verifier {
                self.belief.restore(&verifier.backup);
                if let (Some(particles), Some(backup)) =
                    (&mut self.particles, &verifier.particles_backup)
                {
                    particles.restore(backup);
                }
            }
            return Err(e);
        }
        self.initialized = true;
        self.last_timestamp = Some(frame.timestamp);
        out.frame_index = self.frames;
        self.frames += 1;
        self.write_result(out);
        Ok(())
    }

    /// Checks the most probable places against the query keypoints and weighs the belief by
    /// their inliers (see [`crate::verify`]); a checked place's best view becomes the one with
    /// the most inliers. Does nothing when verification is off.
    fn verify(&mut self) -> Result<(), LocalizeError> {
        let Some(verifier) = &mut self.verifier else {
            return Ok(());
        };
        let options = &self.options.verification;
        let keypoints = self.map.keypoints().expect("checked at construction");
        let m = self.map.place_count();
        let c = options.candidates.min(m);
        let places = place_belief(&self.particles, &self.belief);
        select_most_probable(&mut self.order, places, c, false);
        verifier.checked.clear();
        verifier.fix = None;
        for &place in &self.order[..c] {
            verifier.views.clear();
            verifier
                .views
                .extend_from_slice(self.map.place_views(place)?);
            let scores = &self.view_scores;
            verifier
                .views
                .sort_unstable_by(|a, b| scores[*b as usize].total_cmp(&scores[*a as usize]));
            let mut best = (0u32, self.best_views[place as usize]);
            for &view in verifier.views.iter().take(options.views_per_candidate) {
                let stored = keypoints
                    .view(view as usize)
                    .expect("one keypoint entry per view");
                let check = check_pair(verifier.query.as_ref(), stored, &options.pair)?;
                if check.inliers > best.0 {
                    best = (check.inliers, view);
                }
            }
            verifier.checked.push((place, best.0, best.1));
        }
        let most = verifier.checked.iter().map(|c| c.1).max().unwrap_or(0);
        let weight = f64::from(options.inlier_weight);
        // exp(weight * (inliers - most)) for checked places, exp(-weight * most) for the rest:
        // the same ratios as exp(weight * inliers) with unchecked places at 0, kept at most 1.
        let unchecked = (-weight * f64::from(most)).exp();
        let checked = &verifier.checked;
        let factor = |place| {
            checked
                .iter()
                .find(|c| c.0 as usize == place)
                .map_or(unchecked, |c| {
                    (weight * (f64::from(c.1) - f64::from(most))).exp()
                })
        };
        match &mut self.particles {
            Some(particles) => particles.weigh_places(factor),
            None => self.belief.weigh_places(&self.params, factor),
        }
        for &(place, inliers, view) in checked {
            if inliers > 0 {
                self.best_views[place as usize] = view;
            }
        }
        let best = checked.iter().max_by_key(|c| (c.1, std::cmp::Reverse(c.0)));
        if let (Some(camera), Some(&(_, inliers, view))) = (&options.camera, best) {
            if inliers >= options.locate.min_inliers {
                let stored = keypoints.view(view as usize).expect("view in range");
                let scene = keypoints
                    .view_world_points(view as usize)
                    .expect("checked at construction");
                let found = locate(
                    verifier.query.as_ref(),
                    stored,
                    scene,
                    camera,
                    options.pair.max_hamming,
                    &options.locate,
                )?;
                verifier.fix = found.map(|f| PoseFix {
                    view,
                    world_t_optical: f.world_t_optical,
                    inliers: f.inliers,
                });
            }
        }
        if let (Some(particles), Some(fix)) = (&mut self.particles, &verifier.fix) {
            particles.weigh_by_position(&Point3::from(fix.world_t_optical.translation.vector));
        }
        Ok(())
    }

    fn write_result(&mut self, out: &mut Localization) {
        let m = self.map.place_count();
        let p = place_belief(&self.particles, &self.belief);
        let on_map = 1.0 - self.belief.off_map;
        let k = self.options.top_k.min(m);
        select_most_probable(&mut self.order, p, k, true);
        out.candidates.clear();
        out.candidates.extend(self.order[..k].iter().map(|&place| {
            let view = self.best_views[place as usize];
            let check = self
                .verifier
                .as_ref()
                .and_then(|v| v.checked.iter().find(|c| c.0 == place));
            Candidate {
                place,
                view,
                probability: (p[place as usize] * on_map) as f32,
                similarity: self.view_scores[view as usize],
                verified: check.is_some(),
                inliers: check.map_or(0, |c| c.1),
            }
        }));
        let best = out.candidates[0];
        out.place = best.place;
        out.view = best.view;
        out.confidence = best.probability;
        out.similarity = best.similarity;
        out.off_map_probability = self.belief.off_map as f32;
        out.off_map = self.belief.off_map > 0.5;
        out.pose_fix = self.verifier.as_ref().and_then(|v| v.fix);
    }
}

/// The posterior over places given that the robot is on the map: the particle cloud's in
/// metric mode, else the graph filter's. (A free function, so that callers may borrow other
/// fields of the localizer mutably meanwhile.)
fn place_belief<'a>(particles: &'a Option<Particles>, belief: &'a Belief) -> &'a [f64] {
    particles.as_ref().map_or(&belief.places, |p| &p.places)
}

/// Moves the `k` (>= 1) most probable places of `order` (place ids) to its front, ties broken by
/// the lower id; sorts them best first when `sorted`.
fn select_most_probable(order: &mut [u32], probability: &[f64], k: usize, sorted: bool) {
    let by_probability = |a: &u32, b: &u32| {
        probability[*b as usize]
            .total_cmp(&probability[*a as usize])
            .then(a.cmp(b))
    };
    if k < order.len() {
        order.select_nth_unstable_by(k - 1, by_probability);
    }
    if sorted {
        order[..k].sort_unstable_by(by_probability);
    }
}
