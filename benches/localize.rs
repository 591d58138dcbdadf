//! Per-frame localization and map loading, single thread, D = 512.
//!
//! Run: `cargo bench --bench localize` (add `-- --quick` for a shorter run). Figures are
//! recorded in BENCHMARKS.md. Targets (2-core machine): <= 0.3 ms per frame at 1k views,
//! <= 30 ms at 100k views, map load <= 20 ms at 10k views.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
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
            let mut out = Localization::default();
            let mut i = 0usize;
            group.bench_with_input(BenchmarkId::new(name, views), &views, |b, _| {
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

criterion_group!(benches, per_frame, map_load);
criterion_main!(benches);
