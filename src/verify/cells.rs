//! Dense cells: the describer's own CNN feature map (MobileNetV2 block 13, stride 16) cut into
//! per-cell descriptors, so that verification needs no second network (the Patch-NetVLAD
//! idea; the seed re-ranks with patch features too). Each cell is a keypoint at its centre;
//! the cells with the largest activation norm are kept (blank sky and road have little).

use super::keypoints::{CellDescriptor, Descriptors, Keypoints, CELL_DIM, MAX_KEYPOINTS};
use crate::errors::VisionError;

/// Cells kept per image by default: 192 cells of 96 bytes plus an 8-byte position take
/// 19,968 bytes per view, within the 20,000 of the 500 ORB keypoints maps stored before
/// (320 x 240 images have 20 x 15 = 300 cells).
pub const DEFAULT_CELLS: usize = 192;
/// The feature map cells come from: the default ONNX model's output of MobileNetV2 block 13.
pub const CELL_TAP: &str = "f13";

/// The `max_cells` cells of largest norm of a channel-major `channels x height x width` map
/// whose cells are `cell_size` image pixels wide and high, as keypoints (cell centres,
/// best first, ties by position) with unit descriptors quantised to int8. Fails unless the map
/// has [`CELL_DIM`] channels and `values` holds the whole map.
pub fn cells_from_map(
    values: &[f32],
    [channels, height, width]: [usize; 3],
    cell_size: [f32; 2],
    max_cells: usize,
) -> Result<Keypoints, VisionError> {
    if channels != CELL_DIM || values.len() != channels * height * width {
        return Err(VisionError::Model(format!(
            "dense cells need a {CELL_DIM}-channel feature map; got {channels} x {height} x {width} with {} values",
            values.len()
        )));
    }
    if !(1..=MAX_KEYPOINTS).contains(&max_cells) {
        return Err(VisionError::InvalidArgument(format!(
            "cells per image is {max_cells}, must lie in 1..={MAX_KEYPOINTS}"
        )));
    }
    let plane = height * width;
    let cell = |i: usize| -> [f32; CELL_DIM] { std::array::from_fn(|c| values[c * plane + i]) };
    let mut ranked: Vec<(f32, usize)> = (0..plane)
        .map(|i| (cell(i).iter().map(|v| v * v).sum::<f32>(), i))
        .filter(|&(norm2, _)| norm2 > 0.0 && norm2.is_finite())
        .collect();
    ranked.sort_unstable_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
    ranked.truncate(max_cells);
    let points = ranked
        .iter()
        .map(|&(_, i)| {
            let (x, y) = ((i % width) as f32, (i / width) as f32);
            [(x + 0.5) * cell_size[0], (y + 0.5) * cell_size[1]]
        })
        .collect();
    let descriptors: Vec<CellDescriptor> = ranked
        .iter()
        .map(|&(norm2, i)| {
            let scale = 127.0 / norm2.sqrt();
            cell(i).map(|v| (v * scale).round().clamp(-127.0, 127.0) as i8)
        })
        .collect();
    Ok(Keypoints {
        points,
        descriptors: Descriptors::Cells(descriptors),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_strongest_cells_are_kept_at_their_centres() {
        // 2 x 3 map, cell (x=2, y=0) strongest, (x=0, y=1) second, one cell all zero.
        let (h, w) = (2, 3);
        let mut values = vec![0.1f32; CELL_DIM * h * w];
        for c in 0..CELL_DIM {
            values[c * h * w + 2] = 1.0;
            values[c * h * w + 3] = 0.5;
            values[c * h * w + 4] = 0.0;
        }
        let cells = cells_from_map(&values, [CELL_DIM, h, w], [16.0, 16.0], 2).unwrap();
        assert_eq!(cells.points, vec![[40.0, 8.0], [8.0, 24.0]]);
        let Descriptors::Cells(d) = &cells.descriptors else {
            panic!("cells")
        };
        assert!(d[0].iter().all(|&v| v == 13), "127 / sqrt(96) = 12.96");
        let all = cells_from_map(&values, [CELL_DIM, h, w], [16.0, 16.0], 100).unwrap();
        assert_eq!(all.len(), 5, "the zero cell is dropped");
    }

    #[test]
    fn a_map_of_another_width_is_refused() {
        let err = cells_from_map(&[0.0; 32 * 4], [32, 2, 2], [8.0, 8.0], 10).unwrap_err();
        assert!(
            matches!(err, VisionError::Model(ref m) if m.contains("96-channel")),
            "{err}"
        );
    }
}
