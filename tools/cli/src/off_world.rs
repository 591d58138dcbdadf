//! Does the localizer notice that the robot has left its map? A localizer settles on the first
//! frames of the mapped flight, then gets frames flown through another generated world (another
//! style, so not the map's building under another light); the report is the share of those
//! frames flagged off-map once 10 have passed (the target is "flagged within 10 frames") and
//! the first one flagged.

use anyhow::{Context, Result};
use nalgebra::Isometry3;
use topoloc::describe::{Describer, DescriberOptions};
use topoloc::image::ImageView;
use topoloc::{Frame, Localization, Localizer, Map};
use topoloc_sim::capture::image_view;
use topoloc_sim::render::Image;
use topoloc_sim::scenario::{fly_elsewhere, ScenarioOptions, Step};
use topoloc_sim::world::WorldParams;
use topoloc_synthetic::Sequence;

/// Off-map frames counted only after this many: "flagged within 10 frames".
pub(crate) const SETTLE_FRAMES: usize = 10;

/// Frames from another world, described by the map's describer.
pub(crate) struct OffWorldFrames {
    /// The world's style name.
    pub style: String,
    descriptors: Vec<Vec<f32>>,
    /// `previous_T_current` per frame (identity for the first).
    increments: Vec<Isometry3<f64>>,
    images: Vec<Image>,
}

/// How one configuration flagged the frames from another world.
#[derive(Clone, Copy, Debug)]
pub(crate) struct OffWorldFlags {
    /// Share of the frames after the first [`SETTLE_FRAMES`] flagged off-map.
    pub flagged_after_settle: f64,
    /// Index (among the off-world frames) of the first frame flagged.
    pub first_flag: Option<usize>,
}

/// Flies `options.trajectory` through a world of `params` and describes its first `frames`
/// frames with `map`'s describer.
pub(crate) fn off_world_frames(
    map: &Map,
    params: &WorldParams,
    options: &ScenarioOptions,
    frames: usize,
    progress: &(dyn Fn(Step, usize, usize) + Sync),
) -> Result<OffWorldFrames> {
    let elsewhere = fly_elsewhere(
        params,
        options,
        &options.capture.intrinsics,
        frames,
        progress,
    )?;
    let model = map
        .describer()
        .cloned()
        .context("the map stores no describer")?;
    let mut describer = Describer::new(model, &DescriberOptions::default())?;
    let descriptors = elsewhere
        .images
        .iter()
        .map(|image| {
            let mut out = Vec::new();
            describer.describe(&image_view(image), &mut out)?;
            Ok(out)
        })
        .collect::<Result<Vec<_>>>()?;
    let poses = &elsewhere.odometry;
    let increments = (0..poses.len())
        .map(|i| match i {
            0 => Isometry3::identity(),
            _ => poses[i - 1].world_t_camera.inverse() * poses[i].world_t_camera,
        })
        .collect();
    Ok(OffWorldFrames {
        style: params.style.name.clone(),
        descriptors,
        increments,
        images: elsewhere.images,
    })
}

/// Localizes the first `lead_in` frames of `on` with a new `localizer` (given their
/// `on_images` when it verifies), then every frame of `off`, and reports how the off-world
/// frames were flagged. The off-world frames carry their own odometry when `use_odometry` (the
/// robot keeps moving).
pub(crate) fn off_world_flags(
    mut localizer: Localizer,
    on: &Sequence,
    on_images: Option<&[ImageView<'_>]>,
    lead_in: usize,
    off: &OffWorldFrames,
    use_odometry: bool,
) -> Result<OffWorldFlags> {
    let verifying = localizer.options().verification.enabled();
    let image_only = localizer.wants_image_only();
    let mut out = Localization::default();
    let lead_in = lead_in.min(on.frames.len());
    for (i, f) in on.frames[..lead_in].iter().enumerate() {
        let frame = Frame {
            timestamp: f.timestamp,
            descriptor: if image_only { &[] } else { &f.descriptor },
            odometry: use_odometry.then_some(f.odometry),
            image: on_images.map(|images| images[i]),
        };
        localizer.process(&frame, &mut out)?;
    }
    let last = on.frames[..lead_in].last().map_or(0.0, |f| f.timestamp);
    let period = match on.frames.get(1) {
        Some(second) => second.timestamp - on.frames[0].timestamp,
        None => 0.1,
    };
    let mut flags = Vec::with_capacity(off.descriptors.len());
    for (i, descriptor) in off.descriptors.iter().enumerate() {
        let frame = Frame {
            timestamp: last + period * (i + 1) as f64,
            descriptor: if image_only { &[] } else { descriptor },
            odometry: use_odometry.then_some(off.increments[i]),
            image: verifying.then(|| image_view(&off.images[i])),
        };
        localizer.process(&frame, &mut out)?;
        flags.push(out.off_map);
    }
    let counted = flags.get(SETTLE_FRAMES..).unwrap_or_default();
    Ok(OffWorldFlags {
        flagged_after_settle: counted.iter().filter(|&&f| f).count() as f64
            / counted.len().max(1) as f64,
        first_flag: flags.iter().position(|&f| f),
    })
}
