//! The `topoloc` command: the demo (the README's main job), and benchmark helpers.

mod demo;
mod images;
mod memory;
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
        #[arg(long, value_delimiter = ',', default_value = "0.01,0.02,0.03,0.05")]
        temperatures: Vec<f32>,
        /// Off-map margins to try.
        #[arg(long, value_delimiter = ',', default_value = "0,0.5,1,2")]
        margins: Vec<f32>,
    },
    /// Place recognition on frame-aligned image folders with the ONNX multi-level backend.
    EvalImages {
        /// Folder of map (reference) images, in frame order.
        #[arg(long)]
        map_images: PathBuf,
        /// Folder of query images; query frame i matches map frame i.
        #[arg(long)]
        images: PathBuf,
        /// Frame tolerance for a correct match.
        #[arg(long, default_value_t = 2)]
        tolerance: usize,
        /// PCA output dimension (limited by the number of map frames).
        #[arg(long, default_value_t = 512)]
        dim: usize,
        /// Network outputs to pool (comma-separated).
        #[arg(long, value_delimiter = ',', default_value = "f6,f13,f17,f18")]
        taps: Vec<String>,
        /// Pooling grid per tap, ROWSxCOLS.
        #[arg(long, default_value = "4x4")]
        grid: String,
        /// Localizer temperature (the library default).
        #[arg(long, default_value_t = 0.2)]
        temperature: f32,
        /// Most map frames the PCA is fitted on (evenly spaced).
        #[arg(long, default_value_t = 1000)]
        pca_samples: usize,
        /// Print JSON.
        #[arg(long)]
        json: bool,
    },
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
        Command::EvalImages {
            map_images,
            images,
            tolerance,
            dim,
            taps,
            grid,
            temperature,
            pca_samples,
            json,
        } => {
            let (rows, cols) = grid
                .split_once('x')
                .ok_or_else(|| anyhow::anyhow!("--grid must look like 4x4"))?;
            let grid = (rows.parse()?, cols.parse()?);
            images::run(&images::EvalImagesArgs {
                map_images,
                images,
                tolerance,
                dim,
                taps,
                grid,
                temperature,
                pca_samples,
                json,
            })
        }
        Command::MeasureMap { map } => memory::measure(&map),
    }
}
