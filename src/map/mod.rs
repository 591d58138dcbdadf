//! The graph map: places (the seed's macro nodes), their views (micro nodes) and the edges
//! between places.
//!
//! A [`Map`] is immutable once built. Build one with [`MapBuilder`], from a keyframe sequence
//! with [`crate::build`], or load one from a file with [`Map::load`]. Maps are `Send + Sync`
//! and are shared between localizers through `Arc<Map>`.
//!
//! Conventions: positions and translations are in metres; a view pose is `world_T_camera`
//! (the camera frame expressed in the world frame); descriptors are `f32`, L2-normalised,
//! stored row-major, one row per view.

mod builder;
mod error;
mod file;

pub use builder::{MapBuilder, ViewAttributes};
pub use error::MapError;
/// Not a stable API: for topoloc's fuzzers and hostile-file tests.
#[doc(hidden)]
pub use file::reseal;
pub use file::{
    LoadOptions, FORMAT_NAME, FORMAT_VERSION_MAJOR, FORMAT_VERSION_MINOR, MAX_DESCRIPTOR_DIM,
};

use crate::describe::DescriberModel;
use crate::descriptor::{check_unit_descriptor, DescriptorIdentity, ExpectedDescriptor};
use crate::verify::ViewKeypoints;
use nalgebra::{Isometry3, Point3};
use std::sync::Arc;

/// Index of a place in a map, `0..map.place_count()`.
pub type PlaceId = u32;
/// Index of a view in a map, `0..map.view_count()`.
pub type ViewId = u32;

/// An undirected edge between two places; `a < b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Edge {
    /// Lower place index.
    pub a: PlaceId,
    /// Higher place index.
    pub b: PlaceId,
    /// Positive weight; higher means a stronger link (the localizer moves belief along edges in
    /// proportion to their weight).
    pub weight: f32,
}

/// Per-view attributes besides the descriptor.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewRecord {
    /// Place this view belongs to.
    pub place: PlaceId,
    /// Keyframe id in the host SLAM system, if the view came from one.
    pub keyframe_id: Option<u64>,
    /// Camera pose `world_T_camera`, if known.
    pub world_t_camera: Option<Isometry3<f64>>,
    /// Reference to the source image (path or URI), if any.
    pub image: Option<String>,
}

/// Row-major descriptor matrix, either owned or a zero-copy view of a memory-mapped file.
pub(crate) enum DescriptorStore {
    Owned(Vec<f32>),
    /// Little-endian `f32`s, 4-byte aligned (checked when the store was made, file/mod.rs).
    Mapped(bytes::Bytes),
}

impl DescriptorStore {
    pub(crate) fn as_slice(&self) -> &[f32] {
        match self {
            DescriptorStore::Owned(v) => v,
            DescriptorStore::Mapped(bytes) => bytemuck::cast_slice(bytes),
        }
    }
}

/// An immutable topological map. See the module documentation.
pub struct Map {
    identity: DescriptorIdentity,
    creator: String,
    descriptors: DescriptorStore,
    views: Vec<ViewRecord>,
    place_positions: Vec<Option<Point3<f64>>>,
    /// CSR: views of place p are `place_view_ids[place_view_offsets[p]..place_view_offsets[p+1]]`.
    place_view_offsets: Vec<u32>,
    place_view_ids: Vec<ViewId>,
    edges: Vec<Edge>,
    /// CSR adjacency: neighbours of p are `neighbour_ids[neighbour_offsets[p]..neighbour_offsets[p+1]]`,
    /// with the matching weights in `neighbour_weights`.
    neighbour_offsets: Vec<u32>,
    neighbour_ids: Vec<PlaceId>,
    neighbour_weights: Vec<f32>,
    /// How to describe images for this map, when it was built from images.
    describer: Option<Arc<DescriberModel>>,
    /// ORB keypoints of every view, for geometric verification (maps built from images).
    keypoints: Option<ViewKeypoints>,
    /// Cached [`Map::similarity_spread`].
    spread: std::sync::OnceLock<f32>,
}

impl std::fmt::Debug for Map {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Map")
            .field("identity", &self.identity)
            .field("places", &self.place_count())
            .field("views", &self.view_count())
            .field("edges", &self.edges.len())
            .finish()
    }
}

impl Map {
    /// Assembles and validates a map from its parts. Used by the builder and the file loader so
    /// that every map, however made, passes the same checks.
    pub(crate) fn from_parts(
        identity: DescriptorIdentity,
        creator: String,
        descriptors: DescriptorStore,
        views: Vec<ViewRecord>,
        place_positions: Vec<Option<Point3<f64>>>,
        mut edges: Vec<Edge>,
    ) -> Result<Self, MapError> {
        identity.validate()?;
        let dim = identity.dim as usize;
        let places = place_positions.len();
        if places == 0 {
            return Err(MapError::EmptyMap);
        }
        if places > u32::MAX as usize || views.len() > u32::MAX as usize {
            return Err(MapError::InvalidArgument(
                "more than 2^32-1 places or views".into(),
            ));
        }
        check_descriptors(descriptors.as_slice(), views.len(), dim)?;
        let views_per_place = count_views(&views, places)?;
        check_positions(&place_positions)?;
        edges.sort_by_key(|e| (e.a, e.b));
        check_edges(&edges, places)?;
        let (place_view_offsets, place_view_ids) = place_view_index(&views, &views_per_place);
        let (neighbour_offsets, neighbour_ids, neighbour_weights) = adjacency(&edges, places);

        Ok(Self {
            identity,
            creator,
            descriptors,
            views,
            place_positions,
            place_view_offsets,
            place_view_ids,
            edges,
            neighbour_offsets,
            neighbour_ids,
            neighbour_weights,
            describer: None,
            keypoints: None,
            spread: std::sync::OnceLock::new(),
        })
    }

    /// Attaches the describer model that produced the map's descriptors, so that localizers can
    /// describe images themselves. Its identity must equal the map's descriptor identity.
    pub fn with_describer(mut self, model: Arc<DescriberModel>) -> Result<Self, MapError> {
        model
            .validate()
            .map_err(|e| MapError::InvalidArgument(format!("describer model: {e}")))?;
        let identity = model.identity();
        if identity != self.identity {
            return Err(MapError::DescriptorMismatch {
                map: self.identity.clone(),
                expected: ExpectedDescriptor {
                    kind: Some(identity.kind),
                    model: Some(identity.model),
                    dim: Some(identity.dim),
                },
            });
        }
        self.describer = Some(model);
        Ok(self)
    }

    /// Attaches the ORB keypoints of every view (for geometric verification); fails unless the
    /// store holds exactly one entry per view.
    pub fn with_keypoints(mut self, keypoints: ViewKeypoints) -> Result<Self, MapError> {
        if keypoints.view_count() != self.view_count() {
            return Err(MapError::InvalidArgument(format!(
                "keypoints for {} views, the map has {}",
                keypoints.view_count(),
                self.view_count()
            )));
        }
        self.keypoints = Some(keypoints);
        Ok(self)
    }

    /// A copy of this map whose keypoints carry the map-frame scene point of each keypoint
    /// (view after view, in the order of [`ViewKeypoints::points`]; all three coordinates NaN
    /// where unknown): what a host with depth or SLAM map points attaches so that the
    /// localizer can place the camera metrically. The copy owns its descriptors (a memory-mapped
    /// map is read into memory). Fails, leaving this map as it is, when the map stores no
    /// keypoints or the points do not match them one to one.
    pub fn with_keypoint_world_points(&self, world_points: Vec<[f32; 3]>) -> Result<Map, MapError> {
        let keypoints = self.keypoints.as_ref().ok_or_else(|| {
            MapError::InvalidArgument(
                "the map stores no keypoints to attach scene points to (build it from images)"
                    .into(),
            )
        })?;
        let keypoints = keypoints
            .clone()
            .with_world_points(world_points)
            .map_err(MapError::InvalidArgument)?;
        Ok(Self {
            identity: self.identity.clone(),
            creator: self.creator.clone(),
            descriptors: DescriptorStore::Owned(self.descriptors.as_slice().to_vec()),
            views: self.views.clone(),
            place_positions: self.place_positions.clone(),
            place_view_offsets: self.place_view_offsets.clone(),
            place_view_ids: self.place_view_ids.clone(),
            edges: self.edges.clone(),
            neighbour_offsets: self.neighbour_offsets.clone(),
            neighbour_ids: self.neighbour_ids.clone(),
            neighbour_weights: self.neighbour_weights.clone(),
            describer: self.describer.clone(),
            keypoints: Some(keypoints),
            spread: self.spread.clone(),
        })
    }

    /// The ORB keypoints of every view, if the map stores them (maps built from images do).
    pub fn keypoints(&self) -> Option<&ViewKeypoints> {
        self.keypoints.as_ref()
    }

    /// The typical spread of similarities in this map's descriptor space: the median, over up to
    /// 64 evenly spaced views, of the standard deviation of a view's cosine similarity to the
    /// views of all other places. It sets the scale of the localizer's automatic temperature
    /// (descriptor spaces differ widely in spread; BENCHMARKS.md). Computed on first use (at most ~2e8 multiply-adds: fewer
    /// sample views on large maps), then cached; 0 for a map with a single place.
    pub fn similarity_spread(&self) -> f32 {
        *self.spread.get_or_init(|| self.compute_similarity_spread())
    }

    fn compute_similarity_spread(&self) -> f32 {
        let (n, d) = (self.view_count(), self.dim());
        let budget = 200_000_000 / (n * d).max(1);
        let samples = budget.clamp(8, 64).min(n);
        let data = self.descriptors();
        let mut stds: Vec<f64> = (0..samples)
            .filter_map(|k| {
                let v = k * n / samples;
                let query = &data[v * d..(v + 1) * d];
                let own = self.views[v].place;
                let (mut count, mut sum, mut sum_sq) = (0usize, 0.0f64, 0.0f64);
                for (row, record) in data.chunks_exact(d).zip(&self.views) {
                    if record.place == own {
                        continue;
                    }
                    let s = f64::from(row.iter().zip(query).map(|(a, b)| a * b).sum::<f32>());
                    count += 1;
                    sum += s;
                    sum_sq += s * s;
                }
                (count > 1).then(|| {
                    let mean = sum / count as f64;
                    (sum_sq / count as f64 - mean * mean).max(0.0).sqrt()
                })
            })
            .collect();
        if stds.is_empty() {
            return 0.0;
        }
        stds.sort_by(f64::total_cmp);
        stds[stds.len() / 2] as f32
    }

    /// The describer model stored with the map (maps built from images have one).
    pub fn describer(&self) -> Option<&Arc<DescriberModel>> {
        self.describer.as_ref()
    }

    /// The descriptor that produced this map's vectors.
    pub fn descriptor(&self) -> &DescriptorIdentity {
        &self.identity
    }

    /// Free text naming the program that created the map.
    pub fn creator(&self) -> &str {
        &self.creator
    }

    /// Number of places (macro nodes).
    pub fn place_count(&self) -> usize {
        self.place_positions.len()
    }

    /// Number of views (micro nodes).
    pub fn view_count(&self) -> usize {
        self.views.len()
    }

    /// Number of undirected edges.
    pub fn edge_count(&self) -> usize {
        self.edges.len()
    }

    /// Descriptor dimension D.
    pub fn dim(&self) -> usize {
        self.identity.dim as usize
    }

    /// True when the descriptors are read in place from a memory-mapped file (zero-copy load).
    pub fn is_memory_mapped(&self) -> bool {
        matches!(self.descriptors, DescriptorStore::Mapped { .. })
    }

    /// All descriptors, row-major `view_count() x dim()`.
    pub fn descriptors(&self) -> &[f32] {
        self.descriptors.as_slice()
    }

    /// Descriptor of one view (D values, unit norm).
    pub fn view_descriptor(&self, view: ViewId) -> Result<&[f32], MapError> {
        self.check_view(view)?;
        let d = self.dim();
        Ok(&self.descriptors()[view as usize * d..(view as usize + 1) * d])
    }

    /// Descriptor of one view without bounds checks (for per-frame loops; `view < view_count()`).
    pub(crate) fn view_descriptor_unchecked(&self, view: usize) -> &[f32] {
        let d = self.dim();
        &self.descriptors()[view * d..(view + 1) * d]
    }

    /// Attributes of one view.
    pub fn view(&self, view: ViewId) -> Result<&ViewRecord, MapError> {
        self.check_view(view)?;
        Ok(&self.views[view as usize])
    }

    /// All view records, indexed by view id.
    pub fn views(&self) -> &[ViewRecord] {
        &self.views
    }

    /// Place of each view, without bounds checks (for per-frame loops).
    pub(crate) fn view_place_unchecked(&self, view: usize) -> usize {
        self.views[view].place as usize
    }

    /// Views of a place, in increasing id order.
    pub fn place_views(&self, place: PlaceId) -> Result<&[ViewId], MapError> {
        self.check_place(place)?;
        let p = place as usize;
        Ok(&self.place_view_ids
            [self.place_view_offsets[p] as usize..self.place_view_offsets[p + 1] as usize])
    }

    /// Views of a place without bounds checks (for per-frame loops; `place < place_count()`).
    pub(crate) fn place_views_unchecked(&self, place: usize) -> &[ViewId] {
        &self.place_view_ids
            [self.place_view_offsets[place] as usize..self.place_view_offsets[place + 1] as usize]
    }

    /// Neighbouring places without bounds checks (for per-frame loops; `place < place_count()`).
    pub(crate) fn neighbours_unchecked(&self, place: usize) -> &[PlaceId] {
        &self.neighbour_ids
            [self.neighbour_offsets[place] as usize..self.neighbour_offsets[place + 1] as usize]
    }

    /// Position of a place in metres, if the map has one.
    pub fn place_position(&self, place: PlaceId) -> Result<Option<Point3<f64>>, MapError> {
        self.check_place(place)?;
        Ok(self.place_positions[place as usize])
    }

    /// Neighbouring places and the weights of the edges to them.
    pub fn neighbours(&self, place: PlaceId) -> Result<(&[PlaceId], &[f32]), MapError> {
        self.check_place(place)?;
        let p = place as usize;
        let range = self.neighbour_offsets[p] as usize..self.neighbour_offsets[p + 1] as usize;
        Ok((
            &self.neighbour_ids[range.clone()],
            &self.neighbour_weights[range],
        ))
    }

    /// All edges, sorted by `(a, b)`.
    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    pub(crate) fn place_positions(&self) -> &[Option<Point3<f64>>] {
        &self.place_positions
    }

    fn check_place(&self, place: PlaceId) -> Result<(), MapError> {
        if (place as usize) < self.place_count() {
            Ok(())
        } else {
            Err(MapError::UnknownPlace {
                place,
                places: self.place_count(),
            })
        }
    }

    fn check_view(&self, view: ViewId) -> Result<(), MapError> {
        if (view as usize) < self.view_count() {
            Ok(())
        } else {
            Err(MapError::UnknownView {
                view,
                views: self.view_count(),
            })
        }
    }
}

/// Every row of the `views x dim` descriptor matrix is finite with unit norm.
fn check_descriptors(data: &[f32], views: usize, dim: usize) -> Result<(), MapError> {
    if data.len() != views * dim {
        return Err(MapError::Invalid(format!(
            "descriptor matrix holds {} values, expected {views} views x D={dim}",
            data.len()
        )));
    }
    for (v, row) in data.chunks_exact(dim).enumerate() {
        check_unit_descriptor(row).map_err(|e| MapError::Invalid(format!("view {v}: {e}")))?;
    }
    Ok(())
}

/// Views per place, after checking that every view names an existing place and has a finite
/// pose, and that every place has a view.
fn count_views(views: &[ViewRecord], places: usize) -> Result<Vec<u32>, MapError> {
    let mut views_per_place = vec![0u32; places];
    for (v, view) in views.iter().enumerate() {
        let p = view.place as usize;
        if p >= places {
            return Err(MapError::Invalid(format!(
                "view {v} belongs to place {p}, but the map has {places} places"
            )));
        }
        views_per_place[p] += 1;
        if let Some(pose) = &view.world_t_camera {
            check_pose(pose).map_err(|e| MapError::Invalid(format!("view {v}: {e}")))?;
        }
    }
    if let Some(p) = views_per_place.iter().position(|&n| n == 0) {
        return Err(MapError::Invalid(format!("place {p} has no view")));
    }
    Ok(views_per_place)
}

fn check_positions(place_positions: &[Option<Point3<f64>>]) -> Result<(), MapError> {
    for (p, pos) in place_positions.iter().enumerate() {
        if pos.is_some_and(|pos| !pos.iter().all(|x| x.is_finite())) {
            return Err(MapError::Invalid(format!(
                "place {p} has a non-finite position"
            )));
        }
    }
    Ok(())
}

/// Edges (sorted by `(a, b)`) join two different existing places, once, with a finite
/// positive weight.
fn check_edges(edges: &[Edge], places: usize) -> Result<(), MapError> {
    for (i, e) in edges.iter().enumerate() {
        if e.a >= e.b || e.b as usize >= places {
            return Err(MapError::Invalid(format!(
                "edge ({}, {}) must join two different existing places (a < b < {places})",
                e.a, e.b
            )));
        }
        if !(e.weight.is_finite() && e.weight > 0.0) {
            return Err(MapError::Invalid(format!(
                "edge ({}, {}) has weight {}, must be finite and > 0",
                e.a, e.b, e.weight
            )));
        }
        if i > 0 && (edges[i - 1].a, edges[i - 1].b) == (e.a, e.b) {
            return Err(MapError::Invalid(format!(
                "edge ({}, {}) appears twice",
                e.a, e.b
            )));
        }
    }
    Ok(())
}

/// CSR index of the views of every place: offsets and view ids.
fn place_view_index(views: &[ViewRecord], views_per_place: &[u32]) -> (Vec<u32>, Vec<ViewId>) {
    let offsets = prefix_offsets(views_per_place);
    let mut fill = offsets.clone();
    let mut ids = vec![0; views.len()];
    for (v, view) in views.iter().enumerate() {
        let slot = &mut fill[view.place as usize];
        ids[*slot as usize] = v as ViewId;
        *slot += 1;
    }
    (offsets, ids)
}

/// CSR adjacency of the places: offsets, neighbour ids and the matching edge weights.
fn adjacency(edges: &[Edge], places: usize) -> (Vec<u32>, Vec<PlaceId>, Vec<f32>) {
    let mut degree = vec![0u32; places];
    for e in edges {
        degree[e.a as usize] += 1;
        degree[e.b as usize] += 1;
    }
    let offsets = prefix_offsets(&degree);
    let mut fill = offsets.clone();
    let mut ids = vec![0; edges.len() * 2];
    let mut weights = vec![0.0; edges.len() * 2];
    for e in edges {
        for (from, to) in [(e.a, e.b), (e.b, e.a)] {
            let slot = &mut fill[from as usize];
            ids[*slot as usize] = to;
            weights[*slot as usize] = e.weight;
            *slot += 1;
        }
    }
    (offsets, ids, weights)
}

fn prefix_offsets(counts: &[u32]) -> Vec<u32> {
    let mut offsets = Vec::with_capacity(counts.len() + 1);
    let mut total = 0u32;
    offsets.push(0);
    for &c in counts {
        total += c;
        offsets.push(total);
    }
    offsets
}

fn check_pose(pose: &Isometry3<f64>) -> Result<(), String> {
    if !is_finite_pose(pose) {
        return Err("pose has a non-finite value".into());
    }
    Ok(())
}

/// True when every value of a rigid transform (translation and rotation quaternion) is finite:
/// the check every pose a caller gives (view poses, odometry, keyframe poses) passes.
pub(crate) fn is_finite_pose(pose: &Isometry3<f64>) -> bool {
    pose.translation
        .vector
        .iter()
        .chain(pose.rotation.coords.iter())
        .all(|x| x.is_finite())
}
