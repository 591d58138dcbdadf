//! The dataset folder end to end: a planned looping trajectory in a hand-made world, its ground
//! truth and odometry, written and read back; then damaged folders, each refused with an error
//! that names the file.

use nalgebra::Point3;
use std::path::Path;
use topoloc::build::TimedPose;
use topoloc::skeleton::OccupancyGrid;
use topoloc_sim::camera::Intrinsics;
use topoloc_sim::dataset::{image_name, Dataset, DatasetError, DatasetInfo, DatasetWriter};
use topoloc_sim::ground_truth::{ground_truth, visits, FrameTruth, PlaceGraph};
use topoloc_sim::odometry::{odometry, OdometryNoise};
use topoloc_sim::trajectory::{Planner, PlannerOptions, TrajectorySpec};

/// A 12 x 9 m hall, 3 m high, around a 6 x 3 m block: a corridor loop 3 m wide.
fn ring_world() -> OccupancyGrid {
    let size = 0.1;
    let mut grid = OccupancyGrid::empty([120, 90, 30], size, Point3::origin()).unwrap();
    let [nx, ny, nz] = grid.dims();
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let shell = x == 0 || y == 0 || z == 0 || x == nx - 1 || y == ny - 1 || z == nz - 1;
                let block = (30..90).contains(&x) && (30..60).contains(&y);
                grid.set([x, y, z], shell || block);
            }
        }
    }
    grid
}

/// Places at the four corners of the loop and the middle of its long sides.
fn ring_graph() -> PlaceGraph {
    let positions: Vec<Point3<f64>> = [
        (1.5, 1.5),
        (6.0, 1.5),
        (10.5, 1.5),
        (10.5, 7.5),
        (6.0, 7.5),
        (1.5, 7.5),
    ]
    .iter()
    .map(|&(x, y)| Point3::new(x, y, 1.5))
    .collect();
    let mut graph = PlaceGraph::with_four_views(
        &positions,
        &[(0, 1), (1, 2), (2, 3), (3, 4), (4, 5), (5, 0)],
    );
    for (i, place) in graph.places.iter_mut().enumerate() {
        place.kind = if i % 3 == 0 || i % 3 == 2 {
            "corner"
        } else {
            "corridor"
        }
        .into();
    }
    graph
}

fn info(rate_hz: f64) -> DatasetInfo {
    DatasetInfo {
        world_seed: 42,
        trajectory_seed: 7,
        split: "test".into(),
        style: "plain".into(),
        condition: "day".into(),
        rate_hz,
        odometry_seed: 9,
        odometry_noise: OdometryNoise::typical_vio(),
    }
}

/// A small image whose pixels encode the frame, so that a mixed-up order shows.
fn image(k: &Intrinsics, frame: usize) -> Vec<u8> {
    let (w, h) = (k.width as usize, k.height as usize);
    let mut rgb = vec![0u8; w * h * 3];
    for (i, px) in rgb.chunks_mut(3).enumerate() {
        px.copy_from_slice(&[(frame % 256) as u8, (i % w * 8) as u8, (i / w * 8) as u8]);
    }
    rgb
}

/// Everything a dataset holds, as written.
struct Written {
    graph: PlaceGraph,
    ground_truth: Vec<TimedPose>,
    odometry: Vec<TimedPose>,
    nodes: Vec<FrameTruth>,
}

/// Writes a dataset of the ring world along `frames` poses.
fn write(root: &Path, frames: Vec<TimedPose>, rate_hz: f64) -> Written {
    let grid = ring_world();
    let graph = ring_graph();
    let k = Intrinsics::from_hfov(32, 24, 90.0);
    let nodes = ground_truth(&grid, &graph, &frames).unwrap();
    let odom = odometry(&frames, &OdometryNoise::typical_vio(), 9).unwrap();
    let writer = DatasetWriter::create(root, k).unwrap();
    for f in 0..frames.len() {
        writer.write_image(f, &image(&k, f)).unwrap();
    }
    writer
        .finish(&info(rate_hz), &graph, &frames, &odom, &nodes)
        .unwrap();
    Written {
        graph,
        ground_truth: frames,
        odometry: odom,
        nodes,
    }
}

/// Twelve frames along the south corridor at 10 Hz.
fn straight_frames() -> Vec<TimedPose> {
    (0..12)
        .map(|i| TimedPose {
            timestamp: i as f64 * 0.1,
            world_t_camera: topoloc_sim::camera::pose(
                Point3::new(1.0 + i as f64 * 0.8, 1.5, 1.5),
                0.1 * i as f64,
                0.0,
            ),
        })
        .collect()
}

#[test]
fn a_looping_trajectory_round_trips_through_the_folder() {
    let grid = ring_world();
    let planner = Planner::new(
        &grid,
        PlannerOptions {
            clearance_m: 0.4,
            band: (1.0, 2.0),
        },
    )
    .unwrap();
    let spec = TrajectorySpec {
        seed: 5,
        goals: 4,
        revisits: 1,
        min_goal_distance_m: 5.0,
        ..TrajectorySpec::default()
    };
    let trajectory = planner.random_trajectory(&spec).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    let written = write(&root, trajectory.frames.clone(), spec.motion.rate_hz);

    let ds = Dataset::open(&root).unwrap();
    let n = trajectory.frames.len();
    assert_eq!(ds.frame_count(), n);
    assert_eq!(ds.manifest.format, "topoloc-sim-dataset");
    assert_eq!(ds.manifest.format_version, "1.1");
    assert_eq!(ds.manifest.info, info(spec.motion.rate_hz));
    assert_eq!(ds.manifest.files.len(), 5 + n);
    assert_eq!(ds.intrinsics, Intrinsics::from_hfov(32, 24, 90.0));
    assert_eq!(ds.graph, written.graph);
    assert_eq!(ds.nodes, written.nodes);
    for (read, wrote) in [
        (&ds.ground_truth, &written.ground_truth),
        (&ds.odometry, &written.odometry),
    ] {
        assert_eq!(read.len(), n);
        for (a, b) in read.iter().zip(wrote) {
            assert_eq!(a.timestamp, b.timestamp);
            assert_eq!(a.world_t_camera.translation, b.world_t_camera.translation);
            assert!(
                a.world_t_camera
                    .rotation
                    .angle_to(&b.world_t_camera.rotation)
                    < 1e-6
            );
        }
    }
    for f in [0, n / 2, n - 1] {
        assert_eq!(
            ds.read_image(f).unwrap(),
            image(&ds.intrinsics, f),
            "frame {f}"
        );
    }
    // The loop brings the camera back to places it saw before.
    let runs = visits(&ds.nodes);
    let revisited = runs
        .iter()
        .enumerate()
        .any(|(i, v)| runs[..i].iter().any(|u| u.place == v.place));
    assert!(revisited, "{runs:?}");

    // Perfect answers score 1; always answering a neighbour scores 0 MNA but full OHA.
    let perfect: Vec<Vec<u32>> = ds.nodes.iter().map(|t| vec![t.place]).collect();
    let m = ds.evaluate(&perfect).unwrap();
    assert_eq!((m.mna, m.oha, m.queries), (1.0, 1.0, n));
    assert_eq!(m.recall_at_n.len(), 10);
    let neighbour: Vec<Vec<u32>> = ds
        .nodes
        .iter()
        .map(|t| vec![(t.place + 1) % 6, t.place])
        .collect();
    let m = ds.evaluate(&neighbour).unwrap();
    assert_eq!((m.mna, m.oha, m.recall_at_n[1].recall), (0.0, 1.0, 1.0));
    let err = ds.evaluate(&perfect[1..]).unwrap_err().to_string();
    assert!(err.contains(&format!("for {n} frames")), "{err}");
}

/// Writes the small dataset into a fresh folder, damages it, and returns the error of opening.
fn open_damaged(damage: impl FnOnce(&Path)) -> String {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("ds");
    write(&root, straight_frames(), 10.0);
    Dataset::open(&root).expect("the undamaged dataset opens");
    damage(&root);
    Dataset::open(&root).unwrap_err().to_string()
}

fn edit(path: &Path, change: impl FnOnce(String) -> String) {
    let text = std::fs::read_to_string(path).unwrap();
    std::fs::write(path, change(text)).unwrap();
}

/// Damage: replace the first `from` by `to` in `file`.
fn replace(file: &'static str, from: &'static str, to: &'static str) -> Damage {
    Box::new(move |root| edit(&root.join(file), |t| t.replacen(from, to, 1)))
}

type Damage = Box<dyn FnOnce(&Path)>;

#[test]
fn damaged_folders_are_refused_naming_the_file() {
    let cases: Vec<(&str, Damage, Vec<&str>)> = vec![
        (
            "no folder",
            Box::new(|r| std::fs::remove_dir_all(r).unwrap()),
            vec!["ds", "dataset folder is missing"],
        ),
        (
            "no manifest",
            Box::new(|r| std::fs::remove_file(r.join("manifest.json")).unwrap()),
            vec!["manifest.json", "missing"],
        ),
        (
            "bad JSON",
            replace("graph.json", "[", "{"),
            vec!["graph.json", "line"],
        ),
        (
            "missing key",
            replace("manifest.json", "\"split\"", "\"splat\""),
            vec!["manifest.json", "split"],
        ),
        (
            "newer version",
            replace("manifest.json", "\"1.1\"", "\"2.1\""),
            vec!["manifest.json", "2.1", "newer"],
        ),
        (
            "another format",
            replace("manifest.json", "topoloc-sim-dataset", "tum"),
            vec!["manifest.json", "format"],
        ),
        (
            "bad intrinsics",
            Box::new(|r| {
                edit(&r.join("intrinsics.json"), |t| {
                    let mut k: serde_json::Value = serde_json::from_str(&t).unwrap();
                    k["fx"] = (-1.0).into();
                    k.to_string()
                })
            }),
            vec!["intrinsics.json", "fx"],
        ),
        (
            "missing image",
            Box::new(|r| std::fs::remove_file(r.join(image_name(3))).unwrap()),
            vec!["000003.png", "missing"],
        ),
        (
            "extra image",
            Box::new(|r| {
                std::fs::copy(r.join(image_name(0)), r.join("images/extra.png"))
                    .map(drop)
                    .unwrap()
            }),
            vec!["images", "13 PNG images for 12 frames"],
        ),
        (
            "bad TUM line",
            replace("groundtruth.txt", " 1.5 ", " x "),
            vec!["groundtruth.txt", "line 2", "'x'"],
        ),
        (
            "short odometry",
            Box::new(|r| {
                edit(&r.join("odometry.txt"), |t| {
                    t.lines().take(5).collect::<Vec<_>>().join("\n")
                })
            }),
            vec!["odometry.txt", "4 poses for 12 frames"],
        ),
        (
            "bad node row",
            replace("nodes.csv", "\n3,", "\n3,x"),
            vec!["nodes.csv line 5", "place"],
        ),
        (
            "unknown place",
            replace("nodes.csv", "\n2,0,", "\n2,9,"),
            vec!["nodes.csv line 4", "place 9"],
        ),
        (
            "bad header",
            replace("nodes.csv", "frame,", "query,"),
            vec!["nodes.csv line 1", "header"],
        ),
    ];
    for (name, damage, expected) in cases {
        let err = open_damaged(damage);
        for word in expected {
            assert!(err.contains(word), "{name}: '{word}' not in: {err}");
        }
    }
}

#[test]
fn the_writer_refuses_bad_input_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let k = Intrinsics::from_hfov(32, 24, 90.0);
    std::fs::write(dir.path().join("stale.txt"), "x").unwrap();
    let err = DatasetWriter::create(dir.path(), k).unwrap_err();
    assert!(matches!(err, DatasetError::NotEmpty { .. }), "{err}");
    let bad_k = Intrinsics { width: 0, ..k };
    assert!(DatasetWriter::create(&dir.path().join("a"), bad_k)
        .unwrap_err()
        .to_string()
        .contains("intrinsics.width"));

    let frames = straight_frames();
    let graph = ring_graph();
    let nodes = ground_truth(&ring_world(), &graph, &frames).unwrap();
    let writer = DatasetWriter::create(&dir.path().join("b"), k).unwrap();
    let err = writer.write_image(0, &[0; 10]).unwrap_err().to_string();
    assert!(
        err.contains("000000.png") && err.contains("needs 2304"),
        "{err}"
    );
    for f in 0..frames.len() - 1 {
        writer.write_image(f, &image(&k, f)).unwrap();
    }
    let err = writer
        .finish(&info(10.0), &graph, &frames, &frames, &nodes)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("images") && err.contains("11 PNG images for 12 frames"),
        "{err}"
    );
    assert!(
        !dir.path().join("b/manifest.json").exists(),
        "no manifest for an incomplete dataset"
    );

    let writer = DatasetWriter::create(&dir.path().join("c"), k).unwrap();
    let err = writer
        .finish(&info(10.0), &graph, &frames, &frames[1..], &nodes)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("odometry.txt") && err.contains("11 poses for 12 frames"),
        "{err}"
    );
}

/// Depth images (format 1.1) are written as 16-bit millimetres, listed in the manifest, read
/// back by path, and required for every frame once one frame has one.
#[test]
fn depth_images_round_trip_and_are_complete() {
    let dir = tempfile::tempdir().unwrap();
    let k = Intrinsics::from_hfov(32, 24, 90.0);
    let frames = straight_frames();
    let graph = ring_graph();
    let nodes = ground_truth(&ring_world(), &graph, &frames).unwrap();
    let depth_of = |f: usize| -> Vec<f32> {
        (0..32 * 24)
            .map(|i| match i % 7 {
                0 => f32::NAN,
                _ => 0.5 + f as f32 * 0.25 + (i % 32) as f32 * 0.01,
            })
            .collect()
    };

    let root = dir.path().join("with-depth");
    let writer = DatasetWriter::create(&root, k).unwrap();
    for f in 0..frames.len() {
        writer.write_image(f, &image(&k, f)).unwrap();
        writer.write_depth(f, &depth_of(f)).unwrap();
    }
    let err = writer.write_depth(0, &[1.0; 5]).unwrap_err().to_string();
    assert!(
        err.contains("depth/000000.png") && err.contains("needs 768"),
        "{err}"
    );
    writer
        .finish(&info(10.0), &graph, &frames, &frames, &nodes)
        .unwrap();
    let dataset = Dataset::open(&root).unwrap();
    assert_eq!(dataset.manifest.depth_scale, Some(1000.0));
    assert!(dataset
        .manifest
        .files
        .iter()
        .any(|f| f == "depth/000011.png"));
    let path = dataset.depth_path(3).unwrap();
    let mm = opencv::imgcodecs::imread(path.to_str().unwrap(), opencv::imgcodecs::IMREAD_ANYDEPTH)
        .unwrap();
    use opencv::prelude::*;
    assert_eq!(mm.typ(), opencv::core::CV_16UC1);
    let expected = depth_of(3);
    for (i, &e) in expected.iter().enumerate() {
        let got = *mm.at_2d::<u16>(i as i32 / 32, i as i32 % 32).unwrap();
        let want = if e.is_nan() {
            0
        } else {
            (e * 1000.0).round() as u16
        };
        assert_eq!(got, want, "pixel {i}");
    }

    // Without depth the manifest says so, and a missing depth frame is refused.
    let plain = dir.path().join("plain");
    write(&plain, straight_frames(), 10.0);
    let dataset = Dataset::open(&plain).unwrap();
    assert_eq!(dataset.manifest.depth_scale, None);
    assert!(dataset.depth_path(0).is_none());
    let writer = DatasetWriter::create(&dir.path().join("partial"), k).unwrap();
    for f in 0..frames.len() {
        writer.write_image(f, &image(&k, f)).unwrap();
    }
    writer.write_depth(0, &depth_of(0)).unwrap();
    let err = writer
        .finish(&info(10.0), &graph, &frames, &frames, &nodes)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("depth") && err.contains("1 PNG images for 12 frames"),
        "{err}"
    );
    let manifest = root.join("manifest.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(
        &manifest,
        text.replace("\"depth_scale\": 1000.0", "\"depth_scale\": -1.0"),
    )
    .unwrap();
    let err = Dataset::open(&root).unwrap_err().to_string();
    assert!(err.contains("depth_scale is -1"), "{err}");
    std::fs::write(&manifest, text).unwrap();
    std::fs::remove_file(root.join("depth/000004.png")).unwrap();
    let err = Dataset::open(&root).unwrap_err().to_string();
    assert!(err.contains("depth/000004.png"), "{err}");
}
