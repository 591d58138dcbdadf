//! The ONNX backend: typed errors naming what is missing, and, when scripts/setup-models.sh has
//! put the model and runtime in the cache (CI does), real descriptors from the default model.

mod common;

use topoloc::describe::onnx::{OnnxMlf, OnnxOptions, DEFAULT_MODEL_FILE};
use topoloc::errors::VisionError;
use topoloc::image::{ImageView, PixelFormat};

#[test]
fn a_missing_model_names_the_path_tried() {
    let options = OnnxOptions {
        model: Some("/nonexistent/model.onnx".into()),
        ..Default::default()
    };
    match OnnxMlf::new(options) {
        Err(VisionError::BackendUnavailable { what, tried, hint }) => {
            assert_eq!(what, "ONNX model");
            assert_eq!(
                tried,
                vec![std::path::PathBuf::from("/nonexistent/model.onnx")]
            );
            assert!(hint.contains("setup-models"), "{hint}");
        }
        Err(other) => panic!("expected BackendUnavailable, got {other}"),
        Ok(_) => panic!("expected BackendUnavailable, got a backend"),
    }
}

/// The default model from the cache, or `None` (and a note) when set-up has not run.
fn cached_model() -> Option<std::path::PathBuf> {
    common::models::cached(DEFAULT_MODEL_FILE)
}

fn expect_runtime_unavailable(options: OnnxOptions, path: &str, hint_has: &str) {
    match OnnxMlf::new(options) {
        Err(VisionError::BackendUnavailable { what, tried, hint }) => {
            assert_eq!(what, "ONNX Runtime");
            assert_eq!(tried, vec![std::path::PathBuf::from(path)]);
            assert!(hint.contains(hint_has), "{hint}");
        }
        Err(other) => panic!("expected BackendUnavailable, got {other}"),
        Ok(_) => panic!("expected BackendUnavailable, got a backend"),
    }
}

#[test]
fn an_explicit_runtime_path_is_the_only_one_tried() {
    let Some(model) = cached_model() else { return };
    // A missing explicit library is an error, never a silent fall-back to the cached one.
    let missing = "/nonexistent/libonnxruntime.so";
    let options = |runtime: &str| OnnxOptions {
        model: Some(model.clone()),
        runtime: Some(runtime.into()),
        ..Default::default()
    };
    expect_runtime_unavailable(options(missing), missing, "does not exist");
    // Once the runtime is loaded (from the cache), another library cannot be loaded as well.
    OnnxMlf::new(OnnxOptions {
        model: Some(model.clone()),
        ..Default::default()
    })
    .expect("runtime from the cache");
    let other = model.to_str().unwrap();
    expect_runtime_unavailable(options(other), other, "only once per process");
    // The missing path still fails the same way after the load.
    expect_runtime_unavailable(options(missing), missing, "does not exist");
}

#[test]
fn the_default_model_gives_per_level_normalised_deterministic_vectors() {
    if cached_model().is_none() {
        return;
    }
    let mut backend =
        OnnxMlf::new(OnnxOptions::default()).expect("runtime and model from the cache");
    // A fixed test pattern: diagonal stripes with a colour gradient.
    let (w, h) = (160u32, 120u32);
    let data: Vec<u8> = (0..h)
        .flat_map(|y| {
            (0..w).flat_map(move |x| {
                [
                    ((x + y) % 32 * 8) as u8,
                    (x * 255 / w) as u8,
                    (y * 255 / h) as u8,
                ]
            })
        })
        .collect();
    let image = ImageView::packed(w, h, PixelFormat::Rgb8, &data);
    let a = backend.raw_features(&image).unwrap();
    let b = backend.raw_features(&image).unwrap();
    assert_eq!(a, b, "not deterministic");
    // Taps f6 (32 ch), f13 (96), f17 (320), f18 (1280), each pooled to 4x4.
    let sizes = [32 * 16, 96 * 16, 320 * 16, 1280 * 16];
    assert_eq!(a.len(), sizes.iter().sum::<usize>());
    let mut start = 0;
    for size in sizes {
        let norm = a[start..start + size]
            .iter()
            .map(|x| x * x)
            .sum::<f32>()
            .sqrt();
        assert!((norm - 1.0).abs() < 1e-4, "level norm {norm}");
        start += size;
    }
    // A different image gives a different, but not unrelated, vector.
    let flipped: Vec<u8> = data.chunks_exact(3).rev().flatten().copied().collect();
    let c = backend
        .raw_features(&ImageView::packed(w, h, PixelFormat::Rgb8, &flipped))
        .unwrap();
    let cosine = a.iter().zip(&c).map(|(x, y)| x * y).sum::<f32>() / 4.0;
    assert!(cosine > 0.2 && cosine < 0.999, "cosine {cosine}");
    // Bad input is refused before the network runs.
    assert!(matches!(
        backend.raw_features(&ImageView { width: 0, ..image }),
        Err(VisionError::InvalidImage(_))
    ));
}
