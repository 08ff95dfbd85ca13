//! Stage one and two of scene loading: Mitsuba XML → an intermediate tree.
//!
//! The document is parsed with `roxmltree`; `<default>` parameters and `$name` references
//! are substituted (command-line `-D name=value` overrides win over defaults), files
//! version < 2 (Mitsuba 0.5 and 0.6) are upgraded (camelCase names become snake_case,
//! `lookAt` becomes `lookat`, `uscale`/`vscale`/`uoffset`/`voffset` become a `to_uv`
//! transform, a `diffuse` BSDF's `diffuse_reflectance` becomes `reflectance`; parameter
//! names are upgraded alike, in `<default>`s and in `$name` references, so either spelling
//! matches), `<include>` is expanded, and `<ref>`s are resolved (to any object with that
//! id, nested in another or not). The result is a flat arena of [`Node`]s whose
//! properties remember where they came from and whether anything used them, so that an
//! unused property is an error naming its file and line (as in Mitsuba).

use crate::error::{Error, Location, Result};
use glam::{Mat4, Vec3};
use std::cell::Cell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// The kinds of object Mitsuba scenes declare.
pub const OBJECT_TAGS: &[&str] = &[
    "scene",
    "shape",
    "bsdf",
    "emitter",
    "sensor",
    "film",
    "rfilter",
    "sampler",
    "integrator",
    "texture",
    "medium",
    "phase",
    "volume",
    "spectrum_plugin",
];

/// A property value.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Float(f64),
    Integer(i64),
    Boolean(bool),
    String(String),
    Rgb(Vec3),
    /// `<point>` and `<vector>`.
    Vector(Vec3),
    Transform(Mat4),
}

impl Value {
    pub fn type_name(&self) -> &'static str {
        match self {
            Value::Float(_) => "float",
            Value::Integer(_) => "integer",
            Value::Boolean(_) => "boolean",
            Value::String(_) => "string",
            Value::Rgb(_) => "rgb",
            Value::Vector(_) => "point/vector",
            Value::Transform(_) => "transform",
        }
    }
}

#[derive(Debug)]
pub struct Property {
    pub name: String,
    pub value: Value,
    pub loc: Location,
    pub used: Cell<bool>,
}

/// Index of a node in the [`Document`] arena.
pub type NodeId = usize;

/// A nested object (inline or through `<ref>`), with the name it was given.
#[derive(Debug)]
pub struct Child {
    pub name: Option<String>,
    pub node: NodeId,
    pub loc: Location,
    pub used: Cell<bool>,
}

/// One object of the scene: `<shape type="ply" id="floor">…</shape>`.
#[derive(Debug)]
pub struct Node {
    /// The tag: `shape`, `bsdf`, …
    pub tag: String,
    /// The `type` attribute: `ply`, `diffuse`, …
    pub plugin: String,
    pub id: Option<String>,
    pub loc: Location,
    pub props: Vec<Property>,
    pub children: Vec<Child>,
    /// Declared in a version 0.x file (upgraded): properties that only Mitsuba 0.5/0.6
    /// knew may be accepted (see `load.rs`).
    pub legacy: bool,
}

impl Node {
    /// A property by name, marking it used.
    pub fn prop(&self, name: &str) -> Option<&Property> {
        let p = self.props.iter().find(|p| p.name == name)?;
        p.used.set(true);
        Some(p)
    }

    fn type_error(&self, p: &Property, expected: &str) -> Error {
        Error::input(
            &p.loc,
            format!(
                "property \"{}\" of {} \"{}\" has type {}, expected {}",
                p.name,
                self.tag,
                self.plugin,
                p.value.type_name(),
                expected
            ),
        )
    }

    pub fn float(&self, name: &str) -> Result<Option<f32>> {
        match self.prop(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Float(v) => Ok(Some(v as f32)),
                Value::Integer(v) => Ok(Some(v as f32)),
                _ => Err(self.type_error(p, "float")),
            },
        }
    }

    pub fn float_or(&self, name: &str, default: f32) -> Result<f32> {
        Ok(self.float(name)?.unwrap_or(default))
    }

    pub fn integer(&self, name: &str) -> Result<Option<i64>> {
        match self.prop(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Integer(v) => Ok(Some(v)),
                _ => Err(self.type_error(p, "integer")),
            },
        }
    }

    pub fn boolean_or(&self, name: &str, default: bool) -> Result<bool> {
        match self.prop(name) {
            None => Ok(default),
            Some(p) => match p.value {
                Value::Boolean(v) => Ok(v),
                _ => Err(self.type_error(p, "boolean")),
            },
        }
    }

    pub fn string(&self, name: &str) -> Result<Option<&str>> {
        match self.prop(name) {
            None => Ok(None),
            Some(p) => match &p.value {
                Value::String(v) => Ok(Some(v.as_str())),
                _ => Err(self.type_error(p, "string")),
            },
        }
    }

    /// An RGB colour; a float is accepted as grey, as in Mitsuba.
    pub fn rgb(&self, name: &str) -> Result<Option<Vec3>> {
        match self.prop(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Rgb(v) => Ok(Some(v)),
                Value::Float(v) => Ok(Some(Vec3::splat(v as f32))),
                Value::Integer(v) => Ok(Some(Vec3::splat(v as f32))),
                _ => Err(self.type_error(p, "rgb")),
            },
        }
    }

    pub fn vector(&self, name: &str) -> Result<Option<Vec3>> {
        match self.prop(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Vector(v) => Ok(Some(v)),
                _ => Err(self.type_error(p, "point/vector")),
            },
        }
    }

    pub fn transform(&self, name: &str) -> Result<Option<Mat4>> {
        match self.prop(name) {
            None => Ok(None),
            Some(p) => match p.value {
                Value::Transform(m) => Ok(Some(m)),
                _ => Err(self.type_error(p, "transform")),
            },
        }
    }

    /// The location of a property (for errors about its value).
    pub fn prop_loc(&self, name: &str) -> Location {
        self.props.iter().find(|p| p.name == name).map(|p| p.loc.clone()).unwrap_or_else(|| self.loc.clone())
    }
}

/// The parsed scene file: an arena of nodes with the root at index 0.
#[derive(Debug)]
pub struct Document {
    pub nodes: Vec<Node>,
    pub root: NodeId,
    pub path: PathBuf,
    /// Parameters after `<default>`s and command-line overrides.
    pub params: HashMap<String, String>,
    /// The files read: the scene file and its `<include>`s, in the order read.
    pub files: Vec<PathBuf>,
}

impl Document {
    pub fn node(&self, id: NodeId) -> &Node {
        &self.nodes[id]
    }

    /// Children of `id` with the given tag, marking them used.
    pub fn children<'a>(&'a self, id: NodeId, tag: &'a str) -> impl Iterator<Item = &'a Child> + 'a {
        self.nodes[id].children.iter().filter(move |c| self.nodes[c.node].tag == tag).inspect(|c| c.used.set(true))
    }

    /// Fails on the first property or nested object of `id` that nothing used.
    pub fn check_unused(&self, id: NodeId) -> Result<()> {
        let n = &self.nodes[id];
        if let Some(p) = n.props.iter().find(|p| !p.used.get()) {
            return Err(Error::input(
                &p.loc,
                format!("unused property \"{}\" in {} plugin \"{}\"", p.name, n.tag, n.plugin),
            ));
        }
        if let Some(c) = n.children.iter().find(|c| !c.used.get()) {
            let child = &self.nodes[c.node];
            // Where media may be nested.
            let lacking = if child.tag == "medium" || child.tag == "phase" {
                " (a medium belongs to a shape, as its interior or exterior, or to the sensor; a phase function to a medium)"
            } else {
                ""
            };
            return Err(Error::input(
                &c.loc,
                format!(
                    "unexpected nested {} \"{}\" in {} plugin \"{}\"{lacking}",
                    child.tag, child.plugin, n.tag, n.plugin
                ),
            ));
        }
        Ok(())
    }
}

/// The longest attribute value `$parameter` substitution may produce (nested `<default>`s
/// could otherwise grow a value exponentially).
const MAX_SUBSTITUTED: usize = 1 << 20;

/// Reads and parses a scene file with command-line parameter overrides.
pub fn parse_file(path: &Path, overrides: &[(String, String)]) -> Result<Document> {
    parse_str(&Parser::read(path)?, path, overrides)
}

/// Parses scene text as if read from `path`: messages name `path`, and `<include>`s
/// resolve against its folder.
pub fn parse_str(text: &str, path: &Path, overrides: &[(String, String)]) -> Result<Document> {
    let mut p = Parser {
        nodes: Vec::new(),
        ids: HashMap::new(),
        params: HashMap::new(),
        overrides: overrides.iter().cloned().collect(),
        pending_refs: Vec::new(),
        include_depth: 0,
        files: vec![path.to_path_buf()],
        upgrade: false,
    };
    let root = p.parse_root(path, text)?;
    p.resolve_refs()?;
    Ok(Document { nodes: p.nodes, root, path: path.to_path_buf(), params: p.params, files: p.files })
}

struct PendingRef {
    parent: NodeId,
    slot: usize,
    id: String,
    loc: Location,
}

struct Parser {
    nodes: Vec<Node>,
    ids: HashMap<String, (NodeId, Location)>,
    params: HashMap<String, String>,
    overrides: HashMap<String, String>,
    pending_refs: Vec<PendingRef>,
    include_depth: usize,
    files: Vec<PathBuf>,
    /// The file being parsed is version 0.x (its names are upgraded); substitution of
    /// `$name` then upgrades the name as `<default>` names are.
    upgrade: bool,
}

/// `camelCase` → `snake_case`, Mitsuba 3's rule for upgrading version 0.x names.
pub fn camel_to_snake(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 4);
    let chars: Vec<char> = s.chars().collect();
    for (i, &c) in chars.iter().enumerate() {
        if c.is_ascii_uppercase() && i > 0 && (chars[i - 1].is_ascii_lowercase() || chars[i - 1].is_ascii_digit()) {
            out.push('_');
        }
        out.push(c.to_ascii_lowercase());
    }
    out
}

struct FileCtx {
    path: Arc<PathBuf>,
    upgrade: bool,
    /// Byte offsets at which the file's lines start.
    line_starts: Vec<usize>,
}

impl FileCtx {
    fn new(path: Arc<PathBuf>, upgrade: bool, text: &str) -> FileCtx {
        let starts = std::iter::once(0).chain(text.match_indices('\n').map(|(i, _)| i + 1)).collect();
        FileCtx { path, upgrade, line_starts: starts }
    }

    /// The file and line:column of `node`, as roxmltree's `text_pos_at` gives them (line
    /// and column from 1, the column in characters), found in the line index instead of by
    /// counting from the start of the file.
    fn loc(&self, doc: &roxmltree::Document, node: roxmltree::Node) -> Location {
        let pos = node.range().start;
        let row = self.line_starts.partition_point(|&s| s <= pos);
        let start = self.line_starts[row - 1];
        let col = doc.input_text()[start..pos].chars().count() + 1;
        Location { file: self.path.clone(), line: Some(row as u32), col: Some(col as u32) }
    }
}

fn parse_version(s: &str) -> Option<(u32, u32, u32)> {
    let mut it = s.trim().split('.').map(|x| x.parse::<u32>());
    let major = it.next()?.ok()?;
    let minor = it.next().unwrap_or(Ok(0)).ok()?;
    let patch = it.next().unwrap_or(Ok(0)).ok()?;
    Some((major, minor, patch))
}

impl Parser {
    fn read(path: &Path) -> Result<String> {
        let bytes = std::fs::read(path).map_err(|e| Error::in_file(path, format!("cannot read scene file: {e}")))?;
        String::from_utf8(bytes).map_err(|e| {
            Error::in_file(
                path,
                format!("scene file is not UTF-8 text (invalid byte at offset {})", e.utf8_error().valid_up_to()),
            )
        })
    }

    fn parse_root(&mut self, path: &Path, text: &str) -> Result<NodeId> {
        let doc = roxmltree::Document::parse(text).map_err(|e| xml_error(path, &e))?;
        let root = doc.root_element();
        let ctx0 = FileCtx::new(Arc::new(path.to_path_buf()), false, text);
        let loc = ctx0.loc(&doc, root);
        if root.tag_name().name() != "scene" {
            return Err(Error::input(
                &loc,
                format!("the root element is <{}>, expected <scene>", root.tag_name().name()),
            ));
        }
        let version =
            root.attribute("version").ok_or_else(|| Error::input(&loc, "<scene> has no \"version\" attribute"))?;
        let (major, _, _) =
            parse_version(version).ok_or_else(|| Error::input(&loc, format!("invalid version \"{version}\"")))?;
        if major > 3 {
            return Err(Error::input(&loc, format!("scene version {version} is newer than this loader (3.x)")));
        }
        let ctx = FileCtx { upgrade: major < 2, ..ctx0 };
        self.upgrade = ctx.upgrade;
        let id = self.new_node("scene", String::new(), None, loc);
        self.parse_children(&doc, root, id, &ctx)?;
        Ok(id)
    }

    fn new_node(&mut self, tag: &str, plugin: String, id: Option<String>, loc: Location) -> NodeId {
        let legacy = self.upgrade;
        self.nodes.push(Node {
            tag: tag.to_string(),
            plugin,
            id,
            loc,
            props: Vec::new(),
            children: Vec::new(),
            legacy,
        });
        self.nodes.len() - 1
    }

    /// The value of parameter `name`: a command-line override, else a `<default>`. In a
    /// version 0.x file the name is upgraded as `<default>` names are (`$photonCount` finds
    /// `<default name="photonCount">`, stored as `photon_count`), and an override matches
    /// in either spelling.
    fn param(&self, name: &str) -> Option<&String> {
        if !self.upgrade {
            return self.overrides.get(name).or_else(|| self.params.get(name));
        }
        let snake = camel_to_snake(name);
        self.overrides
            .get(name)
            .or_else(|| self.overrides.get(&snake))
            .or_else(|| self.overrides.iter().find(|(k, _)| camel_to_snake(k) == snake).map(|(_, v)| v))
            .or_else(|| self.params.get(&snake))
    }

    /// Substitutes `$name` parameters in an attribute value.
    fn subst(&self, value: &str, loc: &Location) -> Result<String> {
        let mut s = value.to_string();
        for _round in 0..16 {
            if !s.contains('$') {
                return Ok(s);
            }
            let mut out = String::with_capacity(s.len());
            let mut rest = s.as_str();
            while let Some(pos) = rest.find('$') {
                out.push_str(&rest[..pos]);
                let after = &rest[pos + 1..];
                let len = after.find(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).unwrap_or(after.len());
                if len == 0 {
                    return Err(Error::input(loc, format!("\"$\" without a parameter name in \"{value}\"")));
                }
                let name = &after[..len];
                let v = self.param(name).ok_or_else(|| Error::input(loc, format!("undefined parameter \"${name}\" (declare it with <default name=\"{name}\" …/> or pass -D {name}=…)")))?;
                out.push_str(v);
                if out.len() > MAX_SUBSTITUTED {
                    return Err(Error::input(
                        loc,
                        format!("parameter substitution in \"{value}\" grows beyond {MAX_SUBSTITUTED} bytes"),
                    ));
                }
                rest = &after[len..];
            }
            out.push_str(rest);
            s = out;
        }
        Err(Error::input(loc, format!("parameter substitution in \"{value}\" does not terminate (cyclic <default>s)")))
    }

    fn attr(&self, node: roxmltree::Node, name: &str, loc: &Location) -> Result<Option<String>> {
        match node.attribute(name) {
            None => Ok(None),
            Some(v) => Ok(Some(self.subst(v, loc)?)),
        }
    }

    fn req_attr(&self, node: roxmltree::Node, name: &str, loc: &Location) -> Result<String> {
        self.attr(node, name, loc)?
            .ok_or_else(|| Error::input(loc, format!("<{}> needs a \"{name}\" attribute", node.tag_name().name())))
    }

    fn check_attrs(node: roxmltree::Node, allowed: &[&str], loc: &Location) -> Result<()> {
        for a in node.attributes() {
            if !allowed.contains(&a.name()) {
                return Err(Error::input(
                    loc,
                    format!("unexpected attribute \"{}\" on <{}>", a.name(), node.tag_name().name()),
                ));
            }
        }
        Ok(())
    }

    fn parse_children(
        &mut self,
        doc: &roxmltree::Document,
        xml: roxmltree::Node,
        parent: NodeId,
        ctx: &FileCtx,
    ) -> Result<()> {
        // Version-0.x texture coordinate properties, gathered into a `to_uv` transform.
        let mut uv = [None::<f64>; 4]; // uoffset, voffset, uscale, vscale
        let mut uv_loc = None;
        for child in xml.children().filter(|c| c.is_element()) {
            let loc = ctx.loc(doc, child);
            let mut tag = child.tag_name().name().to_string();
            if ctx.upgrade && tag == "lookAt" {
                tag = "lookat".into();
            }
            let name = match child.attribute("name") {
                Some(n) if ctx.upgrade => Some(camel_to_snake(n)),
                Some(n) => Some(n.to_string()),
                None => None,
            };
            // Mitsuba 3's upgrade renames a `diffuse` BSDF's `diffuseReflectance`.
            let name = match name {
                Some(n)
                    if ctx.upgrade
                        && n == "diffuse_reflectance"
                        && self.nodes[parent].tag == "bsdf"
                        && self.nodes[parent].plugin == "diffuse" =>
                {
                    Some("reflectance".to_string())
                }
                n => n,
            };
            match tag.as_str() {
                "default" => {
                    Self::check_attrs(child, &["name", "value"], &loc)?;
                    let name = name.ok_or_else(|| Error::input(&loc, "<default> needs a \"name\" attribute"))?;
                    let value = child
                        .attribute("value")
                        .ok_or_else(|| Error::input(&loc, "<default> needs a \"value\" attribute"))?;
                    if self.params.contains_key(&name) {
                        return Err(Error::input(&loc, format!("<default> \"{name}\" is declared twice")));
                    }
                    let value = self.subst(value, &loc)?;
                    self.params.insert(name, value);
                }
                "include" => {
                    Self::check_attrs(child, &["filename"], &loc)?;
                    let file = self.req_attr(child, "filename", &loc)?;
                    let base = ctx.path.parent().unwrap_or(Path::new("."));
                    let path = base.join(&file);
                    if self.include_depth > 16 {
                        return Err(Error::input(&loc, "includes nested too deeply (a cycle?)"));
                    }
                    let text = Self::read(&path).map_err(|e| Error::input(&loc, format!("in <include>: {e}")))?;
                    self.files.push(path.clone());
                    let inc = roxmltree::Document::parse(&text).map_err(|e| xml_error(&path, &e))?;
                    let r = inc.root_element();
                    let ictx = FileCtx::new(Arc::new(path), false, &text);
                    let rloc = ictx.loc(&inc, r);
                    if r.tag_name().name() != "scene" {
                        return Err(Error::input(&rloc, "an included file must have a <scene> root"));
                    }
                    let v = r
                        .attribute("version")
                        .and_then(parse_version)
                        .ok_or_else(|| Error::input(&rloc, "<scene> needs a valid \"version\" attribute"))?;
                    let ictx = FileCtx { upgrade: v.0 < 2, ..ictx };
                    self.include_depth += 1;
                    self.upgrade = ictx.upgrade;
                    self.parse_children(&inc, r, parent, &ictx)?;
                    self.upgrade = ctx.upgrade;
                    self.include_depth -= 1;
                }
                "ref" => {
                    Self::check_attrs(child, &["id", "name"], &loc)?;
                    let id = self.req_attr(child, "id", &loc)?;
                    let slot = self.nodes[parent].children.len();
                    self.nodes[parent].children.push(Child {
                        name,
                        node: usize::MAX,
                        loc: loc.clone(),
                        used: Cell::new(false),
                    });
                    self.pending_refs.push(PendingRef { parent, slot, id, loc });
                }
                t if OBJECT_TAGS.contains(&t) => {
                    if t == "scene" {
                        return Err(Error::input(&loc, "<scene> cannot be nested"));
                    }
                    Self::check_attrs(child, &["type", "id", "name"], &loc)?;
                    let plugin = self.req_attr(child, "type", &loc)?;
                    let id = self.attr(child, "id", &loc)?;
                    let node = self.new_node(t, plugin, id.clone(), loc.clone());
                    if let Some(id) = id {
                        if let Some((_, first)) = self.ids.get(&id) {
                            return Err(Error::input(
                                &loc,
                                format!("duplicate id \"{id}\" (first declared at {first})"),
                            ));
                        }
                        self.ids.insert(id, (node, loc.clone()));
                    }
                    self.parse_children(doc, child, node, ctx)?;
                    self.nodes[parent].children.push(Child { name, node, loc, used: Cell::new(false) });
                }
                _ => {
                    let name = name.ok_or_else(|| Error::input(&loc, format!("<{tag}> needs a \"name\" attribute")))?;
                    if ctx.upgrade
                        && self.nodes[parent].tag != "scene"
                        && matches!(name.as_str(), "uoffset" | "voffset" | "uscale" | "vscale")
                        && tag == "float"
                    {
                        let v = self.number(&self.req_attr(child, "value", &loc)?, &loc)?;
                        uv[["uoffset", "voffset", "uscale", "vscale"].iter().position(|n| *n == name).unwrap_or(0)] =
                            Some(v);
                        uv_loc.get_or_insert(loc.clone());
                        continue;
                    }
                    let value = self.parse_value(doc, child, &tag, &loc, ctx)?;
                    if self.nodes[parent].props.iter().any(|p| p.name == name) {
                        return Err(Error::input(&loc, format!("property \"{name}\" is specified twice")));
                    }
                    self.nodes[parent].props.push(Property { name, value, loc, used: Cell::new(false) });
                }
            }
        }
        if let Some(loc) = uv_loc {
            let [uo, vo, us, vs] = uv;
            // Texture transforms act on (u, v, 1) through the upper-left 3×3 block (as in
            // Mitsuba 3), so the offsets go in the third column.
            let (us, vs) = (us.unwrap_or(1.0) as f32, vs.unwrap_or(1.0) as f32);
            let (uo, vo) = (uo.unwrap_or(0.0) as f32, vo.unwrap_or(0.0) as f32);
            let m = Mat4::from_cols_array(&[
                us,
                0.0,
                0.0,
                0.0,
                0.0,
                vs,
                0.0,
                0.0,
                uo * us,
                vo * vs,
                1.0,
                0.0,
                0.0,
                0.0,
                0.0,
                1.0,
            ]);
            self.nodes[parent].props.push(Property {
                name: "to_uv".into(),
                value: Value::Transform(m),
                loc,
                used: Cell::new(false),
            });
        }
        Ok(())
    }

    fn number(&self, s: &str, loc: &Location) -> Result<f64> {
        let v: f64 = s.trim().parse().map_err(|_| Error::input(loc, format!("\"{s}\" is not a number")))?;
        if !v.is_finite() {
            return Err(Error::input(loc, format!("\"{s}\" is not a finite number")));
        }
        Ok(v)
    }

    fn numbers(&self, s: &str, loc: &Location) -> Result<Vec<f64>> {
        s.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .map(|t| self.number(t, loc))
            .collect()
    }

    fn vec3_attr(&self, node: roxmltree::Node, loc: &Location, default: f64) -> Result<Vec3> {
        if let Some(v) = self.attr(node, "value", loc)? {
            let n = self.numbers(&v, loc)?;
            return match n.len() {
                1 => Ok(Vec3::splat(n[0] as f32)),
                3 => Ok(Vec3::new(n[0] as f32, n[1] as f32, n[2] as f32)),
                k => Err(Error::input(loc, format!("expected 3 numbers in \"{v}\", found {k}"))),
            };
        }
        let mut out = [default; 3];
        for (i, a) in ["x", "y", "z"].iter().enumerate() {
            if let Some(v) = self.attr(node, a, loc)? {
                out[i] = self.number(&v, loc)?;
            }
        }
        Ok(Vec3::new(out[0] as f32, out[1] as f32, out[2] as f32))
    }

    fn parse_value(
        &self,
        doc: &roxmltree::Document,
        node: roxmltree::Node,
        tag: &str,
        loc: &Location,
        ctx: &FileCtx,
    ) -> Result<Value> {
        let value = || self.req_attr(node, "value", loc);
        Ok(match tag {
            "float" => {
                Self::check_attrs(node, &["name", "value"], loc)?;
                Value::Float(self.number(&value()?, loc)?)
            }
            "integer" => {
                Self::check_attrs(node, &["name", "value"], loc)?;
                let v = value()?;
                let f = self.number(&v, loc)?;
                if f.fract() != 0.0 || f.abs() > 9.0e15 {
                    return Err(Error::input(loc, format!("\"{v}\" is not an integer")));
                }
                Value::Integer(f as i64)
            }
            "boolean" => {
                Self::check_attrs(node, &["name", "value"], loc)?;
                match value()?.trim().to_ascii_lowercase().as_str() {
                    "true" => Value::Boolean(true),
                    "false" => Value::Boolean(false),
                    v => {
                        return Err(Error::input(loc, format!("\"{v}\" is not a boolean (true or false)")));
                    }
                }
            }
            "string" => {
                Self::check_attrs(node, &["name", "value"], loc)?;
                Value::String(value()?)
            }
            "rgb" | "color" => {
                Self::check_attrs(node, &["name", "value"], loc)?;
                let v = value()?;
                let n = self.numbers(&v, loc)?;
                match n.len() {
                    1 => Value::Rgb(Vec3::splat(n[0] as f32)),
                    3 => Value::Rgb(Vec3::new(n[0] as f32, n[1] as f32, n[2] as f32)),
                    k => {
                        return Err(Error::input(loc, format!("<{tag}> needs 1 or 3 numbers, found {k} in \"{v}\"")));
                    }
                }
            }
            "spectrum" => {
                Self::check_attrs(node, &["name", "value", "filename"], loc)?;
                let v = value()?;
                if v.contains(':') {
                    return Err(Error::input(
                        loc,
                        "wavelength-sampled <spectrum> values are not supported by this RGB renderer; give one value or use <rgb>",
                    ));
                }
                let n = self.numbers(&v, loc)?;
                match n.len() {
                    1 => Value::Rgb(Vec3::splat(n[0] as f32)),
                    k => {
                        return Err(Error::input(loc, format!("<spectrum> needs one value, found {k}")));
                    }
                }
            }
            "point" | "vector" => {
                Self::check_attrs(node, &["name", "value", "x", "y", "z"], loc)?;
                Value::Vector(self.vec3_attr(node, loc, 0.0)?)
            }
            "transform" => {
                Self::check_attrs(node, &["name"], loc)?;
                Value::Transform(self.parse_transform(doc, node, ctx)?)
            }
            _ => return Err(Error::input(loc, format!("unknown element <{tag}>"))),
        })
    }

    fn parse_transform(&self, doc: &roxmltree::Document, node: roxmltree::Node, ctx: &FileCtx) -> Result<Mat4> {
        let mut m = Mat4::IDENTITY;
        for op in node.children().filter(|c| c.is_element()) {
            let loc = ctx.loc(doc, op);
            let mut tag = op.tag_name().name().to_string();
            if ctx.upgrade && tag == "lookAt" {
                tag = "lookat".into();
            }
            let step = match tag.as_str() {
                "translate" => {
                    Self::check_attrs(op, &["x", "y", "z", "value"], &loc)?;
                    Mat4::from_translation(self.vec3_attr(op, &loc, 0.0)?)
                }
                "scale" => {
                    Self::check_attrs(op, &["x", "y", "z", "value"], &loc)?;
                    Mat4::from_scale(self.vec3_attr(op, &loc, 1.0)?)
                }
                "rotate" => {
                    Self::check_attrs(op, &["x", "y", "z", "value", "angle"], &loc)?;
                    let axis = self.vec3_attr(op, &loc, 0.0)?;
                    let angle = self.number(&self.req_attr(op, "angle", &loc)?, &loc)?;
                    if axis.length_squared() == 0.0 {
                        return Err(Error::input(&loc, "<rotate> needs a non-zero axis"));
                    }
                    Mat4::from_axis_angle(axis.normalize(), (angle as f32).to_radians())
                }
                "matrix" => {
                    Self::check_attrs(op, &["value"], &loc)?;
                    let v = self.req_attr(op, "value", &loc)?;
                    let n = self.numbers(&v, &loc)?;
                    let n: Vec<f32> = n.iter().map(|&x| x as f32).collect();
                    match n.len() {
                        // Mitsuba writes matrices row by row; glam stores columns.
                        16 => Mat4::from_cols_array(&[
                            n[0], n[4], n[8], n[12], n[1], n[5], n[9], n[13], n[2], n[6], n[10], n[14], n[3], n[7],
                            n[11], n[15],
                        ]),
                        9 => Mat4::from_cols_array(&[
                            n[0], n[3], n[6], 0.0, n[1], n[4], n[7], 0.0, n[2], n[5], n[8], 0.0, 0.0, 0.0, 0.0, 1.0,
                        ]),
                        k => {
                            return Err(Error::input(&loc, format!("<matrix> needs 16 (or 9) numbers, found {k}")));
                        }
                    }
                }
                "lookat" => {
                    Self::check_attrs(op, &["origin", "target", "up"], &loc)?;
                    let p = |a: &str| -> Result<Option<Vec3>> {
                        match self.attr(op, a, &loc)? {
                            None => Ok(None),
                            Some(v) => {
                                let n = self.numbers(&v, &loc)?;
                                if n.len() != 3 {
                                    return Err(Error::input(
                                        &loc,
                                        format!("\"{a}\" needs 3 numbers, found {}", n.len()),
                                    ));
                                }
                                Ok(Some(Vec3::new(n[0] as f32, n[1] as f32, n[2] as f32)))
                            }
                        }
                    };
                    let origin = p("origin")?.ok_or_else(|| Error::input(&loc, "<lookat> needs \"origin\""))?;
                    let target = p("target")?.ok_or_else(|| Error::input(&loc, "<lookat> needs \"target\""))?;
                    let dir = target - origin;
                    if dir.length_squared() == 0.0 {
                        return Err(Error::input(&loc, "<lookat> origin and target coincide"));
                    }
                    let dir = dir.normalize();
                    let up = match p("up")? {
                        Some(u) => u,
                        None => crate::math::Frame::from_normal(dir).s,
                    };
                    let left = up.cross(dir);
                    if left.length_squared() < 1e-12 {
                        return Err(Error::input(&loc, "<lookat> \"up\" is parallel to the viewing direction"));
                    }
                    let left = left.normalize();
                    let new_up = dir.cross(left);
                    Mat4::from_cols(left.extend(0.0), new_up.extend(0.0), dir.extend(0.0), origin.extend(1.0))
                }
                t => {
                    return Err(Error::input(&loc, format!("unknown transform operation <{t}>")));
                }
            };
            m = step * m;
        }
        if !m.is_finite() {
            return Err(Error::input(&ctx.loc(doc, node), "the transform is not finite"));
        }
        Ok(m)
    }

    /// Points every `<ref>` at the object with its id (declared anywhere, nested in another
    /// object or not), then refuses references that make an object contain itself.
    fn resolve_refs(&mut self) -> Result<()> {
        for r in std::mem::take(&mut self.pending_refs) {
            let (node, _) = self
                .ids
                .get(&r.id)
                .ok_or_else(|| Error::input(&r.loc, format!("reference to undefined id \"{}\"", r.id)))?;
            self.nodes[r.parent].children[r.slot].node = *node;
        }
        // Depth-first over nested objects and references: an edge back to an object still
        // being visited closes a cycle (only a reference can).
        let mut state = vec![0u8; self.nodes.len()]; // 0 unseen, 1 being visited, 2 done
        for start in 0..self.nodes.len() {
            if state[start] != 0 {
                continue;
            }
            state[start] = 1;
            let mut stack: Vec<(NodeId, usize)> = vec![(start, 0)];
            while let Some(top) = stack.last_mut() {
                let (node, i) = *top;
                let Some(c) = self.nodes[node].children.get(i) else {
                    state[node] = 2;
                    stack.pop();
                    continue;
                };
                top.1 += 1;
                match state[c.node] {
                    0 => {
                        state[c.node] = 1;
                        stack.push((c.node, 0));
                    }
                    1 => {
                        let target = &self.nodes[c.node];
                        return Err(Error::input(
                            &c.loc,
                            format!(
                                "reference to id \"{}\" makes {} \"{}\" contain itself",
                                target.id.as_deref().unwrap_or(""),
                                target.tag,
                                target.plugin
                            ),
                        ));
                    }
                    _ => {}
                }
            }
        }
        Ok(())
    }
}

fn xml_error(path: &Path, e: &roxmltree::Error) -> Error {
    let pos = e.pos();
    Error::Input {
        loc: Location { file: Arc::new(path.to_path_buf()), line: Some(pos.row), col: Some(pos.col) },
        msg: format!("malformed XML: {e}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The line index gives every node the line and column roxmltree counts out itself.
    #[test]
    fn locations_are_roxmltree_positions() {
        let text = "<scene version=\"3.0.0\">\r\n\t<!-- é ü 字 -->\n  <bsdf type=\"diffuse\" id=\"ä\"><rgb name=\"reflectance\" value=\"0.5\"/>\n</bsdf><shape type=\"sphere\"/>\n\n<shape type=\"obj\">  <string name=\"filename\" value=\"ö.obj\"/></shape></scene>";
        let doc = roxmltree::Document::parse(text).unwrap();
        let ctx = FileCtx::new(Arc::new(PathBuf::from("a.xml")), false, text);
        let mut n = 0;
        for node in doc.descendants() {
            let expect = doc.text_pos_at(node.range().start);
            let loc = ctx.loc(&doc, node);
            assert_eq!((loc.line, loc.col), (Some(expect.row), Some(expect.col)), "{node:?}");
            n += 1;
        }
        assert!(n > 8);
    }

    #[test]
    fn camel_case_upgrade() {
        assert_eq!(camel_to_snake("toWorld"), "to_world");
        assert_eq!(camel_to_snake("intIOR"), "int_ior");
        assert_eq!(camel_to_snake("maxDepth"), "max_depth");
        assert_eq!(camel_to_snake("sampleCount"), "sample_count");
        assert_eq!(camel_to_snake("fov"), "fov");
        assert_eq!(camel_to_snake("specularReflectance"), "specular_reflectance");
    }
}
