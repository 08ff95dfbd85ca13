//! Helpers shared by the integration tests.
#![allow(dead_code)]

use pcbpt::accel::Backend;
use pcbpt::compare::{self, Metrics};
use pcbpt::image_io::{self, Image};
use pcbpt::integrator::{self, Budget, IntegratorKind, RenderOptions, RenderOutput};
use pcbpt::scene::{LoadOptions, Scene};
use std::path::{Path, PathBuf};

pub mod distributed;
pub mod hits;

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn load(path: &Path, defines: &[(&str, &str)], backend: Backend) -> Scene {
    load_at(path, defines, None, backend)
}

/// [`load`] with the film size replaced (`render --resolution`).
pub fn load_at(path: &Path, defines: &[(&str, &str)], resolution: Option<(u32, u32)>, backend: Backend) -> Scene {
    let overrides = defines.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
    Scene::load(path, &LoadOptions { overrides, backend, resolution, ..Default::default() })
        .unwrap_or_else(|e| panic!("{e}"))
}

pub fn render(scene: &Scene, kind: IntegratorKind, spp: u32, seed: u64, threads: usize) -> RenderOutput {
    render_with(scene, kind, spp, seed, threads, &|_| {})
}

/// As [`render`], with the options changed by `set` first.
pub fn render_with(
    scene: &Scene,
    kind: IntegratorKind,
    spp: u32,
    seed: u64,
    threads: usize,
    set: &dyn Fn(&mut RenderOptions),
) -> RenderOutput {
    let mut o = RenderOptions::new(kind, Budget::Spp(spp));
    o.run.seed = seed;
    o.run.threads = threads;
    set(&mut o);
    integrator::render(scene, &o).unwrap()
}

pub fn image(out: RenderOutput) -> Image {
    Image::new(out.width, out.height, out.image)
}

pub fn reference(name: &str) -> Image {
    image_io::read_exr(&root().join("tests/data").join(name)).unwrap_or_else(|e| panic!("{e}"))
}

/// The relMSE noise of one render, from two independent renders `a` and `b` of the same
/// estimator: `relMSE(a, b) / 2`, relative to the reference's values.
fn render_noise(reference: &Image, a: &Image, b: &Image) -> f64 {
    a.pixels
        .iter()
        .zip(&b.pixels)
        .zip(&reference.pixels)
        .map(|((x, y), r)| (0..3).map(|c| ((x[c] - y[c]) as f64).powi(2) / ((r[c] as f64).powi(2) + 0.01)).sum::<f64>())
        .sum::<f64>()
        / (3.0 * a.pixels.len() as f64)
        / 2.0
}

/// The verdict of a render against a reference: the image mean must agree within
/// `mean_tol`, and the relMSE must not exceed what the noise of the two renders explains.
///
/// The test's own noise is estimated from two renders with different seeds,
/// `noise = relMSE(A, B) / 2`; the reference, made by the same kind of estimator with
/// `ref_spp` samples, carries `noise * spp / ref_spp`. Bias (a wrong weight, a missing
/// bounce, a wrong pdf) shows up as relMSE in excess of that sum, which `excess_tol` bounds.
pub struct Verdict {
    pub metrics: Metrics,
    pub noise: f64,
    pub expected: f64,
    /// Pixels left out of the mean (see [`Verdict::excluding_emitters`]).
    pub excluded: usize,
}

impl Verdict {
    pub fn new(reference: &Image, a: &Image, b: &Image, spp: u32, ref_spp: u32) -> Verdict {
        let metrics = compare::metrics(reference, a).unwrap();
        let noise = render_noise(reference, a, b);
        let expected = noise * (1.0 + spp as f64 / ref_spp as f64);
        Verdict { metrics, noise, expected, excluded: 0 }
    }

    /// Judges the average of two independent renders `a` and `b` against a reference made
    /// by a different estimator, whose own relMSE noise `ref_noise` is given (measured from
    /// the path tracer's noise at the reference's sample count). The average carries half
    /// the noise of one render: `expected = relMSE(a, b) / 4 + ref_noise`.
    pub fn averaged(reference: &Image, a: &Image, b: &Image, ref_noise: f64) -> (Verdict, Image) {
        let avg = Image::new(a.width, a.height, a.pixels.iter().zip(&b.pixels).map(|(x, y)| (*x + *y) * 0.5).collect());
        let metrics = compare::metrics(reference, &avg).unwrap();
        let noise = render_noise(reference, a, b) / 2.0;
        (Verdict { metrics, noise, expected: noise + ref_noise, excluded: 0 }, avg)
    }

    /// Compares image means over the pixels whose reference value stays below `cutoff`:
    /// pixels that see a tiny, very bright emitter directly carry a large share of the mean
    /// and their estimate is pure pixel-coverage noise (in `veach-mis`, 6 pixels of 20 736
    /// hold 22% of the mean). relMSE still covers every pixel.
    pub fn excluding_emitters(self, reference: &Image, a: &Image, cutoff: f32) -> Verdict {
        let keep: Vec<bool> = reference.pixels.iter().map(|p| p.max_element() <= cutoff).collect();
        self.mean_over(reference, a, &keep)
    }

    /// Compares image means over the pixels `keep` marks alone.
    pub fn mean_over(mut self, reference: &Image, a: &Image, keep: &[bool]) -> Verdict {
        let sum = |img: &Image| {
            img.pixels.iter().zip(keep).filter(|(_, k)| **k).map(|(p, _)| (p.x + p.y + p.z) as f64).sum::<f64>()
        };
        self.excluded = keep.iter().filter(|k| !**k).count();
        self.metrics.mean_ratio = sum(a) / sum(reference);
        self
    }

    pub fn check(&self, what: &str, mean_tol: f64, excess_tol: f64) -> Result<(), String> {
        let m = &self.metrics;
        let msg = format!(
            "{what}: mean ratio {:.5} ({} pixels left out of it), relMSE {:.4e}, noise {:.4e}, expected relMSE {:.4e}",
            m.mean_ratio, self.excluded, m.relmse, self.noise, self.expected
        );
        eprintln!("{msg}");
        // A mean over no pixel (NaN) passes nothing.
        let mean_within = (m.mean_ratio - 1.0).abs() <= mean_tol;
        if !mean_within {
            return Err(format!("image mean off by more than {:.2}%: {msg}", mean_tol * 100.0));
        }
        let explained = m.relmse <= self.expected * excess_tol;
        if !explained {
            return Err(format!("relMSE exceeds {excess_tol}× what noise explains: {msg}"));
        }
        Ok(())
    }
}

/// A test scene and its Mitsuba 3 path-tracer reference in `tests/data`.
///
/// The references are path-traced, so their noise is the path tracer's at the reference
/// sample count, measured with our path tracer (same estimator): cornell-ply 5.09e-3 at 64 spp
/// → 8.0e-5 at 4096; veach-mis 2.82e-3 at 64 spp → 2.2e-5 at 8192; veach-ajar 0.29 at 256 spp
/// → 4.5e-3 at 16384; staircase2 (320×180) 0.0484 at 32 spp (three pairs of seeds) → 1.5e-3
/// at 1024. sunlit-room's (4.6e-3 at 1024) comes from Mitsuba's own chunks instead, as this
/// renderer does not read `sunsky` yet: a quarter of the relMSE between two halves.
/// cornell-box's and materials' is not measured: the path tracer alone is judged against
/// them, as the references' own estimator (from the noise of its two renders).
pub struct Case {
    pub name: &'static str,
    pub scene: &'static str,
    pub defines: &'static [(&'static str, &'static str)],
    pub reference: &'static str,
    /// The reference's relMSE noise, where it was measured.
    pub ref_noise: Option<f64>,
    /// Pixels brighter than this in the reference are left out of the mean (tiny emitters).
    pub mean_cutoff: Option<f32>,
    /// The film size replacing the scene's, for scenes that fix it in the XML.
    pub resolution: Option<(u32, u32)>,
    /// How far the image mean may be from the reference's.
    pub mean_tol: f64,
}

pub const CORNELL_PLY: Case = Case {
    name: "cornell-ply",
    scene: "scenes/cornell-ply/cornell_mi.xml",
    defines: &[],
    reference: "cornell-ply_mitsuba3-path_4096spp_maxdepth8_box.exr",
    ref_noise: Some(8.0e-5),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.005,
};

pub const CORNELL_BOX: Case = Case {
    name: "cornell-box",
    scene: "scenes/cornell-box/scene.xml",
    defines: &[("resx", "128"), ("resy", "128"), ("max_depth", "30")],
    reference: "cornell-box.exr",
    ref_noise: None,
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.005,
};

pub const MATERIALS: Case = Case {
    name: "materials",
    scene: "scenes/materials/scene.xml",
    defines: &[("resx", "160"), ("resy", "120")],
    reference: "materials.exr",
    ref_noise: None,
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.005,
};

pub const VEACH_MIS: Case = Case {
    name: "veach-mis",
    scene: "scenes/veach-mis/scene.xml",
    defines: &[("resx", "192"), ("resy", "108")],
    reference: "veach-mis.exr",
    ref_noise: Some(2.2e-5),
    mean_cutoff: Some(100.0),
    resolution: None,
    mean_tol: 0.005,
};

/// An open box under a point light and a spot light, both out of the camera's view (a
/// scene made for the tests: lights with a Dirac position).
/// A glass ball on a floor under a small light: its caustic seen directly and through the
/// ball.
pub const GLASS_CAUSTIC: Case = Case {
    name: "glass-caustic",
    scene: "scenes/glass-caustic/scene.xml",
    defines: &[("resx", "160"), ("resy", "90")],
    reference: "glass-caustic.exr",
    ref_noise: Some(1.25e-3),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.01,
};

/// Fog through the open front of a box, a glass sphere, a small light (Mitsuba 3's `volpath`).
pub const FOG_CAUSTIC: Case = Case {
    name: "fog-caustic",
    scene: "scenes/fog-caustic/scene.xml",
    defines: &[("resx", "64"), ("resy", "64")],
    reference: "fog-caustic.exr",
    ref_noise: Some(7.4e-4),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.01,
};

/// A plume of smoke (a heterogeneous medium over a 32³ grid) on a floor under a square
/// light (Mitsuba 3's `volpath`).
pub const SMOKE: Case = Case {
    name: "smoke",
    scene: "scenes/smoke/scene.xml",
    defines: &[("resx", "64"), ("resy", "64")],
    reference: "smoke.exr",
    ref_noise: Some(1.13e-5),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.01,
};

pub const SPOT_POINT: Case = Case {
    name: "spot-point",
    scene: "scenes/spot-point/scene.xml",
    defines: &[("resx", "128"), ("resy", "96")],
    reference: "spot-point.exr",
    ref_noise: Some(1.45e-3),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.005,
};

pub const VEACH_AJAR: Case = Case {
    name: "veach-ajar",
    scene: "scenes/veach-ajar/scene.xml",
    defines: &[("resx", "160"), ("resy", "90"), ("max_depth", "-1")],
    reference: "veach-ajar.exr",
    ref_noise: Some(4.5e-3),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.005,
};

/// Bitterli's "Modern Hall" as published (Mitsuba 0.5, film fixed at 1280×720 in the file),
/// at 320×180 with its own max_depth (65) and tent filter. Its reference has 1024 spp, so its
/// own noise is a fifth of a 128-spp render's; the mean is held to 1%.
pub const STAIRCASE2: Case = Case {
    name: "staircase2",
    scene: "scenes/staircase2/scene.xml",
    defines: &[],
    reference: "staircase2.exr",
    ref_noise: Some(1.5e-3),
    mean_cutoff: None,
    resolution: Some((320, 180)),
    mean_tol: 0.01,
};

/// A room lit only by `sunsky` (sun 30° up, sun and sky scaled by 20) through an open
/// window, at its own 320×180, `max_depth` 16 and tent filter: a patch of sunlight on the floor
/// and the back wall lights the rest of the room, which a glass sphere, a rough gold sphere
/// and a rough-plastic box share. Its reference has 1024 spp; its own noise (4.6e-3)
/// is a quarter of the relMSE between the averages of its chunks 0–1 and 2–3 (the JSON's
/// `noise`). The mean is held to 1% over the pixels below 2.0 in the reference: the sky seen
/// through the window is 61% of the whole image's mean and would hide a bias in the room
/// (the room's pixels, mean 0.193, are what the sun patch lights; 8 645 sky and highlight
/// pixels are left out of the mean, not of the relMSE).
pub const SUNLIT_ROOM: Case = Case {
    name: "sunlit-room",
    scene: "scenes/sunlit-room/scene.xml",
    defines: &[],
    reference: "sunlit-room.exr",
    ref_noise: Some(4.6e-3),
    mean_cutoff: Some(2.0),
    resolution: None,
    mean_tol: 0.01,
};

/// Bitterli's "The Grey & White Room" as published (Mitsuba 0.5, film fixed at 1280×720),
/// at 320×180 with its own max_depth (65) and tent filter: an envmap through windows, the
/// leaves cut out by `leaf.png`'s alpha. Its reference has 1024 spp; the mean is held to 1%.
pub const LIVING_ROOM: Case = Case {
    name: "living-room",
    scene: "scenes/living-room/scene.xml",
    defines: &[],
    reference: "living-room.exr",
    ref_noise: Some(5.5e-3),
    mean_cutoff: None,
    resolution: Some((320, 180)),
    mean_tol: 0.01,
};

/// The `sunsky06` scenes (a ground, a box, a sphere and a wall under Mitsuba 0.6's `sun`,
/// `sky` or `sunsky`, written as Mitsuba 0.6 files) against Mitsuba 0.6's own renders (stock
/// build, 1024 spp, `maxDepth` 8, box filter, 320×180). Each reference's noise is what this
/// renderer's path tracer has at 1024 spp on the same scene (a quarter of the relMSE between
/// two 64-spp renders, over 16); the mean is held to 1%.
pub const SUN06: Case = Case {
    name: "sunsky06-sun",
    scene: "scenes/sunsky06/sun.xml",
    defines: &[],
    reference: "sunsky06-sun_mitsuba06-path_320x180.exr",
    ref_noise: Some(6.5e-5),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.01,
};

pub const SKY06: Case = Case {
    name: "sunsky06-sky",
    scene: "scenes/sunsky06/sky.xml",
    defines: &[],
    reference: "sunsky06-sky_mitsuba06-path_320x180.exr",
    ref_noise: Some(2.7e-4),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.01,
};

pub const SUNSKY06: Case = Case {
    name: "sunsky06-sunsky",
    scene: "scenes/sunsky06/sunsky.xml",
    defines: &[],
    reference: "sunsky06-sunsky_mitsuba06-path_320x180.exr",
    ref_noise: Some(3.6e-4),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.01,
};

/// A plane under a grazing area light, its shading normal perturbed by a bump map
/// (`scenes/bumpmap/`). The references carry the path tracer's relMSE noise at their 2048
/// spp, measured on these scenes: one render's noise at 64 spp (from a pair of seeds) scaled
/// by 64 / 2048, 8.2e-4 → 2.6e-5 with the bump map and 5.7e-4 → 1.8e-5 with the normal map.
pub const BUMPMAP: Case = Case {
    name: "bumpmap",
    scene: "scenes/bumpmap/scene.xml",
    defines: &[],
    reference: "bumpmap.exr",
    ref_noise: Some(2.6e-5),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.01,
};

/// [`BUMPMAP`]'s plane with a normal map instead.
pub const NORMALMAP: Case = Case {
    name: "normalmap",
    scene: "scenes/bumpmap/normalmap.xml",
    defines: &[],
    reference: "normalmap.exr",
    ref_noise: Some(1.8e-5),
    mean_cutoff: None,
    resolution: None,
    mean_tol: 0.01,
};

impl Case {
    pub fn scene(&self) -> Scene {
        load_at(&root().join(self.scene), self.defines, self.resolution, Backend::Embree)
    }

    /// Two renders `a` and `b` with different seeds, averaged, against the reference: image
    /// mean within `mean_tol` (0.5%) and relMSE within 1.3× of half their noise plus the
    /// reference's.
    pub fn check(&self, a: &Image, b: &Image, what: &str) {
        let reference = reference(self.reference);
        let (mut v, avg) = Verdict::averaged(&reference, a, b, self.noise());
        if let Some(cutoff) = self.mean_cutoff {
            v = v.excluding_emitters(&reference, &avg, cutoff);
        }
        v.check(&format!("{}, {what}", self.name), self.mean_tol, 1.3).unwrap();
    }

    /// The reference's relMSE noise. Panics where it was not measured.
    pub fn noise(&self) -> f64 {
        self.ref_noise.unwrap_or_else(|| panic!("{}: the reference's noise is not measured", self.name))
    }
}

/// The pixels that light tracing (`t = 1`: a light subpath connected to the camera) can
/// render: for each pixel, camera rays on an 8 × 8 grid over the film positions whose
/// samples reach it through the scene's filter, none of which may escape to a light at
/// infinity or first hit a surface with a Dirac lobe (glass, a mirror, smooth plastic's
/// coat): light subpaths never connect to the camera through those. Where `min_alpha` is
/// above zero, first hits on microfacet surfaces smoother than it are left out too: light
/// subpaths reach the camera through their narrow lobes only rarely, with huge weights
/// (a `ward` lobe counts by its roughness too).
pub fn reachable_by_light_tracing(scene: &Scene, min_alpha: f32) -> Vec<bool> {
    use pcbpt::bsdf::BsdfModel;
    let alpha = |model: &BsdfModel, uv: glam::Vec2| {
        let m = match model {
            BsdfModel::RoughConductor { distribution, .. } | BsdfModel::RoughDielectric { distribution, .. } => {
                distribution.at(uv)
            }
            BsdfModel::RoughPlastic { params, .. } => params.distribution,
            BsdfModel::Ward { alpha, .. } => {
                let (u, v) = alpha.at(uv);
                return u.min(v);
            }
            _ => return f32::INFINITY,
        };
        m.alpha_u.min(m.alpha_v)
    };
    // The first surface along the camera ray, past null surfaces (media's boundaries, where
    // a medium's scattering before that surface is within light tracing's reach too).
    let first_surface = |pos: glam::Vec2| {
        let mut ray = scene.camera.generate_ray(pos);
        for _ in 0..64 {
            let si = scene.intersect(&ray)?;
            if !scene.bsdf(&si).is_null() {
                return Some(si);
            }
            ray = si.spawn_ray(ray.d.normalize());
        }
        None
    };
    let renderable = |pos: glam::Vec2| match first_surface(pos) {
        None => false,
        Some(si) => {
            // Every lobe a Dirac delta, or smooth plastic's coat beside its diffuse base.
            let bsdf = scene.bsdf(&si);
            !bsdf.is_delta()
                && !matches!(bsdf.model, BsdfModel::Plastic { .. })
                && alpha(&bsdf.model, si.uv) >= min_alpha
        }
    };
    let (w, h) = (scene.film.width, scene.film.height);
    let r = scene.film.filter.radius().max(0.5);
    let n = 8;
    let grid: Vec<glam::Vec2> = (0..n * n)
        .map(|k| glam::Vec2::new((k % n) as f32 + 0.5, (k / n) as f32 + 0.5) / n as f32 * 2.0 - 1.0)
        .collect();
    let film = glam::Vec2::new(w as f32, h as f32);
    (0..w * h)
        .map(|i| {
            let centre = glam::Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
            grid.iter().all(|o| renderable((centre + *o * r).clamp(glam::Vec2::ZERO, film)))
        })
        .collect()
}

/// The mean of `xs` and its standard error (at least two values).
pub fn mean_and_standard_error(xs: &[f64]) -> (f64, f64) {
    let n = xs.len() as f64;
    let mean = xs.iter().sum::<f64>() / n;
    let se = (xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0) / n).sqrt();
    (mean, se)
}

/// The budget's statistics of a PCBPT or SPCBPT render.
pub fn budget_of(s: &pcbpt::integrator::RenderStats) -> Option<&pcbpt::integrator::budget::BudgetStats> {
    use pcbpt::integrator::{pcbpt::PcbptStats, spcbpt::SpcbptStats};
    let pc = s.details.get::<PcbptStats>().map(|d| d.budget.as_ref());
    pc.or_else(|| s.details.get::<SpcbptStats>().map(|d| d.budget.as_ref())).flatten()
}
