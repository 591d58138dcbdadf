//! Shared by the CLI integration tests: generated grey "places" (the library tests' generator),
//! PGM files of them, running the `topoloc` binary, and reading what it and `simulate` write.
#![allow(dead_code)] // each test crate uses its own part

use std::path::Path;
use std::process::{Command, Output};

#[path = "../../../../tests/common/images.rs"]
mod images;
pub use images::{H, W};

/// A textured grey W x H "place" (rectangles of pseudo-random shades over a gradient).
pub fn place(seed: u64) -> Vec<u8> {
    images::place_image(seed)
}

/// The same place seen again, deterministically: brighter and shifted by 4 pixels.
pub fn seen_again(image: &[u8]) -> Vec<u8> {
    (0..W * H)
        .map(|k| {
            let (x, y) = (k % W, k / W);
            (u16::from(image[y * W + (x + 4).min(W - 1)]) * 9 / 10 + 20) as u8
        })
        .collect()
}

/// Writes a binary PGM of `width` x `height` grey pixels.
pub fn write_pgm_sized(path: &Path, width: usize, height: usize, pixels: &[u8]) {
    let mut bytes = format!("P5\n{width} {height}\n255\n").into_bytes();
    bytes.extend_from_slice(pixels);
    std::fs::write(path, bytes).unwrap();
}

/// Writes a binary PGM of W x H grey pixels.
pub fn write_pgm(path: &Path, pixels: &[u8]) {
    write_pgm_sized(path, W, H, pixels);
}

/// Creates the folders `map_dir` and `query_dir` and writes `places` places into them,
/// `000.pgm`, `001.pgm`, ...: place `i` in `map_dir`, the same place seen again in `query_dir`.
pub fn write_places(map_dir: &Path, query_dir: &Path, places: u64) {
    std::fs::create_dir_all(map_dir).unwrap();
    std::fs::create_dir_all(query_dir).unwrap();
    for i in 0..places {
        let image = place(i);
        write_pgm(&map_dir.join(format!("{i:03}.pgm")), &image);
        write_pgm(&query_dir.join(format!("{i:03}.pgm")), &seen_again(&image));
    }
}

/// The header of `topoloc loops --out`.
pub const HINTS_HEADER: &str =
    "query_index,matched_index,inliers,confidence,scale_known,tx,ty,tz,qx,qy,qz,qw,\
     query_frame,matched_frame";

/// Two sessions under `dir`: `map/` and `query/` as [`write_places`] writes 12 places, and
/// `both/` with the map's images (`a000.pgm` ...) then the queries (`b000.pgm` ...), as one
/// run. Returns the three folders.
pub fn two_sessions(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf, std::path::PathBuf) {
    let (map_dir, query_dir, both) = (dir.join("map"), dir.join("query"), dir.join("both"));
    write_places(&map_dir, &query_dir, 12);
    std::fs::create_dir_all(&both).unwrap();
    for i in 0..12 {
        let name = format!("{i:03}.pgm");
        std::fs::copy(map_dir.join(&name), both.join(format!("a{name}"))).unwrap();
        std::fs::copy(query_dir.join(&name), both.join(format!("b{name}"))).unwrap();
    }
    (map_dir, query_dir, both)
}

/// A path as a command-line argument.
pub fn s(path: &Path) -> String {
    path.to_str().unwrap().to_string()
}

/// A JSON file, parsed.
pub fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Rows of a TUM file: (timestamp, [tx, ty, tz]).
pub fn tum_rows(path: &Path) -> Vec<(f64, [f64; 3])> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            (v[0], [v[1], v[2], v[3]])
        })
        .collect()
}

/// Writes the camera of the dataset folder `traj` (its `intrinsics.json`) to `path` as the
/// CLI's intrinsics file `fx fy cx cy`, the principal point moved by `-centre` pixels
/// (topoloc-sim puts the centre of the top-left pixel at (0.5, 0.5), OpenCV at (0, 0)).
pub fn write_intrinsics(traj: &Path, path: &Path, centre: f64) {
    let k = read_json(&traj.join("intrinsics.json"));
    let k = |key: &str| k[key].as_f64().unwrap();
    let text = format!(
        "{} {} {} {}",
        k("fx"),
        k("fy"),
        k("cx") - centre,
        k("cy") - centre
    );
    std::fs::write(path, text).unwrap();
}

/// Runs the `topoloc` binary with `args`, capturing its output.
pub fn topoloc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_topoloc"))
        .args(args)
        .output()
        .expect("topoloc runs")
}

/// Asserts that a run failed and that its stderr names each of `needles`.
#[track_caller]
pub fn fails_with(output: &Output, needles: &[&str]) {
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "succeeded: {stderr}");
    for needle in needles {
        assert!(stderr.contains(needle), "'{needle}' not in: {stderr}");
    }
}

/// The one JSON object on the stdout of a successful run.
pub fn json(output: &Output) -> serde_json::Value {
    assert!(
        output.status.success(),
        "stderr: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    serde_json::from_slice(&output.stdout).expect("one JSON object on stdout")
}

/// `topoloc simulate` of a tiny world (one storey, two rooms; two legs at 4 Hz keep it fast)
/// into `out`, with `views_per_place` and `extra` arguments; its JSON summary.
pub fn simulate_tiny(out: &Path, views_per_place: usize, extra: &[&str]) -> serde_json::Value {
    let views = views_per_place.to_string();
    let mut args = vec![
        "simulate",
        "--backend",
        "vlad",
        "--rooms",
        "2",
        "--floors",
        "1",
        "--legs",
        "2",
        "--rate-hz",
        "4",
        "--trajectories",
        "1",
        "--views-per-place",
        &views,
        "--out",
        out.to_str().unwrap(),
        "--json",
    ];
    args.extend_from_slice(extra);
    json(&topoloc(&args))
}

/// `topoloc eval --json` of the dataset folder `dataset` against `map`, with `extra` arguments.
pub fn eval_dataset(map: &Path, dataset: &Path, extra: &[&str]) -> Output {
    let (map, dataset) = (s(map), s(dataset));
    let args = ["eval", "--map", &map, "--dataset", &dataset, "--json"];
    topoloc(&[&args[..], extra].concat())
}

/// `topoloc build-map --backend vlad` of the images in `images` into `map`; its JSON summary.
pub fn build_vlad_map(images: &Path, map: &Path) -> serde_json::Value {
    json(&topoloc(&[
        "build-map",
        "--images",
        images.to_str().unwrap(),
        "--backend",
        "vlad",
        "--out",
        map.to_str().unwrap(),
        "--json",
    ]))
}
