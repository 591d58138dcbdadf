//! The demo's picture: a generated world from above with its skeleton graph, the query
//! trajectory, and where one localizer configuration put each frame (a line from the camera to
//! the predicted place: green when it is the true place, orange within one graph hop, red
//! otherwise), under a caption naming that configuration.

use crate::plot::{ensure_font, FONT_FAMILY};
use anyhow::{anyhow, Result};
use nalgebra::Point3;
use plotters::element::BitMapElement;
use plotters::prelude::*;
use std::path::Path;
use topoloc::eval::HopDistances;
use topoloc::map::PlaceId;
use topoloc::skeleton::NodeKind;
use topoloc_sim::scenario::{Flight, Scene};

/// Shortest side of the picture, pixels; the plan is scaled up by a whole factor to reach it.
const MIN_SIDE: u32 = 700;

/// Writes the top view of storey 0 of `scene` with `flight` and `predicted` (one place per
/// frame, `PlaceId::MAX` for none) to `path` (PNG); `caption`, the first line of the legend,
/// says whose predictions they are.
pub fn write_top_view(
    path: &Path,
    scene: &Scene,
    flight: &Flight,
    predicted: &[PlaceId],
    caption: &str,
) -> Result<()> {
    ensure_font()?;
    let plan = scene.world.top_view(0);
    let scale = (MIN_SIDE / plan.width.min(plan.height)).max(1);
    let (w, h) = (plan.width * scale, plan.height * scale);
    let mut buf = vec![0u8; (w * h * 3) as usize];
    for y in 0..h {
        for x in 0..w {
            let px = plan.pixel(x / scale, y / scale);
            let i = 3 * (y * w + x) as usize;
            buf[i..i + 3].copy_from_slice(&px);
        }
    }
    let grid = scene.world.grid();
    let origin = grid.origin();
    let voxel = grid.voxel_size();
    // North (+y) up: row 0 is the largest y.
    let to_px = |p: &Point3<f64>| -> (i32, i32) {
        let col = (p.x - origin.x) / voxel * scale as f64;
        let row = (plan.height as f64 - (p.y - origin.y) / voxel) * scale as f64;
        (col as i32, row as i32)
    };

    let root = BitMapBackend::new(path, (w, h)).into_drawing_area();
    let background = BitMapElement::with_owned_buffer((0, 0), (w, h), buf)
        .ok_or_else(|| anyhow!("top view buffer has the wrong size"))?;
    root.draw(&background)?;

    let hops = HopDistances::from_map(&scene.map);
    let places = &scene.graph.places;
    let step = (flight.truth.len() / 400).max(1);
    for (i, truth) in flight.truth.iter().enumerate().step_by(step) {
        let Some(&guess) = predicted.get(i) else {
            break;
        };
        let Some(place) = places.get(guess as usize) else {
            continue;
        };
        let colour = match hops.hops(guess, truth.place) {
            Some(0) => RGBColor(40, 170, 60),
            Some(1) => RGBColor(240, 150, 20),
            _ => RGBColor(220, 30, 30),
        };
        let camera = Point3::from(
            flight.trajectory.frames[i]
                .world_t_camera
                .translation
                .vector,
        );
        root.draw(&PathElement::new(
            vec![to_px(&camera), to_px(&place.position)],
            colour.mix(0.6).stroke_width(1),
        ))?;
    }
    for edge in &scene.graph.edges {
        let (a, b) = (&places[edge.a as usize], &places[edge.b as usize]);
        root.draw(&PathElement::new(
            vec![to_px(&a.position), to_px(&b.position)],
            RGBColor(60, 60, 60).stroke_width(2),
        ))?;
    }
    let path_px: Vec<(i32, i32)> = flight
        .trajectory
        .frames
        .iter()
        .map(|f| to_px(&Point3::from(f.world_t_camera.translation.vector)))
        .collect();
    root.draw(&PathElement::new(path_px, BLUE.stroke_width(2)))?;
    for place in places {
        let colour = match place.kind {
            NodeKind::End => RGBColor(0, 160, 220),
            NodeKind::Corner => RGBColor(30, 150, 30),
            NodeKind::Branch => RGBColor(210, 20, 20),
            NodeKind::Intermediate => RGBColor(90, 90, 90),
        };
        root.draw(&Circle::new(to_px(&place.position), 5, colour.filled()))?;
    }
    let every = match step {
        1 => "every frame".to_string(),
        n => format!("one frame in {n}"),
    };
    let lines = format!("blue: query trajectory; lines: camera to predicted place, {every}");
    let legend = [
        (caption, BLACK),
        (
            "places: end (cyan), corner (green), branch (red), intermediate (grey)",
            BLACK,
        ),
        (lines.as_str(), BLUE),
        (
            "green = true place, orange = one hop, red = wrong",
            RGBColor(40, 120, 40),
        ),
    ];
    // A white backdrop keeps the legend readable over walls and corridors.
    let font = (FONT_FAMILY, 15).into_font();
    let mut width = 0;
    for (text, _) in &legend {
        width = width.max(root.estimate_text_size(text, &font.clone().into())?.0);
    }
    root.draw(&Rectangle::new(
        [(4, 4), (12 + width as i32, 10 + 18 * legend.len() as i32)],
        WHITE.mix(0.85).filled(),
    ))?;
    for (k, (text, colour)) in legend.iter().enumerate() {
        root.draw(&Text::new(
            *text,
            (8, 8 + 18 * k as i32),
            font.clone().color(colour),
        ))?;
    }
    root.present()
        .map_err(|e| anyhow!("writing {}: {e}", path.display()))?;
    Ok(())
}
