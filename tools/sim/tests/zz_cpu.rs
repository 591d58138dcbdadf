use nalgebra::Point3;
use topoloc_sim::camera::{pose, Intrinsics};
use topoloc_sim::render::{Condition, ConditionKind, Renderer};
use topoloc_sim::style::Split;
use topoloc_sim::world::{RegionKind, World};
fn cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .unwrap()
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap()
}
#[test]
fn cpu() {
    let k = Intrinsics::default_camera();
    for split in [Split::Train, Split::Test] {
        let world = World::generate(&split.world_params(0)).unwrap();
        let r = Renderer::new(&world);
        let mut poses = vec![];
        for reg in world
            .regions()
            .iter()
            .filter(|r| r.kind != RegionKind::Shaft)
        {
            let band = world.flight_band(reg.floor);
            let c = Point3::new(
                0.5 * (reg.min[0] + reg.max[0]),
                0.5 * (reg.min[1] + reg.max[1]),
                0.5 * (band[0] + band[1]),
            );
            for q in 0..4 {
                poses.push(pose(c, q as f64 * std::f64::consts::FRAC_PI_2, 0.0));
            }
        }
        for kind in [
            ConditionKind::Bright,
            ConditionKind::Night,
            ConditionKind::MotionBlur,
        ] {
            let c = Condition::preset(kind);
            let mut cpu = vec![];
            for i in 0..120 {
                let c0 = cpu_ns();
                std::hint::black_box(r.render(&poses[i % poses.len()], &k, &c, i as u64));
                cpu.push(cpu_ns() - c0);
            }
            cpu.sort();
            eprintln!(
                "{split} {}: cpu mean {:.2} ms",
                kind.name(),
                cpu.iter().sum::<u64>() as f64 / 120e6
            );
        }
    }
}
