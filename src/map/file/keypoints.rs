//! Sections `view_keypoint_*` (1.2): each view's ORB keypoints, (1.3) their scene points, and
//! (1.4) XFeat or dense-cell descriptors in place of ORB ones (`view_keypoint_xfeat`, I8,
//! total x 64; `view_keypoint_cells`, I8, total x 96).

use super::container::{le_bytes, OutTensor, OutTensors, TensorReader};
use crate::map::{Map, MapError};
use crate::verify::{
    Descriptors, ViewKeypoints, CELL_DIM, DESCRIPTOR_BYTES, MAX_KEYPOINTS, XFEAT_DIM,
};
use safetensors::Dtype;

/// Name of the ORB descriptor tensor (U8, total x 32).
const ORB_TENSOR: &str = "view_keypoint_descriptors";
/// Name of the XFeat descriptor tensor (I8, total x 64), since 1.4.
const XFEAT_TENSOR: &str = "view_keypoint_xfeat";
/// Name of the dense-cell descriptor tensor (I8, total x 96), since 1.4.
const CELLS_TENSOR: &str = "view_keypoint_cells";

/// Adds `view_keypoint_offsets`, `view_keypoint_points`, the descriptors (`_descriptors` for
/// ORB, `_xfeat` for XFeat) and, when stored, `view_keypoint_world_points`.
pub(super) fn write<'a>(map: &'a Map, out: &mut OutTensors<'a>) {
    let Some(k) = map.keypoints() else {
        return;
    };
    let (name, dtype) = match k.descriptors() {
        Descriptors::Orb(_) => (ORB_TENSOR, Dtype::U8),
        Descriptors::XFeat(_) => (XFEAT_TENSOR, Dtype::I8),
        Descriptors::Cells(_) => (CELLS_TENSOR, Dtype::I8),
    };
    out.push((
        name,
        OutTensor::new(
            dtype,
            vec![k.total(), k.descriptors().row_bytes()],
            k.descriptors().to_bytes(),
        ),
    ));
    out.push((
        "view_keypoint_offsets",
        OutTensor::new(
            Dtype::U64,
            vec![map.view_count() + 1],
            le_bytes(k.offsets(), u64::to_le_bytes),
        ),
    ));
    out.push((
        "view_keypoint_points",
        OutTensor::new(
            Dtype::F32,
            vec![k.total(), 2],
            le_bytes(k.points().as_flattened(), f32::to_le_bytes),
        ),
    ));
    if let Some(world) = k.world_points() {
        out.push((
            "view_keypoint_world_points",
            OutTensor::new(
                Dtype::F32,
                vec![k.total(), 3],
                le_bytes(world.as_flattened(), f32::to_le_bytes),
            ),
        ));
    }
}

/// Reads the keypoints of a map of `views` views, if it stores them.
pub(super) fn read(
    reader: &TensorReader<'_, '_>,
    views: usize,
) -> Result<Option<ViewKeypoints>, MapError> {
    if !reader.has("view_keypoint_offsets") {
        return Ok(None);
    }
    let offsets = reader.u64s("view_keypoint_offsets", &[views + 1])?;
    let total = offsets.last().copied().unwrap_or(0);
    let most = (views as u64).saturating_mul(MAX_KEYPOINTS as u64);
    if total > most {
        return Err(MapError::Corrupt(format!(
            "view keypoints: {total} keypoints in {views} views, more than {MAX_KEYPOINTS} per view"
        )));
    }
    let total = total as usize;
    let points = reader.f32s("view_keypoint_points", &[total, 2])?;
    let descriptors = read_descriptors(reader, total)?;
    let points = points.chunks_exact(2).map(|p| [p[0], p[1]]).collect();
    let corrupt = |e| MapError::Corrupt(format!("view keypoints: {e}"));
    let keypoints = ViewKeypoints::from_parts(offsets, points, descriptors).map_err(corrupt)?;
    if !reader.has("view_keypoint_world_points") {
        return Ok(Some(keypoints));
    }
    let world = reader.f32s("view_keypoint_world_points", &[total, 3])?;
    let world = world.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
    keypoints
        .with_world_points(world)
        .map(Some)
        .map_err(corrupt)
}

/// The keypoint descriptors: exactly one of the ORB, XFeat and cell tensors, `total` rows.
fn read_descriptors(reader: &TensorReader<'_, '_>, total: usize) -> Result<Descriptors, MapError> {
    let present: Vec<&str> = [ORB_TENSOR, XFEAT_TENSOR, CELLS_TENSOR]
        .into_iter()
        .filter(|name| reader.has(name))
        .collect();
    match present[..] {
        [ORB_TENSOR] => {
            let bytes = reader.get(ORB_TENSOR, Dtype::U8, &[total, DESCRIPTOR_BYTES])?;
            Ok(Descriptors::Orb(rows(bytes, |b| b)))
        }
        [XFEAT_TENSOR] => {
            let bytes = reader.get(XFEAT_TENSOR, Dtype::I8, &[total, XFEAT_DIM])?;
            Ok(Descriptors::XFeat(rows(bytes, |b| b as i8)))
        }
        [CELLS_TENSOR] => {
            let bytes = reader.get(CELLS_TENSOR, Dtype::I8, &[total, CELL_DIM])?;
            Ok(Descriptors::Cells(rows(bytes, |b| b as i8)))
        }
        [] => Err(MapError::Corrupt(format!(
            "view keypoints: offsets but no descriptors ({ORB_TENSOR}, {XFEAT_TENSOR} or {CELLS_TENSOR})"
        ))),
        _ => Err(MapError::Corrupt(format!(
            "view keypoints: {present:?} are all present; a map stores one kind"
        ))),
    }
}

/// Rows of `N` values converted from the bytes of a tensor (whose shape was checked).
fn rows<T: Copy + Default, const N: usize>(bytes: &[u8], convert: impl Fn(u8) -> T) -> Vec<[T; N]> {
    bytes
        .chunks_exact(N)
        .map(|c| std::array::from_fn(|i| convert(c[i])))
        .collect()
}
