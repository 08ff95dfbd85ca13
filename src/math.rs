//! Small geometric helpers shared by every module: colours, orthonormal frames, affine
//! transforms with their normal matrices, and the ray-offset rule used to leave a surface.

use glam::{Mat3, Mat4, Vec3};

/// Linear RGB radiance, reflectance or throughput.
pub type Rgb = Vec3;

/// Rec. 709 luminance of a linear RGB value (Mitsuba 3's `luminance`).
#[inline]
pub fn luminance(c: Rgb) -> f32 {
    0.212671 * c.x + 0.715160 * c.y + 0.072169 * c.z
}

/// `x.floor() as i32`, without a call to the library's `floor` (which targets without
/// SSE 4.1 make): the same value for every `x`, NaN and infinities included.
#[inline]
pub fn floor_i32(x: f32) -> i32 {
    let i = x as i32;
    i.saturating_sub((x < i as f32) as i32)
}

/// `(sin x, cos x)` for `|x| <= π/4`, by their Taylor series (through `x⁹` and `x¹⁰`, whose
/// remainders are below 3e-9 there): within two ulps of the exact values, without a
/// library call.
#[inline]
pub fn sin_cos_quarter(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let sin = x * (1.0 + x2 * (-1.0 / 6.0 + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362_880.0)))));
    let cos =
        1.0 + x2 * (-0.5 + x2 * (1.0 / 24.0 + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0 + x2 * (-1.0 / 3_628_800.0)))));
    (sin, cos)
}

/// Largest component of a colour.
#[inline]
pub fn max_component(c: Rgb) -> f32 {
    c.x.max(c.y).max(c.z)
}

/// Orthonormal frame with `n` as its z axis (Duff et al. 2017, "Building an orthonormal basis, revisited").
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl Frame {
    /// The world axes.
    pub const IDENTITY: Frame = Frame { s: Vec3::X, t: Vec3::Y, n: Vec3::Z };

    pub fn from_normal(n: Vec3) -> Frame {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { s, t, n }
    }

    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// An affine transform with its inverse transpose kept for normals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Transform {
    pub matrix: Mat4,
    normal: Mat3,
}

impl Default for Transform {
    fn default() -> Self {
        Transform::new(Mat4::IDENTITY)
    }
}

impl Transform {
    pub fn new(matrix: Mat4) -> Transform {
        let normal = Mat3::from_mat4(matrix).inverse().transpose();
        Transform { matrix, normal }
    }

    #[inline]
    pub fn point(&self, p: Vec3) -> Vec3 {
        self.matrix.transform_point3(p)
    }

    #[inline]
    pub fn vector(&self, v: Vec3) -> Vec3 {
        self.matrix.transform_vector3(v)
    }

    /// Transforms a normal (by the inverse transpose); the result is not normalised.
    #[inline]
    pub fn normal(&self, n: Vec3) -> Vec3 {
        self.normal * n
    }

    /// `true` when the transform flips orientation (negative determinant).
    pub fn flips_handedness(&self) -> bool {
        Mat3::from_mat4(self.matrix).determinant() < 0.0
    }
}

/// Mitsuba's ray epsilon: a relative offset that moves a spawned ray off the surface it
/// leaves, scaled by the magnitude of the position (floating-point error grows with it).
pub const RAY_EPSILON: f32 = 1500.0 * f32::EPSILON / 2.0;
/// Shadow rays stop this fraction short of their target.
pub const SHADOW_EPSILON: f32 = RAY_EPSILON * 10.0;

/// Offsets `p` along the geometric normal `ng`, towards the side `dir` points to.
#[inline]
pub fn offset_origin(p: Vec3, ng: Vec3, dir: Vec3) -> Vec3 {
    let mag = (1.0 + p.abs().max_element()) * RAY_EPSILON;
    let off = ng * mag;
    if ng.dot(dir) >= 0.0 { p + off } else { p - off }
}

/// Reflects `w` about `n` (both pointing away from the surface).
#[inline]
pub fn reflect(w: Vec3, n: Vec3) -> Vec3 {
    2.0 * w.dot(n) * n - w
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floor_i32_is_floor_then_cast() {
        let special = [0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 2.999_999_8, -2.999_999_8, 1e9, -1e9, 3e9, -3e9];
        let more = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MIN_POSITIVE, -f32::MIN_POSITIVE, f32::MAX];
        let mut state = 0x2545_f491_u32;
        let random = (0..10_000).map(|_| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state as f32 / u32::MAX as f32 - 0.5) * 4096.0
        });
        for x in special.into_iter().chain(more).chain(random) {
            assert_eq!(floor_i32(x), x.floor() as i32, "x = {x}");
        }
        // A value that differs from the cast alone must differ here too: the test can fail.
        assert_ne!((-0.5f32) as i32, floor_i32(-0.5));
    }

    #[test]
    fn sin_cos_quarter_is_within_two_ulps() {
        let quarter = std::f64::consts::FRAC_PI_4;
        let mut worst = 0.0f64;
        for i in -20_000..=20_000 {
            let x = (i as f64 / 20_000.0 * quarter) as f32;
            let (s, c) = sin_cos_quarter(x);
            let (es, ec) = ((x as f64).sin(), (x as f64).cos());
            // Error in units of the exact value's ulp in f32.
            for (got, exact) in [(s, es), (c, ec)] {
                let ulp = if exact == 0.0 {
                    f32::MIN_POSITIVE as f64
                } else {
                    ((exact.abs() as f32).next_up() - exact.abs() as f32) as f64
                };
                worst = worst.max((got as f64 - exact).abs() / ulp);
            }
        }
        assert!(worst <= 2.0, "worst error {worst} ulps");
        // Outside its range (or with a term dropped) the series is off by far more.
        let (_, c) = sin_cos_quarter(3.0);
        assert!((c as f64 - 3f64.cos()).abs() > 1e-3);
    }

    #[test]
    fn frame_is_orthonormal() {
        for n in
            [Vec3::Z, -Vec3::Z, Vec3::X, Vec3::new(0.3, -0.5, 0.8).normalize(), Vec3::new(-1e-7, 0.0, -1.0).normalize()]
        {
            let f = Frame::from_normal(n);
            assert!((f.s.length() - 1.0).abs() < 1e-5);
            assert!((f.t.length() - 1.0).abs() < 1e-5);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(n).abs() < 1e-5 && f.t.dot(n).abs() < 1e-5);
            let v = Vec3::new(0.2, 0.7, -0.4);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }

    #[test]
    fn normals_stay_perpendicular_under_nonuniform_scale() {
        let t = Transform::new(Mat4::from_scale(Vec3::new(1.0, 4.0, 0.5)));
        let tangent = Vec3::new(1.0, 1.0, 0.0);
        let n = Vec3::new(1.0, -1.0, 0.0);
        assert!(t.vector(tangent).dot(t.normal(n)).abs() < 1e-5);
    }
}
