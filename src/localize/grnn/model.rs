//! The GRNN's ONNX model: loading it (the file the caller names, or the one built into the
//! library), checking it against the contract `python/train/export.py` writes, and one run.
//!
//! Contract (N nodes, M edges, D descriptor dimension, S state width; N, M dynamic or fixed):
//! inputs `nodes` f32 (N, D), `edges` i64 (2, M), `frame` f32 (1, D), `state` f32 (1, N, S),
//! `stats` f32 (1, 3); outputs `logits` f32 (1, N), `new_state` f32 (1, N, S); metadata
//! `topoloc.model` = `grnn` and `topoloc.state` = S, and optionally `topoloc.max_nodes`.

use super::GrnnError;
use crate::errors::VisionError;
use crate::onnx_runtime;
use ort::session::Session;
use ort::value::{Outlet, TensorElementType, TensorRef};
use std::path::Path;

/// The model built into the library: `models/grnn.onnx`, which `python/train/make_model.sh`
/// reproduces (trained on generated Train and Tr-T worlds; BENCHMARKS.md).
pub(crate) static BUILT_IN: &[u8] = include_bytes!("../../../models/grnn.onnx");

/// A loaded model and what its contract fixes.
pub(super) struct Network {
    session: Session,
    /// Width S of the recurrent state per node.
    pub state_width: usize,
    /// Most nodes one step accepts (a fixed `nodes` dimension or `topoloc.max_nodes`).
    pub max_nodes: Option<usize>,
}

/// One step's inputs (see the module's contract).
#[derive(Clone, Copy)]
pub(super) struct StepInput<'a> {
    /// The window's view descriptors, n x D row-major.
    pub nodes: &'a [f32],
    /// The window's micro edges: m sources, then m targets (window-local).
    pub edges: &'a [i64],
    /// The frame's unit descriptor (D).
    pub frame: &'a [f32],
    /// The recurrent state of the window's nodes, n x S.
    pub state: &'a [f32],
    /// The frame's similarity statistics over the whole map: max, mean, deviation.
    pub stats: &'a [f32; 3],
}

/// One step's outputs, reused from frame to frame.
#[derive(Default)]
pub(super) struct StepOutput {
    /// A logit per node (n).
    pub logits: Vec<f32>,
    /// The new recurrent state, n x S.
    pub new_state: Vec<f32>,
}

/// The shape an input or output must have: element type and one entry per dimension, `None`
/// where any size goes.
struct Expected {
    name: &'static str,
    ty: TensorElementType,
    dims: [Option<i64>; 3],
    rank: usize,
}

impl Network {
    /// Loads `path` (or the built-in model) on the ONNX Runtime `runtime` (or the configured
    /// one) and checks it against the contract for descriptors of dimension `dim`.
    pub fn load(
        path: Option<&Path>,
        runtime: Option<&Path>,
        dim: usize,
    ) -> Result<Self, GrnnError> {
        let bytes = match path {
            Some(path) => std::fs::read(path).map_err(|e| {
                GrnnError::Unavailable(VisionError::BackendUnavailable {
                    what: "GRNN model".into(),
                    tried: vec![path.to_path_buf()],
                    hint: format!("{e}; pass an ONNX file written by python/train/export.py, or none for the built-in model"),
                })
            })?,
            None => BUILT_IN.to_vec(),
        };
        let name = path.map_or("the built-in GRNN model".into(), |p| {
            p.display().to_string()
        });
        let session =
            onnx_runtime::session_from_memory(runtime, &bytes, 1).map_err(|e| match e {
                VisionError::Model(message) => GrnnError::NotOnnx(format!("{name}: {message}")),
                other => GrnnError::Unavailable(other),
            })?;
        let contract = |message: String| GrnnError::Contract(format!("{name}: {message}"));
        let metadata = session.metadata().map_err(|e| contract(e.to_string()))?;
        let kind = metadata.custom("topoloc.model");
        if kind.as_deref() != Some("grnn") {
            return Err(contract(format!(
                "metadata topoloc.model is {kind:?}, expected \"grnn\" (python/train/export.py writes it)"
            )));
        }
        let state_width = metadata
            .custom("topoloc.state")
            .and_then(|s| s.parse::<usize>().ok())
            .filter(|&s| s > 0)
            .ok_or_else(|| {
                contract("metadata topoloc.state is missing or not a positive integer".into())
            })?;
        let declared_max =
            match metadata.custom("topoloc.max_nodes") {
                Some(text) => Some(text.parse::<usize>().ok().filter(|&n| n > 0).ok_or_else(
                    || {
                        contract(format!(
                            "metadata topoloc.max_nodes = {text:?} is not a positive integer"
                        ))
                    },
                )?),
                None => None,
            };
        drop(metadata);
        let (d, s) = (dim as i64, state_width as i64);
        let f32 = TensorElementType::Float32;
        let inputs = [
            Expected {
                name: "nodes",
                ty: f32,
                dims: [None, Some(d), None],
                rank: 2,
            },
            Expected {
                name: "edges",
                ty: TensorElementType::Int64,
                dims: [Some(2), None, None],
                rank: 2,
            },
            Expected {
                name: "frame",
                ty: f32,
                dims: [Some(1), Some(d), None],
                rank: 2,
            },
            Expected {
                name: "state",
                ty: f32,
                dims: [Some(1), None, Some(s)],
                rank: 3,
            },
            Expected {
                name: "stats",
                ty: f32,
                dims: [Some(1), Some(3), None],
                rank: 2,
            },
        ];
        let outputs = [
            Expected {
                name: "logits",
                ty: f32,
                dims: [Some(1), None, None],
                rank: 2,
            },
            Expected {
                name: "new_state",
                ty: f32,
                dims: [Some(1), None, Some(s)],
                rank: 3,
            },
        ];
        check_outlets("input", session.inputs(), &inputs).map_err(contract)?;
        check_outlets("output", session.outputs(), &outputs).map_err(contract)?;
        let fixed_nodes = session.inputs()[0]
            .dtype()
            .tensor_shape()
            .and_then(|shape| shape.first().copied())
            .filter(|&n| n > 0)
            .map(|n| n as usize);
        let max_nodes = match (fixed_nodes, declared_max) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        Ok(Self {
            session,
            state_width,
            max_nodes,
        })
    }

    /// One step on `input`; writes the logits (n) and the new state (n x S) into `output`.
    pub fn run(&mut self, input: &StepInput<'_>, output: &mut StepOutput) -> Result<(), GrnnError> {
        let StepInput {
            nodes,
            edges,
            frame,
            state,
            stats,
        } = *input;
        let (d, s) = (frame.len(), self.state_width);
        let n = nodes.len() / d;
        let m = edges.len() / 2;
        let run = |e: ort::Error| GrnnError::Run(e.to_string());
        let outputs = self
            .session
            .run(ort::inputs![
                "nodes" => TensorRef::from_array_view(([n, d], nodes)).map_err(run)?,
                "edges" => TensorRef::from_array_view(([2usize, m], edges)).map_err(run)?,
                "frame" => TensorRef::from_array_view(([1usize, d], frame)).map_err(run)?,
                "state" => TensorRef::from_array_view(([1usize, n, s], state)).map_err(run)?,
                "stats" => TensorRef::from_array_view(([1usize, 3], &stats[..])).map_err(run)?,
            ])
            .map_err(run)?;
        let (shape, values) = outputs["logits"].try_extract_tensor::<f32>().map_err(run)?;
        if **shape != [1, n as i64] {
            return Err(GrnnError::Run(format!(
                "logits have shape {shape:?}, expected [1, {n}]"
            )));
        }
        output.logits.clear();
        output.logits.extend_from_slice(values);
        let (shape, values) = outputs["new_state"]
            .try_extract_tensor::<f32>()
            .map_err(run)?;
        if **shape != [1, n as i64, s as i64] {
            return Err(GrnnError::Run(format!(
                "new_state has shape {shape:?}, expected [1, {n}, {s}]"
            )));
        }
        output.new_state.clear();
        output.new_state.extend_from_slice(values);
        Ok(())
    }
}

/// Checks that `outlets` are exactly `expected`, in order: names, element types, ranks and the
/// dimensions the contract fixes (a model's dynamic dimension accepts any size).
fn check_outlets(kind: &str, outlets: &[Outlet], expected: &[Expected]) -> Result<(), String> {
    let names: Vec<&str> = outlets.iter().map(|o| o.name()).collect();
    let wanted: Vec<&str> = expected.iter().map(|e| e.name).collect();
    if names != wanted {
        return Err(format!("{kind}s are {names:?}, expected {wanted:?}"));
    }
    for (outlet, e) in outlets.iter().zip(expected) {
        let (Some(ty), Some(shape)) = (outlet.dtype().tensor_type(), outlet.dtype().tensor_shape())
        else {
            return Err(format!("{kind} '{}' is not a tensor", e.name));
        };
        if ty != e.ty {
            return Err(format!(
                "{kind} '{}' holds {ty:?}, expected {:?}",
                e.name, e.ty
            ));
        }
        if shape.len() != e.rank {
            return Err(format!(
                "{kind} '{}' has rank {}, expected {}",
                e.name,
                shape.len(),
                e.rank
            ));
        }
        for (axis, (&got, want)) in shape.iter().zip(e.dims).enumerate() {
            if let Some(want) = want {
                if got >= 0 && got != want {
                    return Err(format!(
                        "{kind} '{}' has size {got} on axis {axis}, expected {want}",
                        e.name
                    ));
                }
            }
        }
    }
    Ok(())
}
