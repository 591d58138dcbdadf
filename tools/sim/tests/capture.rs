//! Map capture on a generated world: the skeleton graph of its free space, four yaw views per
//! place, a VLAD map on that graph, and views found again under another condition.

use std::sync::Arc;
use topoloc::describe::vlad::VladOptions;
use topoloc::describe::{BackendConfig, FitOptions};
use topoloc::map::{skeleton_graph, ImageMapOptions, SkeletonOptions};
use topoloc::{Frame, Localizer, LocalizerOptions, Mode};
use topoloc_sim::capture::{build_map, capture, image_view, CaptureError, CaptureOptions};
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
    let captured = capture(&renderer, &graph, &options).unwrap();
    let views = 4 * graph.places.len();
    assert_eq!(captured.images.len(), views);
    assert_eq!(captured.layout.views.len(), views);
    // View j of place i looks along yaw j * 90 degrees from the place.
    let (place, pose) = captured.layout.views[4 * 2 + 1];
    assert_eq!(place, 2);
    assert_eq!(pose.translation.vector, graph.places[2].position.coords);
    assert!((topoloc_sim::camera::yaw_of(&pose) - std::f64::consts::FRAC_PI_2).abs() < 1e-9);
    // Deterministic.
    let again = capture(&renderer, &graph, &options).unwrap();
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
    let queries = capture(&renderer, &graph, &dim).unwrap();
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
    match capture(&renderer, &graph, &bad) {
        Err(CaptureError::InvalidArgument(m)) => assert!(m.contains("views_per_place"), "{m}"),
        other => panic!(
            "expected InvalidArgument, got {:?}",
            other.map(|c| c.images.len())
        ),
    }
}
