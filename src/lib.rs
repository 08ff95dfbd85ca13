//! `pcbpt`: a CPU renderer for probabilistic connections in bidirectional path tracing
//! (Popov et al. 2015) and the light-transport methods it is compared against.
//!
//! The crate is organised by what things are: ray queries ([`accel`]), scene loading and
//! the render-ready scene ([`scene`]), the camera and film, BSDFs, lights, textures,
//! sampling ([`sampling`], with the χ² harness), integrators, image I/O and comparison.
//! Code outside the compiler's safety checks lives only in [`ffi`]: the Embree bindings
//! and, with `--features oiio`, the `cxx` bridge to OpenImageIO.
#![deny(unsafe_code)]

pub mod accel;
pub mod aov;
pub mod bsdf;
pub mod camera;
pub mod compare;
pub mod denoise;
pub mod display;
pub mod error;
pub mod experiment;
pub mod ffi;
pub mod film;
pub mod image_io;
pub mod integrator;
pub mod light;
pub mod math;
pub mod medium;
pub mod partial;
pub mod sampling;
pub mod scene;
pub mod texture;
pub mod workers;

pub use error::{Error, Result};
