//! Volumes, the values a `heterogeneous` medium reads: `gridvolume` (a `.vol` grid, see
//! [`crate::scene::vol`]; Mitsuba 3 also calls it `grid`) and `constvolume`, nested in the
//! medium as `<volume name="...">`, or a plain `float`/`rgb` property of that name.
//!
//! A Mitsuba 3 grid fills the unit cube under its `to_world` (the file's bounding box is
//! used only with `use_grid_bbox`), its values at the cells' centres, looked up with
//! `filter_type` `trilinear` (the default) or `nearest`, beyond the outer centres clamped
//! (`wrap_mode` `clamp`, the only one read). A Mitsuba 0.6 grid fills the file's bounding
//! box (or `min`–`max`) under its `toWorld`, its first and last values on the box's faces.

use super::Builder;
use crate::error::{Error, Location, Result};
use crate::math::Rgb;
use crate::medium::grid::{Grid, Samples, Volume};
use crate::scene::vol::{VolFile, load_vol};
use crate::scene::xml::{Node, NodeId};
use glam::{Affine3A, Mat4, Vec3};

/// A volume as read, with where it was given (the property or the nested volume) and, for
/// a grid, the file it came from.
pub(super) struct ReadVolume {
    pub volume: Volume,
    pub loc: Location,
    pub file: Option<String>,
}

impl ReadVolume {
    /// An error about this volume's values, naming its file where it has one.
    pub fn error(&self, msg: impl std::fmt::Display) -> Error {
        match &self.file {
            Some(f) => Error::input(&self.loc, format!("{f}: {msg}")),
            None => Error::input(&self.loc, msg.to_string()),
        }
    }
}

impl Builder<'_> {
    /// The volume `name` of medium `id`: its nested `<volume name="...">`, or its `float`
    /// or `rgb` property of that name, or `default`.
    pub(super) fn medium_volume(&mut self, id: NodeId, name: &str, default: Rgb) -> Result<ReadVolume> {
        let node = self.node(id);
        let nested: Vec<NodeId> =
            self.doc.children(id, "volume").filter(|c| c.name.as_deref() == Some(name)).map(|c| c.node).collect();
        match nested.as_slice() {
            [] => {
                let value = node.rgb(name)?.unwrap_or(default);
                Ok(ReadVolume { volume: Volume::Constant(value), loc: node.prop_loc(name), file: None })
            }
            [v] => {
                if node.prop(name).is_some() {
                    return Err(Error::input(
                        &node.prop_loc(name),
                        format!("\"{name}\" is given both as a value and as a nested volume"),
                    ));
                }
                self.volume(*v)
            }
            [_, second, ..] => Err(Error::input(&self.node(*second).loc, format!("a second \"{name}\" volume"))),
        }
    }

    /// A `<volume>` node.
    fn volume(&mut self, id: NodeId) -> Result<ReadVolume> {
        let node = self.node(id);
        let read = match node.plugin.as_str() {
            "constvolume" => {
                let value = node.rgb("value")?.unwrap_or(Rgb::ONE);
                ReadVolume { volume: Volume::Constant(value), loc: node.prop_loc("value"), file: None }
            }
            "gridvolume" | "grid" => self.grid_volume(node)?,
            _ => return Err(self.unknown_plugin(id, &["gridvolume", "constvolume"])),
        };
        self.check_unused(id)?;
        Ok(read)
    }

    fn grid_volume(&mut self, node: &Node) -> Result<ReadVolume> {
        let (path, _) = self.existing_file(node, "volume grid")?;
        let loc = node.prop_loc("filename");
        let vol = load_vol(&path).map_err(|e| Error::input(&loc, e.to_string()))?;
        self.stats.files.push(path.clone());
        let to_world = node.transform("to_world")?.unwrap_or(Mat4::IDENTITY);
        let Placement { samples, nearest, bbox } =
            if node.legacy { legacy_placement(node, &vol)? } else { placement(node, &vol)? };
        let to_local = match bbox {
            Some((min, max)) => Affine3A::from_scale(Vec3::ONE / (max - min)) * Affine3A::from_translation(-min),
            None => Affine3A::IDENTITY,
        } * Affine3A::from_mat4(to_world).inverse();
        if !to_local.is_finite() {
            return Err(Error::input(&node.prop_loc("to_world"), "the volume's to_world cannot be inverted"));
        }
        let grid = Grid::new(vol.res, vol.channels, vol.data, to_local, samples, nearest);
        Ok(ReadVolume { volume: Volume::Grid(grid), loc, file: Some(path.display().to_string()) })
    }
}

/// Where a grid's values sit, how they are looked up, and the box of the volume's own
/// space the grid fills (the unit cube where `None`).
struct Placement {
    samples: Samples,
    nearest: bool,
    bbox: Option<(Vec3, Vec3)>,
}

/// Mitsuba 3's placement of a grid: cell-centred values, `filter_type`, `wrap_mode` and, with
/// `use_grid_bbox`, the file's box.
fn placement(node: &Node, vol: &VolFile) -> Result<Placement> {
    let nearest = match node.string("filter_type")?.unwrap_or("trilinear") {
        "trilinear" => false,
        "nearest" => true,
        other => {
            return Err(Error::input(
                &node.prop_loc("filter_type"),
                format!("unknown volume filter_type \"{other}\" (trilinear or nearest)"),
            ));
        }
    };
    match node.string("wrap_mode")?.unwrap_or("clamp") {
        "clamp" => {}
        other => {
            return Err(Error::input(
                &node.prop_loc("wrap_mode"),
                format!("volume wrap_mode \"{other}\" is not supported (clamp is)"),
            ));
        }
    }
    // Mitsuba converts colours to spectra unless `raw`; in RGB there is nothing to convert.
    node.boolean_or("raw", false)?;
    let bbox = node.boolean_or("use_grid_bbox", false)?.then_some(vol.bbox);
    Ok(Placement { samples: Samples::CellCentred, nearest, bbox })
}

/// Mitsuba 0.6's placement of a grid: values on the faces of the file's box, or of the box
/// `min`–`max` given in the scene.
fn legacy_placement(node: &Node, vol: &VolFile) -> Result<Placement> {
    let min = node.vector("min")?.unwrap_or(vol.bbox.0);
    let max = node.vector("max")?.unwrap_or(vol.bbox.1);
    if !(min.is_finite() && max.is_finite() && max.cmpgt(min).all()) {
        return Err(Error::input(&node.prop_loc("max"), format!("the volume's box {min} – {max} is empty")));
    }
    Ok(Placement { samples: Samples::Corners, nearest: false, bbox: Some((min, max)) })
}
