//! Builds the User-Mode Linux XSAVE shim (`src/vcan/uml_xstate.c`) as a shared object
//! and tells the crate where it is (`FES_UML_XSTATE_SHIM`, empty where it does not apply).

use std::path::PathBuf;

fn main() -> Result<(), String> {
    let src = "src/vcan/uml_xstate.c";
    println!("cargo:rerun-if-changed={src}");
    let arch = std::env::var("CARGO_CFG_TARGET_ARCH").unwrap_or_default();
    let os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if arch != "x86_64" || os != "linux" {
        // XSAVE is x86's; UML's other hosts need no shim.
        println!("cargo:rustc-env=FES_UML_XSTATE_SHIM=");
        return Ok(());
    }
    let out = PathBuf::from(std::env::var_os("OUT_DIR").ok_or("cargo sets no OUT_DIR")?);
    let so = out.join("libfes_uml_xstate.so");
    let compiler = cc::Build::new().get_compiler();
    let status = compiler
        .to_command()
        .args(["-O2", "-shared", "-fPIC", "-Wall", "-Werror", "-o"])
        .arg(&so)
        .arg(src)
        .arg("-ldl")
        .status()
        .map_err(|e| format!("running the C compiler {:?}: {e}", compiler.path()))?;
    if !status.success() {
        return Err(format!("compiling {src} failed ({status})"));
    }
    println!("cargo:rustc-env=FES_UML_XSTATE_SHIM={}", so.display());
    Ok(())
}
