//! Hostile map files: every size, string and offset a file declares is checked before anything
//! is allocated or looped over from it. Each case edits a real map (its JSON metadata and/or its
//! tensors), recomputes the CRC-32 exactly as the format does, and expects a typed error at
//! load, never a panic or a huge allocation (the allocator below refuses any single allocation
//! over [`ALLOCATION_LIMIT`], which aborts the test binary). Also: saves keep the target's
//! permissions and clean up stale temporary files; images too small for ORB are refused.

mod common;

use common::chain_map;
use common::images::{place_image, vlad_image_map};
use safetensors::{Dtype, SafeTensors};
use serde_json::{json, Value};
use std::alloc::{GlobalAlloc, Layout, System};
use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, OnceLock};
use topoloc::describe::limits::{MAX_INPUT_SIDE, MAX_POOL_GRID, MAX_TAPS};
use topoloc::describe::pca::Components;
use topoloc::describe::{BackendSpec, DescriberModel};
use topoloc::errors::VisionError;
use topoloc::image::{ImageView, PixelFormat};
use topoloc::map::{LoadOptions, MapError, ViewAttributes, MAX_DESCRIPTOR_DIM};
use topoloc::verify::{KeypointDetector, VerificationOptions, MAX_KEYPOINTS};
use topoloc::{
    DescriptorIdentity, Frame, LocalizeError, Localizer, LocalizerOptions, Map, MapBuilder, Mode,
};

/// Largest single allocation the tests allow: far above any map here (under 1 MB), far below
/// what a declared size like 100,000 x 100,000 would ask for.
const ALLOCATION_LIMIT: usize = 256 << 20;

struct BoundedAllocator;

// SAFETY: forwards to the system allocator; refusing (null) is a valid allocator answer.
unsafe impl GlobalAlloc for BoundedAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if layout.size() > ALLOCATION_LIMIT {
            return std::ptr::null_mut();
        }
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > ALLOCATION_LIMIT {
            return std::ptr::null_mut();
        }
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static ALLOCATOR: BoundedAllocator = BoundedAllocator;

fn load(bytes: &[u8]) -> Result<Map, MapError> {
    Map::from_bytes(bytes, &LoadOptions::default())
}

/// A small map built from images with the VLAD backend: describer (PCA, codebook) and
/// keypoints included. Built once.
fn image_map_bytes() -> &'static [u8] {
    static BYTES: OnceLock<Vec<u8>> = OnceLock::new();
    BYTES.get_or_init(|| image_map().to_bytes().unwrap())
}

fn image_map() -> Map {
    let images: Vec<Vec<u8>> = (0..4).map(place_image).collect();
    vlad_image_map(&images)
}

/// A file's tensors by name: dtype, shape, bytes.
type Tensors = BTreeMap<String, (Dtype, Vec<usize>, Vec<u8>)>;

/// Splits a file into its `topoloc` metadata object and its tensors.
fn split(bytes: &[u8]) -> (Value, Tensors) {
    let st = SafeTensors::deserialize(bytes).unwrap();
    let (_, metadata) = SafeTensors::read_metadata(bytes).unwrap();
    let meta: Value =
        serde_json::from_str(&metadata.metadata().as_ref().unwrap()["topoloc"]).unwrap();
    let tensors = st
        .tensors()
        .into_iter()
        .map(|(name, t)| (name, (t.dtype(), t.shape().to_vec(), t.data().to_vec())))
        .collect();
    (meta, tensors)
}

/// The format's checksum: CRC-32 of the metadata re-serialised as a generic JSON value without
/// `crc32`, then every tensor's bytes in tensor-name order.
fn crc_of<'a>(meta: &Value, tensor_bytes: impl Iterator<Item = &'a [u8]>) -> String {
    let mut unsigned = meta.clone();
    unsigned.as_object_mut().unwrap().remove("crc32");
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(unsigned.to_string().as_bytes());
    tensor_bytes.for_each(|b| hasher.update(b));
    format!("{:08x}", hasher.finalize())
}

/// Writes a file from metadata and tensors, with the checksum recomputed.
fn join(mut meta: Value, tensors: &Tensors) -> Vec<u8> {
    let crc = crc_of(&meta, tensors.values().map(|(_, _, b)| b.as_slice()));
    meta["crc32"] = json!(crc);
    let views: Vec<(String, safetensors::tensor::TensorView)> = tensors
        .iter()
        .map(|(name, (dtype, shape, bytes))| {
            let view = safetensors::tensor::TensorView::new(*dtype, shape.clone(), bytes).unwrap();
            (name.clone(), view)
        })
        .collect();
    let metadata = HashMap::from([("topoloc".to_string(), meta.to_string())]);
    safetensors::serialize(views, Some(metadata)).unwrap()
}

/// Edits a valid file's metadata and tensors and re-signs it.
fn edited(bytes: &[u8], edit: impl FnOnce(&mut Value, &mut Tensors)) -> Vec<u8> {
    let (mut meta, mut tensors) = split(bytes);
    edit(&mut meta, &mut tensors);
    join(meta, &tensors)
}

/// Edits the raw safetensors JSON header (offsets, shapes) and re-frames the file around the
/// original data; the checksum is left alone (the framing must fail first).
fn raw_header_edit(bytes: &[u8], edit: impl FnOnce(&mut Value)) -> Vec<u8> {
    let n = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let mut header: Value = serde_json::from_slice(&bytes[8..8 + n]).unwrap();
    edit(&mut header);
    let text = header.to_string();
    let mut out = (text.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(text.as_bytes());
    out.extend_from_slice(&bytes[8 + n..]);
    out
}

fn f32_bytes(values: impl IntoIterator<Item = f32>) -> Vec<u8> {
    values.into_iter().flat_map(f32::to_le_bytes).collect()
}

fn u64_bytes(values: impl IntoIterator<Item = u64>) -> Vec<u8> {
    values.into_iter().flat_map(u64::to_le_bytes).collect()
}

/// Loads, and expects a [`MapError::Corrupt`] whose message contains `needle`.
#[track_caller]
fn expect_corrupt(bytes: &[u8], needle: &str) {
    match load(bytes) {
        Err(MapError::Corrupt(msg)) => assert!(msg.contains(needle), "'{needle}' not in: {msg}"),
        other => panic!(
            "expected Corrupt ({needle}), got {:?}",
            other.map(|_| "a map")
        ),
    }
}

fn onnx_spec(taps: usize, grid: Value, input_size: Value) -> Value {
    json!({
        "backend": "onnx",
        "model_sha256": "0123456789abcdef".repeat(4),
        "taps": (0..taps).map(|i| format!("f{i}")).collect::<Vec<_>>(),
        "grid": grid,
        "input_size": input_size,
        "preprocessing": "rgb/255 imagenet-mean-std",
    })
}

#[test]
fn an_edited_but_resigned_file_still_loads() {
    // The helpers reproduce the format: an unchanged round trip through them loads.
    let again = edited(image_map_bytes(), |_, _| {});
    let map = load(&again).expect("re-signed file loads");
    assert!(map.describer().is_some() && map.keypoints().is_some());
}

#[test]
fn the_fuzzers_reseal_makes_an_edited_file_pass_the_checksum() {
    // An edit without re-signing fails the checksum; the library's reseal (used by the fuzzers'
    // mutator) fixes exactly that, and agrees with this file's own checksum code.
    let mut bytes = image_map_bytes().to_vec();
    let (meta, _) = split(&bytes);
    let creator = meta["creator"].as_str().unwrap().to_string();
    let at = bytes
        .windows(creator.len())
        .position(|w| w == creator.as_bytes())
        .unwrap();
    bytes[at] ^= 0x20;
    expect_corrupt(&bytes, "checksum");
    let resealed = topoloc::map::reseal(&bytes).expect("framing and metadata still parse");
    let map = load(&resealed).expect("resealed file loads");
    assert_ne!(map.creator(), creator);
    let (meta, tensors) = split(&resealed);
    let oracle = crc_of(&meta, tensors.values().map(|(_, _, b)| b.as_slice()));
    assert_eq!(meta["crc32"].as_str(), Some(oracle.as_str()));
    assert!(topoloc::map::reseal(b"not a map").is_none());
}

#[test]
fn huge_onnx_describer_shapes_are_refused_at_load_before_any_model_is_needed() {
    let cases = [
        (
            "grid",
            onnx_spec(4, json!([100_000, 100_000]), json!([320, 240])),
        ),
        (
            "grid",
            onnx_spec(4, json!([1u64 << 63, 1]), json!([320, 240])),
        ),
        (
            "grid",
            onnx_spec(4, json!([MAX_POOL_GRID + 1, 4]), json!([320, 240])),
        ),
        ("grid", onnx_spec(4, json!([0, 4]), json!([320, 240]))),
        ("taps", onnx_spec(75_000, json!([4, 4]), json!([320, 240]))),
        (
            "taps",
            onnx_spec(MAX_TAPS + 1, json!([4, 4]), json!([320, 240])),
        ),
        ("taps", onnx_spec(0, json!([4, 4]), json!([320, 240]))),
        (
            "input size",
            onnx_spec(4, json!([4, 4]), json!([100_000, 100_000])),
        ),
        (
            "input size",
            onnx_spec(4, json!([4, 4]), json!([MAX_INPUT_SIDE + 1, 240])),
        ),
        ("input size", onnx_spec(4, json!([4, 4]), json!([320, 0]))),
    ];
    for (needle, spec) in cases {
        let bytes = edited(image_map_bytes(), |meta, tensors| {
            meta["describer"] = spec.clone();
            tensors.remove("describer_codebook");
        });
        expect_corrupt(&bytes, needle);
    }
    // Bad tap names and model hashes too.
    let mut spec = onnx_spec(4, json!([4, 4]), json!([320, 240]));
    spec["taps"][1] = json!("f\u{0}1");
    let bytes = edited(image_map_bytes(), |meta, _| meta["describer"] = spec);
    expect_corrupt(&bytes, "tap");
    let mut spec = onnx_spec(4, json!([4, 4]), json!([320, 240]));
    spec["model_sha256"] = json!("not a hash");
    let bytes = edited(image_map_bytes(), |meta, _| meta["describer"] = spec);
    expect_corrupt(&bytes, "hash");
}

#[test]
fn describer_models_built_in_rust_get_the_same_checks() {
    let map = load(image_map_bytes()).unwrap();
    let vlad = map.describer().unwrap().as_ref().clone();
    assert!(vlad.validate().is_ok());
    let onnx = |grid: [usize; 2], taps: usize, input_size: [u32; 2]| DescriberModel {
        spec: BackendSpec::Onnx {
            model_sha256: "ab".repeat(32),
            taps: (0..taps).map(|i| format!("f{i}")).collect(),
            grid,
            input_size,
            preprocessing: "rgb/255 imagenet-mean-std".into(),
        },
        pca: vlad.pca.clone(),
        codebook: None,
    };
    // The VLAD PCA input (64 x 256) is a whole number of 4 x 4 grids: a consistent ONNX model.
    assert!(onnx([4, 4], 4, [320, 240]).validate().is_ok());
    for bad in [
        onnx([100_000, 100_000], 4, [320, 240]),
        onnx([1 << 63, 1], 4, [320, 240]),
        onnx([4, 4], 75_000, [320, 240]),
        onnx([4, 4], 4, [100_000, 240]),
        onnx([3, 3], 4, [320, 240]), // 16384 values are no whole number of 9-cell grids
    ] {
        assert!(
            matches!(bad.validate(), Err(VisionError::InvalidArgument(_))),
            "{:?}",
            bad.spec
        );
    }
    let mut wrong_codebook = vlad.clone();
    wrong_codebook.codebook.as_mut().unwrap().clusters = 32;
    assert!(wrong_codebook.validate().is_err());
    let mut huge_pca = vlad.clone();
    huge_pca.pca.output_dim = usize::MAX;
    assert!(huge_pca.validate().is_err(), "overflowing PCA shape");
}

#[test]
fn pca_and_codebook_shapes_must_agree_with_the_dimensions() {
    let bytes = image_map_bytes();
    let (_, tensors) = split(bytes);
    let input_dim = tensors["describer_pca_mean"].1[0];
    // A shorter PCA mean: the components no longer fit.
    let short_mean = edited(bytes, |_, t| {
        t.insert(
            "describer_pca_mean".into(),
            (
                Dtype::F32,
                vec![input_dim - 1],
                f32_bytes(vec![0.0; input_dim - 1]),
            ),
        );
    });
    expect_corrupt(&short_mean, "describer_pca_components");
    // A codebook of another shape than the VLAD options say.
    let codebook = edited(bytes, |_, t| {
        t.insert(
            "describer_codebook".into(),
            (Dtype::F32, vec![128, 128], f32_bytes(vec![0.5; 128 * 128])),
        );
    });
    expect_corrupt(&codebook, "describer_codebook");
    // VLAD options that disagree with the stored codebook and PCA.
    let clusters = edited(bytes, |meta, _| meta["describer"]["clusters"] = json!(32));
    expect_corrupt(&clusters, "describer");
    let huge_clusters = edited(bytes, |meta, _| {
        meta["describer"]["clusters"] = json!(1u64 << 62)
    });
    expect_corrupt(&huge_clusters, "clusters");
    // PCA components for another descriptor dimension than the map's.
    let dim = edited(bytes, |meta, _| meta["descriptor"]["dim"] = json!(2));
    assert!(matches!(load(&dim), Err(MapError::Corrupt(_))));
}

#[test]
fn pca_rows_are_exactly_one_form_with_sound_scales() {
    // Image maps store i8 rows with one scale per row (format 1.5).
    let bytes = image_map_bytes();
    let (_, tensors) = split(bytes);
    let (dtype, shape, rows) = tensors["describer_pca_components_i8"].clone();
    assert_eq!(dtype, Dtype::I8);
    assert!(!tensors.contains_key("describer_pca_components"));
    let (d, f) = (shape[0], shape[1]);
    assert_eq!(tensors["describer_pca_scales"].1, vec![d]);
    let scales = |values: Vec<f32>| {
        edited(bytes, |_, t| {
            t.insert(
                "describer_pca_scales".into(),
                (Dtype::F32, vec![values.len()], f32_bytes(values)),
            );
        })
    };
    expect_corrupt(&scales(vec![0.01; d + 1]), "describer_pca_scales");
    expect_corrupt(&scales(vec![-0.01; d]), "scales must not be negative");
    expect_corrupt(&scales(vec![f32::NAN; d]), "NaN or infinite");
    expect_corrupt(&scales(vec![f32::INFINITY; d]), "NaN or infinite");
    // Finite but unusable: every frame would fail with NON_FINITE or ZERO_DESCRIPTOR.
    expect_corrupt(&scales(vec![3e38; d]), "must be in [0, 1000000000]");
    expect_corrupt(&scales(vec![0.0; d]), "all 0");
    let without_scales = edited(bytes, |_, t| {
        t.remove("describer_pca_scales");
    });
    expect_corrupt(&without_scales, "describer_pca_scales");
    // Both forms, or neither.
    let both = edited(bytes, |_, t| {
        t.insert(
            "describer_pca_components".into(),
            (Dtype::F32, vec![d, f], f32_bytes(vec![0.0; d * f])),
        );
    });
    expect_corrupt(&both, "both");
    let neither = edited(bytes, |_, t| {
        t.remove("describer_pca_components_i8");
    });
    expect_corrupt(&neither, "describer_pca_components");
    // Rows of another dtype or shape.
    let as_u8 = edited(bytes, |_, t| {
        t.insert(
            "describer_pca_components_i8".into(),
            (Dtype::U8, shape.clone(), rows.clone()),
        );
    });
    expect_corrupt(&as_u8, "dtype");
    let transposed = edited(bytes, |_, t| {
        t.insert(
            "describer_pca_components_i8".into(),
            (Dtype::I8, vec![f, d], rows.clone()),
        );
    });
    expect_corrupt(&transposed, "shape");
    // Every i8 value is a valid row value (the fingerprint is what refuses edited rows):
    // the extremes describe to finite unit descriptors.
    let rows_edited = edited(bytes, |_, t| {
        let mut changed = rows.clone();
        changed[0] ^= 1;
        t.insert(
            "describer_pca_components_i8".into(),
            (Dtype::I8, shape.clone(), changed),
        );
    });
    expect_corrupt(&rows_edited, "descriptor mismatch");
    let mut pca = image_map().describer().unwrap().pca.clone();
    pca.components = Components::I8 {
        values: (0..d * f)
            .map(|i| if i % 2 == 0 { 0x80u8 } else { 0x7f })
            .collect::<Vec<u8>>()
            .into(),
        scales: vec![1.0; d],
    };
    let y = pca.project(&vec![0.5; f]).unwrap();
    assert!(
        (y.iter().map(|v| v * v).sum::<f32>() - 1.0).abs() < 1e-5,
        "{y:?}"
    );
    assert!(y.iter().all(|v| v.is_finite()), "{y:?}");
}

/// Replaces the keypoints of a file with `per_view[v]` points per view at `point`.
fn with_keypoints(bytes: &[u8], per_view: &[u64], point: [f32; 2]) -> Vec<u8> {
    edited(bytes, |_, t| {
        let total: u64 = per_view.iter().sum();
        let mut offsets = vec![0u64];
        for &n in per_view {
            offsets.push(offsets.last().unwrap() + n);
        }
        let n = total as usize;
        t.insert(
            "view_keypoint_offsets".into(),
            (Dtype::U64, vec![offsets.len()], u64_bytes(offsets)),
        );
        t.insert(
            "view_keypoint_points".into(),
            (Dtype::F32, vec![n, 2], f32_bytes(point.repeat(n))),
        );
        t.insert(
            "view_keypoint_descriptors".into(),
            (Dtype::U8, vec![n, 32], vec![7u8; n * 32]),
        );
        t.remove("view_keypoint_world_points");
    })
}

#[test]
fn keypoint_counts_and_positions_are_bounded() {
    let bytes = image_map_bytes();
    let views = load(bytes).unwrap().view_count();
    let mut counts = vec![3u64; views];
    assert!(load(&with_keypoints(bytes, &counts, [10.0, 20.0])).is_ok());
    counts[1] = MAX_KEYPOINTS as u64 + 1;
    expect_corrupt(&with_keypoints(bytes, &counts, [10.0, 20.0]), "keypoints");
    let counts = vec![3u64; views];
    for point in [
        [f32::NAN, 1.0],
        [1.0, f32::INFINITY],
        [-1.0, 5.0],
        [5.0, 1e9],
    ] {
        expect_corrupt(&with_keypoints(bytes, &counts, point), "keypoint");
    }
    // Offsets that promise far more keypoints than exist.
    let lying = edited(bytes, |_, t| {
        let mut offsets = vec![0u64; views + 1];
        offsets[views] = u64::MAX;
        t.insert(
            "view_keypoint_offsets".into(),
            (Dtype::U64, vec![views + 1], u64_bytes(offsets)),
        );
    });
    expect_corrupt(&lying, "keypoints");
}

#[test]
fn keypoint_descriptors_are_exactly_one_kind_of_the_right_shape() {
    let bytes = image_map_bytes();
    let views = load(bytes).unwrap().view_count();
    let orb = with_keypoints(bytes, &vec![3u64; views], [10.0, 20.0]);
    let n = 3 * views;
    // XFeat and cell descriptors (1.4) load in place of ORB ones.
    for (name, width) in [("view_keypoint_xfeat", 64), ("view_keypoint_cells", 96)] {
        let learned = edited(&orb, |_, t| {
            t.remove("view_keypoint_descriptors");
            t.insert(
                name.into(),
                (Dtype::I8, vec![n, width], vec![3u8; n * width]),
            );
        });
        assert!(load(&learned).is_ok(), "{name}");
        // Two kinds at once, a wrong width, or a wrong dtype are corrupt.
        let both = edited(&learned, |_, t| {
            t.insert(
                "view_keypoint_descriptors".into(),
                (Dtype::U8, vec![n, 32], vec![7u8; n * 32]),
            );
        });
        expect_corrupt(&both, "one kind");
        let narrow = edited(&learned, |_, t| {
            t.insert(name.into(), (Dtype::I8, vec![n, 32], vec![3u8; n * 32]));
        });
        expect_corrupt(&narrow, name);
        let unsigned = edited(&learned, |_, t| {
            t.insert(
                name.into(),
                (Dtype::U8, vec![n, width], vec![3u8; n * width]),
            );
        });
        expect_corrupt(&unsigned, name);
    }
    let none = edited(&orb, |_, t| {
        t.remove("view_keypoint_descriptors");
    });
    expect_corrupt(&none, "no descriptors");
}

#[test]
fn nul_bytes_in_strings_are_refused() {
    let bytes = chain_map(3, 2, 8).to_bytes().unwrap();
    for (path, value) in [
        (&["descriptor", "kind"][..], "te\u{0}st"),
        (&["descriptor", "model"][..], "chain\u{0}-v1"),
        (&["creator"][..], "topoloc\u{0}evil"),
    ] {
        let bad = edited(&bytes, |meta, _| {
            let mut slot = &mut *meta;
            for key in path {
                slot = &mut slot[*key];
            }
            *slot = json!(value);
        });
        expect_corrupt(&bad, "NUL");
    }
    let bad_image = edited(&bytes, |_, t| {
        t.get_mut("view_image_bytes").unwrap().2[3] = 0;
    });
    expect_corrupt(&bad_image, "NUL");

    // The builder refuses them too.
    let identity = |kind: &str, model: &str| DescriptorIdentity::new(kind, model, 3).unwrap();
    let one_view = |mut builder: MapBuilder, image: Option<&str>| {
        let p = builder.add_place(None).unwrap();
        let attributes = ViewAttributes {
            image: image.map(String::from),
            ..ViewAttributes::default()
        };
        builder
            .add_view(p, &[1.0, 0.0, 0.0], attributes)
            .and_then(|_| builder.build())
    };
    let invalid = |r: Result<Map, MapError>| matches!(r, Err(MapError::InvalidArgument(_)));
    assert!(one_view(MapBuilder::new(identity("ok", "ok")), None).is_ok());
    assert!(invalid(one_view(
        MapBuilder::new(identity("a\0b", "")),
        None
    )));
    assert!(invalid(one_view(
        MapBuilder::new(identity("a", "b\0")),
        None
    )));
    assert!(invalid(one_view(
        MapBuilder::new(identity("a", "b")),
        Some("img\0.png")
    )));
    let mut creator = MapBuilder::new(identity("a", "b"));
    creator.set_creator("me\0");
    assert!(invalid(one_view(creator, None)));
    assert!(DescriptorIdentity::new("a", "", MAX_DESCRIPTOR_DIM + 1).is_err());
    // An identity written field by field skips that check; the builder refuses it still.
    let mut huge = MapBuilder::new(DescriptorIdentity {
        kind: "a".into(),
        model: String::new(),
        dim: MAX_DESCRIPTOR_DIM + 1,
    });
    huge.add_place(None).unwrap();
    assert!(matches!(huge.build(), Err(MapError::InvalidArgument(_))));
}

#[test]
fn only_exact_major_minor_versions_of_this_major_load() {
    let bytes = chain_map(2, 1, 4).to_bytes().unwrap();
    let with_version = |v: &str| edited(&bytes, |meta, _| meta["version"] = json!(v));
    for good in ["1.3", "1.0", "1.7", "1.10"] {
        if good == "1.0" {
            continue; // 1.0 files use the legacy checksum (tests/map_file.rs)
        }
        assert!(load(&with_version(good)).is_ok(), "{good}");
    }
    for bad in [
        "0", "1", "1.", ".3", "+1.3", "01.3", "1.03", "1.3.4", "0.3", "0.0", "-1.3", " 1.3",
        "1.3 ", "1.x", "", "１.3", "1e0.3", "1.+3",
    ] {
        match load(&with_version(bad)) {
            Err(MapError::Corrupt(_)) => {}
            other => panic!("version '{bad}': expected Corrupt, got {:?}", other.err()),
        }
    }
    for newer in ["2.0", "10.3", "99999999999999999999999.1"] {
        match load(&with_version(newer)) {
            Err(MapError::UnsupportedVersion { found, supported }) => {
                assert_eq!((found.as_str(), supported), (newer, 1));
            }
            other => panic!(
                "version '{newer}': expected UnsupportedVersion, got {:?}",
                other.err()
            ),
        }
    }
}

#[test]
fn huge_declared_counts_lengths_and_offsets_are_typed_errors() {
    let bytes = chain_map(3, 2, 8).to_bytes().unwrap();
    // Counts and dimension in the metadata.
    for (key, value) in [
        ("views", json!(1u64 << 40)),
        ("views", json!(u64::MAX)),
        ("places", json!(u64::MAX)),
        ("edges", json!(1u64 << 33)),
    ] {
        let bad = edited(&bytes, |meta, _| meta[key] = value);
        expect_corrupt(&bad, key);
    }
    for dim in [
        0u64,
        u64::from(MAX_DESCRIPTOR_DIM) + 1,
        1 << 31,
        u64::from(u32::MAX),
    ] {
        let bad = edited(&bytes, |meta, _| meta["descriptor"]["dim"] = json!(dim));
        assert!(matches!(load(&bad), Err(MapError::Corrupt(_))), "dim {dim}");
    }
    // Image reference offsets far outside the bytes.
    let bad = edited(&bytes, |_, t| {
        let n = t["view_image_offsets"].1[0];
        let mut offsets = vec![0u64; n];
        offsets[1] = u64::MAX;
        offsets[2] = u64::MAX;
        t.get_mut("view_image_offsets").unwrap().2 = u64_bytes(offsets);
    });
    expect_corrupt(&bad, "image reference");

    // The container's own framing.
    let mut huge_header = bytes.clone();
    huge_header[..8].copy_from_slice(&u64::MAX.to_le_bytes());
    assert!(matches!(load(&huge_header), Err(MapError::Corrupt(_))));
    let last_tensor = |header: &mut Value| -> String {
        let object = header.as_object().unwrap();
        let (name, _) = object
            .iter()
            .filter(|(k, _)| *k != "__metadata__")
            .max_by_key(|(_, t)| t["data_offsets"][1].as_u64().unwrap())
            .unwrap();
        name.clone()
    };
    for end in [u64::MAX, u64::MAX - 7, 1 << 62] {
        let bad = raw_header_edit(&bytes, |h| {
            let name = last_tensor(h);
            h[&name]["data_offsets"][1] = json!(end);
        });
        match load(&bad) {
            Err(MapError::Corrupt(_)) | Err(MapError::Truncated(_)) => {}
            other => panic!("data end {end}: got {:?}", other.err()),
        }
    }
    let bad = raw_header_edit(&bytes, |h| {
        h["descriptors"]["shape"] = json!([1u64 << 32, 1u64 << 32]);
    });
    assert!(matches!(load(&bad), Err(MapError::Corrupt(_))));
    let bad = raw_header_edit(&bytes, |h| {
        h["descriptors"]["data_offsets"] = json!([u64::MAX - 3, 5]);
    });
    assert!(load(&bad).is_err());
}

/// Recomputes a (possibly damaged) file's checksum and writes it in place of the stored one,
/// when the file still parses far enough for that; other bytes are left untouched.
fn resign_in_place(bytes: &mut [u8]) {
    let Ok(st) = SafeTensors::deserialize(bytes) else {
        return;
    };
    let Ok((_, metadata)) = SafeTensors::read_metadata(bytes) else {
        return;
    };
    let Some(meta_json) = metadata.metadata().as_ref().and_then(|m| m.get("topoloc")) else {
        return;
    };
    let Ok(meta) = serde_json::from_str::<Value>(meta_json) else {
        return;
    };
    let Some(stored) = meta.get("crc32").and_then(Value::as_str).map(String::from) else {
        return;
    };
    let mut names = st.names();
    names.sort_unstable();
    let Ok(tensors) = names
        .iter()
        .map(|n| st.tensor(n))
        .collect::<Result<Vec<_>, _>>()
    else {
        return;
    };
    let crc = crc_of(&meta, tensors.iter().map(|t| t.data()));
    drop(tensors);
    let pattern = format!(r#"\"crc32\":\"{stored}\""#);
    let header_len = u64::from_le_bytes(bytes[..8].try_into().unwrap()) as usize;
    let header = &bytes[8..8 + header_len];
    if let Some(at) = header
        .windows(pattern.len())
        .position(|w| w == pattern.as_bytes())
    {
        if crc.len() == stored.len() {
            let start = 8 + at + r#"\"crc32\":\""#.len();
            bytes[start..start + crc.len()].copy_from_slice(crc.as_bytes());
        }
    }
}

#[test]
fn random_mutations_with_a_valid_checksum_never_panic() {
    use rand::{Rng, SeedableRng};
    let original = image_map_bytes();
    let header_end = 8 + u64::from_le_bytes(original[..8].try_into().unwrap()) as usize;
    let mut rng = rand::rngs::SmallRng::seed_from_u64(0x0707_010c);
    let (mut loaded, mut refused, mut past_checksum) = (0, 0, 0);
    for round in 0..2000 {
        let mut bytes = original.to_vec();
        for _ in 0..rng.random_range(1..=4) {
            // Mostly the header, where sizes and offsets are declared; sometimes the data.
            let at = if rng.random_bool(0.75) {
                rng.random_range(0..header_end)
            } else {
                rng.random_range(0..bytes.len())
            };
            bytes[at] = match rng.random_range(0..4) {
                0 => rng.random(),
                1 => bytes[at] ^ (1 << rng.random_range(0..8)),
                2 => b"0123456789"[rng.random_range(0..10)],
                _ => b"-.e9\"\\,:[]{}\0"[rng.random_range(0..13)],
            };
        }
        resign_in_place(&mut bytes);
        let outcome = std::panic::catch_unwind(|| load(&bytes).map(|m| m.view_count()));
        match outcome {
            Ok(Ok(_)) => loaded += 1,
            Ok(Err(e)) => {
                // Every MapError is typed; count those the checksum did not catch.
                refused += 1;
                past_checksum += usize::from(!e.to_string().contains("checksum"));
            }
            Err(_) => panic!("round {round}: loading a mutated file panicked"),
        }
    }
    eprintln!(
        "{loaded} mutated files loaded, {refused} refused with typed errors \
         ({past_checksum} of them past the checksum)"
    );
    assert_eq!(loaded + refused, 2000);
    assert!(
        past_checksum > 500,
        "the mutations must reach the parser, not only the checksum: {past_checksum}"
    );
}

#[cfg(unix)]
#[test]
fn saves_keep_permissions_and_remove_stale_temporary_files() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("map.topoloc");
    let map = chain_map(2, 1, 4);
    map.save(&path).unwrap();
    let mode = |p: &std::path::Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
    let plain = dir.path().join("plain");
    std::fs::write(&plain, b"").unwrap();
    assert_eq!(
        mode(&path),
        mode(&plain),
        "a new map gets the default permissions (umask), like any new file"
    );
    std::fs::remove_file(&plain).unwrap();
    for wanted in [0o644, 0o640, 0o600] {
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(wanted)).unwrap();
        map.save(&path).unwrap();
        assert_eq!(mode(&path), wanted, "permissions kept");
    }

    let stale = dir.path().join(".map.topoloc.topoloc-tmp-Ab12Cd");
    let other = dir.path().join(".other.topoloc.topoloc-tmp-Ab12Cd");
    std::fs::write(&stale, b"half a map").unwrap();
    std::fs::write(&other, b"another map's temporary file").unwrap();
    map.save(&path).unwrap();
    assert!(
        !stale.exists(),
        "the stale temporary file of this map is gone"
    );
    assert!(other.exists(), "other maps' temporary files are left alone");
    assert!(Map::load(&path, &LoadOptions::default()).is_ok());
}

#[test]
fn images_too_small_for_orb_are_invalid_images() {
    let mut detector = KeypointDetector::new(500).unwrap();
    let data = vec![100u8; 8192];
    for (w, h) in [(1u32, 1u32), (1, 240), (320, 1), (1, 8192), (8192, 1)] {
        let image = ImageView::packed(w, h, PixelFormat::Gray8, &data);
        assert!(
            matches!(detector.detect(&image), Err(VisionError::InvalidImage(_))),
            "{w}x{h}"
        );
    }
    for (w, h) in [(2u32, 2u32), (2, 240), (320, 2)] {
        let image = ImageView::packed(w, h, PixelFormat::Gray8, &data);
        assert!(detector.detect(&image).is_ok(), "{w}x{h}");
    }

    // Through a localizer with verification on.
    let map = Arc::new(load(image_map_bytes()).unwrap());
    let options = LocalizerOptions {
        mode: Mode::SingleFrame,
        verification: VerificationOptions::with_candidates(2),
        ..LocalizerOptions::default()
    };
    let mut localizer = Localizer::with_describer(map, options, &Default::default()).unwrap();
    let textured = place_image(1);
    for (w, h) in [(1u32, 240u32), (240, 1)] {
        let frame = Frame {
            timestamp: 0.0,
            image: Some(ImageView::packed(w, h, PixelFormat::Gray8, &textured)),
            ..Frame::default()
        };
        match localizer.localize(&frame) {
            Err(LocalizeError::Describe(VisionError::InvalidImage(_))) => {}
            other => panic!("{w}x{h}: expected InvalidImage, got {:?}", other.err()),
        }
    }
}
