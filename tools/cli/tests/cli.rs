//! The CLI contract of `topoloc build-map` and `topoloc eval`, which other tools call: JSON keys,
//! the predictions CSV, the PNG, and clear failures. Uses the VLAD backend on generated PGM
//! images, so it needs no model and no shared data.

use std::path::Path;
use std::process::Command;

const W: usize = 320;
const H: usize = 240;

/// A textured grey "place" (rectangles of pseudo-random shades over a gradient).
fn place(seed: u64) -> Vec<u8> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15).wrapping_add(11);
    let mut next = move |m: usize| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 33) as usize % m
    };
    let mut data: Vec<u8> = (0..W * H).map(|i| ((i % W) * 120 / W + 30) as u8).collect();
    for _ in 0..150 {
        let (x0, y0, w, h) = (next(W), next(H), 6 + next(50), 6 + next(50));
        let shade = next(256) as u8;
        for y in y0..(y0 + h).min(H) {
            for x in x0..(x0 + w).min(W) {
                data[y * W + x] = shade;
            }
        }
    }
    data
}

fn write_pgm(path: &Path, pixels: &[u8]) {
    let mut bytes = format!("P5\n{W} {H}\n255\n").into_bytes();
    bytes.extend_from_slice(pixels);
    std::fs::write(path, bytes).unwrap();
}

fn topoloc(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_topoloc"))
        .args(args)
        .output()
        .expect("topoloc runs")
}

fn json(output: &std::process::Output) -> serde_json::Value {
    assert!(
        output.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).expect("one JSON object on stdout")
}

#[test]
fn build_map_and_eval_follow_the_contract() {
    let dir = tempfile::tempdir().unwrap();
    let (map_dir, query_dir) = (dir.path().join("map"), dir.path().join("query"));
    std::fs::create_dir_all(&map_dir).unwrap();
    std::fs::create_dir_all(&query_dir).unwrap();
    let places = 12;
    for i in 0..places {
        let image = place(i);
        write_pgm(&map_dir.join(format!("{i:03}.pgm")), &image);
        // The query: the same place, brighter and shifted by 4 pixels.
        let query: Vec<u8> = (0..W * H)
            .map(|k| {
                let (x, y) = (k % W, k / W);
                (u16::from(image[y * W + (x + 4).min(W - 1)]) * 9 / 10 + 20) as u8
            })
            .collect();
        write_pgm(&query_dir.join(format!("{i:03}.pgm")), &query);
    }
    let map = dir.path().join("places.topoloc");
    let s = |p: &Path| p.to_str().unwrap().to_string();

    let built = json(&topoloc(&[
        "build-map",
        "--images",
        &s(&map_dir),
        "--backend",
        "vlad",
        "--out",
        &s(&map),
        "--json",
    ]));
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
}

#[test]
fn failures_name_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("no-such-folder");
    let out = topoloc(&[
        "build-map",
        "--images",
        missing.to_str().unwrap(),
        "--backend",
        "vlad",
        "--out",
        dir.path().join("m.topoloc").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("no-such-folder"), "{stderr}");

    let not_a_map = dir.path().join("not-a-map.topoloc");
    std::fs::write(&not_a_map, b"hello").unwrap();
    let out = topoloc(&[
        "eval",
        "--map",
        not_a_map.to_str().unwrap(),
        "--images",
        dir.path().to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("not-a-map.topoloc"), "{stderr}");
}
