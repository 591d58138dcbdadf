//! Conversions between C representations (row-major 4x4 pose arrays, optional strings) and the
//! Rust types of the core.

use super::boundary::slice;
use super::error::FfiError;
use crate::descriptor::ExpectedDescriptor;
use crate::verify::PinholeCamera;
use nalgebra::{Isometry3, Matrix3, Rotation3, Translation3, UnitQuaternion};
use std::ffi::c_char;

/// Largest deviation from orthonormality accepted in a rotation block.
const ROTATION_TOLERANCE: f64 = 1e-6;

/// Reads an optional rigid transform given as 16 doubles, row-major 4x4 `[R t; 0 0 0 1]`.
/// NULL means "none". The rotation block must be orthonormal with determinant +1.
pub(crate) fn optional_pose(
    ptr: *const f64,
    name: &str,
) -> Result<Option<Isometry3<f64>>, FfiError> {
    if ptr.is_null() {
        return Ok(None);
    }
    let m = slice(ptr, 16, name)?;
    if !m.iter().all(|x| x.is_finite()) {
        return Err(FfiError::new(
            super::topoloc_status::TOPOLOC_ERR_NON_FINITE,
            format!("'{name}' has a NaN or infinite value"),
        ));
    }
    let r = Matrix3::new(m[0], m[1], m[2], m[4], m[5], m[6], m[8], m[9], m[10]);
    let orthonormal = (r.transpose() * r - Matrix3::identity()).abs().max() < ROTATION_TOLERANCE;
    if !orthonormal || r.determinant() < 0.0 {
        return Err(FfiError::invalid(format!(
            "'{name}' rotation block is not a rotation (orthonormal, det +1)"
        )));
    }
    if m[12] != 0.0 || m[13] != 0.0 || m[14] != 0.0 || m[15] != 1.0 {
        return Err(FfiError::invalid(format!(
            "'{name}' last row must be 0 0 0 1"
        )));
    }
    let rotation = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(r));
    Ok(Some(Isometry3::from_parts(
        Translation3::new(m[3], m[7], m[11]),
        rotation,
    )))
}

/// Writes a rigid transform as 16 doubles, row-major 4x4.
pub(crate) fn pose_to_row_major(pose: &Isometry3<f64>) -> [f64; 16] {
    let h = pose.to_homogeneous();
    std::array::from_fn(|i| h[(i / 4, i % 4)])
}

/// Pinhole intrinsics from C fields, where `fx == 0` means none (validated by the options
/// that hold them).
pub(crate) fn optional_camera(fx: f64, fy: f64, cx: f64, cy: f64) -> Option<PinholeCamera> {
    (fx != 0.0).then_some(PinholeCamera { fx, fy, cx, cy })
}

/// Builds an [`ExpectedDescriptor`] from optional C strings and a dimension (0 = any).
pub(crate) fn expected_descriptor(
    kind: *const c_char,
    model: *const c_char,
    dim: u32,
) -> Result<ExpectedDescriptor, FfiError> {
    Ok(ExpectedDescriptor {
        kind: super::boundary::optional_string(kind, "expected_descriptor_kind")?,
        model: super::boundary::optional_string(model, "expected_descriptor_model")?,
        dim: (dim != 0).then_some(dim),
    })
}
