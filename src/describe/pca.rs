//! Principal component analysis: fitted on a map's raw descriptors (thin SVD of the centred
//! samples, faer), then used to project every descriptor to D dimensions.
//!
//! The projection rows are stored either as `f32` or, four times smaller, as `i8` with one
//! scale per row ([`PcaPrecision::I8`], [`Pca::with_precision`]): with D = 512 rows of the MobileNetV2 multi-level vector
//! (F = 27,648) that is 14 MB instead of 57 MB, the largest part of a map built from images.

use crate::errors::VisionError;
use bytes::Bytes;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};

/// How the projection rows of a [`Pca`] are stored.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PcaPrecision {
    /// `f32`, exact: 4 bytes per value.
    F32,
    /// `i8` with one `f32` scale per row: 1 byte per value (the default for new maps).
    #[default]
    I8,
}

impl PcaPrecision {
    /// `"f32"` or `"i8"`.
    pub fn name(self) -> &'static str {
        match self {
            PcaPrecision::F32 => "f32",
            PcaPrecision::I8 => "i8",
        }
    }
}

/// The projection rows, `D x F`, row-major.
#[derive(Clone, Debug, PartialEq)]
pub enum Components {
    /// Exact values, already divided by the singular values when whitened.
    F32(Vec<f32>),
    /// Row `k` is `scales[k] * values[k * F..(k + 1) * F]`; `scales[k]` is the row's largest
    /// magnitude over 127, so every row uses the whole `i8` range.
    I8 {
        /// `D x F` quantised values, as bytes: in a loaded map, a slice of the mapped file
        /// (read in place, not copied).
        values: Bytes,
        /// One finite, non-negative scale per row (D values).
        scales: Vec<f32>,
    },
}

impl Components {
    /// How the rows are stored.
    pub fn precision(&self) -> PcaPrecision {
        match self {
            Components::F32(_) => PcaPrecision::F32,
            Components::I8 { .. } => PcaPrecision::I8,
        }
    }

    /// Number of values, `D x F`.
    pub fn len(&self) -> usize {
        match self {
            Components::F32(v) => v.len(),
            Components::I8 { values, .. } => values.len(),
        }
    }

    /// True when there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The quantised rows and their scales, when stored as `i8`.
    pub fn as_i8(&self) -> Option<(&[i8], &[f32])> {
        match self {
            Components::F32(_) => None,
            Components::I8 { values, scales } => Some((bytemuck::cast_slice(values), scales)),
        }
    }

    /// The exact rows, when stored as `f32`.
    pub fn as_f32(&self) -> Option<&[f32]> {
        match self {
            Components::F32(v) => Some(v),
            Components::I8 { .. } => None,
        }
    }

    /// Bytes of the stored rows and scales.
    pub fn memory_bytes(&self) -> usize {
        match self {
            Components::F32(v) => v.len() * 4,
            Components::I8 { values, scales } => values.len() + scales.len() * 4,
        }
    }
}

/// A fitted projection: `y = W (x - mean)`, optionally whitened, then L2-normalised.
#[derive(Clone, Debug, PartialEq)]
pub struct Pca {
    /// Input dimension F.
    pub input_dim: usize,
    /// Output dimension D.
    pub output_dim: usize,
    /// Mean of the fitting samples (F values).
    pub mean: Vec<f32>,
    /// Projection rows W.
    pub components: Components,
}

impl Pca {
    /// Fits on `samples` (row-major `n x input_dim`). The output dimension is
    /// `min(dim, n - 1, input_dim)`: PCA cannot find more directions than the samples span.
    /// `whiten` scales each component to unit variance. The rows are `f32`.
    pub fn fit(
        samples: &[f32],
        input_dim: usize,
        dim: usize,
        whiten: bool,
    ) -> Result<Self, VisionError> {
        if input_dim == 0 || !samples.len().is_multiple_of(input_dim) {
            return Err(VisionError::InvalidArgument(format!(
                "{} values are not rows of {input_dim}",
                samples.len()
            )));
        }
        let n = samples.len() / input_dim;
        if n < 2 {
            return Err(VisionError::InvalidArgument(format!(
                "PCA needs at least 2 samples, got {n}"
            )));
        }
        let mut mean = vec![0.0f64; input_dim];
        for row in samples.chunks_exact(input_dim) {
            mean.iter_mut()
                .zip(row)
                .for_each(|(m, &x)| *m += f64::from(x));
        }
        mean.iter_mut().for_each(|m| *m /= n as f64);
        let centred = Mat::<f64>::from_fn(n, input_dim, |i, j| {
            f64::from(samples[i * input_dim + j]) - mean[j]
        });
        let svd = centred
            .thin_svd()
            .map_err(|e| VisionError::InvalidArgument(format!("PCA: SVD failed: {e:?}")))?;
        let singular = svd.S().column_vector();
        let v = svd.V();
        let output_dim = dim.min(n - 1).min(input_dim);
        let mut components = Vec::with_capacity(output_dim * input_dim);
        for k in 0..output_dim {
            let scale = if whiten {
                1.0 / singular[k].max(1e-12) * ((n - 1) as f64).sqrt()
            } else {
                1.0
            };
            components.extend((0..input_dim).map(|j| (v[(j, k)] * scale) as f32));
        }
        Ok(Self {
            input_dim,
            output_dim,
            mean: mean.into_iter().map(|m| m as f32).collect(),
            components: Components::F32(components),
        })
    }

    /// The same projection with its rows stored at `precision`: `i8` rounds each value to the
    /// nearest of 255 levels spanning its row's largest magnitude. Already-quantised rows
    /// cannot be made exact again (they are returned unchanged).
    pub fn with_precision(self, precision: PcaPrecision) -> Self {
        match (precision, &self.components) {
            (PcaPrecision::I8, Components::F32(rows)) => {
                let mut values = Vec::with_capacity(rows.len());
                let mut scales = Vec::with_capacity(self.output_dim);
                for row in rows.chunks_exact(self.input_dim.max(1)) {
                    let largest = row.iter().fold(0.0f32, |m, x| m.max(x.abs()));
                    let scale = largest / 127.0;
                    let inverse = if scale > 0.0 { 1.0 / scale } else { 0.0 };
                    values.extend(row.iter().map(|x| (x * inverse).round() as i8 as u8));
                    scales.push(scale);
                }
                Self {
                    components: Components::I8 {
                        values: values.into(),
                        scales,
                    },
                    ..self
                }
            }
            _ => self,
        }
    }

    /// Projects one raw vector and L2-normalises the result.
    pub fn project(&self, x: &[f32]) -> Result<Vec<f32>, VisionError> {
        if x.len() != self.input_dim {
            return Err(VisionError::InvalidArgument(format!(
                "PCA input has {} values, expected {}",
                x.len(),
                self.input_dim
            )));
        }
        let centred: Vec<f32> = x.iter().zip(&self.mean).map(|(a, m)| a - m).collect();
        let mut y = vec![0.0f32; self.output_dim];
        match &self.components {
            // One faer matrix-vector product (D x F by F), single-threaded.
            Components::F32(rows) => matmul(
                MatMut::from_column_major_slice_mut(&mut y, self.output_dim, 1),
                Accum::Replace,
                MatRef::from_row_major_slice(rows, self.output_dim, self.input_dim),
                MatRef::from_column_major_slice(&centred, self.input_dim, 1),
                1.0f32,
                Par::Seq,
            ),
            Components::I8 { values, scales } => {
                int8::project(bytemuck::cast_slice(values), scales, &centred, &mut y);
            }
        }
        super::mlf::l2_normalize(&mut y);
        Ok(y)
    }
}

/// The `i8` matrix-vector product in integers: the input is quantised once to `i16` (one
/// scale, 32,767 levels), each row's products are summed exactly in 64-bit integers, then the
/// row and input scales are applied. Integer sums make the AVX2 path (`vpmaddwd`, where the
/// processor has it) and the portable one give identical results.
mod int8 {
    /// Rows processed together by the AVX2 path, so that each loaded input block serves four.
    const ROWS: usize = 4;

    /// `y[k] = scales[k] * (values[k] . x)`; `values` holds `y.len()` rows of `x.len()`.
    pub(super) fn project(values: &[i8], scales: &[f32], x: &[f32], y: &mut [f32]) {
        let largest = x.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        if !largest.is_finite() || x.iter().any(|v| v.is_nan()) {
            y.fill(f32::NAN); // as the f32 product would give
            return;
        }
        if largest == 0.0 {
            y.fill(0.0);
            return;
        }
        let x_scale = f64::from(largest) / f64::from(i16::MAX);
        let xq: Vec<i16> = x
            .iter()
            .map(|&v| (f64::from(v) / x_scale).round() as i16)
            .collect();
        let f = x.len();
        let row = |k: usize| &values[k * f..(k + 1) * f];
        let mut sums = vec![0i64; y.len()];
        let whole = y.len() / ROWS * ROWS;
        for k in (0..whole).step_by(ROWS) {
            let rows = std::array::from_fn(|r| row(k + r));
            sums[k..k + ROWS].copy_from_slice(&dot_rows(rows, &xq));
        }
        for (k, sum) in sums.iter_mut().enumerate().skip(whole) {
            *sum = dot(row(k), &xq);
        }
        for ((out, &sum), &scale) in y.iter_mut().zip(&sums).zip(scales) {
            *out = (sum as f64 * f64::from(scale) * x_scale) as f32;
        }
    }

    /// One row's exact dot product.
    fn dot(row: &[i8], x: &[i16]) -> i64 {
        row.iter()
            .zip(x)
            .map(|(&q, &v)| i64::from(q) * i64::from(v))
            .sum()
    }

    /// Four rows' dot products.
    fn dot_rows(rows: [&[i8]; ROWS], x: &[i16]) -> [i64; ROWS] {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { avx2::dot_rows(rows, x) };
        }
        rows.map(|row| dot(row, x))
    }

    #[cfg(target_arch = "x86_64")]
    mod avx2 {
        use super::{dot, ROWS};
        use std::arch::x86_64::*;

        /// Values per step: 16 `i16` lanes.
        const STEP: usize = 16;
        /// Steps summed in 32-bit lanes before they are widened: each step adds less than
        /// 2^23 to a lane (two products of at most 128 x 32,767), so 255 steps stay below 2^31.
        const STEPS_PER_FLUSH: usize = 255;

        /// As `rows.map(|r| dot(r, x))`, 16 values at a time with `vpmaddwd`.
        #[target_feature(enable = "avx2")]
        pub(super) unsafe fn dot_rows(rows: [&[i8]; ROWS], x: &[i16]) -> [i64; ROWS] {
            let n = x.len();
            debug_assert!(rows.iter().all(|r| r.len() == n));
            let whole = n / STEP * STEP;
            let mut totals = [0i64; ROWS];
            let mut start = 0;
            while start < whole {
                let end = (start + STEP * STEPS_PER_FLUSH).min(whole);
                let mut acc = [_mm256_setzero_si256(); ROWS];
                let mut j = start;
                while j < end {
                    // SAFETY: j + 16 <= whole <= n = len of x and of every row.
                    let xv = _mm256_loadu_si256(x.as_ptr().add(j).cast());
                    for (a, row) in acc.iter_mut().zip(&rows) {
                        let q = _mm256_cvtepi8_epi16(_mm_loadu_si128(row.as_ptr().add(j).cast()));
                        *a = _mm256_add_epi32(*a, _mm256_madd_epi16(q, xv));
                    }
                    j += STEP;
                }
                for (total, a) in totals.iter_mut().zip(&acc) {
                    let mut lanes = [0i32; 8];
                    _mm256_storeu_si256(lanes.as_mut_ptr().cast(), *a);
                    *total += lanes.iter().map(|&v| i64::from(v)).sum::<i64>();
                }
                start = end;
            }
            for (total, row) in totals.iter_mut().zip(&rows) {
                *total += dot(&row[whole..], &x[whole..]);
            }
            totals
        }
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        #[test]
        fn block_sums_are_exact_at_the_extremes() {
            // Long enough for several flushes of the 32-bit lanes, with a tail; the extreme
            // products in every lane would overflow 32 bits without the flushes.
            let n = 16 * 255 * 3 + 16 * 7 + 5;
            let x: Vec<i16> = (0..n)
                .map(|i| if i % 3 == 0 { i16::MIN + 1 } else { i16::MAX })
                .collect();
            let rows: Vec<Vec<i8>> = vec![
                vec![i8::MIN; n],
                vec![i8::MAX; n],
                (0..n)
                    .map(|i| if i % 3 == 0 { i8::MIN } else { i8::MAX })
                    .collect(),
                (0..n).map(|i| (i % 255) as i8).collect(),
            ];
            let expected: Vec<i64> = rows.iter().map(|r| dot(r, &x)).collect();
            let got = dot_rows(std::array::from_fn(|r| rows[r].as_slice()), &x);
            assert_eq!(got.to_vec(), expected);
            assert!(expected[2] > i64::from(i32::MAX), "{}", expected[2]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_the_dominant_direction() {
        // Points along (1, 1, 0) with small noise in z: the first component is +-(1,1,0)/sqrt2.
        let samples: Vec<f32> = (0..10)
            .flat_map(|i| [i as f32, i as f32, if i % 2 == 0 { 0.01 } else { -0.01 }])
            .collect();
        let pca = Pca::fit(&samples, 3, 1, false).unwrap();
        assert_eq!((pca.input_dim, pca.output_dim), (3, 1));
        let c = pca.components.as_f32().unwrap();
        assert!(
            (c[0].abs() - std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-4
                && (c[0] - c[1]).abs() < 1e-4
                && c[2].abs() < 1e-3,
            "{c:?}"
        );
        assert!((pca.mean[0] - 4.5).abs() < 1e-6);
        let y = pca.project(&[9.0, 9.0, 0.0]).unwrap();
        assert!((y[0].abs() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn output_dimension_is_limited_by_the_samples() {
        let samples: Vec<f32> = (0..4 * 8).map(|i| ((i * 37) % 11) as f32).collect();
        assert_eq!(Pca::fit(&samples, 8, 512, true).unwrap().output_dim, 3);
        assert!(Pca::fit(&samples[..8], 8, 4, false).is_err());
        assert!(Pca::fit(&samples, 8, 4, false)
            .unwrap()
            .project(&[0.0; 7])
            .is_err());
    }

    /// Deterministic values in [-1, 1).
    fn values(n: usize, seed: usize) -> Vec<f32> {
        (0..n)
            .map(|i| (((i + seed) * 2_654_435_761) % 10_007) as f32 / 5_003.5 - 1.0)
            .collect()
    }

    #[test]
    fn quantised_rows_span_the_int8_range_and_keep_zero_rows() {
        let (d, f) = (3, 37);
        let mut rows = values(d * f, 1);
        rows[2 * f..].iter_mut().for_each(|v| *v = 0.0);
        let pca = Pca {
            input_dim: f,
            output_dim: d,
            mean: vec![0.0; f],
            components: Components::F32(rows.clone()),
        }
        .with_precision(PcaPrecision::I8);
        let (values, scales) = pca.components.as_i8().expect("quantised");
        assert_eq!((values.len(), scales.len()), (d * f, d));
        for k in 0..2 {
            let row = &values[k * f..(k + 1) * f];
            assert_eq!(row.iter().map(|q| q.unsigned_abs()).max(), Some(127));
            for (q, x) in row.iter().zip(&rows[k * f..]) {
                assert!((f32::from(*q) * scales[k] - x).abs() <= scales[k] / 2.0 + 1e-6);
            }
        }
        assert_eq!(scales[2], 0.0);
        assert!(values[2 * f..].iter().all(|&q| q == 0));
        assert_eq!(pca.components.memory_bytes(), d * f + 4 * d);
        // Quantising twice changes nothing; the exact rows are not recovered.
        assert_eq!(pca.clone().with_precision(PcaPrecision::F32), pca);
    }

    #[test]
    fn int8_projection_matches_the_f32_product_of_the_quantised_rows() {
        // 7 rows (a block of 4, then 3 alone) of 203 values (16-value chunks and a tail).
        for (d, f) in [(7, 203), (4, 16), (1, 5)] {
            let exact = Pca {
                input_dim: f,
                output_dim: d,
                mean: values(f, 7).iter().map(|m| m * 0.1).collect(),
                components: Components::F32(values(d * f, 3)),
            };
            let quantised = exact.clone().with_precision(PcaPrecision::I8);
            let (q, scales) = quantised.components.as_i8().expect("quantised");
            let dequantised = Pca {
                components: Components::F32(
                    q.chunks_exact(f)
                        .zip(scales)
                        .flat_map(|(row, s)| row.iter().map(move |&v| f32::from(v) * s))
                        .collect(),
                ),
                ..exact.clone()
            };
            let x = values(f, 11);
            let a = quantised.project(&x).unwrap();
            let b = dequantised.project(&x).unwrap();
            for (p, e) in a.iter().zip(&b) {
                assert!((p - e).abs() < 1e-5, "{d}x{f}: {a:?} vs {b:?}");
            }
            // And close to the exact projection: cosine of the unit vectors.
            let cosine: f32 = a
                .iter()
                .zip(exact.project(&x).unwrap())
                .map(|(p, e)| p * e)
                .sum();
            assert!(cosine > 0.999, "{d}x{f}: cosine {cosine}");
        }
    }
}
