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
        Camera { to_world, position, tan_half, resolution, near_clip, far_clip }
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
    fn near_clip_is_a_plane() {
        let c = Camera::new(Transform::default(), 90.0, FovAxis::X, (100, 100), 1.0, 1e4);
        let r = c.generate_ray(Vec2::new(0.0, 50.0));
        assert!((r.at(r.tmin).z - 1.0).abs() < 1e-5);
    }
}
