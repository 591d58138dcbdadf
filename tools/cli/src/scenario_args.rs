//! Options shared by the commands that fly generated scenarios (`demo`, `simulate`, `suite`):
//! the map capture, the query light and rate, the backend choice, and the scenario built from
//! them.

use crate::backend_args::{Backend, LocalFeatures};
use topoloc::build::ImageMapOptions;
use topoloc::describe::onnx::{cache_dir, DEFAULT_MODEL_FILE};
use topoloc::describe::BackendConfig;
use topoloc::verify::FeatureKind;
use topoloc_sim::render::{Condition, ConditionKind};
use topoloc_sim::scenario::ScenarioOptions;
use topoloc_sim::style::Split;
use topoloc_sim::world::WorldParams;

/// Query frames' light and rate, and the map's descriptor backend, shared by `simulate` and
/// `suite`.
#[derive(clap::Args, Clone, Debug)]
pub struct QueryArgs {
    /// Query frames per second.
    #[arg(long, default_value_t = 10.0)]
    pub rate_hz: f64,
    /// Lighting of the query frames (maps are captured in bright light).
    #[arg(long, default_value = "dim", value_parser = parse_condition)]
    pub condition: ConditionKind,
    /// Descriptor backend of the map; default: ONNX when its model is set up, else VLAD.
    #[arg(long, value_enum)]
    pub backend: Option<Backend>,
}

pub(crate) fn parse_split(name: &str) -> Result<Split, String> {
    name.parse()
}

pub(crate) fn parse_condition(name: &str) -> Result<ConditionKind, String> {
    ConditionKind::from_name(name).ok_or_else(|| {
        let names: Vec<_> = ConditionKind::ALL.iter().map(|k| k.name()).collect();
        format!("expected one of {}", names.join(", "))
    })
}

/// Views captured per place by `demo`, `simulate` and `suite` unless `--views-per-place` says
/// otherwise. The seed's micro nodes are 4 views 90 degrees apart; 12 (30 degrees apart) was
/// measured better on generated worlds (BENCHMARKS.md, "Which data chose each default"), since
/// a query turned 45 degrees from every view shares only half its field of view with each.
pub(crate) const VIEWS_PER_PLACE: usize = 12;

/// Map capture options shared by `demo`, `simulate` and `suite`.
#[derive(clap::Args, Clone, Debug)]
pub struct CaptureArgs {
    /// Map views per place, evenly turned in yaw, 1..=16 (4 is the seed's micro nodes).
    #[arg(long, default_value_t = VIEWS_PER_PLACE)]
    pub views_per_place: usize,
    /// Also capture those views from 4 points this far around each place (metres, 0 = off;
    /// points kept where free, in sight of the place and nearest to it). 0.8 raised test-split
    /// MNA/OHA by about 0.05 at 5x the views and map build time (BENCHMARKS.md).
    #[arg(long, default_value_t = 0.0)]
    pub ring_m: f64,
    /// Local features stored per map view for geometric verification (cells need the ONNX
    /// backend: they come from its forward pass). Default ORB; `demo`: XFeat when its model
    /// is set up.
    #[arg(long, value_enum)]
    pub local_features: Option<LocalFeatures>,
}

/// The scenario of `demo`, `simulate` and `suite`: `world` with `capture` views per place
/// captured in bright light and described with `backend`, queried under `condition`
/// along `legs` legs (one of them back to an earlier goal, a loop, when there are two or more)
/// at `rate_hz`; the trajectory seed is left to the caller.
pub(crate) fn scenario_options(
    world: WorldParams,
    backend: BackendConfig,
    capture: &CaptureArgs,
    condition: ConditionKind,
    legs: usize,
    rate_hz: f64,
) -> ScenarioOptions {
    let mut options = ScenarioOptions::new(
        world,
        ImageMapOptions {
            backend,
            features: capture
                .local_features
                .map_or(FeatureKind::Orb, FeatureKind::from),
            ..ImageMapOptions::default()
        },
    );
    options.capture.views_per_place = capture.views_per_place;
    options.capture.ring_radius_m = capture.ring_m;
    options.query_condition = Condition::preset(condition);
    options.trajectory.goals = legs;
    options.trajectory.revisits = options.trajectory.revisits.min(legs.saturating_sub(1));
    options.trajectory.motion.rate_hz = rate_hz;
    options
}

/// The backend of `demo`, `simulate` and `suite`: the one asked for, else ONNX when its model is in the cache.
pub(crate) fn choose_backend(asked: Option<Backend>) -> (BackendConfig, String) {
    let model = cache_dir().join(DEFAULT_MODEL_FILE);
    match asked {
        Some(Backend::Vlad) => (BackendConfig::Vlad(Default::default()), "VLAD (asked for)".into()),
        Some(Backend::Onnx) => (BackendConfig::Onnx(Default::default()), "ONNX MLF (asked for)".into()),
        None if model.is_file() => (
            BackendConfig::Onnx(Default::default()),
            format!("ONNX MLF (model found: {})", model.display()),
        ),
        None => (
            BackendConfig::Vlad(Default::default()),
            format!(
                "VLAD dense ORB: no ONNX model at {} (run scripts/setup-models.sh for the CNN backend)",
                model.display()
            ),
        ),
    }
}
