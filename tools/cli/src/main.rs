//! The `topoloc` command: the demo (the README's main job), maps from images, simulated
//! datasets, evaluation, and benchmark helpers.

mod ate;
mod backend_args;
mod build_map;
mod demo;
mod eval;
mod frames;
mod localize;
mod loops;
mod memory;
mod odometry;
mod off_world;
mod plot;
mod process;
mod progress;
mod scaling;
mod scenario_args;
mod sequence;
mod simulate;
mod stages;
mod suite;
mod sweep;
mod top_view;
mod verify_eval;

use anyhow::Result;
use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "topoloc",
    version,
    about = "Visual topological localization for SLAM: demo and tools"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate an indoor world, build its graph and map, fly a query trajectory under other
    /// light, localize every frame; print MNA/OHA/R@N, latency and memory; write a top view.
    Demo(demo::DemoArgs),
    /// Measure map file size, load time and resident memory, stage by stage: the map, its
    /// localizer (with the map's describer for maps built from images) and frames.
    BenchMemory(memory::BenchMemoryArgs),
    /// Sweep temperature and off-map margin on generated worlds (how the defaults were chosen).
    Sweep {
        /// Number of generated worlds (seeds 100..100+N, held out from the demo).
        #[arg(long, default_value_t = 3)]
        worlds: u64,
        /// Frames per on-map sequence (half as many off-map).
        #[arg(long, default_value_t = 1000)]
        frames: usize,
        /// Temperatures to try.
        #[arg(long, value_delimiter = ',', default_value = "0.1,0.2,0.3")]
        temperatures: Vec<f32>,
        /// Off-map margins to try.
        #[arg(long, value_delimiter = ',', default_value = "-1,0,1")]
        margins: Vec<f32>,
    },
    /// Time per-frame localization against map size (20 to 2,000 places by default, as the
    /// seed's Fig. 4.11): single-frame, filter and filter with odometry on generated corridor
    /// worlds; print a markdown table (median and p90 ms, descriptor memory) and write a PNG.
    Scaling(scaling::ScalingArgs),
    /// Build a map from an image folder or a KITTI, TUM RGB-D or EuRoC sequence folder; the
    /// describer (backend, PCA, codebook) is stored in it.
    BuildMap(build_map::BuildMapArgs),
    /// Localize a query image folder (or a dataset written by `simulate`) against a map built
    /// from images and report R@N, R@100P, latency (and MNA/OHA with ground-truth nodes or a
    /// dataset), single-frame and filtered.
    Eval(eval::EvalArgs),
    /// Localize a stream of frames (an image folder or a video) against a map, printing one
    /// result per frame as it goes (text, or JSON lines), optionally with TUM odometry.
    Localize(Box<localize::LocalizeArgs>),
    /// Verify the appearance top places of every query image against a map with keypoints
    /// and report how well inliers tell the true place from look-alikes (inlier medians,
    /// R@1 before and after re-ranking, times).
    EvalVerify(verify_eval::VerifyEvalArgs),
    /// Loop-closure hints over an image sequence (online graph growth, or a second session
    /// against --map): accepted hints to a CSV, gate counts and latency.
    Loops(Box<loops::LoopsArgs>),
    /// Generate world K of a split, build its graph and map (saved as OUT/map.topoloc) and write
    /// query trajectories as dataset folders OUT/traj-00i for `eval --dataset`.
    Simulate(simulate::SimulateArgs),
    /// The seed-style benchmark: MNA and OHA per split (train, tr-t, tr-a, test), mean and
    /// std over generated worlds, for every localizer configuration.
    Suite(suite::SuiteArgs),
    /// ATE, ARE, RPE and R_traj of an estimated trajectory against its ground truth (TUM,
    /// KITTI or EuRoC files; evo's association and Umeyama alignment).
    Ate(ate::AteArgs),
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Demo(args) => demo::run(&args),
        Command::BenchMemory(args) => memory::run(&args),
        Command::Sweep {
            worlds,
            frames,
            temperatures,
            margins,
        } => sweep::run(worlds, frames, &temperatures, &margins),
        Command::Scaling(args) => scaling::run(&args),
        Command::BuildMap(args) => build_map::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::Localize(args) => localize::run(&args),
        Command::EvalVerify(args) => verify_eval::run(&args),
        Command::Loops(args) => loops::run(&args),
        Command::Simulate(args) => simulate::run(&args),
        Command::Suite(args) => suite::run(&args),
        Command::Ate(args) => ate::run(&args),
    }
}
