//! Embree's C API as `build.rs` binds it from `wrapper.h` with bindgen (Embree 3, or
//! Embree 4 under `cfg(embree4)`): the raw functions and types that the Embree backend
//! ([`crate::accel::embree`]) wraps.
#![allow(
    non_upper_case_globals,
    non_camel_case_types,
    non_snake_case,
    dead_code,
    unused_imports,
    unnecessary_transmutes,
    clippy::all
)]

include!(concat!(env!("OUT_DIR"), "/embree_bindings.rs"));
