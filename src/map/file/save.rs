//! Atomic saves: a temporary file next to the target, flushed and renamed over it.
//!
//! Temporary files are named `.{file name}.topoloc-tmp-XXXXXX` so that they can be recognised:
//! a save killed half-way leaves one behind, and the next successful save of the same map
//! removes every such file of that map. (Two processes saving the same path at once already
//! race, the last rename winning; one of them may now also find its temporary file gone and
//! report an I/O error instead of silently losing its map.)

use crate::map::MapError;
use std::ffi::OsString;
use std::io::Write;
use std::path::Path;

/// What the name of a temporary file holds between the map's file name and the random part.
pub(super) const TEMP_MARK: &str = ".topoloc-tmp-";

/// The name prefix of `name`'s temporary files: `.{name}.topoloc-tmp-`.
fn temp_prefix(name: &std::ffi::OsStr) -> OsString {
    let mut prefix = OsString::from(".");
    prefix.push(name);
    prefix.push(TEMP_MARK);
    prefix
}

/// Writes `bytes` to `path` atomically. An existing target keeps its permissions; a new file
/// gets the default permissions (0666 less the process umask), as any created file would.
pub(super) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), MapError> {
    let io = |source| MapError::Io {
        path: path.to_path_buf(),
        source,
    };
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let name = path.file_name().ok_or_else(|| {
        io(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "the path names no file",
        ))
    })?;
    let prefix = temp_prefix(name);
    let existing = std::fs::metadata(path).ok().map(|m| m.permissions());
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix("").rand_bytes(6);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        // Masked by the umask when the file is created, like any new file.
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let mut tmp = builder.tempfile_in(dir).map_err(io)?;
    if let Some(permissions) = existing {
        tmp.as_file().set_permissions(permissions).map_err(io)?;
    }
    tmp.write_all(bytes).map_err(io)?;
    tmp.as_file().sync_all().map_err(io)?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    // Make the rename itself durable.
    if let Ok(d) = std::fs::File::open(dir) {
        let _ = d.sync_all();
    }
    remove_stale_temporaries(dir, &prefix);
    Ok(())
}

/// Removes the temporary files of earlier, interrupted saves of the same map (best effort).
fn remove_stale_temporaries(dir: &Path, prefix: &OsString) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let prefix = prefix.as_encoded_bytes();
    for entry in entries.flatten() {
        let name = entry.file_name();
        let stale = name.as_encoded_bytes().starts_with(prefix)
            && entry.file_type().is_ok_and(|t| t.is_file());
        if stale && std::fs::remove_file(entry.path()).is_ok() {
            log::warn!(
                "removed {}, a temporary file left by an interrupted save",
                entry.path().display()
            );
        }
    }
}
