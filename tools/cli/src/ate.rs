//! `topoloc ate`: how far an estimated trajectory is from its ground truth.
//!
//! ```text
//! topoloc ate EST GT [--align none|se3|sim3] [--format tum|kitti|euroc] [--json]
//! ```
//! Associates the two by timestamps (within `--max-diff` seconds, the estimate shifted by
//! `--offset`), aligns the estimate (Umeyama; `sim3`, the default, also corrects its scale)
//! and prints ATE and ARE (RMSE, mean, median, max), RPE over `--delta` poses, and R_traj, as
//! `evo_ape` / `evo_rpe` compute them. Formats are detected from the first data line (8
//! numbers TUM, 12 KITTI, comma-separated EuRoC) unless given; KITTI files take their
//! timestamps from `--est-times` / `--gt-times` (one per line), else the frame index.

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use serde_json::json;
use std::path::{Path, PathBuf};
use topoloc::eval::{
    evaluate, Alignment, ErrorStats, Trajectory, TrajectoryError, TrajectoryFormat,
    TrajectoryOptions,
};

/// Options of `ate`.
#[derive(Args, Clone, Debug)]
pub struct AteArgs {
    /// The estimated trajectory.
    pub estimate: PathBuf,
    /// The ground-truth (reference) trajectory.
    pub ground_truth: PathBuf,
    /// How the estimate is aligned to the ground truth.
    #[arg(long, value_enum, default_value_t = AlignArg::Sim3)]
    pub align: AlignArg,
    /// Format of both files [default: detected per file].
    #[arg(long, value_enum)]
    pub format: Option<FormatArg>,
    /// Timestamps of a KITTI estimate, one per line.
    #[arg(long)]
    pub est_times: Option<PathBuf>,
    /// Timestamps of a KITTI ground truth, one per line.
    #[arg(long)]
    pub gt_times: Option<PathBuf>,
    /// Largest timestamp difference of an associated pair, seconds.
    #[arg(long, default_value_t = TrajectoryOptions::default().max_diff_s)]
    pub max_diff: f64,
    /// Added to the estimate's timestamps, seconds.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub offset: f64,
    /// The RPE's step, in associated poses.
    #[arg(long, default_value_t = TrajectoryOptions::default().rpe_delta)]
    pub delta: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// `--align`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum AlignArg {
    /// As given.
    None,
    /// Rigid (rotation and translation).
    Se3,
    /// Rigid and scale.
    Sim3,
}

/// `--format`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// `timestamp tx ty tz qx qy qz qw`.
    Tum,
    /// 12 numbers per line, row-major 3x4.
    Kitti,
    /// EuRoC ground-truth CSV.
    Euroc,
}

/// Runs the command.
pub fn run(args: &AteArgs) -> Result<()> {
    let estimate = read(&args.estimate, args.format, args.est_times.as_deref())?;
    let truth = read(&args.ground_truth, args.format, args.gt_times.as_deref())?;
    let options = TrajectoryOptions {
        alignment: match args.align {
            AlignArg::None => Alignment::None,
            AlignArg::Se3 => Alignment::Se3,
            AlignArg::Sim3 => Alignment::Sim3,
        },
        max_diff_s: args.max_diff,
        offset_s: args.offset,
        rpe_delta: args.delta,
    };
    let report = evaluate(&truth, &estimate, &options)?;
    let stats = |s: &ErrorStats| {
        json!({"rmse": s.rmse, "mean": s.mean, "median": s.median, "std": s.std,
               "min": s.min, "max": s.max})
    };
    if args.json {
        println!(
            "{}",
            json!({
                "estimate": args.estimate.display().to_string(),
                "ground_truth": args.ground_truth.display().to_string(),
                "alignment": options.alignment.name(),
                "pairs": report.pairs,
                "scale": report.alignment.scale,
                "ate_m": stats(&report.ate_m),
                "are_deg": stats(&report.are_deg),
                "rpe_m": stats(&report.rpe_m),
                "rpe_deg": stats(&report.rpe_deg),
                "rpe_delta": options.rpe_delta,
                "estimate_length_m": report.estimate_length_m,
                "ground_truth_length_m": report.reference_length_m,
                "r_traj": report.length_ratio,
            })
        );
        return Ok(());
    }
    let line = |name: &str, unit: &str, s: &ErrorStats| {
        println!(
            "{name:4} RMSE {:.6} {unit}  mean {:.6}  median {:.6}  max {:.6}",
            s.rmse, s.mean, s.median, s.max
        )
    };
    println!(
        "{} pairs, alignment {} (scale {:.6})",
        report.pairs,
        options.alignment.name(),
        report.alignment.scale
    );
    line("ATE", "m", &report.ate_m);
    line("ARE", "deg", &report.are_deg);
    line("RPE", "m", &report.rpe_m);
    line("RPE", "deg", &report.rpe_deg);
    println!(
        "R_traj {:.4} (estimate {:.3} m, ground truth {:.3} m)",
        report.length_ratio, report.estimate_length_m, report.reference_length_m
    );
    Ok(())
}

/// A trajectory file in `format` (detected when `None`), with KITTI timestamps from `times`.
fn read(path: &Path, format: Option<FormatArg>, times: Option<&Path>) -> Result<Trajectory> {
    let format = format.map(|f| match f {
        FormatArg::Tum => TrajectoryFormat::Tum,
        FormatArg::Kitti => TrajectoryFormat::Kitti,
        FormatArg::Euroc => TrajectoryFormat::Euroc,
    });
    let trajectory = Trajectory::read(path, format).map_err(|e| match e {
        TrajectoryError::UnknownFormat => anyhow::anyhow!("{}: {e}; pass --format", path.display()),
        e => anyhow::Error::new(e).context(path.display().to_string()),
    })?;
    let Some(times) = times else {
        return Ok(trajectory);
    };
    let text =
        std::fs::read_to_string(times).with_context(|| format!("reading {}", times.display()))?;
    let stamps = text
        .split_whitespace()
        .map(str::parse::<f64>)
        .collect::<Result<Vec<_>, _>>()
        .with_context(|| format!("{}: one number per line", times.display()))?;
    trajectory
        .with_timestamps(stamps)
        .with_context(|| format!("{} with {}", path.display(), times.display()))
}
