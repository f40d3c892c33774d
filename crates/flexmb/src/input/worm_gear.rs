//! `[[worm_gear]]`: worm gear pairs with mesh and thrust-washer friction (documented in
//! `docs/model-format.md`, "Worm gear"; mechanics in [`crate::elements::worm_gear`]).

use super::fields::{nonzero_vec3, physical, physical_or_zero, read_wheels, teeth};
use super::fields::{Origin, Origins};
use super::reader::{Result, Table};
use crate::model::limits::{MAX_FRICTION, MAX_KINEMATIC};
use crate::model::Model;
use std::collections::HashMap;

pub(super) fn read_worm_gears(
    top: &Table<'_>,
    model: &mut Model,
    origins: &mut Origins,
) -> Result<()> {
    let mut names = HashMap::new();
    for t in top.items("worm_gear")? {
        t.check_keys(&[
            "name",
            "node_a",
            "node_b",
            "center_a",
            "center_b",
            "axis_a",
            "axis_b",
            "starts",
            "teeth",
            "worm_radius",
            "pressure_angle_deg",
            "left_hand",
            "mesh_stiffness",
            "damping",
            "friction",
            "stiction_velocity",
            "washer_radius",
        ])?;
        let (name, [node_a, node_b], centers) =
            read_wheels(&t, &mut names, "worm_gear", model, origins)?;
        let axis_a = nonzero_vec3(&t.req("axis_a")?)?;
        let f = t.req("axis_b")?;
        let axis_b = nonzero_vec3(&f)?;
        let cosine = axis_a.normalize().dot(&axis_b.normalize());
        if cosine.abs() > 1e-6 {
            return Err(f.err(format!(
                "must be perpendicular to axis_a (to 1e-6), they are {:.4} deg apart",
                cosine.clamp(-1.0, 1.0).acos().to_degrees()
            )));
        }
        let starts = teeth(&t.req("starts")?)?;
        let z2 = teeth(&t.req("teeth")?)?;
        let r1 = physical(&t.req("worm_radius")?)?;
        let k = physical(&t.req("mesh_stiffness")?)?;
        let axes = [axis_a, axis_b];
        let g = model.add_worm_gear(&name, [node_a, node_b], centers, axes, (starts, z2, r1), k);
        let gear = &mut model.worm_gears[g];
        if let Some(f) = t.field("pressure_angle_deg") {
            gear.pressure_angle = f.f64_in(-90.0, 90.0)?.to_radians();
        }
        if let Some(f) = t.field("left_hand") {
            gear.left_hand = f.bool()?;
        }
        if let Some(f) = t.field("damping") {
            gear.damping = physical_or_zero(&f)?;
        }
        if let Some(f) = t.field("friction") {
            physical_or_zero(&f)?;
            gear.friction = f.f64_in(0.0, MAX_FRICTION)?;
        }
        if let Some(f) = t.field("stiction_velocity") {
            physical(&f)?;
            gear.stiction_velocity = f.f64_in(0.0, MAX_KINEMATIC)?;
        }
        if let Some(f) = t.field("washer_radius") {
            physical_or_zero(&f)?;
            gear.washer_radius = f.f64_in(0.0, MAX_KINEMATIC)?;
        }
        origins.worm_gears.push(Origin::of(&t));
    }
    Ok(())
}
