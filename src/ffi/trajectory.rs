//! C functions of trajectory metrics (ABI 1.11): ATE, ARE, RPE and R_traj of an estimate
//! against its reference, with evo's association and Umeyama alignment.

use super::boundary::{run, slice, string};
use super::convert::pose_to_row_major;
use super::error::FfiError;
use super::status::topoloc_status::{self, *};
use super::versioned::{
    check_versioned, init_versioned, read_optional, versioned, write_versioned,
};
use crate::eval::{
    evaluate, Alignment, ErrorStats, Trajectory, TrajectoryError, TrajectoryFormat,
    TrajectoryOptions, TrajectoryReport,
};
use nalgebra::{Isometry3, Translation3};
use std::ffi::c_char;

/// An alignment of `topoloc_trajectory_options`: one of the `TOPOLOC_ALIGN_*` values.
pub type topoloc_alignment = u32;
/// No alignment: both trajectories are in one world frame.
pub const TOPOLOC_ALIGN_NONE: topoloc_alignment = 0;
/// Rigid Umeyama alignment (rotation, translation).
pub const TOPOLOC_ALIGN_SE3: topoloc_alignment = 1;
/// Umeyama alignment with scale (the seed thesis's; monocular estimates need it).
pub const TOPOLOC_ALIGN_SIM3: topoloc_alignment = 2;

/// A trajectory file format of `topoloc_trajectory_evaluate_files`: one of the
/// `TOPOLOC_TRAJECTORY_*` values.
pub type topoloc_trajectory_format = u32;
/// Detected from the first data line (8 numbers TUM, 12 KITTI, commas EuRoC).
pub const TOPOLOC_TRAJECTORY_DETECT: topoloc_trajectory_format = 0;
/// TUM: `timestamp tx ty tz qx qy qz qw`.
pub const TOPOLOC_TRAJECTORY_TUM: topoloc_trajectory_format = 1;
/// KITTI odometry: 12 numbers, row-major 3x4; the frame index is the timestamp.
pub const TOPOLOC_TRAJECTORY_KITTI: topoloc_trajectory_format = 2;
/// EuRoC ground-truth CSV: `timestamp_ns, px, py, pz, qw, qx, qy, qz, ...`.
pub const TOPOLOC_TRAJECTORY_EUROC: topoloc_trajectory_format = 3;

/// How trajectories are associated and aligned. Initialise with
/// `topoloc_trajectory_options_default`.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_trajectory_options {
    /// `sizeof(topoloc_trajectory_options)`, set by the `_default` function.
    pub struct_size: usize,
    /// `TOPOLOC_ALIGN_*`. Default `TOPOLOC_ALIGN_SIM3`.
    pub alignment: topoloc_alignment,
    /// Largest timestamp difference of an associated pair, seconds.
    pub max_diff_s: f64,
    /// Added to the estimate's timestamps before associating, seconds.
    pub offset_s: f64,
    /// The RPE's step in associated poses.
    pub rpe_delta: u32,
}

versioned! {
    topoloc_trajectory_options {
        let d = TrajectoryOptions::default();
        Self {
            alignment: TOPOLOC_ALIGN_SIM3,
            max_diff_s: d.max_diff_s,
            offset_s: d.offset_s,
            rpe_delta: d.rpe_delta as u32,
        }
    }
}

/// Fills the first `size` bytes of `*options` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_trajectory_options_default(options)`.
#[no_mangle]
pub extern "C" fn topoloc_trajectory_options_init(
    options: *mut topoloc_trajectory_options,
    size: usize,
) -> topoloc_status {
    init_versioned(options, size, "options")
}

/// Statistics of one error over the associated poses. Array element: its layout never
/// changes.
#[repr(C)]
#[derive(Clone, Copy, Default)]
pub struct topoloc_error_stats {
    /// Root mean square.
    pub rmse: f64,
    /// Mean.
    pub mean: f64,
    /// Median.
    pub median: f64,
    /// Population standard deviation.
    pub std: f64,
    /// Smallest.
    pub min: f64,
    /// Largest.
    pub max: f64,
}

/// What `topoloc_trajectory_evaluate` measured. The caller sets `struct_size` with
/// `topoloc_trajectory_report_default`; topoloc writes the rest.
#[repr(C)]
#[derive(Clone, Copy)]
pub struct topoloc_trajectory_report {
    /// `sizeof(topoloc_trajectory_report)`, set by the `_default` function.
    pub struct_size: usize,
    /// Associated pose pairs.
    pub pairs: usize,
    /// The alignment's scale (1 unless `TOPOLOC_ALIGN_SIM3`).
    pub scale: f64,
    /// The alignment's rotation and translation as a row-major 4x4 (identity for
    /// `TOPOLOC_ALIGN_NONE`): an aligned estimate position is `scale * R p + t`.
    pub alignment: [f64; 16],
    /// ATE: position error, metres.
    pub ate_m: topoloc_error_stats,
    /// ARE: rotation error, degrees.
    pub are_deg: topoloc_error_stats,
    /// RPE over `rpe_delta` poses, translation, metres.
    pub rpe_m: topoloc_error_stats,
    /// RPE, rotation, degrees.
    pub rpe_deg: topoloc_error_stats,
    /// The aligned estimate's path length, metres.
    pub estimate_length_m: f64,
    /// The reference's path length, metres.
    pub reference_length_m: f64,
    /// R_traj: `estimate_length_m / reference_length_m` (0 for a reference of no length).
    pub length_ratio: f64,
}

versioned! {
    topoloc_trajectory_report {
        Self {
            pairs: 0,
            scale: 1.0,
            alignment: pose_to_row_major(&Isometry3::identity()),
            ate_m: topoloc_error_stats::default(),
            are_deg: topoloc_error_stats::default(),
            rpe_m: topoloc_error_stats::default(),
            rpe_deg: topoloc_error_stats::default(),
            estimate_length_m: 0.0,
            reference_length_m: 0.0,
            length_ratio: 0.0,
        }
    }
}

/// Fills the first `size` bytes of `*report` with defaults and sets `struct_size`; call it
/// through the header macro `topoloc_trajectory_report_default(report)`.
#[no_mangle]
pub extern "C" fn topoloc_trajectory_report_init(
    report: *mut topoloc_trajectory_report,
    size: usize,
) -> topoloc_status {
    init_versioned(report, size, "report")
}

/// Judges an estimated trajectory against its reference (as `evo_ape` / `evo_rpe`): pairs by
/// timestamps, aligns, measures. Each trajectory is `count` timestamps (seconds, not
/// decreasing) and `count` poses of 7 doubles, `tx ty tz qx qy qz qw` (TUM's layout:
/// `world_T_body`, unit quaternion with w last). `options` may be NULL for defaults. On
/// success `*report` is written; on error it is unchanged. Thread-safe (no state).
/// Errors: `_INVALID_ARGUMENT` (counts, decreasing timestamps, a quaternion whose norm is not 1, no
/// associated pair, fewer than 3 pairs to align or `rpe_delta + 1` to measure, degenerate
/// positions), `_NON_FINITE`, `_INVALID_OPTION`.
#[no_mangle]
pub extern "C" fn topoloc_trajectory_evaluate(
    reference_timestamps: *const f64,
    reference_poses: *const f64,
    reference_count: usize,
    estimate_timestamps: *const f64,
    estimate_poses: *const f64,
    estimate_count: usize,
    options: *const topoloc_trajectory_options,
    report: *mut topoloc_trajectory_report,
) -> topoloc_status {
    evaluate_into(report, options, || {
        let reference = trajectory(
            reference_timestamps,
            reference_poses,
            reference_count,
            "reference",
        )?;
        let estimate = trajectory(
            estimate_timestamps,
            estimate_poses,
            estimate_count,
            "estimate",
        )?;
        Ok((reference, estimate))
    })
}

/// `topoloc_trajectory_evaluate` of two trajectory files (UTF-8 paths) in `format`
/// (`TOPOLOC_TRAJECTORY_*`; `_DETECT` tells each file's format from its first data line).
/// Errors: those of `topoloc_trajectory_evaluate`, `_IO` (unreadable file), `_INVALID_ARGUMENT` (a
/// malformed line: the message names it; an unknown format).
#[no_mangle]
pub extern "C" fn topoloc_trajectory_evaluate_files(
    reference_path: *const c_char,
    estimate_path: *const c_char,
    format: topoloc_trajectory_format,
    options: *const topoloc_trajectory_options,
    report: *mut topoloc_trajectory_report,
) -> topoloc_status {
    evaluate_into(report, options, || {
        let reference = read_file(string(reference_path, "reference_path")?, format)?;
        let estimate = read_file(string(estimate_path, "estimate_path")?, format)?;
        Ok((reference, estimate))
    })
}

/// The body of both evaluating functions: checks `report`, reads the options, then the
/// trajectories (`reference`, `estimate`), and writes what evaluating them measured.
fn evaluate_into(
    report: *mut topoloc_trajectory_report,
    options: *const topoloc_trajectory_options,
    trajectories: impl FnOnce() -> Result<(Trajectory, Trajectory), FfiError>,
) -> topoloc_status {
    run(|| {
        check_versioned(report, "report")?;
        let options = trajectory_options(options)?;
        let (reference, estimate) = trajectories()?;
        let judged = evaluate(&reference, &estimate, &options)?;
        write_versioned(report, c_report(&judged), "report")
    })
}

fn trajectory_options(
    options: *const topoloc_trajectory_options,
) -> Result<TrajectoryOptions, FfiError> {
    let o = read_optional(options, "options")?;
    let alignment = match o.alignment {
        TOPOLOC_ALIGN_NONE => Alignment::None,
        TOPOLOC_ALIGN_SE3 => Alignment::Se3,
        TOPOLOC_ALIGN_SIM3 => Alignment::Sim3,
        other => {
            return Err(FfiError::invalid_option(format!(
                "options.alignment is {other}, not a TOPOLOC_ALIGN_* value"
            )))
        }
    };
    Ok(TrajectoryOptions {
        alignment,
        max_diff_s: o.max_diff_s,
        offset_s: o.offset_s,
        rpe_delta: o.rpe_delta as usize,
    })
}

/// A trajectory from the C arrays (`count` timestamps, `7 * count` pose values).
fn trajectory(
    timestamps: *const f64,
    poses: *const f64,
    count: usize,
    name: &str,
) -> Result<Trajectory, FfiError> {
    let n = count
        .checked_mul(7)
        .ok_or_else(|| FfiError::invalid(format!("{name}_count {count} is too large")))?;
    let stamps = slice(timestamps, count, &format!("{name}_timestamps"))?;
    let values = slice(poses, n, &format!("{name}_poses"))?;
    if let Some(i) = values.iter().chain(stamps).position(|v| !v.is_finite()) {
        return Err(FfiError::new(
            TOPOLOC_ERR_NON_FINITE,
            format!("{name}: value {i} of the poses and timestamps is not finite"),
        ));
    }
    Ok(Trajectory::from_tum_values(stamps.to_vec(), values)?)
}

fn read_file(path: &str, format: topoloc_trajectory_format) -> Result<Trajectory, FfiError> {
    let format = match format {
        TOPOLOC_TRAJECTORY_DETECT => None,
        TOPOLOC_TRAJECTORY_TUM => Some(TrajectoryFormat::Tum),
        TOPOLOC_TRAJECTORY_KITTI => Some(TrajectoryFormat::Kitti),
        TOPOLOC_TRAJECTORY_EUROC => Some(TrajectoryFormat::Euroc),
        other => {
            return Err(FfiError::invalid(format!(
                "format is {other}, not a TOPOLOC_TRAJECTORY_* value"
            )))
        }
    };
    Trajectory::read(std::path::Path::new(path), format).map_err(|e| match e {
        TrajectoryError::Io(_) => e.into(),
        e => FfiError::invalid(format!("{path}: {e}")),
    })
}

fn c_stats(s: &ErrorStats) -> topoloc_error_stats {
    topoloc_error_stats {
        rmse: s.rmse,
        mean: s.mean,
        median: s.median,
        std: s.std,
        min: s.min,
        max: s.max,
    }
}

fn c_report(r: &TrajectoryReport) -> topoloc_trajectory_report {
    let alignment = pose_to_row_major(&Isometry3::from_parts(
        Translation3::from(r.alignment.translation),
        r.alignment.rotation,
    ));
    topoloc_trajectory_report {
        pairs: r.pairs,
        scale: r.alignment.scale,
        alignment,
        ate_m: c_stats(&r.ate_m),
        are_deg: c_stats(&r.are_deg),
        rpe_m: c_stats(&r.rpe_m),
        rpe_deg: c_stats(&r.rpe_deg),
        estimate_length_m: r.estimate_length_m,
        reference_length_m: r.reference_length_m,
        length_ratio: r.length_ratio,
        ..topoloc_trajectory_report::default()
    }
}
