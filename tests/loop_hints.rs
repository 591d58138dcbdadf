//! Verified loop-closure hints: a route driven twice gives no hint on the first pass (nothing
//! outside the exclusion window, or other places' inliers too few), refuses the first revisits as not yet consistent, then
//! accepts one hint per keyframe naming the first visit; a look-alike (same descriptor,
//! another scene) is refused for its inliers; a shift with no parallax gets no pose with the
//! gate that says so; bad features and duplicate ids are typed errors that change nothing.

mod common;

use common::correspondences::{keypoints, scene, truth, CAMERA};
use common::images::{gray, place_image, revisit};
use common::{mix, unit_vector};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use topoloc::descriptor::DescriptorIdentity;
use topoloc::loops::{
    DatabaseOptions, Gate, HintOptions, KeyframeDatabase, KeyframeEntry, KeyframeFeatures,
    LoopDetector, LoopsError, OdometryGate,
};
use topoloc::map::{LoadOptions, Map};
use topoloc::verify::{
    CellDescriptor, Descriptors, FeatureKind, FundamentalEstimator, KeypointDetector, Keypoints,
    PairOptions, PinholeCamera,
};

const DIM: usize = 16;
const PLACES: u64 = 8;
/// Ids of the second pass start here.
const SECOND: u64 = 20;

fn detector(options: HintOptions) -> LoopDetector {
    let identity = DescriptorIdentity::new("test", "hints", DIM as u32).unwrap();
    let db = KeyframeDatabase::new(identity, DatabaseOptions::default()).unwrap();
    LoopDetector::new(db, options).unwrap()
}

/// The defaults scaled to these short routes: a 5-keyframe exclusion window, stretches of 2.
fn options() -> HintOptions {
    HintOptions {
        exclude_recent_ids: 5,
        exclude_recent_s: 5.0,
        candidate_id_gap: 2,
        ..HintOptions::default()
    }
}

fn features(image: &[u8]) -> KeyframeFeatures {
    KeyframeFeatures {
        keypoints: KeypointDetector::new(500)
            .unwrap()
            .detect(&gray(image))
            .unwrap(),
        camera_points: None,
    }
}

/// Keyframe `id` with the body's odometry pose.
fn posed(id: u64, descriptor: &[f32], pose: Isometry3<f64>) -> KeyframeEntry<'_> {
    KeyframeEntry {
        world_t_body: Some(pose),
        ..entry(id, descriptor)
    }
}

/// Features of generated correspondences (see `common::correspondences`), with their scene
/// points when the keyframe has them.
fn point_features(points: &[[f32; 2]], scene: Option<Vec<[f32; 3]>>) -> KeyframeFeatures {
    KeyframeFeatures {
        keypoints: keypoints(points),
        camera_points: scene,
    }
}

fn entry(id: u64, descriptor: &[f32]) -> KeyframeEntry<'_> {
    KeyframeEntry {
        id,
        timestamp: id as f64,
        descriptor,
        ..KeyframeEntry::default()
    }
}

/// The first pass: keyframe p sees place p.
fn first_pass(detector: &mut LoopDetector) {
    for p in 0..PLACES {
        let d = unit_vector(p, DIM);
        let done = detector
            .process(&entry(p, &d), features(&place_image(p)))
            .unwrap();
        // Early keyframes have nothing outside the window; later ones find earlier, other
        // places, whose inliers refuse them.
        assert!(
            matches!(done.gate(), Gate::NoCandidate | Gate::TooFewInliers),
            "first pass, keyframe {p}: {done:?}"
        );
    }
}

/// Keyframe `SECOND + p` revisits place p (shifted image, another exposure, noisy descriptor).
fn revisit_keyframe(detector: &mut LoopDetector, p: u64) -> topoloc::loops::Processed {
    revisit_at(detector, p, SECOND + p, (SECOND + p) as f64, None)
}

/// Keyframe `id`, taken at `timestamp` (at the body pose, if any), revisits place p.
fn revisit_at(
    detector: &mut LoopDetector,
    p: u64,
    id: u64,
    timestamp: f64,
    world_t_body: Option<Isometry3<f64>>,
) -> topoloc::loops::Processed {
    let d = mix(&unit_vector(p, DIM), &unit_vector(p + 1000, DIM), 0.2);
    let image = revisit(&place_image(p), p + 50);
    let keyframe = KeyframeEntry {
        timestamp,
        world_t_body,
        ..entry(id, &d)
    };
    detector.process(&keyframe, features(&image)).unwrap()
}

#[test]
fn a_second_pass_gets_one_consistent_hint_per_keyframe() {
    let mut detector = detector(options());
    first_pass(&mut detector);
    for p in 0..PLACES {
        let done = revisit_keyframe(&mut detector, p);
        let hint = done.hint.expect("a verified candidate");
        assert_eq!(hint.matched_id, p, "revisit of place {p}");
        assert!(hint.inliers >= 30, "{hint:?}");
        assert!(hint.confidence > 0.5, "{hint:?}");
        match p {
            0 | 1 => assert_eq!(
                hint.gate,
                Gate::Inconsistent {
                    agreeing: p as usize + 1
                }
            ),
            _ => {
                assert_eq!(hint.gate, Gate::Accepted, "keyframe {}", SECOND + p);
                assert!(hint.pose.is_none(), "no intrinsics, no pose");
                assert_eq!(done.accepted().map(|h| h.query_id), Some(SECOND + p));
            }
        }
        // The keyframe that completes the streak confirms the two that began it.
        let confirmed: Vec<(u64, u64)> = done
            .confirmed
            .iter()
            .inspect(|h| assert_eq!(h.gate, Gate::Accepted, "{h:?}"))
            .map(|h| (h.query_id, h.matched_id))
            .collect();
        let expected = match p {
            2 => vec![(SECOND, 0), (SECOND + 1, 1)],
            _ => vec![],
        };
        assert_eq!(confirmed, expected, "confirmed by keyframe {}", SECOND + p);
    }
}

#[test]
fn a_broken_streak_confirms_nothing_and_an_erased_keyframe_is_never_confirmed() {
    // Broken: the look-alike refuses, the next revisit starts again from one.
    let mut detector = detector(options());
    first_pass(&mut detector);
    revisit_keyframe(&mut detector, 0);
    let look_alike = unit_vector(1, DIM);
    detector
        .process(&entry(SECOND + 1, &look_alike), features(&place_image(777)))
        .unwrap();
    for p in 2..5 {
        let done = revisit_keyframe(&mut detector, p);
        let expected: Vec<u64> = match p {
            4 => vec![SECOND + 2, SECOND + 3],
            _ => vec![],
        };
        let got: Vec<u64> = done.confirmed.iter().map(|h| h.query_id).collect();
        assert_eq!(
            got,
            expected,
            "keyframe {}: the pending ones since the break",
            SECOND + p
        );
    }
    // Erased: a pending hint from or to an erased keyframe is dropped.
    let mut detector = detector_with_pending_streak();
    detector.erase(SECOND).unwrap();
    detector.erase(1).unwrap();
    let done = revisit_keyframe(&mut detector, 2);
    assert_eq!(done.accepted().map(|h| h.matched_id), Some(2), "{done:?}");
    assert!(done.confirmed.is_empty(), "{:?}", done.confirmed);
}

/// A detector after the first pass and two revisits (places 0 and 1) refused as inconsistent.
fn detector_with_pending_streak() -> LoopDetector {
    let mut detector = detector(options());
    first_pass(&mut detector);
    for p in 0..2 {
        let gate = revisit_keyframe(&mut detector, p).gate();
        assert!(matches!(gate, Gate::Inconsistent { .. }), "{gate:?}");
    }
    detector
}

#[test]
fn a_look_alike_is_refused_for_its_inliers_and_breaks_the_streak() {
    let mut detector = detector(options());
    first_pass(&mut detector);
    for p in 0..3 {
        revisit_keyframe(&mut detector, p);
    }
    // Place 3's descriptor, another scene.
    let d = unit_vector(3, DIM);
    let done = detector
        .process(&entry(SECOND + 3, &d), features(&place_image(777)))
        .unwrap();
    let hint = done.hint.expect("the descriptor finds candidates");
    assert_eq!(hint.gate, Gate::TooFewInliers, "{hint:?}");
    assert!(hint.inliers < 30 && hint.confidence < 0.5, "{hint:?}");
    let after = revisit_keyframe(&mut detector, 4).hint.unwrap();
    assert_eq!(
        after.gate,
        Gate::Inconsistent { agreeing: 1 },
        "the streak restarted"
    );
}

#[test]
fn a_match_that_outruns_the_keyframes_breaks_the_streak() {
    // Revisit keyframes 0.2 s apart match first-pass keyframes 1 s apart: places 0, 1, 2
    // keep the pace (1 s <= 3 x 0.2 s + 0.5 s); a jump from place 2 to place 4 (2 s) does
    // not, though their groups overlap (2-3-4 in the place graph), unless the odometry put
    // keyframes 2 and 4 beside each other.
    let path = [0, 1, 2, 4, 5, 6];
    // Posed: keyframes 2.5 m apart along x (a place each), keyframe 4 2.5 m beside keyframe
    // 2; a revisit keyframe stands where the keyframe it revisits stood.
    let at = |p: u64| match p {
        4 => Isometry3::translation(5.0, 2.5, 0.0),
        _ => Isometry3::translation(2.5 * p as f64, 0.0, 0.0),
    };
    let run = |options: HintOptions, four_beside_two: bool| -> Vec<Gate> {
        let mut detector = detector(options);
        match four_beside_two {
            false => first_pass(&mut detector),
            true => {
                for p in 0..PLACES {
                    let d = unit_vector(p, DIM);
                    detector
                        .process(&posed(p, &d, at(p)), features(&place_image(p)))
                        .unwrap();
                }
            }
        }
        path.iter()
            .enumerate()
            .map(|(k, &p)| {
                let t = SECOND as f64 + 0.2 * k as f64;
                let pose = four_beside_two.then(|| at(p));
                let done = revisit_at(&mut detector, p, SECOND + k as u64, t, pose);
                let hint = done.hint.expect("a verified candidate");
                assert_eq!(hint.matched_id, p, "keyframe {k}");
                hint.gate
            })
            .collect()
    };
    let paced = run(options(), false);
    let consistent = |agreeing| Gate::Inconsistent { agreeing };
    assert_eq!(
        paced,
        [
            consistent(1),
            consistent(2),
            Gate::Accepted,
            consistent(1),
            consistent(2),
            Gate::Accepted
        ]
    );
    let unpaced = run(
        HintOptions {
            max_match_pace: 0.0,
            ..options()
        },
        false,
    );
    assert_eq!(&unpaced[..3], &paced[..3]);
    assert!(
        unpaced[3..].iter().all(|g| *g == Gate::Accepted),
        "{unpaced:?}"
    );
    assert_eq!(run(options(), true), unpaced, "one spot, passed twice");
}

#[test]
fn a_revisit_without_parallax_gets_the_rotation_and_no_translation() {
    let mut detector = detector(HintOptions {
        camera: Some(PinholeCamera {
            fx: 300.0,
            fy: 300.0,
            cx: 160.0,
            cy: 120.0,
        }),
        consistent_keyframes: 1,
        ..options()
    });
    first_pass(&mut detector);
    let hint = revisit_keyframe(&mut detector, 2).hint.unwrap();
    assert!(hint.accepted(), "a rotation is a pose: {hint:?}");
    let pose = hint.pose.expect("the rotation-only pose");
    assert!(!pose.scale_known);
    assert_eq!(pose.matched_t_query.translation.vector.norm(), 0.0);
    // The revisit is the place's image shifted 3 pixels left: a turn of atan(3 / 300) about y.
    let expected = (3.0f64 / 300.0).atan().to_degrees();
    let turn = pose.matched_t_query.rotation.angle().to_degrees();
    assert!(
        (turn - expected).abs() < 0.15,
        "{turn} deg, {expected} expected"
    );
    let axis = pose.matched_t_query.rotation.axis().unwrap();
    assert!(axis.y.abs() > 0.95, "about y: {axis:?}");
}

#[test]
fn the_work_done_is_counted_and_refinement_adds_the_stretch() {
    let mut work = Vec::new();
    for refine_keyframes in [0, 2] {
        let mut detector = detector(HintOptions {
            refine_keyframes,
            ..options()
        });
        first_pass(&mut detector);
        let done = revisit_keyframe(&mut detector, 3);
        assert_eq!(done.hint.unwrap().matched_id, 3, "{done:?}");
        assert_eq!(done.work.pose_fits, 0, "no intrinsics, no pose fit");
        work.push(done.work.pair_checks);
    }
    // Without refinement one check per candidate (at most 5); with two, the two
    // keyframes nearest the best candidate (ids 2 and 4, its stretch) besides.
    assert!((1..=5).contains(&work[0]), "{work:?}");
    assert!(work[1] >= work[0] + 2, "{work:?}");
}

#[test]
fn fits_are_chosen_per_feature_kind_and_refinement_is_bounded() {
    let defaults = HintOptions::default();
    assert_eq!(defaults.pair_for(FeatureKind::XFeat), &defaults.pair);
    assert_eq!(defaults.pair_for(FeatureKind::Orb), &defaults.pair);
    assert_eq!(defaults.pair_for(FeatureKind::Cells), &defaults.cells_pair);
    assert_eq!(defaults.pair.estimator, FundamentalEstimator::Ransac);
    assert_eq!(
        (defaults.pair.min_cosine, defaults.pair.max_iterations),
        (0.82, 100),
        "learned matches above XFeat's own floor, RANSAC 100"
    );
    assert_eq!(
        defaults.cells_pair.min_cosine, -1.0,
        "cells keep every match"
    );
    assert_eq!(defaults.cells_pair.estimator, FundamentalEstimator::Magsac);
    let too_many = HintOptions {
        refine_keyframes: 65,
        ..HintOptions::default()
    };
    assert!(matches!(
        too_many.validate(),
        Err(LoopsError::InvalidOption(m)) if m.contains("refine_keyframes")
    ));
    for (pace, slack) in [(-1.0, 0.5), (f64::NAN, 0.5), (3.0, -1.0)] {
        let bad_pace = HintOptions {
            max_match_pace: pace,
            match_pace_slack_s: slack,
            ..HintOptions::default()
        };
        assert!(matches!(
            bad_pace.validate(),
            Err(LoopsError::InvalidOption(m)) if m.contains("match_pace")
        ));
    }
    let bad_cells_fit = HintOptions {
        cells_pair: PairOptions {
            max_iterations: 0,
            ..HintOptions::default().cells_pair
        },
        ..HintOptions::default()
    };
    assert!(matches!(
        bad_cells_fit.validate(),
        Err(LoopsError::InvalidOption(m)) if m.contains("cells_pair")
    ));
}

/// Two keyframes with the same features pass every geometric gate; the more similar one's
/// odometry pose lies 1.5 m off (within a 2 m bound): the one the odometry agrees with wins.
#[test]
fn among_passing_candidates_the_odometry_picks_the_one_it_agrees_with() {
    let mut detector = detector(HintOptions {
        camera: Some(CAMERA),
        consistent_keyframes: 1,
        odometry: Some(OdometryGate {
            max_translation_m: 2.0,
            ..OdometryGate::default()
        }),
        odometry_candidates: 0,
        ..options()
    });
    let (q, m, s) = scene(120, 20, &truth(), 9);
    let (d_true, d_query) = (unit_vector(1, DIM), unit_vector(2, DIM));
    let d_alike = mix(&d_query, &d_true, 0.1);
    let matched = || point_features(&m, Some(s.clone()));
    detector
        .process(&posed(0, &d_true, Isometry3::identity()), matched())
        .unwrap();
    detector
        .process(
            &posed(10, &d_alike, Isometry3::translation(0.0, 1.5, 0.0)),
            matched(),
        )
        .unwrap();
    let hint = detector
        .process(&posed(20, &d_query, truth()), point_features(&q, None))
        .unwrap()
        .hint
        .unwrap();
    assert_eq!(
        (hint.gate, hint.matched_id),
        (Gate::Accepted, 0),
        "{hint:?}"
    );
}

/// Six look-alikes (more similar descriptors, another scene, 30 m away by odometry) fill the
/// appearance candidates; the odometry proposes the true keyframe, which is accepted. Without
/// odometry candidates it is never checked.
#[test]
fn the_odometry_proposes_a_revisit_appearance_ranks_low() {
    for odometry_candidates in [0, 1] {
        let mut detector = detector(HintOptions {
            camera: Some(CAMERA),
            consistent_keyframes: 1,
            odometry_candidates,
            ..options()
        });
        let (q, m, s) = scene(120, 20, &truth(), 9);
        let (d_true, d_query) = (unit_vector(1, DIM), unit_vector(2, DIM));
        detector
            .process(
                &posed(0, &d_true, Isometry3::identity()),
                point_features(&m, Some(s)),
            )
            .unwrap();
        let far = Isometry3::translation(30.0, 0.0, 0.0);
        let alike: Vec<Vec<f32>> = (1..=6u64)
            .map(|k| mix(&d_query, &unit_vector(100 + k, DIM), 0.3))
            .collect();
        for (k, d_alike) in (1..=6u64).zip(&alike) {
            let (_, m_other, s_other) = scene(120, 20, &truth(), 100 + k);
            detector
                .process(
                    &posed(2 * k, d_alike, far),
                    point_features(&m_other, Some(s_other)),
                )
                .unwrap();
        }
        let done = detector
            .process(&posed(20, &d_query, truth()), point_features(&q, None))
            .unwrap();
        let hint = done.hint.expect("candidates");
        match odometry_candidates {
            0 => assert!(hint.matched_id != 0 && !hint.accepted(), "{hint:?}"),
            _ => assert_eq!(
                (hint.gate, hint.matched_id),
                (Gate::Accepted, 0),
                "{hint:?}"
            ),
        }
    }
}

#[test]
fn bad_features_and_duplicate_ids_change_nothing() {
    let mut detector = detector(options());
    first_pass(&mut detector);
    revisit_keyframe(&mut detector, 0);
    let d = unit_vector(1, DIM);
    let cells = KeyframeFeatures {
        keypoints: Keypoints {
            points: vec![[8.0, 8.0]],
            descriptors: Descriptors::Cells(vec![[1i8; 96] as CellDescriptor]),
        },
        camera_points: None,
    };
    let before = detector.database().len();
    let err = detector.process(&entry(SECOND + 1, &d), cells).unwrap_err();
    assert!(
        matches!(err, LoopsError::InvalidKeyframe(ref m) if m.contains("cells") && m.contains("orb")),
        "{err}"
    );
    let mut short = features(&place_image(1));
    short.camera_points = Some(vec![[0.0, 0.0, 1.0]; 3]);
    let err = detector.process(&entry(SECOND + 1, &d), short).unwrap_err();
    assert!(
        matches!(err, LoopsError::InvalidKeyframe(ref m) if m.contains("camera points")),
        "{err}"
    );
    let err = detector
        .process(&entry(SECOND, &d), features(&place_image(1)))
        .unwrap_err();
    assert!(
        matches!(err, LoopsError::DuplicateId(id) if id == SECOND),
        "{err}"
    );
    assert_eq!(detector.database().len(), before, "nothing was added");
    let next = revisit_keyframe(&mut detector, 1).hint.unwrap();
    assert_eq!(
        next.gate,
        Gate::Inconsistent { agreeing: 2 },
        "the streak is intact"
    );
}

/// A detector with intrinsics (and `options`) holding keyframe 0 at the identity, with the
/// scene points of its keypoints; returns it with the pixels of those points seen from
/// `truth()` and keyframe 0's descriptor.
fn with_metric_keyframe(options: HintOptions) -> (LoopDetector, Vec<[f32; 2]>, Vec<f32>) {
    let mut detector = detector(HintOptions {
        camera: Some(CAMERA),
        ..options
    });
    let (q, m, s) = scene(120, 20, &truth(), 9);
    let d = unit_vector(1, DIM);
    detector
        .process(
            &posed(0, &d, Isometry3::identity()),
            point_features(&m, Some(s)),
        )
        .unwrap();
    (detector, q, d)
}

/// Keyframe 0 with its scene points in its camera frame, then keyframe 10 seeing the same
/// points from `truth()`; the bodies' odometry poses are the identity and `query_pose`.
fn metric_revisit(query_pose: Isometry3<f64>) -> topoloc::loops::LoopHint {
    metric_revisit_via(OdometryGate::default(), &[], query_pose)
}

/// [`metric_revisit`] with the odometry gate `gate`, and keyframes without features at odometry
/// poses `via` (ids 1, 2, ...) in between: the route the odometry travelled.
fn metric_revisit_via(
    gate: OdometryGate,
    via: &[Isometry3<f64>],
    query_pose: Isometry3<f64>,
) -> topoloc::loops::LoopHint {
    let (mut detector, q, d) = with_metric_keyframe(HintOptions {
        consistent_keyframes: 1,
        odometry: Some(gate),
        ..options()
    });
    for (i, &pose) in via.iter().enumerate() {
        let id = i as u64 + 1;
        let other = unit_vector(100 + id, DIM);
        detector
            .process(&posed(id, &other, pose), KeyframeFeatures::default())
            .unwrap();
    }
    let done = detector
        .process(&posed(10, &d, query_pose), point_features(&q, None))
        .unwrap();
    done.hint.expect("keyframe 0 is the candidate")
}

/// Keyframes 10 and 11 revisit keyframe 0 (both see its points from `truth()`), with a
/// 2-keyframe streak; their odometry poses are `truth()` moved by `offsets` (metres along y).
/// Returns keyframe 11's hint and the ids it confirmed.
fn streak_of_two(offsets: [f64; 2]) -> (topoloc::loops::LoopHint, Vec<u64>) {
    let (mut detector, q, d) = with_metric_keyframe(HintOptions {
        consistent_keyframes: 2,
        ..options()
    });
    let mut last = None;
    for (id, dy) in [10, 11].into_iter().zip(offsets) {
        let pose = Translation3::new(0.0, dy, 0.0) * truth();
        last = Some(
            detector
                .process(&posed(id, &d, pose), point_features(&q, None))
                .unwrap(),
        );
    }
    let done = last.unwrap();
    let confirmed = done.confirmed.iter().map(|h| h.query_id).collect();
    (done.hint.unwrap(), confirmed)
}

/// A confirmed hint must agree with the accepted one along the route: two hints that each
/// pass the 1 m odometry bound alone (0.9 m off, in opposite directions) put keyframe 10 1.8
/// m from where the odometry has it relative to keyframe 11, so it is not confirmed.
#[test]
fn a_streak_member_is_confirmed_only_when_its_pose_agrees_along_the_route() {
    let (hint, confirmed) = streak_of_two([0.0, 0.0]);
    assert_eq!(
        (hint.gate, hint.matched_id),
        (Gate::Accepted, 0),
        "{hint:?}"
    );
    assert_eq!(confirmed, [10], "the odometry agrees with both hints");
    let (hint, confirmed) = streak_of_two([0.9, -0.9]);
    assert_eq!(hint.gate, Gate::Accepted, "0.9 m passes alone: {hint:?}");
    assert!(confirmed.is_empty(), "1.8 m along the route: {confirmed:?}");
}

#[test]
fn a_metric_hint_carries_the_pose_and_must_agree_with_odometry() {
    let hint = metric_revisit(truth());
    assert_eq!(
        (hint.gate, hint.matched_id),
        (Gate::Accepted, 0),
        "{hint:?}"
    );
    let pose = hint.pose.expect("intrinsics and scene points give a pose");
    assert!(pose.scale_known);
    let error = (pose.matched_t_query.translation.vector - truth().translation.vector).norm();
    assert!(error < 0.05, "{error} m");
    // Odometry that drifted 45 degrees in yaw and 30 m is not the same loop.
    let drifted = Isometry3::from_parts(
        Translation3::new(30.0, 0.0, 0.0),
        UnitQuaternion::from_scaled_axis(Vector3::z() * 45f64.to_radians()),
    ) * truth();
    let refused = metric_revisit(drifted);
    match refused.gate {
        Gate::Odometry {
            rotation_deg,
            translation_m,
        } => assert!(rotation_deg > 40.0 && translation_m > 25.0, "{refused:?}"),
        other => panic!("expected the odometry gate, got {other:?}"),
    }
    assert!(refused.pose.is_some(), "the refused pose is still reported");
}

/// The translation bound grows with the odometry's path between the two keyframes: 2 m of
/// disagreement is too much right after keyframe 0, and the drift of a 200 m detour.
#[test]
fn the_odometry_bound_grows_with_the_distance_travelled() {
    let gate = OdometryGate {
        max_translation_m: 0.5,
        max_translation_per_m: 0.02,
        ..OdometryGate::default()
    };
    let drifted = Translation3::new(0.0, 2.0, 0.0) * truth();
    match metric_revisit_via(gate, &[], drifted).gate {
        Gate::Odometry { translation_m, .. } => {
            assert!((translation_m - 2.0).abs() < 0.1, "{translation_m}")
        }
        other => panic!("expected the odometry gate, got {other:?}"),
    }
    let at = |x: f64, y: f64| Isometry3::translation(x, y, 0.0);
    let detour = [at(50.0, 0.0), at(50.0, 50.0), at(0.0, 50.0), at(0.0, 0.0)];
    let hint = metric_revisit_via(gate, &detour, drifted);
    assert_eq!(
        (hint.gate, hint.matched_id),
        (Gate::Accepted, 0),
        "{hint:?}"
    );
    // A fixed bound (no drift rate) refuses it after the detour too.
    let fixed = OdometryGate {
        max_translation_per_m: 0.0,
        ..gate
    };
    let refused = metric_revisit_via(fixed, &detour, drifted);
    assert!(matches!(refused.gate, Gate::Odometry { .. }), "{refused:?}");
}

/// A perfect look-alike (the true keyframe's features, a more similar descriptor) whose
/// odometry puts it 30 m and 90 degrees away: the odometry refuses it and the next candidate,
/// the true keyframe, is accepted instead of the look-alike hiding it.
#[test]
fn a_look_alike_refused_by_odometry_gives_way_to_the_true_keyframe() {
    let mut detector = detector(HintOptions {
        camera: Some(CAMERA),
        consistent_keyframes: 1,
        ..options()
    });
    let (q, m, s) = scene(120, 20, &truth(), 9);
    let (d_true, d_query) = (unit_vector(1, DIM), unit_vector(2, DIM));
    let d_alike = mix(&d_query, &d_true, 0.1);
    detector
        .process(
            &posed(0, &d_true, Isometry3::identity()),
            point_features(&m, Some(s.clone())),
        )
        .unwrap();
    let far = Isometry3::from_parts(
        Translation3::new(30.0, 0.0, 0.0),
        UnitQuaternion::from_scaled_axis(Vector3::z() * 90f64.to_radians()),
    );
    detector
        .process(&posed(10, &d_alike, far), point_features(&m, Some(s)))
        .unwrap();
    let done = detector
        .process(&posed(20, &d_query, truth()), point_features(&q, None))
        .unwrap();
    let candidates = detector
        .database()
        .relocalization_candidates(&d_query, 3)
        .unwrap();
    let earlier: Vec<u64> = candidates
        .iter()
        .map(|c| c.keyframe_id)
        .filter(|&id| id != 20)
        .collect();
    assert_eq!(earlier, [10, 0], "the look-alike ranks first");
    let hint = done.hint.expect("a candidate");
    assert_eq!(
        (hint.gate, hint.matched_id),
        (Gate::Accepted, 0),
        "{hint:?}"
    );
}

/// The detector saved and loaded as a map file (bytes), then reopened for a second session.
fn reloaded(detector: &LoopDetector, options: HintOptions) -> LoopDetector {
    let bytes = detector.to_map().unwrap().to_bytes().unwrap();
    let map = Map::from_bytes(&bytes, &LoadOptions::default()).unwrap();
    LoopDetector::from_map(&map, DatabaseOptions::default(), options).unwrap()
}

#[test]
fn a_saved_detector_verifies_the_next_session_against_its_keypoints() {
    let mut first = detector(options());
    first_pass(&mut first);
    let map = first.to_map().unwrap();
    let stored = map.keypoints().expect("the keyframes' keypoints are saved");
    assert_eq!(stored.view_count(), PLACES as usize);
    assert!(stored.total() > 100 * PLACES as usize, "{}", stored.total());
    // The second session's revisits verify against the first session's keyframes, as a live
    // detector's do (they got NO_CANDIDATE when the save dropped the keypoints).
    let mut second = reloaded(&first, options());
    for p in 0..PLACES {
        let hint = revisit_keyframe(&mut second, p)
            .hint
            .expect("a verified candidate");
        assert_eq!(hint.matched_id, p, "revisit of place {p}");
        assert!(hint.inliers >= 30, "{hint:?}");
    }
}

#[test]
fn a_saved_detector_keeps_its_scene_points_for_metric_hints() {
    let metric = HintOptions {
        camera: Some(CAMERA),
        consistent_keyframes: 1,
        ..options()
    };
    let (first, q, d) = with_metric_keyframe(metric.clone());
    let live = {
        let (mut live, _, _) = with_metric_keyframe(metric.clone());
        live.process(&posed(10, &d, truth()), point_features(&q, None))
            .unwrap()
            .hint
            .expect("keyframe 0 is the candidate")
    };
    let mut second = reloaded(&first, metric);
    let hint = second
        .process(&posed(10, &d, truth()), point_features(&q, None))
        .unwrap()
        .hint
        .expect("keyframe 0 is the candidate");
    assert_eq!(hint.gate, Gate::Accepted, "{hint:?}");
    let (pose, live_pose) = (hint.pose.expect("metric"), live.pose.expect("metric"));
    assert!(
        (pose.matched_t_query.translation.vector - live_pose.matched_t_query.translation.vector)
            .norm()
            < 1e-3,
        "{pose:?} vs {live_pose:?}"
    );
}

/// A host whose odometry restarts in a new world frame (ORB-SLAM3's new map after tracking is
/// lost) begins a session: the keyframe just lost is found at once (it was inside the
/// exclusion window), the new session's clock may start earlier, and the odometry of two
/// unrelated frames is not compared (it would refuse the true place).
#[test]
fn a_new_session_finds_the_map_just_lost_without_comparing_odometry() {
    let metric = HintOptions {
        consistent_keyframes: 1,
        odometry: Some(OdometryGate::default()),
        ..options()
    };
    // In the new map's frame the camera is back at the origin: 45 degrees and 30 m from where
    // the lost map's frame has it.
    let restarted = Isometry3::from_parts(
        Translation3::new(30.0, 0.0, 0.0),
        UnitQuaternion::from_scaled_axis(Vector3::z() * 45f64.to_radians()),
    ) * truth();
    let revisit = |detector: &mut LoopDetector, q: &[[f32; 2]], d: &[f32], timestamp: f64| {
        let keyframe = KeyframeEntry {
            timestamp,
            ..posed(3, d, restarted)
        };
        detector.process(&keyframe, point_features(q, None))
    };

    let (mut same_session, q, d) = with_metric_keyframe(metric.clone());
    let done = revisit(&mut same_session, &q, &d, 1.0).unwrap();
    assert_eq!(
        done.gate(),
        Gate::NoCandidate,
        "inside the exclusion window"
    );

    let (mut detector, q, d) = with_metric_keyframe(metric);
    detector.begin_session();
    assert_eq!(
        detector.database().timestamp_of(0).unwrap(),
        f64::NEG_INFINITY
    );
    let hint = revisit(&mut detector, &q, &d, -100.0)
        .unwrap()
        .hint
        .expect("keyframe 0 is a candidate");
    assert_eq!(
        (hint.gate, hint.matched_id),
        (Gate::Accepted, 0),
        "{hint:?}"
    );
    let pose = hint.pose.expect("the fitted pose, not the odometry's");
    let error = (pose.matched_t_query.translation.vector - truth().translation.vector).norm();
    assert!(error < 0.05, "{error} m");

    // Within the new session, time must not go back, and the refusal changes nothing.
    let earlier = KeyframeEntry {
        timestamp: -200.0,
        ..posed(4, &d, restarted)
    };
    let refused = detector.process(&earlier, point_features(&q, None));
    assert!(
        matches!(refused, Err(LoopsError::OutOfOrder(_))),
        "{refused:?}"
    );
    assert_eq!(detector.database().len(), 2);
}
