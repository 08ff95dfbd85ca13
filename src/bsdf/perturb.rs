//! Shading-normal perturbation: Mitsuba 3's `bumpmap` (a height texture's gradient) and
//! `normalmap` (a tangent-space normal in an RGB texture).
//!
//! The perturbed frame is computed where a ray hits the surface and becomes the surface
//! interaction's shading frame ([`crate::scene::Scene::intersect`]), so every integrator
//! scatters in it and takes its cosines and shading-normal corrections against it. What
//! Mitsuba's wrappers add to the nested BSDF's value is applied by [`Bsdf`](super::Bsdf)
//! itself from [`At::base_n`], the unperturbed shading normal in the perturbed frame: a
//! direction must lie on the same side of both normals, and the light's side is attenuated
//! by the shadowing term of Estevez et al. (Ray Tracing Gems, 2019) unless
//! `use_shadowing_function` is off.

use crate::math::Frame;
use crate::texture::Texture;
use glam::{Vec2, Vec3};

/// Where a BSDF is evaluated: the surface's texture coordinates and, on a perturbed
/// surface, the unperturbed shading normal in the (perturbed) shading frame (`Vec3::Z`
/// elsewhere).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct At {
    pub uv: Vec2,
    pub base_n: Vec3,
}

impl From<Vec2> for At {
    #[inline]
    fn from(uv: Vec2) -> At {
        At { uv, base_n: Vec3::Z }
    }
}

/// How the shading normal is perturbed.
#[derive(Clone, Debug, PartialEq)]
pub enum PerturbKind {
    /// `bumpmap`: the gradient of a height texture's luminance times `scale`.
    Bump { height: Texture, scale: f32 },
    /// `normalmap`: the normal `2 rgb - 1` in the unperturbed shading frame.
    Normal { normals: Texture },
}

/// A perturbation of the shading frame with Mitsuba's options.
#[derive(Clone, Debug, PartialEq)]
pub struct Perturbation {
    pub kind: PerturbKind,
    /// Mitsuba's `use_shadowing_function` (default on).
    pub shadowing: bool,
}

/// The unperturbed shading frame Mitsuba 3 builds from a surface's `dp/du`: the normal `n`,
/// `s` the part of `dp_du` orthogonal to it (any tangent when that is zero), `t = n × s`.
pub fn tangent_frame(n: Vec3, dp_du: Vec3) -> Frame {
    let s = dp_du - n * n.dot(dp_du);
    let s = if dp_du == Vec3::ZERO { Frame::from_normal(n).s } else { s.normalize() };
    Frame { s, t: n.cross(s), n }
}

impl Perturbation {
    /// The perturbed frame in the coordinates of the unperturbed shading frame `base` (built
    /// by [`tangent_frame`]), at texture coordinates `uv` of a surface with the partial
    /// derivatives `dp_du`, `dp_dv` and the geometric normal `ng` (all in world space).
    pub fn local_frame(&self, base: &Frame, dp_du: Vec3, dp_dv: Vec3, ng: Vec3, uv: Vec2) -> Frame {
        match &self.kind {
            PerturbKind::Bump { height, scale } => {
                let grad = *scale * height.luminance_gradient(uv).unwrap_or(Vec2::ZERO);
                let ns = base.n;
                let du = dp_du + ns * (grad.x - ns.dot(dp_du));
                let dv = dp_dv + ns * (grad.y - ns.dot(dp_dv));
                let mut n = du.cross(dv).normalize();
                // On the side of the geometric normal.
                if ng.dot(n) < 0.0 {
                    n = -n;
                }
                let n = base.to_local(n);
                // Mitsuba 3 orthogonalises the world-space dp/du against this local normal
                // (which fixes the tangent of an anisotropic nested BSDF): done alike.
                let s = (dp_du - n * n.dot(dp_du)).normalize();
                Frame { s, t: n.cross(s), n }
            }
            PerturbKind::Normal { normals } => {
                let n = (normals.eval(uv) * 2.0 - Vec3::ONE).normalize();
                let s = (Vec3::X - n * n.x).normalize();
                Frame { s, t: n.cross(s), n }
            }
        }
    }

    /// The perturbed frame in world space and the unperturbed normal in it, or `None` where
    /// the perturbation is undefined (a zero normal from the texture, a degenerate
    /// gradient): the surface then keeps its frame.
    pub fn apply(&self, base: &Frame, dp_du: Vec3, dp_dv: Vec3, ng: Vec3, uv: Vec2) -> Option<(Frame, Vec3)> {
        let local = self.local_frame(base, dp_du, dp_dv, ng, uv);
        let world = Frame { s: base.to_world(local.s), t: base.to_world(local.t), n: base.to_world(local.n) };
        let base_n = Vec3::new(local.s.z, local.t.z, local.n.z);
        let finite = local.s.is_finite() && local.t.is_finite() && local.n.is_finite();
        finite.then_some((world, base_n))
    }
}

/// `tan² θ` of a unit vector whose cosine with the normal is `cos`.
#[inline]
fn tan2(cos: f32) -> f32 {
    let c2 = cos * cos;
    (1.0 - c2).max(0.0) / c2
}

/// The shadowing term of Estevez et al. for light arriving along `w_light` (both vectors in
/// the perturbed frame; `base_n` the unperturbed normal): `2 / (1 + √(1 + α² tan² θ))`, with
/// `α² = min(tan² θₚ / 8, 1)` from the perturbation's tilt `θₚ` and `θ` the light's angle
/// to the unperturbed normal.
#[inline]
pub fn shadow_terminator(base_n: Vec3, w_light: Vec3) -> f32 {
    let alpha2 = (0.125 * tan2(base_n.z)).min(1.0);
    if alpha2 == 0.0 {
        return 1.0;
    }
    2.0 / (1.0 + (1.0 + alpha2 * tan2(base_n.dot(w_light))).sqrt())
}

/// Whether `w` lies on the same side of the unperturbed and the perturbed normal.
#[inline]
pub fn same_side(base_n: Vec3, w: Vec3) -> bool {
    base_n.dot(w) * w.z > 0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::{Bitmap, FilterType, WrapMode};
    use glam::Mat3;
    use std::sync::Arc;

    /// A height ramp `h = a·x_pixel + b·y_pixel` on a `w × h` bitmap.
    fn ramp(w: u32, h: u32, a: f32, b: f32) -> Texture {
        let texels = (0..h).flat_map(|y| (0..w).map(move |x| Vec3::splat(a * x as f32 + b * y as f32))).collect();
        Texture::Bitmap {
            bitmap: Arc::new(Bitmap::new(w, h, texels, FilterType::Bilinear, WrapMode::Clamp)),
            to_uv: Mat3::IDENTITY,
        }
    }

    #[test]
    fn bump_normal_of_a_linear_ramp_is_the_analytic_tilt() {
        // A ramp of slope (a·W, b·H) per unit of uv on a plane z = 0 parameterised by
        // p = (2u, 3v, 0): the surface (2u, 3v, s·h(u, v)) has the normal
        // (-s·hu/2, -s·hv/3, 1), normalised.
        let (w, h, a, b, scale) = (16, 8, 0.01, -0.03, 0.7);
        let tex = ramp(w, h, a, b);
        let (hu, hv) = (a * w as f32, b * h as f32);
        let p = Perturbation { kind: PerturbKind::Bump { height: tex.clone(), scale }, shadowing: true };
        let (dp_du, dp_dv) = (Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 3.0, 0.0));
        let base = tangent_frame(Vec3::Z, dp_du);
        let expected = Vec3::new(-scale * hu / 2.0, -scale * hv / 3.0, 1.0).normalize();
        for uv in [Vec2::new(0.3, 0.4), Vec2::new(0.51, 0.77), Vec2::new(0.05 + 0.5 / 16.0, 0.5)] {
            let g = tex.luminance_gradient(uv).unwrap();
            assert!((g - Vec2::new(hu, hv)).abs().max_element() < 1e-4, "gradient {g} at {uv}");
            let (frame, base_n) = p.apply(&base, dp_du, dp_dv, Vec3::Z, uv).unwrap();
            assert!((frame.n - expected).length() < 1e-5, "{} vs {expected}", frame.n);
            assert!((base_n - frame.to_local(Vec3::Z)).length() < 1e-6);
            assert!(frame.s.dot(frame.n).abs() < 1e-6 && (frame.s.cross(frame.t) - frame.n).length() < 1e-5);
        }
        // The tilt is along the negative gradient; the geometric normal's side is kept
        // when the ramp is steep enough to turn it over, and a flat map changes nothing.
        let flat = Perturbation { kind: PerturbKind::Bump { height: ramp(4, 4, 0.0, 0.0), scale }, shadowing: true };
        let (frame, base_n) = flat.apply(&base, dp_du, dp_dv, Vec3::Z, Vec2::splat(0.5)).unwrap();
        assert!((frame.n - Vec3::Z).length() < 1e-6 && base_n == frame.to_local(Vec3::Z));
        let (down, _) = p.apply(&base, dp_du, dp_dv, -Vec3::Z, Vec2::splat(0.5)).unwrap();
        assert!((down.n + expected).length() < 1e-5);
    }

    #[test]
    fn gradient_is_the_derivative_of_the_bilinear_lookup() {
        // A non-linear bitmap: central differences of `eval` inside a texel cell equal the
        // analytic gradient, with a uv transform that scales and shears.
        let texels = (0..25).map(|i| Vec3::new(((i * 7) % 11) as f32 * 0.1, (i % 3) as f32 * 0.2, 0.3)).collect();
        let bitmap = Arc::new(Bitmap::new(5, 5, texels, FilterType::Bilinear, WrapMode::Repeat));
        let to_uv = Mat3::from_cols(Vec3::new(1.5, 0.2, 0.0), Vec3::new(0.0, 0.8, 0.0), Vec3::new(0.1, 0.0, 1.0));
        let tex = Texture::Bitmap { bitmap, to_uv };
        let lum = |uv: Vec2| crate::math::luminance(tex.eval(uv)) as f64;
        for uv in [Vec2::new(0.33, 0.47), Vec2::new(0.71, 0.13), Vec2::new(-0.2, 1.35)] {
            let g = tex.luminance_gradient(uv).unwrap();
            let e = 1e-3;
            let du = (lum(uv + Vec2::new(e, 0.0)) - lum(uv - Vec2::new(e, 0.0))) / (2.0 * e as f64);
            let dv = (lum(uv + Vec2::new(0.0, e)) - lum(uv - Vec2::new(0.0, e))) / (2.0 * e as f64);
            assert!((g.x as f64 - du).abs() < 2e-2 * du.abs().max(1.0), "∂u {} vs {du} at {uv}", g.x);
            assert!((g.y as f64 - dv).abs() < 2e-2 * dv.abs().max(1.0), "∂v {} vs {dv} at {uv}", g.y);
        }
    }

    #[test]
    fn normal_map_frame_and_shadowing() {
        // rgb (0.5, 0.5, 1) is the unperturbed normal; a tilted texel tilts it in the
        // tangent frame's s–n plane.
        let base = tangent_frame(Vec3::Z, Vec3::X);
        let flat = Perturbation {
            kind: PerturbKind::Normal { normals: Texture::Constant(Vec3::new(0.5, 0.5, 1.0)) },
            shadowing: true,
        };
        let (f, b) = flat.apply(&base, Vec3::X, Vec3::Y, Vec3::Z, Vec2::ZERO).unwrap();
        assert!((f.n - Vec3::Z).length() < 1e-6 && (b - Vec3::Z).length() < 1e-6);
        assert_eq!(shadow_terminator(b, Vec3::new(0.99, 0.0, 0.141)), 1.0);
        let tilted = Perturbation {
            kind: PerturbKind::Normal { normals: Texture::Constant(Vec3::new(0.8, 0.5, 0.9)) },
            shadowing: true,
        };
        let (f, b) = tilted.apply(&base, Vec3::X, Vec3::Y, Vec3::Z, Vec2::ZERO).unwrap();
        let n = Vec3::new(0.6, 0.0, 0.8);
        assert!((f.n - n).length() < 1e-6 && (f.s - Vec3::new(0.8, 0.0, -0.6)).length() < 1e-6);
        assert!((b - Vec3::new(-0.6, 0.0, 0.8)).length() < 1e-6);
        // tan² θₚ = 9/16: α² = 9/128; light at 60° from the unperturbed normal: tan² = 3.
        let w = f.to_local(Vec3::new(0.0, 0.75f32.sqrt(), 0.5));
        let g = shadow_terminator(b, w);
        let expected = 2.0 / (1.0 + (1.0 + 9.0 / 128.0 * 3.0f32).sqrt());
        assert!((g - expected).abs() < 1e-6, "{g} vs {expected}");
        // Below the unperturbed surface but above the perturbed one.
        let between = f.to_local(Vec3::new(0.995, 0.0, -0.0998).normalize());
        assert!(between.z > 0.0 && !same_side(b, between) && same_side(b, w));
    }
}
