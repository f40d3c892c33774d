//! `[[contact]]`: unilateral contact pairs (documented in `docs/model-format.md`, "Contact").
//! Points and directions are given in the inertial frame at t = 0, like a spring's points,
//! and stored in their node's frame.

use super::fields::{physical, physical_or_zero, point, read_name, resolve_node, to_node_frame};
use super::fields::{Origin, Origins};
use super::reader::{Result, Table};
use crate::model::contact::{Bristles, Contact, ContactLaw, ContactShape, Dissipation, Friction};
use crate::model::limits::MAX_KINEMATIC;
use crate::model::{Model, NodeId};
use flexmb_lie::Vec3;
use std::collections::HashMap;

/// The default smallest impact velocity \[m/s\].
const MIN_IMPACT_VELOCITY: f64 = 1e-3;

pub(super) fn read_contacts(
    top: &Table<'_>,
    model: &mut Model,
    origins: &mut Origins,
) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("contact")? {
        t.check_keys(&[
            "name",
            "node_a",
            "node_b",
            "a",
            "b",
            "law",
            "stiffness",
            "hertz",
            "exponent",
            "restitution",
            "min_impact_velocity",
            "friction",
        ])?;
        let name = read_name(&t, &mut names, "contact")?;
        let node_a = match t.field("node_a") {
            Some(f) => resolve_node(model, origins, &f, true)?,
            None => None,
        };
        let node_b = resolve_node(model, origins, &t.req("node_b")?, true)?;
        let shape_a = read_shape(model, node_a, &t.req("a")?.table()?)?;
        let shape_b = read_shape(model, node_b, &t.req("b")?.table()?)?;
        let dissipation = match t.opt_choice(
            "law",
            &[
                "lankarani_nikravesh",
                "hunt_crossley",
                "flores",
                "exact_restitution",
            ],
        )? {
            Some("hunt_crossley") => Dissipation::HuntCrossley,
            Some("flores") => Dissipation::Flores,
            Some("exact_restitution") => Dissipation::ExactRestitution,
            _ => Dissipation::LankaraniNikravesh,
        };
        let stiffness = match (t.field("stiffness"), t.field("hertz")) {
            (Some(f), None) => physical(&f)?,
            (None, Some(f)) => {
                let h = f.table()?;
                h.check_keys(&["young", "poisson"])?;
                let young = h.req("young")?.numbers(2, "Young's moduli [E_a, E_b]")?;
                let poisson = h.req("poisson")?.numbers(2, "Poisson ratios [nu_a, nu_b]")?;
                hertz_stiffness(&shape_a, &shape_b, [young[0], young[1]], [poisson[0], poisson[1]])
                    .map_err(|m| f.err(m))?
            }
            (Some(_), Some(f)) => return Err(f.err("give either stiffness or hertz, not both")),
            (None, None) => return Err(t.key_err("stiffness", "missing: give stiffness (N/m^n) or hertz = { young = [E_a, E_b], poisson = [nu_a, nu_b] }")),
        };
        let exponent = match t.field("exponent") {
            Some(f) => f.f64_in(1.0, 10.0)?,
            None => 1.5,
        };
        let restitution = {
            let f = t.req("restitution")?;
            let e = f.f64()?;
            if !(e > 0.0 && e <= 1.0) {
                return Err(f.err(format!("must be in (0, 1], got {e}")));
            }
            e
        };
        let min_impact_velocity = match t.field("min_impact_velocity") {
            Some(f) => physical(&f)?,
            None => MIN_IMPACT_VELOCITY,
        };
        let friction = match t.field("friction") {
            Some(f) => {
                let ft = f.table()?;
                ft.check_keys(&["coefficient", "stiction_velocity", "viscous", "bristles"])?;
                let bristles = match ft.field("bristles") {
                    Some(f) => {
                        let b = f.table()?;
                        b.check_keys(&["stiffness", "damping", "static_coefficient"])?;
                        Some(Bristles {
                            stiffness: physical(&b.req("stiffness")?)?,
                            damping: match b.field("damping") {
                                Some(f) => physical_or_zero(&f)?,
                                None => 0.0,
                            },
                            static_coefficient: physical(&b.req("static_coefficient")?)?,
                        })
                    }
                    None => None,
                };
                Some(Friction {
                    coefficient: physical_or_zero(&ft.req("coefficient")?)?,
                    stiction_velocity: match ft.field("stiction_velocity") {
                        Some(f) => physical(&f)?,
                        None => 1e-3,
                    },
                    viscous: match ft.field("viscous") {
                        Some(f) => physical_or_zero(&f)?,
                        None => 0.0,
                    },
                    bristles,
                })
            }
            None => None,
        };
        model.contacts.push(Contact {
            name,
            node_a,
            node_b,
            shape_a,
            shape_b,
            law: ContactLaw {
                dissipation,
                stiffness,
                exponent,
                restitution,
                min_impact_velocity,
            },
            friction,
        });
        origins.contacts.push(Origin::of(&t));
    }
    Ok(())
}

/// A shape table `{ shape = "plane" | "sphere" | "cylinder", ... }` (inertial at t = 0),
/// in the frame of `node`.
fn read_shape(model: &Model, node: Option<NodeId>, t: &Table<'_>) -> Result<ContactShape> {
    let rotation = node.map(|n| model.nodes[n.0].frame.r);
    let direction = |v: Vec3| {
        let local = rotation.map_or(v, |r| r.transpose() * v);
        local / local.norm()
    };
    let nonzero = |key: &str| -> Result<Vec3> {
        let f = t.req(key)?;
        let v = f.vec3_within(MAX_KINEMATIC)?;
        if v.norm() > 1e-12 {
            Ok(direction(v))
        } else {
            Err(f.err("must be a non-zero vector (length above 1e-12)"))
        }
    };
    let at = |key: &str| -> Result<Vec3> { Ok(to_node_frame(model, node, &point(&t.req(key)?)?)) };
    let inside = || -> Result<bool> { t.field("inside").map_or(Ok(false), |f| f.bool()) };
    Ok(
        match t
            .req("shape")?
            .choice(&["plane", "sphere", "point", "cylinder"])?
        {
            "plane" => {
                t.check_keys(&["shape", "point", "normal"])?;
                ContactShape::Plane {
                    point: at("point")?,
                    normal: nonzero("normal")?,
                }
            }
            "point" => {
                t.check_keys(&["shape", "point"])?;
                ContactShape::Sphere {
                    center: at("point")?,
                    radius: 0.0,
                    inside: false,
                }
            }
            "sphere" => {
                t.check_keys(&["shape", "center", "radius", "inside"])?;
                ContactShape::Sphere {
                    center: at("center")?,
                    radius: physical(&t.req("radius")?)?,
                    inside: inside()?,
                }
            }
            _ => {
                t.check_keys(&["shape", "point", "axis", "radius", "inside"])?;
                ContactShape::Cylinder {
                    point: at("point")?,
                    axis: nonzero("axis")?,
                    radius: physical(&t.req("radius")?)?,
                    inside: inside()?,
                }
            }
        },
    )
}

/// Hertz's stiffness `K = 4/3 E* sqrt(R*)` of a sphere against a plane or a sphere
/// (Johnson 1985, Contact Mechanics, Sect. 4.2: `1/E* = (1 - nu_a^2)/E_a + (1 - nu_b^2)/E_b`,
/// `1/R* = 1/R_a + 1/R_b`, a concave A of radius R_a counting as `-R_a`).
fn hertz_stiffness(
    a: &ContactShape,
    b: &ContactShape,
    young: [f64; 2],
    poisson: [f64; 2],
) -> std::result::Result<f64, String> {
    for (e, nu) in young.iter().zip(&poisson) {
        if !(e.is_finite() && *e > 0.0) {
            return Err(format!("Young's modulus must be positive, got {e}"));
        }
        if !(nu.is_finite() && (-1.0..0.5).contains(nu)) {
            return Err(format!("Poisson's ratio must be in [-1, 0.5), got {nu}"));
        }
    }
    let e_star =
        1.0 / ((1.0 - poisson[0].powi(2)) / young[0] + (1.0 - poisson[1].powi(2)) / young[1]);
    let ContactShape::Sphere { radius: rb, .. } = *b else {
        return Err(
            "Hertz's point-contact stiffness is for a sphere B (use stiffness for other shapes)"
                .into(),
        );
    };
    let curvature = match *a {
        ContactShape::Plane { .. } => 1.0 / rb,
        ContactShape::Sphere { radius: ra, inside, .. } => {
            let ka = if ra > 0.0 { 1.0 / ra } else { f64::INFINITY };
            1.0 / rb + if inside { -ka } else { ka }
        }
        ContactShape::Cylinder { .. } => {
            return Err("Hertz's point-contact stiffness is for a sphere on a plane or a sphere (use stiffness for cylinders)".into())
        }
    };
    if !(curvature.is_finite() && curvature > 0.0) {
        return Err("the two radii give no finite contact radius (a sphere B of radius 0, or as large as the socket)".into());
    }
    Ok(4.0 / 3.0 * e_star * (1.0 / curvature).sqrt())
}
