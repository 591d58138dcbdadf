//! The CLI contract of `topoloc build-map` and `topoloc eval`, which other tools call: JSON keys,
//! the predictions CSV, the PNG, and clear failures. Uses the VLAD backend on generated PGM
//! images, so it needs no model and no shared data.

use std::path::Path;

mod common;
use common::{
    build_vlad_map, eval_dataset, fails_with, json, place, read_json, s, simulate_tiny, topoloc,
    tum_rows, two_sessions, write_intrinsics, write_pgm, write_places, HINTS_HEADER,
};

#[test]
fn build_map_and_eval_follow_the_contract() {
    let dir = tempfile::tempdir().unwrap();
    let (map_dir, query_dir) = (dir.path().join("map"), dir.path().join("query"));
    let places = 12;
    // The queries: the same places, brighter and shifted by 4 pixels.
    write_places(&map_dir, &query_dir, places);
    let map = dir.path().join("places.topoloc");

    let built = build_vlad_map(&map_dir, &map);
    assert_eq!(built["places"], places);
    assert_eq!(built["views"], places);
    assert!(built["descriptor"]
        .as_str()
        .unwrap()
        .starts_with("vlad-orb"));

    let (predictions, plot) = (dir.path().join("p.csv"), dir.path().join("p.png"));
    let report = json(&topoloc(&[
        "eval",
        "--map",
        &s(&map),
        "--images",
        &s(&query_dir),
        "--tolerance",
        "0",
        "--json",
        "--predictions",
        &s(&predictions),
        "--plot",
        &s(&plot),
    ]));
    for key in [
        "r_at_1",
        "r_at_5",
        "r_at_100p",
        "frames",
        "ms_per_frame_median",
    ] {
        assert!(report.get(key).is_some(), "missing '{key}' in {report}");
    }
    assert_eq!(report["frames"], places);
    assert_eq!(report["mode"], "filter");
    assert!(
        report["single_frame"]["r_at_1"].as_f64().unwrap() >= 0.9,
        "{report}"
    );
    assert!(report["r_at_5"].as_f64().unwrap() >= report["r_at_1"].as_f64().unwrap());
    assert!(report.get("mna").is_none(), "no ground-truth nodes given");
    // The queries are the map's own images: none may be flagged off the map.
    assert_eq!(report["off_map_rate"].as_f64(), Some(0.0), "{report}");
    assert_eq!(
        report["single_frame"]["off_map_rate_after_10"].as_f64(),
        Some(0.0)
    );

    let csv = std::fs::read_to_string(&predictions).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), places as usize);
    for (i, row) in rows.iter().enumerate() {
        let fields: Vec<&str> = row.split(',').collect();
        assert_eq!(fields[0], i.to_string());
        let predicted: i64 = fields[1].parse().unwrap();
        assert!((0..places as i64).contains(&predicted), "{row}");
        let confidence: f64 = fields[2].parse().unwrap();
        assert!((0.0..=1.0).contains(&confidence), "{row}");
        for candidate in &fields[3..] {
            let (index, score) = candidate.split_once(':').expect("index:score");
            assert!(index.parse::<usize>().unwrap() < places as usize);
            assert!(
                score.parse::<f64>().unwrap() <= confidence + 1e-6,
                "ranked: {row}"
            );
        }
    }
    let png = std::fs::read(&plot).unwrap();
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");

    // Single-frame only, and graph metrics from ground-truth nodes (place i = frame i).
    let gt = dir.path().join("gt.csv");
    let rows: String = (0..places).map(|i| format!("{i},{i}\n")).collect();
    std::fs::write(&gt, format!("query_index,place\n{rows}")).unwrap();
    let single = json(&topoloc(&[
        "eval",
        "--map",
        &s(&map),
        "--images",
        &s(&query_dir),
        "--single-frame",
        "--gt-nodes",
        &s(&gt),
        "--json",
    ]));
    assert_eq!(single["mode"], "single_frame");
    assert!(single.get("filter").is_none());
    assert_eq!(single["mna"], single["single_frame"]["mna"]);
    assert!(single["oha"].as_f64().unwrap() >= single["mna"].as_f64().unwrap());

    // Verification with an off-map threshold: the queries are the map's places, never off it.
    let eval = |extra: &[&str]| {
        let (map, queries) = (s(&map), s(&query_dir));
        let mut a = vec!["eval", "--map", &map, "--images", &queries, "--json"];
        a.extend_from_slice(extra);
        topoloc(&a)
    };
    let verified = json(&eval(&["--verify", "3", "--off-map-inliers", "20"]));
    assert_eq!(
        verified["filter"]["off_map_rate"].as_f64(),
        Some(0.0),
        "{verified}"
    );
    fails_with(&eval(&["--off-map-inliers", "20"]), &["--verify"]);
}

#[test]
fn failures_name_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let (missing, out) = (
        s(&dir.path().join("no-such-folder")),
        s(&dir.path().join("m.topoloc")),
    );
    let not_a_map = dir.path().join("not-a-map.topoloc");
    std::fs::write(&not_a_map, b"hello").unwrap();
    let (not_a_map, images) = (s(&not_a_map), s(dir.path()));
    let build = [
        "build-map",
        "--images",
        &missing,
        "--backend",
        "vlad",
        "--out",
        &out,
    ];
    let eval = ["eval", "--map", &not_a_map, "--images", &images];
    fails_with(&topoloc(&build), &["no-such-folder"]);
    fails_with(&topoloc(&eval), &["not-a-map.topoloc"]);
}

#[test]
fn demo_runs_the_whole_pipeline_and_reports_the_contract_keys() {
    // A small world and two legs keep this fast; the default demo is measured in BENCHMARKS.md.
    let dir = tempfile::tempdir().unwrap();
    let plot = dir.path().join("demo.png");
    let out = topoloc(&[
        "demo",
        "--json",
        "--backend",
        "vlad",
        "--rooms",
        "2",
        "--legs",
        "2",
        "--plot",
        plot.to_str().unwrap(),
    ]);
    let report = json(&out);
    for key in [
        "mna",
        "oha",
        "r_at_1",
        "r_at_5",
        "ms_per_frame_median",
        "peak_rss_mb",
    ] {
        assert!(report[key].is_number(), "{key} missing: {report}");
    }
    let names = [
        "single-frame",
        "filter",
        "filter+odometry",
        "metric+odometry",
        "filter+odometry+verification",
    ];
    for config in names {
        let c = &report["configurations"][config];
        for key in ["mna", "oha", "r_at_1", "r_at_5"] {
            let v = c[key].as_f64().unwrap_or(-1.0);
            assert!((0.0..=1.0).contains(&v), "{config}.{key} = {v}");
        }
        // MNA counts the exact place, OHA also its neighbours: never fewer.
        assert!(c["oha"].as_f64() >= c["mna"].as_f64(), "{config}: {c}");
    }
    // The top view draws the best configuration: the highest MNA, ties broken by OHA, then by
    // the table's order; the top-level figures are its own.
    let configurations = &report["configurations"];
    let plotted = report["plotted_configuration"].as_str().unwrap_or_default();
    let at = names
        .iter()
        .position(|n| *n == plotted)
        .unwrap_or_else(|| panic!("plotted_configuration {plotted:?}: {report}"));
    let figures = |name: &str| {
        let c = &configurations[name];
        (c["mna"].as_f64().unwrap(), c["oha"].as_f64().unwrap())
    };
    let (mna, oha) = figures(plotted);
    for (i, name) in names.iter().enumerate() {
        let (m, o) = figures(name);
        let beaten = m > mna || (m == mna && (o > oha || (o == oha && i < at)));
        assert!(
            !beaten,
            "{name} ({m}, {o}) beats the plotted {plotted}: {report}"
        );
    }
    assert_eq!(report["mna"].as_f64(), Some(mna), "{report}");
    assert_eq!(report["oha"].as_f64(), Some(oha), "{report}");
    // The filter+odometry configurations are also tested on frames from another world.
    for (config, tested) in [
        ("filter+odometry", true),
        ("filter+odometry+verification", true),
        ("filter", false),
    ] {
        let flagged = configurations[config]["off_world_flagged_after_10"].as_f64();
        assert_eq!(flagged.is_some(), tested, "{config}: {report}");
        assert!(flagged.is_none_or(|f| (0.0..=1.0).contains(&f)));
    }
    assert_eq!(report["off_world"]["style"], "lab", "{report}");
    // The VLAD backend has no XFeat: ORB keypoints, which leave off-map flags to appearance.
    assert_eq!(report["local_features"], "orb", "{report}");
    assert!(report["places"].as_u64().unwrap() >= 4, "{report}");
    // 12 views per place by default (30 degrees apart).
    assert_eq!(report["views_per_place"].as_u64(), Some(12));
    assert_eq!(
        report["views"].as_u64(),
        report["places"].as_u64().map(|p| 12 * p)
    );
    assert!(report["frames"].as_u64().unwrap() >= 20, "{report}");
    assert!(
        report["backend"].as_str().unwrap().starts_with("vlad"),
        "{report}"
    );
    let png = std::fs::read(&plot).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    // Bad input names the option.
    fails_with(
        &topoloc(&["demo", "--condition", "foggy"]),
        &["--condition foggy"],
    );
}

#[test]
fn simulate_writes_a_dataset_that_eval_reads() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    let summary = simulate_tiny(&out, 4, &[]);
    let places = summary["places"].as_u64().unwrap();
    assert!(places >= 4, "{summary}");
    assert_eq!(summary["views"].as_u64(), Some(4 * places));
    assert_eq!(summary["split"], "train");
    assert_eq!(summary["condition"], "dim");
    let frames = summary["trajectories"][0]["frames"].as_u64().unwrap() as usize;
    assert!(frames >= 10, "{summary}");

    // The folder layout of the dataset format.
    let map = out.join("map.topoloc");
    let traj = out.join("traj-000");
    assert!(map.is_file());
    for file in [
        "manifest.json",
        "intrinsics.json",
        "graph.json",
        "groundtruth.txt",
        "odometry.txt",
        "nodes.csv",
    ] {
        assert!(traj.join(file).is_file(), "{file} missing");
    }
    let pngs = std::fs::read_dir(traj.join("images")).unwrap().count();
    assert_eq!(pngs, frames);
    assert!(traj.join("images/000000.png").is_file());
    let nodes = std::fs::read_to_string(traj.join("nodes.csv")).unwrap();
    assert_eq!(nodes.lines().next(), Some("frame,place,view,visible"));
    assert_eq!(nodes.lines().count(), frames + 1);
    let poses = std::fs::read_to_string(traj.join("groundtruth.txt")).unwrap();
    let poses = poses.lines().filter(|l| !l.starts_with('#')).count();
    assert_eq!(poses, frames);
    let manifest = read_json(&traj.join("manifest.json"));
    assert_eq!(manifest["frame_count"].as_u64(), Some(frames as u64));
    assert_eq!(manifest["style"], "office");

    // eval reads it: the seed's graph metrics, single-frame, filter, filter with odometry.
    let predictions = dir.path().join("predictions.csv");
    let report = json(&eval_dataset(
        &map,
        &traj,
        &["--odometry", "--predictions", &s(&predictions)],
    ));
    for key in [
        "mna",
        "oha",
        "r_at_1",
        "r_at_5",
        "r_at_10",
        "frames",
        "ms_per_frame_median",
    ] {
        assert!(report[key].is_number(), "{key} missing: {report}");
    }
    assert_eq!(report["frames"].as_u64(), Some(frames as u64));
    assert_eq!(report["mode"], "filter");
    assert_eq!(report["mna"], report["filter"]["mna"]);
    for config in ["single_frame", "filter", "filter_odometry"] {
        let c = &report[config];
        let v = |key: &str| c[key].as_f64().unwrap_or(-1.0);
        for n in 1..=10 {
            let key = format!("r_at_{n}");
            assert!((0.0..=1.0).contains(&v(&key)), "{config}.{key}: {c}");
        }
        for key in ["mna", "oha"] {
            assert!((0.0..=1.0).contains(&v(key)), "{config}.{key}: {c}");
        }
        // MNA counts the exact place, OHA also its neighbours; deeper lists never recall less.
        assert!(v("oha") >= v("mna"), "{config}: {c}");
        assert!(
            v("r_at_10") >= v("r_at_5") && v("r_at_5") >= v("r_at_1"),
            "{config}: {c}"
        );
    }
    let csv = std::fs::read_to_string(&predictions).unwrap();
    assert!(csv.starts_with("frame,predicted_place,confidence"), "{csv}");
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), frames);
    for (i, row) in rows.iter().enumerate() {
        let fields: Vec<&str> = row.split(',').collect();
        assert_eq!(fields[0], i.to_string());
        assert!(fields[1].parse::<u64>().unwrap() < places, "{row}");
        for candidate in &fields[3..] {
            let (place, _) = candidate.split_once(':').expect("place:probability");
            assert!(place.parse::<u64>().unwrap() < places, "{row}");
        }
    }

    // Failures name what is wrong. A non-empty output folder:
    let failed = topoloc(&["simulate", "--backend", "vlad", "--out", &s(&out)]);
    fails_with(&failed, &["not empty"]);
    // A map of another world (here: of eight images) has another graph:
    let images = dir.path().join("images");
    std::fs::create_dir_all(&images).unwrap();
    for i in 0..8 {
        write_pgm(&images.join(format!("{i:03}.pgm")), &place(i));
    }
    let other = dir.path().join("other.topoloc");
    build_vlad_map(&images, &other);
    let eval = |map: &Path, dataset: &Path, needles: &[&str]| {
        fails_with(&eval_dataset(map, dataset, &[]), needles);
    };
    let other_graph = format!("8 places, the dataset's graph {places}");
    eval(&other, &traj, &["graph.json", &other_graph]);
    // The same place count, but a place moved:
    let graph_path = traj.join("graph.json");
    let mut graph = read_json(&graph_path);
    let x = graph["places"][0]["position"][0].as_f64().unwrap();
    graph["places"][0]["position"][0] = serde_json::json!(x + 1.0);
    std::fs::write(&graph_path, graph.to_string()).unwrap();
    eval(&map, &traj, &["place 0 is at"]);
    // A file of the dataset missing, and no dataset at all:
    std::fs::remove_file(traj.join("nodes.csv")).unwrap();
    eval(&map, &traj, &["nodes.csv"]);
    eval(
        &map,
        &dir.path().join("no-such-dataset"),
        &["no-such-dataset"],
    );
}

#[test]
fn scaling_reports_every_size_and_writes_the_plot() {
    let dir = tempfile::tempdir().unwrap();
    let plot = dir.path().join("s.png");
    let report = json(&topoloc(&[
        "scaling",
        "--sizes",
        "20,100",
        "--frames",
        "30",
        "--json",
        "--plot",
        plot.to_str().unwrap(),
    ]));
    let sizes = report["sizes"].as_array().expect("sizes array");
    let places: Vec<u64> = sizes
        .iter()
        .map(|s| s["places"].as_u64().unwrap())
        .collect();
    assert_eq!(places, [20, 100], "{report}");
    for size in sizes {
        assert_eq!(
            size["views"].as_u64(),
            size["places"].as_u64().map(|p| 4 * p)
        );
        assert!(size["descriptor_bytes"].as_u64().unwrap() > 0, "{size}");
        for config in ["single_frame", "filter", "filter_odometry"] {
            let median = size[config]["ms_median"].as_f64().unwrap_or(-1.0);
            let p90 = size[config]["ms_p90"].as_f64().unwrap_or(-1.0);
            assert!(median > 0.0, "{config}: {size}");
            assert!(p90 >= median, "{config}: {size}");
        }
    }
    let png = std::fs::read(&plot).unwrap();
    assert!(!png.is_empty());
    assert_eq!(&png[1..4], b"PNG");
}

#[test]
fn suite_reports_mean_and_std_per_split_and_configuration() {
    // Two splits, two tiny worlds each: enough to check the table's structure and statistics.
    let out = topoloc(&[
        "suite",
        "--json",
        "--backend",
        "vlad",
        "--splits",
        "tr-a,test",
        "--worlds",
        "2",
        "--rooms",
        "2",
        "--legs",
        "1",
        "--views-per-place",
        "4",
    ]);
    let report = json(&out);
    assert_eq!(report["views_per_place"].as_u64(), Some(4));
    assert_eq!(report["verify"].as_u64(), Some(5));
    for split in ["tr-a", "test"] {
        let s = &report["splits"][split];
        assert_eq!(s["worlds"].as_array().map(Vec::len), Some(2), "{report}");
        for world in s["worlds"].as_array().unwrap() {
            assert_eq!(
                world["views"].as_u64(),
                world["places"].as_u64().map(|p| 4 * p)
            );
        }
        for config in [
            "single-frame",
            "filter",
            "filter+odometry",
            "filter+odometry+verification",
            "metric+odometry",
            "metric+odometry+verification",
            "metric+odometry+pose-fix",
        ] {
            let c = &s["configurations"][config];
            for metric in ["mna", "oha"] {
                let values: Vec<f64> = c[metric]
                    .as_array()
                    .unwrap()
                    .iter()
                    .map(|v| v.as_f64().unwrap())
                    .collect();
                assert_eq!(values.len(), 2);
                assert!(values.iter().all(|v| (0.0..=1.0).contains(v)), "{c}");
                let mean = (values[0] + values[1]) / 2.0;
                let std = (values[0] - values[1]).abs() / 2.0;
                let got_mean = c[format!("{metric}_mean")].as_f64().unwrap();
                let got_std = c[format!("{metric}_std")].as_f64().unwrap();
                assert!((got_mean - mean).abs() < 1e-12, "{config}.{metric}: {c}");
                assert!((got_std - std).abs() < 1e-12, "{config}.{metric}: {c}");
            }
        }
    }
    fails_with(&topoloc(&["suite", "--splits", "tr-x"]), &["tr-x"]);
}

#[test]
fn suite_refuses_unknown_or_empty_configuration_lists() {
    let out = topoloc(&["suite", "--configurations", "filter,bogus"]);
    fails_with(&out, &["unknown configuration 'bogus'", "metric+odometry"]);
    let out = topoloc(&[
        "suite",
        "--verify",
        "0",
        "--configurations",
        "metric+odometry+verification",
    ]);
    fails_with(&out, &["no configuration to run"]);
}

/// With depth images (`simulate --depth`, `loops --depth`), keyframes carry 3D points and hints
/// metric relative poses: here every keyframe may match its predecessor, whose true relative
/// pose the ground truth gives.
#[test]
fn loops_with_depth_images_give_metric_hints() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    let summary = simulate_tiny(&out, 4, &["--depth"]);
    let traj = out.join("traj-000");
    let frames = summary["trajectories"][0]["frames"].as_u64().unwrap() as usize;
    assert_eq!(
        std::fs::read_dir(traj.join("depth")).unwrap().count(),
        frames
    );
    let manifest = read_json(&traj.join("manifest.json"));
    assert_eq!(manifest["depth_scale"], 1000.0);
    let intrinsics = dir.path().join("k.txt");
    // In OpenCV's pixel convention (the centre of the top-left pixel at (0, 0)).
    write_intrinsics(&traj, &intrinsics, 0.5);
    let run = |depth: Option<&Path>| {
        let mut args = vec![
            "--images".to_string(),
            s(&traj.join("images")),
            "--poses".into(),
            s(&traj.join("odometry.txt")),
            "--truth".into(),
            s(&traj.join("groundtruth.txt")),
            "--camera-frame".into(),
            "x-forward".into(),
            "--intrinsics".into(),
            s(&intrinsics),
            "--backend".into(),
            "vlad".into(),
            "--local-features".into(),
            "orb".into(),
            "--exclude-ids".into(),
            "1".into(),
            "--exclude-seconds".into(),
            "0".into(),
            "--candidate-id-gap".into(),
            "0".into(),
            "--consistent-keyframes".into(),
            "1".into(),
        ];
        if let Some(depth) = depth {
            args.extend(["--depth".to_string(), s(depth)]);
            args.extend(["--pr-curve".to_string(), s(&dir.path().join("pr.png"))]);
        }
        let refs: Vec<&str> = args.iter().map(String::as_str).collect();
        loops_report(dir.path(), &refs)
    };
    let (metric, rows) = run(Some(&traj.join("depth")));
    let truth = &metric["truth"];
    for key in [
        "no_revisit_km",
        "no_revisit_hints",
        "hints_per_km_without_revisit",
    ] {
        assert!(truth.get(key).is_some(), "missing '{key}' in {metric}");
    }
    // The PR curve over the hints' confidence: falling thresholds, the PNG drawn.
    let curve = truth["precision_recall"].as_array().unwrap();
    assert!(!curve.is_empty(), "{metric}");
    let thresholds: Vec<f64> = curve
        .iter()
        .map(|p| p["confidence"].as_f64().unwrap())
        .collect();
    assert!(thresholds.windows(2).all(|w| w[1] < w[0]), "{thresholds:?}");
    let last = curve.last().unwrap();
    assert_eq!(last["recall"], truth["recall"], "{metric}");
    assert_eq!(last["precision"], truth["precision"], "{metric}");
    let r100 = truth["recall_at_full_precision"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&r100), "{metric}");
    let png = std::fs::read(dir.path().join("pr.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG"), "a PNG");
    assert!(
        rows.len() > frames / 2,
        "most keyframes match a neighbour: {metric}"
    );
    for row in &rows[1..] {
        assert_eq!(row[4], "1", "metric hints: {row:?}");
    }
    assert!(
        truth["translation_error_m_median"].as_f64().unwrap() < 0.1
            && truth["rotation_error_deg_median"].as_f64().unwrap() < 1.0,
        "{metric}"
    );
    let (unscaled, rows) = run(None);
    assert!(rows.len() > 1, "{unscaled}");
    assert!(rows[1..].iter().all(|row| row[4] == "0"), "{rows:?}");
    assert!(
        unscaled["truth"]["translation_error_m_median"].is_null(),
        "{unscaled}"
    );

    // A missing depth image, or depth without intrinsics, is a clear failure.
    std::fs::remove_file(traj.join("depth/000003.png")).unwrap();
    let images = s(&traj.join("images"));
    let depth = s(&traj.join("depth"));
    let csv = s(&dir.path().join("x.csv"));
    let (k_arg, vlad) = (s(&intrinsics), "vlad");
    let failed = topoloc(&[
        "loops",
        "--images",
        &images,
        "--intrinsics",
        &k_arg,
        "--depth",
        &depth,
        "--backend",
        vlad,
        "--local-features",
        "orb",
        "--out",
        &csv,
    ]);
    fails_with(&failed, &["000003.png"]);
    let failed = topoloc(&[
        "loops", "--images", &images, "--depth", &depth, "--out", &csv,
    ]);
    fails_with(&failed, &["--intrinsics"]);
}

/// The hints file and report of `topoloc loops`: `dir/map` holds 12 places, `dir/query` the
/// same places again (shifted, brighter).
fn loops_report(dir: &Path, args: &[&str]) -> (serde_json::Value, Vec<Vec<String>>) {
    let out = dir.join(format!("hints-{}.csv", args.len()));
    let mut all = vec![
        "loops".to_string(),
        "--out".into(),
        s(&out),
        "--json".into(),
    ];
    all.extend(args.iter().map(|a| a.to_string()));
    let refs: Vec<&str> = all.iter().map(String::as_str).collect();
    let report = json(&topoloc(&refs));
    let rows = std::fs::read_to_string(&out)
        .unwrap()
        .lines()
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect();
    (report, rows)
}

#[test]
fn loops_follows_the_contract_online_and_against_a_map() {
    let dir = tempfile::tempdir().unwrap();
    let (map_dir, query_dir, both) = two_sessions(dir.path());
    let places = 12;
    let map = dir.path().join("places.topoloc");
    build_vlad_map(&map_dir, &map);
    // A second session against the map: hints name the map's keyframe ids.
    let decisions = dir.path().join("decisions.csv");
    let (report, rows) = loops_report(
        dir.path(),
        &[
            "--images",
            &s(&query_dir),
            "--map",
            &s(&map),
            "--aligned-tolerance",
            "0",
            "--decisions",
            &s(&decisions),
        ],
    );
    // One decision per keyframe, with the gate that decided; the accepted ones are the hints.
    let decided = std::fs::read_to_string(&decisions).unwrap();
    let decided: Vec<Vec<&str>> = decided.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(
        decided[0].join(","),
        "query_index,gate,matched_index,inliers,confidence,detail"
    );
    assert_eq!(decided.len(), 1 + places as usize);
    let gates = report["gates"].as_object().unwrap();
    for (gate, count) in gates {
        let rows = decided[1..].iter().filter(|r| r[1] == gate).count();
        assert_eq!(
            Some(rows as u64),
            count.as_u64(),
            "gate {gate}: {decided:?}"
        );
    }
    for key in [
        "hints",
        "gates",
        "keyframe_ms_median",
        "keyframe_ms_p90",
        "precision",
        "recall",
        "accepted",
    ] {
        assert!(report.get(key).is_some(), "missing '{key}' in {report}");
    }
    assert_eq!(rows[0].join(","), HINTS_HEADER);
    assert!(rows.len() > 1 + places as usize / 2, "{report}");
    for row in &rows[1..] {
        assert_eq!(row.len(), 14, "{row:?}");
        assert_eq!(row[0], row[1], "query i matches map keyframe i: {row:?}");
        assert!(
            row[4..12].iter().all(String::is_empty),
            "no intrinsics, no pose: {row:?}"
        );
        assert_eq!(row[12], row[0], "every frame a keyframe: {row:?}");
        assert_eq!(row[13], "", "a match in the map has no frame: {row:?}");
    }
    assert_eq!(report["precision"], 1.0, "{report}");
    // The same queries as a KITTI sequence (image_0/ and times.txt at 10 Hz), every second
    // frame a keyframe: timestamps from the layout, hints name the map's keyframe ids.
    let kitti = dir.path().join("kitti");
    std::fs::create_dir_all(kitti.join("image_0")).unwrap();
    let mut times = String::new();
    for i in 0..places {
        let name = format!("{i:03}.pgm");
        std::fs::copy(query_dir.join(&name), kitti.join("image_0").join(name)).unwrap();
        times.push_str(&format!("{:e}\n", i as f64 * 0.1));
    }
    std::fs::write(kitti.join("times.txt"), times).unwrap();
    let (report, rows) = loops_report(
        dir.path(),
        &["--images", &s(&kitti), "--map", &s(&map), "--every", "2"],
    );
    assert_eq!(report["sequence"]["layout"], "Kitti", "{report}");
    assert_eq!(report["sequence"]["keyframes"], places / 2, "{report}");
    for row in &rows[1..] {
        let (q, m): (u32, u32) = (row[0].parse().unwrap(), row[1].parse().unwrap());
        assert_eq!(2 * q, m, "keyframe {q} is query image {}: {row:?}", 2 * q);
    }
    // `localize` reads the layout too: every frame, timed by times.txt.
    let out = topoloc(&[
        "localize",
        "--map",
        &s(&map),
        "--images",
        &s(&kitti),
        "--json-lines",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let frames: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(frames.len(), places as usize);
    assert!(
        (frames[3]["timestamp"].as_f64().unwrap() - 0.3).abs() < 1e-9,
        "{:?}",
        frames[3]
    );
    let times: Vec<String> = (0..places)
        .map(|i| match i {
            1 => "later".to_string(),
            _ => format!("{i}"),
        })
        .collect();
    std::fs::write(kitti.join("times.txt"), times.join("\n")).unwrap();
    let csv_path = s(&dir.path().join("k.csv"));
    let args = [
        "loops",
        "--images",
        &s(&kitti),
        "--map",
        &s(&map),
        "--out",
        &csv_path,
    ];
    fails_with(&topoloc(&args), &["times.txt line 2", "later"]);
    // Online, no map: the second half of the folder revisits the first.
    let (report, rows) = loops_report(
        dir.path(),
        &[
            "--images",
            &s(&both),
            "--backend",
            "vlad",
            "--local-features",
            "orb",
            "--exclude-ids",
            "6",
            "--exclude-seconds",
            "6",
        ],
    );
    assert_eq!(report["keyframes"], 2 * places);
    assert!(rows.len() > 1, "the revisits close loops: {report}");
    for row in &rows[1..] {
        let (q, m): (u64, u64) = (row[0].parse().unwrap(), row[1].parse().unwrap());
        assert_eq!(
            q,
            m + places,
            "revisit {q} matches first visit {m}: {row:?}"
        );
    }
    // A bad intrinsics file, or a fit without iterations, is a clear failure naming it.
    let bad = dir.path().join("k.txt");
    std::fs::write(&bad, "300 -1 160 120").unwrap();
    let (images, map, csv) = (s(&query_dir), s(&map), s(&dir.path().join("x.csv")));
    let refused = |extra: &[&str], needle: &str| {
        let mut args = vec!["loops", "--images", &images, "--map", &map, "--out", &csv];
        args.extend_from_slice(extra);
        fails_with(&topoloc(&args), &[needle]);
    };
    refused(&["--intrinsics", &s(&bad)], "fy");
    refused(
        &["--pair-estimator", "ransac", "--pair-iterations", "0"],
        "max_iterations",
    );
}

/// `topoloc ate` on a simulated run: the drifting odometry against its ground truth, every
/// alignment, the contract keys, and a clear failure on a file that is no trajectory.
#[test]
fn ate_judges_the_simulated_odometry_against_its_ground_truth() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sim");
    simulate_tiny(&out, 4, &[]);
    let traj = out.join("traj-000");
    let (odometry, truth) = (traj.join("odometry.txt"), traj.join("groundtruth.txt"));
    let (odometry, truth) = (odometry.to_str().unwrap(), truth.to_str().unwrap());
    let frames = tum_rows(Path::new(truth)).len();
    let ate = |align: &str| {
        let report = json(&topoloc(&[
            "ate", odometry, truth, "--align", align, "--json",
        ]));
        for key in ["ate_m", "are_deg", "rpe_m", "rpe_deg"] {
            for stat in ["rmse", "mean", "median", "std", "min", "max"] {
                assert!(report[key][stat].is_f64(), "{key}.{stat}: {report}");
            }
        }
        assert_eq!(report["pairs"], frames, "{report}");
        assert!(report["r_traj"].as_f64().unwrap() > 0.5, "{report}");
        report["ate_m"]["rmse"].as_f64().unwrap()
    };
    let (none, se3, sim3) = (ate("none"), ate("se3"), ate("sim3"));
    assert!(none > 0.0, "the odometry drifts");
    assert!(
        sim3 <= se3 + 1e-12 && se3 <= none + 1e-12,
        "{none} {se3} {sim3}"
    );
    let itself = json(&topoloc(&["ate", truth, truth, "--json"]));
    assert!(itself["ate_m"]["rmse"].as_f64().unwrap() < 1e-9, "{itself}");
    // Not a trajectory: the error names the file and says what to pass.
    let bad = dir.path().join("notes.txt");
    std::fs::write(&bad, "just some words\n").unwrap();
    let failed = topoloc(&["ate", bad.to_str().unwrap(), truth]);
    fails_with(&failed, &["notes.txt", "--format"]);
}

#[test]
fn bench_memory_measures_every_stage_of_an_image_map() {
    let dir = tempfile::tempdir().unwrap();
    let (map_dir, query_dir) = (dir.path().join("map"), dir.path().join("query"));
    write_places(&map_dir, &query_dir, 8);
    // The PCA rows: i8 by default, f32 on request (larger file, another identity).
    let map = dir.path().join("i8.topoloc");
    let built = build_vlad_map(&map_dir, &map);
    assert!(built["descriptor"].as_str().unwrap().contains("/i8 fit="));
    let exact = dir.path().join("f32.topoloc");
    let built_f32 = json(&topoloc(&[
        "build-map",
        "--images",
        &s(&map_dir),
        "--backend",
        "vlad",
        "--pca-precision",
        "f32",
        "--out",
        &s(&exact),
        "--json",
    ]));
    assert!(!built_f32["descriptor"].as_str().unwrap().contains("/i8"));
    let size = |p: &Path| std::fs::metadata(p).unwrap().len();
    assert!(
        size(&map) < size(&exact),
        "{} vs {}",
        size(&map),
        size(&exact)
    );

    let (map_arg, queries) = (s(&map), s(&query_dir));
    let bench = |extra: &[&str]| {
        let args = ["bench-memory", "--map", &map_arg, "--images", &queries];
        topoloc(&[&args[..], extra].concat())
    };
    let report = json(&bench(&["--frames", "5", "--json"]));
    assert_eq!(report["frames"], 5);
    assert_eq!(report["places"], 8);
    assert_eq!(report["generated"], false);
    assert_eq!(report["file_bytes"], size(&map));
    assert!(report["describer"]
        .as_str()
        .unwrap()
        .starts_with("vlad-orb"));
    for key in [
        "rss_start_mib",
        "rss_map_mib",
        "rss_localizer_mib",
        "rss_frames_mib",
        "peak_rss_mib",
        "load_ms_median",
        "frame_ms_median",
    ] {
        let v = report[key].as_f64().unwrap_or(-1.0);
        assert!(v > 0.0, "'{key}' = {v} in {report}");
    }
    assert!(report["peak_rss_mib"].as_f64() >= report["rss_frames_mib"].as_f64());
    // A map needs its query images, and a folder of non-images is refused by name.
    let alone = topoloc(&["bench-memory", "--map", &s(&map)]);
    assert!(!alone.status.success());
    std::fs::write(query_dir.join("notes.txt"), "not an image").unwrap();
    fails_with(&bench(&["--frames", "50"]), &["notes.txt"]);
}
