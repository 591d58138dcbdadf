//! World generation and rendering: connectivity, splits, determinism, bad input, and images
//! with enough texture for local features (ORB) under every condition.

use nalgebra::Point3;
use opencv::core::{KeyPoint, Mat, Vector};
use opencv::features2d::{ORB_ScoreType, ORB};
use opencv::prelude::*;
use topoloc_sim::camera::{pose, Intrinsics, Pose};
use topoloc_sim::render::{Condition, ConditionKind, Image, RenderError, Renderer};
use topoloc_sim::style::{Split, Style};
use topoloc_sim::texture::TextureFamily;
use topoloc_sim::world::{RegionKind, World, WorldError, WorldParams};

/// World `k` of `split` on 0.15 m voxels: quicker to generate than the default.
fn coarse(split: Split, k: u32) -> WorldParams {
    WorldParams {
        voxel_size: 0.15,
        ..split.world_params(k)
    }
}

/// ORB keypoints (OpenCV defaults but 1000 features, as the library's VLAD extractor).
fn orb_count(image: &Image) -> usize {
    let bgr = image.to_bgr_mat().unwrap();
    let mut grey = Mat::default();
    opencv::imgproc::cvt_color_def(&bgr, &mut grey, opencv::imgproc::COLOR_BGR2GRAY).unwrap();
    let mut orb = ORB::create(1000, 1.2, 8, 31, 0, 2, ORB_ScoreType::HARRIS_SCORE, 31, 20).unwrap();
    let mut keypoints = Vector::<KeyPoint>::new();
    orb.detect(&grey, &mut keypoints, &Mat::default()).unwrap();
    keypoints.len()
}

fn mean_and_std(image: &Image) -> (f64, f64) {
    let grey = image.to_gray();
    let n = grey.len() as f64;
    let mean = grey.iter().map(|&g| g as f64).sum::<f64>() / n;
    let var = grey.iter().map(|&g| (g as f64 - mean).powi(2)).sum::<f64>() / n;
    (mean, var.sqrt())
}

fn median(mut v: Vec<usize>) -> usize {
    v.sort_unstable();
    v[v.len() / 2]
}

/// Typical frames: the centre of rooms and corridors, mid flight band, looking along x and y.
fn typical_poses(world: &World, count: usize) -> Vec<Pose> {
    let mut poses = Vec::new();
    for r in world
        .regions()
        .iter()
        .filter(|r| r.kind != RegionKind::Shaft)
        .take(count)
    {
        let band = world.flight_band(r.floor);
        let centre = Point3::new(
            0.5 * (r.min[0] + r.max[0]),
            0.5 * (r.min[1] + r.max[1]),
            0.5 * (band[0] + band[1]),
        );
        for yaw in [0.0, std::f64::consts::FRAC_PI_2] {
            poses.push(pose(centre, yaw, 0.0));
        }
    }
    poses
}

/// Frames 1.5 m from a room wall, facing it (what a head light reaches).
fn near_wall_poses(world: &World, count: usize) -> Vec<Pose> {
    let mut poses = Vec::new();
    for r in world
        .regions()
        .iter()
        .filter(|r| r.kind == RegionKind::Room)
        .take(count)
    {
        let band = world.flight_band(r.floor);
        let z = 0.5 * (band[0] + band[1]);
        let x = 0.5 * (r.min[0] + r.max[0]);
        poses.push(pose(
            Point3::new(x, r.min[1] + 1.5, z),
            -std::f64::consts::FRAC_PI_2,
            0.0,
        ));
        poses.push(pose(
            Point3::new(x, r.max[1] - 1.5, z),
            std::f64::consts::FRAC_PI_2,
            0.0,
        ));
    }
    poses
}

#[test]
fn generated_worlds_are_connected_and_well_formed() {
    for split in [Split::Train, Split::TrA, Split::Test] {
        for k in 0..2 {
            let params = split.world_params(k);
            let world = World::generate(&params).unwrap();
            let name = format!("{split} world {k}");
            assert_eq!(
                world.free_components(),
                1,
                "{name}: free space is connected"
            );
            let floors = params.floors as usize;
            assert_eq!(world.floor_count(), floors);
            let count = |kind| world.regions().iter().filter(|r| r.kind == kind).count();
            assert_eq!(
                count(RegionKind::Room),
                floors * params.rooms_per_floor as usize,
                "{name}"
            );
            assert_eq!(
                count(RegionKind::Shaft),
                floors - 1,
                "{name}: one shaft per slab"
            );
            for (i, r) in world.regions().iter().enumerate() {
                if r.kind == RegionKind::Room {
                    assert!(
                        world.doors().iter().any(|d| d.regions.contains(&i)),
                        "{name}: room {i} has a door"
                    );
                    assert!(
                        world.lamps().iter().any(|l| l.region == i),
                        "{name}: room {i} is lit"
                    );
                    let band = world.flight_band(r.floor);
                    let c = Point3::new(
                        0.5 * (r.min[0] + r.max[0]),
                        0.5 * (r.min[1] + r.max[1]),
                        band[0],
                    );
                    assert_eq!(
                        world.region_at(&c),
                        Some(i),
                        "{name}: room {i} maps to itself"
                    );
                }
            }
            for f in 0..floors {
                let [z0, z1] = world.floor_range(f);
                let [lo, hi] = world.flight_band(f);
                assert!(
                    z0 < lo && lo < hi && hi < z1,
                    "{name}: flight band inside storey {f}"
                );
            }
            let table = world.material_table().len();
            assert!(world.materials().iter().all(|&m| (m as usize) < table));
            let grid = world.grid();
            assert!(grid
                .cells()
                .iter()
                .zip(world.materials())
                .all(|(&o, &m)| o == (m != 0)));
            // The outside is closed: every border voxel is occupied.
            let [nx, ny, nz] = grid.dims();
            for z in 0..nz {
                for y in 0..ny {
                    assert!(grid.is_occupied([0, y, z]) && grid.is_occupied([nx - 1, y, z]));
                }
            }
        }
    }
}

#[test]
fn shafts_join_the_storeys() {
    let params = WorldParams {
        floors: 3,
        voxel_size: 0.2,
        ..Split::Train.world_params(1)
    };
    let world = World::generate(&params).unwrap();
    assert_eq!(world.free_components(), 1);
    for shaft in world
        .regions()
        .iter()
        .filter(|r| r.kind == RegionKind::Shaft)
    {
        let x = 0.5 * (shaft.min[0] + shaft.max[0]);
        let y = 0.5 * (shaft.min[1] + shaft.max[1]);
        let below = world.flight_band(shaft.floor)[1];
        let above = world.flight_band(shaft.floor + 1)[0];
        let a = Point3::new(x, y, below);
        let b = Point3::new(x, y, above);
        assert!(
            world.grid().segment_is_free(&a, &b),
            "a vertical flight through the shaft"
        );
    }
}

#[test]
fn splits_give_the_documented_styles() {
    let train = World::generate(&Split::Train.world_params(0)).unwrap();
    let trt = World::generate(&Split::TrT.world_params(0)).unwrap();
    assert_eq!(
        train.materials(),
        trt.materials(),
        "Tr-T flies the training worlds"
    );
    assert_eq!(train.regions(), trt.regions());
    let tra = World::generate(&Split::TrA.world_params(0)).unwrap();
    assert_ne!(train.params().seed, tra.params().seed, "Tr-A: new worlds");
    let test = World::generate(&Split::Test.world_params(0)).unwrap();
    for (world, style) in [
        (&train, Style::office()),
        (&tra, Style::office()),
        (&test, Style::lab()),
    ] {
        assert_eq!(world.params().style, style);
        let family = |m: u16| world.material_table()[m as usize].family;
        for r in world
            .regions()
            .iter()
            .filter(|r| r.kind != RegionKind::Shaft)
        {
            assert!(style.wall_families.contains(&family(r.wall_material)));
            assert!(style.floor_families.contains(&family(r.floor_material)));
            assert!(style.ceiling_families.contains(&family(r.ceiling_material)));
        }
        for f in world.furniture() {
            assert!(style.furniture.contains(&f.kind));
        }
    }
    // The test style shows no surface family or colour of the training style.
    let office = Style::office();
    let seen: Vec<TextureFamily> = office
        .wall_families
        .iter()
        .chain(&office.floor_families)
        .chain(&office.ceiling_families)
        .copied()
        .collect();
    for r in test
        .regions()
        .iter()
        .filter(|r| r.kind != RegionKind::Shaft)
    {
        for m in [r.wall_material, r.floor_material, r.ceiling_material] {
            let material = &test.material_table()[m as usize];
            assert!(!seen.contains(&material.family));
            assert!(!office.palette.contains(&material.colour));
        }
    }
    // Perceptual aliasing: rooms share a handful of wall materials.
    let mut walls: Vec<u16> = train.regions().iter().map(|r| r.wall_material).collect();
    walls.sort_unstable();
    walls.dedup();
    assert!(walls.len() <= office.wall_materials as usize);
}

#[test]
fn worlds_and_renders_are_deterministic() {
    let params = coarse(Split::TrA, 3);
    let a = World::generate(&params).unwrap();
    let b = World::generate(&params).unwrap();
    assert_eq!(a.materials(), b.materials());
    assert_eq!(a.regions(), b.regions());
    assert_eq!(a.landmarks(), b.landmarks());
    assert_eq!(a.furniture(), b.furniture());
    let other = World::generate(&WorldParams {
        seed: params.seed + 1,
        ..params.clone()
    })
    .unwrap();
    assert_ne!(a.materials(), other.materials());

    let k = Intrinsics::from_hfov(96, 72, 90.0);
    let p = typical_poses(&a, 1)[0];
    let (ra, rb) = (Renderer::new(&a), Renderer::new(&b));
    for kind in ConditionKind::ALL {
        let c = Condition::preset(kind);
        assert_eq!(
            ra.render(&p, &k, &c, 5),
            rb.render(&p, &k, &c, 5),
            "{}",
            kind.name()
        );
    }
    let noisy = Condition::preset(ConditionKind::Noise);
    assert_ne!(
        ra.render(&p, &k, &noisy, 5),
        ra.render(&p, &k, &noisy, 6),
        "noise follows the seed"
    );
}

/// The depth image is the forward distance to the surface point each pixel centre sees, the
/// geometry a depth camera would report.
#[test]
fn depth_images_agree_with_surface_points() {
    let world = World::generate(&coarse(Split::Train, 1)).unwrap();
    let renderer = Renderer::new(&world);
    let k = Intrinsics::from_hfov(64, 48, 90.0);
    for p in typical_poses(&world, 3) {
        let depth = renderer.try_render_depth(&p, &k).unwrap();
        assert_eq!(depth.len(), 64 * 48);
        let forward = p.rotation * nalgebra::Vector3::x();
        let mut checked = 0;
        for (row, col) in [(0u32, 0u32), (24, 32), (47, 63), (10, 50), (40, 5)] {
            let d = depth[(row * 64 + col) as usize];
            let expected = renderer
                .surface_point(&p, &k, f64::from(col) + 0.5, f64::from(row) + 0.5)
                .map(|q| (q - p.translation.vector).coords.dot(&forward));
            match expected {
                Some(e) => {
                    assert!(
                        (f64::from(d) - e).abs() < 1e-3,
                        "({row}, {col}): {d} vs {e}"
                    );
                    assert!(d > 0.0);
                    checked += 1;
                }
                None => assert!(d.is_nan(), "({row}, {col}) leaves the grid: {d}"),
            }
        }
        assert!(checked >= 4, "a room view sees its walls");
    }
    let bad = Intrinsics { fx: -1.0, ..k };
    assert!(renderer
        .try_render_depth(&typical_poses(&world, 1)[0], &bad)
        .is_err());
}

#[test]
fn bad_input_names_the_field() {
    let ok = Split::Train.world_params(0);
    let message = |p: WorldParams| World::generate(&p).unwrap_err().to_string();
    assert!(message(WorldParams {
        floors: 0,
        ..ok.clone()
    })
    .contains("`floors`"));
    assert!(message(WorldParams {
        room_size: [8.0, 3.0],
        ..ok.clone()
    })
    .contains("`room_size`"));
    assert!(message(WorldParams {
        voxel_size: 0.5,
        ..ok.clone()
    })
    .contains("`voxel_size`"));
    let huge = WorldParams {
        voxel_size: 0.05,
        rooms_per_floor: 32,
        room_size: [19.0, 20.0],
        floors: 3,
        ceiling_height: 6.0,
        ..ok.clone()
    };
    match World::generate(&huge) {
        Err(WorldError::InvalidParam { field, .. }) => assert_eq!(field, "voxel_size"),
        other => panic!(
            "a grid too large must be refused, got {:?}",
            other.map(|_| ())
        ),
    }

    let world = World::generate(&WorldParams {
        voxel_size: 0.2,
        ..ok
    })
    .unwrap();
    let renderer = Renderer::new(&world);
    let p = typical_poses(&world, 1)[0];
    let k = Intrinsics::from_hfov(32, 24, 90.0);
    let bad = Condition {
        gain: -1.0,
        ..Condition::default()
    };
    match renderer.try_render(&p, &k, &bad, 0) {
        Err(RenderError::InvalidCondition { field, .. }) => assert_eq!(field, "gain"),
        other => panic!("expected a bad condition, got {:?}", other.map(|_| ())),
    }
    let bad_k = Intrinsics { fy: f64::NAN, ..k };
    let e = renderer
        .try_render(&p, &bad_k, &Condition::default(), 0)
        .unwrap_err();
    assert!(e.to_string().contains("fy"), "{e}");
    // A camera outside the building sees black, not a panic.
    let outside = pose(Point3::new(-50.0, -50.0, 1.0), 0.0, 0.0);
    let dark = Condition {
        noise_sigma: 0.0,
        ..Condition::default()
    };
    assert!(renderer
        .render(&outside, &k, &dark, 0)
        .rgb
        .iter()
        .all(|&b| b == 0));
}

/// Every condition keeps enough texture for local features on typical frames; night only near
/// walls (the head light fades with distance).
#[test]
fn frames_carry_texture_for_orb() {
    let k = Intrinsics::default_camera();
    for split in [Split::Train, Split::Test] {
        let world = World::generate(&split.world_params(0)).unwrap();
        let renderer = Renderer::new(&world);
        let typical = typical_poses(&world, 5);
        let near = near_wall_poses(&world, 3);
        for kind in ConditionKind::ALL {
            let condition = Condition::preset(kind);
            let poses = if kind == ConditionKind::Night {
                &near
            } else {
                &typical
            };
            let mut counts = Vec::new();
            for (i, p) in poses.iter().enumerate() {
                let image = renderer.render(p, &k, &condition, i as u64);
                let (mean, std) = mean_and_std(&image);
                assert!(
                    std > 8.0 && mean > 10.0,
                    "{split} {}: blank frame {i}",
                    kind.name()
                );
                counts.push(orb_count(&image));
            }
            let m = median(counts.clone());
            eprintln!(
                "{split} {}: ORB keypoints {counts:?}, median {m}",
                kind.name()
            );
            assert!(
                m >= 200,
                "{split} {}: median {m} ORB keypoints",
                kind.name()
            );
        }
    }
}

/// Writes contact sheets (six conditions per view) and plans to $SIM_PREVIEW_DIR:
/// `SIM_PREVIEW_DIR=/tmp/sim cargo test --release -p topoloc-sim --test world_render preview
/// -- --ignored`.
#[test]
#[ignore]
fn preview() {
    let dir = std::env::var("SIM_PREVIEW_DIR").unwrap_or_else(|_| "/tmp/simprev".into());
    let k = Intrinsics::default_camera();
    for split in [Split::Train, Split::Test] {
        let world = World::generate(&split.world_params(0)).unwrap();
        let renderer = Renderer::new(&world);
        for f in 0..world.floor_count() {
            let path = format!("{dir}/{split}_top{f}.png");
            world.top_view(f).write_png(path.as_ref()).unwrap();
        }
        for (i, p) in typical_poses(&world, 6).iter().enumerate() {
            let mut sheet = Image::new(3 * k.width, 2 * k.height);
            for (j, kind) in ConditionKind::ALL.into_iter().enumerate() {
                let image = renderer.render(p, &k, &Condition::preset(kind), 1);
                let (ox, oy) = ((j as u32 % 3) * k.width, (j as u32 / 3) * k.height);
                for y in 0..k.height {
                    for x in 0..k.width {
                        sheet.set_pixel(ox + x, oy + y, image.pixel(x, y));
                    }
                }
            }
            sheet
                .write_png(format!("{dir}/{split}_view{i}.png").as_ref())
                .unwrap();
        }
    }
}
