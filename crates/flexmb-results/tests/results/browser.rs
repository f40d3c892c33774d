//! The browser animation in a real browser: headless Chromium opens the page written by
//! `write_html`, at two snapshots, and takes screenshots whose 3D view must show the model
//! (not a blank canvas) and must differ between the two snapshots.
//!
//! Chromium is Debian's `chromium` package at `/usr/bin/chromium` (or `FLEXMB_CHROMIUM`).
//! Without it these tests fail and say how to install it (`apt-get install -y chromium`; CI
//! installs it). There is no GPU: WebGL runs on SwiftShader, Chromium's software renderer,
//! through ANGLE. `--use-angle=swiftshader --enable-unsafe-swiftshader` asks for it (without
//! the second flag Chromium 156 still falls back to it but warns that this fallback is
//! deprecated); `--disable-gpu` leaves the hardware path alone. `--virtual-time-budget` lets
//! the page's scripts (inflating the data, the first frames) run before the screenshot is
//! taken, and `--dump-dom` in the same run shows that the page finished: the viewer marks the
//! document element `data-ready="true"` and sets the title to `flexmb ready` once it has drawn
//! the frame that the URL's `#frame=K&paused` chose. `--enable-logging=stderr --v=0` brings the
//! page's console to Chromium's stderr, where the tests want none. (A canvas resized after
//! its last draw comes out blank in such a screenshot: the viewer draws again on a resize.)
//!
//! The screenshots (and the pages) are kept in `target/browser-screenshots/`, or in
//! `FLEXMB_SCREENSHOT_DIR`; their paths are printed (`cargo test -- --nocapture`).

use flexmb_results::{write_html, Results};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const CHROMIUM: &str = "/usr/bin/chromium";
const WIDTH: u32 = 1000;
const HEIGHT: u32 = 700;
/// Where the 3D view is in a 1000 x 700 window, less the overlays drawn over it (the hint and
/// the clock at the top, the colour bar at the bottom left): the header is 36 px high, the
/// controls below the view start at y = 656, the side panel at x = 700.
const REGION: (u32, u32, u32, u32) = (10, 95, 690, 575);
/// The scene's background (#e8ecf1).
const BACKGROUND: [u8; 3] = [0xe8, 0xec, 0xf1];

fn collect(name: &str, t_end: f64) -> Results {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../examples")
        .join(name);
    let mut file = flexmb::input::read_model_file(&path, &[]).expect("the example reads");
    match &mut file.analysis {
        flexmb::input::Analysis::Dynamic(s) => s.t_end = t_end,
        _ => panic!("{name} is a dynamic example"),
    }
    let (results, error) = Results::collect(&file);
    assert!(error.is_none(), "{name}: {error:?}");
    results
}

fn chromium() -> PathBuf {
    let path =
        std::env::var_os("FLEXMB_CHROMIUM").map_or_else(|| PathBuf::from(CHROMIUM), PathBuf::from);
    assert!(
        path.exists(),
        "headless Chromium is needed for the browser tests, and {} is missing: install it with \
         `apt-get update && apt-get install -y chromium` (Debian's package; CI installs it), or \
         point FLEXMB_CHROMIUM at a Chromium binary",
        path.display()
    );
    path
}

fn artefacts() -> PathBuf {
    let dir = std::env::var_os("FLEXMB_SCREENSHOT_DIR").map_or_else(
        || {
            Path::new(env!("CARGO_TARGET_TMPDIR"))
                .parent()
                .expect("the target directory")
                .join("browser-screenshots")
        },
        PathBuf::from,
    );
    std::fs::create_dir_all(&dir).expect("the screenshot directory can be made");
    dir
}

/// An RGB screenshot.
struct Shot {
    path: PathBuf,
    width: u32,
    rgb: Vec<u8>,
}

impl Shot {
    fn pixel(&self, x: u32, y: u32) -> [u8; 3] {
        let i = 3 * (y * self.width + x) as usize;
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    fn region(&self) -> impl Iterator<Item = (u32, u32)> {
        let (x0, y0, x1, y1) = REGION;
        (y0..y1).flat_map(move |y| (x0..x1).map(move |x| (x, y)))
    }
}

fn distance(a: [u8; 3], b: [u8; 3]) -> u8 {
    (0..3).map(|c| a[c].abs_diff(b[c])).max().unwrap_or(0)
}

/// Opens `page` at `fragment` and takes a screenshot into `png`; returns it with the DOM that
/// Chromium printed.
fn screenshot(page: &Path, fragment: &str, png: &Path) -> (Shot, String) {
    let profile = std::env::temp_dir().join(format!(
        "flexmb-chromium-{}-{}",
        std::process::id(),
        png.file_stem().unwrap().to_string_lossy()
    ));
    let _ = std::fs::remove_dir_all(&profile);
    let _ = std::fs::remove_file(png);
    let url = format!("file://{}#{fragment}", page.display());
    let mut child = Command::new(chromium())
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            "--enable-logging=stderr",
            "--v=0",
            &format!("--user-data-dir={}", profile.display()),
            &format!("--window-size={WIDTH},{HEIGHT}"),
            "--virtual-time-budget=5000",
            &format!("--screenshot={}", png.display()),
            "--dump-dom",
            &url,
        ])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("Chromium starts");
    // Read its output while it runs (a full pipe would stall it), and stop it if it hangs.
    let stdout = child.stdout.take().unwrap();
    let stderr = child.stderr.take().unwrap();
    let out = std::thread::spawn(move || std::io::read_to_string(stdout).unwrap_or_default());
    let err = std::thread::spawn(move || std::io::read_to_string(stderr).unwrap_or_default());
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("Chromium runs") {
            break status;
        }
        if start.elapsed() > Duration::from_secs(90) {
            let _ = child.kill();
            let _ = child.wait();
            panic!("Chromium took more than 90 s on {url}");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let dom = out.join().unwrap();
    let log = err.join().unwrap();
    let _ = std::fs::remove_dir_all(&profile);
    assert!(
        status.success() && png.exists(),
        "Chromium failed on {url} ({status}):\n{log}"
    );
    // The page's console stays quiet (an uncaught error, or the viewer's own report of one,
    // would show here), but for the software renderer's notes on reading pixels back (the
    // screenshot's doing).
    let console: Vec<&str> = log
        .lines()
        .filter(|l| l.contains(":CONSOLE") && !l.contains("GL Driver Message"))
        .collect();
    assert!(
        console.is_empty(),
        "the page wrote to its console on {url}:\n{}",
        console.join("\n")
    );

    let decoder = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(png).expect("the screenshot opens"),
    ));
    let mut reader = decoder.read_info().expect("the screenshot is a PNG");
    let mut buffer = vec![0; reader.output_buffer_size().expect("a sane size")];
    let info = reader
        .next_frame(&mut buffer)
        .expect("the screenshot decodes");
    assert_eq!(
        (info.width, info.height),
        (WIDTH, HEIGHT),
        "{}",
        png.display()
    );
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    let channels = match info.color_type {
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        other => panic!("unexpected PNG colour type {other:?}"),
    };
    let rgb = buffer[..info.buffer_size()]
        .chunks(channels)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    println!("screenshot: {}", png.display());
    (
        Shot {
            path: png.to_path_buf(),
            width: info.width,
            rgb,
        },
        dom,
    )
}

/// The 3D view shows something: many pixels away from the background, several colours, and
/// some of them clearly coloured (not only the grey grid: the joints' orange spheres at least).
fn assert_not_blank(shot: &Shot) {
    let mut drawn = 0usize;
    let mut coloured = 0usize;
    let mut colours = std::collections::HashSet::new();
    let mut total = 0usize;
    for (x, y) in shot.region() {
        let p = shot.pixel(x, y);
        total += 1;
        if distance(p, BACKGROUND) > 30 {
            drawn += 1;
            colours.insert([p[0] >> 4, p[1] >> 4, p[2] >> 4]);
        }
        let chroma = p.iter().max().unwrap() - p.iter().min().unwrap();
        if chroma > 40 {
            coloured += 1;
        }
    }
    println!(
        "  {}: {drawn} of {total} pixels drawn, {coloured} coloured, {} colours",
        shot.path.display(),
        colours.len()
    );
    assert!(
        drawn > total / 50,
        "{}: the 3D view looks blank ({drawn} of {total} pixels differ from the background)",
        shot.path.display()
    );
    assert!(
        coloured > 500,
        "{}: hardly anything coloured in the 3D view ({coloured} pixels)",
        shot.path.display()
    );
    assert!(
        colours.len() >= 12,
        "{}: only {} colours in the 3D view",
        shot.path.display(),
        colours.len()
    );
}

/// The number of pixels of the 3D view that clearly differ between two screenshots.
fn changed(a: &Shot, b: &Shot) -> usize {
    a.region()
        .filter(|&(x, y)| distance(a.pixel(x, y), b.pixel(x, y)) > 40)
        .count()
}

fn assert_ready(dom: &str, what: &str) {
    assert!(
        dom.contains("data-ready=\"true\""),
        "{what}: the viewer did not finish drawing (no data-ready=\"true\"); the page says: {}",
        dom.split("id=\"message\"")
            .nth(1)
            .map_or("(nothing)", |m| &m[..m.len().min(400)])
    );
    assert!(
        dom.contains("<title>flexmb ready</title>"),
        "{what}: title not set"
    );
}

/// Writes the page of `results`, screenshots it at snapshots `k1` and `k2`, checks both and
/// returns how many pixels changed.
fn check_animation(name: &str, results: &Results, k1: usize, k2: usize) -> usize {
    let dir = artefacts();
    let page = dir.join(format!("{name}.html"));
    write_html(results, &page).expect("the page is written");
    let bytes = std::fs::metadata(&page).unwrap().len();
    println!("page: {} ({bytes} bytes)", page.display());
    assert!(bytes < 2_000_000, "{name}: the page is {bytes} bytes");

    let (a, dom_a) = screenshot(
        &page,
        &format!("frame={k1}&paused"),
        &dir.join(format!("{name}-frame{k1}.png")),
    );
    let (b, dom_b) = screenshot(
        &page,
        &format!("frame={k2}&paused"),
        &dir.join(format!("{name}-frame{k2}.png")),
    );
    assert_ready(&dom_a, name);
    assert_ready(&dom_b, name);
    // The slider went to the frame asked for.
    assert!(dom_a.contains(&format!("{} / {}", k1 + 1, results.snapshots.len())));
    assert!(dom_b.contains(&format!("{} / {}", k2 + 1, results.snapshots.len())));
    assert_not_blank(&a);
    assert_not_blank(&b);
    let n = changed(&a, &b);
    println!("  {n} pixels of the 3D view differ between snapshots {k1} and {k2}");
    n
}

#[test]
fn heavy_top_animation_draws_the_top_and_moves_between_snapshots_in_headless_chromium() {
    chromium();
    // 11 snapshots, 0.01 s apart; the top turns through about 130 degrees about its axis of
    // symmetry between snapshots 2 and 8.
    let results = collect("heavy_top.toml", 0.1);
    assert_eq!(results.snapshots.len(), 11);
    let changed = check_animation("heavy_top", &results, 2, 8);
    assert!(
        changed > 2000,
        "the top hardly moved on screen: {changed} pixels"
    );
}

#[test]
fn right_angle_cantilever_animation_draws_the_beams_and_moves_between_snapshots_in_headless_chromium(
) {
    chromium();
    // 48 steps of 0.125 s (6 s): the elbow rises to its peak near t = 3 s; snapshots 12 and 28
    // are t = 1.5 s (pushed up, bending) and 3.5 s (past the peak).
    let results = collect("right_angle_cantilever.toml", 6.0);
    assert_eq!(results.snapshots.len(), 49);
    let changed = check_animation("right_angle_cantilever", &results, 12, 28);
    assert!(
        changed > 2000,
        "the beams hardly moved on screen: {changed} pixels"
    );
}
