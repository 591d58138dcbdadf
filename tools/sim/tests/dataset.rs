//! The dataset folder end to end: a planned looping trajectory in a hand-made world, its ground
//! truth and odometry, written and read back; then damaged folders, each refused with an error
//! that names the file.

use nalgebra::Point3;
use std::path::Path;
use topoloc::build::TimedPose;
use topoloc::skeleton::OccupancyGrid;
use topoloc_sim::camera::Intrinsics;
use topoloc_sim::dataset::{
    image_name, Dataset, DatasetError, DatasetInfo, DatasetWriter, Manifest,
};
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

/// A flight through the ring world and everything a dataset of it holds.
struct Ring {
    k: Intrinsics,
    graph: PlaceGraph,
    ground_truth: Vec<TimedPose>,
    odometry: Vec<TimedPose>,
    nodes: Vec<FrameTruth>,
}

impl Ring {
    /// The ring world flown along `frames` poses.
    fn along(frames: Vec<TimedPose>) -> Self {
        let graph = ring_graph();
        Self {
            k: Intrinsics::from_hfov(32, 24, 90.0),
            nodes: ground_truth(&ring_world(), &graph, &frames).unwrap(),
            odometry: odometry(&frames, &OdometryNoise::typical_vio(), 9).unwrap(),
            ground_truth: frames,
            graph,
        }
    }

    /// A writer into `root` that has the images of the first `count` frames.
    fn writer(&self, root: &Path, count: usize) -> DatasetWriter {
        let writer = DatasetWriter::create(root, self.k).unwrap();
        for f in 0..count {
            writer.write_image(f, &image(&self.k, f)).unwrap();
        }
        writer
    }

    /// Finishes `writer` with the flight's records but `odometry`, at `rate_hz`.
    fn finish(
        &self,
        writer: DatasetWriter,
        rate_hz: f64,
        odometry: &[TimedPose],
    ) -> Result<Manifest, DatasetError> {
        let (graph, nodes) = (&self.graph, &self.nodes);
        writer.finish(&info(rate_hz), graph, &self.ground_truth, odometry, nodes)
    }
}

/// Writes a dataset of the ring world along `frames` poses.
fn write(root: &Path, frames: Vec<TimedPose>, rate_hz: f64) -> Ring {
    let ring = Ring::along(frames);
    let writer = ring.writer(root, ring.ground_truth.len());
    ring.finish(writer, rate_hz, &ring.odometry).unwrap();
    ring
}

/// Asserts that the error message `err` names each of `words`.
#[track_caller]
fn assert_names(err: impl std::fmt::Display, words: &[&str]) {
    let err = err.to_string();
    for word in words {
        assert!(err.contains(word), "'{word}' not in: {err}");
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
    // The default flight: four legs 5 m or more apart, one of them back to an earlier goal.
    let spec = TrajectorySpec {
        seed: 5,
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

type Damage = Box<dyn FnOnce(&Path)>;

#[test]
fn damaged_folders_are_refused_naming_the_file() {
    // Edits: the first `from` in `file` replaced by `to`; the error names the file and `words`.
    let edits: [(&str, &str, &str, &[&str]); 8] = [
        ("graph.json", "[", "{", &["line"]),
        ("manifest.json", "\"split\"", "\"splat\"", &["split"]),
        ("manifest.json", "\"1.1\"", "\"2.1\"", &["2.1", "newer"]),
        ("manifest.json", "topoloc-sim-dataset", "tum", &["format"]),
        ("groundtruth.txt", " 1.5 ", " x ", &["line 2", "'x'"]),
        ("nodes.csv", "\n3,", "\n3,x", &["line 5", "place"]),
        ("nodes.csv", "\n2,0,", "\n2,9,", &["line 4", "place 9"]),
        ("nodes.csv", "frame,", "query,", &["line 1", "header"]),
    ];
    for (file, from, to, words) in edits {
        let err = open_damaged(|root| edit(&root.join(file), |t| t.replacen(from, to, 1)));
        assert_names(err, &[&[file], words].concat());
    }
    let cases: Vec<(Damage, Vec<&str>)> = vec![
        (
            Box::new(|r| std::fs::remove_dir_all(r).unwrap()),
            vec!["ds", "dataset folder is missing"],
        ),
        (
            Box::new(|r| std::fs::remove_file(r.join("manifest.json")).unwrap()),
            vec!["manifest.json", "missing"],
        ),
        (
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
            Box::new(|r| std::fs::remove_file(r.join(image_name(3))).unwrap()),
            vec!["000003.png", "missing"],
        ),
        (
            Box::new(|r| {
                std::fs::copy(r.join(image_name(0)), r.join("images/extra.png"))
                    .map(drop)
                    .unwrap()
            }),
            vec!["images", "13 PNG images for 12 frames"],
        ),
        (
            Box::new(|r| {
                edit(&r.join("odometry.txt"), |t| {
                    t.lines().take(5).collect::<Vec<_>>().join("\n")
                })
            }),
            vec!["odometry.txt", "4 poses for 12 frames"],
        ),
    ];
    for (damage, words) in cases {
        assert_names(open_damaged(damage), &words);
    }
}

#[test]
fn the_writer_refuses_bad_input_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let ring = Ring::along(straight_frames());
    let k = ring.k;
    std::fs::write(dir.path().join("stale.txt"), "x").unwrap();
    let err = DatasetWriter::create(dir.path(), k).unwrap_err();
    assert!(matches!(err, DatasetError::NotEmpty { .. }), "{err}");
    let bad_k = Intrinsics { width: 0, ..k };
    let err = DatasetWriter::create(&dir.path().join("a"), bad_k).unwrap_err();
    assert_names(err, &["intrinsics.width"]);

    let n = ring.ground_truth.len();
    let writer = ring.writer(&dir.path().join("b"), n - 1);
    let err = writer.write_image(0, &[0; 10]).unwrap_err();
    assert_names(err, &["000000.png", "needs 2304"]);
    let err = ring.finish(writer, 10.0, &ring.ground_truth).unwrap_err();
    assert_names(err, &["images", "11 PNG images for 12 frames"]);
    assert!(
        !dir.path().join("b/manifest.json").exists(),
        "no manifest for an incomplete dataset"
    );

    let writer = DatasetWriter::create(&dir.path().join("c"), k).unwrap();
    let err = ring
        .finish(writer, 10.0, &ring.ground_truth[1..])
        .unwrap_err();
    assert_names(err, &["odometry.txt", "11 poses for 12 frames"]);
}

/// Depth images (format 1.1) are written as 16-bit millimetres, listed in the manifest, read
/// back by path, and required for every frame once one frame has one.
#[test]
fn depth_images_round_trip_and_are_complete() {
    let dir = tempfile::tempdir().unwrap();
    let ring = Ring::along(straight_frames());
    let n = ring.ground_truth.len();
    let depth_of = |f: usize| -> Vec<f32> {
        (0..32 * 24)
            .map(|i| match i % 7 {
                0 => f32::NAN,
                _ => 0.5 + f as f32 * 0.25 + (i % 32) as f32 * 0.01,
            })
            .collect()
    };

    let root = dir.path().join("with-depth");
    let writer = ring.writer(&root, n);
    for f in 0..n {
        writer.write_depth(f, &depth_of(f)).unwrap();
    }
    let err = writer.write_depth(0, &[1.0; 5]).unwrap_err();
    assert_names(err, &["depth/000000.png", "needs 768"]);
    ring.finish(writer, 10.0, &ring.ground_truth).unwrap();
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
    let writer = ring.writer(&dir.path().join("partial"), n);
    writer.write_depth(0, &depth_of(0)).unwrap();
    let err = ring.finish(writer, 10.0, &ring.ground_truth).unwrap_err();
    assert_names(err, &["depth", "1 PNG images for 12 frames"]);
    let manifest = root.join("manifest.json");
    let text = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(
        &manifest,
        text.replace("\"depth_scale\": 1000.0", "\"depth_scale\": -1.0"),
    )
    .unwrap();
    assert_names(Dataset::open(&root).unwrap_err(), &["depth_scale is -1"]);
    std::fs::write(&manifest, text).unwrap();
    std::fs::remove_file(root.join("depth/000004.png")).unwrap();
    assert_names(Dataset::open(&root).unwrap_err(), &["depth/000004.png"]);
}
