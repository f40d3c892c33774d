//! Display geometry in the model file: shapes on bodies and nodes, mesh files read with the
//! model (STL binary and text, OBJ), beam tube radii, and located errors for bad input.

use flexmb::input::{parse_model_str, read_model_file};
use flexmb::model::display::ShapeKind;
use flexmb_lie::Vec3;
use std::path::{Path, PathBuf};

const HEAD: &str = r#"flexmb = 1
[model]
group = "SE3"
[solver]
analysis = "dynamic"
t_end = 0.01
h = 1e-3
"#;

fn dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A unit right tetrahedron (4 triangles, outward normals) as binary STL, text STL and OBJ.
fn write_meshes(d: &Path) {
    let v = [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
    ];
    let faces = [[0usize, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]];
    let mut bin = vec![0u8; 80];
    bin.extend_from_slice(&(faces.len() as u32).to_le_bytes());
    let mut text = String::from("solid t\n");
    let mut obj = String::new();
    for p in &v {
        obj.push_str(&format!("v {} {} {}\n", p[0], p[1], p[2]));
    }
    for f in &faces {
        bin.extend_from_slice(&[0u8; 12]);
        text.push_str("facet normal 0 0 0\nouter loop\n");
        for &k in f {
            for c in v[k] {
                bin.extend_from_slice(&c.to_le_bytes());
            }
            text.push_str(&format!("vertex {} {} {}\n", v[k][0], v[k][1], v[k][2]));
        }
        bin.extend_from_slice(&[0u8; 2]);
        text.push_str("endloop\nendfacet\n");
        obj.push_str(&format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1));
    }
    text.push_str("endsolid t\n");
    std::fs::write(d.join("tet.stl"), bin).unwrap();
    std::fs::write(d.join("tet_text.stl"), text).unwrap();
    std::fs::write(d.join("tet.obj"), obj).unwrap();
}

#[test]
fn shapes_meshes_and_tube_radii_are_read_into_the_model() {
    let d = dir("display_good");
    write_meshes(&d);
    let text = format!(
        r##"{HEAD}
[[node]]
name = "marker"
display = [{{ shape = "sphere", radius = 0.05, colour = [1, 0, 0] }}]

[[body]]
name = "link"
mass = 1.0
inertia = [0.1, 0.1, 0.1]
display = [
  {{ shape = "box", size = [1, 0.1, 0.2], position = [0.5, 0, 0], colour = "#ff8000" }},
  {{ shape = "cylinder", radius = 0.02, length = 1.0, orientation = {{ axis = [0, 1, 0], angle_deg = 90 }} }},
  {{ shape = "mesh", file = "tet.stl", scale = 0.001 }},
  {{ shape = "mesh", file = "tet_text.stl" }},
  {{ shape = "mesh", file = "tet.obj", scale = 2 }},
]

[[beam]]
name = "arm"
start = [0, 0, 0]
end = [1, 0, 0]
elements = 3
orientation = [0, 0, 1]
display_radius = 0.03
section = {{ EA = 1e6, GA2 = 1e6, GA3 = 1e6, GJ = 1e3, EI2 = 1e3, EI3 = 1e3, rhoA = 1.0, rhoJ = 0.2, rhoI2 = 0.1, rhoI3 = 0.1 }}
"##
    );
    let model_path = d.join("model.toml");
    std::fs::write(&model_path, &text).unwrap();
    let m = read_model_file(&model_path, &[])
        .expect("the model reads")
        .model;
    let shapes = &m.display.shapes;
    assert_eq!(shapes.len(), 6);
    assert_eq!(m.nodes[shapes[0].node.0].name, "marker");
    assert_eq!(shapes[0].kind, ShapeKind::Sphere { radius: 0.05 });
    assert_eq!(shapes[0].colour, [1.0, 0.0, 0.0]);
    assert_eq!(m.nodes[shapes[1].node.0].name, "link");
    assert_eq!(
        shapes[1].kind,
        ShapeKind::Box {
            size: Vec3::new(1.0, 0.1, 0.2)
        }
    );
    assert_eq!(shapes[1].frame.x, Vec3::new(0.5, 0.0, 0.0));
    assert_eq!(shapes[1].colour, [1.0, 128.0 / 255.0, 0.0]);
    // The cylinder's z axis turned onto x by the rotation about y.
    assert!((shapes[2].frame.r * Vec3::z() - Vec3::x()).norm() < 1e-12);
    let mesh = |k: usize| match &shapes[k].kind {
        ShapeKind::Mesh {
            vertices,
            triangles,
            ..
        } => (vertices.clone(), triangles.clone()),
        other => panic!("not a mesh: {other:?}"),
    };
    for (k, scale) in [(3, 0.001), (4, 1.0), (5, 2.0)] {
        let (v, t) = mesh(k);
        assert_eq!(t.len(), 4, "shape {k}");
        let far = v.iter().map(|p| p.norm()).fold(0.0, f64::max);
        assert!((far - scale).abs() < 1e-9 * scale, "shape {k}: {far}");
        assert!(t.iter().flatten().all(|&i| (i as usize) < v.len()));
    }
    assert_eq!(m.display.tubes.len(), 1);
    assert_eq!(
        (
            m.display.tubes[0].first,
            m.display.tubes[0].count,
            m.display.tubes[0].radius
        ),
        (0, 3, 0.03)
    );
}

/// The error of a model with one body whose `display` is `shape` (one inline table).
fn error_of(shape: &str) -> String {
    let text = format!(
        "{HEAD}\n[[body]]\nname = \"b\"\nmass = 1.0\ninertia = [1, 1, 1]\ndisplay = [{shape}]\n"
    );
    match parse_model_str(&text, "shapes.toml", &[]) {
        Ok(_) => panic!("accepted: {shape}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_shapes_are_errors_naming_file_line_and_field() {
    let cases = [
        ("{ shape = \"cone\", radius = 1 }", "shape"),
        ("{ shape = \"sphere\", radius = -1 }", "radius"),
        (
            "{ shape = \"sphere\", radius = 1, size = [1, 1, 1] }",
            "size",
        ),
        ("{ shape = \"box\", size = [1, 0, 1] }", "size"),
        ("{ shape = \"box\" }", "size"),
        ("{ shape = \"cylinder\", radius = 1 }", "length"),
        (
            "{ shape = \"sphere\", radius = 1, colour = \"#12345\" }",
            "colour",
        ),
        (
            "{ shape = \"sphere\", radius = 1, colour = [1, 2, 0] }",
            "colour",
        ),
        (
            "{ shape = \"sphere\", radius = 1, position = [1, \"a\", 0] }",
            "position",
        ),
        (
            "{ shape = \"sphere\", radius = 1, colour = \"#ffffff\", color = \"#000000\" }",
            "color",
        ),
        ("{ shape = \"sphere\", radius = 1, radiuss = 2 }", "radiuss"),
        ("{ shape = \"mesh\", file = \"missing.stl\" }", "file"),
        ("{ shape = \"mesh\", file = \"part.step\" }", "file"),
        ("{ shape = \"sphere\", radius = nan }", "radius"),
    ];
    for (shape, field) in cases {
        let e = error_of(shape);
        assert!(e.contains("shapes.toml:13:"), "{shape}: {e}");
        assert!(
            e.contains(&format!("display[0].{field}")) || e.contains(&format!("'{field}'")),
            "{shape}: {e}"
        );
    }
}

#[test]
fn a_mesh_that_is_not_a_mesh_is_an_error_with_its_path() {
    let d = dir("display_bad_mesh");
    std::fs::write(d.join("junk.obj"), "f 1 2 3\n").unwrap();
    std::fs::write(d.join("empty.stl"), "solid e\nendsolid e\n").unwrap();
    for file in ["junk.obj", "empty.stl"] {
        let text = format!(
            "{HEAD}\n[[body]]\nname = \"b\"\nmass = 1.0\ninertia = [1, 1, 1]\ndisplay = [{{ shape = \"mesh\", file = \"{file}\" }}]\n"
        );
        let path = d.join("model.toml");
        std::fs::write(&path, text).unwrap();
        let e = read_model_file(&path, &[])
            .expect_err("refused")
            .to_string();
        assert!(e.contains(file) && e.contains("display[0].file"), "{e}");
    }
}
