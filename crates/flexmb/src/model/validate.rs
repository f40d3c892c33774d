//! `Model::validate`: references, physical data and ranges of every item, one pass over the
//! model (linear in its size).
//!
//! Every number is checked finite and within [`super::limits`]; every error names the item
//! (table, index, name) and the field, which the model-file front end maps back to a line.

use super::contact::{Contact, ContactShape};
use super::limits::{
    within, MAX_ANGLE, MAX_FRICTION, MAX_FUNCTION_DEPTH, MAX_FUNCTION_TERMS, MAX_ITEMS,
    MAX_KINEMATIC, MAX_PHYSICAL, MAX_ROPE_POINTS, MAX_TIME, MIN_PHYSICAL, MIN_RELATIVE_LENGTH,
    MIN_STEP,
};
use super::ModelError;
use super::{ItemRef, JointKind, Model, NodeId, RopePoint, SensorKind, TimeFunction};
use flexmb_lie::{Frame, Group, Mat3, Vec3};
use std::collections::HashMap;

/// Most characters of a name or value quoted in an error message.
pub(crate) const QUOTED: usize = 60;

/// `text` cut to `max` characters, with an ellipsis (for names and values in messages).
pub(crate) fn clip(text: &str, max: usize) -> String {
    match text.char_indices().nth(max) {
        None => text.to_string(),
        Some((end, _)) => format!("{}...", &text[..end]),
    }
}

/// Names of the CSV columns written before the sensors (`time`, or `load_factor` for a
/// static analysis).
const RESERVED_COLUMNS: [&str; 2] = ["time", "load_factor"];

type Check = Result<(), String>;

/// A finite vector of length at most `max` (a bound on the length holds in every frame).
fn finite3(v: &Vec3, max: f64) -> Check {
    if let Some(c) = v.iter().find(|c| !c.is_finite()) {
        return Err(format!("has a non-finite component ({c})"));
    }
    if v.norm() > max {
        return Err(format!(
            "has length {:e}, beyond {max:e} (see limits)",
            v.norm()
        ));
    }
    Ok(())
}

/// A contact shape's own data: finite points, unit directions, radii in range.
fn check_contact_shape(shape: &ContactShape) -> Check {
    let unit = |v: &Vec3, what: &str| {
        finite3(v, 2.0)?;
        if (v.norm() - 1.0).abs() > 1e-9 {
            return Err(format!(
                "{what} must be a unit vector, got length {}",
                v.norm()
            ));
        }
        Ok(())
    };
    let radius = |r: f64| in_range(r, 0.0, MAX_KINEMATIC).map_err(|m| format!("radius {m}"));
    match shape {
        ContactShape::Plane { point, normal } => {
            finite3(point, 2.0 * MAX_KINEMATIC)?;
            unit(normal, "the normal")
        }
        ContactShape::Sphere {
            center, radius: r, ..
        } => {
            finite3(center, 2.0 * MAX_KINEMATIC)?;
            radius(*r)
        }
        ContactShape::Cylinder {
            point,
            axis,
            radius: r,
            ..
        } => {
            finite3(point, 2.0 * MAX_KINEMATIC)?;
            unit(axis, "the axis")?;
            radius(*r)
        }
    }
}

/// Whether the two shapes of a contact make a pair the element handles.
fn contact_pair(model: &Model, c: &Contact) -> Check {
    let (a, b) = (&c.shape_a, &c.shape_b);
    if b.inside() {
        return Err("shape B cannot be 'inside': the shape that contains the other is A".into());
    }
    match (a, b) {
        (_, ContactShape::Plane { .. }) => {
            Err("shape B cannot be a plane: a plane is shape A, against a sphere or point B".into())
        }
        (ContactShape::Plane { .. }, ContactShape::Cylinder { .. }) => {
            Err("a plane touches a sphere or a point, not a cylinder".into())
        }
        (ContactShape::Sphere { .. }, ContactShape::Cylinder { .. }) => {
            Err("a sphere A touches a sphere or a point B, not a cylinder".into())
        }
        (ContactShape::Cylinder { axis: ea, .. }, ContactShape::Cylinder { axis: eb, .. }) => {
            let rotation =
                |n: Option<NodeId>| n.map_or(Mat3::identity(), |n| model.nodes[n.0].frame.r);
            let (ea, eb) = (rotation(c.node_a) * ea, rotation(c.node_b) * eb);
            if ea.cross(&eb).norm() > 1e-6 {
                return Err(
                    "two cylinders (planar circles) must have parallel axes at t = 0".into(),
                );
            }
            inside_fits(a, b)
        }
        _ => inside_fits(a, b),
    }
}

/// A shape B inside A must be smaller than A.
fn inside_fits(a: &ContactShape, b: &ContactShape) -> Check {
    if a.inside() && b.radius() >= a.radius() {
        return Err(format!(
            "radius {} does not fit inside shape A of radius {}",
            b.radius(),
            a.radius()
        ));
    }
    Ok(())
}

fn in_range(v: f64, lo: f64, hi: f64) -> Check {
    if v >= lo && v <= hi {
        Ok(())
    } else {
        Err(format!("must be between {lo:e} and {hi:e}, got {v}"))
    }
}

fn rotation(r: &Mat3) -> Check {
    let ortho = (r.transpose() * r - Mat3::identity()).norm();
    if ortho <= 1e-9 && r.determinant() > 0.0 {
        Ok(())
    } else {
        Err(format!(
            "is not a rotation matrix (|R^T R - I| = {ortho:.3e})"
        ))
    }
}

/// A frame fixed on a node: a rotation, and a position within twice the coordinate range
/// (a point given in the frame of a node anywhere in the range).
/// A normal pressure angle of a gear or worm gear \[rad\], in (0, 1.2).
fn pressure_angle(a: f64) -> Check {
    if a > 0.0 && a < 1.2 {
        Ok(())
    } else {
        Err(format!(
            "must be between 0 and 68.75 deg, got {} deg",
            a.to_degrees()
        ))
    }
}

fn local_frame(f: &Frame) -> Check {
    rotation(&f.r)?;
    finite3(&f.x, 2.0 * MAX_KINEMATIC)
}

/// A symmetric positive semidefinite 6 x 6 matrix with finite entries within the physical
/// range (a bushing's stiffness or damping).
fn symmetric_psd(m: &flexmb_lie::Mat6) -> Check {
    if let Some(v) = m.iter().find(|v| !v.is_finite() || v.abs() > MAX_PHYSICAL) {
        return Err(format!(
            "has the entry {v}: entries must be finite and at most {MAX_PHYSICAL:e} in magnitude"
        ));
    }
    let scale = m.abs().max();
    let asym = (m - m.transpose()).abs().max();
    if asym > 1e-12 * scale {
        return Err(format!(
            "is not symmetric (largest |M_ij - M_ji| = {asym:.3e})"
        ));
    }
    let smallest = m.symmetric_eigenvalues().min();
    if smallest < -1e-12 * scale {
        return Err(format!(
            "is not positive semidefinite (smallest eigenvalue {smallest:.6e})"
        ));
    }
    Ok(())
}

/// A force law: preload in range; tables of at least 2 points, finite, strictly increasing
/// in `e`; polynomials of 1 to 16 finite coefficients. An error names the model-file key.
fn check_force_law(law: &super::ForceLaw) -> Result<(), (&'static str, String)> {
    in_range(law.preload, -MAX_PHYSICAL, MAX_PHYSICAL).map_err(|m| ("preload", m))?;
    for (curve, side) in [
        (&law.curve, None),
        (&law.compression, Some("compression")),
        (&law.extension, Some("extension")),
    ] {
        let Some(curve) = curve else { continue };
        let field = |own: &'static str| side.unwrap_or(own);
        match curve {
            super::ForceCurve::Table(points) => {
                let field = field("force_table");
                if points.len() < 2 {
                    let n = points.len();
                    let m = format!("has {n} point(s): a force table needs at least 2");
                    return Err((field, m));
                }
                for (k, (e, f)) in points.iter().enumerate() {
                    in_range(*e, -2.0 * MAX_KINEMATIC, 2.0 * MAX_KINEMATIC)
                        .and_then(|()| in_range(*f, -MAX_PHYSICAL, MAX_PHYSICAL))
                        .map_err(|m| (field, format!("point {k}: {m}")))?;
                }
                if let Some(k) = points.windows(2).position(|w| w[1].0 <= w[0].0) {
                    return Err((
                        field,
                        format!(
                            "is not sorted in elongation: point {} (e = {}) does not come after point {k} (e = {}); the elongations must increase strictly",
                            k + 1,
                            points[k + 1].0,
                            points[k].0
                        ),
                    ));
                }
            }
            super::ForceCurve::Polynomial(a) => {
                let field = field("polynomial");
                if a.is_empty() || a.len() > 16 {
                    return Err((
                        field,
                        format!(
                            "has {} coefficients: give 1 to 16 ([a1, a2, ...] of a1 e + a2 e^2 + ...)",
                            a.len()
                        ),
                    ));
                }
                for (j, aj) in a.iter().enumerate() {
                    in_range(*aj, -MAX_PHYSICAL, MAX_PHYSICAL)
                        .map_err(|m| (field, format!("coefficient {j}: {m}")))?;
                }
            }
        }
    }
    Ok(())
}

impl TimeFunction {
    /// Finite parameters within the ranges, increasing times, and intervals of at least
    /// [`MIN_STEP`] (so slopes stay finite); functions of functions at most
    /// [`MAX_FUNCTION_DEPTH`] levels deep, sums of 1 to [`MAX_FUNCTION_TERMS`] functions, and
    /// the factors of nested scaled functions multiplying to at most [`MAX_PHYSICAL`]. The
    /// message of an error in a nested function starts with its path (`function.duration`,
    /// `functions[1].height`).
    pub fn check(&self) -> Result<(), String> {
        if self.deeper_than(MAX_FUNCTION_DEPTH) {
            return Err(format!(
                "functions are nested more than {MAX_FUNCTION_DEPTH} levels deep"
            ));
        }
        self.check_nested(1.0)
    }

    /// [`TimeFunction::check`] of a function inside scaled functions whose factors multiply
    /// to `scale`.
    fn check_nested(&self, scale: f64) -> Result<(), String> {
        let value = |name: &str, v: f64| {
            in_range(v, -MAX_PHYSICAL, MAX_PHYSICAL).map_err(|m| format!("{name} {m}"))
        };
        let time = |name: &str, v: f64| {
            in_range(v, -MAX_TIME, MAX_TIME).map_err(|m| format!("{name} {m}"))
        };
        let nested = |path: &str, g: &TimeFunction, scale: f64| {
            g.check_nested(scale).map_err(|m| format!("{path}.{m}"))
        };
        match self {
            TimeFunction::Constant { value: v } => value("value", *v),
            TimeFunction::Linear {
                slope,
                start,
                offset,
            } => {
                value("slope", *slope)?;
                time("start", *start)?;
                value("offset", *offset)
            }
            TimeFunction::Ramp { t0, t1, value: v } => {
                time("t0", *t0)?;
                time("t1", *t1)?;
                value("value", *v)?;
                if t1 - t0 < MIN_STEP {
                    return Err(format!(
                        "t1 = {t1} must exceed t0 = {t0} by at least {MIN_STEP:e}"
                    ));
                }
                Ok(())
            }
            TimeFunction::Step { t0, value: v } => {
                time("t0", *t0)?;
                value("value", *v)
            }
            TimeFunction::Sine {
                amplitude,
                frequency,
                phase,
                offset,
            } => {
                value("amplitude", *amplitude)?;
                in_range(*frequency, -MAX_KINEMATIC, MAX_KINEMATIC)
                    .map_err(|m| format!("frequency {m}"))?;
                in_range(*phase, -MAX_ANGLE, MAX_ANGLE).map_err(|m| format!("phase {m}"))?;
                value("offset", *offset)
            }
            TimeFunction::Chirp {
                amplitude,
                f0,
                f1,
                duration,
                offset,
            } => {
                value("amplitude", *amplitude)?;
                for (name, f) in [("f0", f0), ("f1", f1)] {
                    in_range(*f, -MAX_KINEMATIC, MAX_KINEMATIC)
                        .map_err(|m| format!("{name} {m}"))?;
                }
                in_range(*duration, MIN_STEP, MAX_TIME).map_err(|m| format!("duration {m}"))?;
                value("offset", *offset)
            }
            TimeFunction::Table { points } => {
                if points.is_empty() {
                    return Err("needs at least one [t, value] point".into());
                }
                for (i, &(t, v)) in points.iter().enumerate() {
                    time(&format!("points[{i}] time"), t)?;
                    value(&format!("points[{i}] value"), v)?;
                    if i > 0 && t - points[i - 1].0 < MIN_STEP {
                        return Err(format!(
                            "times must increase by at least {MIN_STEP:e}, got t = {t} after t = {}",
                            points[i - 1].0
                        ));
                    }
                }
                Ok(())
            }
            TimeFunction::SpinUp { omega, duration } => {
                in_range(*omega, -MAX_KINEMATIC, MAX_KINEMATIC)
                    .map_err(|m| format!("omega {m}"))?;
                in_range(*duration, MIN_STEP, MAX_TIME).map_err(|m| format!("duration {m}"))
            }
            TimeFunction::Bump {
                height,
                start,
                duration,
            } => {
                value("height", *height)?;
                time("start", *start)?;
                in_range(*duration, MIN_STEP, MAX_TIME).map_err(|m| format!("duration {m}"))
            }
            TimeFunction::SmoothStep {
                value: v,
                start,
                duration,
            } => {
                value("value", *v)?;
                time("start", *start)?;
                in_range(*duration, MIN_STEP, MAX_TIME).map_err(|m| format!("duration {m}"))
            }
            TimeFunction::Delay { delay, function } => {
                time("delay", *delay)?;
                nested("function", function, scale)
            }
            TimeFunction::Window {
                start,
                end,
                function,
            } => {
                time("start", *start)?;
                time("end", *end)?;
                if end - start < MIN_STEP {
                    return Err(format!(
                        "end = {end} must exceed start = {start} by at least {MIN_STEP:e}"
                    ));
                }
                nested("function", function, scale)
            }
            TimeFunction::Sum { functions } => {
                if functions.is_empty() || functions.len() > MAX_FUNCTION_TERMS {
                    return Err(format!(
                        "functions must hold 1 to {MAX_FUNCTION_TERMS} functions, got {}",
                        functions.len()
                    ));
                }
                for (i, g) in functions.iter().enumerate() {
                    nested(&format!("functions[{i}]"), g, scale)?;
                }
                Ok(())
            }
            TimeFunction::Scaled { factor, function } => {
                value("factor", *factor)?;
                let scale = scale * factor.abs();
                if scale > MAX_PHYSICAL {
                    return Err(format!(
                        "factor {factor} makes the factors of the nested scaled functions multiply to {scale:e}, beyond {MAX_PHYSICAL:e}"
                    ));
                }
                nested("function", function, scale)
            }
        }
    }
}

/// Index of the first item whose name appeared before.
fn first_duplicate<'n>(names: impl Iterator<Item = &'n str>) -> Option<(usize, usize)> {
    let mut seen: HashMap<&str, usize> = HashMap::new();
    for (i, name) in names.enumerate() {
        if let Some(&first) = seen.get(name) {
            return Some((first, i));
        }
        seen.insert(name, i);
    }
    None
}

impl Model {
    /// Checks the references, the physical data and the ranges of every item (see
    /// [`super::limits`]); the error names the item and the field.
    pub fn validate(&self) -> Result<(), ModelError> {
        let n = self.nodes.len();
        if n > MAX_ITEMS || self.beams.len() > MAX_ITEMS {
            return Err(bad(
                "model",
                0,
                &self.title,
                "size",
                format!(
                    "{n} nodes and {} beam elements: a model has at most {MAX_ITEMS} of each",
                    self.beams.len()
                ),
            ));
        }
        finite3(&self.gravity, MAX_KINEMATIC)
            .map_err(|m| bad("model", 0, &self.title, "gravity", m))?;

        self.validate_nodes()?;
        self.validate_bodies()?;
        self.validate_joints()?;
        self.validate_loads()?;
        self.validate_springs()?;
        self.validate_rotational_springs()?;
        self.validate_bushings()?;
        self.validate_contacts()?;
        self.validate_ropes()?;
        self.validate_gears()?;
        self.validate_worm_gears()?;
        self.validate_control()?;
        self.validate_beams()?;
        self.validate_sensors()?;
        Ok(())
    }

    /// The checks of [`Self::validate`] on the nodes.
    fn validate_nodes(&self) -> Result<(), ModelError> {
        for (i, node) in self.nodes.iter().enumerate() {
            let fail = |field, m| bad("node", i, &node.name, field, m);
            rotation(&node.frame.r).map_err(|m| fail("orientation", m))?;
            finite3(&node.frame.x, MAX_KINEMATIC).map_err(|m| fail("position", m))?;
            finite3(&node.velocity, MAX_KINEMATIC).map_err(|m| fail("velocity", m))?;
            finite3(&node.angular_velocity, MAX_KINEMATIC)
                .map_err(|m| fail("angular_velocity", m))?;
        }
        if let Some((first, i)) = first_duplicate(self.nodes.iter().map(|x| x.name.as_str())) {
            return Err(bad(
                "node",
                i,
                &self.nodes[i].name,
                "name",
                format!("duplicate node name (also node #{})", first + 1),
            ));
        }
        Ok(())
    }

    /// The checks of [`Self::validate`] on the bodies.
    fn validate_bodies(&self) -> Result<(), ModelError> {
        let check_node =
            |table, i, name: &str, field, id| self.check_node(table, i, name, field, id);
        for (i, b) in self.bodies.iter().enumerate() {
            let fail = |field, m| bad("body", i, &b.name, field, m);
            check_node("body", i, &b.name, "node", Some(b.node))?;
            in_range(b.mass, MIN_PHYSICAL, MAX_PHYSICAL).map_err(|m| fail("mass", m))?;
            finite3(&b.com, MAX_KINEMATIC).map_err(|m| fail("com", m))?;
            if !b.inertia.iter().all(|c| c.abs() <= MAX_PHYSICAL) {
                return Err(fail(
                    "inertia",
                    format!("has values that are not finite or exceed {MAX_PHYSICAL:e}"),
                ));
            }
            let sym = (b.inertia - b.inertia.transpose()).norm();
            let eig = b.inertia.symmetric_eigenvalues();
            if sym > 1e-9 * b.inertia.norm()
                || eig.iter().any(|&e| !within(e, MIN_PHYSICAL, f64::INFINITY))
            {
                return Err(fail(
                    "inertia",
                    format!(
                        "must be symmetric positive definite with principal moments of at least {MIN_PHYSICAL:e} (eigenvalues {:.4e}, {:.4e}, {:.4e})",
                        eig[0], eig[1], eig[2]
                    ),
                ));
            }
            // Triangle inequality of principal moments (a physical body's inertia).
            let mut e = [eig[0], eig[1], eig[2]];
            e.sort_by(f64::total_cmp);
            if e[0] + e[1] < e[2] * (1.0 - 1e-9) {
                return Err(fail(
                    "inertia",
                    format!(
                        "principal moments {:.4e}, {:.4e}, {:.4e} violate the triangle inequality",
                        e[0], e[1], e[2]
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The checks of [`Self::validate`] on the joints.
    fn validate_joints(&self) -> Result<(), ModelError> {
        let check_node =
            |table, i, name: &str, field, id| self.check_node(table, i, name, field, id);
        for (i, j) in self.joints.iter().enumerate() {
            let fail = |field, m| bad("joint", i, &j.name, field, m);
            check_node("joint", i, &j.name, "node_a", j.node_a)?;
            check_node("joint", i, &j.name, "node_b", j.node_b)?;
            if j.node_a.is_none() && j.node_b.is_none() {
                return Err(fail("node_b", "a joint needs at least one node".into()));
            }
            if j.node_a.is_some() && j.node_a == j.node_b {
                return Err(fail("node_b", "joins a node to itself".into()));
            }
            local_frame(&j.frame_a).map_err(|m| fail("position", format!("frame A {m}")))?;
            local_frame(&j.frame_b).map_err(|m| fail("position", format!("frame B {m}")))?;
            if let JointKind::Gear {
                teeth_a, teeth_b, ..
            } = j.kind
            {
                for (field, z) in [("teeth_a", teeth_a), ("teeth_b", teeth_b)] {
                    if z == 0 {
                        return Err(fail(field, "must be a whole number of teeth >= 1".into()));
                    }
                }
                self.check_wheels([j.node_a, j.node_b], [&j.frame_a, &j.frame_b])
                    .map_err(|m| fail("center_b", m))?;
            }
            if let Some(drive) = &j.drive {
                if !matches!(j.kind, JointKind::Revolute | JointKind::Prismatic) {
                    return Err(fail(
                        "drive",
                        format!(
                            "only revolute and prismatic joints can be driven, not {}",
                            j.kind.name()
                        ),
                    ));
                }
                drive.check().map_err(|m| fail("drive", m))?;
            }
        }
        if let Some((first, i)) = first_duplicate(self.joints.iter().map(|x| x.name.as_str())) {
            return Err(bad(
                "joint",
                i,
                &self.joints[i].name,
                "name",
                format!("duplicate joint name (also joint #{})", first + 1),
            ));
        }
        Ok(())
    }

    /// The checks of [`Self::validate`] on the loads.
    fn validate_loads(&self) -> Result<(), ModelError> {
        let check_node =
            |table, i, name: &str, field, id| self.check_node(table, i, name, field, id);
        for (i, l) in self.loads.iter().enumerate() {
            let fail = |field, m| bad("load", i, &l.name, field, m);
            check_node("load", i, &l.name, "node", Some(l.node))?;
            finite3(&l.force, MAX_PHYSICAL).map_err(|m| fail("force", m))?;
            finite3(&l.torque, MAX_PHYSICAL).map_err(|m| fail("torque", m))?;
            l.function.check().map_err(|m| fail("function", m))?;
            let owner = l.input.map(|k| self.inputs.get(k).map(|input| input.load));
            if owner.is_some_and(|load| load != Some(i)) {
                let m = "is not an input of the model that names this load";
                return Err(fail("input", m.into()));
            }
        }
        for (k, input) in self.inputs.iter().enumerate() {
            if self.loads.get(input.load).and_then(|l| l.input) != Some(k) {
                let m = "names no load that it scales";
                return Err(bad("load", input.load, &input.name, "input", m.into()));
            }
        }
        Ok(())
    }

    /// The checks of [`Self::validate`] on the spring-dampers and their force laws.
    fn validate_springs(&self) -> Result<(), ModelError> {
        let check_node =
            |table, i, name: &str, field, id| self.check_node(table, i, name, field, id);
        for (i, s) in self.springs.iter().enumerate() {
            let fail = |field, m| bad("spring", i, &s.name, field, m);
            check_node("spring", i, &s.name, "node_a", s.node_a)?;
            check_node("spring", i, &s.name, "node_b", s.node_b)?;
            self.two_nodes(s.node_a, s.node_b, "spring")
                .map_err(|m| fail("node_b", m))?;
            finite3(&s.point_a, 2.0 * MAX_KINEMATIC).map_err(|m| fail("point_a", m))?;
            finite3(&s.point_b, 2.0 * MAX_KINEMATIC).map_err(|m| fail("point_b", m))?;
            in_range(s.stiffness, 0.0, MAX_PHYSICAL).map_err(|m| fail("stiffness", m))?;
            in_range(s.damping, 0.0, MAX_PHYSICAL).map_err(|m| fail("damping", m))?;
            if let Some(branch) = &s.relaxation {
                in_range(branch.stiffness, MIN_PHYSICAL, MAX_PHYSICAL)
                    .map_err(|m| fail("relaxation_stiffness", m))?;
                in_range(branch.damping, MIN_PHYSICAL, MAX_PHYSICAL)
                    .map_err(|m| fail("relaxation_damping", m))?;
            }
            // The default rest length is the distance of two points in range: up to 2e9.
            in_range(s.rest_length, 0.0, 2.0 * MAX_KINEMATIC)
                .map_err(|m| fail("rest_length", m))?;
            let world = |node: Option<NodeId>, p: &Vec3| match node {
                Some(id) => self.nodes[id.0].frame.point(p),
                None => *p,
            };
            let (pa, pb) = (world(s.node_a, &s.point_a), world(s.node_b, &s.point_b));
            let gap = (pb - pa).norm();
            let scale = s.rest_length.max(pa.norm()).max(pb.norm());
            if s.rest_length > 0.0 && gap <= 1e-9 * scale {
                return Err(fail(
                    "rest_length",
                    format!(
                        "is {} but the end points coincide at t = 0 (distance {gap:.3e}): the direction of the spring force is undefined there; move an end point or set rest_length = 0",
                        s.rest_length
                    ),
                ));
            }
        }

        let mut with_law = vec![false; self.springs.len()];
        for law in &self.spring_laws {
            let Some(s) = self.springs.get(law.spring) else {
                return Err(bad(
                    "spring",
                    law.spring,
                    "",
                    "spring",
                    format!(
                        "a nonlinear law names spring index {} but the model has {} springs",
                        law.spring,
                        self.springs.len()
                    ),
                ));
            };
            let fail = |field, m| bad("spring", law.spring, &s.name, field, m);
            if std::mem::replace(&mut with_law[law.spring], true) {
                return Err(fail("stiffness", "has two nonlinear laws".into()));
            }
            check_force_law(&law.law).map_err(|(field, m)| fail(field, m))?;
            if law.law.acts != super::SpringSide::Both && s.relaxation.is_some() {
                return Err(fail(
                    "acts",
                    "a one-sided spring (a stop) cannot have a Maxwell branch: its branch would hold a force while the stop is off".into(),
                ));
            }
        }
        Ok(())
    }

    /// The checks of [`Self::validate`] on the rotational springs.
    fn validate_rotational_springs(&self) -> Result<(), ModelError> {
        for (i, s) in self.rotational_springs.iter().enumerate() {
            let fail = |field, m| bad("rotational_spring", i, &s.name, field, m);
            let Some(joint) = self.joints.get(s.joint.0) else {
                return Err(fail(
                    "joint",
                    format!("joint index {} does not exist", s.joint.0),
                ));
            };
            if !matches!(joint.kind, JointKind::Revolute | JointKind::Cylindrical) {
                return Err(fail(
                    "joint",
                    format!(
                        "joint '{}' is {}: a rotational spring acts about the axis of a revolute or cylindrical joint",
                        clip(&joint.name, QUOTED),
                        joint.kind.name()
                    ),
                ));
            }
            in_range(s.stiffness, 0.0, MAX_PHYSICAL).map_err(|m| fail("stiffness", m))?;
            in_range(s.damping, 0.0, MAX_PHYSICAL).map_err(|m| fail("damping", m))?;
            in_range(s.angle, -MAX_ANGLE, MAX_ANGLE).map_err(|m| fail("angle", m))?;
            check_force_law(&s.law).map_err(|(field, m)| fail(field, m))?;
        }
        Ok(())
    }

    /// The checks of [`Self::validate`] on the bushings.
    fn validate_bushings(&self) -> Result<(), ModelError> {
        let check_node =
            |table, i, name: &str, field, id| self.check_node(table, i, name, field, id);
        for (i, b) in self.bushings.iter().enumerate() {
            let fail = |field, m| bad("bushing", i, &b.name, field, m);
            check_node("bushing", i, &b.name, "node_a", b.node_a)?;
            check_node("bushing", i, &b.name, "node_b", b.node_b)?;
            self.two_nodes(b.node_a, b.node_b, "bushing")
                .map_err(|m| fail("node_b", m))?;
            local_frame(&b.frame_a).map_err(|m| fail("frame_a", m))?;
            local_frame(&b.frame_b).map_err(|m| fail("frame_b", m))?;
            for (m, field) in [(&b.stiffness, "stiffness"), (&b.damping, "damping")] {
                symmetric_psd(m).map_err(|msg| fail(field, msg))?;
            }
        }
        Ok(())
    }

    /// The checks of [`Self::validate`] on the contacts.
    fn validate_contacts(&self) -> Result<(), ModelError> {
        let check_node =
            |table, i, name: &str, field, id| self.check_node(table, i, name, field, id);
        for (i, c) in self.contacts.iter().enumerate() {
            let fail = |field, m| bad("contact", i, &c.name, field, m);
            check_node("contact", i, &c.name, "node_a", c.node_a)?;
            check_node("contact", i, &c.name, "node_b", c.node_b)?;
            self.two_nodes(c.node_a, c.node_b, "contact")
                .map_err(|m| fail("node_b", m))?;
            for (field, shape) in [("a", &c.shape_a), ("b", &c.shape_b)] {
                check_contact_shape(shape).map_err(|m| fail(field, m))?;
            }
            contact_pair(self, c).map_err(|m| fail("b", m))?;
            let law = &c.law;
            in_range(law.stiffness, MIN_PHYSICAL, MAX_PHYSICAL)
                .map_err(|m| fail("stiffness", m))?;
            in_range(law.exponent, 1.0, 10.0).map_err(|m| fail("exponent", m))?;
            if !(law.restitution > 0.0 && law.restitution <= 1.0) {
                return Err(fail(
                    "restitution",
                    format!("must be in (0, 1], got {}", law.restitution),
                ));
            }
            in_range(law.min_impact_velocity, MIN_PHYSICAL, MAX_PHYSICAL)
                .map_err(|m| fail("min_impact_velocity", m))?;
            if let Some(f) = &c.friction {
                in_range(f.coefficient, 0.0, MAX_FRICTION).map_err(|m| fail("friction", m))?;
                in_range(f.stiction_velocity, MIN_PHYSICAL, MAX_PHYSICAL)
                    .map_err(|m| fail("friction", format!("stiction_velocity {m}")))?;
                in_range(f.viscous, 0.0, MAX_PHYSICAL)
                    .map_err(|m| fail("friction", format!("viscous {m}")))?;
                if let Some(b) = &f.bristles {
                    in_range(b.stiffness, MIN_PHYSICAL, MAX_PHYSICAL)
                        .map_err(|m| fail("friction", format!("bristles.stiffness {m}")))?;
                    in_range(b.damping, 0.0, MAX_PHYSICAL)
                        .map_err(|m| fail("friction", format!("bristles.damping {m}")))?;
                    if !(b.static_coefficient >= f.coefficient && b.static_coefficient > 0.0) {
                        return Err(fail(
                            "friction",
                            format!(
                                "bristles.static_coefficient {} must be positive and at least the coefficient {}",
                                b.static_coefficient, f.coefficient
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// The checks of [`Self::validate`] on the ropes.
    fn validate_ropes(&self) -> Result<(), ModelError> {
        let check_node =
            |table, i, name: &str, field, id| self.check_node(table, i, name, field, id);
        for (i, r) in self.ropes.iter().enumerate() {
            let fail = |field, m| bad("rope", i, &r.name, field, m);
            let n_points = r.points.len();
            if !(2..=MAX_ROPE_POINTS).contains(&n_points) {
                return Err(fail(
                    "points",
                    format!("has {n_points} points: a rope runs through 2 to {MAX_ROPE_POINTS} points (its local matrix is dense)"),
                ));
            }
            for p in &r.points {
                check_node("rope", i, &r.name, "points", p.node)?;
                finite3(&p.point, 2.0 * MAX_KINEMATIC).map_err(|m| fail("points", m))?;
            }
            if r.points.iter().all(|p| p.node.is_none()) {
                return Err(fail(
                    "points",
                    "every point is on the ground: give at least one node".into(),
                ));
            }
            in_range(r.stiffness, 0.0, MAX_PHYSICAL).map_err(|m| fail("stiffness", m))?;
            in_range(r.damping, 0.0, MAX_PHYSICAL).map_err(|m| fail("damping", m))?;
            let world = |p: &RopePoint| match p.node {
                Some(id) => self.nodes[id.0].frame.point(&p.point),
                None => p.point,
            };
            let length: f64 = r
                .points
                .windows(2)
                .map(|w| (world(&w[1]) - world(&w[0])).norm())
                .sum();
            in_range(r.rest_length, 0.0, 2.0 * MAX_KINEMATIC * n_points as f64)
                .map_err(|m| fail("rest_length", m))?;
            for (s, w) in r.points.windows(2).enumerate() {
                let (a, b) = (world(&w[0]), world(&w[1]));
                if (b - a).norm() <= 1e-9 * length.max(a.norm()).max(b.norm()) {
                    return Err(fail(
                        "points",
                        format!(
                            "points {} and {} coincide at t = 0: the direction of the rope between them is undefined",
                            s + 1,
                            s + 2
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The checks of [`Self::validate`] on the beam elements.
    fn validate_beams(&self) -> Result<(), ModelError> {
        let check_node =
            |table, i, name: &str, field, id| self.check_node(table, i, name, field, id);
        let model_extent = self.extent();
        for (i, b) in self.beams.iter().enumerate() {
            let fail = |field, m| bad("beam", i, &b.name, field, m);
            for (field, id) in [("node_a", b.nodes[0]), ("node_b", b.nodes[1])] {
                check_node("beam", i, &b.name, field, Some(id))?;
            }
            if self.group != Group::SE3 {
                return Err(fail(
                    "group",
                    "beams are formulated on SE(3): set the model's group to \"SE3\"".into(),
                ));
            }
            if b.nodes[0] == b.nodes[1] || !(b.length > 0.0 && b.length <= MAX_KINEMATIC) {
                return Err(fail(
                    "length",
                    format!("must be positive, got {}", b.length),
                ));
            }
            rotation(&b.offset_a).map_err(|m| fail("section", format!("offset A {m}")))?;
            rotation(&b.offset_b).map_err(|m| fail("section", format!("offset B {m}")))?;
            let c = &b.section.stiffness;
            if !c.iter().all(|v| v.abs() <= MAX_PHYSICAL) {
                return Err(fail(
                    "section",
                    format!("the sectional stiffness has values that are not finite or exceed {MAX_PHYSICAL:e}"),
                ));
            }
            let sym = (c - c.transpose()).norm();
            let diagonal_ok = (0..6).all(|k| c[(k, k)] >= MIN_PHYSICAL);
            if sym > 1e-9 * c.norm() || !diagonal_ok || c.cholesky().is_none() {
                return Err(fail(
                    "section",
                    format!("the sectional stiffness must be symmetric positive definite, with diagonal entries of at least {MIN_PHYSICAL:e}"),
                ));
            }
            for (what, v) in [
                ("mass-proportional damping", b.section.damping_mass),
                (
                    "stiffness-proportional damping",
                    b.section.damping_stiffness,
                ),
            ] {
                in_range(v, 0.0, MAX_PHYSICAL)
                    .map_err(|m| fail("section", format!("{what} {m}")))?;
            }
            in_range(b.section.mass_per_length, MIN_PHYSICAL, MAX_PHYSICAL)
                .map_err(|m| fail("section", format!("mass per length {m}")))?;
            let j = &b.section.rotary_inertia;
            let j_ok = j.iter().all(|v| v.abs() <= MAX_PHYSICAL)
                && (0..3).all(|k| j[(k, k)] >= MIN_PHYSICAL);
            if !j_ok || (j - j.transpose()).norm() > 1e-9 * j.norm() || j.cholesky().is_none() {
                return Err(fail(
                    "section",
                    format!("the sectional rotary inertia must be symmetric positive definite, with entries between {MIN_PHYSICAL:e} and {MAX_PHYSICAL:e}"),
                ));
            }
            // Degenerate elements: short against the model, or against their own section.
            if b.length < MIN_RELATIVE_LENGTH * model_extent {
                return Err(fail(
                    "length",
                    format!(
                        "{:e} is below {MIN_RELATIVE_LENGTH:e} times the extent of the model ({model_extent:.4e}): a degenerate element",
                        b.length
                    ),
                ));
            }
            let gyration = ((c[(3, 3)].max(c[(4, 4)]).max(c[(5, 5)])) / c[(0, 0)]).sqrt();
            if b.length < MIN_RELATIVE_LENGTH * gyration {
                return Err(fail(
                    "length",
                    format!(
                        "{:e} is below {MIN_RELATIVE_LENGTH:e} times the radius of gyration of the section ({gyration:.4e} = sqrt of the largest of GJ, EI2, EI3 over EA): a degenerate element",
                        b.length
                    ),
                ));
            }
        }
        Ok(())
    }

    /// The checks of [`Self::validate`] on the sensors.
    fn validate_sensors(&self) -> Result<(), ModelError> {
        let check_node =
            |table, i, name: &str, field, id| self.check_node(table, i, name, field, id);
        for (i, s) in self.sensors.iter().enumerate() {
            let fail = |field, m| bad("sensor", i, &s.name, field, m);
            check_sensor_name(&s.name).map_err(|m| fail("name", m))?;
            let (node, components) = match &s.kind {
                SensorKind::Position {
                    node,
                    point,
                    component,
                }
                | SensorKind::Velocity {
                    node,
                    point,
                    component,
                }
                | SensorKind::Acceleration {
                    node,
                    point,
                    component,
                } => {
                    finite3(point, 2.0 * MAX_KINEMATIC).map_err(|m| fail("point", m))?;
                    (Some(*node), Some((*component, 3)))
                }
                SensorKind::Quaternion { node, component } => (Some(*node), Some((*component, 4))),
                SensorKind::AngularVelocity {
                    node, component, ..
                }
                | SensorKind::AngularAcceleration {
                    node, component, ..
                } => (Some(*node), Some((*component, 3))),
                SensorKind::JointCoordinate { joint }
                | SensorKind::JointForce { joint, .. }
                | SensorKind::JointTorque { joint, .. } => {
                    let Some(j) = self.joints.get(joint.0) else {
                        return Err(fail(
                            "joint",
                            format!("joint index {} does not exist", joint.0),
                        ));
                    };
                    let coordinate = matches!(
                        j.kind,
                        JointKind::Revolute | JointKind::Prismatic | JointKind::Cylindrical
                    );
                    if matches!(s.kind, SensorKind::JointCoordinate { .. }) && !coordinate {
                        return Err(fail(
                            "joint",
                            format!(
                                "joint '{}' is {}; a joint coordinate exists for revolute, prismatic and cylindrical joints",
                                clip(&j.name, QUOTED),
                                j.kind.name()
                            ),
                        ));
                    }
                    match s.kind {
                        SensorKind::JointForce { component, .. }
                        | SensorKind::JointTorque { component, .. } => (None, Some((component, 3))),
                        _ => (None, None),
                    }
                }
                SensorKind::BeamStrain { beam, component }
                | SensorKind::BeamStress { beam, component } => {
                    if *beam >= self.beams.len() {
                        return Err(fail(
                            "beam",
                            format!("beam element index {beam} does not exist"),
                        ));
                    }
                    (None, Some((*component, 6)))
                }
                SensorKind::SpringForce { spring } => {
                    if *spring >= self.springs.len() {
                        return Err(fail(
                            "spring",
                            format!("spring index {spring} does not exist"),
                        ));
                    }
                    (None, None)
                }
                SensorKind::Contact { contact, quantity } => {
                    if *contact >= self.contacts.len() {
                        return Err(fail(
                            "contact",
                            format!("contact index {contact} does not exist"),
                        ));
                    }
                    (None, Some((*quantity, super::CONTACT_QUANTITIES.len())))
                }
                SensorKind::RopeForce { rope } => {
                    if *rope >= self.ropes.len() {
                        return Err(fail("rope", format!("rope index {rope} does not exist")));
                    }
                    (None, None)
                }
                SensorKind::RotationalSpringTorque { spring } => {
                    if *spring >= self.rotational_springs.len() {
                        return Err(fail(
                            "spring",
                            format!("rotational spring index {spring} does not exist"),
                        ));
                    }
                    (None, None)
                }
                SensorKind::BushingForce { bushing, component } => {
                    if *bushing >= self.bushings.len() {
                        return Err(fail(
                            "bushing",
                            format!("bushing index {bushing} does not exist"),
                        ));
                    }
                    (None, Some((*component, 6)))
                }
                SensorKind::KineticEnergy
                | SensorKind::PotentialEnergy
                | SensorKind::TotalEnergy
                | SensorKind::ConstraintViolation => (None, None),
                SensorKind::GearForce { gear } | SensorKind::GearTransmissionError { gear } => {
                    if *gear >= self.gears.len() {
                        return Err(fail("gear", format!("gear index {gear} does not exist")));
                    }
                    (None, None)
                }
                SensorKind::Block { block, output } => {
                    let Some(b) = self.control.blocks.get(*block) else {
                        return Err(fail("block", format!("block index {block} does not exist")));
                    };
                    (None, Some((*output, b.kind.n_outputs())))
                }
            };
            check_node("sensor", i, &s.name, "node", node)?;
            if let Some((c, count)) = components {
                if c >= count {
                    return Err(fail(
                        "component",
                        format!("component index {c} does not exist (0 to {})", count - 1),
                    ));
                }
            }
        }
        if let Some((first, i)) = first_duplicate(self.sensors.iter().map(|x| x.name.as_str())) {
            return Err(bad(
                "sensor",
                i,
                &self.sensors[i].name,
                "name",
                format!(
                    "duplicate sensor name (also sensor #{}): each names a column of sensors.csv",
                    first + 1
                ),
            ));
        }
        Ok(())
    }
}

/// A sensor's name is the header of its column in `sensors.csv`: not empty, not the name of
/// the first column, no CSV delimiters, quotes or control characters.
fn check_sensor_name(name: &str) -> Check {
    if name.trim().is_empty() {
        return Err("must not be empty (it names a column of sensors.csv)".into());
    }
    if RESERVED_COLUMNS.contains(&name) {
        return Err(format!(
            "'{name}' is the name of the first column of sensors.csv ({}); choose another",
            RESERVED_COLUMNS.join(" or ")
        ));
    }
    if name.contains([',', '"']) || name.chars().any(char::is_control) {
        return Err(
            "must not contain commas, double quotes, line breaks or other control characters (it names a column of sensors.csv)"
                .into(),
        );
    }
    Ok(())
}

impl Model {
    /// The two wheel frames of a gear joint or gear pair (on `nodes`, inertial for the
    /// ground): axes parallel and in the same sense, centres apart and not on one line along
    /// the axis (the line of centres defines the wheels' angles), each x axis towards the
    /// other centre.
    fn check_wheels(&self, nodes: [Option<NodeId>; 2], wheels: [&Frame; 2]) -> Check {
        for w in wheels {
            local_frame(w)?;
        }
        let world = |n: Option<NodeId>, w: &Frame| match n {
            Some(id) => self.nodes[id.0].frame.compose(w),
            None => *w,
        };
        let (wa, wb) = (world(nodes[0], wheels[0]), world(nodes[1], wheels[1]));
        let (ka, kb) = (wa.r.column(2), wb.r.column(2));
        if ka.dot(&kb) < 1.0 - 1e-9 {
            return Err(format!(
                "the wheel axes are not parallel and in the same sense at t = 0 (angle {:.4} deg)",
                ka.dot(&kb).clamp(-1.0, 1.0).acos().to_degrees()
            ));
        }
        let d = wb.x - wa.x;
        let radial = (d - ka * ka.dot(&d)).norm();
        if radial <= 1e-9 * d.norm().max(1.0) {
            return Err(format!(
                "the wheel centres are {:.3e} m apart across the axis: the line of centres is undefined",
                radial
            ));
        }
        Ok(())
    }

    fn validate_worm_gears(&self) -> Result<(), ModelError> {
        for (i, g) in self.worm_gears.iter().enumerate() {
            let fail = |field, m| bad("worm_gear", i, &g.name, field, m);
            self.check_node("worm_gear", i, &g.name, "node_a", g.node_a)?;
            self.check_node("worm_gear", i, &g.name, "node_b", g.node_b)?;
            self.two_nodes(g.node_a, g.node_b, "worm gear")
                .map_err(|m| fail("node_b", m))?;
            for (field, z) in [("starts", g.starts), ("teeth", g.teeth)] {
                if z == 0 {
                    return Err(fail(field, "must be a whole number >= 1".into()));
                }
            }
            for f in [&g.frame_a, &g.frame_b] {
                local_frame(f).map_err(|m| fail("center_b", m))?;
            }
            let world = |n: Option<NodeId>, f: &Frame| match n {
                Some(id) => self.nodes[id.0].frame.compose(f),
                None => *f,
            };
            let (wa, wb) = (world(g.node_a, &g.frame_a), world(g.node_b, &g.frame_b));
            let cosine = wa.r.column(2).dot(&wb.r.column(2));
            if cosine.abs() > 1e-6 {
                return Err(fail(
                    "axis_b",
                    format!(
                        "the worm and wheel axes must be perpendicular at t = 0, they are {:.4} deg apart",
                        cosine.clamp(-1.0, 1.0).acos().to_degrees()
                    ),
                ));
            }
            in_range(g.center_distance, MIN_PHYSICAL, MAX_KINEMATIC)
                .map_err(|m| fail("center_b", format!("centre distance {m}")))?;
            if !(g.worm_radius > 0.0 && g.worm_radius < g.center_distance) {
                return Err(fail(
                    "worm_radius",
                    format!(
                        "must be above 0 and below the centre distance {:.6e} m (the wheel's pitch radius is the rest), got {}",
                        g.center_distance, g.worm_radius
                    ),
                ));
            }
            pressure_angle(g.pressure_angle).map_err(|m| fail("pressure_angle_deg", m))?;
            in_range(g.mesh_stiffness, MIN_PHYSICAL, MAX_PHYSICAL)
                .map_err(|m| fail("mesh_stiffness", m))?;
            in_range(g.damping, 0.0, MAX_PHYSICAL).map_err(|m| fail("damping", m))?;
            in_range(g.friction, 0.0, MAX_FRICTION).map_err(|m| fail("friction", m))?;
            in_range(g.stiction_velocity, MIN_PHYSICAL, MAX_KINEMATIC)
                .map_err(|m| fail("stiction_velocity", m))?;
            in_range(g.washer_radius, 0.0, MAX_KINEMATIC).map_err(|m| fail("washer_radius", m))?;
        }
        Ok(())
    }

    /// The block diagram: wiring (inputs name existing outputs, as many as the kind
    /// takes), the nodes and joints of measurements and actuators, and the parameters
    /// (finite; time constants, the filter constant of a PID with a derivative, a motor's
    /// constants and a hold's period positive; limits ordered; a transfer function's
    /// leading denominator coefficient nonzero).
    fn validate_control(&self) -> Result<(), ModelError> {
        use super::control::BlockKind;
        let blocks = &self.control.blocks;
        // the numbering of the unknowns is that of the blocks (a model built in Rust)
        let fresh = super::control::ControlSystem::new(blocks.clone());
        if fresh != self.control {
            return Err(bad(
                "block",
                0,
                blocks.first().map_or("", |b| b.name.as_str()),
                "blocks",
                "the blocks were changed after ControlSystem::new: build the system again".into(),
            ));
        }
        for (i, b) in blocks.iter().enumerate() {
            let fail = |field, m| bad("block", i, &b.name, field, m);
            let names = b.kind.param_names();
            let n_own = names.len() - b.n_amplitudes();
            if b.params.len() != n_own {
                return Err(fail(
                    "params",
                    format!("{} parameters, the kind takes {n_own}", b.params.len()),
                ));
            }
            // (the amplitudes of a function are checked with the function)
            for (k, v) in b.params.iter().enumerate() {
                if !v.is_finite() {
                    return Err(fail(
                        "params",
                        format!("{} is {v}", names[b.n_amplitudes() + k]),
                    ));
                }
            }
            if b.inputs.len() != b.kind.n_inputs() {
                return Err(fail(
                    "inputs",
                    format!(
                        "a {} block takes {} inputs, got {}",
                        b.kind.name(),
                        b.kind.n_inputs(),
                        b.inputs.len()
                    ),
                ));
            }
            for s in &b.inputs {
                let known = blocks
                    .get(s.block)
                    .is_some_and(|source| s.output < source.kind.n_outputs());
                if !known {
                    return Err(fail(
                        "inputs",
                        format!("output {} of block {} does not exist", s.output, s.block),
                    ));
                }
            }
            let positive = |field: &'static str, v: f64| {
                if v > 0.0 {
                    Ok(())
                } else {
                    Err(fail(field, format!("must be positive, got {v}")))
                }
            };
            let ordered = |lo: f64, hi: f64| {
                if lo <= hi {
                    Ok(())
                } else {
                    Err(fail("upper", format!("must be >= lower ({lo}), got {hi}")))
                }
            };
            let p = &b.params;
            match &b.kind {
                BlockKind::Lag => positive("time_constant", p[1])?,
                BlockKind::Pid => {
                    positive("tf", p[3])?;
                    ordered(p[4], p[5])?;
                    if p[6] < 0.0 {
                        return Err(fail("kb", format!("must be >= 0, got {}", p[6])));
                    }
                }
                BlockKind::RateLimiter => {
                    positive("rising", p[0])?;
                    positive("falling", p[1])?;
                    positive("time_constant", p[2])?;
                }
                BlockKind::Saturation | BlockKind::DeadZone => ordered(p[0], p[1])?,
                BlockKind::TransferFunction { num, den } => {
                    if *den == 0 || p[*num] == 0.0 {
                        return Err(fail(
                            "denominator",
                            "the leading coefficient must not be 0".into(),
                        ));
                    }
                    if num > den {
                        return Err(fail(
                            "numerator",
                            "the transfer function must be proper".into(),
                        ));
                    }
                }
                BlockKind::Hold { period } => positive("period", *period)?,
                BlockKind::DcMotor => {
                    for (k, field) in ["resistance", "inductance", "torque_constant", "back_emf"]
                        .iter()
                        .enumerate()
                    {
                        positive(field, p[k])?;
                    }
                }
                BlockKind::Measure(q) => self.check_quantity(i, b, q)?,
                BlockKind::Actuator(t) => self.check_target(i, b, t)?,
                BlockKind::Servo {
                    quantity, target, ..
                } => {
                    self.check_quantity(i, b, quantity)?;
                    self.check_target(i, b, target)?;
                }
                _ => {}
            }
        }
        Ok(())
    }

    /// The node or joint a measurement of block `i` reads exists.
    fn check_quantity(
        &self,
        i: usize,
        b: &super::control::Block,
        q: &super::control::Quantity,
    ) -> Result<(), ModelError> {
        use super::control::Quantity;
        // a force measured on node B of a joint or contact (`what`, named `name`)
        let on_node_b = |field, what: &str, name: &str, node_b: Option<NodeId>| {
            match node_b {
            Some(_) => Ok(()),
            None => Err(bad(
                "block",
                i,
                &b.name,
                field,
                format!(
                    "{what} '{name}' has the ground as its node B: its force is measured on node B (swap its nodes)"
                ),
            )),
        }
        };
        match q {
            Quantity::Position { node, .. }
            | Quantity::Velocity { node, .. }
            | Quantity::Acceleration { node, .. }
            | Quantity::AngularVelocity { node, .. } => {
                self.check_node("block", i, &b.name, "node", Some(*node))
            }
            Quantity::JointCoordinate { joint } | Quantity::JointRate { joint } => {
                self.check_joint_index(i, b, *joint)
            }
            Quantity::ConstraintForce { joint, .. } => {
                self.check_joint_index(i, b, *joint)?;
                let j = &self.joints[joint.0];
                on_node_b("joint", "joint", &j.name, j.node_b)
            }
            Quantity::ContactForce { contact, .. } => match self.contacts.get(*contact) {
                None => Err(bad(
                    "block",
                    i,
                    &b.name,
                    "contact",
                    format!("contact index {contact} does not exist"),
                )),
                Some(c) => on_node_b("contact", "contact", &c.name, c.node_b),
            },
            Quantity::SectionForce { beam, component } => {
                if *beam >= self.beams.len() {
                    Err(bad(
                        "block",
                        i,
                        &b.name,
                        "beam",
                        format!("beam element index {beam} does not exist"),
                    ))
                } else if *component >= 6 {
                    Err(bad(
                        "block",
                        i,
                        &b.name,
                        "component",
                        format!("must be 0 to 5, got {component}"),
                    ))
                } else {
                    Ok(())
                }
            }
        }
    }

    /// The node or joint the actuator of block `i` acts on exists.
    fn check_target(
        &self,
        i: usize,
        b: &super::control::Block,
        t: &super::control::Target,
    ) -> Result<(), ModelError> {
        use super::control::Target;
        match t {
            Target::Force { node, .. } | Target::Moment { node, .. } => {
                self.check_node("block", i, &b.name, "node", Some(*node))
            }
            Target::Joint { joint } => self.check_joint_index(i, b, *joint),
        }
    }

    fn check_joint_index(
        &self,
        i: usize,
        b: &super::control::Block,
        joint: super::JointId,
    ) -> Result<(), ModelError> {
        if joint.0 < self.joints.len() {
            Ok(())
        } else {
            Err(bad(
                "block",
                i,
                &b.name,
                "joint",
                format!("joint index {} does not exist", joint.0),
            ))
        }
    }

    fn validate_gears(&self) -> Result<(), ModelError> {
        let check_node =
            |table, i, name: &str, field, id| self.check_node(table, i, name, field, id);
        for (i, g) in self.gears.iter().enumerate() {
            let fail = |field, m| bad("gear", i, &g.name, field, m);
            check_node("gear", i, &g.name, "node_a", g.node_a)?;
            check_node("gear", i, &g.name, "node_b", g.node_b)?;
            self.two_nodes(g.node_a, g.node_b, "gear pair")
                .map_err(|m| fail("node_b", m))?;
            let geo = &g.geometry;
            for (field, z) in [("teeth_a", geo.teeth_a), ("teeth_b", geo.teeth_b)] {
                if z == 0 {
                    return Err(fail(field, "must be a whole number of teeth >= 1".into()));
                }
            }
            in_range(geo.module, MIN_PHYSICAL, MAX_KINEMATIC).map_err(|m| fail("module", m))?;
            pressure_angle(geo.pressure_angle).map_err(|m| fail("pressure_angle_deg", m))?;
            if geo.helix_angle.is_nan() || geo.helix_angle.abs() >= 1.2 {
                return Err(fail(
                    "helix_angle_deg",
                    format!(
                        "must be between -68.75 and 68.75 deg, got {} deg",
                        geo.helix_angle.to_degrees()
                    ),
                ));
            }
            if geo.internal && geo.teeth_b <= geo.teeth_a {
                return Err(fail(
                    "teeth_b",
                    format!(
                        "an internal pair needs more teeth on the ring gear B than on the pinion A, got {} and {}",
                        geo.teeth_b, geo.teeth_a
                    ),
                ));
            }
            self.check_wheels([g.node_a, g.node_b], [&g.frame_a, &g.frame_b])
                .map_err(|m| fail("center_b", m))?;
            let [ra, rb] = geo.base_radii();
            let least = (ra + geo.sigma() * rb).abs();
            if g.center_distance.is_nan() || g.center_distance <= least * (1.0 + 1e-9) {
                return Err(fail(
                    "center_b",
                    format!(
                        "the centre distance {:.6e} m must exceed {} of the base radii, {least:.6e} m (working pressure angle above 0)",
                        g.center_distance,
                        if geo.internal { "the difference" } else { "the sum" }
                    ),
                ));
            }
            in_range(g.mesh_stiffness, MIN_PHYSICAL, MAX_PHYSICAL)
                .map_err(|m| fail("mesh_stiffness", m))?;
            in_range(g.damping, 0.0, MAX_PHYSICAL).map_err(|m| fail("damping", m))?;
            in_range(g.backlash, 0.0, MAX_KINEMATIC).map_err(|m| fail("backlash", m))?;
            let pitch = 2.0 * std::f64::consts::PI * ra / geo.teeth_a as f64;
            if g.backlash >= 0.5 * pitch {
                return Err(fail(
                    "backlash",
                    format!(
                        "is {} m, not below half the base pitch ({:.6e} m): the flanks would not be told apart",
                        g.backlash,
                        0.5 * pitch
                    ),
                ));
            }
            let table = &g.stiffness_table;
            if table.len() == 1 {
                return Err(fail(
                    "stiffness_table",
                    "needs at least 2 points [position, factor] (or none)".into(),
                ));
            }
            for (i, &(u, f)) in table.iter().enumerate() {
                let increasing = i == 0 || u > table[i - 1].0;
                if !(within(u, 0.0, 1.0) && u < 1.0 && increasing && within(f, 1e-6, 1e6)) {
                    return Err(fail(
                        "stiffness_table",
                        format!(
                            "point {}: positions must increase strictly within [0, 1) (fractions of the mesh period) and factors lie in [1e-6, 1e6], got [{u}, {f}]",
                            i + 1
                        ),
                    ));
                }
            }
            let least = table.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
            let least = if table.is_empty() { 1.0 } else { least };
            let sum: f64 = g
                .stiffness_variation
                .iter()
                .map(|h| h.amplitude.abs())
                .sum();
            let finite = |hs: &[super::Harmonic]| {
                hs.iter()
                    .all(|h| h.amplitude.is_finite() && within(h.phase, -MAX_ANGLE, MAX_ANGLE))
            };
            if !finite(&g.stiffness_variation) || sum.is_nan() || sum >= least {
                return Err(fail(
                    "stiffness_variation",
                    format!("needs finite harmonics whose relative amplitudes add up to less than {least} (the smallest factor of the stiffness table, 1 without one: the stiffness stays positive), got {sum}"),
                ));
            }
            let te: f64 = g.transmission_error.iter().map(|h| h.amplitude.abs()).sum();
            if !finite(&g.transmission_error) || te.is_nan() || te >= 0.25 * pitch {
                return Err(fail(
                    "transmission_error",
                    format!("needs finite harmonics whose amplitudes add up to less than a quarter of the base pitch ({:.6e} m), got {te}", 0.25 * pitch),
                ));
            }
            if !within(g.mesh_phase, -MAX_ANGLE, MAX_ANGLE) {
                return Err(fail(
                    "mesh_phase",
                    format!(
                        "must be finite, at most {MAX_ANGLE:e} in magnitude, got {}",
                        g.mesh_phase
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// The error about `field` of item `index` (named `name`) of `table`.
fn bad(
    table: &'static str,
    index: usize,
    name: &str,
    field: &'static str,
    message: String,
) -> ModelError {
    ModelError::Invalid {
        item: ItemRef {
            table,
            index,
            name: clip(name, QUOTED),
            field,
        },
        message,
    }
}

impl Model {
    /// The node `id` of `field` of an item exists (or is the ground).
    fn check_node(
        &self,
        table: &'static str,
        i: usize,
        name: &str,
        field: &'static str,
        id: Option<NodeId>,
    ) -> Result<(), ModelError> {
        match id {
            Some(NodeId(k)) if k >= self.nodes.len() => Err(bad(
                table,
                i,
                name,
                field,
                format!("node index {k} does not exist"),
            )),
            _ => Ok(()),
        }
    }

    /// A two-node item (`what`: "spring", "bushing", ...) joins two different nodes, or a
    /// node and the ground.
    fn two_nodes(&self, a: Option<NodeId>, b: Option<NodeId>, what: &str) -> Check {
        match (a, b) {
            (None, None) => Err(format!(
                "joins the ground to the ground: a {what} acts between two different nodes (or a node and the ground)"
            )),
            (Some(a), Some(b)) if a == b => Err(format!(
                "joins node '{}' to itself: a {what} acts between two different nodes (or a node and the ground)",
                clip(&self.nodes[a.0].name, QUOTED)
            )),
            _ => Ok(()),
        }
    }
}
