//! The Debian packages of the FES stack, `fes-stack` (rig) and `fes-stack-bench` (bench).
//!
//! This crate has no code: it is where `cargo deb` reads the packages' metadata
//! (`[package.metadata.deb]` in its `Cargo.toml`). The packages gather the binaries of four
//! crates (rt-core, stim-driver, supervisor, workbench, and sim-muscle on the bench), so no
//! one of them is "the stack"; a crate of its own keeps the packaging out of their
//! manifests. Build the packages with `scripts/package`; what is in them, and what their
//! maintainer scripts do, is in docs/deployment.md ("The Debian package").
