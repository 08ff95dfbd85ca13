//! Mitsuba 0.6's sun (`sun`, and the sun of `sunsky`, in files of version 0.x): the
//! spectral radiance of the solar disk seen through a clear atmosphere, after Preetham,
//! Shirley and Smits, "A Practical Analytic Model for Daylight" (1999), with the
//! extra-terrestrial solar spectrum and the ozone, mixed-gas and water-vapour absorption
//! coefficients of Iqbal, "An Introduction to Solar Radiation" (1983), the tables Mitsuba
//! 0.6 uses. The spectrum is projected to linear Rec. 709 RGB as Mitsuba 0.6's RGB builds
//! project it ([`cie::to_rgb`]).
//!
//! Mitsuba 0.6 draws the disk with an angular radius of 0.2679° (half of 0.5358°) and keeps
//! its power when `sunRadiusScale` widens it; with `sunRadiusScale` 0 the sun is a
//! directional light of the disk's irradiance.

use crate::light::cie::{self, Piecewise};
use crate::math::Rgb;

/// Wavelengths (nm) of the ozone absorption coefficients.
const K_O_WAVELENGTHS: [f64; 64] = [
    300.0, 305.0, 310.0, 315.0, 320.0, 325.0, 330.0, 335.0, 340.0, 345.0, 350.0, 355.0, 445.0, 450.0, 455.0, 460.0,
    465.0, 470.0, 475.0, 480.0, 485.0, 490.0, 495.0, 500.0, 505.0, 510.0, 515.0, 520.0, 525.0, 530.0, 535.0, 540.0,
    545.0, 550.0, 555.0, 560.0, 565.0, 570.0, 575.0, 580.0, 585.0, 590.0, 595.0, 600.0, 605.0, 610.0, 620.0, 630.0,
    640.0, 650.0, 660.0, 670.0, 680.0, 690.0, 700.0, 710.0, 720.0, 730.0, 740.0, 750.0, 760.0, 770.0, 780.0, 790.0,
];

/// Ozone absorption coefficients (cm⁻¹).
const K_O: [f64; 64] = [
    10.0, 4.8, 2.7, 1.35, 0.8, 0.380, 0.160, 0.075, 0.04, 0.019, 0.007, 0.0, 0.003, 0.003, 0.004, 0.006, 0.008, 0.009,
    0.012, 0.014, 0.017, 0.021, 0.025, 0.03, 0.035, 0.04, 0.045, 0.048, 0.057, 0.063, 0.07, 0.075, 0.08, 0.085, 0.095,
    0.103, 0.110, 0.12, 0.122, 0.12, 0.118, 0.115, 0.12, 0.125, 0.130, 0.12, 0.105, 0.09, 0.079, 0.067, 0.057, 0.048,
    0.036, 0.028, 0.023, 0.018, 0.014, 0.011, 0.010, 0.009, 0.007, 0.004, 0.0, 0.0,
];

/// Wavelengths (nm) and coefficients (cm⁻¹) of the mixed gases' absorption.
const K_G_WAVELENGTHS: [f64; 4] = [759.0, 760.0, 770.0, 771.0];
const K_G: [f64; 4] = [0.0, 3.0, 0.210, 0.0];

/// Wavelengths (nm) and coefficients (cm⁻¹) of water vapour's absorption.
const K_WA_WAVELENGTHS: [f64; 13] =
    [689.0, 690.0, 700.0, 710.0, 720.0, 730.0, 740.0, 750.0, 760.0, 770.0, 780.0, 790.0, 800.0];
const K_WA: [f64; 13] = [
    0.0, 0.160e-1, 0.240e-1, 0.125e-1, 0.100e+1, 0.870, 0.610e-1, 0.100e-2, 0.100e-4, 0.100e-4, 0.600e-3, 0.175e-1,
    0.360e-1,
];

/// Wavelengths (nm) of the extra-terrestrial solar spectrum, 380 to 750 nm every 10 nm.
const SOLAR_WAVELENGTHS: [f64; 38] = {
    let mut w = [0.0; 38];
    let mut i = 0;
    while i < 38 {
        w[i] = 380.0 + 10.0 * i as f64;
        i += 1;
    }
    w
};

/// The extra-terrestrial solar radiance, W m⁻² nm⁻¹ sr⁻¹.
const SOLAR: [f64; 38] = [
    16559.0, 16233.7, 21127.5, 25888.2, 25829.1, 24232.3, 26760.5, 29658.3, 30545.4, 30057.5, 30663.7, 28830.4,
    28712.1, 27825.0, 27100.6, 27233.6, 26361.3, 25503.8, 25060.2, 25311.6, 25355.9, 25134.2, 24631.5, 24173.2,
    23685.3, 23212.1, 22827.7, 22339.8, 21970.2, 21526.7, 21097.9, 20728.3, 20240.4, 19870.8, 19427.2, 19072.4,
    18628.9, 18259.2,
];

/// Mitsuba 0.6's angular radius of the sun (radians): half its apparent diameter of 0.5358°.
pub const ANGULAR_RADIUS: f32 = (0.5 * 0.5358 * std::f64::consts::PI / 180.0) as f32;

/// The air mass a ray from the sun at zenith angle `zenith` (radians) crosses, relative to
/// the vertical (Kasten's formula, as Preetham et al. give it). `None` where it has no
/// value: the sun more than 3.885° below the horizon.
fn optical_mass(zenith: f64) -> Option<f64> {
    let below = 93.885 - zenith.to_degrees();
    (below > 0.0).then(|| 1.0 / (zenith.cos() + 0.15 * below.powf(-1.253)))
}

/// The sun's spectral radiance at the ground, every 5 nm from 350 to 800 nm, for a sun at
/// zenith angle `zenith` (radians) and the atmosphere's `turbidity`.
fn spectrum(zenith: f64, turbidity: f64) -> Option<([f64; 91], [f64; 91])> {
    let m = optical_mass(zenith)?;
    let curve = |wavelengths: &'static [f64], values: &'static [f64]| Piecewise { wavelengths, values };
    let (k_o, k_g, k_wa, solar) = (
        curve(&K_O_WAVELENGTHS, &K_O),
        curve(&K_G_WAVELENGTHS, &K_G),
        curve(&K_WA_WAVELENGTHS, &K_WA),
        curve(&SOLAR_WAVELENGTHS, &SOLAR),
    );
    // Aerosols: Ångström's turbidity coefficient from the turbidity, wavelength exponent 1.3.
    let beta = 0.04608365822050 * turbidity - 0.04586025928522;
    let (ozone_cm, water_cm) = (0.35, 2.0);
    let mut wavelengths = [0.0; 91];
    let mut values = [0.0; 91];
    for i in 0..91 {
        let lambda = 350.0 + 5.0 * i as f64;
        let um = lambda / 1000.0;
        let rayleigh = (-m * 0.008735 * um.powf(-4.08)).exp();
        let aerosol = (-m * beta * um.powf(-1.3)).exp();
        let ozone = (-m * k_o.eval(lambda) * ozone_cm).exp();
        let kg = k_g.eval(lambda);
        let gases = (-1.41 * kg * m / (1.0 + 118.93 * kg * m).powf(0.45)).exp();
        let kwa = k_wa.eval(lambda);
        let water = (-0.2385 * kwa * water_cm * m / (1.0 + 20.07 * kwa * water_cm * m).powf(0.45)).exp();
        wavelengths[i] = lambda;
        values[i] = solar.eval(lambda) * rayleigh * aerosol * ozone * gases * water;
    }
    Some((wavelengths, values))
}

/// The radiance of Mitsuba 0.6's sun disk (linear Rec. 709 RGB, before any scale) for a
/// sun at zenith angle `zenith` (radians) in an atmosphere of `turbidity`; zero for a sun
/// so far below the horizon that the model has no value.
pub fn radiance(zenith: f32, turbidity: f32) -> Rgb {
    match spectrum(zenith as f64, turbidity as f64) {
        Some((w, v)) => cie::to_rgb(&Piecewise { wavelengths: &w, values: &v }),
        None => Rgb::ZERO,
    }
}

/// The solid angle of a disk of [`ANGULAR_RADIUS`], `2π (1 − cos θ)` in single precision as
/// Mitsuba 0.6 computes it (the rounding of `cos θ` near 1 is a quarter of a percent).
pub fn solid_angle() -> f32 {
    2.0 * std::f32::consts::PI * (1.0 - ANGULAR_RADIUS.cos())
}

/// The irradiance of the unscaled disk on a surface facing it: its radiance times
/// [`solid_angle`], whatever `sunRadiusScale` makes of its size.
pub fn irradiance(zenith: f32, turbidity: f32) -> Rgb {
    radiance(zenith, turbidity) * solid_angle()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The atmosphere dims and reddens the sun as it sinks, more so in a hazier sky; a sun
    /// at the zenith in the clearest sky keeps most of the extra-terrestrial light.
    #[test]
    fn the_sun_dims_and_reddens_towards_the_horizon() {
        let high = radiance(0.0, 2.0);
        let low = radiance(80f32.to_radians(), 2.0);
        let hazy = radiance(0.0, 8.0);
        assert!(high.min_element() > 0.0);
        assert!(low.y < 0.6 * high.y && hazy.y < high.y, "{high} {low} {hazy}");
        assert!(low.x / low.z > 1.5 * high.x / high.z, "no reddening: {high} against {low}");
        // Air mass 1, turbidity 2: the visible band keeps some 70–85% (Rayleigh, aerosol, ozone).
        let y_top = cie::to_rgb(&Piecewise { wavelengths: &SOLAR_WAVELENGTHS, values: &SOLAR });
        let kept = high.y / y_top.y;
        assert!((0.65..0.9).contains(&kept), "{kept}");
        assert_eq!(radiance(95f32.to_radians(), 3.0), Rgb::ZERO);
    }

    /// The optical mass is 1 at the zenith and about 38 at the horizon (Kasten).
    #[test]
    fn optical_mass_is_kastens() {
        assert!((optical_mass(0.0).unwrap() - 1.0).abs() < 1e-3);
        let horizon = optical_mass(std::f64::consts::FRAC_PI_2).unwrap();
        assert!((30.0..45.0).contains(&horizon), "{horizon}");
        assert!(optical_mass(94f64.to_radians()).is_none());
    }
}
