//! The `topoloc` command: the demo (the README's main job), maps from images, evaluation, and
//! benchmark helpers.

mod backend_args;
mod build_map;
mod demo;
mod eval;
mod memory;
mod plot;
mod process;
mod sweep;

use anyhow::Result;
use clap::{Parser, Subcommand};
use std::path::PathBuf;

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
    /// Generate a world and a camera stream, localize every frame, print metrics and latency.
    Demo {
        /// World and sequence seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Places in the generated world (4 views each).
        #[arg(long, default_value_t = 120)]
        places: usize,
        /// Frames in the query sequence (10 Hz).
        #[arg(long, default_value_t = 1500)]
        frames: usize,
        /// Print one JSON object with the final figures instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Measure map file size, load time and resident memory of a loaded map plus localizer.
    BenchMemory {
        /// Views in the generated map (4 per place).
        #[arg(long, default_value_t = 10_000)]
        views: usize,
        /// Descriptor dimension.
        #[arg(long, default_value_t = 512)]
        dim: usize,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
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
    /// Build a map from an image folder; the describer (backend, PCA, codebook) is stored in it.
    BuildMap(build_map::BuildMapArgs),
    /// Localize a query image folder against a map built from images and report R@N, R@100P,
    /// latency (and MNA/OHA with ground-truth nodes), single-frame and filtered.
    Eval(eval::EvalArgs),
    /// (internal) Child process of bench-memory: load MAP and report its figures as JSON.
    #[command(hide = true)]
    MeasureMap { map: PathBuf },
}

fn main() -> Result<()> {
    match Cli::parse().command {
        Command::Demo {
            seed,
            places,
            frames,
            json,
        } => demo::run(&demo::DemoArgs {
            seed,
            places,
            frames,
            json,
        }),
        Command::BenchMemory { views, dim, json } => memory::run(views, dim, json),
        Command::Sweep {
            worlds,
            frames,
            temperatures,
            margins,
        } => sweep::run(worlds, frames, &temperatures, &margins),
        Command::BuildMap(args) => build_map::run(&args),
        Command::Eval(args) => eval::run(&args),
        Command::MeasureMap { map } => memory::measure(&map),
    }
}
