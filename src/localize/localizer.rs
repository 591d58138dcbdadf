//! The [`Localizer`]: one camera's frames through the stages of the data flow (validate,
//! describe, score, update, verify, report), each a method below.

use super::estimator::{Estimator, Scores};
use super::filter::FilterParams;
use super::options::{LocalizerOptions, Mode};
use super::result::{Candidate, Frame, Localization};
use super::scratch::{select_most_probable, Scratch};
use super::similarity;
use super::verification::Verifier;
use super::{LocalizeError, TimestampError};
use crate::describe::{Describer, DescriberOptions};
use crate::descriptor::normalize_descriptor_into;
use crate::map::{is_finite_pose, Map, MapError};
use crate::verify::CELL_TAP;
use nalgebra::Isometry3;
use std::sync::Arc;

/// Localizes a stream of frames against one map.
///
/// Holds the filter state, so one localizer follows one camera; it is `Send` but not meant to
/// be shared between threads without a lock. Many localizers may share one `Arc<Map>`.
/// After construction, `process` allocates nothing (except for verification).
pub struct Localizer {
    map: Arc<Map>,
    options: LocalizerOptions,
    params: FilterParams,
    estimator: Estimator,
    initialized: bool,
    frames: u64,
    last_timestamp: Option<f64>,
    scratch: Scratch,
    describer: Option<Describer>,
    verifier: Option<Verifier>,
}

impl Localizer {
    /// Creates a localizer; fails on invalid options or when the map was built with another
    /// descriptor than `options.expected`.
    pub fn new(map: Arc<Map>, options: LocalizerOptions) -> Result<Self, LocalizeError> {
        let params = options.filter_params()?;
        map.descriptor()
            .check_compatible(&options.expected)
            .map_err(MapError::from)?;
        let estimator =
            Estimator::new(&map, options.mode, &params, &options.metric, &options.grnn)?;
        let verifier = match options.verification.enabled() {
            true => Some(Verifier::new(&map, &options.verification, &estimator)?),
            false => None,
        };
        Ok(Self {
            verifier,
            estimator,
            params,
            initialized: false,
            frames: 0,
            last_timestamp: None,
            scratch: Scratch::new(&map),
            describer: None,
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
            &self.scratch.view_scores
        }
    }

    /// Forgets all history: the next frame is treated as the first.
    pub fn reset(&mut self) {
        self.estimator.set_initial(&self.params);
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

    /// True when verification uses the map's dense cells: frames must then carry their image
    /// and no descriptor, since the localizer's own forward pass gives both.
    pub fn wants_image_only(&self) -> bool {
        self.verifier.as_ref().is_some_and(Verifier::wants_cells)
    }

    /// Processes one frame, writing into `out` (reusing its candidate buffer). Validates the
    /// whole frame before touching any state, so an error leaves the localizer unchanged.
    /// Cost: one pass over the descriptor matrix plus O(places + edges); in metric mode also
    /// O(particles x places) for the particles' nearest places; with verification on,
    /// also keypoint detection in the frame's image and one match + RANSAC per checked view,
    /// and with a camera one PnP fit (these allocate). Verification needs `frame.image` even
    /// when a descriptor is given.
    pub fn process(
        &mut self,
        frame: &Frame<'_>,
        out: &mut Localization,
    ) -> Result<(), LocalizeError> {
        self.validate(frame)?;
        self.describe(frame)?;
        self.score();
        if let Some(verifier) = &mut self.verifier {
            verifier.save(&self.estimator);
        }
        self.update(frame.odometry.as_ref())?;
        if let Some(verifier) = &mut self.verifier {
            let checked = verifier.verify(
                &self.map,
                &self.options.verification,
                &self.params,
                &mut self.estimator,
                &mut self.scratch,
            );
            if let Err(e) = checked {
                verifier.restore(&mut self.estimator);
                return Err(e);
            }
        }
        self.initialized = true;
        self.last_timestamp = Some(frame.timestamp);
        out.frame_index = self.frames;
        self.frames += 1;
        self.report(out);
        log::trace!(
            "frame {} (t = {}): place {}, view {}, confidence {:.3}, off-map {}",
            out.frame_index,
            frame.timestamp,
            out.place,
            out.view,
            out.confidence,
            out.off_map
        );
        Ok(())
    }

    /// Stage 1: the frame's timestamp and odometry are usable.
    fn validate(&self, frame: &Frame<'_>) -> Result<(), LocalizeError> {
        if !frame.timestamp.is_finite() {
            return Err(LocalizeError::Timestamp(TimestampError::NonFinite(
                frame.timestamp,
            )));
        }
        if let (true, Some(last)) = (self.filtering(), self.last_timestamp) {
            if frame.timestamp < last {
                return Err(LocalizeError::Timestamp(TimestampError::Backwards {
                    timestamp: frame.timestamp,
                    previous: last,
                }));
            }
        }
        if let Some(pose) = &frame.odometry {
            check_odometry(pose)?;
        }
        Ok(())
    }

    /// Stage 2: the unit-norm query descriptor (the host's, or the frame's image described),
    /// and with verification on the query keypoints.
    fn describe(&mut self, frame: &Frame<'_>) -> Result<(), LocalizeError> {
        let scratch = &mut self.scratch;
        let wants_cells = self.verifier.as_ref().is_some_and(Verifier::wants_cells);
        let no_describer = || {
            LocalizeError::NoDescriber(
                "the frame has an image but no descriptor, and this localizer has no describer (Rust: Localizer::with_describer; C: image_backend TOPOLOC_BACKEND_AUTO on a map built from images)".into(),
            )
        };
        let mut cells = None;
        let descriptor: &[f32] = match (frame.descriptor.is_empty(), &frame.image) {
            (true, Some(image)) if wants_cells => {
                let describer = self.describer.as_mut().ok_or_else(no_describer)?;
                cells =
                    Some(describer.describe_with_tap(image, &mut scratch.described, CELL_TAP)?);
                &scratch.described
            }
            (true, Some(image)) => {
                let describer = self.describer.as_mut().ok_or_else(no_describer)?;
                describer.describe(image, &mut scratch.described)?;
                &scratch.described
            }
            _ => frame.descriptor,
        };
        normalize_descriptor_into(descriptor, self.map.dim(), &mut scratch.query)?;
        if let Some(verifier) = &mut self.verifier {
            match (&cells, wants_cells) {
                (Some(tap), _) => verifier.set_cells(tap, self.options.verification.query_keypoints)?,
                (None, true) => {
                    return Err(LocalizeError::Verification(
                        "the map verifies with dense cells of the describer's CNN: frames need their image and no descriptor of their own, and the localizer a describer".into(),
                    ))
                }
                (None, false) => verifier.detect(frame.image.as_ref())?,
            }
        }
        Ok(())
    }

    /// Stage 3: similarity of the query to every view, and every place's best view.
    fn score(&mut self) {
        let scratch = &mut self.scratch;
        similarity::view_similarities(&self.map, &scratch.query, &mut scratch.view_scores);
        similarity::pool_places(
            &self.map,
            &scratch.view_scores,
            &mut scratch.place_scores,
            &mut scratch.best_views,
        );
    }

    /// Stage 4: the estimator's prediction by the motion model and appearance update (for the
    /// learned estimator, one step of the network). On error the estimator is unchanged.
    fn update(&mut self, odometry: Option<&Isometry3<f64>>) -> Result<(), LocalizeError> {
        let continued = self.filtering() && self.initialized;
        let scores = Scores {
            query: &self.scratch.query,
            views: &self.scratch.view_scores,
            places: &self.scratch.place_scores,
        };
        self.estimator
            .step(&self.map, &self.params, continued, odometry, scores)
    }

    /// Stage 6: the top-k places, the best one and the off-map decision into `out`.
    fn report(&mut self, out: &mut Localization) {
        let m = self.map.place_count();
        let p = self.estimator.places();
        let on_map = 1.0 - self.estimator.off_map();
        let k = self.options.top_k.min(m);
        let scratch = &mut self.scratch;
        select_most_probable(&mut scratch.order, p, k, true);
        out.candidates.clear();
        out.candidates
            .extend(scratch.order[..k].iter().map(|&place| {
                let view = scratch.best_views[place as usize];
                let check = self.verifier.as_ref().and_then(|v| v.checked(place));
                Candidate {
                    place,
                    view,
                    probability: (p[place as usize] * on_map) as f32,
                    similarity: scratch.view_scores[view as usize],
                    verified: check.is_some(),
                    inliers: check.unwrap_or(0),
                }
            }));
        let best = out.candidates[0];
        out.place = best.place;
        out.view = best.view;
        out.confidence = best.probability;
        out.similarity = best.similarity;
        out.off_map_probability = self.estimator.off_map() as f32;
        out.off_map = self.estimator.off_map() > 0.5;
        out.pose_fix = self.verifier.as_ref().and_then(Verifier::pose_fix);
    }

    /// Whether frames are filtered over time (every mode but single-frame).
    fn filtering(&self) -> bool {
        self.options.mode != Mode::SingleFrame
    }
}

fn check_odometry(pose: &Isometry3<f64>) -> Result<(), LocalizeError> {
    if is_finite_pose(pose) {
        Ok(())
    } else {
        Err(LocalizeError::Odometry(
            "odometry has a non-finite value".into(),
        ))
    }
}
