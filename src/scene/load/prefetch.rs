//! Reading a scene's files ahead, on all the loader's threads: before the builder walks the
//! document, every OBJ mesh a `shape` names and every image a `bitmap` texture or an
//! `envmap` names is read, decoded and laid out as a bitmap in parallel; the builder then
//! takes each file from here where it would have read it. A scene of hundreds of OBJ files
//! and a dozen JPEG textures (Bitterli's interiors) loads in a fraction of the time one
//! thread takes.
//!
//! Nothing is decided here: a result (an error included) waits until the builder asks for
//! its file, so a file no plugin uses is never an error, and the builder's messages name the
//! line that uses the file as before. What the builder does not find here (a file it reads
//! a second time, a PLY file, which is streamed with a progress bar, a mask's opacity
//! bitmap, read for its alpha) it reads itself.

use super::mesh::{self, TriangleMesh};
use crate::error::Result;
use crate::scene::xml::{Document, Node, NodeId, Value};
use crate::texture::Bitmap;
use rayon::prelude::*;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// One file to read ahead.
enum File {
    Mesh(PathBuf),
    /// An image and whether its 8-bit values are kept raw (`raw` of a `bitmap`).
    Texture(PathBuf, bool),
}

/// A file as read.
enum Read {
    Mesh(PathBuf, Result<TriangleMesh>),
    Texture(PathBuf, bool, Result<Bitmap>),
}

/// What was read ahead, by file.
#[derive(Default)]
pub(super) struct Prefetched {
    meshes: HashMap<PathBuf, Result<TriangleMesh>>,
    textures: HashMap<(PathBuf, bool), Result<Bitmap>>,
}

/// A string property's value, without marking the property used (the builder reads it
/// again and checks it).
fn string<'n>(node: &'n Node, name: &str) -> Option<&'n str> {
    node.props.iter().find(|p| p.name == name).and_then(|p| match &p.value {
        Value::String(s) => Some(s.as_str()),
        _ => None,
    })
}

/// A boolean property's value or `default` (`None` where it is not a boolean: the builder
/// reports that).
fn boolean(node: &Node, name: &str, default: bool) -> Option<bool> {
    match node.props.iter().find(|p| p.name == name).map(|p| &p.value) {
        None => Some(default),
        Some(Value::Boolean(b)) => Some(*b),
        Some(_) => None,
    }
}

impl Prefetched {
    /// Reads every OBJ mesh and texture image the document names (relative to `base`), in
    /// parallel on the current thread pool.
    pub(super) fn read(doc: &Document, base: &Path) -> Prefetched {
        // A mask's opacity bitmap is read for its alpha channel (`load/mask.rs`), not as a
        // colour texture: decoding it here would be work for nothing.
        let opacities: HashSet<NodeId> = (doc.nodes.iter())
            .filter(|n| n.tag == "bsdf" && n.plugin == "mask")
            .flat_map(|n| n.children.iter().filter(|c| c.name.as_deref() == Some("opacity")).map(|c| c.node))
            .collect();
        let mut files: Vec<File> = Vec::new();
        for (id, node) in doc.nodes.iter().enumerate() {
            let Some(filename) = string(node, "filename") else { continue };
            let path = base.join(filename);
            match (node.tag.as_str(), node.plugin.as_str()) {
                ("shape", "obj") => files.push(File::Mesh(path)),
                ("texture", "bitmap") if !opacities.contains(&id) => {
                    if let Some(raw) = boolean(node, "raw", false) {
                        files.push(File::Texture(path, raw));
                    }
                }
                ("emitter", "envmap") => files.push(File::Texture(path, false)),
                _ => {}
            }
        }
        let mut seen = HashSet::new();
        files.retain(|f| match f {
            File::Mesh(p) => p.is_file() && seen.insert((p.clone(), None)),
            File::Texture(p, raw) => p.is_file() && seen.insert((p.clone(), Some(*raw))),
        });
        // Largest first, each thread taking the next file from the queue as it finishes one:
        // a few large files among hundreds of small ones keep every thread busy to the end
        // (rayon's halving of the list left one thread with the large ones).
        let size = |f: &File| match f {
            File::Mesh(p) | File::Texture(p, _) => std::fs::metadata(p).map(|m| m.len()).unwrap_or(0),
        };
        files.sort_by_cached_key(|f| std::cmp::Reverse(size(f)));
        let queue = Mutex::new(files.into_iter());
        let next = || queue.lock().unwrap_or_else(|e| e.into_inner()).next();
        let read: Vec<Read> = (0..rayon::current_num_threads())
            .into_par_iter()
            .with_max_len(1)
            .flat_map_iter(|_| {
                std::iter::from_fn(|| {
                    Some(match next()? {
                        File::Mesh(p) => {
                            let m = mesh::load_obj(&p);
                            Read::Mesh(p, m)
                        }
                        File::Texture(p, raw) => {
                            let t = super::texture::read_bitmap(&p, raw);
                            Read::Texture(p, raw, t)
                        }
                    })
                })
            })
            .collect();
        let mut out = Prefetched::default();
        for r in read {
            match r {
                Read::Mesh(p, m) => {
                    out.meshes.insert(p, m);
                }
                Read::Texture(p, raw, t) => {
                    out.textures.insert((p, raw), t);
                }
            }
        }
        out
    }

    /// The OBJ mesh at `path`, if it was read ahead (once: a second call reads nothing).
    pub(super) fn take_mesh(&mut self, path: &Path) -> Option<Result<TriangleMesh>> {
        self.meshes.remove(path)
    }

    /// The bitmap of the image at `path` read with `raw`, if it was read ahead (once), with
    /// its filter and wrap mode still to be set.
    pub(super) fn take_texture(&mut self, path: &Path, raw: bool) -> Option<Result<Bitmap>> {
        self.textures.remove(&(path.to_path_buf(), raw))
    }
}
