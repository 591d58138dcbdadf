//! Stage 5 of a frame: geometric verification of the most probable places against the query
//! image ([`crate::verify`]), the belief weighed by their inliers, the off-map decision taken
//! from them, and the pose fix of the best-verified view.

use super::estimator::Estimator;
use super::filter::FilterParams;
use super::result::PoseFix;
use super::scratch::{select_most_probable, Scratch};
use super::LocalizeError;
use crate::describe::onnx::DenseTap;
use crate::errors::VisionError;
use crate::image::ImageView;
use crate::map::{Map, PlaceId, ViewId};
use crate::verify::{
    cells_from_map, check_pair, locate, spatial_check, FeatureDetector, FeatureKind, Keypoints,
    VerificationOptions, VerificationScore, ViewKeypoints,
};
use nalgebra::Point3;

/// Largest off-map log-likelihood ratio one frame's inliers give (a frame with no inlier at
/// all is strong evidence, not certainty).
const MAX_LOG_RATIO: f64 = 50.0;

/// State of geometric verification: the query detector, the per-place results of the current
/// frame, and a copy of the estimator to restore if a check fails half-way.
pub(super) struct Verifier {
    /// Detects the kind of features the map stores; `None` for dense cells, which come from
    /// the describer's forward pass ([`Verifier::set_cells`]).
    detector: Option<FeatureDetector>,
    query: Keypoints,
    /// Places checked in the current frame with their best inlier count and view.
    checked: Vec<(PlaceId, u32, ViewId)>,
    views: Vec<ViewId>,
    /// The pose fix of the current frame.
    fix: Option<PoseFix>,
    /// The most inliers at which a frame is as likely off the map as on it (0: appearance
    /// decides); the options' value or the map's feature kind's default.
    off_map_inliers: f32,
    backup: Estimator,
}

impl Verifier {
    /// A verifier for `map`; fails when the map lacks what the options need (keypoints, and
    /// their scene points for a camera).
    pub fn new(
        map: &Map,
        options: &VerificationOptions,
        estimator: &Estimator,
    ) -> Result<Self, LocalizeError> {
        let Some(keypoints) = map.keypoints() else {
            return Err(LocalizeError::Verification(
                "verification is on but the map stores no keypoints (build it from images with keypoints > 0, or set verification.candidates to 0)".into(),
            ));
        };
        if options.camera.is_some() && keypoints.world_points().is_none() {
            return Err(LocalizeError::Verification(
                "verification.camera is set but the map stores no keypoint scene points (attach them with ViewKeypoints::with_world_points, or leave the camera unset)".into(),
            ));
        }
        Ok(Self {
            detector: match keypoints.kind() {
                FeatureKind::Cells => None,
                kind => Some(FeatureDetector::new(
                    kind,
                    options.query_keypoints,
                    &options.xfeat,
                )?),
            },
            query: Keypoints::default(),
            checked: Vec::with_capacity(options.candidates),
            views: Vec::new(),
            fix: None,
            off_map_inliers: options
                .off_map_inliers
                .unwrap_or_else(|| keypoints.kind().default_off_map_inliers()),
            backup: estimator.clone(),
        })
    }

    /// True when the map stores dense cells: the describer must run with the cell tap and
    /// hand its map to [`Verifier::set_cells`].
    pub fn wants_cells(&self) -> bool {
        self.detector.is_none()
    }

    /// Detects the query keypoints; verification needs the frame's image.
    pub fn detect(&mut self, image: Option<&ImageView<'_>>) -> Result<(), LocalizeError> {
        let image = image.ok_or_else(|| {
            VisionError::InvalidImage(
                "verification is on: the frame needs its image (beside or instead of a descriptor)"
                    .into(),
            )
        })?;
        if let Some(detector) = &mut self.detector {
            self.query = detector.detect(image)?;
        }
        Ok(())
    }

    /// Takes the query's dense cells from the describer's feature map.
    pub fn set_cells(&mut self, tap: &DenseTap, max_cells: usize) -> Result<(), LocalizeError> {
        self.query = cells_from_map(
            &tap.values,
            [tap.channels, tap.height, tap.width],
            tap.cell_size,
            max_cells,
        )?;
        Ok(())
    }

    /// Keeps the estimator's state before the frame changes it.
    pub fn save(&mut self, estimator: &Estimator) {
        estimator.save(&mut self.backup);
    }

    /// Puts back the state kept by [`Verifier::save`].
    pub fn restore(&self, estimator: &mut Estimator) {
        estimator.restore(&self.backup);
    }

    /// The inliers of `place` if it was checked in the current frame.
    pub fn checked(&self, place: PlaceId) -> Option<u32> {
        self.checked.iter().find(|c| c.0 == place).map(|c| c.1)
    }

    /// The pose fix of the current frame.
    pub fn pose_fix(&self) -> Option<PoseFix> {
        self.fix
    }

    /// Checks the most probable places against the query keypoints and weighs the belief by
    /// their inliers; a checked place's best view becomes the one with the most inliers; with
    /// a camera, the best-verified view places the camera (a pose fix, which metric mode's
    /// particles are weighed by).
    pub fn verify(
        &mut self,
        map: &Map,
        options: &VerificationOptions,
        params: &FilterParams,
        estimator: &mut Estimator,
        scratch: &mut Scratch,
    ) -> Result<(), LocalizeError> {
        let keypoints = map.keypoints().expect("checked at construction");
        self.check_candidates(map, keypoints, options, estimator, scratch)?;
        self.weigh_off_map(options, estimator);
        self.weigh_by_inliers(options, params, estimator);
        for &(place, inliers, view) in &self.checked {
            if inliers > 0 {
                scratch.best_views[place as usize] = view;
            }
        }
        self.fix = self.locate_best(keypoints, options)?;
        if let Some(fix) = &self.fix {
            estimator.weigh_by_position(&Point3::from(fix.world_t_optical.translation.vector));
        }
        Ok(())
    }

    /// Checks the `options.candidates` most probable places on their views most similar to the
    /// query, recording each place's best inlier count and view.
    fn check_candidates(
        &mut self,
        map: &Map,
        keypoints: &ViewKeypoints,
        options: &VerificationOptions,
        estimator: &Estimator,
        scratch: &mut Scratch,
    ) -> Result<(), LocalizeError> {
        let c = options.candidates.min(map.place_count());
        select_most_probable(&mut scratch.order, estimator.places(), c, false);
        self.checked.clear();
        for &place in &scratch.order[..c] {
            self.views.clear();
            self.views.extend_from_slice(map.place_views(place)?);
            let scores = &scratch.view_scores;
            self.views
                .sort_unstable_by(|a, b| scores[*b as usize].total_cmp(&scores[*a as usize]));
            let mut best = (0u32, scratch.best_views[place as usize]);
            for &view in self.views.iter().take(options.views_per_candidate) {
                let stored = keypoints
                    .view(view as usize)
                    .expect("one keypoint entry per view");
                let evidence = match options.score {
                    VerificationScore::Inliers => {
                        check_pair(
                            self.query.as_ref(),
                            stored,
                            options.pair_for(keypoints.kind()),
                        )?
                        .inliers
                    }
                    VerificationScore::Spatial => {
                        let spatial = spatial_check(
                            self.query.as_ref(),
                            stored,
                            options.pair_for(keypoints.kind()).max_hamming,
                        )?;
                        (spatial.score * self.query.len() as f32).round() as u32
                    }
                };
                if evidence > best.0 {
                    best = (evidence, view);
                }
            }
            self.checked.push((place, best.0, best.1));
        }
        Ok(())
    }

    /// The most inliers (or s-GC evidence) among the places checked in this frame; 0 for none.
    fn most_inliers(&self) -> u32 {
        self.checked.iter().map(|c| c.1).max().unwrap_or(0)
    }

    /// The frame's off-map update from the most inliers among the checked places, in place of
    /// the appearance scores' (unless the threshold is 0).
    fn weigh_off_map(&self, options: &VerificationOptions, estimator: &mut Estimator) {
        if self.off_map_inliers <= 0.0 || self.checked.is_empty() {
            return;
        }
        let most = self.most_inliers();
        let log_ratio = (f64::from(self.off_map_inliers) - f64::from(most))
            / f64::from(options.off_map_inlier_scale);
        estimator.replace_off_map_evidence(log_ratio.min(MAX_LOG_RATIO).exp());
    }

    /// Multiplies each place's belief by exp(weight * inliers), unchecked places counting 0.
    fn weigh_by_inliers(
        &self,
        options: &VerificationOptions,
        params: &FilterParams,
        estimator: &mut Estimator,
    ) {
        let most = self.most_inliers();
        let weight = f64::from(options.inlier_weight);
        // exp(weight * (inliers - most)) for checked places, exp(-weight * most) for the rest:
        // the same ratios as exp(weight * inliers) with unchecked places at 0, kept at most 1.
        let unchecked = (-weight * f64::from(most)).exp();
        let checked = &self.checked;
        estimator.weigh_places(params, |place| {
            checked
                .iter()
                .find(|c| c.0 as usize == place)
                .map_or(unchecked, |c| {
                    (weight * (f64::from(c.1) - f64::from(most))).exp()
                })
        });
    }

    /// The camera placed against the view with the most inliers, when a camera is set and
    /// that view has enough of them.
    fn locate_best(
        &self,
        keypoints: &ViewKeypoints,
        options: &VerificationOptions,
    ) -> Result<Option<PoseFix>, LocalizeError> {
        let best = self
            .checked
            .iter()
            .max_by_key(|c| (c.1, std::cmp::Reverse(c.0)));
        let (Some(camera), Some(&(_, inliers, view))) = (&options.camera, best) else {
            return Ok(None);
        };
        if inliers < options.locate.min_inliers {
            return Ok(None);
        }
        let stored = keypoints.view(view as usize).expect("view in range");
        let scene = keypoints
            .view_world_points(view as usize)
            .expect("checked at construction");
        let found = locate(
            self.query.as_ref(),
            stored,
            scene,
            camera,
            options.pair.max_hamming,
            &options.locate,
        )?;
        Ok(found.map(|f| PoseFix {
            view,
            world_t_optical: f.world_t_optical,
            inliers: f.inliers,
        }))
    }
}
