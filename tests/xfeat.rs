//! XFeat learned local features: keypoints of a place seen again (shifted, with another
//! exposure and noise) match its own with many fundamental-matrix inliers and an unrelated
//! place's with few; they survive the map file as int8 (format 1.4); ORB and XFeat keypoints
//! do not mix; a missing model and a too small image are typed errors. Tests needing the
//! cache's XFeat export skip, with a note, when `scripts/setup-models.sh` has not run.

mod common;

use common::chain_map;
use common::images::{gray, place_image, revisit, H, W};
use topoloc::errors::VisionError;
use topoloc::image::{ImageView, PixelFormat};
use topoloc::verify::xfeat::DEFAULT_XFEAT_MODEL_FILE;
use topoloc::verify::{
    check_pair, spatial_check, Descriptors, FeatureKind, KeypointDetector, Keypoints, PairOptions,
    ViewKeypoints, XFeatDetector, XFeatOptions, MIN_MATCHES,
};
use topoloc::{LoadOptions, Map};

/// A detector on the cache's model, or `None` (and a note) before set-up.
fn detector(max_keypoints: usize) -> Option<XFeatDetector> {
    common::models::cached(DEFAULT_XFEAT_MODEL_FILE)?;
    Some(XFeatDetector::new(&XFeatOptions::default(), max_keypoints).unwrap())
}

#[test]
fn keypoints_are_unit_int8_descriptors_inside_the_image() {
    let Some(mut xfeat) = detector(256) else {
        return;
    };
    let found = xfeat.detect(&gray(&place_image(1))).unwrap();
    assert!(
        found.len() > 100 && found.len() <= 256,
        "{} keypoints",
        found.len()
    );
    let Descriptors::XFeat(rows) = &found.descriptors else {
        panic!("XFeat gave {:?} descriptors", found.descriptors.kind())
    };
    for row in rows {
        let norm2: i32 = row.iter().map(|&v| i32::from(v) * i32::from(v)).sum();
        assert!(
            (127 * 127 - 400..=127 * 127 + 400).contains(&norm2),
            "|d|^2 = {norm2}"
        );
    }
    for p in &found.points {
        assert!(
            (0.0..320.0).contains(&p[0]) && (0.0..240.0).contains(&p[1]),
            "{p:?}"
        );
    }
    let again = xfeat.detect(&gray(&place_image(1))).unwrap();
    assert_eq!(found, again, "detection is deterministic");
}

#[test]
fn a_revisit_matches_its_place_and_not_another() {
    let Some(mut xfeat) = detector(256) else {
        return;
    };
    let stored = xfeat.detect(&gray(&place_image(2))).unwrap();
    let other = xfeat.detect(&gray(&place_image(5))).unwrap();
    let query = xfeat.detect(&gray(&revisit(&place_image(2), 9))).unwrap();
    let options = PairOptions::default();
    let same = check_pair(query.as_ref(), stored.as_ref(), &options).unwrap();
    let different = check_pair(query.as_ref(), other.as_ref(), &options).unwrap();
    assert!(same.inliers >= 60, "revisit: {same:?}");
    assert!(
        same.inliers >= 3 * different.inliers.max(MIN_MATCHES as u32),
        "{same:?} vs {different:?}"
    );
    let same_spatial = spatial_check(query.as_ref(), stored.as_ref(), 64).unwrap();
    let other_spatial = spatial_check(query.as_ref(), other.as_ref(), 64).unwrap();
    assert!(
        same_spatial.score > 2.0 * other_spatial.score,
        "{same_spatial:?} vs {other_spatial:?}"
    );
}

#[test]
fn a_large_image_is_scaled_to_the_budget_and_its_keypoints_back_to_its_pixels() {
    let Some(mut xfeat) = detector(256) else {
        return;
    };
    // The place at 3x (960 x 720: 691,200 pixels, over the default budget of 160,000).
    const K: usize = 3;
    let small = place_image(2);
    let (w, h) = (W * K, H * K);
    let large: Vec<u8> = (0..w * h)
        .map(|i| small[(i / w / K) * W + (i % w) / K])
        .collect();
    let view = ImageView::packed(w as u32, h as u32, PixelFormat::Gray8, &large);
    let found = xfeat.detect(&view).unwrap();
    let xs = found.points.iter().map(|p| p[0]);
    let widest = xs.fold(0f32, f32::max);
    assert!(
        widest > 0.8 * w as f32 && widest < w as f32,
        "keypoints reach x = {widest} of {w}"
    );
    // The same scene: scaled down by 3, the keypoints match the place's own.
    let points = found
        .points
        .iter()
        .map(|p| [p[0] / K as f32, p[1] / K as f32]);
    let scaled = Keypoints {
        points: points.collect(),
        descriptors: found.descriptors.clone(),
    };
    let own = xfeat.detect(&gray(&small)).unwrap();
    let pair = check_pair(scaled.as_ref(), own.as_ref(), &PairOptions::default()).unwrap();
    assert!(pair.inliers >= 60, "{pair:?}");
    let full = XFeatOptions {
        max_pixels: 0,
        ..XFeatOptions::default()
    };
    let mut unscaled = XFeatDetector::new(&full, 256).unwrap();
    assert_ne!(
        unscaled.detect(&view).unwrap(),
        found,
        "0 runs the full size"
    );
}

#[test]
fn xfeat_keypoints_survive_the_map_file_and_do_not_mix_with_orb() {
    let Some(mut xfeat) = detector(128) else {
        return;
    };
    let views: Vec<Keypoints> = (0..4)
        .map(|p| xfeat.detect(&gray(&place_image(p))).unwrap())
        .collect();
    let store = ViewKeypoints::from_views(FeatureKind::XFeat, &views).unwrap();
    assert_eq!(store.kind(), FeatureKind::XFeat);
    let map = chain_map(4, 1, 8).with_keypoints(store.clone()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("xfeat.topoloc");
    map.save(&path).unwrap();
    let loaded = Map::load(&path, &LoadOptions::default()).unwrap();
    assert_eq!(loaded.keypoints(), Some(&store));
    let orb = KeypointDetector::new(100)
        .unwrap()
        .detect(&gray(&place_image(0)))
        .unwrap();
    let mixed = ViewKeypoints::from_views(FeatureKind::XFeat, [&views[0], &orb]).unwrap_err();
    assert!(mixed.contains("view 1") && mixed.contains("orb"), "{mixed}");
    let refused = check_pair(orb.as_ref(), views[0].as_ref(), &PairOptions::default()).unwrap_err();
    assert!(
        matches!(refused, VisionError::InvalidArgument(ref m) if m.contains("orb") && m.contains("xfeat")),
        "{refused}"
    );
}

#[test]
fn a_missing_model_and_a_tiny_image_are_typed_errors() {
    let missing = XFeatOptions {
        model: Some("/nonexistent/xfeat.onnx".into()),
        ..XFeatOptions::default()
    };
    match XFeatDetector::new(&missing, 100) {
        Err(VisionError::BackendUnavailable { tried, hint, .. }) => {
            assert_eq!(
                tried,
                vec![std::path::PathBuf::from("/nonexistent/xfeat.onnx")]
            );
            assert!(hint.contains("setup-models"), "{hint}");
        }
        Err(other) => panic!("expected BackendUnavailable, got {other}"),
        Ok(_) => panic!("expected BackendUnavailable"),
    }
    assert!(matches!(
        XFeatDetector::new(&XFeatOptions::default(), 0),
        Err(VisionError::InvalidArgument(_))
    ));
    let Some(mut xfeat) = detector(100) else {
        return;
    };
    let tiny = vec![128u8; 31 * 40];
    let err = xfeat
        .detect(&ImageView::packed(40, 31, PixelFormat::Gray8, &tiny))
        .unwrap_err();
    assert!(
        matches!(err, VisionError::InvalidImage(ref m) if m.contains("32")),
        "{err}"
    );
}
