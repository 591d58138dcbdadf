//! Principal component analysis: fitted on a map's raw descriptors (thin SVD of the centred
//! samples, faer), then used to project every descriptor to D dimensions.

use crate::errors::VisionError;
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, MatMut, MatRef, Par};

/// A fitted projection: `y = W (x - mean)`, optionally whitened, then L2-normalised.
#[derive(Clone, Debug, PartialEq)]
pub struct Pca {
    /// Input dimension F.
    pub input_dim: usize,
    /// Output dimension D.
    pub output_dim: usize,
    /// Mean of the fitting samples (F values).
    pub mean: Vec<f32>,
    /// Projection rows, row-major `D x F`, already divided by the singular values when whitened.
    pub components: Vec<f32>,
}

impl Pca {
    /// Fits on `samples` (row-major `n x input_dim`). The output dimension is
    /// `min(dim, n - 1, input_dim)`: PCA cannot find more directions than the samples span.
    /// `whiten` scales each component to unit variance.
    pub fn fit(
        samples: &[f32],
        input_dim: usize,
        dim: usize,
        whiten: bool,
    ) -> Result<Self, VisionError> {
        if input_dim == 0 || samples.len() % input_dim != 0 {
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
            components,
        })
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
        // One faer matrix-vector product (D x F by F), single-threaded.
        let mut y = vec![0.0f32; self.output_dim];
        matmul(
            MatMut::from_column_major_slice_mut(&mut y, self.output_dim, 1),
            Accum::Replace,
            MatRef::from_row_major_slice(&self.components, self.output_dim, self.input_dim),
            MatRef::from_column_major_slice(&centred, self.input_dim, 1),
            1.0f32,
            Par::Seq,
        );
        super::mlf::l2_normalize(&mut y);
        Ok(y)
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
        let c = &pca.components;
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
}
