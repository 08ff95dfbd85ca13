//! The path tracer in scenes with participating media and null surfaces (contract §1 with
//! Mitsuba's `volpath` for the media): free flights sampled through each medium
//! ([`crate::medium::Medium::sample`]: closed-form in a homogeneous medium, delta tracking in
//! a heterogeneous one; an absorbing-only medium is crossed with its transmittance),
//! phase-function sampling at scattering events, next-event estimation from surfaces and
//! medium points with the transmittance of the shadow ray through the media and null
//! surfaces on its way ([`Scene::transmittance`]), MIS by the power heuristic between phase
//! or BSDF sampling and light sampling as on surfaces.
//!
//! A scattering event is a vertex like a surface bounce (it counts towards `max_depth` and
//! Russian roulette); crossing a null surface (a boundary between media) is not: the ray
//! goes on unchanged in the medium on the other side.

use super::{BsdfSampling, PathState, PathTracer};
use crate::accel::Ray;
use crate::integrator::stats::Counters;
use crate::math::{Rgb, SHADOW_EPSILON};
use crate::medium::Medium;
use crate::sampling::{Random, power_heuristic};
use crate::scene::{MAX_NULL_CROSSINGS, Scene};
use glam::Vec3;

impl PathTracer {
    /// Radiance arriving along a camera ray that starts in the camera's medium.
    pub fn li_media<R: Random>(&self, scene: &Scene, mut ray: Ray, sampler: &mut R, counters: &mut Counters) -> Rgb {
        let mut s = PathState { medium: scene.camera_medium, ..PathState::new(ray) };
        if self.max_depth == 0 {
            return s.l;
        }
        let mut crossings = 0;
        loop {
            counters.extension_rays += 1;
            let hit = scene.intersect(&ray);
            let len = ray.d.length();
            let d = ray.d / len;
            if let Some(m) = s.medium {
                let medium = &scene.media[m as usize];
                let t_max = hit.as_ref().map_or(f32::INFINITY, |si| si.t * len);
                let flight = medium.sample(ray.o, d, t_max, sampler);
                s.beta *= flight.weight;
                if s.beta == Rgb::ZERO {
                    break;
                }
                if flight.scattered {
                    let p = ray.o + d * flight.t;
                    match self.scatter(scene, medium, p, -d, &mut s, sampler, counters) {
                        Some(next) => {
                            ray = next;
                            continue;
                        }
                        None => break,
                    }
                }
            }
            let Some(si) = hit else {
                self.escaped(scene, &mut s, d, &mut BsdfSampling);
                break;
            };
            let bsdf = scene.bsdf(&si);
            if bsdf.is_null() {
                // A boundary between media: on into the medium behind it.
                crossings += 1;
                if crossings > MAX_NULL_CROSSINGS {
                    break;
                }
                s.medium = scene.medium_after(&si, d, s.medium);
                ray = si.spawn_ray(d);
                continue;
            }
            // The surface's light, with next-event estimation through the media and null
            // surfaces on the way; then on by sampling the BSDF.
            let medium = s.medium;
            let Some(lit) = self.light_at(scene, &mut s, &si, sampler, counters, &mut BsdfSampling, |ray, infinite| {
                scene.transmittance_to(ray, scene.medium_after(&si, ray.d, medium), infinite)
            }) else {
                break;
            };
            s.l += lit.direct;
            if !self.go_on(&mut s, &si, &lit, sampler, &mut BsdfSampling) {
                break;
            }
            ray = s.ray;
            s.medium = scene.medium_after(&si, ray.d, s.medium);
        }
        s.l
    }

    /// A scattering event at `p` in `medium` (light leaving along `wo`): next-event
    /// estimation with the phase function, then the next direction sampled from it. `None`
    /// when the path ends here.
    #[allow(clippy::too_many_arguments)]
    fn scatter<R: Random>(
        &self,
        scene: &Scene,
        medium: &Medium,
        p: Vec3,
        wo: Vec3,
        s: &mut PathState,
        sampler: &mut R,
        counters: &mut Counters,
    ) -> Option<Ray> {
        s.depth += 1;
        if s.depth >= self.max_depth {
            return None;
        }
        let u_light = sampler.next_1d();
        let u_light1 = sampler.next_1d();
        let u_light2 = sampler.next_2d();
        if let Some((light_index, pmf, _)) = scene.light_sampler.sample(u_light) {
            let light = &scene.lights[light_index];
            if let Some(ls) = light.sample_li(&scene.shapes, &scene.bounds, p, u_light1, u_light2) {
                let f = medium.phase.eval(wo, ls.wi);
                counters.shadow_rays += 1;
                let segment = Ray::segment(p, ls.p - p, 1.0 - SHADOW_EPSILON);
                let tr = scene.transmittance_to(&segment, s.medium, light.is_infinite());
                if f > 0.0 && tr != Rgb::ZERO {
                    let pdf_light = pmf * ls.pdf;
                    let w = if ls.delta { 1.0 } else { power_heuristic(pdf_light, f) };
                    s.l += s.beta * tr * ls.li * (f * w / pdf_light);
                }
            }
        }
        // The phase function is sampled exactly: its weight f / pdf is one.
        let (wi, pdf) = medium.phase.sample(wo, sampler.next_2d());
        s.prev_pdf = pdf;
        s.prev_delta = false;
        s.prev_p = p;
        if !self.roulette(s, sampler) {
            return None;
        }
        Some(Ray::new(p, wi))
    }
}
