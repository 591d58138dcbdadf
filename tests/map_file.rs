//! The map file: bit-exact round trips, atomic saves, and typed errors for every kind of
//! damaged or foreign file (truncated at every offset, every byte flipped).

mod common;

use common::chain_map;
use common::images::{place_image, vlad_image_map_with};
use topoloc::describe::PcaPrecision;
use topoloc::map::{LoadOptions, MapError, FORMAT_VERSION_MINOR};
use topoloc::{ExpectedDescriptor, Map};

fn load_bytes(bytes: &[u8]) -> Result<Map, MapError> {
    Map::from_bytes(bytes, &LoadOptions::default())
}

#[test]
fn round_trip_is_bit_exact_and_keeps_everything() {
    let map = chain_map(5, 4, 16);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("chain.topoloc");
    map.save(&path).unwrap();
    let loaded = Map::load(&path, &LoadOptions::default()).unwrap();
    assert!(
        loaded.is_memory_mapped(),
        "descriptors should be read in place"
    );
    assert_eq!(std::fs::read(&path).unwrap(), loaded.to_bytes().unwrap());
    assert_eq!(loaded.descriptors(), map.descriptors());
    assert_eq!(loaded.views(), map.views());
    assert_eq!(loaded.edges(), map.edges());
    assert_eq!(loaded.descriptor(), map.descriptor());
    assert_eq!(loaded.creator(), map.creator());
    for p in 0..5 {
        assert_eq!(
            loaded.place_position(p).unwrap(),
            map.place_position(p).unwrap()
        );
        assert_eq!(loaded.neighbours(p).unwrap(), map.neighbours(p).unwrap());
        assert_eq!(loaded.place_views(p).unwrap(), map.place_views(p).unwrap());
    }
    assert_eq!(
        loaded.view(2).unwrap().image.as_deref(),
        Some("images/place000_view2.png")
    );
    assert_eq!(loaded.view(3).unwrap().image, None);
}

#[test]
fn map_without_edges_or_attributes_round_trips() {
    let mut builder =
        topoloc::MapBuilder::new(topoloc::DescriptorIdentity::new("bare", "", 3).unwrap());
    let p = builder.add_place(None).unwrap();
    builder
        .add_view(p, &[0.0, 3.0, 4.0], Default::default())
        .unwrap();
    let map = builder.build().unwrap();
    let bytes = map.to_bytes().unwrap();
    let loaded = load_bytes(&bytes).unwrap();
    assert_eq!(loaded.descriptors(), &[0.0, 0.6, 0.8]);
    assert_eq!(loaded.edge_count(), 0);
    assert_eq!(loaded.place_position(0).unwrap(), None);
    assert_eq!(loaded.to_bytes().unwrap(), bytes);
}

#[test]
fn every_truncation_is_a_typed_error() {
    let bytes = chain_map(3, 2, 8).to_bytes().unwrap();
    for len in 0..bytes.len() {
        match load_bytes(&bytes[..len]) {
            Err(MapError::Truncated(_)) => {}
            Err(MapError::NotAMap(_)) if len == 0 => {}
            other => panic!(
                "truncated at {len} of {}: expected Truncated, got {other:?}",
                bytes.len()
            ),
        }
    }
}

#[test]
fn every_flipped_byte_is_detected() {
    let bytes = chain_map(3, 2, 8).to_bytes().unwrap();
    for i in 0..bytes.len() {
        for mask in [0x01u8, 0x80] {
            let mut damaged = bytes.clone();
            damaged[i] ^= mask;
            assert!(
                load_bytes(&damaged).is_err(),
                "flipping byte {i} with {mask:#04x} went unnoticed"
            );
        }
    }
}

#[test]
fn trailing_garbage_is_corrupt() {
    let mut bytes = chain_map(2, 1, 4).to_bytes().unwrap();
    bytes.extend_from_slice(b"junk");
    assert!(matches!(load_bytes(&bytes), Err(MapError::Corrupt(_))));
}

#[test]
fn foreign_files_are_not_maps() {
    assert!(matches!(
        load_bytes(b"hello, this is a text file and not a map at all"),
        Err(MapError::NotAMap(_))
    ));
    let foreign = safetensors::serialize(
        [(
            "weights",
            safetensors::tensor::TensorView::new(
                safetensors::Dtype::F32,
                vec![1],
                &[0, 0, 128, 63],
            )
            .unwrap(),
        )],
        None,
    )
    .unwrap();
    assert!(matches!(load_bytes(&foreign), Err(MapError::NotAMap(_))));
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty");
    std::fs::write(&empty, b"").unwrap();
    assert!(matches!(
        Map::load(&empty, &LoadOptions::default()),
        Err(MapError::NotAMap(_))
    ));
    assert!(matches!(
        Map::load(dir.path().join("missing"), &LoadOptions::default()),
        Err(MapError::Io { .. })
    ));
}

#[test]
fn newer_major_version_is_refused() {
    let bytes = chain_map(2, 1, 4).to_bytes().unwrap();
    let pattern = format!(r#"\"version\":\"1.{FORMAT_VERSION_MINOR}\""#);
    let pattern = pattern.as_bytes();
    let at = bytes
        .windows(pattern.len())
        .position(|w| w == pattern)
        .expect("version in header");
    let mut newer = bytes.clone();
    newer[at + r#"\"version\":\""#.len()] = b'2';
    match load_bytes(&newer) {
        Err(MapError::UnsupportedVersion {
            found,
            supported: 1,
        }) => assert_eq!(found, format!("2.{FORMAT_VERSION_MINOR}")),
        other => panic!("expected UnsupportedVersion, got {other:?}"),
    }
}

#[test]
fn descriptor_mismatch_is_refused_on_load() {
    let bytes = chain_map(2, 1, 4).to_bytes().unwrap();
    let expect = |kind: Option<&str>, dim: Option<u32>| LoadOptions {
        expected: ExpectedDescriptor {
            kind: kind.map(String::from),
            model: None,
            dim,
        },
    };
    assert!(Map::from_bytes(&bytes, &expect(Some("test"), Some(4))).is_ok());
    assert!(matches!(
        Map::from_bytes(&bytes, &expect(Some("vlad-orb"), None)),
        Err(MapError::DescriptorMismatch { .. })
    ));
    assert!(matches!(
        Map::from_bytes(&bytes, &expect(None, Some(512))),
        Err(MapError::DescriptorMismatch { .. })
    ));
}

#[test]
fn save_is_atomic_and_leaves_no_temporary_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("map.topoloc");
    chain_map(2, 1, 4).save(&path).unwrap();
    chain_map(3, 1, 4).save(&path).unwrap();
    assert_eq!(
        Map::load(&path, &LoadOptions::default())
            .unwrap()
            .place_count(),
        3
    );
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("map.topoloc")]);
    let err = chain_map(2, 1, 4)
        .save(dir.path().join("no/such/dir/map.topoloc"))
        .unwrap_err();
    assert!(matches!(err, MapError::Io { .. }), "{err:?}");
}

/// Rewrites a map's file bytes as format 1.0 wrote them: the metadata serialised in its struct
/// field order (format, version, descriptor, creator, counts), checksummed in that form.
fn as_version_1_0(bytes: &[u8]) -> Vec<u8> {
    use safetensors::SafeTensors;
    let st = SafeTensors::deserialize(bytes).unwrap();
    let (_, metadata) = SafeTensors::read_metadata(bytes).unwrap();
    let meta: serde_json::Value =
        serde_json::from_str(&metadata.metadata().as_ref().unwrap()["topoloc"]).unwrap();
    let d = &meta["descriptor"];
    let legacy = format!(
        r#"{{"format":"topoloc-map","version":"1.0","descriptor":{{"kind":{},"model":{},"dim":{}}},"creator":{},"places":{},"views":{},"edges":{}}}"#,
        d["kind"],
        d["model"],
        d["dim"],
        meta["creator"],
        meta["places"],
        meta["views"],
        meta["edges"]
    );
    let mut names = st.names();
    names.sort_unstable();
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(legacy.as_bytes());
    for name in &names {
        hasher.update(st.tensor(name).unwrap().data());
    }
    let signed = format!(
        r#"{},"crc32":"{:08x}"}}"#,
        &legacy[..legacy.len() - 1],
        hasher.finalize()
    );
    let tensors: Vec<(String, safetensors::tensor::TensorView)> = names
        .iter()
        .map(|n| (n.to_string(), st.tensor(n).unwrap()))
        .collect();
    safetensors::serialize(
        tensors,
        Some(std::collections::HashMap::from([(
            "topoloc".to_string(),
            signed,
        )])),
    )
    .unwrap()
}

#[test]
fn files_written_by_format_1_0_still_load() {
    let map = chain_map(4, 2, 8);
    let old = as_version_1_0(&map.to_bytes().unwrap());
    let loaded = load_bytes(&old).expect("a 1.0 file loads");
    assert_eq!(loaded.descriptors(), map.descriptors());
    assert_eq!(loaded.edges(), map.edges());
    // The legacy checksum still protects it.
    let mut flipped = old.clone();
    let last = flipped.len() - 1;
    flipped[last] ^= 1;
    assert!(matches!(load_bytes(&flipped), Err(MapError::Corrupt(_))));
}

#[test]
fn i8_pca_rows_round_trip_in_place_and_describe_as_before() {
    let images: Vec<Vec<u8>> = (0..6).map(place_image).collect();
    let dir = tempfile::tempdir().unwrap();
    let mut sizes = Vec::new();
    let mut rows = 0;
    for precision in [PcaPrecision::I8, PcaPrecision::F32] {
        let built = vlad_image_map_with(&images, precision);
        let model = built.describer().unwrap().clone();
        rows = model.pca.output_dim * model.pca.input_dim;
        assert_eq!(model.pca.components.precision(), precision);
        // The identity tells the two forms apart (their projections differ slightly).
        assert_eq!(
            built.descriptor().model.contains("/i8 fit="),
            precision == PcaPrecision::I8,
            "{}",
            built.descriptor().model
        );
        let path = dir.path().join(format!("{}.topoloc", precision.name()));
        built.save(&path).unwrap();
        sizes.push(std::fs::metadata(&path).unwrap().len());
        for loaded in [
            Map::load(&path, &LoadOptions::default()).unwrap(),
            load_bytes(&std::fs::read(&path).unwrap()).unwrap(),
        ] {
            assert_eq!(loaded.descriptor(), built.descriptor());
            let again = loaded.describer().unwrap();
            assert_eq!(again.pca, model.pca, "rows, scales and mean are bit-exact");
            // The map's own views were projected with the stored rows: projecting a view's
            // raw vector with the loaded model gives the stored descriptor.
            let raw: Vec<f32> = (0..model.pca.input_dim)
                .map(|j| ((j * 13) % 7) as f32 * 0.01)
                .collect();
            assert_eq!(
                again.pca.project(&raw).unwrap(),
                model.pca.project(&raw).unwrap()
            );
            for v in 0..built.view_count() as u32 {
                assert_eq!(
                    loaded.view_descriptor(v).unwrap(),
                    built.view_descriptor(v).unwrap()
                );
            }
        }
    }
    // The i8 rows take a quarter of the f32 rows' bytes (plus a scale per row and a longer
    // tensor table).
    let saved = sizes[1] as i64 - sizes[0] as i64;
    assert!(
        (saved - 3 * rows as i64).abs() < 1024,
        "i8 {} vs f32 {} bytes for {rows} values",
        sizes[0],
        sizes[1]
    );
}
