//! Participating media: Mitsuba's `homogeneous` and `heterogeneous` media and their
//! `isotropic` and `hg` phase functions, declared at the top of a file (with an `id`) or
//! nested in a shape (as its `interior` or `exterior`) or in the sensor.
//!
//! Homogeneous coefficients are read as the file's version reads them: Mitsuba 3's
//! `sigma_t` (by default one) and `albedo` (by default 0.75); Mitsuba 0.5/0.6's `sigmaA` and
//! `sigmaS`, or `sigmaT` and `albedo`, each pair given whole (Mitsuba 0.6 filled a missing
//! one from its `Skin1` preset, which this renderer does not have). Both versions take a
//! `scale`.
//!
//! A heterogeneous medium's extinction is a one-channel grid volume (`load/volume.rs`):
//! Mitsuba 3's `sigma_t`, Mitsuba 0.6's `density`, times `scale`; its `albedo` a constant
//! or a grid of one or three channels. Mitsuba 0.6's `method` (`woodcock`, or `simpson`
//! with its `stepSize`) is read as this renderer's delta and ratio tracking, which converge
//! to what either gave. A heterogeneous medium whose extinction and albedo are both
//! constants is a homogeneous one.

use super::Builder;
use super::volume::ReadVolume;
use crate::error::{Error, Result};
use crate::math::Rgb;
use crate::medium::grid::Volume;
use crate::medium::{Heterogeneous, Homogeneous, Medium, MediumInterface, MediumKind, Phase};
use crate::scene::xml::{Node, NodeId};

impl Builder<'_> {
    /// The medium `id` describes (made once however many shapes refer to it).
    pub(super) fn medium(&mut self, id: NodeId) -> Result<u32> {
        if let Some(&m) = self.medium_ids.get(&id) {
            return Ok(m);
        }
        let node = self.node(id);
        let kind = match node.plugin.as_str() {
            "homogeneous" => {
                let (sigma_a, sigma_s) = if node.legacy { legacy_coefficients(node)? } else { coefficients(node)? };
                let scale = scale(node)?;
                MediumKind::Homogeneous(Homogeneous::new(sigma_a * scale, sigma_s * scale))
            }
            "heterogeneous" => self.heterogeneous(id)?,
            _ => return Err(self.unknown_plugin(id, &["homogeneous", "heterogeneous"])),
        };
        let phase = match self.single_child(id, "phase", "a medium")? {
            Some(p) => self.phase(p)?,
            None => Phase::Isotropic,
        };
        let name = node.id.clone().unwrap_or_else(|| node.plugin.clone());
        self.check_unused(id)?;
        self.media.push(Medium { kind, phase, name });
        let m = (self.media.len() - 1) as u32;
        self.medium_ids.insert(id, m);
        Ok(m)
    }

    /// A `heterogeneous` medium's extinction grid, albedo and scale.
    fn heterogeneous(&mut self, id: NodeId) -> Result<MediumKind> {
        let node = self.node(id);
        let extinction = if node.legacy { "density" } else { "sigma_t" };
        if node.legacy {
            self.legacy_method(node)?;
            let nested = self.doc.children(id, "volume").any(|c| c.name.as_deref() == Some("density"));
            if !nested && node.prop("density").is_none() {
                return Err(Error::input(
                    &node.loc,
                    "a heterogeneous medium needs a \"density\" volume (as Mitsuba 0.6 did)",
                ));
            }
        }
        let sigma_t = self.medium_volume(id, extinction, Rgb::ONE)?;
        let albedo = self.medium_volume(id, "albedo", Rgb::splat(0.75))?;
        let scale = scale(node)?;
        check_albedo(&albedo)?;
        check_extinction(&sigma_t, extinction)?;
        let grid = match sigma_t.volume {
            Volume::Grid(grid) => grid,
            Volume::Constant(st) => {
                let st = non_negative(node, extinction, st)?;
                return match albedo.volume {
                    Volume::Constant(al) => {
                        Ok(MediumKind::Homogeneous(Homogeneous::new(st * (Rgb::ONE - al) * scale, st * al * scale)))
                    }
                    Volume::Grid(_) => Err(albedo.error(format!(
                        "a heterogeneous medium with a grid albedo needs a grid \"{extinction}\" too (the medium fills that grid's box)"
                    ))),
                };
            }
        };
        Ok(MediumKind::Heterogeneous(Box::new(Heterogeneous::new(grid, scale, albedo.volume))))
    }

    /// Mitsuba 0.6's `method`: `woodcock` is what this renderer does; `simpson` (a quadrature
    /// of step `stepSize`) converges to the same image, with a warning.
    fn legacy_method(&mut self, node: &Node) -> Result<()> {
        match node.string("method")?.unwrap_or("woodcock") {
            "woodcock" => {}
            "simpson" => {
                node.float("step_size")?;
                self.stats.warnings.push(format!(
                    "{}: the heterogeneous medium's method \"simpson\" (a quadrature of stepSize) is rendered by delta and ratio tracking, unbiased estimators of the same transmittance",
                    node.prop_loc("method")
                ));
            }
            other => {
                return Err(Error::input(
                    &node.prop_loc("method"),
                    format!("unknown heterogeneous medium method \"{other}\" (woodcock or simpson)"),
                ));
            }
        }
        Ok(())
    }

    fn phase(&mut self, id: NodeId) -> Result<Phase> {
        let node = self.node(id);
        let phase = match node.plugin.as_str() {
            "isotropic" => Phase::Isotropic,
            "hg" => {
                let g = node.float_or("g", 0.8)?;
                if !(g > -1.0 && g < 1.0) {
                    return Err(Error::input(
                        &node.prop_loc("g"),
                        format!("the hg phase function's g = {g} must lie in (-1, 1)"),
                    ));
                }
                Phase::HenyeyGreenstein { g }
            }
            _ => return Err(self.unknown_plugin(id, &["isotropic", "hg"])),
        };
        self.check_unused(id)?;
        Ok(phase)
    }

    /// The media a shape's nested or referenced `<medium name="interior|exterior">`
    /// children put on its two sides, if it has any.
    pub(super) fn medium_interface(&mut self, shape: NodeId) -> Result<Option<MediumInterface>> {
        let children: Vec<_> =
            self.doc.children(shape, "medium").map(|c| (c.name.clone(), c.node, c.loc.clone())).collect();
        if children.is_empty() {
            return Ok(None);
        }
        let mut interface = MediumInterface::default();
        for (name, node, loc) in children {
            let side = match name.as_deref() {
                Some("interior") => &mut interface.interior,
                Some("exterior") => &mut interface.exterior,
                _ => {
                    return Err(Error::input(
                        &loc,
                        "a shape's <medium> needs name=\"interior\" or name=\"exterior\" (the side it fills)",
                    ));
                }
            };
            if side.is_some() {
                return Err(Error::input(&loc, format!("a second {} medium", name.unwrap_or_default())));
            }
            *side = Some(self.medium(node)?);
        }
        Ok(Some(interface))
    }

    /// The medium a sensor sits in.
    pub(super) fn sensor_medium(&mut self, sensor: NodeId) -> Result<Option<u32>> {
        match self.single_child(sensor, "medium", "a sensor")? {
            Some(m) => Ok(Some(self.medium(m)?)),
            None => Ok(None),
        }
    }
}

/// A medium's `scale`: finite and non-negative.
fn scale(node: &Node) -> Result<f32> {
    let scale = node.float_or("scale", 1.0)?;
    if !(scale.is_finite() && scale >= 0.0) {
        return Err(Error::input(&node.prop_loc("scale"), format!("medium scale {scale} must be finite and ≥ 0")));
    }
    Ok(scale)
}

/// A heterogeneous medium's extinction grid, if it is one: one channel of finite,
/// non-negative values.
fn check_extinction(read: &ReadVolume, name: &str) -> Result<()> {
    let Volume::Grid(grid) = &read.volume else { return Ok(()) };
    if grid.channels() != 1 {
        return Err(read.error(format!(
            "the \"{name}\" grid has {} channels: extinction is read from one channel (coloured extinction is not supported)",
            grid.channels()
        )));
    }
    if let Some((i, v)) = grid.values().iter().enumerate().find(|(_, v)| !(v.is_finite() && **v >= 0.0)) {
        return Err(read.error(format!("the \"{name}\" grid's value {v} (at index {i}) must be finite and ≥ 0")));
    }
    Ok(())
}

/// A heterogeneous medium's albedo: values in [0, 1], one channel or three.
fn check_albedo(read: &ReadVolume) -> Result<()> {
    let bad = match &read.volume {
        Volume::Constant(v) => {
            (!(v.is_finite() && v.min_element() >= 0.0 && v.max_element() <= 1.0)).then(|| v.to_string())
        }
        Volume::Grid(g) => g.values().iter().find(|v| !(0.0..=1.0).contains(*v)).map(|v| v.to_string()),
    };
    match bad {
        Some(v) => Err(read.error(format!("medium albedo {v} must lie in [0, 1]"))),
        None => Ok(()),
    }
}

/// Mitsuba 3's `sigma_t` and `albedo`, as absorption and scattering coefficients.
fn coefficients(node: &Node) -> Result<(Rgb, Rgb)> {
    let sigma_t = non_negative(node, "sigma_t", node.rgb("sigma_t")?.unwrap_or(Rgb::ONE))?;
    let albedo = albedo(node, node.rgb("albedo")?.unwrap_or(Rgb::splat(0.75)))?;
    Ok((sigma_t * (Rgb::ONE - albedo), sigma_t * albedo))
}

/// Mitsuba 0.5/0.6's `sigmaA` and `sigmaS`, or `sigmaT` and `albedo`.
fn legacy_coefficients(node: &Node) -> Result<(Rgb, Rgb)> {
    for deprecated in ["density_multiplier", "size_multiplier"] {
        if node.prop(deprecated).is_some() {
            return Err(Error::input(
                &node.prop_loc(deprecated),
                format!("\"{deprecated}\" was renamed \"scale\" (as Mitsuba 0.6 said)"),
            ));
        }
    }
    if node.prop("material").is_some() {
        return Err(Error::input(
            &node.prop_loc("material"),
            "named medium presets (\"material\") are not supported: give sigmaA and sigmaS",
        ));
    }
    let pair = |a: &str, b: &str| -> Result<Option<(Rgb, Rgb)>> {
        match (node.rgb(a)?, node.rgb(b)?) {
            (None, None) => Ok(None),
            (Some(x), Some(y)) => Ok(Some((x, y))),
            (given, _) => {
                let (has, lacks) = if given.is_some() { (a, b) } else { (b, a) };
                Err(Error::input(
                    &node.prop_loc(has),
                    format!(
                        "a medium with \"{}\" needs \"{}\" too (Mitsuba 0.6 took it from its Skin1 preset)",
                        legacy_name(has),
                        legacy_name(lacks)
                    ),
                ))
            }
        }
    };
    let sa_ss = pair("sigma_a", "sigma_s")?;
    let st_albedo = pair("sigma_t", "albedo")?;
    match (sa_ss, st_albedo) {
        (Some((sa, ss)), None) => Ok((non_negative(node, "sigma_a", sa)?, non_negative(node, "sigma_s", ss)?)),
        (None, Some((st, al))) => {
            let (st, al) = (non_negative(node, "sigma_t", st)?, albedo(node, al)?);
            Ok((st * (Rgb::ONE - al), st * al))
        }
        (Some(_), Some(_)) => {
            Err(Error::input(&node.prop_loc("sigma_t"), "give sigmaA and sigmaS, or sigmaT and albedo, not both pairs"))
        }
        (None, None) => {
            Err(Error::input(&node.loc, "a homogeneous medium needs sigmaA and sigmaS (or sigmaT and albedo)"))
        }
    }
}

/// A property's name as a version 0.x file spells it (`sigma_a` → `sigmaA`).
fn legacy_name(name: &str) -> String {
    let mut out = String::new();
    let mut upper = false;
    for c in name.chars() {
        match c {
            '_' => upper = true,
            c if upper => {
                out.push(c.to_ascii_uppercase());
                upper = false;
            }
            c => out.push(c),
        }
    }
    out
}

fn non_negative(node: &Node, name: &str, v: Rgb) -> Result<Rgb> {
    if v.is_finite() && v.min_element() >= 0.0 {
        Ok(v)
    } else {
        Err(Error::input(&node.prop_loc(name), format!("medium coefficient {name} = {v} must be finite and ≥ 0")))
    }
}

fn albedo(node: &Node, v: Rgb) -> Result<Rgb> {
    if v.is_finite() && v.min_element() >= 0.0 && v.max_element() <= 1.0 {
        Ok(v)
    } else {
        Err(Error::input(&node.prop_loc("albedo"), format!("medium albedo {v} must lie in [0, 1]")))
    }
}
