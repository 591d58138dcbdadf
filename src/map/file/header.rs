//! The container's framing (8-byte header length, JSON header, data length) and the topoloc
//! metadata in it: format name, version, identity, counts, describer spec and checksum.

use super::{FORMAT_NAME, FORMAT_VERSION_MAJOR, MAX_DESCRIPTOR_DIM};
use crate::describe::describer::BackendSpec;
use crate::descriptor::DescriptorIdentity;
use crate::map::MapError;
use serde::{Deserialize, Serialize};

/// The only key of the safetensors metadata.
pub(super) const META_KEY: &str = "topoloc";
/// Longest JSON header accepted; far above any real map's header (a few hundred bytes).
const MAX_HEADER_BYTES: u64 = 1 << 20;
/// What a topoloc map file's JSON header starts with (safetensors writes `__metadata__` first).
const HEADER_START: &[u8] = b"{\"__metadata__\":{";

/// The `topoloc` metadata object.
#[derive(Serialize, Deserialize)]
pub(super) struct FileMeta {
    pub(super) format: String,
    pub(super) version: String,
    pub(super) descriptor: DescriptorIdentity,
    pub(super) creator: String,
    pub(super) places: u64,
    pub(super) views: u64,
    pub(super) edges: u64,
    /// The describer's backend (1.1, maps built from images).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) describer: Option<BackendSpec>,
    /// Absent while the checksum itself is computed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(super) crc32: Option<String>,
}

/// CRC-32 (hex) of the metadata JSON followed by every tensor's bytes in tensor-name order.
pub(super) fn checksum<'a>(
    meta_json: &str,
    tensors_by_name: impl Iterator<Item = &'a [u8]>,
) -> String {
    let mut hasher = crc32fast::Hasher::new();
    hasher.update(meta_json.as_bytes());
    for bytes in tensors_by_name {
        hasher.update(bytes);
    }
    format!("{:08x}", hasher.finalize())
}

/// Serialises a metadata object without its `crc32` field: the checksummed form since 1.1.
pub(super) fn canonical_json(mut value: serde_json::Value) -> String {
    if let Some(object) = value.as_object_mut() {
        object.remove("crc32");
    }
    value.to_string()
}

/// Decides whether a damaged header still looks like the start of a topoloc map, which tells a
/// truncated or corrupt map apart from some other file.
fn starts_like_map(bytes: &[u8]) -> bool {
    let Some(header) = bytes.get(8..) else {
        return true;
    };
    let n = header.len().min(HEADER_START.len());
    header[..n] == HEADER_START[..n]
}

/// Fails when serialised map `bytes` have a header longer than a reader accepts: a map is
/// never saved that cannot be loaded.
pub(super) fn check_header_fits(bytes: &[u8]) -> Result<(), MapError> {
    let header_len = bytes
        .get(..8)
        .map_or(0, |b| u64::from_le_bytes(b.try_into().expect("8 bytes")));
    if header_len > MAX_HEADER_BYTES {
        return Err(MapError::Invalid(format!(
            "the map's header would be {header_len} bytes, a reader accepts at most \
             {MAX_HEADER_BYTES}: shorten the creator or the descriptor's kind or model"
        )));
    }
    Ok(())
}

/// Checks the framing of a file (header length, JSON header, total length) and returns the
/// `topoloc` metadata JSON string.
pub(super) fn frame(bytes: &[u8]) -> Result<String, MapError> {
    let len = bytes.len();
    if len < 8 {
        return Err(MapError::Truncated(format!(
            "{len} bytes, shorter than the 8-byte header length"
        )));
    }
    let header_len = u64::from_le_bytes(bytes[..8].try_into().expect("8 bytes"));
    if !(2..=MAX_HEADER_BYTES).contains(&header_len) {
        return Err(if starts_like_map(bytes) && header_len > MAX_HEADER_BYTES {
            MapError::Corrupt(format!("implausible header length {header_len}"))
        } else {
            MapError::NotAMap(format!(
                "implausible safetensors header length {header_len}"
            ))
        });
    }
    let header_end = 8 + header_len as usize; // at most 8 + 2^20
    if len < header_end {
        return Err(if starts_like_map(bytes) {
            MapError::Truncated(format!(
                "{len} bytes, but the header alone needs {header_end}"
            ))
        } else {
            MapError::NotAMap("not a safetensors file".into())
        });
    }
    let header: serde_json::Value = match serde_json::from_slice(&bytes[8..header_end]) {
        Ok(v) => v,
        Err(e) if starts_like_map(bytes) => {
            return Err(MapError::Corrupt(format!("header is not valid JSON: {e}")))
        }
        Err(_) => return Err(MapError::NotAMap("not a safetensors file".into())),
    };
    let meta_json = header
        .get("__metadata__")
        .and_then(|m| m.get(META_KEY))
        .and_then(|v| v.as_str())
        .ok_or_else(|| MapError::NotAMap("safetensors file without topoloc metadata".into()))?
        .to_owned();
    check_data_length(&header, header_end as u64, len as u64)?;
    Ok(meta_json)
}

/// Checks that the file ends exactly where the header's largest data offset says, with checked
/// arithmetic: a declared offset near `u64::MAX` is corrupt, not a wrapped length.
fn check_data_length(
    header: &serde_json::Value,
    header_end: u64,
    len: u64,
) -> Result<(), MapError> {
    let data_end = header
        .as_object()
        .into_iter()
        .flatten()
        .filter(|(k, _)| k.as_str() != "__metadata__")
        .filter_map(|(_, t)| t.get("data_offsets")?.get(1)?.as_u64())
        .max()
        .unwrap_or(0);
    let expected_len = header_end.checked_add(data_end).ok_or_else(|| {
        MapError::Corrupt(format!(
            "the header declares data up to byte {data_end}, past any possible file length"
        ))
    })?;
    if len < expected_len {
        return Err(MapError::Truncated(format!(
            "{len} bytes, the header promises {expected_len}"
        )));
    }
    if len > expected_len {
        return Err(MapError::Corrupt(format!(
            "{} unexpected bytes after the data",
            len - expected_len
        )));
    }
    Ok(())
}

/// Parses the metadata JSON: returns it as a typed struct and as a generic value (for the
/// checksum), after checking the format name and the version.
pub(super) fn read_meta(meta_json: &str) -> Result<(FileMeta, serde_json::Value), MapError> {
    let meta_object: serde_json::Value = serde_json::from_str(meta_json)
        .map_err(|e| MapError::Corrupt(format!("topoloc metadata: {e}")))?;
    let meta: FileMeta = serde_json::from_value(meta_object.clone())
        .map_err(|e| MapError::Corrupt(format!("topoloc metadata: {e}")))?;
    if meta.format != FORMAT_NAME {
        return Err(MapError::NotAMap(format!(
            "format is '{}', not '{FORMAT_NAME}'",
            meta.format
        )));
    }
    check_version(&meta.version)?;
    Ok((meta, meta_object))
}

/// Accepts exactly `MAJOR.MINOR` (decimal digits, no sign, no leading zero except in "0") with
/// the major version of this build; a higher major version is
/// [`MapError::UnsupportedVersion`], anything else [`MapError::Corrupt`].
pub(super) fn check_version(version: &str) -> Result<(), MapError> {
    let number = |s: &str| {
        !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()) && (s == "0" || !s.starts_with('0'))
    };
    let corrupt = || {
        MapError::Corrupt(format!(
            "unreadable format version '{}': expected MAJOR.MINOR with major version {FORMAT_VERSION_MAJOR}",
            version.get(..32).unwrap_or(version)
        ))
    };
    let (major, minor) = version.split_once('.').ok_or_else(corrupt)?;
    if !number(major) || !number(minor) {
        return Err(corrupt());
    }
    // Digits only: a major version too long for u64 is newer than any.
    match major.parse::<u64>() {
        Ok(m) if m == u64::from(FORMAT_VERSION_MAJOR) => Ok(()),
        Ok(m) if m < u64::from(FORMAT_VERSION_MAJOR) => Err(corrupt()),
        _ => Err(MapError::UnsupportedVersion {
            found: version.to_string(),
            supported: FORMAT_VERSION_MAJOR,
        }),
    }
}

/// Checks the metadata's declared sizes and strings before anything is read from them: counts
/// at most `u32::MAX` (as maps hold), a dimension in 1..=[`MAX_DESCRIPTOR_DIM`], and no NUL in
/// the descriptor kind, model or creator (C getters would return them cut short).
pub(super) fn check_meta(meta: &FileMeta) -> Result<(), MapError> {
    for (what, count) in [
        ("places", meta.places),
        ("views", meta.views),
        ("edges", meta.edges),
    ] {
        if count > u64::from(u32::MAX) {
            return Err(MapError::Corrupt(format!(
                "{count} {what}, more than a map can hold (2^32 - 1)"
            )));
        }
    }
    let dim = meta.descriptor.dim;
    if !(1..=MAX_DESCRIPTOR_DIM).contains(&dim) {
        return Err(MapError::Corrupt(format!(
            "descriptor dimension {dim} must lie in 1..={MAX_DESCRIPTOR_DIM}"
        )));
    }
    check_no_nul(&meta.descriptor.kind, "descriptor kind")?;
    check_no_nul(&meta.descriptor.model, "descriptor model")?;
    check_no_nul(&meta.creator, "creator")
}

/// Refuses a string holding a NUL byte ([`MapError::Corrupt`], naming `what`).
pub(super) fn check_no_nul(value: &str, what: &str) -> Result<(), MapError> {
    if value.contains('\0') {
        return Err(MapError::Corrupt(format!("{what} holds a NUL byte")));
    }
    Ok(())
}
