//! `topoloc bench-memory`: map file size, load time and resident memory of a loaded map plus a
//! localizer, measured in a fresh child process so that the generator's allocations do not count.

use crate::process::{median_and_p90, resident_memory_mib};
use anyhow::{bail, Context, Result};
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;
use topoloc::map::LoadOptions;
use topoloc::{Frame, Localizer, LocalizerOptions, Map};

/// Generates a map of `views` views, saves it, and measures it in a child process.
pub fn run(views: usize, dim: usize, json: bool) -> Result<()> {
    let dir = tempfile::tempdir()?;
    let path = dir.path().join("bench.topoloc");
    topoloc_synthetic::random_map(views, 4, dim, 11).save(&path)?;
    let file_bytes = std::fs::metadata(&path)?.len();
    let exe = std::env::current_exe()?;
    let output = std::process::Command::new(exe)
        .arg("measure-map")
        .arg(&path)
        .output()?;
    if !output.status.success() {
        bail!(
            "measure-map failed: {}",
            String::from_utf8_lossy(&output.stderr)
        );
    }
    let child: serde_json::Value =
        serde_json::from_slice(&output.stdout).context("measure-map output")?;
    let report = serde_json::json!({
        "views": views,
        "dim": dim,
        "file_bytes": file_bytes,
        "file_mib": file_bytes as f64 / (1 << 20) as f64,
        "load_ms_median": child["load_ms_median"],
        "rss_before_mib": child["rss_before_mib"],
        "rss_after_mib": child["rss_after_mib"],
        "rss_delta_mib": child["rss_delta_mib"],
        "peak_rss_mib": child["peak_rss_mib"],
    });
    if json {
        println!("{report}");
    } else {
        println!("map of {views} views x D={dim}");
        println!(
            "  file size           {:.1} MiB ({file_bytes} bytes)",
            report["file_mib"].as_f64().unwrap_or(0.0)
        );
        println!(
            "  load time (median)  {:.2} ms",
            report["load_ms_median"].as_f64().unwrap_or(0.0)
        );
        println!(
            "  resident memory     {:.1} MiB before load, {:.1} MiB with map + localizer (+{:.1} MiB), peak {:.1} MiB",
            report["rss_before_mib"].as_f64().unwrap_or(0.0),
            report["rss_after_mib"].as_f64().unwrap_or(0.0),
            report["rss_delta_mib"].as_f64().unwrap_or(0.0),
            report["peak_rss_mib"].as_f64().unwrap_or(0.0)
        );
    }
    Ok(())
}

/// Child side: loads `path` 20 times (timing each), keeps one map with a localizer that has
/// processed frames, and prints the figures as JSON.
pub fn measure(path: &Path) -> Result<()> {
    let (rss_before, _) = resident_memory_mib().context("needs /proc/self/status")?;
    let mut load_ms = Vec::new();
    let mut map = None;
    for _ in 0..20 {
        drop(map.take()); // drop the previous map first, so that the peak counts one map
        let start = Instant::now();
        let loaded = Map::load(path, &LoadOptions::default())?;
        load_ms.push(start.elapsed().as_secs_f64() * 1e3);
        map = Some(loaded);
    }
    let map = Arc::new(map.expect("loaded at least once"));
    let mut localizer = Localizer::new(map.clone(), LocalizerOptions::default())?;
    for i in 0..10u32 {
        let view = (i * 97) % map.view_count() as u32;
        let descriptor = map.view_descriptor(view)?.to_vec();
        localizer.localize(&Frame {
            timestamp: f64::from(i),
            descriptor: &descriptor,
            odometry: None,
            image: None,
        })?;
    }
    let (rss_after, peak) = resident_memory_mib().context("needs /proc/self/status")?;
    let (median, _) = median_and_p90(&load_ms);
    println!(
        "{}",
        serde_json::json!({
            "load_ms_median": median,
            "rss_before_mib": rss_before,
            "rss_after_mib": rss_after,
            "rss_delta_mib": rss_after - rss_before,
            "peak_rss_mib": peak,
        })
    );
    Ok(())
}
