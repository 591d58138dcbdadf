//! Images in: maps built from images store their describer (round trip through the file), a
//! localizer describes image frames with it, identity mismatches and bad images give typed
//! errors and leave the localizer unchanged. VLAD runs everywhere; the ONNX cases run when
//! scripts/setup-models.sh has filled the cache (CI does) and are skipped otherwise.

mod common;

use common::images::{gray, place_image, revisit, H, W};
use nalgebra::{Isometry3, Point3, Vector3};
use std::sync::Arc;
use topoloc::build::{
    build_from_images, BuildStage, ImageLayout, ImageMapError, ImageMapOptions, ImageSource,
    PlaceLayout, DEFAULT_MAP_FEATURES,
};
use topoloc::describe::onnx::{OnnxMlf, OnnxOptions, DEFAULT_MODEL_FILE, F32_MODEL_FILE};
use topoloc::describe::vlad::VladOptions;
use topoloc::describe::{BackendConfig, BackendKind, BackendSpec, Describer, DescriberOptions};
use topoloc::errors::VisionError;
use topoloc::image::{ImageView, PixelFormat};
use topoloc::map::MapError;
use topoloc::verify::FeatureKind;
use topoloc::{Frame, LoadOptions, LocalizeError, Localizer, LocalizerOptions, Map, Mode};

/// A bad image: its name, the view, and the error it must get.
type BadImageCase<'a> = (&'static str, ImageView<'a>, fn(&LocalizeError) -> bool);

fn no_progress(_: BuildStage, _: usize, _: usize) -> bool {
    true
}

fn build(images: &[Vec<u8>], backend: BackendConfig) -> Result<Map, ImageMapError> {
    let sources: Vec<ImageSource> = images
        .iter()
        .map(|d| ImageSource::Pixels(gray(d)))
        .collect();
    let options = ImageMapOptions {
        backend,
        threads: 2,
        ..ImageMapOptions::default()
    };
    build_from_images(&sources, ImageLayout::Sequence, &options, &mut no_progress)
        .map(|(map, _)| map)
}

fn image_frame(data: &[u8], t: f64) -> Frame<'_> {
    Frame {
        timestamp: t,
        image: Some(gray(data)),
        ..Frame::default()
    }
}

fn onnx_available() -> bool {
    common::models::cached(DEFAULT_MODEL_FILE).is_some()
}

/// Builds a map from `places` images, saves and reloads it, and localizes revisits of every
/// place single-frame: at least `min_correct` of them must be found.
fn round_trip_and_localize(backend: BackendConfig, places: u64, min_correct: usize) {
    let images: Vec<Vec<u8>> = (0..places).map(place_image).collect();
    let built = build(&images, backend).expect("map from images");
    assert_eq!(built.place_count(), places as usize);
    assert_eq!(
        built.view(3).unwrap().keyframe_id,
        Some(3),
        "image index kept"
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("images.topoloc");
    built.save(&path).unwrap();
    let map = Arc::new(Map::load(&path, &LoadOptions::default()).unwrap());
    assert_eq!(map.descriptor(), built.descriptor());
    assert_eq!(
        map.describer().map(|m| m.as_ref()),
        built.describer().map(|m| m.as_ref()),
        "describer survives the file bit for bit"
    );

    let options = LocalizerOptions {
        mode: Mode::SingleFrame,
        ..Default::default()
    };
    let mut localizer =
        Localizer::with_describer(map.clone(), options, &DescriberOptions::default()).unwrap();
    assert!(localizer.describes_images());
    let mut correct = 0;
    for (p, image) in images.iter().enumerate() {
        let query = revisit(image, p as u64 + 100);
        let out = localizer.localize(&image_frame(&query, p as f64)).unwrap();
        correct += usize::from(out.place as usize == p);
    }
    assert!(
        correct >= min_correct,
        "{correct} of {places} revisits localized (need {min_correct})"
    );
}

#[test]
fn vlad_maps_store_their_describer_and_localize_image_frames() {
    round_trip_and_localize(BackendConfig::Vlad(VladOptions::default()), 12, 11);
}

#[test]
fn onnx_maps_store_their_describer_and_localize_image_frames() {
    if !onnx_available() {
        return;
    }
    round_trip_and_localize(BackendConfig::Onnx(OnnxOptions::default()), 12, 11);
}

#[test]
fn bad_images_give_typed_errors_and_leave_the_localizer_unchanged() {
    let images: Vec<Vec<u8>> = (0..6).map(place_image).collect();
    let map = Arc::new(build(&images, BackendConfig::Vlad(VladOptions::default())).unwrap());
    let mut localizer =
        Localizer::with_describer(map.clone(), Default::default(), &Default::default()).unwrap();
    let mut twin = Localizer::with_describer(map, Default::default(), &Default::default()).unwrap();
    let first = localizer.localize(&image_frame(&images[0], 0.0)).unwrap();
    twin.localize(&image_frame(&images[0], 0.0)).unwrap();

    let tiny = [128u8];
    let constant = vec![90u8; W * H];
    let black = vec![0u8; W * H * 3];
    let cases: Vec<BadImageCase> = vec![
        (
            "1x1",
            ImageView::packed(1, 1, PixelFormat::Gray8, &tiny),
            |e| matches!(e, LocalizeError::Describe(VisionError::Uninformative(_))),
        ),
        (
            "10000x10000",
            ImageView::packed(10_000, 10_000, PixelFormat::Gray8, &tiny),
            |e| matches!(e, LocalizeError::Describe(VisionError::InvalidImage(_))),
        ),
        (
            "zero width",
            ImageView::packed(0, 10, PixelFormat::Gray8, &tiny),
            |e| matches!(e, LocalizeError::Describe(VisionError::InvalidImage(_))),
        ),
        (
            "short stride",
            ImageView {
                stride: W - 1,
                ..gray(&images[1])
            },
            |e| matches!(e, LocalizeError::Describe(VisionError::InvalidImage(_))),
        ),
        ("short buffer", gray(&images[1][..W * H - 1]), |e| {
            matches!(e, LocalizeError::Describe(VisionError::InvalidImage(_)))
        }),
        ("constant", gray(&constant), |e| {
            matches!(e, LocalizeError::Describe(VisionError::Uninformative(_)))
        }),
        (
            "all black RGB",
            ImageView::packed(W as u32, H as u32, PixelFormat::Rgb8, &black),
            |e| matches!(e, LocalizeError::Describe(VisionError::Uninformative(_))),
        ),
    ];
    for (t, (name, image, expected)) in cases.into_iter().enumerate() {
        let frame = Frame {
            timestamp: 1.0 + t as f64,
            image: Some(image),
            ..Frame::default()
        };
        match localizer.localize(&frame) {
            Err(e) => assert!(expected(&e), "{name}: unexpected error {e}"),
            Ok(out) => panic!("{name}: expected an error, got {out:?}"),
        }
    }
    // Nothing above changed the state: both localizers agree on the next frame.
    let a = localizer.localize(&image_frame(&images[1], 20.0)).unwrap();
    let b = twin.localize(&image_frame(&images[1], 20.0)).unwrap();
    assert_eq!(a, b);
    assert_eq!(first.frame_index + 1, a.frame_index);
}

#[test]
fn image_frames_need_a_describer() {
    let images: Vec<Vec<u8>> = (0..4).map(place_image).collect();
    let map = Arc::new(build(&images, BackendConfig::Vlad(VladOptions::default())).unwrap());
    let mut plain = Localizer::new(map, Default::default()).unwrap();
    assert!(matches!(
        plain.localize(&image_frame(&images[0], 0.0)),
        Err(LocalizeError::NoDescriber(_))
    ));
    let descriptors_only = Arc::new(topoloc_synthetic::random_map(5, 1, 8, 1));
    assert!(matches!(
        Localizer::with_describer(descriptors_only, Default::default(), &Default::default()),
        Err(LocalizeError::NoDescriber(_))
    ));
}

#[test]
fn a_describer_of_another_backend_or_model_is_refused() {
    let images: Vec<Vec<u8>> = (0..4).map(place_image).collect();
    let map = Arc::new(build(&images, BackendConfig::Vlad(VladOptions::default())).unwrap());
    let onnx = DescriberOptions {
        backend: Some(BackendKind::Onnx),
        ..Default::default()
    };
    assert!(matches!(
        Localizer::with_describer(map.clone(), Default::default(), &onnx),
        Err(LocalizeError::Describe(VisionError::Mismatch(_)))
    ));
    // The same backend kind with another local feature is refused too (the family policy
    // that C's TOPOLOC_BACKEND_VLAD_SIFT applies lives in the core).
    let sift = DescriberOptions {
        backend: Some(BackendKind::Vlad),
        family: Some("vlad-sift".into()),
        ..Default::default()
    };
    assert!(matches!(
        Localizer::with_describer(map.clone(), Default::default(), &sift),
        Err(LocalizeError::Describe(VisionError::Mismatch(_)))
    ));
    let orb = DescriberOptions {
        family: Some("vlad-orb".into()),
        ..Default::default()
    };
    assert!(Localizer::with_describer(map.clone(), Default::default(), &orb).is_ok());
    if !onnx_available() {
        return;
    }
    let onnx_map = build(&images, BackendConfig::Onnx(OnnxOptions::default())).unwrap();
    let mut model = onnx_map.describer().unwrap().as_ref().clone();
    if let BackendSpec::Onnx { model_sha256, .. } = &mut model.spec {
        model_sha256.replace_range(0..4, "0000");
    }
    match Describer::new(Arc::new(model), &DescriberOptions::default()) {
        // Neither cache file is the map's: both are named.
        Err(VisionError::Mismatch(msg)) => assert!(
            msg.contains("sha256")
                && msg.contains(DEFAULT_MODEL_FILE)
                && msg.contains(F32_MODEL_FILE),
            "{msg}"
        ),
        Err(e) => panic!("expected Mismatch, got {e}"),
        Ok(_) => panic!("expected Mismatch, got a describer"),
    }
}

/// Maps name their network by its hash: a map of the f32 network (built before int8 was the
/// default, or by a host that asked for it) loads with no model path, from the cache's f32
/// file, and describes as it was built; a map of the int8 default loads the int8 file.
#[test]
fn maps_of_the_f32_network_and_of_the_int8_default_both_load_from_the_cache() {
    let (Some(f32_file), true) = (common::models::cached(F32_MODEL_FILE), onnx_available()) else {
        return;
    };
    let images: Vec<Vec<u8>> = (0..4).map(place_image).collect();
    let f32_backend = BackendConfig::Onnx(OnnxOptions {
        model: Some(f32_file),
        ..OnnxOptions::default()
    });
    let mut identities = Vec::new();
    for backend in [f32_backend, BackendConfig::Onnx(OnnxOptions::default())] {
        let map = build(&images, backend).unwrap();
        let model = map.describer().unwrap().clone();
        let mut describer = Describer::new(model.clone(), &DescriberOptions::default())
            .expect("the cache holds the map's network");
        assert_eq!(describer.identity(), map.descriptor());
        // The map's own first image describes as the map's first view was.
        let mut out = Vec::new();
        describer.describe(&gray(&images[0]), &mut out).unwrap();
        let view = map.view_descriptor(0).unwrap().to_vec();
        let cosine: f32 = out.iter().zip(&view).map(|(a, b)| a * b).sum();
        assert!(cosine > 0.999, "cosine {cosine} to the map's own view");
        identities.push(describer.identity().clone());
    }
    assert_ne!(
        identities[0], identities[1],
        "two networks, two descriptor identities"
    );
}

/// A network that is not the declared one is refused when it is loaded, naming the file and
/// what was expected: XFeat's model (one grey `image` input) as the describer's CNN, and the
/// CNN (a 3-channel `input`) as XFeat.
#[test]
fn models_with_other_inputs_are_refused_naming_the_file() {
    let (Some(xfeat), Some(cnn)) = (
        common::models::cached(topoloc::verify::xfeat::DEFAULT_XFEAT_MODEL_FILE),
        common::models::cached(DEFAULT_MODEL_FILE),
    ) else {
        return;
    };
    let as_cnn = OnnxMlf::new(OnnxOptions {
        model: Some(xfeat.clone()),
        ..OnnxOptions::default()
    });
    match as_cnn {
        Err(VisionError::Model(msg)) => assert!(
            msg.contains(&*xfeat.to_string_lossy()) && msg.contains("'input'"),
            "{msg}"
        ),
        Err(e) => panic!("expected a model error, got {e}"),
        Ok(_) => panic!("XFeat accepted as the describer's CNN"),
    }
    let options = topoloc::verify::XFeatOptions {
        model: Some(cnn.clone()),
        ..Default::default()
    };
    match topoloc::verify::XFeatDetector::new(&options, 256) {
        Err(VisionError::Model(msg)) => assert!(
            msg.contains(&*cnn.to_string_lossy()) && msg.contains("'image'"),
            "{msg}"
        ),
        Err(e) => panic!("expected a model error, got {e}"),
        Ok(_) => panic!("the CNN accepted as XFeat"),
    }
}

#[test]
fn a_corrupt_or_missing_model_file_is_a_typed_error() {
    let dir = tempfile::tempdir().unwrap();
    let corrupt = dir.path().join("corrupt.onnx");
    std::fs::write(&corrupt, b"this is not an ONNX model").unwrap();
    let images: Vec<Vec<u8>> = (0..3).map(place_image).collect();
    for (model, runtime_needed) in [(dir.path().join("missing.onnx"), false), (corrupt, true)] {
        let backend = BackendConfig::Onnx(OnnxOptions {
            model: Some(model.clone()),
            ..OnnxOptions::default()
        });
        match build(&images, backend) {
            Err(ImageMapError::Describe(VisionError::BackendUnavailable { tried, .. })) => {
                assert!(
                    tried.contains(&model) || runtime_needed,
                    "the path tried is named: {tried:?}"
                )
            }
            Err(ImageMapError::Describe(VisionError::Model(msg))) => {
                assert!(runtime_needed && msg.contains("corrupt.onnx"), "{msg}")
            }
            Err(e) => panic!("{}: unexpected error {e}", model.display()),
            Ok(_) => panic!("{}: expected an error", model.display()),
        }
    }
}

#[test]
fn a_missing_xfeat_model_is_backend_unavailable_naming_its_path() {
    // XFeat is the default local features: a build that cannot load its model says which file
    // was tried, with the kind a host can act on (not a generic model error).
    let model = tempfile::tempdir().unwrap().path().join("xfeat.onnx");
    let sources: Vec<Vec<u8>> = (0..3).map(place_image).collect();
    let sources: Vec<ImageSource> = sources
        .iter()
        .map(|d| ImageSource::Pixels(gray(d)))
        .collect();
    let mut options = ImageMapOptions {
        backend: BackendConfig::Vlad(VladOptions::default()),
        threads: 2,
        ..ImageMapOptions::default()
    };
    assert_eq!(options.features, DEFAULT_MAP_FEATURES);
    assert_eq!(DEFAULT_MAP_FEATURES, FeatureKind::XFeat);
    options.xfeat.model = Some(model.clone());
    match build_from_images(&sources, ImageLayout::Sequence, &options, &mut no_progress) {
        Err(ImageMapError::Describe(VisionError::BackendUnavailable { tried, .. })) => {
            assert!(tried.contains(&model), "the path tried is named: {tried:?}")
        }
        Err(e) => panic!("unexpected error {e}"),
        Ok(_) => panic!("expected an error"),
    }
}

#[test]
fn progress_is_reported_and_can_cancel() {
    let images: Vec<Vec<u8>> = (0..8).map(place_image).collect();
    let sources: Vec<ImageSource> = images
        .iter()
        .map(|d| ImageSource::Pixels(gray(d)))
        .collect();
    let mut seen = Vec::new();
    let mut record = |stage: BuildStage, done: usize, total: usize| {
        seen.push((stage, done, total));
        true
    };
    let options = ImageMapOptions {
        backend: BackendConfig::Vlad(VladOptions::default()),
        ..ImageMapOptions::default()
    };
    build_from_images(&sources, ImageLayout::Sequence, &options, &mut record).unwrap();
    assert_eq!(seen.first().map(|s| s.0), Some(BuildStage::Describing));
    assert!(seen.contains(&(BuildStage::Describing, 8, 8)));
    assert_eq!(seen.last(), Some(&(BuildStage::Fitting, 1, 1)));
    let mut cancel = |_: BuildStage, _: usize, _: usize| false;
    assert!(matches!(
        build_from_images(&sources, ImageLayout::Sequence, &options, &mut cancel),
        Err(ImageMapError::Cancelled)
    ));
}

#[test]
fn a_known_place_graph_lays_out_the_views() {
    // Three places on a line, two views each (yaw 0 and pi), edges 0-1 and 1-2.
    let images: Vec<Vec<u8>> = (0..6).map(|i| place_image(500 + i)).collect();
    let sources: Vec<ImageSource> = images
        .iter()
        .map(|d| ImageSource::Pixels(gray(d)))
        .collect();
    let positions: Vec<Point3<f64>> = (0..3)
        .map(|p| Point3::new(2.0 * p as f64, 0.0, 1.2))
        .collect();
    let views: Vec<(u32, Isometry3<f64>)> = (0..6)
        .map(|i| {
            let place = (i / 2) as u32;
            let yaw = if i % 2 == 0 {
                0.0
            } else {
                std::f64::consts::PI
            };
            let pose = Isometry3::new(positions[place as usize].coords, Vector3::z() * yaw);
            (place, pose)
        })
        .collect();
    let layout = PlaceLayout {
        positions: positions.clone(),
        edges: vec![(0, 1), (1, 2)],
        views: views.clone(),
    };
    let options = ImageMapOptions {
        backend: BackendConfig::Vlad(VladOptions::default()),
        threads: 1,
        ..ImageMapOptions::default()
    };
    let (map, _) = build_from_images(
        &sources,
        ImageLayout::Graph(&layout),
        &options,
        &mut no_progress,
    )
    .unwrap();
    assert_eq!(
        (map.place_count(), map.view_count(), map.edge_count()),
        (3, 6, 2)
    );
    for (p, position) in positions.iter().enumerate() {
        assert_eq!(map.place_position(p as u32).unwrap(), Some(*position));
        assert_eq!(
            map.place_views(p as u32).unwrap(),
            &[2 * p as u32, 2 * p as u32 + 1]
        );
    }
    for (i, (_, pose)) in views.iter().enumerate() {
        let view = map.view(i as u32).unwrap();
        assert_eq!(view.keyframe_id, Some(i as u64));
        assert_eq!(view.world_t_camera, Some(*pose));
    }
    assert_eq!(map.neighbours(1).unwrap().0, &[0, 2]);
    // One layout view per image, places that exist.
    let short = PlaceLayout {
        views: views[..5].to_vec(),
        ..layout.clone()
    };
    let err = build_from_images(
        &sources,
        ImageLayout::Graph(&short),
        &options,
        &mut no_progress,
    )
    .unwrap_err();
    assert!(
        err.to_string().contains("5 layout views for 6 images"),
        "{err}"
    );
    let mut unknown = layout.clone();
    unknown.edges.push((1, 7));
    assert!(matches!(
        build_from_images(
            &sources,
            ImageLayout::Graph(&unknown),
            &options,
            &mut no_progress
        ),
        Err(ImageMapError::Map(MapError::UnknownPlace { place: 7, .. }))
    ));
}
