//! Stage three of scene loading: instantiating the parsed document into a [`Scene`].
//!
//! Each plugin reads the properties it knows; whatever is left unread is an error that
//! names the file and line (as in Mitsuba), as is an unknown plugin type.

use super::mesh::{self, TriangleMesh};
use super::progress::LoadProgress;
use super::shape::{Shape, ShapeGeometry};
use super::xml::Value;
use super::xml::{self, Document, Node, NodeId};
use super::{IntegratorSpec, LoadOptions, LoadStats, Scene};
use crate::accel::{Accel, Cutout};
use crate::bsdf::fresnel::{fresnel_diffuse_reflectance, lookup_conductor, lookup_ior};
use crate::bsdf::microfacet::{Microfacet, MicrofacetType, Roughness};
use crate::bsdf::plastic::{PlasticParams, RoughPlasticParams};
use crate::bsdf::ward::{WardAlpha, WardParams, WardVariant};
use crate::bsdf::{Bsdf, BsdfModel};
use crate::error::Location;
use crate::error::{Error, Result};
use crate::light::{Bounds, EnvMap, Light, LightSampler};
use crate::math::Frame;
use crate::math::Transform;
use crate::texture::{FilterType, Texture, WrapMode};
use glam::{Mat3, Mat4, Vec3};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

mod coating;
mod mask;
mod perturb;
mod prefetch;
mod sensor;
mod sunsky;
mod texture;

/// BSDF plugins this renderer implements.
pub const BSDF_PLUGINS: &[&str] = &[
    "diffuse",
    "mask",
    "twosided",
    "conductor",
    "roughconductor",
    "dielectric",
    "thindielectric",
    "roughdielectric",
    "plastic",
    "roughplastic",
    "roughdiffuse",
    "coating",
    "roughcoating",
    "ward",
    "bumpmap",
    "normalmap",
];

/// The largest image this renderer accepts (pixels).
pub const MAX_PIXELS: u64 = 1 << 28;

impl Scene {
    /// Loads a Mitsuba XML scene and builds its accelerator.
    pub fn load(path: &Path, options: &LoadOptions) -> Result<Scene> {
        let start = Instant::now();
        let doc = xml::parse_file(path, &options.overrides)?;
        Scene::on_threads(options, || Scene::from_document(doc, path, options, start))
    }

    /// Loads scene text as if read from `path` (messages name it; meshes, textures and
    /// includes resolve against its folder).
    pub fn load_str(text: &str, path: &Path, options: &LoadOptions) -> Result<Scene> {
        let start = Instant::now();
        let doc = xml::parse_str(text, path, &options.overrides)?;
        Scene::on_threads(options, || Scene::from_document(doc, path, options, start))
    }

    /// Runs `load` on a pool of `options.threads` threads (all cores for 0): the files read
    /// ahead and the tables built in parallel use no more than the render will.
    fn on_threads(options: &LoadOptions, load: impl FnOnce() -> Result<Scene> + Send) -> Result<Scene> {
        if options.threads == 0 {
            return load();
        }
        crate::workers::pool(options.threads)?.install(load)
    }

    fn from_document(doc: Document, path: &Path, options: &LoadOptions, start: Instant) -> Result<Scene> {
        let mut b = Builder {
            doc: &doc,
            base: path.parent().map(Path::to_path_buf).unwrap_or_default(),
            bsdf_ids: HashMap::new(),
            bsdfs: Vec::new(),
            textures: HashMap::new(),
            shapes: Vec::new(),
            lights: Vec::new(),
            stats: LoadStats { files: doc.files.clone(), ..LoadStats::default() },
            progress: LoadProgress::new(options.progress),
            options,
            ignored: Vec::new(),
            read_as_bilinear: Vec::new(),
            coatings: Vec::new(),
            prefetched: prefetch::Prefetched::default(),
        };
        b.prefetched = prefetch::Prefetched::read(&doc, &b.base);
        let mut sensor = None;
        let mut integrator = None;
        let root = doc.node(doc.root);
        for child in &root.children {
            let node = doc.node(child.node);
            child.used.set(true);
            match node.tag.as_str() {
                "shape" => b.shape(child.node)?,
                "bsdf" => {
                    b.bsdf(child.node)?;
                }
                "emitter" if SUNSKY_PLUGINS.contains(&doc.node(child.node).plugin.as_str()) => {
                    let lights = b.sunsky(child.node)?;
                    b.lights.extend(lights);
                }
                "emitter" => {
                    let light = b.emitter(child.node, None)?;
                    b.lights.push(light);
                }
                "sensor" => {
                    if sensor.is_some() {
                        return Err(Error::input(
                            &node.loc,
                            "a second <sensor>: this renderer renders one sensor per scene",
                        ));
                    }
                    sensor = Some(b.sensor(child.node)?);
                }
                "integrator" => {
                    if integrator.is_some() {
                        return Err(Error::input(&node.loc, "a second <integrator>"));
                    }
                    integrator = Some(b.integrator(child.node)?);
                }
                "texture" => {
                    b.texture_node(child.node)?;
                }
                t => {
                    return Err(Error::input(&node.loc, format!("<{t}> plugins are not supported by this renderer")));
                }
            }
        }
        doc.check_unused(doc.root)?;
        let (camera, film, sampler) = sensor.ok_or_else(|| Error::input(&root.loc, "the scene has no <sensor>"))?;
        b.push_warnings();
        let integrator = integrator.unwrap_or(IntegratorSpec {
            plugin: "path".into(),
            max_depth: -1,
            rr_depth: 3,
            hide_emitters: false,
            strict_normals: false,
        });
        if b.lights.is_empty() {
            return Err(Error::input(&root.loc, "the scene has no emitters: the image would be black"));
        }
        for (o, _) in &options.overrides {
            // A version 0.x file's parameter names are upgraded (either spelling matches).
            let legacy = root.legacy && doc.params.contains_key(&xml::camel_to_snake(o));
            if !doc.params.contains_key(o) && !legacy {
                b.stats.warnings.push(format!(
                    "parameter -D {o}=… is not declared by a <default> in the scene and was used only where referenced"
                ));
            }
        }
        for s in &mut b.shapes {
            if s.light.is_some() {
                s.prepare_sampling();
            }
        }
        let bounds = scene_bounds(&b.shapes, camera.position);
        let light_sampler = LightSampler::new(&b.lights, &b.shapes, &bounds);
        let infinite_lights = (0..b.lights.len()).filter(|&i| b.lights[i].is_infinite()).collect();
        b.stats.mesh_bytes = b.shapes.iter().map(Shape::memory_bytes).sum();
        b.stats.read_seconds = start.elapsed().as_secs_f64();
        let bvh_start = Instant::now();
        let spinner = b.progress.phase(format!(
            "building the {} BVH over {} triangles",
            options.backend,
            group_thousands(b.stats.triangles as u64)
        ));
        let geometry: Vec<_> = b.shapes.iter().map(|s| s.accel_geometry()).collect();
        let cutouts: Vec<(u32, Arc<dyn Cutout>)> = b
            .shapes
            .iter()
            .enumerate()
            .filter_map(|(i, s)| Some((i as u32, s.cutout(b.bsdfs[s.bsdf].opacity.as_ref()?)?)))
            .collect();
        let accel = Accel::build_with_cutouts(options.backend, &geometry, &cutouts, options.build.clone())?;
        drop(geometry);
        b.stats.bvh_seconds = bvh_start.elapsed().as_secs_f64();
        LoadProgress::done(spinner, format!("built the {} BVH in {:.2} s", options.backend, b.stats.bvh_seconds));
        Ok(Scene {
            path: path.to_path_buf(),
            shapes: b.shapes,
            bsdfs: b.bsdfs,
            lights: b.lights,
            light_sampler,
            infinite_lights,
            bounds,
            camera,
            film,
            integrator,
            sampler,
            accel,
            stats: b.stats,
        })
    }
}

struct Builder<'d> {
    doc: &'d Document,
    base: PathBuf,
    bsdf_ids: HashMap<NodeId, usize>,
    bsdfs: Vec<Bsdf>,
    textures: HashMap<NodeId, Texture>,
    shapes: Vec<Shape>,
    lights: Vec<Light>,
    stats: LoadStats,
    progress: LoadProgress,
    options: &'d LoadOptions,
    /// Properties accepted but ignored (they mean nothing here): name, plugin, where.
    ignored: Vec<(String, String, Location)>,
    /// Bitmaps whose `filter_type` (`trilinear`, `ewa`) is read as bilinear lookups.
    read_as_bilinear: Vec<(String, Location)>,
    /// Rough plastic coatings made so far: their tables depend on the distribution and the
    /// index alone, and scenes reuse a few coatings across many materials.
    coatings: Vec<RoughPlasticParams>,
    /// The meshes and textures read ahead in parallel (`load/prefetch.rs`).
    prefetched: prefetch::Prefetched,
}

/// The emitters at infinity that model the sun and the sky (`load/sunsky.rs`).
const SUNSKY_PLUGINS: &[&str] = &["sunsky", "sun", "sky"];

fn positive(node: &Node, name: &str, v: f32) -> Result<f32> {
    if v > 0.0 && v.is_finite() {
        Ok(v)
    } else {
        Err(Error::input(&node.prop_loc(name), format!("\"{name}\" must be positive, got {v}")))
    }
}

fn non_negative_rgb(node: &Node, name: &str, v: Vec3) -> Result<Vec3> {
    if v.is_finite() && v.min_element() >= 0.0 {
        Ok(v)
    } else {
        Err(Error::input(&node.prop_loc(name), format!("\"{name}\" must be finite and non-negative, got {v}")))
    }
}

impl<'d> Builder<'d> {
    fn node(&self, id: NodeId) -> &'d Node {
        self.doc.node(id)
    }

    /// Accepts property `name` of `node`, if given, without reading it; it is named in the
    /// warning about ignored properties.
    /// [`Document::check_unused`], except that a Mitsuba 0.5/0.6 file's unused properties are
    /// ignored with a warning naming each (Mitsuba 0.6 warned of them and rendered); a
    /// Mitsuba 3 file's are errors.
    fn check_unused(&mut self, id: NodeId) -> Result<()> {
        let node = self.doc.node(id);
        if node.legacy {
            for p in node.props.iter().filter(|p| !p.used.get()) {
                self.ignore(node, &p.name);
                p.used.set(true);
            }
        }
        self.doc.check_unused(id)
    }

    fn ignore(&mut self, node: &Node, name: &str) {
        if let Some(p) = node.prop(name) {
            self.ignored.push((name.to_string(), format!("{} \"{}\"", node.tag, node.plugin), p.loc.clone()));
        }
    }

    /// One warning for the ignored properties (each name once, with where it first
    /// appears) and one for the bitmaps read as bilinear lookups.
    fn push_warnings(&mut self) {
        if !self.ignored.is_empty() {
            let mut names: Vec<(&str, &str, &Location, usize)> = Vec::new();
            for (name, plugin, loc) in &self.ignored {
                match names.iter_mut().find(|n| n.0 == name) {
                    Some(n) => n.3 += 1,
                    None => names.push((name, plugin, loc, 1)),
                }
            }
            names.sort_by_key(|n| (n.2.file.clone(), n.2.line, n.2.col));
            let list: Vec<String> = names
                .iter()
                .map(|(name, plugin, loc, n)| {
                    let more = if *n > 1 { format!(" and {} more", n - 1) } else { String::new() };
                    format!("\"{name}\" of {plugin} ({loc}{more})")
                })
                .collect();
            self.stats.warnings.push(format!(
                "ignored {} that {} nothing to this renderer (Mitsuba 0.5/0.6 film options; the output format follows the output file's extension): {}",
                if list.len() == 1 { "a property" } else { "properties" },
                if list.len() == 1 { "means" } else { "mean" },
                list.join(", ")
            ));
        }
        if let Some((first, loc)) = self.read_as_bilinear.first() {
            let more = match self.read_as_bilinear.len() {
                1 => String::new(),
                n => format!(" and {} more", n - 1),
            };
            self.stats.warnings.push(format!(
                "bitmap filter_type \"{first}\" ({loc}{more}) is read as bilinear lookups: a filter footprint from camera rays alone would make light paths see other texels than camera paths"
            ));
        }
    }

    /// The one nested object of `tag` in `id`, if any; two are an error (`what` names them).
    fn single_child(&self, id: NodeId, tag: &str, what: &str) -> Result<Option<NodeId>> {
        let nodes: Vec<NodeId> = self.doc.children(id, tag).map(|c| c.node).collect();
        match nodes.as_slice() {
            [] => Ok(None),
            [one] => Ok(Some(*one)),
            [_, second, ..] => Err(Error::input(&self.node(*second).loc, format!("{what} can have only one <{tag}>"))),
        }
    }

    fn unknown_plugin(&self, id: NodeId, known: &[&str]) -> Error {
        let n = self.node(id);
        Error::input(&n.loc, format!("unknown {} plugin \"{}\" (supported: {})", n.tag, n.plugin, known.join(", ")))
    }

    /// A rough plastic's parameters, its coating's tables shared with an earlier material of
    /// the same distribution and index (the same values as [`RoughPlasticParams::new`]).
    fn coating(&mut self, distribution: Microfacet, eta: f32, nonlinear: bool, weight: f32) -> RoughPlasticParams {
        if let Some(c) =
            self.coatings.iter().find(|c| c.distribution == distribution && c.eta.to_bits() == eta.to_bits())
        {
            return RoughPlasticParams { nonlinear, specular_sampling_weight: weight, ..c.clone() };
        }
        let params = RoughPlasticParams::new(distribution, eta, nonlinear, weight);
        self.coatings.push(params.clone());
        params
    }

    /// An index of refraction given as a number or by name (`bk7`, `air`, …).
    fn ior(&self, id: NodeId, name: &str, default: &str) -> Result<f32> {
        let node = self.doc.node(id);
        let v = match node.prop(name).map(|p| (&p.value, p.loc.clone())) {
            None => lookup_ior(default).unwrap_or(1.0),
            Some((Value::Float(f), _)) => *f as f32,
            Some((Value::Integer(i), _)) => *i as f32,
            Some((Value::String(s), loc)) => {
                lookup_ior(s).ok_or_else(|| Error::input(&loc, format!("unknown index of refraction \"{s}\"")))?
            }
            Some((v, loc)) => {
                return Err(Error::input(
                    &loc,
                    format!("\"{name}\" has type {}, expected a number or a material name", v.type_name()),
                ));
            }
        };
        positive(node, name, v)
    }

    /// `distribution` and `sample_visible` of a microfacet BSDF.
    fn microfacet_kind(&self, id: NodeId) -> Result<(MicrofacetType, bool)> {
        let node = self.doc.node(id);
        let kind = match node.string("distribution")?.unwrap_or("beckmann") {
            "beckmann" => MicrofacetType::Beckmann,
            "ggx" => MicrofacetType::Ggx,
            d => {
                let msg = format!("unknown distribution \"{d}\" (beckmann, ggx)");
                return Err(Error::input(&node.prop_loc("distribution"), msg));
            }
        };
        Ok((kind, node.boolean_or("sample_visible", true)?))
    }

    /// A roughness given as a positive number or a texture (`alpha`, `alpha_u`, `alpha_v`).
    fn alpha_texture(&mut self, id: NodeId, name: &str) -> Result<Option<Texture>> {
        let node = self.doc.node(id);
        let nested =
            node.children.iter().find(|c| c.name.as_deref() == Some(name) && self.doc.node(c.node).tag == "texture");
        if let Some(c) = nested {
            c.used.set(true);
        }
        match (node.float(name)?, nested.map(|c| c.node)) {
            (Some(_), Some(t)) => {
                Err(Error::input(&self.node(t).loc, format!("\"{name}\" is given both as a value and as a texture")))
            }
            (Some(v), None) => Ok(Some(Texture::Constant(Vec3::splat(positive(node, name, v)?)))),
            (None, Some(t)) => Ok(Some(self.texture_node(t)?)),
            (None, None) => Ok(None),
        }
    }

    /// Microfacet roughness: `alpha`, or `alpha_u` and `alpha_v`, each a number or a texture
    /// (default 0.1). Roughness is kept at least 1e-4, as in Mitsuba.
    fn roughness(&mut self, id: NodeId) -> Result<Roughness> {
        let (kind, sample_visible) = self.microfacet_kind(id)?;
        let a = self.alpha_texture(id, "alpha")?;
        let au = self.alpha_texture(id, "alpha_u")?;
        let av = self.alpha_texture(id, "alpha_v")?;
        let (tu, tv) = match (a, au, av) {
            (Some(a), None, None) => (a.clone(), a),
            (None, Some(u), Some(v)) => (u, v),
            (None, None, None) => (Texture::Constant(Vec3::splat(0.1)), Texture::Constant(Vec3::splat(0.1))),
            _ => {
                return Err(Error::input(
                    &self.node(id).loc,
                    "give either \"alpha\" or both \"alpha_u\" and \"alpha_v\"",
                ));
            }
        };
        let base = Microfacet { kind, alpha_u: 0.1, alpha_v: 0.1, sample_visible };
        Ok(match (&tu, &tv) {
            (Texture::Constant(u), Texture::Constant(v)) => {
                Roughness::Fixed(Microfacet { alpha_u: u.x.max(1e-4), alpha_v: v.x.max(1e-4), ..base })
            }
            _ => Roughness::Textured { base, alpha_u: tu, alpha_v: tv },
        })
    }

    /// A constant microfacet distribution (for plugins that precompute tables from it).
    fn microfacet(&mut self, id: NodeId) -> Result<Microfacet> {
        match self.roughness(id)? {
            Roughness::Fixed(m) => Ok(m),
            Roughness::Textured { .. } => {
                Err(Error::input(&self.node(id).loc, format!("{} needs a constant roughness", self.node(id).plugin)))
            }
        }
    }

    /// Mitsuba 0.6's `ward`: `variant` (default `balanced`), the roughness `alpha` (default
    /// 0.1) that `alpha_u` and `alpha_v` override, each a positive number or a texture,
    /// `specular_reflectance` (default 0.2) and `diffuse_reflectance` (default 0.5), scaled
    /// together where they sum to more than 1 unless `ensure_energy_conservation` is off
    /// (with a warning, as 0.6 gave).
    fn ward(&mut self, id: NodeId) -> Result<BsdfModel> {
        let node = self.doc.node(id);
        let name = node.string("variant")?.unwrap_or("balanced");
        let variant = WardVariant::from_name(name).ok_or_else(|| {
            let msg = format!("unknown ward variant \"{name}\" ({})", WardVariant::NAMES.join(", "));
            Error::input(&node.prop_loc("variant"), msg)
        })?;
        let alpha = self.alpha_texture(id, "alpha")?.unwrap_or(Texture::Constant(Vec3::splat(0.1)));
        let alpha_u = self.alpha_texture(id, "alpha_u")?.unwrap_or_else(|| alpha.clone());
        let alpha_v = self.alpha_texture(id, "alpha_v")?.unwrap_or(alpha);
        let alpha = match (alpha_u, alpha_v) {
            (Texture::Constant(u), Texture::Constant(v)) => WardAlpha::Fixed { u: u.x, v: v.x },
            (u, v) => WardAlpha::Textured { u, v },
        };
        let diffuse_reflectance = self.texture_prop(id, "diffuse_reflectance", Vec3::splat(0.5))?;
        let specular_reflectance = self.texture_prop(id, "specular_reflectance", Vec3::splat(0.2))?;
        let ensure = node.boolean_or("ensure_energy_conservation", true)?;
        let params = WardParams::new(variant, &diffuse_reflectance, &specular_reflectance, ensure);
        if params.scale != 1.0 {
            let sum = (diffuse_reflectance.max() + specular_reflectance.max()).max_element();
            self.stats.warnings.push(format!(
                "{}: the ward BSDF's specular_reflectance and diffuse_reflectance sum to {sum} (> 1) in a channel; \
                 both are scaled by {} to keep energy, as Mitsuba 0.6 did (ensure_energy_conservation=false keeps them)",
                node.loc, params.scale
            ));
        }
        Ok(BsdfModel::Ward { params, alpha, diffuse_reflectance, specular_reflectance })
    }

    /// Conductor parameters: a named `material` or `eta` and `k` (default: a perfect mirror),
    /// relative to the exterior medium's index `ext_eta` (Mitsuba 0.6's `extEta`, a number
    /// or a named index; default 1): both are divided by it, as Mitsuba 0.6 did. A version
    /// 0.x file's `eta` and `k` may have negative channels (RGB fits of measured data do),
    /// which Mitsuba 0.6 rendered: its Fresnel term, like this renderer's, depends on
    /// `(eta + ik)²` up to complex conjugation, which the magnitudes keep, so they are taken,
    /// with a warning.
    fn conductor(&mut self, id: NodeId) -> Result<(Vec3, Vec3)> {
        let node = self.doc.node(id);
        let (eta, k) = match (node.string("material")?, node.rgb("eta")?, node.rgb("k")?) {
            (Some(m), None, None) => lookup_conductor(m).ok_or_else(|| {
                Error::input(&node.prop_loc("material"), format!("unknown conductor material \"{m}\""))
            })?,
            (None, Some(eta), Some(k)) if node.legacy && (eta.min_element() < 0.0 || k.min_element() < 0.0) => {
                let mut magnitude = |name: &str, v: Vec3| {
                    if v.is_finite() && v.min_element() < 0.0 {
                        self.stats.warnings.push(format!(
                            "{}: the conductor's {name} {v} has a negative channel; its magnitude is used (the Fresnel \
                             term depends on (eta + ik)² up to conjugation, as in Mitsuba 0.6)",
                            node.prop_loc(name)
                        ));
                    }
                    non_negative_rgb(node, name, v.abs())
                };
                (magnitude("eta", eta)?, magnitude("k", k)?)
            }
            (None, Some(eta), Some(k)) => (non_negative_rgb(node, "eta", eta)?, non_negative_rgb(node, "k", k)?),
            (None, None, None) => (Vec3::ZERO, Vec3::ONE),
            _ => return Err(Error::input(&node.loc, "give either \"material\" or both \"eta\" and \"k\"")),
        };
        let ext_eta = match node.prop("ext_eta") {
            None => 1.0,
            Some(_) => self.ior(id, "ext_eta", "air")?,
        };
        Ok((eta / ext_eta, k / ext_eta))
    }

    /// Instantiates a BSDF once per node (shared through `ref`).
    fn bsdf(&mut self, id: NodeId) -> Result<usize> {
        if let Some(&i) = self.bsdf_ids.get(&id) {
            return Ok(i);
        }
        let bsdf = self.bsdf_value(id)?;
        self.bsdfs.push(bsdf);
        self.bsdf_ids.insert(id, self.bsdfs.len() - 1);
        Ok(self.bsdfs.len() - 1)
    }

    fn bsdf_value(&mut self, id: NodeId) -> Result<Bsdf> {
        let plugin = self.node(id).plugin.clone();
        let one = Vec3::ONE;
        let model = match plugin.as_str() {
            "bumpmap" | "normalmap" => return self.perturbed_bsdf(id),
            "diffuse" => BsdfModel::Diffuse { reflectance: self.texture_prop(id, "reflectance", Vec3::splat(0.5))? },
            "roughdiffuse" => self.rough_diffuse(id)?,
            "twosided" => {
                let inner: Vec<NodeId> = self.doc.children(id, "bsdf").map(|c| c.node).collect();
                return match inner.as_slice() {
                    [one] => {
                        let mut b = self.bsdf_value(*one)?;
                        b.two_sided = true;
                        self.check_unused(id)?;
                        Ok(b)
                    }
                    [] => Err(Error::input(&self.node(id).loc, "twosided needs a nested <bsdf>")),
                    _ => Err(Error::input(
                        &self.node(id).loc,
                        "twosided with different front and back BSDFs is not supported",
                    )),
                };
            }
            "conductor" => {
                let (eta, k) = self.conductor(id)?;
                BsdfModel::Conductor {
                    eta,
                    k,
                    specular_reflectance: self.texture_prop(id, "specular_reflectance", one)?,
                }
            }
            "roughconductor" => {
                let (eta, k) = self.conductor(id)?;
                let distribution = self.roughness(id)?;
                let specular_reflectance = self.texture_prop(id, "specular_reflectance", one)?;
                BsdfModel::RoughConductor { distribution, eta, k, specular_reflectance }
            }
            "dielectric" | "thindielectric" | "roughdielectric" => {
                let eta = self.ior(id, "int_ior", "bk7")? / self.ior(id, "ext_ior", "air")?;
                let specular_reflectance = self.texture_prop(id, "specular_reflectance", one)?;
                let specular_transmittance = self.texture_prop(id, "specular_transmittance", one)?;
                match plugin.as_str() {
                    "dielectric" => BsdfModel::Dielectric { eta, specular_reflectance, specular_transmittance },
                    "thindielectric" => BsdfModel::ThinDielectric { eta, specular_reflectance, specular_transmittance },
                    _ => {
                        let distribution = self.roughness(id)?;
                        BsdfModel::RoughDielectric { distribution, eta, specular_reflectance, specular_transmittance }
                    }
                }
            }
            "plastic" | "roughplastic" => {
                let eta = self.ior(id, "int_ior", "polypropylene")? / self.ior(id, "ext_ior", "air")?;
                let diffuse_reflectance = self.texture_prop(id, "diffuse_reflectance", Vec3::splat(0.5))?;
                let specular_reflectance = self.texture_prop(id, "specular_reflectance", one)?;
                let nonlinear = self.node(id).boolean_or("nonlinear", false)?;
                let d = diffuse_reflectance.mean().element_sum() / 3.0;
                let s = specular_reflectance.mean().element_sum() / 3.0;
                let weight = if d + s > 0.0 { s / (d + s) } else { 0.5 };
                if plugin == "plastic" {
                    let fdr_int = fresnel_diffuse_reflectance(1.0 / eta);
                    let params = PlasticParams { eta, nonlinear, fdr_int, specular_sampling_weight: weight };
                    BsdfModel::Plastic { params, diffuse_reflectance, specular_reflectance }
                } else {
                    let distribution = self.microfacet(id)?;
                    if distribution.alpha_u != distribution.alpha_v {
                        return Err(Error::input(&self.node(id).loc, "roughplastic is isotropic: give \"alpha\""));
                    }
                    let params = self.coating(distribution, eta, nonlinear, weight);
                    BsdfModel::RoughPlastic { params, diffuse_reflectance, specular_reflectance }
                }
            }
            "ward" => self.ward(id)?,
            "mask" => return self.mask(id),
            "coating" | "roughcoating" => return self.coated(id),
            _ => return Err(self.unknown_plugin(id, BSDF_PLUGINS)),
        };
        self.check_unused(id)?;
        Ok(Bsdf::new(model))
    }

    /// Mitsuba 0.6's `roughdiffuse`: `reflectance` (or `diffuseReflectance`), `alpha` (a
    /// number or a texture, default 0.2) and `useFastApprox`.
    fn rough_diffuse(&mut self, id: NodeId) -> Result<BsdfModel> {
        let name =
            if self.node(id).prop("diffuse_reflectance").is_some() { "diffuse_reflectance" } else { "reflectance" };
        let reflectance = self.texture_prop(id, name, Vec3::splat(0.5))?;
        let alpha = self.texture_prop(id, "alpha", Vec3::splat(0.2))?;
        let values: Vec<Vec3> = match &alpha {
            Texture::Constant(c) => vec![*c],
            Texture::Bitmap { bitmap, .. } => bitmap.texels().collect(),
            Texture::Checkerboard { color0, color1, .. } => vec![*color0, *color1],
        };
        if let Some(bad) = values.iter().find(|v| !(v.is_finite() && v.min_element() >= 0.0)) {
            return Err(Error::input(
                &self.node(id).prop_loc("alpha"),
                format!("roughdiffuse's alpha must be finite and non-negative, got {bad}"),
            ));
        }
        let fast = self.node(id).boolean_or("use_fast_approx", false)?;
        Ok(BsdfModel::RoughDiffuse { reflectance, alpha, fast })
    }

    fn resolve_path(&self, node: &Node, name: &str) -> Result<PathBuf> {
        let f = node
            .string(name)?
            .ok_or_else(|| Error::input(&node.loc, format!("{} \"{}\" needs a \"{name}\"", node.tag, node.plugin)))?;
        Ok(self.base.join(f))
    }

    /// Reads the mesh file a shape names (a PLY file streamed, with a progress bar; shape
    /// `shape_index` of a `.serialized` file).
    fn load_mesh(&mut self, node: &Node) -> Result<TriangleMesh> {
        let path = self.resolve_path(node, "filename")?;
        let size = match std::fs::metadata(&path) {
            Ok(m) if m.is_file() => m.len(),
            _ => {
                return Err(Error::input(
                    &node.prop_loc("filename"),
                    format!("mesh file {} does not exist", path.display()),
                ));
            }
        };
        let start = Instant::now();
        let bar = self.progress.file(&path, size);
        let loaded = if node.plugin == "obj" {
            self.prefetched.take_mesh(&path).unwrap_or_else(|| mesh::load_obj(&path))
        } else if node.plugin == "serialized" {
            let index = node.integer("shape_index")?.unwrap_or(0);
            let index = u32::try_from(index).map_err(|_| {
                Error::input(&node.prop_loc("shape_index"), format!("shape_index must be non-negative, got {index}"))
            })?;
            super::serialized::load_serialized(&path, index)
        } else {
            mesh::load_ply_with_progress(&path, &mut |read| {
                if let Some(b) = &bar {
                    b.set_position(read);
                }
            })
        };
        let m = loaded.map_err(|e| Error::input(&node.prop_loc("filename"), e.to_string()))?;
        self.stats.files.push(path.clone());
        let summary = format!(
            "read {}: {} triangles, {:.1} MB in {:.2} s",
            path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
            group_thousands(m.indices.len() as u64),
            size as f64 / 1e6,
            start.elapsed().as_secs_f64()
        );
        LoadProgress::done(bar, summary);
        Ok(m)
    }

    fn shape(&mut self, id: NodeId) -> Result<()> {
        let node = self.doc.node(id);
        let to_world = Transform::new(node.transform("to_world")?.unwrap_or(Mat4::IDENTITY));
        let flip_normals = node.boolean_or("flip_normals", false)?;
        let name = node.id.clone().unwrap_or_else(|| node.plugin.clone());
        let geometry = match node.plugin.as_str() {
            "obj" | "ply" | "serialized" => {
                let mut m = self.load_mesh(node)?;
                let face_normals = node.boolean_or("face_normals", false)?;
                if face_normals {
                    m.normals = None;
                }
                // Mitsuba flips OBJ texture coordinates by default (`flip_tex_coords`).
                let flip_default = node.plugin == "obj";
                if node.boolean_or("flip_tex_coords", flip_default)?
                    && let Some(uv) = &mut m.uvs
                {
                    uv.iter_mut().for_each(|t| t.y = 1.0 - t.y);
                }
                m.transform(&to_world);
                // Mitsuba smooths a mesh loaded without normals (in world space).
                if m.normals.is_none() && !face_normals {
                    m.compute_vertex_normals();
                }
                ShapeGeometry::Mesh(m)
            }
            "rectangle" | "cube" | "disk" => {
                let mut m = match node.plugin.as_str() {
                    "rectangle" => mesh::rectangle(),
                    "cube" => mesh::cube(),
                    _ => mesh::disk(256),
                };
                m.transform(&to_world);
                // These shapes transform their normals as normals; keep the winding (and so
                // the geometric normal) consistent with that under mirroring transforms.
                if to_world.flips_handedness() {
                    m.reverse_winding();
                }
                ShapeGeometry::Mesh(m)
            }
            "sphere" => {
                let center = node.vector("center")?.unwrap_or(Vec3::ZERO);
                let radius = positive(node, "radius", node.float_or("radius", 1.0)?)?;
                let c = to_world.point(center);
                let axes = [Vec3::X, Vec3::Y, Vec3::Z].map(|a| to_world.vector(a).length());
                if (axes[0] - axes[1]).abs() > 1e-4 * axes[0] || (axes[0] - axes[2]).abs() > 1e-4 * axes[0] {
                    return Err(Error::input(&node.prop_loc("to_world"), "a sphere's to_world must scale uniformly"));
                }
                ShapeGeometry::Sphere { center: c, radius: radius * axes[0] }
            }
            _ => {
                return Err(
                    self.unknown_plugin(id, &["obj", "ply", "serialized", "rectangle", "cube", "disk", "sphere"])
                );
            }
        };
        let bsdf = match self.single_child(id, "bsdf", "a shape")? {
            None => {
                // Mitsuba's defaults: grey diffuse, but black for a shape that emits.
                let emits = self.doc.node(id).children.iter().any(|c| self.doc.node(c.node).tag == "emitter");
                let reflectance = if emits { 0.0 } else { 0.5 };
                self.bsdfs.push(Bsdf::diffuse(Texture::Constant(Vec3::splat(reflectance))));
                self.bsdfs.len() - 1
            }
            Some(b) => self.bsdf(b)?,
        };
        let placed = match &geometry {
            ShapeGeometry::Mesh(m) => m.position_out_of_range().map(|i| mesh::out_of_range_message(i, m.positions[i])),
            ShapeGeometry::Sphere { center, radius } => (!(center.is_finite()
                && center.abs().max_element() + radius <= mesh::MAX_COORDINATE))
                .then(|| format!("the sphere reaches beyond ±{:e}", mesh::MAX_COORDINATE)),
        };
        if let Some(msg) = placed {
            return Err(Error::input(&node.loc, format!("after to_world, {msg}")));
        }
        let mut shape = Shape::new(geometry, bsdf, flip_normals, name);
        if let ShapeGeometry::Mesh(m) = &shape.geometry {
            self.stats.triangles += m.indices.len();
            self.stats.vertices += m.positions.len();
            let degenerate = m.degenerate_count();
            if degenerate > 0 {
                self.stats.degenerate_triangles += degenerate;
                self.stats.warnings.push(format!(
                    "{}: shape \"{}\" has {degenerate} degenerate (zero-area) triangles; they are never hit",
                    node.loc, shape.name
                ));
            }
        } else {
            self.stats.spheres += 1;
        }
        let masked = self.bsdfs[shape.bsdf].opacity.is_some();
        if masked && matches!(shape.geometry, ShapeGeometry::Sphere { .. }) {
            return Err(Error::input(
                &node.loc,
                format!("shape \"{}\": a mask (cut-out) is supported on triangle meshes, not on spheres", shape.name),
            ));
        }
        if let Some(e) = self.single_child(id, "emitter", "a shape")? {
            if masked {
                return Err(Error::input(
                    &self.node(e).loc,
                    format!(
                        "the emitting shape \"{}\" has a mask: emitters with cut-outs are not supported",
                        shape.name
                    ),
                ));
            }
            if shape.area().is_nan() || shape.area() <= 0.0 {
                return Err(Error::input(
                    &self.node(e).loc,
                    format!("the emitting shape \"{}\" has zero area", shape.name),
                ));
            }
            let light = self.emitter(e, Some(self.shapes.len()))?;
            shape.light = Some(self.lights.len());
            self.lights.push(light);
        }
        self.check_unused(id)?;
        self.shapes.push(shape);
        Ok(())
    }

    fn emitter(&mut self, id: NodeId, shape: Option<usize>) -> Result<Light> {
        let node = self.doc.node(id);
        let light = match (node.plugin.as_str(), shape) {
            ("area", Some(shape)) => Light::Area { shape, radiance: self.texture_prop(id, "radiance", Vec3::ONE)? },
            ("area", None) => {
                return Err(Error::input(&node.loc, "an area emitter must be nested in a <shape>"));
            }
            ("point", None) => {
                let pos = match (node.vector("position")?, node.transform("to_world")?) {
                    (Some(_), Some(_)) => {
                        return Err(Error::input(&node.loc, "give either \"position\" or \"to_world\", not both"));
                    }
                    (Some(p), None) => p,
                    (None, Some(m)) => m.transform_point3(Vec3::ZERO),
                    (None, None) => Vec3::ZERO,
                };
                let intensity = non_negative_rgb(node, "intensity", node.rgb("intensity")?.unwrap_or(Vec3::ONE))?;
                Light::Point { position: pos, intensity }
            }
            ("spot", None) => {
                let m = node.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
                let axis = m.transform_vector3(Vec3::Z).normalize_or_zero();
                if axis == Vec3::ZERO {
                    return Err(Error::input(&node.prop_loc("to_world"), "the spot light's to_world is singular"));
                }
                let intensity = non_negative_rgb(node, "intensity", node.rgb("intensity")?.unwrap_or(Vec3::ONE))?;
                let cutoff = node.float_or("cutoff_angle", 20.0)?;
                let beam = node.float_or("beam_width", cutoff * 0.75)?;
                if !(cutoff > 0.0 && cutoff <= 180.0 && beam > 0.0 && beam <= cutoff) {
                    return Err(Error::input(
                        &node.loc,
                        format!("need 0 < beam_width ≤ cutoff_angle ≤ 180, got {beam} and {cutoff}"),
                    ));
                }
                Light::Spot {
                    position: m.transform_point3(Vec3::ZERO),
                    frame: Frame::from_normal(axis),
                    intensity,
                    cutoff: cutoff.to_radians(),
                    beam_width: beam.to_radians(),
                }
            }
            ("directional", None) => {
                let dir = match (node.vector("direction")?, node.transform("to_world")?) {
                    (Some(_), Some(_)) => {
                        return Err(Error::input(&node.loc, "give either \"direction\" or \"to_world\", not both"));
                    }
                    (Some(d), None) => d,
                    (None, Some(m)) => m.transform_vector3(Vec3::Z),
                    (None, None) => Vec3::Z,
                };
                if !dir.is_finite() || dir.length_squared() == 0.0 {
                    return Err(Error::input(&node.prop_loc("direction"), "the direction must be non-zero"));
                }
                let irradiance = non_negative_rgb(node, "irradiance", node.rgb("irradiance")?.unwrap_or(Vec3::ONE))?;
                Light::Directional { direction: dir.normalize(), irradiance }
            }
            ("constant", None) => Light::Constant {
                radiance: non_negative_rgb(node, "radiance", node.rgb("radiance")?.unwrap_or(Vec3::ONE))?,
            },
            ("envmap", None) => {
                let path = self.resolve_path(node, "filename")?;
                let to_world = Mat3::from_mat4(node.transform("to_world")?.unwrap_or(Mat4::IDENTITY));
                let det = to_world.determinant();
                if det.is_nan() || det.abs() <= 1e-6 {
                    return Err(Error::input(&node.prop_loc("to_world"), "the envmap's to_world is singular"));
                }
                let scale = node.float_or("scale", 1.0)?;
                if !(scale >= 0.0 && scale.is_finite()) {
                    return Err(Error::input(&node.prop_loc("scale"), "scale must be finite and non-negative"));
                }
                let bitmap = self
                    .load_bitmap(&path, false, FilterType::Bilinear, WrapMode::Repeat)
                    .map_err(|e| Error::input(&node.prop_loc("filename"), e.to_string()))?;
                self.stats.files.push(path.clone());
                if bitmap.texels().any(|t| !t.is_finite() || t.min_element() < 0.0) {
                    return Err(Error::input(
                        &node.prop_loc("filename"),
                        format!("{}: the environment map has negative or non-finite texels", path.display()),
                    ));
                }
                Light::Envmap(Arc::new(EnvMap::new(Arc::new(bitmap), to_world, scale)))
            }
            (p @ ("point" | "spot" | "directional" | "constant" | "envmap" | "sunsky" | "sun" | "sky"), Some(_)) => {
                return Err(Error::input(&node.loc, format!("a {p} emitter cannot be attached to a shape")));
            }
            _ => {
                return Err(self.unknown_plugin(
                    id,
                    &["area", "point", "spot", "directional", "constant", "envmap", "sunsky", "sun", "sky"],
                ));
            }
        };
        self.check_unused(id)?;
        Ok(light)
    }
}

/// A sphere around every shape and the camera position.
fn scene_bounds(shapes: &[Shape], camera: Vec3) -> Bounds {
    let (mut lo, mut hi) = (camera, camera);
    for s in shapes {
        match &s.geometry {
            ShapeGeometry::Mesh(m) => {
                for p in &m.positions {
                    lo = lo.min(*p);
                    hi = hi.max(*p);
                }
            }
            ShapeGeometry::Sphere { center, radius } => {
                lo = lo.min(*center - Vec3::splat(*radius));
                hi = hi.max(*center + Vec3::splat(*radius));
            }
        }
    }
    let center = (lo + hi) * 0.5;
    // A scene of nothing but the camera still gets a sphere (lights at infinity start their
    // paths on a disk of its radius), large enough for the coordinates around it.
    Bounds { center, radius: ((hi - lo).length() * 0.5).max(1e-3 * (1.0 + center.abs().max_element())) }
}

/// `n` with a space between groups of three digits (`10 000 000`).
pub fn group_thousands(n: u64) -> String {
    let digits = n.to_string();
    let mut out = String::with_capacity(digits.len() + digits.len() / 3);
    for (i, c) in digits.chars().enumerate() {
        if i > 0 && (digits.len() - i).is_multiple_of(3) {
            out.push(' ');
        }
        out.push(c);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::group_thousands;
    use crate::bsdf::BsdfModel;
    use crate::scene::{LoadOptions, Scene};
    use crate::texture::{Bitmap, FilterType, Texture, WrapMode};

    /// A file used by several textures (and once raw) gives each the bitmap that reading it
    /// alone gives, with its own filter and wrap mode, whatever the number of threads that
    /// read the files ahead; rough plastics of one coating share its tables and keep their
    /// own weights.
    #[test]
    fn files_read_ahead_give_what_reading_them_alone_gives() {
        let texture = |filter: &str, raw: bool| {
            format!(
                r#"<texture type="bitmap" name="reflectance"><string name="filename" value="textures/tiles.png"/><string name="filter_type" value="{filter}"/><boolean name="raw" value="{raw}"/></texture>"#
            )
        };
        let text = format!(
            r#"<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="40"/><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
    <shape type="rectangle"><emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>
    <bsdf type="diffuse">{}</bsdf>
    <bsdf type="diffuse">{}</bsdf>
    <bsdf type="diffuse">{}</bsdf>
    <bsdf type="roughplastic"><float name="alpha" value="0.2"/><rgb name="diffuse_reflectance" value="0.8"/></bsdf>
    <bsdf type="roughplastic"><float name="alpha" value="0.2"/><rgb name="diffuse_reflectance" value="0.1"/><boolean name="nonlinear" value="true"/></bsdf>
</scene>"#,
            texture("bilinear", false),
            texture("nearest", false),
            texture("bilinear", true)
        );
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let path = root.join("scenes/materials/legacy.xml");
        let png = root.join("scenes/materials/textures/tiles.png");
        for threads in [1, 2, 3] {
            let s = Scene::load_str(&text, &path, &LoadOptions { threads, ..Default::default() }).unwrap();
            let bitmaps: Vec<&Bitmap> = s
                .bsdfs
                .iter()
                .filter_map(|b| match &b.model {
                    BsdfModel::Diffuse { reflectance: Texture::Bitmap { bitmap, .. } } => Some(&**bitmap),
                    _ => None,
                })
                .collect();
            let plastics: Vec<_> = s
                .bsdfs
                .iter()
                .filter_map(|b| match &b.model {
                    BsdfModel::RoughPlastic { params, .. } => Some(params),
                    _ => None,
                })
                .collect();
            assert_eq!((bitmaps.len(), plastics.len()), (3, 2));
            for (i, filter, raw) in
                [(0, FilterType::Bilinear, false), (1, FilterType::Nearest, false), (2, FilterType::Bilinear, true)]
            {
                let img = crate::image_io::read_texture(&png, raw).unwrap();
                let alone = Bitmap::new(img.width, img.height, img.pixels, filter, WrapMode::Repeat);
                assert_eq!(*bitmaps[i], alone, "texture {i}, {threads} threads");
            }
            let (a, b) = (plastics[0], plastics[1]);
            assert!(std::sync::Arc::ptr_eq(&a.external_transmittance, &b.external_transmittance));
            let alone =
                crate::bsdf::plastic::RoughPlasticParams::new(a.distribution, a.eta, true, b.specular_sampling_weight);
            assert_eq!(*b, alone);
            assert!(!a.nonlinear && a.specular_sampling_weight != b.specular_sampling_weight);
        }
    }

    #[test]
    fn thousands_are_grouped() {
        let cases = [(0, "0"), (999, "999"), (1000, "1 000"), (10_000_000, "10 000 000"), (123_456, "123 456")];
        for (n, s) in cases {
            assert_eq!(group_thousands(n), s);
        }
    }
}
