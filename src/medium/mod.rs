//! Participating media: Mitsuba's `homogeneous` ([`homogeneous`]) and `heterogeneous`
//! ([`heterogeneous`], over the volumes of [`grid`]) media with their phase functions
//! ([`phase`]), and the interfaces shapes put between media.
//!
//! A medium is described by its extinction σt and albedo (or absorption and scattering
//! coefficients σa, σs, with σt = σa + σs) per colour channel, per unit length of the scene:
//! light travelling through it keeps the fraction `exp(-∫σt)`, and a fraction σs of what is
//! lost per unit length is scattered into other directions by the phase function.
//! [`Medium`] gives the integrators what they ask of every kind alike: free flights
//! ([`Medium::sample`]) and the transmittance of a segment ([`Medium::transmittance`]).
//!
//! A heterogeneous medium's transmittance is an unbiased random estimate (ratio tracking).
//! Its random numbers come from a stream keyed by the segment itself (its origin,
//! direction and length), so that a shadow ray needs no sampler and the same segment always
//! gets the same estimate (as a path's Metropolis mutations expect of its contribution).

pub mod grid;
pub mod heterogeneous;
pub mod homogeneous;
pub mod phase;

use crate::math::Rgb;
use crate::sampling::{Random, Sampler};
use glam::Vec3;
pub use heterogeneous::Heterogeneous;
pub use homogeneous::Homogeneous;
pub use phase::Phase;

/// A participating medium: how it attenuates and scatters, and its phase function.
#[derive(Clone, Debug)]
pub struct Medium {
    pub kind: MediumKind,
    pub phase: Phase,
    /// The file's `id`, or the plugin's name.
    pub name: String,
}

/// The kinds of media.
#[derive(Clone, Debug)]
pub enum MediumKind {
    Homogeneous(Homogeneous),
    /// Boxed: a grid's placement and majorant outweigh the homogeneous coefficients.
    Heterogeneous(Box<Heterogeneous>),
}

/// Where a sampled free flight ends.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MediumSample {
    /// The distance travelled (the segment's length when the flight reached its end).
    pub t: f32,
    /// The flight ended inside the medium, with a scattering event at `t`.
    pub scattered: bool,
    /// What the path's throughput is multiplied by: `σs T(t) / p(t)` for a scattering
    /// event, `T(t_max) / P(t ≥ t_max)` otherwise.
    pub weight: Rgb,
}

impl Medium {
    /// A homogeneous medium of absorption `sigma_a` and scattering `sigma_s`.
    pub fn new(sigma_a: Rgb, sigma_s: Rgb, phase: Phase, name: String) -> Medium {
        Medium { kind: MediumKind::Homogeneous(Homogeneous::new(sigma_a, sigma_s)), phase, name }
    }

    /// The medium's coefficients when it is homogeneous.
    #[inline]
    pub fn homogeneous(&self) -> Option<&Homogeneous> {
        match &self.kind {
            MediumKind::Homogeneous(m) => Some(m),
            MediumKind::Heterogeneous(_) => None,
        }
    }

    /// Whether light scatters in the medium (otherwise it only absorbs).
    #[inline]
    pub fn scatters(&self) -> bool {
        match &self.kind {
            MediumKind::Homogeneous(m) => m.scatters(),
            MediumKind::Heterogeneous(m) => m.scatters(),
        }
    }

    /// The fraction of light that crosses the segment from `o` along the unit direction `d`
    /// to the distance `t_max` (infinite for a ray that leaves the scene).
    #[inline]
    pub fn transmittance(&self, o: Vec3, d: Vec3, t_max: f32) -> Rgb {
        match &self.kind {
            MediumKind::Homogeneous(m) => m.transmittance(t_max),
            MediumKind::Heterogeneous(m) => Rgb::splat(m.transmittance(o, d, t_max, &mut segment_stream(o, d, t_max))),
        }
    }

    /// Samples a free flight along the segment from `o` along the unit direction `d` to the
    /// distance `t_max` (infinite for a ray that leaves the scene). A homogeneous medium
    /// takes two numbers from `rng`; a heterogeneous one as many as its tracking needs.
    #[inline]
    pub fn sample<R: Random>(&self, o: Vec3, d: Vec3, t_max: f32, rng: &mut R) -> MediumSample {
        match &self.kind {
            MediumKind::Homogeneous(m) => {
                let u_channel = rng.next_1d();
                m.sample(t_max, u_channel, rng.next_1d())
            }
            MediumKind::Heterogeneous(m) => m.sample(o, d, t_max, rng),
        }
    }
}

/// The random stream of a segment's transmittance estimate, keyed by the segment.
fn segment_stream(o: Vec3, d: Vec3, t_max: f32) -> Sampler {
    let bits = |a: f32, b: f32| (a.to_bits() as u64) << 32 | b.to_bits() as u64;
    Sampler::new(&[0x6d65_6469_756d, bits(o.x, o.y), bits(o.z, d.x), bits(d.y, d.z), t_max.to_bits() as u64])
}

/// The media on the two sides of a shape's surface (Mitsuba's `interior` and `exterior`):
/// `None` is vacuum. A ray crossing the surface along its normal enters the exterior.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MediumInterface {
    pub interior: Option<u32>,
    pub exterior: Option<u32>,
}

impl MediumInterface {
    /// The medium a ray leaving the surface in direction `d` travels in, for the surface's
    /// geometric normal `ng`.
    #[inline]
    pub fn towards(&self, ng: Vec3, d: Vec3) -> Option<u32> {
        if ng.dot(d) > 0.0 { self.exterior } else { self.interior }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_normal_side_is_the_exterior() {
        let i = MediumInterface { interior: Some(0), exterior: None };
        assert_eq!(i.towards(Vec3::Z, Vec3::new(0.0, 0.3, 1.0)), None);
        assert_eq!(i.towards(Vec3::Z, Vec3::new(0.0, 0.3, -1.0)), Some(0));
    }
}
