//! The ONNX Runtime shared library, loaded once per process at run time (so the library works
//! without it until a network is asked for), and the cache folder the set-up script fills.
//! Both the descriptor backend ([`crate::describe::onnx`]) and the learned local features
//! ([`crate::verify::xfeat`]) take their sessions' environment from here.

use crate::errors::VisionError;
use ort::session::Session;
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};

/// The cache folder of set-up files: `TOPOLOC_CACHE`, else `~/.cache/topoloc`.
pub fn cache_dir() -> PathBuf {
    std::env::var_os("TOPOLOC_CACHE")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(std::env::var_os("HOME").unwrap_or_default()).join(".cache/topoloc")
        })
}

/// Candidate paths of the ONNX Runtime library, in the order they are tried. A configured path
/// (the option, else `TOPOLOC_ORT_LIBRARY`, else `ORT_DYLIB_PATH`) is the only candidate: asking
/// for a library and silently getting another would hide a set-up mistake. Without one, the
/// libraries `scripts/setup-models.sh` put in the cache are tried.
fn runtime_candidates(explicit: Option<&Path>) -> Vec<PathBuf> {
    if let Some(path) = configured_runtime(explicit) {
        return vec![path];
    }
    let dir = cache_dir().join("onnxruntime");
    let mut cached: Vec<PathBuf> = std::fs::read_dir(&dir)
        .into_iter()
        .flatten()
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("libonnxruntime.so"))
        })
        .collect();
    cached.sort();
    if cached.is_empty() {
        cached.push(dir.join("libonnxruntime.so.<version>"));
    }
    cached
}

/// The runtime library the caller configured: the option, else `TOPOLOC_ORT_LIBRARY`, else
/// `ORT_DYLIB_PATH`; `None` when none is set.
fn configured_runtime(explicit: Option<&Path>) -> Option<PathBuf> {
    explicit.map(Path::to_path_buf).or_else(|| {
        ["TOPOLOC_ORT_LIBRARY", "ORT_DYLIB_PATH"]
            .iter()
            .find_map(|var| std::env::var_os(var).filter(|v| !v.is_empty()))
            .map(PathBuf::from)
    })
}

/// The ONNX Runtime loaded in this process, and from where.
struct LoadedRuntime {
    path: PathBuf,
    environment: ort::environment::Environment,
}

/// The process-wide ONNX Runtime environment. The runtime library can be loaded once per
/// process: a later request for a different configured library fails rather than silently
/// using the first. Failed loads are not remembered, so a corrected path works on retry.
pub(crate) fn environment(
    explicit: Option<&Path>,
) -> Result<&'static ort::environment::Environment, VisionError> {
    static RUNTIME: OnceLock<LoadedRuntime> = OnceLock::new();
    static LOADING: Mutex<()> = Mutex::new(());
    let configured = configured_runtime(explicit);
    let tried = runtime_candidates(explicit);
    let unavailable = |hint: String| VisionError::BackendUnavailable {
        what: "ONNX Runtime".into(),
        tried: tried.clone(),
        hint,
    };
    let Some(path) = tried.iter().find(|p| p.is_file()) else {
        return Err(unavailable(if configured.is_some() {
            "the configured ONNX Runtime library does not exist (option, TOPOLOC_ORT_LIBRARY or \
             ORT_DYLIB_PATH, in that order)"
                .into()
        } else {
            "run scripts/setup-models.sh, or pass the library path (option or TOPOLOC_ORT_LIBRARY)"
                .into()
        }));
    };
    let _serialised = LOADING
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner());
    let loaded = match RUNTIME.get() {
        Some(loaded) => loaded,
        None => {
            let environment = ort::init_from(path)
                .map_err(|e| unavailable(format!("loading {}: {e}", path.display())))?
                .with_logger(std::sync::Arc::new(forward_runtime_log))
                .build()
                .map_err(|e| {
                    unavailable(format!(
                        "creating the ONNX Runtime environment from {}: {e}",
                        path.display()
                    ))
                })?;
            log::info!("ONNX Runtime loaded from {}", path.display());
            RUNTIME.get_or_init(|| LoadedRuntime {
                path: path.clone(),
                environment,
            })
        }
    };
    let same_library =
        || std::fs::canonicalize(path).ok() == std::fs::canonicalize(&loaded.path).ok();
    if configured.is_none() || same_library() {
        Ok(&loaded.environment)
    } else {
        Err(unavailable(format!(
            "this process already loaded ONNX Runtime from {}; it can be loaded only once per \
             process, so {} cannot be used",
            loaded.path.display(),
            path.display()
        )))
    }
}

/// A session on `model` (read whole, so its SHA-256 names it) with `threads` intra-op threads,
/// and that hash in hex. Missing files are [`VisionError::BackendUnavailable`] naming the path
/// and `hint`; a file ONNX Runtime refuses is [`VisionError::Model`].
pub(crate) fn session(
    runtime: Option<&Path>,
    model: &Path,
    threads: usize,
    hint: &str,
) -> Result<(Session, String), VisionError> {
    let bytes = read_model(model, hint)?;
    let session = session_from_memory(runtime, &bytes, threads).map_err(|e| match e {
        VisionError::Model(message) => {
            VisionError::Model(format!("{}: {message}", model.display()))
        }
        other => other,
    })?;
    Ok((session, format!("{:x}", Sha256::digest(&bytes))))
}

/// SHA-256 (hex) of the file at `path`; a file that cannot be read is
/// [`VisionError::BackendUnavailable`] naming it and `hint`.
pub(crate) fn file_sha256(path: &Path, hint: &str) -> Result<String, VisionError> {
    Ok(format!("{:x}", Sha256::digest(read_model(path, hint)?)))
}

/// The bytes of the model file at `path`; one that cannot be read is
/// [`VisionError::BackendUnavailable`] naming it and `hint`.
fn read_model(path: &Path, hint: &str) -> Result<Vec<u8>, VisionError> {
    std::fs::read(path).map_err(|e| VisionError::BackendUnavailable {
        what: "ONNX model".into(),
        tried: vec![path.to_path_buf()],
        hint: format!("{e}; {hint}"),
    })
}

/// Checks that `session` (loaded from `model`) has exactly one input, named `name`, a float
/// tensor of rank 4 whose known dimensions equal `dims` where those are given (`None`: any;
/// a dimension the model leaves dynamic passes; `Some(-1)`: the model must leave it dynamic).
/// Else [`VisionError::Model`] naming the file, what it has and what was expected: a network
/// that would fail at its first image is refused when it is loaded.
pub(crate) fn check_single_input(
    session: &Session,
    model: &Path,
    name: &str,
    dims: [Option<i64>; 4],
) -> Result<(), VisionError> {
    use ort::value::{TensorElementType, ValueType};
    let expected = || {
        let dim = |d: &Option<i64>| d.map_or("?".to_string(), |v| v.to_string());
        format!(
            "one float input '{name}' of shape [{}]",
            dims.iter().map(dim).collect::<Vec<_>>().join(", ")
        )
    };
    let refuse = |has: String| {
        Err(VisionError::Model(format!(
            "{} has {has}; expected {}",
            model.display(),
            expected()
        )))
    };
    let inputs = session.inputs();
    let [input] = inputs else {
        let names: Vec<&str> = inputs.iter().map(|i| i.name()).collect();
        return refuse(format!("inputs {names:?}"));
    };
    if input.name() != name {
        return refuse(format!("the input '{}'", input.name()));
    }
    let ValueType::Tensor { ty, shape, .. } = input.dtype() else {
        return refuse(format!("an input '{name}' that is not a tensor"));
    };
    let fits = |(have, want): (&i64, &Option<i64>)| *have < 0 || want.is_none_or(|w| *have == w);
    if *ty != TensorElementType::Float32 || shape.len() != 4 || !shape.iter().zip(&dims).all(fits) {
        return refuse(format!(
            "an input '{name}' of {ty:?} shape {:?}",
            &shape[..]
        ));
    }
    Ok(())
}

/// A session on the model `bytes` with `threads` intra-op threads. A runtime that cannot be
/// loaded is [`VisionError::BackendUnavailable`]; bytes ONNX Runtime refuses are
/// [`VisionError::Model`].
pub(crate) fn session_from_memory(
    runtime: Option<&Path>,
    bytes: &[u8],
    threads: usize,
) -> Result<Session, VisionError> {
    let env = environment(runtime)?;
    let onnx = |e: ort::Error| VisionError::Model(e.to_string());
    Session::builder(env)
        .map_err(onnx)?
        .with_intra_threads(threads.max(1))
        .map_err(|e| onnx(e.into()))?
        // Memory patterns pre-plan one arena block per input shape; off, a frame's activations
        // reuse the arena's blocks (BENCHMARKS.md, "Memory budget").
        .with_memory_pattern(false)
        .map_err(|e| onnx(e.into()))?
        .commit_from_memory(bytes)
        .map_err(onnx)
}

/// ONNX Runtime's own messages, as `log` records of target `onnxruntime` (its INFO messages,
/// a dozen per session, as DEBUG): never on stderr.
fn forward_runtime_log(
    level: ort::logging::LogLevel,
    category: &str,
    _id: &str,
    code_location: &str,
    message: &str,
) {
    use ort::logging::LogLevel;
    let level = match level {
        LogLevel::Verbose => log::Level::Trace,
        LogLevel::Info => log::Level::Debug,
        LogLevel::Warning => log::Level::Warn,
        LogLevel::Error | LogLevel::Fatal => log::Level::Error,
    };
    log::log!(target: "onnxruntime", level, "[{category}] {code_location}: {message}");
}
