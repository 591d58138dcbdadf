//! `topoloc localize`: one result line per frame on stdout (text or JSON lines), frame times
//! and odometry matched by the documented rules, per-frame error lines, fatal input errors on
//! stderr with a non-zero exit. Maps come from generated images (VLAD backend: no model
//! needed): textured PGM "places" through `build-map`, and a tiny `topoloc simulate` world
//! with its odometry, ground truth and true place per frame.

use opencv::core::{Mat, Size, CV_8UC1};
use opencv::prelude::*;
use opencv::{imgproc, videoio};
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

mod common;
use common::{
    build_vlad_map, eval_dataset, json, place, read_json, s, seen_again, simulate_tiny, topoloc,
    tum_rows, write_intrinsics, write_pgm_sized as write_pgm, write_places, H, W,
};

/// Places of the PGM map (one image each).
const PLACES: usize = 12;

/// Place `i` seen again: brighter and shifted by 4 pixels.
fn query(i: usize) -> Vec<u8> {
    seen_again(&place(i as u64))
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn assert_stderr_contains(out: &Output, text: &str) {
    assert!(stderr(out).contains(text), "{}", stderr(out));
}

/// Runs `localize` with `args`, expects success, parses every stdout line as JSON.
fn json_lines(args: &[&str]) -> Vec<Value> {
    let out = topoloc(&[&["localize", "--json-lines"], args].concat());
    assert!(out.status.success(), "stderr: {}", stderr(&out));
    parse_lines(&out)
}

/// Every stdout line of `out` parsed as JSON.
fn parse_lines(out: &Output) -> Vec<Value> {
    String::from_utf8(out.stdout.clone())
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect()
}

/// Runs `localize` with `args` and expects failure; its stderr.
fn failure(args: &[&str]) -> String {
    let out = topoloc(&[&["localize"], args].concat());
    assert!(!out.status.success(), "should fail: {args:?}");
    assert!(out.stdout.is_empty(), "stdout carries results only");
    stderr(&out)
}

/// A map and its queries in a temporary folder (removed on drop), where tests write more.
struct Fixture {
    dir: tempfile::TempDir,
    map: PathBuf,
    /// The query frames: a folder of images ([`pgm`]) or a dataset folder ([`sim`]).
    queries: PathBuf,
}

impl Fixture {
    fn root(&self) -> &Path {
        self.dir.path()
    }
}

/// The PGM fixture: a map of `PLACES` images and a query folder `000.pgm`..`011.pgm` (place
/// i seen again).
fn pgm() -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let (map_dir, queries) = (dir.path().join("map"), dir.path().join("queries"));
    write_places(&map_dir, &queries, PLACES as u64);
    let map = dir.path().join("places.topoloc");
    build_vlad_map(&map_dir, &map);
    Fixture { dir, map, queries }
}

/// Checks the keys and types of a result line and its candidates (ranked, `top_k` of them).
fn check_result(line: &Value, top_k: usize) {
    for key in ["frame", "place", "view"] {
        assert!(line[key].is_u64(), "{key}: {line}");
    }
    for key in [
        "timestamp",
        "confidence",
        "similarity",
        "off_map_probability",
        "ms",
    ] {
        assert!(line[key].is_f64(), "{key}: {line}");
    }
    assert!(
        line["source"].is_string() && line["off_map"].is_boolean(),
        "{line}"
    );
    assert!(line["odometry"].is_boolean(), "{line}");
    assert!(line.get("error").is_none(), "{line}");
    for key in ["keyframe", "view_image", "pose_fix", "odometry_timestamp"] {
        assert!(line.get(key).is_some(), "{key} missing: {line}");
    }
    let confidence = line["confidence"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&confidence), "{line}");
    let candidates = line["candidates"].as_array().unwrap();
    assert_eq!(candidates.len(), top_k, "{line}");
    assert_eq!(candidates[0]["place"], line["place"]);
    assert_eq!(candidates[0]["view"], line["view"]);
    assert_eq!(candidates[0]["probability"], line["confidence"]);
    for pair in candidates.windows(2) {
        let p = |c: &Value| c["probability"].as_f64().unwrap();
        assert!(p(&pair[0]) >= p(&pair[1]), "ranked: {line}");
    }
    for c in candidates {
        assert!(c["similarity"].is_f64() && c["verified"].is_boolean() && c["inliers"].is_u64());
    }
}

/// Checks the results of the PGM fixture's queries: one per query, each with `top_k`
/// candidates, frame `i` from `source(i)`, and place `i` found for all but at most one.
fn check_pgm_queries(lines: &[Value], top_k: usize, source: impl Fn(usize) -> String) {
    assert_eq!(lines.len(), PLACES);
    let mut right = 0;
    for (i, line) in lines.iter().enumerate() {
        check_result(line, top_k);
        assert_eq!(line["frame"], i);
        assert_eq!(line["source"], source(i));
        right += usize::from(line["place"] == i);
    }
    assert!(right >= PLACES - 1, "R@1 {right}/{PLACES}");
}

#[test]
fn image_folder_streams_one_ranked_result_per_frame() {
    let fixture = &pgm();
    let (map, queries) = (s(&fixture.map), s(&fixture.queries));
    let lines = json_lines(&["--map", &map, "--images", &queries, "--top-k", "3"]);
    check_pgm_queries(&lines, 3, |i| format!("{i:03}.pgm"));
    for (i, line) in lines.iter().enumerate() {
        // Numeric names are the timestamps (seconds).
        assert_eq!(line["timestamp"].as_f64(), Some(i as f64));
        assert_eq!(line["odometry"], false);
        assert!(line["odometry_timestamp"].is_null() && line["pose_fix"].is_null());
        assert_eq!(line["off_map"], false, "the map's own places: {line}");
        // Views record their source image as keyframe id; place i is map image i.
        assert_eq!(line["keyframe"], line["view"]);
    }

    // --max-frames, --stride and --fps.
    let lines = json_lines(&["--map", &map, "--images", &queries, "--max-frames", "4"]);
    assert_eq!(lines.len(), 4);
    let lines = json_lines(&["--map", &map, "--images", &queries, "--stride", "5"]);
    let frames: Vec<u64> = lines.iter().map(|l| l["frame"].as_u64().unwrap()).collect();
    assert_eq!(frames, [0, 5, 10]);
    let args = [
        "--map",
        &map,
        "--images",
        &queries,
        "--fps",
        "20",
        "--start-time",
        "100",
    ];
    let lines = json_lines(&args);
    assert!((lines[3]["timestamp"].as_f64().unwrap() - 100.15).abs() < 1e-9);

    // Text: one line per frame, nothing else on stdout.
    let out = topoloc(&["localize", "--map", &map, "--images", &queries]);
    assert!(out.status.success(), "{}", stderr(&out));
    let text = String::from_utf8(out.stdout.clone()).unwrap();
    let rows: Vec<&str> = text.lines().collect();
    assert_eq!(rows.len(), PLACES);
    for (i, row) in rows.iter().enumerate() {
        let fields: Vec<&str> = row.split_whitespace().collect();
        assert_eq!(fields[0], i.to_string(), "{row}");
        assert_eq!(fields[1], format!("{i:03}.pgm"), "{row}");
        assert!(row.contains(" place ") && row.contains(" | top "), "{row}");
    }
    assert_stderr_contains(&out, "12 frames, 12 localized");
}

#[test]
fn frames_that_fail_are_error_lines_and_the_stream_goes_on() {
    let fixture = &pgm();
    let dir = fixture.root().join("mixed");
    std::fs::create_dir_all(&dir).unwrap();
    for i in 0..6 {
        write_pgm(&dir.join(format!("{i:03}.pgm")), W, H, &query(i));
    }
    std::fs::write(dir.join("002.pgm"), "not an image").unwrap();
    write_pgm(&dir.join("004.pgm"), W / 2, H / 2, &query(4)[..W * H / 4]);
    std::fs::write(dir.join("notes.txt"), "not a frame").unwrap();
    // A blank frame: the describer finds nothing in it.
    write_pgm(&dir.join("006.pgm"), W, H, &vec![128; W * H]);
    let out = topoloc(&[
        "localize",
        "--json-lines",
        "--map",
        &s(&fixture.map),
        "--images",
        &s(&dir),
        // Frame by frame: the filter would step once per localized frame and lag one place
        // behind after each skipped one.
        "--mode",
        "single-frame",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let lines = parse_lines(&out);
    assert_eq!(lines.len(), 7, "notes.txt is not a frame: {lines:?}");
    assert_eq!(lines[6]["error_kind"], "localize");
    assert!(
        lines[6]["error"]
            .as_str()
            .unwrap()
            .contains("uninformative"),
        "{}",
        lines[6]
    );
    assert_eq!(lines[2]["error_kind"], "decode");
    assert!(
        lines[2]["error"].as_str().unwrap().contains("002.pgm"),
        "{}",
        lines[2]
    );
    assert_eq!(lines[4]["error_kind"], "size");
    assert!(
        lines[4]["error"].as_str().unwrap().contains("160x120"),
        "{}",
        lines[4]
    );
    for i in [0, 1, 3, 5] {
        check_result(&lines[i], 5);
        assert_eq!(lines[i]["place"], i, "{}", lines[i]);
    }
    for i in [2, 4, 6] {
        assert_eq!(lines[i]["frame"], i);
        assert_eq!(lines[i]["source"], format!("{i:03}.pgm"));
        assert!(lines[i].get("place").is_none());
    }
    let err = stderr(&out);
    assert!(
        err.contains("notes.txt") && err.contains("3 errors"),
        "{err}"
    );

    // No frame localized at all: non-zero exit after the error lines.
    let bad = fixture.root().join("all-bad");
    std::fs::create_dir_all(&bad).unwrap();
    std::fs::write(bad.join("a.png"), "text").unwrap();
    let out = topoloc(&["localize", "--map", &s(&fixture.map), "--images", &s(&bad)]);
    assert!(!out.status.success());
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 1);
    assert_stderr_contains(&out, "none of the 1 frames");
}

#[test]
fn bad_input_exits_non_zero_naming_what_is_wrong() {
    let fixture = &pgm();
    let (map, queries) = (s(&fixture.map), s(&fixture.queries));
    let tum = |name: &str, text: &str| {
        let path = fixture.root().join(name);
        std::fs::write(&path, text).unwrap();
        s(&path)
    };
    let good = "0 0 0 0 0 0 0 1\n";
    let with_odometry =
        |file: &str| failure(&["--map", &map, "--images", &queries, "--odometry", file]);
    let err = with_odometry(&tum(
        "bad-field.txt",
        &format!("# t x y z\n{good}1 0 0 abc 0 0 0 1\n"),
    ));
    assert!(
        err.contains("bad-field.txt line 3, field 4 (tz): 'abc' is not a number"),
        "{err}"
    );
    let err = with_odometry(&tum("short.txt", &format!("{good}1 0 0 0 0 0 1\n")));
    assert!(
        err.contains("short.txt line 2: 7 fields, expected 8"),
        "{err}"
    );
    let err = with_odometry(&tum(
        "back.txt",
        &format!("{good}2 0 0 0 0 0 0 1\n1 0 0 0 0 0 0 1\n"),
    ));
    assert!(err.contains("line 3, field 1 (timestamp)"), "{err}");
    let err = with_odometry(&s(&fixture.root().join("missing.txt")));
    assert!(err.contains("missing.txt"), "{err}");

    let err = failure(&[
        "--map",
        &s(&fixture.root().join("none.topoloc")),
        "--images",
        &queries,
    ]);
    assert!(
        err.contains("--map") && err.contains("none.topoloc"),
        "{err}"
    );

    // A map of descriptors, without a describer.
    let mut builder =
        topoloc::MapBuilder::new(topoloc::DescriptorIdentity::new("host", "test", 4).unwrap());
    for k in 0..3 {
        let p = builder.add_place(None).unwrap();
        let mut d = [0.1f32; 4];
        d[k] = 1.0;
        builder.add_view(p, &d, Default::default()).unwrap();
    }
    let bare = fixture.root().join("bare.topoloc");
    builder.build().unwrap().save(&bare).unwrap();
    let err = failure(&["--map", &s(&bare), "--images", &queries]);
    assert!(
        err.contains("the map has no describer") && err.contains("topoloc build-map"),
        "{err}"
    );

    // Unnumbered file names give no frame times for odometry.
    let named = fixture.root().join("named");
    std::fs::create_dir_all(&named).unwrap();
    write_pgm(&named.join("left.pgm"), W, H, &query(0));
    let good = tum("good.txt", good);
    let err = failure(&["--map", &map, "--images", &s(&named), "--odometry", &good]);
    assert!(err.contains("--fps"), "{err}");
    // Frames beyond the tolerance of every pose.
    let err = failure(&[
        "--map",
        &map,
        "--images",
        &queries,
        "--odometry",
        &good,
        "--start-time",
        "5",
        "--fps",
        "1",
    ]);
    assert!(
        err.contains("no frame time is within 0.02 s of a pose"),
        "{err}"
    );
    let err = failure(&[
        "--map",
        &map,
        "--images",
        &s(&fixture.root().join("no-dir")),
    ]);
    assert!(err.contains("--images") && err.contains("no-dir"), "{err}");
    let err = failure(&["--map", &map, "--video", &good]);
    assert!(err.contains("--video") && err.contains("good.txt"), "{err}");
    let err = failure(&["--map", &map, "--images", &queries, "--fps", "0"]);
    assert!(err.contains("--fps 0"), "{err}");
    let err = failure(&["--map", &map, "--images", &queries, "--intrinsics", &good]);
    assert!(err.contains("--verify"), "{err}");
    let err = failure(&["--map", &map]);
    assert!(err.contains("--images") && err.contains("--video"), "{err}");
}

#[test]
fn video_frames_take_the_container_times() {
    let fixture = &pgm();
    let video = fixture.root().join("queries.avi");
    let fourcc = videoio::VideoWriter::fourcc('M', 'J', 'P', 'G').unwrap();
    let size = Size::new(W as i32, H as i32);
    let mut writer =
        videoio::VideoWriter::new(s(&video).as_str(), fourcc, 4.0, size, true).unwrap();
    assert!(writer.is_opened().unwrap(), "OpenCV writes MJPG AVI");
    for i in 0..PLACES {
        let pixels = query(i);
        let grey = Mat::new_rows_cols_with_data(H as i32, W as i32, &pixels).unwrap();
        assert_eq!(grey.typ(), CV_8UC1);
        let mut bgr = Mat::default();
        imgproc::cvt_color_def(&grey, &mut bgr, imgproc::COLOR_GRAY2BGR).unwrap();
        writer.write(&bgr).unwrap();
    }
    writer.release().unwrap();

    let map = s(&fixture.map);
    let lines = json_lines(&["--map", &map, "--video", &s(&video)]);
    check_pgm_queries(&lines, 5, |i| format!("frame {i}"));
    for (i, line) in lines.iter().enumerate() {
        let t = line["timestamp"].as_f64().unwrap();
        assert!(
            (t - 0.25 * i as f64).abs() < 1e-6,
            "4 fps container: {line}"
        );
    }

    // Odometry by container time from --start-time: every frame has a pose, every frame but
    // the first a motion.
    let poses: String = (0..PLACES)
        .map(|i| format!("{} {i} 0 0 0 0 0 1\n", 50.0 + 0.25 * i as f64))
        .collect();
    let odometry = fixture.root().join("video-odometry.txt");
    std::fs::write(&odometry, poses).unwrap();
    let lines = json_lines(&[
        "--map",
        &map,
        "--video",
        &s(&video),
        "--odometry",
        &s(&odometry),
    ]);
    assert_eq!(lines.len(), PLACES);
    for (i, line) in lines.iter().enumerate() {
        assert_eq!(line["odometry"], i > 0, "{line}");
        let t = 50.0 + 0.25 * i as f64;
        assert!(
            (line["timestamp"].as_f64().unwrap() - t).abs() < 1e-6,
            "{line}"
        );
        assert_eq!(line["odometry_timestamp"].as_f64(), Some(t), "{line}");
    }
}

/// A tiny simulated world (bright light, 12 views per place) with its dataset folder
/// `traj-000` as the queries, and `eval --dataset --odometry`'s report.
fn sim() -> (Fixture, Value) {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    simulate_tiny(&out, 12, &["--condition", "bright"]);
    let (map, queries) = (out.join("map.topoloc"), out.join("traj-000"));
    let eval = json(&eval_dataset(&map, &queries, &["--odometry"]));
    (Fixture { dir, map, queries }, eval)
}

/// The true place of every frame (`nodes.csv`) and each place's neighbours (`graph.json`).
fn truth(traj: &Path) -> (Vec<u64>, Vec<Vec<u64>>) {
    let nodes = std::fs::read_to_string(traj.join("nodes.csv")).unwrap();
    let places = nodes
        .lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).unwrap().parse().unwrap())
        .collect();
    let graph = read_json(&traj.join("graph.json"));
    let mut neighbours = vec![Vec::new(); graph["places"].as_array().unwrap().len()];
    for edge in graph["edges"].as_array().unwrap() {
        let (a, b) = (edge[0].as_u64().unwrap(), edge[1].as_u64().unwrap());
        neighbours[a as usize].push(b);
        neighbours[b as usize].push(a);
    }
    (places, neighbours)
}

/// MNA (exact place) and OHA (place or a neighbour) of streamed results.
fn accuracy(lines: &[Value], truth: &[u64], neighbours: &[Vec<u64>]) -> (f64, f64) {
    assert_eq!(lines.len(), truth.len());
    let (mut exact, mut near) = (0, 0);
    for (line, &t) in lines.iter().zip(truth) {
        let p = line["place"].as_u64().unwrap();
        exact += usize::from(p == t);
        near += usize::from(p == t || neighbours[t as usize].contains(&p));
    }
    let n = truth.len() as f64;
    (exact as f64 / n, near as f64 / n)
}

/// One simulated sequence (it takes a while to generate) for the odometry, verification and
/// pipe checks.
#[test]
fn simulated_sequence_with_odometry_verification_and_a_closing_pipe() {
    let (sim, eval) = sim();
    odometry_is_matched_by_time_and_fed_as_relative_motion(&sim, &eval);
    verification_with_intrinsics_gives_pose_fixes_near_the_truth(&sim);
    closing_stdout_ends_the_stream_cleanly(&sim);
}

fn odometry_is_matched_by_time_and_fed_as_relative_motion(sim: &Fixture, eval: &Value) {
    let (map, images) = (s(&sim.map), s(&sim.queries.join("images")));
    let odometry = s(&sim.queries.join("odometry.txt"));
    let odometry = odometry.as_str();
    let (places, neighbours) = truth(&sim.queries);
    let frames = places.len();
    assert!(frames >= 100, "{frames} frames");

    // The dataset's frames are 4 Hz from t = 0, as its TUM files say.
    let at_4hz = ["--map", &map, "--images", &images, "--fps", "4"];
    let without = json_lines(&at_4hz);
    let with = json_lines(&[&at_4hz[..], &["--odometry", odometry]].concat());
    assert_eq!(with.len(), frames);
    for (i, line) in with.iter().enumerate() {
        check_result(line, 5);
        assert_eq!(line["odometry"], i > 0, "{line}");
        assert_eq!(line["odometry_timestamp"].as_f64(), Some(i as f64 * 0.25));
    }
    // The stream gives what `eval --dataset` measures for the same configurations, and the
    // filter with odometry is mostly right: the true place or a neighbour.
    let (mna, oha) = accuracy(&without, &places, &neighbours);
    let (mna_odo, oha_odo) = accuracy(&with, &places, &neighbours);
    for (config, key, streamed) in [
        ("filter", "mna", mna),
        ("filter", "oha", oha),
        ("filter_odometry", "mna", mna_odo),
        ("filter_odometry", "oha", oha_odo),
    ] {
        let measured = eval[config][key].as_f64().unwrap();
        assert!(
            (streamed - measured).abs() < 1e-9,
            "{config}.{key}: {streamed} vs {eval}"
        );
    }
    assert!(oha_odo >= 0.75, "OHA with odometry {oha_odo}");
    assert!(oha_odo > oha, "odometry helps: {oha_odo} vs {oha}");

    // Poses off by 10 ms still match within the default 20 ms; not within 5 ms.
    let late = [
        &at_4hz[..],
        &["--start-time", "0.01", "--odometry", odometry],
    ]
    .concat();
    let shifted = json_lines(&[&late[..], &["--max-frames", "8"]].concat());
    assert!(shifted.iter().skip(1).all(|l| l["odometry"] == true));
    assert_eq!(shifted[3]["odometry_timestamp"].as_f64(), Some(0.75));
    let tight = [&late[..], &["--odometry-tolerance", "0.005"]].concat();
    assert!(failure(&tight).contains("within 0.005 s"));

    // Frames 10-14 lose their poses: they get none, frame 15 (after a frame without a pose)
    // has a pose but no motion, frame 16 a motion again.
    let text = std::fs::read_to_string(odometry).unwrap();
    let kept: String = text
        .lines()
        .filter(|l| {
            let t: f64 = l.split_whitespace().next().unwrap().parse().unwrap_or(-1.0);
            !(2.4..3.6).contains(&t)
        })
        .map(|l| format!("{l}\n"))
        .collect();
    let gappy = sim.queries.join("gappy.txt");
    std::fs::write(&gappy, kept).unwrap();
    let gappy = s(&gappy);
    let lines = json_lines(&[&at_4hz[..], &["--max-frames", "20", "--odometry", &gappy]].concat());
    for (i, line) in lines.iter().enumerate() {
        let has_pose = !(10..15).contains(&i);
        assert_eq!(line["odometry_timestamp"].is_null(), !has_pose, "{line}");
        assert_eq!(line["odometry"], i > 0 && has_pose && i != 15, "{line}");
    }
}

fn verification_with_intrinsics_gives_pose_fixes_near_the_truth(sim: &Fixture) {
    let camera = sim.queries.join("camera.txt");
    write_intrinsics(&sim.queries, &camera, 0.0);
    let frames = 40;
    let lines = json_lines(&[
        "--map",
        &s(&sim.map),
        "--images",
        &s(&sim.queries.join("images")),
        "--fps",
        "4",
        "--verify",
        "3",
        "--intrinsics",
        &s(&camera),
        "--max-frames",
        &frames.to_string(),
    ]);
    assert_eq!(lines.len(), frames);
    let truth = tum_rows(&sim.queries.join("groundtruth.txt"));
    let mut errors = Vec::new();
    for (line, (_, position)) in lines.iter().zip(&truth) {
        check_result(line, 5);
        let verified = line["candidates"].as_array().unwrap()[..3]
            .iter()
            .filter(|c| c["verified"] == true)
            .count();
        assert_eq!(
            verified, 3,
            "the 3 most probable places are checked: {line}"
        );
        let fix = &line["pose_fix"];
        if fix.is_null() {
            continue;
        }
        assert!(fix["inliers"].as_u64().unwrap() >= 30, "{fix}");
        let numbers = |key: &str| -> Vec<f64> {
            let values = fix[key].as_array().unwrap();
            values.iter().map(|v| v.as_f64().unwrap()).collect()
        };
        let (t, q) = (numbers("translation"), numbers("quaternion"));
        assert!(
            (q.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-6,
            "{fix}"
        );
        let d: f64 = (0..3)
            .map(|k| (t[k] - position[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        errors.push(d);
    }
    assert!(
        errors.len() >= 10,
        "{} pose fixes in {frames} frames",
        errors.len()
    );
    errors.sort_by(f64::total_cmp);
    let median = errors[errors.len() / 2];
    assert!(median < 0.15, "median pose fix error {median} m");
}

fn closing_stdout_ends_the_stream_cleanly(sim: &Fixture) {
    // 169 JSON lines are well over a pipe's 64 KiB: the writer blocks, then finds it closed.
    let mut child = Command::new(env!("CARGO_BIN_EXE_topoloc"))
        .args([
            "localize",
            "--json-lines",
            "--map",
            &s(&sim.map),
            "--images",
            &s(&sim.queries.join("images")),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut reader = BufReader::new(child.stdout.take().unwrap());
    let mut first = String::new();
    reader.read_line(&mut first).unwrap();
    let line: Value = serde_json::from_str(&first).unwrap();
    assert_eq!(
        line["frame"], 0,
        "the first result arrives as soon as it is ready"
    );
    drop(reader);
    let out = child.wait_with_output().unwrap();
    let err = stderr(&out);
    assert!(out.status.success(), "{err}");
    assert!(!err.contains("panicked") && !err.contains("Error"), "{err}");
}
