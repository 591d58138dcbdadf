//! The map file: one safetensors container holding the map's arrays, with the map's identity in
//! its JSON metadata.
//!
//! Layout (all little-endian; N views, M places, E edges, D descriptor dimension):
//!
//! | tensor | dtype | shape | meaning |
//! |---|---|---|---|
//! | `descriptors` | F32 | N x D | unit-norm view descriptors, row-major |
//! | `view_place` | U32 | N | place of each view |
//! | `view_flags` | U8 | N | bit 0: has keyframe id, bit 1: has pose, bit 2: has image reference |
//! | `view_keyframe` | U64 | N | keyframe id (0 when absent) |
//! | `view_pose` | F64 | N x 7 | `world_T_camera` as tx ty tz qx qy qz qw (identity when absent) |
//! | `view_image_offsets` | U64 | N+1 | byte ranges of the image references in `view_image_bytes` |
//! | `view_image_bytes` | U8 | total | UTF-8 image references, concatenated |
//! | `place_flags` | U8 | M | bit 0: has position |
//! | `place_position` | F64 | M x 3 | position in metres (0 when absent) |
//! | `edges` | U32 | E x 2 | undirected edges, a < b, sorted |
//! | `edge_weight` | F32 | E | edge weights |
//! | `describer_pca_mean` | F32 | F | (1.1, maps built from images) PCA mean of the raw vectors |
//! | `describer_pca_components` | F32 | D x F | (1.1) PCA projection rows, or |
//! | `describer_pca_components_i8` | I8 | D x F | (1.5) those rows quantised, row k times `describer_pca_scales[k]`; exactly one of the two |
//! | `describer_pca_scales` | F32 | D | (1.5) with the I8 rows: each row's scale (its largest magnitude / 127) |
//! | `describer_codebook` | F32 | K x L | (1.1, VLAD only) codebook of K centres of local descriptors |
//! | `view_keypoint_offsets` | U64 | N+1 | (1.2, optional) ranges of each view's keypoints |
//! | `view_keypoint_points` | F32 | T x 2 | (1.2) keypoint pixel positions x, y |
//! | `view_keypoint_descriptors` | U8 | T x 32 | (1.2) their ORB descriptors, or |
//! | `view_keypoint_xfeat` | I8 | T x 64 | (1.4) their XFeat descriptors, `round(127 x unit)`, or |
//! | `view_keypoint_cells` | I8 | T x 96 | (1.4) dense cells of the describer's CNN (keypoints at cell centres); exactly one of the three |
//! | `view_keypoint_world_points` | F32 | T x 3 | (1.3, optional) map-frame scene point of each keypoint, NaN when unknown |
//!
//! The only metadata key, `topoloc`, holds a JSON object with `format` (`"topoloc-map"`),
//! `version` (`"MAJOR.MINOR"`), `descriptor` (`kind`, `model`, `dim`), `creator`, the counts, and
//! `crc32`: the CRC-32 (hex) of that JSON serialised without `crc32`, followed by every tensor's
//! bytes in tensor-name order, so that any flipped byte is detected. Since 1.1 the JSON may hold
//! `describer` (the backend and its configuration, see [`BackendSpec`]), and the checksummed
//! JSON is the metadata object re-serialised as a generic JSON value without `crc32`, so that
//! fields added by newer minor versions stay covered (1.0 re-serialised its own struct). Readers accept any file of the
//! same major version; a newer minor version may add tensors, which older readers ignore
//! (a 1.3 reader refuses a 1.4 map with XFeat keypoints as missing `view_keypoint_descriptors`,
//! and a 1.4 reader a 1.5 map with I8 PCA rows as missing `describer_pca_components`).
//!
//! One module per concern: [`header`] (framing, metadata, version, checksum), one reader/writer
//! per section ([`descriptors`], [`views`], [`places`], [`edges`], [`describer`],
//! [`keypoints`]), the safetensors plumbing ([`container`]) and atomic saves ([`save`]). Every
//! size a file declares is bounded before anything is allocated or looped over from it:
//! counts and dimensions in [`header::check_meta`], the describer by
//! [`crate::describe::DescriberModel::validate`] and its limits, keypoints by
//! [`crate::verify::ViewKeypoints::from_parts`].

mod container;
mod describer;
mod descriptors;
mod edges;
mod header;
mod keypoints;
mod places;
mod save;
mod views;

use super::{DescriptorStore, Edge, Map, MapError, ViewRecord};
use crate::describe::describer::DescriberModel;
use crate::descriptor::{DescriptorIdentity, ExpectedDescriptor};
use crate::verify::ViewKeypoints;
use bytes::Bytes;
use container::{decode_f32, OutTensors, TensorReader};
use header::{canonical_json, checksum, FileMeta, META_KEY};
use nalgebra::Point3;
use safetensors::SafeTensors;
use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

/// Value of the `format` field that marks a safetensors file as a topoloc map.
pub const FORMAT_NAME: &str = "topoloc-map";
/// Major format version written and read by this build.
pub const FORMAT_VERSION_MAJOR: u32 = 1;
/// Minor format version written by this build.
pub const FORMAT_VERSION_MINOR: u32 = 5;

pub use crate::descriptor::MAX_DESCRIPTOR_DIM;

/// Options for [`Map::load`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LoadOptions {
    /// Refuse the map (with [`MapError::DescriptorMismatch`]) unless it was built with this descriptor.
    pub expected: ExpectedDescriptor,
}

impl Map {
    /// Serialises the map into the file format described in this module.
    pub fn to_bytes(&self) -> Result<Vec<u8>, MapError> {
        let mut tensors: OutTensors = Vec::new();
        descriptors::write(self, &mut tensors);
        views::write(self, &mut tensors);
        places::write(self, &mut tensors);
        edges::write(self, &mut tensors);
        describer::write(self, &mut tensors);
        keypoints::write(self, &mut tensors);
        tensors.sort_by_key(|(name, _)| *name);

        let meta = FileMeta {
            format: FORMAT_NAME.into(),
            version: format!("{FORMAT_VERSION_MAJOR}.{FORMAT_VERSION_MINOR}"),
            descriptor: self.descriptor().clone(),
            creator: self.creator().into(),
            places: self.place_count() as u64,
            views: self.view_count() as u64,
            edges: self.edge_count() as u64,
            describer: self.describer().map(|m| m.spec.clone()),
            crc32: None,
        };
        let unsigned_json =
            canonical_json(serde_json::to_value(&meta).expect("map metadata serialises"));
        let crc = checksum(&unsigned_json, tensors.iter().map(|(_, t)| &*t.bytes));
        let meta = FileMeta {
            crc32: Some(crc),
            ..meta
        };
        // One key only: safetensors writes metadata from a HashMap, whose order is random.
        let metadata = HashMap::from([(
            META_KEY.to_string(),
            serde_json::to_string(&meta).expect("serialises"),
        )]);
        let bytes =
            safetensors::serialize(tensors.iter().map(|(name, t)| (*name, t)), Some(metadata))
                .map_err(|e| MapError::Invalid(format!("serialising the map failed: {e}")))?;
        header::check_header_fits(&bytes)?;
        Ok(bytes)
    }

    /// Writes the map to `path` atomically: a temporary file in the same directory is written,
    /// flushed to disk and renamed over `path`, so a crash never leaves a partial map behind.
    /// An existing file keeps its permissions (a new one gets the umask's default). Temporary
    /// files are named `.{name}.topoloc-tmp-XXXXXX`; those left by interrupted saves of the
    /// same map are removed after a successful save.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), MapError> {
        let started = std::time::Instant::now();
        let bytes = self.to_bytes()?;
        save::write_atomically(path.as_ref(), &bytes)?;
        log::info!(
            "saved {}: {} places, {} views, {} bytes in {:.1} ms",
            path.as_ref().display(),
            self.place_count(),
            self.view_count(),
            bytes.len(),
            started.elapsed().as_secs_f64() * 1e3
        );
        Ok(())
    }

    /// Loads and validates a map file, memory-mapping it: descriptors are read in place, not
    /// copied. The file must not be modified while the map is alive (topoloc's own `save`
    /// replaces files by rename, which is safe).
    pub fn load(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Map, MapError> {
        let path = path.as_ref();
        let started = std::time::Instant::now();
        let io = |source| MapError::Io {
            path: path.to_path_buf(),
            source,
        };
        let file = std::fs::File::open(path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        if len == 0 {
            return Err(MapError::NotAMap(format!("'{}' is empty", path.display())));
        }
        // SAFETY: the mapping is read-only; see the doc comment on concurrent modification.
        let mmap = Arc::new(unsafe { memmap2::Mmap::map(&file) }.map_err(io)?);
        let shared = Bytes::from_owner(MappedFile(mmap.clone()));
        let parsed = parse(&shared, &|data| shared.slice_ref(data), options)?;
        release_pages(&mmap);
        let descriptors = shared.slice(parsed.descriptor_bytes.clone());
        let aligned = (descriptors.as_ptr() as usize).is_multiple_of(std::mem::align_of::<f32>());
        let store = if aligned && cfg!(target_endian = "little") {
            DescriptorStore::Mapped(descriptors)
        } else {
            DescriptorStore::Owned(decode_f32(&descriptors))
        };
        let map = parsed.into_map(store)?;
        log::info!(
            "loaded {}: {} places, {} views, D = {}, {} bytes{} in {:.1} ms",
            path.display(),
            map.place_count(),
            map.view_count(),
            map.dim(),
            len,
            if aligned {
                " (descriptors mapped)"
            } else {
                " (descriptors copied)"
            },
            started.elapsed().as_secs_f64() * 1e3
        );
        Ok(map)
    }

    /// Parses and validates a map from bytes in the file format (copies the descriptors).
    pub fn from_bytes(bytes: &[u8], options: &LoadOptions) -> Result<Map, MapError> {
        if bytes.is_empty() {
            return Err(MapError::NotAMap("no bytes".into()));
        }
        let parsed = parse(bytes, &Bytes::copy_from_slice, options)?;
        let store = DescriptorStore::Owned(decode_f32(&bytes[parsed.descriptor_bytes.clone()]));
        parsed.into_map(store)
    }
}

/// A mapped map file as the owner of [`Bytes`] views into it (descriptors, i8 PCA rows).
struct MappedFile(Arc<memmap2::Mmap>);

impl AsRef<[u8]> for MappedFile {
    fn as_ref(&self) -> &[u8] {
        &self.0
    }
}

/// Returns the pages of a parsed file to the page cache. The checksum read every page; from
/// now on only the parts the map uses in place (descriptors, i8 PCA rows) are read from the
/// mapping, and they fault back in as frames touch them, so the loaded map's resident pages
/// of the file never exceed the file. Failing to advise costs memory, not correctness (logged).
fn release_pages(mmap: &memmap2::Mmap) {
    #[cfg(unix)]
    // SAFETY: the mapping is a read-only shared file mapping: MADV_DONTNEED only drops the
    // process's page-table entries, and the next read of a page re-reads the file's contents
    // (unchanged while the map lives, see `Map::load`), so views into it stay valid.
    if let Err(e) = unsafe { mmap.unchecked_advise(memmap2::UncheckedAdvice::DontNeed) } {
        log::debug!("madvise(MADV_DONTNEED) on a loaded map failed: {e}");
    }
}

/// Everything read from a file except the descriptor store.
struct ParsedMap {
    identity: DescriptorIdentity,
    creator: String,
    descriptor_bytes: std::ops::Range<usize>,
    views: Vec<ViewRecord>,
    place_positions: Vec<Option<Point3<f64>>>,
    edges: Vec<Edge>,
    describer: Option<DescriberModel>,
    keypoints: Option<ViewKeypoints>,
}

impl ParsedMap {
    fn into_map(self, store: DescriptorStore) -> Result<Map, MapError> {
        Map::from_parts(
            self.identity,
            self.creator,
            store,
            self.views,
            self.place_positions,
            self.edges,
        )
        .and_then(|map| match self.describer {
            Some(model) => map.with_describer(Arc::new(model)),
            None => Ok(map),
        })
        .and_then(|map| match self.keypoints {
            Some(keypoints) => map.with_keypoints(keypoints),
            None => Ok(map),
        })
        .map_err(|e| match e {
            MapError::Invalid(msg) | MapError::InvalidArgument(msg) => MapError::Corrupt(msg),
            MapError::EmptyMap => MapError::Corrupt("the map has no places".into()),
            MapError::DescriptorMismatch { .. } => {
                MapError::Corrupt(format!("the stored describer does not fit the map: {e}"))
            }
            other => other,
        })
    }
}

/// The checksum a file with this metadata (`crc32` taken out) and these tensors must carry:
/// 1.0 checksummed its own struct's serialisation, later versions the generic JSON value.
fn file_checksum(
    st: &SafeTensors<'_>,
    meta: &FileMeta,
    meta_object: serde_json::Value,
) -> Result<String, MapError> {
    let unsigned_json = if meta.version == "1.0" {
        serde_json::to_string(meta).expect("map metadata serialises")
    } else {
        canonical_json(meta_object)
    };
    let mut names: Vec<&str> = st.names();
    names.sort_unstable();
    let tensors: Vec<_> = names
        .iter()
        .map(|n| st.tensor(n))
        .collect::<Result<_, _>>()
        .map_err(|e| MapError::Corrupt(e.to_string()))?;
    Ok(checksum(&unsigned_json, tensors.iter().map(|t| t.data())))
}

/// Rewrites the `crc32` of a file whose framing, metadata and tensor table parse, so that
/// the loader's later checks see it (for the fuzzers' structure-aware mutator and for tests
/// of hostile files: a valid checksum proves nothing). `None` when the file does not get as
/// far as the checksum anyway.
pub fn reseal(bytes: &[u8]) -> Option<Vec<u8>> {
    let meta_json = header::frame(bytes).ok()?;
    let (mut meta, mut meta_object) = header::read_meta(&meta_json).ok()?;
    let st = SafeTensors::deserialize(bytes).ok()?;
    meta.crc32 = None;
    let crc = file_checksum(&st, &meta, meta_object.clone()).ok()?;
    meta_object
        .as_object_mut()?
        .insert("crc32".into(), serde_json::Value::String(crc));
    let header_len = usize::try_from(u64::from_le_bytes(bytes.get(..8)?.try_into().ok()?)).ok()?;
    let data = bytes.get(8usize.checked_add(header_len)?..)?;
    let mut table: serde_json::Value = serde_json::from_slice(&bytes[8..8 + header_len]).ok()?;
    table
        .get_mut("__metadata__")?
        .as_object_mut()?
        .insert(META_KEY.into(), meta_object.to_string().into());
    // `__metadata__` first, as safetensors writes it (the loader's "looks like a map" test).
    let mut tensors = table.as_object()?.clone();
    let metadata = tensors.remove("__metadata__")?;
    let mut header = format!("{{\"__metadata__\":{metadata}");
    for (name, entry) in tensors {
        header.push_str(&format!(",{}:{entry}", serde_json::Value::String(name)));
    }
    header.push('}');
    while header.len() % 8 != 0 {
        header.push(' ');
    }
    let mut out = Vec::with_capacity(8 + header.len() + data.len());
    out.extend_from_slice(&(header.len() as u64).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    Some(out)
}

/// Parses and validates a file: framing and metadata ([`header`]), checksum, then each
/// section.
/// `share` keeps a part of `bytes` that the map uses in place (a view of a mapped file, or a
/// copy).
fn parse(
    bytes: &[u8],
    share: &dyn Fn(&[u8]) -> Bytes,
    options: &LoadOptions,
) -> Result<ParsedMap, MapError> {
    let meta_json = header::frame(bytes)?;
    let (mut meta, meta_object) = header::read_meta(&meta_json)?;
    let st = SafeTensors::deserialize(bytes)
        .map_err(|e| MapError::Corrupt(format!("safetensors: {e}")))?;
    let stored_crc = meta.crc32.take().unwrap_or_default();
    let crc = file_checksum(&st, &meta, meta_object)?;
    if crc != stored_crc {
        return Err(MapError::Corrupt(format!(
            "checksum mismatch (stored '{stored_crc}', computed '{crc}')"
        )));
    }
    header::check_meta(&meta)?;
    meta.descriptor.check_compatible(&options.expected)?;

    // check_meta bounded the counts by u32::MAX and the dimension by MAX_DESCRIPTOR_DIM.
    let reader = TensorReader { st: &st };
    let (n, m, e) = (
        meta.views as usize,
        meta.places as usize,
        meta.edges as usize,
    );
    let d = meta.descriptor.dim as usize;
    Ok(ParsedMap {
        descriptor_bytes: descriptors::read(&reader, bytes, n, d)?,
        views: views::read(&reader, n)?,
        place_positions: places::read(&reader, m)?,
        edges: edges::read(&reader, e)?,
        describer: match meta.describer {
            Some(spec) => Some(describer::read(&reader, spec, d, share)?),
            None => None,
        },
        keypoints: keypoints::read(&reader, n)?,
        identity: meta.descriptor,
        creator: meta.creator,
    })
}
