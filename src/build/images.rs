//! Maps built from images: every image is described in parallel (rayon), the describer model
//! (PCA, VLAD codebook) is fitted on all of them, and the map is assembled either as a sequence
//! (consecutive groups of `views_per_place` images form a place, places chained in order), with
//! camera poses by [`from_keyframes`] (places by spacing, revisits merged), or on a known place
//! graph ([`ImageLayout`]).
//!
//! The map stores its describer, so localizers created with `Localizer::with_describer`
//! describe query images exactly as the map's images were. Each view records the index of its
//! source image as its keyframe id and the image's path (when built from files).

use super::keyframes::{from_keyframes, Keyframe, KeyframeOptions};
use crate::bounds::Bounds;
use crate::describe::describer::{fit, BackendConfig, Extractor, FitOptions, RawFeatures};
use crate::descriptor::DescriptorIdentity;
use crate::errors::VisionError;
use crate::image::{read_rgb, ImageView, PixelFormat};
use crate::map::{Map, MapBuilder, MapError, PlaceId, ViewAttributes};
use crate::verify::{
    cells_from_map, FeatureDetector, FeatureKind, Keypoints, ViewKeypoints, XFeatOptions, CELL_TAP,
    DEFAULT_KEYPOINTS, MAX_KEYPOINTS,
};
use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How to build a map from images.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageMapOptions {
    /// Descriptor backend and its options. Default: ONNX (as the CLI and the C API).
    pub backend: BackendConfig,
    /// How the describer model is fitted (D, samples).
    pub fit: FitOptions,
    /// Without poses: consecutive images per place (1, or 4 for the seed's yaw views). With
    /// poses: the most views a place may hold. Default 1.
    pub views_per_place: usize,
    /// Place spacing and merging when poses are given.
    pub keyframes: KeyframeOptions,
    /// Worker threads describing images; 0 means one per core, at most
    /// `MAX_BUILD_THREADS`. They are joined before the build returns.
    pub threads: usize,
    /// Keypoints stored per view for geometric verification (`crate::verify`), at most
    /// [`MAX_KEYPOINTS`]; 0 stores none. Default [`DEFAULT_KEYPOINTS`] (about 20 KB per view
    /// of ORB).
    pub keypoints: usize,
    /// Which local features those keypoints are. Default [`DEFAULT_MAP_FEATURES`].
    pub features: FeatureKind,
    /// Where the XFeat network is, when `features` is XFeat.
    pub xfeat: XFeatOptions,
}

impl Default for ImageMapOptions {
    fn default() -> Self {
        Self {
            backend: BackendConfig::Onnx(Default::default()),
            fit: FitOptions::default(),
            views_per_place: 1,
            keyframes: KeyframeOptions::default(),
            threads: 0,
            keypoints: DEFAULT_KEYPOINTS,
            features: DEFAULT_MAP_FEATURES,
            xfeat: XFeatOptions::default(),
        }
    }
}

/// The local features a map built from images stores by default: XFeat, the kind that verified
/// best on Gardens Point's second session (BENCHMARKS.md says which data chose it). Its model
/// comes from `scripts/setup-models.sh`; a build without it fails naming what to install.
pub const DEFAULT_MAP_FEATURES: FeatureKind = FeatureKind::XFeat;

/// The most describing threads a build accepts ([`ImageMapOptions::threads`]).
pub const MAX_BUILD_THREADS: usize = 256;

impl ImageMapOptions {
    /// Accepted values of [`Self::threads`] (0: one per core).
    pub const THREADS_RANGE: Bounds = Bounds::whole(0, MAX_BUILD_THREADS as u64);
    /// Accepted values of [`Self::views_per_place`].
    pub const VIEWS_PER_PLACE_RANGE: Bounds = Bounds::whole(1, 64);
    /// Accepted values of [`Self::keypoints`] (0: none stored).
    pub const KEYPOINTS_RANGE: Bounds = Bounds::whole(0, MAX_KEYPOINTS as u64);
}

/// Where an image comes from.
#[derive(Clone, Copy, Debug)]
pub enum ImageSource<'a> {
    /// A file OpenCV can decode; its path is recorded with the view.
    File(&'a std::path::Path),
    /// Pixels in memory.
    Pixels(ImageView<'a>),
}

/// The stage a build is in, for progress reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildStage {
    /// Describing images: `done` of `total`.
    Describing,
    /// Fitting the describer model (codebook, PCA) and assembling the map.
    Fitting,
}

/// What [`build_from_images`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ImageMapReport {
    /// Images described.
    pub images: usize,
    /// Images without content (blank, constant, no local feature) kept as views anyway, so that
    /// image indices stay aligned; their descriptors carry no place information.
    pub uninformative: Vec<usize>,
    /// Wall time describing images, seconds.
    pub describe_seconds: f64,
    /// Wall time fitting and assembling, seconds.
    pub fit_seconds: f64,
}

/// Errors of [`build_from_images`]: the image (index and source) that failed, or the step.
#[derive(Debug, thiserror::Error)]
pub enum ImageMapError {
    /// Describing one image failed.
    #[error("image {index} ({source_name}): {error}")]
    Image {
        /// Index in the input list.
        index: usize,
        /// Path, or "pixels".
        source_name: String,
        /// Why.
        error: VisionError,
    },
    /// Loading the backend or fitting the model failed.
    #[error(transparent)]
    Describe(#[from] VisionError),
    /// Assembling the map failed.
    #[error(transparent)]
    Map(#[from] MapError),
    /// The progress callback asked to stop.
    #[error("cancelled by the progress callback")]
    Cancelled,
}

/// How the described images become places and edges.
#[derive(Clone, Copy, Debug)]
pub enum ImageLayout<'a> {
    /// Consecutive groups of [`ImageMapOptions::views_per_place`] images form places, chained in
    /// order.
    Sequence,
    /// One `world_T_camera` per image: places by spacing and revisits merged
    /// ([`from_keyframes`] with [`ImageMapOptions::keyframes`]).
    Keyframes(&'a [Isometry3<f64>]),
    /// A known place graph (e.g. from skeleton map building): image `i` is a view of place
    /// `views[i].0` taken from pose `views[i].1`.
    Graph(&'a PlaceLayout),
}

/// A known place graph for [`ImageLayout::Graph`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlaceLayout {
    /// Position of each place, world metres.
    pub positions: Vec<Point3<f64>>,
    /// Undirected edges between places (each pair once).
    pub edges: Vec<(PlaceId, PlaceId)>,
    /// For each image, in order: its place and its `world_T_camera`.
    pub views: Vec<(PlaceId, Isometry3<f64>)>,
}

/// Describes `images` with the chosen backend, fits the describer and builds the map (see the
/// module documentation) with `layout`.
/// `progress(stage, done, total)` is called on the calling thread about ten times a second and
/// at each stage change; returning `false` cancels the build ([`ImageMapError::Cancelled`]).
pub fn build_from_images(
    images: &[ImageSource<'_>],
    layout: ImageLayout<'_>,
    options: &ImageMapOptions,
    progress: &mut dyn FnMut(BuildStage, usize, usize) -> bool,
) -> Result<(Map, ImageMapReport), ImageMapError> {
    check_request(images.len(), &layout, options)?;
    // Load one extractor first so that a missing backend fails before any thread starts.
    let first = Extractor::new(&options.backend)?;
    let spec = first.spec().clone();
    let start = Instant::now();
    let raws = describe_in_parallel(images, first, options, progress)?;
    let describe_seconds = start.elapsed().as_secs_f64();

    if !progress(BuildStage::Fitting, 0, 1) {
        return Err(ImageMapError::Cancelled);
    }
    let start = Instant::now();
    let uninformative: Vec<usize> = raws
        .iter()
        .enumerate()
        .filter(|(_, described)| !described.informative)
        .map(|(i, _)| i)
        .collect();
    let keypoints = (options.keypoints > 0)
        .then(|| ViewKeypoints::from_views(options.features, raws.iter().map(|d| &d.keypoints)))
        .transpose()
        .map_err(|e| VisionError::Model(format!("local features: {e}")))?;
    let raws: Vec<RawFeatures> = raws.into_iter().map(|d| d.raw).collect();
    let (model, descriptors) = fit(&spec, &raws, &options.fit)?;
    let identity = model.identity();
    let sources: Vec<Option<String>> = images
        .iter()
        .map(|s| match s {
            ImageSource::File(p) => Some(p.display().to_string()),
            ImageSource::Pixels(_) => None,
        })
        .collect();
    let map = assemble(identity, &descriptors, &sources, layout, options)?;
    let map = map.with_describer(Arc::new(model))?;
    let map = match keypoints {
        Some(keypoints) => map.with_keypoints(keypoints)?,
        None => map,
    };
    if !progress(BuildStage::Fitting, 1, 1) {
        return Err(ImageMapError::Cancelled);
    }
    let report = ImageMapReport {
        images: images.len(),
        uninformative,
        describe_seconds,
        fit_seconds: start.elapsed().as_secs_f64(),
    };
    Ok((map, report))
}

/// The request is well-formed: enough images, one pose or layout view per image, options in
/// range.
fn check_request(
    images: usize,
    layout: &ImageLayout<'_>,
    options: &ImageMapOptions,
) -> Result<(), ImageMapError> {
    if images < 2 {
        return Err(MapError::InvalidArgument(format!(
            "a map from images needs at least 2 images, got {}",
            images
        ))
        .into());
    }
    let per_image = match layout {
        ImageLayout::Sequence => None,
        ImageLayout::Keyframes(poses) => Some((poses.len(), "poses")),
        ImageLayout::Graph(graph) => Some((graph.views.len(), "layout views")),
    };
    if let Some((count, what)) = per_image.filter(|(count, _)| *count != images) {
        return Err(MapError::InvalidArgument(format!(
            "{count} {what} for {} images: give one per image",
            images
        ))
        .into());
    }
    ImageMapOptions::THREADS_RANGE
        .check("threads (0 = one per core)", options.threads)
        .and_then(|()| {
            ImageMapOptions::VIEWS_PER_PLACE_RANGE.check("views_per_place", options.views_per_place)
        })
        .and_then(|()| {
            ImageMapOptions::KEYPOINTS_RANGE.check("keypoints (0 = none)", options.keypoints)
        })
        .map_err(MapError::InvalidArgument)?;
    if options.keypoints > 0
        && options.features == FeatureKind::Cells
        && !matches!(options.backend, BackendConfig::Onnx(_))
    {
        return Err(MapError::InvalidArgument(
            "features is cells: dense cells come from a CNN feature map and need the ONNX backend"
                .into(),
        )
        .into());
    }
    Ok(())
}

/// The map of the described images, placed as `layout` says.
fn assemble(
    identity: DescriptorIdentity,
    descriptors: &[Vec<f32>],
    sources: &[Option<String>],
    layout: ImageLayout<'_>,
    options: &ImageMapOptions,
) -> Result<Map, MapError> {
    Ok(match layout {
        ImageLayout::Keyframes(poses) => {
            let keyframes: Vec<Keyframe> = descriptors
                .iter()
                .zip(poses)
                .enumerate()
                .map(|(i, (d, pose))| Keyframe {
                    id: i as u64,
                    descriptor: d,
                    world_t_camera: Some(*pose),
                })
                .collect();
            let keyframe_options = KeyframeOptions {
                max_views_per_place: options.views_per_place as u32,
                ..options.keyframes.clone()
            };
            from_keyframes(identity, &keyframes, &keyframe_options)?
        }
        ImageLayout::Sequence => {
            sequence_map(identity, descriptors, sources, options.views_per_place)?
        }
        ImageLayout::Graph(graph) => graph_map(identity, descriptors, sources, graph)?,
    })
}

/// Consecutive groups of `per_place` images form places, chained in order.
fn sequence_map(
    identity: DescriptorIdentity,
    descriptors: &[Vec<f32>],
    sources: &[Option<String>],
    per_place: usize,
) -> Result<Map, MapError> {
    let mut builder = MapBuilder::new(identity);
    for (group, chunk) in descriptors.chunks(per_place).enumerate() {
        let place = builder.add_place(None)?;
        for (k, d) in chunk.iter().enumerate() {
            let index = group * per_place + k;
            builder.add_view(
                place,
                d,
                ViewAttributes {
                    keyframe_id: Some(index as u64),
                    world_t_camera: None,
                    image: sources[index].clone(),
                },
            )?;
        }
        if place > 0 {
            builder.add_edge(place - 1, place, 1.0)?;
        }
    }
    builder.build()
}

/// The places and edges of `graph`, each image a view of its place.
fn graph_map(
    identity: DescriptorIdentity,
    descriptors: &[Vec<f32>],
    sources: &[Option<String>],
    graph: &PlaceLayout,
) -> Result<Map, MapError> {
    let mut builder = MapBuilder::new(identity);
    for position in &graph.positions {
        builder.add_place(Some(*position))?;
    }
    for (index, ((place, pose), d)) in graph.views.iter().zip(descriptors).enumerate() {
        builder.add_view(
            *place,
            d,
            ViewAttributes {
                keyframe_id: Some(index as u64),
                world_t_camera: Some(*pose),
                image: sources[index].clone(),
            },
        )?;
    }
    for &(a, b) in &graph.edges {
        builder.add_edge(a, b, 1.0)?;
    }
    builder.build()
}

/// What one image gave.
struct Described {
    raw: RawFeatures,
    /// False for an image without content (see [`ImageMapReport::uninformative`]).
    informative: bool,
    /// Its keypoints (empty when the options ask for none).
    keypoints: Keypoints,
}

/// One worker's tools: the backend's extractor and, when keypoints are stored, a detector.
type Workers = (Extractor, Option<FeatureDetector>);

/// Raw features (and keypoints) of every image; in input order.
///
/// Longer than most functions on purpose: the workers, the scoped pool and the progress loop
/// share the `done` / `cancelled` counters and the spare extractor by borrow, and reading them
/// in one place shows how cancellation reaches every thread.
fn describe_in_parallel(
    images: &[ImageSource<'_>],
    first: Extractor,
    options: &ImageMapOptions,
    progress: &mut dyn FnMut(BuildStage, usize, usize) -> bool,
) -> Result<Vec<Described>, ImageMapError> {
    let total = images.len();
    let cells = (options.keypoints > 0 && options.features == FeatureKind::Cells)
        .then_some(options.keypoints);
    let done = AtomicUsize::new(0);
    let cancelled = AtomicBool::new(false);
    let spare = std::sync::Mutex::new(Some(first));
    let work = |pool: &rayon::ThreadPool| {
        pool.install(|| {
            images
                .par_iter()
                .enumerate()
                .map_init(
                    || -> Result<Workers, VisionError> {
                        let extractor = match spare.lock().map(|mut s| s.take()) {
                            Ok(Some(e)) => e,
                            _ => Extractor::new(&options.backend)?,
                        };
                        let detector = match (options.keypoints, cells) {
                            (0, _) | (_, Some(_)) => None,
                            (n, None) => {
                                Some(FeatureDetector::new(options.features, n, &options.xfeat)?)
                            }
                        };
                        Ok((extractor, detector))
                    },
                    |workers, (index, source)| {
                        if cancelled.load(Ordering::Relaxed) {
                            return Err(ImageMapError::Cancelled);
                        }
                        let (extractor, detector) = workers
                            .as_mut()
                            .map_err(|e| ImageMapError::Describe(e.duplicate()))?;
                        let result = describe_one(extractor, detector.as_mut(), cells, source)
                            .map_err(|error| ImageMapError::Image {
                                index,
                                source_name: match source {
                                    ImageSource::File(p) => p.display().to_string(),
                                    ImageSource::Pixels(_) => "pixels".into(),
                                },
                                error,
                            });
                        done.fetch_add(1, Ordering::Relaxed);
                        result
                    },
                )
                .collect::<Result<Vec<_>, _>>()
        })
    };
    // The pool is scoped: its workers are joined before `build_scoped` returns, so no thread of
    // ours outlives the build (a C host may unload the library right after it).
    let run_pool = || {
        rayon::ThreadPoolBuilder::new()
            .num_threads(options.threads)
            .build_scoped(|thread| thread.run(), work)
            .map_err(|e| VisionError::InvalidArgument(format!("thread pool: {e}")))?
    };
    std::thread::scope(|scope| {
        let handle = scope.spawn(run_pool);
        let mut last = usize::MAX;
        while !handle.is_finished() {
            let now = done.load(Ordering::Relaxed);
            // After the callback asked to stop, it is not called again.
            if now != last && !cancelled.load(Ordering::Relaxed) {
                last = now;
                if !progress(BuildStage::Describing, now, total) {
                    cancelled.store(true, Ordering::Relaxed);
                }
            }
            std::thread::sleep(Duration::from_millis(100));
        }
        let result = handle
            .join()
            .unwrap_or_else(|panic| std::panic::resume_unwind(panic));
        if cancelled.load(Ordering::Relaxed) {
            return Err(ImageMapError::Cancelled);
        }
        if result.is_ok() && !progress(BuildStage::Describing, total, total) {
            return Err(ImageMapError::Cancelled);
        }
        result
    })
}

/// Raw features and keypoints of one image (by `detector`, or the `cells` strongest dense cells
/// of the same forward pass); uninformative images give the backend's output anyway (a blank
/// image's CNN features, or an empty set of local features) and `false`.
fn describe_one(
    extractor: &mut Extractor,
    detector: Option<&mut FeatureDetector>,
    cells: Option<usize>,
    source: &ImageSource<'_>,
) -> Result<Described, VisionError> {
    let owned;
    let view = match source {
        ImageSource::File(path) => {
            owned = read_rgb(path)?;
            ImageView::packed(owned.0, owned.1, PixelFormat::Rgb8, &owned.2)
        }
        ImageSource::Pixels(view) => *view,
    };
    if let Some(max_cells) = cells {
        let (raw, informative, tap) = extractor.extract_with_tap(&view, CELL_TAP)?;
        let keypoints = cells_from_map(
            &tap.values,
            [tap.channels, tap.height, tap.width],
            tap.cell_size,
            max_cells,
        )?;
        return Ok(Described {
            raw,
            informative,
            keypoints,
        });
    }
    let (raw, informative) = extractor.extract_keeping_uninformative(&view)?;
    let keypoints = match detector {
        Some(d) => d.detect(&view)?,
        None => Keypoints::default(),
    };
    Ok(Described {
        raw,
        informative,
        keypoints,
    })
}
