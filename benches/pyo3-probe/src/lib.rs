//! A measuring probe: the smallest pyo3 module that does what the ctypes shim's
//! `Localizer.process` does per frame (localize one descriptor on a map), so that
//! `bench.py` can compare the two bindings' per-call overhead, their copies of the descriptor
//! and their handling of the GIL. Not a product: see python/README.md, "Why ctypes, not pyo3".

use numpy::PyReadonlyArray1;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Instant;
use topoloc::{LoadOptions, Localization, Localizer, LocalizerOptions, Map};

/// The answer for one frame (the fields of the shim's `topoloc.Result` that a descriptor frame
/// fills).
#[pyclass(frozen, get_all, module = "topoloc_pyo3_probe")]
struct ProbeResult {
    frame_index: u64,
    place: u32,
    view: u32,
    confidence: f32,
    similarity: f32,
    off_map: bool,
    off_map_probability: f32,
    /// `(place, view, probability, similarity)`, best first.
    candidates: Vec<(u32, u32, f32, f32)>,
}

impl ProbeResult {
    fn from_localization(out: &Localization) -> Self {
        Self {
            frame_index: out.frame_index,
            place: out.place,
            view: out.view,
            confidence: out.confidence,
            similarity: out.similarity,
            off_map: out.off_map,
            off_map_probability: out.off_map_probability,
            candidates: out
                .candidates
                .iter()
                .map(|c| (c.place, c.view, c.probability, c.similarity))
                .collect(),
        }
    }
}

/// A localizer with the library's default options on a map file (what
/// `topoloc.Localizer(topoloc.Map.load(path))` makes). pyo3 0.30 classes must be `Sync` and a
/// localizer is only `Send` (its OpenCV detectors are not `Sync`), so the state sits behind a
/// mutex, as the shim's localizer sits behind its busy lock; a second thread calling while one
/// is inside gets a `RuntimeError`, as with the shim.
#[pyclass(module = "topoloc_pyo3_probe")]
struct Probe {
    inner: Mutex<Inner>,
}

struct Inner {
    localizer: Localizer,
    scratch: Localization,
    /// Address of the descriptor the last call handed to the localizer (0 before any).
    last_address: usize,
    /// Whether the last call had to copy the descriptor (a non-contiguous array).
    last_copied: bool,
}

/// The descriptor as a slice: borrowed from the numpy array when it is contiguous, else
/// copied into `copy`. A non-float32 array is refused by the argument conversion (TypeError).
fn borrow_descriptor<'a>(
    array: &'a PyReadonlyArray1<'_, f32>,
    copy: &'a mut Vec<f32>,
) -> (&'a [f32], bool) {
    match array.as_slice() {
        Ok(slice) => (slice, false),
        Err(_) => {
            *copy = array.as_array().to_vec();
            (copy.as_slice(), true)
        }
    }
}

fn localize_error(e: topoloc::LocalizeError) -> PyErr {
    PyValueError::new_err(e.to_string())
}

impl Inner {
    fn run(&mut self, slice: &[f32], copied: bool, timestamp: f64) -> PyResult<ProbeResult> {
        let frame = topoloc::Frame {
            timestamp,
            descriptor: slice,
            ..Default::default()
        };
        self.localizer
            .process(&frame, &mut self.scratch)
            .map_err(localize_error)?;
        self.last_address = slice.as_ptr() as usize;
        self.last_copied = copied;
        Ok(ProbeResult::from_localization(&self.scratch))
    }
}

impl Probe {
    fn lock(&self) -> PyResult<MutexGuard<'_, Inner>> {
        self.inner
            .try_lock()
            .map_err(|_| PyRuntimeError::new_err("Probe called while another thread uses it"))
    }
}

#[pymethods]
impl Probe {
    #[new]
    fn new(path: &str) -> PyResult<Self> {
        let map = Map::load(path, &LoadOptions::default())
            .map_err(|e| PyRuntimeError::new_err(format!("loading {path}: {e}")))?;
        let localizer =
            Localizer::new(Arc::new(map), LocalizerOptions::default()).map_err(localize_error)?;
        Ok(Self {
            inner: Mutex::new(Inner {
                localizer,
                scratch: Localization::default(),
                last_address: 0,
                last_copied: false,
            }),
        })
    }

    /// Localizes one frame holding the GIL (what a plain `#[pymethods]` function does).
    fn process(
        &self,
        descriptor: PyReadonlyArray1<'_, f32>,
        timestamp: f64,
    ) -> PyResult<ProbeResult> {
        let mut copy = Vec::new();
        let (slice, copied) = borrow_descriptor(&descriptor, &mut copy);
        self.lock()?.run(slice, copied, timestamp)
    }

    /// Localizes one frame with the GIL released during the Rust work (`Python::detach`).
    fn process_detached(
        &self,
        py: Python<'_>,
        descriptor: PyReadonlyArray1<'_, f32>,
        timestamp: f64,
    ) -> PyResult<ProbeResult> {
        let mut copy = Vec::new();
        let (slice, copied) = borrow_descriptor(&descriptor, &mut copy);
        let mut guard = self.lock()?;
        let inner = &mut *guard;
        py.detach(|| inner.run(slice, copied, timestamp))
    }

    /// The binding's own cost: converts and borrows the arguments as `process` does, then
    /// returns without localizing.
    fn noop(&self, descriptor: PyReadonlyArray1<'_, f32>, timestamp: f64) -> PyResult<()> {
        let mut copy = Vec::new();
        let (slice, copied) = borrow_descriptor(&descriptor, &mut copy);
        let mut inner = self.lock()?;
        inner.last_address = slice.as_ptr() as usize;
        inner.last_copied = copied;
        let _ = timestamp;
        Ok(())
    }

    /// Seconds of each of `n` localizations timed inside Rust (no Python in the loop): the
    /// work itself, which the bindings' overheads are compared with.
    fn inner_seconds(
        &self,
        descriptor: PyReadonlyArray1<'_, f32>,
        first_timestamp: f64,
        n: usize,
    ) -> PyResult<Vec<f64>> {
        let mut copy = Vec::new();
        let (slice, copied) = borrow_descriptor(&descriptor, &mut copy);
        let mut inner = self.lock()?;
        let mut out = Vec::with_capacity(n);
        for i in 0..n {
            let start = Instant::now();
            inner.run(slice, copied, first_timestamp + i as f64)?;
            out.push(start.elapsed().as_secs_f64());
        }
        Ok(out)
    }

    /// Forgets the history (the next frame may have any timestamp).
    fn reset(&self) -> PyResult<()> {
        self.lock()?.localizer.reset();
        Ok(())
    }

    /// Address of the descriptor memory the last call gave the localizer.
    #[getter]
    fn last_address(&self) -> PyResult<usize> {
        Ok(self.lock()?.last_address)
    }

    /// Whether the last call copied the descriptor.
    #[getter]
    fn last_copied(&self) -> PyResult<bool> {
        Ok(self.lock()?.last_copied)
    }
}

#[pymodule]
fn topoloc_pyo3_probe(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Probe>()?;
    m.add_class::<ProbeResult>()?;
    m.add("TOPOLOC_VERSION", topoloc::VERSION)?;
    Ok(())
}
