//! Section `place_*`: each place's flags and position.

use super::container::{le_bytes, OutTensor, OutTensors, TensorReader};
use crate::map::{Map, MapError};
use nalgebra::Point3;
use safetensors::Dtype;
use std::borrow::Cow;

const PLACE_HAS_POSITION: u8 = 1;

/// Adds `place_flags` and `place_position`.
pub(super) fn write(map: &Map, out: &mut OutTensors<'_>) {
    let positions = map.place_positions();
    let m = positions.len();
    let place_flags: Vec<u8> = positions
        .iter()
        .map(|p| (p.is_some() as u8) * PLACE_HAS_POSITION)
        .collect();
    let place_position: Vec<f64> = positions
        .iter()
        .flat_map(|p| p.map_or([0.0; 3], |p| [p.x, p.y, p.z]))
        .collect();
    out.extend([
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
    ]);
}

/// Reads the positions of `m` places.
pub(super) fn read(
    reader: &TensorReader<'_, '_>,
    m: usize,
) -> Result<Vec<Option<Point3<f64>>>, MapError> {
    let place_flags = reader.get("place_flags", Dtype::U8, &[m])?;
    let place_position = reader.f64s("place_position", &[m, 3])?;
    Ok(place_flags
        .iter()
        .zip(place_position.chunks_exact(3))
        .map(|(&flags, p)| (flags & PLACE_HAS_POSITION != 0).then(|| Point3::new(p[0], p[1], p[2])))
        .collect())
}
