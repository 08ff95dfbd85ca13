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

use super::{BsdfSampling, PathTracer, weighs_against_light_sampling};
use crate::accel::Ray;
use crate::integrator::stats::Counters;
use crate::math::{Rgb, SHADOW_EPSILON, max_component};
use crate::medium::Medium;
use crate::sampling::{Random, power_heuristic};
use crate::scene::{MAX_NULL_CROSSINGS, Scene};
use glam::Vec3;

/// Where the path's last vertex was, what its sampling density was, and the throughput.
struct PathState {
    l: Rgb,
    beta: Rgb,
    /// Vertices after the camera so far (scattering events and surface bounces).
    depth: u32,
    prev_pdf: f32,
    prev_delta: bool,
    prev_p: Vec3,
    medium: Option<u32>,
}

impl PathTracer {
    /// Radiance arriving along a camera ray that starts in the camera's medium.
    pub fn li_media<R: Random>(&self, scene: &Scene, mut ray: Ray, sampler: &mut R, counters: &mut Counters) -> Rgb {
        let mut s = PathState {
            l: Rgb::ZERO,
            beta: Rgb::ONE,
            depth: 0,
            prev_pdf: 0.0,
            prev_delta: true,
            prev_p: ray.o,
            medium: scene.camera_medium,
        };
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
                self.add_infinite_lights(scene, d, &mut s);
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
            s.depth += 1;
            if let Some((light_index, light)) = scene.area_light(&si) {
                let le = light.radiance(si.ng, si.uv, si.wo);
                if le != Rgb::ZERO {
                    let w = self.emission_weight(s.depth - 1, s.prev_delta, s.prev_pdf, || {
                        scene.light_sampler.pmf(light_index) * light.pdf_li(&scene.shapes, s.prev_p, &si)
                    });
                    s.l += s.beta * le * w;
                }
            }
            if s.depth >= self.max_depth {
                break;
            }
            let wo = si.shading.to_local(si.wo);
            if !self.sides_agree(&si, si.wo, wo.z) {
                break;
            }

            // Next-event estimation, through the media and null surfaces on the way.
            let medium = s.medium;
            s.l += self.surface_nee(scene, &si, bsdf, wo, s.beta, sampler, counters, &BsdfSampling, |ray, infinite| {
                scene.transmittance_to(ray, scene.medium_after(&si, ray.d, medium), infinite)
            });

            // Continue the path by sampling the BSDF.
            let Some((bs, wi_world)) = self.sample_next(&si, bsdf, wo, sampler, &mut BsdfSampling) else { break };
            s.beta *= bs.weight;
            s.prev_pdf = bs.pdf;
            s.prev_delta = bs.delta;
            s.prev_p = si.p;
            s.medium = scene.medium_after(&si, wi_world, s.medium);
            if !self.roulette(&mut s, sampler) {
                break;
            }
            ray = si.spawn_ray(wi_world);
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

    /// Russian roulette from `rr_depth` on: `false` when the path ends.
    fn roulette<R: Random>(&self, s: &mut PathState, sampler: &mut R) -> bool {
        if s.beta == Rgb::ZERO {
            return false;
        }
        if s.depth >= self.rr_depth {
            let q = max_component(s.beta).min(0.95);
            if sampler.next_1d() >= q {
                return false;
            }
            s.beta /= q;
        }
        true
    }

    /// The lights at infinity seen along `d` as the path leaves the scene.
    fn add_infinite_lights(&self, scene: &Scene, d: Vec3, s: &mut PathState) {
        for &light_index in &scene.infinite_lights {
            let light = &scene.lights[light_index];
            let (le, pdf) = if weighs_against_light_sampling(s.depth, s.prev_delta) {
                light.eval_pdf_infinite(d)
            } else {
                (light.eval_infinite(d), 0.0)
            };
            if le == Rgb::ZERO {
                continue;
            }
            let w =
                self.emission_weight(s.depth, s.prev_delta, s.prev_pdf, || scene.light_sampler.pmf(light_index) * pdf);
            s.l += s.beta * le * w;
        }
    }
}
