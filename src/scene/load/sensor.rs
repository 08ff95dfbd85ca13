//! The sensor, its film, reconstruction filter and sampler, and the scene file's
//! integrator block: the parts of a scene that say how to render it rather than what.

use super::{Builder, INTEGRATOR_PLUGINS, MAX_PIXELS, positive};
use crate::camera::{Camera, FovAxis};
use crate::error::{Error, Result};
use crate::film::Filter;
use crate::integrator::IntegratorKind;
use crate::math::Transform;
use crate::scene::xml::{NodeId, Value};
use crate::scene::{FilmSpec, IntegratorSpec, SamplerSpec};
use glam::Mat4;

/// Film properties of Mitsuba 0.5/0.6 (and of other films) that mean nothing to this
/// renderer: accepted, and named in one warning.
const IGNORED_FILM_PROPERTIES: &[&str] = &["high_quality_edges", "banner", "attach_log", "gamma"];

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
                FilmSpec { width, height, filter: Filter::Gaussian { stddev: 0.5 } }
            }
            Some(n) => self.film(n)?,
        };
        let sampler = match self.single_child(id, "sampler", "a sensor")? {
            None => SamplerSpec { spp: 4, seed: 0 },
            Some(n) => self.sampler(n)?,
        };
        self.doc.check_unused(id)?;
        let camera = Camera::new(Transform::new(to_world), fov, axis, (film.width, film.height), near, far);
        Ok((camera, film, sampler))
    }

    fn film(&mut self, id: NodeId) -> Result<FilmSpec> {
        let node = self.doc.node(id);
        if node.plugin != "hdrfilm" {
            return Err(self.unknown_plugin(id, &["hdrfilm"]));
        }
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
        // output file's extension.
        for (name, agree) in OUTPUT_FORMAT_PROPERTIES {
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
        self.doc.check_unused(id)?;
        Ok(FilmSpec { width, height, filter })
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
        self.doc.check_unused(id)?;
        Ok(f)
    }

    fn sampler(&mut self, id: NodeId) -> Result<SamplerSpec> {
        let node = self.doc.node(id);
        if node.plugin != "independent" {
            return Err(self.unknown_plugin(id, &["independent"]));
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
        self.doc.check_unused(id)?;
        Ok(SamplerSpec { spp: spp as u32, seed: seed as u64 })
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
                    INTEGRATOR_PLUGINS.join(", ")
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
        self.doc.check_unused(id)?;
        Ok(IntegratorSpec {
            plugin: node.plugin.clone(),
            max_depth: max_depth as i32,
            rr_depth: rr_depth.min(1 << 16) as u32,
            hide_emitters,
        })
    }
}
