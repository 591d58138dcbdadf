//! Incremental construction of a [`Map`] from places, views and edges.

use super::{
    is_finite_pose, DescriptorStore, Edge, Map, MapError, PlaceId, ViewId, ViewRecord,
    MAX_DESCRIPTOR_DIM,
};
use crate::descriptor::{normalize_descriptor_into, DescriptorIdentity};
use nalgebra::{Isometry3, Point3};
use std::collections::HashSet;

/// Optional attributes of a view added to a [`MapBuilder`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewAttributes {
    /// Keyframe id in the host SLAM system.
    pub keyframe_id: Option<u64>,
    /// Camera pose `world_T_camera`.
    pub world_t_camera: Option<Isometry3<f64>>,
    /// Reference to the source image (path or URI).
    pub image: Option<String>,
}

/// Collects places, views and edges, then produces a validated [`Map`].
///
/// Every `add_*` method validates its input and leaves the builder unchanged on error.
/// Descriptors are L2-normalised on insertion. Not thread-safe; `build` does not consume the
/// builder, so a host can keep adding and rebuild.
#[derive(Clone, Debug)]
pub struct MapBuilder {
    identity: DescriptorIdentity,
    creator: String,
    descriptors: Vec<f32>,
    views: Vec<ViewRecord>,
    place_positions: Vec<Option<Point3<f64>>>,
    edges: Vec<Edge>,
    edge_set: HashSet<(PlaceId, PlaceId)>,
    scratch: Vec<f32>,
}

impl MapBuilder {
    /// Starts an empty map whose vectors come from the descriptor `identity`.
    pub fn new(identity: DescriptorIdentity) -> Self {
        Self {
            identity,
            creator: format!("topoloc {}", env!("CARGO_PKG_VERSION")),
            descriptors: Vec::new(),
            views: Vec::new(),
            place_positions: Vec::new(),
            edges: Vec::new(),
            edge_set: HashSet::new(),
            scratch: Vec::new(),
        }
    }

    /// Sets the free-text creator recorded in the map file.
    pub fn set_creator(&mut self, creator: impl Into<String>) {
        self.creator = creator.into();
    }

    /// Descriptor identity of the map being built.
    pub fn descriptor(&self) -> &DescriptorIdentity {
        &self.identity
    }

    /// Places added so far.
    pub fn place_count(&self) -> usize {
        self.place_positions.len()
    }

    /// Views added so far.
    pub fn view_count(&self) -> usize {
        self.views.len()
    }

    /// Adds a place, optionally with a position in metres, and returns its id.
    pub fn add_place(&mut self, position: Option<Point3<f64>>) -> Result<PlaceId, MapError> {
        if let Some(p) = position {
            if !p.iter().all(|x| x.is_finite()) {
                return Err(MapError::NonFinite("place position must be finite".into()));
            }
        }
        let id = PlaceId::try_from(self.place_positions.len())
            .map_err(|_| MapError::InvalidArgument("too many places".into()))?;
        self.place_positions.push(position);
        Ok(id)
    }

    /// Adds a view with its descriptor (D values, normalised here) to an existing place.
    pub fn add_view(
        &mut self,
        place: PlaceId,
        descriptor: &[f32],
        attributes: ViewAttributes,
    ) -> Result<ViewId, MapError> {
        if place as usize >= self.place_positions.len() {
            return Err(MapError::UnknownPlace {
                place,
                places: self.place_positions.len(),
            });
        }
        if attributes
            .world_t_camera
            .as_ref()
            .is_some_and(|pose| !is_finite_pose(pose))
        {
            return Err(MapError::NonFinite("view pose must be finite".into()));
        }
        if let Some(image) = &attributes.image {
            refuse_nul(image, "view image reference")?;
        }
        normalize_descriptor_into(descriptor, self.identity.dim as usize, &mut self.scratch)?;
        let id = ViewId::try_from(self.views.len())
            .map_err(|_| MapError::InvalidArgument("too many views".into()))?;
        self.descriptors.extend_from_slice(&self.scratch);
        self.views.push(ViewRecord {
            place,
            keyframe_id: attributes.keyframe_id,
            world_t_camera: attributes.world_t_camera,
            image: attributes.image,
        });
        Ok(id)
    }

    /// Joins two different existing places with an undirected edge of positive weight.
    /// Adding an edge that exists already is an error.
    pub fn add_edge(&mut self, a: PlaceId, b: PlaceId, weight: f32) -> Result<(), MapError> {
        let places = self.place_positions.len();
        for p in [a, b] {
            if p as usize >= places {
                return Err(MapError::UnknownPlace { place: p, places });
            }
        }
        if a == b {
            return Err(MapError::InvalidArgument(format!(
                "edge from place {a} to itself"
            )));
        }
        if !weight.is_finite() {
            return Err(MapError::NonFinite(format!("edge weight {weight}")));
        }
        if weight <= 0.0 {
            return Err(MapError::InvalidArgument(format!(
                "edge weight {weight} must be > 0"
            )));
        }
        let (a, b) = (a.min(b), a.max(b));
        if self.has_edge(a, b) {
            return Err(MapError::InvalidArgument(format!(
                "edge ({a}, {b}) exists already"
            )));
        }
        self.edges.push(Edge { a, b, weight });
        self.edge_set.insert((a, b));
        Ok(())
    }

    /// Whether places `a` and `b` are joined already (in either order).
    pub fn has_edge(&self, a: PlaceId, b: PlaceId) -> bool {
        let (a, b) = (a.min(b), a.max(b));
        self.edge_set.contains(&(a, b))
    }

    /// Position of a place added so far.
    pub(crate) fn place_position(&self, place: PlaceId) -> Option<Point3<f64>> {
        self.place_positions.get(place as usize).copied().flatten()
    }

    /// Normalised descriptor of a view added so far.
    pub(crate) fn view_descriptor(&self, view: ViewId) -> &[f32] {
        let d = self.identity.dim as usize;
        &self.descriptors[view as usize * d..(view as usize + 1) * d]
    }

    /// Validates and produces the map. Fails with [`MapError::EmptyMap`] without places,
    /// [`MapError::Invalid`] when a place has no view, and [`MapError::InvalidArgument`] when
    /// the descriptor kind, model or creator holds a NUL byte (C getters would cut it short) or
    /// the dimension exceeds [`MAX_DESCRIPTOR_DIM`] (the map file refuses larger ones).
    pub fn build(&self) -> Result<Map, MapError> {
        refuse_nul(&self.identity.kind, "descriptor kind")?;
        refuse_nul(&self.identity.model, "descriptor model")?;
        refuse_nul(&self.creator, "creator")?;
        if self.identity.dim > MAX_DESCRIPTOR_DIM {
            return Err(MapError::InvalidArgument(format!(
                "descriptor dimension {} exceeds {MAX_DESCRIPTOR_DIM}",
                self.identity.dim
            )));
        }
        Map::from_parts(
            self.identity.clone(),
            self.creator.clone(),
            DescriptorStore::Owned(self.descriptors.clone()),
            self.views.clone(),
            self.place_positions.clone(),
            self.edges.clone(),
        )
    }
}

/// Refuses a string holding a NUL byte with [`MapError::InvalidArgument`] naming `what`.
fn refuse_nul(value: &str, what: &str) -> Result<(), MapError> {
    if value.contains('\0') {
        return Err(MapError::InvalidArgument(format!(
            "{what} holds a NUL byte"
        )));
    }
    Ok(())
}
