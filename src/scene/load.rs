//! Stage three of scene loading: instantiating the parsed document into a [`Scene`].
//!
//! Each plugin reads the properties it knows; whatever is left unread is an error that
//! names the file and line (as in Mitsuba), as is an unknown plugin type.

use super::hair::{Hair, HairParams};
use super::mesh::{self, TriangleMesh};
use super::progress::LoadProgress;
use super::shape::{Shape, ShapeGeometry};
use super::xml::{self, Document, Node, NodeId};
use super::{IntegratorSpec, LoadOptions, LoadStats, Scene};
use crate::accel::{Accel, Cutout};
use crate::bsdf::Bsdf;
use crate::bsdf::plastic::RoughPlasticParams;
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

mod bsdf;
mod coating;
mod mask;
mod medium;
mod perturb;
mod prefetch;
mod sensor;
mod sunsky;
mod texture;
mod volume;

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
            media: Vec::new(),
            medium_ids: HashMap::new(),
            camera_medium: None,
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
                "medium" => {
                    b.medium(child.node)?;
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
        let volumetric = !b.media.is_empty() || b.shapes.iter().any(|s| b.bsdfs[s.bsdf].is_null());
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
            media: b.media,
            camera_medium: b.camera_medium,
            volumetric,
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
    /// Participating media (`load/medium.rs`), and where each medium node went.
    media: Vec<crate::medium::Medium>,
    medium_ids: HashMap<NodeId, u32>,
    /// The sensor's medium.
    camera_medium: Option<u32>,
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

    fn resolve_path(&self, node: &Node, name: &str) -> Result<PathBuf> {
        let f = node
            .string(name)?
            .ok_or_else(|| Error::input(&node.loc, format!("{} \"{}\" needs a \"{name}\"", node.tag, node.plugin)))?;
        Ok(self.base.join(f))
    }

    /// The file a shape's `filename` names and its size, or an error naming the line and
    /// saying that the `what` file does not exist.
    fn existing_file(&self, node: &Node, what: &str) -> Result<(PathBuf, u64)> {
        let path = self.resolve_path(node, "filename")?;
        match std::fs::metadata(&path) {
            Ok(m) if m.is_file() => Ok((path, m.len())),
            _ => {
                Err(Error::input(&node.prop_loc("filename"), format!("{what} file {} does not exist", path.display())))
            }
        }
    }

    /// Reads the mesh file a shape names (a PLY file streamed, with a progress bar; shape
    /// `shape_index` of a `.serialized` file).
    fn load_mesh(&mut self, node: &Node) -> Result<TriangleMesh> {
        let (path, size) = self.existing_file(node, "mesh")?;
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

    /// Reads the `.mitshair` file a `hair` shape names and prepares its strands in world
    /// space (Mitsuba 0.6's `radius`, `angle_threshold`, `reduction`).
    fn load_hair(&mut self, node: &Node, to_world: &Transform) -> Result<Hair> {
        let (path, size) = self.existing_file(node, "hair")?;
        let defaults = HairParams::default();
        let params = HairParams {
            radius: node.float_or("radius", defaults.radius)?,
            angle_threshold: node.float_or("angle_threshold", defaults.angle_threshold)?,
            reduction: node.float_or("reduction", defaults.reduction)?,
        };
        let start = Instant::now();
        let bar = self.progress.file(&path, size);
        let strands =
            super::hair::read_hair(&path).map_err(|e| Error::input(&node.prop_loc("filename"), e.to_string()))?;
        let hair = Hair::build(&strands, to_world, params).map_err(|e| {
            let prop = ["radius", "angle_threshold", "reduction", "to_world"].into_iter().find(|p| e.contains(p));
            let loc = prop.map_or_else(|| node.loc.clone(), |p| node.prop_loc(p));
            Error::input(&loc, format!("{}: {e}", path.display()))
        })?;
        self.stats.files.push(path.clone());
        let summary = format!(
            "read {}: {} hair segments in {} strands, {:.1} MB in {:.2} s",
            path.file_name().map(|n| n.to_string_lossy()).unwrap_or_default(),
            group_thousands(hair.segments.len() as u64),
            group_thousands(hair.strands as u64),
            size as f64 / 1e6,
            start.elapsed().as_secs_f64()
        );
        LoadProgress::done(bar, summary);
        Ok(hair)
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
            "hair" => ShapeGeometry::Hair(self.load_hair(node, &to_world)?),
            _ => {
                return Err(self
                    .unknown_plugin(id, &["obj", "ply", "serialized", "rectangle", "cube", "disk", "sphere", "hair"]));
            }
        };
        let media = self.medium_interface(id)?;
        let emits = self.doc.node(id).children.iter().any(|c| self.doc.node(c.node).tag == "emitter");
        let bsdf = match self.single_child(id, "bsdf", "a shape")? {
            // Mitsuba's defaults: black for a shape that emits, grey diffuse otherwise; but in
            // a version 0.x file no surface for a boundary of media (Mitsuba 0.6's null BSDF,
            // which Mitsuba 3 files give by name).
            None if media.is_some() && !emits && node.legacy => {
                self.bsdfs.push(Bsdf::new(crate::bsdf::BsdfModel::Null));
                self.bsdfs.len() - 1
            }
            None => {
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
            // Checked by `Hair::build`.
            ShapeGeometry::Hair(_) => None,
        };
        if let Some(msg) = placed {
            return Err(Error::input(&node.loc, format!("after to_world, {msg}")));
        }
        let mut shape = Shape::new(geometry, bsdf, flip_normals, name);
        shape.media = media;
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
        } else if let ShapeGeometry::Hair(h) = &shape.geometry {
            self.stats.hair_segments += h.segments.len();
        } else {
            self.stats.spheres += 1;
        }
        let masked = self.bsdfs[shape.bsdf].opacity.is_some();
        if masked && !matches!(shape.geometry, ShapeGeometry::Mesh(_)) {
            return Err(Error::input(
                &node.loc,
                format!(
                    "shape \"{}\": a mask (cut-out) is supported on triangle meshes, not on spheres or hair",
                    shape.name
                ),
            ));
        }
        if let Some(e) = self.single_child(id, "emitter", "a shape")? {
            if let ShapeGeometry::Hair(_) = &shape.geometry {
                return Err(Error::input(
                    &self.node(e).loc,
                    format!("the hair shape \"{}\" cannot emit: hair is not an area light", shape.name),
                ));
            }
            if masked {
                return Err(Error::input(
                    &self.node(e).loc,
                    format!(
                        "the emitting shape \"{}\" has a mask: emitters with cut-outs are not supported",
                        shape.name
                    ),
                ));
            }
            if self.bsdfs[shape.bsdf].is_null() {
                return Err(Error::input(
                    &self.node(e).loc,
                    format!("the emitting shape \"{}\" has a null BSDF: give it a surface", shape.name),
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
            ShapeGeometry::Hair(h) => {
                for p in &h.vertices {
                    lo = lo.min(*p - Vec3::splat(h.radius));
                    hi = hi.max(*p + Vec3::splat(h.radius));
                }
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
