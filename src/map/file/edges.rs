//! Section `edges`, `edge_weight`: the undirected edges between places and their weights.

use super::container::{le_bytes, OutTensor, OutTensors, TensorReader};
use crate::map::{Edge, Map, MapError};
use safetensors::Dtype;

/// Adds `edges` and `edge_weight`.
pub(super) fn write(map: &Map, out: &mut OutTensors<'_>) {
    let e = map.edge_count();
    let edges: Vec<u32> = map.edges().iter().flat_map(|e| [e.a, e.b]).collect();
    let edge_weight: Vec<f32> = map.edges().iter().map(|e| e.weight).collect();
    out.extend([
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
    ]);
}

/// Reads `e` edges.
pub(super) fn read(reader: &TensorReader<'_, '_>, e: usize) -> Result<Vec<Edge>, MapError> {
    let edge_ids = reader.u32s("edges", &[e, 2])?;
    let edge_weight = reader.f32s("edge_weight", &[e])?;
    Ok(edge_ids
        .chunks_exact(2)
        .zip(edge_weight)
        .map(|(ids, weight)| Edge {
            a: ids[0],
            b: ids[1],
            weight,
        })
        .collect())
}
