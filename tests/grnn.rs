//! The learned estimator (`Mode::Grnn`) through the public API: it follows a walk with the
//! model built into the library, is deterministic, depends on its carried state, forgets
//! everything on reset, leaves its state unchanged after bad input, and refuses with a typed
//! error a file that is not ONNX, a model of another contract, a map without a graph and a map
//! whose windows exceed the model.
//! Needs ONNX Runtime (scripts/setup-models.sh): skipped without it, failing in CI.

mod common;

use common::{chain_map, mix, unit_vector};
use std::sync::Arc;
use topoloc::{
    DescriptorIdentity, Frame, GrnnError, GrnnOptions, Localization, LocalizeError, Localizer,
    LocalizerOptions, Map, MapBuilder, Mode,
};

const DIM: u32 = 32;

fn options(model: Option<std::path::PathBuf>) -> LocalizerOptions {
    LocalizerOptions {
        mode: Mode::Grnn,
        grnn: GrnnOptions {
            model,
            ..GrnnOptions::default()
        },
        ..LocalizerOptions::default()
    }
}

/// A GRNN localizer on `map` with the built-in model, or `None` (after saying why) when ONNX
/// Runtime is not set up.
fn grnn(map: &Arc<Map>) -> Option<Localizer> {
    match Localizer::new(map.clone(), options(None)) {
        Ok(localizer) => Some(localizer),
        Err(LocalizeError::Grnn(GrnnError::Unavailable(e))) => {
            common::models::unavailable(&e.to_string());
            None
        }
        Err(e) => panic!("creating the GRNN localizer: {e}"),
    }
}

/// Walks 0 -> 29 along the chain, three frames per place, each its first view plus noise.
fn walk(map: &Map, noise: f32) -> (Vec<Vec<f32>>, Vec<u32>) {
    let truth: Vec<u32> = (0..30).flat_map(|p| [p, p, p]).collect();
    let frames = truth
        .iter()
        .enumerate()
        .map(|(i, &p)| {
            let view = map.place_views(p).unwrap()[0];
            let noise_vector = unit_vector(50_000 + i as u64, map.dim());
            mix(map.view_descriptor(view).unwrap(), &noise_vector, noise)
        })
        .collect();
    (frames, truth)
}

fn frame(i: usize, descriptor: &[f32]) -> Frame<'_> {
    Frame {
        timestamp: i as f64 * 0.1,
        descriptor,
        odometry: None,
        image: None,
    }
}

fn run(localizer: &mut Localizer, frames: &[Vec<f32>]) -> Vec<Localization> {
    let results = frames
        .iter()
        .enumerate()
        .map(|(i, d)| localizer.localize(&frame(i, d)).unwrap());
    results.collect()
}

#[test]
fn the_built_in_model_follows_a_walk_deterministically_and_reset_forgets() {
    let map = Arc::new(chain_map(40, 4, DIM));
    let Some(mut localizer) = grnn(&map) else {
        return;
    };
    let (frames, truth) = walk(&map, 0.5);
    let first = run(&mut localizer, &frames);
    let correct = first
        .iter()
        .zip(&truth)
        .filter(|(r, t)| r.place == **t)
        .count();
    let accuracy = correct as f64 / truth.len() as f64;
    assert!(
        accuracy >= 0.9,
        "GRNN accuracy {accuracy} on a walk with light noise"
    );
    for r in &first {
        let total: f32 = r.candidates.iter().map(|c| c.probability).sum();
        assert!(total <= 1.0 + 1e-4 && r.confidence > 0.0, "{r:?}");
        assert!(r
            .candidates
            .windows(2)
            .all(|w| w[0].probability >= w[1].probability));
    }
    localizer.reset();
    assert_eq!(
        run(&mut localizer, &frames),
        first,
        "reset must forget everything"
    );
    let mut other = grnn(&map).unwrap();
    assert_eq!(run(&mut other, &frames), first, "two localizers must agree");
}

#[test]
fn forgetting_the_state_changes_every_frame_but_the_first() {
    let map = Arc::new(chain_map(40, 4, DIM));
    let Some(mut carrying) = grnn(&map) else {
        return;
    };
    let forgetful = LocalizerOptions {
        grnn: GrnnOptions {
            forget_state: true,
            ..GrnnOptions::default()
        },
        ..options(None)
    };
    let mut forgetting = Localizer::new(map.clone(), forgetful).unwrap();
    let (frames, _) = walk(&map, 0.5);
    let (kept, forgot) = (run(&mut carrying, &frames), run(&mut forgetting, &frames));
    assert_eq!(kept[0], forgot[0], "the first frame has no state to carry");
    let differing = kept
        .iter()
        .zip(&forgot)
        .skip(1)
        .filter(|(a, b)| (a.confidence - b.confidence).abs() > 1e-4)
        .count();
    assert!(
        differing * 10 >= 9 * (frames.len() - 1),
        "only {differing} of {} later frames changed without the carried state",
        frames.len() - 1
    );
}

#[test]
fn bad_input_leaves_the_recurrent_state_unchanged() {
    let map = Arc::new(chain_map(40, 4, DIM));
    let Some(mut clean) = grnn(&map) else {
        return;
    };
    let mut interrupted = grnn(&map).unwrap();
    let (frames, _) = walk(&map, 0.5);
    let expected = run(&mut clean, &frames);
    for (i, d) in frames.iter().enumerate() {
        if i == 20 {
            let short = &d[..5];
            let err = interrupted.localize(&frame(i, short)).unwrap_err();
            assert!(matches!(err, LocalizeError::Descriptor(_)), "{err}");
            let backwards = interrupted.localize(&frame(0, d)).unwrap_err();
            assert!(
                matches!(backwards, LocalizeError::Timestamp(_)),
                "{backwards}"
            );
        }
        assert_eq!(
            interrupted.localize(&frame(i, d)).unwrap(),
            expected[i],
            "frame {i}"
        );
    }
}

#[test]
fn a_file_that_is_not_onnx_is_refused() {
    let map = Arc::new(chain_map(5, 2, DIM));
    if grnn(&map).is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("grnn.onnx");
    std::fs::write(&path, b"not a protobuf at all \x00\x01\x02").unwrap();
    let err = Localizer::new(map, options(Some(path))).err().unwrap();
    assert!(
        matches!(err, LocalizeError::Grnn(GrnnError::NotOnnx(_))),
        "{err}"
    );
}

#[test]
fn a_model_of_another_contract_is_refused() {
    let map = Arc::new(chain_map(5, 2, DIM));
    let Some(other) = common::models::cached("models/xfeat.onnx") else {
        return;
    };
    let err = Localizer::new(map, options(Some(other))).err().unwrap();
    assert!(
        matches!(err, LocalizeError::Grnn(GrnnError::Contract(_))),
        "{err}"
    );
    assert!(err.to_string().contains("topoloc.model"), "{err}");
}

#[test]
fn a_missing_model_file_names_the_path() {
    let map = Arc::new(chain_map(5, 2, DIM));
    if grnn(&map).is_none() {
        return;
    }
    let path = std::path::PathBuf::from("/nonexistent/grnn.onnx");
    let err = Localizer::new(map, options(Some(path))).err().unwrap();
    assert!(
        matches!(err, LocalizeError::Grnn(GrnnError::Unavailable(_))),
        "{err}"
    );
    assert!(err.to_string().contains("/nonexistent/grnn.onnx"), "{err}");
}

#[test]
fn maps_without_a_graph_or_too_large_for_the_model_are_refused() {
    let mut builder = MapBuilder::new(DescriptorIdentity::new("test", "chain-v1", DIM).unwrap());
    for p in 0..3u64 {
        let place = builder.add_place(None).unwrap();
        let d = unit_vector(p, DIM as usize);
        builder.add_view(place, &d, Default::default()).unwrap();
    }
    let no_edges = Arc::new(builder.build().unwrap());
    let err = Localizer::new(no_edges, options(None)).err().unwrap();
    assert!(
        matches!(err, LocalizeError::Grnn(GrnnError::NoGraph(_))),
        "{err}"
    );

    // Two places of 2,500 views: a window of both is beyond the built-in model's 2,048 nodes.
    let huge = Arc::new(chain_map(2, 2_500, 8));
    match Localizer::new(huge, options(None)) {
        Err(LocalizeError::Grnn(GrnnError::GraphTooLarge { nodes, limit })) => {
            assert_eq!((nodes, limit), (5_000, 2_048));
        }
        Err(LocalizeError::Grnn(GrnnError::Unavailable(e))) => {
            common::models::unavailable(&e.to_string())
        }
        other => panic!("expected GraphTooLarge, got {:?}", other.err()),
    }
}
