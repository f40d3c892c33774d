//! The Paraview time series of a run: [`export_vtk`] writes, into one directory, a VTK XML
//! unstructured grid (`.vtu`) per snapshot and per kind of piece, and collections (`.pvd`)
//! that give each file its time.
//!
//! # How to look at it
//!
//! In Paraview: File > Open `results.pvd`, Apply, then play the animation. Each kind of piece
//! is a block of the dataset (named `beams`, `bodies`, `frames`, `joints`): pick one with
//! Extract Block, or open its own collection instead (`beams.pvd`, `bodies.pvd`,
//! `frames.pvd`, `joints.pvd`: same files), which gives each kind its own colouring. To see
//! the bodies in their colours, colour by `colour` and untick Map Scalars (in the
//! Properties' advanced options); to see a section force, colour the beams by, say,
//! `bending_moment_3`. Joint forces show as arrows with Glyph (orientation array `force`,
//! scale array `force`).
//!
//! # The files
//!
//! For snapshot `k` (its index, zero-padded to six digits), a piece of a kind the model has:
//!
//! - `beams_k.vtu`: each beam element as a tube of its drawn radius ([`BeamInfo::radius`]),
//!   [`VtkOptions::tube_sides`] sides, open at its ends, with its rings turning with the
//!   sections at its two nodes (a direction normal to the element at the first snapshot,
//!   carried by each node's rotation), then its centre line. Points: per element, the ring
//!   around node A, the ring around node B, then the two nodes. Cells: the tubes' triangles
//!   (`2 sides` per element, element after element), then one line per element. Cell data,
//!   one scalar `Float64` array per component of the element's strains and stress resultants
//!   ([`crate::Snapshot::beam_strain`], [`crate::Snapshot::beam_stress`], section frame),
//!   the same on every cell of an element: `axial_strain`, `shear_strain_2`,
//!   `shear_strain_3`, `torsion`, `curvature_2`, `curvature_3`, `axial_force`,
//!   `shear_force_2`, `shear_force_3`, `torque`, `bending_moment_2`, `bending_moment_3`;
//!   and `Int32` ids: `element` (index in [`ModelInfo::beams`]) and `member` (index of its
//!   `[[beam]]`, numbered in order of first appearance in [`ModelInfo::beams`]).
//! - `bodies_k.vtu`: every display shape ([`ModelInfo::shapes`]) triangulated by
//!   [`geometry::triangles`] and placed by its node's configuration at the snapshot composed
//!   with the shape's placement. Points: shape after shape, its vertices. Cells: its
//!   triangles. Cell data: `colour` (`UInt8`, 3 components, the shape's colour times 255),
//!   `shape` (index in [`ModelInfo::shapes`]), `node` (index in [`ModelInfo::nodes`]) and
//!   `body` (index in [`ModelInfo::bodies`] of the body on that node, -1 for none), `Int32`.
//! - `frames_k.vtu`: a triad per node, its three axes as lines from the node, all of the
//!   same length, 5 % of the model's size (the diagonal of the box around the nodes of all
//!   snapshots, or the largest shape when that is larger). Points: per node its origin and
//!   the tips of its x, y and z axes. Cells: per node the lines to the three tips. Cell
//!   data: `axis` (0, 1, 2), `node` (`Int32`) and `colour` (`UInt8`: red, green, blue for
//!   x, y, z).
//! - `joints_k.vtu`: a vertex per joint at its point
//!   ([`crate::Snapshot::joint_position`]). Point data: `force` and `torque` (`Float64`, 3
//!   components: the reaction on node B, inertial, torque about the joint's point) and
//!   `joint` (`Int32`, index in [`ModelInfo::joints`]).
//!
//! A kind the model has none of (no beam, no joint, no shape with a triangle, ...) is not
//! written. `results.pvd` lists
//! every file with `timestep` = [`crate::Snapshot::at`] (time or load factor), `part` = the
//! kind's rank among those written and `name` = the kind; `<kind>.pvd` lists one kind's.
//!
//! The files are VTK XML `UnstructuredGrid` version 1.0, little endian, `UInt64` headers,
//! connectivity and offsets in `Int64`. The data arrays are inline, base64-encoded binary by
//! default, or ASCII ([`Encoding`]). Both hold the numbers to the bit (ASCII floats in their
//! shortest exact form) and come to about the same size (binary floats are shorter, binary
//! `Int64` indices longer: 1 to 1.5 MB per snapshot for the 1000-link chain); binary is the
//! quicker for Paraview to read. Each file is streamed through a buffered writer as it is
//! computed. Files of an earlier export that this one does not list (more snapshots, another
//! kind) are left in the directory.

use crate::geometry::{self, Placement};
use crate::info::{BeamInfo, ModelInfo};
use crate::{Results, Snapshot};
use flexmb_lie::{so3, Mat3, Vec3};
use std::fs::{self, File};
use std::io::{self, BufWriter, Write};
use std::iter::repeat_n;
use std::path::{Path, PathBuf};

/// Sides of a beam's tube by default.
pub const TUBE_SIDES: usize = 12;

/// How the data arrays are written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Encoding {
    /// `format="binary"`: little-endian bytes, base64-encoded, inline.
    #[default]
    Binary,
    /// `format="ascii"`: numbers as text (floats in their shortest exact form).
    Ascii,
}

/// Options of [`export_vtk_with`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VtkOptions {
    pub encoding: Encoding,
    /// Sides of a beam's tube (at least 3).
    pub tube_sides: usize,
}

impl Default for VtkOptions {
    fn default() -> Self {
        Self {
            encoding: Encoding::Binary,
            tube_sides: TUBE_SIDES,
        }
    }
}

/// What [`export_vtk`] wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VtkSeries {
    /// `results.pvd`: every piece of every snapshot.
    pub pvd: PathBuf,
    /// The collection of each kind written (`beams.pvd`, `bodies.pvd`, `frames.pvd`,
    /// `joints.pvd`, those the model has), in that order.
    pub kinds: Vec<PathBuf>,
    /// Number of `.vtu` files written.
    pub files: usize,
}

#[derive(Debug, thiserror::Error)]
pub enum VtkError {
    #[error("cannot create the directory {}: {source}", path.display())]
    Directory {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    #[error("cannot write {}: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    /// The snapshots do not match the model's metadata (a truncated or foreign file).
    #[error("the results do not hold together: {0}")]
    Inconsistent(String),
}

/// Writes the Paraview series of `results` into `dir` (created if needed), binary-encoded,
/// with tubes of [`TUBE_SIDES`] sides. See the module documentation for what is written.
pub fn export_vtk(results: &Results, dir: &Path) -> Result<VtkSeries, VtkError> {
    export_vtk_with(results, dir, &VtkOptions::default())
}

/// [`export_vtk`] with other options.
pub fn export_vtk_with(
    results: &Results,
    dir: &Path,
    options: &VtkOptions,
) -> Result<VtkSeries, VtkError> {
    check(results)?;
    fs::create_dir_all(dir).map_err(|source| VtkError::Directory {
        path: dir.to_path_buf(),
        source,
    })?;
    let scene = Scene::new(results, options.tube_sides.max(3));
    let kinds: Vec<Kind> = Kind::ALL.into_iter().filter(|k| scene.has(*k)).collect();
    let mut files = 0;
    for (index, snap) in results.snapshots.iter().enumerate() {
        for &kind in &kinds {
            let path = dir.join(kind.file(index));
            write_file(&path, |w| {
                let mut vtu = Vtu {
                    w,
                    encoding: options.encoding,
                };
                scene.write(kind, snap, &mut vtu)
            })?;
            files += 1;
        }
    }
    let pvd = dir.join("results.pvd");
    write_file(&pvd, |w| write_collection(w, results, &kinds, true))?;
    let mut paths = Vec::new();
    for &kind in &kinds {
        let path = dir.join(format!("{}.pvd", kind.name()));
        write_file(&path, |w| write_collection(w, results, &[kind], false))?;
        paths.push(path);
    }
    Ok(VtkSeries {
        pvd,
        kinds: paths,
        files,
    })
}

/// The sizes of the snapshots against the model's.
fn check(results: &Results) -> Result<(), VtkError> {
    let info = &results.info;
    let nodes = info.nodes.len();
    let bad = |what: String| Err(VtkError::Inconsistent(what));
    for (k, s) in info.shapes.iter().enumerate() {
        if s.node >= nodes {
            return bad(format!("shape {k} is on node {}, of {nodes}", s.node));
        }
        if let Some(t) = s
            .triangles
            .iter()
            .flatten()
            .find(|&&i| i as usize >= s.vertices.len())
        {
            return bad(format!(
                "shape {k} has a triangle on vertex {t}, of {}",
                s.vertices.len()
            ));
        }
    }
    if let Some((k, b)) = info
        .beams
        .iter()
        .enumerate()
        .find(|(_, b)| b.nodes.iter().any(|&n| n >= nodes))
    {
        return bad(format!(
            "beam element {k} ({}) has a node out of {nodes}",
            b.name
        ));
    }
    for (k, s) in results.snapshots.iter().enumerate() {
        let sizes = [
            ("node positions", s.position.len(), nodes),
            ("node orientations", s.orientation.len(), nodes),
            ("joint positions", s.joint_position.len(), info.joints.len()),
            ("joint reactions", s.joint_reaction.len(), info.joints.len()),
            ("beam strains", s.beam_strain.len(), info.beams.len()),
            ("beam stresses", s.beam_stress.len(), info.beams.len()),
        ];
        if let Some((what, has, wants)) = sizes.iter().find(|(_, has, wants)| has != wants) {
            return bad(format!("snapshot {k} has {has} {what}, the model {wants}"));
        }
    }
    Ok(())
}

/// Creates `path`, lets `body` write it through a buffer and flushes it.
fn write_file(
    path: &Path,
    body: impl FnOnce(&mut BufWriter<File>) -> io::Result<()>,
) -> Result<(), VtkError> {
    let run = || {
        let mut w = BufWriter::with_capacity(1 << 16, File::create(path)?);
        body(&mut w)?;
        w.flush()
    };
    run().map_err(|source| VtkError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// The kinds of pieces, in the order they are listed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Beams,
    Bodies,
    Frames,
    Joints,
}

impl Kind {
    const ALL: [Kind; 4] = [Kind::Beams, Kind::Bodies, Kind::Frames, Kind::Joints];

    fn name(self) -> &'static str {
        match self {
            Kind::Beams => "beams",
            Kind::Bodies => "bodies",
            Kind::Frames => "frames",
            Kind::Joints => "joints",
        }
    }

    fn file(self, index: usize) -> String {
        format!("{}_{index:06}.vtu", self.name())
    }
}

/// A `.pvd` collection of the files of `kinds`, snapshot after snapshot; `named`: each with
/// its part number and kind.
fn write_collection(
    w: &mut impl Write,
    results: &Results,
    kinds: &[Kind],
    named: bool,
) -> io::Result<()> {
    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(
        w,
        "<VTKFile type=\"Collection\" version=\"1.0\" byte_order=\"LittleEndian\" \
         header_type=\"UInt64\">"
    )?;
    writeln!(w, "  <Collection>")?;
    for (index, snap) in results.snapshots.iter().enumerate() {
        for (part, kind) in kinds.iter().enumerate() {
            write!(w, "    <DataSet timestep=\"")?;
            write_f64(w, snap.at)?;
            if named {
                write!(w, "\" part=\"{part}\" name=\"{}", kind.name())?;
            } else {
                write!(w, "\" part=\"0")?;
            }
            writeln!(w, "\" file=\"{}\"/>", kind.file(index))?;
        }
    }
    writeln!(w, "  </Collection>")?;
    writeln!(w, "</VTKFile>")
}

const VTK_VERTEX: u8 = 1;
const VTK_LINE: u8 = 3;
const VTK_TRIANGLE: u8 = 5;

/// A shape ready to draw: its surface in its frame, placed on its node.
struct ShapeMesh {
    vertices: Vec<[f64; 3]>,
    triangles: Vec<[u32; 3]>,
    placement: Placement,
    node: usize,
    colour: [u8; 3],
    body: i32,
}

/// What every snapshot's pieces share.
struct Scene<'a> {
    info: &'a ModelInfo,
    sides: usize,
    shapes: Vec<ShapeMesh>,
    /// Per beam element: the direction its rings start along, in the frames of its nodes.
    references: Vec<[Vec3; 2]>,
    /// Per beam element: the index of its member.
    members: Vec<i32>,
    /// Length of a node triad's axes \[m\].
    triad: f64,
}

impl<'a> Scene<'a> {
    fn new(results: &'a Results, sides: usize) -> Self {
        let info = &results.info;
        let shapes: Vec<ShapeMesh> = info
            .shapes
            .iter()
            .map(|s| {
                let (vertices, triangles) = geometry::triangles(s);
                ShapeMesh {
                    vertices,
                    triangles,
                    placement: Placement::shape(s),
                    node: s.node,
                    colour: s.colour.map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8),
                    body: info
                        .bodies
                        .iter()
                        .position(|b| b.node == s.node)
                        .map_or(-1, |b| b as i32),
                }
            })
            .collect();
        let references = match results.snapshots.first() {
            Some(first) => info.beams.iter().map(|b| reference(b, first)).collect(),
            None => Vec::new(),
        };
        let mut names: Vec<&str> = Vec::new();
        let members = info
            .beams
            .iter()
            .map(|b| {
                let k = names
                    .iter()
                    .position(|&m| m == b.member)
                    .unwrap_or_else(|| {
                        names.push(&b.member);
                        names.len() - 1
                    });
                k as i32
            })
            .collect();
        Self {
            info,
            sides,
            triad: 0.05 * size(results, &shapes),
            shapes,
            references,
            members,
        }
    }

    fn has(&self, kind: Kind) -> bool {
        match kind {
            Kind::Beams => !self.info.beams.is_empty(),
            Kind::Bodies => self.shapes.iter().any(|s| !s.triangles.is_empty()),
            Kind::Frames => !self.info.nodes.is_empty(),
            Kind::Joints => !self.info.joints.is_empty(),
        }
    }

    fn write(&self, kind: Kind, snap: &Snapshot, vtu: &mut Vtu<impl Write>) -> io::Result<()> {
        match kind {
            Kind::Beams => self.beams(snap, vtu),
            Kind::Bodies => self.bodies(snap, vtu),
            Kind::Frames => self.frames(snap, vtu),
            Kind::Joints => self.joints(snap, vtu),
        }
    }

    fn beams(&self, snap: &Snapshot, vtu: &mut Vtu<impl Write>) -> io::Result<()> {
        let beams = &self.info.beams;
        let (n, s) = (beams.len(), self.sides);
        let block = 2 * s + 2;
        let (tris, cells) = (2 * s * n, 2 * s * n + n);
        vtu.begin(block * n, cells)?;
        vtu.open("CellData")?;
        for (c, name) in flexmb::output::BEAM_QUANTITIES.iter().enumerate() {
            let value = |e: usize| {
                if c < 6 {
                    snap.beam_strain[e][c]
                } else {
                    snap.beam_stress[e][c - 6]
                }
            };
            vtu.array(name, 1, cells, per_element(n, s, value))?;
        }
        vtu.array("element", 1, cells, per_element(n, s, |e| e as i32))?;
        vtu.array("member", 1, cells, per_element(n, s, |e| self.members[e]))?;
        vtu.close("CellData")?;
        vtu.open("Points")?;
        let points = beams.iter().zip(&self.references).flat_map(|(b, r)| {
            let [xa, xb] = b.nodes.map(|k| snap.position[k]);
            let refs = [0, 1].map(|end| (rotation(snap, b.nodes[end]) * r[end]).into());
            let mut p = geometry::tube(xa, xb, refs, b.radius, s);
            p.push(xa);
            p.push(xb);
            p.into_iter().flatten()
        });
        vtu.array("Points", 3, 3 * block * n, points)?;
        vtu.close("Points")?;
        let tube: Vec<[u32; 3]> = geometry::tube_triangles(s).collect();
        let connectivity = (0..n)
            .flat_map(|e| {
                let base = (e * block) as i64;
                tube.iter().flatten().map(move |&i| base + i as i64)
            })
            .chain((0..n).flat_map(|e| {
                let centre = (e * block + 2 * s) as i64;
                [centre, centre + 1]
            }));
        let offsets = (1..=tris)
            .map(|c| 3 * c as i64)
            .chain((1..=n).map(|e| (3 * tris + 2 * e) as i64));
        let types = repeat_n(VTK_TRIANGLE, tris).chain(repeat_n(VTK_LINE, n));
        vtu.cells(3 * tris + 2 * n, connectivity, cells, offsets, types)?;
        vtu.end()
    }

    fn bodies(&self, snap: &Snapshot, vtu: &mut Vtu<impl Write>) -> io::Result<()> {
        let points: usize = self.shapes.iter().map(|s| s.vertices.len()).sum();
        let cells: usize = self.shapes.iter().map(|s| s.triangles.len()).sum();
        vtu.begin(points, cells)?;
        vtu.open("CellData")?;
        let colour = per_shape(&self.shapes, |_, s| s.colour).flatten();
        vtu.array("colour", 3, 3 * cells, colour)?;
        vtu.array("shape", 1, cells, per_shape(&self.shapes, |k, _| k as i32))?;
        vtu.array(
            "node",
            1,
            cells,
            per_shape(&self.shapes, |_, s| s.node as i32),
        )?;
        vtu.array("body", 1, cells, per_shape(&self.shapes, |_, s| s.body))?;
        vtu.close("CellData")?;
        vtu.open("Points")?;
        let placed = self.shapes.iter().flat_map(|s| {
            let node = Placement::node(snap.position[s.node], snap.orientation[s.node]);
            let at = node.then(&s.placement);
            s.vertices.iter().flat_map(move |&v| at.apply(v))
        });
        vtu.array("Points", 3, 3 * points, placed)?;
        vtu.close("Points")?;
        let mut first = 0i64;
        let connectivity = self.shapes.iter().flat_map(|s| {
            let base = first;
            first += s.vertices.len() as i64;
            s.triangles.iter().flatten().map(move |&i| base + i as i64)
        });
        let offsets = (1..=cells).map(|c| 3 * c as i64);
        let types = repeat_n(VTK_TRIANGLE, cells);
        vtu.cells(3 * cells, connectivity, cells, offsets, types)?;
        vtu.end()
    }

    fn frames(&self, snap: &Snapshot, vtu: &mut Vtu<impl Write>) -> io::Result<()> {
        let n = self.info.nodes.len();
        vtu.begin(4 * n, 3 * n)?;
        vtu.open("CellData")?;
        vtu.array("axis", 1, 3 * n, (0..3 * n).map(|c| (c % 3) as i32))?;
        vtu.array("node", 1, 3 * n, (0..3 * n).map(|c| (c / 3) as i32))?;
        let rgb = (0..3 * n).flat_map(|c| {
            let mut colour = [0u8; 3];
            colour[c % 3] = 255;
            colour
        });
        vtu.array("colour", 3, 9 * n, rgb)?;
        vtu.close("CellData")?;
        vtu.open("Points")?;
        let points = (0..n).flat_map(|k| {
            let node = Placement::node(snap.position[k], snap.orientation[k]);
            let mut p = [node.apply([0.0; 3]); 4];
            for axis in 0..3 {
                let mut tip = [0.0; 3];
                tip[axis] = self.triad;
                p[axis + 1] = node.apply(tip);
            }
            p.into_iter().flatten()
        });
        vtu.array("Points", 3, 12 * n, points)?;
        vtu.close("Points")?;
        let connectivity = (0..n).flat_map(|k| {
            let o = 4 * k as i64;
            [o, o + 1, o, o + 2, o, o + 3]
        });
        let offsets = (1..=3 * n).map(|c| 2 * c as i64);
        vtu.cells(
            6 * n,
            connectivity,
            3 * n,
            offsets,
            repeat_n(VTK_LINE, 3 * n),
        )?;
        vtu.end()
    }

    fn joints(&self, snap: &Snapshot, vtu: &mut Vtu<impl Write>) -> io::Result<()> {
        let n = self.info.joints.len();
        vtu.begin(n, n)?;
        vtu.open("PointData")?;
        let force = snap.joint_reaction.iter().flat_map(|r| [r[0], r[1], r[2]]);
        vtu.array("force", 3, 3 * n, force)?;
        let torque = snap.joint_reaction.iter().flat_map(|r| [r[3], r[4], r[5]]);
        vtu.array("torque", 3, 3 * n, torque)?;
        vtu.array("joint", 1, n, (0..n).map(|k| k as i32))?;
        vtu.close("PointData")?;
        vtu.open("Points")?;
        let points = snap.joint_position.iter().flatten().copied();
        vtu.array("Points", 3, 3 * n, points)?;
        vtu.close("Points")?;
        let ids = (0..n).map(|k| k as i64);
        let offsets = (1..=n).map(|k| k as i64);
        vtu.cells(n, ids, n, offsets, repeat_n(VTK_VERTEX, n))?;
        vtu.end()
    }
}

/// Element `e`'s value `f(e)` on every cell of the beams' piece: its tube's `2 sides`
/// triangles, element after element, then (after all triangles) its line.
fn per_element<T: Copy>(
    n: usize,
    sides: usize,
    f: impl Fn(usize) -> T + Copy,
) -> impl Iterator<Item = T> {
    (0..n)
        .flat_map(move |e| repeat_n(f(e), 2 * sides))
        .chain((0..n).map(f))
}

/// Shape `k`'s value `f(k, shape)` on each of its triangles, shape after shape.
fn per_shape<'a, T: Copy + 'a>(
    shapes: &'a [ShapeMesh],
    f: impl Fn(usize, &ShapeMesh) -> T + 'a,
) -> impl Iterator<Item = T> + 'a {
    shapes
        .iter()
        .enumerate()
        .flat_map(move |(k, s)| repeat_n(f(k, s), s.triangles.len()))
}

/// The rotation of node `k` at `snap` (node to inertial).
fn rotation(snap: &Snapshot, k: usize) -> Mat3 {
    so3::from_quaternion(snap.orientation[k])
}

/// The direction a beam element's rings start along, in the frames of its two nodes: a
/// normal to the element at the first snapshot ([`geometry::perpendicular`]).
fn reference(beam: &BeamInfo, first: &Snapshot) -> [Vec3; 2] {
    let [a, b] = beam.nodes.map(|k| Vec3::from(first.position[k]));
    let d = (b - a).try_normalize(0.0).unwrap_or_else(Vec3::x);
    let normal = geometry::perpendicular(&d);
    beam.nodes.map(|k| rotation(first, k).transpose() * normal)
}

/// The model's size: the diagonal of the box around the nodes of all snapshots, or the
/// diagonal of the largest shape when that is larger; 1 m for a model of neither.
fn size(results: &Results, shapes: &[ShapeMesh]) -> f64 {
    let mut lo = Vec3::repeat(f64::INFINITY);
    let mut hi = Vec3::repeat(f64::NEG_INFINITY);
    for p in results.snapshots.iter().flat_map(|s| &s.position) {
        let p = Vec3::from(*p);
        lo = lo.inf(&p);
        hi = hi.sup(&p);
    }
    let nodes = if lo.x <= hi.x { (hi - lo).norm() } else { 0.0 };
    let largest = shapes
        .iter()
        .map(|s| {
            let (lo, hi) = s.vertices.iter().fold(
                (Vec3::repeat(f64::INFINITY), Vec3::repeat(f64::NEG_INFINITY)),
                |(lo, hi), v| (lo.inf(&Vec3::from(*v)), hi.sup(&Vec3::from(*v))),
            );
            if s.vertices.is_empty() {
                0.0
            } else {
                (hi - lo).norm()
            }
        })
        .fold(0.0, f64::max);
    let size = nodes.max(largest);
    if size > 0.0 && size.is_finite() {
        size
    } else {
        1.0
    }
}

/// A number written in a data array.
trait Value: Copy {
    /// The VTK type name.
    const TYPE: &'static str;
    /// Its little-endian bytes.
    fn bytes(self, f: impl FnMut(&[u8]));
    /// Its text.
    fn text(self, w: &mut impl Write) -> io::Result<()>;
}

impl Value for f64 {
    const TYPE: &'static str = "Float64";
    fn bytes(self, mut f: impl FnMut(&[u8])) {
        f(&self.to_le_bytes())
    }
    fn text(self, w: &mut impl Write) -> io::Result<()> {
        write_f64(w, self)
    }
}

macro_rules! integer_value {
    ($t:ty, $name:literal) => {
        impl Value for $t {
            const TYPE: &'static str = $name;
            fn bytes(self, mut f: impl FnMut(&[u8])) {
                f(&self.to_le_bytes())
            }
            fn text(self, w: &mut impl Write) -> io::Result<()> {
                write!(w, "{self}")
            }
        }
    };
}
integer_value!(i64, "Int64");
integer_value!(i32, "Int32");
integer_value!(u8, "UInt8");

/// A float in its shortest form that reads back to the same bits; in exponent form outside
/// `[1e-4, 1e15)` so that no number is written with dozens of zeros. Not-a-number and the
/// infinities as `nan`, `inf`, `-inf`.
fn write_f64(w: &mut impl Write, x: f64) -> io::Result<()> {
    let a = x.abs();
    if x.is_nan() {
        write!(w, "nan")
    } else if x == 0.0 || (1e-4..1e15).contains(&a) || a.is_infinite() {
        write!(w, "{x}")
    } else {
        write!(w, "{x:e}")
    }
}

/// One `.vtu` file being written: the calls go `begin`, then sections (`open`, arrays,
/// `close`), then `cells`, then `end`.
struct Vtu<W: Write> {
    w: W,
    encoding: Encoding,
}

impl<W: Write> Vtu<W> {
    fn begin(&mut self, points: usize, cells: usize) -> io::Result<()> {
        writeln!(self.w, "<?xml version=\"1.0\"?>")?;
        writeln!(
            self.w,
            "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" \
             header_type=\"UInt64\">"
        )?;
        writeln!(self.w, "  <UnstructuredGrid>")?;
        writeln!(
            self.w,
            "    <Piece NumberOfPoints=\"{points}\" NumberOfCells=\"{cells}\">"
        )
    }

    fn open(&mut self, section: &str) -> io::Result<()> {
        writeln!(self.w, "      <{section}>")
    }

    fn close(&mut self, section: &str) -> io::Result<()> {
        writeln!(self.w, "      </{section}>")
    }

    /// A data array of `len` numbers (`len / components` tuples) taken from `values`.
    fn array<T: Value>(
        &mut self,
        name: &str,
        components: usize,
        len: usize,
        values: impl IntoIterator<Item = T>,
    ) -> io::Result<()> {
        let format = match self.encoding {
            Encoding::Binary => "binary",
            Encoding::Ascii => "ascii",
        };
        writeln!(
            self.w,
            "        <DataArray type=\"{}\" Name=\"{name}\" NumberOfComponents=\"{components}\" \
             format=\"{format}\">",
            T::TYPE
        )?;
        write!(self.w, "          ")?;
        let mut count = 0;
        match self.encoding {
            Encoding::Binary => {
                use base64::engine::general_purpose::STANDARD;
                let bytes = len * std::mem::size_of::<T>();
                let mut b64 = base64::write::EncoderWriter::new(&mut self.w, &STANDARD);
                b64.write_all(&(bytes as u64).to_le_bytes())?;
                let mut buffer = Vec::with_capacity(BINARY_CHUNK + 16);
                for v in values {
                    count += 1;
                    v.bytes(|b| buffer.extend_from_slice(b));
                    if buffer.len() >= BINARY_CHUNK {
                        b64.write_all(&buffer)?;
                        buffer.clear();
                    }
                }
                b64.write_all(&buffer)?;
                b64.finish()?;
            }
            Encoding::Ascii => {
                for v in values {
                    if count > 0 {
                        let gap = if count % (3 * components.max(2)) == 0 {
                            "\n          "
                        } else {
                            " "
                        };
                        self.w.write_all(gap.as_bytes())?;
                    }
                    v.text(&mut self.w)?;
                    count += 1;
                }
            }
        }
        if count != len {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!("array {name}: {count} values written, {len} announced"),
            ));
        }
        writeln!(self.w)?;
        writeln!(self.w, "        </DataArray>")
    }

    /// The `Cells` section: `connectivity` (`links` point indices), `offsets` (the end of
    /// each of the `cells` cells in it) and `types`.
    fn cells(
        &mut self,
        links: usize,
        connectivity: impl IntoIterator<Item = i64>,
        cells: usize,
        offsets: impl IntoIterator<Item = i64>,
        types: impl IntoIterator<Item = u8>,
    ) -> io::Result<()> {
        self.open("Cells")?;
        self.array("connectivity", 1, links, connectivity)?;
        self.array("offsets", 1, cells, offsets)?;
        self.array("types", 1, cells, types)?;
        self.close("Cells")
    }

    fn end(&mut self) -> io::Result<()> {
        writeln!(self.w, "    </Piece>")?;
        writeln!(self.w, "  </UnstructuredGrid>")?;
        writeln!(self.w, "</VTKFile>")
    }
}

/// Bytes of a binary array encoded at a time.
const BINARY_CHUNK: usize = 3 * 4096;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_are_written_to_read_back_exactly() {
        for x in [
            0.0,
            -0.0,
            1.0,
            0.1,
            -2.5e-7,
            1e-4,
            123456.789,
            1e15,
            6.02e23,
            f64::MIN_POSITIVE,
        ] {
            let mut s = Vec::new();
            write_f64(&mut s, x).unwrap();
            let s = String::from_utf8(s).unwrap();
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), x.to_bits(), "{s}");
            assert!(s.len() < 25, "{s}");
        }
    }
}
