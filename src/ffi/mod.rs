//! The crate's foreign-function bindings, and with them all of its code outside the
//! compiler's safety checks (the crate denies `unsafe` everywhere else): the Embree backend
//! of the ray queries ([`embree`], bound by our own bindgen layer over `wrapper.h`) and,
//! with `--features oiio`, the `cxx` bridge to OpenImageIO (`oiio`). Every `unsafe`
//! block here carries a `// SAFETY:` comment saying why it is sound.
#![allow(unsafe_code)]

pub mod embree;
#[cfg(feature = "oiio")]
pub mod oiio;
