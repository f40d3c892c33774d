//! The Paraview series, read back by readers that owe it nothing: Python's `xml.etree` for the
//! collection and `meshio` for every `.vtu` it lists (tests/read_vtk.py). The tests that read
//! the files need `python3` with meshio (`pip install meshio`; another interpreter through
//! `FLEXMB_PYTHON`) and fail when it is missing.

use flexmb::input::{Analysis, ModelFile};
use flexmb_results::info::ShapeInfo;
use flexmb_results::vtk::{export_vtk_with, Encoding, VtkOptions, TUBE_SIDES};
use flexmb_results::{export_vtk, Results, Snapshot, VtkError, VtkSeries};
use serde::Deserialize;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::process::Command;

fn model(name: &str, t_end: f64) -> ModelFile {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name);
    let mut file = flexmb::input::read_model_file(&path, &[]).expect("the example reads");
    if let Analysis::Dynamic(s) = &mut file.analysis {
        s.t_end = t_end;
    }
    file
}

fn collect(name: &str, t_end: f64) -> Results {
    collect_file(&model(name, t_end))
}

fn collect_file(file: &ModelFile) -> Results {
    let (results, error) = Results::collect(file);
    assert!(error.is_none(), "{error:?}");
    assert!(!results.snapshots.is_empty());
    results
}

/// The heavy top without the display shapes of its file: drawn as its default inertia box.
fn bare_top(t_end: f64) -> Results {
    let mut file = model("heavy_top.toml", t_end);
    file.model.display = Default::default();
    collect_file(&file)
}

/// An empty directory of its own for a test.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join("vtk")
        .join(name);
    if dir.exists() {
        std::fs::remove_dir_all(&dir).unwrap();
    }
    dir
}

/// What tests/read_vtk.py found.
#[derive(Debug, Deserialize, PartialEq)]
struct Dump {
    header: HashMap<String, String>,
    datasets: Vec<DataSet>,
}

#[derive(Debug, Deserialize, PartialEq)]
struct DataSet {
    timestep: String,
    part: String,
    name: Option<String>,
    file: String,
    header: HashMap<String, String>,
    /// VTK type of each data array, by name.
    types: HashMap<String, String>,
    points: Vec<[f64; 3]>,
    /// Cell blocks in file order: meshio's type name and the point indices of each cell.
    cells: Vec<(String, Vec<Vec<i64>>)>,
    /// One row per point (cell) of each array.
    point_data: HashMap<String, Vec<Vec<f64>>>,
    cell_data: HashMap<String, Vec<Vec<f64>>>,
}

impl DataSet {
    fn cells(&self) -> Vec<(&str, &[i64])> {
        self.cells
            .iter()
            .flat_map(|(t, c)| c.iter().map(move |c| (t.as_str(), c.as_slice())))
            .collect()
    }
    fn cell(&self, name: &str) -> &[Vec<f64>] {
        self.cell_data
            .get(name)
            .unwrap_or_else(|| panic!("{}: no cell array {name}", self.file))
    }
    fn point(&self, name: &str) -> &[Vec<f64>] {
        self.point_data
            .get(name)
            .unwrap_or_else(|| panic!("{}: no point array {name}", self.file))
    }
}

fn read_back(pvd: &Path) -> Dump {
    let python = std::env::var("FLEXMB_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/read_vtk.py");
    let out = Command::new(&python)
        .arg(&script)
        .arg(pvd)
        .output()
        .unwrap_or_else(|e| {
            panic!(
                "this test reads the .vtu files back with Python's meshio, and `{python}` \
                 cannot be run ({e}): install python3 and `pip install meshio`, or set \
                 FLEXMB_PYTHON"
            )
        });
    let stderr = String::from_utf8_lossy(&out.stderr);
    match out.status.code() {
        Some(0) => {}
        Some(3) => panic!(
            "this test reads the .vtu files back with Python's meshio, which `{python}` \
             does not have: `pip install meshio` ({})",
            stderr.trim()
        ),
        _ => panic!("{} failed on {}: {stderr}", script.display(), pvd.display()),
    }
    serde_json::from_slice(&out.stdout).expect("read_vtk.py prints JSON")
}

/// The timesteps of a `.pvd`, read with nothing but string search.
fn timesteps(pvd: &Path) -> Vec<(f64, String)> {
    let text = std::fs::read_to_string(pvd).unwrap();
    let attr = |line: &str, name: &str| {
        let start = line.find(&format!("{name}=\"")).unwrap() + name.len() + 2;
        line[start..start + line[start..].find('"').unwrap()].to_string()
    };
    text.lines()
        .filter(|l| l.contains("<DataSet"))
        .map(|l| (attr(l, "timestep").parse().unwrap(), attr(l, "file")))
        .collect()
}

/// Node-to-inertial rotation of a unit quaternion `w, x, y, z`, written out here rather than
/// taken from the crates.
fn rotation(q: [f64; 4]) -> [[f64; 3]; 3] {
    let [w, x, y, z] = q;
    [
        [
            w * w + x * x - y * y - z * z,
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            w * w - x * x + y * y - z * z,
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            w * w - x * x - y * y + z * z,
        ],
    ]
}

fn mul(r: &[[f64; 3]; 3], v: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| (0..3).map(|j| r[i][j] * v[j]).sum())
}

fn add(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| a[i] + b[i])
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| a[i] - b[i])
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|i| a[i] * b[i]).sum()
}

fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

/// Where a point given in `shape`'s frame is at `snap`.
fn place(snap: &Snapshot, shape: &ShapeInfo, p: [f64; 3]) -> [f64; 3] {
    let node = rotation(snap.orientation[shape.node]);
    let local = add(shape.position, mul(&rotation(shape.orientation), p));
    add(snap.position[shape.node], mul(&node, local))
}

/// The 8 corners of a box shape, in its shape frame.
fn corners(shape: &ShapeInfo) -> Vec<[f64; 3]> {
    let h = shape.size.map(|s| s / 2.0);
    let signs = [-1.0, 1.0];
    let mut c = Vec::new();
    for sx in signs {
        for sy in signs {
            for sz in signs {
                c.push([sx * h[0], sy * h[1], sz * h[2]]);
            }
        }
    }
    c
}

/// Each of `expected` is one of `points` (to `tol`), and as many.
fn same_points(points: &[[f64; 3]], expected: &[[f64; 3]], tol: f64) {
    assert_eq!(points.len(), expected.len());
    for e in expected {
        assert!(
            points.iter().any(|p| norm(sub(*p, *e)) < tol),
            "no point at {e:?} in {points:?}"
        );
    }
}

/// The checks every series passes: the collection and its timesteps, the file headers, one
/// file per kind written and snapshot, the cells' types.
fn check_series(results: &Results, series: &VtkSeries, dump: &Dump, kinds: &[&str]) {
    let n = results.snapshots.len();
    assert!(n >= 3, "a series of a few snapshots: {n}");
    assert_eq!(series.files, n * kinds.len());
    assert_eq!(dump.header["type"], "Collection");
    assert_eq!(dump.datasets.len(), n * kinds.len());
    let listed = timesteps(&series.pvd);
    assert_eq!(listed.len(), n * kinds.len());
    for (k, (snap, group)) in results
        .snapshots
        .iter()
        .zip(dump.datasets.chunks(kinds.len()))
        .enumerate()
    {
        for (part, (d, kind)) in group.iter().zip(kinds).enumerate() {
            assert_eq!(
                d.timestep.parse::<f64>().unwrap().to_bits(),
                snap.at.to_bits()
            );
            assert_eq!(d.part, part.to_string());
            assert_eq!(d.name.as_deref(), Some(*kind));
            assert_eq!(d.file, format!("{kind}_{k:06}.vtu"));
            let (t, file) = &listed[k * kinds.len() + part];
            assert_eq!((t.to_bits(), file), (snap.at.to_bits(), &d.file));
            let h = &d.header;
            assert_eq!(
                (
                    h["type"].as_str(),
                    h["version"].as_str(),
                    h["byte_order"].as_str(),
                    h["header_type"].as_str()
                ),
                ("UnstructuredGrid", "1.0", "LittleEndian", "UInt64")
            );
            assert_eq!(d.types["connectivity"], "Int64");
            assert_eq!(d.types["offsets"], "Int64");
            assert_eq!(d.types["types"], "UInt8");
            assert_eq!(d.types["Points"], "Float64");
        }
    }
    // One collection per kind, listing that kind's files at the same times.
    assert_eq!(series.kinds.len(), kinds.len());
    for (path, kind) in series.kinds.iter().zip(kinds) {
        assert_eq!(path.file_name().unwrap(), format!("{kind}.pvd").as_str());
        let own = timesteps(path);
        assert_eq!(own.len(), n);
        for (k, (t, file)) in own.iter().enumerate() {
            assert_eq!(t.to_bits(), results.snapshots[k].at.to_bits());
            assert_eq!(file, &format!("{kind}_{k:06}.vtu"));
        }
    }
    for kind in ["beams", "bodies", "frames", "joints"] {
        let dir = series.pvd.parent().unwrap();
        assert_eq!(
            dir.join(format!("{kind}_000000.vtu")).exists(),
            kinds.contains(&kind)
        );
    }
}

/// The datasets of one kind, snapshot after snapshot.
fn of_kind<'a>(dump: &'a Dump, kind: &str) -> Vec<&'a DataSet> {
    dump.datasets
        .iter()
        .filter(|d| d.name.as_deref() == Some(kind))
        .collect()
}

/// The node triads: origin and three tips per node, the axes along the node's rotation, all
/// of one length.
fn check_frames(results: &Results, dump: &Dump) {
    let nodes = results.info.nodes.len();
    let mut length = None;
    for (snap, d) in results.snapshots.iter().zip(of_kind(dump, "frames")) {
        assert_eq!(d.points.len(), 4 * nodes);
        let cells = d.cells();
        assert_eq!(cells.len(), 3 * nodes);
        let (axis, node, colour) = (d.cell("axis"), d.cell("node"), d.cell("colour"));
        for (c, (kind, points)) in cells.iter().enumerate() {
            let (k, a) = (c / 3, c % 3);
            assert_eq!(*kind, "line");
            assert_eq!((axis[c][0], node[c][0]), (a as f64, k as f64));
            let mut rgb = [0.0; 3];
            rgb[a] = 255.0;
            assert_eq!(colour[c], rgb);
            let [o, tip] = [points[0], points[1]].map(|i| d.points[i as usize]);
            assert_eq!(o, snap.position[k]);
            let r = rotation(snap.orientation[k]);
            let arm = sub(tip, o);
            let l = *length.get_or_insert(norm(arm));
            assert!((norm(arm) - l).abs() < 1e-12 * l);
            let along = [r[0][a], r[1][a], r[2][a]];
            assert!(norm(sub(arm, along.map(|x| x * l))) < 1e-12 * l);
        }
    }
}

/// The joints: a vertex each at its point, with its reaction.
fn check_joints(results: &Results, dump: &Dump) {
    let n = results.info.joints.len();
    for (snap, d) in results.snapshots.iter().zip(of_kind(dump, "joints")) {
        assert_eq!(d.points, snap.joint_position);
        assert_eq!(d.cells().len(), n);
        for (k, (kind, points)) in d.cells().into_iter().enumerate() {
            assert_eq!((kind, points), ("vertex", &[k as i64][..]));
            let r = snap.joint_reaction[k];
            assert_eq!(d.point("force")[k], r[..3]);
            assert_eq!(d.point("torque")[k], r[3..]);
            assert_eq!(d.point("joint")[k], [k as f64]);
        }
        assert_eq!(d.types["force"], "Float64");
        assert_eq!(d.types["joint"], "Int32");
    }
}

#[test]
fn heavy_top_box_follows_the_node_and_the_series_lists_every_snapshot() {
    let results = bare_top(0.05);
    let dir = scratch("heavy_top");
    let series = export_vtk(&results, &dir).unwrap();
    assert_eq!(series.pvd, dir.join("results.pvd"));
    let dump = read_back(&series.pvd);
    check_series(&results, &series, &dump, &["bodies", "frames", "joints"]);
    let shape = &results.info.shapes[0];
    let colour = shape.colour.map(|c| (c * 255.0).round());
    let mut turned = 0.0f64;
    for (snap, d) in results.snapshots.iter().zip(of_kind(&dump, "bodies")) {
        // The box's corners where the node's quaternion puts them.
        let expected: Vec<_> = corners(shape)
            .iter()
            .map(|&c| place(snap, shape, c))
            .collect();
        same_points(&d.points, &expected, 1e-12);
        let cells = d.cells();
        assert_eq!(cells.len(), 12);
        assert!(cells.iter().all(|(t, _)| *t == "triangle"));
        for c in 0..12 {
            assert_eq!(d.cell("colour")[c], colour);
            assert_eq!(
                [
                    d.cell("shape")[c][0],
                    d.cell("node")[c][0],
                    d.cell("body")[c][0]
                ],
                [0.0; 3]
            );
        }
        assert_eq!(d.types["colour"], "UInt8");
        turned = turned.max(1.0 - snap.orientation[0][0].abs());
    }
    assert!(turned > 1e-2, "the top turns: {turned}");
    check_frames(&results, &dump);
    check_joints(&results, &dump);
    let force = results.snapshots.last().unwrap().joint_reaction[0];
    assert!(
        norm([force[0], force[1], force[2]]) > 10.0,
        "the pivot holds the top: {force:?}"
    );

    // The same series in ASCII holds the same numbers, to the bit.
    let ascii_dir = scratch("heavy_top_ascii");
    let options = VtkOptions {
        encoding: Encoding::Ascii,
        ..Default::default()
    };
    let ascii = export_vtk_with(&results, &ascii_dir, &options).unwrap();
    assert_eq!(read_back(&ascii.pvd), dump);
    let text = |p: PathBuf| std::fs::read_to_string(p).unwrap();
    assert!(text(ascii_dir.join("bodies_000001.vtu")).contains("format=\"ascii\""));
    assert!(!text(ascii_dir.join("bodies_000001.vtu")).contains("format=\"binary\""));
    assert!(text(dir.join("bodies_000001.vtu")).contains("format=\"binary\""));
}

#[test]
fn right_angle_cantilever_tubes_carry_their_section_forces() {
    let results = collect("right_angle_cantilever.toml", 0.25);
    let dir = scratch("right_angle_cantilever");
    let series = export_vtk(&results, &dir).unwrap();
    let dump = read_back(&series.pvd);
    check_series(&results, &series, &dump, &["beams", "frames", "joints"]);
    let info = &results.info;
    let (n, s) = (info.beams.len(), TUBE_SIDES);
    assert_eq!(n, 20);
    let names = [
        "axial_strain",
        "shear_strain_2",
        "shear_strain_3",
        "torsion",
        "curvature_2",
        "curvature_3",
        "axial_force",
        "shear_force_2",
        "shear_force_3",
        "torque",
        "bending_moment_2",
        "bending_moment_3",
    ];
    for (snap, d) in results.snapshots.iter().zip(of_kind(&dump, "beams")) {
        assert_eq!(d.points.len(), n * (2 * s + 2));
        // All the triangles, element after element, then a line per element.
        let cells = d.cells();
        assert_eq!(cells.len(), n * (2 * s + 1));
        assert_eq!(d.cells.len(), 2);
        assert_eq!(
            (d.cells[0].0.as_str(), d.cells[1].0.as_str()),
            ("triangle", "line")
        );
        let element_of = |c: usize| {
            if c < 2 * s * n {
                c / (2 * s)
            } else {
                c - 2 * s * n
            }
        };
        for name in names.iter().chain(&["element", "member"]) {
            assert_eq!(d.cell(name).len(), cells.len(), "{name}");
        }
        for (c, (kind, points)) in cells.iter().enumerate() {
            let e = element_of(c);
            let b = &info.beams[e];
            for (k, name) in names.iter().enumerate() {
                let v = if k < 6 {
                    snap.beam_strain[e][k]
                } else {
                    snap.beam_stress[e][k - 6]
                };
                assert_eq!(d.cell(name)[c], [v], "{name} of element {e}");
            }
            assert_eq!(d.cell("element")[c], [e as f64]);
            let member = if b.member == "leg1" { 0.0 } else { 1.0 };
            assert!(b.member == "leg1" || b.member == "leg2", "{}", b.member);
            assert_eq!(d.cell("member")[c], [member]);
            let [a, z] = b.nodes.map(|k| snap.position[k]);
            if *kind == "line" {
                assert_eq!(
                    [d.points[points[0] as usize], d.points[points[1] as usize]],
                    [a, z]
                );
                continue;
            }
            // Every point of a tube's triangle at the drawn radius from its segment.
            for &p in *points {
                let p = d.points[p as usize];
                let axis = sub(z, a);
                let t = (dot(sub(p, a), axis) / dot(axis, axis)).clamp(0.0, 1.0);
                let closest = add(a, axis.map(|x| x * t));
                let distance = norm(sub(p, closest));
                assert!(
                    (distance - b.radius).abs() < 1e-9 * b.radius,
                    "{distance} {}",
                    b.radius
                );
            }
        }
        // The two rings of an element start on the same side (no half turn between them).
        for e in 0..n {
            let b = &info.beams[e];
            let [a, z] = b.nodes.map(|k| snap.position[k]);
            let first = e * (2 * s + 2);
            let ra = sub(d.points[first], a);
            let rz = sub(d.points[first + s], z);
            assert!(dot(ra, rz) > 0.9 * b.radius * b.radius, "element {e}");
        }
        assert_eq!(d.types["bending_moment_2"], "Float64");
        assert_eq!(d.types["member"], "Int32");
    }
    // The impulse has started: element 0, at the clamp, bends at the last snapshot, and the
    // file says so.
    let last = results.snapshots.last().unwrap();
    let beams = of_kind(&dump, "beams");
    let d = beams.last().unwrap();
    let bending = last.beam_stress[0][4]
        .abs()
        .max(last.beam_stress[0][5].abs());
    assert!(bending > 0.1, "{:?}", last.beam_stress[0]);
    assert_eq!(d.cell("bending_moment_2")[0], [last.beam_stress[0][4]]);
    assert_eq!(
        d.cell("bending_moment_3")[2 * s * n],
        [last.beam_stress[0][5]]
    );
    check_frames(&results, &dump);
    check_joints(&results, &dump);
}

#[test]
fn four_bar_bodies_and_joint_reactions() {
    let results = collect("four_bar.toml", 0.02);
    let dir = scratch("four_bar");
    let series = export_vtk(&results, &dir).unwrap();
    let dump = read_back(&series.pvd);
    check_series(&results, &series, &dump, &["bodies", "frames", "joints"]);
    let info = &results.info;
    assert_eq!((info.shapes.len(), info.joints.len()), (5, 7));
    for (snap, d) in results.snapshots.iter().zip(of_kind(&dump, "bodies")) {
        assert_eq!((d.points.len(), d.cells().len()), (40, 60));
        for (k, shape) in info.shapes.iter().enumerate() {
            // Shape after shape: its 8 corners, then (cells) its 12 triangles.
            let expected: Vec<_> = corners(shape)
                .iter()
                .map(|&c| place(snap, shape, c))
                .collect();
            same_points(&d.points[8 * k..8 * k + 8], &expected, 1e-12);
            let body = info
                .bodies
                .iter()
                .position(|b| b.node == shape.node)
                .unwrap();
            for c in 12 * k..12 * k + 12 {
                assert_eq!(d.cell("shape")[c], [k as f64]);
                assert_eq!(d.cell("node")[c], [shape.node as f64]);
                assert_eq!(d.cell("body")[c], [body as f64]);
                assert_eq!(
                    d.cell("colour")[c],
                    shape.colour.map(|c| (c * 255.0).round())
                );
                assert!(d.cells()[c]
                    .1
                    .iter()
                    .all(|&i| (8 * k..8 * k + 8).contains(&(i as usize))));
            }
        }
    }
    // The cranks hang on their centre of mass half a metre from the node: a known offset,
    // turned by the crank's rotation.
    let last = results.snapshots.last().unwrap();
    let crank = &info.shapes[0];
    assert_eq!(crank.position, [0.0, 0.5, 0.0]);
    let centre = place(last, crank, [0.0; 3]);
    let along = mul(&rotation(last.orientation[crank.node]), [0.0, 0.5, 0.0]);
    assert!(norm(sub(centre, add(last.position[crank.node], along))) < 1e-12);
    check_frames(&results, &dump);
    check_joints(&results, &dump);
    assert!(last
        .joint_reaction
        .iter()
        .any(|r| norm([r[0], r[1], r[2]]) > 1.0));
}

#[test]
fn every_shape_kind_is_drawn_where_its_node_and_placement_put_it() {
    let mut results = bare_top(0.02);
    let half = std::f64::consts::FRAC_1_SQRT_2;
    let base = ShapeInfo {
        node: 0,
        colour: [1.0, 0.0, 0.5],
        ..Default::default()
    };
    results.info.shapes.extend([
        ShapeInfo {
            kind: "cylinder".into(),
            size: [0.2, 0.2, 0.6],
            position: [0.0, 0.0, 0.3],
            orientation: [half, half, 0.0, 0.0],
            ..base.clone()
        },
        ShapeInfo {
            kind: "sphere".into(),
            size: [0.1; 3],
            position: [0.2, 0.0, 0.0],
            orientation: [1.0, 0.0, 0.0, 0.0],
            ..base.clone()
        },
        ShapeInfo {
            kind: "mesh".into(),
            size: [1.0; 3],
            position: [0.0, -0.1, 0.0],
            orientation: [0.5, 0.5, 0.5, 0.5],
            vertices: vec![[0.0; 3], [0.3, 0.0, 0.0], [0.0, 0.3, 0.0], [0.0, 0.0, 0.3]],
            triangles: vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
            ..base.clone()
        },
    ]);
    let dir = scratch("every_shape");
    let series = export_vtk(&results, &dir).unwrap();
    let dump = read_back(&series.pvd);
    let info = &results.info;
    let sizes = [(8, 12), (50, 96), (114, 224), (4, 4)];
    let (points, cells) = sizes.iter().fold((0, 0), |(p, c), s| (p + s.0, c + s.1));
    for (snap, d) in results.snapshots.iter().zip(of_kind(&dump, "bodies")) {
        assert_eq!((d.points.len(), d.cells().len()), (points, cells));
        let (mut p, mut c) = (0, 0);
        for (k, (shape, (np, nc))) in info.shapes.iter().zip(sizes).enumerate() {
            let mine = &d.points[p..p + np];
            assert!(d.cell("shape")[c..c + nc].iter().all(|v| v == &[k as f64]));
            let colour = shape.colour.map(|c| (c * 255.0).round());
            assert!(d.cell("colour")[c..c + nc].iter().all(|v| v == &colour));
            // Back in the shape's frame: where its kind says.
            let node = rotation(snap.orientation[0]);
            let local = |q: &[f64; 3]| {
                let in_node: [f64; 3] = std::array::from_fn(|i| {
                    (0..3)
                        .map(|j| node[j][i] * (q[j] - snap.position[0][j]))
                        .sum()
                });
                let r = rotation(shape.orientation);
                let v = sub(in_node, shape.position);
                std::array::from_fn::<f64, 3, _>(|i| (0..3).map(|j| r[j][i] * v[j]).sum())
            };
            match shape.kind.as_str() {
                "cylinder" => {
                    for q in mine.iter().map(local) {
                        assert!((q[2].abs() - 0.3).abs() < 1e-12);
                        let radial = q[0].hypot(q[1]);
                        assert!(radial < 1e-12 || (radial - 0.1).abs() < 1e-12, "{q:?}");
                    }
                }
                "sphere" => {
                    assert!(mine
                        .iter()
                        .map(local)
                        .all(|q| (norm(q) - 0.05).abs() < 1e-12));
                }
                "mesh" => {
                    let expected: Vec<_> = shape
                        .vertices
                        .iter()
                        .map(|&v| place(snap, shape, v))
                        .collect();
                    assert_eq!(mine.len(), 4);
                    for (a, b) in mine.iter().zip(&expected) {
                        assert!(norm(sub(*a, *b)) < 1e-12);
                    }
                }
                _ => {}
            }
            p += np;
            c += nc;
        }
    }
}

#[test]
fn a_directory_that_cannot_be_made_is_an_error_naming_it() {
    let results = Results::default();
    let file = scratch("not_a_directory");
    std::fs::create_dir_all(file.parent().unwrap()).unwrap();
    std::fs::write(&file, "a file").unwrap();
    let target = file.join("series");
    match export_vtk(&results, &target) {
        Err(e @ VtkError::Directory { .. }) => {
            assert!(e.to_string().contains(&*target.to_string_lossy()), "{e}")
        }
        other => panic!("{other:?}"),
    }
    std::fs::remove_file(&file).unwrap();
}

#[test]
fn results_that_do_not_match_their_model_are_refused_before_writing() {
    let mut results = collect("four_bar.toml", 0.002);
    results.snapshots[1].joint_reaction.pop();
    let dir = scratch("inconsistent");
    match export_vtk(&results, &dir) {
        Err(VtkError::Inconsistent(what)) => {
            assert!(
                what.contains("snapshot 1") && what.contains("joint reactions"),
                "{what}"
            )
        }
        other => panic!("{other:?}"),
    }
    assert!(!dir.exists());
}

#[test]
fn no_snapshot_gives_an_empty_collection() {
    let mut results = collect("four_bar.toml", 0.002);
    results.snapshots.clear();
    let dir = scratch("empty");
    let series = export_vtk(&results, &dir).unwrap();
    assert_eq!(series.files, 0);
    assert!(timesteps(&series.pvd).is_empty());
    let text = std::fs::read_to_string(&series.pvd).unwrap();
    assert!(text.contains("<Collection>") && text.contains("</VTKFile>"));
}
