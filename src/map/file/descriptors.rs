//! Section `descriptors`: the N x D matrix of unit-norm view descriptors (F32).

use super::container::{le_bytes, OutTensor, OutTensors, TensorReader};
use crate::map::{Map, MapError};
use safetensors::Dtype;
use std::borrow::Cow;
use std::ops::Range;

/// Adds the descriptor matrix, borrowed in place on little-endian targets.
pub(super) fn write<'a>(map: &'a Map, out: &mut OutTensors<'a>) {
    let bytes: Cow<[u8]> = if cfg!(target_endian = "little") {
        let floats = map.descriptors();
        // SAFETY: f32 has no padding or invalid bit patterns; on little-endian targets its
        // in-memory bytes are its little-endian encoding.
        Cow::Borrowed(unsafe {
            std::slice::from_raw_parts(floats.as_ptr().cast::<u8>(), floats.len() * 4)
        })
    } else {
        le_bytes(map.descriptors(), f32::to_le_bytes)
    };
    out.push((
        "descriptors",
        OutTensor::new(Dtype::F32, vec![map.view_count(), map.dim()], bytes),
    ));
}

/// The byte range of the `n x d` descriptor matrix within `file` (which `reader` parsed), so
/// that a loader can map it in place.
pub(super) fn read(
    reader: &TensorReader<'_, '_>,
    file: &[u8],
    n: usize,
    d: usize,
) -> Result<Range<usize>, MapError> {
    let descriptors = reader.get("descriptors", Dtype::F32, &[n, d])?;
    let start = descriptors.as_ptr() as usize - file.as_ptr() as usize;
    Ok(start..start + descriptors.len())
}
