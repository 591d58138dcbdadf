//! The safetensors side of the format: tensors to write, and typed reads with shape checks.

use crate::map::MapError;
use safetensors::{Dtype, SafeTensors, View};
use std::borrow::Cow;

/// The tensors of one file being written, by name (sorted by name before serialising).
pub(super) type OutTensors<'a> = Vec<(&'static str, OutTensor<'a>)>;

/// A tensor to write: dtype, shape and its little-endian bytes.
pub(super) struct OutTensor<'a> {
    dtype: Dtype,
    shape: Vec<usize>,
    pub(super) bytes: Cow<'a, [u8]>,
}

impl<'a> OutTensor<'a> {
    pub(super) fn new(dtype: Dtype, shape: Vec<usize>, bytes: Cow<'a, [u8]>) -> Self {
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

/// The little-endian bytes of `values`.
pub(super) fn le_bytes<T: Copy, const W: usize>(
    values: &[T],
    to_le: impl Fn(T) -> [u8; W],
) -> Cow<'static, [u8]> {
    Cow::Owned(values.iter().flat_map(|&v| to_le(v)).collect())
}

/// Little-endian `f32`s (a trailing partial value is ignored).
pub(super) fn decode_f32(bytes: &[u8]) -> Vec<f32> {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
        .collect()
}

/// Typed access to the tensors of a parsed file, with shape checks that name the tensor. Every
/// tensor's byte length was checked against its shape by safetensors, so decoding allocates no
/// more than the file holds.
pub(super) struct TensorReader<'a, 'data> {
    pub(super) st: &'a SafeTensors<'data>,
}

impl<'data> TensorReader<'_, 'data> {
    /// Whether the file holds a tensor of that name.
    pub(super) fn has(&self, name: &str) -> bool {
        self.st.tensor(name).is_ok()
    }

    pub(super) fn get_any_len(&self, name: &str, dtype: Dtype) -> Result<&'data [u8], MapError> {
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

    pub(super) fn get(
        &self,
        name: &str,
        dtype: Dtype,
        shape: &[usize],
    ) -> Result<&'data [u8], MapError> {
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

    pub(super) fn u32s(&self, name: &str, shape: &[usize]) -> Result<Vec<u32>, MapError> {
        Ok(self
            .get(name, Dtype::U32, shape)?
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().expect("4")))
            .collect())
    }

    pub(super) fn u64s(&self, name: &str, shape: &[usize]) -> Result<Vec<u64>, MapError> {
        Ok(self
            .get(name, Dtype::U64, shape)?
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().expect("8")))
            .collect())
    }

    pub(super) fn f32s(&self, name: &str, shape: &[usize]) -> Result<Vec<f32>, MapError> {
        Ok(decode_f32(self.get(name, Dtype::F32, shape)?))
    }

    pub(super) fn f64s(&self, name: &str, shape: &[usize]) -> Result<Vec<f64>, MapError> {
        Ok(self
            .get(name, Dtype::F64, shape)?
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8")))
            .collect())
    }
}
