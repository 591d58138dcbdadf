//! Links OpenCV's videoio module, which `topoloc localize --video` reads frames with. The
//! workspace's `OPENCV_LINK_LIBS` (.cargo/config.toml) lists only the modules the library
//! uses, so the opencv crate does not link this one itself.

fn main() {
    println!("cargo:rustc-link-lib=dylib=opencv_videoio");
    println!("cargo:rerun-if-changed=build.rs");
}
