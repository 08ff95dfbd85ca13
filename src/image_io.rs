//! Reading and writing images: linear float RGB as OpenEXR (`exr`), sRGB 8-bit as PNG
//! (`image`), chosen by the file extension. Every output is written to a temporary file
//! beside the target and renamed over it, so a killed process never leaves a truncated
//! image behind.

use crate::error::{Error, Result};
use crate::math::Rgb;
use exr::prelude::{Image as ExrImage, SpecificChannels, Vec2 as ExrVec2, WritableImage};
use std::path::{Path, PathBuf};

/// A linear RGB image, row-major from the top-left.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Rgb>,
}

impl Image {
    pub fn new(width: u32, height: u32, pixels: Vec<Rgb>) -> Image {
        assert_eq!(pixels.len(), width as usize * height as usize, "pixel count does not match the size");
        Image { width, height, pixels }
    }

    /// Mean over pixels and channels.
    pub fn mean(&self) -> f64 {
        self.pixels.iter().map(|p| (p.x + p.y + p.z) as f64).sum::<f64>() / (3.0 * self.pixels.len().max(1) as f64)
    }

    pub fn get(&self, x: u32, y: u32) -> Rgb {
        self.pixels[y as usize * self.width as usize + x as usize]
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Exr,
    Png,
}

impl Format {
    pub fn from_path(path: &Path) -> Result<Format> {
        match path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref() {
            Some("exr") => Ok(Format::Exr),
            Some("png") => Ok(Format::Png),
            _ => Err(Error::Usage(format!("{}: unknown image format (use .exr or .png)", path.display()))),
        }
    }
}

/// sRGB transfer function of a linear value in `[0, 1]`.
#[inline]
pub fn linear_to_srgb(v: f32) -> f32 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 { 12.92 * v } else { 1.055 * v.powf(1.0 / 2.4) - 0.055 }
}

fn temp_path(path: &Path) -> PathBuf {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "image".into());
    path.with_file_name(format!(".{name}.{}.tmp", std::process::id()))
}

/// Writes a text file atomically (temporary file, then rename).
pub fn write_text(path: &Path, text: &str) -> Result<()> {
    let tmp = temp_path(path);
    std::fs::write(&tmp, text)
        .and_then(|_| std::fs::rename(&tmp, path))
        .map_err(|e| Error::Output { path: path.to_path_buf(), msg: e.to_string() })
}

/// Writes `image` to `path` (EXR or PNG by extension) atomically.
pub fn write(path: &Path, image: &Image) -> Result<()> {
    let format = Format::from_path(path)?;
    let tmp = temp_path(path);
    let out_err = |msg: String| Error::Output { path: path.to_path_buf(), msg };
    let result = match format {
        Format::Exr => {
            let w = image.width as usize;
            // Compressed on one thread so that the blocks are written in order: the same
            // pixels always give the same bytes.
            let channels = SpecificChannels::rgb(|ExrVec2(x, y): ExrVec2<usize>| {
                let p: Rgb = image.pixels[y * w + x];
                (p.x, p.y, p.z)
            });
            ExrImage::from_channels((w, image.height as usize), channels)
                .write()
                .non_parallel()
                .to_file(&tmp)
                .map_err(|e| out_err(format!("cannot write EXR: {e}")))
        }
        Format::Png => {
            let bytes: Vec<u8> = image
                .pixels
                .iter()
                .flat_map(|p| [p.x, p.y, p.z])
                .map(|v| (linear_to_srgb(v) * 255.0 + 0.5) as u8)
                .collect();
            image::save_buffer_with_format(
                &tmp,
                &bytes,
                image.width,
                image.height,
                image::ExtendedColorType::Rgb8,
                image::ImageFormat::Png,
            )
            .map_err(|e| out_err(format!("cannot write PNG: {e}")))
        }
    };
    if let Err(e) = result {
        let _ = std::fs::remove_file(&tmp);
        return Err(e);
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        out_err(format!("cannot move the finished image into place: {e}"))
    })
}

/// Writes 8-bit RGB pixels as PNG atomically (false-colour images and figures).
pub fn write_png_rgb8(path: &Path, width: u32, height: u32, bytes: &[u8]) -> Result<()> {
    let tmp = temp_path(path);
    image::save_buffer_with_format(&tmp, bytes, width, height, image::ExtendedColorType::Rgb8, image::ImageFormat::Png)
        .map_err(|e| Error::Output { path: path.to_path_buf(), msg: format!("cannot write PNG: {e}") })?;
    std::fs::rename(&tmp, path).map_err(|e| Error::Output {
        path: path.to_path_buf(),
        msg: format!("cannot move the finished image into place: {e}"),
    })
}

/// Reads the first RGB(A) layer of an EXR file as linear RGB.
pub fn read_exr(path: &Path) -> Result<Image> {
    let img = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |res: ExrVec2<usize>, _| (res.width(), res.height(), vec![Rgb::ZERO; res.width() * res.height()]),
        |(w, _, px): &mut (usize, usize, Vec<Rgb>), pos: ExrVec2<usize>, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = Rgb::new(r, g, b);
        },
    )
    .map_err(|e| Error::in_file(path, format!("cannot read EXR: {e}")))?;
    let (w, h, px) = img.layer_data.channel_data.pixels;
    Ok(Image::new(w as u32, h as u32, px))
}

/// Reads an EXR (linear) or PNG/JPEG (sRGB, decoded to linear) image.
pub fn read(path: &Path) -> Result<Image> {
    match path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase()).as_deref() {
        Some("exr") => read_exr(path),
        _ => {
            let img =
                image::open(path).map_err(|e| Error::in_file(path, format!("cannot read image: {e}")))?.to_rgb32f();
            let (w, h) = img.dimensions();
            let px = img
                .pixels()
                .map(|p| Rgb::new(srgb_to_linear(p[0]), srgb_to_linear(p[1]), srgb_to_linear(p[2])))
                .collect();
            Ok(Image::new(w, h, px))
        }
    }
}

/// Inverse of [`linear_to_srgb`].
#[inline]
pub fn srgb_to_linear(v: f32) -> f32 {
    if v <= 0.04045 { v / 12.92 } else { ((v + 0.055) / 1.055).powf(2.4) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_round_trip_is_exact_and_atomic() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.exr");
        let px: Vec<Rgb> = (0..12).map(|i| Rgb::new(i as f32 * 0.37, 1e-5 * i as f32, 1e4)).collect();
        let img = Image::new(4, 3, px);
        write(&path, &img).unwrap();
        assert_eq!(read_exr(&path).unwrap(), img);
        let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(leftovers.len(), 1, "{leftovers:?}");
    }

    #[test]
    fn png_is_srgb_encoded() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        write(&path, &Image::new(2, 1, vec![Rgb::splat(0.5), Rgb::splat(2.0)])).unwrap();
        let back = image::open(&path).unwrap().to_rgb8();
        assert_eq!(back.get_pixel(0, 0)[0], 188); // sRGB(0.5) = 0.7354
        assert_eq!(back.get_pixel(1, 0)[0], 255);
    }

    #[test]
    fn unknown_extension_is_an_error() {
        assert!(write(Path::new("x.tiff"), &Image::new(1, 1, vec![Rgb::ZERO])).is_err());
    }
}
