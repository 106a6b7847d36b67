//! Puts the workspace-root `memory.x` where `cortex-m-rt`'s `link.x` finds it.
//!
//! Only the ARM build links with `-Tlink.x` (see `.cargo/config.toml`); on the
//! host the extra search path is unused and harmless.

use std::{env, error::Error, fs, path::PathBuf};

fn main() -> Result<(), Box<dyn Error>> {
    let manifest_dir = PathBuf::from(env::var("CARGO_MANIFEST_DIR")?);
    let memory_x = manifest_dir.join("../../memory.x");
    let out_dir = PathBuf::from(env::var("OUT_DIR")?);
    fs::copy(&memory_x, out_dir.join("memory.x"))?;
    println!("cargo:rustc-link-search={}", out_dir.display());
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
    Ok(())
}
