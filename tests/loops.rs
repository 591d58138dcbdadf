//! The keyframe database: online place growth with and without poses, loop queries that
//! exclude recent keyframes, erase, save and reload for a second session, and bad input that
//! leaves the database as it was.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use topoloc::descriptor::DescriptorIdentity;
use topoloc::loops::{DatabaseOptions, KeyframeDatabase, KeyframeEntry, LoopQuery, LoopsError};
use topoloc::{LoadOptions, Map};

const DIM: usize = 64;

fn identity() -> DescriptorIdentity {
    DescriptorIdentity::new("test", "loops", DIM as u32).unwrap()
}

/// A unit-ish descriptor for "scene" `s`, with a small deterministic perturbation `k`.
fn scene(s: usize, k: usize) -> Vec<f32> {
    let mut d = vec![0.0f32; DIM];
    d[s % DIM] = 1.0;
    d[(s * 7 + 3) % DIM] += 0.3;
    d[(k * 5 + 1) % DIM] += 0.05;
    d
}

fn at(x: f64, y: f64) -> Isometry3<f64> {
    Isometry3::from_parts(Translation3::new(x, y, 0.0), UnitQuaternion::identity())
}

fn entry(id: u64, descriptor: &[f32], pose: Option<Isometry3<f64>>) -> KeyframeEntry<'_> {
    KeyframeEntry {
        id,
        timestamp: id as f64 * 0.5,
        descriptor,
        world_t_body: pose,
        body_t_camera: None,
    }
}

fn edges(db: &KeyframeDatabase) -> Vec<(u32, u32)> {
    db.edges().collect()
}

#[test]
fn without_poses_appearance_alone_starts_places() {
    let mut db = KeyframeDatabase::new(identity(), DatabaseOptions::default()).unwrap();
    let scenes = [0, 0, 0, 1, 1, 2, 2, 2];
    let descriptors: Vec<Vec<f32>> = scenes
        .iter()
        .enumerate()
        .map(|(k, &s)| scene(s, k))
        .collect();
    let places: Vec<(u32, bool)> = descriptors
        .iter()
        .enumerate()
        .map(|(i, d)| {
            let added = db.add(&entry(10 + i as u64, d, None)).unwrap();
            (added.place, added.new_place)
        })
        .collect();
    assert_eq!(
        places,
        vec![
            (0, true),
            (0, false),
            (0, false),
            (1, true),
            (1, false),
            (2, true),
            (2, false),
            (2, false)
        ]
    );
    assert_eq!(db.len(), 8);
    assert_eq!(db.place_count(), 3);
    assert_eq!(edges(&db), vec![(0, 1), (1, 2)]);
}

#[test]
fn with_poses_a_novel_keyframe_near_its_place_stays_and_places_link_in_space() {
    let options = DatabaseOptions {
        place_spacing_m: 2.0,
        neighbour_radius_m: 3.0,
        ..Default::default()
    };
    let mut db = KeyframeDatabase::new(identity(), options).unwrap();
    let (a, b, c, d) = (scene(0, 0), scene(1, 0), scene(2, 0), scene(3, 0));
    // Novel (another scene) but 1 m away: the same place, another view of it.
    assert_eq!(db.add(&entry(1, &a, Some(at(0.0, 0.0)))).unwrap().place, 0);
    let near = db.add(&entry(2, &b, Some(at(1.0, 0.0)))).unwrap();
    assert_eq!((near.place, near.new_place), (0, false));
    // Novel and 5 m away: a new place; then 5 m further, another.
    assert_eq!(db.add(&entry(3, &c, Some(at(5.0, 0.0)))).unwrap().place, 1);
    assert_eq!(db.add(&entry(4, &d, Some(at(5.0, 5.0)))).unwrap().place, 2);
    // Back near the start with a new appearance: a new place (no merge by drifting odometry),
    // linked to the previous place and to place 0, 0.5 m away.
    let back = db.add(&entry(5, &scene(4, 0), Some(at(0.5, 0.2)))).unwrap();
    assert_eq!((back.place, back.new_place), (3, true));
    assert_eq!(edges(&db), vec![(0, 1), (0, 3), (1, 2), (2, 3)]);
    // The camera offset counts: the body is 5 m from place 3, the camera is on it.
    let offset = Isometry3::from_parts(
        Translation3::new(-4.5, 0.0, 0.0),
        UnitQuaternion::identity(),
    );
    let e = scene(5, 0);
    let kf = KeyframeEntry {
        body_t_camera: Some(offset),
        ..entry(6, &e, Some(at(5.0, 0.2)))
    };
    assert_eq!(db.add(&kf).unwrap().place, 3);
}

/// A corridor of 20 distinct places, two keyframes each, ids 100.., then a revisit of place 3.
fn corridor() -> KeyframeDatabase {
    let mut db = KeyframeDatabase::new(identity(), DatabaseOptions::default()).unwrap();
    for p in 0..20usize {
        for k in 0..2 {
            let id = 100 + (2 * p + k) as u64;
            db.add(&entry(id, &scene(p * 3 + 1, k), None)).unwrap();
        }
    }
    db
}

/// With `min_id_gap`, the candidates come from different stretches of ids: the best of each,
/// in order of similarity, never two closer in id than the gap.
#[test]
fn an_id_gap_takes_one_candidate_per_stretch() {
    let db = corridor();
    let revisit = scene(3 * 3 + 1, 9);
    let query_at_most = |max_results, min_id_gap| {
        db.loop_candidates(
            &revisit,
            &LoopQuery {
                max_results,
                min_id_gap,
                ..Default::default()
            },
        )
        .unwrap()
    };
    let query = |min_id_gap| query_at_most(4, min_id_gap);
    let plain = query(0);
    let ids: Vec<u64> = plain.iter().map(|m| m.keyframe_id).collect();
    assert!(
        ids.iter()
            .any(|a| ids.iter().any(|b| a != b && a.abs_diff(*b) < 6)),
        "without a gap, neighbours fill the slots: {ids:?}"
    );
    let spread = query(6);
    assert_eq!(spread.len(), 4);
    assert_eq!(spread[0], plain[0], "the best candidate stays first");
    for (i, a) in spread.iter().enumerate() {
        for b in &spread[i + 1..] {
            assert!(a.keyframe_id.abs_diff(b.keyframe_id) >= 6, "{spread:?}");
        }
    }
    assert!(spread
        .windows(2)
        .all(|w| w[0].similarity >= w[1].similarity));
    // A gap wider than the database leaves one candidate.
    assert_eq!(query(1000).len(), 1);
    // Room is made for what is found, not for what is asked (usize::MAX once aborted).
    assert!(query_at_most(usize::MAX, 6).len() >= spread.len());
}

#[test]
fn loop_queries_find_the_revisited_place_and_exclude_recent_keyframes() {
    let db = corridor();
    let revisit = scene(3 * 3 + 1, 9);
    let all = db
        .loop_candidates(
            &revisit,
            &LoopQuery {
                max_results: 3,
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(all.len(), 3);
    assert_eq!(all[0].place, 3);
    assert!(
        all[0].keyframe_id == 106 || all[0].keyframe_id == 107,
        "{all:?}"
    );
    assert!(all.windows(2).all(|w| w[0].similarity >= w[1].similarity));
    // DBoW2's max_id: keyframes after 105 are "recent" and excluded, so place 3 is not found.
    let older = db
        .loop_candidates(
            &revisit,
            &LoopQuery {
                max_results: 40,
                max_id: Some(105),
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(older.len(), 6);
    assert!(older.iter().all(|m| m.keyframe_id <= 105 && m.place != 3));
    // By time: keyframe k has timestamp (100 + k) / 2 s.
    let before = db
        .loop_candidates(
            &revisit,
            &LoopQuery {
                max_results: 40,
                before_timestamp: Some(53.0),
                ..Default::default()
            },
        )
        .unwrap();
    assert_eq!(before.len(), 6);
    assert_eq!(
        db.relocalization_candidates(&revisit, 1).unwrap()[0].place,
        3
    );
    assert!(db
        .loop_candidates(
            &revisit,
            &LoopQuery {
                max_results: 0,
                ..Default::default()
            }
        )
        .unwrap()
        .is_empty());
}

#[test]
fn erase_removes_a_keyframe_from_queries_and_an_emptied_place_from_the_saved_map() {
    let mut db = corridor();
    let revisit = scene(3 * 3 + 1, 9);
    db.erase(106).unwrap();
    let best = db.relocalization_candidates(&revisit, 1).unwrap()[0];
    assert_eq!((best.keyframe_id, best.place), (107, 3));
    assert!(matches!(
        db.erase(106),
        Err(LoopsError::UnknownKeyframe(106))
    ));
    db.erase(107).unwrap();
    assert_ne!(
        db.relocalization_candidates(&revisit, 1).unwrap()[0].place,
        3
    );
    assert_eq!(db.len(), 38);
    let map = db.to_map().unwrap();
    assert_eq!(map.place_count(), 19);
    assert_eq!(map.view_count(), 38);
    // Place 3 is gone, so 2 and the old 4 are no longer linked through it.
    assert_eq!(map.edge_count(), 17);
}

#[test]
fn a_saved_database_reloads_for_a_second_session_and_extends() {
    let db = corridor();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("session1.topoloc");
    db.save(&path).unwrap();
    let map = Map::load(&path, &LoadOptions::default()).unwrap();
    assert_eq!((map.place_count(), map.view_count()), (20, 40));
    let mut second = KeyframeDatabase::from_map(&map, DatabaseOptions::default()).unwrap();
    let revisit = scene(3 * 3 + 1, 9);
    assert_eq!(
        second.relocalization_candidates(&revisit, 5).unwrap(),
        db.relocalization_candidates(&revisit, 5).unwrap()
    );
    // Reloaded keyframes are older than any new timestamp.
    let q = LoopQuery {
        max_results: 50,
        before_timestamp: Some(0.0),
        ..Default::default()
    };
    assert_eq!(second.loop_candidates(&revisit, &q).unwrap().len(), 40);
    // New ids continue above the session's; an id of the first session is refused.
    assert!(matches!(
        second.add(&entry(139, &scene(1, 1), None)),
        Err(LoopsError::DuplicateId(139))
    ));
    assert!(matches!(
        second.add(&entry(50, &scene(1, 1), None)),
        Err(LoopsError::OutOfOrder(_))
    ));
    let added = second.add(&entry(500, &revisit, None)).unwrap();
    assert!(added.new_place && added.place == 20, "{added:?}");
    assert_eq!(second.len(), 41);
    // A map whose views carry no keyframe ids is not a database.
    let bare = topoloc_synthetic::random_map(8, 2, DIM, 3);
    assert!(matches!(
        KeyframeDatabase::from_map(&bare, DatabaseOptions::default()),
        Err(LoopsError::InvalidOption(_))
    ));
}

/// Each keyframe records the odometry's path length from the session's first keyframe, which
/// survives erasing a keyframe on the way; reloaded keyframes have none (another session).
#[test]
fn keyframes_record_the_distance_the_odometry_travelled() {
    let mut db = KeyframeDatabase::new(identity(), DatabaseOptions::default()).unwrap();
    let route = [(0.0, 0.0), (3.0, 4.0), (3.0, 16.0)];
    for (i, &(x, y)) in route.iter().enumerate() {
        db.add(&entry(i as u64, &scene(i, 0), Some(at(x, y))))
            .unwrap();
    }
    let travelled = |db: &KeyframeDatabase, id| db.travelled_m(id).unwrap();
    assert_eq!(
        [0, 1, 2].map(|id| travelled(&db, id)),
        [Some(0.0), Some(5.0), Some(17.0)]
    );
    db.erase(2).unwrap();
    assert_eq!(
        db.travelled_to(&nalgebra::Point3::new(3.0, 20.0, 0.0)),
        Some(21.0)
    );
    assert!(matches!(
        db.travelled_m(2),
        Err(LoopsError::UnknownKeyframe(2))
    ));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("travel.topoloc");
    db.save(&path).unwrap();
    let map = Map::load(&path, &LoadOptions::default()).unwrap();
    let reloaded = KeyframeDatabase::from_map(&map, DatabaseOptions::default()).unwrap();
    assert_eq!(travelled(&reloaded, 1), None);
    assert_eq!(reloaded.travelled_to(&nalgebra::Point3::origin()), None);
    let unposed = corridor();
    assert_eq!(travelled(&unposed, 100), None);
}

/// Odometry candidates: this session's keyframes within the radius (which grows with the path
/// travelled since each) and the angle, nearest first, recent ones excluded; none reloaded.
#[test]
fn nearby_candidates_are_the_keyframes_the_odometry_puts_close() {
    let mut db = KeyframeDatabase::new(identity(), DatabaseOptions::default()).unwrap();
    let turned = Isometry3::from_parts(
        Translation3::new(1.0, 0.0, 0.0),
        UnitQuaternion::from_scaled_axis(Vector3::z() * 90f64.to_radians()),
    );
    // 0 and 1 near the origin (1 turned away), 2 and 3 far out, 4 back near the origin.
    let route = [
        at(0.5, 0.0),
        turned,
        at(40.0, 0.0),
        at(40.0, 40.0),
        at(2.5, 0.0),
    ];
    for (i, pose) in route.iter().enumerate() {
        db.add(&entry(i as u64, &scene(i, 0), Some(*pose))).unwrap();
    }
    let d = scene(9, 0);
    let query = |radius: &dyn Fn(f64) -> f64, max_id| {
        let q = LoopQuery {
            max_results: 3,
            max_id: Some(max_id),
            ..Default::default()
        };
        db.nearby_candidates(&d, &at(0.0, 0.0), radius, 30.0, &q)
            .unwrap()
            .iter()
            .map(|m| m.keyframe_id)
            .collect::<Vec<_>>()
    };
    assert_eq!(
        query(&|_| 3.0, 10),
        [0, 4],
        "nearest first, the turned one left out"
    );
    assert_eq!(query(&|_| 3.0, 3), [0], "recent keyframes excluded");
    assert_eq!(query(&|_| 1.0, 10), [0]);
    // The path from keyframe 0 (0.5 m away) is long; from 4 (2.5 m away) short.
    assert_eq!(query(&|travelled| 0.01 * travelled, 10), [0]);
    let own = db
        .nearby_candidates(
            &scene(0, 0),
            &at(0.0, 0.0),
            |_| 3.0,
            30.0,
            &LoopQuery::default(),
        )
        .unwrap();
    assert_eq!(own[0].keyframe_id, 0);
    assert!(own[0].similarity > 0.99, "the descriptor's cosine: {own:?}");
    assert!(own[1].similarity < 0.5, "{own:?}");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("near.topoloc");
    db.save(&path).unwrap();
    let map = Map::load(&path, &LoadOptions::default()).unwrap();
    let reloaded = KeyframeDatabase::from_map(&map, DatabaseOptions::default()).unwrap();
    let none = reloaded
        .nearby_candidates(&d, &at(0.0, 0.0), |_| 100.0, 180.0, &LoopQuery::default())
        .unwrap();
    assert!(none.is_empty(), "another session's odometry: {none:?}");
    assert!(matches!(
        db.nearby_candidates(&d[..3], &at(0.0, 0.0), |_| 3.0, 30.0, &LoopQuery::default()),
        Err(LoopsError::Descriptor(_))
    ));
}

/// A bad keyframe: its name, the entry, and the error it must get.
type BadKeyframe<'a> = (&'static str, KeyframeEntry<'a>, fn(&LoopsError) -> bool);

#[test]
fn bad_keyframes_get_typed_errors_and_leave_the_database_unchanged() {
    let mut db = KeyframeDatabase::new(identity(), DatabaseOptions::default()).unwrap();
    let d = scene(0, 0);
    db.add(&entry(10, &d, Some(at(0.0, 0.0)))).unwrap();
    let before = db.to_map().unwrap().to_bytes().unwrap();
    let nan_pose = Isometry3::from_parts(
        Translation3::from(Vector3::new(f64::NAN, 0.0, 0.0)),
        UnitQuaternion::identity(),
    );
    let short = vec![1.0f32; DIM - 1];
    let zeros = vec![0.0f32; DIM];
    let cases: Vec<BadKeyframe> = vec![
        ("duplicate id", entry(10, &d, Some(at(0.0, 0.0))), |e| {
            matches!(e, LoopsError::DuplicateId(10))
        }),
        ("id going back", entry(9, &d, Some(at(0.0, 0.0))), |e| {
            matches!(e, LoopsError::OutOfOrder(_))
        }),
        (
            "time going back",
            KeyframeEntry {
                timestamp: 1.0,
                ..entry(11, &d, Some(at(0.0, 0.0)))
            },
            |e| matches!(e, LoopsError::OutOfOrder(_)),
        ),
        (
            "NaN time",
            KeyframeEntry {
                timestamp: f64::NAN,
                ..entry(11, &d, Some(at(0.0, 0.0)))
            },
            |e| matches!(e, LoopsError::NonFinite(_)),
        ),
        ("NaN pose", entry(11, &d, Some(nan_pose)), |e| {
            matches!(e, LoopsError::NonFinite(_))
        }),
        (
            "NaN camera offset",
            KeyframeEntry {
                body_t_camera: Some(nan_pose),
                ..entry(11, &d, Some(at(0.0, 0.0)))
            },
            |e| matches!(e, LoopsError::NonFinite(_)),
        ),
        ("no pose after poses", entry(11, &d, None), |e| {
            matches!(e, LoopsError::InvalidOption(_))
        }),
        (
            "short descriptor",
            entry(11, &short, Some(at(0.0, 0.0))),
            |e| matches!(e, LoopsError::Descriptor(_)),
        ),
        (
            "zero descriptor",
            entry(11, &zeros, Some(at(0.0, 0.0))),
            |e| matches!(e, LoopsError::Descriptor(_)),
        ),
    ];
    for (name, kf, expected) in cases {
        let err = db.add(&kf).expect_err(name);
        assert!(expected(&err), "{name}: {err}");
        assert_eq!(
            db.to_map().unwrap().to_bytes().unwrap(),
            before,
            "{name} changed the database"
        );
    }
    assert!(matches!(
        db.loop_candidates(&short, &LoopQuery::default()),
        Err(LoopsError::Descriptor(_))
    ));
    let nan_time = LoopQuery {
        before_timestamp: Some(f64::NAN),
        ..Default::default()
    };
    assert!(matches!(
        db.loop_candidates(&d, &nan_time),
        Err(LoopsError::NonFinite(_))
    ));
    assert!(matches!(
        KeyframeDatabase::new(
            identity(),
            DatabaseOptions {
                novelty_similarity: 2.0,
                ..Default::default()
            }
        ),
        Err(LoopsError::InvalidOption(_))
    ));
    assert!(matches!(
        KeyframeDatabase::new(
            identity(),
            DatabaseOptions {
                place_spacing_m: f64::NAN,
                ..Default::default()
            }
        ),
        Err(LoopsError::InvalidOption(_))
    ));
    // After all that, a good keyframe still goes in.
    assert_eq!(
        db.add(&entry(11, &scene(5, 0), Some(at(9.0, 0.0))))
            .unwrap()
            .place,
        1
    );
    let empty = KeyframeDatabase::new(identity(), DatabaseOptions::default()).unwrap();
    assert!(matches!(
        empty.to_map(),
        Err(LoopsError::Map(topoloc::MapError::EmptyMap))
    ));
}

#[test]
fn memory_per_keyframe_is_the_descriptor_plus_a_small_record() {
    let mut db = KeyframeDatabase::new(identity(), DatabaseOptions::default()).unwrap();
    let n = 2000;
    for i in 0..n {
        db.add(&entry(i as u64, &scene(i / 3, i), None)).unwrap();
    }
    let per_keyframe = db.memory_bytes() as f64 / n as f64;
    let descriptor = (DIM * 4) as f64;
    // Vec growth can double a buffer: allow up to twice the exact size.
    assert!(per_keyframe >= descriptor + 32.0, "{per_keyframe}");
    assert!(per_keyframe <= 2.0 * (descriptor + 160.0), "{per_keyframe}");
}
