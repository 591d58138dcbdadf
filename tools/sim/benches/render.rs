//! Rendering speed at 320x240 on one thread, and world set-up costs.
//!
//! Run: `cargo bench -p topoloc-sim --bench render` (add `-- --quick` for a shorter run).
//! Target: >= 50 frames/s (<= 20 ms per frame) for typical frames: the camera at the centre of
//! the rooms and corridors of a training world, in the middle of the flight band, looking along
//! each of the four axes, cycled frame after frame.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use nalgebra::Point3;
use std::hint::black_box;
use std::time::Duration;
use topoloc_sim::camera::{pose, Intrinsics, Pose};
use topoloc_sim::render::{Condition, ConditionKind, Renderer};
use topoloc_sim::style::Split;
use topoloc_sim::world::{RegionKind, World};

/// Camera poses at the centre of each room and corridor, four headings each.
fn typical_poses(world: &World) -> Vec<Pose> {
    let mut poses = Vec::new();
    for r in world
        .regions()
        .iter()
        .filter(|r| r.kind != RegionKind::Shaft)
    {
        let band = world.flight_band(r.floor);
        let centre = Point3::new(
            0.5 * (r.min[0] + r.max[0]),
            0.5 * (r.min[1] + r.max[1]),
            0.5 * (band[0] + band[1]),
        );
        for quarter in 0..4 {
            poses.push(pose(
                centre,
                quarter as f64 * std::f64::consts::FRAC_PI_2,
                0.0,
            ));
        }
    }
    poses
}

fn render(c: &mut Criterion) {
    let k = Intrinsics::default_camera();
    let mut group = c.benchmark_group("render_320x240");
    group.throughput(Throughput::Elements(1));
    group.measurement_time(Duration::from_secs(8));
    for split in [Split::Train, Split::Test] {
        let world = World::generate(&split.world_params(0)).expect("world");
        let renderer = Renderer::new(&world);
        let poses = typical_poses(&world);
        for kind in [
            ConditionKind::Bright,
            ConditionKind::Night,
            ConditionKind::MotionBlur,
        ] {
            let condition = Condition::preset(kind);
            let mut i = 0usize;
            let id = BenchmarkId::new(split.name(), kind.name());
            group.bench_function(id, |b| {
                b.iter(|| {
                    i += 1;
                    black_box(renderer.render(&poses[i % poses.len()], &k, &condition, i as u64))
                })
            });
        }
    }
    group.finish();
}

fn setup(c: &mut Criterion) {
    let mut group = c.benchmark_group("world_setup");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(8));
    let params = Split::Train.world_params(0);
    group.bench_function("generate", |b| {
        b.iter(|| black_box(World::generate(&params).unwrap()))
    });
    let world = World::generate(&params).unwrap();
    group.bench_function("renderer_new", |b| {
        b.iter(|| black_box(Renderer::new(&world)))
    });
    group.finish();
}

criterion_group!(benches, render, setup);
criterion_main!(benches);
