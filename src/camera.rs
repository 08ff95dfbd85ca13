//! Mitsuba's `perspective` sensor: a pinhole camera looking down its local +z axis, with
//! local +x to the left of the image and +y up, placed by `to_world`.

use crate::accel::Ray;
use crate::math::Transform;
use glam::{Vec2, Vec3};

/// Which image axis the field of view refers to (`fov_axis`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FovAxis {
    X,
    Y,
    Diagonal,
    Smaller,
    Larger,
}

impl FovAxis {
    pub fn parse(s: &str) -> Option<FovAxis> {
        Some(match s {
            "x" => FovAxis::X,
            "y" => FovAxis::Y,
            "diagonal" => FovAxis::Diagonal,
            "smaller" => FovAxis::Smaller,
            "larger" => FovAxis::Larger,
            _ => return None,
        })
    }
}

#[derive(Clone, Debug)]
pub struct Camera {
    pub to_world: Transform,
    pub position: Vec3,
    /// tan of half the field of view along x and y.
    pub tan_half: Vec2,
    pub resolution: (u32, u32),
    pub near_clip: f32,
    pub far_clip: f32,
    /// World → camera-local rotation (the inverse of `to_world`'s linear part).
    to_local: glam::Mat3,
    /// `1 / tan_half` and `1 / A` (the image rectangle's area at unit distance), for the
    /// projections of light tracing.
    inv_tan_half: Vec2,
    inv_area: f32,
}

/// The camera seen from a point: where on the film the point appears and the importance
/// it receives (what light tracing splats).
#[derive(Clone, Copy, Debug)]
pub struct CameraConnection {
    /// Film position in pixel units.
    pub raster: Vec2,
    /// Unit direction from the point to the camera.
    pub wi: Vec3,
    pub dist2: f32,
    pub inv_dist2: f32,
    /// [`Camera::pdf_direction`] of the direction from the camera to the point,
    /// `1 / (A cos³θ)`, which is also `We · cos θ_camera`: the emitted importance times the
    /// camera-side cosine (the pinhole has no surface, so the cosine stays with the
    /// importance).
    pub pdf_dir: f32,
}

impl Camera {
    pub fn new(
        to_world: Transform,
        fov_degrees: f32,
        axis: FovAxis,
        resolution: (u32, u32),
        near_clip: f32,
        far_clip: f32,
    ) -> Camera {
        let (w, h) = (resolution.0 as f32, resolution.1 as f32);
        let aspect = w / h;
        let t = (fov_degrees.to_radians() * 0.5).tan();
        let axis = match axis {
            FovAxis::Smaller => {
                if w <= h {
                    FovAxis::X
                } else {
                    FovAxis::Y
                }
            }
            FovAxis::Larger => {
                if w >= h {
                    FovAxis::X
                } else {
                    FovAxis::Y
                }
            }
            a => a,
        };
        let tan_half = match axis {
            FovAxis::X => Vec2::new(t, t / aspect),
            FovAxis::Y => Vec2::new(t * aspect, t),
            _ => {
                let diag = (w * w + h * h).sqrt();
                Vec2::new(t * w / diag, t * h / diag)
            }
        };
        let position = to_world.point(Vec3::ZERO);
        let to_local = glam::Mat3::from_mat4(to_world.matrix).inverse();
        let inv_area = 1.0 / (4.0 * tan_half.x * tan_half.y);
        Camera {
            to_world,
            position,
            tan_half,
            resolution,
            near_clip,
            far_clip,
            to_local,
            inv_tan_half: 1.0 / tan_half,
            inv_area,
        }
    }

    /// Film position (pixel units) of a world direction `d` (of any length) leaving the
    /// camera, when it falls on the image, and `d` in camera space (`z` along the view).
    #[inline]
    fn raster_of(&self, d: Vec3) -> Option<(Vec2, Vec3)> {
        let l = self.to_local * d;
        if l.z <= 0.0 {
            return None;
        }
        let inv_z = 1.0 / l.z;
        let sx = 0.5 * (1.0 - l.x * inv_z * self.inv_tan_half.x);
        let sy = 0.5 * (1.0 - l.y * inv_z * self.inv_tan_half.y);
        if !(0.0..1.0).contains(&sx) || !(0.0..1.0).contains(&sy) {
            return None;
        }
        Some((Vec2::new(sx * self.resolution.0 as f32, sy * self.resolution.1 as f32), l))
    }

    /// `1 / (A cos³θ)` for a camera-space direction at angle θ to the view axis, given its
    /// `z` and its length.
    #[inline]
    fn inv_area_cos3(&self, z: f32, length: f32) -> f32 {
        let sec = length / z;
        self.inv_area * sec * sec * sec
    }

    /// Solid-angle density with which [`Camera::generate_ray`], at a uniformly random film
    /// position, produces direction `d` (unit): `1 / (A cos³θ)`; zero off the image.
    #[inline]
    pub fn pdf_direction(&self, d: Vec3) -> f32 {
        match self.raster_of(d) {
            Some((_, l)) => self.inv_area_cos3(l.z, l.length()),
            None => 0.0,
        }
    }

    /// Importance `We = 1 / (A cos⁴θ)` of a direction (unit) leaving the camera, normalised
    /// so that `∫ We cos θ dω = 1` over the image.
    #[inline]
    pub fn importance(&self, d: Vec3) -> f32 {
        self.raster_of(d).map_or(0.0, |(_, l)| {
            let length = l.length();
            self.inv_area_cos3(l.z, length) * length / l.z
        })
    }

    /// Connects a world point to the pinhole: `None` when the point is behind the camera,
    /// outside the image, or outside the clip range.
    #[inline]
    pub fn connect(&self, p: Vec3) -> Option<CameraConnection> {
        let d = p - self.position;
        let dist2 = d.length_squared();
        if dist2 <= 0.0 {
            return None;
        }
        let dist = dist2.sqrt();
        let inv_dist = 1.0 / dist;
        // The unit direction, so that the density below is bit-for-bit `pdf_direction`'s.
        let dir = d * inv_dist;
        let (raster, l) = self.raster_of(dir)?;
        // The depth along the view axis, `dist cos θ`, against the clip planes.
        let length = l.length();
        let depth = dist * l.z / length;
        if depth < self.near_clip || depth > self.far_clip {
            return None;
        }
        let pdf_dir = self.inv_area_cos3(l.z, length);
        Some(CameraConnection { raster, wi: -dir, dist2, inv_dist2: inv_dist * inv_dist, pdf_dir })
    }

    /// The primary ray through a film position in pixel units (`(0,0)` is the top-left
    /// corner of the image, `(width, height)` the bottom-right).
    #[inline]
    pub fn generate_ray(&self, film: Vec2) -> Ray {
        let s = film / Vec2::new(self.resolution.0 as f32, self.resolution.1 as f32);
        let local = Vec3::new((1.0 - 2.0 * s.x) * self.tan_half.x, (1.0 - 2.0 * s.y) * self.tan_half.y, 1.0);
        let len = local.length();
        let d = self.to_world.vector(local).normalize();
        // The clip planes are perpendicular to the viewing axis: along a unit direction
        // they lie at near / cos θ = near |local|.
        Ray { o: self.position, d, tmin: self.near_clip * len, tmax: self.far_clip * len }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Mat4;

    #[test]
    fn centre_ray_looks_along_z_and_left_is_plus_x() {
        let c = Camera::new(Transform::default(), 90.0, FovAxis::X, (200, 100), 0.0, 1e4);
        let r = c.generate_ray(Vec2::new(100.0, 50.0));
        assert!((r.d - Vec3::Z).length() < 1e-6);
        let left = c.generate_ray(Vec2::new(0.0, 50.0));
        assert!((left.d - Vec3::new(1.0, 0.0, 1.0).normalize()).length() < 1e-5);
        let top = c.generate_ray(Vec2::new(100.0, 0.0));
        assert!((top.d - Vec3::new(0.0, 0.5, 1.0).normalize()).length() < 1e-5);
    }

    #[test]
    fn fov_axis_smaller_uses_the_short_side() {
        let c = Camera::new(Transform::new(Mat4::IDENTITY), 90.0, FovAxis::Smaller, (200, 100), 0.0, 1e4);
        assert!((c.tan_half.y - 1.0).abs() < 1e-6 && (c.tan_half.x - 2.0).abs() < 1e-6);
    }

    #[test]
    fn connect_inverts_generate_ray() {
        let to_world = Transform::new(
            Mat4::from_translation(Vec3::new(1.0, 2.0, 3.0))
                * Mat4::from_rotation_y(0.7)
                * Mat4::from_rotation_x(-0.3)
                * Mat4::from_scale(Vec3::new(-1.0, 1.0, -1.0)),
        );
        let c = Camera::new(to_world, 40.0, FovAxis::X, (64, 48), 0.01, 1e4);
        for pos in [Vec2::new(10.3, 7.9), Vec2::new(63.5, 0.2), Vec2::new(0.1, 47.9)] {
            let r = c.generate_ray(pos);
            let k = c.connect(r.at(5.0)).unwrap();
            assert!((k.raster - pos).abs().max_element() < 1e-3, "{pos} -> {}", k.raster);
            assert!((k.wi + r.d).length() < 1e-5);
            assert_eq!(k.pdf_dir, c.pdf_direction(-k.wi));
        }
    }

    #[test]
    fn importance_integrates_to_one_over_the_image() {
        // ∫ We cos θ dω over the image, by uniform sphere sampling (the camera looks along +z).
        let c = Camera::new(Transform::default(), 50.0, FovAxis::X, (40, 30), 0.0, 1e4);
        let mut s = crate::sampling::Sampler::new(&[9]);
        let n = 400_000;
        let sum: f64 = (0..n)
            .map(|_| {
                let d = crate::sampling::square_to_uniform_sphere(s.next_2d());
                (c.importance(d) * d.z) as f64 * 4.0 * std::f64::consts::PI
            })
            .sum();
        assert!((sum / n as f64 - 1.0).abs() < 0.02, "{}", sum / n as f64);
        // The direction density also integrates to one.
        let sum: f64 = (0..n)
            .map(|_| {
                c.pdf_direction(crate::sampling::square_to_uniform_sphere(s.next_2d())) as f64
                    * 4.0
                    * std::f64::consts::PI
            })
            .sum();
        assert!((sum / n as f64 - 1.0).abs() < 0.02, "{}", sum / n as f64);
    }

    #[test]
    fn near_clip_is_a_plane() {
        let c = Camera::new(Transform::default(), 90.0, FovAxis::X, (100, 100), 1.0, 1e4);
        let r = c.generate_ray(Vec2::new(0.0, 50.0));
        assert!((r.at(r.tmin).z - 1.0).abs() < 1e-5);
    }
}
