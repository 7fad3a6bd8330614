//! No code. This crate exists for its `Cargo.toml`: it asks for the features the workspace
//! builds the SDK's third-party dependencies with, so a build of one crate (`-p dear-client-c`,
//! a Python wheel) reuses the artifacts of the others instead of compiling iceoryx2's stack
//! again with smaller feature sets. Its manifest says which crates and why.

#![forbid(unsafe_code)]
