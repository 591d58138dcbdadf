//! Shared by the CLI integration tests: generated grey "places" (the library tests' generator),
//! PGM files of them, and running the `topoloc` binary.
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

/// Runs the `topoloc` binary with `args`, capturing its output.
pub fn topoloc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_topoloc"))
        .args(args)
        .output()
        .expect("topoloc runs")
}

/// The one JSON object on the stdout of a successful run.
/// Asserts that a run failed and that its stderr names `needle`.
#[track_caller]
pub fn fails_with(output: &Output, needle: &str) {
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(!output.status.success(), "succeeded: {stderr}");
    assert!(stderr.contains(needle), "'{needle}' not in: {stderr}");
}

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
