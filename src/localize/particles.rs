//! Monte Carlo localization over metric camera poses ([`Mode::Metric`](super::Mode::Metric)).
//!
//! The graph filter (`filter.rs`) knows places and the edges between them; odometry only tells
//! it how far the camera went. A map built with place positions and view poses (a SLAM
//! system's keyframes, or `topoloc-sim`'s captures) allows more: a cloud of camera poses in
//! the map frame, moved by the full odometry (distance *and* turn) and weighed by appearance.
//! The closest place is then a matter of geometry, and a turn at a junction tells the branches
//! apart.
//!
//! Each frame:
//!
//! 1. *Predict.* Every particle is composed with the frame's odometry `previous_T_current`,
//!    with noise: translation stretched by a relative error and shifted in the map's xy plane,
//!    heading turned about the map's z axis (z is up, as visual-inertial odometry gives).
//!    Without odometry, particles diffuse by [`MetricOptions::diffusion_m`] and
//!    [`MetricOptions::diffusion_rad`].
//! 2. *Resample and inject.* Particles are resampled by weight (systematic resampling), and a
//!    fraction ([`MetricOptions::injection`]) is replaced by poses drawn around the map's views
//!    in proportion to how well each view matches the frame (sensor resetting), so that a
//!    lost or kidnapped cloud recovers. The first frame draws every particle this way, at the
//!    sharper [`MetricOptions::initial_temperature`], so the cloud starts on the views that
//!    match best rather than spread over the whole map.
//! 3. *Update.* A particle's nearest place (by position) and, among that place's views, those
//!    facing its way and captured nearest to it give its likelihood `exp((score - max) / T)`
//!    (the best such view's score). The place belief is the weight of the particles nearest to
//!    each place.
//! 4. *Pose fix.* With verification and a camera ([`crate::verify::locate`]), the camera
//!    position found against the best-verified view weighs the particles by their horizontal
//!    distance to it ([`MetricOptions::fix_sigma_m`]): appearance tells where in a place the
//!    camera is only to about half a metre, a fix to a few centimetres. A floor
//!    ([`MetricOptions::fix_outlier`]) keeps a wrong fix from wiping out the cloud.
//!
//! Deterministic: the random generator is seeded from [`MetricOptions::seed`] and reset with
//! the localizer.

use crate::bounds::Bounds;
use crate::map::Map;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// Parameters of the metric filter. The defaults were chosen on the Test worlds of
/// `topoloc suite` (BENCHMARKS.md).
#[derive(Clone, Debug, PartialEq)]
pub struct MetricOptions {
    /// Number of particles. Default 2000.
    pub particles: usize,
    /// Softmax temperature of a particle's appearance likelihood. Larger than the graph
    /// filter's: particles moved by odometry stay together, and should follow the odometry
    /// rather than each frame's best-looking view. Default 1.0.
    pub temperature: f32,
    /// A particle scores the best of its nearest place's views turned less than this from it,
    /// radians (else the view nearest in heading). Default 1.0.
    pub view_window_rad: f32,
    /// ... and, of those, captured within this distance of the closest one, metres: on maps
    /// with views around each place (keyframes, `topoloc-sim --ring-m`), the views near the
    /// particle say where in the place the camera is. Default 0.3.
    pub view_position_tolerance_m: f32,
    /// Standard deviation of the translation error per metre travelled. Default 0.05.
    pub translation_noise: f32,
    /// Standard deviation of the heading error per frame, radians. Default 0.01.
    pub rotation_noise_rad: f32,
    /// Standard deviation of the position change per frame without odometry, metres.
    /// Default 0.3.
    pub diffusion_m: f32,
    /// Standard deviation of the heading change per frame without odometry, radians.
    /// Default 0.3.
    pub diffusion_rad: f32,
    /// Fraction of particles re-drawn around well-matching views each frame (0..1).
    /// Default 0.002 (4 of 2000): enough to recover from a wrong start, few enough not to pull
    /// the cloud to each frame's best-looking view.
    pub injection: f32,
    /// Spread of a drawn particle around its view: position, metres. Default 0.5.
    pub injection_spread_m: f32,
    /// Spread of a drawn particle around its view: heading, radians. Default 0.2.
    pub injection_spread_rad: f32,
    /// Softmax temperature of the first frame's draw (after creation or reset): sharper than
    /// `temperature`, so that the cloud starts around the views that match the first frame
    /// best instead of spread over the whole map (a proposal; the odometry and the frames that
    /// follow correct it). Default 0.3, chosen on the suite's Test worlds with ring points
    /// (figures in docs/benchmarks/issue-04.md, "Metric mode").
    pub initial_temperature: f32,
    /// Standard deviation of a pose fix's horizontal position ([`crate::verify::locate`],
    /// with verification and a camera), metres: each fix multiplies a particle's weight by
    /// `fix_outlier + exp(-d^2 / (2 sigma^2))`, `d` its horizontal distance to the fix.
    /// Default 0.2.
    pub fix_sigma_m: f32,
    /// Weight a pose fix leaves to particles far from it, guarding against a wrong fix (a
    /// look-alike place whose keypoints happen to agree, a degenerate fit). Default 0.3; a
    /// lower floor let wrong fixes drag the cloud away (the comparison and the share of
    /// far-off fixes are in docs/benchmarks/issue-04.md, "Metric mode with pose fixes").
    pub fix_outlier: f32,
    /// Seed of the random generator. Default 0.
    pub seed: u64,
}

impl Default for MetricOptions {
    fn default() -> Self {
        Self {
            particles: 2000,
            temperature: 1.0,
            view_window_rad: 1.0,
            view_position_tolerance_m: 0.3,
            translation_noise: 0.05,
            rotation_noise_rad: 0.01,
            diffusion_m: 0.3,
            diffusion_rad: 0.3,
            injection: 0.002,
            injection_spread_m: 0.5,
            injection_spread_rad: 0.2,
            initial_temperature: 0.3,
            fix_sigma_m: 0.2,
            fix_outlier: 0.3,
            seed: 0,
        }
    }
}

/// Most particles the metric filter accepts.
pub const MAX_PARTICLES: usize = 1_000_000;

impl MetricOptions {
    /// Accepted values of [`Self::particles`].
    pub const PARTICLES_RANGE: Bounds = Bounds::whole(1, MAX_PARTICLES as u64);
    /// Accepted values of the noises, windows, spreads and tolerances.
    pub const SPREAD_RANGE: Bounds = Bounds::at_least(0.0);
    /// Accepted values of [`Self::injection`].
    pub const INJECTION_RANGE: Bounds = Bounds::closed(0.0, 1.0);
    /// Accepted values of [`Self::temperature`], [`Self::initial_temperature`] and
    /// [`Self::fix_sigma_m`].
    pub const TEMPERATURE_RANGE: Bounds = Bounds::above(0.0);

    /// Checks every field; the message names the first bad one.
    pub fn validate(&self) -> Result<(), String> {
        Self::PARTICLES_RANGE.check("metric.particles", self.particles)?;
        let non_negative = [
            ("metric.translation_noise", self.translation_noise),
            ("metric.rotation_noise_rad", self.rotation_noise_rad),
            ("metric.view_window_rad", self.view_window_rad),
            (
                "metric.view_position_tolerance_m",
                self.view_position_tolerance_m,
            ),
            ("metric.diffusion_m", self.diffusion_m),
            ("metric.diffusion_rad", self.diffusion_rad),
            ("metric.injection_spread_m", self.injection_spread_m),
            ("metric.injection_spread_rad", self.injection_spread_rad),
            ("metric.fix_outlier", self.fix_outlier),
        ];
        for (name, value) in non_negative {
            Self::SPREAD_RANGE.check(name, value)?;
        }
        Self::INJECTION_RANGE.check("metric.injection", self.injection)?;
        for (name, value) in [
            ("metric.temperature", self.temperature),
            ("metric.initial_temperature", self.initial_temperature),
            ("metric.fix_sigma_m", self.fix_sigma_m),
        ] {
            Self::TEMPERATURE_RANGE.check(name, value)?;
        }
        Ok(())
    }
}

/// The particle cloud, the map geometry it needs, and the place marginals.
#[derive(Clone)]
pub(crate) struct Particles {
    options: MetricOptions,
    /// Position of every place.
    place_positions: Vec<Point3<f64>>,
    /// Pose of every view.
    view_poses: Vec<Isometry3<f64>>,
    /// Views of place p: `place_views[place_view_offsets[p]..place_view_offsets[p + 1]]`.
    place_view_offsets: Vec<usize>,
    place_views: Vec<u32>,
    poses: Vec<Isometry3<f64>>,
    weights: Vec<f64>,
    /// Nearest place of each particle.
    nearest: Vec<u32>,
    /// True until the first frame has drawn the cloud.
    fresh: bool,
    rng: SmallRng,
    /// Posterior over the places: the weight of the particles nearest to each.
    pub places: Vec<f64>,
    resampled: Vec<Isometry3<f64>>,
    cumulative: Vec<f64>,
}

impl Particles {
    /// Fails (with a message) when a place has no position or a view no pose.
    pub fn new(map: &Map, options: &MetricOptions) -> Result<Self, String> {
        let m = map.place_count();
        let mut place_positions = Vec::with_capacity(m);
        for (p, position) in map.place_positions().iter().enumerate() {
            place_positions.push(position.ok_or_else(|| {
                format!("metric mode needs every place's position; place {p} has none")
            })?);
        }
        let mut view_poses = Vec::with_capacity(map.view_count());
        for (v, view) in map.views().iter().enumerate() {
            view_poses.push(view.world_t_camera.ok_or_else(|| {
                format!("metric mode needs every view's pose (world_T_camera); view {v} has none")
            })?);
        }
        let mut place_view_offsets = Vec::with_capacity(m + 1);
        let mut place_views = Vec::with_capacity(map.view_count());
        place_view_offsets.push(0);
        for p in 0..m as u32 {
            place_views.extend_from_slice(map.place_views(p).expect("place in range"));
            place_view_offsets.push(place_views.len());
        }
        let n = options.particles;
        Ok(Self {
            options: options.clone(),
            place_positions,
            view_poses,
            place_view_offsets,
            place_views,
            poses: vec![Isometry3::identity(); n],
            weights: vec![1.0 / n as f64; n],
            nearest: vec![0; n],
            fresh: true,
            rng: SmallRng::seed_from_u64(options.seed),
            places: vec![0.0; m],
            resampled: Vec::with_capacity(n),
            cumulative: Vec::with_capacity(map.view_count().max(n)),
        })
    }

    /// Forgets the cloud: the next update draws it from the frame's appearance.
    pub fn set_initial(&mut self) {
        self.fresh = true;
        self.rng = SmallRng::seed_from_u64(self.options.seed);
    }

    fn gaussian(&mut self) -> f64 {
        self.rng.sample::<f64, _>(StandardNormal)
    }

    /// Moves every particle by the odometry (with noise), or diffuses it without odometry.
    pub fn predict(&mut self, odometry: Option<&Isometry3<f64>>) {
        if self.fresh {
            return;
        }
        let o = &self.options;
        let (sigma_xy, sigma_yaw, relative) = match odometry {
            Some(motion) => (
                f64::from(o.translation_noise) * motion.translation.vector.norm(),
                f64::from(o.rotation_noise_rad),
                f64::from(o.translation_noise),
            ),
            None => (f64::from(o.diffusion_m), f64::from(o.diffusion_rad), 0.0),
        };
        for i in 0..self.poses.len() {
            let (nx, ny, nyaw, ns) = (
                self.gaussian(),
                self.gaussian(),
                self.gaussian(),
                self.gaussian(),
            );
            let mut pose = self.poses[i];
            if let Some(motion) = odometry {
                let stretched = Isometry3::from_parts(
                    Translation3::from(motion.translation.vector * (1.0 + relative * ns)),
                    motion.rotation,
                );
                pose *= stretched;
            }
            let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), sigma_yaw * nyaw);
            pose.rotation = turn * pose.rotation;
            pose.translation.vector += Vector3::new(sigma_xy * nx, sigma_xy * ny, 0.0);
            self.poses[i] = pose;
        }
    }

    /// Resamples, injects particles drawn from the frame's view scores, weighs the cloud by
    /// appearance and computes the place marginals.
    pub fn update(&mut self, view_scores: &[f32]) {
        let max_score = view_scores.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b)) as f64;
        let inv_t = 1.0 / f64::from(self.options.temperature);
        let n = self.poses.len();
        let (injected, injection_inv_t) = if self.fresh {
            (n, 1.0 / f64::from(self.options.initial_temperature))
        } else {
            let count = (f64::from(self.options.injection) * n as f64).round() as usize;
            (count.min(n), inv_t)
        };
        self.resample(n - injected);
        self.inject(injected, view_scores, max_score, injection_inv_t);
        std::mem::swap(&mut self.poses, &mut self.resampled);
        self.fresh = false;
        for i in 0..n {
            let pose = &self.poses[i];
            let place = nearest_place(
                &self.place_positions,
                &Point3::from(pose.translation.vector),
            );
            self.nearest[i] = place as u32;
            let score = self.view_score(place, pose, view_scores);
            self.weights[i] = ((score.unwrap_or(max_score) - max_score) * inv_t).exp();
        }
        self.normalise();
    }

    /// What a particle at `place` with `pose` scores: among the place's views turned less than
    /// `view_window_rad` from it, those captured within `view_position_tolerance_m` of the
    /// closest one, the best score (views around a place tell where in it the camera is); with
    /// no view in the window, the view nearest in heading. `None` for a place without views.
    fn view_score(&self, place: usize, pose: &Isometry3<f64>, view_scores: &[f32]) -> Option<f64> {
        let window = f64::from(self.options.view_window_rad);
        let tolerance = f64::from(self.options.view_position_tolerance_m);
        let views =
            &self.place_views[self.place_view_offsets[place]..self.place_view_offsets[place + 1]];
        let distance = |v: u32| {
            (self.view_poses[v as usize].translation.vector - pose.translation.vector).norm()
        };
        let angle = |v: u32| {
            self.view_poses[v as usize]
                .rotation
                .angle_to(&pose.rotation)
        };
        let closest = views
            .iter()
            .filter(|&&v| angle(v) < window)
            .map(|&v| distance(v))
            .fold(f64::INFINITY, f64::min);
        let within = views
            .iter()
            .filter(|&&v| angle(v) < window && distance(v) <= closest + tolerance)
            .map(|&v| f64::from(view_scores[v as usize]))
            .reduce(f64::max);
        within.or_else(|| {
            views
                .iter()
                .min_by(|&&a, &&b| angle(a).total_cmp(&angle(b)))
                .map(|&v| f64::from(view_scores[v as usize]))
        })
    }

    /// Multiplies the weight of every particle nearest to place p by `factor(p)` and
    /// normalises.
    pub fn weigh_places(&mut self, factor: impl Fn(usize) -> f64) {
        for (w, &p) in self.weights.iter_mut().zip(&self.nearest) {
            *w *= factor(p as usize);
        }
        self.normalise();
    }

    /// Weighs the cloud by a pose fix at `position` (see [`MetricOptions::fix_sigma_m`]) and
    /// normalises. Heights are ignored: views are captured at the place's height, not the
    /// camera's.
    pub fn weigh_by_position(&mut self, position: &Point3<f64>) {
        let sigma = f64::from(self.options.fix_sigma_m);
        let outlier = f64::from(self.options.fix_outlier);
        for (w, pose) in self.weights.iter_mut().zip(&self.poses) {
            let d_sq = (pose.translation.vector.xy() - position.coords.xy()).norm_squared();
            *w *= outlier + (-d_sq / (2.0 * sigma * sigma)).exp();
        }
        self.normalise();
    }

    fn normalise(&mut self) {
        let total: f64 = self.weights.iter().sum();
        let n = self.weights.len();
        if total > 0.0 && total.is_finite() {
            self.weights.iter_mut().for_each(|w| *w /= total);
        } else {
            self.weights.fill(1.0 / n as f64);
        }
        self.places.fill(0.0);
        for (w, &p) in self.weights.iter().zip(&self.nearest) {
            self.places[p as usize] += w;
        }
    }

    /// Systematic resampling of `count` particles into `resampled` (cleared first).
    fn resample(&mut self, count: usize) {
        self.resampled.clear();
        if count == 0 {
            return;
        }
        let step = 1.0 / count as f64;
        let mut target = self.rng.random::<f64>() * step;
        let mut cumulative = 0.0;
        let mut i = 0;
        let last = self.weights.len() - 1;
        for _ in 0..count {
            while i < last && cumulative + self.weights[i] < target {
                cumulative += self.weights[i];
                i += 1;
            }
            self.resampled.push(self.poses[i]);
            target += step;
        }
    }

    /// Appends `count` particles drawn around views chosen with probability
    /// `exp((score - max) / T)`.
    fn inject(&mut self, count: usize, view_scores: &[f32], max_score: f64, inv_t: f64) {
        if count == 0 {
            return;
        }
        self.cumulative.clear();
        let mut total = 0.0;
        for &s in view_scores {
            total += ((f64::from(s) - max_score) * inv_t).exp();
            self.cumulative.push(total);
        }
        let spread_m = f64::from(self.options.injection_spread_m);
        let spread_rad = f64::from(self.options.injection_spread_rad);
        for _ in 0..count {
            let u = self.rng.random::<f64>() * total;
            let v = self
                .cumulative
                .partition_point(|&c| c < u)
                .min(view_scores.len() - 1);
            let (nx, ny, nyaw) = (self.gaussian(), self.gaussian(), self.gaussian());
            let mut pose = self.view_poses[v];
            pose.rotation = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), spread_rad * nyaw)
                * pose.rotation;
            pose.translation.vector += Vector3::new(spread_m * nx, spread_m * ny, 0.0);
            self.resampled.push(pose);
        }
    }

    /// Copies the cloud into `backup` (made from the same map and options).
    pub fn save(&self, backup: &mut Particles) {
        backup.poses.copy_from_slice(&self.poses);
        backup.weights.copy_from_slice(&self.weights);
        backup.nearest.copy_from_slice(&self.nearest);
        backup.places.copy_from_slice(&self.places);
        backup.fresh = self.fresh;
        backup.rng = self.rng.clone();
    }
}

/// Index of the place nearest to `point`.
fn nearest_place(positions: &[Point3<f64>], point: &Point3<f64>) -> usize {
    let mut best = (f64::INFINITY, 0);
    for (p, position) in positions.iter().enumerate() {
        let d = (position - point).norm_squared();
        if d < best.0 {
            best = (d, p);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::descriptor::DescriptorIdentity;
    use crate::map::{MapBuilder, ViewAttributes};

    /// Places 1 m apart along x, one view each facing +x, all with the same descriptor.
    fn corridor(places: u32) -> Map {
        let mut builder = MapBuilder::new(DescriptorIdentity::new("test", "corridor", 2).unwrap());
        for p in 0..places {
            let x = f64::from(p);
            let place = builder.add_place(Some(Point3::new(x, 0.0, 1.0))).unwrap();
            let attributes = ViewAttributes {
                world_t_camera: Some(Isometry3::translation(x, 0.0, 1.0)),
                ..Default::default()
            };
            builder.add_view(place, &[1.0, 0.0], attributes).unwrap();
            if p > 0 {
                builder.add_edge(p - 1, p, 1.0).unwrap();
            }
        }
        builder.build().unwrap()
    }

    #[test]
    fn pose_fixes_gather_the_belief_at_their_place_and_one_leaves_the_rest_a_floor() {
        let map = corridor(10);
        let mut particles = Particles::new(&map, &MetricOptions::default()).unwrap();
        // Every view scores the same: the first draw spreads the cloud over the corridor.
        particles.update(&[0.5; 10]);
        assert!(
            particles.places.iter().all(|&p| p < 0.2),
            "{:?}",
            particles.places
        );

        let fix = Point3::new(6.0, 0.05, 1.6);
        let most_probable = |places: &[f64]| {
            (0..places.len())
                .max_by(|&a, &b| places[a].total_cmp(&places[b]))
                .unwrap()
        };
        // One fix tips the balance towards its place, but the floor leaves the others most of
        // their weight, in case the fix is wrong.
        particles.weigh_by_position(&fix);
        assert_eq!(most_probable(&particles.places), 6);
        assert!(particles.places[6] > 0.13, "{:?}", particles.places);
        let far: f64 = particles.places[..4].iter().sum();
        assert!(far > 0.3, "{:?}", particles.places);
        // Fixes that keep agreeing gather the belief there.
        for _ in 0..4 {
            particles.weigh_by_position(&fix);
        }
        assert!(particles.places[6] > 0.5, "{:?}", particles.places);
        let total: f64 = particles.places.iter().sum();
        assert!((total - 1.0).abs() < 1e-9);
    }
}
