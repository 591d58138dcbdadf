//! Writes the fuzzers' seed corpora (run by fuzz/run.sh):
//!
//! ```sh
//! cargo run --release --example fuzz_seeds -- OUT_DIR
//! ```
//!
//! `OUT_DIR/map_load/`: real maps of every format version (1.0 to 1.5) and backend: external
//! descriptors with keyframe ids, poses, positions and image references; VLAD from images with
//! ORB keypoints, with and without scene points, with i8 PCA rows (1.5) and f32 ones (older); and, when scripts/setup-models.sh has filled
//! the cache, ONNX with dense cells and with XFeat keypoints. `OUT_DIR/describer_spec/`: the
//! describer specs of those maps (JSON). `OUT_DIR/keyframe_db/`: small operation programs.
//! `OUT_DIR/base/`: the maps the describer and image targets start from.

#[path = "../tests/common/images.rs"]
#[allow(dead_code)]
mod images;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion};
use std::path::Path;
use topoloc::build::{build_from_images, ImageLayout, ImageMapOptions, ImageSource};
use topoloc::describe::onnx::{cache_dir, OnnxOptions, DEFAULT_MODEL_FILE};
use topoloc::describe::vlad::VladOptions;
use topoloc::describe::{BackendConfig, FitOptions, PcaPrecision};
use topoloc::map::ViewAttributes;
use topoloc::verify::xfeat::DEFAULT_XFEAT_MODEL_FILE;
use topoloc::verify::{FeatureKind, DEFAULT_CELLS};
use topoloc::{DescriptorIdentity, Map, MapBuilder};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let out = std::env::args().nth(1).ok_or("usage: fuzz_seeds OUT_DIR")?;
    let out = Path::new(&out);
    for dir in ["map_load", "describer_spec", "keyframe_db", "base"] {
        std::fs::create_dir_all(out.join(dir))?;
    }
    let mut written = 0;
    let mut write = |dir: &str, name: &str, bytes: &[u8]| -> std::io::Result<()> {
        written += 1;
        std::fs::write(out.join(dir).join(name), bytes)
    };

    let plain = plain_map()?.to_bytes()?;
    write("map_load", "plain-1.5", &plain)?;
    for minor in 0..5 {
        let older = with_version(&plain, minor).ok_or("could not rewrite the version")?;
        Map::from_bytes(&older, &Default::default())?;
        write("map_load", &format!("plain-1.{minor}"), &older)?;
    }

    let vlad_config = BackendConfig::Vlad(VladOptions {
        clusters: 8,
        max_features: 200,
        input_size: (160, 120),
        ..VladOptions::default()
    });
    let vlad = image_map(vlad_config.clone(), FeatureKind::Orb, 48, PcaPrecision::I8)?;
    let vlad_bytes = vlad.to_bytes()?;
    write("map_load", "vlad-orb-1.5", &vlad_bytes)?;
    // Before 1.5 the PCA rows were f32.
    let vlad_f32 = image_map(vlad_config, FeatureKind::Orb, 48, PcaPrecision::F32)?;
    let vlad_f32_bytes = vlad_f32.to_bytes()?;
    write(
        "map_load",
        "vlad-orb-1.2",
        &with_version(&vlad_f32_bytes, 2).ok_or("version")?,
    )?;
    for (map, name, older) in [(&vlad, "1.5", None), (&vlad_f32, "1.3", Some(3))] {
        let total = map.keypoints().map_or(0, |k| k.total());
        let points: Vec<[f32; 3]> = (0..total)
            .map(|i| match i % 5 {
                0 => [f32::NAN; 3],
                _ => [i as f32 * 0.01, 0.5, 2.0 + (i % 7) as f32 * 0.1],
            })
            .collect();
        let with_points = map.with_keypoint_world_points(points)?.to_bytes()?;
        let bytes = match older {
            Some(minor) => with_version(&with_points, minor).ok_or("version")?,
            None => with_points,
        };
        write("map_load", &format!("vlad-orb-points-{name}"), &bytes)?;
    }
    write("base", "vlad.topoloc", &vlad_bytes)?;
    write(
        "describer_spec",
        "vlad.json",
        spec_of(&vlad_bytes)?.as_bytes(),
    )?;

    if cache_dir().join(DEFAULT_MODEL_FILE).is_file() {
        let onnx = BackendConfig::Onnx(OnnxOptions {
            grid: (1, 1),
            ..OnnxOptions::default()
        });
        let cells = image_map(
            onnx.clone(),
            FeatureKind::Cells,
            DEFAULT_CELLS.min(32),
            PcaPrecision::I8,
        )?
        .to_bytes()?;
        write("map_load", "onnx-cells-1.5", &cells)?;
        write("base", "onnx.topoloc", &cells)?;
        write("describer_spec", "onnx.json", spec_of(&cells)?.as_bytes())?;
        if cache_dir().join(DEFAULT_XFEAT_MODEL_FILE).is_file() {
            let xfeat = image_map(onnx, FeatureKind::XFeat, 32, PcaPrecision::F32)?.to_bytes()?;
            write(
                "map_load",
                "onnx-xfeat-1.4",
                &with_version(&xfeat, 4).ok_or("version")?,
            )?;
        } else {
            eprintln!("fuzz_seeds: no XFeat model: no XFeat seed (run scripts/setup-models.sh)");
        }
    } else {
        eprintln!("fuzz_seeds: no ONNX model: no ONNX seeds (run scripts/setup-models.sh)");
    }

    // Keyframe-database programs: mostly adds with poses and keypoints, an erase, a query.
    let mut state = 0x2545_F491u64;
    for program in 0..8 {
        let bytes: Vec<u8> = (0..600)
            .map(|i| {
                state = state
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                match (program, i % 97) {
                    (_, 4) => 0x1a, // add: pose, points
                    _ => (state >> 56) as u8,
                }
            })
            .collect();
        write("keyframe_db", &format!("program-{program}"), &bytes)?;
    }
    eprintln!("fuzz_seeds: {written} files in {}", out.display());
    Ok(())
}

/// External descriptors: 5 places, 2 views each, with every optional attribute.
fn plain_map() -> Result<Map, topoloc::MapError> {
    let dim = 32;
    let mut builder = MapBuilder::new(DescriptorIdentity::new("external", "fuzz seed", dim)?);
    for p in 0..5u32 {
        let place = builder.add_place(Some(Point3::new(f64::from(p), 0.5, 0.0)))?;
        for v in 0..2u32 {
            let d: Vec<f32> = (0..dim)
                .map(|i| ((i * 7 + p * 3 + v) % 11) as f32 - 5.0)
                .collect();
            let pose = Isometry3::from_parts(
                Translation3::new(f64::from(p), 0.0, 0.0),
                UnitQuaternion::from_euler_angles(0.0, 0.0, f64::from(v) * 1.57),
            );
            let attributes = ViewAttributes {
                keyframe_id: Some(u64::from(p * 2 + v)),
                world_t_camera: Some(pose),
                image: (v == 0).then(|| format!("images/{p:04}.png")),
            };
            builder.add_view(place, &d, attributes)?;
        }
        if p > 0 {
            builder.add_edge(p - 1, p, 1.0)?;
        }
    }
    builder.build()
}

/// A map from six generated 320x240 images with `keypoints` local features per view.
fn image_map(
    backend: BackendConfig,
    features: FeatureKind,
    keypoints: usize,
    precision: PcaPrecision,
) -> Result<Map, Box<dyn std::error::Error>> {
    let pixels: Vec<Vec<u8>> = (0..6).map(images::place_image).collect();
    let sources: Vec<ImageSource> = pixels
        .iter()
        .map(|d| ImageSource::Pixels(images::gray(d)))
        .collect();
    let options = ImageMapOptions {
        backend,
        fit: FitOptions {
            dim: 4,
            pca_precision: precision,
            ..FitOptions::default()
        },
        keypoints,
        features,
        threads: 1,
        ..ImageMapOptions::default()
    };
    let (map, _) = build_from_images(&sources, ImageLayout::Sequence, &options, &mut |_, _, _| {
        true
    })?;
    Ok(map)
}

/// The file with its metadata's version set to `1.{minor}` and the checksum recomputed.
fn with_version(bytes: &[u8], minor: u32) -> Option<Vec<u8>> {
    let from = format!(
        "\\\"version\\\":\\\"{}.{}\\\"",
        topoloc::map::FORMAT_VERSION_MAJOR,
        topoloc::map::FORMAT_VERSION_MINOR
    );
    let to = format!("\\\"version\\\":\\\"1.{minor}\\\"");
    let at = bytes
        .windows(from.len())
        .position(|w| w == from.as_bytes())?;
    let mut edited = bytes.to_vec();
    edited[at..at + from.len()].copy_from_slice(to.as_bytes());
    topoloc::map::reseal(&edited)
}

/// The describer spec (JSON) stored in a map file's metadata.
fn spec_of(bytes: &[u8]) -> Result<String, Box<dyn std::error::Error>> {
    let (_, metadata) = safetensors::SafeTensors::read_metadata(bytes)?;
    let topoloc = metadata
        .metadata()
        .as_ref()
        .and_then(|m| m.get("topoloc"))
        .ok_or("no topoloc metadata")?;
    let meta: serde_json::Value = serde_json::from_str(topoloc)?;
    Ok(meta["describer"].to_string())
}
