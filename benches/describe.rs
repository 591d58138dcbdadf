//! Describing images, one thread, 320x240 input, D = 512: the ONNX multi-level descriptor, the
//! VLAD-ORB descriptor, and the whole localize step (describe + filter) on a 1k-view map; and
//! geometric verification: ORB keypoints of the input, and one pair check (matching + RANSAC)
//! against the input shifted by 6 pixels (many inliers) and against it mirrored (few).
//!
//! Run: `cargo bench --bench describe` (add `-- --quick` for a shorter run). The ONNX cases need
//! scripts/setup-models.sh (skipped with a message otherwise). The input is a 320x240 colour
//! photograph-like image: a Gardens Point frame when ../shared/data is present (resized), else
//! a generated textured image. Targets: ONNX <= 25 ms, VLAD-ORB <= 15 ms, localize within 1 ms
//! of describe at 1k views. Figures are recorded in BENCHMARKS.md.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;
use topoloc::describe::describer::RawFeatures;
use topoloc::describe::onnx::{cache_dir, OnnxOptions, DEFAULT_MODEL_FILE, F32_MODEL_FILE};
use topoloc::describe::pca::{Components, Pca, PcaPrecision};
use topoloc::describe::vlad::{Codebook, VladOptions};
use topoloc::describe::{BackendConfig, Describer, DescriberModel, Extractor};
use topoloc::image::{read_rgb, ImageView, PixelFormat};
use topoloc::verify::{check_pair, KeypointDetector, PairOptions, DEFAULT_KEYPOINTS};
use topoloc::{Frame, Localization, Localizer, LocalizerOptions, MapBuilder};
use topoloc_synthetic::random_map;

const DIM: usize = 512;
const VIEWS: usize = 1_000;
const W: u32 = 320;
const H: u32 = 240;

/// A 320x240 RGB input: a real frame if the shared data is there, else a generated texture.
fn input_image() -> Vec<u8> {
    let real = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/gardens-point/day_left/Image000.jpg");
    if let Ok((w, h, rgb)) = read_rgb(&real) {
        let mut out = vec![0u8; (W * H * 3) as usize];
        // Nearest-neighbour resize: the bench measures describing a 320x240 input.
        for y in 0..H as usize {
            for x in 0..W as usize {
                let (sx, sy) = (x * w as usize / W as usize, y * h as usize / H as usize);
                let s = (sy * w as usize + sx) * 3;
                out[(y * W as usize + x) * 3..][..3].copy_from_slice(&rgb[s..s + 3]);
            }
        }
        eprintln!("input: {} resized to 320x240", real.display());
        return out;
    }
    eprintln!("input: generated texture (no shared data)");
    let mut state = 12345u64;
    let mut next = move |m: u32| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 33) % u64::from(m)) as u32
    };
    let mut data: Vec<u8> = (0..W * H * 3)
        .map(|i| ((i / 3) % W * 200 / W) as u8)
        .collect();
    for _ in 0..200 {
        let (x0, y0, w, h) = (next(W), next(H), 4 + next(40), 4 + next(40));
        let colour = [next(256) as u8, next(256) as u8, next(256) as u8];
        for y in y0..(y0 + h).min(H) {
            for x in x0..(x0 + w).min(W) {
                data[((y * W + x) * 3) as usize..][..3].copy_from_slice(&colour);
            }
        }
    }
    data
}

/// A describer model for `config` with a D = 512 projection (random rows: the cost of PCA is
/// what matters here, not its directions) and, for VLAD, a codebook trained on the input.
fn model(config: &BackendConfig, image: &ImageView) -> Option<DescriberModel> {
    let mut extractor = match Extractor::new(config) {
        Ok(e) => e,
        Err(e) => {
            eprintln!("skipped {config:?}: {e}");
            return None;
        }
    };
    let raw = extractor.extract(image).expect("describable input");
    let (input_dim, codebook) = match &raw {
        RawFeatures::Mlf(v) => (v.len(), None),
        RawFeatures::Local(l) => {
            let clusters = VladOptions::default().clusters;
            let codebook = Codebook::train(&l.values, l.dim, clusters).expect("codebook");
            (clusters * l.dim, Some(codebook))
        }
    };
    let components = (0..DIM * input_dim)
        .map(|i| ((i * 2654435761) % 1000) as f32 / 1000.0 - 0.5)
        .collect();
    Some(DescriberModel {
        spec: extractor.spec().clone(),
        pca: Pca {
            input_dim,
            output_dim: DIM,
            mean: vec![0.0; input_dim],
            components: Components::F32(components),
        }
        .with_precision(PcaPrecision::default()),
        codebook,
    })
}

fn describe(c: &mut Criterion) {
    let pixels = input_image();
    let image = ImageView::packed(W, H, PixelFormat::Rgb8, &pixels);
    let onnx_ready = cache_dir().join(DEFAULT_MODEL_FILE).is_file();
    let mut configs = vec![("vlad-orb", BackendConfig::Vlad(VladOptions::default()))];
    if onnx_ready {
        configs.insert(0, ("onnx-mlf", BackendConfig::Onnx(OnnxOptions::default())));
        // The f32 network beside the int8 default, in the same run.
        let f32_model = cache_dir().join(F32_MODEL_FILE);
        if f32_model.is_file() {
            let f32_options = OnnxOptions {
                model: Some(f32_model),
                ..OnnxOptions::default()
            };
            configs.insert(1, ("onnx-mlf-f32", BackendConfig::Onnx(f32_options)));
        }
    } else {
        eprintln!("skipped onnx-mlf: no model in {}", cache_dir().display());
    }
    let mut group = c.benchmark_group("describe_320x240");
    group
        .sample_size(30)
        .measurement_time(Duration::from_secs(6));
    for (name, config) in configs {
        let Some(model) = model(&config, &image) else {
            continue;
        };
        let model = Arc::new(model);
        let mut describer = Describer::new(model.clone(), &Default::default()).unwrap();
        let mut out = Vec::new();
        group.bench_function(format!("{name}/describe"), |b| {
            b.iter(|| describer.describe(black_box(&image), &mut out).unwrap())
        });

        // The same describer inside a localizer on a 1k-view map of its identity.
        let random = random_map(VIEWS, 4, DIM, 3);
        let mut builder = MapBuilder::new(model.identity());
        for p in 0..random.place_count() as u32 {
            builder.add_place(None).unwrap();
            for &v in random.place_views(p).unwrap() {
                builder
                    .add_view(p, random.view_descriptor(v).unwrap(), Default::default())
                    .unwrap();
            }
        }
        for e in random.edges() {
            builder.add_edge(e.a, e.b, e.weight).unwrap();
        }
        let map = Arc::new(builder.build().unwrap().with_describer(model).unwrap());
        let mut localizer =
            Localizer::with_describer(map, LocalizerOptions::default(), &Default::default())
                .unwrap();
        let mut result = Localization::default();
        let mut t = 0.0;
        group.bench_function(format!("{name}/localize_1k_views"), |b| {
            b.iter(|| {
                t += 0.1;
                let frame = Frame {
                    timestamp: t,
                    image: Some(image),
                    ..Frame::default()
                };
                localizer.process(black_box(&frame), &mut result).unwrap()
            })
        });
    }
    group.finish();
}

/// The projection alone, D = 512 rows of the multi-level vector (F = 27,648), stored as f32
/// and as i8: the part of describing that grows with the map's PCA.
fn pca_project(c: &mut Criterion) {
    const F: usize = 27_648;
    let exact = Pca {
        input_dim: F,
        output_dim: DIM,
        mean: vec![0.01; F],
        components: Components::F32(
            (0..DIM * F)
                .map(|i| ((i * 2654435761) % 1000) as f32 / 1000.0 - 0.5)
                .collect(),
        ),
    };
    let x: Vec<f32> = (0..F).map(|i| (i % 97) as f32 / 97.0).collect();
    let mut group = c.benchmark_group("pca_project_512x27648");
    group
        .sample_size(30)
        .measurement_time(Duration::from_secs(5));
    for precision in [PcaPrecision::F32, PcaPrecision::I8] {
        let pca = exact.clone().with_precision(precision);
        group.bench_function(precision.name(), |b| {
            b.iter(|| pca.project(black_box(&x)).unwrap())
        });
    }
    group.finish();
}

/// `pixels` (RGB, W x H) moved `dx` pixels left, or mirrored left-right when `dx` is `None`.
fn moved(pixels: &[u8], dx: Option<usize>) -> Vec<u8> {
    let w = W as usize;
    let mut out = pixels.to_vec();
    for (row_out, row_in) in out.chunks_exact_mut(w * 3).zip(pixels.chunks_exact(w * 3)) {
        for x in 0..w {
            let from = match dx {
                Some(d) => (x + d).min(w - 1),
                None => w - 1 - x,
            };
            row_out[x * 3..x * 3 + 3].copy_from_slice(&row_in[from * 3..from * 3 + 3]);
        }
    }
    out
}

fn verify(c: &mut Criterion) {
    let pixels = input_image();
    let image = ImageView::packed(W, H, PixelFormat::Rgb8, &pixels);
    let mut detector = KeypointDetector::new(DEFAULT_KEYPOINTS).unwrap();
    let stored = detector.detect(&image).unwrap();
    let mut group = c.benchmark_group("verify_320x240");
    group
        .sample_size(30)
        .measurement_time(Duration::from_secs(6));
    group.bench_function("detect_500_keypoints", |b| {
        b.iter(|| detector.detect(black_box(&image)).unwrap())
    });
    let options = PairOptions::default();
    for (name, dx) in [
        ("check_pair/same_place", Some(6)),
        ("check_pair/other_place", None),
    ] {
        let query_pixels = moved(&pixels, dx);
        let query = detector
            .detect(&ImageView::packed(W, H, PixelFormat::Rgb8, &query_pixels))
            .unwrap();
        let check = check_pair(query.as_ref(), stored.as_ref(), &options).unwrap();
        eprintln!("{name}: {check:?}");
        group.bench_function(name, |b| {
            b.iter(|| check_pair(black_box(query.as_ref()), stored.as_ref(), &options).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, describe, pca_project, verify);
criterion_main!(benches);
