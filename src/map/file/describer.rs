//! Section `describer_*` (1.1): the describer's PCA and VLAD codebook; its backend spec lives
//! in the metadata.

use super::container::{decode_f32, le_bytes, OutTensor, OutTensors, TensorReader};
use crate::describe::describer::{BackendSpec, DescriberModel};
use crate::describe::pca::Pca;
use crate::describe::vlad::Codebook;
use crate::map::{Map, MapError};
use safetensors::Dtype;

/// Adds `describer_pca_mean`, `describer_pca_components` and, for VLAD, `describer_codebook`.
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
    out.push((
        "describer_pca_components",
        OutTensor::new(
            Dtype::F32,
            vec![pca.output_dim, pca.input_dim],
            le_bytes(&pca.components, f32::to_le_bytes),
        ),
    ));
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
pub(super) fn read(
    reader: &TensorReader<'_, '_>,
    spec: BackendSpec,
    dim: usize,
) -> Result<DescriberModel, MapError> {
    let corrupt = |e| MapError::Corrupt(format!("describer: {e}"));
    spec.validate().map_err(corrupt)?;
    let mean = decode_f32(reader.get_any_len("describer_pca_mean", Dtype::F32)?);
    let input_dim = mean.len();
    let components = reader.f32s("describer_pca_components", &[dim, input_dim])?;
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
