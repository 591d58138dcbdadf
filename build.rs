//! Gives the shared library an explicit SONAME, which a Rust cdylib otherwise lacks, so that
//! hosts linking it follow ABI-compatible upgrades: `libtopoloc.so.MAJOR`, or
//! `libtopoloc.so.0.MINOR` before 1.0 (where a minor release may change the ABI). The same rule
//! is in CMakeLists.txt and the test scripts.
fn main() {
    let version = |part: &str| {
        std::env::var(format!("CARGO_PKG_VERSION_{part}")).expect("cargo sets the version")
    };
    let (major, minor) = (version("MAJOR"), version("MINOR"));
    let soname_version = if major == "0" {
        format!("0.{minor}")
    } else {
        major
    };
    let target_os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if target_os == "linux" {
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libtopoloc.so.{soname_version}");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
