//! Building a map from a keyframe sequence (a SLAM run, or any ordered image sequence).
//!
//! Keyframes are visited in order. With poses, a keyframe joins the nearest existing place within
//! `place_spacing_m` (so revisits merge into the place seen before) and otherwise starts a new
//! place; within a place it becomes a new view only when its appearance is novel (its best cosine
//! similarity to the place's views is below `novelty_similarity`) and the place has room.
//! Without poses, a keyframe starts a new place when it is novel with respect to the current
//! place, and is dropped as redundant otherwise. Edges join the places of consecutive keyframes
//! and, with positions, all places closer than `neighbour_radius_m`.

use crate::bounds::Bounds;
use crate::descriptor::{normalize_descriptor_into, DescriptorIdentity};
use crate::map::{Map, MapBuilder, MapError, PlaceId, ViewAttributes};
use nalgebra::{Isometry3, Point3};

/// One keyframe of the input sequence.
#[derive(Clone, Debug)]
pub struct Keyframe<'a> {
    /// Host keyframe id, stored with the view it becomes.
    pub id: u64,
    /// Global descriptor (D values; normalised here).
    pub descriptor: &'a [f32],
    /// Camera pose `world_T_camera`, if known.
    pub world_t_camera: Option<Isometry3<f64>>,
}

/// Parameters of [`from_keyframes`].
#[derive(Clone, Debug, PartialEq)]
pub struct KeyframeOptions {
    /// Distance in metres within which a keyframe joins an existing place. Default 2.0.
    pub place_spacing_m: f64,
    /// Cosine similarity below which a keyframe's appearance counts as novel. Default 0.9.
    pub novelty_similarity: f32,
    /// Places closer than this (metres) are joined by an edge. Default 1.5 x spacing = 3.0.
    pub neighbour_radius_m: f64,
    /// Most views a place may hold. Default 4 (the seed's four yaw views).
    pub max_views_per_place: u32,
}

impl Default for KeyframeOptions {
    fn default() -> Self {
        Self {
            place_spacing_m: 2.0,
            novelty_similarity: 0.9,
            neighbour_radius_m: 3.0,
            max_views_per_place: 4,
        }
    }
}

impl KeyframeOptions {
    /// Accepted values of [`Self::place_spacing_m`].
    pub const PLACE_SPACING_M_RANGE: Bounds = Bounds::above(0.0);
    /// Accepted values of [`Self::neighbour_radius_m`].
    pub const NEIGHBOUR_RADIUS_M_RANGE: Bounds = Bounds::at_least(0.0);
    /// Accepted values of [`Self::novelty_similarity`] (a cosine).
    pub const NOVELTY_SIMILARITY_RANGE: Bounds = Bounds::closed(-1.0, 1.0);
    /// Accepted values of [`Self::max_views_per_place`].
    pub const MAX_VIEWS_PER_PLACE_RANGE: Bounds = Bounds::whole_at_least(1);

    fn validate(&self) -> Result<(), MapError> {
        Self::PLACE_SPACING_M_RANGE
            .check("place_spacing_m", self.place_spacing_m)
            .and_then(|()| {
                Self::NEIGHBOUR_RADIUS_M_RANGE.check("neighbour_radius_m", self.neighbour_radius_m)
            })
            .and_then(|()| {
                Self::NOVELTY_SIMILARITY_RANGE.check("novelty_similarity", self.novelty_similarity)
            })
            .and_then(|()| {
                Self::MAX_VIEWS_PER_PLACE_RANGE
                    .check("max_views_per_place", self.max_views_per_place)
            })
            .map_err(MapError::InvalidArgument)
    }
}

/// Turns a keyframe sequence into a map (see the module documentation). Either every keyframe
/// has a pose or none has; a mix is refused because spacing would then mean nothing.
pub fn from_keyframes(
    identity: DescriptorIdentity,
    keyframes: &[Keyframe<'_>],
    options: &KeyframeOptions,
) -> Result<Map, MapError> {
    options.validate()?;
    if keyframes.is_empty() {
        return Err(MapError::EmptyMap);
    }
    let with_poses = keyframes[0].world_t_camera.is_some();
    if keyframes
        .iter()
        .any(|k| k.world_t_camera.is_some() != with_poses)
    {
        return Err(MapError::InvalidArgument(
            "either every keyframe has a pose or none has".into(),
        ));
    }
    let dim = identity.dim as usize;
    let mut builder = MapBuilder::new(identity);
    let mut views_of_place: Vec<Vec<u32>> = Vec::new();
    let mut unit = Vec::with_capacity(dim);
    let mut previous_place: Option<PlaceId> = None;

    for (index, keyframe) in keyframes.iter().enumerate() {
        normalize_descriptor_into(keyframe.descriptor, dim, &mut unit).map_err(|e| {
            MapError::InvalidArgument(format!("keyframe {index} (id {}): {e}", keyframe.id))
        })?;
        let position = keyframe
            .world_t_camera
            .map(|pose| Point3::from(pose.translation.vector));
        let candidate = match position {
            Some(p) => nearest_place_within(&builder, p, options.place_spacing_m),
            None => previous_place,
        };
        let place = match candidate {
            Some(place) => {
                let views = &views_of_place[place as usize];
                let novel = best_similarity(&builder, views, &unit) < options.novelty_similarity;
                match (novel, position.is_some()) {
                    // Same spot, new appearance: another view of the place, if it has room.
                    (true, true) if views.len() < options.max_views_per_place as usize => {
                        Some(place)
                    }
                    // No poses: novelty alone decides that the robot reached a new place.
                    (true, false) => None,
                    // Redundant keyframe, or a full place: nothing to add.
                    _ => {
                        link(&mut builder, previous_place, place)?;
                        previous_place = Some(place);
                        continue;
                    }
                }
            }
            None => None,
        };
        let place = match place {
            Some(p) => p,
            None => {
                views_of_place.push(Vec::new());
                builder.add_place(position)?
            }
        };
        let attributes = ViewAttributes {
            keyframe_id: Some(keyframe.id),
            world_t_camera: keyframe.world_t_camera,
            image: None,
        };
        let view = builder.add_view(place, &unit, attributes)?;
        views_of_place[place as usize].push(view);
        link(&mut builder, previous_place, place)?;
        previous_place = Some(place);
    }

    if with_poses && options.neighbour_radius_m > 0.0 {
        join_close_places(&mut builder, options.neighbour_radius_m)?;
    }
    builder.build()
}

/// Highest cosine similarity of a unit descriptor to the given views.
fn best_similarity(builder: &MapBuilder, views: &[u32], unit: &[f32]) -> f32 {
    let dot = |a: &[f32]| -> f32 { a.iter().zip(unit).map(|(x, y)| x * y).sum() };
    views
        .iter()
        .map(|&v| dot(builder.view_descriptor(v)))
        .fold(f32::NEG_INFINITY, f32::max)
}

fn link(builder: &mut MapBuilder, from: Option<PlaceId>, to: PlaceId) -> Result<(), MapError> {
    match from {
        Some(from) if from != to && !builder.has_edge(from, to) => builder.add_edge(from, to, 1.0),
        _ => Ok(()),
    }
}

fn nearest_place_within(builder: &MapBuilder, p: Point3<f64>, radius: f64) -> Option<PlaceId> {
    (0..builder.place_count() as PlaceId)
        .filter_map(|place| {
            builder
                .place_position(place)
                .map(|q| (place, (q - p).norm()))
        })
        .filter(|&(_, d)| d <= radius)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(place, _)| place)
}

fn join_close_places(builder: &mut MapBuilder, radius: f64) -> Result<(), MapError> {
    let places = builder.place_count() as PlaceId;
    for a in 0..places {
        let Some(pa) = builder.place_position(a) else {
            continue;
        };
        for b in a + 1..places {
            let Some(pb) = builder.place_position(b) else {
                continue;
            };
            if (pa - pb).norm() <= radius && !builder.has_edge(a, b) {
                builder.add_edge(a, b, 1.0)?;
            }
        }
    }
    Ok(())
}
