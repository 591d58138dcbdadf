//! Skeleton map building on a 40 m x 30 m x 3 m office floor (rooms, doors, corridors, pillars,
//! furniture), single thread: thinning alone and the whole graph, at 0.2 m and 0.1 m voxels.
//!
//! Run: `cargo bench --bench skeleton` (add `-- --quick` for a shorter run). Target (issue 4):
//! a few seconds at most at 0.1 m.

#[path = "../tests/common/skeleton_worlds.rs"]
mod worlds;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use std::hint::black_box;
use std::time::Duration;
use topoloc::skeleton::{skeleton_graph, skeletonize, SkeletonOptions};

fn office(c: &mut Criterion) {
    let options = SkeletonOptions::default();
    let mut group = c.benchmark_group("skeleton_office_40x30x3m");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(20));
    for voxel in [0.2, 0.1] {
        let grid = worlds::office(voxel);
        let graph = skeleton_graph(&grid, &options).unwrap();
        eprintln!(
            "office at {voxel} m: {} voxels ({} free), skeleton {} voxels, {} places, {} edges",
            grid.len(),
            grid.free_count(),
            graph.skeleton.len(),
            graph.places.len(),
            graph.edges.len()
        );
        group.throughput(Throughput::Elements(grid.len() as u64));
        group.bench_with_input(BenchmarkId::new("thinning", voxel), &grid, |b, g| {
            b.iter(|| black_box(skeletonize(g, &options).unwrap()))
        });
        group.bench_with_input(BenchmarkId::new("graph", voxel), &grid, |b, g| {
            b.iter(|| black_box(skeleton_graph(g, &options).unwrap()))
        });
    }
    group.finish();
}

criterion_group!(benches, office);
criterion_main!(benches);
