//! The OpenImageIO layer (`--features oiio`): every format it writes reads back as written;
//! where `exr` or `image` read a file too (EXR, PNG, JPEG, Radiance HDR, TGA), OpenImageIO
//! gives the same pixels; TIFF, HDR, TGA and tiled mip-mapped `.tx` files read back as
//! expected; bad files give an error naming
//! the file; a scene with TIFF textures renders exactly like the same scene with PNG/EXR
//! ones; and the command line picks the library by `PCBPT_IMAGE_IO`.
#![cfg(feature = "oiio")]

mod common;

use common::{image, load, render, root};
use pcbpt::accel::Backend;
use pcbpt::image_io::{self, Image, Library, linear_to_srgb, oiio, srgb_to_linear};
use pcbpt::integrator::IntegratorKind;
use pcbpt::math::Rgb;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A smooth pattern with distinct channels, scaled to `[0, peak]`.
fn pattern(w: u32, h: u32, peak: f32) -> Image {
    let px = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
            Rgb::new(x * peak, y * y * peak, (0.5 + 0.5 * (7.0 * x + 3.0 * y).sin()) * peak)
        })
        .collect();
    Image::new(w, h, px)
}

/// What reading an 8-bit sRGB file of `img` gives: each value encoded as the PNG writer
/// does, divided by 255 and decoded.
fn quantized(img: &Image) -> Image {
    let q = |v: f32| srgb_to_linear(((linear_to_srgb(v) * 255.0 + 0.5) as u8) as f32 / 255.0);
    Image::new(img.width, img.height, img.pixels.iter().map(|p| Rgb::new(q(p.x), q(p.y), q(p.z))).collect())
}

fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> =
        std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    v.sort();
    v
}

#[test]
fn written_formats_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let hdr = pattern(13, 7, 40.0);
    let ldr = pattern(13, 7, 1.0);

    // EXR written by OpenImageIO: exact, and the `exr` reader agrees.
    let exr = dir.path().join("a.exr");
    image_io::write_with(&exr, &hdr, Library::Oiio).unwrap();
    assert_eq!(oiio::info(&exr).unwrap().format, "openexr");
    assert_eq!(image_io::read_with(&exr, false, Library::Oiio).unwrap(), hdr);
    assert_eq!(image_io::read_with(&exr, false, Library::Native).unwrap(), hdr);

    // TIFF output goes through OpenImageIO by itself: 32-bit float, linear, exact.
    let tif = dir.path().join("a.tif");
    image_io::write_with(&tif, &hdr, Library::Auto).unwrap();
    let info = oiio::info(&tif).unwrap();
    assert_eq!((info.format.as_str(), info.bits, info.channels, info.width, info.height), ("tiff", 32, 3, 13, 7));
    assert_eq!(image_io::read_with(&tif, false, Library::Auto).unwrap(), hdr);

    // PNG by OpenImageIO and by `image`: both 8-bit sRGB, read alike by both readers.
    let expect = quantized(&ldr);
    for (name, writer) in [("o.png", Library::Oiio), ("n.png", Library::Native)] {
        let png = dir.path().join(name);
        image_io::write_with(&png, &ldr, writer).unwrap();
        assert_eq!(oiio::info(&png).unwrap().bits, 8, "{name}");
        for reader in [Library::Native, Library::Oiio] {
            assert_eq!(image_io::read_with(&png, false, reader).unwrap(), expect, "{name} read by {reader:?}");
        }
    }
    // Written atomically: nothing but the finished files is left.
    assert_eq!(names(dir.path()), ["a.exr", "a.tif", "n.png", "o.png"]);
}

/// Both readers give the same pixels for `path`, as sRGB-decoded and as raw values.
fn same_pixels(path: &Path) -> Image {
    let native = image_io::read_with(path, false, Library::Native).unwrap();
    assert_eq!(image_io::read_with(path, false, Library::Oiio).unwrap(), native, "{}", path.display());
    let raw = image_io::read_with(path, true, Library::Native).unwrap();
    assert_eq!(image_io::read_with(path, true, Library::Oiio).unwrap(), raw, "{} (raw)", path.display());
    native
}

#[test]
fn oiio_reads_exr_and_png_like_the_native_readers() {
    let dir = tempfile::tempdir().unwrap();
    let img = pattern(17, 9, 5.0);

    // EXR from the native writer (float RGB).
    let a = dir.path().join("native.exr");
    image_io::write_with(&a, &img, Library::Native).unwrap();
    assert_eq!(same_pixels(&a), img);

    // Half-float RGBA EXR from the `exr` crate: alpha is ignored by both.
    use exr::prelude::{Image as ExrImage, SpecificChannels, Vec2, WritableImage, f16};
    let b = dir.path().join("half_rgba.exr");
    let (w, h) = (img.width as usize, img.height as usize);
    let channels = SpecificChannels::rgba(|Vec2(x, y): Vec2<usize>| {
        let p = img.pixels[y * w + x];
        (f16::from_f32(p.x), f16::from_f32(p.y), f16::from_f32(p.z), f16::from_f32(0.25 + 0.01 * x as f32))
    });
    ExrImage::from_channels((w, h), channels).write().to_file(&b).unwrap();
    let info = oiio::info(&b).unwrap();
    assert_eq!((info.channels, info.bits), (4, 32));
    let half = same_pixels(&b);
    assert_eq!(half.get(3, 2).x, f16::from_f32(img.get(3, 2).x).to_f32());

    // PNGs of every colour type the `image` crate writes: grey, grey and alpha, RGB, RGBA,
    // 8 and 16 bits. Alpha varies, so colour multiplied by alpha would differ.
    let (w, h) = (11u32, 6u32);
    let n = (w * h) as usize;
    let v8 = |i: usize, c: usize| ((i * 37 + c * 91) % 256) as u8;
    let v16 = |i: usize, c: usize| ((i * 4099 + c * 12345) % 65536) as u16;
    use image::ExtendedColorType as T;
    let cases: Vec<(&str, T, Vec<u8>, u32)> = vec![
        ("l8.png", T::L8, (0..n).map(|i| v8(i, 0)).collect(), 1),
        ("la8.png", T::La8, (0..n * 2).map(|k| v8(k / 2, k % 2)).collect(), 2),
        ("rgb8.png", T::Rgb8, (0..n * 3).map(|k| v8(k / 3, k % 3)).collect(), 3),
        ("rgba8.png", T::Rgba8, (0..n * 4).map(|k| v8(k / 4, k % 4)).collect(), 4),
        ("rgb16.png", T::Rgb16, (0..n * 3).flat_map(|k| v16(k / 3, k % 3).to_ne_bytes()).collect(), 3),
        ("la16.png", T::La16, (0..n * 2).flat_map(|k| v16(k / 2, k % 2).to_ne_bytes()).collect(), 2),
    ];
    for (name, color, bytes, channels) in cases {
        let p = dir.path().join(name);
        image::save_buffer_with_format(&p, &bytes, w, h, color, image::ImageFormat::Png).unwrap();
        let info = oiio::info(&p).unwrap();
        let bits = if name.contains("16") { 16 } else { 8 };
        assert_eq!((info.channels, info.bits), (channels, bits), "{name}");
        let px = same_pixels(&p);
        if channels <= 2 {
            assert!(px.pixels.iter().all(|p| p.x == p.y && p.y == p.z), "{name}: grey is repeated");
        }
    }
}

/// JPEG decoders are allowed to differ: the standard bounds the IDCT's error but does not fix
/// its arithmetic, and the `image` crate (zune-jpeg) and OpenImageIO (libjpeg-turbo) upsample
/// the half-resolution chroma of a colour JPEG differently. The difference is measured on the
/// stored 8-bit values (`raw`) and bounded; a grey JPEG has no chroma to upsample.
#[test]
fn oiio_reads_jpeg_like_the_native_reader_within_decoder_rounding() {
    let dir = tempfile::tempdir().unwrap();
    let img = pattern(64, 48, 1.0);
    let bytes: Vec<u8> =
        img.pixels.iter().flat_map(|p| [p.x, p.y, p.z]).map(|v| (linear_to_srgb(v) * 255.0 + 0.5) as u8).collect();
    let grey: Vec<u8> = bytes.chunks(3).map(|c| c[1]).collect();
    let mut measured = Vec::new();
    for (name, data, color) in
        [("rgb.jpg", &bytes, image::ExtendedColorType::Rgb8), ("grey.jpg", &grey, image::ExtendedColorType::L8)]
    {
        let p = dir.path().join(name);
        image::save_buffer_with_format(&p, data, 64, 48, color, image::ImageFormat::Jpeg).unwrap();
        let native = image_io::read_with(&p, true, Library::Native).unwrap();
        let oiio = image_io::read_with(&p, true, Library::Oiio).unwrap();
        let levels: Vec<f32> = native
            .pixels
            .iter()
            .zip(&oiio.pixels)
            .flat_map(|(a, b)| (0..3).map(move |c| ((a[c] - b[c]).abs() * 255.0).round()))
            .collect();
        let max = levels.iter().fold(0.0f32, |m, &d| m.max(d));
        let mean = levels.iter().map(|&d| d as f64).sum::<f64>() / levels.len() as f64;
        let differ = levels.iter().filter(|&&d| d > 0.0).count() as f64 / levels.len() as f64;
        eprintln!(
            "{name}: native vs OpenImageIO in 8-bit levels: max {max}, mean {mean:.4}, {:.2}% differ",
            differ * 100.0
        );
        measured.push((name, max, mean));
    }
    for (name, max, mean) in measured {
        // Measured: colour max 3 levels, mean 0.0145 (1.2% of the values differ); grey none.
        let (max_bound, mean_bound) = if name == "rgb.jpg" { (4.0, 0.05) } else { (0.0, 0.0) };
        assert!(max <= max_bound && mean <= mean_bound, "{name}: max {max} levels, mean {mean}");
    }
}

#[test]
fn tiff_hdr_tga_and_mipmapped_tx_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let ldr = pattern(150, 90, 1.0);
    let hdr = pattern(150, 90, 60.0);
    let path = |n: &str| dir.path().join(n);

    // 8-bit TIFF: sRGB-encoded like PNG.
    oiio::write_encoded(&path("a8.tif"), &ldr, oiio::Encoding::Srgb8).unwrap();
    assert_eq!(oiio::info(&path("a8.tif")).unwrap().bits, 8);
    assert_eq!(image_io::read(&path("a8.tif")).unwrap(), quantized(&ldr));

    // TGA: 8-bit sRGB, read by `image` (the default) and by OpenImageIO alike.
    oiio::write(&path("a.tga"), &ldr).unwrap();
    assert_eq!(oiio::info(&path("a.tga")).unwrap().format, "targa");
    assert_eq!(image_io::read(&path("a.tga")).unwrap(), quantized(&ldr));
    assert_eq!(same_pixels(&path("a.tga")), quantized(&ldr));

    // Radiance HDR (RGBE): one shared exponent and an 8-bit mantissa per channel, so each
    // channel is off by less than one mantissa step, 2^e / 256 ≤ max(r, g, b) / 128.
    oiio::write(&path("a.hdr"), &hdr).unwrap();
    assert_eq!(oiio::info(&path("a.hdr")).unwrap().format, "hdr");
    let back = image_io::read(&path("a.hdr")).unwrap();
    let mut worst = 0.0f32;
    for (a, b) in hdr.pixels.iter().zip(&back.pixels) {
        let m = a.max_element();
        for c in 0..3 {
            worst = worst.max((a[c] - b[c]).abs() / m);
        }
    }
    eprintln!("HDR: largest error {worst:.5} of the pixel's largest channel (bound 1/128)");
    assert!(worst < 1.0 / 128.0 && worst > 0.0, "HDR error {worst}");
    // Both decoders expand RGBE the same way (mantissa × 2^(exponent − 136)).
    assert_eq!(same_pixels(&path("a.hdr")), back);

    // Tiled, mip-mapped `.tx` from a float TIFF and from an 8-bit one: the full-resolution
    // level is read, exactly.
    image_io::write(&path("src.tif"), &hdr).unwrap();
    for (src, expect) in [("src.tif", &hdr), ("a8.tif", &quantized(&ldr))] {
        let tx = path(&format!("{src}.tx"));
        oiio::make_texture(&path(src), &tx).unwrap();
        let info = oiio::info(&tx).unwrap();
        // 150 × 90 halves to 1 × 1 in 8 levels.
        assert_eq!(info.format, "tiff");
        assert_eq!((info.tile_width, info.tile_height, info.mip_levels), (64, 64, 8), "{src}");
        assert_eq!((info.width, info.height), (150, 90));
        assert_eq!(&image_io::read(&tx).unwrap(), expect, "{src}");
    }
    assert_eq!(
        names(dir.path()),
        ["a.hdr", "a.tga", "a8.tif", "a8.tif.tx", "src.tif", "src.tif.tx"],
        "no temporary file is left"
    );
}

fn assert_error(result: pcbpt::Result<impl std::fmt::Debug>, file: &Path, says: &str) {
    let e = result.expect_err("an error").to_string();
    assert!(
        e.contains(&file.display().to_string()) && e.contains(says),
        "error {e:?} should name {} and say {says:?}",
        file.display()
    );
}

#[test]
fn bad_files_give_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = |n: &str| dir.path().join(n);

    assert_error(image_io::read(&path("missing.tif")), &path("missing.tif"), "OpenImageIO cannot read");
    std::fs::write(path("garbage.tif"), b"II*\0 this is not a TIFF file").unwrap();
    assert_error(image_io::read(&path("garbage.tif")), &path("garbage.tif"), "OpenImageIO cannot read");
    std::fs::write(path("notes.xyz"), b"plain text").unwrap();
    assert_error(image_io::read_with(&path("notes.xyz"), false, Library::Oiio), &path("notes.xyz"), "cannot read");

    // A PNG cut in half.
    image_io::write(&path("whole.png"), &pattern(64, 64, 1.0)).unwrap();
    let bytes = std::fs::read(path("whole.png")).unwrap();
    std::fs::write(path("cut.png"), &bytes[..bytes.len() / 2]).unwrap();
    assert_error(image_io::read_with(&path("cut.png"), false, Library::Oiio), &path("cut.png"), "cannot read");

    // Five channels, none named R, G or B.
    use exr::prelude::*;
    let chans: Vec<AnyChannel<FlatSamples>> =
        ["u", "v", "w", "x", "y"].iter().map(|n| AnyChannel::new(*n, FlatSamples::F32(vec![0.5; 4]))).collect();
    let layer = Layer::new((2, 2), LayerAttributes::default(), Encoding::UNCOMPRESSED, AnyChannels::sort(chans.into()));
    Image::from_layer(layer).write().to_file(path("five.exr")).unwrap();
    assert_error(
        image_io::read_with(&path("five.exr"), false, Library::Oiio),
        &path("five.exr"),
        "expected 1 to 4 channels",
    );

    // Writing where no file can be made, and in a format OpenImageIO does not write.
    let img = pattern(4, 4, 1.0);
    let nowhere = path("no/such/folder/out.tif");
    assert_error(image_io::write(&nowhere, &img), &nowhere, "OpenImageIO cannot write");
    assert_error(oiio::write(&path("out.xyz"), &img), &path("out.xyz"), "OpenImageIO cannot write");
    assert_error(oiio::make_texture(&path("missing.png"), &path("t.tx")), &path("t.tx"), "missing.png");
    assert_eq!(
        names(dir.path()),
        ["cut.png", "five.exr", "garbage.tif", "notes.xyz", "whole.png"],
        "failed writes leave nothing behind"
    );
}

/// Copies `scenes/materials` into `dir` with its textures converted by `convert` (file name
/// in, new file name out).
fn materials_scene(dir: &Path, convert: impl Fn(&Path, &Path) -> PathBuf) -> PathBuf {
    let src = root().join("scenes/materials");
    std::fs::create_dir_all(dir.join("textures")).unwrap();
    let mut xml = std::fs::read_to_string(src.join("scene.xml")).unwrap();
    for name in ["tiles.png", "sky.exr"] {
        let new = convert(&src.join("textures").join(name), &dir.join("textures"));
        let new_name = new.file_name().unwrap().to_str().unwrap();
        xml = xml.replace(&format!("textures/{name}"), &format!("textures/{new_name}"));
    }
    let scene = dir.join("scene.xml");
    std::fs::write(&scene, xml).unwrap();
    scene
}

#[test]
fn scene_with_tiff_textures_renders_like_png_and_exr() {
    let dir = tempfile::tempdir().unwrap();
    let native = materials_scene(&dir.path().join("native"), |src, to| {
        let dst = to.join(src.file_name().unwrap());
        std::fs::copy(src, &dst).unwrap();
        dst
    });
    // The 8-bit sRGB PNG becomes an 8-bit sRGB TIFF with the same stored values; the float
    // EXR environment map a float TIFF.
    let tiff = materials_scene(&dir.path().join("tiff"), |src, to| {
        let dst = to.join(src.file_name().unwrap()).with_extension("tif");
        let img = image_io::read_with(src, false, Library::Native).unwrap();
        let encoding = if src.extension().unwrap() == "png" { oiio::Encoding::Srgb8 } else { oiio::Encoding::Float };
        oiio::write_encoded(&dst, &img, encoding).unwrap();
        assert_eq!(image_io::read_texture(&dst, false).unwrap(), img, "{} converts exactly", src.display());
        dst
    });
    let xml = std::fs::read_to_string(&tiff).unwrap();
    assert!(xml.contains("textures/tiles.tif") && xml.contains("textures/sky.tif") && !xml.contains(".png"));
    assert_eq!(names(&dir.path().join("tiff/textures")), ["sky.tif", "tiles.tif"]);

    let defines = [("resx", "48"), ("resy", "36")];
    let a = image(render(&load(&native, &defines, Backend::Embree), IntegratorKind::Path, 4, 7, 1));
    let b = image(render(&load(&tiff, &defines, Backend::Embree), IntegratorKind::Path, 4, 7, 1));
    assert!(a.mean() > 0.0);
    assert_eq!(a, b, "the TIFF-textured scene renders differently");
}

fn pcbpt(args: &[&str], library: Option<&str>) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_pcbpt"));
    cmd.args(args).env_remove(Library::ENV);
    if let Some(l) = library {
        cmd.env(Library::ENV, l);
    }
    cmd.output().expect("runs the binary")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn command_line_writes_tiff_and_picks_the_library_by_environment() {
    let dir = tempfile::tempdir().unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let scene = root().join("scenes/cornell-box/scene.xml");
    let (exr, tif) = (dir.path().join("out.exr"), dir.path().join("out.tif"));
    for out in [&exr, &tif] {
        let o = pcbpt(
            &[
                "render",
                &s(&scene),
                "-o",
                &s(out),
                "-D",
                "resx=24",
                "-D",
                "resy=24",
                "--spp",
                "2",
                "--seed",
                "3",
                "--quiet",
            ],
            None,
        );
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let rendered = image_io::read_exr(&exr).unwrap();
    assert_eq!(image_io::read(&tif).unwrap(), rendered, "the TIFF holds the rendered floats");

    // `compare` reads TIFF through OpenImageIO by itself, not with PCBPT_IMAGE_IO=native.
    let o = pcbpt(&["compare", &s(&exr), &s(&tif), "--metric", "relmse"], None);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), "0.000000e0");
    let o = pcbpt(&["compare", &s(&exr), &s(&tif)], Some("native"));
    assert!(!o.status.success() && stderr(&o).contains(&s(&tif)), "{}", stderr(&o));

    // A TIFF named `.png`: the PNG decoder refuses it, OpenImageIO (forced) reads it.
    let fake = dir.path().join("tiff_inside.png");
    std::fs::copy(&tif, &fake).unwrap();
    let o = pcbpt(&["compare", &s(&exr), &s(&fake), "--metric", "relmse"], None);
    assert!(!o.status.success() && stderr(&o).contains(&s(&fake)), "{}", stderr(&o));
    let o = pcbpt(&["compare", &s(&exr), &s(&fake), "--metric", "relmse"], Some("oiio"));
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(String::from_utf8_lossy(&o.stdout).trim(), "0.000000e0");

    let o = pcbpt(&["compare", &s(&exr), &s(&tif)], Some("bogus"));
    assert!(!o.status.success() && stderr(&o).contains("PCBPT_IMAGE_IO=bogus"), "{}", stderr(&o));
}
