//! The independent mutation of MEMLT: a whole new path from the bidirectional generator
//! ([`super::independent_path`]: a length `∝ 2^-k`, a uniform split into light and camera
//! walks, every vertex new), proposed whatever the current path is. Not one of Mitsuba
//! 0.6's mutations (`--independent-mutation`): it is the path-space form of Kelemen's large
//! step, which lets a chain move between regions of the image that its local moves join
//! only rarely (a caustic seen directly and through a glass ball, say) in proportion to
//! their brightness. Its densities are the generator's: `T(x → y) = p(y)`, `T(y → x) =
//! p(x)`, with `p` the generator's density of a whole path ([`super::whole_path_density`]).

use super::bidirectional::{Lengths, Proposal};
use crate::integrator::Counters;
use crate::integrator::bidir::Vertex;
use crate::sampling::Random;
use crate::scene::Scene;

/// Proposes a path independent of `x` (with `lengths`, the generator's); `None` when the
/// generator fails.
pub fn propose(
    scene: &Scene,
    x: &[Vertex],
    lengths: Lengths,
    rng: &mut impl Random,
    c: &mut Counters,
) -> Option<Proposal> {
    let (path, measured, forward) = super::independent_path(scene, lengths, rng, c)?;
    Some(Proposal { path, measured, forward, backward: super::whole_path_density(scene, lengths, x) })
}
