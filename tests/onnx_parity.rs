//! Parity of the ONNX backend with an independent reference: scripts/mlf_reference.py computes
//! the same multi-level features with PyTorch alone (torchvision MobileNetV2 and the .pth weights,
//! no ONNX Runtime, no topoloc code), and the Rust pipeline (preprocessing, ONNX Runtime, adaptive
//! pooling, per-level L2) must agree with it on a fixed 320x240 pattern. The pattern is already at
//! the network input size, so neither side resizes; resizing is covered by other tests.
//!
//! The f32 network is the one compared with PyTorch; the int8 default is compared with the f32
//! network (it is a quantization of it, so PyTorch has no int8 reference).
//!
//! Skipped (with a message) only when the cache lacks the model or the weights
//! (scripts/setup-models.sh) or /usr/bin/python3 cannot import torch and torchvision.

mod common;

use std::path::Path;
use std::process::Command;
use topoloc::describe::onnx::{OnnxMlf, OnnxOptions, DEFAULT_MODEL_FILE, F32_MODEL_FILE};
use topoloc::describe::pca::Pca;
use topoloc::image::{ImageView, PixelFormat};

const PYTHON: &str = "/usr/bin/python3";
const WEIGHTS_FILE: &str = "models/mobilenet_v2-b0353104.pth";
const W: u32 = 320;
const H: u32 = 240;

/// A deterministic 320x240 RGB pattern with structure at every scale: diagonal stripes, colour
/// gradients, a fine checkerboard, a ring and a few solid blocks.
fn pattern() -> Vec<u8> {
    let mut data = Vec::with_capacity((W * H * 3) as usize);
    for y in 0..H {
        for x in 0..W {
            let (fx, fy) = (x as i32, y as i32);
            let mut px = [
                ((x + 2 * y) % 40 * 6) as u8,
                (x * 255 / (W - 1)) as u8,
                (y * 255 / (H - 1)) as u8,
            ];
            let ring = (fx - 230).pow(2) + (fy - 150).pow(2);
            if (20..80).contains(&x) && (30..90).contains(&y) {
                px = [220, 40, 30];
            } else if (100..160).contains(&x) && (160..220).contains(&y) {
                px = if (x / 4 + y / 4) % 2 == 0 {
                    [250; 3]
                } else {
                    [10; 3]
                };
            } else if (1600..3600).contains(&ring) {
                px = [30, 60, 200];
            } else if (250..310).contains(&x) && (10..50).contains(&y) {
                px = [(y * 6) as u8, 200, (x % 16 * 16) as u8];
            }
            data.extend_from_slice(&px);
        }
    }
    data
}

/// The reference vector, or None (after printing why) when the test must be skipped.
fn reference(image: &[u8], taps: &[&str], grid: (usize, usize)) -> Option<Vec<f32>> {
    let _model = common::models::cached(F32_MODEL_FILE)?;
    let weights = common::models::cached(WEIGHTS_FILE)?;
    let has_torch = Command::new(PYTHON)
        .args(["-c", "import torch, torchvision"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_torch {
        common::models::unavailable(&format!(
            "{PYTHON} cannot import torch and torchvision (python3-torch)"
        ));
        return None;
    }
    let dir = tempfile::tempdir().unwrap();
    let raw = dir.path().join("pattern.rgb");
    std::fs::write(&raw, image).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/mlf_reference.py");
    let output = Command::new(PYTHON)
        .arg(&script)
        .arg("--weights")
        .arg(&weights)
        .arg("--image")
        .arg(&raw)
        .args(["--width", &W.to_string(), "--height", &H.to_string()])
        .args(["--taps", &taps.join(",")])
        .args(["--grid", &grid.0.to_string(), &grid.1.to_string()])
        .output()
        .unwrap_or_else(|e| panic!("running {}: {e}", script.display()));
    assert!(
        output.status.success(),
        "{} failed: {}",
        script.display(),
        String::from_utf8_lossy(&output.stderr)
    );
    Some(serde_json::from_slice(&output.stdout).expect("a JSON list of floats"))
}

/// The f32 network of the cache with these taps and grid.
fn backend(taps: &[&str], grid: (usize, usize)) -> OnnxMlf {
    backend_of(F32_MODEL_FILE, taps, grid)
}

fn backend_of(file: &str, taps: &[&str], grid: (usize, usize)) -> OnnxMlf {
    OnnxMlf::new(OnnxOptions {
        model: Some(common::models::cache_dir().join(file)),
        taps: taps.iter().map(|t| t.to_string()).collect(),
        grid,
        ..Default::default()
    })
    .expect("runtime and model from the cache")
}

/// Runs both sides and asserts max |a - b| < 1e-4 and cosine > 0.99999; with more than one grid
/// cell, also that every level varies across the cells (the pattern exercises all of them).
fn check_parity(taps: &[&str], grid: (usize, usize), channels: &[usize]) {
    let cells = grid.0 * grid.1;
    let expected_len = channels.iter().sum::<usize>() * cells;
    let image = pattern();
    let Some(expected) = reference(&image, taps, grid) else {
        return;
    };
    let actual = backend(taps, grid)
        .raw_features(&ImageView::packed(W, H, PixelFormat::Rgb8, &image))
        .unwrap();
    assert_eq!(actual.len(), expected_len, "Rust vector length");
    assert_eq!(expected.len(), expected_len, "reference vector length");
    let max_diff = actual
        .iter()
        .zip(&expected)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    let dot = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(&x, &y)| f64::from(x) * f64::from(y))
            .sum::<f64>()
    };
    let cosine =
        dot(&actual, &expected) / (dot(&actual, &actual) * dot(&expected, &expected)).sqrt();
    eprintln!(
        "taps {taps:?} grid {grid:?}: {expected_len} values, max |diff| {max_diff:.3e}, \
         cosine {cosine:.12} (1 - cosine {:.1e})",
        1.0 - cosine
    );
    let mut start = 0;
    for (tap, &c) in taps.iter().zip(channels) {
        let level = &actual[start..start + c * cells];
        let level_diff = level
            .iter()
            .zip(&expected[start..])
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f32, f32::max);
        // Norm of the level's deviation from its per-channel means (the level has norm 1).
        let spread = level
            .chunks_exact(cells)
            .map(|ch| {
                let mean = ch.iter().sum::<f32>() / cells as f32;
                ch.iter().map(|v| (v - mean).powi(2)).sum::<f32>()
            })
            .sum::<f32>()
            .sqrt();
        if cells == 1 {
            eprintln!("  {tap}: max |diff| {level_diff:.3e}");
        } else {
            eprintln!("  {tap}: max |diff| {level_diff:.3e}, spatial spread {spread:.3}");
            assert!(
                spread > 0.05,
                "{tap} hardly varies across the grid: {spread}"
            );
        }
        start += c * cells;
    }
    assert!(
        max_diff < 1e-4,
        "taps {taps:?} grid {grid:?}: max |diff| {max_diff:e} (cosine {cosine})"
    );
    assert!(
        cosine > 0.99999,
        "taps {taps:?} grid {grid:?}: cosine {cosine} (max |diff| {max_diff:e})"
    );
}

#[test]
fn default_options_match_the_pytorch_reference() {
    // f6 (32 channels), f13 (96), f17 (320), f18 (1280), each pooled to 4x4.
    check_parity(&["f6", "f13", "f17", "f18"], (4, 4), &[32, 96, 320, 1280]);
}

#[test]
fn other_taps_and_global_pooling_match_the_pytorch_reference() {
    // f3 (24 channels) and f18 (1280), globally pooled.
    check_parity(&["f3", "f18"], (1, 1), &[24, 1280]);
}

#[test]
fn pca_of_the_mlf_vector_matches_a_direct_computation() {
    if common::models::cached(F32_MODEL_FILE).is_none() {
        return;
    }
    let image = pattern();
    let x = backend(&["f6", "f13", "f17", "f18"], (4, 4))
        .raw_features(&ImageView::packed(W, H, PixelFormat::Rgb8, &image))
        .unwrap();
    let f = x.len();
    // Deterministic perturbations of the vector: x + 0.01 sin(...) with a different pattern each.
    let perturbed = |k: usize| -> Vec<f32> {
        x.iter()
            .enumerate()
            .map(|(j, &v)| v + 0.01 * ((j * (k + 1)) as f32 * 0.37 + k as f32).sin())
            .collect()
    };
    let samples: Vec<Vec<f32>> = std::iter::once(x.clone())
        .chain((0..5).map(perturbed))
        .collect();
    let (n, d) = (samples.len(), 5);
    let pca = Pca::fit(&samples.concat(), f, d, false).unwrap();
    assert_eq!((pca.input_dim, pca.output_dim), (f, d));
    // Mean: the plain average.
    for j in 0..f {
        let mean = samples.iter().map(|s| f64::from(s[j])).sum::<f64>() / n as f64;
        assert!((f64::from(pca.mean[j]) - mean).abs() < 1e-6, "mean[{j}]");
    }
    // Rows of W orthonormal; variance along them non-increasing; together (n - 1 of them) they
    // keep all of every centred sample's energy.
    let rows = pca.components.as_f32().expect("Pca::fit gives f32 rows");
    let row = |k: usize| &rows[k * f..(k + 1) * f];
    let dot = |a: &[f32], b: &[f64]| {
        a.iter()
            .zip(b)
            .map(|(&p, &q)| f64::from(p) * q)
            .sum::<f64>()
    };
    for a in 0..d {
        for b in 0..d {
            let wb: Vec<f64> = row(b).iter().map(|&v| f64::from(v)).collect();
            let expected = if a == b { 1.0 } else { 0.0 };
            assert!(
                (dot(row(a), &wb) - expected).abs() < 1e-4,
                "W W^T [{a},{b}]"
            );
        }
    }
    let centred: Vec<Vec<f64>> = samples
        .iter()
        .map(|s| {
            s.iter()
                .zip(&pca.mean)
                .map(|(&v, &m)| f64::from(v - m))
                .collect()
        })
        .collect();
    let variance: Vec<f64> = (0..d)
        .map(|k| centred.iter().map(|c| dot(row(k), c).powi(2)).sum())
        .collect();
    assert!(
        variance.windows(2).all(|v| v[0] >= v[1] * (1.0 - 1e-6)),
        "{variance:?}"
    );
    let energy: f64 = centred.iter().flatten().map(|v| v * v).sum();
    let captured: f64 = variance.iter().sum();
    assert!(
        (captured / energy - 1.0).abs() < 1e-3,
        "{captured} of {energy}"
    );
    // project() == normalise(W (q - mean)), for a sample and for an unseen vector.
    for q in [x.clone(), perturbed(7)] {
        let c: Vec<f64> = q
            .iter()
            .zip(&pca.mean)
            .map(|(&v, &m)| f64::from(v) - f64::from(m))
            .collect();
        let y: Vec<f64> = (0..d).map(|k| dot(row(k), &c)).collect();
        let norm = y.iter().map(|v| v * v).sum::<f64>().sqrt();
        let projected = pca.project(&q).unwrap();
        for (k, (&p, &e)) in projected.iter().zip(&y).enumerate() {
            assert!(
                (f64::from(p) - e / norm).abs() < 1e-5,
                "y[{k}]: {p} vs {}",
                e / norm
            );
        }
    }
}

fn cosine(a: &[f32], b: &[f32]) -> f64 {
    let dot = |x: &[f32], y: &[f32]| -> f64 {
        x.iter()
            .zip(y)
            .map(|(&p, &q)| f64::from(p) * f64::from(q))
            .sum()
    };
    dot(a, b) / (dot(a, a) * dot(b, b)).sqrt()
}

/// The int8 default keeps the f32 network's multi-level features: per tap (4x4 cells), the
/// cosine of the two pooled vectors on the pattern in full light and darkened to a night's
/// 15%, where quantization's coarse activation ranges would show first.
#[test]
fn int8_model_keeps_the_f32_networks_features_per_tap() {
    if common::models::cached(F32_MODEL_FILE).is_none()
        || common::models::cached(DEFAULT_MODEL_FILE).is_none()
    {
        return;
    }
    let bright = pattern();
    let dark: Vec<u8> = bright
        .iter()
        .map(|&v| (f32::from(v) * 0.15) as u8)
        .collect();
    for (tap, floor) in [("f6", 0.97), ("f13", 0.96), ("f17", 0.91), ("f18", 0.92)] {
        let mut f32_net = backend(&[tap], (4, 4));
        let mut int8_net = backend_of(DEFAULT_MODEL_FILE, &[tap], (4, 4));
        for (light, image) in [("bright", &bright), ("dark", &dark)] {
            let view = ImageView::packed(W, H, PixelFormat::Rgb8, image);
            let a = f32_net.raw_features(&view).unwrap();
            let b = int8_net.raw_features(&view).unwrap();
            let c = cosine(&a, &b);
            println!("{tap} {light}: cosine {c:.5}");
            assert!(
                c > floor,
                "{tap} {light}: int8 against f32 cosine {c:.5} <= {floor}"
            );
        }
    }
}

/// The two cache files are different networks to a map: a map records its model's hash, and
/// the int8 file is not the f32 one.
#[test]
fn int8_and_f32_models_have_different_hashes() {
    let (Some(_), Some(_)) = (
        common::models::cached(F32_MODEL_FILE),
        common::models::cached(DEFAULT_MODEL_FILE),
    ) else {
        return;
    };
    let taps = ["f6", "f13", "f17", "f18"];
    let a = backend_of(F32_MODEL_FILE, &taps, (4, 4));
    let b = backend_of(DEFAULT_MODEL_FILE, &taps, (4, 4));
    assert_ne!(a.model_sha256(), b.model_sha256());
    assert_ne!(a.identity(), b.identity());
}
