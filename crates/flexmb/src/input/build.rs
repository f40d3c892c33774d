//! Interprets the (overridden) TOML tree: builds the [`Model`] with its public API, reads the
//! analysis settings, and maps [`Model::validate`] errors back to the file.

use super::error::InputError;
use super::fields::{
    item_named, nonzero_vec3, opt_point, physical, physical_or_zero, point, read_name,
    read_orientation, read_wheels, require_joint, require_node, resolve_node, teeth, to_node_frame,
    Origin, Origins, GROUND, SECTION_COMPONENTS,
};
use super::reader::{suggestion, Field, Result, Source, Table, Value, QUOTED};
use super::time_function::read_function;
use super::{Analysis, ModelFile};
use crate::error::ModelError;
use crate::model::limits::{within, MAX_ANGLE, MAX_KINEMATIC, MAX_PHYSICAL};
use crate::model::{
    box_inertia, clip, frame_from_axis, Bushing, BushingForm, ForceCurve, ForceLaw, Input,
    JointKind, Load, LoadFrame, Model, NodeId, Relaxation, Rope, RopePoint, RotationalSpring,
    Sensor, SensorFrame, SensorKind, SpringDamper, SpringLaw, SpringSide, TimeFunction,
};
use crate::solve::{DynamicSettings, NewtonSettings, StaticMethod, StaticSettings};
use flexmb_lie::{Frame, Group, Mat3, Mat6, Vec3};
use std::collections::HashMap;

const TOP_KEYS: &[&str] = &[
    "flexmb",
    "title",
    "description",
    "model",
    "solver",
    "node",
    "body",
    "joint",
    "load",
    "input",
    "spring",
    "rope",
    "contact",
    "beam",
    "sensor",
    "sensitivity",
    "design_parameter",
    "reference",
    "criterion",
    "gear",
    "rotational_spring",
    "bushing",
    "worm_gear",
    "block",
];
/// The keys of a `[[sensor]]`: `name`, `type`, then those a type may use.
const SENSOR_KEYS: &[&str] = &[
    "name",
    "type",
    "node",
    "point",
    "component",
    "frame",
    "joint",
    "beam",
    "spring",
    "rope",
    "contact",
    "gear",
    "bushing",
    "block",
];
const NODE_STATE_KEYS: &[&str] = &[
    "position",
    "orientation",
    "velocity",
    "angular_velocity",
    "angular_velocity_body",
];
pub(crate) fn build(src: &Source<'_>, root: &Value<'_>) -> Result<ModelFile> {
    let top = Field {
        src,
        value: root,
        path: String::new(),
        item: None,
    }
    .table()?;
    // The version first: a file of another version may well have other keys.
    let version = top.req("flexmb")?;
    match version.int()? {
        1 => {}
        v => {
            return Err(version.err(format!(
                "unsupported format version {v}; this flexmb reads version 1"
            )))
        }
    }
    top.check_keys(TOP_KEYS)?;
    let title = top.opt_str("title")?.unwrap_or_default().to_string();
    let description = top.opt_str("description")?.unwrap_or_default().to_string();

    let mt = top.req("model")?.table()?;
    mt.check_keys(&["group", "gravity"])?;
    let group = match mt.req("group")?.choice(&["SE3", "R3xSO3"])? {
        "SE3" => Group::SE3,
        _ => Group::R3xSO3,
    };
    let mut model = Model::new(group);
    model.title = title;
    model.gravity = match mt.field("gravity") {
        Some(f) => f.vec3_within(MAX_KINEMATIC)?,
        None => Vec3::zeros(),
    };

    let analysis = read_solver(&top.req("solver")?.table()?)?;

    let mut origins = Origins {
        model: Some(Origin::of(&mt)),
        ..Origins::default()
    };
    // Beams are meshed after the nodes of [[node]] and [[body]] exist (a beam may start at
    // them) and before the bodies are attached (a body may sit on a beam node).
    read_nodes_and_bodies(
        &top,
        &mut model,
        &mut origins,
        |model, origins, node_names| super::beam::read_beams(&top, model, origins, node_names),
    )?;
    read_joints(&top, &mut model, &mut origins)?;
    read_loads(&top, &mut model, &mut origins)?;
    read_inputs(&top, &mut model, &mut origins)?;
    read_springs(&top, &mut model, &mut origins)?;
    read_ropes(&top, &mut model, &mut origins)?;
    super::contact::read_contacts(&top, &mut model, &mut origins)?;
    read_gears(&top, &mut model, &mut origins)?;
    super::worm_gear::read_worm_gears(&top, &mut model, &mut origins)?;
    read_rotational_springs(&top, &mut model, &mut origins)?;
    read_bushings(&top, &mut model, &mut origins)?;
    super::control::read_blocks(&top, &mut model, &mut origins)?;
    read_sensors(&top, &mut model, &mut origins)?;

    model
        .validate()
        .map_err(|e| map_model_error(src, e, &origins))?;
    if let Some((block, message)) = crate::solve::initial::unsolvable_loop(&model) {
        let e = ModelError::Invalid {
            item: crate::model::ItemRef {
                table: "block",
                index: block,
                name: model.control.blocks[block].name.clone(),
                field: "inputs",
            },
            message,
        };
        return Err(map_model_error(src, e, &origins));
    }
    let sensitivity = super::sensitivity::read_sensitivity(&top, &model, &analysis, src.file)?;
    Ok(ModelFile {
        model,
        analysis,
        description,
        sensitivity,
    })
}

fn map_model_error(src: &Source<'_>, e: ModelError, origins: &Origins) -> InputError {
    let item = e.item().clone();
    let message = match e {
        ModelError::Invalid { message, .. } => message,
    };
    let model_origin = origins.model.as_slice();
    let list = match item.table {
        "model" => model_origin,
        "node" => &origins.nodes,
        "body" => &origins.bodies,
        "joint" => &origins.joints,
        "load" => &origins.loads,
        "spring" => &origins.springs,
        "rope" => &origins.ropes,
        "contact" => &origins.contacts,
        "rotational_spring" => &origins.rotational_springs,
        "bushing" => &origins.bushings,
        "beam" => &origins.beams,
        "sensor" => &origins.sensors,
        "gear" => &origins.gears,
        "worm_gear" => &origins.worm_gears,
        "block" => &origins.blocks,
        _ => &[],
    };
    match list.get(item.index) {
        Some(o) => {
            let key = o
                .aliases
                .iter()
                .find(|(f, _)| *f == item.field)
                .map_or(item.field, |(_, k)| *k);
            let span = o
                .fields
                .iter()
                .find(|(k, _)| k == key)
                .map_or(o.span.clone(), |(_, s)| s.clone());
            src.field_error(
                &span,
                &format!("{}.{key}", o.path),
                o.item.as_ref(),
                if o.unprefixed.contains(&item.field) {
                    message
                } else {
                    format!("{}{message}", o.prefix)
                },
            )
        }
        None => src.field_error(
            &(0..0),
            &format!("{}[{}].{}", item.table, item.index, item.field),
            None,
            message,
        ),
    }
}

/// The key among `keys` (in order of preference) to blame for a value derived from them: the
/// first one a `--set` gave, else the first one in the file, else the first.
fn blame<'k>(t: &Table<'_>, keys: &[&'k str]) -> &'k str {
    keys.iter()
        .find(|k| t.has(k) && t.src.set_by(&t.child_path(k)).is_some())
        .or_else(|| keys.iter().find(|k| t.has(k)))
        .unwrap_or(&keys[0])
}

/// Keys of `[solver]` common to both analyses (the Newton settings and the threads).
const SOLVER_SHARED_KEYS: &[&str] = &["analysis", "rtol", "atol", "max_iterations", "threads"];
/// Keys of `[solver]` that only a dynamic analysis has.
const SOLVER_DYNAMIC_KEYS: &[&str] = &[
    "t_end",
    "h",
    "rho_inf",
    "output_interval",
    "h_min",
    "reuse_jacobian",
    "max_contraction",
    "max_jacobian_age",
    "formulation",
    "scheme",
    "hht_alpha",
    "newmark_beta",
    "newmark_gamma",
    "lie_update",
    "lie_update_sigma",
    "predictor",
];
/// Keys of `[solver]` that only a static analysis has.
const SOLVER_STATIC_KEYS: &[&str] = &[
    "load_factor",
    "increment",
    "min_increment",
    "max_increment",
    "method",
    "arc_length",
    "max_steps",
    "target_iterations",
    "adaptive",
    "pseudo_time",
    "pseudo_damping",
];

fn read_solver(t: &Table<'_>) -> Result<Analysis> {
    let all: Vec<&str> = [SOLVER_SHARED_KEYS, SOLVER_DYNAMIC_KEYS, SOLVER_STATIC_KEYS].concat();
    t.check_keys(&all)?;
    let kind = t.req("analysis")?.choice(&["dynamic", "static"])?;
    let (other, other_keys) = match kind {
        "dynamic" => ("static", SOLVER_STATIC_KEYS),
        _ => ("dynamic", SOLVER_DYNAMIC_KEYS),
    };
    if let Some(key) = t.first_key_of(other_keys) {
        return Err(t.key_name_err(
            key,
            format!("is a setting of the {other} analysis, not allowed with analysis = \"{kind}\""),
        ));
    }
    let (newton, analysis) = if kind == "dynamic" {
        let s = read_dynamic(t)?;
        (s.newton, Analysis::Dynamic(s))
    } else {
        let s = read_static(t)?;
        (s.newton, Analysis::Static(s))
    };
    let newton = read_newton(t, newton)?;
    let threads = match t.field("threads") {
        Some(f) => {
            let n = f.int()?;
            let n = usize::try_from(n).map_err(|_| {
                f.err(format!(
                    "must be 0 (all cores) or a number of threads, got {n}"
                ))
            })?;
            Some(n)
        }
        None => None,
    };
    let analysis = match analysis {
        Analysis::Dynamic(mut s) => {
            s.newton = newton;
            s.threads = threads.unwrap_or(s.threads);
            Analysis::Dynamic(s)
        }
        Analysis::Static(mut s) => {
            s.newton = newton;
            s.threads = threads.unwrap_or(s.threads);
            Analysis::Static(s)
        }
    };
    // The ranges are the solver's own rules, reported here at the key they are about.
    let checked = match &analysis {
        Analysis::Dynamic(s) => s.check(),
        Analysis::Static(s) => s.check(),
    };
    checked.map_err(|e| t.key_err(blame(t, &e.keys), e.message))?;
    Ok(analysis)
}

/// The Newton keys shared by both analyses, over the analysis' defaults (their ranges are
/// checked by the solver's settings, see [`read_solver`]).
fn read_newton(t: &Table<'_>, mut n: NewtonSettings) -> Result<NewtonSettings> {
    if let Some(f) = t.field("rtol") {
        n.rtol = f.f64()?;
    }
    if let Some(f) = t.field("atol") {
        n.atol = f.f64()?;
    }
    if let Some(f) = t.field("max_iterations") {
        n.max_iterations = count(&f)?;
    }
    Ok(n)
}

/// A non-negative integer (its range is checked by the solver's settings).
fn count(f: &Field<'_>) -> Result<usize> {
    let n = f.int()?;
    usize::try_from(n).map_err(|_| f.err(format!("must be a positive integer, got {n}")))
}

fn read_static(t: &Table<'_>) -> Result<StaticSettings> {
    let mut s = StaticSettings::new();
    if let Some(f) = t.field("load_factor") {
        s.load_factor = f.f64()?;
    }
    // Increments are steps in the load factor, which plays the role of time.
    if let Some(f) = t.field("increment") {
        s.initial_increment = f.f64()?;
    }
    if let Some(f) = t.field("min_increment") {
        s.min_increment = f.f64()?;
    }
    if let Some(f) = t.field("max_increment") {
        s.max_increment = f.f64()?;
    }
    if let Some(m) = t.opt_choice("method", &["load_control", "arc_length", "pseudo_dynamic"])? {
        s.method = match m {
            "arc_length" => StaticMethod::ArcLength,
            "pseudo_dynamic" => StaticMethod::PseudoDynamic,
            _ => StaticMethod::LoadControl,
        };
    }
    for key in ["pseudo_time", "pseudo_damping"] {
        if let Some(f) = t.field(key) {
            if s.method != StaticMethod::PseudoDynamic {
                return Err(t.key_name_err(key, "only allowed with method = \"pseudo_dynamic\""));
            }
            if key == "pseudo_time" {
                s.pseudo_time = f.f64()?;
            } else {
                s.pseudo_damping = f.f64()?;
            }
        }
    }
    if let Some(f) = t.field("arc_length") {
        if s.method != StaticMethod::ArcLength {
            return Err(t.key_name_err("arc_length", "only allowed with method = \"arc_length\""));
        }
        s.arc_length = f.f64()?;
    }
    if let Some(f) = t.field("max_steps") {
        s.max_steps = count(&f)?;
    }
    if let Some(f) = t.field("adaptive") {
        s.adaptive = f.bool()?;
    }
    if let Some(f) = t.field("target_iterations") {
        s.target_iterations = count(&f)?;
    }
    Ok(s)
}

fn read_dynamic(t: &Table<'_>) -> Result<DynamicSettings> {
    let t_end = t.req("t_end")?.f64()?;
    let h = t.req("h")?.f64()?;
    let mut s = DynamicSettings::new(t_end, h);
    if let Some(f) = t.field("rho_inf") {
        s.rho_inf = f.f64()?;
    }
    if let Some(f) = t.field("output_interval") {
        s.output_interval = f.f64()?;
    }
    if let Some(f) = t.field("h_min") {
        s.h_min = f.f64()?;
    }
    if let Some(f) = t.field("formulation") {
        s.formulation = match f.choice(&["auto", "index3", "index2"])? {
            "index3" => crate::solve::Formulation::Index3,
            "index2" => crate::solve::Formulation::StabilizedIndex2,
            _ => crate::solve::Formulation::Auto,
        };
    }
    let lie_update = t
        .field("lie_update")
        .map(|f| {
            f.choice(&[
                "bruls_cardona",
                "commutator",
                "lie_algebra",
                "lie_algebra_r3xso3",
            ])
        })
        .transpose()?;
    if t.has("lie_update_sigma") && lie_update != Some("commutator") {
        return Err(t.key_err(
            "lie_update_sigma",
            "only allowed with lie_update = \"commutator\"".to_string(),
        ));
    }
    use crate::solve::LieUpdate;
    s.lie_update = match lie_update {
        Some("commutator") => LieUpdate::Commutator {
            sigma: match t.field("lie_update_sigma") {
                Some(f) => f.f64()?,
                None => 1.0 / 12.0,
            },
        },
        Some("lie_algebra") => LieUpdate::LieAlgebra,
        Some("lie_algebra_r3xso3") => LieUpdate::LieAlgebraR3xSO3,
        _ => LieUpdate::BrulsCardona,
    };
    if let Some(f) = t.field("predictor") {
        s.adaptive_predictor = f.choice(&["linear", "adaptive"])? == "adaptive";
    }
    let scheme = t
        .field("scheme")
        .map(|f| f.choice(&["generalized_alpha", "hht", "newmark"]))
        .transpose()?;
    let only_for = |key: &str, which: &str| -> Result<()> {
        if t.has(key) && scheme != Some(which) {
            return Err(t.key_err(key, format!("only allowed with scheme = \"{which}\"")));
        }
        Ok(())
    };
    only_for("hht_alpha", "hht")?;
    only_for("newmark_beta", "newmark")?;
    only_for("newmark_gamma", "newmark")?;
    match scheme {
        Some("hht") => {
            let alpha = t.req("hht_alpha")?.f64()?;
            s.scheme = crate::solve::Scheme::Hht { alpha };
        }
        Some("newmark") => {
            let value = |key: &str, default: f64| t.field(key).map_or(Ok(default), |f| f.f64());
            s.scheme = crate::solve::Scheme::Newmark {
                beta: value("newmark_beta", 0.25)?,
                gamma: value("newmark_gamma", 0.5)?,
            };
        }
        _ => {}
    }
    if let Some(f) = t.field("reuse_jacobian") {
        s.newton.reuse_jacobian = f.bool()?;
    }
    if let Some(f) = t.field("max_contraction") {
        s.newton.max_contraction = f.f64()?;
    }
    if let Some(f) = t.field("max_jacobian_age") {
        s.newton.max_jacobian_age = count(&f)?;
    }
    Ok(s)
}

/// Initial state of a node read from the node keys of a [[node]] or a [[body]].
struct NodeInit {
    frame: Frame,
    velocity: Vec3,
    angular_velocity: Vec3,
}

fn read_node_init(t: &Table<'_>) -> Result<NodeInit> {
    let position = opt_point(t, "position")?.unwrap_or_else(Vec3::zeros);
    let r = match t.field("orientation") {
        Some(f) => read_orientation(&f)?,
        None => Mat3::identity(),
    };
    let velocity = opt_point(t, "velocity")?.unwrap_or_else(Vec3::zeros);
    let inertial = opt_point(t, "angular_velocity")?;
    let body = opt_point(t, "angular_velocity_body")?;
    let angular_velocity =
        match (inertial, body) {
            (Some(_), Some(_)) => return Err(t.key_err(
                "angular_velocity_body",
                "give either angular_velocity (inertial frame) or angular_velocity_body, not both",
            )),
            (Some(w), None) => r.transpose() * w,
            (None, Some(w)) => w,
            (None, None) => Vec3::zeros(),
        };
    Ok(NodeInit {
        frame: Frame::new(position, r),
        velocity,
        angular_velocity,
    })
}

fn add_node(model: &mut Model, origins: &mut Origins, name: &str, init: NodeInit) -> NodeId {
    let id = model.add_node(name, init.frame);
    origins.node_ids.insert(name.to_string(), id);
    model.nodes[id.0].velocity = init.velocity;
    model.nodes[id.0].angular_velocity = init.angular_velocity;
    id
}

fn read_inertia(f: &Field<'_>, mass: f64) -> Result<Mat3> {
    let what = "[Ixx, Iyy, Izz], a full matrix [[3], [3], [3]] or { box = [a, b, c] }";
    let inertia = match f.value.get_ref() {
        toml::de::DeValue::Table(_) => {
            let t = f.table()?;
            t.check_keys(&["box"])?;
            let b = t.req("box")?;
            let sides = b.vec3_within(MAX_KINEMATIC)?;
            if sides.iter().any(|&s| s < 0.0) {
                return Err(b.err("side lengths must be >= 0"));
            }
            box_inertia(mass, &sides)
        }
        toml::de::DeValue::Array(a) if a.len() == 3 && a.iter().all(|v| v.get_ref().is_array()) => {
            let m = f.mat3_rows()?;
            for (i, j) in [(0, 1), (0, 2), (1, 2)] {
                if (m[(i, j)] - m[(j, i)]).abs() > 1e-9 * m.abs().max() {
                    return Err(f.err(format!(
                        "must be symmetric, but row {} column {} is {} and row {} column {} is {}",
                        i + 1,
                        j + 1,
                        m[(i, j)],
                        j + 1,
                        i + 1,
                        m[(j, i)]
                    )));
                }
            }
            m
        }
        toml::de::DeValue::Array(a) if a.len() == 3 => Mat3::from_diagonal(&f.vec3()?),
        _ => {
            return Err(f.err(format!(
                "expected {what}, got {}",
                super::reader::describe(f.value.get_ref())
            )))
        }
    };
    if let Some(c) = inertia.iter().find(|c| !within(c.abs(), 0.0, MAX_PHYSICAL)) {
        return Err(f.err(format!(
            "has a value {c:e} beyond {MAX_PHYSICAL:e} (see 'Ranges' in docs/model-format.md)"
        )));
    }
    Ok(inertia)
}

/// Reads the [[node]] items, creates the nodes of the [[body]] items that bring their own,
/// calls `between` with the node names (and the path of the item that created each node),
/// then adds the bodies.
fn read_nodes_and_bodies(
    top: &Table<'_>,
    model: &mut Model,
    origins: &mut Origins,
    between: impl FnOnce(&mut Model, &mut Origins, &mut HashMap<String, String>) -> Result<()>,
) -> Result<()> {
    let mut node_names = HashMap::new();
    for t in top.items("node")? {
        let mut keys = vec!["name", "display"];
        keys.extend_from_slice(NODE_STATE_KEYS);
        t.check_keys(&keys)?;
        let name = read_name(&t, &mut node_names, "node")?;
        if name == GROUND {
            return Err(t.key_err("name", "'ground' is reserved for the fixed inertial frame"));
        }
        let init = read_node_init(&t)?;
        let node = add_node(model, origins, &name, init);
        super::display::read_shapes(&t, node, &mut model.display.shapes)?;
        origins.nodes.push(Origin::of(&t));
    }

    let bodies = top.items("body")?;
    let mut body_names = HashMap::new();
    let mut body_keys = vec!["name", "node", "mass", "com", "inertia", "display"];
    body_keys.extend_from_slice(NODE_STATE_KEYS);
    // Pass 1: names, and the nodes of the bodies that bring their own.
    let mut own_nodes = Vec::with_capacity(bodies.len());
    for t in &bodies {
        t.check_keys(&body_keys)?;
        let name = read_name(t, &mut body_names, "body")?;
        match t.field("node") {
            Some(f) => {
                f.str()?;
                for k in NODE_STATE_KEYS {
                    t.forbid(k, "when 'node' is given (set it on the [[node]])")?;
                }
            }
            None => {
                if name == GROUND {
                    return Err(t.key_err(
                        "name",
                        "'ground' is reserved for the fixed inertial frame (the body would create a node of that name)",
                    ));
                }
                if let Some(first) = node_names.get(&name) {
                    return Err(t.key_err(
                        "name",
                        format!(
                            "the body creates a node named '{name}', which is already used by {first}; attach the body with node = \"{name}\" or rename it"
                        ),
                    ));
                }
                node_names.insert(name.clone(), t.path.clone());
                let init = read_node_init(t)?;
                own_nodes.push(Some(add_node(model, origins, &name, init)));
                origins.nodes.push(Origin::of(t));
                continue;
            }
        }
        own_nodes.push(None);
    }
    between(model, origins, &mut node_names)?;
    // Pass 2: the bodies, on any node.
    for (t, own) in bodies.iter().zip(own_nodes) {
        let name = t.req("name")?.str()?;
        let node = match own {
            Some(id) => id,
            None => require_node(model, origins, &t.req("node")?)?,
        };
        let mass = physical(&t.req("mass")?)?;
        let com = opt_point(t, "com")?.unwrap_or_else(Vec3::zeros);
        let inertia = read_inertia(&t.req("inertia")?, mass)?;
        model.add_body(name, node, mass, com, inertia);
        super::display::read_shapes(t, node, &mut model.display.shapes)?;
        origins.bodies.push(Origin::of(t));
    }
    Ok(())
}

fn read_joints(top: &Table<'_>, model: &mut Model, origins: &mut Origins) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("joint")? {
        if t.has("type") && t.req("type")?.str()? == "gear" {
            read_gear_joint(&t, &mut names, model, origins)?;
            continue;
        }
        t.check_keys(&[
            "name",
            "type",
            "node_a",
            "node_b",
            "position",
            "axis",
            "axis_b",
            "reference",
            "drive",
        ])?;
        let name = read_name(&t, &mut names, "joint")?;
        let kind = match t.req("type")?.choice(&[
            "fixed",
            "spherical",
            "revolute",
            "prismatic",
            "cylindrical",
            "universal",
            "planar",
            "gear",
        ])? {
            "fixed" => JointKind::Fixed,
            "spherical" => JointKind::Spherical,
            "revolute" => JointKind::Revolute,
            "prismatic" => JointKind::Prismatic,
            "cylindrical" => JointKind::Cylindrical,
            "universal" => JointKind::Universal,
            _ => JointKind::Planar,
        };
        let node_a = match t.field("node_a") {
            Some(f) => resolve_node(model, origins, &f, true)?,
            None => None,
        };
        let node_b = resolve_node(model, origins, &t.req("node_b")?, true)?;
        let position = point(&t.req("position")?)?;
        let (orientation, orientation_b) =
            if matches!(kind, JointKind::Fixed | JointKind::Spherical) {
                let why = format!("for a {} joint", kind.name());
                for k in ["axis", "axis_b", "reference"] {
                    t.forbid(k, &why)?;
                }
                (Mat3::identity(), None)
            } else {
                let af = t.req("axis")?;
                let axis = nonzero_vec3(&af)?;
                let reference = match t.field("reference") {
                    Some(f) => {
                        let r = nonzero_vec3(&f)?;
                        if r.normalize().cross(&axis.normalize()).norm() < 1e-6 {
                            return Err(f.err("must not be parallel to axis"));
                        }
                        Some(r)
                    }
                    None => None,
                };
                let orientation = frame_from_axis(&axis, reference.as_ref());
                let orientation_b = if kind == JointKind::Universal {
                    let bf = t.req("axis_b")?;
                    let axis_b = nonzero_vec3(&bf)?;
                    let cos = axis.normalize().dot(&axis_b.normalize());
                    if cos.abs() > 1e-6 {
                        return Err(bf.err(format!(
                            "must be perpendicular to axis (angle between them {:.4} deg)",
                            cos.clamp(-1.0, 1.0).acos().to_degrees()
                        )));
                    }
                    Some(frame_from_axis(&axis_b, Some(&axis)))
                } else {
                    t.forbid("axis_b", "except for a universal joint")?;
                    None
                };
                (orientation, orientation_b)
            };
        let drive = t.field("drive").map(|f| read_function(&f)).transpose()?;
        let id = model.add_joint(
            &name,
            kind,
            node_a,
            node_b,
            position,
            orientation,
            orientation_b,
        );
        model.joints[id.0].drive = drive;
        origins.joint_ids.insert(name.clone(), id);
        origins.joints.push(Origin::of(&t));
    }
    Ok(())
}

fn read_loads(top: &Table<'_>, model: &mut Model, origins: &mut Origins) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("load")? {
        t.check_keys(&[
            "name",
            "node",
            "beam",
            "force",
            "torque",
            "force_per_length",
            "torque_per_length",
            "frame",
            "function",
        ])?;
        let name = read_name(&t, &mut names, "load")?;
        let (frame, function) = frame_and_function(&t, 1.0)?;
        if let Some(beam) = t.field("beam") {
            // A load distributed along every element of a [[beam]], lumped to its nodes.
            t.forbid(
                "node",
                "with `beam`: a load acts on a `node` or along a `beam`, not both",
            )?;
            t.forbid(
                "force",
                "with `beam`: a distributed load takes `force_per_length`",
            )?;
            t.forbid(
                "torque",
                "with `beam`: a distributed load takes `torque_per_length`",
            )?;
            let beam_name = beam.str()?;
            let Some(range) = origins.beam_elements.get(beam_name) else {
                let names = || origins.beam_elements.keys().map(String::as_str);
                return Err(beam.err(format!(
                    "no [[beam]] named '{}'{}",
                    clip(beam_name, QUOTED),
                    suggestion(beam_name, names())
                )));
            };
            let elements: Vec<usize> = range.clone().collect();
            let f = opt_load(&t, "force_per_length")?;
            let m = opt_load(&t, "torque_per_length")?;
            let added = model.add_beam_load(&name, &elements, f, m, frame, function);
            for _ in 0..added {
                origins.loads.push(Origin::of(&t));
            }
            continue;
        }
        t.forbid(
            "force_per_length",
            "without `beam`: only a distributed load takes it",
        )?;
        t.forbid(
            "torque_per_length",
            "without `beam`: only a distributed load takes it",
        )?;
        let node = require_node(model, origins, &t.req("node")?)?;
        let force = opt_load(&t, "force")?;
        let torque = opt_load(&t, "torque")?;
        model.loads.push(Load {
            name,
            node,
            force,
            torque,
            frame,
            function,
            input: None,
        });
        origins.loads.push(Origin::of(&t));
    }
    Ok(())
}

/// `[[input]]`: an input `u_k` of the model, an actuator force and torque at a node per
/// unit of `u` ([`crate::model::Input`]), the load it scales read like a `[[load]]`'s on a
/// node; `function` gives `u(t)` in a run (0 without it).
fn read_inputs(top: &Table<'_>, model: &mut Model, origins: &mut Origins) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("input")? {
        t.check_keys(&["name", "node", "force", "torque", "frame", "function"])?;
        let name = read_name(&t, &mut names, "input")?;
        if let Some(load) = model.loads.iter().find(|l| l.name == name) {
            return Err(t.req("name")?.err(format!(
                "'{}' names a [[load]] too: an input's name must be its own",
                clip(&load.name, QUOTED)
            )));
        }
        let (frame, function) = frame_and_function(&t, 0.0)?;
        let node = require_node(model, origins, &t.req("node")?)?;
        let (force, torque) = (opt_load(&t, "force")?, opt_load(&t, "torque")?);
        if force == Vec3::zeros() && torque == Vec3::zeros() {
            return Err(t.key_err(
                "force",
                "an input needs a `force` or a `torque` (per unit of the input): with neither it acts on nothing",
            ));
        }
        model.inputs.push(Input {
            name: name.clone(),
            load: model.loads.len(),
        });
        model.loads.push(Load {
            name,
            node,
            force,
            torque,
            frame,
            function,
            input: Some(model.inputs.len() - 1),
        });
        origins.loads.push(Origin::of(&t));
    }
    Ok(())
}

/// The `frame` (default inertial) and `function` (default the constant `default`) of a
/// `[[load]]` or an `[[input]]`.
fn frame_and_function(t: &Table<'_>, default: f64) -> Result<(LoadFrame, TimeFunction)> {
    let frame = match t.opt_choice("frame", &["inertial", "body"])? {
        Some("body") => LoadFrame::Body,
        _ => LoadFrame::Inertial,
    };
    let function = match t.field("function") {
        Some(f) => read_function(&f)?,
        None => TimeFunction::Constant { value: default },
    };
    Ok((frame, function))
}

/// A force or torque (also per length), zero when absent.
fn opt_load(t: &Table<'_>, key: &str) -> Result<Vec3> {
    t.field(key)
        .map_or(Ok(Vec3::zeros()), |f| f.vec3_within(MAX_PHYSICAL))
}

fn read_springs(top: &Table<'_>, model: &mut Model, origins: &mut Origins) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("spring")? {
        t.check_keys(&[
            "name",
            "node_a",
            "node_b",
            "point_a",
            "point_b",
            "stiffness",
            "damping",
            "rest_length",
            "relaxation_stiffness",
            "relaxation_damping",
            "preload",
            "acts",
            "force_table",
            "polynomial",
            "compression",
            "extension",
        ])?;
        let name = read_name(&t, &mut names, "spring")?;
        let node_a = match t.field("node_a") {
            Some(f) => resolve_node(model, origins, &f, true)?,
            None => None,
        };
        let node_b = resolve_node(model, origins, &t.req("node_b")?, true)?;
        let pa = point(&t.req("point_a")?)?;
        let pb = point(&t.req("point_b")?)?;
        let law = read_force_law(&t)?;
        // a nonlinear law may stand without a linear part
        let stiffness = stiffness_or_curve(&t, law.as_ref())?;
        let damping = match t.field("damping") {
            Some(f) => physical_or_zero(&f)?,
            None => 0.0,
        };
        let rest_length = match t.field("rest_length") {
            Some(f) => {
                let v = f.f64()?;
                if v < 0.0 {
                    return Err(f.err(format!("must be >= 0, got {v}")));
                }
                f.f64_in(0.0, MAX_KINEMATIC)?
            }
            None => (pa - pb).norm(),
        };
        let relaxation = match (
            t.field("relaxation_stiffness"),
            t.field("relaxation_damping"),
        ) {
            (None, None) => None,
            (Some(k), Some(c)) => Some(Relaxation {
                stiffness: physical(&k)?,
                damping: physical(&c)?,
            }),
            (Some(f), None) | (None, Some(f)) => {
                let message =
                    "a Maxwell branch needs both relaxation_stiffness and relaxation_damping";
                return Err(f.err(message.to_string()));
            }
        };
        model.springs.push(SpringDamper {
            name,
            node_a,
            node_b,
            point_a: to_node_frame(model, node_a, &pa),
            point_b: to_node_frame(model, node_b, &pb),
            stiffness,
            damping,
            rest_length,
            relaxation,
        });
        let spring = model.springs.len() - 1;
        model
            .spring_laws
            .extend(law.map(|law| SpringLaw { spring, law }));
        origins.springs.push(Origin::of(&t));
    }
    Ok(())
}

/// The keys of a nonlinear force law ([`read_force_law`]).
const LAW_KEYS: [&str; 6] = [
    "preload",
    "acts",
    "force_table",
    "polynomial",
    "compression",
    "extension",
];

/// The nonlinear force law of a `[[spring]]` or `[[rotational_spring]]`, if it has any of
/// [`LAW_KEYS`].
fn read_force_law(t: &Table<'_>) -> Result<Option<ForceLaw>> {
    if !LAW_KEYS.iter().any(|k| t.has(k)) {
        return Ok(None);
    }
    let mut law = ForceLaw::default();
    if let Some(f) = t.field("preload") {
        law.preload = f.f64_in(-MAX_PHYSICAL, MAX_PHYSICAL)?;
    }
    if let Some(f) = t.field("acts") {
        law.acts = match f.choice(&["both", "compression", "extension"])? {
            "compression" => SpringSide::Compression,
            "extension" => SpringSide::Extension,
            _ => SpringSide::Both,
        };
    }
    law.curve = read_force_curve(t)?;
    for (key, side) in [
        ("compression", &mut law.compression),
        ("extension", &mut law.extension),
    ] {
        if let Some(f) = t.field(key) {
            let sub = f.table()?;
            sub.check_keys(&["force_table", "polynomial"])?;
            *side = read_force_curve(&sub)?;
            if side.is_none() {
                return Err(f.err("give the side's curve: force_table = [[e, F], ...] or polynomial = [a1, a2, ...]"));
            }
        }
    }
    Ok(Some(law))
}

/// `stiffness`: required, or 0 when absent from a table with a force curve (`law`).
fn stiffness_or_curve(t: &Table<'_>, law: Option<&ForceLaw>) -> Result<f64> {
    match (t.field("stiffness"), law) {
        (Some(f), _) => physical_or_zero(&f),
        (None, Some(law)) if law.has_curve() => Ok(0.0),
        (None, _) => physical_or_zero(&t.req("stiffness")?),
    }
}

/// A 6 x 6 matrix: `[k1, ..., k6]` (diagonal) or six rows of six numbers. Symmetry and
/// definiteness are checked by `Model::validate`.
fn read_matrix6(f: &Field<'_>) -> Result<Mat6> {
    let rows = f.array()?;
    if rows.len() == 6 && rows.iter().all(|v| !v.get_ref().is_array()) {
        let d = f.numbers(6, "6 numbers (the diagonal) or 6 rows of 6 numbers")?;
        return Ok(Mat6::from_diagonal(&flexmb_lie::Vec6::from_column_slice(
            &d,
        )));
    }
    if rows.len() != 6 {
        return Err(f.err(format!(
            "expected 6 numbers (the diagonal) or 6 rows of 6 numbers, got an array of {}",
            rows.len()
        )));
    }
    let mut m = Mat6::zeros();
    for (i, v) in rows.iter().enumerate() {
        let row = f.elem(i, v).numbers(6, "a row of 6 numbers")?;
        for (j, x) in row.into_iter().enumerate() {
            m[(i, j)] = x;
        }
    }
    Ok(m)
}

fn read_bushings(top: &Table<'_>, model: &mut Model, origins: &mut Origins) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("bushing")? {
        t.check_keys(&[
            "name",
            "node_a",
            "node_b",
            "position",
            "orientation",
            "stiffness",
            "damping",
            "form",
        ])?;
        let name = read_name(&t, &mut names, "bushing")?;
        let node_a = match t.field("node_a") {
            Some(f) => resolve_node(model, origins, &f, true)?,
            None => None,
        };
        let node_b = resolve_node(model, origins, &t.req("node_b")?, true)?;
        let position = match opt_point(&t, "position")? {
            Some(p) => p,
            None => node_b
                .or(node_a)
                .map_or(Vec3::zeros(), |n| model.nodes[n.0].frame.x),
        };
        let orientation = match t.field("orientation") {
            Some(f) => read_orientation(&f)?,
            None => Mat3::identity(),
        };
        let stiffness = read_matrix6(&t.req("stiffness")?)?;
        let damping = match t.field("damping") {
            Some(f) => read_matrix6(&f)?,
            None => Mat6::zeros(),
        };
        let at = Frame::new(position, orientation);
        let local = |n: Option<NodeId>| match n {
            Some(id) => model.nodes[id.0].frame.inverse().compose(&at),
            None => at,
        };
        model.bushings.push(Bushing {
            name,
            node_a,
            node_b,
            frame_a: local(node_a),
            frame_b: local(node_b),
            stiffness,
            damping,
            form: match t.opt_choice("form", &["large_rotation", "small_rotation"])? {
                Some("small_rotation") => BushingForm::SmallRotation,
                _ => BushingForm::LargeRotation,
            },
        });
        origins.bushings.push(
            Origin::of(&t)
                .alias("frame_a", "position")
                .alias("frame_b", "position"),
        );
    }
    Ok(())
}

fn read_rotational_springs(
    top: &Table<'_>,
    model: &mut Model,
    origins: &mut Origins,
) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("rotational_spring")? {
        let mut keys = vec![
            "name",
            "joint",
            "stiffness",
            "damping",
            "angle",
            "angle_deg",
        ];
        keys.extend(LAW_KEYS);
        t.check_keys(&keys)?;
        let name = read_name(&t, &mut names, "rotational spring")?;
        let joint = require_joint(model, origins, &t.req("joint")?)?;
        let law = read_force_law(&t)?;
        let stiffness = stiffness_or_curve(&t, law.as_ref())?;
        let damping = match t.field("damping") {
            Some(f) => physical_or_zero(&f)?,
            None => 0.0,
        };
        let angle = match (t.field("angle"), t.field("angle_deg")) {
            (Some(_), Some(f)) => return Err(f.err("give angle or angle_deg, not both")),
            (Some(f), None) => f.f64_in(-MAX_ANGLE, MAX_ANGLE)?,
            (None, Some(f)) => f.f64_in(-MAX_ANGLE, MAX_ANGLE)?.to_radians(),
            (None, None) => 0.0,
        };
        model.rotational_springs.push(RotationalSpring {
            name,
            joint,
            stiffness,
            damping,
            angle,
            law: law.unwrap_or_default(),
        });
        origins.rotational_springs.push(Origin::of(&t));
    }
    Ok(())
}

/// `force_table` or `polynomial` of a table (at most one).
fn read_force_curve(t: &Table<'_>) -> Result<Option<ForceCurve>> {
    match (t.field("force_table"), t.field("polynomial")) {
        (Some(_), Some(p)) => Err(p.err("give force_table or polynomial, not both")),
        (Some(f), None) => {
            let mut points: Vec<(f64, f64)> = Vec::new();
            let list = f.array()?;
            for (i, v) in list.iter().enumerate() {
                let pt = f.elem(i, v);
                let ef = pt.numbers(2, "a point [elongation (m), force (N)]")?;
                if let Some(&(previous, _)) = points.last() {
                    if ef[0] <= previous {
                        return Err(pt.err(format!(
                            "is not sorted in elongation: e = {} does not come after e = {previous}; the elongations must increase strictly",
                            ef[0]
                        )));
                    }
                }
                points.push((ef[0], ef[1]));
            }
            if points.len() < 2 {
                return Err(f.err(format!(
                    "has {} point(s): a force table needs at least 2",
                    points.len()
                )));
            }
            Ok(Some(ForceCurve::Table(points)))
        }
        (None, Some(p)) => {
            let list = p.array()?;
            let a = list
                .iter()
                .enumerate()
                .map(|(j, v)| p.elem(j, v).f64_in(-MAX_PHYSICAL, MAX_PHYSICAL))
                .collect::<Result<Vec<f64>>>()?;
            Ok(Some(ForceCurve::Polynomial(a)))
        }
        (None, None) => Ok(None),
    }
}

fn read_ropes(top: &Table<'_>, model: &mut Model, origins: &mut Origins) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("rope")? {
        t.check_keys(&["name", "points", "stiffness", "damping", "rest_length"])?;
        let name = read_name(&t, &mut names, "rope")?;
        let list = t.req("points")?;
        let mut points = Vec::new();
        let mut length = 0.0;
        let mut previous: Option<Vec3> = None;
        for (i, v) in list.array()?.iter().enumerate() {
            let pt = list.elem(i, v).table()?;
            pt.check_keys(&["node", "point"])?;
            let node = match pt.field("node") {
                Some(f) => resolve_node(model, origins, &f, true)?,
                None => None,
            };
            let p = point(&pt.req("point")?)?;
            length += previous.map_or(0.0, |q: Vec3| (p - q).norm());
            previous = Some(p);
            points.push(RopePoint {
                node,
                point: to_node_frame(model, node, &p),
            });
        }
        let law = read_force_law(&t)?;
        // a nonlinear law may stand without a linear part
        let stiffness = stiffness_or_curve(&t, law.as_ref())?;
        let damping = match t.field("damping") {
            Some(f) => physical_or_zero(&f)?,
            None => 0.0,
        };
        let rest_length = match t.field("rest_length") {
            Some(f) => physical_or_zero(&f)?,
            None => length,
        };
        model.ropes.push(Rope {
            name,
            points,
            stiffness,
            damping,
            rest_length,
        });
        origins.ropes.push(Origin::of(&t));
    }
    Ok(())
}

fn read_sensors(top: &Table<'_>, model: &mut Model, origins: &mut Origins) -> Result<()> {
    const XYZ: &[&str] = &["x", "y", "z"];
    const WXYZ: &[&str] = &["w", "x", "y", "z"];
    const BEAM: &[&str] = SECTION_COMPONENTS;
    let mut names = HashMap::new();
    for t in top.items("sensor")? {
        t.check_keys(SENSOR_KEYS)?;
        let name = read_name(&t, &mut names, "sensor")?;
        let ty = t.req("type")?.choice(&[
            "position",
            "velocity",
            "acceleration",
            "quaternion",
            "angular_velocity",
            "angular_acceleration",
            "joint_coordinate",
            "joint_force",
            "joint_torque",
            "kinetic_energy",
            "potential_energy",
            "total_energy",
            "constraint_violation",
            "beam_strain",
            "beam_stress",
            "spring_force",
            "rope_force",
            "contact",
            "gear_force",
            "gear_transmission_error",
            "rotational_spring_torque",
            "bushing_force",
            "block",
        ])?;
        let why = format!("for a {ty} sensor");
        let uses: &[&str] = match ty {
            "position" | "velocity" | "acceleration" => &["node", "point", "component"],
            "quaternion" => &["node", "component"],
            "angular_velocity" | "angular_acceleration" => &["node", "component", "frame"],
            "joint_coordinate" => &["joint"],
            "joint_force" | "joint_torque" => &["joint", "component"],
            "beam_strain" | "beam_stress" => &["beam", "component"],
            "spring_force" => &["spring"],
            "rope_force" => &["rope"],
            "contact" => &["contact", "component"],
            "gear_force" | "gear_transmission_error" => &["gear"],
            "rotational_spring_torque" => &["spring"],
            "bushing_force" => &["bushing", "component"],
            "block" => &["block"],
            _ => &[],
        };
        // The keys after `name` and `type`: each sensor type uses some of them.
        for &k in &SENSOR_KEYS[2..] {
            if !uses.contains(&k) {
                t.forbid(k, &why)?;
            }
        }
        let node = || -> Result<NodeId> { require_node(model, origins, &t.req("node")?) };
        let component = |allowed: &[&'static str]| -> Result<usize> {
            let c = t.req("component")?.choice(allowed)?;
            Ok(allowed.iter().position(|a| *a == c).unwrap_or(0))
        };
        let joint = || require_joint(model, origins, &t.req("joint")?);
        let kind = match ty {
            "position" | "velocity" | "acceleration" => {
                let node = node()?;
                let p = opt_point(&t, "point")?.unwrap_or(model.nodes[node.0].frame.x);
                let point = to_node_frame(model, Some(node), &p);
                let component = component(XYZ)?;
                match ty {
                    "position" => SensorKind::Position {
                        node,
                        point,
                        component,
                    },
                    "velocity" => SensorKind::Velocity {
                        node,
                        point,
                        component,
                    },
                    _ => SensorKind::Acceleration {
                        node,
                        point,
                        component,
                    },
                }
            }
            "quaternion" => SensorKind::Quaternion {
                node: node()?,
                component: component(WXYZ)?,
            },
            "angular_velocity" | "angular_acceleration" => {
                let node = node()?;
                let frame = match t.opt_choice("frame", &["inertial", "body"])? {
                    Some("body") => SensorFrame::Body,
                    _ => SensorFrame::Inertial,
                };
                let component = component(XYZ)?;
                if ty == "angular_velocity" {
                    SensorKind::AngularVelocity {
                        node,
                        frame,
                        component,
                    }
                } else {
                    SensorKind::AngularAcceleration {
                        node,
                        frame,
                        component,
                    }
                }
            }
            "joint_coordinate" => {
                let j = joint()?;
                let k = model.joints[j.0].kind;
                if !matches!(
                    k,
                    JointKind::Revolute | JointKind::Prismatic | JointKind::Cylindrical
                ) {
                    return Err(t.key_err(
                        "joint",
                        format!(
                            "joint '{}' is {}; a joint coordinate exists for revolute, prismatic and cylindrical joints",
                            model.joints[j.0].name,
                            k.name()
                        ),
                    ));
                }
                SensorKind::JointCoordinate { joint: j }
            }
            "joint_force" => SensorKind::JointForce {
                joint: joint()?,
                component: component(XYZ)?,
            },
            "joint_torque" => SensorKind::JointTorque {
                joint: joint()?,
                component: component(XYZ)?,
            },
            "beam_strain" => SensorKind::BeamStrain {
                beam: super::beam::require_element(model, origins, &t.req("beam")?)?,
                component: component(BEAM)?,
            },
            "beam_stress" => SensorKind::BeamStress {
                beam: super::beam::require_element(model, origins, &t.req("beam")?)?,
                component: component(BEAM)?,
            },
            "spring_force" => {
                let names = || model.springs.iter().map(|s| s.name.as_str());
                let spring = item_named(&t.req("spring")?, names, "spring", "springs")?;
                SensorKind::SpringForce { spring }
            }
            "contact" => {
                let names = || model.contacts.iter().map(|c| c.name.as_str());
                let contact = item_named(&t.req("contact")?, names, "contact", "contacts")?;
                let quantity = component(&crate::model::CONTACT_QUANTITIES)?;
                SensorKind::Contact { contact, quantity }
            }
            "rope_force" => {
                let names = || model.ropes.iter().map(|r| r.name.as_str());
                let rope = item_named(&t.req("rope")?, names, "rope", "ropes")?;
                SensorKind::RopeForce { rope }
            }
            "gear_force" | "gear_transmission_error" => {
                let names = || model.gears.iter().map(|g| g.name.as_str());
                let gear = item_named(&t.req("gear")?, names, "gear pair", "gear pairs")?;
                if ty == "gear_force" {
                    SensorKind::GearForce { gear }
                } else {
                    SensorKind::GearTransmissionError { gear }
                }
            }
            "rotational_spring_torque" => {
                let names = || model.rotational_springs.iter().map(|s| s.name.as_str());
                let plural = "rotational springs";
                let spring = item_named(&t.req("spring")?, names, "rotational spring", plural)?;
                SensorKind::RotationalSpringTorque { spring }
            }
            "block" => {
                let f = t.req("block")?;
                let names: Vec<String> = model
                    .control
                    .blocks
                    .iter()
                    .map(|b| b.name.clone())
                    .collect();
                let signal = super::control::resolve_signal(&f, f.str()?, &names)?;
                let outputs = model.control.blocks[signal.block].kind.n_outputs();
                if signal.output >= outputs {
                    return Err(f.err(format!(
                        "block '{}' has {outputs} output(s) (numbered from 0)",
                        names[signal.block]
                    )));
                }
                SensorKind::Block {
                    block: signal.block,
                    output: signal.output,
                }
            }
            "bushing_force" => {
                let names = || model.bushings.iter().map(|b| b.name.as_str());
                let bushing = item_named(&t.req("bushing")?, names, "bushing", "bushings")?;
                let component = component(&["fx", "fy", "fz", "mx", "my", "mz"])?;
                SensorKind::BushingForce { bushing, component }
            }
            "kinetic_energy" => SensorKind::KineticEnergy,
            "potential_energy" => SensorKind::PotentialEnergy,
            "total_energy" => SensorKind::TotalEnergy,
            _ => SensorKind::ConstraintViolation,
        };
        model.sensors.push(Sensor { name, kind });
        origins.sensors.push(Origin::of(&t));
    }
    Ok(())
}

/// A `[[joint]]` of type "gear" (an ideal gear ratio, [`crate::joints::gear`]).
fn read_gear_joint(
    t: &Table<'_>,
    names: &mut HashMap<String, String>,
    model: &mut Model,
    origins: &mut Origins,
) -> Result<()> {
    t.check_keys(&[
        "name", "type", "node_a", "node_b", "center_a", "center_b", "axis", "teeth_a", "teeth_b",
        "internal",
    ])?;
    let (name, [node_a, node_b], centers) = read_wheels(t, names, "joint", model, origins)?;
    let axis = nonzero_vec3(&t.req("axis")?)?;
    let za = teeth(&t.req("teeth_a")?)?;
    let zb = teeth(&t.req("teeth_b")?)?;
    let internal = match t.field("internal") {
        Some(f) => f.bool()?,
        None => false,
    };
    let id = model.add_gear_joint(&name, [node_a, node_b], centers, &axis, (za, zb, internal));
    origins.joint_ids.insert(name, id);
    origins.joints.push(Origin::of(t));
    Ok(())
}

/// A list of harmonics `[[amplitude, phase], ...]` (phase in rad) whose amplitudes are in
/// `[-max, max]`.
fn harmonics(f: &Field<'_>, max: f64) -> Result<Vec<crate::model::Harmonic>> {
    let list = f.array()?;
    if list.len() > 64 {
        return Err(f.err(format!("holds at most 64 harmonics, got {}", list.len())));
    }
    let mut out = Vec::with_capacity(list.len());
    for (i, v) in list.iter().enumerate() {
        let e = f.elem(i, v);
        let p = e.numbers(2, "a harmonic [amplitude, phase]")?;
        if let toml::de::DeValue::Array(a) = v.get_ref() {
            e.elem(0, &a[0]).f64_in(-max, max)?;
            e.elem(1, &a[1]).f64_in(-MAX_ANGLE, MAX_ANGLE)?;
        }
        out.push(crate::model::Harmonic {
            amplitude: p[0],
            phase: p[1],
        });
    }
    Ok(out)
}

fn read_gears(top: &Table<'_>, model: &mut Model, origins: &mut Origins) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("gear")? {
        t.check_keys(&[
            "name",
            "node_a",
            "node_b",
            "center_a",
            "center_b",
            "axis",
            "teeth_a",
            "teeth_b",
            "module",
            "pressure_angle_deg",
            "helix_angle_deg",
            "internal",
            "mesh_stiffness",
            "damping",
            "backlash",
            "stiffness_variation",
            "stiffness_table",
            "transmission_error",
            "mesh_phase",
            "locate_impacts",
        ])?;
        let (name, [node_a, node_b], centers) =
            read_wheels(&t, &mut names, "gear", model, origins)?;
        let axis = nonzero_vec3(&t.req("axis")?)?;
        let angle = |key: &str, default: f64| -> Result<f64> {
            Ok(match t.field(key) {
                Some(f) => f.f64_in(-90.0, 90.0)?.to_radians(),
                None => default.to_radians(),
            })
        };
        let geometry = crate::model::GearGeometry {
            teeth_a: teeth(&t.req("teeth_a")?)?,
            teeth_b: teeth(&t.req("teeth_b")?)?,
            module: physical(&t.req("module")?)?,
            pressure_angle: angle("pressure_angle_deg", 20.0)?,
            helix_angle: angle("helix_angle_deg", 0.0)?,
            internal: match t.field("internal") {
                Some(f) => f.bool()?,
                None => false,
            },
        };
        let k = physical(&t.req("mesh_stiffness")?)?;
        let g = model.add_gear_pair(&name, [node_a, node_b], centers, &axis, geometry, k);
        let gear = &mut model.gears[g];
        if let Some(f) = t.field("damping") {
            gear.damping = physical_or_zero(&f)?;
        }
        if let Some(f) = t.field("backlash") {
            let v = f.f64()?;
            if v < 0.0 {
                return Err(f.err(format!("must be >= 0, got {v}")));
            }
            gear.backlash = f.f64_in(0.0, MAX_KINEMATIC)?;
        }
        if let Some(f) = t.field("stiffness_variation") {
            gear.stiffness_variation = harmonics(&f, 1.0)?;
        }
        if let Some(f) = t.field("stiffness_table") {
            let list = f.array()?;
            if list.len() > 1000 {
                return Err(f.err(format!("holds at most 1000 points, got {}", list.len())));
            }
            let mut table = Vec::with_capacity(list.len());
            for (i, v) in list.iter().enumerate() {
                let p = f.elem(i, v).numbers(
                    2,
                    "a point [position (fraction of the mesh period), factor]",
                )?;
                table.push((p[0], p[1]));
            }
            gear.stiffness_table = table;
        }
        if let Some(f) = t.field("transmission_error") {
            gear.transmission_error = harmonics(&f, MAX_KINEMATIC)?;
        }
        if let Some(f) = t.field("mesh_phase") {
            gear.mesh_phase = f.f64_in(-MAX_ANGLE, MAX_ANGLE)?;
        }
        if let Some(f) = t.field("locate_impacts") {
            gear.locate_impacts = f.bool()?;
        }
        origins.gears.push(Origin::of(&t));
    }
    Ok(())
}
