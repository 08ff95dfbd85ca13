//! Reading and writing images: linear float RGB as OpenEXR (`exr`), sRGB 8-bit as PNG
//! (`image`), chosen by the file extension; `image` also reads JPEG, Radiance HDR (`.hdr`),
//! TGA and BMP. Every output is written to a temporary file
//! beside the target and renamed over it, so a killed process never leaves a truncated
//! image behind.
//!
//! Built with `--features oiio`, the formats these crates do not read (TIFF, tiled
//! mip-mapped `.tx`, …) are read through the system OpenImageIO ([`oiio`]), and
//! `.tif`/`.tiff` outputs are written through it (32-bit float, linear). The environment
//! variable `PCBPT_IMAGE_IO` picks the library ([`Library`]): `auto` (the default), `native`
//! or `oiio` (OpenImageIO for every format, EXR/PNG/JPEG included).
//!
//! Pixels become linear RGB the same way whichever library decoded them: float data as
//! stored, 8/16-bit data divided by its largest value and decoded from sRGB (unless a texture
//! asks for `raw` values); alpha is dropped and grey repeated into R, G and B.

use crate::error::{Error, Result};
use crate::math::Rgb;
use exr::prelude::{Image as ExrImage, SpecificChannels, Vec2 as ExrVec2, WritableImage};
use std::path::{Path, PathBuf};

#[cfg(feature = "oiio")]
pub mod oiio;
pub mod tonemap;

/// Which library reads and writes image files; [`Library::from_env`] reads the choice from
/// `PCBPT_IMAGE_IO`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Library {
    /// `exr` for EXR, `image` for PNG, JPEG, Radiance HDR, TGA and BMP, and (with
    /// `--features oiio`) OpenImageIO for every other format and for TIFF output.
    Auto,
    /// Only `exr` and `image`.
    Native,
    /// OpenImageIO for every format (needs `--features oiio`).
    Oiio,
}

impl Library {
    /// The environment variable that picks the library: `auto`, `native` or `oiio`.
    pub const ENV: &'static str = "PCBPT_IMAGE_IO";

    /// The library `PCBPT_IMAGE_IO` asks for; [`Library::Auto`] when it is unset or empty.
    pub fn from_env() -> Result<Library> {
        match std::env::var(Library::ENV) {
            Err(std::env::VarError::NotPresent) => Ok(Library::Auto),
            Ok(v) => match v.trim().to_ascii_lowercase().as_str() {
                "" | "auto" => Ok(Library::Auto),
                "native" => Ok(Library::Native),
                "oiio" => Ok(Library::Oiio),
                _ => Err(Error::Usage(format!("{}={v}: expected auto, native or oiio", Library::ENV))),
            },
            Err(e) => Err(Error::Usage(format!("{}: {e}", Library::ENV))),
        }
    }

    /// [`Library::Oiio`] in a build without OpenImageIO is an error.
    fn check(self) -> Result<Library> {
        if self == Library::Oiio && !cfg!(feature = "oiio") {
            return Err(Error::Usage(format!(
                "{}=oiio: this pcbpt is built without OpenImageIO; rebuild it with `--features oiio`",
                Library::ENV
            )));
        }
        Ok(self)
    }
}

/// Extensions of formats that only OpenImageIO reads here, for the error of a build without
/// it.
#[cfg(not(feature = "oiio"))]
const OIIO_ONLY: &[&str] = &["tif", "tiff", "tx", "rgbe", "dpx", "psd", "webp", "jp2", "dds", "gif"];

/// Extensions `exr` and `image` read (whatever the build: one decoder per format, so builds
/// with and without OpenImageIO render the same pixels).
const NATIVE: &[&str] = &["exr", "png", "jpg", "jpeg", "hdr", "tga", "bmp"];

fn extension(path: &Path) -> Option<String> {
    path.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase())
}

/// The library that decodes a file.
enum Reader {
    Exr,
    Image,
    #[cfg(feature = "oiio")]
    Oiio,
}

fn reader(path: &Path, library: Library) -> Result<Reader> {
    let ext = extension(path);
    let native = if ext.as_deref() == Some("exr") { Reader::Exr } else { Reader::Image };
    let native_format = ext.as_deref().is_some_and(|e| NATIVE.contains(&e));
    match library.check()? {
        Library::Native => Ok(native),
        #[cfg(feature = "oiio")]
        Library::Oiio => Ok(Reader::Oiio),
        #[cfg(feature = "oiio")]
        Library::Auto if !native_format => Ok(Reader::Oiio),
        #[cfg(not(feature = "oiio"))]
        Library::Auto if !native_format && ext.as_deref().is_some_and(|e| OIIO_ONLY.contains(&e)) => {
            Err(Error::in_file(
                path,
                format!(
                    "{} images are read through OpenImageIO: rebuild pcbpt with `--features oiio`",
                    ext.unwrap_or_default().to_uppercase()
                ),
            ))
        }
        _ => Ok(native),
    }
}

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
    /// 32-bit float linear TIFF, written through OpenImageIO.
    #[cfg(feature = "oiio")]
    Tiff,
}

impl Format {
    pub fn from_path(path: &Path) -> Result<Format> {
        match extension(path).as_deref() {
            Some("exr") => Ok(Format::Exr),
            Some("png") => Ok(Format::Png),
            #[cfg(feature = "oiio")]
            Some("tif" | "tiff") => Ok(Format::Tiff),
            #[cfg(not(feature = "oiio"))]
            Some("tif" | "tiff") => Err(Error::Usage(format!(
                "{}: TIFF images are written through OpenImageIO: rebuild pcbpt with `--features oiio`",
                path.display()
            ))),
            #[cfg(feature = "oiio")]
            _ => Err(Error::Usage(format!("{}: unknown image format (use .exr, .png or .tif)", path.display()))),
            #[cfg(not(feature = "oiio"))]
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

/// Runs `write_to` on a temporary file beside `path`, then renames it over `path`; on
/// failure the temporary file is removed and the error names `path`.
pub(crate) fn write_atomically(
    path: &Path,
    write_to: impl FnOnce(&Path) -> std::result::Result<(), String>,
) -> Result<()> {
    let tmp = temp_path(path);
    let out_err = |msg: String| Error::Output { path: path.to_path_buf(), msg };
    if let Err(msg) = write_to(&tmp) {
        let _ = std::fs::remove_file(&tmp);
        return Err(out_err(msg));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        out_err(format!("cannot move the finished image into place: {e}"))
    })
}

/// The pixels as 8-bit sRGB-encoded RGB, as PNG files store them.
pub(crate) fn encode_srgb8(image: &Image) -> Vec<u8> {
    tonemap::Ldr::default().encode8(image)
}

/// Writes `image` to `path` (EXR or PNG, and TIFF with `--features oiio`, by extension)
/// atomically, with the library `PCBPT_IMAGE_IO` picks.
pub fn write(path: &Path, image: &Image) -> Result<()> {
    write_with(path, image, Library::from_env()?)
}

/// [`write`], except that a PNG is tonemapped as `ldr` describes (a scene's `ldrfilm`); an
/// EXR keeps the linear values.
pub fn write_film(path: &Path, image: &Image, ldr: Option<&tonemap::Ldr>) -> Result<()> {
    match ldr {
        Some(ldr) if Format::from_path(path)? == Format::Png => {
            write_png_rgb8(path, image.width, image.height, &ldr.encode8(image))
        }
        _ => write(path, image),
    }
}

/// Writes `image` to `path` (format by extension) atomically, with `library`.
pub fn write_with(path: &Path, image: &Image, library: Library) -> Result<()> {
    let format = Format::from_path(path)?;
    match (format, library.check()?) {
        #[cfg(feature = "oiio")]
        (Format::Tiff, _) | (_, Library::Oiio) => oiio::write(path, image),
        (Format::Exr, _) => write_atomically(path, |tmp| {
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
                .to_file(tmp)
                .map_err(|e| format!("cannot write EXR: {e}"))
        }),
        (Format::Png, _) => write_png_rgb8(path, image.width, image.height, &encode_srgb8(image)),
    }
}

/// Named channels of an image (AOVs): `(name, one value per pixel)`.
pub type Channels = Vec<(String, Vec<f32>)>;

/// Writes `image` as an EXR file atomically with extra channels `(name, one value per
/// pixel)` beside its `R`, `G` and `B` (AOVs); the names are sorted as OpenEXR stores them.
pub fn write_exr_channels(path: &Path, image: &Image, extra: &[(String, Vec<f32>)]) -> Result<()> {
    use exr::prelude::{AnyChannel, AnyChannels, Encoding, FlatSamples, Layer, LayerAttributes};
    if Format::from_path(path)? != Format::Exr {
        return Err(Error::Usage(format!("{}: AOVs are written as channels of an EXR file", path.display())));
    }
    let n = image.pixels.len();
    let mut list = exr::prelude::SmallVec::new();
    for (c, name) in ["R", "G", "B"].into_iter().enumerate() {
        list.push(AnyChannel::new(name, FlatSamples::F32(image.pixels.iter().map(|p| p[c]).collect())));
    }
    for (name, values) in extra {
        assert_eq!(values.len(), n, "one value per pixel");
        list.push(AnyChannel::new(name.as_str(), FlatSamples::F32(values.clone())));
    }
    let size = (image.width as usize, image.height as usize);
    let layer = Layer::new(size, LayerAttributes::default(), Encoding::SMALL_LOSSLESS, AnyChannels::sort(list));
    write_atomically(path, |tmp| {
        ExrImage::from_layer(layer).write().non_parallel().to_file(tmp).map_err(|e| format!("cannot write EXR: {e}"))
    })
}

/// Reads every channel of an EXR file's first layer as `(name, one value per pixel)`.
pub fn read_exr_channels(path: &Path) -> Result<(u32, u32, Channels)> {
    use exr::prelude::{ReadChannels, ReadLayers};
    let img = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| Error::in_file(path, format!("cannot read EXR: {e}")))?;
    let layer = &img.layer_data;
    let channels =
        layer.channel_data.list.iter().map(|c| (c.name.to_string(), c.sample_data.values_as_f32().collect())).collect();
    Ok((layer.size.width() as u32, layer.size.height() as u32, channels))
}

/// Writes 8-bit RGB pixels as PNG atomically (false-colour images and figures).
pub fn write_png_rgb8(path: &Path, width: u32, height: u32, bytes: &[u8]) -> Result<()> {
    write_atomically(path, |tmp| {
        image::save_buffer_with_format(
            tmp,
            bytes,
            width,
            height,
            image::ExtendedColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(|e| format!("cannot write PNG: {e}"))
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

/// Reads an image as linear RGB with the library `PCBPT_IMAGE_IO` picks: EXR and Radiance
/// HDR (linear), PNG, JPEG, TGA and BMP (sRGB, decoded to linear), and with `--features oiio`
/// every format OpenImageIO reads.
pub fn read(path: &Path) -> Result<Image> {
    read_as(path, false, Library::from_env()?, "image")
}

/// Reads a texture as linear RGB with the library `PCBPT_IMAGE_IO` picks, as [`read`]
/// does; `raw` keeps 8/16-bit values as stored (divided by their largest value) instead of
/// decoding them from sRGB.
pub fn read_texture(path: &Path, raw: bool) -> Result<Image> {
    read_as(path, raw, Library::from_env()?, "texture")
}

/// Reads an image as linear RGB with `library`; `raw` as for [`read_texture`].
pub fn read_with(path: &Path, raw: bool, library: Library) -> Result<Image> {
    read_as(path, raw, library, "image")
}

fn read_as(path: &Path, raw: bool, library: Library, what: &str) -> Result<Image> {
    Ok(decode_as(path, raw, library, what)?.into_image())
}

/// Reads a texture as [`read_texture`] does, keeping 8-bit channels as bytes (what
/// [`crate::texture::Bitmap`] stores them as): no pass over the texels in `f32`.
pub fn read_texture_data(path: &Path, raw: bool) -> Result<TextureData> {
    decode_as(path, raw, Library::from_env()?, "texture")
}

fn decode_as(path: &Path, raw: bool, library: Library, what: &str) -> Result<TextureData> {
    match reader(path, library)? {
        Reader::Exr => Ok(TextureData::Linear(read_exr(path)?)),
        Reader::Image => {
            let img = image::open(path).map_err(|e| Error::in_file(path, format!("cannot read {what}: {e}")))?;
            Ok(TextureData::of(img, raw))
        }
        #[cfg(feature = "oiio")]
        Reader::Oiio => Ok(TextureData::of(oiio::read(path)?, raw)),
    }
}

/// Decoded pixels on their way to linear RGB: 8-bit channels as bytes, or linear floats.
#[derive(Clone, Debug, PartialEq)]
pub enum TextureData {
    /// Three bytes a texel, row-major from the top-left (grey repeated, alpha dropped); byte
    /// `k` stands for `table[k]`.
    Bytes {
        width: u32,
        height: u32,
        rgb: Vec<u8>,
        table: Box<[f32; 256]>,
    },
    Linear(Image),
}

impl TextureData {
    /// Float data as stored; 8/16-bit data divided by its largest value, then decoded from
    /// sRGB unless `raw`. Alpha is dropped, grey repeated.
    fn of(img: image::DynamicImage, raw: bool) -> TextureData {
        use image::ColorType as C;
        if matches!(img.color(), C::L8 | C::La8 | C::Rgb8 | C::Rgba8) {
            let table = byte_table(img.color(), !raw);
            let rgb = img.into_rgb8();
            let (width, height) = rgb.dimensions();
            return TextureData::Bytes { width, height, rgb: rgb.into_raw(), table };
        }
        let float_data = matches!(img.color(), C::Rgb32F | C::Rgba32F);
        let rgb = img.into_rgb32f();
        let (w, h) = rgb.dimensions();
        let decode = |v: f32| if raw || float_data { v } else { srgb_to_linear(v) };
        let px = rgb.pixels().map(|p| Rgb::new(decode(p[0]), decode(p[1]), decode(p[2]))).collect();
        TextureData::Linear(Image::new(w, h, px))
    }

    pub fn width(&self) -> u32 {
        match self {
            TextureData::Bytes { width, .. } => *width,
            TextureData::Linear(img) => img.width,
        }
    }

    pub fn height(&self) -> u32 {
        match self {
            TextureData::Bytes { height, .. } => *height,
            TextureData::Linear(img) => img.height,
        }
    }

    /// The pixels as linear RGB.
    pub fn into_image(self) -> Image {
        match self {
            TextureData::Bytes { width, height, rgb, table } => {
                let px = rgb
                    .chunks_exact(3)
                    .map(|c| Rgb::new(table[c[0] as usize], table[c[1] as usize], table[c[2] as usize]));
                Image::new(width, height, px.collect())
            }
            TextureData::Linear(img) => img,
        }
    }
}

/// The linear values of the 256 values of an 8-bit channel of an image of colour type
/// `color`: what `image` converts byte `k` to in `f32` (for grey data not always `k / 255`
/// to the last bit), decoded from sRGB if `srgb`. Made by converting the 256 values, so a
/// texture kept as bytes reads exactly as its `f32` conversion would.
pub fn byte_table(color: image::ColorType, srgb: bool) -> Box<[f32; 256]> {
    use image::{ColorType as C, DynamicImage as D, ImageBuffer as B};
    let k: Vec<u8> = (0..=255).collect();
    let spread = |n: usize| -> Vec<u8> { k.iter().flat_map(|&v| std::iter::repeat_n(v, n)).collect() };
    let probe = match color {
        C::L8 => D::ImageLuma8(B::from_raw(256, 1, k.clone()).expect("256 values")),
        C::La8 => D::ImageLumaA8(B::from_raw(256, 1, spread(2)).expect("256 values")),
        C::Rgba8 => D::ImageRgba8(B::from_raw(256, 1, spread(4)).expect("256 values")),
        _ => D::ImageRgb8(B::from_raw(256, 1, spread(3)).expect("256 values")),
    };
    let f = probe.into_rgb32f();
    Box::new(std::array::from_fn(|i| {
        let v = f.get_pixel(i as u32, 0)[0];
        if srgb { srgb_to_linear(v) } else { v }
    }))
}

/// The alpha channel of an image, if it has one: `(width, height, alpha)`, row-major from
/// the top-left. Alpha is linear: 8/16-bit values are divided by their largest value, never
/// decoded from sRGB. `None` for an image without alpha (JPEG, RGB PNG or EXR).
pub fn read_alpha(path: &Path) -> Result<Option<(u32, u32, Vec<f32>)>> {
    match reader(path, Library::from_env()?)? {
        Reader::Exr => {
            let meta = exr::meta::MetaData::read_from_file(path, false)
                .map_err(|e| Error::in_file(path, format!("cannot read EXR: {e}")))?;
            let has_alpha =
                meta.headers.first().is_some_and(|h| h.channels.list.iter().any(|c| c.name.eq_case_insensitive("A")));
            if !has_alpha {
                return Ok(None);
            }
            let img = exr::prelude::read_first_rgba_layer_from_file(
                path,
                |res: ExrVec2<usize>, _| (res.width(), res.height(), vec![0.0f32; res.width() * res.height()]),
                |(w, _, px): &mut (usize, usize, Vec<f32>), pos: ExrVec2<usize>, (_, _, _, a): (f32, f32, f32, f32)| {
                    px[pos.y() * *w + pos.x()] = a;
                },
            )
            .map_err(|e| Error::in_file(path, format!("cannot read EXR: {e}")))?;
            let (w, h, px) = img.layer_data.channel_data.pixels;
            Ok(Some((w as u32, h as u32, px)))
        }
        Reader::Image => {
            let img = image::open(path).map_err(|e| Error::in_file(path, format!("cannot read texture: {e}")))?;
            Ok(alpha_of(img))
        }
        #[cfg(feature = "oiio")]
        Reader::Oiio => Ok(alpha_of(oiio::read(path)?)),
    }
}

fn alpha_of(img: image::DynamicImage) -> Option<(u32, u32, Vec<f32>)> {
    if !img.color().has_alpha() {
        return None;
    }
    let rgba = img.into_rgba32f();
    let (w, h) = rgba.dimensions();
    Some((w, h, rgba.pixels().map(|p| p[3]).collect()))
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
        let e = write(Path::new("x.xyz"), &Image::new(1, 1, vec![Rgb::ZERO])).unwrap_err().to_string();
        assert!(e.contains("x.xyz") && e.contains("unknown image format"), "{e}");
    }

    #[cfg(not(feature = "oiio"))]
    #[test]
    fn oiio_formats_name_the_file_and_the_feature() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["a.tif", "b.RGBE", "c.webp", "d.tx"] {
            let path = dir.path().join(name);
            std::fs::write(&path, b"not read").unwrap();
            let e = read(&path).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains("--features oiio"), "{e}");
        }
        let e = write(&dir.path().join("out.tiff"), &Image::new(1, 1, vec![Rgb::ZERO])).unwrap_err().to_string();
        assert!(e.contains("out.tiff") && e.contains("--features oiio"), "{e}");
        let e = read_with(&dir.path().join("a.tif"), false, Library::Oiio).unwrap_err().to_string();
        assert!(e.contains("PCBPT_IMAGE_IO=oiio") && e.contains("--features oiio"), "{e}");
    }

    /// Every byte value of every 8-bit colour type becomes what `image`'s `f32` conversion
    /// and the sRGB curve give, bit for bit, whether kept as bytes or made linear.
    #[test]
    fn byte_tables_are_the_f32_conversion() {
        let dir = tempfile::tempdir().unwrap();
        let bytes: Vec<u8> = (0..=255).collect();
        let grey = image::DynamicImage::ImageLuma8(image::GrayImage::from_raw(256, 1, bytes.clone()).unwrap());
        let grey_alpha: Vec<u8> = bytes.iter().flat_map(|&v| [v, v.wrapping_mul(7)]).collect();
        let rgba: Vec<u8> = bytes.iter().flat_map(|&v| [v, 255 - v, v.wrapping_mul(7), v.wrapping_mul(13)]).collect();
        let images = [
            grey.clone(),
            image::DynamicImage::ImageLumaA8(image::ImageBuffer::from_raw(256, 1, grey_alpha).unwrap()),
            image::DynamicImage::ImageRgba8(image::RgbaImage::from_raw(256, 1, rgba.clone()).unwrap()),
            image::DynamicImage::ImageRgba8(image::RgbaImage::from_raw(256, 1, rgba).unwrap()).to_rgb8().into(),
        ];
        for img in images {
            for raw in [false, true] {
                let floats = img.clone().into_rgb32f();
                let expect: Vec<Rgb> = floats
                    .pixels()
                    .map(|p| p.0.map(|v| if raw { v } else { srgb_to_linear(v) }))
                    .map(|[r, g, b]| Rgb::new(r, g, b))
                    .collect();
                let data = TextureData::of(img.clone(), raw);
                assert!(matches!(data, TextureData::Bytes { .. }));
                let got = data.into_image().pixels;
                let bits = |v: &[Rgb]| v.iter().flat_map(|p| p.to_array().map(f32::to_bits)).collect::<Vec<_>>();
                assert_eq!(bits(&got), bits(&expect), "{:?}, raw {raw}", img.color());
            }
        }
        // 16-bit data stays float.
        let path = dir.path().join("a16.png");
        image::DynamicImage::ImageRgb16(image::ImageBuffer::from_raw(1, 1, vec![0u16, 30000, 65535]).unwrap())
            .save(&path)
            .unwrap();
        assert!(matches!(read_texture_data(&path, false).unwrap(), TextureData::Linear(_)));
    }

    /// Radiance HDR, TGA and BMP are read by `image` in every build: HDR as stored (within its
    /// shared-exponent rounding), TGA and BMP as sRGB like PNG; a damaged file names itself.
    #[test]
    fn hdr_tga_and_bmp_are_read_natively() {
        let dir = tempfile::tempdir().unwrap();
        let hdr = dir.path().join("sky.hdr");
        let values = [Rgb::new(0.25, 1.5, 40.0), Rgb::new(3.0, 0.0, 0.125)];
        let px: Vec<image::Rgb<f32>> = values.iter().map(|v| image::Rgb([v.x, v.y, v.z])).collect();
        let file = std::io::BufWriter::new(std::fs::File::create(&hdr).unwrap());
        image::codecs::hdr::HdrEncoder::new(file).encode(&px, 2, 1).unwrap();
        for library in [Library::Auto, Library::Native] {
            let back = read_with(&hdr, false, library).unwrap();
            assert_eq!((back.width, back.height), (2, 1));
            for (a, b) in values.iter().zip(&back.pixels) {
                // One 8-bit mantissa per channel under a shared exponent.
                assert!((*a - *b).abs().max_element() <= a.max_element() / 128.0, "{a} read as {b}");
            }
            // Float data is linear: `raw` changes nothing.
            assert_eq!(read_with(&hdr, true, library).unwrap(), back);
        }
        let bytes = [10u8, 128, 255, 0, 64, 200];
        let expect: Vec<Rgb> = bytes
            .chunks(3)
            .map(|c| Rgb::new(c[0] as f32, c[1] as f32, c[2] as f32) / 255.0)
            .map(|c| Rgb::new(srgb_to_linear(c.x), srgb_to_linear(c.y), srgb_to_linear(c.z)))
            .collect();
        for name in ["a.tga", "a.bmp", "a.png"] {
            let path = dir.path().join(name);
            image::RgbImage::from_raw(2, 1, bytes.to_vec()).unwrap().save(&path).unwrap();
            assert_eq!(read(&path).unwrap().pixels, expect, "{name}");
        }
        std::fs::write(dir.path().join("bad.hdr"), b"#?RADIANCE\nnot an image").unwrap();
        let e = read(&dir.path().join("bad.hdr")).unwrap_err().to_string();
        assert!(e.contains("bad.hdr") && e.contains("cannot read"), "{e}");
    }

    #[test]
    fn alpha_is_read_linear_where_there_is_one() {
        let dir = tempfile::tempdir().unwrap();
        let rgba = dir.path().join("a.png");
        image::RgbaImage::from_raw(2, 1, vec![10, 20, 30, 0, 200, 100, 50, 128]).unwrap().save(&rgba).unwrap();
        // Alpha as stored (not decoded from sRGB); the colour is what `read_texture` gives.
        let (w, h, a) = read_alpha(&rgba).unwrap().unwrap();
        assert_eq!((w, h, a), (2, 1, vec![0.0, 128.0 / 255.0]));
        let rgb = dir.path().join("b.png");
        image::RgbImage::from_raw(1, 1, vec![1, 2, 3]).unwrap().save(&rgb).unwrap();
        assert_eq!(read_alpha(&rgb).unwrap(), None);
    }

    #[test]
    fn grey_and_alpha_become_rgb_like_the_image_crate() {
        // 2×1 grey+alpha, 8-bit: grey repeated, alpha dropped, sRGB decoded unless raw.
        let ga = image::DynamicImage::ImageLumaA8(image::ImageBuffer::from_raw(2, 1, vec![0, 7, 188, 255]).unwrap());
        let img = TextureData::of(ga.clone(), false).into_image();
        assert_eq!(img.get(1, 0), Rgb::splat(srgb_to_linear(188.0 / 255.0)));
        assert_eq!(img.get(0, 0), Rgb::ZERO);
        assert_eq!(TextureData::of(ga, true).into_image().get(1, 0), Rgb::splat(188.0 / 255.0));
        // Float data is linear whatever `raw` says.
        let f =
            image::DynamicImage::ImageRgba32F(image::ImageBuffer::from_raw(1, 1, vec![0.25, 2.0, 0.5, 0.1]).unwrap());
        assert_eq!(TextureData::of(f, false).into_image().get(0, 0), Rgb::new(0.25, 2.0, 0.5));
    }
}
