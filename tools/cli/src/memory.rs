//! `topoloc bench-memory`: map file size, load time and resident memory of a loaded map, its
//! localizer (with the map's describer: ONNX Runtime and the model, for maps built from images)
//! and frames, measured stage by stage in a fresh child process, `topoloc-measure`
//! (src/bin/measure.rs): a lean binary that links what a host linking the library links (not
//! the CLI's video decoding, plots or simulator), so that its bare process is a host's.

use crate::backend_args::RuntimeArgs;
use anyhow::{bail, Context, Result};
use clap::Args;
use std::path::PathBuf;

/// Options of `bench-memory`.
#[derive(Args, Clone, Debug)]
pub struct BenchMemoryArgs {
    /// Views in the generated map (4 per place); not used with --map.
    #[arg(long, default_value_t = 10_000)]
    pub views: usize,
    /// Descriptor dimension of the generated map; not used with --map.
    #[arg(long, default_value_t = 512)]
    pub dim: usize,
    /// Measure this map built from images instead of a generated one: its localizer describes
    /// the frames of --images with the map's stored describer (for ONNX maps: ONNX Runtime and
    /// the model are loaded and counted).
    #[arg(long, requires = "images")]
    pub map: Option<PathBuf>,
    /// Folder of query images for --map (file-name order).
    #[arg(long, requires = "map")]
    pub images: Option<PathBuf>,
    /// Frames localized before the last reading (generated maps: view descriptors).
    #[arg(long, default_value_t = 50)]
    pub frames: usize,
    #[command(flatten)]
    pub runtime: RuntimeArgs,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Generates a map (or takes `--map`), then measures it in a child process.
pub fn run(args: &BenchMemoryArgs) -> Result<()> {
    let dir = tempfile::tempdir()?;
    let path = match &args.map {
        Some(map) => map.clone(),
        None => {
            let path = dir.path().join("bench.topoloc");
            topoloc_synthetic::random_map(args.views, 4, args.dim, 11).save(&path)?;
            path
        }
    };
    let file_bytes = std::fs::metadata(&path)
        .with_context(|| format!("--map {}", path.display()))?
        .len();
    let measure = std::env::current_exe()?.with_file_name("topoloc-measure");
    if !measure.is_file() {
        bail!(
            "{} is missing: it is built with the CLI (cargo build --release -p topoloc-cli)",
            measure.display()
        );
    }
    let mut child = std::process::Command::new(&measure);
    child
        .arg(&path)
        .arg("--frames")
        .arg(args.frames.to_string());
    if let Some(images) = &args.images {
        child.arg("--images").arg(images);
    }
    if let Some(model) = &args.runtime.onnx_model {
        child.arg("--onnx-model").arg(model);
    }
    if let Some(runtime) = &args.runtime.onnx_runtime {
        child.arg("--onnx-runtime").arg(runtime);
    }
    let output = child.output()?;
    if !output.status.success() {
        bail!(
            "topoloc-measure failed: {}",
            String::from_utf8_lossy(&output.stderr)
        );
    }
    let mut report: serde_json::Value =
        serde_json::from_slice(&output.stdout).context("topoloc-measure output")?;
    let file_mib = file_bytes as f64 / (1 << 20) as f64;
    let extra = serde_json::json!({
        "map": path,
        "generated": args.map.is_none(),
        "file_bytes": file_bytes,
        "file_mib": file_mib,
    });
    for (key, value) in extra.as_object().expect("an object") {
        report[key] = value.clone();
    }
    if args.json {
        println!("{report}");
    } else {
        print_report(&report);
    }
    Ok(())
}

fn print_report(r: &serde_json::Value) {
    let f = |key: &str| r[key].as_f64().unwrap_or(f64::NAN);
    println!(
        "map {} ({} places, {} views, D = {}{})",
        r["map"].as_str().unwrap_or("?"),
        r["places"],
        r["views"],
        r["dim"],
        r["describer"]
            .as_str()
            .map_or(String::new(), |d| format!(", {d}"))
    );
    println!(
        "  file size           {:.1} MiB ({} bytes)",
        f("file_mib"),
        r["file_bytes"]
    );
    println!("  load time (median)  {:.2} ms", f("load_ms_median"));
    println!("  resident memory, MiB (stage: total, added)");
    println!("    bare process      {:.1}", f("rss_start_mib"));
    println!(
        "    + map             {:.1}  +{:.1} ({:.2} x the file)",
        f("rss_map_mib"),
        f("map_mib"),
        f("map_mib") / f("file_mib")
    );
    println!(
        "    + localizer       {:.1}  +{:.1}{}",
        f("rss_localizer_mib"),
        f("localizer_mib"),
        if r["describer"].is_string() {
            " (describer: runtime and model)"
        } else {
            ""
        }
    );
    println!(
        "    + {} frames      {:.1}  +{:.1}",
        r["frames"],
        f("rss_frames_mib"),
        f("frames_mib")
    );
    println!("    peak              {:.1}", f("peak_rss_mib"));
    println!("  frame time (median) {:.2} ms", f("frame_ms_median"));
}
