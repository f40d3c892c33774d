//! The display geometry of a model file: `display = [...]` on a `[[body]]` or a `[[node]]`
//! (shapes on its node) and `display_radius` on a `[[beam]]` (docs/model-format.md,
//! "Display geometry"). Mesh files (STL, binary or text, and OBJ) are read here, relative
//! to the model file's folder, so that a bad mesh is an error of the model file.

use super::fields::{physical, point};
use super::reader::{Field, Result, Table};
use crate::model::display::{Shape, ShapeKind};
use crate::model::limits::MAX_KINEMATIC;
use crate::model::NodeId;
use flexmb_lie::{Frame, Mat3, Vec3};
use std::path::Path;

/// Keys of one shape.
const SHAPE_KEYS: &[&str] = &[
    "shape",
    "size",
    "radius",
    "length",
    "file",
    "scale",
    "position",
    "orientation",
    "colour",
    "color",
];

/// Most triangles of one mesh file.
const MAX_TRIANGLES: usize = 2_000_000;

/// Reads the `display` array of `t` (if any) into shapes on `node`.
pub(super) fn read_shapes(t: &Table<'_>, node: NodeId, out: &mut Vec<Shape>) -> Result<()> {
    let Some(f) = t.field("display") else {
        return Ok(());
    };
    for (i, v) in f.array()?.iter().enumerate() {
        out.push(read_shape(&f.elem(i, v), node)?);
    }
    Ok(())
}

fn read_shape(f: &Field<'_>, node: NodeId) -> Result<Shape> {
    let t = f.table()?;
    t.check_keys(SHAPE_KEYS)?;
    let kind = t
        .req("shape")?
        .choice(&["box", "cylinder", "sphere", "mesh"])?;
    let allowed: &[&str] = match kind {
        "box" => &["size"],
        "cylinder" => &["radius", "length"],
        "sphere" => &["radius"],
        _ => &["file", "scale"],
    };
    for key in ["size", "radius", "length", "file", "scale"] {
        if !allowed.contains(&key) {
            t.forbid(key, &format!("with shape = \"{kind}\""))?;
        }
    }
    let size = |key: &str| -> Result<f64> { physical(&t.req(key)?) };
    let kind = match kind {
        "box" => {
            let sf = t.req("size")?;
            let s = sf.vec3_within(MAX_KINEMATIC)?;
            if s.iter().any(|&x| x <= 0.0) {
                return Err(sf.err("the three sides must be positive"));
            }
            ShapeKind::Box { size: s }
        }
        "cylinder" => ShapeKind::Cylinder {
            radius: size("radius")?,
            length: size("length")?,
        },
        "sphere" => ShapeKind::Sphere {
            radius: size("radius")?,
        },
        _ => {
            let scale = match t.field("scale") {
                Some(s) => physical(&s)?,
                None => 1.0,
            };
            read_mesh(&t.req("file")?, scale)?
        }
    };
    let position = match t.field("position") {
        Some(p) => point(&p)?,
        None => Vec3::zeros(),
    };
    let r = match t.field("orientation") {
        Some(o) => super::fields::read_orientation(&o)?,
        None => Mat3::identity(),
    };
    if t.has("colour") && t.has("color") {
        return Err(t.key_err("color", "give one of 'colour' and 'color'"));
    }
    let colour = match t.field("colour").or_else(|| t.field("color")) {
        Some(c) => read_colour(&c)?,
        None => DEFAULT_COLOUR,
    };
    Ok(Shape {
        node,
        kind,
        frame: Frame::new(position, r),
        colour,
    })
}

/// Colour of a shape without one.
const DEFAULT_COLOUR: [f64; 3] = [0.62, 0.64, 0.68];

/// `"#rrggbb"` or `[r, g, b]` in [0, 1].
fn read_colour(f: &Field<'_>) -> Result<[f64; 3]> {
    if let Ok(text) = f.str() {
        let hex = text.strip_prefix('#').unwrap_or("");
        if hex.len() != 6 || !hex.chars().all(|c| c.is_ascii_hexdigit()) {
            return Err(f.err(format!(
                "expected \"#rrggbb\" (six hexadecimal digits) or [r, g, b] in [0, 1], got \"{}\"",
                crate::model::clip(text, crate::model::QUOTED)
            )));
        }
        let byte = |k: usize| u8::from_str_radix(&hex[k..k + 2], 16).expect("hex digits") as f64;
        return Ok([byte(0) / 255.0, byte(2) / 255.0, byte(4) / 255.0]);
    }
    let v = f.numbers(3, "r, g, b")?;
    if v.iter().any(|c| !(0.0..=1.0).contains(c)) {
        return Err(f.err("the three components must be in [0, 1]"));
    }
    Ok([v[0], v[1], v[2]])
}

/// Reads an STL or OBJ file (by its extension), relative to the model file's folder.
fn read_mesh(f: &Field<'_>, scale: f64) -> Result<ShapeKind> {
    let given = f.str()?;
    let base = Path::new(f.src.file).parent().unwrap_or(Path::new(""));
    let path = base.join(given);
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let read = match ext.as_deref() {
        Some("stl") => read_stl(&path),
        Some("obj") => read_obj(&path),
        _ => return Err(f.err("a mesh file must end in .stl or .obj")),
    };
    let (vertices, triangles) =
        read.map_err(|e| f.err(format!("cannot read the mesh {}: {e}", path.display())))?;
    if triangles.is_empty() {
        return Err(f.err(format!("the mesh {} has no triangles", path.display())));
    }
    if triangles.len() > MAX_TRIANGLES {
        return Err(f.err(format!(
            "the mesh {} has {} triangles; at most {MAX_TRIANGLES}",
            path.display(),
            triangles.len()
        )));
    }
    let mut scaled = Vec::with_capacity(vertices.len());
    for v in vertices {
        let v = v * scale;
        if !v.iter().all(|x| x.is_finite() && x.abs() <= MAX_KINEMATIC) {
            return Err(f.err(format!(
                "the mesh {} has a vertex that is not finite or beyond {MAX_KINEMATIC:e} m",
                path.display()
            )));
        }
        scaled.push(v);
    }
    Ok(ShapeKind::Mesh {
        path: given.to_string(),
        vertices: scaled,
        triangles,
    })
}

type Mesh = (Vec<Vec3>, Vec<[u32; 3]>);

fn read_stl(path: &Path) -> std::result::Result<Mesh, String> {
    let mut file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let mesh = stl_io::read_stl(&mut file).map_err(|e| e.to_string())?;
    let vertices = mesh
        .vertices
        .iter()
        .map(|v| Vec3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect::<Vec<_>>();
    let triangles = mesh
        .faces
        .iter()
        .map(|f| f.vertices.map(|k| k as u32))
        .collect();
    Ok((vertices, triangles))
}

fn read_obj(path: &Path) -> std::result::Result<Mesh, String> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj(path, &options).map_err(|e| e.to_string())?;
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    for m in models {
        let base = vertices.len() as u32;
        vertices.extend(
            m.mesh
                .positions
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0] as f64, p[1] as f64, p[2] as f64)),
        );
        for t in m.mesh.indices.chunks_exact(3) {
            let tri = [base + t[0], base + t[1], base + t[2]];
            if tri.iter().any(|&k| k as usize >= vertices.len()) {
                return Err("a face refers to a vertex that does not exist".into());
            }
            triangles.push(tri);
        }
    }
    Ok((vertices, triangles))
}

/// `display_radius` of a `[[beam]]`: the radius its tube is drawn with.
pub(super) fn read_radius(t: &Table<'_>) -> Result<Option<f64>> {
    t.field("display_radius").map(|f| physical(&f)).transpose()
}
