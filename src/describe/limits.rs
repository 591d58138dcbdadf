//! The largest describer configuration accepted: every size a stored describer model (or a
//! caller's options) declares is checked against these bounds before anything is allocated or
//! looped over from it, so that a hostile map file cannot make a localizer allocate gigabytes or
//! spin for seconds per frame.
//!
//! The bounds sit far above every configuration topoloc builds (4 taps, a 4 x 4 grid, 320 x 240
//! input, VLAD of at most 1024 x 256 values, D = 512) and far below what would hurt a host.

/// Most ONNX feature maps ("taps") pooled into one raw vector. The default model exports 4
/// multi-level taps; MobileNetV2 has 19 blocks, so 32 allows every block of any such backbone.
pub const MAX_TAPS: usize = 32;

/// Longest tap (ONNX output) name, in bytes.
pub const MAX_TAP_NAME_BYTES: usize = 256;

/// Largest pooling grid side (rows or columns). The default grid is 4 x 4; the coarsest default
/// tap of the default model is 10 x 8 cells at 320 x 240 input, so a grid finer than 32 cells
/// only repeats values. Pooling costs `channels x rows x columns` values per tap: at 32 x 32 and
/// 1280 channels that is 5 MB, where the probe's 100,000 x 100,000 grid aborted the host.
pub const MAX_POOL_GRID: usize = 32;

/// Accepted scales of a stored i8 PCA row (0: an all-zero row). A fitted row's scale is its
/// largest value over 127: at most 1/127 for unit rows, more when whitened; a file's scale
/// beyond this bound would overflow the projection to infinity on ordinary inputs.
pub const PCA_ROW_SCALE_RANGE: Bounds = Bounds::closed(0.0, 1e9);

/// Accepted rows or columns of an ONNX pooling grid.
pub const POOL_GRID_RANGE: Bounds = Bounds::whole(1, MAX_POOL_GRID as u64);

/// Smallest network or VLAD input side, in pixels (as [`crate::describe::vlad::VladOptions`]
/// always accepted).
pub const MIN_INPUT_SIDE: u32 = 32;

/// Largest network or VLAD input side, in pixels: 2048 x 2048 x 3 floats is 48 MB of input
/// tensor, the most a per-frame describer should ever need.
pub const MAX_INPUT_SIDE: u32 = 2048;

/// Largest raw vector (the PCA input dimension F): VLAD's largest is 1024 clusters x 256 ORB
/// bits = 262,144 values; the default ONNX vector is 27,648. 2^20 floats are 4 MB per frame.
pub const MAX_PCA_INPUT_DIM: usize = 1 << 20;

/// Largest descriptor dimension a describer projects to (the PCA output dimension D; default
/// 512, and D is at most the number of map images minus one).
pub const MAX_PCA_OUTPUT_DIM: usize = 16_384;

/// Length of the hexadecimal SHA-256 of an ONNX model file.
pub const SHA256_HEX_LEN: usize = 64;

use crate::bounds::Bounds;
use crate::errors::VisionError;

/// Checks an ONNX configuration against the bounds above: 1..=[`MAX_TAPS`] taps with non-empty
/// names of at most [`MAX_TAP_NAME_BYTES`] bytes without NUL, a grid of 1..=[`MAX_POOL_GRID`]
/// cells per side, and an input of [`MIN_INPUT_SIDE`]..=[`MAX_INPUT_SIDE`] pixels per side.
pub fn check_onnx_config(
    taps: &[String],
    grid: [usize; 2],
    input_size: [u32; 2],
) -> Result<(), VisionError> {
    let bad = |m: String| Err(VisionError::InvalidArgument(m));
    if taps.is_empty() || taps.len() > MAX_TAPS {
        return bad(format!(
            "ONNX backend has {} taps, must have 1..={MAX_TAPS}",
            taps.len()
        ));
    }
    if let Some(tap) = taps
        .iter()
        .find(|t| t.is_empty() || t.len() > MAX_TAP_NAME_BYTES || t.contains('\0'))
    {
        return bad(format!(
            "ONNX tap name {:?} must be 1..={MAX_TAP_NAME_BYTES} bytes without NUL",
            tap.get(..64).unwrap_or(tap)
        ));
    }
    POOL_GRID_RANGE
        .check("ONNX pooling grid rows", grid[0])
        .and_then(|()| POOL_GRID_RANGE.check("ONNX pooling grid columns", grid[1]))
        .map_err(VisionError::InvalidArgument)?;
    check_input_size(input_size, "ONNX")
}

/// Checks an input size (width, height) against [`MIN_INPUT_SIDE`]..=[`MAX_INPUT_SIDE`].
pub fn check_input_size(input_size: [u32; 2], backend: &str) -> Result<(), VisionError> {
    let [w, h] = input_size;
    let side = MIN_INPUT_SIDE..=MAX_INPUT_SIDE;
    if !side.contains(&w) || !side.contains(&h) {
        return Err(VisionError::InvalidArgument(format!(
            "{backend} input size is {w}x{h}, each side must lie in {MIN_INPUT_SIDE}..={MAX_INPUT_SIDE}"
        )));
    }
    Ok(())
}
