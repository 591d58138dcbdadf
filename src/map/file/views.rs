//! Section `view_*`: each view's place, flags, keyframe id, pose and image reference.

use super::container::{le_bytes, OutTensor, OutTensors, TensorReader};
use super::header::check_no_nul;
use crate::map::{Map, MapError, ViewRecord};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion};
use safetensors::Dtype;
use std::borrow::Cow;

const VIEW_HAS_KEYFRAME: u8 = 1;
const VIEW_HAS_POSE: u8 = 2;
const VIEW_HAS_IMAGE: u8 = 4;

/// Adds `view_place`, `view_flags`, `view_keyframe`, `view_pose`, `view_image_offsets` and
/// `view_image_bytes`.
pub(super) fn write(map: &Map, out: &mut OutTensors<'_>) {
    let views = map.views();
    let n = views.len();
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
    out.extend([
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
    ]);
}

/// Reads the records of `n` views (`n` at most `u32::MAX`, checked with the metadata).
pub(super) fn read(reader: &TensorReader<'_, '_>, n: usize) -> Result<Vec<ViewRecord>, MapError> {
    let view_place = reader.u32s("view_place", &[n])?;
    let view_flags = reader.get("view_flags", Dtype::U8, &[n])?;
    let view_keyframe = reader.u64s("view_keyframe", &[n])?;
    let view_pose = reader.f64s("view_pose", &[n, 7])?;
    let image_offsets = reader.u64s("view_image_offsets", &[n + 1])?;
    let image_bytes = reader.get_any_len("view_image_bytes", Dtype::U8)?;
    // Every array above holds n entries backed by the file's bytes: n is bounded by the file.
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
            let range = (image_offsets[v], image_offsets[v + 1]);
            Some(read_image_reference(image_bytes, range, v)?)
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
    Ok(views)
}

/// View `v`'s image reference: bytes `a..b` of `image_bytes`, UTF-8 without NUL.
fn read_image_reference(
    image_bytes: &[u8],
    (a, b): (u64, u64),
    v: usize,
) -> Result<String, MapError> {
    let (a, b) = (
        usize::try_from(a).unwrap_or(usize::MAX),
        usize::try_from(b).unwrap_or(usize::MAX),
    );
    let slice = image_bytes
        .get(a..b)
        .filter(|_| a <= b)
        .ok_or_else(|| MapError::Corrupt(format!("view {v}: image reference out of range")))?;
    let image = String::from_utf8(slice.to_vec())
        .map_err(|_| MapError::Corrupt(format!("view {v}: image reference is not UTF-8")))?;
    check_no_nul(&image, &format!("view {v}: image reference"))?;
    Ok(image)
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
