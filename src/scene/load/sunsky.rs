//! The `sunsky` emitter and its halves `sun` and `sky` (Mitsuba 0.6's plugins; here a
//! `sunsky` with the other half off), with Mitsuba 3's parameters and Mitsuba 0.6's upgraded.
//! A file of version 0.x gets Mitsuba 0.6's sun ([`sun06`]: its radiance, its size and
//! `sunRadiusScale`, 0 for a directional sun) beside the Hosek–Wilkie sky both versions share.

use super::Builder;
use crate::error::{Error, Result};
use crate::light::Light;
use crate::light::sun06;
use crate::light::sunsky::{self, DateTime, Place, SUN_APERTURE_DEG, Sky, Sun, SunSkyParams};
use crate::scene::xml::{Node, NodeId};
use glam::{Mat3, Mat4, Vec3};
use std::sync::Arc;

/// The properties that place the sun by date, time and location.
const DATE_TIME: &[&str] = &["latitude", "longitude", "timezone", "year", "month", "day", "hour", "minute", "second"];

/// Mitsuba 0.6's local frame of the sky (`+y` up, azimuth measured from `-z` towards `+x`)
/// in terms of Mitsuba 3's (`+z` up, azimuth from `+x` towards `+y`, the sun's azimuth from
/// a date offset by π): a version 0.x file's sky keeps its horizon and its sun.
const LEGACY_FRAME: Mat3 = Mat3::from_cols(Vec3::Z, Vec3::NEG_X, Vec3::Y);

/// A number property that must lie in `[lo, hi]`.
fn in_range(node: &Node, name: &str, default: f32, lo: f32, hi: f32) -> Result<f32> {
    let v = node.float_or(name, default)?;
    if (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(Error::input(
            &node.prop_loc(name),
            format!("\"{name}\" of {} must be within [{lo}, {hi}], got {v}", node.plugin),
        ))
    }
}

/// An integer property that must lie in `[lo, hi]`.
fn int_in_range(node: &Node, name: &str, default: i64, lo: i64, hi: i64) -> Result<i32> {
    let v = node.integer(name)?.unwrap_or(default);
    if (lo..=hi).contains(&v) {
        Ok(v as i32)
    } else {
        Err(Error::input(
            &node.prop_loc(name),
            format!("\"{name}\" of {} must be within [{lo}, {hi}], got {v}", node.plugin),
        ))
    }
}

impl Builder<'_> {
    /// The lights of a `sunsky`, `sun` or `sky` emitter: the sky and the sun, each only when
    /// it shines (a scale of zero, or a sun below the horizon, leaves it out).
    pub(super) fn sunsky(&mut self, id: NodeId) -> Result<Vec<Light>> {
        let node = self.node(id);
        let plugin = node.plugin.as_str();
        let (has_sun, has_sky) = match plugin {
            "sun" => (true, false),
            "sky" => (false, true),
            _ => (true, true),
        };
        // Mitsuba 0.6's `scale` scales what the plugin emits (sun and sky for `sunsky`).
        let scale = if node.legacy { in_range(node, "scale", 1.0, 0.0, f32::MAX)? } else { 1.0 };
        let sun_scale = if has_sun { in_range(node, "sun_scale", scale, 0.0, f32::MAX)? } else { 0.0 };
        let sky_scale = if has_sky { in_range(node, "sky_scale", scale, 0.0, f32::MAX)? } else { 0.0 };
        let turbidity = in_range(node, "turbidity", 3.0, 1.0, 10.0)?;
        // Mitsuba 0.6's sky defaults to a ground albedo of 0.2, Mitsuba 3's to 0.3.
        let albedo = node.rgb("albedo")?.unwrap_or(Vec3::splat(if node.legacy { 0.2 } else { 0.3 }));
        if !(albedo.min_element() >= 0.0 && albedo.max_element() <= 1.0) {
            return Err(Error::input(
                &node.prop_loc("albedo"),
                format!("\"albedo\" of {plugin} must be within [0, 1] in every channel, got {albedo}"),
            ));
        }
        // Mitsuba 0.6's sunRadiusScale of 0 makes the sun a directional light.
        let mut directional_sun = false;
        let sun_aperture = if node.legacy && node.prop("sun_radius_scale").is_some() {
            let s = node.float("sun_radius_scale")?.unwrap_or(1.0);
            if !(s >= 0.0 && SUN_APERTURE_DEG * s < 180.0) {
                return Err(Error::input(
                    &node.prop_loc("sun_radius_scale"),
                    format!(
                        "\"sunRadiusScale\" must be 0 (a directional sun) or positive and give a sun smaller than a half sphere, got {s}"
                    ),
                ));
            }
            directional_sun = s == 0.0;
            if directional_sun { SUN_APERTURE_DEG } else { SUN_APERTURE_DEG * s }
        } else {
            let a = node.float_or("sun_aperture", SUN_APERTURE_DEG)?;
            if !(a > 0.0 && a < 180.0) {
                return Err(Error::input(
                    &node.prop_loc("sun_aperture"),
                    format!("\"sun_aperture\" must be within ]0, 180[ degrees, got {a}"),
                ));
            }
            a
        };
        let complex_sun = node.boolean_or("complex_sun", false)?;
        let m = node.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
        let mut to_world = Mat3::from_mat4(m);
        let det = to_world.determinant();
        if det.is_nan() || det.abs() <= 1e-6 {
            return Err(Error::input(
                &node.prop_loc("to_world"),
                format!("the {plugin} emitter's to_world is singular"),
            ));
        }
        if node.legacy {
            to_world *= LEGACY_FRAME;
        }
        let sun_local = if let Some(d) = node.vector("sun_direction")? {
            if let Some(p) = DATE_TIME.iter().find(|p| node.props.iter().any(|q| q.name == **p)) {
                return Err(Error::input(
                    &node.prop_loc(p),
                    format!("\"{p}\" and \"sun_direction\" both place the sun: give one or the other"),
                ));
            }
            if !d.is_finite() || d.length_squared() == 0.0 {
                return Err(Error::input(&node.prop_loc("sun_direction"), "\"sun_direction\" must be non-zero"));
            }
            (to_world.inverse() * d.normalize()).normalize()
        } else {
            let place = Place {
                latitude: in_range(node, "latitude", Place::default().latitude, -90.0, 90.0)?,
                longitude: in_range(node, "longitude", Place::default().longitude, -360.0, 360.0)?,
                timezone: in_range(node, "timezone", Place::default().timezone, -24.0, 24.0)?,
            };
            let d = DateTime::default();
            let time = DateTime {
                year: int_in_range(node, "year", d.year as i64, -4000, 100_000)?,
                month: int_in_range(node, "month", d.month as i64, 1, 12)?,
                day: int_in_range(node, "day", d.day as i64, 1, 31)?,
                hour: in_range(node, "hour", d.hour, 0.0, 24.0)?,
                minute: in_range(node, "minute", d.minute, 0.0, 60.0)?,
                second: in_range(node, "second", d.second, 0.0, 60.0)?,
            };
            let (theta, phi) = sunsky::sun_coordinates(&time, &place);
            sunsky::sph_to_dir(theta, phi)
        };
        // Mitsuba 0.6's baked environment map and its options mean nothing here.
        let mut ignored = Vec::new();
        if node.legacy {
            for name in ["resolution", "stretch", "extend"] {
                if node.prop(name).is_some() {
                    ignored.push(name);
                }
            }
        }
        let loc = node.loc.clone();
        if !ignored.is_empty() {
            self.stats.warnings.push(format!(
                "{loc}: ignored Mitsuba 0.6 propert{} of {plugin}: {} (the sky is evaluated in every direction, not baked into an image)",
                if ignored.len() == 1 { "y" } else { "ies" },
                ignored.join(", ")
            ));
        }
        self.check_unused(id)?;
        let sun06 = node.legacy;
        let params = SunSkyParams {
            to_world,
            sun_local,
            turbidity,
            albedo,
            sun_scale,
            sky_scale,
            sun_aperture,
            complex_sun,
            sun06,
        };
        if !params.sun_visible() {
            self.stats.warnings.push(format!(
                "{loc}: the sun is below the horizon ({:.2}° elevation): the {plugin} emitter is black, as in Mitsuba 3",
                90.0 - sun_local.z.clamp(-1.0, 1.0).acos().to_degrees()
            ));
            return Ok(Vec::new());
        }
        let mut lights = Vec::new();
        if sky_scale > 0.0 {
            lights.push(Light::Sky(Arc::new(Sky::new(&params))));
        }
        if sun_scale > 0.0 && directional_sun {
            let zenith = sun_local.z.clamp(-1.0, 1.0).acos();
            let irradiance = sun06::irradiance(zenith, turbidity) * sun_scale;
            lights.push(Light::Directional { direction: -(to_world * sun_local).normalize(), irradiance });
        } else if sun_scale > 0.0 {
            lights.push(Light::Sun(Arc::new(Sun::new(&params))));
        }
        Ok(lights)
    }
}
