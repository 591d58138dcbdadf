//! Progress bars of the scenario's long steps (`topoloc demo`, `topoloc simulate`).

use crate::backend_args::progress_bar;
use std::sync::Mutex;
use topoloc_sim::scenario::Step;

/// Progress bars of the long steps, one at a time (none when quiet, e.g. in JSON mode).
/// [`report`](Self::report) may be called from worker threads.
pub(crate) struct StepBars {
    quiet: bool,
    current: Mutex<Option<(Step, indicatif::ProgressBar)>>,
}

impl StepBars {
    pub(crate) fn new(quiet: bool) -> Self {
        Self {
            quiet,
            current: Mutex::new(None),
        }
    }

    /// `done` of `total` items of `step`; a new step replaces the bar of the previous one.
    pub(crate) fn report(&self, step: Step, done: usize, total: usize) {
        if self.quiet {
            return;
        }
        let mut current = self.current.lock().unwrap_or_else(|p| p.into_inner());
        if current.as_ref().is_none_or(|(s, _)| *s != step) {
            if let Some((_, bar)) = current.take() {
                bar.finish_and_clear();
            }
            let name = match step {
                Step::Capture => "map views",
                Step::BuildMap => "describing",
                Step::Render => "rendering",
                Step::Describe => "describing",
            };
            *current = Some((step, progress_bar(total, name)));
        }
        if let Some((_, bar)) = current.as_ref() {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        }
    }

    /// Clears the current bar.
    pub(crate) fn finish(&self) {
        if let Some((_, bar)) = self
            .current
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .take()
        {
            bar.finish_and_clear();
        }
    }
}
