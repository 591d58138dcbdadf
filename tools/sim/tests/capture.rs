//! Map capture on a generated world: the skeleton graph of its free space, four yaw views per
//! place, a VLAD map on that graph, and views found again under another condition.

use std::sync::Arc;
use topoloc::build::ImageMapOptions;
use topoloc::describe::vlad::VladOptions;
use topoloc::describe::{BackendConfig, FitOptions};
use topoloc::skeleton::{skeleton_graph, SkeletonOptions};
use topoloc::verify::{locate, FeatureKind, KeypointDetector, LocateOptions};
use topoloc::{Frame, Localizer, LocalizerOptions, Mode};
use topoloc_sim::capture::{
    build_map, capture, image_view, with_scene_points, CaptureError, CaptureOptions,
};
use topoloc_sim::render::{Condition, ConditionKind, Renderer};
use topoloc_sim::world::{World, WorldParams};

fn small_world() -> World {
    let params = WorldParams {
        floors: 1,
        rooms_per_floor: 3,
        ..WorldParams::from_style(7, topoloc_sim::style::Style::office())
    };
    World::generate(&params).expect("world")
}

#[test]
fn captured_views_build_a_map_on_the_skeleton_graph_that_finds_them_again() {
    let world = small_world();
    let graph = skeleton_graph(world.grid(), &SkeletonOptions::default()).expect("graph");
    assert!(graph.places.len() >= 4, "{} places", graph.places.len());
    let renderer = Renderer::new(&world);
    let options = CaptureOptions::default();
    let captured = capture(&renderer, world.grid(), &graph, &options).unwrap();
    let views = 4 * graph.places.len();
    assert_eq!(captured.images.len(), views);
    assert_eq!(captured.layout.views.len(), views);
    // View j of place i looks along yaw j * 90 degrees from the place.
    let (place, pose) = captured.layout.views[4 * 2 + 1];
    assert_eq!(place, 2);
    assert_eq!(pose.translation.vector, graph.places[2].position.coords);
    assert!((topoloc_sim::camera::yaw_of(&pose) - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
    // Deterministic.
    let again = capture(&renderer, world.grid(), &graph, &options).unwrap();
    assert!(again.images == captured.images);

    // A small codebook keeps the test fast; the defaults are measured by the benchmarks.
    let map_options = ImageMapOptions {
        backend: BackendConfig::Vlad(VladOptions {
            clusters: 16,
            ..VladOptions::default()
        }),
        fit: FitOptions {
            codebook_samples: 20_000,
            ..FitOptions::default()
        },
        threads: 2,
        // The test places dim views with ORB keypoints: the map stores ORB too.
        features: FeatureKind::Orb,
        ..ImageMapOptions::default()
    };
    let (map, _) = build_map(&captured, &map_options, &mut |_, _, _| true).unwrap();
    assert_eq!(map.place_count(), graph.places.len());
    assert_eq!(map.view_count(), views);
    assert_eq!(map.edge_count(), graph.edges.len());

    // The same views under dim light: most are found at their own place, single-frame.
    let dim = CaptureOptions {
        condition: Condition::preset(ConditionKind::Dim),
        seed: 99,
        ..options
    };
    let queries = capture(&renderer, world.grid(), &graph, &dim).unwrap();

    // With scene points, each dim view is placed back at its own pose against its bright twin.
    let map = with_scene_points(map, &renderer, &captured, &options.intrinsics).unwrap();
    let keypoints = map.keypoints().unwrap();
    let mut detector = KeypointDetector::new(500).unwrap();
    let mut errors: Vec<f64> = (0..views)
        .filter_map(|v| {
            let query = detector.detect(&image_view(&queries.images[v])).unwrap();
            let fix = locate(
                query.as_ref(),
                keypoints.view(v).unwrap(),
                keypoints.view_world_points(v).unwrap(),
                &options.intrinsics.pinhole(),
                64,
                &LocateOptions::default(),
            )
            .unwrap()?;
            Some((fix.position().coords - captured.layout.views[v].1.translation.vector).norm())
        })
        .collect();
    errors.sort_by(f64::total_cmp);
    assert!(
        errors.len() * 10 >= views * 8,
        "{} of {views} views placed",
        errors.len()
    );
    let (median, worst) = (errors[errors.len() / 2], errors[errors.len() - 1]);
    assert!(median < 0.01, "median error {median:.3} m");
    assert!(worst < 0.1, "worst error {worst:.3} m");

    let map = Arc::new(map);
    let mut localizer = Localizer::with_describer(
        map,
        LocalizerOptions {
            mode: Mode::SingleFrame,
            ..Default::default()
        },
        &Default::default(),
    )
    .unwrap();
    let correct = queries
        .images
        .iter()
        .zip(&queries.layout.views)
        .filter(|(image, (place, _))| {
            let frame = Frame {
                image: Some(image_view(image)),
                ..Frame::default()
            };
            localizer.localize(&frame).unwrap().place == *place
        })
        .count();
    let rate = correct as f64 / views as f64;
    assert!(
        rate >= 0.6,
        "{correct} of {views} views found at their place"
    );
}

#[test]
fn bad_capture_options_name_the_field() {
    let world = small_world();
    let graph = skeleton_graph(world.grid(), &SkeletonOptions::default()).unwrap();
    let renderer = Renderer::new(&world);
    let bad = CaptureOptions {
        views_per_place: 0,
        ..Default::default()
    };
    let cases = [
        (bad, "views_per_place"),
        (
            CaptureOptions {
                ring_radius_m: -0.5,
                ..Default::default()
            },
            "ring_radius_m",
        ),
        (
            CaptureOptions {
                ring_radius_m: f64::NAN,
                ..Default::default()
            },
            "ring_radius_m",
        ),
        (
            CaptureOptions {
                ring_radius_m: 1.0,
                ring_points: 17,
                ..Default::default()
            },
            "ring_points",
        ),
    ];
    for (options, field) in cases {
        match capture(&renderer, world.grid(), &graph, &options) {
            Err(CaptureError::InvalidArgument(m)) => assert!(m.contains(field), "{m}"),
            other => panic!(
                "{field}: expected InvalidArgument, got {:?}",
                other.map(|c| c.images.len())
            ),
        }
    }
}

#[test]
fn ring_views_follow_the_centre_views_and_stay_in_their_place_cell() {
    let world = small_world();
    let graph = skeleton_graph(world.grid(), &SkeletonOptions::default()).unwrap();
    let renderer = Renderer::new(&world);
    let centre_only = CaptureOptions::default();
    let ring = CaptureOptions {
        ring_radius_m: 0.6,
        ..Default::default()
    };
    let plain = capture(&renderer, world.grid(), &graph, &centre_only).unwrap();
    let ringed = capture(&renderer, world.grid(), &graph, &ring).unwrap();
    let centre_views = 4 * graph.places.len();
    // The centre views keep their ids (ground truth names them) and come first.
    assert_eq!(plain.layout.views[..], ringed.layout.views[..centre_views]);
    assert!(ringed.images[..centre_views] == plain.images[..]);
    let extra = &ringed.layout.views[centre_views..];
    assert!(!extra.is_empty(), "no ring point kept in the whole world");
    assert_eq!(extra.len() % 4, 0, "every ring point has all four yaws");
    assert_eq!(ringed.images.len(), ringed.layout.views.len());
    let positions: Vec<_> = graph.places.iter().map(|p| p.position).collect();
    for (place, pose) in extra {
        let q = nalgebra::Point3::from(pose.translation.vector);
        let own = positions[*place as usize];
        assert!(((q - own).norm() - 0.6).abs() < 1e-9, "on the ring");
        assert!(
            world.grid().segment_is_free(&own, &q),
            "in sight of its place"
        );
        let nearest = positions
            .iter()
            .map(|p| (q - p).norm())
            .fold(f64::INFINITY, f64::min);
        assert_eq!(nearest, (q - own).norm(), "nearest to its own place");
    }
    // Ring views are grouped by place, place-major after the centre views.
    assert!(extra.windows(2).all(|w| w[0].0 <= w[1].0));
}
