//! Triangulated display geometry, for every exporter that draws the model: the display
//! shapes ([`triangles`], in the shape's own frame), beam tubes ([`tube`]) and the placement
//! of a shape at a node configuration ([`Placement`]).
//!
//! Every triangle is listed counter-clockwise seen from outside (its normal
//! `(p1 - p0) x (p2 - p0)` points out of the solid), and every surface is closed except the
//! tube, which is open at both ends.

use crate::info::ShapeInfo;
use flexmb_lie::{so3, Mat3, Vec3};

/// Sides of the polygon that stands for a cylinder's circle.
pub const CYLINDER_SIDES: usize = 24;
/// Meridians and parallels bands of a sphere (a UV sphere).
pub const SPHERE_MERIDIANS: usize = 16;
pub const SPHERE_BANDS: usize = 8;

/// The surface of `shape` in its own frame: vertices \[m\] and triangles (vertex indices).
///
/// - `box`: 8 corners at `±size / 2`, 12 triangles;
/// - `cylinder`: along z from `-size[2] / 2` to `size[2] / 2`, semi-axes `size[0] / 2` and
///   `size[1] / 2` (a circle when they are equal), [`CYLINDER_SIDES`] sides and both caps
///   (a centre point each): `2 n + 2` vertices, `4 n` triangles;
/// - `sphere`: an ellipsoid of semi-axes `size / 2` (a sphere when they are equal) drawn as
///   a UV sphere of [`SPHERE_MERIDIANS`] meridians and [`SPHERE_BANDS`] bands:
///   `2 + m (b - 1)` vertices, `2 m (b - 1)` triangles;
/// - `mesh`: its own vertices and triangles;
/// - any other kind: nothing.
pub fn triangles(shape: &ShapeInfo) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let half = shape.size.map(|s| 0.5 * s);
    match shape.kind.as_str() {
        "box" => cuboid(half),
        "cylinder" => cylinder(half, CYLINDER_SIDES),
        "sphere" => ellipsoid(half, SPHERE_MERIDIANS, SPHERE_BANDS),
        "mesh" => (shape.vertices.clone(), shape.triangles.clone()),
        _ => (Vec::new(), Vec::new()),
    }
}

/// A box of half sides `half` centred on the origin. Corner `i` has the sign of bit `k` of
/// `i` on axis `k` (bit set: `+`).
fn cuboid(half: [f64; 3]) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let vertices = (0..8)
        .map(|i| std::array::from_fn(|k| if i >> k & 1 == 1 { half[k] } else { -half[k] }))
        .collect();
    let mut tris = Vec::with_capacity(12);
    for axis in 0..3 {
        for positive in [false, true] {
            // In-plane axes (u, v) with u x v along the outward normal, so that the corners
            // (-,-), (+,-), (+,+), (-,+) in (u, v) turn counter-clockwise seen from outside.
            let (u, v) = if positive {
                ((axis + 1) % 3, (axis + 2) % 3)
            } else {
                ((axis + 2) % 3, (axis + 1) % 3)
            };
            let corner = |su: u32, sv: u32| (u32::from(positive) << axis) | (su << u) | (sv << v);
            let quad = [corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1)];
            tris.push([quad[0], quad[1], quad[2]]);
            tris.push([quad[0], quad[2], quad[3]]);
        }
    }
    (vertices, tris)
}

/// A cylinder along z: `sides` points around the bottom (`z = -half[2]`), `sides` around the
/// top, then the centres of the bottom and of the top.
fn cylinder(half: [f64; 3], sides: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let n = sides as u32;
    let mut vertices = Vec::with_capacity(2 * sides + 2);
    for z in [-half[2], half[2]] {
        for j in 0..sides {
            let (s, c) = angle(j, sides).sin_cos();
            vertices.push([half[0] * c, half[1] * s, z]);
        }
    }
    vertices.push([0.0, 0.0, -half[2]]);
    vertices.push([0.0, 0.0, half[2]]);
    let (bottom, top) = (2 * n, 2 * n + 1);
    let mut tris = Vec::with_capacity(4 * sides);
    for j in 0..n {
        let k = (j + 1) % n;
        tris.push([j, k, n + j]);
        tris.push([k, n + k, n + j]);
        tris.push([bottom, k, j]);
        tris.push([top, n + j, n + k]);
    }
    (vertices, tris)
}

/// An ellipsoid: the south pole, `bands - 1` parallels of `meridians` points from south to
/// north, the north pole.
fn ellipsoid(half: [f64; 3], meridians: usize, bands: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let (m, rings) = (meridians as u32, bands as u32 - 1);
    let mut vertices = Vec::with_capacity(2 + meridians * (bands - 1));
    vertices.push([0.0, 0.0, -half[2]]);
    for r in 1..bands {
        let polar = std::f64::consts::PI * (1.0 - r as f64 / bands as f64);
        let (sp, cp) = polar.sin_cos();
        for j in 0..meridians {
            let (s, c) = angle(j, meridians).sin_cos();
            vertices.push([half[0] * sp * c, half[1] * sp * s, half[2] * cp]);
        }
    }
    vertices.push([0.0, 0.0, half[2]]);
    let north = 1 + m * rings;
    let at = |ring: u32, j: u32| 1 + ring * m + j % m;
    let mut tris = Vec::with_capacity(2 * meridians * (bands - 1));
    for j in 0..m {
        tris.push([0, at(0, j + 1), at(0, j)]);
        for ring in 0..rings - 1 {
            tris.push([at(ring, j), at(ring, j + 1), at(ring + 1, j)]);
            tris.push([at(ring, j + 1), at(ring + 1, j + 1), at(ring + 1, j)]);
        }
        tris.push([north, at(rings - 1, j), at(rings - 1, j + 1)]);
    }
    (vertices, tris)
}

fn angle(j: usize, n: usize) -> f64 {
    std::f64::consts::TAU * j as f64 / n as f64
}

/// The vertices of a tube of `radius` around the segment from `a` to `b`: `sides` points
/// around `a`, then `sides` around `b`, each ring in the plane through its end normal to the
/// segment, so that every point is at `radius` from the segment.
///
/// The first point of each ring lies along `reference[0]` (at `a`) or `reference[1]` (at
/// `b`), projected onto that plane; the next ones turn positively about `b - a`. Drawing the
/// references fixed in the end sections makes the tube twist with them. A reference (nearly)
/// along the segment is replaced by [`perpendicular`]. A segment of zero length gives its
/// rings in the plane normal to x.
pub fn tube(
    a: [f64; 3],
    b: [f64; 3],
    reference: [[f64; 3]; 2],
    radius: f64,
    sides: usize,
) -> Vec<[f64; 3]> {
    let (a, b) = (Vec3::from(a), Vec3::from(b));
    let d = (b - a).try_normalize(0.0).unwrap_or_else(Vec3::x);
    let mut points = Vec::with_capacity(2 * sides);
    for (end, r) in [(a, reference[0]), (b, reference[1])] {
        let r = Vec3::from(r);
        let n = (r - d * d.dot(&r))
            .try_normalize(1e-6 * r.norm())
            .unwrap_or_else(|| perpendicular(&d));
        let m = d.cross(&n);
        for j in 0..sides {
            let (s, c) = angle(j, sides).sin_cos();
            points.push((end + radius * (c * n + s * m)).into());
        }
    }
    points
}

/// The triangles of a [`tube`] of `sides` sides (vertex indices from 0), counter-clockwise
/// seen from outside: `2 sides` of them.
pub fn tube_triangles(sides: usize) -> impl Iterator<Item = [u32; 3]> {
    let n = sides as u32;
    (0..n).flat_map(move |j| {
        let k = (j + 1) % n;
        [[j, k, n + j], [k, n + k, n + j]]
    })
}

/// A unit vector normal to the unit vector `d`: its cross product with the coordinate axis
/// least aligned with it.
pub fn perpendicular(d: &Vec3) -> Vec3 {
    let k = (0..3)
        .min_by(|&i, &j| d[i].abs().total_cmp(&d[j].abs()))
        .unwrap_or(0);
    let mut e = Vec3::zeros();
    e[k] = 1.0;
    d.cross(&e).normalize()
}

/// A rigid placement `x -> origin + rotation x`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub origin: Vec3,
    pub rotation: Mat3,
}

impl Placement {
    /// The placement of a node: its position and unit quaternion `w, x, y, z`
    /// (node-to-inertial), as in a [`crate::Snapshot`].
    pub fn node(position: [f64; 3], orientation: [f64; 4]) -> Self {
        Self {
            origin: position.into(),
            rotation: so3::from_quaternion(orientation),
        }
    }

    /// The placement of `shape`'s frame in its node frame.
    pub fn shape(shape: &ShapeInfo) -> Self {
        Self::node(shape.position, shape.orientation)
    }

    /// `self` followed by `inner`: a point given in `inner`'s frame, mapped to `self`'s outer
    /// frame.
    pub fn then(&self, inner: &Placement) -> Self {
        Self {
            origin: self.origin + self.rotation * inner.origin,
            rotation: self.rotation * inner.rotation,
        }
    }

    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        (self.origin + self.rotation * Vec3::from(p)).into()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn shape(kind: &str, size: [f64; 3]) -> ShapeInfo {
        ShapeInfo {
            kind: kind.into(),
            size,
            ..Default::default()
        }
    }

    /// Volume enclosed by a triangulated surface (divergence theorem): positive when the
    /// triangles turn counter-clockwise seen from outside.
    fn volume(v: &[[f64; 3]], t: &[[u32; 3]]) -> f64 {
        t.iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| Vec3::from(v[i as usize]));
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum()
    }

    /// Every edge of a closed, consistently oriented surface is used once in each direction.
    fn is_closed(t: &[[u32; 3]]) -> bool {
        let mut edges = HashMap::new();
        for t in t {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        edges
            .iter()
            .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1))
    }

    #[test]
    fn a_box_has_its_corners_and_volume_and_faces_outward() {
        let (v, t) = triangles(&shape("box", [1.0, 2.0, 3.0]));
        assert_eq!((v.len(), t.len()), (8, 12));
        assert!(v
            .iter()
            .all(|p| p[0].abs() == 0.5 && p[1].abs() == 1.0 && p[2].abs() == 1.5));
        assert!((volume(&v, &t) - 6.0).abs() < 1e-12);
        assert!(is_closed(&t));
    }

    #[test]
    fn a_cylinder_is_closed_along_z_with_the_polygons_area() {
        let (v, t) = triangles(&shape("cylinder", [0.4, 0.4, 2.0]));
        let n = CYLINDER_SIDES;
        assert_eq!((v.len(), t.len()), (2 * n + 2, 4 * n));
        let polygon = 0.5 * n as f64 * 0.2f64.powi(2) * angle(1, n).sin();
        assert!((volume(&v, &t) - 2.0 * polygon).abs() < 1e-12);
        assert!(is_closed(&t));
        assert!(v.iter().all(|p| p[2].abs() == 1.0));
        for p in &v[..2 * n] {
            assert!(((p[0] * p[0] + p[1] * p[1]).sqrt() - 0.2).abs() < 1e-15);
        }
    }

    #[test]
    fn a_sphere_is_closed_with_its_points_on_the_sphere() {
        let (v, t) = triangles(&shape("sphere", [2.0, 2.0, 2.0]));
        let (m, b) = (SPHERE_MERIDIANS, SPHERE_BANDS);
        assert_eq!((v.len(), t.len()), (2 + m * (b - 1), 2 * m * (b - 1)));
        assert!(v
            .iter()
            .all(|p| (Vec3::from(*p).norm() - 1.0).abs() < 1e-14));
        assert!(is_closed(&t));
        // A little less than 4/3 pi, the sphere's volume, and more than the octahedron's.
        let vol = volume(&v, &t);
        assert!(vol < 4.0 / 3.0 * std::f64::consts::PI && vol > 3.5, "{vol}");
    }

    #[test]
    fn a_mesh_is_its_own_triangles_and_an_unknown_kind_nothing() {
        let mut s = shape("mesh", [1.0; 3]);
        s.vertices = vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        s.triangles = vec![[0, 1, 2]];
        assert_eq!(triangles(&s), (s.vertices.clone(), s.triangles.clone()));
        assert_eq!(triangles(&shape("torus", [1.0; 3])), (vec![], vec![]));
    }

    #[test]
    fn a_tube_has_its_points_at_the_radius_and_faces_outward() {
        let (a, b) = ([1.0, 2.0, 3.0], [2.0, 4.0, 1.0]);
        let points = tube(a, b, [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]], 0.1, 8);
        assert_eq!(points.len(), 16);
        let (a, b) = (Vec3::from(a), Vec3::from(b));
        let d = (b - a).normalize();
        for (k, p) in points.iter().enumerate() {
            let end = if k < 8 { a } else { b };
            let r = Vec3::from(*p) - end;
            assert!((r.norm() - 0.1).abs() < 1e-14 && r.dot(&d).abs() < 1e-14);
        }
        // The first point of each ring along its reference projected onto the ring's plane.
        for (k, reference) in [(0, Vec3::z()), (8, Vec3::x())] {
            let end = if k == 0 { a } else { b };
            let n = (reference - d * d.dot(&reference)).normalize();
            assert!((Vec3::from(points[k]) - end - 0.1 * n).norm() < 1e-14);
        }
        // Outward: each triangle's normal points away from the axis.
        for t in tube_triangles(8) {
            let [p, q, r] = t.map(|i| Vec3::from(points[i as usize]));
            let centre = (p + q + r) / 3.0;
            let radial = (centre - a) - d * d.dot(&(centre - a));
            assert!((q - p).cross(&(r - p)).dot(&radial) > 0.0);
        }
        // A reference along the segment falls back on a perpendicular.
        let points = tube([0.0; 3], [0.0, 0.0, 2.0], [[0.0, 0.0, 1.0]; 2], 0.5, 4);
        assert!(points
            .iter()
            .all(|p| ((p[0] * p[0] + p[1] * p[1]).sqrt() - 0.5).abs() < 1e-15));
    }

    #[test]
    fn placements_compose_as_frames() {
        let half = std::f64::consts::FRAC_1_SQRT_2;
        // 90 degrees about z, then a shape 90 degrees about x at (1, 0, 0) in the node frame.
        let node = Placement::node([1.0, 2.0, 3.0], [half, 0.0, 0.0, half]);
        let s = Placement::node([1.0, 0.0, 0.0], [half, half, 0.0, 0.0]);
        let p = node.then(&s).apply([0.0, 1.0, 0.0]);
        // Shape y -> node z (rotation about x), plus (1, 0, 0): node (1, 0, 1); about z:
        // inertial (0, 1, 1) + (1, 2, 3).
        let expected = [1.0, 3.0, 4.0];
        assert!((0..3).all(|k| (p[k] - expected[k]).abs() < 1e-15), "{p:?}");
    }
}
