//! MEMLT's separate direct-light estimate against its chains under a time budget
//! (`--direct-balance`): how much of the time the direct-light pass takes.
//!
//! The contract (`memlt.md`) has the direct light handled as Mitsuba 0.6
//! does, by a separate path-traced estimate of `--direct-samples` samples per pixel. A fixed
//! sample count suits a fixed budget of mutations; under `--time` it leaves the split of the
//! time to chance: on a scene lit mostly directly (a room under the sky) a few samples per
//! pixel take a small share of the time and their noise can be most of the image's, on a
//! caustic the chains' noise is (`docs/results/memlt.md`). Each part's noise is measured
//! here as a relative variance per second `V` (the relMSE it would have after one second: a
//! part given `t` seconds has `V / t`), each from two independent halves of itself: the
//! direct pass's first `--direct-samples` against a second pass of as many, the chains' first
//! half against their second half after a tenth of their time ([`MEASURE_SHARE`]).
//! The sum `V_d / t_d + V_c / t_c` over a fixed `t_d + t_c = W` is least at
//! `t_d = W √V_d / (√V_d + √V_c)`; the direct pass then goes on for what it lacks of that,
//! at most half of the time left ([`MAX_SHARE_OF_REST`]). The chains' noise measured early
//! includes their start-up, so `V_c` errs high and the direct pass's share low.

use crate::compare::relative_square;
use crate::film::Film;
use crate::math::Rgb;

/// The share of the chains' time after which both parts' noise is measured.
pub const MEASURE_SHARE: f64 = 0.1;

/// The most of the time left at the measurement that the direct pass may take.
pub const MAX_SHARE_OF_REST: f64 = 0.5;

/// The variance of an estimate made of two independent halves `a` and `b` (estimates of the
/// same image from `na` and `nb` independent units: samples, chains), relative as `pcbpt
/// compare`'s relMSE is to `reference` (per channel, over `r² + 0.01`), averaged over the
/// pixels' channels. Each half has variance `σ² / n`, so `E[(a − b)²] = σ² (na + nb) / (na nb)`
/// and the whole estimate's variance, `σ² / (na + nb)`, is `E[(a − b)²] na nb / (na + nb)²`.
pub fn halves_variance(a: &[Rgb], b: &[Rgb], (na, nb): (f64, f64), reference: &[Rgb]) -> f64 {
    assert!(a.len() == b.len() && a.len() == reference.len(), "three images of one size");
    if a.is_empty() || na <= 0.0 || nb <= 0.0 {
        return 0.0;
    }
    let factor = na * nb / ((na + nb) * (na + nb));
    let sum: f64 = a
        .iter()
        .zip(b)
        .zip(reference)
        .map(|((p, q), r)| {
            [(p.x, q.x, r.x), (p.y, q.y, r.y), (p.z, q.z, r.z)]
                .iter()
                .map(|&(p, q, r)| relative_square(p as f64 - q as f64, r))
                .sum::<f64>()
        })
        .sum();
    factor * sum / (3 * a.len()) as f64
}

/// The direct pass's share of the time that minimises `V_d / t_d + V_c / t_c`.
pub fn direct_share(v_direct: f64, v_chains: f64) -> f64 {
    let (d, c) = (v_direct.max(0.0).sqrt(), v_chains.max(0.0).sqrt());
    if d + c > 0.0 { d / (d + c) } else { 0.0 }
}

/// The seconds the direct pass should go on for, having taken `direct` seconds, with the
/// chains' `chains` seconds spent and `rest` left: what it lacks of its best share of the
/// whole (`direct + chains + rest`), at most [`MAX_SHARE_OF_REST`] of `rest`.
pub fn extra_direct_seconds(direct: f64, chains: f64, rest: f64, v_direct: f64, v_chains: f64) -> f64 {
    let whole = direct + chains + rest.max(0.0);
    (whole * direct_share(v_direct, v_chains) - direct).clamp(0.0, MAX_SHARE_OF_REST * rest.max(0.0))
}

/// The chains' two halves, developed: the first half of the groups' films (a run's
/// [`crate::integrator::metropolis::ChainRun::groups`]) against the rest, each over its own chains' share
/// of the `done` mutations of `chains` chains, with its chain count; `None` with fewer than
/// two groups.
pub fn chain_halves(groups: &[(Film, usize)], done: u64, chains: usize) -> Option<[(Vec<Rgb>, f64); 2]> {
    if groups.len() < 2 || chains == 0 {
        return None;
    }
    let half = |gs: &[(Film, usize)]| {
        let n: usize = gs.iter().map(|g| g.1).sum();
        let first = &gs[0].0;
        let mut f = Film::new(first.width, first.height, first.filter);
        for (g, _) in gs {
            f.add_film_splats(g);
        }
        f.light_paths = done / chains as u64 * n as u64;
        (f.develop(), n as f64)
    };
    let k = groups.len() / 2;
    Some([half(&groups[..k]), half(&groups[k..])])
}

/// Both parts' relative variances per second (the extra samples and seconds left at zero)
/// and the seconds the direct pass should go on for ([`extra_direct_seconds`]): the direct
/// pass's two halves of `seconds.0` seconds in all,
/// the chains' halves after `seconds.1` seconds, whose part of the image is finally scaled by
/// `scale` (two-stage Metropolis), relative to the image so far, `estimate`, with
/// `seconds.2` left.
pub fn measure(
    direct: &(Vec<Rgb>, Vec<Rgb>),
    chains: &[(Vec<Rgb>, f64); 2],
    estimate: &[Rgb],
    scale: f64,
    (direct_seconds, chain_seconds, rest): (f64, f64, f64),
) -> (DirectBalance, f64) {
    let v_direct = halves_variance(&direct.0, &direct.1, (1.0, 1.0), estimate) * direct_seconds;
    let [(a, na), (b, nb)] = chains;
    let v_chains = halves_variance(a, b, (*na, *nb), estimate) * scale * scale * chain_seconds;
    let measured = DirectBalance {
        direct_noise: v_direct,
        chain_noise: v_chains,
        measured_after: chain_seconds,
        extra_samples: 0,
        extra_seconds: 0.0,
    };
    (measured, extra_direct_seconds(direct_seconds, chain_seconds, rest, v_direct, v_chains))
}

/// What the balance measured and did, for the statistics.
#[derive(Clone, Copy, Debug, Default, serde::Serialize)]
pub struct DirectBalance {
    /// The relative variances per second `V_d` and `V_c` (zero where not measured).
    pub direct_noise: f64,
    pub chain_noise: f64,
    /// The chains' seconds before the measurement.
    pub measured_after: f64,
    /// Samples per pixel the direct pass added after it, and their seconds.
    pub extra_samples: u32,
    pub extra_seconds: f64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compare::RELMSE_EPSILON;
    use crate::sampling::Sampler;

    /// Normal deviates by Box–Muller.
    fn normal(rng: &mut Sampler) -> f64 {
        let (u, v) = (rng.next_1d() as f64, rng.next_1d() as f64);
        (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    /// Halves of `na` and `nb` unit estimates (each the reference plus noise of standard
    /// deviation `sigma` per unit) and the whole estimate's true relative variance.
    fn halves(na: usize, nb: usize, sigma: f64, seed: u64) -> (Vec<Rgb>, Vec<Rgb>, Vec<Rgb>, f64) {
        let mut rng = Sampler::new(&[seed]);
        let pixels = 12000;
        let reference: Vec<Rgb> = (0..pixels).map(|i| Rgb::splat(0.5 + (i % 7) as f32 * 0.1)).collect();
        let mean_of = |n: usize, rng: &mut Sampler| -> Vec<Rgb> {
            reference
                .iter()
                .map(|r| {
                    let mut c = [0.0f64; 3];
                    for x in &mut c {
                        *x = (0..n).map(|_| sigma * normal(rng)).sum::<f64>() / n as f64;
                    }
                    *r + Rgb::new(c[0] as f32, c[1] as f32, c[2] as f32)
                })
                .collect()
        };
        let (a, b) = (mean_of(na, &mut rng), mean_of(nb, &mut rng));
        let whole = sigma * sigma / (na + nb) as f64;
        let truth =
            reference.iter().map(|r| whole / (r.x as f64 * r.x as f64 + RELMSE_EPSILON)).sum::<f64>() / pixels as f64;
        (a, b, reference, truth)
    }

    #[test]
    fn halves_give_the_whole_estimates_variance() {
        // Equal and unequal halves: the estimate is within 5% of the truth (36 000 squared
        // differences: its relative standard error is under 1%).
        for (na, nb, seed) in [(8, 8, 1), (3, 13, 2), (1, 1, 3)] {
            let (a, b, r, truth) = halves(na, nb, 0.3, seed);
            let v = halves_variance(&a, &b, (na as f64, nb as f64), &r);
            assert!((v / truth - 1.0).abs() < 0.05, "{na}+{nb}: {v} against {truth}");
            // Negative control: taking the halves as equal when they are not is caught.
            if na != nb {
                let wrong = halves_variance(&a, &b, (1.0, 1.0), &r);
                assert!((wrong / truth - 1.0).abs() > 0.2, "{na}+{nb}: equal halves {wrong} against {truth}");
            }
        }
        let (a, _, r, _) = halves(4, 4, 0.3, 4);
        assert_eq!(halves_variance(&a, &a, (4.0, 4.0), &r), 0.0);
        assert_eq!(halves_variance(&a, &a, (0.0, 4.0), &r), 0.0);
    }

    #[test]
    fn the_share_minimises_the_summed_noise() {
        let total = |vd: f64, vc: f64, s: f64| vd / s + vc / (1.0 - s);
        for (vd, vc) in [(1e-6, 0.4), (0.05, 0.9), (0.3, 0.3), (2.0, 0.01)] {
            let s = direct_share(vd, vc);
            assert!(s > 0.0 && s < 1.0);
            for ds in [-0.01, 0.01] {
                let t = (s + ds * s.min(1.0 - s)).clamp(1e-9, 1.0 - 1e-9);
                assert!(total(vd, vc, s) < total(vd, vc, t), "{vd} {vc}: {s} against {t}");
            }
        }
        assert_eq!(direct_share(0.0, 0.0), 0.0);
        assert_eq!(direct_share(0.0, 1.0), 0.0);
        assert_eq!(direct_share(1.0, 0.0), 1.0);
    }

    #[test]
    fn the_extra_time_is_what_the_share_lacks_within_half_the_rest() {
        // Equal noise: half of the 40 s; 2 s spent, so 18 more, within half of the 36 left.
        assert!((extra_direct_seconds(2.0, 2.0, 36.0, 1.0, 1.0) - 18.0).abs() < 1e-9);
        // Direct noise nine times the chains': three quarters, capped at half the rest.
        assert!((extra_direct_seconds(1.0, 3.0, 36.0, 9.0, 1.0) - 18.0).abs() < 1e-9);
        // A direct pass that already took more than its share takes no more.
        assert_eq!(extra_direct_seconds(5.0, 4.0, 31.0, 1e-6, 1.0), 0.0);
        assert_eq!(extra_direct_seconds(1.0, 4.0, -1.0, 1.0, 1.0), 0.0);
    }
}
