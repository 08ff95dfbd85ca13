//! Fresnel equations, refraction, and the named indices of refraction and conductors that
//! Mitsuba 3 accepts (`int_ior="bk7"`, `material="Au"`).

use crate::math::Rgb;
use glam::Vec3;

/// Unpolarised Fresnel reflectance of a dielectric interface with relative index
/// `eta = η_inside / η_outside`, for a direction with cosine `cos_i` to the normal (negative
/// when arriving from the inside). Total internal reflection gives 1.
#[inline]
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let (cos_i, eta) = if cos_i < 0.0 { (-cos_i, 1.0 / eta) } else { (cos_i, eta) };
    if eta == 1.0 {
        return 0.0;
    }
    let sin2_t = (1.0 - cos_i * cos_i).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
    let r_parl = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parl * r_parl + r_perp * r_perp)
}

/// Fresnel reflectance of a conductor with complex index `eta + i k` (per channel), for a
/// cosine `cos_i` (its absolute value is used).
pub fn fresnel_conductor(cos_i: f32, eta: Rgb, k: Rgb) -> Rgb {
    let c = cos_i.abs().min(1.0);
    Rgb::new(conductor1(c, eta.x, k.x), conductor1(c, eta.y, k.y), conductor1(c, eta.z, k.z))
}

fn conductor1(cos_i: f32, eta: f32, k: f32) -> f32 {
    let cos2 = cos_i * cos_i;
    let sin2 = 1.0 - cos2;
    let t1 = eta * eta - k * k - sin2;
    let a2pb2 = (t1 * t1 + 4.0 * k * k * eta * eta).max(0.0).sqrt();
    let a = (0.5 * (a2pb2 + t1)).max(0.0).sqrt();
    let term1 = a2pb2 + cos2;
    let term2 = 2.0 * cos_i * a;
    let rs = (term1 - term2) / (term1 + term2);
    let term3 = a2pb2 * cos2 + sin2 * sin2;
    let term4 = term2 * sin2;
    let rp = rs * (term3 - term4) / (term3 + term4);
    let r = 0.5 * (rs + rp);
    if r.is_finite() { r } else { 1.0 }
}

/// Refracts `w` (pointing away from the surface, local frame, normal `n`) through an
/// interface of relative index `eta` (inside / outside, `n` pointing outside). Returns the
/// refracted direction and the relative index along the path, or `None` on total internal
/// reflection.
#[inline]
pub fn refract(w: Vec3, n: Vec3, eta: f32) -> Option<(Vec3, f32)> {
    let mut cos_i = n.dot(w);
    let (mut eta, mut n) = (eta, n);
    if cos_i < 0.0 {
        eta = 1.0 / eta;
        cos_i = -cos_i;
        n = -n;
    }
    let sin2_i = (1.0 - cos_i * cos_i).max(0.0);
    let sin2_t = sin2_i / (eta * eta);
    if sin2_t >= 1.0 {
        return None;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    Some((-w / eta + (cos_i / eta - cos_t) * n, eta))
}

/// Hemispherical average of the dielectric Fresnel reflectance, `2 ∫ F(cos θ) cos θ dcos θ`,
/// by the polynomial fits Mitsuba 3 uses.
pub fn fresnel_diffuse_reflectance(eta: f32) -> f32 {
    let r = if eta >= 1.0 {
        // Light arriving from the less dense side (d'Eon and Irving's fit in 1/η).
        let i = 1.0 / eta as f64;
        0.919317 - 3.4793 * i + 6.75335 * i * i - 7.80989 * i.powi(3) + 4.98554 * i.powi(4) - 1.36881 * i.powi(5)
    } else {
        // From the denser side (Egan and Hilgeman's fit).
        let e = eta as f64;
        -1.4399 * e * e + 0.7099 * e + 0.6681 + 0.0636 / e
    };
    r as f32
}

/// Mitsuba's named indices of refraction.
pub const IOR_TABLE: &[(&str, f32)] = &[
    ("vacuum", 1.0),
    ("helium", 1.000036),
    ("hydrogen", 1.000132),
    ("air", 1.000277),
    ("carbon dioxide", 1.00045),
    ("water", 1.3330),
    ("acetone", 1.36),
    ("ethanol", 1.361),
    ("carbon tetrachloride", 1.461),
    ("glycerol", 1.4729),
    ("benzene", 1.501),
    ("silicone oil", 1.52045),
    ("bromine", 1.661),
    ("water ice", 1.31),
    ("fused quartz", 1.458),
    ("pyrex", 1.470),
    ("acrylic glass", 1.49),
    ("polypropylene", 1.49),
    ("bk7", 1.5046),
    ("sodium chloride", 1.544),
    ("amber", 1.55),
    ("pet", 1.5750),
    ("diamond", 2.419),
];

pub fn lookup_ior(name: &str) -> Option<f32> {
    let n = name.trim().to_ascii_lowercase();
    IOR_TABLE.iter().find(|(k, _)| *k == n).map(|(_, v)| *v)
}

/// Mitsuba 3's named conductors as RGB `(eta, k)` (its spectral data reduced to RGB by
/// Mitsuba 3.9's `scalar_rgb` variant).
pub const CONDUCTORS: &[(&str, [f32; 3], [f32; 3])] = &[
    ("a-C", [2.94405, 2.22714, 1.96816], [0.887465, 0.799299, 0.81529]),
    ("Ag", [0.155276, 0.116728, 0.138388], [4.82835, 3.12222, 2.1469]),
    ("Al", [1.6575, 0.880405, 0.521244], [9.22381, 6.2695, 4.837]),
    ("AlAs", [3.6053, 3.23294, 2.21632], [0.000679437, 0.0, 0.00751271]),
    ("AlSb", [0.0, 4.13937, 4.66925], [0.0, 0.0940091, 1.30057]),
    ("Au", [0.143036, 0.375307, 1.44205], [3.983, 2.38556, 1.60336]),
    ("Be", [4.18501, 3.18503, 2.78406], [3.83547, 3.01012, 2.86899]),
    ("Cr", [4.36967, 2.91651, 1.6549], [5.20655, 4.23131, 3.7547]),
    ("CsI", [2.1449, 1.70232, 1.66243], [0.0, 0.0, 0.0]),
    ("Cu", [0.201005, 0.92375, 1.10222], [3.91326, 2.45305, 2.14209]),
    ("Cu2O", [3.55177, 2.94987, 2.75188], [0.114207, 0.193897, 0.606134]),
    ("CuO", [3.24754, 2.44781, 2.21022], [0.52109, 0.570031, 0.722179]),
    ("d-C", [2.70872, 2.31883, 2.2289], [0.0, 0.0, 0.0]),
    ("Hg", [2.39894, 1.44003, 0.90957], [6.32759, 4.37192, 3.42176]),
    ("HgTe", [4.77904, 3.2312, 2.6599], [1.63161, 1.58081, 1.72929]),
    ("Ir", [3.0863, 2.08219, 1.61791], [5.59215, 4.06709, 3.26731]),
    ("K", [0.0640432, 0.0464098, 0.0381849], [2.1042, 1.34894, 0.913126]),
    ("Li", [0.265791, 0.195618, 0.220949], [3.54015, 2.31112, 1.66861]),
    ("MgO", [2.08958, 1.65072, 1.59488], [4.3327e-12, 0.0, 2.49865e-11]),
    ("Mo", [4.48397, 3.52513, 2.77631], [4.11144, 3.42083, 3.15061]),
    ("Na_palik", [0.0602694, 0.0561409, 0.0619884], [3.17927, 2.11249, 1.57904]),
    ("Nb", [3.42007, 2.79009, 2.39563], [3.44139, 2.73767, 2.57975]),
    ("Ni_palik", [2.3673, 1.66337, 1.46708], [4.49881, 3.05015, 2.34544]),
    ("Rh", [2.58579, 1.86022, 1.55426], [6.78226, 4.70299, 3.97607]),
    ("Se", [4.05831, 2.84294, 2.82085], [0.75405, 0.638444, 0.521808]),
    ("SiC", [3.17234, 2.52597, 2.47937], [7.53766e-07, 0.0, 1.01925e-05]),
    ("SnTe", [4.52425, 1.98164, 1.28159], [0.0, 0.0, 0.0]),
    ("Ta", [2.06272, 2.39294, 2.62793], [2.40836, 1.74149, 1.94703]),
    ("Te", [7.39023, 4.4821, 2.63711], [3.25602, 3.52706, 3.29205]),
    ("ThF4", [1.83071, 1.44223, 1.38765], [0.0, 0.0, 0.0]),
    ("TiC", [3.70053, 2.83742, 2.58229], [3.26564, 2.35159, 2.17279]),
    ("TiN", [1.64845, 1.15052, 1.37982], [3.36833, 1.9435, 1.10207]),
    ("TiO2", [3.45661, 2.80174, 2.90517], [0.000105265, 0.0, 0.000652887]),
    ("VC", [3.65757, 2.75274, 2.53267], [3.0683, 2.19869, 1.96319]),
    ("V_palik", [4.27758, 3.51295, 2.76107], [3.4913, 2.88945, 3.11152]),
    ("VN", [2.8656, 2.11919, 1.94009], [3.03224, 2.05612, 1.61631]),
    ("W", [4.37082, 3.30025, 2.99841], [3.50064, 2.60487, 2.27323]),
];

/// `(eta, k)` of a named conductor; `none` is a perfect mirror.
pub fn lookup_conductor(name: &str) -> Option<(Rgb, Rgb)> {
    if name == "none" {
        return Some((Rgb::ZERO, Rgb::ONE));
    }
    let base = name.trim_end_matches("_palik");
    CONDUCTORS
        .iter()
        .find(|(k, _, _)| *k == name || *k == base || k.trim_end_matches("_palik") == base)
        .map(|(_, e, k)| (Rgb::from(*e), Rgb::from(*k)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dielectric_fresnel_known_values() {
        // Normal incidence: ((n-1)/(n+1))².
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert!((fresnel_dielectric(-1.0, 1.5) - 0.04).abs() < 1e-6);
        // Total internal reflection beyond the critical angle from inside.
        assert_eq!(fresnel_dielectric(-0.5, 1.5), 1.0);
        assert_eq!(fresnel_dielectric(0.3, 1.0), 0.0);
    }

    #[test]
    fn conductor_fresnel_limits() {
        assert!((fresnel_conductor(0.7, Rgb::ZERO, Rgb::ONE) - Rgb::ONE).abs().max_element() < 1e-6);
        // A conductor with k = 0 is a dielectric.
        let f = fresnel_conductor(0.6, Rgb::splat(1.5), Rgb::ZERO);
        assert!((f.x - fresnel_dielectric(0.6, 1.5)).abs() < 1e-5);
        assert!((fresnel_conductor(0.0, Rgb::splat(0.2), Rgb::splat(3.9)).x - 1.0).abs() < 1e-5);
    }

    #[test]
    fn refraction_obeys_snell() {
        let w = Vec3::new(0.6, 0.0, 0.8);
        let (t, etap) = refract(w, Vec3::Z, 1.5).unwrap();
        assert!((etap - 1.5).abs() < 1e-6 && t.z < 0.0);
        assert!((t.length() - 1.0).abs() < 1e-5);
        assert!((0.6 - 1.5 * (1.0 - t.z * t.z).sqrt()).abs() < 1e-5);
        // Back out again.
        let (back, _) = refract(t, Vec3::Z, 1.5).unwrap();
        assert!((back - w).length() < 1e-5);
        assert!(refract(Vec3::new(0.8, 0.0, -0.6), Vec3::Z, 1.5).is_none());
    }

    #[test]
    fn diffuse_reflectance_matches_mitsuba() {
        // Values printed by Mitsuba 3.9 `fresnel_diffuse_reflectance`.
        assert!((fresnel_diffuse_reflectance(1.49) - 0.090_299_96).abs() < 1e-5);
        assert!((fresnel_diffuse_reflectance(1.0 / 1.49) - 0.590_732_5).abs() < 1e-5);
        // ... and agree with direct integration of the Fresnel term to within the fit's error.
        let n = 20000;
        let exact: f64 = (0..n)
            .map(|i| {
                let c = (i as f64 + 0.5) / n as f64;
                2.0 * fresnel_dielectric(c as f32, 1.49) as f64 * c / n as f64
            })
            .sum();
        assert!((exact - fresnel_diffuse_reflectance(1.49) as f64).abs() < 2e-3, "{exact}");
    }

    #[test]
    fn named_materials() {
        assert_eq!(lookup_ior("bk7"), Some(1.5046));
        let (eta, k) = lookup_conductor("Au").unwrap();
        assert!(eta.x < 0.2 && k.x > 3.0);
        assert!(lookup_conductor("Cu_palik").is_some());
        assert!(lookup_conductor("unobtainium").is_none());
    }
}
