//! `[[block]]`: control blocks wired by name (documented in `docs/model-format.md`,
//! "Control blocks"). A block's inputs name other blocks (`"pid"`, or `"observer[1]"` for
//! the second output of a block with several); blocks may come in any order.
//! Points are given in the inertial frame at t = 0 and stored in their node's frame, as a
//! sensor's.

use super::fields::{nonzero_vec3, physical, point, read_name, require_joint, require_node};
use super::fields::{to_node_frame, Origin, Origins};
use super::reader::{name_list, suggestion, Field, Result, Table, QUOTED};
use super::time_function::read_function;
use crate::model::clip;
use crate::model::control::{Block, BlockKind, ControlSystem, Quantity, Signal, Target};
use crate::model::limits::MAX_PHYSICAL;
use crate::model::{Model, TimeFunction};
use flexmb_lie::Vec3;
use std::collections::HashMap;

const TYPES: &[&str] = &[
    "source",
    "gain",
    "sum",
    "product",
    "integrator",
    "lag",
    "pid",
    "state_space",
    "transfer_function",
    "saturation",
    "dead_zone",
    "rate_limiter",
    "lookup",
    "hold",
    "dc_motor",
    "measure",
    "actuator",
    "servo",
];

/// Any finite number in the physical range (gains, limits, coefficients: any sign).
fn number(f: &Field<'_>) -> Result<f64> {
    f.f64_in(-MAX_PHYSICAL, MAX_PHYSICAL)
}

fn number_or(t: &Table<'_>, key: &str, default: f64) -> Result<f64> {
    t.field(key).map_or(Ok(default), |f| number(&f))
}

/// A list of numbers (any length from `min`).
fn list(f: &Field<'_>, min: usize) -> Result<Vec<f64>> {
    let items = f.array()?;
    if items.len() < min {
        return Err(f.err(format!("needs at least {min} numbers, got {}", items.len())));
    }
    items
        .iter()
        .enumerate()
        .map(|(i, v)| number(&f.elem(i, v)))
        .collect()
}

/// A matrix as an array of rows, `rows x cols` (`None`: any), row-major.
fn matrix(
    f: &Field<'_>,
    rows: Option<usize>,
    cols: Option<usize>,
) -> Result<(usize, usize, Vec<f64>)> {
    let items = f.array()?;
    if let Some(r) = rows.filter(|&r| r != items.len()) {
        return Err(f.err(format!("needs {r} rows, got {}", items.len())));
    }
    let mut out = Vec::new();
    let mut width = cols;
    for (i, v) in items.iter().enumerate() {
        let row = list(&f.elem(i, v), 0)?;
        match width {
            Some(w) if w != row.len() => {
                return Err(f
                    .elem(i, v)
                    .err(format!("needs {w} columns, got {}", row.len())))
            }
            _ => width = Some(row.len()),
        }
        out.extend(row);
    }
    Ok((items.len(), width.unwrap_or(0), out))
}

/// The unit vector of `<prefix>axis`, or of `<prefix>component = "x" | "y" | "z"`.
fn axis(t: &Table<'_>, prefix: &str) -> Result<Vec3> {
    let (axis_key, component_key) = (format!("{prefix}axis"), format!("{prefix}component"));
    match (t.field(&axis_key), t.field(&component_key)) {
        (Some(f), None) => Ok(nonzero_vec3(&f)?.normalize()),
        (None, Some(f)) => {
            let c = f.choice(&["x", "y", "z"])?;
            let k = ["x", "y", "z"].iter().position(|x| *x == c).unwrap_or(0);
            Ok(Vec3::ith(k, 1.0))
        }
        (Some(_), Some(f)) => Err(f.err("give either axis or component, not both")),
        (None, None) => Err(t.key_err(
            "component",
            "missing: give component = \"x\" | \"y\" | \"z\" or axis = [x, y, z]",
        )),
    }
}

/// A source's signal from a CSV file with a header (path relative to the model file), its
/// columns `time_column` (default `t`) and `column`, read as a `[[reference]]`'s
/// ([`super::sensitivity::read_signal`]): interpolated linearly, constant outside.
fn read_signal_file(t: &Table<'_>, f: &Field<'_>) -> Result<TimeFunction> {
    let base = std::path::Path::new(f.src.file).parent();
    let name = f.str()?;
    let path = base.map_or_else(|| name.into(), |b| b.join(name));
    let time_column = t.opt_str("time_column")?.unwrap_or("t");
    let column = t.req("column")?.str()?;
    let (times, values) = super::sensitivity::read_signal(&path, time_column, column)
        .map_err(|m| f.err(format!("{}: {m}", path.display())))?;
    Ok(TimeFunction::Table {
        points: times.into_iter().zip(values).collect(),
    })
}

/// The field that names a block's inputs (`input` or `inputs`), and each name with its
/// own field.
type InputNames<'a> = (Field<'a>, Vec<(Field<'a>, &'a str)>);

/// What one `[[block]]` says before its inputs are resolved.
struct Parsed<'a> {
    table: Table<'a>,
    block: Block,
    inputs: Option<InputNames<'a>>,
}

pub(super) fn read_blocks(top: &Table<'_>, model: &mut Model, origins: &mut Origins) -> Result<()> {
    let mut names = HashMap::new();
    let mut parsed = Vec::new();
    for t in top.items("block")? {
        let ty = t.req("type")?.choice(TYPES)?;
        t.check_keys(&keys(ty))?;
        let name = read_name(&t, &mut names, "block")?;
        let inputs = read_input_names(&t)?;
        let n_named = inputs.as_ref().map_or(0, |(_, v)| v.len());
        let (kind, params) = read_kind(ty, &t, model, origins, n_named)?;
        origins.blocks.push(Origin::of(&t));
        parsed.push(Parsed {
            table: t,
            block: Block {
                name,
                kind,
                params,
                inputs: Vec::new(),
            },
            inputs,
        });
    }
    let block_names: Vec<String> = parsed.iter().map(|p| p.block.name.clone()).collect();
    let outputs: Vec<usize> = parsed.iter().map(|p| p.block.kind.n_outputs()).collect();
    let mut blocks = Vec::with_capacity(parsed.len());
    for p in parsed {
        let mut block = p.block;
        let want = block.kind.n_inputs();
        let given = p.inputs.as_ref().map_or(0, |(_, v)| v.len());
        if want != given {
            let msg = format!(
                "a {} block takes {want} input{}, got {given}",
                block.kind.name(),
                if want == 1 { "" } else { "s" }
            );
            return Err(match &p.inputs {
                Some((f, _)) => f.err(msg),
                None => p.table.key_err("input", msg),
            });
        }
        for (f, name) in p.inputs.iter().flat_map(|(_, v)| v) {
            let s = resolve_signal(f, name, &block_names)?;
            let n = outputs[s.block];
            if s.output >= n {
                return Err(f.err(format!(
                    "'{}': block '{}' has {n} output{} (numbered from 0)",
                    clip(name, QUOTED),
                    block_names[s.block],
                    if n == 1 { "" } else { "s" }
                )));
            }
            block.inputs.push(s);
        }
        blocks.push(block);
    }
    model.control = ControlSystem::new(blocks);
    Ok(())
}

/// The names of `input` (one) or `inputs` (a list).
fn read_input_names<'a>(t: &Table<'a>) -> Result<Option<InputNames<'a>>> {
    match (t.field("input"), t.field("inputs")) {
        (Some(f), None) => {
            let name = f.str()?;
            Ok(Some((f.clone(), vec![(f, name)])))
        }
        (None, Some(f)) => {
            let items = f.array()?;
            let mut out = Vec::with_capacity(items.len());
            for (i, v) in items.iter().enumerate() {
                let e = f.elem(i, v);
                let name = e.str()?;
                out.push((e, name));
            }
            Ok(Some((f, out)))
        }
        (Some(_), Some(f)) => Err(f.err("give either input or inputs, not both")),
        (None, None) => Ok(None),
    }
}

/// `"name"` or `"name[k]"` as a signal.
pub(super) fn resolve_signal(f: &Field<'_>, text: &str, names: &[String]) -> Result<Signal> {
    let (name, output) = match text.strip_suffix(']').and_then(|s| s.split_once('[')) {
        Some((n, k)) => {
            let k: usize = k.trim().parse().map_err(|_| {
                f.err(format!(
                    "'{}': the output index must be a whole number",
                    clip(text, QUOTED)
                ))
            })?;
            (n, k)
        }
        None => (text, 0),
    };
    let block = names.iter().position(|n| n == name).ok_or_else(|| {
        let all = || names.iter().map(String::as_str);
        f.err(format!(
            "unknown signal '{}'{}: no block of that name (blocks: {})",
            clip(name, QUOTED),
            suggestion(name, all()),
            name_list(all(), 12)
        ))
    })?;
    Ok(Signal { block, output })
}

/// The keys a block of type `ty` may have.
fn keys(ty: &str) -> Vec<&'static str> {
    let mut k = vec!["name", "type", "input", "inputs"];
    k.extend_from_slice(match ty {
        "source" => &["function", "file", "time_column", "column"],
        "gain" => &["gain"],
        "sum" => &["signs"],
        "integrator" => &["gain", "initial"],
        "lag" => &["gain", "time_constant", "initial"],
        "pid" => &["kp", "ki", "kd", "tf", "lower", "upper", "kb"],
        "state_space" => &["A", "B", "C", "D", "x0"],
        "transfer_function" => &["numerator", "denominator"],
        "saturation" | "dead_zone" => &["lower", "upper"],
        "rate_limiter" => &["rising", "falling", "time_constant"],
        "lookup" => &["points"],
        "hold" => &["period"],
        "dc_motor" => &["resistance", "inductance", "torque_constant", "back_emf"],
        "measure" => &[
            "quantity",
            "node",
            "point",
            "component",
            "axis",
            "joint",
            "beam",
            "contact",
        ],
        "actuator" => &[
            "target",
            "node",
            "point",
            "component",
            "axis",
            "joint",
            "follower",
        ],
        "servo" => &[
            "quantity",
            "node",
            "point",
            "component",
            "axis",
            "joint",
            "function",
            "target",
            "target_node",
            "target_point",
            "target_component",
            "target_axis",
            "target_joint",
            "follower",
            "initial",
        ],
        _ => &[],
    });
    k
}

/// `lower <= upper` of a block's limits (defaults: unbounded).
fn limits(t: &Table<'_>) -> Result<(f64, f64)> {
    let lower = number_or(t, "lower", -f64::MAX)?;
    let upper = number_or(t, "upper", f64::MAX)?;
    if lower > upper {
        return Err(t.key_err("upper", format!("must be >= lower ({lower}), got {upper}")));
    }
    Ok((lower, upper))
}

fn read_kind(
    ty: &str,
    t: &Table<'_>,
    model: &Model,
    origins: &Origins,
    n_inputs: usize,
) -> Result<(BlockKind, Vec<f64>)> {
    let positive = |key: &str| physical(&t.req(key)?);
    Ok(match ty {
        "source" => {
            let f = match (t.field("function"), t.field("file")) {
                (Some(f), None) => read_function(&f)?,
                (None, Some(f)) => read_signal_file(t, &f)?,
                (Some(_), Some(f)) => return Err(f.err("give either function or file, not both")),
                (None, None) => {
                    return Err(t.key_err(
                        "function",
                        "missing: give function = { type = ... } or file = \"signal.csv\"",
                    ))
                }
            };
            (BlockKind::Source(f), Vec::new())
        }
        "gain" => {
            let f = t.req("gain")?;
            match f.array() {
                Ok(_) => {
                    let (rows, cols, k) = matrix(&f, None, Some(n_inputs))?;
                    (BlockKind::Gain { rows, cols }, k)
                }
                Err(_) => (BlockKind::Gain { rows: 1, cols: 1 }, vec![number(&f)?]),
            }
        }
        "sum" => {
            let signs = match t.field("signs") {
                Some(f) => {
                    let s = list(&f, 1)?;
                    if s.len() != n_inputs {
                        return Err(f.err(format!(
                            "needs one sign per input ({n_inputs}), got {}",
                            s.len()
                        )));
                    }
                    s
                }
                None => vec![1.0; n_inputs],
            };
            (BlockKind::Sum { signs }, Vec::new())
        }
        "product" => (BlockKind::Product { inputs: n_inputs }, Vec::new()),
        "integrator" => (
            BlockKind::Integrator,
            vec![number_or(t, "gain", 1.0)?, number_or(t, "initial", 0.0)?],
        ),
        "lag" => (
            BlockKind::Lag,
            vec![
                number_or(t, "gain", 1.0)?,
                positive("time_constant")?,
                number_or(t, "initial", 0.0)?,
            ],
        ),
        "pid" => {
            let kd = number_or(t, "kd", 0.0)?;
            let tf = match t.field("tf") {
                Some(f) => physical(&f)?,
                None if kd != 0.0 => {
                    return Err(t.key_err(
                        "tf",
                        "missing: a PID with kd needs the time constant tf > 0 of its derivative filter",
                    ))
                }
                None => 1.0,
            };
            let (lower, upper) = limits(t)?;
            let kb = match t.field("kb") {
                Some(f) => {
                    let v = number(&f)?;
                    if v < 0.0 {
                        return Err(f.err(format!("must be >= 0, got {v}")));
                    }
                    v
                }
                None => 0.0,
            };
            let params = vec![
                number_or(t, "kp", 0.0)?,
                number_or(t, "ki", 0.0)?,
                kd,
                tf,
                lower,
                upper,
                kb,
            ];
            (BlockKind::Pid, params)
        }
        "state_space" => {
            let af = t.req("A")?;
            let (n, cols, a) = matrix(&af, None, None)?;
            if cols != n {
                return Err(af.err(format!("must be square, got {n} x {cols}")));
            }
            let (_, m, b) = matrix(&t.req("B")?, Some(n), Some(n_inputs))?;
            let (p, _, c) = matrix(&t.req("C")?, None, Some(n))?;
            let d = match t.field("D") {
                Some(f) => matrix(&f, Some(p), Some(m))?.2,
                None => vec![0.0; p * m],
            };
            let x0 = match t.field("x0") {
                Some(f) => {
                    let x = list(&f, 0)?;
                    if x.len() != n {
                        return Err(f.err(format!(
                            "needs {n} numbers (one per state), got {}",
                            x.len()
                        )));
                    }
                    x
                }
                None => vec![0.0; n],
            };
            let kind = BlockKind::StateSpace {
                states: n,
                inputs: m,
                outputs: p,
            };
            (kind, [a, b, c, d, x0].concat())
        }
        "transfer_function" => {
            let nf = t.req("numerator")?;
            let num = list(&nf, 1)?;
            let df = t.req("denominator")?;
            let den = list(&df, 1)?;
            if den[0] == 0.0 {
                return Err(df.err("the leading coefficient must not be 0"));
            }
            if num.len() > den.len() {
                return Err(nf.err(format!(
                    "the transfer function must be proper: numerator degree {} above denominator degree {}",
                    num.len() - 1,
                    den.len() - 1
                )));
            }
            let kind = BlockKind::TransferFunction {
                num: num.len(),
                den: den.len(),
            };
            (kind, [num, den].concat())
        }
        "saturation" | "dead_zone" => {
            let (lower, upper) = limits(t)?;
            let kind = if ty == "saturation" {
                BlockKind::Saturation
            } else {
                BlockKind::DeadZone
            };
            (kind, vec![lower, upper])
        }
        "rate_limiter" => (
            BlockKind::RateLimiter,
            vec![
                positive("rising")?,
                positive("falling")?,
                positive("time_constant")?,
            ],
        ),
        "lookup" => {
            let f = t.req("points")?;
            let (n, _, pts) = matrix(&f, None, Some(2))?;
            if n < 2 {
                return Err(f.err(format!("needs at least 2 points [u, y], got {n}")));
            }
            let breakpoints: Vec<f64> = pts.iter().step_by(2).copied().collect();
            if breakpoints.windows(2).any(|w| w[1] <= w[0]) {
                return Err(f.err("the inputs u of the points must increase"));
            }
            let values = pts.iter().skip(1).step_by(2).copied().collect();
            (BlockKind::Lookup { breakpoints }, values)
        }
        "hold" => (
            BlockKind::Hold {
                period: positive("period")?,
            },
            Vec::new(),
        ),
        "dc_motor" => (
            BlockKind::DcMotor,
            vec![
                positive("resistance")?,
                positive("inductance")?,
                positive("torque_constant")?,
                positive("back_emf")?,
            ],
        ),
        "measure" => (
            BlockKind::Measure(read_quantity(t, model, origins, QUANTITIES)?),
            Vec::new(),
        ),
        "servo" => {
            let quantity = read_quantity(t, model, origins, &["position", "joint_coordinate"])?;
            let target = read_target(t, model, origins, "target_")?;
            let function = read_function(&t.req("function")?)?;
            let params = vec![number_or(t, "initial", 0.0)?];
            let kind = BlockKind::Servo {
                quantity,
                target,
                function,
            };
            (kind, params)
        }
        _ => (
            BlockKind::Actuator(read_target(t, model, origins, "")?),
            Vec::new(),
        ),
    })
}

/// The quantities a measurement reads.
const QUANTITIES: &[&str] = &[
    "position",
    "velocity",
    "acceleration",
    "angular_velocity",
    "joint_coordinate",
    "joint_rate",
    "constraint_force",
    "constraint_moment",
    "section_force",
    "contact_force",
];

/// The `quantity` of a measurement or servo (one of `allowed`) and what it is of.
fn read_quantity(
    t: &Table<'_>,
    model: &Model,
    origins: &Origins,
    allowed: &[&'static str],
) -> Result<Quantity> {
    let q = t.req("quantity")?.choice(allowed)?;
    Ok(match q {
        "joint_coordinate" | "joint_rate" => {
            let f = t.req("joint")?;
            let joint = require_joint(model, origins, &f)?;
            check_joint_axis(model, &f, joint)?;
            if q == "joint_rate" {
                Quantity::JointRate { joint }
            } else {
                Quantity::JointCoordinate { joint }
            }
        }
        "constraint_force" | "constraint_moment" => {
            let f = t.req("joint")?;
            let joint = require_joint(model, origins, &f)?;
            Quantity::ConstraintForce {
                joint,
                axis: axis(t, "")?,
                moment: q == "constraint_moment",
            }
        }
        "contact_force" => {
            let f = t.req("contact")?;
            let names = || model.contacts.iter().map(|c| c.name.as_str());
            let contact = super::fields::item_named(&f, names, "contact", "contacts")?;
            Quantity::ContactForce {
                contact,
                axis: axis(t, "")?,
            }
        }
        "section_force" => {
            let beam = super::beam::require_element(model, origins, &t.req("beam")?)?;
            let names = super::fields::SECTION_COMPONENTS;
            let c = t.req("component")?.choice(names)?;
            let component = names.iter().position(|s| *s == c).unwrap_or(0);
            Quantity::SectionForce { beam, component }
        }
        _ => {
            let node = require_node(model, origins, &t.req("node")?)?;
            let axis = axis(t, "")?;
            let p = match t.field("point") {
                Some(f) => point(&f)?,
                None => model.nodes[node.0].frame.x,
            };
            let point = to_node_frame(model, Some(node), &p);
            match q {
                "position" => Quantity::Position { node, point, axis },
                "velocity" => Quantity::Velocity { node, point, axis },
                "acceleration" => Quantity::Acceleration { node, point, axis },
                _ => Quantity::AngularVelocity { node, axis },
            }
        }
    })
}

/// A joint a measurement or actuator acts along: revolute, cylindrical or prismatic.
fn check_joint_axis(model: &Model, f: &Field<'_>, joint: crate::model::JointId) -> Result<()> {
    use crate::model::JointKind;
    let j = &model.joints[joint.0];
    match j.kind {
        JointKind::Revolute | JointKind::Cylindrical | JointKind::Prismatic => Ok(()),
        k => Err(f.err(format!(
            "joint '{}' is {}: a block acts along the axis of a revolute, cylindrical or prismatic joint",
            j.name,
            k.name()
        ))),
    }
}

/// The `target` of an actuator (its keys `joint`, `node`, ...) or of a servo (`target_joint`,
/// `target_node`, ...: `prefix` "target_").
fn read_target(t: &Table<'_>, model: &Model, origins: &Origins, prefix: &str) -> Result<Target> {
    let key = |k: &str| format!("{prefix}{k}");
    let target = t.req("target")?.choice(&["joint", "force", "moment"])?;
    Ok(match target {
        "joint" => {
            let f = t.req(&key("joint"))?;
            let joint = require_joint(model, origins, &f)?;
            check_joint_axis(model, &f, joint)?;
            Target::Joint { joint }
        }
        _ => {
            let node = require_node(model, origins, &t.req(&key("node"))?)?;
            let follower = match t.field("follower") {
                Some(f) => f.bool()?,
                None => false,
            };
            let mut axis = axis(t, prefix)?;
            if follower {
                axis = model.nodes[node.0].frame.r.transpose() * axis;
            }
            if target == "moment" {
                Target::Moment {
                    node,
                    axis,
                    follower,
                }
            } else {
                let p = match t.field(&key("point")) {
                    Some(f) => point(&f)?,
                    None => model.nodes[node.0].frame.x,
                };
                Target::Force {
                    node,
                    point: to_node_frame(model, Some(node), &p),
                    axis,
                    follower,
                }
            }
        }
    })
}
