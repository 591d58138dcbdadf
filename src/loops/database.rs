//! The keyframe database: every keyframe the host adds is kept (loop queries name keyframes, as
//! DBoW2 and ORB-SLAM's `KeyFrameDatabase` do) and assigned to a place of a graph that grows
//! online.
//!
//! Place assignment, per keyframe in order: it joins the place of the previous keyframe unless
//! it is *novel* there (its best cosine similarity to that place's keyframes is below
//! [`DatabaseOptions::novelty_similarity`]) *and far* from it (with poses: farther than
//! [`DatabaseOptions::place_spacing_m`] from the place's position; without poses appearance
//! alone decides). A new place is linked to the previous one and, with poses, to every place
//! within [`DatabaseOptions::neighbour_radius_m`]. Keyframes never merge into an old place by
//! pose: the host's odometry drifts, and finding the old place again by appearance is what a
//! loop query is for.
//!
//! Sessions: a host whose odometry restarts in a new world frame (ORB-SLAM3 starting a new map
//! after tracking is lost, VINS-Fusion starting a new sequence) calls
//! [`KeyframeDatabase::begin_session`]. The keyframes held then become an earlier session's,
//! as those of [`KeyframeDatabase::from_map`] are: their times and path lengths are no longer
//! compared with the new session's, and their poses, in another world frame, are compared only
//! with poses of their own session. New places are then linked by pose only within the session.

use super::LoopsError;
use crate::bounds::Bounds;
use crate::descriptor::{normalize_descriptor_into, row_similarities, DescriptorIdentity};
use crate::map::{is_finite_pose, Map, MapBuilder, PlaceId, ViewAttributes};
use nalgebra::{Isometry3, Point3};
use std::collections::BTreeSet;
use std::path::Path;

/// How keyframes become places. `Default` gives the documented defaults (those of
/// [`crate::build::KeyframeOptions`], so that a database and a keyframe-built map agree).
#[derive(Clone, Debug, PartialEq)]
pub struct DatabaseOptions {
    /// Cosine similarity below which a keyframe is novel at the previous keyframe's place.
    /// Default 0.9.
    pub novelty_similarity: f32,
    /// With poses, a novel keyframe starts a new place only farther than this from the
    /// previous place's position (metres). Default 2.0.
    pub place_spacing_m: f64,
    /// With poses, a new place is linked to every place within this distance (metres; 0 links
    /// consecutive places only). Default 3.0.
    pub neighbour_radius_m: f64,
}

impl Default for DatabaseOptions {
    fn default() -> Self {
        Self {
            novelty_similarity: 0.9,
            place_spacing_m: 2.0,
            neighbour_radius_m: 3.0,
        }
    }
}

impl DatabaseOptions {
    /// Accepted values of [`Self::novelty_similarity`] (a cosine).
    pub const NOVELTY_SIMILARITY_RANGE: Bounds = Bounds::closed(-1.0, 1.0);
    /// Accepted values of [`Self::place_spacing_m`] and [`Self::neighbour_radius_m`], metres.
    pub const DISTANCE_RANGE: Bounds = Bounds::at_least(0.0);

    fn validate(&self) -> Result<(), LoopsError> {
        Self::NOVELTY_SIMILARITY_RANGE
            .check("novelty_similarity", self.novelty_similarity)
            .and_then(|()| Self::DISTANCE_RANGE.check("place_spacing_m", self.place_spacing_m))
            .and_then(|()| {
                Self::DISTANCE_RANGE.check("neighbour_radius_m", self.neighbour_radius_m)
            })
            .map_err(LoopsError::InvalidOption)
    }
}

/// One keyframe as the host gives it.
#[derive(Clone, Debug, Default)]
pub struct KeyframeEntry<'a> {
    /// The host's keyframe id; must increase from one keyframe to the next.
    pub id: u64,
    /// Time in seconds; must not decrease.
    pub timestamp: f64,
    /// Global descriptor (D values of the database's descriptor; normalised here).
    pub descriptor: &'a [f32],
    /// Odometry pose of the body, `world_T_body` (metres). Either every keyframe has one or
    /// none has.
    pub world_t_body: Option<Isometry3<f64>>,
    /// Camera in the body frame, `body_T_camera`; identity when `None`.
    pub body_t_camera: Option<Isometry3<f64>>,
}

impl KeyframeEntry<'_> {
    /// The camera's odometry pose, `world_T_body * body_T_camera`, when the keyframe has one.
    pub fn world_t_camera(&self) -> Option<Isometry3<f64>> {
        self.world_t_body
            .map(|body| body * self.body_t_camera.unwrap_or_else(Isometry3::identity))
    }
}

/// Where an added keyframe went.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Added {
    /// Its place.
    pub place: PlaceId,
    /// Whether the keyframe started that place.
    pub new_place: bool,
}

/// Which keyframes a loop query may return (DBoW2's `max_results`, `max_id`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopQuery {
    /// Most candidates returned, best first.
    pub max_results: usize,
    /// Only keyframes with an id at most this (excludes the recent ones); `None` = any.
    pub max_id: Option<u64>,
    /// Only keyframes with a timestamp earlier than this; `None` = any. Keyframes reloaded
    /// from a map count as earlier than every timestamp.
    pub before_timestamp: Option<f64>,
    /// A keyframe whose id is less than this from a better candidate's is left out, so that
    /// the candidates come from different stretches of the route: consecutive keyframes see the
    /// same things, and one look-alike stretch would otherwise fill every slot (ORB-SLAM groups
    /// its candidates by covisibility for the same reason). 0 = keep all (default).
    pub min_id_gap: u64,
}

impl Default for LoopQuery {
    fn default() -> Self {
        Self {
            max_results: 5,
            max_id: None,
            before_timestamp: None,
            min_id_gap: 0,
        }
    }
}

/// One candidate keyframe of a query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Match {
    /// The keyframe's id.
    pub keyframe_id: u64,
    /// Its place.
    pub place: PlaceId,
    /// Cosine similarity of the query to the keyframe.
    pub similarity: f32,
}

/// What the database keeps of a keyframe besides its descriptor row.
#[derive(Clone, Debug)]
struct Record {
    id: u64,
    /// `-inf` for keyframes reloaded from a map (their times belong to another session).
    timestamp: f64,
    place: PlaceId,
    world_t_camera: Option<Isometry3<f64>>,
    /// The odometry's path length from this session's first keyframe to this one (metres);
    /// `None` without poses and for reloaded keyframes (another session's odometry).
    travelled_m: Option<f64>,
    /// The session whose world frame `world_t_camera` is in (0 for the first, and for
    /// keyframes reloaded from a map).
    session: u32,
}

#[derive(Clone, Debug, Default)]
struct Place {
    position: Option<Point3<f64>>,
    /// The session whose world frame `position` is in.
    session: u32,
    /// Ids of its keyframes, increasing.
    members: Vec<u64>,
}

/// Keyframes of one SLAM run (or several, reloaded), grouped into places, queried by
/// appearance. Not `Sync` for writing: one host thread adds and erases; queries take `&self`.
///
/// Memory: `4 D` bytes of descriptor plus about 100 bytes of record and membership per
/// keyframe (see [`KeyframeDatabase::memory_bytes`]; figures in BENCHMARKS.md).
#[derive(Clone, Debug)]
pub struct KeyframeDatabase {
    identity: DescriptorIdentity,
    options: DatabaseOptions,
    /// In id order; row `r` of `descriptors` belongs to `records[r]`.
    records: Vec<Record>,
    descriptors: Vec<f32>,
    places: Vec<Place>,
    /// Undirected place links `(a, b)`, `a < b`.
    edges: BTreeSet<(PlaceId, PlaceId)>,
    last_place: Option<PlaceId>,
    last_timestamp: Option<f64>,
    /// Whether keyframes carry poses; fixed by the first keyframe of a session.
    with_poses: Option<bool>,
    /// This session's last added camera position and path length there (kept when that
    /// keyframe is erased).
    last_travel: Option<(Point3<f64>, f64)>,
    /// The current session (see the module documentation), counted from 0.
    session: u32,
    /// The largest id ever added or reloaded (kept when that keyframe is erased): ids must
    /// increase past it.
    last_id: Option<u64>,
    unit: Vec<f32>,
}

impl KeyframeDatabase {
    /// An empty database for descriptors of `identity` (the graph grows from nothing).
    pub fn new(identity: DescriptorIdentity, options: DatabaseOptions) -> Result<Self, LoopsError> {
        options.validate()?;
        identity.validate().map_err(crate::map::MapError::from)?;
        Ok(Self {
            unit: Vec::with_capacity(identity.dim as usize),
            identity,
            options,
            records: Vec::new(),
            descriptors: Vec::new(),
            places: Vec::new(),
            edges: BTreeSet::new(),
            last_place: None,
            last_timestamp: None,
            with_poses: None,
            last_travel: None,
            session: 0,
            last_id: None,
        })
    }

    /// A database holding a map's views as keyframes, for a later session that queries it
    /// (localization only: add nothing) or extends it. Every view must carry a keyframe id,
    /// increasing with the view index (maps saved by [`KeyframeDatabase::save`] do); new
    /// keyframes need larger ids. The reloaded keyframes are an earlier session's, as after
    /// [`KeyframeDatabase::begin_session`]: older than any timestamp, their poses compared
    /// only among themselves, never with the new keyframes' (which are in the host's new
    /// world frame), and the first new keyframe starts a new place.
    pub fn from_map(map: &Map, options: DatabaseOptions) -> Result<Self, LoopsError> {
        let mut db = Self::new(map.descriptor().clone(), options)?;
        let mut previous: Option<u64> = None;
        for (v, view) in map.views().iter().enumerate() {
            let id = view.keyframe_id.ok_or_else(|| {
                LoopsError::InvalidOption(format!(
                    "view {v} has no keyframe id: a keyframe database reloads only maps it saved"
                ))
            })?;
            if previous.is_some_and(|p| id <= p) {
                return Err(LoopsError::OutOfOrder(format!(
                    "view {v} has keyframe id {id}, not above the previous view's"
                )));
            }
            previous = Some(id);
            db.records.push(Record {
                id,
                timestamp: f64::NEG_INFINITY,
                place: view.place,
                world_t_camera: view.world_t_camera,
                travelled_m: None,
                session: 0,
            });
        }
        db.descriptors.extend_from_slice(map.descriptors());
        db.places = (0..map.place_count() as PlaceId)
            .map(|p| Place {
                position: map.place_position(p).ok().flatten(),
                session: 0,
                members: Vec::new(),
            })
            .collect();
        for r in &db.records {
            db.places[r.place as usize].members.push(r.id);
        }
        db.edges = map.edges().iter().map(|e| (e.a, e.b)).collect();
        db.with_poses = db.records.first().map(|r| r.world_t_camera.is_some());
        db.last_id = db.records.last().map(|r| r.id);
        // The map's keyframes are an earlier session's (session 0, their poses in the map's
        // world frame): the keyframes added now are in the host's new world frame.
        db.begin_session();
        Ok(db)
    }

    /// Adds a keyframe and assigns it to a place (module documentation). The whole entry is
    /// checked first: on error the database is unchanged.
    pub fn add(&mut self, keyframe: &KeyframeEntry<'_>) -> Result<Added, LoopsError> {
        let camera = self.check_entry(keyframe)?;
        let position = camera.map(|pose| Point3::from(pose.translation.vector));
        let join = self
            .last_place
            .filter(|&last| !self.starts_place(last, position));
        let added = match join {
            Some(place) => Added {
                place,
                new_place: false,
            },
            None => Added {
                place: self.new_place(position),
                new_place: true,
            },
        };
        let travelled_m = position.map(|p| self.travelled_to(&p).unwrap_or(0.0));
        self.records.push(Record {
            id: keyframe.id,
            timestamp: keyframe.timestamp,
            place: added.place,
            world_t_camera: camera,
            travelled_m,
            session: self.session,
        });
        self.last_travel = position.zip(travelled_m);
        self.descriptors.extend_from_slice(&self.unit);
        self.places[added.place as usize].members.push(keyframe.id);
        self.last_place = Some(added.place);
        self.last_timestamp = Some(keyframe.timestamp);
        self.with_poses = Some(camera.is_some());
        self.last_id = Some(keyframe.id);
        Ok(added)
    }

    /// Validates an entry against the database's state; leaves its unit descriptor in
    /// `self.unit` and returns the camera pose `world_T_camera`, if any.
    fn check_entry(
        &mut self,
        keyframe: &KeyframeEntry<'_>,
    ) -> Result<Option<Isometry3<f64>>, LoopsError> {
        if self.index_of(keyframe.id).is_some() {
            return Err(LoopsError::DuplicateId(keyframe.id));
        }
        if let Some(last) = self.last_id.filter(|&last| last >= keyframe.id) {
            return Err(LoopsError::OutOfOrder(format!(
                "id {} after id {last}: ids must increase (also past erased keyframes')",
                keyframe.id
            )));
        }
        if !keyframe.timestamp.is_finite() {
            return Err(LoopsError::NonFinite(format!(
                "timestamp {}",
                keyframe.timestamp
            )));
        }
        if let Some(last) = self.last_timestamp.filter(|&t| keyframe.timestamp < t) {
            return Err(LoopsError::OutOfOrder(format!(
                "timestamp {} is earlier than the previous keyframe's {last}",
                keyframe.timestamp
            )));
        }
        for (name, pose) in [
            ("world_t_body", &keyframe.world_t_body),
            ("body_t_camera", &keyframe.body_t_camera),
        ] {
            if pose.as_ref().is_some_and(|p| !is_finite_pose(p)) {
                return Err(LoopsError::NonFinite(format!(
                    "{name} has a NaN or infinite value"
                )));
            }
        }
        let has_pose = keyframe.world_t_body.is_some();
        if self.with_poses.is_some_and(|w| w != has_pose) {
            return Err(LoopsError::InvalidOption(
                "either every keyframe has world_t_body or none has".into(),
            ));
        }
        normalize_descriptor_into(keyframe.descriptor, self.dim(), &mut self.unit)?;
        Ok(keyframe.world_t_camera())
    }

    /// Whether the keyframe in `self.unit` (at `position`) leaves place `last` for a new one.
    fn starts_place(&self, last: PlaceId, position: Option<Point3<f64>>) -> bool {
        let place = &self.places[last as usize];
        let best = place
            .members
            .iter()
            .filter_map(|&id| self.index_of(id))
            .map(|r| dot(self.row(r), &self.unit))
            .fold(f32::NEG_INFINITY, f32::max);
        let novel = best < self.options.novelty_similarity;
        let far = match (position, place.position) {
            (Some(p), Some(q)) => (p - q).norm() > self.options.place_spacing_m,
            _ => true,
        };
        novel && far
    }

    /// Creates a place at `position`, linked to the previous place and to the places near it.
    fn new_place(&mut self, position: Option<Point3<f64>>) -> PlaceId {
        let place = self.places.len() as PlaceId;
        if let Some(last) = self.last_place {
            self.edges.insert((last, place));
        }
        if let Some(p) = position {
            let radius = self.options.neighbour_radius_m;
            for (other, q) in self.places.iter().enumerate() {
                let near = q.position.is_some_and(|q| (q - p).norm() <= radius);
                if near && q.session == self.session {
                    self.edges.insert((other as PlaceId, place));
                }
            }
        }
        self.places.push(Place {
            position,
            session: self.session,
            members: Vec::new(),
        });
        place
    }

    /// Loop candidates for `descriptor`: the keyframes `query` allows, most similar first (ties
    /// by the lower id). Cost: one pass over the keyframes' descriptors; allocates the scores
    /// (with `min_id_gap`, also a sort of the allowed keyframes).
    pub fn loop_candidates(
        &self,
        descriptor: &[f32],
        query: &LoopQuery,
    ) -> Result<Vec<Match>, LoopsError> {
        let mut unit = Vec::with_capacity(self.dim());
        normalize_descriptor_into(descriptor, self.dim(), &mut unit)?;
        if let Some(t) = query.before_timestamp.filter(|t| t.is_nan()) {
            return Err(LoopsError::NonFinite(format!("before_timestamp {t}")));
        }
        let mut scores = vec![0.0f32; self.records.len()];
        row_similarities(&self.descriptors, self.dim(), &unit, &mut scores);
        let mut found: Vec<Match> = self
            .records
            .iter()
            .zip(&scores)
            .filter(|(r, _)| query.max_id.is_none_or(|m| r.id <= m))
            .filter(|(r, _)| query.before_timestamp.is_none_or(|t| r.timestamp < t))
            .map(|(r, &similarity)| Match {
                keyframe_id: r.id,
                place: r.place,
                similarity,
            })
            .collect();
        let order = |a: &Match, b: &Match| {
            b.similarity
                .total_cmp(&a.similarity)
                .then(a.keyframe_id.cmp(&b.keyframe_id))
        };
        if query.min_id_gap > 0 {
            found.sort_unstable_by(order);
            let mut kept: Vec<Match> = Vec::with_capacity(query.max_results.min(found.len()));
            for m in found {
                if kept.len() == query.max_results {
                    break;
                }
                if kept
                    .iter()
                    .all(|k| k.keyframe_id.abs_diff(m.keyframe_id) >= query.min_id_gap)
                {
                    kept.push(m);
                }
            }
            return Ok(kept);
        }
        if query.max_results < found.len() && query.max_results > 0 {
            found.select_nth_unstable_by(query.max_results - 1, order);
        }
        found.truncate(query.max_results);
        found.sort_unstable_by(order);
        Ok(found)
    }

    /// Relocalization candidates for a frame that is not added: every keyframe may match.
    pub fn relocalization_candidates(
        &self,
        descriptor: &[f32],
        max_results: usize,
    ) -> Result<Vec<Match>, LoopsError> {
        self.loop_candidates(
            descriptor,
            &LoopQuery {
                max_results,
                ..LoopQuery::default()
            },
        )
    }

    /// Removes a keyframe (ORB-SLAM culls redundant keyframes). Its place stays in the graph
    /// while it has other keyframes; an emptied place is left out when the database is saved.
    pub fn erase(&mut self, id: u64) -> Result<(), LoopsError> {
        let r = self.index_of(id).ok_or(LoopsError::UnknownKeyframe(id))?;
        let record = self.records.remove(r);
        let d = self.dim();
        self.descriptors.drain(r * d..(r + 1) * d);
        self.places[record.place as usize]
            .members
            .retain(|&member| member != id);
        Ok(())
    }

    /// The database as a topoloc map: a view per keyframe (its id, its camera pose), places
    /// with at least one keyframe (renumbered in order), their links. Fails on an empty
    /// database ([`crate::map::MapError::EmptyMap`]).
    pub fn to_map(&self) -> Result<Map, LoopsError> {
        let mut builder = MapBuilder::new(self.identity.clone());
        builder.set_creator(format!("topoloc {} keyframe database", crate::VERSION));
        let mut renumbered: Vec<Option<PlaceId>> = vec![None; self.places.len()];
        for (p, place) in self.places.iter().enumerate() {
            if !place.members.is_empty() {
                renumbered[p] = Some(builder.add_place(place.position)?);
            }
        }
        for (r, record) in self.records.iter().enumerate() {
            let place = renumbered[record.place as usize].expect("a keyframe's place has members");
            let attributes = ViewAttributes {
                keyframe_id: Some(record.id),
                world_t_camera: record.world_t_camera,
                image: None,
            };
            builder.add_view(place, self.row(r), attributes)?;
        }
        for &(a, b) in &self.edges {
            if let (Some(a), Some(b)) = (renumbered[a as usize], renumbered[b as usize]) {
                builder.add_edge(a.min(b), a.max(b), 1.0)?;
            }
        }
        Ok(builder.build()?)
    }

    /// Saves the database as a topoloc map file (atomic, see [`Map::save`]); reload it with
    /// [`Map::load`] and [`KeyframeDatabase::from_map`].
    pub fn save(&self, path: impl AsRef<Path>) -> Result<(), LoopsError> {
        Ok(self.to_map()?.save(path)?)
    }

    /// Keyframes held.
    pub fn len(&self) -> usize {
        self.records.len()
    }

    /// The smallest id the next keyframe may have: one above the largest id ever added or
    /// reloaded (erased keyframes' included), 0 for a new database; `None` once id `u64::MAX`
    /// was added (no id can follow). A later run whose host ids restart at 0 offsets its ids
    /// by this value after [`KeyframeDatabase::from_map`].
    pub fn next_id(&self) -> Option<u64> {
        self.last_id.map_or(Some(0), |last| last.checked_add(1))
    }

    /// True when no keyframe is held.
    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Places created so far (emptied ones included).
    pub fn place_count(&self) -> usize {
        self.places.len()
    }

    /// The place of a keyframe.
    pub fn place_of(&self, id: u64) -> Result<PlaceId, LoopsError> {
        Ok(self.record(id)?.place)
    }

    /// Whether keyframe `id` is in the database (added, not erased).
    pub fn contains(&self, id: u64) -> bool {
        self.index_of(id).is_some()
    }

    /// Starts a new session whose odometry is in a new world frame (module documentation):
    /// the keyframes held become an earlier session's. Their timestamps become `-inf` and
    /// their path lengths unknown. The next keyframe starts a new place, and its timestamp may
    /// be earlier than the last one's; ids must still increase. Whether keyframes carry
    /// poses stays fixed. Cannot fail.
    pub fn begin_session(&mut self) {
        for record in &mut self.records {
            record.timestamp = f64::NEG_INFINITY;
            record.travelled_m = None;
        }
        self.last_place = None;
        self.last_timestamp = None;
        self.last_travel = None;
        self.session = self.session.saturating_add(1);
    }

    /// Whether keyframes `a` and `b` have poses in one world frame: both have poses and were
    /// added in the same session ([`KeyframeDatabase::begin_session`]).
    pub fn share_world_frame(&self, a: u64, b: u64) -> Result<bool, LoopsError> {
        let (a, b) = (self.record(a)?, self.record(b)?);
        Ok(a.session == b.session && a.world_t_camera.is_some() && b.world_t_camera.is_some())
    }

    /// The ids held from `lo` to `hi` (both included), increasing: a slice of the id-ordered
    /// records found by binary search, so the cost is the ids returned, not `hi - lo`.
    pub fn ids_between(&self, lo: u64, hi: u64) -> impl DoubleEndedIterator<Item = u64> + '_ {
        let start = self.records.partition_point(|r| r.id < lo);
        let end = self.records.partition_point(|r| r.id <= hi).max(start);
        self.records[start..end].iter().map(|r| r.id)
    }

    /// Cosine similarity of `descriptor` (normalised here) to keyframe `id`'s.
    pub fn similarity(&self, descriptor: &[f32], id: u64) -> Result<f32, LoopsError> {
        let r = self.index_of(id).ok_or(LoopsError::UnknownKeyframe(id))?;
        let mut unit = Vec::with_capacity(self.dim());
        normalize_descriptor_into(descriptor, self.dim(), &mut unit)?;
        Ok(dot(self.row(r), &unit))
    }

    /// The largest id held (the last added, unless erased since); `None` when empty.
    pub fn max_id(&self) -> Option<u64> {
        self.records.last().map(|r| r.id)
    }

    /// Whether keyframe `id` was added in the current session (its pose is in the frame of
    /// the keyframes added now).
    pub fn in_current_session(&self, id: u64) -> Result<bool, LoopsError> {
        Ok(self.record(id)?.session == self.session)
    }

    /// Whether keyframes `a` and `b` both have poses in one world frame
    /// ([`KeyframeDatabase::share_world_frame`]) and their cameras lie within
    /// [`DatabaseOptions::neighbour_radius_m`] of each other (the distance that links places).
    pub fn are_neighbours(&self, a: u64, b: u64) -> Result<bool, LoopsError> {
        if !self.share_world_frame(a, b)? {
            return Ok(false);
        }
        let (a, b) = (self.world_t_camera(a)?, self.world_t_camera(b)?);
        Ok(a.zip(b).is_some_and(|(a, b)| {
            (a.translation.vector - b.translation.vector).norm() <= self.options.neighbour_radius_m
        }))
    }

    /// A keyframe's timestamp, seconds; `-inf` for keyframes reloaded from a map (their
    /// times belong to another session).
    pub fn timestamp_of(&self, id: u64) -> Result<f64, LoopsError> {
        Ok(self.record(id)?.timestamp)
    }

    /// The camera pose of a keyframe, `world_T_camera` (`world_T_body * body_T_camera`), when
    /// keyframes carry poses.
    pub fn world_t_camera(&self, id: u64) -> Result<Option<Isometry3<f64>>, LoopsError> {
        Ok(self.record(id)?.world_t_camera)
    }

    /// The odometry's path length (metres) from this session's first keyframe to keyframe
    /// `id`; `None` without poses and for keyframes reloaded from a map.
    pub fn travelled_m(&self, id: u64) -> Result<Option<f64>, LoopsError> {
        Ok(self.record(id)?.travelled_m)
    }

    /// The path length a keyframe at camera position `position` would get if added now
    /// (the last one's plus the straight step to it); `None` before this session's first
    /// keyframe with a pose.
    pub fn travelled_to(&self, position: &Point3<f64>) -> Option<f64> {
        self.last_travel
            .map(|(last, travelled)| travelled + (position - last).norm())
    }

    /// Loop candidates by odometry, for revisits that appearance ranks low (LIO-SAM proposes
    /// its loops by a radius search the same way): this session's keyframes that `query`
    /// allows (its `max_results`, `max_id` and `before_timestamp`; not its id gap) whose
    /// camera lies within `radius_m(path length travelled since that keyframe)` of
    /// `world_t_camera` and faces within `max_angle_deg` of it, nearest first (ties by id).
    /// `similarity` is the query descriptor's cosine to each. Empty without poses.
    pub fn nearby_candidates(
        &self,
        descriptor: &[f32],
        world_t_camera: &Isometry3<f64>,
        radius_m: impl Fn(f64) -> f64,
        max_angle_deg: f64,
        query: &LoopQuery,
    ) -> Result<Vec<Match>, LoopsError> {
        let mut unit = Vec::with_capacity(self.dim());
        normalize_descriptor_into(descriptor, self.dim(), &mut unit)?;
        let here = Point3::from(world_t_camera.translation.vector);
        let Some(travelled_here) = self.travelled_to(&here) else {
            return Ok(Vec::new());
        };
        let max_angle = max_angle_deg.to_radians();
        let mut near: Vec<(f64, usize)> = self
            .records
            .iter()
            .enumerate()
            .filter(|(_, r)| query.max_id.is_none_or(|m| r.id <= m))
            .filter(|(_, r)| query.before_timestamp.is_none_or(|t| r.timestamp < t))
            .filter_map(|(i, r)| {
                let (pose, travelled) = (r.world_t_camera?, r.travelled_m?);
                let distance = (pose.translation.vector - here.coords).norm();
                let turned = pose.rotation.angle_to(&world_t_camera.rotation);
                (distance <= radius_m(travelled_here - travelled) && turned <= max_angle)
                    .then_some((distance, i))
            })
            .collect();
        near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        Ok(near
            .into_iter()
            .take(query.max_results)
            .map(|(_, i)| Match {
                keyframe_id: self.records[i].id,
                place: self.records[i].place,
                similarity: dot(self.row(i), &unit),
            })
            .collect())
    }

    /// True when places `a` and `b` are the same or linked.
    pub fn same_or_linked(&self, a: PlaceId, b: PlaceId) -> bool {
        a == b || self.edges.contains(&(a.min(b), a.max(b)))
    }

    /// The keyframes of place `place` and of the places linked to it (its group), by id.
    pub fn group_keyframes(&self, place: PlaceId) -> Vec<u64> {
        let mut ids: Vec<u64> = self
            .places
            .iter()
            .enumerate()
            .filter(|&(p, _)| self.same_or_linked(place, p as PlaceId))
            .flat_map(|(_, p)| p.members.iter().copied())
            .collect();
        ids.sort_unstable();
        ids
    }

    /// True when the groups of `a` and `b` (each place with its linked places) share a place:
    /// ORB-SLAM's consistency test, with the place graph in the role of covisibility.
    pub fn groups_overlap(&self, a: PlaceId, b: PlaceId) -> bool {
        self.same_or_linked(a, b)
            || self
                .edges
                .iter()
                .filter_map(|&(x, y)| match (x == a, y == a) {
                    (true, _) => Some(y),
                    (_, true) => Some(x),
                    _ => None,
                })
                .any(|n| self.same_or_linked(n, b))
    }

    /// Place links `(a, b)`, `a < b`.
    pub fn edges(&self) -> impl Iterator<Item = (PlaceId, PlaceId)> + '_ {
        self.edges.iter().copied()
    }

    /// Heap bytes the database holds (descriptors, records, memberships, links), from the
    /// capacities of its buffers.
    pub fn memory_bytes(&self) -> usize {
        use std::mem::size_of;
        self.descriptors.capacity() * size_of::<f32>()
            + self.records.capacity() * size_of::<Record>()
            + self.places.capacity() * size_of::<Place>()
            + self
                .places
                .iter()
                .map(|p| p.members.capacity() * size_of::<u64>())
                .sum::<usize>()
            // A B-tree node per few links; about 3 words per link.
            + self.edges.len() * 3 * size_of::<usize>()
    }

    /// The descriptor identity (kind, model, D) every keyframe's descriptor has.
    pub fn identity(&self) -> &DescriptorIdentity {
        &self.identity
    }

    fn dim(&self) -> usize {
        self.identity.dim as usize
    }

    fn row(&self, r: usize) -> &[f32] {
        let d = self.dim();
        &self.descriptors[r * d..(r + 1) * d]
    }

    /// Index of keyframe `id` in `records` (kept in id order).
    fn index_of(&self, id: u64) -> Option<usize> {
        self.records.binary_search_by_key(&id, |r| r.id).ok()
    }

    /// The record of keyframe `id`, or [`LoopsError::UnknownKeyframe`].
    fn record(&self, id: u64) -> Result<&Record, LoopsError> {
        self.index_of(id)
            .map(|r| &self.records[r])
            .ok_or(LoopsError::UnknownKeyframe(id))
    }
}

fn dot(a: &[f32], b: &[f32]) -> f32 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}
