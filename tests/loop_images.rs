//! Keyframe images in: a [`KeyframeDescriber`] gives the loop detector the global descriptor
//! and local features of an image (VLAD with ORB here, which need no model), so a revisit of a
//! place turns into an accepted hint; features the describer cannot give are a typed error.

mod common;

use common::images::{gray, place_image, revisit};
use topoloc::build::{build_from_images, BuildStage, ImageLayout, ImageMapOptions, ImageSource};
use topoloc::describe::vlad::VladOptions;
use topoloc::describe::{BackendConfig, Describer, DescriberOptions};
use topoloc::errors::VisionError;
use topoloc::loops::{
    DatabaseOptions, Gate, HintOptions, KeyframeDatabase, KeyframeDescriber, KeyframeEntry,
    LoopDetector, LoopsError,
};
use topoloc::verify::{FeatureKind, XFeatOptions};

/// A VLAD describer fitted on the images of `places` places.
fn describer(places: u64) -> Describer {
    let images: Vec<Vec<u8>> = (0..places).map(place_image).collect();
    let sources: Vec<ImageSource> = images
        .iter()
        .map(|i| ImageSource::Pixels(gray(i)))
        .collect();
    let options = ImageMapOptions {
        backend: BackendConfig::Vlad(VladOptions::default()),
        ..ImageMapOptions::default()
    };
    let mut no_progress = |_: BuildStage, _: usize, _: usize| true;
    let (map, _) =
        build_from_images(&sources, ImageLayout::Sequence, &options, &mut no_progress).unwrap();
    let model = map
        .describer()
        .cloned()
        .expect("maps from images store their describer");
    Describer::new(model, &DescriberOptions::default()).unwrap()
}

#[test]
fn a_revisit_described_from_its_image_is_a_loop() {
    let mut keyframes =
        KeyframeDescriber::new(describer(6), FeatureKind::Orb, &XFeatOptions::default()).unwrap();
    assert_eq!(keyframes.kind(), FeatureKind::Orb);
    let identity = keyframes.describer().identity().clone();
    let db = KeyframeDatabase::new(identity, DatabaseOptions::default()).unwrap();
    let mut detector = LoopDetector::new(
        db,
        HintOptions {
            exclude_recent_ids: 5,
            exclude_recent_s: 0.0,
            consistent_keyframes: 1,
            ..HintOptions::default()
        },
    )
    .unwrap();
    let mut descriptor = Vec::new();
    let mut add = |detector: &mut LoopDetector, id: u64, image: &[u8]| {
        let features = keyframes.describe(&gray(image), &mut descriptor).unwrap();
        assert!(
            features.keypoints.len() > 100,
            "ORB keypoints of a textured image"
        );
        let entry = KeyframeEntry {
            id,
            timestamp: id as f64,
            descriptor: &descriptor,
            ..KeyframeEntry::default()
        };
        detector.process(&entry, features).unwrap()
    };
    for p in 0..6 {
        add(&mut detector, p, &place_image(p));
    }
    let done = add(&mut detector, 20, &revisit(&place_image(2), 77));
    let hint = done.hint.expect("a verified candidate");
    assert_eq!(
        (hint.gate, hint.matched_id),
        (Gate::Accepted, 2),
        "{hint:?}"
    );
}

#[test]
fn cells_need_a_describer_with_a_cnn_and_bad_images_are_typed_errors() {
    let refused =
        KeyframeDescriber::new(describer(3), FeatureKind::Cells, &XFeatOptions::default());
    assert!(
        matches!(refused, Err(LoopsError::InvalidOption(ref m)) if m.contains("ONNX")),
        "{:?}",
        refused.err()
    );
    let mut keyframes =
        KeyframeDescriber::new(describer(3), FeatureKind::Orb, &XFeatOptions::default()).unwrap();
    let blank = vec![128u8; common::images::W * common::images::H];
    match keyframes.describe(&gray(&blank), &mut Vec::new()) {
        Err(LoopsError::Vision(VisionError::Uninformative(_))) => {}
        other => panic!("a blank image: {:?}", other.err()),
    }
}
