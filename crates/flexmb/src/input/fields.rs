//! Readers of the fields that many tables share: numbers with units, points and directions,
//! orientations, names, references to nodes and joints, gear wheels; and where each model
//! item came from in the file ([`Origin`], [`Origins`]), to place the errors found later.

use super::error::ItemLabel;
use super::reader::{name_list, suggestion, Field, Result, Span, Table, QUOTED};
use crate::model::limits::{
    MAX_ANGLE, MAX_KINEMATIC, MAX_PHYSICAL, MAX_TIME, MIN_PHYSICAL, MIN_STEP,
};
use crate::model::{clip, rotation_from_vector, Model, NodeId};
use flexmb_lie::{so3, Mat3, Vec3};
use std::collections::HashMap;

pub(super) const GROUND: &str = "ground";

/// Where a model item came from in the file, to place errors found by `Model::validate`.
#[derive(Clone)]
pub(super) struct Origin {
    pub(super) path: String,
    pub(super) item: Option<ItemLabel>,
    pub(super) span: Span,
    pub(super) fields: Vec<(String, Span)>,
    /// Fields of the model item that have another name in the file:
    /// `(field of Model::validate, key of the file's table)`.
    pub(super) aliases: Vec<(&'static str, &'static str)>,
    /// Put before the message (names the element of a meshed beam), except for the fields
    /// in `unprefixed`.
    pub(super) prefix: String,
    pub(super) unprefixed: Vec<&'static str>,
}

impl Origin {
    pub(super) fn of(t: &Table<'_>) -> Self {
        Self {
            path: t.path.clone(),
            item: t.item.clone(),
            span: t.span.clone(),
            fields: t.spans(),
            aliases: Vec::new(),
            prefix: String::new(),
            unprefixed: Vec::new(),
        }
    }

    /// Maps the model field `field` to the file key `key`.
    pub(super) fn alias(mut self, field: &'static str, key: &'static str) -> Self {
        self.aliases.push((field, key));
        self
    }

    pub(super) fn prefixed(mut self, prefix: String) -> Self {
        self.prefix = prefix;
        self
    }

    /// No prefix for errors about the model field `field`.
    pub(super) fn unprefixed(mut self, field: &'static str) -> Self {
        self.unprefixed.push(field);
        self
    }
}

#[derive(Default)]
pub(super) struct Origins {
    /// The `[model]` table.
    pub(super) model: Option<Origin>,
    pub(super) nodes: Vec<Origin>,
    pub(super) bodies: Vec<Origin>,
    pub(super) joints: Vec<Origin>,
    pub(super) loads: Vec<Origin>,
    pub(super) springs: Vec<Origin>,
    pub(super) ropes: Vec<Origin>,
    pub(super) contacts: Vec<Origin>,
    pub(super) rotational_springs: Vec<Origin>,
    pub(super) bushings: Vec<Origin>,
    /// One per element of `Model::beams`.
    pub(super) beams: Vec<Origin>,
    pub(super) sensors: Vec<Origin>,
    pub(super) gears: Vec<Origin>,
    pub(super) worm_gears: Vec<Origin>,
    pub(super) blocks: Vec<Origin>,
    /// Node and joint of each name, as they are created (names are unique in a file): look-ups
    /// by hash keep reading linear in the size of the model.
    pub(super) node_ids: HashMap<String, NodeId>,
    pub(super) joint_ids: HashMap<String, crate::model::JointId>,
    /// The elements of each `[[beam]]` (indices in `Model::beams`), by the beam's name.
    pub(super) beam_elements: HashMap<String, std::ops::Range<usize>>,
}

/// A positive physical constant (mass, section property, ...) in
/// `[MIN_PHYSICAL, MAX_PHYSICAL]`.
pub(super) fn physical(f: &Field<'_>) -> Result<f64> {
    let v = f.f64()?;
    if v <= 0.0 {
        return Err(f.err(format!("must be positive, got {v}")));
    }
    f.f64_in(MIN_PHYSICAL, MAX_PHYSICAL)
}

/// A constant that may be 0 (stiffness or damping of a spring, damping of a beam), at most
/// `MAX_PHYSICAL`.
pub(super) fn physical_or_zero(f: &Field<'_>) -> Result<f64> {
    let v = f.f64()?;
    if v < 0.0 {
        return Err(f.err(format!("must be >= 0, got {v}")));
    }
    f.f64_in(0.0, MAX_PHYSICAL)
}

/// A direction: any length from 1e-12 to the coordinate range.
pub(super) fn nonzero_vec3(f: &Field<'_>) -> Result<Vec3> {
    let v = f.vec3_within(MAX_KINEMATIC)?;
    if v.norm() > 1e-12 {
        Ok(v)
    } else {
        Err(f.err("must be a non-zero vector (length above 1e-12)"))
    }
}

/// A position or point in the coordinate range.
pub(super) fn point(f: &Field<'_>) -> Result<Vec3> {
    f.vec3_within(MAX_KINEMATIC)
}

pub(super) fn opt_point(t: &Table<'_>, key: &str) -> Result<Option<Vec3>> {
    t.field(key).map(|f| point(&f)).transpose()
}

/// Reads `name`: a non-empty string, unique within `seen` (name -> path of its first use).
pub(super) fn read_name(
    t: &Table<'_>,
    seen: &mut HashMap<String, String>,
    what: &str,
) -> Result<String> {
    let f = t.req("name")?;
    let name = f.str()?;
    if name.trim().is_empty() {
        return Err(f.err("must not be empty"));
    }
    if let Some(first) = seen.get(name) {
        return Err(f.err(format!(
            "duplicate {what} name '{}' (already used by {first})",
            clip(name, QUOTED)
        )));
    }
    seen.insert(name.to_string(), t.path.clone());
    Ok(name.to_string())
}

pub(super) fn read_orientation(f: &Field<'_>) -> Result<Mat3> {
    let t = f.table()?;
    let forms = ["rotation_vector", "quaternion", "axis", "matrix"];
    t.check_keys(&[
        "rotation_vector",
        "quaternion",
        "axis",
        "angle_deg",
        "matrix",
    ])?;
    let given: Vec<&str> = forms.iter().copied().filter(|k| t.has(k)).collect();
    if given.len() > 1 {
        return Err(t.key_err(
            given[1],
            format!(
                "give only one of rotation_vector, quaternion, axis (with angle_deg), matrix; found both '{}' and '{}'",
                given[0], given[1]
            ),
        ));
    }
    match given.first().copied() {
        None if t.has("angle_deg") => Err(t.key_err("axis", "is required with angle_deg")),
        None => Err(f.err(
            "give one of rotation_vector = [3], quaternion = [w, x, y, z], axis = [3] with angle_deg, matrix = [[3], [3], [3]]",
        )),
        Some("rotation_vector") => {
            let f = t.req("rotation_vector")?;
            let v = f.vec3()?;
            // A component out of range alone is named by vec3_within below.
            if v.amax() <= MAX_ANGLE && v.norm() > MAX_ANGLE {
                return Err(f.err(format!(
                    "has an angle |v| = {:e} rad beyond {MAX_ANGLE:e}: a double no longer holds the orientation to 1e-10",
                    v.norm()
                )));
            }
            Ok(rotation_from_vector(&f.vec3_within(MAX_ANGLE)?))
        }
        Some("quaternion") => {
            let q = t.req("quaternion")?;
            let v = q.numbers(4, "a quaternion [w, x, y, z] of 4 numbers")?;
            let n = v.iter().map(|c| c * c).sum::<f64>().sqrt();
            if (n - 1.0).abs() > 1e-6 {
                return Err(q.err(format!("must be a unit quaternion, got |q| = {n}")));
            }
            Ok(so3::from_quaternion([v[0], v[1], v[2], v[3]]))
        }
        Some("axis") => {
            let axis = nonzero_vec3(&t.req("axis")?)?;
            let angle = t.req("angle_deg")?.f64_in(-MAX_ANGLE, MAX_ANGLE)?;
            Ok(rotation_from_vector(&(axis.normalize() * angle.to_radians())))
        }
        _ => {
            let m = t.req("matrix")?;
            let r = m.mat3_rows()?;
            let ortho = (r.transpose() * r - Mat3::identity()).norm();
            let det = r.determinant();
            if !(ortho <= 1e-6 && det > 0.0) {
                return Err(m.err(format!(
                    "is not a rotation matrix (|R^T R - I| = {ortho:.3e}, det R = {det:.6})"
                )));
            }
            Ok(so3::orthonormalize(&r))
        }
    }
}

/// A node name (not the ground).
/// The joint named by `f`.
pub(super) fn require_joint(
    model: &Model,
    origins: &Origins,
    f: &Field<'_>,
) -> Result<crate::model::JointId> {
    let jname = f.str()?;
    origins.joint_ids.get(jname).copied().ok_or_else(|| {
        let names = || model.joints.iter().map(|j| j.name.as_str());
        f.err(format!(
            "unknown joint '{}'{} (joints: {})",
            clip(jname, QUOTED),
            suggestion(jname, names()),
            name_list(names(), 12)
        ))
    })
}

pub(super) fn require_node(model: &Model, origins: &Origins, f: &Field<'_>) -> Result<NodeId> {
    match resolve_node(model, origins, f, false)? {
        Some(id) => Ok(id),
        None => Err(f.err("must be a node, not the ground")),
    }
}

/// A node name, or "ground" (`None`) when `ground_ok`.
pub(super) fn resolve_node(
    model: &Model,
    origins: &Origins,
    f: &Field<'_>,
    ground_ok: bool,
) -> Result<Option<NodeId>> {
    let name = f.str()?;
    if name == GROUND {
        return if ground_ok {
            Ok(None)
        } else {
            Err(f.err("must be a node, not the ground"))
        };
    }
    origins
        .node_ids
        .get(name)
        .copied()
        .map(Some)
        .ok_or_else(|| {
            let names = || model.nodes.iter().map(|n| n.name.as_str());
            f.err(format!(
                "unknown node '{}'{} (nodes: {}{})",
                clip(name, QUOTED),
                suggestion(name, names()),
                name_list(names(), 12),
                if ground_ok { ", or 'ground'" } else { "" }
            ))
        })
}

/// A point given in inertial coordinates at t = 0, in the frame of `node` (inertial for ground).
pub(super) fn to_node_frame(model: &Model, node: Option<NodeId>, p: &Vec3) -> Vec3 {
    match node {
        Some(id) => model.nodes[id.0].frame.inverse().point(p),
        None => *p,
    }
}

/// The index of the item that `f` names among `names` (e.g. the springs), or an error with
/// the closest name and the list.
pub(super) fn item_named<'n, I: Iterator<Item = &'n str>>(
    f: &Field<'_>,
    names: impl Fn() -> I,
    what: &str,
    plural: &str,
) -> Result<usize> {
    let name = f.str()?;
    names().position(|n| n == name).ok_or_else(|| {
        f.err(format!(
            "unknown {what} '{}'{} ({plural}: {})",
            clip(name, QUOTED),
            suggestion(name, names()),
            name_list(names(), 12)
        ))
    })
}

/// The stress resultants of a beam section (the `beam_strain` and `beam_stress` sensors'
/// and the `section_force` measurement's components).
pub(super) const SECTION_COMPONENTS: &[&str] = &[
    "axial",
    "shear_2",
    "shear_3",
    "torsion",
    "bending_2",
    "bending_3",
];

/// A whole number of teeth, at least 1.
pub(super) fn teeth(f: &Field<'_>) -> Result<u32> {
    let z = f.int()?;
    match u32::try_from(z) {
        Ok(z) if (1..=100_000).contains(&z) => Ok(z),
        _ => Err(f.err(format!(
            "must be a whole number of teeth from 1 to 100000, got {z}"
        ))),
    }
}

/// The name (unique among `table`), the two nodes (`node_a`, `node_b`, either may be the
/// ground) and the centres of two meshing members: gear joints, gear pairs, worm gears.
pub(super) fn read_wheels(
    t: &Table<'_>,
    names: &mut HashMap<String, String>,
    table: &str,
    model: &Model,
    origins: &Origins,
) -> Result<(String, [Option<NodeId>; 2], [Vec3; 2])> {
    let name = read_name(t, names, table)?;
    let node_a = resolve_node(model, origins, &t.req("node_a")?, true)?;
    let node_b = resolve_node(model, origins, &t.req("node_b")?, true)?;
    let centers = wheel_centers(t, model, [node_a, node_b])?;
    Ok((name, [node_a, node_b], centers))
}

/// The centres of two wheels on `nodes` (inertial, t = 0): `center_a`, `center_b`, each by
/// default its node's position (required for a wheel on the ground).
pub(super) fn wheel_centers(
    t: &Table<'_>,
    model: &Model,
    nodes: [Option<NodeId>; 2],
) -> Result<[Vec3; 2]> {
    let mut out = [Vec3::zeros(); 2];
    for (i, key) in ["center_a", "center_b"].into_iter().enumerate() {
        out[i] = match (opt_point(t, key)?, nodes[i]) {
            (Some(p), _) => p,
            (None, Some(n)) => model.nodes[n.0].frame.x,
            (None, None) => {
                return Err(t.key_err(
                    key,
                    format!(
                        "is required for a wheel on the ground (node_{} = \"ground\")",
                        ["a", "b"][i]
                    ),
                ))
            }
        };
    }
    Ok(out)
}

/// A positive time (or load factor step) in `[MIN_STEP, MAX_TIME]`.
pub(super) fn positive_step(f: &Field<'_>) -> Result<f64> {
    let v = f.f64()?;
    if v <= 0.0 {
        return Err(f.err(format!("must be positive, got {v}")));
    }
    f.f64_in(MIN_STEP, MAX_TIME)
}
