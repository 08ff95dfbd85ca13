//! Mitsuba 3's `sunsky` emitter in RGB: the Hosek–Wilkie sky (2012) and sun (2013) at
//! infinity, in a local frame with `+z` up and `+x` north (`to_world` places it).
//!
//! The sky and the sun are two lights ([`Sky`], [`Sun`]) so that light selection by power
//! weighs them separately: the sky is importance-sampled by a table of its luminance over the
//! upper hemisphere, the sun as the cone of directions its disk subtends. Both follow Mitsuba
//! 3.9's `include/mitsuba/render/sunsky.h` in its RGB variants: the same data (Hosek and
//! Wilkie's RGB fits, `sunsky_data.bin`, made by `scripts/sunsky_tables.py`; 3-clause BSD,
//! `SUNSKY_LICENSE`), interpolated the same way (linearly in turbidity and albedo, a quintic
//! Bézier in the cube root of the sun's elevation), the same constants, and the sun's position
//! from a date and place computed in single precision as Mitsuba 3 computes it.

use crate::light::sun06;
use crate::math::{Frame, Rgb, luminance};
use crate::sampling::Distribution2D;
use glam::{Mat3, Vec2, Vec3};
use std::f32::consts::PI;

/// The RGB tables (little-endian `f32`), one after the other:
/// sky parameters `[10 turbidity][2 albedo][6 control points][3 channels][9]`,
/// sky radiance `[10][2][6][3]`, sun irradiance `[10 turbidity][30 elevations][3]` and the
/// limb-darkened sun `[10 turbidity][45 segments][3][4 powers of x][6 powers of cos ψ]`.
const DATA: &[u8] = include_bytes!("sunsky_data.bin");
const SKY_PARAMS: usize = 0;
const SKY_RAD: usize = SKY_PARAMS + 10 * 2 * 6 * 3 * 9;
const SUN_IRRAD: usize = SKY_RAD + 10 * 2 * 6 * 3;
const SUN_RAD: usize = SUN_IRRAD + 10 * 30 * 3;
const DATA_LEN: usize = SUN_RAD + 10 * 45 * 3 * 4 * 6;
const _: () = assert!(DATA.len() == 4 * DATA_LEN);

/// The sun's mean apparent diameter in degrees (`sun_aperture`'s default).
pub const SUN_APERTURE_DEG: f32 = 0.5358;
/// The half aperture Mitsuba 3 divides the sun's irradiance by (in double precision, then
/// rounded): Mitsuba 0.6's angular radius of the sun, which Mitsuba 3 kept.
const SUN_HALF_APERTURE: f32 = sun06::ANGULAR_RADIUS;
/// Mitsuba 3's `MI_CIE_Y_NORMALIZATION`.
const CIE_Y_NORMALIZATION: f32 = (1.0 / 106.750_259_399_414_06_f64) as f32;
/// Mitsuba 3's `SPEC_TO_RGB_SUN_CONV`.
const SPEC_TO_RGB_SUN_CONV: f32 = 467.069_28;
const SUN_SEGMENTS: usize = 45;
/// Resolution of the sky's sampling table over (azimuth, zenith angle) of the upper
/// hemisphere: cells of 0.9375°, which nest in the 7.5° cells of the χ² tests (their
/// quadrature of the piecewise-constant density is then exact).
const SKY_TABLE: (usize, usize) = (384, 96);

#[inline]
fn data(i: usize) -> f32 {
    f32::from_le_bytes([DATA[4 * i], DATA[4 * i + 1], DATA[4 * i + 2], DATA[4 * i + 3]])
}

/// An index into an axis of `n` entries and the weight of the next one, as Mitsuba's
/// `take_interp` interpolates (clamped to the last interval).
#[inline]
fn interval(x: f32, n: usize) -> (usize, f32) {
    let i = (x.max(0.0).floor() as usize).min(n - 2);
    (i, x - i as f32)
}

/// The angle between two unit vectors, accurate near 0 and π (Dr.Jit's `unit_angle`).
#[inline]
fn unit_angle(a: Vec3, b: Vec3) -> f32 {
    if a.dot(b) < 0.0 {
        PI - 2.0 * (0.5 * (a + b).length()).min(1.0).asin()
    } else {
        2.0 * (0.5 * (b - a).length()).min(1.0).asin()
    }
}

/// Mitsuba's spherical coordinates `(θ, φ)` → `(sin θ cos φ, sin θ sin φ, cos θ)`.
#[inline]
pub fn sph_to_dir(theta: f32, phi: f32) -> Vec3 {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    Vec3::new(cp * st, sp * st, ct)
}

/// A date and local time (Mitsuba 3's defaults: 10 July 2010, 15:00).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DateTime {
    pub year: i32,
    pub month: i32,
    pub day: i32,
    pub hour: f32,
    pub minute: f32,
    pub second: f32,
}

/// Where on Earth, in degrees, and the time zone in hours (Mitsuba 3's default: Tokyo).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Place {
    pub latitude: f32,
    pub longitude: f32,
    pub timezone: f32,
}

impl Default for DateTime {
    fn default() -> DateTime {
        DateTime { year: 2010, month: 7, day: 10, hour: 15.0, minute: 0.0, second: 0.0 }
    }
}

impl Default for Place {
    fn default() -> Place {
        Place { latitude: 35.6894, longitude: 139.6917, timezone: 9.0 }
    }
}

/// The sun's zenith angle and azimuth (`φ`, Mitsuba 3's convention) in the local frame, from
/// "Computing the Solar Vector" (Blanco-Muriel et al., Solar Energy 2001) in single precision
/// as Mitsuba 3 evaluates it: the Julian date is a float spaced a quarter of a day apart, so
/// the sun's place along the ecliptic moves in quarter-day steps (the hour angle takes the
/// time of day exactly).
pub fn sun_coordinates(t: &DateTime, place: &Place) -> (f32, f32) {
    let dec_hours = t.hour - place.timezone + (t.minute + t.second / 60.0) / 60.0;
    let aux1 = (t.month - 14) / 12;
    let aux2 = (1461 * (t.year + 4800 + aux1)) / 4 + (367 * (t.month - 2 - 12 * aux1)) / 12
        - (3 * ((t.year + 4900 + aux1) / 100)) / 4
        + t.day
        - 32075;
    let julian = aux2 as f32 - 0.5 + dec_hours / 24.0;
    let elapsed = julian - 2_451_545.0;

    let omega = 2.1429f32 - 0.001_039_459_4 * elapsed;
    let mean_longitude = 4.895_063f32 + 0.017_202_792 * elapsed;
    let anomaly = 6.240_060_3f32 + 0.017_201_97 * elapsed;
    let ecliptic_longitude = mean_longitude + 0.033_416_07 * anomaly.sin() + 0.000_348_94 * (2.0 * anomaly).sin()
        - 0.000_113_4
        - 0.000_020_3 * omega.sin();
    let ecliptic_obliquity = 0.409_092_8f32 - 6.2140e-9 * elapsed + 0.000_039_6 * omega.cos();

    let sin_el = ecliptic_longitude.sin();
    let mut right_ascension = (ecliptic_obliquity.cos() * sin_el).atan2(ecliptic_longitude.cos());
    if right_ascension < 0.0 {
        right_ascension += 2.0 * PI;
    }
    let declination = (ecliptic_obliquity.sin() * sin_el).asin();

    let gmst = 6.697_424_3f32 + 0.065_709_83 * elapsed + dec_hours;
    let lmst = (gmst * 15.0 + place.longitude).to_radians();
    let lat = place.latitude.to_radians();
    let (sin_lat, cos_lat) = lat.sin_cos();
    let hour_angle = lmst - right_ascension;
    let cos_ha = hour_angle.cos();
    let mut zenith = (cos_lat * cos_ha * declination.cos() + declination.sin() * sin_lat).acos();
    let mut azimuth = (-hour_angle.sin()).atan2(declination.tan() * cos_lat - sin_lat * cos_ha);
    if azimuth < 0.0 {
        azimuth += 2.0 * PI;
    }
    // Parallax: the Earth's mean radius over the astronomical unit (km).
    zenith += (6371.01f64 / 149_597_890.0) as f32 * zenith.sin();
    (zenith, azimuth - PI)
}

/// What a `sunsky` (or `sun`, `sky`) emitter was given, with the sun's direction resolved.
#[derive(Clone, Debug)]
pub struct SunSkyParams {
    /// Local → world rotation (the emitter's `to_world`).
    pub to_world: Mat3,
    /// Unit direction towards the sun in the local frame (`+z` up).
    pub sun_local: Vec3,
    /// Atmospheric turbidity in [1, 10].
    pub turbidity: f32,
    /// Ground albedo per channel, in [0, 1].
    pub albedo: Rgb,
    pub sun_scale: f32,
    pub sky_scale: f32,
    /// The sun's apparent diameter in degrees.
    pub sun_aperture: f32,
    /// Mitsuba 3's `complex_sun`: limb darkening and a radiance that varies with elevation.
    pub complex_sun: bool,
    /// Mitsuba 0.6's sun ([`crate::light::sun06`]) instead of Hosek and Wilkie's.
    pub sun06: bool,
}

impl SunSkyParams {
    /// The sun's elevation above the horizon (radians), from its zenith angle as Mitsuba
    /// computes it.
    fn sun_eta(&self) -> f32 {
        0.5 * PI - unit_angle_z(self.sun_local)
    }

    /// Whether the sun is above the horizon (at or above it, Mitsuba 3 shows sun and sky).
    pub fn sun_visible(&self) -> bool {
        self.sun_local.z >= 0.0
    }

    /// Mitsuba 3's half aperture of the sun: the diameter halved, then converted.
    fn half_aperture(&self) -> f32 {
        (0.5 * self.sun_aperture).to_radians()
    }
}

/// The zenith angle of a unit vector, accurate near the poles (Dr.Jit's `unit_angle_z`).
#[inline]
fn unit_angle_z(v: Vec3) -> f32 {
    let t = 2.0 * (0.5 * Vec3::new(v.x, v.y, v.z - v.z.signum()).length()).min(1.0).asin();
    if v.z >= 0.0 { t } else { PI - t }
}

/// Tables interpolated in turbidity (index `turbidity - 1`).
fn turbidity_interval(turbidity: f32) -> (usize, f32) {
    interval((turbidity - 1.0).clamp(0.0, 9.0), 10)
}

/// The Hosek–Wilkie sky: radiance from the nine parameters and the mean radiance of each
/// channel, zero below the horizon.
#[derive(Debug)]
pub struct Sky {
    to_world: Mat3,
    to_local: Mat3,
    sun: Vec3,
    params: [[f32; 9]; 3],
    /// Mean radiance per channel, times `sky_scale` and Mitsuba's CIE Y normalisation.
    radiance: [f32; 3],
    distribution: Distribution2D,
    /// `∫ luminance(L) dω` over the sky.
    integral: f32,
}

impl Sky {
    pub fn new(p: &SunSkyParams) -> Sky {
        let (t, tw) = turbidity_interval(p.turbidity);
        let eta = p.sun_eta();
        // Bernstein weights of the six control points at x = cbrt(2 η / π).
        let x = (2.0 / PI * eta).cbrt().min(1.0 - f32::EPSILON / 2.0);
        let binom = [1.0, 5.0, 10.0, 10.0, 5.0, 1.0];
        let bez: Vec<f32> = (0..6).map(|k| binom[k] * x.powi(k as i32) * (1.0 - x).powi(5 - k as i32)).collect();
        // A channel's value of a table `[10][2][6][3][n]` at entry `j`.
        let value = |base: usize, n: usize, c: usize, j: usize| -> f32 {
            let a = p.albedo[c];
            let mut sum = 0.0;
            for (ctrl, b) in bez.iter().enumerate() {
                let at = |ti: usize, ai: usize| data(base + (((ti * 2 + ai) * 6 + ctrl) * 3 + c) * n + j);
                let tu = |ai: usize| at(t, ai) * (1.0 - tw) + at(t + 1, ai) * tw;
                sum += b * (tu(0) * (1.0 - a) + tu(1) * a);
            }
            sum
        };
        let mut params = [[0.0; 9]; 3];
        let mut radiance = [0.0; 3];
        for c in 0..3 {
            for (j, v) in params[c].iter_mut().enumerate() {
                *v = value(SKY_PARAMS, 9, c, j);
            }
            radiance[c] = value(SKY_RAD, 1, c, 0) * p.sky_scale * CIE_Y_NORMALIZATION;
        }
        let mut sky = Sky {
            to_world: p.to_world,
            to_local: p.to_world.inverse(),
            sun: p.sun_local,
            params,
            radiance,
            distribution: Distribution2D::new(&[1.0], 1, 1),
            integral: 0.0,
        };
        if !p.sun_visible() {
            sky.radiance = [0.0; 3];
        }
        // The sampling table: luminance × sin θ at cell centres, floored at a small fraction
        // of the mean so that every direction of the upper hemisphere can be drawn.
        let (w, h) = SKY_TABLE;
        let mut weights = Vec::with_capacity(w * h);
        let mut integral = 0.0f64;
        for y in 0..h {
            let (t0, t1) = (0.5 * PI * y as f32 / h as f32, 0.5 * PI * (y + 1) as f32 / h as f32);
            let theta = 0.5 * (t0 + t1);
            let cell = (2.0 * PI / w as f32) * (t0.cos() - t1.cos());
            for x in 0..w {
                let l = luminance(sky.eval_local(sph_to_dir(theta, 2.0 * PI * (x as f32 + 0.5) / w as f32))).max(0.0);
                integral += (l * cell) as f64;
                weights.push(l * theta.sin());
            }
        }
        let mean = weights.iter().map(|&v| v as f64).sum::<f64>() / weights.len() as f64;
        let floor = (1e-3 * mean).max(f32::MIN_POSITIVE as f64) as f32;
        for v in &mut weights {
            *v = v.max(floor);
        }
        sky.distribution = Distribution2D::new(&weights, w, h);
        sky.integral = integral as f32;
        sky
    }

    /// Radiance from local direction `v` (unit): Hosek and Wilkie's formula per channel.
    fn eval_local(&self, v: Vec3) -> Rgb {
        let cos_theta = v.z;
        if cos_theta < 0.0 || self.radiance == [0.0; 3] {
            return Rgb::ZERO;
        }
        let gamma = unit_angle(self.sun, v);
        let cos_gamma = gamma.cos();
        let cg2 = cos_gamma * cos_gamma;
        let mut out = [0.0f32; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let p = &self.params[c];
            let c1 = 1.0 + p[0] * (p[1] / (cos_theta + 0.01)).exp();
            let chi = (1.0 + cg2) / (1.0 + p[8] * p[8] - 2.0 * p[8] * cos_gamma).powf(1.5);
            let c2 = p[2] + p[3] * (p[4] * gamma).exp() + p[5] * cg2 + p[6] * chi + p[7] * cos_theta.max(0.0).sqrt();
            *o = c1 * c2 * self.radiance[c];
        }
        Rgb::from_array(out)
    }

    /// Radiance arriving from world direction `d` (unit).
    pub fn eval(&self, d: Vec3) -> Rgb {
        self.eval_local((self.to_local * d).normalize())
    }

    /// The table's coordinates of a local direction of the upper hemisphere.
    fn uv(v: Vec3) -> Vec2 {
        let mut u = v.y.atan2(v.x) / (2.0 * PI);
        u -= u.floor();
        Vec2::new(u, unit_angle_z(v) / (0.5 * PI))
    }

    /// Solid-angle density of [`Sky::sample`] drawing world direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        let v = (self.to_local * d).normalize();
        if v.z < 0.0 {
            return 0.0;
        }
        let uv = Self::uv(v);
        let sin_t = (uv.y * 0.5 * PI).sin();
        if sin_t <= 0.0 || uv.y >= 1.0 { 0.0 } else { self.distribution.pdf(uv) / (PI * PI * sin_t) }
    }

    /// A world direction drawn from the table, and its solid-angle density.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, f32)> {
        let (uv, pdf_uv) = self.distribution.sample(u);
        let theta = uv.y * 0.5 * PI;
        let sin_t = theta.sin();
        if sin_t <= 0.0 || pdf_uv <= 0.0 {
            return None;
        }
        let d = (self.to_world * sph_to_dir(theta, 2.0 * PI * uv.x)).normalize();
        Some((d, pdf_uv / (PI * PI * sin_t)))
    }

    /// `∫ luminance(L) dω` over the sky (for light selection by power).
    pub fn luminance_integral(&self) -> f32 {
        self.integral
    }
}

/// The sun: a disk of directions of half-angle `acos(cos_max)` about `dir`, uniform radiance
/// (Mitsuba 3's default, or Mitsuba 0.6's sun for files of version 0.x) or Hosek and
/// Wilkie's limb-darkened disk (`complex_sun`); zero below the horizon.
#[derive(Debug)]
pub struct Sun {
    to_local: Mat3,
    /// Towards the sun, world and local.
    dir: Vec3,
    local: Vec3,
    frame: Frame,
    /// `1 - cos` of the disk's angular radius (the cosine rounded as Mitsuba 3 rounds it;
    /// the difference is exact), which decides what the disk covers.
    one_minus_cos: f32,
    half_aperture: f32,
    radiance: Rgb,
    /// `[45 segments][3][4][6]` coefficients of the limb-darkened sun at this turbidity,
    /// with the factor that scales them to radiance.
    complex: Option<(Vec<f32>, f32)>,
    /// The sun's irradiance on a surface facing it, `∫ L dω` over the disk.
    irradiance: Rgb,
}

/// Hosek and Wilkie's sun for `p`, scaled by `factor` (the scale times the ratio of the
/// standard disk's solid angle to this one's): its mean radiance, and with `complex_sun` its
/// limb-darkening coefficients at this turbidity with the factor that scales them.
fn hosek_wilkie_sun(p: &SunSkyParams, factor: f32) -> (Rgb, Option<(Vec<f32>, f32)>) {
    let (t, tw) = turbidity_interval(p.turbidity);
    // Irradiance tables every 3° of elevation from 2°.
    let e = ((p.sun_eta().to_degrees() - 2.0) / 3.0).clamp(0.0, 30.0 - (1.0 - f32::EPSILON / 2.0));
    let (ei, ew) = interval(e, 30);
    let irr = |c: usize| {
        let at = |ti: usize, ej: usize| data(SUN_IRRAD + (ti * 30 + ej) * 3 + c);
        let tu = |ej: usize| at(t, ej) * (1.0 - tw) + at(t + 1, ej) * tw;
        tu(ei) * (1.0 - ew) + tu(ei + 1) * ew
    };
    let factor = factor * SPEC_TO_RGB_SUN_CONV * CIE_Y_NORMALIZATION;
    let mean = factor / (2.0 * PI * (1.0 - SUN_HALF_APERTURE.cos()));
    let radiance = Rgb::new(irr(0), irr(1), irr(2)) * mean;
    let complex = p.complex_sun.then(|| {
        let n = SUN_SEGMENTS * 72;
        let coefs =
            (0..n).map(|i| data(SUN_RAD + t * n + i) * (1.0 - tw) + data(SUN_RAD + (t + 1) * n + i) * tw).collect();
        (coefs, factor)
    });
    (radiance, complex)
}

impl Sun {
    pub fn new(p: &SunSkyParams) -> Sun {
        let half = p.half_aperture();
        let cos_max = half.cos();
        let area_ratio = (1.0 - SUN_HALF_APERTURE.cos()) / (1.0 - cos_max);
        let scale = if p.sun_visible() { p.sun_scale } else { 0.0 };
        // Both models keep the disk's power whatever its size.
        let (radiance, complex) = if p.sun06 {
            (sun06::radiance(unit_angle_z(p.sun_local), p.turbidity) * (scale * area_ratio), None)
        } else {
            hosek_wilkie_sun(p, scale * area_ratio)
        };
        let dir = (p.to_world * p.sun_local).normalize();
        let mut sun = Sun {
            to_local: p.to_world.inverse(),
            dir,
            local: p.sun_local,
            frame: Frame::from_normal(dir),
            one_minus_cos: 1.0 - cos_max,
            half_aperture: half,
            radiance,
            complex,
            irradiance: Rgb::ZERO,
        };
        // ∫ L dω over the disk by stratified cone samples (exact for the uniform disk).
        let k = 32;
        let mut sum = Rgb::ZERO;
        for i in 0..k {
            for j in 0..k {
                let u = Vec2::new((i as f32 + 0.5) / k as f32, (j as f32 + 0.5) / k as f32);
                sum += sun.eval(sun.sample(u).0);
            }
        }
        sun.irradiance = sum / (k * k) as f32 / sun.cone_pdf();
        sun
    }

    /// Whether world direction `d` (unit) lies on the disk: `1 - cos γ = |d - dir|² / 2`,
    /// which keeps its precision at a quarter of a degree where `cos γ` does not.
    #[inline]
    fn covers(&self, d: Vec3) -> bool {
        0.5 * (d - self.dir).length_squared() <= self.one_minus_cos
    }

    #[inline]
    fn cone_pdf(&self) -> f32 {
        1.0 / (2.0 * PI * self.one_minus_cos)
    }

    /// Radiance arriving from world direction `d` (unit).
    pub fn eval(&self, d: Vec3) -> Rgb {
        let v = (self.to_local * d).normalize();
        if v.z < 0.0 || !self.covers(d) {
            return Rgb::ZERO;
        }
        let Some((coefs, factor)) = &self.complex else { return self.radiance };
        let gamma = unit_angle(self.local, v);
        let elevation = 0.5 * PI - v.z.clamp(-1.0, 1.0).acos();
        let pos = (((2.0 * elevation / PI).cbrt() * SUN_SEGMENTS as f32) as usize).min(SUN_SEGMENTS - 1);
        let x = elevation - 0.5 * PI * (pos as f32 / SUN_SEGMENTS as f32).powi(3);
        let sin_half = self.half_aperture.sin();
        let sin_gamma = gamma.sin();
        let cos_psi = (1.0 - sin_gamma * sin_gamma / (sin_half * sin_half)).max(0.0).sqrt();
        let mut out = [0.0f32; 3];
        for (c, o) in out.iter_mut().enumerate() {
            let mut xk = 1.0;
            for k in 0..4 {
                let mut cj = 1.0;
                for j in 0..6 {
                    *o += xk * cj * coefs[((pos * 3 + c) * 4 + k) * 6 + j];
                    cj *= cos_psi;
                }
                xk *= x;
            }
        }
        Rgb::from_array(out) * *factor
    }

    /// Solid-angle density of [`Sun::sample`] drawing world direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        if self.covers(d) { self.cone_pdf() } else { 0.0 }
    }

    /// A world direction uniform in the sun's cone, and its solid-angle density. The polar
    /// angle comes from `1 - cos θ` uniform in `[0, 1 - cos_max]` (in single precision
    /// `cos θ` itself takes only some 180 values across the real sun).
    pub fn sample(&self, u: Vec2) -> (Vec3, f32) {
        let om = u.y * self.one_minus_cos;
        let sin_t = (om * (2.0 - om)).max(0.0).sqrt();
        let (sp, cp) = (2.0 * PI * u.x).sin_cos();
        let d = self.frame.to_world(Vec3::new(sin_t * cp, sin_t * sp, 1.0 - om));
        (d.normalize(), self.cone_pdf())
    }

    /// The irradiance the sun gives a surface facing it (for light selection by power).
    pub fn irradiance(&self) -> Rgb {
        self.irradiance
    }

    /// Unit direction towards the sun's centre (world).
    pub fn direction(&self) -> Vec3 {
        self.dir
    }
}

#[cfg(test)]
mod tests;
