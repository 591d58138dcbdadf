//! Gives the shared library an explicit SONAME (`libtopoloc.so.MAJOR`), which a Rust cdylib
//! otherwise lacks, so that hosts linking it follow ABI-compatible upgrades.
fn main() {
    let major =
        std::env::var("CARGO_PKG_VERSION_MAJOR").expect("cargo sets CARGO_PKG_VERSION_MAJOR");
    let target_os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if target_os == "linux" {
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libtopoloc.so.{major}");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
