//! `topoloc sweep`: the measurement behind the localizer's default temperature and off-map
//! margin. On generated worlds it reports, per setting, the on-map accuracy (MNA, OHA), the
//! share of on-map frames wrongly flagged off-map, the share of frames from a *different* world
//! (same descriptor statistics, truly off-map) that are flagged off-map, and the calibration
//! (ECE) and R@100P of the confidence.

use crate::demo::evaluate;
use anyhow::Result;
use std::sync::Arc;
use topoloc::eval::HopDistances;
use topoloc::{Frame, Localization, Localizer, LocalizerOptions, Mode};
use topoloc_synthetic::{SyntheticWorld, WorldParams};

/// First world seed of the sweep: worlds 100.. are held out from the demo's default seed 0.
const FIRST_SEED: u64 = 100;

/// Runs the sweep over `worlds` world seeds and prints one row per setting (means over worlds).
pub fn run(worlds: u64, frames: usize, temperatures: &[f32], margins: &[f32]) -> Result<()> {
    println!(
        "{:>6} {:>7} {:>6} {:>6} {:>9} {:>9} {:>6} {:>7}",
        "T", "margin", "MNA", "OHA", "false-off", "off-found", "ECE", "R@100P"
    );
    for &temperature in temperatures {
        for &margin in margins {
            let options = LocalizerOptions {
                mode: Mode::Filter,
                temperature,
                off_map_margin: margin,
                ..Default::default()
            };
            let mut sums = [0.0f64; 6];
            for seed in FIRST_SEED..FIRST_SEED + worlds {
                let world = SyntheticWorld::generate(&WorldParams {
                    seed,
                    ..Default::default()
                })?;
                let stranger = SyntheticWorld::generate(&WorldParams {
                    seed: seed + 1000,
                    ..Default::default()
                })?;
                let map = world.map().clone();
                let hops = HopDistances::from_map(&map);
                let on = evaluate(
                    "sweep",
                    &map,
                    &world.sequence(frames, seed + 1),
                    &hops,
                    options.clone(),
                    true,
                    None,
                )?;
                let found = off_map_rate(
                    &map,
                    &stranger.sequence(frames / 2, seed + 2),
                    options.clone(),
                )?;
                for (s, v) in sums.iter_mut().zip([
                    on.mna,
                    on.oha,
                    on.off_map_rate,
                    found,
                    on.ece,
                    on.r_at_100p,
                ]) {
                    *s += v / worlds as f64;
                }
            }
            println!(
                "{temperature:>6.3} {margin:>7.2} {:>6.3} {:>6.3} {:>9.3} {:>9.3} {:>6.3} {:>7.3}",
                sums[0], sums[1], sums[2], sums[3], sums[4], sums[5]
            );
        }
    }
    Ok(())
}

/// Share of frames flagged off-map when a stream from another world is localized in `map`,
/// after a 10-frame settling period.
fn off_map_rate(
    map: &Arc<topoloc::Map>,
    sequence: &topoloc_synthetic::Sequence,
    options: LocalizerOptions,
) -> Result<f64> {
    let mut localizer = Localizer::new(map.clone(), options)?;
    let mut out = Localization::default();
    let mut flagged = 0usize;
    let settle = 10.min(sequence.frames.len());
    for (i, f) in sequence.frames.iter().enumerate() {
        let frame = Frame {
            timestamp: f.timestamp,
            descriptor: &f.descriptor,
            odometry: Some(f.odometry),
            image: None,
        };
        localizer.process(&frame, &mut out)?;
        flagged += usize::from(i >= settle && out.off_map);
    }
    Ok(flagged as f64 / (sequence.frames.len() - settle).max(1) as f64)
}
