//! Image input and output through the system OpenImageIO (`--features oiio`).
//!
//! Reads every format OpenImageIO reads (TIFF, Radiance HDR, TGA, tiled and mip-mapped
//! `.tx`, OpenEXR, PNG, JPEG, …) and writes through its writers (EXR, PNG, TIFF and the
//! rest). Of a multi-image or mip-mapped file, the first subimage at full resolution
//! (subimage 0, MIP level 0) is read.
//!
//! Pixels come back as an [`image::DynamicImage`] so that they are turned into linear RGB
//! by the same code as the `image` crate's: 8-bit integer data stays 8-bit, wider integers
//! become 16-bit, half/float/double become float; alpha is read straight (unassociated), as
//! stored. The C++ side and its `cxx` bridge live in [`crate::ffi::oiio`], with the crate's
//! other foreign bindings: this module is safe Rust.

use super::{Image, encode_srgb8, write_atomically};
use crate::error::{Error, Result};
use crate::ffi::oiio as ffi;
use image::{DynamicImage, ImageBuffer};
use std::path::Path;

fn utf8(path: &Path) -> Result<&str> {
    path.to_str().ok_or_else(|| Error::in_file(path, "OpenImageIO needs a UTF-8 file name"))
}

/// Reads the pixels `info` describes with `read` into a new buffer, and wraps them in the
/// `image` crate's type for their channel count.
fn read_into<T: image::Primitive>(
    path: &Path,
    info: &ffi::Info,
    read: impl FnOnce(&mut [T]) -> Result<(), cxx::Exception>,
) -> Result<DynamicImage>
where
    image::Luma<T>: image::Pixel<Subpixel = T>,
    image::LumaA<T>: image::Pixel<Subpixel = T>,
    image::Rgb<T>: image::Pixel<Subpixel = T>,
    image::Rgba<T>: image::Pixel<Subpixel = T>,
    DynamicImage: From<ImageBuffer<image::Luma<T>, Vec<T>>>
        + From<ImageBuffer<image::LumaA<T>, Vec<T>>>
        + From<ImageBuffer<image::Rgb<T>, Vec<T>>>
        + From<ImageBuffer<image::Rgba<T>, Vec<T>>>,
{
    let (w, h, c) = (info.width, info.height, info.channels);
    let n = w as usize * h as usize * c as usize;
    let mut data = Vec::new();
    data.try_reserve_exact(n).map_err(|_| Error::in_file(path, format!("the image is too large ({w}×{h}×{c})")))?;
    data.resize(n, T::DEFAULT_MIN_VALUE);
    read(&mut data).map_err(|e| read_error(path, e))?;
    let img = match c {
        1 => ImageBuffer::<image::Luma<T>, _>::from_raw(w, h, data).map(DynamicImage::from),
        2 => ImageBuffer::<image::LumaA<T>, _>::from_raw(w, h, data).map(DynamicImage::from),
        3 => ImageBuffer::<image::Rgb<T>, _>::from_raw(w, h, data).map(DynamicImage::from),
        4 => ImageBuffer::<image::Rgba<T>, _>::from_raw(w, h, data).map(DynamicImage::from),
        _ => None,
    };
    img.ok_or_else(|| Error::in_file(path, format!("OpenImageIO returned {c} channels of {w}×{h} pixels")))
}

fn read_error(path: &Path, e: cxx::Exception) -> Error {
    Error::in_file(path, format!("OpenImageIO cannot read the image: {}", e.what()))
}

pub use ffi::Info;

/// What OpenImageIO finds in the image file `path`, without reading its pixels.
pub fn info(path: &Path) -> Result<Info> {
    Ok(ffi::open(utf8(path)?).map_err(|e| read_error(path, e))?.info())
}

/// Reads `path` through OpenImageIO: subimage 0 at MIP level 0 (the full resolution).
pub fn read(path: &Path) -> Result<DynamicImage> {
    let mut input = ffi::open(utf8(path)?).map_err(|e| read_error(path, e))?;
    let info = input.info();
    match info.bits {
        8 => read_into::<u8>(path, &info, |out| input.pin_mut().read_u8(out)),
        16 => read_into::<u16>(path, &info, |out| input.pin_mut().read_u16(out)),
        _ => read_into::<f32>(path, &info, |out| input.pin_mut().read_f32(out)),
    }
}

/// How pixels are stored in a file written through OpenImageIO.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    /// 32-bit float, linear, as the EXR writer stores them.
    Float,
    /// 8-bit, sRGB-encoded, as the PNG writer stores them.
    Srgb8,
}

impl Encoding {
    /// Float for the formats that hold floats (EXR, TIFF, Radiance HDR), else 8-bit sRGB.
    pub fn for_path(path: &Path) -> Encoding {
        let ext = path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("exr" | "tif" | "tiff" | "hdr") => Encoding::Float,
            _ => Encoding::Srgb8,
        }
    }
}

/// Writes `image` through OpenImageIO in the format its extension names (EXR, PNG, TIFF,
/// HDR, TGA, …), with [`Encoding::for_path`], atomically.
pub fn write(path: &Path, image: &Image) -> Result<()> {
    write_encoded(path, image, Encoding::for_path(path))
}

/// Writes `image` through OpenImageIO in the format its extension names, stored as
/// `encoding` says, atomically.
pub fn write_encoded(path: &Path, image: &Image, encoding: Encoding) -> Result<()> {
    utf8(path)?;
    let format = path.extension().and_then(|e| e.to_str()).unwrap_or_default().to_owned();
    let (w, h) = (image.width, image.height);
    write_atomically(path, |tmp| {
        let tmp = tmp.to_str().ok_or("OpenImageIO needs a UTF-8 file name")?;
        match encoding {
            Encoding::Float => {
                let data: Vec<f32> = image.pixels.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
                ffi::write_f32(tmp, &format, w, h, 3, &data)
            }
            Encoding::Srgb8 => ffi::write_u8(tmp, &format, w, h, 3, &encode_srgb8(image)),
        }
        .map_err(|e| format!("OpenImageIO cannot write the image: {}", e.what()))
    })
}

/// Makes a tiled, mip-mapped TIFF texture (`.tx`) of the image `src` at `dst`, atomically,
/// with OpenImageIO's `make_texture` (as `maketx` does); pixels keep `src`'s data type.
pub fn make_texture(src: &Path, dst: &Path) -> Result<()> {
    let src_utf8 = utf8(src)?;
    utf8(dst)?;
    write_atomically(dst, |tmp| {
        let tmp = tmp.to_str().ok_or("OpenImageIO needs a UTF-8 file name")?;
        ffi::make_texture(src_utf8, tmp)
            .map_err(|e| format!("OpenImageIO cannot make a texture of {}: {}", src.display(), e.what()))
    })
}
