//! Firmware build script: refuses non-Cortex-M targets with a clear message, and passes the
//! linker scripts (cortex-m-rt's link.x with the workspace-root memory.x, defmt.x, and this
//! crate's ccmram.x that places the control step in CCM SRAM) to the binary only.
use std::{env, fs, path::PathBuf};

fn main() {
    let target = env::var("TARGET").unwrap_or_default();
    if !target.starts_with("thumbv7em-none-eabi") {
        // `panic!` in a build script prints the message and fails the build
        panic!(
            "\n\nacim-firmware is STM32G474 (Cortex-M4F) firmware and must be built for \
             thumbv7em-none-eabihf, not `{target}`:\n    \
             cargo build --release -p acim-firmware --target thumbv7em-none-eabihf\n\
             (host tests of the hardware-independent parts: cargo test -p acim-firmware-core)\n\n"
        );
    }
    // ccmram.x goes to OUT_DIR, which is added to the linker search path
    let out = PathBuf::from(env::var("OUT_DIR").unwrap());
    fs::copy("ccmram.x", out.join("ccmram.x")).expect("copy ccmram.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=ccmram.x");
    println!("cargo:rerun-if-changed=build.rs");
    println!("cargo:rerun-if-env-changed=DEFMT_LOG");
    println!("cargo:rustc-link-arg-bins=-Tccmram.x");
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    println!("cargo:rustc-link-arg-bins=--nmagic");
    // defmt logs only errors unless DEFMT_LOG says otherwise; telemetry is `info`
    if env::var_os("DEFMT_LOG").is_none() {
        println!("cargo:rustc-env=DEFMT_LOG=info");
    }
}
