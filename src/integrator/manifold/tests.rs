//! The manifold's tests: the Jacobian against finite differences, walks through reflections and refractions, and the densities against walked and reversed chains.

use crate::integrator::manifold::*;
use crate::sampling::Sampler;

fn rand3(rng: &mut Sampler) -> DVec3 {
    DVec3::new(rng.next_1d() as f64, rng.next_1d() as f64, rng.next_1d() as f64) * 2.0 - DVec3::ONE
}

/// A chain of `k` specular vertices zig-zagging along `+x`, with curved surfaces (normal
/// derivatives in the tangent plane) and skewed parameterisations; vertex `i` refracts
/// where `refract(i)`. The constraints need not hold: the Jacobian is checked anywhere.
fn chain(rng: &mut Sampler, k: usize, refract: impl Fn(usize) -> bool) -> Vec<ChainVertex> {
    (0..k + 2)
        .map(|i| {
            let p = DVec3::new(i as f64 * 1.3, if i % 2 == 0 { 0.0 } else { 1.1 }, 0.0) + rand3(rng) * 0.2;
            // Normals facing the previous vertex roughly, so that reflections stay on one
            // side and refractions cross.
            let n = (DVec3::new(-0.3, if i % 2 == 0 { 1.0 } else { -1.0 }, 0.2) + rand3(rng) * 0.2).normalize();
            let tangent = |v: DVec3| v - n * n.dot(v);
            let dp_du = tangent(rand3(rng)) + n * 0.1 * rng.next_1d() as f64 + n.any_orthonormal_vector();
            let dp_dv = tangent(rand3(rng)) + n.cross(dp_du) * 0.8;
            let (dn_du, dn_dv) = (tangent(rand3(rng)) * 0.7, tangent(rand3(rng)) * 0.7);
            ChainVertex::new(p, (dp_du, dp_dv), n, (dn_du, dn_dv), if refract(i) { 1.5 } else { 1.0 }).unwrap()
        })
        .collect()
}

/// Central differences of the constraints, one parameter of one vertex at a time.
fn numeric_column(chain: &[ChainVertex], vertex: usize, axis: usize, h: f64) -> Vec<DVec2> {
    let mut d = DVec2::ZERO;
    d[axis] = h;
    let at = |step: DVec2| {
        let mut c = chain.to_vec();
        c[vertex] = chain[vertex].moved(step);
        constraints(&c)
    };
    at(d).iter().zip(at(-d)).map(|(a, b)| (*a - b) / (2.0 * h)).collect()
}

/// The whole Jacobian (specular rows, every vertex's columns), dense.
fn dense(chain: &[ChainVertex], jac: &Jacobian) -> Vec<Vec<f64>> {
    let k = chain.len() - 2;
    let mut m = vec![vec![0.0; 2 * (k + 2)]; 2 * k];
    for i in 0..k {
        for (block, col) in [(jac.below[i], i), (jac.diagonal[i], i + 1), (jac.above[i], i + 2)] {
            for a in 0..2 {
                for r in 0..2 {
                    m[2 * i + r][2 * col + a] = block.col(a)[r];
                }
            }
        }
    }
    m
}

/// Determinant by Gaussian elimination with partial pivoting.
fn dense_determinant(mut m: Vec<Vec<f64>>) -> f64 {
    let n = m.len();
    let mut det = 1.0;
    for c in 0..n {
        let p = (c..n).max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs())).unwrap();
        if p != c {
            m.swap(p, c);
            det = -det;
        }
        det *= m[c][c];
        let (top, rest) = m.split_at_mut(c + 1);
        let pivot = &top[c];
        for row in rest {
            let f = row[c] / pivot[c];
            for (x, p) in row.iter_mut().zip(pivot).skip(c) {
                *x -= f * p;
            }
        }
    }
    det
}

#[test]
fn jacobian_matches_finite_differences() {
    let mut rng = Sampler::new(&[11]);
    for k in 1..=3 {
        for pattern in 0..4 {
            let refract = |i: usize| i >= 1 && i <= k && (pattern >> ((i - 1) % 2)) & 1 == 1;
            let c = chain(&mut rng, k, refract);
            let jac = jacobian(&c);
            let analytic = dense(&c, &jac);
            for vertex in 0..k + 2 {
                for axis in 0..2 {
                    let numeric = numeric_column(&c, vertex, axis, 1e-6);
                    for (i, n) in numeric.iter().enumerate() {
                        let a = DVec2::new(analytic[2 * i][2 * vertex + axis], analytic[2 * i + 1][2 * vertex + axis]);
                        assert!(
                            (a - *n).length() <= 1e-6 * (1.0 + n.length()),
                            "k {k}, pattern {pattern}, row {i}, vertex {vertex}, axis {axis}: {a} against {n}"
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn block_solve_and_determinant_match_dense_ones() {
    let mut rng = Sampler::new(&[12]);
    for k in 1..=4 {
        let c = chain(&mut rng, k, |i| i % 2 == 0);
        let jac = jacobian(&c);
        // The specular columns of the finite-difference Jacobian.
        let mut inner = vec![vec![0.0; 2 * k]; 2 * k];
        for vertex in 1..=k {
            for axis in 0..2 {
                for (i, n) in numeric_column(&c, vertex, axis, 1e-6).iter().enumerate() {
                    inner[2 * i][2 * (vertex - 1) + axis] = n.x;
                    inner[2 * i + 1][2 * (vertex - 1) + axis] = n.y;
                }
            }
        }
        let numeric_det = dense_determinant(inner.clone());
        // Hadamard's bound: the determinant's scale for the rows' sizes.
        let scale: f64 = inner.iter().map(|row| row.iter().map(|v| v * v).sum::<f64>().sqrt()).product();
        assert!(numeric_det.abs() > 1e-3 * scale, "k {k}: a well-conditioned test chain ({numeric_det}, {scale})");
        let det = jac.determinant();
        assert!((det - numeric_det).abs() <= 1e-6 * scale, "k {k}: {det} against {numeric_det}");
        let r: Vec<DVec2> = (0..k).map(|_| DVec2::new(rng.next_1d() as f64, rng.next_1d() as f64)).collect();
        let x = jac.solve(&r).unwrap();
        for (row, want) in inner.iter().zip(r.iter().flat_map(|v| [v.x, v.y])) {
            let got: f64 = row.iter().zip(x.iter().flat_map(|v| [v.x, v.y])).map(|(a, b)| a * b).sum();
            assert!((got - want).abs() < 1e-5, "k {k}: {got} against {want}");
        }
    }
}

#[test]
fn constraints_vanish_on_mirror_reflections_and_snell_refractions() {
    // A flat interface z = 0 (normal +z, glass of index 1.5 below), light from above.
    let surface = |eta: f64| {
        let (du, dv) = (DVec3::X, DVec3::Y);
        ChainVertex::new(DVec3::ZERO, (du, dv), DVec3::Z, (DVec3::ZERO, DVec3::ZERO), eta).unwrap()
    };
    let from = DVec3::new(-0.8, 0.3, 1.0);
    let wi = from.normalize();
    let mirrored = DVec3::new(-wi.x, -wi.y, wi.z);
    // Snell: the transmitted direction's tangential part is the incident one's over η.
    let refracted = |eta: f64| {
        let t = DVec3::new(-wi.x, -wi.y, 0.0) / eta;
        DVec3::new(t.x, t.y, -(1.0 - t.length_squared()).sqrt())
    };
    let c = |eta: f64, to: DVec3| constraint(from, &surface(eta), to * 2.0).length();
    assert!(c(1.0, mirrored) < 1e-12);
    assert!(c(1.5, refracted(1.5)) < 1e-12);
    // Seen from inside: the same path reversed.
    assert!(constraint(refracted(1.5) * 2.0, &surface(1.5), from).length() < 1e-12);
    // Bent by the wrong index, or not bent, the constraint is not met.
    assert!(c(1.5, refracted(1.0 / 1.5)) > 1e-2 && c(1.5, refracted(1.0)) > 1e-2);
    assert!(c(1.0, mirrored + DVec3::new(0.05, 0.0, 0.0)) > 1e-2);
}

fn scene(shapes: &str) -> Scene {
    let text = format!(
        r#"<scene version="3.0.0">
<sensor type="perspective"><float name="fov" value="40"/><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
<emitter type="point"><point name="position" x="0" y="0" z="50"/></emitter>
{shapes}
</scene>"#
    );
    Scene::load_str(&text, std::path::Path::new("manifold.xml"), &crate::scene::LoadOptions::default()).unwrap()
}

const GLASS_BALL: &str = r#"<shape type="sphere"><point name="center" x="0" y="0" z="0"/><float name="radius" value="1"/><bsdf type="dielectric"/></shape>"#;
const MIRROR_FLOOR: &str = r#"<shape type="rectangle"><transform name="to_world"><scale value="10"/><translate z="-2"/></transform><bsdf type="conductor"/></shape>"#;
const DIFFUSE_FLOOR: &str = r#"<shape type="rectangle"><transform name="to_world"><scale value="10"/><translate z="-2"/></transform><bsdf type="diffuse"/></shape>"#;
const NEAR_FLOOR: &str = r#"<shape type="rectangle"><transform name="to_world"><scale value="10"/><translate z="-1.2"/></transform><bsdf type="diffuse"/></shape>"#;
const MIRROR_WALL: &str = r#"<shape type="rectangle"><transform name="to_world"><rotate y="1" angle="-90"/><scale value="3"/><translate x="3" z="1"/></transform><bsdf type="conductor"/></shape>"#;
const CEILING: &str = r#"<shape type="rectangle"><transform name="to_world"><rotate x="1" angle="180"/><scale value="10"/><translate z="4"/></transform><bsdf type="diffuse"/></shape>"#;

/// Walks the chain traced from `start` towards `aim` to its end moved by `offset`, and
/// checks the result: the end at the target, the shapes kept, the constraints met.
fn check_walk(scene: &Scene, start: Vec3, aim: Vec3, scatters: &[Scatter], shapes: &[u32], offset: Vec3) {
    let chain = trace(scene, (start, Vec3::ZERO), aim, (scatters, &[]), shapes).expect("the test chain traces");
    assert_eq!(chain.scatters(), scatters);
    let target = chain.end().p + offset;
    let walk = walk(scene, &chain, target, 1e-5);
    let walked = walk.chain.unwrap_or_else(|| panic!("{scatters:?}: no convergence in {} steps", walk.iterations));
    assert!((walked.end().p - target).length() < 1e-4, "{scatters:?}: {} against {target}", walked.end().p);
    assert_eq!(walked.hits.iter().map(|h| h.shape).collect::<Vec<_>>(), shapes);
    assert!((walked.hits[0].p - chain.hits[0].p).length() > 1e-3, "the first vertex moves");
    // The re-traced chain scatters exactly at its hits, but each ray leaves its surface
    // from a point moved off it by the ray epsilon: the constraints from the hits hold to
    // a few times that.
    let epsilon = crate::math::RAY_EPSILON as f64;
    for c in constraints(&walked.vertices(scene).unwrap()) {
        assert!(c.length() < 10.0 * epsilon, "{scatters:?}: constraint {c}");
    }
}

#[test]
fn walks_reach_their_targets_through_reflections_and_refractions() {
    use Scatter::*;
    // One mirror reflection up to a ceiling.
    let s = scene(&format!("{MIRROR_FLOOR}{CEILING}"));
    check_walk(
        &s,
        Vec3::new(-1.0, 0.3, 1.0),
        Vec3::new(0.0, 0.0, -2.0),
        &[Reflect],
        &[0, 1],
        Vec3::new(0.2, -0.1, 0.0),
    );
    // Two refractions through a glass ball onto a floor.
    let s = scene(&format!("{GLASS_BALL}{DIFFUSE_FLOOR}"));
    check_walk(
        &s,
        Vec3::new(0.3, 0.2, 5.0),
        Vec3::new(0.3, 0.2, 0.0),
        &[Refract, Refract],
        &[0, 0, 1],
        Vec3::new(0.05, -0.03, 0.0),
    );
    // A mirror on a wall, then two refractions through the ball onto the floor.
    let s = scene(&format!("{GLASS_BALL}{DIFFUSE_FLOOR}{MIRROR_WALL}"));
    check_walk(
        &s,
        Vec3::new(-2.0, 0.1, 3.0),
        Vec3::new(3.0, 0.1, 1.3),
        &[Reflect, Refract, Refract],
        &[2, 0, 0, 1],
        Vec3::new(0.1, 0.05, 0.0),
    );
}

/// The solid-angle density from walks to the end moved by `±h` along `dp/du` and
/// `dp/dv`: the start's directions' central differences, their cross product over the
/// end's area.
fn walked_density(scene: &Scene, chain: &TracedChain, h: f32) -> f64 {
    let vertices = chain.vertices(scene).unwrap();
    let end = vertices.last().unwrap();
    let direction = |offset: DVec3| {
        let target = chain.end().p + offset.as_vec3();
        let w = walk(scene, chain, target, 1e-5);
        let walked =
            w.chain.unwrap_or_else(|| panic!("{offset} from {}: not reached in {} steps", chain.end().p, w.iterations));
        (walked.hits[0].p - chain.start).normalize().as_dvec3()
    };
    let h64 = h as f64;
    let dw_du = (direction(end.dp_du * h64) - direction(-end.dp_du * h64)) / (2.0 * h64);
    let dw_dv = (direction(end.dp_dv * h64) - direction(-end.dp_dv * h64)) / (2.0 * h64);
    dw_du.cross(dw_dv).length() / end.dp_du.cross(end.dp_dv).length()
}

#[test]
fn solid_angle_density_is_the_walks_and_a_mirrors_unfolded_one() {
    use Scatter::*;
    // A flat mirror: the end seen in the mirror is at the unfolded distance.
    let s = scene(&format!("{MIRROR_FLOOR}{CEILING}"));
    let chain =
        trace(&s, (Vec3::new(-1.0, 0.3, 1.0), Vec3::ZERO), Vec3::new(0.0, 0.0, -2.0), (&[Reflect], &[]), &[0, 1])
            .unwrap();
    let v = chain.vertices(&s).unwrap();
    let unfolded = (v[1].p - v[0].p).length() + (v[2].p - v[1].p).length();
    let cos_end = v[2].n.dot((v[1].p - v[2].p).normalize()).abs();
    let analytic = solid_angle_density(&v).unwrap();
    let expected = cos_end / (unfolded * unfolded);
    assert!((analytic / expected - 1.0).abs() < 1e-5, "{analytic} against {expected}");
    let walked = walked_density(&s, &chain, 5e-4);
    assert!((walked / analytic - 1.0).abs() < 1e-2, "mirror: walks {walked} against {analytic}");
    // Through the glass ball, and through a mirror and the ball, onto a floor just below
    // it (the ball focuses light near z = -2, where the density has a caustic).
    let s = scene(&format!("{GLASS_BALL}{NEAR_FLOOR}{MIRROR_WALL}"));
    for (start, aim, scatters, shapes) in [
        (Vec3::new(0.3, 0.2, 5.0), Vec3::new(0.3, 0.2, 0.0), &[Refract, Refract][..], &[0, 0, 1][..]),
        (Vec3::new(-2.0, 0.1, 3.0), Vec3::new(3.0, 0.1, 1.3), &[Reflect, Refract, Refract], &[2, 0, 0, 1]),
    ] {
        let chain = trace(&s, (start, Vec3::ZERO), aim, (scatters, &[]), shapes).unwrap();
        let analytic = solid_angle_density(&chain.vertices(&s).unwrap()).unwrap();
        let walked = walked_density(&s, &chain, 5e-4);
        assert!((walked / analytic - 1.0).abs() < 1e-2, "{scatters:?}: walks {walked} against {analytic}");
        // Without the refractions' bending the density is another: the test resolves it.
        let straight = 1.0 / (chain.end().p - chain.start).length_squared() as f64;
        assert!((straight / analytic - 1.0).abs() > 0.1, "{scatters:?}");
    }
}

/// `n_end / n_start`: the refractive index of the medium at the chain's end over that at its
/// start, from the refractions on the way (entering a surface from its front multiplies by
/// its relative index, leaving divides by it).
fn index_ratio(vertices: &[ChainVertex], scatters: &[Scatter]) -> f64 {
    let mut ratio = 1.0;
    for (i, scatter) in scatters.iter().enumerate() {
        let (prev, x) = (&vertices[i], &vertices[i + 1]);
        if *scatter == Scatter::Refract && x.eta != 1.0 {
            if (prev.p - x.p).dot(x.n) > 0.0 {
                ratio *= x.eta;
            } else {
                ratio /= x.eta;
            }
        }
    }
    ratio
}

/// `dω_{k+1}/dA_0` of a chain of Dirac vertices by the reciprocity of the generalized
/// geometric term (étendue `n² cos dA dω` is the same at both ends of a bundle of rays):
/// `(n_0 / n_{k+1})² (cos θ_0 / cos θ_{k+1})` times `dω_0/dA_{k+1}`, with the cosines to
/// the geometric normals.
fn etendue_density(scene: &Scene, chain: &TracedChain) -> f64 {
    let vertices = chain.vertices(scene).unwrap();
    let forward = solid_angle_density(&vertices).unwrap();
    let ratio = index_ratio(&vertices, &chain.scatters());
    let first = chain.hits[0].p;
    let before_end = if chain.hits.len() >= 2 { chain.hits[chain.hits.len() - 2].p } else { chain.start };
    let end = chain.end();
    let cos_start = chain.start_ng.dot((first - chain.start).normalize()).abs() as f64;
    let cos_end = end.ng.dot((before_end - end.p).normalize()).abs() as f64;
    forward * cos_start / cos_end / (ratio * ratio)
}

/// The chain traced back from `chain`'s end (on a surface) to its start's surface: the
/// same vertices in the other order, with the start's real tangent frame at its end.
fn reversed(scene: &Scene, chain: &TracedChain, start_shape: u32) -> TracedChain {
    let end = chain.end();
    let mut scatters = chain.scatters();
    scatters.reverse();
    let mut shapes: Vec<u32> = chain.hits[..chain.hits.len() - 1].iter().rev().map(|h| h.shape).collect();
    shapes.push(start_shape);
    let aim = chain.hits[chain.hits.len() - 2].p;
    let mut halves = chain.halves.clone();
    halves.reverse();
    trace(scene, (end.p, end.ng), aim, (&scatters, &halves), &shapes).expect("the reversed chain traces")
}

#[test]
fn end_solid_angle_density_is_the_reversed_chains() {
    use Scatter::*;
    // A dielectric half-space below z = 0 over a floor inside it: the chain's two ends lie
    // in media of different indices (the étendue's n² enters).
    const WATER: &str = r#"<shape type="rectangle"><transform name="to_world"><scale value="10"/></transform><bsdf type="dielectric"><float name="int_ior" value="1.33"/></bsdf></shape>"#;
    const SUNK_FLOOR: &str = r#"<shape type="rectangle"><transform name="to_world"><scale value="10"/><translate z="-1"/></transform><bsdf type="diffuse"/></shape>"#;
    let cases = [
        (
            format!("{GLASS_BALL}{NEAR_FLOOR}{CEILING}"),
            2u32,
            Vec3::new(2.5, 0.5, 4.0),
            Vec3::new(0.3, 0.2, 0.0),
            vec![Refract, Refract],
            vec![0u32, 0, 1],
            true,
        ),
        (
            format!("{MIRROR_FLOOR}{CEILING}"),
            1,
            Vec3::new(-1.0, 0.3, 4.0),
            Vec3::new(0.0, 0.0, -2.0),
            vec![Reflect],
            vec![0, 1],
            false,
        ),
        (
            format!("{WATER}{SUNK_FLOOR}{CEILING}"),
            2,
            Vec3::new(-0.7, 0.3, 4.0),
            Vec3::new(0.0, 0.0, 0.0),
            vec![Refract],
            vec![0, 1],
            true,
        ),
    ];
    for (shapes_xml, start_shape, start, aim, scatters, shapes, asymmetric) in cases {
        let s = scene(&shapes_xml);
        let ng = Vec3::new(0.0, 0.0, -1.0);
        let chain = trace(&s, (start, ng), aim, (&scatters, &[]), &shapes).expect("the test chain traces");
        let back = reversed(&s, &chain, start_shape);
        assert!((back.end().p - start).length() < 1e-3, "{scatters:?}: the reversed chain returns");
        let expected = solid_angle_density(&back.vertices(&s).unwrap()).unwrap();
        let got = chain.end_solid_angle_density(&s).unwrap();
        // The walks work from either end.
        let walked = walked_density(&s, &back, 5e-4);
        assert!((walked / expected - 1.0).abs() < 1e-2, "{scatters:?}: reversed walks {walked} against {expected}");
        assert!((got / expected - 1.0).abs() < 1e-3, "{scatters:?}: {got} against {expected}");
        // And both are the étendue's reciprocity.
        let etendue = etendue_density(&s, &chain);
        assert!((etendue / expected - 1.0).abs() < 1e-3, "{scatters:?}: étendue {etendue} against {expected}");
        // Without the cosines' ratio (or the indices', in the water) it would be another
        // (a mirror between two points of one plane gives both ends the same cosine).
        if !asymmetric {
            continue;
        }
        let forward = solid_angle_density(&chain.vertices(&s).unwrap()).unwrap();
        assert!((forward / expected - 1.0).abs() > 0.05, "{scatters:?}: {forward} against {expected}");
    }
}

#[test]
fn lobe_half_angles_hold_ninety_percent_of_the_lobe() {
    use crate::bsdf::microfacet::{Microfacet, MicrofacetType};
    for kind in [MicrofacetType::Beckmann, MicrofacetType::Ggx] {
        for alpha in [0.05f32, 0.2, 0.6] {
            let m = Microfacet { kind, alpha_u: alpha, alpha_v: alpha, sample_visible: false };
            // ∫ D(m) cos θ dω over the cap θ < θ_d, by the midpoint rule in θ (the
            // distribution is isotropic: 2π sin θ dθ).
            let theta_d = lobe_half_angle(kind, alpha as f64);
            let cap = |limit: f64| {
                let n = 20_000;
                (0..n)
                    .map(|i| {
                        let t = (i as f64 + 0.5) / n as f64 * limit;
                        let h = Vec3::new(t.sin() as f32, 0.0, t.cos() as f32);
                        m.d(h) as f64 * t.cos() * 2.0 * std::f64::consts::PI * t.sin() * limit / n as f64
                    })
                    .sum::<f64>()
            };
            let (inside, all) = (cap(theta_d), cap(std::f64::consts::FRAC_PI_2));
            assert!((all - 1.0).abs() < 2e-3, "{kind:?} α {alpha}: D cos integrates to {all}");
            assert!((inside / all - 0.9).abs() < 2e-3, "{kind:?} α {alpha}: {inside} of {all}");
        }
    }
}

#[test]
fn nonspecular_probability_goes_from_mirror_to_diffuse() {
    let diff = 1f64.to_radians();
    assert_eq!(nonspecular_probability(None, diff), 1.0);
    assert_eq!(nonspecular_probability(Some(0.0), diff), 0.0);
    let p = |alpha: f64| {
        nonspecular_probability(Some(lobe_half_angle(crate::bsdf::microfacet::MicrofacetType::Beckmann, alpha)), diff)
    };
    let ps: Vec<f64> = [1e-4, 1e-3, 0.01, 0.1, 0.5, 2.0].iter().map(|&a| p(a)).collect();
    assert!(ps.windows(2).all(|w| w[0] < w[1]), "rougher lobes are walked over less often: {ps:?}");
    assert!(ps[0] < 1e-3 && ps[5] > 0.9, "{ps:?}");
    // (1 - cos θ_d) / (1 - cos 2θ_d) when the lobe is as wide as the changes: about ¼.
    let q = nonspecular_probability(Some(diff), diff);
    assert!((q - (1.0 - diff.cos()) / (1.0 - (2.0 * diff).cos())).abs() < 1e-12 && (q - 0.25).abs() < 1e-3);
}

#[test]
fn walks_are_reversible() {
    use Scatter::*;
    let s = scene(&format!("{GLASS_BALL}{NEAR_FLOOR}{MIRROR_WALL}"));
    for (start, aim, scatters, shapes) in [
        (Vec3::new(0.3, 0.2, 5.0), Vec3::new(0.3, 0.2, 0.0), &[Refract, Refract][..], &[0, 0, 1][..]),
        (Vec3::new(-2.0, 0.1, 3.0), Vec3::new(3.0, 0.1, 1.3), &[Reflect, Refract, Refract], &[2, 0, 0, 1]),
    ] {
        let current = trace(&s, (start, Vec3::ZERO), aim, (scatters, &[]), shapes).unwrap();
        let proposal = walk(&s, &current, current.end().p + Vec3::new(0.05, -0.04, 0.0), 1e-5).chain.unwrap();
        assert!(returns_to(&s, &proposal, &current, 1e-5), "{scatters:?}");
        // A chain through other points is not where the walk back goes.
        let other = trace(&s, (start, Vec3::ZERO), aim + Vec3::new(0.0, 0.1, 0.0), (scatters, &[]), shapes).unwrap();
        let mut elsewhere = other.clone();
        elsewhere.hits.last_mut().unwrap().p = current.end().p;
        assert!(!returns_to(&s, &proposal, &elsewhere, 1e-5), "{scatters:?}");
    }
}

#[test]
fn walks_to_unreachable_targets_fail() {
    // Light refracted twice by the ball reaches the floor only near its axis.
    let s = scene(&format!("{GLASS_BALL}{DIFFUSE_FLOOR}"));
    let scatters = [Scatter::Refract, Scatter::Refract];
    let chain =
        trace(&s, (Vec3::new(0.3, 0.2, 5.0), Vec3::ZERO), Vec3::new(0.3, 0.2, 0.0), (&scatters, &[]), &[0, 0, 1])
            .unwrap();
    let w = walk(&s, &chain, Vec3::new(8.0, 8.0, -2.0), 1e-5);
    assert!(w.chain.is_none() && w.iterations > 5, "{} iterations", w.iterations);
}

#[test]
fn following_the_end_keeps_the_constraints_to_second_order() {
    // Moving the end by `ε d` and the specular vertices by the tangent map's `ε Δ`
    // changes the constraints by O(ε²); moving the end alone changes them by O(ε).
    let mut rng = Sampler::new(&[13]);
    for k in 1..=3 {
        let c = chain(&mut rng, k, |i| i == 1);
        let jac = jacobian(&c);
        let d = DVec2::new(0.6, -0.8);
        let steps = jac.follow_end(d).unwrap();
        let change = |eps: f64, follow: bool| {
            let mut moved = c.clone();
            moved[k + 1] = c[k + 1].moved(d * eps);
            if follow {
                for (i, s) in steps.iter().enumerate() {
                    moved[i + 1] = c[i + 1].moved(*s * eps);
                }
            }
            let before = constraints(&c);
            constraints(&moved).iter().zip(&before).map(|(a, b)| (*a - *b).length()).fold(0.0, f64::max)
        };
        let (followed, alone) = (change(1e-4, true), change(1e-4, false));
        assert!(followed < 1e-6 && alone > 1e-6, "k {k}: followed {followed}, end alone {alone}");
        // Second order: a ten times smaller step, a hundred times smaller change.
        assert!(change(1e-5, true) < followed / 30.0, "k {k}");
    }
}

/// A unit vector `tilt` radians off `n` (about a random axis).
fn tilted(rng: &mut Sampler, n: DVec3, tilt: f64) -> DVec3 {
    let axis = n.cross(rand3(rng)).normalize();
    (n * tilt.cos() + axis * tilt.sin()).normalize()
}

#[test]
fn kept_half_vectors_are_kept_and_their_density_is_the_directions() {
    use Scatter::*;
    let mut rng = Sampler::new(&[41]);
    let mut refractions = 0;
    for case in 0..400 {
        let n = rand3(&mut rng).normalize();
        let (eta, scatter) = [(1.0, Reflect), (1.5, Refract), (1.33, Reflect)][case % 3];
        // From either side of the surface.
        let side = if case % 2 == 0 { 1.0 } else { -1.0 };
        let (a, b) = (1.2 * rng.next_1d() as f64, 0.3 * rng.next_1d() as f64);
        let wi = tilted(&mut rng, n * side, a);
        let m = tilted(&mut rng, n, b);
        // A transmission's half-vector may point to either side: the one that gives a
        // direction is kept.
        let Some(wo) = scatter_about(wi, m, n, eta, scatter).or_else(|| scatter_about(wi, -m, n, eta, scatter)) else {
            continue;
        };
        let h = half_vector(wi, wo, n, eta);
        assert!((h.dot(m).abs() - 1.0).abs() < 1e-9, "case {case}: half-vector {h} against {m}");
        refractions += usize::from(scatter == Refract);
        // The density against central differences of the tangential half-vector in `wo`.
        let (s, t) = n.any_orthonormal_pair();
        let (e1, e2) = wo.any_orthonormal_pair();
        let c = |w: DVec3| {
            let h = half_vector(wi, w.normalize(), n, eta);
            DVec2::new(h.dot(s), h.dot(t))
        };
        let d = 1e-6;
        let column = |e: DVec3| (c(wo + e * d) - c(wo - e * d)) / (2.0 * d);
        let numeric = DMat2::from_cols(column(e1), column(e2)).determinant().abs();
        let density = half_vector_density(wi, wo, n, eta);
        assert!((density / numeric - 1.0).abs() < 1e-5, "case {case}: {density} against {numeric}");
        // A reflection's formula (no index, no projection onto the tangent plane) would not do.
        let plain = 1.0 / (4.0 * wo.dot(h).abs());
        if scatter == Refract {
            assert!((plain / numeric - 1.0).abs() > 1e-3, "case {case}");
        }
    }
    assert!(refractions > 50, "{refractions} refractions tried");
}

/// A chain through the glass ball onto the near floor whose two refractions keep
/// half-vectors tilted off their normals (a rough ball's glossy vertices treated as
/// specular), with its end on the floor.
fn offset_chain(s: &Scene) -> TracedChain {
    use Scatter::*;
    let start = Vec3::new(2.5, 0.5, 4.0);
    let plain =
        trace(s, (start, Vec3::new(0.0, 0.0, -1.0)), Vec3::new(0.3, 0.2, 0.0), (&[Refract, Refract], &[]), &[0, 0, 1])
            .expect("the plain chain traces");
    let mut rng = Sampler::new(&[43]);
    let v = plain.vertices(s).unwrap();
    let halves: Vec<Half> = (1..3)
        .map(|i| {
            let h = half_vector((v[i - 1].p - v[i].p).normalize(), (v[i + 1].p - v[i].p).normalize(), v[i].n, v[i].eta);
            Half::Local(v[i].to_local(tilted(&mut rng, h, 0.2)))
        })
        .collect();
    let chain = trace(
        s,
        (start, Vec3::new(0.0, 0.0, -1.0)),
        Vec3::new(0.3, 0.2, 0.0),
        (&[Refract, Refract], &halves),
        &[0, 0, 1],
    )
    .expect("the offset chain traces");
    assert!((chain.end().p - plain.end().p).length() > 0.05, "the offsets move the chain");
    chain
}

#[test]
fn offset_chains_walk_keeping_their_half_vectors_and_their_densities_hold() {
    let s = scene(&format!("{GLASS_BALL}{NEAR_FLOOR}{CEILING}"));
    let chain = offset_chain(&s);
    let offsets = |c: &TracedChain| -> Vec<DVec2> {
        c.halves.iter().map(|h| if let Half::Local(m) = h { DVec2::new(m.x, m.y) } else { DVec2::ZERO }).collect()
    };
    // The walk reaches its target with every constraint at its offset.
    let target = chain.end().p + Vec3::new(0.05, -0.03, 0.0);
    let walked = walk(&s, &chain, target, 1e-5).chain.expect("the offset chain walks");
    assert!((walked.end().p - target).length() < 1e-4);
    assert_eq!(offsets(&walked), offsets(&chain));
    let epsilon = crate::math::RAY_EPSILON as f64;
    for (c, o) in constraints(&walked.vertices(&s).unwrap()).iter().zip(offsets(&chain)) {
        assert!((*c - o).length() < 10.0 * epsilon, "constraint {c} against its offset {o}");
        assert!(o.length() > 1e-2, "the offsets are not zero");
    }
    // The tangent map of the offset chain gives the walks' densities at either end.
    let analytic = solid_angle_density(&chain.vertices(&s).unwrap()).unwrap();
    let walked_forward = walked_density(&s, &chain, 5e-4);
    assert!((walked_forward / analytic - 1.0).abs() < 3e-3, "walks {walked_forward} against {analytic}");
    let back = reversed(&s, &chain, 2);
    assert!((back.end().p - chain.start).length() < 1e-3, "the reversed offset chain returns");
    let expected = walked_density(&s, &back, 5e-4);
    let got = chain.end_solid_angle_density(&s).unwrap();
    assert!((got / expected - 1.0).abs() < 3e-3, "{got} against the reversed walks' {expected}");
    // Offsets do not conserve étendue: its reciprocity would be another density here.
    let etendue = etendue_density(&s, &chain);
    assert!((etendue / expected - 1.0).abs() > 1e-2, "étendue {etendue} against {expected}");
}

/// An offset half-vector with its constraint coordinate `axis` (`ĥ·s` or `ĥ·t`) moved by `e`,
/// on the same side of the tangent plane.
fn nudged(half: Half, axis: usize, e: f64) -> Half {
    let Half::Local(m) = half else { panic!("an offset vertex") };
    let mut t = DVec2::new(m.x, m.y);
    t[axis] += e;
    Half::Local(DVec3::new(t.x, t.y, m.z.signum() * (1.0 - t.length_squared()).sqrt()))
}

/// `|det ∂(x_g …) / ∂(C_g …)|` over a chain's specular vertices `x_g` that keep offset
/// half-vectors, its start and end fixed (and its other specular vertices on their
/// constraints), by central differences: each offset moved, the chain re-traced and walked
/// back to its end, those vertices' moves measured in their tangent planes (area).
fn offset_jacobian(s: &Scene, chain: &TracedChain, d: f64) -> f64 {
    let offsets: Vec<usize> = (0..chain.halves.len()).filter(|&j| matches!(chain.halves[j], Half::Local(_))).collect();
    let positions = |c: &TracedChain| -> Vec<DVec3> { offsets.iter().map(|&j| c.hits[j].p.as_dvec3()).collect() };
    let moved = |j: usize, axis: usize, e: f64| -> Vec<DVec3> {
        let mut halves = chain.halves.clone();
        halves[j] = nudged(halves[j], axis, e);
        let shapes: Vec<u32> = chain.hits.iter().map(|h| h.shape).collect();
        let first = trace(s, (chain.start, chain.start_ng), chain.hits[0].p, (&chain.scatters(), &halves), &shapes)
            .expect("the moved chain traces");
        positions(&walk(s, &first, chain.end().p, 2e-6).chain.expect("the moved chain walks back"))
    };
    let bases: Vec<(DVec3, DVec3)> =
        offsets.iter().map(|&j| chain.hits[j].ng.as_dvec3().any_orthonormal_pair()).collect();
    let n = 2 * offsets.len();
    let mut m = vec![vec![0.0; n]; n];
    for (c, &j) in offsets.iter().enumerate() {
        for axis in 0..2 {
            let (plus, minus) = (moved(j, axis, d), moved(j, axis, -d));
            for (i, (u, v)) in bases.iter().enumerate() {
                let dp = (plus[i] - minus[i]) / (2.0 * d);
                m[2 * i][2 * c + axis] = dp.dot(*u);
                m[2 * i + 1][2 * c + axis] = dp.dot(*v);
            }
        }
    }
    dense_determinant(m).abs()
}

/// The finite-difference step of the Jacobians of traced chains (see the first use).
const FD_STEP: f64 = 4e-3;

#[test]
fn offset_chains_give_their_vertices_the_density_the_perturbation_reports() {
    // With the chain's ends fixed, the glossy vertices' positions per unit of their kept
    // half-vectors' coordinates are `dω_end/dA_start` over the product, along the chain from
    // its end to its start, of each vertex's area factor and each kept half-vector's
    // density of the direction leaving it (the manifold perturbation's `b … c` density).
    let s = scene(&format!("{GLASS_BALL}{NEAR_FLOOR}{CEILING}"));
    let chain = offset_chain(&s);
    let v: Vec<DVec3> =
        std::iter::once(chain.start.as_dvec3()).chain(chain.hits.iter().map(|h| h.p.as_dvec3())).collect();
    let ng: Vec<DVec3> =
        std::iter::once(chain.start_ng.as_dvec3()).chain(chain.hits.iter().map(|h| h.ng.as_dvec3())).collect();
    let k = chain.halves.len();
    // Travelling from the end (index k + 1) to the start (index 0).
    let area_factor = |j: usize, from: usize| {
        let d = v[from] - v[j];
        ng[j].dot(d).abs() / d.length_squared() / d.length()
    };
    let mut product = 1.0;
    for j in (0..=k).rev() {
        product *= area_factor(j, j + 1);
        if j >= 1 {
            let si = &chain.hits[j - 1];
            let n = si.shading.n.as_dvec3().normalize();
            let eta = s.bsdf(si).eta() as f64;
            product *= half_vector_density((v[j + 1] - v[j]).normalize(), (v[j - 1] - v[j]).normalize(), n, eta);
        }
    }
    let expected = chain.end_solid_angle_density(&s).unwrap() / product;
    // The step is large enough that the rounding of the traced (`f32`) positions, which
    // differs between Embree's ISAs, stays far below the tolerance: at 1e-3 it moved the
    // determinant by 0.5% on an AVX2 machine, at 4e-3 by 0.04% (the truncation error with it).
    let numeric = offset_jacobian(&s, &chain, FD_STEP);
    assert!((numeric / expected - 1.0).abs() < 3e-3, "{numeric} against {expected}");
    // Without the kept half-vectors' densities it would be another.
    let without: f64 = (1..=k)
        .map(|j| {
            let si = &chain.hits[j - 1];
            half_vector_density(
                (v[j + 1] - v[j]).normalize(),
                (v[j - 1] - v[j]).normalize(),
                si.shading.n.as_dvec3(),
                s.bsdf(si).eta() as f64,
            )
        })
        .product::<f64>()
        * expected;
    assert!((without / numeric - 1.0).abs() > 0.1, "{without} against {numeric}");
}

#[test]
fn kept_half_vectors_followed_from_a_point_give_the_density_the_perturbation_reports() {
    // A chain followed from a fixed point `a` along a direction, every vertex keeping its
    // half-vector: the positions per unit of `a`'s direction and of the half-vectors'
    // coordinates are one over the product of the area factors and the kept half-vectors'
    // densities along the way (the map is triangular: each vertex depends on the direction
    // and the half-vectors before it).
    let s = scene(&format!("{GLASS_BALL}{NEAR_FLOOR}{CEILING}"));
    let a = Vec3::new(2.5, 0.5, 4.0);
    let offset = offset_chain(&s);
    let shapes: Vec<u32> = offset.hits.iter().map(|h| h.shape).collect();
    let chain = trace(&s, (a, Vec3::ZERO), offset.hits[0].p, (&offset.scatters(), &offset.halves), &shapes).unwrap();
    let shapes: Vec<u32> = chain.hits.iter().map(|h| h.shape).collect();
    let scatters = chain.scatters();
    let k = chain.halves.len();
    let w = (chain.hits[0].p - a).normalize().as_dvec3();
    let (e1, e2) = w.any_orthonormal_pair();
    let bases: Vec<(DVec3, DVec3)> = chain.hits.iter().map(|h| h.ng.as_dvec3().any_orthonormal_pair()).collect();
    // Column `c` of the map: 0, 1 turn `a`'s direction, 2 + 2j + axis move half-vector `j`.
    let positions = |c: usize, e: f64| -> Vec<DVec3> {
        let mut halves = chain.halves.clone();
        let mut dir = w;
        if c < 2 {
            dir = (w + [e1, e2][c] * e).normalize();
        } else {
            let (j, axis) = ((c - 2) / 2, (c - 2) % 2);
            halves[j] = nudged(halves[j], axis, e);
        }
        let aim = a + (dir * 2.0).as_vec3();
        let traced = trace(&s, (a, Vec3::ZERO), aim, (&scatters, &halves), &shapes).expect("the moved chain traces");
        traced.hits.iter().map(|h| h.p.as_dvec3()).collect()
    };
    let n = 2 * (k + 1);
    let d = FD_STEP;
    let columns: Vec<Vec<f64>> = (0..n)
        .map(|c| {
            let (plus, minus) = (positions(c, d), positions(c, -d));
            let dp = |i: usize| (plus[i] - minus[i]) / (2.0 * d);
            bases.iter().enumerate().flat_map(|(i, (u, v))| [dp(i).dot(*u), dp(i).dot(*v)]).collect()
        })
        .collect();
    let m: Vec<Vec<f64>> = (0..n).map(|r| columns.iter().map(|col| col[r]).collect()).collect();
    let numeric = dense_determinant(m).abs();
    let v: Vec<DVec3> = std::iter::once(a.as_dvec3()).chain(chain.hits.iter().map(|h| h.p.as_dvec3())).collect();
    let (mut product, mut kept) = (1.0, 1.0);
    for j in 1..=k + 1 {
        let dv = v[j - 1] - v[j];
        product *= chain.hits[j - 1].ng.as_dvec3().dot(dv).abs() / dv.length_squared() / dv.length();
        if j <= k {
            let si = &chain.hits[j - 1];
            let n = si.shading.n.as_dvec3().normalize();
            kept *= half_vector_density(dv.normalize(), (v[j + 1] - v[j]).normalize(), n, s.bsdf(si).eta() as f64);
        }
    }
    let expected = 1.0 / (product * kept);
    assert!((numeric / expected - 1.0).abs() < 3e-3, "{numeric} against {expected}");
    // Without the kept half-vectors' densities it would be another.
    assert!((numeric * product - 1.0).abs() > 0.1, "{} against 1", numeric * product);
}

#[test]
fn a_chain_of_dirac_and_offset_vertices_gives_the_density_the_perturbation_reports() {
    // The glass ball's chain with its first crossing keeping an offset half-vector and its
    // second a Dirac refraction. Travelling from the end `b` (on the floor) to the start `c`,
    // the offset vertex's position per unit of its half-vector's coordinates is
    // `dω_b/dA_c` over `dω_b/dA_g` through the Dirac crossing, the area factor of `c` from
    // `g`, and the kept half-vector's density of the direction leaving `g` towards `c`.
    let s = scene(&format!("{GLASS_BALL}{NEAR_FLOOR}{CEILING}"));
    let offset = offset_chain(&s);
    let mut halves = offset.halves.clone();
    halves[1] = Half::Normal;
    let shapes: Vec<u32> = offset.hits.iter().map(|h| h.shape).collect();
    let chain = trace(&s, (offset.start, offset.start_ng), offset.hits[0].p, (&offset.scatters(), &halves), &shapes)
        .expect("the mixed chain traces");
    let v = chain.vertices(&s).unwrap();
    let (c, g) = (v[0].p, v[1].p);
    // `dω_b/dA_g` through the Dirac crossing: the sub-chain from the end to `g`.
    let through_dirac = solid_angle_density(&[v[3], v[2], v[1]]).unwrap();
    let to_c = c - g;
    let area_c = chain.start_ng.as_dvec3().dot(to_c).abs() / to_c.length_squared() / to_c.length();
    let si = &chain.hits[0];
    let kept = half_vector_density((v[2].p - g).normalize(), to_c.normalize(), v[1].n, s.bsdf(si).eta() as f64);
    let expected = chain.end_solid_angle_density(&s).unwrap() / (through_dirac * area_c * kept);
    let numeric = offset_jacobian(&s, &chain, FD_STEP);
    assert!((numeric / expected - 1.0).abs() < 3e-3, "{numeric} against {expected}");
    // The area factors along the Dirac crossing in place of its generalized geometric term
    // would give another density (the ball's curvature focuses the chain).
    let factor = |a: DVec3, b: DVec3, n: DVec3| n.dot(a - b).abs() / (a - b).length_squared() / (a - b).length();
    let along = factor(v[3].p, v[2].p, v[2].n) * factor(v[2].p, v[1].p, si.ng.as_dvec3());
    let naive = expected * through_dirac / along;
    assert!((naive / numeric - 1.0).abs() > 0.05, "{naive} against {numeric}");
}
