//! Section `describer_*` (1.1): the describer's PCA and VLAD codebook; its backend spec lives
//! in the metadata. The PCA rows are `describer_pca_components` (F32) or, since 1.5,
//! `describer_pca_components_i8` (I8) with `describer_pca_scales` (F32, one per row): exactly
//! one of the two forms.

use super::container::{decode_f32, le_bytes, OutTensor, OutTensors, TensorReader};
use crate::describe::describer::{BackendSpec, DescriberModel};
use crate::describe::pca::{Components, Pca};
use crate::describe::vlad::Codebook;
use crate::map::{Map, MapError};
use bytes::Bytes;
use safetensors::Dtype;
use std::borrow::Cow;

/// The PCA rows as `f32` (1.1).
const F32_ROWS: &str = "describer_pca_components";
/// The PCA rows as `i8` (1.5), with their per-row scales.
const I8_ROWS: &str = "describer_pca_components_i8";
const I8_SCALES: &str = "describer_pca_scales";

/// Adds `describer_pca_mean`, the PCA rows in their stored form and, for VLAD,
/// `describer_codebook`.
pub(super) fn write<'a>(map: &'a Map, out: &mut OutTensors<'a>) {
    let Some(model) = map.describer() else {
        return;
    };
    let pca = &model.pca;
    out.push((
        "describer_pca_mean",
        OutTensor::new(
            Dtype::F32,
            vec![pca.input_dim],
            le_bytes(&pca.mean, f32::to_le_bytes),
        ),
    ));
    let shape = vec![pca.output_dim, pca.input_dim];
    match &pca.components {
        Components::F32(rows) => out.push((
            F32_ROWS,
            OutTensor::new(Dtype::F32, shape, le_bytes(rows, f32::to_le_bytes)),
        )),
        Components::I8 { values, scales } => {
            out.push((
                I8_ROWS,
                OutTensor::new(
                    Dtype::I8,
                    shape,
                    Cow::Borrowed(bytemuck::cast_slice(values)),
                ),
            ));
            out.push((
                I8_SCALES,
                OutTensor::new(
                    Dtype::F32,
                    vec![pca.output_dim],
                    le_bytes(scales, f32::to_le_bytes),
                ),
            ));
        }
    }
    if let Some(c) = &model.codebook {
        out.push((
            "describer_codebook",
            OutTensor::new(
                Dtype::F32,
                vec![c.clusters, c.dim],
                le_bytes(&c.centres, f32::to_le_bytes),
            ),
        ));
    }
}

/// Reads the describer's arrays (PCA, codebook) for a map of descriptor dimension `dim`. The
/// spec's declared sizes are bounded ([`BackendSpec::validate`]) before any array is read.
/// `share` keeps the i8 rows: a view of the mapped file, or a copy.
pub(super) fn read(
    reader: &TensorReader<'_, '_>,
    spec: BackendSpec,
    dim: usize,
    share: &dyn Fn(&[u8]) -> Bytes,
) -> Result<DescriberModel, MapError> {
    let corrupt = |e| MapError::Corrupt(format!("describer: {e}"));
    spec.validate().map_err(corrupt)?;
    let mean = decode_f32(reader.get_any_len("describer_pca_mean", Dtype::F32)?);
    let input_dim = mean.len();
    let components = match (reader.has(F32_ROWS), reader.has(I8_ROWS)) {
        (true, false) => Components::F32(reader.f32s(F32_ROWS, &[dim, input_dim])?),
        (false, true) => Components::I8 {
            values: share(reader.get(I8_ROWS, Dtype::I8, &[dim, input_dim])?),
            scales: reader.f32s(I8_SCALES, &[dim])?,
        },
        (true, true) => {
            return Err(MapError::Corrupt(format!(
                "both '{F32_ROWS}' and '{I8_ROWS}' are present: a map holds one form of its rows"
            )))
        }
        (false, false) => {
            return Err(MapError::Corrupt(format!(
                "tensor '{F32_ROWS}' is missing (nor is '{I8_ROWS}' there)"
            )))
        }
    };
    let codebook = match &spec {
        BackendSpec::Vlad(o) => {
            let local_dim = input_dim / o.clusters.max(1);
            reader.get("describer_codebook", Dtype::F32, &[o.clusters, local_dim])?;
            let centres = decode_f32(reader.get_any_len("describer_codebook", Dtype::F32)?);
            Some(
                Codebook::from_parts(o.clusters, local_dim, centres)
                    .map_err(|e| MapError::Corrupt(format!("describer codebook: {e}")))?,
            )
        }
        BackendSpec::Onnx { .. } => None,
    };
    let model = DescriberModel {
        spec,
        pca: Pca {
            input_dim,
            output_dim: dim,
            mean,
            components,
        },
        codebook,
    };
    model.validate().map_err(corrupt)?;
    Ok(model)
}
