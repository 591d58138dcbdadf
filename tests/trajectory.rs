//! Trajectory metrics: alignment recovers a known similarity, the errors are the ones put in,
//! association follows evo's rules, the three file formats parse, and bad input is a typed
//! error. The agreement with evo itself is checked from Python (python/tests/test_trajectory.py).

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use topoloc::eval::{
    associate, evaluate, umeyama, Alignment, Trajectory, TrajectoryError, TrajectoryFormat,
    TrajectoryOptions,
};

/// A 3D loop: `n` poses at 10 Hz on a circle of radius 5 m that climbs 2 m, facing along it.
fn ground_truth(n: usize) -> Trajectory {
    let poses = (0..n)
        .map(|i| {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            Isometry3::from_parts(
                Translation3::new(5.0 * a.cos(), 5.0 * a.sin(), 2.0 * i as f64 / n as f64),
                UnitQuaternion::from_euler_angles(0.1 * a.sin(), 0.05, a + 1.57),
            )
        })
        .collect();
    Trajectory::new((0..n).map(|i| i as f64 * 0.1).collect(), poses).unwrap()
}

/// `trajectory` moved by the similarity (scale, rotation, translation) of its world frame.
fn transformed(trajectory: &Trajectory, scale: f64, motion: Isometry3<f64>) -> Trajectory {
    let poses = trajectory
        .poses
        .iter()
        .map(|p| {
            Isometry3::from_parts(
                Translation3::from(motion * (p.translation.vector * scale)),
                motion.rotation * p.rotation,
            )
        })
        .collect();
    Trajectory::new(trajectory.timestamps.clone(), poses).unwrap()
}

fn motion() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(3.0, -1.0, 0.5),
        UnitQuaternion::from_euler_angles(0.2, -0.1, 0.7),
    )
}

fn with(alignment: Alignment) -> TrajectoryOptions {
    TrajectoryOptions {
        alignment,
        ..TrajectoryOptions::default()
    }
}

#[test]
fn sim3_alignment_recovers_a_scaled_moved_copy_exactly() {
    let truth = ground_truth(120);
    let estimate = transformed(&truth, 0.5, motion());
    let report = evaluate(&truth, &estimate, &with(Alignment::Sim3)).unwrap();
    assert_eq!(report.pairs, 120);
    assert!(report.ate_m.rmse < 1e-9, "{report:?}");
    assert!(report.are_deg.max < 1e-6, "{report:?}");
    assert!((report.alignment.scale - 2.0).abs() < 1e-9, "{report:?}");
    assert!((report.length_ratio - 1.0).abs() < 1e-9, "{report:?}");
    assert!(report.rpe_m.max < 1e-9 && report.rpe_deg.max < 1e-6);
    // A rigid alignment cannot undo the scale; no alignment cannot undo the motion.
    let rigid = evaluate(&truth, &estimate, &with(Alignment::Se3)).unwrap();
    assert!(
        rigid.ate_m.rmse > 1.0 && rigid.alignment.scale == 1.0,
        "{rigid:?}"
    );
    assert!(
        rigid.are_deg.max < 1e-6,
        "the rotation is still recovered: {rigid:?}"
    );
    let none = evaluate(&truth, &estimate, &with(Alignment::None)).unwrap();
    assert!(none.ate_m.rmse > rigid.ate_m.rmse, "{none:?}");
}

#[test]
fn the_errors_are_the_offsets_put_in() {
    let truth = ground_truth(100);
    // Every other pose 0.3 m off along x, the rest 0.1 m along z: RMSE sqrt((0.09+0.01)/2).
    let offsets: Vec<Vector3<f64>> = (0..100)
        .map(|i| match i % 2 {
            0 => Vector3::new(0.3, 0.0, 0.0),
            _ => Vector3::new(0.0, 0.0, 0.1),
        })
        .collect();
    let poses = truth
        .poses
        .iter()
        .zip(&offsets)
        .map(|(p, o)| {
            Isometry3::from_parts(Translation3::from(p.translation.vector + o), p.rotation)
        })
        .collect();
    let estimate = Trajectory::new(truth.timestamps.clone(), poses).unwrap();
    let report = evaluate(&truth, &estimate, &with(Alignment::None)).unwrap();
    assert!(
        (report.ate_m.rmse - 0.05f64.sqrt()).abs() < 1e-12,
        "{report:?}"
    );
    assert!((report.ate_m.mean - 0.2).abs() < 1e-12 && (report.ate_m.median - 0.2).abs() < 1e-12);
    assert!((report.ate_m.max - 0.3).abs() < 1e-12 && (report.ate_m.min - 0.1).abs() < 1e-12);
    assert!((report.ate_m.std - 0.1).abs() < 1e-12, "{report:?}");
    assert!(report.are_deg.max < 1e-9);
    // Each step's motion is off by the difference of two offsets, |(0.3, 0, -0.1)|, seen in
    // the rotated frame of the first pose: the same length.
    let step = (0.09f64 + 0.01).sqrt();
    assert!((report.rpe_m.rmse - step).abs() < 1e-9, "{report:?}");
}

#[test]
fn association_pairs_the_nearest_timestamp_within_the_tolerance() {
    let truth = ground_truth(50);
    let shifted = |dt: f64| {
        Trajectory::new(
            truth.timestamps.iter().map(|t| t + dt).collect(),
            truth.poses.clone(),
        )
        .unwrap()
    };
    assert_eq!(
        associate(&truth, &shifted(0.004), 0.01, 0.0).unwrap().len(),
        50
    );
    assert!(matches!(
        associate(&truth, &shifted(0.03), 0.01, 0.0),
        Err(TrajectoryError::TooFewPairs(_))
    ));
    // The offset is added to the estimate's timestamps.
    assert_eq!(
        associate(&truth, &shifted(0.03), 0.01, -0.03)
            .unwrap()
            .len(),
        50
    );
    // A timestamp halfway between two takes the earlier; the shorter trajectory drives.
    let one = Trajectory::new(vec![0.15], vec![Isometry3::identity()]).unwrap();
    assert_eq!(associate(&truth, &one, 0.1, 0.0).unwrap(), vec![(1, 0)]);
    assert_eq!(associate(&one, &truth, 0.1, 0.0).unwrap(), vec![(0, 1)]);
    assert!(matches!(
        associate(&truth, &one, f64::NAN, 0.0),
        Err(TrajectoryError::InvalidOption(_))
    ));
}

#[test]
fn a_sparse_estimate_has_a_short_length_ratio() {
    let truth = ground_truth(200);
    // Keyframes of the first half only.
    let half = Trajectory::new(
        truth.timestamps[..100].to_vec(),
        truth.poses[..100].to_vec(),
    )
    .unwrap();
    let report = evaluate(&truth, &half, &TrajectoryOptions::default()).unwrap();
    assert_eq!(report.pairs, 100);
    assert!((report.length_ratio - 0.5).abs() < 0.02, "{report:?}");
}

#[test]
fn collinear_positions_cannot_be_aligned() {
    let line: Vec<Isometry3<f64>> = (0..10)
        .map(|i| Isometry3::translation(i as f64, 0.0, 0.0))
        .collect();
    let truth = Trajectory::new((0..10).map(f64::from).collect(), line).unwrap();
    assert_eq!(
        evaluate(&truth, &truth, &with(Alignment::Se3)),
        Err(TrajectoryError::Degenerate)
    );
    assert!(evaluate(&truth, &truth, &with(Alignment::None)).is_ok());
    let points: Vec<Vector3<f64>> = truth.poses.iter().map(|p| p.translation.vector).collect();
    assert!(matches!(
        umeyama(&points[..2], &points[..2], true),
        Err(TrajectoryError::TooFewPairs(_))
    ));
}

#[test]
fn the_three_formats_parse_to_the_same_poses() {
    let tum = "# timestamp tx ty tz qx qy qz qw\n\
               1.0 1 2 3 0 0 0.7071067811865476 0.7071067811865476\n\
               \n\
               2.0 4 5 6 0 0 0 1\n";
    let euroc = "#timestamp, p_x, p_y, p_z, q_w, q_x, q_y, q_z, v_x\n\
                 1000000000,1,2,3,0.7071067811865476,0,0,0.7071067811865476,9\n\
                 2000000000,4,5,6,1,0,0,0,9\n";
    let kitti = "0 -1 0 1 1 0 0 2 0 0 1 3\n1 0 0 4 0 1 0 5 0 0 1 6\n";
    let a = Trajectory::parse(tum, TrajectoryFormat::Tum).unwrap();
    let b = Trajectory::parse(euroc, TrajectoryFormat::Euroc).unwrap();
    let c = Trajectory::parse(kitti, TrajectoryFormat::Kitti)
        .unwrap()
        .with_timestamps(vec![1.0, 2.0])
        .unwrap();
    for other in [&b, &c] {
        assert_eq!(other.timestamps, a.timestamps);
        for (p, q) in a.poses.iter().zip(&other.poses) {
            assert!((p.translation.vector - q.translation.vector).norm() < 1e-12);
            assert!(p.rotation.angle_to(&q.rotation) < 1e-9, "{p} vs {q}");
        }
    }
    assert_eq!(
        Trajectory::parse(kitti, TrajectoryFormat::Kitti)
            .unwrap()
            .timestamps,
        [0.0, 1.0]
    );
    assert_eq!(TrajectoryFormat::detect(tum), Some(TrajectoryFormat::Tum));
    assert_eq!(
        TrajectoryFormat::detect(euroc),
        Some(TrajectoryFormat::Euroc)
    );
    assert_eq!(
        TrajectoryFormat::detect(kitti),
        Some(TrajectoryFormat::Kitti)
    );
    assert_eq!(TrajectoryFormat::detect("1 2 3\n"), None);
}

#[test]
fn bad_files_are_typed_errors_that_name_the_line() {
    let cases = [
        ("1 2 3 4 5 6 7\n", 1, "8"),
        ("# c\n1 0 0 0 0 0 0 1\n2 nan 0 0 0 0 0 1\n", 3, "not finite"),
        ("1 0 0 0 0 0 0 2\n", 1, "norm"),
        ("1 0 0 0 0 0 0 1\n2 x 0 0 0 0 0 1\n", 2, "not a number"),
    ];
    for (text, line, needle) in cases {
        match Trajectory::parse(text, TrajectoryFormat::Tum) {
            Err(TrajectoryError::Parse { line: l, message }) => {
                assert_eq!(l, line, "{text:?}: {message}");
                assert!(message.contains(needle), "{text:?}: {message}");
            }
            other => panic!("{text:?}: {other:?}"),
        }
    }
    let sheared = "1 0.5 0 0 0 1 0 0 0 0 1 0\n";
    assert!(matches!(
        Trajectory::parse(sheared, TrajectoryFormat::Kitti),
        Err(TrajectoryError::Parse { message, .. }) if message.contains("not a rotation")
    ));
    let mirrored = "-1 0 0 0 0 1 0 0 0 0 1 0\n";
    assert!(Trajectory::parse(mirrored, TrajectoryFormat::Kitti).is_err());
    assert!(matches!(
        Trajectory::parse("2 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n", TrajectoryFormat::Tum),
        Err(TrajectoryError::Invalid(m)) if m.contains("earlier")
    ));
    assert!(matches!(
        Trajectory::new(vec![0.0], vec![]),
        Err(TrajectoryError::Invalid(_))
    ));
    let truth = ground_truth(10);
    assert!(matches!(
        evaluate(
            &truth,
            &truth,
            &TrajectoryOptions {
                rpe_delta: 0,
                ..Default::default()
            }
        ),
        Err(TrajectoryError::InvalidOption(_))
    ));
    assert!(matches!(
        evaluate(
            &truth,
            &truth,
            &TrajectoryOptions {
                rpe_delta: 10,
                ..Default::default()
            }
        ),
        Err(TrajectoryError::TooFewPairs(_))
    ));
    assert!(matches!(
        Trajectory::read(
            std::path::Path::new("/nonexistent/t.txt"),
            Some(TrajectoryFormat::Tum)
        ),
        Err(TrajectoryError::Io(_))
    ));
}
