//! Veach's lens perturbation (Veach and Guibas 1997; contract `memlt.md`, "Mutators"): moves
//! the path's film position by a small offset and re-traces its camera end through the same
//! sequence of Dirac lobes to the first vertex that is not specular, which is joined to the
//! rest of the path by a shadow ray.
//!
//! The offset's length has density `∝ 1/r` between `r1` = 0.1 pixel and `r2`, the radius of
//! a disk covering 5% of the image, in a uniform direction: a density on the film symmetric
//! in the two positions. The film position and the Dirac lobes fix every re-traced vertex, so
//! the transition density is that symmetric factor times the Jacobian from the film to the
//! re-traced vertices' areas: the camera walk's density of those vertices with the Dirac
//! lobes' discrete probabilities taken out. Only that Jacobian enters the acceptance.

use crate::integrator::bidir::{Vertex, VertexKind};
use crate::integrator::memlt::bidirectional::Proposal;
use crate::integrator::memlt::path::{
    connectible, contribution, join, pdf_from_camera, pdf_from_lobe, retrace, settle_sky,
};
use crate::integrator::stats::Counters;
use crate::sampling::Random;
use crate::scene::Scene;
use glam::Vec2;

/// The radii between which offsets are drawn, in pixels.
#[derive(Clone, Copy, Debug)]
pub struct Radii {
    pub r1: f32,
    pub r2: f32,
}

impl Radii {
    /// 0.1 pixel to the radius of a disk covering 5% of a `width × height` image.
    pub fn for_film(width: u32, height: u32) -> Radii {
        let r2 = (0.05 * width as f32 * height as f32 / std::f32::consts::PI).sqrt();
        Radii { r1: 0.1, r2: r2.max(0.2) }
    }

    /// An offset with length density `∝ 1/r` on `[r1, r2]`, uniform direction.
    pub fn sample(&self, u: Vec2) -> Vec2 {
        let r = self.r1 * (self.r2 / self.r1).powf(u.x);
        let phi = 2.0 * std::f32::consts::PI * u.y;
        Vec2::new(r * phi.cos(), r * phi.sin())
    }

    /// The camera ray through film position `raster` moved by an offset from `u` (counted
    /// in `counters`); `None` when the offset leaves the image.
    pub fn camera_ray(
        &self,
        scene: &Scene,
        raster: Vec2,
        u: Vec2,
        counters: &mut Counters,
    ) -> Option<crate::accel::Ray> {
        let pos = raster + self.sample(u);
        let res = Vec2::new(scene.film.width as f32, scene.film.height as f32);
        if pos.x < 0.0 || pos.y < 0.0 || pos.x >= res.x || pos.y >= res.y {
            return None;
        }
        counters.camera_rays += 1;
        Some(scene.camera.generate_ray(pos))
    }
}

/// Where the lens perturbation re-traces to: the index `m` of the first vertex from the
/// camera that is not specular, when it and the vertex before it can take a connection.
pub fn suits(scene: &Scene, x: &[Vertex]) -> Option<usize> {
    let k = x.len() - 1;
    let mut m = k.checked_sub(1)?;
    while m >= 1 && x[m].delta {
        m -= 1;
    }
    (m >= 1 && x[m].kind == VertexKind::Surface && connectible(scene, &x[m]) && connectible(scene, &x[m - 1]))
        .then_some(m)
}

/// The Jacobian of the re-traced vertices `x_m .. x_{k-1}` with respect to the film: the
/// camera walk's area densities with the Dirac lobes' probabilities divided out.
pub fn jacobian(scene: &Scene, x: &[Vertex], m: usize) -> f64 {
    let k = x.len() - 1;
    let mut j = 1.0;
    for i in m..k {
        let p = pdf_from_camera(scene, x, i);
        let lobe = if i + 1 < k { pdf_from_lobe(scene, x, i + 1) } else { 1.0 };
        if lobe <= 0.0 {
            return 0.0;
        }
        j *= p / lobe;
    }
    j
}

/// Proposes a lens perturbation of `x` (film position `raster`), re-tracing `x_m ..
/// x_{k-1}`.
pub fn propose<R: Random>(
    scene: &Scene,
    x: &[Vertex],
    raster: Vec2,
    m: usize,
    radii: Radii,
    rng: &mut R,
    counters: &mut Counters,
) -> Option<Proposal> {
    let k = x.len() - 1;
    let mut ray = radii.camera_ray(scene, raster, rng.next_2d(), counters)?;
    let mut y = x.to_vec();
    let mut medium = scene.camera_medium;
    for i in (m..k).rev() {
        y[i] = retrace(scene, &mut ray, &mut medium, x, i, i > m, counters)?;
    }
    settle_sky(scene, &mut y);
    if !join(scene, &y[m - 1], &y[m], counters) {
        return None;
    }
    let measured = contribution(scene, &y)?;
    let forward = jacobian(scene, &y, m);
    let backward = jacobian(scene, x, m);
    Some(Proposal { path: y, measured, forward, backward })
}
