//! Mitsuba's `.serialized` meshes in a scene: a shape read from one renders as the same
//! mesh read from an OBJ file, `shape_index` picks the shape, and a missing shape is an
//! error naming the scene's line (the reader's own checks: `src/scene/serialized.rs`).

mod common;

use pcbpt::accel::Backend;
use pcbpt::integrator::IntegratorKind;
use pcbpt::scene::mesh::{self, TriangleMesh};
use pcbpt::scene::serialized::write_serialized;
use pcbpt::scene::{LoadOptions, Scene};
use std::path::Path;

fn scene_with(shape: &str) -> String {
    format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="24"/></film>
    </sensor>
    <shape type="sphere"><point name="center" x="0" y="2" z="2"/><float name="radius" value="0.3"/>
        <emitter type="area"><rgb name="radiance" value="20"/></emitter></shape>
    {shape}
</scene>"#
    )
}

fn obj(m: &TriangleMesh) -> String {
    let mut s = String::new();
    m.positions.iter().for_each(|p| s += &format!("v {} {} {}\n", p.x, p.y, p.z));
    m.uvs.iter().flatten().for_each(|t| s += &format!("vt {} {}\n", t.x, t.y));
    m.normals.iter().flatten().for_each(|n| s += &format!("vn {} {} {}\n", n.x, n.y, n.z));
    for t in &m.indices {
        let [a, b, c] = t.map(|k| k + 1);
        s += &format!("f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}\n");
    }
    s
}

fn render(dir: &Path, name: &str, text: &str) -> Vec<glam::Vec3> {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    let scene = common::load(&path, &[], Backend::Embree);
    common::render(&scene, IntegratorKind::Path, 4, 1, 0).image
}

#[test]
fn a_serialized_mesh_renders_as_the_same_mesh_from_an_obj_file() {
    let dir = tempfile::tempdir().unwrap();
    let (quad, cube) = (mesh::rectangle(), mesh::cube());
    std::fs::write(dir.path().join("meshes.serialized"), write_serialized(&[&cube, &quad])).unwrap();
    std::fs::write(dir.path().join("quad.obj"), obj(&quad)).unwrap();
    let diffuse = r#"<bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.4, 0.2"/></bsdf>"#;
    let from_obj = render(
        dir.path(),
        "obj.xml",
        &scene_with(&format!(
            r#"<shape type="obj"><string name="filename" value="quad.obj"/><boolean name="flip_tex_coords" value="false"/>{diffuse}</shape>"#
        )),
    );
    let from_serialized = render(
        dir.path(),
        "serialized.xml",
        &scene_with(&format!(
            r#"<shape type="serialized"><string name="filename" value="meshes.serialized"/><integer name="shape_index" value="1"/>{diffuse}</shape>"#
        )),
    );
    assert!(from_obj.iter().any(|p| p.x > 0.0), "the quad is lit");
    assert_eq!(from_obj, from_serialized);
    // Shape 0 is the cube: another image.
    let cube_image = render(
        dir.path(),
        "cube.xml",
        &scene_with(&format!(
            r#"<shape type="serialized"><string name="filename" value="meshes.serialized"/>{diffuse}</shape>"#
        )),
    );
    assert_ne!(cube_image, from_serialized);
}

#[test]
fn a_missing_shape_is_an_error_naming_the_line() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("one.serialized"), write_serialized(&[&mesh::rectangle()])).unwrap();
    let text = scene_with(
        r#"<shape type="serialized"><string name="filename" value="one.serialized"/><integer name="shape_index" value="3"/></shape>"#,
    );
    let e = Scene::load_str(&text, &dir.path().join("s.xml"), &LoadOptions::default()).err().unwrap().to_string();
    assert!(e.contains("s.xml:8:") && e.contains("one.serialized") && e.contains("past the file's 1 shape"), "{e}");
}
