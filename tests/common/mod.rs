//! Helpers shared by the integration tests: small hand-made maps with known structure.

#![allow(dead_code)]

pub mod correspondences;
pub mod images;
pub mod models;

use nalgebra::{Isometry3, Point3, Vector3};
use topoloc::map::ViewAttributes;
use topoloc::{DescriptorIdentity, Map, MapBuilder};

/// Deterministic pseudo-random unit vector (xorshift), so tests need no RNG crate.
pub fn unit_vector(seed: u64, dim: usize) -> Vec<f32> {
    let mut state = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut v: Vec<f32> = (0..dim)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        })
        .collect();
    let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
    v.iter_mut().for_each(|x| *x /= norm);
    v
}

/// `a + scale * b`, normalised.
pub fn mix(a: &[f32], b: &[f32], scale: f32) -> Vec<f32> {
    let mut v: Vec<f32> = a.iter().zip(b).map(|(x, y)| x + scale * y).collect();
    let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
    v.iter_mut().for_each(|x| *x /= norm);
    v
}

/// A chain of `places` places 2 m apart along x, `views` views each with random descriptors,
/// keyframe ids, poses and image references on every other view.
pub fn chain_map(places: u32, views: u32, dim: u32) -> Map {
    let mut builder = MapBuilder::new(DescriptorIdentity::new("test", "chain-v1", dim).unwrap());
    for p in 0..places {
        let place = builder
            .add_place(Some(Point3::new(2.0 * p as f64, 0.0, 0.0)))
            .unwrap();
        for v in 0..views {
            let yaw = std::f64::consts::FRAC_PI_2 * v as f64;
            let attributes = ViewAttributes {
                keyframe_id: Some(u64::from(p * 100 + v)),
                world_t_camera: Some(Isometry3::new(
                    Vector3::new(2.0 * p as f64, 0.0, 1.5),
                    Vector3::z() * yaw,
                )),
                image: (v % 2 == 0).then(|| format!("images/place{p:03}_view{v}.png")),
            };
            builder
                .add_view(
                    place,
                    &unit_vector(u64::from(p * 16 + v), dim as usize),
                    attributes,
                )
                .unwrap();
        }
        if p > 0 {
            builder.add_edge(p - 1, p, 1.0).unwrap();
        }
    }
    builder.build().unwrap()
}

/// A chain of `places` places (one view each) whose descriptors drift smoothly: each place is
/// its predecessor plus a small random step, so that neighbours look alike, as consecutive
/// frames of a real sequence do.
pub fn smooth_chain_map(places: u32, dim: u32, step: f32) -> Map {
    let mut builder =
        MapBuilder::new(DescriptorIdentity::new("test", "smooth-chain", dim).unwrap());
    let mut current = unit_vector(7, dim as usize);
    for p in 0..places {
        let place = builder.add_place(None).unwrap();
        builder
            .add_view(place, &current, ViewAttributes::default())
            .unwrap();
        if p > 0 {
            builder.add_edge(p - 1, p, 1.0).unwrap();
        }
        current = mix(
            &current,
            &unit_vector(1000 + u64::from(p), dim as usize),
            step,
        );
    }
    builder.build().unwrap()
}

/// A small deterministic generator (64-bit LCG), so tests need no RNG crate.
pub struct Lcg(pub u64);

impl Lcg {
    /// The next value in [0, 1).
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}
