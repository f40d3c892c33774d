//! `[[beam]]`: meshing of straight and circular beams into nodes and two-node beam elements,
//! and the cross-section forms.

use super::fields::{
    nonzero_vec3, physical, physical_or_zero, point, read_name, require_node, Origin, Origins,
};
use super::reader::{describe, name_list, out_of_range, suggestion, Field, Result, Table, QUOTED};
use crate::model::limits::{within, MAX_ITEMS, MAX_KINEMATIC, MAX_PHYSICAL, MIN_PHYSICAL};
use crate::model::parameters::SectionParam;
use crate::model::{clip, BeamMass, BeamSection, Model, NodeId};
use flexmb_lie::{so3, Frame, Mat3, Mat6, Vec3};
use std::collections::HashMap;
use toml::de::DeValue;

const BEAM_KEYS: &[&str] = &[
    "name",
    "start",
    "start_node",
    "end",
    "arc",
    "end_node",
    "elements",
    "orientation",
    "section",
    "damping",
    "element",
    "velocity",
    "angular_velocity",
    "mass_matrix",
    "display_radius",
];

/// Most elements of one `[[beam]]`.
const MAX_ELEMENTS: i64 = 100_000;

/// Below this sine of the angle between `orientation` and the beam axis, they are parallel.
const PARALLEL: f64 = 1e-6;

/// The axis line of a beam, parametrized by `s` in [0, 1].
enum Axis {
    Straight {
        start: Vec3,
        end: Vec3,
    },
    Arc {
        start: Vec3,
        center: Vec3,
        /// Unit rotation axis.
        axis: Vec3,
        /// Signed angle [rad].
        angle: f64,
    },
}

impl Axis {
    fn length(&self) -> f64 {
        match self {
            Axis::Straight { start, end } => (end - start).norm(),
            Axis::Arc {
                start,
                center,
                axis,
                angle,
            } => axis.cross(&(start - center)).norm() * angle.abs(),
        }
    }

    fn point(&self, s: f64) -> Vec3 {
        match self {
            Axis::Straight { start, end } => start + (end - start) * s,
            Axis::Arc {
                start,
                center,
                axis,
                angle,
            } => center + so3::exp(&(axis * (angle * s))) * (start - center),
        }
    }

    /// Unit tangent, pointing from the start to the end.
    fn tangent(&self, s: f64) -> Vec3 {
        match self {
            Axis::Straight { start, end } => (end - start).normalize(),
            Axis::Arc {
                center,
                axis,
                angle,
                ..
            } => axis.cross(&(self.point(s) - center)).normalize() * angle.signum(),
        }
    }

    /// Where along the axis the direction `o` (unit) is closest to parallel to the tangent:
    /// `(sine of the smallest angle between them, s there)`.
    fn most_parallel(&self, o: &Vec3) -> (f64, f64) {
        let sine = |s: f64| (o.cross(&self.tangent(s)).norm(), s);
        let ends = |a: (f64, f64), b: (f64, f64)| if b.0 < a.0 { b } else { a };
        match self {
            Axis::Straight { .. } => sine(0.0),
            Axis::Arc { axis, angle, .. } => {
                let best = ends(sine(0.0), sine(1.0));
                // The tangent turns about `axis`: it is parallel to the in-plane part of `o`
                // where the turned angle is psi (mod pi).
                let in_plane = o - axis * axis.dot(o);
                if in_plane.norm() < 1e-12 {
                    return best;
                }
                let x0 = self.tangent(0.0);
                let psi = axis.dot(&x0.cross(&in_plane)).atan2(x0.dot(&in_plane));
                let (lo, hi) = (angle.min(0.0), angle.max(0.0));
                let phi = psi + ((lo - psi) / std::f64::consts::PI).ceil() * std::f64::consts::PI;
                if phi <= hi {
                    ends(best, (axis.dot(o).abs(), phi / angle))
                } else {
                    best
                }
            }
        }
    }

    /// Section frame at `s`: x along the tangent, z along `o` projected on the plane normal
    /// to x, y = z x x (columns x, y, z).
    fn section_frame(&self, s: f64, o: &Vec3) -> Mat3 {
        let x = self.tangent(s);
        let z = (o - x * x.dot(o)).normalize();
        let y = z.cross(&x);
        Mat3::from_columns(&[x, y, z])
    }
}

/// `[x, y, z]` with 6 significant digits.
fn fmt_vec(v: &Vec3) -> String {
    let round = |c: f64| {
        if c == 0.0 || !c.is_finite() {
            return c;
        }
        let scale = 10f64.powi(5 - c.abs().log10().floor() as i32);
        (c * scale).round() / scale
    };
    format!("[{}, {}, {}]", round(v.x), round(v.y), round(v.z))
}

/// Reads the `[[beam]]` items in file order: creates their nodes and elements.
/// `node_names` maps every node name to the path of the item that created it.
pub(super) fn read_beams(
    top: &Table<'_>,
    model: &mut Model,
    origins: &mut Origins,
    node_names: &mut HashMap<String, String>,
) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("beam")? {
        t.check_keys(BEAM_KEYS)?;
        let name = read_name(&t, &mut names, "beam")?;

        // Start point.
        let (start, start_node) = match (t.field("start"), t.field("start_node")) {
            (Some(_), Some(_)) => {
                return Err(t.key_name_err(
                    "start_node",
                    "give either start (a point) or start_node (an existing node), not both",
                ))
            }
            (Some(f), None) => (point(&f)?, None),
            (None, Some(f)) => {
                let id = require_node(model, origins, &f)?;
                (model.nodes[id.0].frame.x, Some(id))
            }
            (None, None) => {
                return Err(t.key_err(
                    "start",
                    "is required: give start = [x, y, z] or start_node = \"<node name>\"",
                ))
            }
        };

        let ef = t.req("elements")?;
        let n = ef.int()?;
        if !(1..=MAX_ELEMENTS).contains(&n) {
            return Err(ef.err(format!("must be between 1 and {MAX_ELEMENTS}, got {n}")));
        }
        let n = n as usize;
        if model.nodes.len() + n > MAX_ITEMS || model.beams.len() + n > MAX_ITEMS {
            return Err(ef.err(format!(
                "the model would have more than {MAX_ITEMS} nodes or beam elements (the limit of a model's size)"
            )));
        }

        // Axis line.
        let axis = match (t.field("end"), t.field("arc")) {
            (Some(_), Some(_)) => {
                return Err(t.key_name_err(
                    "arc",
                    "give either end (a straight beam) or arc (a circular beam), not both",
                ))
            }
            (None, None) => {
                return Err(t.key_err(
                    "end",
                    "is required: give end = [x, y, z] (a straight beam) or arc = { center, axis, angle_deg } (a circular beam)",
                ))
            }
            (Some(f), None) => {
                let end = point(&f)?;
                let axis = Axis::Straight { start, end };
                let length = axis.length();
                if !(length > 0.0 && length.is_finite()) {
                    return Err(f.err(format!(
                        "must differ from the start point {} (the beam would have length {length})",
                        fmt_vec(&start)
                    )));
                }
                axis
            }
            (None, Some(f)) => read_arc(&f, start, n)?,
        };
        let length = axis.length();

        // End node.
        let end_node = match t.field("end_node") {
            Some(f) => {
                let id = require_node(model, origins, &f)?;
                let at = model.nodes[id.0].frame.x;
                let end = axis.point(1.0);
                let gap = (at - end).norm();
                if gap > 1e-8 * length || gap.is_nan() {
                    return Err(f.err(format!(
                        "node '{}' is at {}, not at the end point of the beam {} (distance {gap:.3e}, tolerance 1e-8 * length = {:.3e})",
                        model.nodes[id.0].name,
                        fmt_vec(&at),
                        fmt_vec(&end),
                        1e-8 * length
                    )));
                }
                Some(id)
            }
            None => None,
        };

        // Orientation of the sections.
        let of = t.req("orientation")?;
        let o = nonzero_vec3(&of)?.normalize();
        let (sine, s) = axis.most_parallel(&o);
        if sine < PARALLEL || sine.is_nan() {
            let p = axis.point(s);
            let at = if matches!(axis, Axis::Straight { .. }) {
                String::new()
            } else if s == 0.0 {
                " at the start point".to_string()
            } else if s == 1.0 {
                " at the end point".to_string()
            } else {
                format!(" at {}", fmt_vec(&p))
            };
            return Err(of.err(format!(
                "is parallel to the beam's axis{at}: it gives the direction of the section's z axis and must not be parallel to the axis anywhere"
            )));
        }

        let mut section = read_section(&t.req("section")?)?;
        read_damping(&t, &mut section)?;

        let element_sections = read_element_sections(&t, &section, n)?;

        let mass_kind = match t.opt_choice("mass_matrix", &["lumped", "consistent"])? {
            None => BeamMass::default(),
            Some("lumped") => BeamMass::Lumped,
            Some(_) => BeamMass::Consistent,
        };

        // Initial velocity: a rigid-body field v(p) = v_start + omega x (p - start).
        let kinematic = |key| {
            t.field(key)
                .map_or(Ok(Vec3::zeros()), |f| f.vec3_within(MAX_KINEMATIC))
        };
        let v_start = kinematic("velocity")?;
        let omega = kinematic("angular_velocity")?;
        if n == 1 && start_node.is_some() && end_node.is_some() {
            for key in ["velocity", "angular_velocity"] {
                if t.has(key) {
                    return Err(t.key_name_err(
                        key,
                        "this beam creates no node (one element between start_node and end_node): give the initial velocities on those nodes",
                    ));
                }
            }
        }

        // Nodes.
        let origin = Origin::of(&t);
        let frames: Vec<Mat3> = (0..=n)
            .map(|i| axis.section_frame(i as f64 / n as f64, &o))
            .collect();
        let mut ids: Vec<NodeId> = Vec::with_capacity(n + 1);
        for (i, frame) in frames.iter().enumerate() {
            let existing = match i {
                0 => start_node,
                i if i == n => end_node,
                _ => None,
            };
            if let Some(id) = existing {
                ids.push(id);
                continue;
            }
            let node_name = format!("{name}.{i}");
            if let Some(first) = node_names.get(&node_name) {
                return Err(t.key_err(
                    "name",
                    format!(
                        "the beam creates a node named '{node_name}', which is already used by {first}; rename the beam or the node"
                    ),
                ));
            }
            node_names.insert(node_name.clone(), t.path.clone());
            let p = axis.point(i as f64 / n as f64);
            let id = model.add_node(&node_name, Frame::new(p, *frame));
            origins.node_ids.insert(node_name.clone(), id);
            model.nodes[id.0].velocity = v_start + omega.cross(&(p - start));
            model.nodes[id.0].angular_velocity = frame.transpose() * omega;
            ids.push(id);
            let key = if t.has("arc") { "arc" } else { "end" };
            origins.nodes.push(
                origin
                    .clone()
                    .alias("position", key)
                    .prefixed(format!("node '{node_name}': ")),
            );
        }

        // Elements.
        let key = if t.has("arc") { "arc" } else { "end" };
        let first = model.beams.len();
        origins.beam_elements.insert(name.clone(), first..first + n);
        if let Some(radius) = super::display::read_radius(&t)? {
            model.display.tubes.push(crate::model::display::Tube {
                first,
                count: n,
                radius,
            });
        }
        for i in 0..n {
            let element = format!("{name}[{i}]");
            model.add_beam_with_mass(
                &element,
                [ids[i], ids[i + 1]],
                element_sections[i]
                    .clone()
                    .unwrap_or_else(|| section.clone()),
                [frames[i], frames[i + 1]],
                mass_kind,
            );
            origins.beams.push(
                origin
                    .clone()
                    .alias("group", "name")
                    .alias("length", key)
                    .alias(
                        "node_a",
                        if start_node.is_some() {
                            "start_node"
                        } else {
                            "start"
                        },
                    )
                    .alias("node_b", if end_node.is_some() { "end_node" } else { key })
                    .prefixed(if n > 1 {
                        format!("element '{element}': ")
                    } else {
                        String::new()
                    })
                    .unprefixed("group"),
            );
        }
    }
    Ok(())
}

fn read_arc(f: &Field<'_>, start: Vec3, n: usize) -> Result<Axis> {
    let t = f.table()?;
    t.check_keys(&["center", "axis", "angle_deg"])?;
    let cf = t.req("center")?;
    let center = point(&cf)?;
    let axis = nonzero_vec3(&t.req("axis")?)?.normalize();
    let af = t.req("angle_deg")?;
    let angle_deg = af.f64()?;
    if angle_deg == 0.0 || angle_deg.abs() > 360.0 {
        return Err(af.err(format!(
            "must be non-zero and at most 360 in magnitude, got {angle_deg}"
        )));
    }
    if angle_deg.abs() / n as f64 >= 180.0 {
        return Err(af.err(format!(
            "each element of an arc must span less than 180 degrees, but {angle_deg} degrees in {n} element{} is {} degrees per element: use more elements",
            if n == 1 { "" } else { "s" },
            angle_deg.abs() / n as f64
        )));
    }
    let radius = axis.cross(&(start - center)).norm();
    if !(radius > 1e-9 * (start - center).norm() && radius.is_finite()) {
        return Err(cf.err(format!(
            "the start point {} lies on the arc's axis through the center (radius {radius:.3e})",
            fmt_vec(&start)
        )));
    }
    Ok(Axis::Arc {
        start,
        center,
        axis,
        angle: angle_deg.to_radians(),
    })
}

/// The sections of the elements that the beam's `element.<k>` tables (`k` from 0, in the
/// order of the elements) change from the beam's `section` and `damping`: a sectional
/// property key (`EA`, ..., `rhoI3`) replaces that diagonal entry of `C` or `J` whatever the
/// form of the beam's section, `stiffness.<i>.<j>` and `rotary_inertia.<i>.<j>` (`i < j`) a
/// coupling (both symmetric entries), `damping.{mass, stiffness}` the Rayleigh
/// coefficients. The keys are the paths of the element's parameters after
/// `beam.<r>.element.<k>.` ([`SectionParam::key`], read and set by the registry's own
/// [`SectionParam::set`]), so that `--set` reaches every parameter of every element. `None`
/// for an element the beam's section describes.
fn read_element_sections(
    t: &Table<'_>,
    beam: &BeamSection,
    n: usize,
) -> Result<Vec<Option<BeamSection>>> {
    let mut out = vec![None; n];
    let Some(f) = t.field("element") else {
        return Ok(out);
    };
    let elements = f.table()?;
    let params = SectionParam::all();
    let paths: Vec<String> = params.iter().map(|p| p.key()).collect();
    for (key, _) in elements.map.iter() {
        let key: &str = key.get_ref();
        let k = match key.parse::<usize>() {
            Ok(k) if k < n && key == k.to_string() => k,
            _ => {
                return Err(elements.key_name_err(
                    key,
                    format!(
                        "must be an element number from 0 to {} (the beam has {n} element{})",
                        n - 1,
                        if n == 1 { "" } else { "s" }
                    ),
                ))
            }
        };
        let mut s = beam.clone();
        let mut leaves = Vec::new();
        parameter_fields(&elements.req(key)?.table()?, "", &paths, &mut leaves)?;
        for (path, f) in leaves {
            let p = params[paths
                .iter()
                .position(|q| *q == path)
                .expect("a parameter's path")];
            let v = match p {
                SectionParam::Stiffness(i, j) | SectionParam::RotaryInertia(i, j) if i != j => {
                    f.f64_in(-MAX_PHYSICAL, MAX_PHYSICAL)?
                }
                SectionParam::DampingMass | SectionParam::DampingStiffness => physical_or_zero(&f)?,
                _ => physical(&f)?,
            };
            p.set(&mut s, v);
        }
        out[k] = Some(s);
    }
    Ok(out)
}

/// The fields of `t` (at `prefix` in an element table) that are parameters of `paths`
/// (`section.EA`, `section.stiffness.0.4`, `damping.mass`, ...), with their paths; a key
/// on no such path is an error listing those that are.
fn parameter_fields<'a>(
    t: &Table<'a>,
    prefix: &str,
    paths: &[String],
    out: &mut Vec<(String, Field<'a>)>,
) -> Result<()> {
    let mut allowed: Vec<&str> = Vec::new();
    for segment in paths
        .iter()
        .filter_map(|p| p.strip_prefix(prefix))
        .filter_map(|rest| rest.split('.').next())
    {
        if !allowed.contains(&segment) {
            allowed.push(segment);
        }
    }
    t.check_keys(&allowed)?;
    for (key, _) in t.map.iter() {
        let path = format!("{prefix}{}", key.get_ref());
        if paths.contains(&path) {
            out.push((path, t.req(key.get_ref())?));
        } else {
            let inner = t.req(key.get_ref())?.table()?;
            parameter_fields(&inner, &format!("{path}."), paths, out)?;
        }
    }
    Ok(())
}

/// The Rayleigh coefficients `damping = { mass, stiffness }` of table `t` into `section`
/// (each key that is given).
fn read_damping(t: &Table<'_>, section: &mut BeamSection) -> Result<()> {
    let Some(f) = t.field("damping") else {
        return Ok(());
    };
    let d = f.table()?;
    d.check_keys(&["mass", "stiffness"])?;
    for (key, slot) in [
        ("mass", &mut section.damping_mass),
        ("stiffness", &mut section.damping_stiffness),
    ] {
        if let Some(v) = d.field(key) {
            *slot = physical_or_zero(&v)?;
        }
    }
    Ok(())
}

/// Keys of the three forms of `section`.
const SECTION_DIRECT: &[&str] = &[
    "EA", "GA2", "GA3", "GJ", "EI2", "EI3", "rhoA", "rhoJ", "rhoI2", "rhoI3",
];
const SECTION_MATERIAL: &[&str] = &["E", "G", "nu", "A", "I2", "I3", "J", "rho", "k2", "k3"];
const SECTION_MATRIX: &[&str] = &["stiffness", "mass_per_length", "rotary_inertia"];
const SECTION_FORMS: [(&str, &[&str]); 3] = [
    ("sectional properties", SECTION_DIRECT),
    ("material and geometry", SECTION_MATERIAL),
    ("matrix", SECTION_MATRIX),
];

fn read_section(f: &Field<'_>) -> Result<BeamSection> {
    let t = f.table()?;
    let all: Vec<&str> = SECTION_FORMS
        .iter()
        .flat_map(|(_, k)| k.iter().copied())
        .collect();
    let Some(first) = t.first_key_of(&all) else {
        t.check_keys(&all)?;
        return Err(f.err(
            "give the sectional properties { EA, GA2, GA3, GJ, EI2, EI3, rhoA, rhoJ, rhoI2, rhoI3 }, or material and geometry { E, G or nu, A, I2, I3, J, rho, k2, k3 }, or matrices { stiffness, mass_per_length, rotary_inertia }",
        ));
    };
    let (form, keys) = SECTION_FORMS
        .iter()
        .copied()
        .find(|(_, k)| k.contains(&first))
        .expect("first is a key of a form");
    let others: Vec<&str> = all.iter().copied().filter(|k| !keys.contains(k)).collect();
    if let Some(other) = t.first_key_of(&others) {
        let (other_form, _) = SECTION_FORMS
            .iter()
            .copied()
            .find(|(_, k)| k.contains(&other))
            .expect("other is a key of a form");
        return Err(t.key_name_err(
            other,
            format!(
                "belongs to the {other_form} form of a section, but '{first}' makes this the {form} form ({}); use one form",
                keys.join(", ")
            ),
        ));
    }
    t.check_keys(keys)?;
    let num = |k: &str| physical(&t.req(k)?);
    let section = match form {
        "sectional properties" => BeamSection::diagonal(
            [
                num("EA")?,
                num("GA2")?,
                num("GA3")?,
                num("GJ")?,
                num("EI2")?,
                num("EI3")?,
            ],
            num("rhoA")?,
            [num("rhoJ")?, num("rhoI2")?, num("rhoI3")?],
        ),
        "material and geometry" => {
            let e = num("E")?;
            let g = match (t.field("G"), t.field("nu")) {
                (Some(_), Some(_)) => {
                    return Err(t.key_name_err("nu", "give either G or nu, not both"))
                }
                (Some(g), None) => physical(&g)?,
                (None, Some(nf)) => {
                    let nu = nf.f64()?;
                    if !(nu > -1.0 && nu <= 0.5) {
                        return Err(nf.err(format!("must be in (-1, 0.5], got {nu}")));
                    }
                    e / (2.0 * (1.0 + nu))
                }
                (None, None) => {
                    return Err(t.key_err("G", "is required (or give Poisson's ratio nu)"))
                }
            };
            let (a, i2, i3, j, rho) = (num("A")?, num("I2")?, num("I3")?, num("J")?, num("rho")?);
            let k2 = t
                .field("k2")
                .map(|f| physical(&f))
                .transpose()?
                .unwrap_or(1.0);
            let k3 = t
                .field("k3")
                .map(|f| physical(&f))
                .transpose()?
                .unwrap_or(1.0);
            BeamSection::diagonal(
                [e * a, k2 * g * a, k3 * g * a, g * j, e * i2, e * i3],
                rho * a,
                [rho * (i2 + i3), rho * i2, rho * i3],
            )
        }
        _ => BeamSection {
            stiffness: read_stiffness(&t.req("stiffness")?)?,
            mass_per_length: num("mass_per_length")?,
            rotary_inertia: read_rotary_inertia(&t.req("rotary_inertia")?)?,
            damping_mass: 0.0,
            damping_stiffness: 0.0,
        },
    };
    // Entries of the matrices, and products of material and geometry, in range.
    let c = &section.stiffness;
    let j = &section.rotary_inertia;
    let entries = c.iter().chain(j.iter());
    if let Some(v) = entries
        .copied()
        .find(|v| !within(v.abs(), 0.0, MAX_PHYSICAL))
    {
        return Err(f.err(format!(
            "has a sectional value {v:e}: {}",
            out_of_range(v, -MAX_PHYSICAL, MAX_PHYSICAL)
        )));
    }
    let diagonal = (0..6)
        .map(|k| c[(k, k)])
        .chain((0..3).map(|k| j[(k, k)]))
        .chain([section.mass_per_length]);
    if let Some(v) = diagonal.into_iter().find(|v| *v < MIN_PHYSICAL) {
        return Err(f.err(format!(
            "has a sectional stiffness, mass or rotary inertia of {v:e}: {}",
            out_of_range(v, MIN_PHYSICAL, MAX_PHYSICAL)
        )));
    }
    Ok(section)
}

/// An `n` x `n` matrix by rows, checked symmetric; entries in row-major order.
fn symmetric_rows(f: &Field<'_>, n: usize) -> Result<Vec<f64>> {
    let what = format!("a {n}x{n} matrix given by {n} rows of {n} numbers");
    let rows = match f.value.get_ref() {
        DeValue::Array(a) if a.len() == n => a,
        v => return Err(f.err(format!("expected {what}, got {}", describe(v)))),
    };
    let mut m = Vec::with_capacity(n * n);
    for (i, row) in rows.iter().enumerate() {
        m.extend(
            f.elem(i, row)
                .numbers(n, &format!("a row of {n} numbers"))?,
        );
    }
    let scale = m.iter().fold(0.0f64, |a, c| a.max(c.abs()));
    for i in 0..n {
        for j in i + 1..n {
            let (a, b) = (m[i * n + j], m[j * n + i]);
            if (a - b).abs() > 1e-9 * scale {
                return Err(f.err(format!(
                    "must be symmetric, but row {} column {} is {a} and row {} column {} is {b}",
                    i + 1,
                    j + 1,
                    j + 1,
                    i + 1
                )));
            }
        }
    }
    Ok(m)
}

fn read_stiffness(f: &Field<'_>) -> Result<Mat6> {
    let m = symmetric_rows(f, 6)?;
    Ok(Mat6::from_row_slice(&m))
}

/// `[rhoJ, rhoI2, rhoI3]` or a full symmetric 3x3 matrix by rows.
fn read_rotary_inertia(f: &Field<'_>) -> Result<Mat3> {
    match f.value.get_ref() {
        DeValue::Array(a) if a.len() == 3 && a.iter().all(|v| v.get_ref().is_array()) => {
            Ok(Mat3::from_row_slice(&symmetric_rows(f, 3)?))
        }
        DeValue::Array(a) if a.len() == 3 => Ok(Mat3::from_diagonal(&f.vec3()?)),
        v => Err(f.err(format!(
            "expected [rhoJ, rhoI2, rhoI3] or a 3x3 matrix [[3], [3], [3]], got {}",
            describe(v)
        ))),
    }
}

/// The index in `Model::beams` of the element named by `f` (`"leg[3]"`): element `i` of the
/// beam of that name, found through `origins.beam_elements`.
pub(super) fn require_element(model: &Model, origins: &Origins, f: &Field<'_>) -> Result<usize> {
    let name = f.str()?;
    let element = name
        .strip_suffix(']')
        .and_then(|r| r.rsplit_once('['))
        .and_then(|(beam, i)| Some((origins.beam_elements.get(beam)?, i.parse::<usize>().ok()?)))
        .filter(|(range, i)| *i < range.len())
        .map(|(range, i)| range.start + i)
        .filter(|&k| model.beams.get(k).is_some_and(|b| b.name == name));
    if let Some(k) = element {
        return Ok(k);
    }
    let shown = clip(name, QUOTED);
    if let Some(range) = origins.beam_elements.get(name) {
        let of_beam = range.len();
        return Err(f.err(format!(
            "'{shown}' is a [[beam]] of {of_beam} element{}; name one of its elements, '{shown}[0]' to '{shown}[{}]'",
            if of_beam == 1 { "" } else { "s" },
            of_beam - 1
        )));
    }
    let names = || model.beams.iter().map(|b| b.name.as_str());
    Err(f.err(format!(
        "unknown beam element '{shown}'{} (beam elements: {})",
        suggestion(name, names()),
        name_list(names(), 12)
    )))
}
