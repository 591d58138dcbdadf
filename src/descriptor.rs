//! What a global descriptor is: the identity of the descriptor space a map was built in
//! ([`DescriptorIdentity`], what a caller expects: [`ExpectedDescriptor`]) and the checks every
//! descriptor vector passes ([`normalize_descriptor_into`], [`DescriptorError`]).
//!
//! Near the bottom of the layer order (see the crate documentation): it imports only
//! [`crate::bounds`].

use crate::bounds::Bounds;
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use serde::{Deserialize, Serialize};

/// Largest descriptor dimension D a map or a loop detector may have (built or loaded): 65,536
/// floats are 256 KB per view, 128 times the default describer's 512 and far above any global
/// descriptor in use (NetVLAD 4096; MLF before PCA, 27,648, is not stored), so a larger one is
/// a mistake or a corrupt file.
pub const MAX_DESCRIPTOR_DIM: u32 = 1 << 16;

/// Longest descriptor kind, bytes of UTF-8 (a family name: `"onnx-mlf"`, `"vlad-orb"`).
pub const MAX_DESCRIPTOR_KIND_BYTES: usize = 256;
/// Longest descriptor model identity, bytes of UTF-8 (a describer's is about 100): with the
/// kind, it fits a map file's header however it is escaped, so a map that saves also loads.
pub const MAX_DESCRIPTOR_MODEL_BYTES: usize = 4096;

/// Tolerance on `| ||x|| - 1 |` for a stored descriptor to count as L2-normalised.
pub const NORM_TOLERANCE: f32 = 1e-3;

/// Which descriptor produced a map's vectors. A query described by anything else is refused,
/// because similarities between different descriptor spaces mean nothing.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DescriptorIdentity {
    /// Backend family, e.g. `"onnx-mlf"`, `"vlad-orb"`, or a host-chosen name for external vectors.
    pub kind: String,
    /// Model identity within the family: file hash, taps, preprocessing; free text.
    pub model: String,
    /// Descriptor dimension D.
    pub dim: u32,
}

impl DescriptorIdentity {
    /// Creates an identity; `kind` must be non-empty and at most [`MAX_DESCRIPTOR_KIND_BYTES`],
    /// `model` at most [`MAX_DESCRIPTOR_MODEL_BYTES`], and `dim` in [`Self::DIM_RANGE`].
    pub fn new(
        kind: impl Into<String>,
        model: impl Into<String>,
        dim: u32,
    ) -> Result<Self, IdentityError> {
        let identity = Self {
            kind: kind.into(),
            model: model.into(),
            dim,
        };
        identity.validate()?;
        Ok(identity)
    }

    /// Accepted values of [`Self::dim`].
    pub const DIM_RANGE: Bounds = Bounds::whole(1, MAX_DESCRIPTOR_DIM as u64);

    pub(crate) fn validate(&self) -> Result<(), IdentityError> {
        if self.kind.is_empty() {
            return Err(IdentityError::Invalid(
                "descriptor kind must not be empty".into(),
            ));
        }
        for (name, value, max) in [
            ("kind", &self.kind, MAX_DESCRIPTOR_KIND_BYTES),
            ("model", &self.model, MAX_DESCRIPTOR_MODEL_BYTES),
        ] {
            if value.len() > max {
                return Err(IdentityError::Invalid(format!(
                    "descriptor {name} is {} bytes, at most {max}",
                    value.len()
                )));
            }
        }
        Self::DIM_RANGE
            .check("descriptor dimension", self.dim)
            .map_err(IdentityError::Invalid)
    }

    /// Checks that a query described by `expected` may be compared with this map's vectors.
    /// Empty `kind`/`model` and zero `dim` in `expected` mean "any".
    pub fn check_compatible(&self, expected: &ExpectedDescriptor) -> Result<(), IdentityError> {
        let kind_ok = expected.kind.as_deref().is_none_or(|k| k == self.kind);
        let model_ok = expected.model.as_deref().is_none_or(|m| m == self.model);
        let dim_ok = expected.dim.is_none_or(|d| d == self.dim);
        if kind_ok && model_ok && dim_ok {
            Ok(())
        } else {
            Err(IdentityError::Mismatch {
                map: self.clone(),
                expected: expected.clone(),
            })
        }
    }
}

impl std::fmt::Display for DescriptorIdentity {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} (model '{}', D={})", self.kind, self.model, self.dim)
    }
}

/// What a caller's descriptor is; each `None` field matches anything.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExpectedDescriptor {
    /// Required backend family.
    pub kind: Option<String>,
    /// Required model identity.
    pub model: Option<String>,
    /// Required dimension.
    pub dim: Option<u32>,
}

impl std::fmt::Display for ExpectedDescriptor {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let any = |s: &Option<String>| s.clone().unwrap_or_else(|| "*".into());
        let dim = self.dim.map_or_else(|| "*".into(), |d| d.to_string());
        write!(
            f,
            "{} (model '{}', D={})",
            any(&self.kind),
            any(&self.model),
            dim
        )
    }
}

/// A descriptor identity that is malformed, or that does not fit what a caller expects.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum IdentityError {
    /// Empty kind or zero dimension; the message says which.
    #[error("invalid descriptor identity: {0}")]
    Invalid(String),
    /// The map's descriptor is not the one the caller expects.
    #[error("descriptor mismatch: the map holds {map}, the caller expects {expected}")]
    Mismatch {
        /// The map's descriptor.
        map: DescriptorIdentity,
        /// What the caller asked for.
        expected: ExpectedDescriptor,
    },
}

/// Checks that a stored descriptor is finite and has unit L2 norm.
pub(crate) fn check_unit_descriptor(row: &[f32]) -> Result<(), String> {
    let mut sum = 0.0f32;
    for &x in row {
        if !x.is_finite() {
            return Err("descriptor has a NaN or infinite value".into());
        }
        sum += x * x;
    }
    let norm = sum.sqrt();
    if (norm - 1.0).abs() > NORM_TOLERANCE {
        return Err(format!(
            "descriptor norm is {norm}, expected 1 (L2-normalised)"
        ));
    }
    Ok(())
}

/// Returns a unit-norm copy of `descriptor`, or an error naming what is wrong with it
/// (wrong length, NaN/Inf, all zeros). Writes into `out` so that per-frame callers reuse a buffer.
pub fn normalize_descriptor_into(
    descriptor: &[f32],
    dim: usize,
    out: &mut Vec<f32>,
) -> Result<(), DescriptorError> {
    if descriptor.len() != dim {
        return Err(DescriptorError::Dimension {
            got: descriptor.len(),
            expected: dim,
        });
    }
    let mut sum = 0.0f64;
    for &x in descriptor {
        if !x.is_finite() {
            return Err(DescriptorError::NonFinite);
        }
        sum += f64::from(x) * f64::from(x);
    }
    // In f64 even the smallest subnormal f32 squares to a positive number: only zeros give 0.
    if sum == 0.0 {
        return Err(DescriptorError::Zero);
    }
    let inv = 1.0 / sum.sqrt();
    out.clear();
    out.extend(descriptor.iter().map(|&x| (f64::from(x) * inv) as f32));
    Ok(())
}

/// What is wrong with a descriptor given by a caller.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DescriptorError {
    /// Length differs from the map's D.
    #[error("descriptor has {got} values, the map's descriptor has D={expected}")]
    Dimension {
        /// Values given.
        got: usize,
        /// The map's D.
        expected: usize,
    },
    /// Contains NaN or infinity.
    #[error("descriptor contains NaN or infinite values")]
    NonFinite,
    /// All values are (close to) zero, so it has no direction.
    #[error("descriptor is all zeros")]
    Zero,
}

/// Computes `out[r] = <rows[r], query>` for every row of the row-major `rows.len() / dim x dim`
/// matrix with one faer matrix-vector product (single-threaded). With unit-norm rows and query
/// this is the cosine similarity. Cost: one pass over the matrix (memory-bound).
pub(crate) fn row_similarities(rows: &[f32], dim: usize, query: &[f32], out: &mut [f32]) {
    let n = out.len();
    debug_assert_eq!(query.len(), dim);
    debug_assert_eq!(rows.len(), n * dim);
    let lhs = MatRef::from_row_major_slice(rows, n, dim);
    let rhs = MatRef::from_column_major_slice(query, dim, 1);
    let dst = MatMut::from_column_major_slice_mut(out, n, 1);
    matmul(dst, Accum::Replace, lhs, rhs, 1.0f32, Par::Seq);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_identity_needs_a_kind_and_a_dimension_up_to_the_bound() {
        assert!(DescriptorIdentity::new("k", "m", 1).is_ok());
        assert!(DescriptorIdentity::new("k", "m", MAX_DESCRIPTOR_DIM).is_ok());
        for dim in [0, MAX_DESCRIPTOR_DIM + 1, 1 << 30, u32::MAX] {
            let err = DescriptorIdentity::new("k", "m", dim).unwrap_err();
            assert!(err.to_string().contains("dimension"), "{err}");
        }
        assert!(DescriptorIdentity::new("", "m", 4).is_err());
    }
}
