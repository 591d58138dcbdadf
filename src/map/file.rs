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
//! | `describer_pca_components` | F32 | D x F | (1.1) PCA projection rows |
//! | `describer_codebook` | F32 | K x L | (1.1, VLAD only) codebook of K centres of local descriptors |
//! | `view_keypoint_offsets` | U64 | N+1 | (1.2, optional) ranges of each view's keypoints |
//! | `view_keypoint_points` | F32 | T x 2 | (1.2) keypoint pixel positions x, y |
//! | `view_keypoint_descriptors` | U8 | T x 32 | (1.2) their ORB descriptors |
//! | `view_keypoint_world_points` | F32 | T x 3 | (1.3, optional) map-frame scene point of each keypoint, NaN when unknown |
//!
//! The only metadata key, `topoloc`, holds a JSON object with `format` (`"topoloc-map"`),
//! `version` (`"MAJOR.MINOR"`), `descriptor` (`kind`, `model`, `dim`), `creator`, the counts, and
//! `crc32`: the CRC-32 (hex) of that JSON serialised without `crc32`, followed by every tensor's
//! bytes in tensor-name order, so that any flipped byte is detected. Since 1.1 the JSON may hold
//! `describer` (the backend and its configuration, see [`BackendSpec`]), and the checksummed
//! JSON is the metadata object re-serialised as a generic JSON value without `crc32`, so that
//! fields added by newer minor versions stay covered (1.0 re-serialised its own struct). Readers accept any file of the
//! same major version; a newer minor version may add tensors, which older readers ignore.

use super::{DescriptorStore, Edge, Map, MapError, ViewRecord};
use crate::describe::describer::{BackendSpec, DescriberModel};
use crate::describe::pca::Pca;
use crate::describe::vlad::Codebook;
use crate::descriptor::{DescriptorIdentity, ExpectedDescriptor};
use crate::verify::{Descriptor, ViewKeypoints, DESCRIPTOR_BYTES};
use nalgebra::{Isometry3, Point3, Quaternion, Translation3, UnitQuaternion};
use safetensors::{Dtype, SafeTensors, View};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::collections::HashMap;
use std::io::Write;
use std::path::Path;
use std::sync::Arc;

/// Value of the `format` field that marks a safetensors file as a topoloc map.
pub const FORMAT_NAME: &str = "topoloc-map";
/// Major format version written and read by this build.
pub const FORMAT_VERSION_MAJOR: u32 = 1;
/// Minor format version written by this build.
pub const FORMAT_VERSION_MINOR: u32 = 3;

const META_KEY: &str = "topoloc";
/// Longest JSON header accepted; far above any real map's header (a few hundred bytes).
const MAX_HEADER_BYTES: u64 = 1 << 20;
/// What a topoloc map file's JSON header starts with (safetensors writes `__metadata__` first).
const HEADER_START: &[u8] = b"{\"__metadata__\":{";

const VIEW_HAS_KEYFRAME: u8 = 1;
const VIEW_HAS_POSE: u8 = 2;
const VIEW_HAS_IMAGE: u8 = 4;
const PLACE_HAS_POSITION: u8 = 1;

/// Options for [`Map::load`].
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LoadOptions {
    /// Refuse the map (with [`MapError::DescriptorMismatch`]) unless it was built with this descriptor.
    pub expected: ExpectedDescriptor,
}

#[derive(Serialize, Deserialize)]
struct FileMeta {
    format: String,
    version: String,
    descriptor: DescriptorIdentity,
    creator: String,
    places: u64,
    views: u64,
    edges: u64,
    /// The describer's backend (1.1, maps built from images).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    describer: Option<BackendSpec>,
    /// Absent while the checksum itself is computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    crc32: Option<String>,
}

/// A tensor to write: dtype, shape and its little-endian bytes.
struct OutTensor<'a> {
    dtype: Dtype,
    shape: Vec<usize>,
    bytes: Cow<'a, [u8]>,
}

impl<'a> OutTensor<'a> {
    fn new(dtype: Dtype, shape: Vec<usize>, bytes: Cow<'a, [u8]>) -> Self {
        Self {
            dtype,
            shape,
            bytes,
        }
    }
}

impl View for &OutTensor<'_> {
    fn dtype(&self) -> Dtype {
        self.dtype
    }
    fn shape(&self) -> &[usize] {
        &self.shape
    }
    fn data(&self) -> Cow<'_, [u8]> {
        Cow::Borrowed(&self.bytes)
    }
    fn data_len(&self) -> usize {
        self.bytes.len()
    }
}

fn le_bytes<T: Copy, const W: usize>(
    values: &[T],
    to_le: impl Fn(T) -> [u8; W],
) -> Cow<'static, [u8]> {
    Cow::Owned(values.iter().flat_map(|&v| to_le(v)).collect())
}

fn checksum<'a>(meta_json: &str, tensors_by_name: impl Iterator<Item = &'a [u8]>) -> String {
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(meta_json.as_bytes());
    for bytes in tensors_by_name {
        hasher.update(bytes);
    }
    format!("{:08x}", hasher.finalize())
}

impl Map {
    /// Serialises the map into the file format described in this module.
    pub fn to_bytes(&self) -> Result<Vec<u8>, MapError> {
        let n = self.view_count();
        let m = self.place_count();
        let e = self.edge_count();
        let d = self.dim();

        let descriptor_bytes: Cow<[u8]> = if cfg!(target_endian = "little") {
            let floats = self.descriptors();
            // SAFETY: f32 has no padding or invalid bit patterns; on little-endian targets its
            // in-memory bytes are its little-endian encoding.
            Cow::Borrowed(unsafe {
                std::slice::from_raw_parts(floats.as_ptr().cast::<u8>(), floats.len() * 4)
            })
        } else {
            le_bytes(self.descriptors(), f32::to_le_bytes)
        };

        let views = self.views();
        let view_place: Vec<u32> = views.iter().map(|v| v.place).collect();
        let view_flags: Vec<u8> = views
            .iter()
            .map(|v| {
                let flag = |present: bool, bit: u8| if present { bit } else { 0 };
                flag(v.keyframe_id.is_some(), VIEW_HAS_KEYFRAME)
                    | flag(v.world_t_camera.is_some(), VIEW_HAS_POSE)
                    | flag(v.image.is_some(), VIEW_HAS_IMAGE)
            })
            .collect();
        let view_keyframe: Vec<u64> = views.iter().map(|v| v.keyframe_id.unwrap_or(0)).collect();
        let view_pose: Vec<f64> = views
            .iter()
            .flat_map(|v| pose_to_array(&v.world_t_camera.unwrap_or_else(Isometry3::identity)))
            .collect();
        let mut image_offsets = Vec::with_capacity(n + 1);
        let mut image_bytes = Vec::new();
        image_offsets.push(0u64);
        for v in views {
            image_bytes.extend_from_slice(v.image.as_deref().unwrap_or("").as_bytes());
            image_offsets.push(image_bytes.len() as u64);
        }
        let positions = self.place_positions();
        let place_flags: Vec<u8> = positions
            .iter()
            .map(|p| (p.is_some() as u8) * PLACE_HAS_POSITION)
            .collect();
        let place_position: Vec<f64> = positions
            .iter()
            .flat_map(|p| p.map_or([0.0; 3], |p| [p.x, p.y, p.z]))
            .collect();
        let edges: Vec<u32> = self.edges().iter().flat_map(|e| [e.a, e.b]).collect();
        let edge_weight: Vec<f32> = self.edges().iter().map(|e| e.weight).collect();

        let mut tensors: Vec<(&str, OutTensor)> = vec![
            (
                "descriptors",
                OutTensor::new(Dtype::F32, vec![n, d], descriptor_bytes),
            ),
            (
                "edge_weight",
                OutTensor::new(
                    Dtype::F32,
                    vec![e],
                    le_bytes(&edge_weight, f32::to_le_bytes),
                ),
            ),
            (
                "edges",
                OutTensor::new(Dtype::U32, vec![e, 2], le_bytes(&edges, u32::to_le_bytes)),
            ),
            (
                "place_flags",
                OutTensor::new(Dtype::U8, vec![m], Cow::Owned(place_flags)),
            ),
            (
                "place_position",
                OutTensor::new(
                    Dtype::F64,
                    vec![m, 3],
                    le_bytes(&place_position, f64::to_le_bytes),
                ),
            ),
            (
                "view_flags",
                OutTensor::new(Dtype::U8, vec![n], Cow::Owned(view_flags)),
            ),
            (
                "view_image_bytes",
                OutTensor::new(Dtype::U8, vec![image_bytes.len()], Cow::Owned(image_bytes)),
            ),
            (
                "view_image_offsets",
                OutTensor::new(
                    Dtype::U64,
                    vec![n + 1],
                    le_bytes(&image_offsets, u64::to_le_bytes),
                ),
            ),
            (
                "view_keyframe",
                OutTensor::new(
                    Dtype::U64,
                    vec![n],
                    le_bytes(&view_keyframe, u64::to_le_bytes),
                ),
            ),
            (
                "view_place",
                OutTensor::new(Dtype::U32, vec![n], le_bytes(&view_place, u32::to_le_bytes)),
            ),
            (
                "view_pose",
                OutTensor::new(
                    Dtype::F64,
                    vec![n, 7],
                    le_bytes(&view_pose, f64::to_le_bytes),
                ),
            ),
        ];
        if let Some(model) = self.describer() {
            let pca = &model.pca;
            tensors.push((
                "describer_pca_mean",
                OutTensor::new(
                    Dtype::F32,
                    vec![pca.input_dim],
                    le_bytes(&pca.mean, f32::to_le_bytes),
                ),
            ));
            tensors.push((
                "describer_pca_components",
                OutTensor::new(
                    Dtype::F32,
                    vec![pca.output_dim, pca.input_dim],
                    le_bytes(&pca.components, f32::to_le_bytes),
                ),
            ));
            if let Some(c) = &model.codebook {
                tensors.push((
                    "describer_codebook",
                    OutTensor::new(
                        Dtype::F32,
                        vec![c.clusters, c.dim],
                        le_bytes(&c.centres, f32::to_le_bytes),
                    ),
                ));
            }
        }
        if let Some(k) = self.keypoints() {
            tensors.push((
                "view_keypoint_descriptors",
                OutTensor::new(
                    Dtype::U8,
                    vec![k.total(), DESCRIPTOR_BYTES],
                    Cow::Borrowed(k.descriptors().as_flattened()),
                ),
            ));
            tensors.push((
                "view_keypoint_offsets",
                OutTensor::new(
                    Dtype::U64,
                    vec![n + 1],
                    le_bytes(k.offsets(), u64::to_le_bytes),
                ),
            ));
            tensors.push((
                "view_keypoint_points",
                OutTensor::new(
                    Dtype::F32,
                    vec![k.total(), 2],
                    le_bytes(k.points().as_flattened(), f32::to_le_bytes),
                ),
            ));
            if let Some(world) = k.world_points() {
                tensors.push((
                    "view_keypoint_world_points",
                    OutTensor::new(
                        Dtype::F32,
                        vec![k.total(), 3],
                        le_bytes(world.as_flattened(), f32::to_le_bytes),
                    ),
                ));
            }
        }
        tensors.sort_by_key(|(name, _)| *name);

        let meta = FileMeta {
            format: FORMAT_NAME.into(),
            version: format!("{FORMAT_VERSION_MAJOR}.{FORMAT_VERSION_MINOR}"),
            descriptor: self.descriptor().clone(),
            creator: self.creator().into(),
            places: m as u64,
            views: n as u64,
            edges: e as u64,
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
        safetensors::serialize(tensors.iter().map(|(name, t)| (*name, t)), Some(metadata))
            .map_err(|e| MapError::Invalid(format!("serialising the map failed: {e}")))
    }

    /// Writes the map to `path` atomically: a temporary file in the same directory is written,
    /// flushed to disk and renamed over `path`, so a crash never leaves a partial map behind.
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), MapError> {
        let path = path.as_ref();
        let io = |source| MapError::Io {
            path: path.to_path_buf(),
            source,
        };
        let bytes = self.to_bytes()?;
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        let mut tmp = tempfile::Builder::new()
            .prefix(".topoloc-map-")
            .suffix(".tmp")
            .tempfile_in(dir)
            .map_err(io)?;
        tmp.write_all(&bytes).map_err(io)?;
        tmp.as_file().sync_all().map_err(io)?;
        tmp.persist(path).map_err(|e| io(e.error))?;
        // Make the rename itself durable.
        if let Ok(d) = std::fs::File::open(dir) {
            let _ = d.sync_all();
        }
        Ok(())
    }

    /// Loads and validates a map file, memory-mapping it: descriptors are read in place, not
    /// copied. The file must not be modified while the map is alive (topoloc's own `save`
    /// replaces files by rename, which is safe).
    pub fn load(path: impl AsRef<Path>, options: &LoadOptions) -> Result<Map, MapError> {
        let path = path.as_ref();
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
        let mmap = unsafe { memmap2::Mmap::map(&file) }.map_err(io)?;
        let parsed = parse(&mmap, options)?;
        let range = parsed.descriptor_bytes.clone();
        let aligned = (mmap.as_ptr() as usize + range.start) % std::mem::align_of::<f32>() == 0;
        let store = if aligned && cfg!(target_endian = "little") {
            DescriptorStore::Mapped {
                mmap,
                byte_offset: range.start,
                len: range.len() / 4,
            }
        } else {
            DescriptorStore::Owned(decode_f32(&mmap[range]))
        };
        parsed.into_map(store)
    }

    /// Parses and validates a map from bytes in the file format (copies the descriptors).
    pub fn from_bytes(bytes: &[u8], options: &LoadOptions) -> Result<Map, MapError> {
        if bytes.is_empty() {
            return Err(MapError::NotAMap("no bytes".into()));
        }
        let parsed = parse(bytes, options)?;
        let store = DescriptorStore::Owned(decode_f32(&bytes[parsed.descriptor_bytes.clone()]));
        parsed.into_map(store)
    }
}

fn decode_f32(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect()
}

fn pose_to_array(pose: &Isometry3<f64>) -> [f64; 7] {
    let t = pose.translation.vector;
    let q = pose.rotation.coords; // x, y, z, w
    [t.x, t.y, t.z, q.x, q.y, q.z, q.w]
}

fn pose_from_array(a: &[f64]) -> Result<Isometry3<f64>, String> {
    if !a.iter().all(|x| x.is_finite()) {
        return Err("non-finite pose".into());
    }
    let q = Quaternion::new(a[6], a[3], a[4], a[5]);
    if (q.norm() - 1.0).abs() > 1e-6 {
        return Err(format!("pose quaternion has norm {}, expected 1", q.norm()));
    }
    Ok(Isometry3::from_parts(
        Translation3::new(a[0], a[1], a[2]),
        UnitQuaternion::new_unchecked(q),
    ))
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

/// Serialises a metadata object without its `crc32` field: the checksummed form since 1.1.
fn canonical_json(mut value: serde_json::Value) -> String {
    if let Some(object) = value.as_object_mut() {
        object.remove("crc32");
    }
    value.to_string()
}

/// Reads the describer's arrays (PCA, codebook) for a map of descriptor dimension `dim`.
fn read_describer(
    reader: &TensorReader<'_, '_>,
    spec: BackendSpec,
    dim: usize,
) -> Result<DescriberModel, MapError> {
    let mean = decode_f32(reader.get_any_len("describer_pca_mean", Dtype::F32)?);
    let input_dim = mean.len();
    let components = reader.f32s("describer_pca_components", &[dim, input_dim])?;
    let codebook = match &spec {
        BackendSpec::Vlad(o) => {
            let centres = decode_f32(reader.get_any_len("describer_codebook", Dtype::F32)?);
            let local_dim = input_dim / o.clusters.max(1);
            reader.get("describer_codebook", Dtype::F32, &[o.clusters, local_dim])?;
            Some(
                Codebook::from_parts(o.clusters, local_dim, centres)
                    .map_err(|e| MapError::Corrupt(format!("describer codebook: {e}")))?,
            )
        }
        BackendSpec::Onnx { .. } => None,
    };
    let model = DescriberModel {
        spec,
        pca: Pca {
            input_dim,
            output_dim: dim,
            mean,
            components,
        },
        codebook,
    };
    model
        .validate()
        .map_err(|e| MapError::Corrupt(format!("describer: {e}")))?;
    Ok(model)
}

/// Reads the views' keypoints (1.2) of a map of `views` views, with their scene points (1.3)
/// when `with_world_points`.
fn read_keypoints(
    reader: &TensorReader<'_, '_>,
    views: usize,
    with_world_points: bool,
) -> Result<ViewKeypoints, MapError> {
    let offsets = reader.u64s("view_keypoint_offsets", &[views + 1])?;
    let total = offsets.last().copied().unwrap_or(0) as usize;
    let points = reader.f32s("view_keypoint_points", &[total, 2])?;
    let descriptors = reader.get(
        "view_keypoint_descriptors",
        Dtype::U8,
        &[total, DESCRIPTOR_BYTES],
    )?;
    let descriptors: Vec<Descriptor> = descriptors
        .chunks_exact(DESCRIPTOR_BYTES)
        .map(|c| c.try_into().expect("32 bytes"))
        .collect();
    let points = points.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
    let corrupt = |e| MapError::Corrupt(format!("view keypoints: {e}"));
    let keypoints = ViewKeypoints::from_parts(offsets, points, descriptors).map_err(corrupt)?;
    if !with_world_points {
        return Ok(keypoints);
    }
    let world = reader.f32s("view_keypoint_world_points", &[total, 3])?;
    let world = world.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    keypoints.with_world_points(world).map_err(corrupt)
}

/// Decides whether a damaged header still looks like the start of a topoloc map, which tells a
/// truncated or corrupt map apart from some other file.
fn starts_like_map(bytes: &[u8]) -> bool {
    let Some(header) = bytes.get(8..) else {
        return true;
    };
    let n = header.len().min(HEADER_START.len());
    header[..n] == HEADER_START[..n]
}

fn parse(bytes: &[u8], options: &LoadOptions) -> Result<ParsedMap, MapError> {
    let len = bytes.len();
    if len < 8 {
        return Err(MapError::Truncated(format!(
            "{len} bytes, shorter than the 8-byte header length"
        )));
    }
    let header_len = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
    if !(2..=MAX_HEADER_BYTES).contains(&header_len) {
        return Err(if starts_like_map(bytes) && header_len > MAX_HEADER_BYTES {
            MapError::Corrupt(format!("implausible header length {header_len}"))
        } else {
            MapError::NotAMap(format!(
                "implausible safetensors header length {header_len}"
            ))
        });
    }
    let header_end = 8 + header_len as usize;
    if len < header_end {
        return Err(if starts_like_map(bytes) {
            MapError::Truncated(format!(
                "{len} bytes, but the header alone needs {header_end}"
            ))
        } else {
            MapError::NotAMap("not a safetensors file".into())
        });
    }
    let header: serde_json::Value = match serde_json::from_slice(&bytes[8..header_end]) {
        Ok(v) => v,
        Err(e) if starts_like_map(bytes) => {
            return Err(MapError::Corrupt(format!("header is not valid JSON: {e}")))
        }
        Err(_) => return Err(MapError::NotAMap("not a safetensors file".into())),
    };
    let meta_value = header
        .get("__metadata__")
        .and_then(|m| m.get(META_KEY))
        .and_then(|v| v.as_str());
    let Some(meta_json) = meta_value else {
        return Err(MapError::NotAMap(
            "safetensors file without topoloc metadata".into(),
        ));
    };
    let data_end = header
        .as_object()
        .into_iter()
        .flatten()
        .filter(|(k, _)| k.as_str() != "__metadata__")
        .filter_map(|(_, t)| t.get("data_offsets")?.get(1)?.as_u64())
        .max()
        .unwrap_or(0);
    let expected_len = header_end as u64 + data_end;
    if (len as u64) < expected_len {
        return Err(MapError::Truncated(format!(
            "{len} bytes, the header promises {expected_len}"
        )));
    }
    if (len as u64) > expected_len {
        return Err(MapError::Corrupt(format!(
            "{} unexpected bytes after the data",
            len as u64 - expected_len
        )));
    }

    let meta_object: serde_json::Value = serde_json::from_str(meta_json)
        .map_err(|e| MapError::Corrupt(format!("topoloc metadata: {e}")))?;
    let mut meta: FileMeta = serde_json::from_value(meta_object.clone())
        .map_err(|e| MapError::Corrupt(format!("topoloc metadata: {e}")))?;
    if meta.format != FORMAT_NAME {
        return Err(MapError::NotAMap(format!(
            "format is '{}', not '{FORMAT_NAME}'",
            meta.format
        )));
    }
    let major: u32 = meta
        .version
        .split('.')
        .next()
        .and_then(|m| m.parse().ok())
        .ok_or_else(|| {
            MapError::Corrupt(format!("unreadable format version '{}'", meta.version))
        })?;
    if major > FORMAT_VERSION_MAJOR {
        return Err(MapError::UnsupportedVersion {
            found: meta.version,
            supported: FORMAT_VERSION_MAJOR,
        });
    }

    let st = SafeTensors::deserialize(bytes)
        .map_err(|e| MapError::Corrupt(format!("safetensors: {e}")))?;
    let stored_crc = meta.crc32.take().unwrap_or_default();
    let unsigned_json = if meta.version == "1.0" {
        serde_json::to_string(&meta).expect("map metadata serialises")
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
    let crc = checksum(&unsigned_json, tensors.iter().map(|t| t.data()));
    if crc != stored_crc {
        return Err(MapError::Corrupt(format!(
            "checksum mismatch (stored '{stored_crc}', computed '{crc}')"
        )));
    }
    meta.descriptor.check_compatible(&options.expected)?;

    let reader = TensorReader { st: &st };
    let (n, m, e) = (
        meta.views as usize,
        meta.places as usize,
        meta.edges as usize,
    );
    let d = meta.descriptor.dim as usize;
    let descriptors = reader.get("descriptors", Dtype::F32, &[n, d])?;
    let base = bytes.as_ptr() as usize;
    let descriptor_bytes = descriptors.as_ptr() as usize - base
        ..descriptors.as_ptr() as usize - base + descriptors.len();

    let view_place = reader.u32s("view_place", &[n])?;
    let view_flags = reader.get("view_flags", Dtype::U8, &[n])?;
    let view_keyframe = reader.u64s("view_keyframe", &[n])?;
    let view_pose = reader.f64s("view_pose", &[n, 7])?;
    let image_offsets = reader.u64s("view_image_offsets", &[n + 1])?;
    let image_bytes = reader.get_any_len("view_image_bytes", Dtype::U8)?;
    let mut views = Vec::with_capacity(n);
    for v in 0..n {
        let flags = view_flags[v];
        let world_t_camera = if flags & VIEW_HAS_POSE != 0 {
            Some(
                pose_from_array(&view_pose[v * 7..v * 7 + 7])
                    .map_err(|e| MapError::Corrupt(format!("view {v}: {e}")))?,
            )
        } else {
            None
        };
        let image = if flags & VIEW_HAS_IMAGE != 0 {
            let (a, b) = (image_offsets[v] as usize, image_offsets[v + 1] as usize);
            let slice = image_bytes.get(a..b).filter(|_| a <= b).ok_or_else(|| {
                MapError::Corrupt(format!("view {v}: image reference out of range"))
            })?;
            Some(String::from_utf8(slice.to_vec()).map_err(|_| {
                MapError::Corrupt(format!("view {v}: image reference is not UTF-8"))
            })?)
        } else {
            None
        };
        views.push(ViewRecord {
            place: view_place[v],
            keyframe_id: (flags & VIEW_HAS_KEYFRAME != 0).then_some(view_keyframe[v]),
            world_t_camera,
            image,
        });
    }

    let place_flags = reader.get("place_flags", Dtype::U8, &[m])?;
    let place_position = reader.f64s("place_position", &[m, 3])?;
    let place_positions = (0..m)
        .map(|p| {
            (place_flags[p] & PLACE_HAS_POSITION != 0).then(|| {
                Point3::new(
                    place_position[3 * p],
                    place_position[3 * p + 1],
                    place_position[3 * p + 2],
                )
            })
        })
        .collect();

    let edge_ids = reader.u32s("edges", &[e, 2])?;
    let edge_weight = reader.f32s("edge_weight", &[e])?;
    let edges = (0..e)
        .map(|i| Edge {
            a: edge_ids[2 * i],
            b: edge_ids[2 * i + 1],
            weight: edge_weight[i],
        })
        .collect();

    let describer = match meta.describer {
        Some(spec) => Some(read_describer(&reader, spec, d)?),
        None => None,
    };

    let keypoints = if names.contains(&"view_keypoint_offsets") {
        let with_world_points = names.contains(&"view_keypoint_world_points");
        Some(read_keypoints(&reader, n, with_world_points)?)
    } else {
        None
    };

    Ok(ParsedMap {
        identity: meta.descriptor,
        creator: meta.creator,
        describer,
        keypoints,
        descriptor_bytes,
        views,
        place_positions,
        edges,
    })
}

/// Typed access to the tensors of a parsed file, with shape checks that name the tensor.
struct TensorReader<'a, 'data> {
    st: &'a SafeTensors<'data>,
}

impl<'data> TensorReader<'_, 'data> {
    fn get_any_len(&self, name: &str, dtype: Dtype) -> Result<&'data [u8], MapError> {
        let t = self
            .st
            .tensor(name)
            .map_err(|_| MapError::Corrupt(format!("tensor '{name}' is missing")))?;
        if t.dtype() != dtype {
            return Err(MapError::Corrupt(format!(
                "tensor '{name}' has dtype {:?}, expected {dtype:?}",
                t.dtype()
            )));
        }
        Ok(t.data())
    }

    fn get(&self, name: &str, dtype: Dtype, shape: &[usize]) -> Result<&'data [u8], MapError> {
        let data = self.get_any_len(name, dtype)?;
        let found = self
            .st
            .tensor(name)
            .expect("checked above")
            .shape()
            .to_vec();
        if found != shape {
            return Err(MapError::Corrupt(format!(
                "tensor '{name}' has shape {found:?}, expected {shape:?}"
            )));
        }
        Ok(data)
    }

    fn u32s(&self, name: &str, shape: &[usize]) -> Result<Vec<u32>, MapError> {
        Ok(self
            .get(name, Dtype::U32, shape)?
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4")))
            .collect())
    }

    fn u64s(&self, name: &str, shape: &[usize]) -> Result<Vec<u64>, MapError> {
        Ok(self
            .get(name, Dtype::U64, shape)?
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().expect("8")))
            .collect())
    }

    fn f32s(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, MapError> {
        Ok(decode_f32(self.get(name, Dtype::F32, shape)?))
    }

    fn f64s(&self, name: &str, shape: &[usize]) -> Result<Vec<f64>, MapError> {
        Ok(self
            .get(name, Dtype::F64, shape)?
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8")))
            .collect())
    }
}
