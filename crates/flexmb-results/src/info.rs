//! What the results say of the model: names, the bodies, beams, joints and springs, the
//! display geometry (with its defaults filled in) and the sensors with their units.

use flexmb::model::display::ShapeKind;
use flexmb::Model;
use flexmb_lie::{Frame, Mat3, Vec3};
use serde::{Deserialize, Serialize};

/// The model's metadata in the results.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ModelInfo {
    pub title: String,
    /// `dynamic` or `static`.
    pub analysis: String,
    /// `SE3` or `R3xSO3`.
    pub group: String,
    /// What the snapshots are taken at: `time` \[s\] or `load_factor`.
    pub first: String,
    /// Node names, in model order.
    pub nodes: Vec<String>,
    pub bodies: Vec<BodyInfo>,
    pub beams: Vec<BeamInfo>,
    pub joints: Vec<JointInfo>,
    pub springs: Vec<SpringInfo>,
    /// Display shapes, those of the model file and the defaults (a body's inertia box).
    pub shapes: Vec<ShapeInfo>,
    pub sensors: Vec<SensorInfo>,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BodyInfo {
    pub name: String,
    /// Index in [`ModelInfo::nodes`].
    pub node: usize,
    /// \[kg\]
    pub mass: f64,
    /// Centre of mass in the node frame \[m\].
    pub com: [f64; 3],
}

/// A beam element.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BeamInfo {
    /// Element name, `<beam>[<k>]`.
    pub name: String,
    /// The `[[beam]]` it belongs to (the name before `[<k>]`; the whole name when it does
    /// not end so).
    pub member: String,
    /// Its two nodes (indices in [`ModelInfo::nodes`]).
    pub nodes: [usize; 2],
    /// Drawn radius \[m\]: the model file's, or a default from the section.
    pub radius: f64,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JointInfo {
    pub name: String,
    /// `fixed`, `spherical`, `revolute`, ...
    pub kind: String,
    /// Nodes A and B (indices in [`ModelInfo::nodes`]), -1 for the ground.
    pub nodes: [i64; 2],
    /// Number of constraint equations (multipliers).
    pub rows: usize,
}

/// A spring-damper (a line between two points).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SpringInfo {
    pub name: String,
    /// Nodes A and B, -1 for the ground.
    pub nodes: [i64; 2],
    /// The attachment points in their node frames (inertial for the ground) \[m\].
    pub points: [[f64; 3]; 2],
}

/// A display shape fixed on a node.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ShapeInfo {
    /// Index in [`ModelInfo::nodes`].
    pub node: usize,
    /// `box`, `cylinder` (along its z axis), `sphere` or `mesh`.
    pub kind: String,
    /// Box: side lengths; cylinder: diameter, diameter, length; sphere: the diameter three
    /// times; mesh: the sides of the box around its vertices \[m\].
    pub size: [f64; 3],
    /// Placement in the node frame: position \[m\] and unit quaternion `w, x, y, z`.
    pub position: [f64; 3],
    pub orientation: [f64; 4],
    /// Red, green, blue in [0, 1].
    pub colour: [f64; 3],
    /// Mesh only: the mesh file as given in the model file, its vertices in the shape frame
    /// \[m\] and its triangles (vertex indices, counter-clockwise seen from outside).
    pub mesh: String,
    pub vertices: Vec<[f64; 3]>,
    pub triangles: Vec<[u32; 3]>,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SensorInfo {
    pub name: String,
    /// For labels: `m`, `rad/s`, `N`, ...; empty for a pure number.
    pub unit: String,
}

/// Colours given to the default shapes, body after body.
const PALETTE: [[f64; 3]; 6] = [
    [0.20, 0.47, 0.75],
    [0.90, 0.50, 0.15],
    [0.25, 0.63, 0.30],
    [0.80, 0.25, 0.25],
    [0.55, 0.40, 0.70],
    [0.55, 0.55, 0.55],
];

impl ModelInfo {
    /// The metadata of `model` for a `dynamic` or `static` analysis; shapes and beam radii the
    /// model does not give get their defaults (see [`default_shape`] and [`default_radius`]).
    pub fn of(model: &Model, analysis: &str) -> Self {
        let extent = extent(model);
        let node_index = |n: Option<flexmb::model::NodeId>| n.map_or(-1, |n| n.0 as i64);
        let mut shapes: Vec<ShapeInfo> = model.display.shapes.iter().map(shape_info).collect();
        for (k, b) in model.bodies.iter().enumerate() {
            if !shapes.iter().any(|s| s.node == b.node.0) {
                shapes.push(default_shape(b, extent, PALETTE[k % PALETTE.len()]));
            }
        }
        let mut radius = vec![None; model.beams.len()];
        for t in &model.display.tubes {
            for r in radius.iter_mut().skip(t.first).take(t.count) {
                *r = Some(t.radius);
            }
        }
        Self {
            title: model.title.clone(),
            analysis: analysis.into(),
            group: model.group.name().into(),
            first: if analysis == "static" {
                "load_factor"
            } else {
                "time"
            }
            .into(),
            nodes: model.nodes.iter().map(|n| n.name.clone()).collect(),
            bodies: model
                .bodies
                .iter()
                .map(|b| BodyInfo {
                    name: b.name.clone(),
                    node: b.node.0,
                    mass: b.mass,
                    com: b.com.into(),
                })
                .collect(),
            beams: model
                .beams
                .iter()
                .zip(radius)
                .map(|(b, r)| BeamInfo {
                    name: b.name.clone(),
                    member: member_of(&b.name).into(),
                    nodes: [b.nodes[0].0, b.nodes[1].0],
                    radius: r.unwrap_or_else(|| default_radius(b, extent)),
                })
                .collect(),
            joints: model
                .joints
                .iter()
                .map(|j| JointInfo {
                    name: j.name.clone(),
                    kind: j.kind.name().into(),
                    nodes: [node_index(j.node_a), node_index(j.node_b)],
                    rows: flexmb::joints::rows(j).len(),
                })
                .collect(),
            springs: model
                .springs
                .iter()
                .map(|s| SpringInfo {
                    name: s.name.clone(),
                    nodes: [node_index(s.node_a), node_index(s.node_b)],
                    points: [s.point_a.into(), s.point_b.into()],
                })
                .collect(),
            shapes,
            sensors: model
                .sensors
                .iter()
                .map(|s| SensorInfo {
                    name: s.name.clone(),
                    unit: flexmb::sensors::unit(&s.kind).into(),
                })
                .collect(),
        }
    }

    /// Index of the sensor called `name`.
    pub fn sensor(&self, name: &str) -> Option<usize> {
        self.sensors.iter().position(|s| s.name == name)
    }
}

/// The `[[beam]]` of an element named `<beam>[<k>]`, or the whole name.
fn member_of(element: &str) -> &str {
    match element.strip_suffix(']').and_then(|s| s.rsplit_once('[')) {
        Some((member, k)) if !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()) => member,
        _ => element,
    }
}

fn quaternion(r: &Mat3) -> [f64; 4] {
    Frame::new(Vec3::zeros(), *r).quaternion()
}

fn shape_info(s: &flexmb::model::display::Shape) -> ShapeInfo {
    let mut info = ShapeInfo {
        node: s.node.0,
        kind: s.kind.name().into(),
        position: s.frame.x.into(),
        orientation: quaternion(&s.frame.r),
        colour: s.colour,
        ..Default::default()
    };
    match &s.kind {
        ShapeKind::Box { size } => info.size = (*size).into(),
        ShapeKind::Cylinder { radius, length } => info.size = [2.0 * radius, 2.0 * radius, *length],
        ShapeKind::Sphere { radius } => info.size = [2.0 * radius; 3],
        ShapeKind::Mesh {
            path,
            vertices,
            triangles,
        } => {
            let (lo, hi) = vertices.iter().fold(
                (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY)),
                |(lo, hi), v| (lo.inf(v), hi.sup(v)),
            );
            info.size = if vertices.is_empty() {
                [0.0; 3]
            } else {
                (hi - lo).into()
            };
            info.mesh = path.clone();
            info.vertices = vertices.iter().map(|&v| v.into()).collect();
            info.triangles = triangles.clone();
        }
    }
    info
}

/// The size of the model: the diagonal of the box around its initial node positions, at
/// least 1e-3 m (a model of one node takes its size from its bodies' inertia boxes).
fn extent(model: &Model) -> f64 {
    let boxes = model
        .bodies
        .iter()
        .map(|b| inertia_box(b).0.norm())
        .fold(0.0, f64::max);
    model.extent().max(boxes).max(1e-3)
}

/// The sides of the homogeneous box with the body's mass and principal moments
/// (`a1^2 = 6 (I2 + I3 - I1) / m`, ...) and the rotation to its principal axes.
fn inertia_box(b: &flexmb::model::RigidBody) -> (Vec3, Mat3) {
    let eig = b.inertia.symmetric_eigen();
    let i = eig.eigenvalues;
    let side = |k: usize| {
        let (a, c) = ((k + 1) % 3, (k + 2) % 3);
        (6.0 * (i[a] + i[c] - i[k]) / b.mass).max(0.0).sqrt()
    };
    let mut r = eig.eigenvectors;
    if r.determinant() < 0.0 {
        r.column_mut(2).neg_mut();
    }
    (Vec3::new(side(0), side(1), side(2)), r)
}

/// A body without shapes is drawn as its equivalent inertia box at its centre of mass along
/// its principal axes (sides at least 1 % of the model's size, so that a point mass shows).
pub fn default_shape(b: &flexmb::model::RigidBody, extent: f64, colour: [f64; 3]) -> ShapeInfo {
    let (sides, r) = inertia_box(b);
    let sides = sides.map(|s| s.max(0.01 * extent));
    ShapeInfo {
        node: b.node.0,
        kind: "box".into(),
        size: sides.into(),
        position: b.com.into(),
        orientation: quaternion(&r),
        colour,
        ..Default::default()
    }
}

/// A beam without a radius is drawn as a tube of the solid circular section with its polar
/// radius of gyration, `r = sqrt(2 rhoJ / rhoA)`, at most 1/60 of the model's size (and that
/// size when the section has no mass).
pub fn default_radius(b: &flexmb::model::Beam, extent: f64) -> f64 {
    let cap = extent / 60.0;
    let rho_a = b.section.mass_per_length;
    let rho_j = b.section.rotary_inertia[(0, 0)];
    if rho_a > 0.0 && rho_j > 0.0 {
        (2.0 * rho_j / rho_a).sqrt().min(cap)
    } else {
        cap
    }
}

#[cfg(test)]
mod tests {
    use super::member_of;

    #[test]
    fn an_elements_member_is_its_name_before_the_index() {
        assert_eq!(member_of("leg1[0]"), "leg1");
        assert_eq!(member_of("arm.a[12]"), "arm.a");
        assert_eq!(member_of("rod"), "rod");
        assert_eq!(member_of("rod[x]"), "rod[x]");
        assert_eq!(member_of("rod[]"), "rod[]");
    }
}
