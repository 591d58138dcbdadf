//! Multi-level features (the seed's MLF): each selected feature map is average-pooled to a fixed
//! grid, flattened, L2-normalised on its own, and the levels are concatenated.

/// One feature map, channel-major: `values[c * height * width + y * width + x]`.
#[derive(Clone, Copy, Debug)]
pub struct FeatureMap<'a> {
    /// Channels.
    pub channels: usize,
    /// Rows.
    pub height: usize,
    /// Columns.
    pub width: usize,
    /// `channels x height x width` values.
    pub values: &'a [f32],
}

/// Adaptive average pooling to `grid_h x grid_w` cells, as PyTorch's `adaptive_avg_pool2d`:
/// cell i spans rows `floor(i H / g) .. ceil((i + 1) H / g)`. Appends `channels x grid_h x grid_w`
/// values (channel-major) to `out`.
pub fn pool_into(map: &FeatureMap<'_>, grid_h: usize, grid_w: usize, out: &mut Vec<f32>) {
    let span =
        |i: usize, size: usize, cells: usize| (i * size / cells, ((i + 1) * size).div_ceil(cells));
    let plane = map.height * map.width;
    for c in 0..map.channels {
        let channel = &map.values[c * plane..(c + 1) * plane];
        for gy in 0..grid_h {
            let (y0, y1) = span(gy, map.height, grid_h);
            for gx in 0..grid_w {
                let (x0, x1) = span(gx, map.width, grid_w);
                let mut sum = 0.0f32;
                for y in y0..y1 {
                    sum += channel[y * map.width + x0..y * map.width + x1]
                        .iter()
                        .sum::<f32>();
                }
                out.push(sum / ((y1 - y0) * (x1 - x0)) as f32);
            }
        }
    }
}

/// L2-normalises `values` in place (left as is when all zeros).
pub fn l2_normalize(values: &mut [f32]) {
    let norm = values.iter().map(|x| x * x).sum::<f32>().sqrt();
    if norm > 0.0 {
        values.iter_mut().for_each(|x| *x /= norm);
    }
}

/// Pools every level to the grid, normalises each level, concatenates: the raw MLF vector.
pub fn multi_level(levels: &[FeatureMap<'_>], grid_h: usize, grid_w: usize) -> Vec<f32> {
    let mut out = Vec::new();
    for level in levels {
        let start = out.len();
        pool_into(level, grid_h, grid_w, &mut out);
        l2_normalize(&mut out[start..]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pooling_matches_hand_computation_with_uneven_cells() {
        // One channel, 3x5, values 0..15; 2x2 grid: rows {0,1} and {1,2}, cols {0,1,2} and {2,3,4}.
        let values: Vec<f32> = (0..15).map(|v| v as f32).collect();
        let map = FeatureMap {
            channels: 1,
            height: 3,
            width: 5,
            values: &values,
        };
        let mut out = Vec::new();
        pool_into(&map, 2, 2, &mut out);
        let mean =
            |cells: &[usize]| cells.iter().map(|&i| i as f32).sum::<f32>() / cells.len() as f32;
        let expected = [
            mean(&[0, 1, 2, 5, 6, 7]),
            mean(&[2, 3, 4, 7, 8, 9]),
            mean(&[5, 6, 7, 10, 11, 12]),
            mean(&[7, 8, 9, 12, 13, 14]),
        ];
        assert_eq!(out, expected);
    }

    #[test]
    fn levels_are_normalised_separately_and_concatenated() {
        let a = [3.0f32, 4.0]; // two channels of 1x1
        let b = [1.0f32, 1.0, 1.0, 1.0]; // one channel of 2x2
        let levels = [
            FeatureMap {
                channels: 2,
                height: 1,
                width: 1,
                values: &a,
            },
            FeatureMap {
                channels: 1,
                height: 2,
                width: 2,
                values: &b,
            },
        ];
        let v = multi_level(&levels, 1, 1);
        assert_eq!(v, vec![0.6, 0.8, 1.0]);
    }
}
