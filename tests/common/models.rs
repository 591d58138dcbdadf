//! The files of `scripts/setup-models.sh` (ONNX Runtime, the MobileNetV2 and XFeat models) that
//! some tests need. Without them a test is skipped on a developer's machine, and fails in CI
//! (`CI=true`), where a missing model means a broken set-up, not a test to skip.

use std::path::PathBuf;
pub use topoloc::describe::onnx::cache_dir;

/// `file` in the model cache, or `None` after saying the test is skipped; panics in CI.
pub fn cached(file: &str) -> Option<PathBuf> {
    let path = cache_dir().join(file);
    if path.is_file() {
        return Some(path);
    }
    unavailable(&format!(
        "no {} (run scripts/setup-models.sh)",
        path.display()
    ));
    None
}

/// Says why a test is skipped, or panics with it in CI.
pub fn unavailable(why: &str) {
    if std::env::var("CI").is_ok_and(|v| v == "true") {
        panic!("{why}; CI=true, where a missing set-up fails the test");
    }
    eprintln!("skipped: {why}");
}
