//! Generates `include/topoloc.h` from `src/ffi` with the pinned cbindgen, adding the version
//! macros from the root Cargo.toml. With `--check`, fails (exit 1) when the checked-in header
//! differs from what would be generated, so CI catches a stale header.
//!
//! Usage: `cargo run -p topoloc-gen-header [-- --check]`

use std::path::{Path, PathBuf};
use std::process::ExitCode;

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("repository root exists")
}

/// Reads `version = "X.Y.Z"` from the `[package]` table of the root Cargo.toml.
fn package_version(root: &Path) -> Result<(String, String, String), String> {
    let text = std::fs::read_to_string(root.join("Cargo.toml"))
        .map_err(|e| format!("reading Cargo.toml: {e}"))?;
    let package = text
        .split("[package]")
        .nth(1)
        .ok_or("no [package] table in Cargo.toml")?;
    let line = package
        .lines()
        .take_while(|l| !l.trim_start().starts_with('['))
        .find(|l| l.trim_start().starts_with("version"))
        .ok_or("no version in [package]")?;
    let version = line.split('"').nth(1).ok_or("unquoted version")?;
    let parts: Vec<&str> = version.split('.').collect();
    match parts.as_slice() {
        [major, minor, patch] => Ok((major.to_string(), minor.to_string(), patch.to_string())),
        _ => Err(format!("version '{version}' is not MAJOR.MINOR.PATCH")),
    }
}

/// `T_default(p)` macros over the exported `T_init(p, size)` functions: they pass the size of
/// the caller's struct, so that a newer library never writes past an older caller's struct.
const DEFAULT_MACROS: &str = "
/* Fill a versioned struct with defaults (and its struct_size) before use. */
#define topoloc_map_load_options_default(p) topoloc_map_load_options_init((p), sizeof *(p))
#define topoloc_view_attributes_default(p) topoloc_view_attributes_init((p), sizeof *(p))
#define topoloc_keyframe_options_default(p) topoloc_keyframe_options_init((p), sizeof *(p))
#define topoloc_localizer_options_default(p) topoloc_localizer_options_init((p), sizeof *(p))
#define topoloc_frame_default(p) topoloc_frame_init((p), sizeof *(p))
#define topoloc_result_default(p) topoloc_result_init((p), sizeof *(p))
#define topoloc_view_info_default(p) topoloc_view_info_init((p), sizeof *(p))
#define topoloc_image_map_options_default(p) topoloc_image_map_options_init((p), sizeof *(p))
#define topoloc_skeleton_options_default(p) topoloc_skeleton_options_init((p), sizeof *(p))
";

fn generate(root: &Path) -> Result<Vec<u8>, String> {
    let (major, minor, patch) = package_version(root)?;
    let mut config =
        cbindgen::Config::from_file(root.join("cbindgen.toml")).map_err(|e| e.to_string())?;
    config.after_includes = Some(format!(
        "\n#define TOPOLOC_VERSION_MAJOR {major}\n#define TOPOLOC_VERSION_MINOR {minor}\n#define TOPOLOC_VERSION_PATCH {patch}\n#define TOPOLOC_VERSION_STRING \"{major}.{minor}.{patch}\"\n{DEFAULT_MACROS}"
    ));
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        // cbindgen follows the `mod` declarations of src/ffi/mod.rs to the other files.
        .with_src(root.join("src/ffi/mod.rs"))
        .generate()
        .map_err(|e| format!("cbindgen: {e}"))?;
    let mut out = Vec::new();
    bindings.write(&mut out);
    Ok(out)
}

fn main() -> ExitCode {
    let check = std::env::args().any(|a| a == "--check");
    let root = repo_root();
    let header_path = root.join("include/topoloc.h");
    let generated = match generate(&root) {
        Ok(g) => g,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    if check {
        let current = std::fs::read(&header_path).unwrap_or_default();
        if current != generated {
            eprintln!("include/topoloc.h is stale: run `cargo run -p topoloc-gen-header` and commit the result");
            return ExitCode::FAILURE;
        }
        println!("include/topoloc.h is up to date");
    } else if let Err(e) = std::fs::write(&header_path, &generated) {
        eprintln!("error: writing {}: {e}", header_path.display());
        return ExitCode::FAILURE;
    } else {
        println!("wrote {}", header_path.display());
    }
    ExitCode::SUCCESS
}
