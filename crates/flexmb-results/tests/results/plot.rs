//! Sensor-history plots: sizes, panels, labels and errors, on short runs of the examples and
//! on made-up results.

use flexmb::input::Analysis;
use flexmb_results::info::SensorInfo;
use flexmb_results::plot::{plot, summary};
use flexmb_results::{Layout, ModelInfo, PlotError, Results, Snapshot, Summary};
use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn model(name: &str) -> flexmb::input::ModelFile {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name);
    flexmb::input::read_model_file(&path, &[]).expect("the example reads")
}

/// The heavy top up to 0.05 s (six snapshots), collected once for all the tests.
fn heavy_top() -> &'static Results {
    static RESULTS: OnceLock<Results> = OnceLock::new();
    RESULTS.get_or_init(|| {
        let mut file = model("heavy_top.toml");
        if let Analysis::Dynamic(s) = &mut file.analysis {
            s.t_end = 0.05;
        }
        let (r, error) = Results::collect(&file);
        assert!(error.is_none());
        r
    })
}

fn out(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("plot");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    let _ = std::fs::remove_file(&path);
    path
}

fn names(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

/// Width, height and RGB pixels of a PNG file.
fn decode(path: &Path) -> (u32, u32, Vec<[u8; 3]>) {
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(path).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().expect("a PNG of a sane size")];
    let info = reader.next_frame(&mut buf).unwrap();
    let channels = info.color_type.samples();
    assert!(channels >= 3 && info.bit_depth == png::BitDepth::Eight);
    let pixels = buf[..info.buffer_size()]
        .chunks(channels)
        .map(|p| [p[0], p[1], p[2]])
        .collect();
    (info.width, info.height, pixels)
}

/// The texts of an SVG file's `<text>` elements.
fn svg_texts(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter_map(|t| {
            let start = t.find('>')? + 1;
            let end = t.find("</text>")?;
            Some(t[start..end].trim().to_string())
        })
        .collect()
}

/// The y labels of the panels: bracketed texts drawn upright (rotated).
fn y_labels(svg: &str) -> Vec<String> {
    svg.split("<text")
        .skip(1)
        .filter(|t| t[..t.find('>').unwrap_or(0)].contains("rotate"))
        .filter_map(|t| Some(t[t.find('>')? + 1..t.find("</text>")?].trim().to_string()))
        .collect()
}

fn svg_size(svg: &str) -> (u32, u32) {
    let attr = |name: &str| -> u32 {
        let s = &svg[svg.find(&format!("{name}=\"")).unwrap() + name.len() + 2..];
        s[..s.find('"').unwrap()].parse().unwrap()
    };
    (attr("width"), attr("height"))
}

#[test]
fn heavy_top_png_has_its_size_and_coloured_lines() {
    let path = out("heavy_top.png");
    plot(heavy_top(), &[], Layout::Auto, &path).unwrap();
    let (w, h, pixels) = decode(&path);
    // Six units (m, none, rad/s, N, J, m or rad), six panels of 350 px, title and x axis.
    assert_eq!((w, h), (1200, 45 + 6 * 350 + 55));
    let white = pixels.iter().filter(|p| **p == [255, 255, 255]).count();
    let inked = pixels.len() - white;
    assert!(
        inked > pixels.len() / 50,
        "{inked} of {} pixels",
        pixels.len()
    );
    // Saturated colours: the lines (greys are the text, frames and grid).
    let colours: HashSet<[u8; 3]> = pixels
        .iter()
        .filter(|p| p.iter().max().unwrap() - p.iter().min().unwrap() > 60)
        .copied()
        .collect();
    assert!(colours.len() >= 5, "{} colours", colours.len());
}

#[test]
fn heavy_top_svg_names_every_sensor_and_unit() {
    let path = out("heavy_top.svg");
    plot(heavy_top(), &[], Layout::Stacked, &path).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    let texts = svg_texts(&svg);
    for s in &heavy_top().info.sensors {
        assert!(texts.contains(&s.name), "{} missing", s.name);
    }
    assert!(texts.iter().any(|t| t.starts_with("Heavy top")));
    assert_eq!(texts.iter().filter(|t| *t == "time [s]").count(), 1);
    assert_eq!(
        y_labels(&svg),
        ["[m]", "[rad/s]", "[N]", "[J]", "[m or rad]"],
        "the quaternion's panel has no unit"
    );
}

#[test]
fn stacked_layout_has_one_panel_per_unit_and_shared_one_in_all() {
    let top = heavy_top();
    let chosen = names(&["com_x", "omega_2", "com_z", "energy"]);
    let path = out("stacked.svg");
    plot(top, &chosen, Layout::Stacked, &path).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    assert_eq!(svg_size(&svg), (1200, 45 + 3 * 350 + 55));
    assert_eq!(y_labels(&svg), ["[m]", "[rad/s]", "[J]"]);

    // Auto: the same unit, one panel.
    let path = out("auto_shared.svg");
    plot(
        top,
        &names(&["com_x", "com_y", "com_z"]),
        Layout::Auto,
        &path,
    )
    .unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    assert_eq!(svg_size(&svg), (1200, 45 + 350 + 55));
    assert_eq!(y_labels(&svg), ["[m]"]);

    // Shared with mixed units: no y label, the units in the legend.
    let path = out("shared.svg");
    plot(top, &chosen, Layout::Shared, &path).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    assert_eq!(svg_size(&svg), (1200, 45 + 350 + 55));
    assert!(y_labels(&svg).is_empty());
    let texts = svg_texts(&svg);
    for label in ["com_x [m]", "omega_2 [rad/s]", "com_z [m]", "energy [J]"] {
        assert!(texts.iter().any(|t| t == label), "{label} missing");
    }
}

#[test]
fn unknown_sensor_is_an_error_that_lists_the_sensors() {
    let path = out("unknown.png");
    let e = plot(heavy_top(), &names(&["com_x", "spin"]), Layout::Auto, &path).unwrap_err();
    assert!(matches!(&e, PlotError::UnknownSensor { name, .. } if name == "spin"));
    let message = e.to_string();
    assert!(message.contains("`spin`"), "{message}");
    assert!(
        message.contains("com_x, com_y, com_z, q_w, q_x, q_y, q_z, omega_1"),
        "{message}"
    );
    assert!(!path.exists());
}

#[test]
fn other_extensions_are_rejected() {
    for name in ["top.pdf", "top", "top.png.txt"] {
        let path = out(name);
        let e = plot(heavy_top(), &[], Layout::Auto, &path).unwrap_err();
        assert!(matches!(e, PlotError::Extension { .. }), "{name}: {e}");
        assert!(e.to_string().contains(".png or .svg"), "{e}");
        assert!(!path.exists());
        assert!(matches!(
            summary(heavy_top(), &path),
            Err(PlotError::Extension { .. })
        ));
    }
    // Upper case is fine.
    let path = out("TOP.SVG");
    plot(heavy_top(), &names(&["energy"]), Layout::Auto, &path).unwrap();
    assert!(path.exists());
}

#[test]
fn a_file_that_cannot_be_written_is_an_error_naming_it() {
    let path = out("no_such_dir").join("top.png");
    let e = plot(heavy_top(), &names(&["energy"]), Layout::Auto, &path).unwrap_err();
    assert!(matches!(e, PlotError::Draw { .. }), "{e}");
    assert!(e.to_string().contains("no_such_dir"), "{e}");
}

#[test]
fn static_run_is_drawn_against_the_load_factor() {
    let mut file = model("bend_45.toml");
    if let Analysis::Static(s) = &mut file.analysis {
        s.load_factor = 150.0;
    }
    let (r, error) = Results::collect(&file);
    assert!(error.is_none());
    assert!(r.snapshots.len() > 2);
    let path = out("bend.svg");
    plot(&r, &[], Layout::Auto, &path).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    let texts = svg_texts(&svg);
    assert!(texts.iter().any(|t| t == "load factor"));
    assert!(!texts.iter().any(|t| t == "time [s]"));
    assert_eq!(y_labels(&svg), ["[m]"]);
    let path = out("bend.png");
    assert_eq!(
        summary(&r, &path).unwrap(),
        Summary::Written { shown: 3, total: 3 }
    );
    assert_eq!(decode(&path).0, 1200);
}

#[test]
fn heavy_top_summary_draws_every_sensor() {
    let path = out("summary.png");
    let s = summary(heavy_top(), &path).unwrap();
    assert_eq!(
        s,
        Summary::Written {
            shown: 13,
            total: 13
        }
    );
    assert_eq!(s.note(), None);
    let (w, h, _) = decode(&path);
    assert_eq!((w, h), (1200, 45 + 6 * 350 + 55));
}

/// Results made up: `units` units with `per_unit` sensors each, with `values(k, i)` for
/// sensor k at snapshot i.
fn made_up(
    units: usize,
    per_unit: usize,
    snapshots: usize,
    values: fn(usize, usize) -> f64,
) -> Results {
    let sensors: Vec<SensorInfo> = (0..units * per_unit)
        .map(|k| SensorInfo {
            name: format!("s{k}"),
            unit: format!("u{}", k / per_unit),
        })
        .collect();
    let n = sensors.len();
    Results {
        info: ModelInfo {
            title: "Made up".into(),
            first: "time".into(),
            sensors,
            ..Default::default()
        },
        snapshots: (0..snapshots)
            .map(|i| Snapshot {
                at: 0.1 * i as f64,
                sensors: (0..n).map(|k| values(k, i)).collect(),
                ..Default::default()
            })
            .collect(),
        steps: Vec::new(),
    }
}

#[test]
fn summary_of_many_sensors_draws_some_and_says_so() {
    let r = made_up(12, 6, 20, |k, i| (k as f64 + 1.0) * (0.3 * i as f64).sin());
    let path = out("many.svg");
    let s = summary(&r, &path).unwrap();
    assert_eq!(
        s,
        Summary::Written {
            shown: 40,
            total: 72
        }
    );
    assert!(s.note().unwrap().contains("40 of the 72"));
    let svg = std::fs::read_to_string(&path).unwrap();
    // Six sensors in each of the first six units and four of the seventh.
    assert_eq!(y_labels(&svg).len(), 7);
    let texts = svg_texts(&svg);
    assert!(texts
        .iter()
        .any(|t| t.starts_with("Showing 40 of 72 sensors")));
    assert!(texts.iter().any(|t| t == "s39"));
    assert!(!texts.iter().any(|t| t == "s40"));
}

#[test]
fn gaps_and_constants_are_drawn_without_panic() {
    let r = made_up(2, 3, 10, |k, i| match (k, i) {
        (0, 3) => f64::NAN,
        (0, 7) => f64::INFINITY,
        (1, _) => 2.5,
        (2, _) => 0.0,
        (3, _) => f64::NAN,
        (4, 0) => 1.0,
        (4, _) => f64::NAN,
        _ => i as f64 * 1e-14,
    });
    let png = out("gaps.png");
    plot(&r, &[], Layout::Auto, &png).unwrap();
    assert!(decode(&png).2.iter().any(|p| *p != [255, 255, 255]));
    let path = out("gaps.svg");
    plot(&r, &[], Layout::Auto, &path).unwrap();
    let svg = std::fs::read_to_string(&path).unwrap();
    let texts = svg_texts(&svg);
    for k in 0..6 {
        assert!(texts.contains(&format!("s{k}")), "s{k} is in the legend");
    }
    assert!(!texts.iter().any(|t| t.contains("NaN") || t.contains("inf")));
}

#[test]
fn nothing_to_draw_writes_nothing() {
    let path = out("empty.png");
    let no_snapshots = made_up(1, 2, 0, |_, _| 0.0);
    assert_eq!(summary(&no_snapshots, &path).unwrap(), Summary::NoSnapshots);
    assert!(matches!(
        plot(&no_snapshots, &[], Layout::Auto, &path),
        Err(PlotError::NoSnapshots)
    ));
    let no_sensors = made_up(0, 0, 5, |_, _| 0.0);
    let s = summary(&no_sensors, &path).unwrap();
    assert_eq!(s, Summary::NoSensors);
    assert!(s.note().unwrap().contains("no sensors"));
    assert!(matches!(
        plot(&no_sensors, &[], Layout::Auto, &path),
        Err(PlotError::NoSensors)
    ));
    assert!(!path.exists());
}
