//! `--denoise`: Intel Open Image Denoise's `RT` filter (HDR) over the rendered image, in a
//! build with `--features oidn`; the denoised image is written beside the raw one
//! ([`denoised_path`]), never in its place. Auxiliary images (first-hit albedo, shading
//! normal) improve the result where the render has them ([`Aux`]); without them the filter
//! sees the colour alone. Without the feature, [`denoise`] refuses with an error that names
//! it.

use crate::error::{Error, Result};
use crate::film::Filter;
use crate::image_io::Channels;
use crate::math::Rgb;
use std::path::{Path, PathBuf};

/// Whether this build can denoise (`--features oidn`).
pub const AVAILABLE: bool = cfg!(feature = "oidn");

/// What denoising a build without the feature says.
const UNAVAILABLE: &str = "--denoise needs a build with `--features oidn` (Intel Open Image Denoise; \
                           `scripts/setup.sh --with-oidn` provides the library)";

/// The auxiliary images of a render, pixel for pixel with its colour.
#[derive(Clone, Copy, Debug, Default)]
pub struct Aux<'a> {
    /// The first non-specular hit's reflectance, in [0, 1].
    pub albedo: Option<&'a [Rgb]>,
    /// The shading normal there (any length, world or camera space); only with an albedo.
    pub normal: Option<&'a [Rgb]>,
}

/// The albedo and normal images the denoiser is guided by: the render's own `albedo` and
/// `normal` AOVs where it has them (`aovs`, as `--aov` gives them), else the first-hit pass
/// of [`crate::aov`] run for them alone (seed `seed`, `threads` threads).
pub fn guides(scene: &crate::scene::Scene, aovs: &Channels, seed: u64, threads: usize) -> Result<(Vec<Rgb>, Vec<Rgb>)> {
    let find = |from: &Channels, names: [&str; 3]| -> Option<Vec<Rgb>> {
        let c: Vec<&Vec<f32>> =
            names.iter().map(|n| from.iter().find(|(name, _)| name == n).map(|(_, v)| v)).collect::<Option<_>>()?;
        Some((0..c[0].len()).map(|i| Rgb::new(c[0][i], c[1][i], c[2][i])).collect())
    };
    const ALBEDO: [&str; 3] = ["Albedo.R", "Albedo.G", "Albedo.B"];
    const NORMAL: [&str; 3] = ["Ns.X", "Ns.Y", "Ns.Z"];
    if let (Some(a), Some(n)) = (find(aovs, ALBEDO), find(aovs, NORMAL)) {
        return Ok((a, n));
    }
    let own = crate::aov::first_hits(scene, &[crate::aov::Aov::Albedo, crate::aov::Aov::Normal], seed, threads)?;
    match (find(&own, ALBEDO), find(&own, NORMAL)) {
        (Some(a), Some(n)) => Ok((a, n)),
        _ => Err(Error::Usage("--denoise: the first-hit pass gave no albedo or normal".into())),
    }
}

/// Where the denoised image of `output` goes: `NAME.denoised.EXT` beside it.
pub fn denoised_path(output: &Path) -> PathBuf {
    let stem = output.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let name = match output.extension() {
        Some(ext) => format!("{stem}.denoised.{}", ext.to_string_lossy()),
        None => format!("{stem}.denoised"),
    };
    output.with_file_name(name)
}

/// What to warn of when the film's reconstruction filter spreads samples over neighbouring
/// pixels: the noise is then correlated between pixels, and the denoiser, trained on
/// independent pixels, takes much of it for detail and leaves it.
pub fn filter_warning(filter: &Filter) -> Option<String> {
    let name = match *filter {
        Filter::Box { radius } if radius <= 0.5 => return None,
        Filter::Box { radius } => format!("box filter of radius {radius}"),
        Filter::Tent { .. } => "tent filter".into(),
        Filter::Gaussian { .. } => "gaussian filter".into(),
    };
    Some(format!(
        "--denoise: the film's {name} correlates the noise of neighbouring pixels, which \
             Open Image Denoise mostly leaves in place; it expects a box filter (<rfilter type=\"box\"/>)"
    ))
}

/// Refuses `--denoise` before rendering in a build that cannot denoise.
pub fn check_available() -> Result<()> {
    if AVAILABLE { Ok(()) } else { Err(Error::Usage(UNAVAILABLE.into())) }
}

/// The denoised `width × height` HDR image `color` (linear radiance), with the auxiliary
/// images `aux` where given.
pub fn denoise(width: u32, height: u32, color: &[Rgb], aux: Aux) -> Result<Vec<Rgb>> {
    let n = width as usize * height as usize;
    let sizes = [Some(color), aux.albedo, aux.normal];
    if sizes.iter().flatten().any(|img| img.len() != n) {
        return Err(Error::Usage(format!("--denoise: the images to denoise are not all {width}×{height}")));
    }
    if aux.normal.is_some() && aux.albedo.is_none() {
        return Err(Error::Usage("--denoise: a normal image is used only with an albedo image".into()));
    }
    filter(width as usize, height as usize, color, aux)
}

#[cfg(feature = "oidn")]
fn filter(width: usize, height: usize, color: &[Rgb], aux: Aux) -> Result<Vec<Rgb>> {
    let flat = |img: &[Rgb]| img.iter().flat_map(|p| p.to_array()).collect::<Vec<f32>>();
    let failed = |what: &str, e: oidn::Error| Error::Usage(format!("--denoise: Open Image Denoise {what}: {e}"));
    let device = oidn::Device::cpu().map_err(|e| failed("has no CPU device", e))?;
    let mut rt = oidn::RayTracing::try_new(&device).map_err(|e| failed("cannot make its RT filter", e))?;
    rt.hdr(true).image_dimensions(width, height);
    // Kept alive until the filter has run: the filter reads them.
    let (albedo, normal) = (aux.albedo.map(flat), aux.normal.map(flat));
    match (&albedo, &normal) {
        (Some(a), Some(n)) => {
            rt.albedo_normal(a, n);
        }
        (Some(a), None) => {
            rt.albedo(a);
        }
        _ => {}
    }
    let input = flat(color);
    let mut output = vec![0.0f32; input.len()];
    rt.filter(&input, &mut output).map_err(|e| failed("failed", e))?;
    Ok(output.chunks_exact(3).map(|c| Rgb::new(c[0], c[1], c[2])).collect())
}

#[cfg(not(feature = "oidn"))]
fn filter(_width: usize, _height: usize, _color: &[Rgb], _aux: Aux) -> Result<Vec<Rgb>> {
    Err(Error::Usage(UNAVAILABLE.into()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_denoised_image_goes_beside_the_raw_one() {
        assert_eq!(denoised_path(Path::new("out/a.exr")), PathBuf::from("out/a.denoised.exr"));
        assert_eq!(denoised_path(Path::new("b.png")), PathBuf::from("b.denoised.png"));
        assert_eq!(denoised_path(Path::new("c")), PathBuf::from("c.denoised"));
    }

    #[test]
    fn only_a_box_filter_of_one_pixel_goes_without_a_warning() {
        assert!(filter_warning(&Filter::Box { radius: 0.5 }).is_none());
        for f in [Filter::Box { radius: 1.0 }, Filter::Tent { radius: 1.0 }, Filter::Gaussian { stddev: 0.5 }] {
            assert!(filter_warning(&f).is_some_and(|w| w.contains("--denoise")), "{f:?}");
        }
    }

    #[test]
    fn mismatched_images_are_refused() {
        let c = vec![Rgb::ONE; 4];
        let a = vec![Rgb::ONE; 3];
        assert!(denoise(2, 2, &c, Aux { albedo: Some(&a), normal: None }).is_err());
        assert!(denoise(2, 2, &c, Aux { albedo: None, normal: Some(&c) }).is_err());
    }
}
