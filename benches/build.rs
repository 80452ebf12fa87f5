//! Link arguments for the firmware bin only, and only for the Cortex-M target (no global
//! rustflags: host builds of this package and of the workspace are unaffected).
use std::env;
use std::path::PathBuf;

fn main() {
    let target = env::var("TARGET").unwrap_or_default();
    println!("cargo:rerun-if-changed=build.rs");
    if target.starts_with("thumb") {
        // the project's memory.x (STM32G474RE) sits at the workspace root
        let root = PathBuf::from(env::var("CARGO_MANIFEST_DIR").unwrap_or_default()).join("..");
        println!("cargo:rustc-link-search={}", root.display());
        println!("cargo:rerun-if-changed=../memory.x");
        println!("cargo:rustc-link-arg-bin=acim-bench-fw=-Tlink.x");
        println!("cargo:rustc-link-arg-bin=acim-bench-fw=--nmagic");
        println!("cargo:rustc-link-arg-bin=acim-bench-fixed=-Tlink.x");
        println!("cargo:rustc-link-arg-bin=acim-bench-fixed=--nmagic");
    }
}
