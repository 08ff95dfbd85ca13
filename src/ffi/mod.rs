//! The crate's foreign-function bindings: Embree's C API ([`embree`], bound by our own
//! bindgen layer over `wrapper.h`) and, with `--features oiio`, the `cxx` bridge to
//! OpenImageIO (`oiio`). With the Embree backend that wraps the bindings
//! ([`crate::accel::embree`]), all of the crate's code outside the compiler's safety checks
//! (the crate denies `unsafe` everywhere else). Every `unsafe` block carries a
//! `// SAFETY:` comment saying why it is sound.
#![allow(unsafe_code)]

pub mod embree;
#[cfg(feature = "oiio")]
pub mod oiio;
