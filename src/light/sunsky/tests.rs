//! The sky and the sun against Mitsuba 3's radiance, their sampling against their densities.

use super::*;
use crate::light::Light;
use crate::sampling::chi2::{Chi2Test, SphereDomain};
use std::sync::Arc;

/// A case's name, a world direction, and the radiance from it (`None`: the sun's direction).
type Query = (&'static str, [f32; 3], Option<[f32; 3]>);

/// Mitsuba 3.9.1's `sunsky` (scalar_rgb) queried by `scripts/sunsky_values.py`: per case the
/// sun's world direction (`None` radiance), then world directions towards the sky and the RGB
/// radiance `eval` returns for them (sky and sun together).
/// Nine significant digits, as printed: each value is the `f32` Mitsuba 3 returned.
#[rustfmt::skip]
#[allow(clippy::excessive_precision)]
const MITSUBA: &[Query] = &[
    ("direction", [0.424264073, 0.565685451, 0.707106769], None),
    ("direction", [0.0, 0.0, 1.0], Some([0.023749318, 0.0415159948, 0.0840941966])),
    ("direction", [0.857142866, -0.428571433, 0.285714269], Some([0.0648994669, 0.108866714, 0.18175219])),
    ("direction", [-0.580258846, 0.812362373, 0.0580258854], Some([0.135046735, 0.18738991, 0.236492217])),
    ("direction", [0.0, 0.89442718, 0.44721359], Some([0.08100079, 0.120438181, 0.187250391])),
    ("direction", [0.20628427, 0.928279161, -0.309426397], Some([0.0, 0.0, 0.0])),
    ("direction", [0.424264073, 0.565685451, 0.707106769], Some([21369.3418, 17551.7266, 12928.2334])),
    ("direction", [0.426141709, 0.565388978, 0.706214249], Some([21369.3418, 17551.7266, 12928.2344])),
    ("direction", [0.421367615, 0.581822157, 0.695652366], Some([0.184878096, 0.209018543, 0.236021578])),
    ("tokyo", [0.0513854474, 0.691747963, 0.720308483], None),
    ("tokyo", [0.0, 0.0, 1.0], Some([0.0243510846, 0.0423087478, 0.0855947733])),
    ("tokyo", [0.857142866, -0.428571433, 0.285714269], Some([0.0590235405, 0.102249764, 0.175069004])),
    ("tokyo", [-0.580258846, 0.812362373, 0.0580258854], Some([0.17369388, 0.231513247, 0.283515662])),
    ("tokyo", [0.0, 0.89442718, 0.44721359], Some([0.142646447, 0.185460895, 0.246763691])),
    ("tokyo", [0.20628427, 0.928279161, -0.309426397], Some([0.0, 0.0, 0.0])),
    ("tokyo", [0.0513854474, 0.691747963, 0.720308483], Some([21418.7363, 17626.2461, 13041.7861])),
    ("tokyo", [0.0534821078, 0.691703022, 0.720198989], Some([21418.7363, 17626.2461, 13041.7861])),
    ("tokyo", [0.0509619489, 0.706045508, 0.706330419], Some([0.182927847, 0.207707122, 0.235750645])),
    ("dusk", [0.243441045, 0.943439126, 0.225075901], None),
    ("dusk", [0.0, 0.0, 1.0], Some([0.0172051433, 0.0262615494, 0.0422279611])),
    ("dusk", [0.857142866, -0.428571433, 0.285714269], Some([0.0497748926, 0.0708221048, 0.0882705376])),
    ("dusk", [-0.580258846, 0.812362373, 0.0580258854], Some([0.170778155, 0.150033981, 0.115212679])),
    ("dusk", [0.0, 0.89442718, 0.44721359], Some([0.349260896, 0.295256644, 0.201171488])),
    ("dusk", [0.20628427, 0.928279161, -0.309426397], Some([0.0, 0.0, 0.0])),
    ("dusk", [0.24344103, 0.943439066, 0.225075886], Some([9095.23242, 5698.44629, 2605.1333])),
    ("dusk", [0.245438904, 0.943043292, 0.224564165], Some([9095.2334, 5698.44629, 2605.13379])),
    ("dusk", [0.239643082, 0.948719084, 0.206163347], Some([1.42995536, 1.06862235, 0.544244587])),
    ("complex", [-0.481543452, 0.240771726, 0.842701018], None),
    ("complex", [0.0, 0.0, 1.0], Some([0.0, 0.0, 0.0])),
    ("complex", [0.857142866, -0.428571433, 0.285714269], Some([0.0, 0.0, 0.0])),
    ("complex", [-0.580258846, 0.812362373, 0.0580258854], Some([0.00917971414, 0.0170271099, 0.0282931477])),
    ("complex", [0.0, 0.89442718, 0.44721359], Some([0.00800072029, 0.0152097922, 0.0259134527])),
    ("complex", [0.20628427, 0.928279161, -0.309426397], Some([0.00618144404, 0.0126715545, 0.0227520298])),
    ("complex", [-0.481543422, 0.240771711, 0.842700958], Some([1356.70178, 954.315308, 467.498932])),
    ("complex", [-0.479706615, 0.240903318, 0.843710363], Some([1354.93066, 952.969666, 466.802185])),
    ("complex", [-0.480188787, 0.260093063, 0.837717295], Some([1150.54187, 794.876892, 384.167694])),
];

/// The cases of `scripts/sunsky_values.py`, with their sun placed as Mitsuba 3 places it.
fn case(name: &str) -> SunSkyParams {
    let base = SunSkyParams {
        to_world: Mat3::IDENTITY,
        sun_local: Vec3::Z,
        turbidity: 3.0,
        albedo: Rgb::splat(0.3),
        sun_scale: 1.0,
        sky_scale: 1.0,
        sun_aperture: SUN_APERTURE_DEG,
        complex_sun: false,
        sun06: false,
    };
    let from_date = |t: DateTime, p: Place| {
        let (theta, phi) = sun_coordinates(&t, &p);
        sph_to_dir(theta, phi)
    };
    match name {
        "direction" => SunSkyParams { sun_local: Vec3::new(0.3, 0.4, 0.5).normalize(), ..base },
        "tokyo" => SunSkyParams { sun_local: from_date(DateTime::default(), Place::default()), ..base },
        "dusk" => SunSkyParams {
            sun_local: from_date(
                DateTime { year: 2021, month: 3, day: 21, hour: 17.0, minute: 40.0, second: 12.0 },
                Place { latitude: 48.85, longitude: 2.35, timezone: 1.0 },
            ),
            turbidity: 7.5,
            albedo: Rgb::new(0.1, 0.5, 0.9),
            ..base
        },
        "complex" => {
            let to_world = Mat3::from_rotation_x(-0.5 * PI);
            SunSkyParams {
                to_world,
                sun_local: (to_world.inverse() * Vec3::new(-0.2, 0.1, 0.35).normalize()).normalize(),
                complex_sun: true,
                sun06: false,
                turbidity: 2.2,
                albedo: Rgb::splat(0.8),
                sun_aperture: 3.0,
                sun_scale: 2.0,
                sky_scale: 0.5,
            }
        }
        _ => unreachable!(),
    }
}

#[test]
fn radiance_matches_mitsuba3() {
    // Single-precision arithmetic on both sides (the sky's exponentials, the sun's 1 - cos of
    // a quarter degree): agreement to 1e-3 relative, 1e-4 for the sun's position.
    let mut worst = 0.0f32;
    let mut last = "";
    let (mut sky, mut sun) = (None, None);
    for &(name, d, expected) in MITSUBA {
        if name != last {
            let p = case(name);
            sky = Some(Sky::new(&p));
            sun = Some(Sun::new(&p));
            last = name;
        }
        let (sky, sun) = (sky.as_ref().unwrap(), sun.as_ref().unwrap());
        let d = Vec3::from_array(d).normalize();
        match expected {
            None => {
                let err = (sun.direction() - d).abs().max_element();
                assert!(err < 1e-4, "{name}: the sun at {} against Mitsuba 3's {d}", sun.direction());
            }
            Some(e) => {
                let got = sky.eval(d) + sun.eval(d);
                for c in 0..3 {
                    let rel = (got[c] - e[c]).abs() / e[c].abs().max(1e-30);
                    assert!(
                        (e[c] == 0.0 && got[c] == 0.0) || rel < 1e-3,
                        "{name} towards {d}: {got} against Mitsuba 3's {e:?}"
                    );
                    if e[c] != 0.0 {
                        worst = worst.max(rel);
                    }
                }
            }
        }
    }
    eprintln!("largest relative difference from Mitsuba 3: {worst:.2e}");
}

#[test]
fn sky_sampling_chi2() {
    // In the sky's own frame (a `to_world` rotates samples and densities alike, checked
    // below), for a high, a low and a hazy sun.
    for name in ["direction", "dusk", "complex"] {
        let sky = Sky::new(&SunSkyParams { to_world: Mat3::IDENTITY, ..case(name) });
        let r = Chi2Test::new(SphereDomain::default()).run(|u| sky.sample(u).map(|s| s.0), |w| sky.pdf(w));
        eprintln!("sky, {name}: {r}");
        assert_sky_fit(&sky, &r);
    }
    let turned = Sky::new(&case("complex"));
    let local = Sky::new(&SunSkyParams { to_world: Mat3::IDENTITY, ..case("complex") });
    let m = case("complex").to_world;
    let mut rng = crate::sampling::Sampler::new(&[9]);
    for _ in 0..1000 {
        let u = rng.next_2d();
        let ((a, pa), (b, pb)) = (turned.sample(u).unwrap(), local.sample(u).unwrap());
        assert!((a - m * b).length() < 1e-5 && (pa - pb).abs() <= 1e-4 * pb, "{a} {pa} against {b} {pb}");
        assert!((turned.pdf(a) - pa).abs() <= 1e-3 * pa, "{} against {pa}", turned.pdf(a));
    }
    // Negative control: the density of the same sky with its sun 25° further round.
    let p = case("direction");
    let sky = Sky::new(&p);
    let turned = Sky::new(&SunSkyParams { sun_local: Mat3::from_rotation_z(25f32.to_radians()) * p.sun_local, ..p });
    let r = Chi2Test::new(SphereDomain::default()).run(|u| sky.sample(u).map(|s| s.0), |w| turned.pdf(w));
    assert!(!r.passed(), "{r}");
}

/// The χ² statistic of a sky's samples, and its density's normalisation. The harness's
/// Simpson quadrature places its cells' edge points a hair inside them, closer than single
/// precision resolves a direction, so on a table whose edges fall on the cells' edges it
/// overestimates the integral by up to 0.2%; the density is constant on each table cell, so
/// a midpoint rule on 8 × 4 points per cell integrates it to float precision instead.
fn assert_sky_fit(sky: &Sky, r: &crate::sampling::chi2::Chi2Result) {
    assert!(r.p_value >= r.significance && r.success_fraction == 1.0, "{r}");
    let (h, w) = (SKY_TABLE.1 * 8, SKY_TABLE.0 * 4);
    let mut integral = 0.0f64;
    for i in 0..h {
        let t0 = 0.5 * std::f64::consts::PI * i as f64 / h as f64;
        let t1 = 0.5 * std::f64::consts::PI * (i + 1) as f64 / h as f64;
        let solid = (t0.cos() - t1.cos()) * 2.0 * std::f64::consts::PI / w as f64;
        for j in 0..w {
            let phi = 2.0 * PI * (j as f32 + 0.5) / w as f32;
            integral += sky.pdf(sph_to_dir((0.5 * (t0 + t1)) as f32, phi)) as f64 * solid;
        }
    }
    assert!((integral - 1.0).abs() < 1e-4, "the sky's density integrates to {integral}");
}

/// Counts of the real sun's sampled directions in 10 rings of equal solid angle × 8 sectors
/// of its disk, against the counts its density `pdf` predicts (the disk is a quarter of a
/// degree across: too small for the sphere's cells).
fn sun_rings(sun: &Sun, pdf: impl Fn(Vec3) -> f32) -> crate::sampling::chi2::Chi2Result {
    let (rings, sectors, n) = (10usize, 8usize, 200_000usize);
    let f = Frame::from_normal(sun.direction());
    let om = sun.one_minus_cos as f64;
    let mut counts = vec![0u64; rings * sectors];
    let mut rng = crate::sampling::Sampler::new(&[31]);
    for _ in 0..n {
        let d = sun.sample(rng.next_2d()).0;
        let x = 0.5 * (d.as_dvec3() - sun.direction().as_dvec3()).length_squared() / om;
        assert!(x <= 1.0 + 1e-3, "a sample {x} of the disk's 1 - cos outside it");
        let l = f.to_local(d);
        let phi = (l.y as f64).atan2(l.x as f64).rem_euclid(2.0 * std::f64::consts::PI);
        let ring = ((x * rings as f64) as usize).min(rings - 1);
        let sector = ((phi / (2.0 * std::f64::consts::PI) * sectors as f64) as usize).min(sectors - 1);
        counts[ring * sectors + sector] += 1;
    }
    // Each cell's expectation: the density at its middle times its solid angle.
    let mut expected = Vec::with_capacity(rings * sectors);
    for ring in 0..rings {
        for sector in 0..sectors {
            let xm = (ring as f64 + 0.5) / rings as f64 * om;
            let theta = (2.0 * (0.5 * xm).sqrt().asin()) as f32;
            let phi = (2.0 * PI) * (sector as f32 + 0.5) / sectors as f32;
            let d = f.to_world(sph_to_dir(theta, phi));
            let solid = 2.0 * std::f64::consts::PI * om / (rings * sectors) as f64;
            expected.push(pdf(d) as f64 * solid * n as f64);
        }
    }
    crate::sampling::chi2::discrete_chi2(&counts, &expected)
}

#[test]
fn sun_sampling_chi2() {
    let p = case("tokyo");
    let sun = Sun::new(&p);
    let r = sun_rings(&sun, |d| sun.pdf(d));
    eprintln!("sun, real size: {r}");
    r.assert_pass();
    // Negative control: the density of a sun a fifth narrower.
    let small = Sun::new(&SunSkyParams { sun_aperture: 0.43, ..p.clone() });
    let r = sun_rings(&sun, |d| small.pdf(d));
    assert!(!r.passed(), "{r}");
    // A larger sun away from the sphere's pole, through the light's own sampling.
    let big = SunSkyParams { sun_local: Vec3::new(0.3, -0.5, 0.6).normalize(), sun_aperture: 24.0, ..p };
    let light = Light::Sun(Arc::new(Sun::new(&big)));
    let t = Chi2Test::new(SphereDomain::default());
    let r = t.run(|u| light.sample_infinite_direction(u).map(|s| s.0), |w| light.pdf_infinite(w));
    eprintln!("sun, 24°: {r}");
    r.assert_pass();
    // Negative control: a cone two degrees narrower than the one sampled.
    let narrower = Sun::new(&SunSkyParams { sun_aperture: 22.0, ..big });
    let r = t.run(|u| light.sample_infinite_direction(u).map(|s| s.0), |w| narrower.pdf(w));
    assert!(!r.passed(), "{r}");
}

#[test]
fn sky_light_samples_what_it_claims() {
    // Through the `Light` wrapper: next-event estimation's directions follow the density.
    let light = Light::Sky(Arc::new(Sky::new(&case("tokyo"))));
    let bounds = crate::light::Bounds { center: Vec3::ZERO, radius: 3.0 };
    let mut u1 = crate::sampling::Sampler::new(&[5]);
    let t = Chi2Test::new(SphereDomain::default());
    let r =
        t.run(|u| light.sample_li(&[], &bounds, Vec3::ZERO, u1.next_1d(), u).map(|s| s.wi), |w| light.pdf_infinite(w));
    let Light::Sky(sky) = &light else { unreachable!() };
    assert_sky_fit(sky, &r);
}

#[test]
fn sun_irradiance_and_power_share() {
    // The uniform sun's irradiance is its radiance times its solid angle, whatever the aperture
    // (Mitsuba 3 keeps the irradiance when `sun_aperture` changes).
    let p = case("direction");
    let sun = Sun::new(&p);
    let wide = Sun::new(&SunSkyParams { sun_aperture: 2.0, ..p.clone() });
    let rel = (luminance(sun.irradiance()) / luminance(wide.irradiance()) - 1.0).abs();
    assert!(rel < 2e-3, "irradiance {} against {} with a 2° sun", sun.irradiance(), wide.irradiance());
    // A clear day's sun gives most of the light, and the sky a fair share.
    let sky = Sky::new(&p);
    let share = luminance(sun.irradiance()) / (luminance(sun.irradiance()) + sky.luminance_integral());
    assert!((0.5..0.95).contains(&share), "the sun's share of the power is {share}");
}

#[test]
fn sun_position_from_date() {
    // Noon at the equator on the March equinox: the sun is almost overhead; at midnight,
    // below the horizon.
    let place = Place { latitude: 0.0, longitude: 0.0, timezone: 0.0 };
    let noon = DateTime { year: 2024, month: 3, day: 20, hour: 12.0, minute: 0.0, second: 0.0 };
    let (theta, _) = sun_coordinates(&noon, &place);
    assert!(theta.to_degrees() < 3.0, "zenith angle {}", theta.to_degrees());
    let (theta, _) = sun_coordinates(&DateTime { hour: 0.0, ..noon }, &place);
    assert!(theta.to_degrees() > 170.0, "zenith angle {}", theta.to_degrees());
}
