//! Sections `view_keypoint_*` (1.2): each view's ORB keypoints, and (1.3) their scene points.

use super::container::{le_bytes, OutTensor, OutTensors, TensorReader};
use crate::map::{Map, MapError};
use crate::verify::{Descriptor, ViewKeypoints, DESCRIPTOR_BYTES, MAX_KEYPOINTS};
use safetensors::Dtype;
use std::borrow::Cow;

/// Adds `view_keypoint_offsets`, `view_keypoint_points`, `view_keypoint_descriptors` and, when
/// stored, `view_keypoint_world_points`.
pub(super) fn write<'a>(map: &'a Map, out: &mut OutTensors<'a>) {
    let Some(k) = map.keypoints() else {
        return;
    };
    out.push((
        "view_keypoint_descriptors",
        OutTensor::new(
            Dtype::U8,
            vec![k.total(), DESCRIPTOR_BYTES],
            Cow::Borrowed(k.descriptors().as_flattened()),
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
