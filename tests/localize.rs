//! Localizer behaviour: correct places on clean and noisy input, the filter's gain over single
//! frames, recovery after a kidnap, the off-map state, determinism, and untouched state after
//! bad input.

mod common;

use common::{chain_map, mix, unit_vector};
use std::sync::Arc;
use topoloc::{
    ExpectedDescriptor, Frame, Localization, LocalizeError, Localizer, LocalizerOptions, Map, Mode,
};

const DIM: u32 = 32;

fn localizer(map: &Arc<Map>, mode: Mode) -> Localizer {
    Localizer::new(
        map.clone(),
        LocalizerOptions {
            mode,
            ..Default::default()
        },
    )
    .unwrap()
}

/// Query for place `p`: its first view mixed with noise of relative size `noise`.
fn query(map: &Map, place: u32, noise: f32, seed: u64) -> Vec<f32> {
    let view = map.place_views(place).unwrap()[0];
    mix(
        map.view_descriptor(view).unwrap(),
        &unit_vector(10_000 + seed, map.dim()),
        noise,
    )
}

fn run(localizer: &mut Localizer, frames: &[Vec<f32>]) -> Vec<Localization> {
    frames
        .iter()
        .enumerate()
        .map(|(i, d)| {
            localizer
                .localize(&Frame {
                    timestamp: i as f64 * 0.1,
                    descriptor: d,
                    odometry: None,
                    image: None,
                })
                .unwrap()
        })
        .collect()
}

/// Walks 0 -> 39 along the chain, `dwell` frames per place.
fn walk(map: &Map, noise: f32, dwell: u32) -> (Vec<Vec<f32>>, Vec<u32>) {
    let truth: Vec<u32> = (0..40)
        .flat_map(|p| std::iter::repeat_n(p, dwell as usize))
        .collect();
    let frames = truth
        .iter()
        .enumerate()
        .map(|(i, &p)| query(map, p, noise, i as u64))
        .collect();
    (frames, truth)
}

fn accuracy(results: &[Localization], truth: &[u32]) -> f64 {
    results
        .iter()
        .zip(truth)
        .filter(|(r, t)| r.place == **t)
        .count() as f64
        / truth.len() as f64
}

#[test]
fn clean_queries_find_their_place_and_view() {
    let map = Arc::new(chain_map(10, 4, DIM));
    let mut loc = localizer(&map, Mode::SingleFrame);
    for place in 0..10 {
        for &view in map.place_views(place).unwrap() {
            let d = map.view_descriptor(view).unwrap();
            let r = loc
                .localize(&Frame {
                    timestamp: 0.0,
                    descriptor: d,
                    odometry: None,
                    image: None,
                })
                .unwrap();
            assert_eq!((r.place, r.view), (place, view));
            assert!((r.similarity - 1.0).abs() < 1e-5);
            assert!(!r.off_map);
            assert_eq!(r.candidates.len(), 5);
            assert!(r
                .candidates
                .windows(2)
                .all(|w| w[0].probability >= w[1].probability));
        }
    }
}

#[test]
fn filter_beats_single_frame_on_noisy_walk() {
    let map = Arc::new(chain_map(40, 4, DIM));
    let (frames, truth) = walk(&map, 1.6, 3);
    let single = accuracy(
        &run(&mut localizer(&map, Mode::SingleFrame), &frames),
        &truth,
    );
    let filtered = accuracy(&run(&mut localizer(&map, Mode::Filter), &frames), &truth);
    assert!(
        single < 0.9,
        "noise too weak to test anything: single-frame accuracy {single}"
    );
    assert!(
        filtered > single + 0.1,
        "filter {filtered} vs single {single}"
    );
}

#[test]
fn filter_keeps_up_with_a_camera_advancing_one_place_per_frame() {
    // Neighbouring places look alike, as consecutive frames of a real sequence do: a filter that
    // lags one place behind is then wrong, which is how an adjacency-only filter loses to
    // single frames on real data. The motion model must keep up, in both directions.
    let map = Arc::new(common::smooth_chain_map(120, DIM, 0.3));
    for direction in ["forward", "backward"] {
        let mut truth: Vec<u32> = (0..120).collect();
        if direction == "backward" {
            truth.reverse();
        }
        let frames: Vec<Vec<f32>> = truth
            .iter()
            .map(|&p| query(&map, p, 1.0, u64::from(p)))
            .collect();
        let single = accuracy(
            &run(&mut localizer(&map, Mode::SingleFrame), &frames),
            &truth,
        );
        let filtered = accuracy(&run(&mut localizer(&map, Mode::Filter), &frames), &truth);
        assert!(
            single < 0.8,
            "noise too weak to test anything: single-frame accuracy {single}"
        );
        assert!(
            filtered > single + 0.15,
            "{direction}: filter {filtered} vs single {single}"
        );
    }
}

#[test]
fn kidnapped_robot_recovers() {
    let map = Arc::new(chain_map(40, 4, DIM));
    let mut loc = localizer(&map, Mode::Filter);
    let mut frames: Vec<Vec<f32>> = (0..20).map(|i| query(&map, i / 4, 0.3, i as u64)).collect();
    frames.extend((0..10).map(|i| query(&map, 30, 0.3, 100 + i)));
    let results = run(&mut loc, &frames);
    assert_eq!(results[19].place, 4);
    let recovered = results[20..]
        .iter()
        .position(|r| r.place == 30)
        .expect("never recovered");
    assert!(recovered <= 3, "took {recovered} frames to recover");
    assert!(results.last().unwrap().confidence > 0.9);
}

#[test]
fn frames_from_another_world_are_off_map_and_tracking_resumes() {
    use topoloc_synthetic::{SyntheticWorld, WorldParams};
    let params = WorldParams {
        dim: 512,
        ..Default::default()
    };
    let world = SyntheticWorld::generate(&params).unwrap();
    let stranger = SyntheticWorld::generate(&WorldParams {
        seed: 77,
        ..params.clone()
    })
    .unwrap();
    let home = world.sequence(120, 1).frames;
    let away = stranger.sequence(60, 2).frames;
    let mut loc = localizer(world.map(), Mode::Filter);
    let mut t = 0.0;
    let mut step = |f: &topoloc_synthetic::SequenceFrame| {
        t += 0.1;
        loc.localize(&Frame {
            timestamp: t,
            descriptor: &f.descriptor,
            odometry: None,
            image: None,
        })
        .unwrap()
    };
    let before: Vec<_> = home[..60].iter().map(&mut step).collect();
    let outside: Vec<_> = away.iter().map(&mut step).collect();
    let after: Vec<_> = home[60..].iter().map(&mut step).collect();
    let flagged = |rs: &[Localization]| rs.iter().filter(|r| r.off_map).count();
    assert_eq!(flagged(&before), 0, "on-map frames flagged off-map");
    assert!(
        flagged(&outside[5..]) >= 50,
        "only {} of 55 off-map frames flagged",
        flagged(&outside[5..])
    );
    assert!(
        flagged(&after[10..]) == 0,
        "off-map flag stuck after returning"
    );
    let correct = after[10..]
        .iter()
        .zip(&home[70..])
        .filter(|(r, f)| r.place == f.truth_place)
        .count();
    assert!(
        correct >= 40,
        "tracking did not resume: {correct} of 50 frames correct"
    );
}

#[test]
fn odometry_without_motion_keeps_the_place() {
    let map = Arc::new(chain_map(10, 4, DIM));
    let mut loc = localizer(&map, Mode::Filter);
    let still = nalgebra::Isometry3::identity();
    let d5 = query(&map, 5, 0.2, 1);
    loc.localize(&Frame {
        timestamp: 0.0,
        descriptor: &d5,
        odometry: None,
        image: None,
    })
    .unwrap();
    // An ambiguous frame halfway between places 5 and 6: with zero motion the belief stays at 5.
    let between = mix(&query(&map, 5, 0.0, 0), &query(&map, 6, 0.0, 0), 1.05);
    let r = loc
        .localize(&Frame {
            timestamp: 0.1,
            descriptor: &between,
            odometry: Some(still),
            image: None,
        })
        .unwrap();
    assert_eq!(r.place, 5);
}

#[test]
fn results_are_deterministic() {
    let map = Arc::new(chain_map(40, 4, DIM));
    let (frames, _) = walk(&map, 1.2, 2);
    let a = run(&mut localizer(&map, Mode::Filter), &frames);
    let b = run(&mut localizer(&map, Mode::Filter), &frames);
    assert_eq!(a, b);
}

#[test]
fn bad_frames_leave_the_state_unchanged() {
    let map = Arc::new(chain_map(40, 4, DIM));
    let (frames, _) = walk(&map, 1.2, 2);
    let clean = run(&mut localizer(&map, Mode::Filter), &frames);

    let mut loc = localizer(&map, Mode::Filter);
    let nan = vec![f32::NAN; DIM as usize];
    let zero = vec![0.0; DIM as usize];
    let short = vec![1.0; DIM as usize - 1];
    let mut results = Vec::new();
    let frame = |timestamp: f64, descriptor| Frame {
        timestamp,
        descriptor,
        odometry: None,
        image: None,
    };
    for (i, d) in frames.iter().enumerate() {
        let t = i as f64 * 0.1;
        for bad in [&nan, &zero, &short] {
            let refused = loc.localize(&frame(t, bad));
            assert!(matches!(refused, Err(LocalizeError::Descriptor(_))));
        }
        let mut bad_times = vec![f64::NAN];
        if i > 0 {
            bad_times.push(t - 1.0);
        }
        for bad in bad_times {
            let refused = loc.localize(&frame(bad, d));
            assert!(matches!(refused, Err(LocalizeError::Timestamp(_))));
        }
        results.push(loc.localize(&frame(t, d)).unwrap());
    }
    assert_eq!(results, clean);
}

#[test]
fn reset_forgets_history() {
    let map = Arc::new(chain_map(40, 4, DIM));
    let (frames, _) = walk(&map, 1.2, 2);
    let mut loc = localizer(&map, Mode::Filter);
    let first = run(&mut loc, &frames[..10]);
    loc.reset();
    assert_eq!(run(&mut loc, &frames[..10]), first);
}

#[test]
fn descriptor_identity_and_options_are_checked() {
    let map = Arc::new(chain_map(3, 1, DIM));
    let expect = |kind: &str| LocalizerOptions {
        expected: ExpectedDescriptor {
            kind: Some(kind.into()),
            ..Default::default()
        },
        ..Default::default()
    };
    assert!(Localizer::new(map.clone(), expect("test")).is_ok());
    assert!(matches!(
        Localizer::new(map.clone(), expect("onnx-mlf")),
        Err(LocalizeError::Map(_))
    ));
    for bad in [
        LocalizerOptions {
            temperature: 0.0,
            ..Default::default()
        },
        LocalizerOptions {
            stay_probability: 1.5,
            ..Default::default()
        },
        LocalizerOptions {
            jump_probability: 0.6,
            off_map_probability: 0.5,
            ..Default::default()
        },
        LocalizerOptions {
            off_map_similarity: f32::NAN,
            ..Default::default()
        },
        LocalizerOptions {
            top_k: 0,
            ..Default::default()
        },
    ] {
        assert!(matches!(
            Localizer::new(map.clone(), bad),
            Err(LocalizeError::InvalidOption(_))
        ));
    }
}

#[test]
fn extreme_options_never_underflow_the_belief() {
    // A tiny temperature with an off-map floor above every score: all place likelihoods would
    // underflow if they were scaled against the off-map score.
    let map = Arc::new(chain_map(20, 2, DIM));
    let options = LocalizerOptions {
        temperature: 1e-4,
        off_map_similarity: 1.0,
        jump_probability: 0.0,
        ..Default::default()
    };
    let mut loc = Localizer::new(map.clone(), options).unwrap();
    for i in 0..5u32 {
        let d = query(&map, 3 + i, 1.0, u64::from(i));
        let r = loc
            .localize(&Frame {
                timestamp: f64::from(i),
                descriptor: &d,
                odometry: None,
                image: None,
            })
            .unwrap();
        assert!(r.confidence.is_finite() && r.off_map_probability.is_finite());
        let total: f32 = r.candidates.iter().map(|c| c.probability).sum();
        assert!(total <= 1.0 + 1e-5);
    }
}
