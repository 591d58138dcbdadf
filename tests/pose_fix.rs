//! Pose fixes: a view whose keypoints carry scene points places a camera that moved in front of
//! it, directly ([`locate`]) and through a verifying localizer; scene points survive the map
//! file; inconsistent scene points, a bad camera and a camera without scene points in the map
//! are typed errors.

mod common;

use common::images::{gray, place_image, H, W};
use common::unit_vector;
use nalgebra::{Point3, Vector3};
use std::sync::Arc;
use topoloc::map::ViewAttributes;
use topoloc::verify::{
    locate, FeatureKind, KeypointDetector, Keypoints, LocateOptions, Located, PinholeCamera,
    VerificationOptions, ViewKeypoints,
};
use topoloc::{
    DescriptorIdentity, Frame, LoadOptions, LocalizeError, Localizer, LocalizerOptions, Map,
    MapBuilder, Mode,
};

const DIM: usize = 16;
/// The view's scene: two walls facing the view camera, the left half of its image 2 m away,
/// the right half 3 m (a single plane leaves a translation-rotation ambiguity).
const DEPTHS: [f64; 2] = [2.0, 3.0];

/// Depth of the wall at map-frame x (the walls meet the view's optical axis at x = 0).
fn wall_depth(x: f64) -> f64 {
    if x < 0.0 {
        DEPTHS[0]
    } else {
        DEPTHS[1]
    }
}

fn camera() -> PinholeCamera {
    PinholeCamera {
        fx: 200.0,
        fy: 200.0,
        cx: (W as f64 - 1.0) / 2.0,
        cy: (H as f64 - 1.0) / 2.0,
    }
}

/// Where the query camera is, in the map frame (the view's optical frame: z forward, x right,
/// y down).
fn query_centre() -> Vector3<f64> {
    Vector3::new(0.2, -0.1, 0.3)
}

fn detect(image: &[u8]) -> Keypoints {
    KeypointDetector::new(500)
        .unwrap()
        .detect(&gray(image))
        .unwrap()
}

/// The view image's keypoints with their scene points on the walls.
fn view_keypoints(image: &[u8]) -> ViewKeypoints {
    let k = camera();
    let keypoints = detect(image);
    let scene = keypoints
        .points
        .iter()
        .map(|p| {
            let (u, v) = (
                (f64::from(p[0]) - k.cx) / k.fx,
                (f64::from(p[1]) - k.cy) / k.fy,
            );
            let depth = if u < 0.0 { DEPTHS[0] } else { DEPTHS[1] };
            [(u * depth) as f32, (v * depth) as f32, depth as f32]
        })
        .collect();
    ViewKeypoints::from_views(FeatureKind::Orb, [&keypoints])
        .unwrap()
        .with_world_points(scene)
        .unwrap()
}

/// What a camera at [`query_centre`], turned like the view, sees of the walls textured with
/// the view image (bilinear resampling; black where it sees between the walls).
fn query_image(view: &[u8]) -> Vec<u8> {
    let (k, c) = (camera(), query_centre());
    let mut out = vec![0u8; W * H];
    for row in 0..H {
        for col in 0..W {
            // Query pixel -> the first wall its ray meets -> view pixel.
            let (du, dv) = ((col as f64 - k.cx) / k.fx, (row as f64 - k.cy) / k.fy);
            let hit = DEPTHS.iter().find_map(|&z| {
                let x = c.x + (z - c.z) * du;
                (wall_depth(x) == z).then(|| (x, c.y + (z - c.z) * dv, z))
            });
            let Some((wx, wy, wz)) = hit else {
                continue;
            };
            let x = k.cx + k.fx * wx / wz;
            let y = k.cy + k.fy * wy / wz;
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = (x - x0, y - y0);
            let at = |dx: f64, dy: f64| {
                let (xi, yi) = ((x0 + dx) as isize, (y0 + dy) as isize);
                if xi < 0 || yi < 0 || xi >= W as isize || yi >= H as isize {
                    0.0
                } else {
                    f64::from(view[yi as usize * W + xi as usize])
                }
            };
            let value = at(0.0, 0.0) * (1.0 - fx) * (1.0 - fy)
                + at(1.0, 0.0) * fx * (1.0 - fy)
                + at(0.0, 1.0) * (1.0 - fx) * fy
                + at(1.0, 1.0) * fx * fy;
            out[row * W + col] = value.round().clamp(0.0, 255.0) as u8;
        }
    }
    out
}

/// [`locate`] of `query` against the single view of `stored`, default options.
fn locate_in(query: &Keypoints, stored: &ViewKeypoints) -> Option<Located> {
    locate(
        query.as_ref(),
        stored.view(0).unwrap(),
        stored.view_world_points(0).unwrap(),
        &camera(),
        64,
        &LocateOptions::default(),
    )
    .unwrap()
}

#[test]
fn a_view_with_scene_points_places_a_camera_that_moved() {
    let view = place_image(5);
    let stored = view_keypoints(&view);
    let found = locate_in(&detect(&query_image(&view)), &stored).expect("a pose");
    let error = (found.position().coords - query_centre()).norm();
    assert!(
        error < 0.03,
        "camera at {:?}, error {error:.3} m",
        found.position()
    );
    assert!(found.inliers >= 50, "{} inliers", found.inliers);
    // Not turned: the optical axes agree with the view's.
    let turned = found.world_t_optical.rotation.angle();
    assert!(turned < 0.02, "turned {turned:.3} rad");

    // Another place's keypoints give no pose.
    let none = locate_in(&detect(&place_image(6)), &stored);
    assert!(none.is_none(), "{none:?}");
}

/// Three places of one view each; place 1's view carries scene points.
fn map_with_scene_points(scene_points: bool) -> Map {
    let mut builder =
        MapBuilder::new(DescriptorIdentity::new("test", "poses", DIM as u32).unwrap());
    let mut views = Vec::new();
    for p in 0..3u64 {
        let place = builder
            .add_place(Some(Point3::new(p as f64, 0.0, 0.0)))
            .unwrap();
        builder
            .add_view(place, &unit_vector(p, DIM), ViewAttributes::default())
            .unwrap();
        views.push(detect(&place_image(p + 4)));
    }
    builder.add_edge(0, 1, 1.0).unwrap();
    builder.add_edge(1, 2, 1.0).unwrap();
    let map = builder.build().unwrap();
    let mut store = ViewKeypoints::from_views(FeatureKind::Orb, &views).unwrap();
    if scene_points {
        let plane = view_keypoints(&place_image(5));
        let mut scene = vec![[f32::NAN; 3]; store.total()];
        let first = store.offsets()[1] as usize;
        scene[first..first + plane.total()].copy_from_slice(plane.world_points().unwrap());
        store = store.with_world_points(scene).unwrap();
    }
    map.with_keypoints(store).unwrap()
}

fn verifying(camera: Option<PinholeCamera>) -> LocalizerOptions {
    LocalizerOptions {
        mode: Mode::SingleFrame,
        verification: VerificationOptions {
            camera,
            ..VerificationOptions::with_candidates(2)
        },
        ..LocalizerOptions::default()
    }
}

#[test]
fn a_verifying_localizer_with_a_camera_reports_the_pose_fix() {
    let map = Arc::new(map_with_scene_points(true));
    let image = query_image(&place_image(5));
    let descriptor = unit_vector(1, DIM);
    let frame = Frame {
        timestamp: 0.0,
        descriptor: &descriptor,
        image: Some(gray(&image)),
        odometry: None,
    };
    let out = Localizer::new(map.clone(), verifying(Some(camera())))
        .unwrap()
        .localize(&frame)
        .unwrap();
    assert_eq!(out.place, 1);
    let fix = out.pose_fix.expect("a pose fix");
    assert_eq!(fix.view, 1);
    let error = (fix.world_t_optical.translation.vector - query_centre()).norm();
    assert!(error < 0.03, "fix {fix:?}, error {error:.3} m");

    // Without a camera, verification alone gives no fix.
    let out = Localizer::new(map, verifying(None))
        .unwrap()
        .localize(&frame)
        .unwrap();
    assert!(out.candidates[0].verified && out.pose_fix.is_none());
}

#[test]
fn scene_points_survive_the_map_file() {
    let map = map_with_scene_points(true);
    let loaded = Map::from_bytes(&map.to_bytes().unwrap(), &LoadOptions::default()).unwrap();
    let (a, b) = (map.keypoints().unwrap(), loaded.keypoints().unwrap());
    let bits = |p: &[[f32; 3]]| p.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        bits(a.world_points().unwrap()),
        bits(b.world_points().unwrap())
    );
    assert!(b.view_world_points(0).unwrap()[0][0].is_nan());
    assert!(b.view_world_points(1).unwrap()[0][0].is_finite());

    let plain = map_with_scene_points(false);
    let loaded = Map::from_bytes(&plain.to_bytes().unwrap(), &LoadOptions::default()).unwrap();
    assert!(loaded.keypoints().unwrap().world_points().is_none());
    assert!(loaded.keypoints().unwrap().view_world_points(0).is_none());
}

#[test]
fn bad_scene_points_and_cameras_are_refused() {
    let store = ViewKeypoints::from_views(FeatureKind::Orb, &[detect(&place_image(1))]).unwrap();
    let n = store.total();
    assert!(store
        .clone()
        .with_world_points(vec![[0.0; 3]; n - 1])
        .is_err());
    let mut half_known = vec![[1.0f32; 3]; n];
    half_known[0] = [1.0, f32::NAN, 1.0];
    assert!(store.clone().with_world_points(half_known).is_err());
    let mut infinite = vec![[1.0f32; 3]; n];
    infinite[1] = [f32::INFINITY; 3];
    assert!(store.with_world_points(infinite).is_err());

    let bad_camera = PinholeCamera {
        fx: 0.0,
        ..camera()
    };
    match Localizer::new(
        Arc::new(map_with_scene_points(true)),
        verifying(Some(bad_camera)),
    ) {
        Err(LocalizeError::InvalidOption(msg)) => assert!(msg.contains("camera.fx"), "{msg}"),
        other => panic!("expected an invalid option, got {:?}", other.err()),
    }
    let bad_locate = LocalizerOptions {
        verification: VerificationOptions {
            locate: LocateOptions {
                min_inliers: 2,
                ..LocateOptions::default()
            },
            ..verifying(Some(camera())).verification
        },
        ..verifying(None)
    };
    assert!(matches!(
        Localizer::new(Arc::new(map_with_scene_points(true)), bad_locate),
        Err(LocalizeError::InvalidOption(_))
    ));
    let unverified = LocalizerOptions {
        verification: VerificationOptions {
            candidates: 0,
            ..verifying(Some(camera())).verification
        },
        ..verifying(None)
    };
    match Localizer::new(Arc::new(map_with_scene_points(true)), unverified) {
        Err(LocalizeError::InvalidOption(msg)) => assert!(msg.contains("candidates"), "{msg}"),
        other => panic!("expected an invalid option, got {:?}", other.err()),
    }
    match Localizer::new(
        Arc::new(map_with_scene_points(false)),
        verifying(Some(camera())),
    ) {
        Err(LocalizeError::Verification(msg)) => {
            assert!(msg.contains("scene points"), "{msg}")
        }
        other => panic!("expected a verification error, got {:?}", other.err()),
    }
}
