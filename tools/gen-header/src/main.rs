//! Generates `include/topoloc.h` from `src/ffi` with the pinned cbindgen, adding the version
//! macros from the root Cargo.toml, a `_default` macro per `_init` function, section banners,
//! and each option field's range and default from the library itself
//! (`topoloc::ffi::option_ranges`, the Rust options' bounds; `topoloc::ffi::option_defaults`,
//! what `_init` writes): neither is written by hand. With `--check`, fails (exit 1) when the
//! checked-in header differs from what would be generated, so CI catches a stale header.
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

/// `T_default(p)` macros over every exported `T_init(p, size)` function: they pass the size of
/// the caller's struct, so that a newer library never writes past an older caller's struct.
fn default_macros(header: &str) -> String {
    let mut macros = String::from(
        "\n/* Fill a versioned struct with defaults (and its struct_size) before use. */\n",
    );
    for line in header.lines() {
        let Some(name) = function_name(line).and_then(|f| f.strip_suffix("_init")) else {
            continue;
        };
        macros.push_str(&format!(
            "#define {name}_default(p) {name}_init((p), sizeof *(p))\n"
        ));
    }
    macros
}

/// The header's sections of functions, in reading order: a banner and the functions' name
/// prefixes. cbindgen writes functions in the order of src/ffi/mod.rs's modules; this only
/// names the sections, and fails when a function belongs to none or a section is split.
const SECTIONS: &[(&str, &[&str])] = &[
    (
        "Versions and errors",
        &[
            "topoloc_version",
            "topoloc_abi_version",
            "topoloc_status_",
            "topoloc_last_error_message",
        ],
    ),
    (
        "Host logging (records to a callback; nothing on stdout or stderr)",
        &["topoloc_set_log_callback"],
    ),
    (
        "Maps: load, save, query (a const topoloc_map* may be shared by many threads)",
        &[
            "topoloc_map_load",
            "topoloc_map_save",
            "topoloc_map_free",
            "topoloc_map_place",
            "topoloc_map_view",
            "topoloc_map_edge",
            "topoloc_map_descriptor",
            "topoloc_map_neighbours",
            "topoloc_view_info",
            "topoloc_map_keypoint_total",
            "topoloc_map_with_keypoint_points",
        ],
    ),
    (
        "Localizer (one camera, one thread at a time)",
        &["topoloc_localizer_", "topoloc_frame_", "topoloc_result_"],
    ),
    (
        "Building maps: from places and views, keyframes, images",
        &[
            "topoloc_map_builder_",
            "topoloc_view_attributes_",
            "topoloc_keyframe_options_",
            "topoloc_map_from_keyframes",
            "topoloc_image_map_options_",
            "topoloc_map_build_from_",
        ],
    ),
    (
        "Describers: images to a map's global descriptors (one thread at a time)",
        &["topoloc_describer_"],
    ),
    (
        "Skeleton graphs from occupancy grids",
        &["topoloc_skeleton_options_", "topoloc_graph_"],
    ),
    (
        "Loop closure: keyframes (descriptors and keypoints, or images) in, gated hints with relative poses out (one thread at a time)",
        &["topoloc_loop_", "topoloc_keyframe_describer_"],
    ),
    (
        "Trajectory metrics: ATE, ARE, RPE and R_traj against ground truth (thread-safe)",
        &["topoloc_trajectory_"],
    ),
];

/// Puts a banner comment before the first function of every section of [`SECTIONS`].
fn add_section_banners(header: &str) -> Result<String, String> {
    let mut out = String::with_capacity(header.len() + 1024);
    let mut pending_doc = String::new();
    let mut current: Option<usize> = None;
    let mut seen = vec![false; SECTIONS.len()];
    for line in header.split_inclusive('\n') {
        let in_doc = !pending_doc.is_empty();
        if line.starts_with("/**") || (in_doc && !pending_doc.ends_with("*/\n")) {
            pending_doc.push_str(line);
            continue;
        }
        if let Some(name) = function_name(line) {
            let section = SECTIONS
                .iter()
                .position(|(_, prefixes)| prefixes.iter().any(|p| name.starts_with(p)))
                .ok_or_else(|| {
                    format!(
                        "function {name} belongs to no header section (tools/gen-header SECTIONS)"
                    )
                })?;
            if current != Some(section) {
                if seen[section] {
                    return Err(format!(
                        "section '{}' is split: order src/ffi/mod.rs's modules",
                        SECTIONS[section].0
                    ));
                }
                seen[section] = true;
                current = Some(section);
                let title = SECTIONS[section].0;
                out.push_str(&format!(
                    "/* {0}\n * {title}\n * {0} */\n\n",
                    "=".repeat(title.len().max(40))
                ));
            }
        }
        out.push_str(&pending_doc);
        pending_doc.clear();
        out.push_str(line);
    }
    out.push_str(&pending_doc);
    Ok(out)
}

/// The function a declaration line declares (`type name(...);` at column 0), if it is one.
fn function_name(line: &str) -> Option<&str> {
    if line.starts_with(' ')
        || line.starts_with('#')
        || line.starts_with("typedef")
        || !line.trim_end().ends_with(");")
    {
        return None;
    }
    let open = line.find('(')?;
    let name = line[..open].rsplit([' ', '*']).next()?;
    name.starts_with("topoloc_").then_some(name)
}

/// cbindgen's header of src/ffi, with `after_includes` after the includes.
fn cbindgen_header(root: &Path, after_includes: String) -> Result<String, String> {
    let mut config =
        cbindgen::Config::from_file(root.join("cbindgen.toml")).map_err(|e| e.to_string())?;
    config.after_includes = Some(after_includes);
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        // cbindgen follows the `mod` declarations of src/ffi/mod.rs to the other files.
        .with_src(root.join("src/ffi/mod.rs"))
        .generate()
        .map_err(|e| format!("cbindgen: {e}"))?;
    let mut out = Vec::new();
    bindings.write(&mut out);
    String::from_utf8(out).map_err(|e| format!("cbindgen wrote non-UTF-8: {e}"))
}

fn generate(root: &Path) -> Result<Vec<u8>, String> {
    let (major, minor, patch) = package_version(root)?;
    let versions = format!(
        "\n#define TOPOLOC_VERSION_MAJOR {major}\n#define TOPOLOC_VERSION_MINOR {minor}\n#define TOPOLOC_VERSION_PATCH {patch}\n#define TOPOLOC_VERSION_STRING \"{major}.{minor}.{patch}\"\n"
    );
    let text = cbindgen_header(root, versions.clone())?;
    // The `_default` macros name the `_init` functions, which only the generated header lists:
    // they go after the version macros once cbindgen has written it.
    let text = text.replacen(&versions, &(versions.clone() + &default_macros(&text)), 1);
    let ranges = topoloc::ffi::option_ranges()
        .into_iter()
        .map(|r| (r.struct_name, r.field, format!("Range: {}.", r.bounds)));
    let defaults = topoloc::ffi::option_defaults()
        .into_iter()
        .map(|d| (d.struct_name, d.field, format!("Default: {}.", d.value)));
    let text = add_field_notes(&text, ranges.chain(defaults))?;
    Ok(add_section_banners(&text)?.into_bytes())
}

/// Ends the doc comment of each `(struct, field, note)`'s field with a line `note`, in order.
fn add_field_notes<'a>(
    header: &str,
    notes: impl Iterator<Item = (&'a str, &'a str, String)>,
) -> Result<String, String> {
    let mut text = header.to_string();
    for (struct_name, field, note) in notes {
        let open = format!("typedef struct {} {{", struct_name);
        let start = text
            .find(&open)
            .ok_or_else(|| format!("no struct {} in the header", struct_name))?;
        let end = start
            + text[start..]
                .find("\n} ")
                .ok_or_else(|| format!("struct {} does not end", struct_name))?
            + 1;
        let declaration = [format!(" {};\n", field), format!("*{};\n", field)];
        let field_at = declaration
            .iter()
            .filter_map(|decl| text[start..end].find(decl.as_str()))
            .min()
            .map(|at| start + at)
            .ok_or_else(|| format!("no field {} in {}", field, struct_name))?;
        let doc_end = text[start..field_at]
            .rfind("   */\n")
            .map(|at| start + at)
            .filter(|&at| !text[at..field_at].contains(';'))
            .ok_or_else(|| format!("{}.{} has no doc comment", struct_name, field))?;
        text.insert_str(doc_end, &format!("   * {note}\n"));
    }
    Ok(text)
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
