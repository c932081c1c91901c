//! Links the firmware examples for the QEMU machine, and nothing else.
//!
//! Acts only when building for a bare-metal target (`target_os = "none"`), and
//! only for examples (`rustc-link-arg-examples`), so `memory.x` never reaches
//! host builds or a downstream firmware crate that depends on this library.
use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=memory.x");
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let out = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("copy memory.x to OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-examples=-Tlink.x");
}
