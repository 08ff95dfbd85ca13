//! The sensor, its film, reconstruction filter and sampler, and the scene file's
//! integrator block: the parts of a scene that say how to render it rather than what.

use super::{Builder, MAX_PIXELS, positive};
use crate::camera::{Camera, FovAxis};
use crate::error::{Error, Result};
use crate::film::Filter;
use crate::image_io::tonemap::{Ldr, Tonemap, Transfer};
use crate::integrator::IntegratorKind;
use crate::math::Transform;
use crate::sampling::SamplerKind;
use crate::scene::xml::{NodeId, Value};
use crate::scene::{FilmSpec, IntegratorSpec, SamplerSpec};
use glam::Mat4;

/// Film properties of Mitsuba 0.5/0.6 (and of other films) that mean nothing to this
/// renderer: accepted, and named in one warning.
const IGNORED_FILM_PROPERTIES: &[&str] = &["high_quality_edges", "banner", "attach_log"];

/// Mitsuba's stratified and low-discrepancy samplers other than `sobol`: each read for its
/// sample count and seed and rendered with the `sobol` sampler, named in one warning.
const MAPPED_SAMPLERS: &[&str] = &["stratified", "ldsampler", "halton", "hammersley", "multijitter", "orthogonal"];

/// Properties of Mitsuba's low-discrepancy samplers that only shape their point sets (the
/// `sobol` sampler scrambles each pixel's sequence by its own seed).
const MAPPED_SAMPLER_PROPERTIES: &[&str] = &["dimension", "scramble", "jitter", "strength"];

/// The film's output-format properties and the values that agree with what this renderer
/// writes (the format follows the output file's extension). In a Mitsuba 3 file an agreeing
/// value is accepted silently; any other value, and any value in a version 0.x file, is
/// ignored with the warning.
const OUTPUT_FORMAT_PROPERTIES: &[(&str, &[&str])] = &[
    ("file_format", &["openexr", "exr"]),
    ("pixel_format", &["rgb", "rgba"]),
    ("component_format", &["float16", "float32"]),
];

impl Builder<'_> {
    /// The film size, or the `--resolution` that replaces it.
    fn film_size(&self, width: u32, height: u32) -> Result<(u32, u32)> {
        let Some((w, h)) = self.options.resolution else {
            return Ok((width, height));
        };
        if w == 0 || h == 0 || w > 65536 || h > 65536 || w as u64 * h as u64 > MAX_PIXELS {
            return Err(Error::Usage(format!(
                "--resolution {w}x{h}: width and height must be between 1 and 65536, at most {MAX_PIXELS} pixels"
            )));
        }
        Ok((w, h))
    }

    pub(super) fn sensor(&mut self, id: NodeId) -> Result<(Camera, FilmSpec, SamplerSpec)> {
        let node = self.doc.node(id);
        if node.plugin != "perspective" {
            return Err(self.unknown_plugin(id, &["perspective"]));
        }
        let to_world = node.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
        let det = to_world.determinant();
        if det.is_nan() || det.abs() <= 1e-12 {
            return Err(Error::input(&node.prop_loc("to_world"), "the sensor's to_world is singular"));
        }
        let fov = match (node.float("fov")?, node.string("focal_length")?) {
            (Some(_), Some(_)) => {
                return Err(Error::input(&node.loc, "give either \"fov\" or \"focal_length\", not both"));
            }
            (Some(f), None) => f,
            (None, Some(fl)) => {
                let mm: f32 = fl.trim_end_matches("mm").trim().parse().map_err(|_| {
                    Error::input(&node.prop_loc("focal_length"), format!("focal length \"{fl}\" is not like \"50mm\""))
                })?;
                // Mitsuba: the focal length of a 35 mm film (36 mm wide), along the diagonal.
                let fov = 2.0
                    * ((36.0f32 * 36.0 + 24.0 * 24.0).sqrt() / (2.0 * positive(node, "focal_length", mm)?))
                        .atan()
                        .to_degrees();
                return self.finish_sensor(id, to_world, fov, Some(FovAxis::Diagonal));
            }
            (None, None) => {
                return Err(Error::input(&node.loc, "the perspective sensor needs a \"fov\""));
            }
        };
        self.finish_sensor(id, to_world, fov, None)
    }

    fn finish_sensor(
        &mut self,
        id: NodeId,
        to_world: Mat4,
        fov: f32,
        axis: Option<FovAxis>,
    ) -> Result<(Camera, FilmSpec, SamplerSpec)> {
        let node = self.doc.node(id);
        if !(fov > 0.0 && fov < 180.0) {
            return Err(Error::input(
                &node.prop_loc("fov"),
                format!("the field of view must lie strictly between 0 and 180 degrees, got {fov}"),
            ));
        }
        let axis = match axis {
            Some(a) => a,
            None => {
                let s = node.string("fov_axis")?.unwrap_or("x");
                FovAxis::parse(s).ok_or_else(|| {
                    Error::input(
                        &node.prop_loc("fov_axis"),
                        format!("unknown fov_axis \"{s}\" (x, y, diagonal, smaller, larger)"),
                    )
                })?
            }
        };
        let near = positive(node, "near_clip", node.float_or("near_clip", 0.01)?)?;
        let far = positive(node, "far_clip", node.float_or("far_clip", 10000.0)?)?;
        if far <= near {
            return Err(Error::input(&node.prop_loc("far_clip"), "far_clip must exceed near_clip"));
        }
        let film = match self.single_child(id, "film", "a sensor")? {
            None => {
                let (width, height) = self.film_size(768, 576)?;
                FilmSpec { width, height, filter: Filter::Gaussian { stddev: 0.5 }, ldr: None }
            }
            Some(n) => self.film(n)?,
        };
        let sampler = match self.single_child(id, "sampler", "a sensor")? {
            None => SamplerSpec { spp: 4, seed: 0, kind: SamplerKind::Independent },
            Some(n) => self.sampler(n)?,
        };
        self.camera_medium = self.sensor_medium(id)?;
        self.check_unused(id)?;
        let camera = Camera::new(Transform::new(to_world), fov, axis, (film.width, film.height), near, far);
        Ok((camera, film, sampler))
    }

    fn film(&mut self, id: NodeId) -> Result<FilmSpec> {
        let node = self.doc.node(id);
        let ldr = match node.plugin.as_str() {
            "hdrfilm" => {
                self.ignore(node, "gamma");
                None
            }
            "ldrfilm" => Some(self.ldr(id)?),
            _ => return Err(self.unknown_plugin(id, &["hdrfilm", "ldrfilm"])),
        };
        let dim = |name: &str, default: i64| -> Result<u32> {
            let v = node.integer(name)?.unwrap_or(default);
            if v <= 0 || v > 65536 {
                return Err(Error::input(
                    &node.prop_loc(name),
                    format!("film {name} must be between 1 and 65536, got {v}"),
                ));
            }
            Ok(v as u32)
        };
        let width = dim("width", 768)?;
        let height = dim("height", 576)?;
        if width as u64 * height as u64 > MAX_PIXELS {
            return Err(Error::input(
                &node.loc,
                format!("a {width}×{height} film exceeds the limit of {MAX_PIXELS} pixels"),
            ));
        }
        let (width, height) = self.film_size(width, height)?;
        for name in IGNORED_FILM_PROPERTIES {
            self.ignore(node, name);
        }
        // Output format options: this renderer writes float RGB (EXR) or sRGB (PNG) by the
        // output file's extension (an `ldrfilm` read its own).
        for (name, agree) in OUTPUT_FORMAT_PROPERTIES.iter().filter(|_| ldr.is_none()) {
            let agrees = match node.prop(name).map(|p| &p.value) {
                None => continue,
                Some(Value::String(v)) => agree.contains(&v.to_ascii_lowercase().as_str()),
                Some(_) => false,
            };
            if node.legacy || !agrees {
                self.ignore(node, name);
            }
        }
        if node.boolean_or("sample_border", false)? {
            return Err(Error::input(&node.prop_loc("sample_border"), "sample_border = true is not supported"));
        }
        let filter = match self.single_child(id, "rfilter", "a film")? {
            None => Filter::Gaussian { stddev: 0.5 },
            Some(n) => self.rfilter(n)?,
        };
        self.check_unused(id)?;
        Ok(FilmSpec { width, height, filter, ldr })
    }

    /// An `ldrfilm`'s 8-bit output, as Mitsuba 0.5/0.6 writes it: the tonemap (`gamma` with an
    /// `exposure` in f-stops, or `reinhard` with `key` and `burn`), the transfer curve
    /// (`gamma`, -1 for sRGB), PNG (a `jpeg` file format and formats other than RGB are
    /// written as RGB PNG, with a warning).
    fn ldr(&mut self, id: NodeId) -> Result<Ldr> {
        let node = self.doc.node(id);
        let lower = |name: &str, default: &str| -> Result<String> {
            Ok(node.string(name)?.unwrap_or(default).to_ascii_lowercase())
        };
        let file_format = lower("file_format", "png")?;
        if !matches!(file_format.as_str(), "png" | "jpg" | "jpeg") {
            return Err(Error::input(
                &node.prop_loc("file_format"),
                format!("unknown ldrfilm fileFormat \"{file_format}\" (png, jpeg)"),
            ));
        }
        if file_format != "png" {
            self.ignore(node, "file_format");
        }
        let pixel_format = lower("pixel_format", "rgb")?;
        if !matches!(pixel_format.as_str(), "rgb" | "rgba" | "luminance" | "luminancealpha") {
            return Err(Error::input(
                &node.prop_loc("pixel_format"),
                format!("unknown ldrfilm pixelFormat \"{pixel_format}\" (rgb, rgba, luminance, luminanceAlpha)"),
            ));
        }
        if pixel_format != "rgb" {
            self.ignore(node, "pixel_format");
        }
        self.ignore(node, "component_format");
        let gamma = node.float_or("gamma", -1.0)?;
        let transfer = Transfer::from_gamma(gamma).ok_or_else(|| {
            Error::input(&node.prop_loc("gamma"), format!("gamma must be -1 (sRGB) or positive, got {gamma}"))
        })?;
        let method = lower("tonemap_method", "gamma")?;
        let tonemap = match method.as_str() {
            "gamma" => {
                let exposure = node.float_or("exposure", 0.0)?;
                if !exposure.is_finite() {
                    return Err(Error::input(&node.prop_loc("exposure"), "exposure must be a finite number of stops"));
                }
                Tonemap::Exposure(exposure)
            }
            "reinhard" => {
                let key = node.float_or("key", 0.18)?;
                if !(key > 0.0 && key <= 1.0) {
                    return Err(Error::input(&node.prop_loc("key"), format!("key must lie in (0, 1], got {key}")));
                }
                let burn = node.float_or("burn", 0.0)?;
                if !(0.0..=1.0).contains(&burn) {
                    return Err(Error::input(&node.prop_loc("burn"), format!("burn must lie in [0, 1], got {burn}")));
                }
                Tonemap::Reinhard { key, burn }
            }
            _ => {
                return Err(Error::input(
                    &node.prop_loc("tonemap_method"),
                    format!("unknown ldrfilm tonemapMethod \"{method}\" (gamma, reinhard)"),
                ));
            }
        };
        // The other method's parameters mean nothing under this one, as in Mitsuba.
        for name in ["exposure", "key", "burn"] {
            if node.props.iter().any(|p| p.name == name && !p.used.get()) {
                node.float(name)?;
                self.ignore(node, name);
            }
        }
        Ok(Ldr { tonemap, transfer })
    }

    fn rfilter(&mut self, id: NodeId) -> Result<Filter> {
        let node = self.doc.node(id);
        let f = match node.plugin.as_str() {
            "box" => Filter::Box { radius: positive(node, "radius", node.float_or("radius", 0.5)?)? },
            "tent" => Filter::Tent { radius: positive(node, "radius", node.float_or("radius", 1.0)?)? },
            "gaussian" => Filter::Gaussian { stddev: positive(node, "stddev", node.float_or("stddev", 0.5)?)? },
            _ => return Err(self.unknown_plugin(id, &["box", "tent", "gaussian"])),
        };
        if f.radius() > 7.5 {
            return Err(Error::input(&node.loc, "the filter radius may be at most 7.5 pixels"));
        }
        self.check_unused(id)?;
        Ok(f)
    }

    fn sampler(&mut self, id: NodeId) -> Result<SamplerSpec> {
        let node = self.doc.node(id);
        let kind = match node.plugin.as_str() {
            "independent" => SamplerKind::Independent,
            "sobol" => SamplerKind::Sobol,
            p if MAPPED_SAMPLERS.contains(&p) => {
                self.stats.warnings.push(format!(
                    "{}: the \"{p}\" sampler is rendered with the sobol sampler (its sample count and seed apply)",
                    node.loc
                ));
                SamplerKind::Sobol
            }
            _ => {
                let mut known = vec!["independent", "sobol"];
                known.extend_from_slice(MAPPED_SAMPLERS);
                return Err(self.unknown_plugin(id, &known));
            }
        };
        if kind == SamplerKind::Sobol {
            for p in MAPPED_SAMPLER_PROPERTIES.iter().filter_map(|name| node.prop(name)) {
                p.used.set(true);
            }
        }
        let spp = node.integer("sample_count")?.unwrap_or(4);
        if !(1..=1 << 24).contains(&spp) {
            return Err(Error::input(
                &node.prop_loc("sample_count"),
                format!("sample_count must be between 1 and 2^24, got {spp}"),
            ));
        }
        let seed = node.integer("seed")?.unwrap_or(0);
        if seed < 0 {
            return Err(Error::input(&node.prop_loc("seed"), "seed must be non-negative"));
        }
        self.check_unused(id)?;
        Ok(SamplerSpec { spp: spp as u32, seed: seed as u64, kind })
    }

    /// The file's `<integrator>`. When the command line picks the integrator
    /// (`LoadOptions::integrator_override`), the block gives only what applies to any
    /// integrator; its type, if this renderer lacks it, and its other properties are one
    /// warning instead of an error.
    pub(super) fn integrator(&mut self, id: NodeId) -> Result<IntegratorSpec> {
        let node = self.doc.node(id);
        let known = IntegratorKind::from_plugin(&node.plugin).is_some();
        if !known && self.options.integrator_override.is_none() {
            let n = self.node(id);
            return Err(Error::input(
                &n.loc,
                format!(
                    "unknown integrator plugin \"{}\" (supported: {}); or pick one with --integrator, and the file's max_depth and rr_depth apply",
                    n.plugin,
                    IntegratorKind::PLUGINS.join(", ")
                ),
            ));
        }
        let max_depth = node.integer("max_depth")?.unwrap_or(-1);
        if !(-1..=1 << 16).contains(&max_depth) {
            return Err(Error::input(
                &node.prop_loc("max_depth"),
                format!("max_depth must be -1 (unlimited) or between 0 and 65536, got {max_depth}"),
            ));
        }
        let rr_depth = node.integer("rr_depth")?.unwrap_or(3);
        if rr_depth < 1 {
            return Err(Error::input(&node.prop_loc("rr_depth"), "rr_depth must be at least 1"));
        }
        let hide_emitters = node.boolean_or("hide_emitters", false)?;
        // Mitsuba 0.6's path tracer reads it; its other integrators warn of it.
        let strict_normals = self.options.integrator_override.is_none()
            && node.plugin == "path"
            && node.boolean_or("strict_normals", false)?;
        if let Some(chosen) = &self.options.integrator_override {
            let mut rest: Vec<String> = Vec::new();
            for p in node.props.iter().filter(|p| !p.used.get()) {
                p.used.set(true);
                rest.push(format!("\"{}\" ({})", p.name, p.loc));
            }
            for c in node.children.iter().filter(|c| !c.used.get()) {
                c.used.set(true);
                let n = self.node(c.node);
                rest.push(format!("nested {} \"{}\" ({})", n.tag, n.plugin, c.loc));
            }
            if !known || !rest.is_empty() {
                let applied: Vec<&str> = ["max_depth", "rr_depth", "hide_emitters"]
                    .into_iter()
                    .filter(|n| node.props.iter().any(|p| p.name == *n))
                    .collect();
                self.stats.warnings.push(format!(
                    "{}: the scene's integrator \"{}\"{} is replaced by {chosen}{}; ignored: {}",
                    node.loc,
                    node.plugin,
                    if known { "" } else { ", which this renderer lacks," },
                    match applied.as_slice() {
                        [] => String::new(),
                        [one] => format!("; its {one} applies"),
                        more => format!("; its {} apply", more.join(", ")),
                    },
                    if rest.is_empty() { "its type".to_string() } else { rest.join(", ") }
                ));
            }
        }
        self.check_unused(id)?;
        Ok(IntegratorSpec {
            plugin: node.plugin.clone(),
            max_depth: max_depth as i32,
            rr_depth: rr_depth.min(1 << 16) as u32,
            hide_emitters,
            strict_normals,
        })
    }
}
