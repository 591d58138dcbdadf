//! Maps from keyframe sequences: spacing, appearance novelty, revisits and edges.

mod common;

use common::{mix, unit_vector};
use nalgebra::{Isometry3, Vector3};
use topoloc::build::{from_keyframes, Keyframe, KeyframeOptions};
use topoloc::{DescriptorIdentity, MapError};

const DIM: usize = 16;

fn identity() -> DescriptorIdentity {
    DescriptorIdentity::new("test", "kf", DIM as u32).unwrap()
}

fn pose(x: f64, yaw: f64) -> Option<Isometry3<f64>> {
    Some(Isometry3::new(
        Vector3::new(x, 0.0, 0.0),
        Vector3::z() * yaw,
    ))
}

/// Keyframe `i` of `descriptors`, with id `i` and the pose `pose_of(i)`.
fn keyframes<'a>(
    descriptors: &'a [Vec<f32>],
    pose_of: impl Fn(usize) -> Option<Isometry3<f64>>,
) -> Vec<Keyframe<'a>> {
    descriptors
        .iter()
        .enumerate()
        .map(|(i, d)| Keyframe {
            id: i as u64,
            descriptor: d,
            world_t_camera: pose_of(i),
        })
        .collect()
}

#[test]
fn poses_space_places_and_revisits_merge() {
    // Forward along x from 0 to 9.5 m every 0.5 m, then back to 0: appearance changes with x.
    let xs: Vec<f64> = (0..20)
        .map(|i| i as f64 * 0.5)
        .chain((0..20).rev().map(|i| i as f64 * 0.5))
        .collect();
    let descriptors: Vec<Vec<f32>> = xs
        .iter()
        .map(|&x| unit_vector(1 + (x / 2.0) as u64, DIM))
        .collect();
    let keyframes = keyframes(&descriptors, |i| pose(xs[i], 0.0));
    let map = from_keyframes(identity(), &keyframes, &KeyframeOptions::default()).unwrap();
    // Places start every time the robot is more than 2 m from every existing place: 0, 2.5, 5, 7.5 m.
    assert_eq!(map.place_count(), 4, "{map:?}");
    let xs_of_places: Vec<f64> = (0..4)
        .map(|p| map.place_position(p).unwrap().unwrap().x)
        .collect();
    assert_eq!(xs_of_places, vec![0.0, 2.5, 5.0, 7.5]);
    // The way back merged into the same places: still a chain 0-1-2-3, nothing more.
    let edges: Vec<(u32, u32)> = map.edges().iter().map(|e| (e.a, e.b)).collect();
    assert_eq!(edges, vec![(0, 1), (1, 2), (2, 3)]);
    // Keyframe ids are kept on the views they became.
    assert_eq!(map.view(0).unwrap().keyframe_id, Some(0));
}

#[test]
fn turning_on_the_spot_adds_views_up_to_the_limit() {
    // Six keyframes at the same spot, each looking another way (distinct appearance).
    let descriptors: Vec<Vec<f32>> = (0..6).map(|i| unit_vector(100 + i, DIM)).collect();
    let keyframes = keyframes(&descriptors, |i| pose(0.0, i as f64));
    let map = from_keyframes(identity(), &keyframes, &KeyframeOptions::default()).unwrap();
    assert_eq!((map.place_count(), map.view_count()), (1, 4));
    let options = KeyframeOptions {
        max_views_per_place: 6,
        ..Default::default()
    };
    assert_eq!(
        from_keyframes(identity(), &keyframes, &options)
            .unwrap()
            .view_count(),
        6
    );
}

#[test]
fn without_poses_novelty_decides() {
    // Three stretches of similar frames: each stretch becomes one place.
    let descriptors: Vec<Vec<f32>> = (0..3u64)
        .flat_map(|s| {
            (0..5u64).map(move |i| {
                mix(
                    &unit_vector(200 + s, DIM),
                    &unit_vector(900 + 10 * s + i, DIM),
                    0.1,
                )
            })
        })
        .collect();
    let keyframes = keyframes(&descriptors, |_| None);
    let map = from_keyframes(identity(), &keyframes, &KeyframeOptions::default()).unwrap();
    assert_eq!(map.place_count(), 3);
    assert_eq!(map.edge_count(), 2);
    assert_eq!(map.place_position(0).unwrap(), None);
}

#[test]
fn bad_input_is_refused() {
    let d = unit_vector(1, DIM);
    let short = vec![1.0f32; DIM - 1];
    let ok = Keyframe {
        id: 0,
        descriptor: &d,
        world_t_camera: pose(0.0, 0.0),
    };
    assert!(matches!(
        from_keyframes(identity(), &[], &KeyframeOptions::default()),
        Err(MapError::EmptyMap)
    ));
    let mixed = [
        ok.clone(),
        Keyframe {
            world_t_camera: None,
            ..ok.clone()
        },
    ];
    assert!(matches!(
        from_keyframes(identity(), &mixed, &KeyframeOptions::default()),
        Err(MapError::InvalidArgument(_))
    ));
    let bad = [
        ok.clone(),
        Keyframe {
            id: 7,
            descriptor: &short,
            ..ok.clone()
        },
    ];
    match from_keyframes(identity(), &bad, &KeyframeOptions::default()) {
        Err(MapError::InvalidArgument(msg)) => assert!(msg.contains("id 7"), "{msg}"),
        other => panic!("{other:?}"),
    }
    let options = KeyframeOptions {
        place_spacing_m: f64::NAN,
        ..Default::default()
    };
    assert!(matches!(
        from_keyframes(identity(), &[ok], &options),
        Err(MapError::InvalidArgument(_))
    ));
}
