//! Firmware build script: on a non-Cortex-M target (a host `cargo build --workspace`) it
//! warns that the result is a stub and stops; otherwise it passes the
//! linker scripts (cortex-m-rt's link.x with the workspace-root memory.x, defmt.x, and this
//! crate's ccmram.x that places the control step in CCM SRAM) to the binary only.
use std::{env, fs, path::PathBuf};

fn main() {
    let target = env::var("TARGET").unwrap_or_default();
    println!("cargo:rerun-if-changed=build.rs");
    if !target.starts_with("thumbv7em-none-eabi") {
        // not a panic: `cargo build --workspace` on the host must work. The host build is
        // a stub binary that says how to build the firmware (src/main.rs).
        println!(
            "cargo:warning=acim-firmware is STM32G474 (Cortex-M4F) firmware; built for \
             `{target}` it is only a stub. Build it with: cargo build --profile firmware -p \
             acim-firmware --target thumbv7em-none-eabihf"
        );
        return;
    }
    // ccmram.x goes to OUT_DIR, which is added to the linker search path
    let out = PathBuf::from(env::var("OUT_DIR").unwrap());
    // the self-test build runs the flux observer's step, the sensor check's window ends
    // (one period in eight) and the start's own steps (the start sequence's entry, the
    // inverter test, the flying start's decision) and the generic modulator from flash
    // (ccmram.x, SELFTEST_IN_FLASH): its CCM SRAM is full with the simulated stage's glue
    // and, with `soft-sincos`, the software sin/cos
    let mut script = fs::read_to_string("ccmram.x").expect("read ccmram.x");
    if env::var_os("CARGO_FEATURE_SELFTEST").is_some() {
        script = script.replace(
            "/* SELFTEST_IN_FLASH:",
            "*(.text._ZN4acim13flux_observer17FluxObserverState6update*)\n    \
             *(.text._ZN4acim12sensor_check20SensorCheck$LT$N$GT$6update*)\n    \
             *(.text._ZN4acim5drive*11begin_start17h*)\n    \
             *(.text._ZN4acim13inverter_test*6update17h*)\n    \
             *(.text._ZN4acim12speed_search*6decide17h*)\n    \
             *(.text._ZN4acim5svpwm8modulate17h*)\n    \
             /* SELFTEST_IN_FLASH:",
        );
    }
    fs::write(out.join("ccmram.x"), script).expect("write ccmram.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rerun-if-changed=ccmram.x");
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
