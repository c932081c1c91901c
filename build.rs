//! Two jobs, both keyed on the target:
//!
//! * `cfg(no_long_multiply)` for cores without a 32x32 -> 64 multiply
//!   (ARMv6-M, ARMv8-M Baseline), which picks `Q32`'s multiply from 16-bit
//!   halves (stable Rust has no `target_feature` for this);
//! * the memory layout of the firmware examples' QEMU machine. Only when
//!   building for a bare-metal target (`target_os = "none"`), and only for
//!   examples (`rustc-link-arg-examples`), so the layout never reaches host
//!   builds or a downstream firmware crate that depends on this library.
use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-changed=memory-m4.x");
    println!("cargo:rerun-if-changed=memory-m0.x");
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo::rustc-check-cfg=cfg(no_long_multiply)");
    let target = env::var("TARGET").unwrap_or_default();
    if target.starts_with("thumbv6m") || target.starts_with("thumbv8m.base") {
        println!("cargo:rustc-cfg=no_long_multiply");
    }
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    // ARMv6-M (Cortex-M0) examples run on QEMU's microbit, the others on
    // mps2-an386; each machine has its own memory map. The root `memory.x`
    // (which cortex-m-rt's `link.x` includes, found in the package root
    // before the search path) includes `memory-target.x`, copied here.
    let source = match target.as_str() {
        t if t.starts_with("thumbv6m") => "memory-m0.x",
        _ => "memory-m4.x",
    };
    let out = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy(source, out.join("memory-target.x")).expect("copy the memory layout to OUT_DIR");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-examples=-Tlink.x");
}
