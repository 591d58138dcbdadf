//! Where a keyframe's time goes: the describing and verification stages add their wall time to
//! the calling thread's totals, which [`take`] returns and resets. Bench commands (the CLI's
//! `bench-loops`) read them per keyframe; nothing else does. Always on: two clock reads per
//! stage, tens of nanoseconds against stages of tens of microseconds and more.

use std::cell::RefCell;
use std::time::{Duration, Instant};

/// A stage of describing a keyframe or checking its loop candidates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    /// The CNN's input: the image converted to RGB, resized and normalised.
    CnnInput,
    /// The CNN's forward pass (ONNX Runtime).
    Cnn,
    /// Pooling the CNN's feature maps and projecting them (PCA): the global descriptor.
    Pooling,
    /// Local features: the keypoint detector on the image (XFeat's resize, network and
    /// keypoint selection; ORB), or the dense cells taken from the CNN's feature map.
    LocalFeatures,
    /// Matching a keyframe's local features with a candidate's (mutual nearest neighbours).
    Matching,
    /// The fundamental-matrix fit of a candidate's matches (and the no-motion count).
    Fit,
    /// Relative-pose fits (essential matrix or PnP).
    Pose,
}

impl Stage {
    /// Every stage, in pipeline order.
    pub const ALL: [Stage; 7] = [
        Stage::CnnInput,
        Stage::Cnn,
        Stage::Pooling,
        Stage::LocalFeatures,
        Stage::Matching,
        Stage::Fit,
        Stage::Pose,
    ];

    /// A short name for tables and JSON (`cnn_input`, `cnn`, ...).
    pub fn name(self) -> &'static str {
        match self {
            Stage::CnnInput => "cnn_input",
            Stage::Cnn => "cnn",
            Stage::Pooling => "pooling",
            Stage::LocalFeatures => "local_features",
            Stage::Matching => "matching",
            Stage::Fit => "fit",
            Stage::Pose => "pose",
        }
    }

    fn index(self) -> usize {
        Stage::ALL
            .iter()
            .position(|&s| s == self)
            .expect("ALL lists every stage")
    }
}

/// Wall time per stage, summed over the calls since the last [`take`] on this thread.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StageTimes {
    totals: [Duration; Stage::ALL.len()],
    calls: [u32; Stage::ALL.len()],
}

impl StageTimes {
    /// The time spent in `stage`.
    pub fn get(&self, stage: Stage) -> Duration {
        self.totals[stage.index()]
    }

    /// How many times `stage` ran.
    pub fn calls(&self, stage: Stage) -> u32 {
        self.calls[stage.index()]
    }

    /// The time of every stage together.
    pub fn total(&self) -> Duration {
        self.totals.iter().sum()
    }
}

thread_local! {
    static TOTALS: RefCell<StageTimes> = RefCell::new(StageTimes::default());
}

/// Runs `f` and adds its wall time to `stage`'s total on this thread. A stage measured inside
/// another is counted in both (none of the library's stages nest).
pub fn measure<T>(stage: Stage, f: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let out = f();
    add(stage, start.elapsed());
    out
}

/// Adds one call of `stage` that took `elapsed` to this thread's totals (for a stage whose
/// end is not a closure's: timed with an [`Instant`] by the caller).
pub fn add(stage: Stage, elapsed: Duration) {
    TOTALS.with(|t| {
        let mut t = t.borrow_mut();
        let i = stage.index();
        t.totals[i] += elapsed;
        t.calls[i] = t.calls[i].saturating_add(1);
    });
}

/// This thread's stage times since the last call (or since it started), reset to zero.
pub fn take() -> StageTimes {
    TOTALS.with(|t| std::mem::take(&mut *t.borrow_mut()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn measured_stages_add_up_per_thread_and_take_resets() {
        let _ = take();
        let slept = measure(Stage::Matching, || {
            std::thread::sleep(Duration::from_millis(3));
            7
        });
        assert_eq!(slept, 7);
        measure(Stage::Matching, || {});
        measure(Stage::Cnn, || std::thread::sleep(Duration::from_millis(1)));
        // Another thread's stages are its own.
        std::thread::spawn(|| {
            measure(Stage::Cnn, || std::thread::sleep(Duration::from_millis(20)))
        })
        .join()
        .unwrap();
        let times = take();
        assert_eq!(times.calls(Stage::Matching), 2);
        assert_eq!(times.calls(Stage::Cnn), 1);
        assert_eq!(times.calls(Stage::Pose), 0);
        assert!(times.get(Stage::Matching) >= Duration::from_millis(3));
        assert_eq!(
            times.total(),
            times.get(Stage::Matching) + times.get(Stage::Cnn)
        );
        assert_eq!(take(), StageTimes::default());
    }
}
