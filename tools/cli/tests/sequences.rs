//! Image sequences through the CLI (issue 46, "The CLI"): `build-map` reads the KITTI, TUM
//! RGB-D and EuRoC layouts `loops` reads; `loops`' hints name keyframes and frames; undefined
//! precision and recall are null; `--keyframe-rate` keeps the asked rate. Tiny generated
//! layouts (textured PGM places, VLAD), no dataset needed.

use std::path::Path;
use std::process::Output;

mod common;
use common::{
    build_vlad_map, fails_with, json, place, s, topoloc, two_sessions, write_pgm, write_places,
    HINTS_HEADER,
};

/// Writes `n` KITTI frames (`image_0/000000.pgm` ..., places 0, 1, ... cycling over
/// `places`) and `times.txt` at `hz` into `dir`.
fn write_kitti(dir: &Path, n: usize, places: u64, hz: f64) {
    std::fs::create_dir_all(dir.join("image_0")).unwrap();
    let mut times = String::new();
    for i in 0..n {
        let image = place(i as u64 % places);
        write_pgm(&dir.join(format!("image_0/{i:06}.pgm")), &image);
        times.push_str(&format!("{:e}\n", i as f64 / hz));
    }
    std::fs::write(dir.join("times.txt"), times).unwrap();
}

/// `topoloc build-map --backend vlad --json` of `images` into `dir/NAME.topoloc`, with `extra`.
fn build(dir: &Path, images: &Path, name: &str, extra: &[&str]) -> Output {
    let (images, out) = (s(images), s(&dir.join(format!("{name}.topoloc"))));
    let args = [
        "build-map",
        "--images",
        &images,
        "--backend",
        "vlad",
        "--out",
        &out,
        "--json",
    ];
    topoloc(&[&args[..], extra].concat())
}

/// `build-map --images` takes the sequence folders `loops --images` takes, frames in the
/// layout's order; `--poses` with another count is matched to them by timestamp.
#[test]
fn build_map_reads_kitti_tum_and_euroc_sequences() {
    let dir = tempfile::tempdir().unwrap();
    let n = 6;

    // KITTI: image_0/ and times.txt (the sequence folder, or its image folder).
    let kitti = dir.path().join("kitti");
    write_kitti(&kitti, n, n as u64, 10.0);
    for (name, path) in [("kitti", kitti.clone()), ("kitti0", kitti.join("image_0"))] {
        let built = json(&build(dir.path(), &path, name, &[]));
        assert_eq!(built["images"], n, "{built}");
        assert_eq!(built["views"], n, "{built}");
        assert_eq!(built["sequence"]["layout"], "Kitti", "{built}");
    }
    // A trajectory at 20 Hz: each frame takes the pose at its timestamp.
    let poses: String = (0..2 * n)
        .map(|k| format!("{} {} 0 0 0 0 0 1\n", k as f64 * 0.05, k as f64 * 1.5))
        .collect();
    let poses_path = dir.path().join("poses.txt");
    std::fs::write(&poses_path, poses).unwrap();
    let posed = json(&build(
        dir.path(),
        &kitti,
        "kitti-posed",
        &["--poses", &s(&poses_path)],
    ));
    assert_eq!(posed["images"], n, "{posed}");
    // Far from every frame (times 100 s on): the frame without a pose is named.
    let late: String = (0..2 * n)
        .map(|k| format!("{} 0 0 0 0 0 0 1\n", 100.0 + k as f64))
        .collect();
    std::fs::write(&poses_path, late).unwrap();
    let far = build(dir.path(), &kitti, "far", &["--poses", &s(&poses_path)]);
    fails_with(&far, &["no pose within", "000000.pgm"]);

    // TUM RGB-D: rgb.txt in time order, which is not the file names' order; the blank image is
    // frame 1 (file-name order would make it 0).
    let tum = dir.path().join("tum");
    std::fs::create_dir_all(tum.join("rgb")).unwrap();
    let names = ["e.pgm", "a.pgm", "b.pgm", "c.pgm", "d.pgm", "f.pgm"];
    let mut rgb = String::from("# color images\n# timestamp filename\n");
    for (i, name) in names.iter().enumerate() {
        let image = match i {
            1 => vec![128; common::W * common::H],
            _ => place(10 + i as u64),
        };
        write_pgm(&tum.join("rgb").join(name), &image);
        rgb.push_str(&format!(
            "{:.6} rgb/{name}\n",
            1305031102.0 + i as f64 / 30.0
        ));
    }
    std::fs::write(tum.join("rgb.txt"), rgb).unwrap();
    let built = json(&build(dir.path(), &tum, "tum", &[]));
    assert_eq!(built["sequence"]["layout"], "TumRgbd", "{built}");
    assert_eq!(built["images"], n, "{built}");
    assert_eq!(
        built["uninformative_images"],
        serde_json::json!([1]),
        "{built}"
    );

    // EuRoC: mav0/cam0/data.csv (nanoseconds) and data/ (from the sequence or mav0 folder).
    let euroc = dir.path().join("euroc");
    let cam = euroc.join("mav0/cam0");
    std::fs::create_dir_all(cam.join("data")).unwrap();
    let mut csv = String::from("#timestamp [ns],filename\n");
    for i in 0..n as u64 {
        let ns = 1403715273262142976 + i * 50_000_000;
        write_pgm(&cam.join(format!("data/{ns}.pgm")), &place(20 + i));
        csv.push_str(&format!("{ns},{ns}.pgm\n"));
    }
    std::fs::write(cam.join("data.csv"), csv).unwrap();
    for (name, path) in [("euroc", euroc.clone()), ("mav0", euroc.join("mav0"))] {
        let built = json(&build(dir.path(), &path, name, &[]));
        assert_eq!(built["sequence"]["layout"], "Euroc", "{built}");
        assert_eq!(built["images"], n, "{built}");
    }

    // A plain folder of images still works, in file-name order.
    let plain = dir.path().join("plain");
    std::fs::create_dir_all(&plain).unwrap();
    for (i, name) in ["b.pgm", "a.pgm", "c.pgm"].iter().enumerate() {
        let image = match i {
            0 => vec![128; common::W * common::H],
            _ => place(30 + i as u64),
        };
        write_pgm(&plain.join(name), &image);
    }
    let built = json(&build(dir.path(), &plain, "plain", &[]));
    assert_eq!(built["sequence"]["layout"], "Folder", "{built}");
    assert_eq!(
        built["uninformative_images"],
        serde_json::json!([1]),
        "{built}"
    );
}

/// The hints file and the one JSON object of `topoloc loops --json --out dir/NAME.csv`.
fn loops(dir: &Path, name: &str, args: &[&str]) -> (serde_json::Value, Vec<Vec<String>>, String) {
    let out = dir.join(format!("{name}.csv"));
    let csv = s(&out);
    let run = topoloc(&[&["loops", "--json", "--out", &csv][..], args].concat());
    let stderr = String::from_utf8_lossy(&run.stderr).to_string();
    let report = json(&run);
    let rows = std::fs::read_to_string(&out)
        .unwrap()
        .lines()
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    (report, rows, stderr)
}

/// Each hint gives its keyframe indices and the frame indices of the same keyframes; a match in
/// a map has no frame (empty in the CSV, null in the JSON).
#[test]
fn loops_hints_give_keyframe_and_frame_indices() {
    let dir = tempfile::tempdir().unwrap();
    let (map_dir, query_dir, both) = two_sessions(dir.path());
    let places = 12;

    // Online, every second frame: keyframe k is frame 2k; revisit b(2j) (keyframe 6 + j)
    // matches a(2j) (keyframe j).
    let (report, rows, _) = loops(
        dir.path(),
        "online",
        &[
            "--images",
            &s(&both),
            "--every",
            "2",
            "--backend",
            "vlad",
            "--local-features",
            "orb",
            "--exclude-ids",
            "3",
            "--exclude-seconds",
            "6",
        ],
    );
    assert_eq!(rows[0].join(","), HINTS_HEADER);
    assert_eq!(report["keyframes"], places, "{report}");
    let frames: Vec<u64> = (0..places).map(|k| 2 * k).collect();
    assert_eq!(
        report["sequence"]["keyframe_frames"],
        serde_json::json!(frames)
    );
    assert!(rows.len() > 1, "the revisits close loops: {report}");
    for row in &rows[1..] {
        let v: Vec<u64> = [0, 1, 12, 13]
            .iter()
            .map(|&c| row[c].parse().unwrap())
            .collect();
        assert_eq!(
            v[0],
            v[1] + places / 2,
            "revisit of the first half: {row:?}"
        );
        assert_eq!((v[2], v[3]), (2 * v[0], 2 * v[1]), "frames: {row:?}");
    }
    for hint in report["accepted"].as_array().unwrap() {
        let (q, m) = (hint["query_index"].as_u64(), hint["matched_index"].as_u64());
        assert_eq!(hint["query_frame"].as_u64(), q.map(|q| 2 * q), "{hint}");
        assert_eq!(hint["matched_frame"].as_u64(), m.map(|m| 2 * m), "{hint}");
    }

    // Against a map, a KITTI sequence every second frame: the map's keyframe ids, the frames of
    // the queries, no frame for the map's side.
    let map = dir.path().join("places.topoloc");
    build_vlad_map(&map_dir, &map);
    let kitti = dir.path().join("kitti");
    std::fs::create_dir_all(kitti.join("image_0")).unwrap();
    let mut times = String::new();
    for i in 0..places {
        let name = format!("{i:03}.pgm");
        std::fs::copy(query_dir.join(&name), kitti.join("image_0").join(name)).unwrap();
        times.push_str(&format!("{:e}\n", i as f64 * 0.1));
    }
    std::fs::write(kitti.join("times.txt"), times).unwrap();
    let (report, rows, _) = loops(
        dir.path(),
        "map",
        &["--images", &s(&kitti), "--map", &s(&map), "--every", "2"],
    );
    assert_eq!(rows[0].join(","), HINTS_HEADER);
    assert!(rows.len() > 1, "{report}");
    for row in &rows[1..] {
        let (q, m, f): (u64, u64, u64) = (
            row[0].parse().unwrap(),
            row[1].parse().unwrap(),
            row[12].parse().unwrap(),
        );
        assert_eq!(
            (m, f),
            (2 * q, 2 * q),
            "map keyframe = query frame: {row:?}"
        );
        assert_eq!(row[13], "", "{row:?}");
    }
    for hint in report["accepted"].as_array().unwrap() {
        assert!(hint["matched_frame"].is_null(), "{hint}");
    }
}

/// A precision without hints and a recall without possible loops are null in the JSON (and
/// `n/a` in the text), not 0.
#[test]
fn loops_reports_null_where_precision_or_recall_is_undefined() {
    let dir = tempfile::tempdir().unwrap();
    let (map_dir, query_dir) = (dir.path().join("map"), dir.path().join("query"));
    let places = 6;
    write_places(&map_dir, &query_dir, places);
    let map = dir.path().join("places.topoloc");
    build_vlad_map(&map_dir, &map);
    // The cameras 100 m apart in a line: no keyframe can close a loop.
    let truth: String = (0..places)
        .map(|i| format!("{i} {} 0 0 0 0 0 1\n", 100 * i))
        .collect();
    let truth_path = dir.path().join("truth.txt");
    std::fs::write(&truth_path, truth).unwrap();
    // No hint can pass 10000 inliers.
    let args = [
        "--images",
        &s(&query_dir),
        "--map",
        &s(&map),
        "--min-inliers",
        "10000",
        "--aligned-tolerance",
        "0",
        "--truth",
        &s(&truth_path),
    ];
    let (report, rows, _) = loops(dir.path(), "none", &args);
    assert_eq!(rows.len(), 1, "no hint: {report}");
    assert_eq!(report["hints"], 0, "{report}");
    assert!(report["precision"].is_null(), "no hint: {report}");
    assert_eq!(
        report["recall"], 0.0,
        "every keyframe could match: {report}"
    );
    let truth = &report["truth"];
    assert_eq!(truth["possible"], 0, "{report}");
    for key in [
        "precision",
        "recall",
        "precision_place_or_pose",
        "pose_precision",
        "recall_at_full_precision",
    ] {
        assert!(truth[key].is_null(), "truth.{key} in {report}");
    }
    // The text report says so too.
    let csv = s(&dir.path().join("text.csv"));
    let text = topoloc(&[&["loops", "--out", &csv][..], &args].concat());
    assert!(text.status.success());
    let stdout = String::from_utf8_lossy(&text.stdout);
    assert!(
        stdout.contains("precision n/a, recall 0.000")
            && stdout.contains("precision n/a, recall n/a"),
        "{stdout}"
    );
}

/// `--keyframe-rate 3` on 10 Hz frames keeps 3 per second (frames 0, 4, 7, 10, ...), not every
/// 4th (2.5 per second), and says the rate it kept on stderr and in the JSON.
#[test]
fn keyframe_rate_keeps_the_asked_rate_on_average() {
    let dir = tempfile::tempdir().unwrap();
    let (map_dir, query_dir) = (dir.path().join("map"), dir.path().join("query"));
    write_places(&map_dir, &query_dir, 4);
    let map = dir.path().join("places.topoloc");
    build_vlad_map(&map_dir, &map);
    // 3 s of KITTI at 10 Hz.
    let kitti = dir.path().join("kitti");
    write_kitti(&kitti, 30, 4, 10.0);
    let (report, _, stderr) = loops(
        dir.path(),
        "rate",
        &[
            "--images",
            &s(&kitti),
            "--map",
            &s(&map),
            "--keyframe-rate",
            "3",
        ],
    );
    let sequence = &report["sequence"];
    assert_eq!(
        sequence["keyframe_frames"],
        serde_json::json!([0, 4, 7, 10, 14, 17, 20, 24, 27]),
        "{report}"
    );
    assert_eq!(report["keyframes"], 9, "{report}");
    let rate = sequence["effective_rate_hz"].as_f64().unwrap();
    assert!((rate - 3.0).abs() < 1e-9, "{report}");
    assert!((sequence["duration_s"].as_f64().unwrap() - 3.0).abs() < 1e-9);
    assert_eq!(sequence["keyframe_rate_hz"], 3.0);
    assert!(
        stderr.contains(
            "9 keyframes of 30 frames (--keyframe-rate 3): 3.000 per second over 3.000 s"
        ),
        "{stderr}"
    );
}
