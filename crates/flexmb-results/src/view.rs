//! The browser animation: one self-contained HTML file that plays a run in 3D.
//!
//! [`write_html`] writes a page that opens from disk with no network: three.js and its
//! OrbitControls (a minified bundle built from the npm packages by `viewer/build.sh` and
//! committed, so that building needs no npm), the viewer (`viewer/viewer.js`,
//! `viewer/template.html`) and the run's data are all inline.
//!
//! # The data block
//!
//! The page carries one JSON object (see [`page_data`]): the model's metadata as in
//! [`crate::ModelInfo`] (display shapes, beams, joints, springs, sensors), the
//! snapshots' times (or load factors) and sensor values as JSON numbers, the bounding box of
//! the whole motion, and the large per-snapshot arrays as *channels*. A channel holds
//! `frames x items x comps` values, each quantized to an integer `q = round((v - origin[c]) /
//! step[c])`, differenced along the frames (the first frame against zero), laid out as four
//! byte planes (all the lowest bytes, then the next ones, ...) and zlib-compressed, then
//! base64. Steps are fine enough not to show: 2^-20 of the motion's size for positions,
//! 2^-20 for quaternion components, 2^-16 of the largest magnitude for beam strains and
//! stress resultants. The page inflates the channels with the browser's own
//! `DecompressionStream`. The page is about 0.8 MB of three.js and viewer plus the data: a
//! 1000-link chain takes about 4 KB per snapshot (100 snapshots: a 1.2 MB page), the heavy top
//! or a 20-element beam well under 1 KB.
//!
//! More than [`MAX_FRAMES`] snapshots are subsampled evenly (the first and the last kept) and
//! the page says so.

use crate::{ModelInfo, Results, Snapshot};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// three.js (MIT licence, `viewer/THREE-LICENSE.txt`) with its OrbitControls, built by
/// `viewer/build.sh`.
const THREE_BUNDLE: &str = include_str!("../viewer/three.bundle.min.js");
const THREE_LICENSE: &str = include_str!("../viewer/THREE-LICENSE.txt");
/// The page around the data, and the viewer's own script.
const TEMPLATE: &str = include_str!("../viewer/template.html");
const VIEWER_JS: &str = include_str!("../viewer/viewer.js");

/// At most this many snapshots go into a page; more are subsampled evenly.
pub const MAX_FRAMES: usize = 2000;

/// Why the animation could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error("the results have no snapshots: there is nothing to animate")]
    NoSnapshots,
    #[error("cannot write the animation {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Writes the browser animation of `results` to `path`: one self-contained HTML file.
pub fn write_html(results: &Results, path: &Path) -> Result<(), ViewError> {
    let page = html(results)?;
    std::fs::write(path, page).map_err(|source| ViewError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// The browser animation of `results` as one self-contained HTML page.
pub fn html(results: &Results) -> Result<String, ViewError> {
    if results.snapshots.is_empty() {
        return Err(ViewError::NoSnapshots);
    }
    let data = page_data(results).to_string();
    // JSON inside a <script> element: no `<` may close it or open a comment. `<` only occurs
    // in strings, where `\u003c` means the same.
    let data = data.replace('<', "\\u003c");
    let title = if results.info.title.is_empty() {
        "flexmb run".to_string()
    } else {
        results.info.title.clone()
    };
    let licence = THREE_LICENSE.replace("--", "- -");
    let mut page = String::with_capacity(TEMPLATE.len() + THREE_BUNDLE.len() + data.len() + 65536);
    fill(
        &mut page,
        TEMPLATE,
        &[
            ("TITLE", &escape_html(&title)),
            ("THREE_LICENSE", &licence),
            ("THREE_BUNDLE", THREE_BUNDLE),
            ("DATA", &data),
            ("VIEWER", VIEWER_JS),
        ],
    );
    Ok(page)
}

/// Copies `template` into `out`, each `{{NAME}}` replaced by its value (one pass: a value is
/// never searched for placeholders).
fn fill(out: &mut String, template: &str, values: &[(&str, &str)]) {
    let mut rest = template;
    while let Some(start) = rest.find("{{") {
        let Some(len) = rest[start + 2..].find("}}") else {
            break;
        };
        let name = &rest[start + 2..start + 2 + len];
        match values.iter().find(|(n, _)| *n == name) {
            Some((_, value)) => {
                out.push_str(&rest[..start]);
                out.push_str(value);
            }
            None => out.push_str(&rest[..start + 4 + len]),
        }
        rest = &rest[start + 4 + len..];
    }
    out.push_str(rest);
}

fn escape_html(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            _ => out.push(c),
        }
    }
    out
}

/// The indices of the snapshots that go into the page: all of them, or [`MAX_FRAMES`]
/// evenly spread from the first to the last.
pub fn kept_frames(count: usize) -> Vec<usize> {
    if count <= MAX_FRAMES {
        return (0..count).collect();
    }
    let last = (count - 1) as f64;
    let mut kept: Vec<usize> = (0..MAX_FRAMES)
        .map(|k| (k as f64 * last / (MAX_FRAMES - 1) as f64).round() as usize)
        .collect();
    kept.dedup();
    kept
}

/// The JSON object that the page animates (see the module documentation).
pub fn page_data(results: &Results) -> Value {
    let info = &results.info;
    let kept = kept_frames(results.snapshots.len());
    let frames: Vec<&Snapshot> = kept.iter().map(|&k| &results.snapshots[k]).collect();

    let (lo, hi) = bounds(info, &frames);
    let size = (0..3).map(|i| hi[i] - lo[i]).fold(0.0, f64::max);
    let centre: Vec<f64> = (0..3).map(|i| 0.5 * (lo[i] + hi[i])).collect();
    let position_step = if size > 0.0 { size } else { 1.0 } * 2f64.powi(-20);

    // Orientations are sent for the nodes that need them: those with a body, a shape or a
    // spring end.
    let mut oriented = vec![false; info.nodes.len()];
    let mut mark = |n: i64| {
        if n >= 0 && (n as usize) < oriented.len() {
            oriented[n as usize] = true;
        }
    };
    info.bodies.iter().for_each(|b| mark(b.node as i64));
    info.shapes.iter().for_each(|s| mark(s.node as i64));
    info.springs
        .iter()
        .for_each(|s| s.nodes.iter().for_each(|&n| mark(n)));
    let oriented: Vec<usize> = (0..oriented.len()).filter(|&n| oriented[n]).collect();

    let flat = |v: &Vec<[f64; 3]>| v.iter().flatten().copied().collect::<Vec<f64>>();
    let positions: Vec<Vec<f64>> = frames.iter().map(|s| flat(&s.position)).collect();
    let position = channel(&positions, 3, vec![position_step; 3], centre.clone());
    // Each quaternion takes the sign nearer the previous frame's (the same rotation), so that
    // the differences along the frames stay small.
    let mut last = vec![[1.0, 0.0, 0.0, 0.0]; oriented.len()];
    let quaternions: Vec<Vec<f64>> = frames
        .iter()
        .map(|s| {
            let mut out = Vec::with_capacity(4 * oriented.len());
            for (k, &n) in oriented.iter().enumerate() {
                let mut q = s
                    .orientation
                    .get(n)
                    .copied()
                    .unwrap_or([1.0, 0.0, 0.0, 0.0]);
                if (0..4).map(|i| q[i] * last[k][i]).sum::<f64>() < 0.0 {
                    q = q.map(|x| -x);
                }
                last[k] = q;
                out.extend_from_slice(&q);
            }
            out
        })
        .collect();
    let orientation = channel(&quaternions, 4, vec![2f64.powi(-20); 4], vec![0.0; 4]);
    let joints: Vec<Vec<f64>> = frames.iter().map(|s| flat(&s.joint_position)).collect();
    let joint_position = channel(&joints, 3, vec![position_step; 3], centre);
    let (strain, strain_range) = section_channel(&frames, |s| &s.beam_strain);
    let (stress, stress_range) = section_channel(&frames, |s| &s.beam_stress);

    let sensors: Vec<Vec<f64>> = (0..info.sensors.len())
        .map(|k| {
            frames
                .iter()
                .map(|s| s.sensors.get(k).copied().unwrap_or(f64::NAN))
                .collect()
        })
        .collect();

    json!({
        "format": 1,
        "title": info.title,
        "analysis": info.analysis,
        "group": info.group,
        "first": info.first,
        "snapshots": results.snapshots.len(),
        "frames": frames.len(),
        "at": frames.iter().map(|s| s.at).collect::<Vec<_>>(),
        "bounds": { "min": lo, "max": hi },
        "nodes": info.nodes,
        "bodies": info.bodies,
        "beams": info.beams,
        "joints": info.joints,
        "springs": info.springs,
        "shapes": info.shapes.iter().map(shape).collect::<Vec<_>>(),
        "sensors": info.sensors.iter().zip(&sensors).map(|(s, v)| json!({
            "name": s.name, "unit": s.unit, "values": v,
        })).collect::<Vec<_>>(),
        "oriented": oriented,
        "position": position,
        "orientation": orientation,
        "joint_position": joint_position,
        "strain": strain,
        "strain_range": strain_range,
        "stress": stress,
        "stress_range": stress_range,
        // Mode shapes: flexmb has no modal analysis yet. The viewer shows a "Mode shapes"
        // panel when this list is not empty (see `setupModes` in viewer.js).
        "modes": [],
    })
}

/// A display shape for the page: its mesh as compressed little-endian arrays.
fn shape(s: &crate::info::ShapeInfo) -> Value {
    let vertices: Vec<u8> = s
        .vertices
        .iter()
        .flatten()
        .flat_map(|&v| (v as f32).to_le_bytes())
        .collect();
    let triangles: Vec<u8> = s
        .triangles
        .iter()
        .flatten()
        .flat_map(|&i| i.to_le_bytes())
        .collect();
    json!({
        "node": s.node,
        "kind": s.kind,
        "size": s.size,
        "position": s.position,
        "orientation": s.orientation,
        "colour": s.colour,
        "mesh": s.mesh,
        "vertices": packed(&vertices),
        "triangles": packed(&triangles),
    })
}

/// The box around the whole motion: node origins, joint points, the display shapes (their
/// spheres) and the ground's spring ends, over every frame.
fn bounds(info: &ModelInfo, frames: &[&Snapshot]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    let mut add = |p: [f64; 3], r: f64| {
        if p.iter().all(|x| x.is_finite()) {
            for i in 0..3 {
                lo[i] = lo[i].min(p[i] - r);
                hi[i] = hi[i].max(p[i] + r);
            }
        }
    };
    // The radius of each node's shapes around the node origin.
    let mut reach = vec![0.0f64; info.nodes.len()];
    for s in &info.shapes {
        let half = 0.5 * s.size.iter().map(|x| x * x).sum::<f64>().sqrt();
        let offset = s.position.iter().map(|x| x * x).sum::<f64>().sqrt();
        if let Some(r) = reach.get_mut(s.node) {
            *r = r.max(offset + half);
        }
    }
    for b in &info.beams {
        for &n in &b.nodes {
            if let Some(r) = reach.get_mut(n) {
                *r = r.max(b.radius);
            }
        }
    }
    for s in frames {
        for (n, p) in s.position.iter().enumerate() {
            add(*p, reach.get(n).copied().unwrap_or(0.0));
        }
        for p in &s.joint_position {
            add(*p, 0.0);
        }
    }
    for s in &info.springs {
        for k in 0..2 {
            if s.nodes[k] < 0 {
                add(s.points[k], 0.0);
            }
        }
    }
    if lo[0] > hi[0] {
        return ([-0.5; 3], [0.5; 3]);
    }
    (lo, hi)
}

/// The strains or stress resultants of every beam element as a channel, with the range of
/// each of the six components over the run.
fn section_channel(
    frames: &[&Snapshot],
    field: impl Fn(&Snapshot) -> &Vec<[f64; 6]>,
) -> (Value, Vec<[f64; 2]>) {
    let mut range = vec![[f64::INFINITY, f64::NEG_INFINITY]; 6];
    for s in frames {
        for e in field(s) {
            for c in 0..6 {
                if e[c].is_finite() {
                    range[c][0] = range[c][0].min(e[c]);
                    range[c][1] = range[c][1].max(e[c]);
                }
            }
        }
    }
    for r in &mut range {
        if r[0] > r[1] {
            *r = [0.0, 0.0];
        }
    }
    let step: Vec<f64> = range
        .iter()
        .map(|r| {
            let m = r[0].abs().max(r[1].abs());
            if m > 0.0 {
                m * 2f64.powi(-16)
            } else {
                1.0
            }
        })
        .collect();
    let values: Vec<Vec<f64>> = frames
        .iter()
        .map(|s| field(s).iter().flatten().copied().collect())
        .collect();
    let ch = channel(&values, 6, step, vec![0.0; 6]);
    (ch, range)
}

/// One channel of `items x comps` numbers per frame (see the module documentation for the
/// encoding). A frame shorter than the first has its missing numbers held.
fn channel(per_frame: &[Vec<f64>], comps: usize, step: Vec<f64>, origin: Vec<f64>) -> Value {
    let n = per_frame.first().map_or(0, Vec::len);
    let total = n * per_frame.len();
    let mut planes = vec![0u8; 4 * total];
    let mut previous = vec![0i32; n];
    for (f, v) in per_frame.iter().enumerate() {
        for j in 0..n {
            let c = j % comps;
            let x = v.get(j).copied().unwrap_or(f64::NAN);
            let q = if x.is_finite() {
                ((x - origin[c]) / step[c]).round().clamp(-1e9, 1e9) as i32
            } else {
                previous[j]
            };
            let delta = q.wrapping_sub(previous[j]).to_le_bytes();
            previous[j] = q;
            for (b, byte) in delta.iter().enumerate() {
                planes[b * total + f * n + j] = *byte;
            }
        }
    }
    json!({
        "items": n / comps,
        "comps": comps,
        "origin": origin,
        "step": step,
        "data": packed(&planes),
    })
}

/// zlib-compressed, then base64.
fn packed(bytes: &[u8]) -> String {
    use base64::Engine as _;
    base64::engine::general_purpose::STANDARD
        .encode(miniz_oxide::deflate::compress_to_vec_zlib(bytes, 6))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placeholders_are_filled_once_and_unknown_ones_kept() {
        let mut out = String::new();
        fill(
            &mut out,
            "a {{X}} b {{Y}} c {{Z}} {{",
            &[("X", "{{Y}}"), ("Y", "y")],
        );
        assert_eq!(out, "a {{Y}} b y c {{Z}} {{");
    }

    #[test]
    fn subsampling_keeps_the_first_and_last_and_at_most_max_frames() {
        assert_eq!(kept_frames(5), vec![0, 1, 2, 3, 4]);
        let k = kept_frames(5 * MAX_FRAMES + 3);
        assert_eq!(k.len(), MAX_FRAMES);
        assert_eq!(k[0], 0);
        assert_eq!(*k.last().unwrap(), 5 * MAX_FRAMES + 2);
        assert!(k.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn a_channel_decodes_back_to_its_values_within_half_a_step() {
        let frames: Vec<Snapshot> = (0..4)
            .map(|f| Snapshot {
                position: vec![
                    [f as f64, -2.5 * f as f64, 1e-3],
                    [0.0, 3.0, -7.0 + f as f64],
                ],
                ..Default::default()
            })
            .collect();
        let values: Vec<Vec<f64>> = frames
            .iter()
            .map(|s| s.position.iter().flatten().copied().collect())
            .collect();
        let step = 1e-4;
        let ch = channel(&values, 3, vec![step; 3], vec![1.0, 0.0, -1.0]);
        // Decode as the page does.
        let b64 = ch["data"].as_str().unwrap();
        use base64::Engine as _;
        let zipped = base64::engine::general_purpose::STANDARD
            .decode(b64)
            .unwrap();
        let planes = miniz_oxide::inflate::decompress_to_vec_zlib(&zipped).unwrap();
        let n = 6;
        let total = n * frames.len();
        let origin = [1.0, 0.0, -1.0];
        let mut acc = vec![0i32; n];
        for (f, s) in frames.iter().enumerate() {
            for j in 0..n {
                let i = f * n + j;
                let d = i32::from_le_bytes([
                    planes[i],
                    planes[total + i],
                    planes[2 * total + i],
                    planes[3 * total + i],
                ]);
                acc[j] = acc[j].wrapping_add(d);
                let v = origin[j % 3] + step * acc[j] as f64;
                let want = s.position[j / 3][j % 3];
                assert!((v - want).abs() <= 0.5 * step + 1e-12, "{v} against {want}");
            }
        }
    }

    #[test]
    fn the_page_is_self_contained_and_its_data_cannot_close_the_script() {
        let results = Results {
            info: ModelInfo {
                title: "A </script> <b>title</b> & more".into(),
                first: "time".into(),
                nodes: vec!["n".into()],
                ..Default::default()
            },
            snapshots: vec![Snapshot {
                position: vec![[0.0; 3]],
                orientation: vec![[1.0, 0.0, 0.0, 0.0]],
                ..Default::default()
            }],
            steps: vec![],
        };
        let page = html(&results).unwrap();
        assert_eq!(
            page.matches("</script>").count(),
            page.matches("<script").count()
        );
        assert!(page.contains("<title>A &lt;/script&gt; &lt;b&gt;title&lt;/b&gt; &amp; more"));
        assert!(!page.contains("src=\"http"));
        assert!(!page.contains("{{DATA}}") && !page.contains("{{VIEWER}}"));
        assert!(matches!(
            html(&Results::default()),
            Err(ViewError::NoSnapshots)
        ));
    }
}
