//! Generated two-view correspondences with known geometry: a pinhole camera, scene points in
//! front of the matched camera, their pixels in both views with noise and optional outliers,
//! and keypoints whose descriptors pair them exactly.

use super::Lcg;
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use topoloc::verify::{Descriptor, Keypoints, PinholeCamera};

/// The camera of both views (320 x 240, 56-degree field of view).
pub const CAMERA: PinholeCamera = PinholeCamera {
    fx: 300.0,
    fy: 300.0,
    cx: 160.0,
    cy: 120.0,
};

/// Near-Gaussian noise of standard deviation `sigma` (a sum of four uniforms).
pub fn noise(rng: &mut Lcg, sigma: f64) -> f64 {
    (0..4).map(|_| rng.next() - 0.5).sum::<f64>() * sigma * (3.0f64).sqrt()
}

/// Query pixels, matched pixels and scene points (matched frame) of one generated scene.
pub type Scene = (Vec<[f32; 2]>, Vec<[f32; 2]>, Vec<[f32; 3]>);

pub fn project(p: &Point3<f64>) -> Option<[f32; 2]> {
    let (u, v) = (
        CAMERA.fx * p.x / p.z + CAMERA.cx,
        CAMERA.fy * p.y / p.z + CAMERA.cy,
    );
    (p.z > 0.1 && (0.0..320.0).contains(&u) && (0.0..240.0).contains(&v))
        .then_some([u as f32, v as f32])
}

/// The relative pose the tests look for: the query 0.4 m right, 0.1 m down, 0.3 m forward of
/// the matched camera, turned 6 degrees about y.
pub fn truth() -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(0.4, 0.1, 0.3),
        UnitQuaternion::from_scaled_axis(Vector3::y() * 6f64.to_radians()),
    )
}

/// Correspondences of `n` scene points seen by both cameras: query pixels, matched pixels,
/// scene points in the matched frame; `outliers` of them have a random query pixel.
pub fn scene(n: usize, outliers: usize, matched_t_query: &Isometry3<f64>, seed: u64) -> Scene {
    let mut rng = Lcg(seed);
    let (mut q, mut m, mut s) = (vec![], vec![], vec![]);
    while q.len() < n {
        let z = 3.0 + 5.0 * rng.next();
        let p = Point3::new((rng.next() - 0.5) * z, (rng.next() - 0.5) * 0.75 * z, z);
        let (Some(pm), Some(pq)) = (
            project(&p),
            project(&matched_t_query.inverse_transform_point(&p)),
        ) else {
            continue;
        };
        let jitter = |px: [f32; 2], rng: &mut Lcg| {
            [
                px[0] + noise(rng, 0.3) as f32,
                px[1] + noise(rng, 0.3) as f32,
            ]
        };
        let query_px = if q.len() < outliers {
            [(rng.next() * 320.0) as f32, (rng.next() * 240.0) as f32]
        } else {
            jitter(pq, &mut rng)
        };
        q.push(query_px);
        m.push(jitter(pm, &mut rng));
        s.push([p.x as f32, p.y as f32, p.z as f32]);
    }
    (q, m, s)
}

/// Keypoints whose i-th descriptor is unique to correspondence i, so mutual matching pairs
/// exactly the generated correspondences.
pub fn keypoints(points: &[[f32; 2]]) -> Keypoints {
    let descriptors: Vec<Descriptor> = (0..points.len())
        .map(|i| {
            let mut rng = Lcg(i as u64 * 7919 + 1);
            std::array::from_fn(|_| (rng.next() * 256.0) as u8)
        })
        .collect();
    Keypoints {
        points: points.to_vec(),
        descriptors: descriptors.into(),
    }
}
