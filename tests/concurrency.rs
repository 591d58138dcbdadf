//! Concurrency: one map shared (`Arc<Map>`) by four estimators on four threads gives results
//! bit-identical to the same estimators run one after another, for every estimator (graph
//! filter, single frame, metric mode with odometry, image frames described and verified), and
//! four keyframe databases with loop detection on four threads give the hints a sequential run
//! gives. The C side (one localizer per thread, a localizer raced by two threads, under
//! ThreadSanitizer) is in tests/c/test_threads.c.

mod common;

use common::images::{gray, place_image, revisit, vlad_image_map};
use common::{chain_map, mix, unit_vector};
use nalgebra::{Isometry3, Vector3};
use std::sync::Arc;
use topoloc::describe::DescriberOptions;
use topoloc::descriptor::DescriptorIdentity;
use topoloc::loops::{
    DatabaseOptions, HintOptions, KeyframeDatabase, KeyframeEntry, KeyframeFeatures, LoopDetector,
};
use topoloc::verify::{KeypointDetector, VerificationOptions};
use topoloc::{Frame, Localizer, LocalizerOptions, Map, Mode};

const THREADS: usize = 4;
const DIM: u32 = 32;

/// Runs `job(k)` for k in 0..THREADS on THREADS threads at once, and again one after another;
/// asserts that both give the same output for every k, and that the outputs differ between k
/// (so that a mix-up between threads could not go unseen).
fn same_on_threads_as_in_sequence<T, F>(what: &str, job: F)
where
    T: PartialEq + std::fmt::Debug + Send,
    F: Fn(usize) -> T + Sync,
{
    let sequential: Vec<T> = (0..THREADS).map(&job).collect();
    let parallel: Vec<T> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..THREADS)
            .map(|k| {
                let job = &job;
                s.spawn(move || job(k))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for k in 0..THREADS {
        assert_eq!(parallel[k], sequential[k], "{what}: thread {k}");
    }
    assert_ne!(
        sequential[0], sequential[1],
        "{what}: the threads' inputs differ"
    );
}

/// The results of a localizer as text: `Debug` prints every float with the shortest digits
/// that round-trip, so equal text is equal bits.
fn fingerprint(results: &[topoloc::Localization]) -> Vec<String> {
    results.iter().map(|r| format!("{r:?}")).collect()
}

/// Descriptor frames along the chain, each thread its own noise; odometry 2 m along x per
/// place when asked.
fn descriptor_run(map: &Arc<Map>, mode: Mode, odometry: bool, k: usize) -> Vec<String> {
    let mut localizer = Localizer::new(
        map.clone(),
        LocalizerOptions {
            mode,
            ..LocalizerOptions::default()
        },
    )
    .unwrap();
    let step = Isometry3::new(Vector3::new(2.0, 0.0, 0.0), Vector3::zeros());
    let results: Vec<_> = (0..map.place_count() as u32 * 3)
        .map(|i| {
            let view = (i / 3) * 3 + i % 3; // chain_map: 3 views per place
            let descriptor = mix(
                map.view_descriptor(view % map.view_count() as u32).unwrap(),
                &unit_vector(10_000 + 97 * k as u64 + u64::from(i), DIM as usize),
                0.4,
            );
            let frame = Frame {
                timestamp: f64::from(i) * 0.1,
                descriptor: &descriptor,
                odometry: (odometry && i > 0 && i % 3 == 0).then_some(step),
                image: None,
            };
            localizer.localize(&frame).unwrap()
        })
        .collect();
    fingerprint(&results)
}

#[test]
fn descriptor_estimators_on_four_threads_match_a_sequential_run() {
    let map = Arc::new(chain_map(20, 3, DIM));
    for (mode, odometry) in [
        (Mode::Filter, false),
        (Mode::Filter, true),
        (Mode::SingleFrame, false),
        (Mode::Metric, true),
    ] {
        same_on_threads_as_in_sequence(&format!("{mode:?}, odometry {odometry}"), |k| {
            descriptor_run(&map, mode, odometry, k)
        });
    }
}

#[test]
fn image_frames_described_and_verified_on_four_threads_match_a_sequential_run() {
    let images: Vec<Vec<u8>> = (0..10).map(place_image).collect();
    let map = Arc::new(vlad_image_map(&images));
    same_on_threads_as_in_sequence("VLAD image frames, top 3 verified", |k| {
        let mut localizer = Localizer::with_describer(
            map.clone(),
            LocalizerOptions {
                verification: VerificationOptions::with_candidates(3),
                ..LocalizerOptions::default()
            },
            &DescriberOptions::default(),
        )
        .unwrap();
        let results: Vec<_> = (0..images.len())
            .map(|i| {
                let frame = revisit(&images[i], 1000 * k as u64 + i as u64);
                localizer
                    .localize(&Frame {
                        timestamp: i as f64,
                        image: Some(gray(&frame)),
                        ..Frame::default()
                    })
                    .unwrap()
            })
            .collect();
        let right = results
            .iter()
            .enumerate()
            .filter(|(i, r)| r.place as usize == *i)
            .count();
        assert!(
            right >= 8,
            "revisits localized at their places: {right} of 10"
        );
        fingerprint(&results)
    });
}

#[test]
fn keyframe_databases_on_four_threads_match_a_sequential_run() {
    const PLACES: u64 = 8;
    let features = |image: &[u8]| KeyframeFeatures {
        keypoints: KeypointDetector::new(500)
            .unwrap()
            .detect(&gray(image))
            .unwrap(),
        camera_points: None,
    };
    same_on_threads_as_in_sequence("loop detection", |k| {
        let identity = DescriptorIdentity::new("test", "threads", 16).unwrap();
        let db = KeyframeDatabase::new(identity, DatabaseOptions::default()).unwrap();
        let mut detector = LoopDetector::new(
            db,
            HintOptions {
                exclude_recent_ids: 5,
                exclude_recent_s: 5.0,
                candidate_id_gap: 2,
                ..HintOptions::default()
            },
        )
        .unwrap();
        // A first pass over the places, then a revisit of each (thread k: its own noise).
        let mut outcomes = Vec::new();
        for pass in 0..2u64 {
            for p in 0..PLACES {
                let id = pass * 20 + p;
                let descriptor = mix(
                    &unit_vector(p, 16),
                    &unit_vector(5000 + 31 * k as u64 + id, 16),
                    0.2,
                );
                let image = if pass == 0 {
                    place_image(p)
                } else {
                    revisit(&place_image(p), 100 * k as u64 + p)
                };
                let entry = KeyframeEntry {
                    id,
                    timestamp: id as f64,
                    descriptor: &descriptor,
                    ..KeyframeEntry::default()
                };
                let done = detector.process(&entry, features(&image)).unwrap();
                outcomes.push(format!("{:?} {:?}", done.hint, done.confirmed));
            }
        }
        assert!(
            outcomes[PLACES as usize..]
                .iter()
                .any(|o| o.contains("Accepted")),
            "the revisits give accepted hints: {outcomes:?}"
        );
        outcomes
    });
}
