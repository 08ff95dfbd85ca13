//! Generates a reproducible big scene for load, BVH-build and memory measurements: a room
//! lit by a ceiling area light and a point light, its floor a displaced terrain, on which
//! stand eight bumpy tori. Half of the triangles are the terrain's, half the tori's.
//!
//! ```sh
//! cargo run --release --example big_scene -- OUT_DIR [--triangles N]
//! pcbpt render OUT_DIR/big.xml --spp 1 -o big.png
//! ```
//!
//! Writes `big.xml` (Mitsuba 3 XML; `-D resx=… -D resy=… -D spp=…` change the film and the
//! sample count, 1920×1080 by default) and binary little-endian PLY meshes with normals
//! and texture coordinates: `terrain.ply` and `torus0.ply` … `torus7.ply`. The same
//! `--triangles` gives the same files, byte for byte. Default: 10 000 000 triangles.

use std::f64::consts::PI;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// Tori standing on the terrain.
const TORI: usize = 8;
/// Half the side of the square room (x and z in `[-ROOM, ROOM]`).
const ROOM: f64 = 10.0;
/// Height of the room's ceiling.
const CEILING: f64 = 8.0;

/// What [`generate`] wrote.
#[derive(Debug)]
pub struct Summary {
    pub scene: PathBuf,
    pub triangles: u64,
    pub vertices: u64,
    pub bytes: u64,
}

/// Height of the terrain at `(x, z)`: rolling hills with finer ridges.
fn height(x: f64, z: f64) -> f64 {
    let hills = 0.9 * (0.31 * x + 0.7).sin() * (0.27 * z - 0.4).cos() + 0.5 * (0.13 * (x + z)).sin();
    let ridges = 0.12 * (1.9 * x + 0.6 * z).sin() * (1.7 * z - 0.8 * x).cos();
    let fine = 0.025 * (7.3 * x).sin() * (6.1 * z).sin();
    0.8 + hills + ridges + fine
}

/// A point of torus `k`'s surface at angles `(a, b)` (around the ring, around the tube).
fn torus_point(k: usize, a: f64, b: f64) -> [f64; 3] {
    let angle = k as f64 * 2.0 * PI / TORI as f64;
    let (cx, cz) = (5.5 * angle.cos(), 5.5 * angle.sin());
    let (major, minor) = (1.1 + 0.1 * (k % 3) as f64, 0.35);
    let bump = 1.0 + 0.12 * (5.0 * a).sin() * (3.0 * b).sin() + 0.04 * (23.0 * a + 2.0 * b).sin() * (17.0 * b).cos();
    let r = minor * bump;
    // The ring stands upright, turned about the vertical axis towards the room's centre.
    let (lx, ly, lz) = ((major + r * b.cos()) * a.cos(), (major + r * b.cos()) * a.sin(), r * b.sin());
    let (s, c) = angle.sin_cos();
    let (x, z) = (cx + lx * s + lz * c, cz - lx * c + lz * s);
    [x, height(cx, cz) + major + 0.2 + ly, z]
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if l > 0.0 { [v[0] / l, v[1] / l, v[2] / l] } else { [0.0, 1.0, 0.0] }
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// Writes a binary PLY of `vertices` vertices (position, normal, uv) and `faces` triangles
/// to `path` through a temporary file renamed into place.
fn write_ply(
    path: &Path,
    vertices: u64,
    faces: u64,
    mut vertex: impl FnMut(u64) -> ([f64; 3], [f64; 3], [f64; 2]),
    mut face: impl FnMut(u64) -> [u32; 3],
) -> std::io::Result<u64> {
    let tmp = path.with_extension("ply.tmp");
    let mut w = BufWriter::with_capacity(1 << 20, File::create(&tmp)?);
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment pcbpt examples/big_scene.rs\nelement vertex {vertices}\n\
         property float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
         property float u\nproperty float v\nelement face {faces}\nproperty list uchar int vertex_indices\nend_header\n"
    );
    w.write_all(header.as_bytes())?;
    for i in 0..vertices {
        let (p, n, uv) = vertex(i);
        for x in p.iter().chain(&n).chain(&uv) {
            w.write_all(&(*x as f32).to_le_bytes())?;
        }
    }
    for i in 0..faces {
        w.write_all(&[3])?;
        for k in face(i) {
            w.write_all(&k.to_le_bytes())?;
        }
    }
    w.into_inner().map_err(|e| e.into_error())?.sync_all()?;
    std::fs::rename(&tmp, path)?;
    Ok(header.len() as u64 + vertices * 32 + faces * 13)
}

/// The terrain: a `g × g` grid of quads over the floor (`2 g²` triangles).
fn terrain(path: &Path, g: u64) -> std::io::Result<u64> {
    let n = g + 1;
    let step = 2.0 * ROOM / g as f64;
    let vertex = |i: u64| {
        let (ix, iz) = (i % n, i / n);
        let (x, z) = (-ROOM + ix as f64 * step, -ROOM + iz as f64 * step);
        let e = 1e-3;
        let dx = (height(x + e, z) - height(x - e, z)) / (2.0 * e);
        let dz = (height(x, z + e) - height(x, z - e)) / (2.0 * e);
        ([x, height(x, z), z], normalize([-dx, 1.0, -dz]), [ix as f64 / g as f64, iz as f64 / g as f64])
    };
    let face = |f: u64| {
        let (q, second) = (f / 2, f % 2 == 1);
        let (ix, iz) = (q % g, q / g);
        let v = |dx: u64, dz: u64| ((iz + dz) * n + ix + dx) as u32;
        // Counter-clockwise seen from above: normals point up.
        if second { [v(1, 0), v(0, 1), v(1, 1)] } else { [v(0, 0), v(0, 1), v(1, 0)] }
    };
    write_ply(path, n * n, 2 * g * g, vertex, face)
}

/// Torus `k`: `ring × tube` quads, closed in both directions (`2 ring tube` triangles).
fn torus(path: &Path, k: usize, ring: u64, tube: u64) -> std::io::Result<u64> {
    let angles = |i: u64| (2.0 * PI * (i % ring) as f64 / ring as f64, 2.0 * PI * (i / ring) as f64 / tube as f64);
    let vertex = |i: u64| {
        let (a, b) = angles(i);
        let e = 1e-4;
        let da = sub(torus_point(k, a + e, b), torus_point(k, a - e, b));
        let db = sub(torus_point(k, a, b + e), torus_point(k, a, b - e));
        let uv = [(i % ring) as f64 / ring as f64, (i / ring) as f64 / tube as f64];
        (torus_point(k, a, b), normalize(cross(da, db)), uv)
    };
    let face = |f: u64| {
        let (q, second) = (f / 2, f % 2 == 1);
        let (ia, ib) = (q % ring, q / ring);
        let v = |da: u64, db: u64| (((ib + db) % tube) * ring + (ia + da) % ring) as u32;
        if second { [v(1, 0), v(1, 1), v(0, 1)] } else { [v(0, 0), v(1, 0), v(0, 1)] }
    };
    write_ply(path, ring * tube, 2 * ring * tube, vertex, face)
}

/// The scene file: room, lights, camera, and the meshes with their materials.
fn scene_xml(tori: usize) -> String {
    let mut s = String::from(
        r#"<scene version="3.0.0">
  <default name="resx" value="1920"/>
  <default name="resy" value="1080"/>
  <default name="spp" value="4"/>
  <integrator type="path"><integer name="max_depth" value="8"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="60"/>
    <transform name="to_world"><lookat origin="-9.3, 6.0, -9.3" target="1.5, 0.5, 1.5" up="0, 1, 0"/></transform>
    <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
    <film type="hdrfilm"><integer name="width" value="$resx"/><integer name="height" value="$resy"/><rfilter type="box"/></film>
  </sensor>
  <bsdf type="diffuse" id="wall"><rgb name="reflectance" value="0.75, 0.73, 0.70"/></bsdf>
  <bsdf type="diffuse" id="ground"><rgb name="reflectance" value="0.35, 0.45, 0.25"/></bsdf>
  <bsdf type="roughplastic" id="glaze"><float name="alpha" value="0.15"/><rgb name="diffuse_reflectance" value="0.60, 0.25, 0.15"/></bsdf>
  <bsdf type="roughconductor" id="metal"><string name="material" value="Au"/><float name="alpha" value="0.2"/></bsdf>
  <shape type="rectangle" id="ceiling-light">
    <transform name="to_world"><rotate x="1" angle="90"/><scale x="2.5" y="1" z="2.5"/><translate y="7.99"/></transform>
    <emitter type="area"><rgb name="radiance" value="14, 13, 11"/></emitter>
  </shape>
  <emitter type="point"><point name="position" x="6" y="5" z="-6"/><rgb name="intensity" value="30, 30, 36"/></emitter>
"#,
    );
    // Walls and ceiling: rectangles facing into the room.
    let (r, h) = (ROOM, CEILING / 2.0);
    let walls = [
        ("ceiling", format!(r#"<rotate x="1" angle="90"/><scale x="{r}" y="1" z="{r}"/><translate y="{CEILING}"/>"#)),
        ("wall-north", format!(r#"<scale x="{r}" y="{h}" z="1"/><translate y="{h}" z="-{r}"/>"#)),
        (
            "wall-south",
            format!(r#"<rotate y="1" angle="180"/><scale x="{r}" y="{h}" z="1"/><translate y="{h}" z="{r}"/>"#),
        ),
        (
            "wall-west",
            format!(r#"<rotate y="1" angle="90"/><scale x="1" y="{h}" z="{r}"/><translate x="-{r}" y="{h}"/>"#),
        ),
        (
            "wall-east",
            format!(r#"<rotate y="1" angle="-90"/><scale x="1" y="{h}" z="{r}"/><translate x="{r}" y="{h}"/>"#),
        ),
    ];
    for (id, t) in walls {
        s += &format!(
            "  <shape type=\"rectangle\" id=\"{id}\"><transform name=\"to_world\">{t}</transform><ref id=\"wall\"/></shape>\n"
        );
    }
    s += "  <shape type=\"ply\" id=\"terrain\"><string name=\"filename\" value=\"terrain.ply\"/><ref id=\"ground\"/></shape>\n";
    for k in 0..tori {
        let bsdf = if k % 2 == 0 { "glaze" } else { "metal" };
        s += &format!(
            "  <shape type=\"ply\" id=\"torus{k}\"><string name=\"filename\" value=\"torus{k}.ply\"/><ref id=\"{bsdf}\"/></shape>\n"
        );
    }
    s + "</scene>\n"
}

/// Writes the scene of at least `triangles` triangles (at least 1000) into `dir`.
pub fn generate(dir: &Path, triangles: u64) -> std::io::Result<Summary> {
    let triangles = triangles.max(1000);
    std::fs::create_dir_all(dir)?;
    // Half for the terrain (2 g² ≥ triangles / 2), half for the tori (2 ring tube each).
    let g = ((triangles as f64 / 4.0).sqrt().ceil() as u64).max(1);
    let per_torus = triangles.div_ceil(2 * TORI as u64);
    let tube = ((per_torus as f64 / 4.0).sqrt().ceil() as u64).max(3);
    let ring = per_torus.div_ceil(2 * tube).max(3);
    let mut bytes = terrain(&dir.join("terrain.ply"), g)?;
    for k in 0..TORI {
        bytes += torus(&dir.join(format!("torus{k}.ply")), k, ring, tube)?;
    }
    let scene = dir.join("big.xml");
    let tmp = dir.join("big.xml.tmp");
    std::fs::write(&tmp, scene_xml(TORI))?;
    std::fs::rename(&tmp, &scene)?;
    Ok(Summary {
        scene,
        triangles: 2 * g * g + TORI as u64 * 2 * ring * tube,
        vertices: (g + 1) * (g + 1) + TORI as u64 * ring * tube,
        bytes,
    })
}

#[allow(dead_code)]
fn main() -> std::process::ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let usage = "usage: big_scene OUT_DIR [--triangles N]";
    let (mut dir, mut triangles) = (None, 10_000_000u64);
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--triangles" => match it.next().map(|n| n.replace('_', "").parse::<u64>()) {
                Some(Ok(n)) if n <= 1 << 31 => triangles = n,
                _ => {
                    eprintln!("--triangles needs a whole number up to 2^31\n{usage}");
                    return std::process::ExitCode::FAILURE;
                }
            },
            "-h" | "--help" => {
                eprintln!("{usage}");
                return std::process::ExitCode::SUCCESS;
            }
            d if dir.is_none() && !d.starts_with('-') => dir = Some(PathBuf::from(d)),
            other => {
                eprintln!("unexpected argument \"{other}\"\n{usage}");
                return std::process::ExitCode::FAILURE;
            }
        }
    }
    let Some(dir) = dir else {
        eprintln!("{usage}");
        return std::process::ExitCode::FAILURE;
    };
    match generate(&dir, triangles) {
        Ok(s) => {
            eprintln!(
                "wrote {}: {} triangles, {} vertices, {:.1} MB of meshes",
                s.scene.display(),
                s.triangles,
                s.vertices,
                s.bytes as f64 / 1e6
            );
            std::process::ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("error: cannot write the scene into {}: {e}", dir.display());
            std::process::ExitCode::FAILURE
        }
    }
}
