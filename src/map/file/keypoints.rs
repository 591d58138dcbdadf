//! Sections `view_keypoint_*` (1.2): each view's ORB keypoints, (1.3) their scene points, and
//! (1.4) XFeat descriptors in place of ORB ones (`view_keypoint_xfeat`, I8, total x 64).

use super::container::{le_bytes, OutTensor, OutTensors, TensorReader};
use crate::map::{Map, MapError};
use crate::verify::{
    Descriptors, ViewKeypoints, XFeatDescriptor, DESCRIPTOR_BYTES, MAX_KEYPOINTS, XFEAT_DIM,
};
use safetensors::Dtype;

/// Name of the ORB descriptor tensor (U8, total x 32).
const ORB_TENSOR: &str = "view_keypoint_descriptors";
/// Name of the XFeat descriptor tensor (I8, total x 64), since 1.4.
pub(super) const XFEAT_TENSOR: &str = "view_keypoint_xfeat";

/// Adds `view_keypoint_offsets`, `view_keypoint_points`, the descriptors (`_descriptors` for
/// ORB, `_xfeat` for XFeat) and, when stored, `view_keypoint_world_points`.
pub(super) fn write<'a>(map: &'a Map, out: &mut OutTensors<'a>) {
    let Some(k) = map.keypoints() else {
        return;
    };
    let (name, dtype) = match k.descriptors() {
        Descriptors::Orb(_) => (ORB_TENSOR, Dtype::U8),
        Descriptors::XFeat(_) => (XFEAT_TENSOR, Dtype::I8),
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

/// The keypoint descriptors: exactly one of the ORB and the XFeat tensor, `total` rows.
fn read_descriptors(reader: &TensorReader<'_, '_>, total: usize) -> Result<Descriptors, MapError> {
    match (reader.has(ORB_TENSOR), reader.has(XFEAT_TENSOR)) {
        (true, false) => {
            let bytes = reader.get(ORB_TENSOR, Dtype::U8, &[total, DESCRIPTOR_BYTES])?;
            Ok(Descriptors::Orb(
                bytes
                    .chunks_exact(DESCRIPTOR_BYTES)
                    .map(|c| c.try_into().expect("32 bytes"))
                    .collect(),
            ))
        }
        (false, true) => {
            let bytes = reader.get(XFEAT_TENSOR, Dtype::I8, &[total, XFEAT_DIM])?;
            Ok(Descriptors::XFeat(
                bytes
                    .chunks_exact(XFEAT_DIM)
                    .map(|c| {
                        let mut row: XFeatDescriptor = [0; XFEAT_DIM];
                        for (out, &b) in row.iter_mut().zip(c) {
                            *out = b as i8;
                        }
                        row
                    })
                    .collect(),
            ))
        }
        (true, true) => Err(MapError::Corrupt(format!(
            "view keypoints: both {ORB_TENSOR} and {XFEAT_TENSOR} are present; a map stores one kind"
        ))),
        (false, false) => Err(MapError::Corrupt(format!(
            "view keypoints: offsets but neither {ORB_TENSOR} nor {XFEAT_TENSOR}"
        ))),
    }
}
