//! Geometric verification: ORB keypoints of a place seen again match its stored keypoints with
//! many RANSAC inliers and an unrelated place's with few; a localizer that verifies tells two
//! places with identical descriptors apart by their keypoints, and flags frames off the map by
//! their lack of inliers when told to; keypoints survive the map file;
//! missing keypoints or images are typed errors that leave the localizer unchanged.

mod common;

use common::images::{gray, place_image, revisit};
use common::unit_vector;
use std::sync::Arc;
use topoloc::errors::VisionError;
use topoloc::map::ViewAttributes;
use topoloc::verify::{
    check_pair, FeatureKind, FundamentalEstimator, KeypointDetector, Keypoints, PairOptions,
    VerificationOptions, VerificationScore, ViewKeypoints,
};
use topoloc::{
    DescriptorIdentity, Frame, LoadOptions, LocalizeError, Localizer, LocalizerOptions, Map,
    MapBuilder, Mode,
};

const DIM: usize = 16;
/// Places of the test map; `TWIN_A` and `TWIN_B` have identical descriptors.
const PLACES: u64 = 10;
const TWIN_A: u64 = 3;
const TWIN_B: u64 = 7;

fn detect(image: &[u8]) -> Keypoints {
    KeypointDetector::new(500)
        .unwrap()
        .detect(&gray(image))
        .unwrap()
}

fn descriptor_of(place: u64) -> Vec<f32> {
    let seed = if place == TWIN_B { TWIN_A } else { place };
    unit_vector(seed, DIM)
}

/// A chain of places, one view each; view p carries the keypoints of `place_image(p)`.
fn twin_map(with_keypoints: bool) -> Map {
    let mut builder =
        MapBuilder::new(DescriptorIdentity::new("test", "twins", DIM as u32).unwrap());
    for p in 0..PLACES {
        let place = builder.add_place(None).unwrap();
        builder
            .add_view(place, &descriptor_of(p), ViewAttributes::default())
            .unwrap();
        if p > 0 {
            builder.add_edge(place - 1, place, 1.0).unwrap();
        }
    }
    let map = builder.build().unwrap();
    if !with_keypoints {
        return map;
    }
    let views: Vec<Keypoints> = (0..PLACES).map(|p| detect(&place_image(p))).collect();
    map.with_keypoints(ViewKeypoints::from_views(FeatureKind::Orb, &views).unwrap())
        .unwrap()
}

fn single_frame(candidates: usize) -> LocalizerOptions {
    LocalizerOptions {
        mode: Mode::SingleFrame,
        verification: VerificationOptions::with_candidates(candidates),
        ..LocalizerOptions::default()
    }
}

#[test]
fn a_place_seen_again_has_many_inliers_and_another_place_few() {
    let stored = detect(&place_image(5));
    let again = detect(&revisit(&place_image(5), 1));
    let other = detect(&place_image(6));
    assert!(stored.len() > 200, "{} keypoints", stored.len());
    let options = PairOptions::default();
    let same = check_pair(again.as_ref(), stored.as_ref(), &options).unwrap();
    let different = check_pair(other.as_ref(), stored.as_ref(), &options).unwrap();
    assert!(same.inliers >= 100, "same place: {same:?}");
    assert!(same.inliers <= same.matches);
    assert!(
        different.inliers < 30 && different.inliers * 4 < same.inliers,
        "other place: {different:?} vs same {same:?}"
    );
}

#[test]
fn a_camera_back_where_the_view_was_taken_keeps_its_inliers_with_either_fit() {
    // No motion: every match stays where it was, which no fundamental matrix describes.
    let stored = detect(&place_image(5));
    let other = detect(&place_image(6));
    for estimator in [
        FundamentalEstimator::Ransac,
        FundamentalEstimator::Magsac,
        FundamentalEstimator::UsacFast,
    ] {
        let options = PairOptions {
            estimator,
            max_iterations: 1000,
            ..PairOptions::default()
        };
        let same = check_pair(stored.as_ref(), stored.as_ref(), &options).unwrap();
        assert!(
            same.matches >= 200 && same.inliers == same.matches,
            "{estimator:?}: {same:?}"
        );
        let different = check_pair(other.as_ref(), stored.as_ref(), &options).unwrap();
        assert!(different.inliers < 30, "{estimator:?}: {different:?}");
    }
}

#[test]
fn featureless_images_give_no_keypoints_and_zero_inliers() {
    let blank = vec![128u8; common::images::W * common::images::H];
    let none = detect(&blank);
    assert!(none.is_empty());
    let stored = detect(&place_image(1));
    let check = check_pair(none.as_ref(), stored.as_ref(), &PairOptions::default()).unwrap();
    assert_eq!((check.matches, check.inliers), (0, 0));
    assert!(KeypointDetector::new(0).is_err());
    assert!(KeypointDetector::new(topoloc::verify::MAX_KEYPOINTS + 1).is_err());
}

/// A frame revisiting twin B: its image and B's descriptor (the same as A's).
fn twin_b_frame<'a>(image: &'a [u8], descriptor: &'a [f32]) -> Frame<'a> {
    Frame {
        timestamp: 0.0,
        descriptor,
        image: Some(gray(image)),
        odometry: None,
    }
}

#[test]
fn verification_tells_places_with_identical_descriptors_apart() {
    let map = Arc::new(twin_map(true));
    let (query_image, descriptor) = (revisit(&place_image(TWIN_B), 2), descriptor_of(TWIN_B));
    let frame = twin_b_frame(&query_image, &descriptor);

    let mut plain = Localizer::new(map.clone(), single_frame(0)).unwrap();
    let out = plain.localize(&frame).unwrap();
    let twins: Vec<f32> = out
        .candidates
        .iter()
        .filter(|c| u64::from(c.place) == TWIN_A || u64::from(c.place) == TWIN_B)
        .map(|c| c.probability)
        .collect();
    assert_eq!(twins.len(), 2);
    assert!(
        (twins[0] - twins[1]).abs() < 1e-6,
        "a tie without verification: {twins:?}"
    );
    assert!(out.candidates.iter().all(|c| !c.verified && c.inliers == 0));

    let mut verifying = Localizer::new(map, single_frame(2)).unwrap();
    let out = verifying.localize(&frame).unwrap();
    assert_eq!(u64::from(out.place), TWIN_B);
    assert!(out.confidence > 0.99, "confidence {}", out.confidence);
    let best = out.candidates[0];
    assert!(best.verified && best.inliers >= 100, "{best:?}");
    let twin = out
        .candidates
        .iter()
        .find(|c| u64::from(c.place) == TWIN_A)
        .expect("the look-alike stays a candidate");
    assert!(twin.verified && twin.inliers < 30, "{twin:?}");
}

/// The seed's s-GC score as the evidence instead of GC inliers: the same look-alike pair is
/// told apart, and the evidence is deterministic (no sampling), so two runs agree exactly.
#[test]
fn the_spatial_score_also_tells_places_with_identical_descriptors_apart() {
    let map = Arc::new(twin_map(true));
    let (query_image, descriptor) = (revisit(&place_image(TWIN_B), 2), descriptor_of(TWIN_B));
    let frame = twin_b_frame(&query_image, &descriptor);
    let mut options = single_frame(2);
    options.verification.score = VerificationScore::Spatial;
    let mut spatial = Localizer::new(map.clone(), options.clone()).unwrap();
    let out = spatial.localize(&frame).unwrap();
    assert_eq!(u64::from(out.place), TWIN_B);
    assert!(out.confidence > 0.99, "confidence {}", out.confidence);
    let best = out.candidates[0];
    let twin = out
        .candidates
        .iter()
        .find(|c| u64::from(c.place) == TWIN_A)
        .expect("the look-alike stays a candidate");
    assert!(best.verified && twin.verified);
    assert!(
        best.inliers > 4 * twin.inliers.max(1),
        "s-GC evidence {best:?} vs look-alike {twin:?}"
    );
    let again = Localizer::new(map, options)
        .unwrap()
        .localize(&frame)
        .unwrap();
    assert_eq!(again.candidates, out.candidates, "s-GC has no sampling");
}

#[test]
fn verification_needs_keypoints_in_the_map_and_an_image_in_the_frame() {
    match Localizer::new(Arc::new(twin_map(false)), single_frame(2)) {
        Err(LocalizeError::Verification(msg)) => assert!(msg.contains("keypoints"), "{msg}"),
        other => panic!("expected a verification error, got {:?}", other.err()),
    }
    let bad = LocalizerOptions {
        verification: VerificationOptions {
            candidates: 2,
            views_per_candidate: 0,
            ..VerificationOptions::default()
        },
        ..LocalizerOptions::default()
    };
    assert!(matches!(
        Localizer::new(Arc::new(twin_map(true)), bad),
        Err(LocalizeError::InvalidOption(_))
    ));

    let mut localizer = Localizer::new(Arc::new(twin_map(true)), single_frame(2)).unwrap();
    let descriptor = descriptor_of(1);
    let without_image = Frame {
        timestamp: 0.0,
        descriptor: &descriptor,
        image: None,
        odometry: None,
    };
    assert!(matches!(
        localizer.localize(&without_image),
        Err(LocalizeError::Describe(VisionError::InvalidImage(_)))
    ));
    // The failed frame left no trace: the next frame is the first.
    let image = place_image(1);
    let frame = Frame {
        image: Some(gray(&image)),
        ..without_image
    };
    let out = localizer.localize(&frame).unwrap();
    assert_eq!(out.frame_index, 0);
    assert_eq!(out.place, 1);
}

/// Off-map flags per frame of a filter verifying 3 places, with the off-map threshold
/// `off_map_inliers` (`None`: the map's kind's default, appearance for ORB): 20 frames seeing
/// place 5 again, 20 frames of unseen images that still carry place 5's descriptor (appearance
/// alone says "on the map"), and 10 frames back at place 5.
fn off_map_flags(off_map_inliers: Option<f32>) -> Vec<bool> {
    let options = LocalizerOptions {
        mode: Mode::Filter,
        verification: VerificationOptions {
            candidates: 3,
            off_map_inliers,
            ..VerificationOptions::default()
        },
        ..LocalizerOptions::default()
    };
    let mut localizer = Localizer::new(Arc::new(twin_map(true)), options).unwrap();
    let descriptor = descriptor_of(5);
    let home = place_image(5);
    let images: Vec<Vec<u8>> = (0..50u64)
        .map(|i| match i {
            20..=39 => place_image(1000 + i),
            _ => revisit(&home, i),
        })
        .collect();
    images
        .iter()
        .enumerate()
        .map(|(i, image)| {
            let frame = Frame {
                timestamp: i as f64 * 0.1,
                descriptor: &descriptor,
                image: Some(gray(image)),
                odometry: None,
            };
            localizer.localize(&frame).unwrap().off_map
        })
        .collect()
}

#[test]
fn the_off_map_flag_follows_the_verification_inliers() {
    let flags = off_map_flags(Some(30.0));
    assert!(
        !flags[..20].iter().any(|&f| f),
        "on-map frames flagged: {flags:?}"
    );
    let first = flags[20..40]
        .iter()
        .position(|&f| f)
        .expect("never flagged");
    assert!(first < 10, "first flagged after {first} unseen frames");
    assert!(
        flags[20 + first..40].iter().all(|&f| f),
        "flag dropped on unseen frames: {flags:?}"
    );
    assert!(
        !flags[43..].iter().any(|&f| f),
        "flag stuck after returning: {flags:?}"
    );
    // Without inlier evidence the matching descriptors keep every frame on the map; ORB maps
    // leave the decision to appearance by default.
    assert!(!off_map_flags(Some(0.0)).iter().any(|&f| f));
    assert_eq!(off_map_flags(None), off_map_flags(Some(0.0)));
    assert_eq!(FeatureKind::Orb.default_off_map_inliers(), 0.0);
    assert!(FeatureKind::XFeat.default_off_map_inliers() > 0.0);
}

#[test]
fn bad_off_map_evidence_options_are_refused() {
    for (inliers, scale, field) in [
        (Some(f32::NAN), 4.0, "off_map_inliers"),
        (Some(-1.0), 4.0, "off_map_inliers"),
        (None, 0.0, "off_map_inlier_scale"),
        (None, f32::INFINITY, "off_map_inlier_scale"),
    ] {
        let options = LocalizerOptions {
            verification: VerificationOptions {
                candidates: 2,
                off_map_inliers: inliers,
                off_map_inlier_scale: scale,
                ..VerificationOptions::default()
            },
            ..LocalizerOptions::default()
        };
        match Localizer::new(Arc::new(twin_map(true)), options) {
            Err(LocalizeError::InvalidOption(msg)) => assert!(msg.contains(field), "{msg}"),
            other => panic!("{field}: expected an invalid option, got {:?}", other.err()),
        }
    }
}

#[test]
fn keypoints_survive_the_map_file() {
    let map = twin_map(true);
    let bytes = map.to_bytes().unwrap();
    let loaded = Map::from_bytes(&bytes, &LoadOptions::default()).unwrap();
    assert_eq!(loaded.keypoints(), map.keypoints());
    let store = loaded.keypoints().unwrap();
    assert_eq!(store.view_count(), PLACES as usize);
    assert!(store.view(PLACES as usize).is_none());

    let plain = twin_map(false);
    let loaded = Map::from_bytes(&plain.to_bytes().unwrap(), &LoadOptions::default()).unwrap();
    assert!(loaded.keypoints().is_none());

    // Keypoints for another number of views are refused.
    let one = ViewKeypoints::from_views(FeatureKind::Orb, &[detect(&place_image(0))]).unwrap();
    assert!(twin_map(false).with_keypoints(one).is_err());
}

#[test]
fn inconsistent_keypoint_arrays_are_refused() {
    let point = [1.0f32, 2.0];
    let descriptor = [0u8; 32];
    assert!(ViewKeypoints::from_parts(vec![0, 1], vec![point], vec![descriptor]).is_ok());
    assert!(ViewKeypoints::from_parts(vec![0, 2], vec![point], vec![descriptor]).is_err());
    assert!(ViewKeypoints::from_parts(vec![1, 1], vec![point], vec![descriptor]).is_err());
    assert!(ViewKeypoints::from_parts(
        vec![0, 1],
        vec![point],
        Vec::<topoloc::verify::Descriptor>::new()
    )
    .is_err());
    assert!(ViewKeypoints::from_parts(vec![0, 1, 0, 1], vec![point], vec![descriptor]).is_err());
    assert!(
        ViewKeypoints::from_parts(vec![0, 1], vec![[f32::NAN, 0.0]], vec![descriptor]).is_err()
    );
}

#[test]
fn a_pair_that_cannot_reach_the_callers_inlier_gate_is_not_fitted() {
    let stored = detect(&place_image(5));
    let options = PairOptions::default();
    let fitted = topoloc::verify::fit_pair(stored.as_ref(), stored.as_ref(), &options).unwrap();
    let matches = fitted.matches.len() as u32;
    assert!(fitted.check().inliers >= 200, "{:?}", fitted.check());
    let within =
        topoloc::verify::fit_pair_reaching(stored.as_ref(), stored.as_ref(), &options, matches)
            .unwrap();
    assert_eq!(within, fitted);
    let beyond =
        topoloc::verify::fit_pair_reaching(stored.as_ref(), stored.as_ref(), &options, matches + 1)
            .unwrap();
    assert_eq!(beyond.matches, fitted.matches);
    assert_eq!(beyond.check().inliers, 0);
}

#[test]
fn a_min_cosine_outside_minus_one_to_one_is_refused() {
    for bad in [1.5f32, -1.01, f32::NAN] {
        let options = PairOptions {
            min_cosine: bad,
            ..PairOptions::default()
        };
        let message = options.validate().unwrap_err();
        assert!(message.contains("min_cosine"), "{bad}: {message}");
    }
    assert!(PairOptions::default().validate().is_ok());
}
