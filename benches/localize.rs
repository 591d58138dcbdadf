//! Per-frame localization and map loading, single thread, D = 512.
//!
//! Run: `cargo bench --bench localize` (add `-- --quick` for a shorter run). Figures are
//! recorded in BENCHMARKS.md. Targets (2-core machine): <= 0.3 ms per frame at 1k views,
//! <= 30 ms at 100k views, map load <= 20 ms at 10k views; the learned GRNN
//! (`localize_grnn`, needs ONNX Runtime: scripts/setup-models.sh) <= 5 ms per frame at 300
//! places of 12 views, beside the graph filter on the same maps.

use criterion::measurement::WallTime;
use criterion::{
    criterion_group, criterion_main, BenchmarkGroup, BenchmarkId, Criterion, Throughput,
};
use std::hint::black_box;
use std::sync::Arc;
use std::time::Duration;
use topoloc::map::LoadOptions;
use topoloc::{Frame, Localization, Localizer, LocalizerOptions, Map, Mode};
use topoloc_synthetic::random_map;

const DIM: usize = 512;
const VIEWS_PER_PLACE: usize = 4;

/// Queries near random views of the map, so that the filter works as in real use.
fn queries(map: &Map, count: usize) -> Vec<Vec<f32>> {
    let views = map.view_count();
    (0..count)
        .map(|i| {
            let view = ((i * 7919) % views) as u32;
            let mut q: Vec<f32> = map.view_descriptor(view).unwrap().to_vec();
            for (j, x) in q.iter_mut().enumerate() {
                *x += 0.02 * (((i * 31 + j * 17) % 13) as f32 - 6.0);
            }
            q
        })
        .collect()
}

/// Times `localizer` on `queries` in turn, one frame per iteration.
fn bench_frames(
    group: &mut BenchmarkGroup<'_, WallTime>,
    id: BenchmarkId,
    localizer: &mut Localizer,
    queries: &[Vec<f32>],
) {
    let mut out = Localization::default();
    let mut i = 0usize;
    group.bench_function(id, |b| {
        b.iter(|| {
            let frame = Frame {
                timestamp: i as f64,
                descriptor: &queries[i % queries.len()],
                odometry: None,
                image: None,
            };
            localizer.process(&frame, &mut out).unwrap();
            i += 1;
            black_box(out.place)
        })
    });
}

fn per_frame(c: &mut Criterion) {
    let mut group = c.benchmark_group("localize_frame");
    for &views in &[100usize, 1_000, 10_000, 100_000] {
        let map = Arc::new(random_map(views, VIEWS_PER_PLACE, DIM, 7));
        let queries = queries(&map, 64);
        group.throughput(Throughput::Elements(1));
        if views >= 10_000 {
            group
                .sample_size(20)
                .measurement_time(Duration::from_secs(8));
        }
        for (name, mode) in [
            ("filter", Mode::Filter),
            ("single_frame", Mode::SingleFrame),
        ] {
            let mut localizer = Localizer::new(
                map.clone(),
                LocalizerOptions {
                    mode,
                    ..Default::default()
                },
            )
            .unwrap();
            bench_frames(
                &mut group,
                BenchmarkId::new(name, views),
                &mut localizer,
                &queries,
            );
        }
    }
    group.finish();
}

/// The whole frame (similarities, window, one network step) with the built-in GRNN model, and
/// the graph filter on the same maps: 20 to 2,000 places of 12 views (the seed's Fig. 4.11).
fn per_frame_grnn(c: &mut Criterion) {
    const VIEWS_PER_PLACE: usize = 12;
    let mut group = c.benchmark_group("localize_grnn");
    for &places in &[20usize, 300, 2_000] {
        let map = Arc::new(random_map(
            places * VIEWS_PER_PLACE,
            VIEWS_PER_PLACE,
            DIM,
            7,
        ));
        let queries = queries(&map, 64);
        group.throughput(Throughput::Elements(1));
        for (name, mode) in [("grnn", Mode::Grnn), ("filter", Mode::Filter)] {
            let options = LocalizerOptions {
                mode,
                ..Default::default()
            };
            let mut localizer = match Localizer::new(map.clone(), options) {
                Ok(localizer) => localizer,
                Err(e) => {
                    eprintln!("localize_grnn skipped: {e}");
                    return;
                }
            };
            bench_frames(
                &mut group,
                BenchmarkId::new(name, places),
                &mut localizer,
                &queries,
            );
        }
    }
    group.finish();
}

fn map_load(c: &mut Criterion) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("map10k.topoloc");
    random_map(10_000, VIEWS_PER_PLACE, DIM, 7)
        .save(&path)
        .unwrap();
    let bytes = std::fs::metadata(&path).unwrap().len();
    eprintln!(
        "map file, 10k views x D={DIM}: {bytes} bytes ({:.1} MiB)",
        bytes as f64 / (1 << 20) as f64
    );
    let mut group = c.benchmark_group("map_load");
    group.bench_function("mmap_10k_views", |b| {
        b.iter(|| black_box(Map::load(&path, &LoadOptions::default()).unwrap()))
    });
    let data = std::fs::read(&path).unwrap();
    group.bench_function("from_bytes_10k_views", |b| {
        b.iter(|| black_box(Map::from_bytes(&data, &LoadOptions::default()).unwrap()))
    });
    group.finish();
}

criterion_group!(benches, per_frame, per_frame_grnn, map_load);
criterion_main!(benches);
