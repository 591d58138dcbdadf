//! The checked-in `include/topoloc.h` is what `topoloc-gen-header` generates from `src/ffi` (run
//! with the Rust tests, so the header check needs no build of its own).

use std::process::Command;

#[test]
fn the_checked_in_header_is_current() {
    let out = Command::new(env!("CARGO_BIN_EXE_topoloc-gen-header"))
        .arg("--check")
        .output()
        .expect("gen-header runs");
    assert!(
        out.status.success(),
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}
