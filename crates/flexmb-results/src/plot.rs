//! Sensor histories as pictures: each sensor's value at every snapshot, drawn as a line
//! against time (x label `time [s]`) or, for a static run, against the load factor (x label
//! `load factor`).
//!
//! [`plot`] draws the sensors it is given, [`summary`] draws all of them (what a run writes as
//! `summary.png`). The figure is titled with the model's title and holds one or more panels
//! stacked above each other, sharing the x axis (its numbers and label are under the bottom
//! panel only):
//! - [`Layout::Shared`]: one panel with every line. Its y label is the unit in brackets when
//!   all the sensors have that unit; otherwise each legend entry carries its own unit.
//! - [`Layout::Stacked`]: one panel per unit, in the order the units first appear among the
//!   sensors; the y label is the unit in brackets, e.g. `[m]` (none for a pure number).
//! - [`Layout::Auto`] (the default): shared when all the sensors have the same unit, stacked
//!   otherwise.
//!
//! Each panel has its legend on a white background in the corner (or the middle of a side)
//! that its lines cross least. The
//! lines of a panel get ten distinct colours, then the colours again dashed, then dotted.
//! A value that is not finite (NaN, infinite) is left out and breaks its line; a y range of
//! zero span (a constant sensor) is widened so that the line shows in the middle.
//!
//! The format follows the file's extension, `.png` (1200 pixels wide, 350 high per panel
//! for up to six panels, less each above that down to 180) or `.svg` (the same size, text as
//! text). Text is drawn with DejaVu Sans, which this crate embeds (`assets/`, with its
//! licence), so that no system font library is needed.

use crate::info::SensorInfo;
use crate::Results;
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::{DashedPathElement, MultiLineText};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{register_font, FontStyle, TextStyle};
use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::OnceLock;

/// How the lines are split into panels.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Layout {
    /// [`Layout::Shared`] when all the sensors have the same unit, [`Layout::Stacked`]
    /// otherwise.
    #[default]
    Auto,
    /// One panel with all the lines.
    Shared,
    /// One panel per unit.
    Stacked,
}

impl FromStr for Layout {
    type Err = String;
    /// `auto`, `shared` or `stacked`.
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(Layout::Auto),
            "shared" => Ok(Layout::Shared),
            "stacked" => Ok(Layout::Stacked),
            _ => Err(format!(
                "unknown layout `{s}`: expected auto, shared or stacked"
            )),
        }
    }
}

impl fmt::Display for Layout {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Layout::Auto => "auto",
            Layout::Shared => "shared",
            Layout::Stacked => "stacked",
        })
    }
}

/// Why a plot was not drawn.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// A sensor asked for is not in the model.
    #[error("no sensor called `{name}`; {}", sensor_list(.available))]
    UnknownSensor {
        name: String,
        /// The names of the model's sensors.
        available: Vec<String>,
    },
    /// The file is neither `.png` nor `.svg`.
    #[error("cannot plot to `{}`: the file name must end in .png or .svg", .path.display())]
    Extension { path: PathBuf },
    /// The model has no sensors ([`summary`] reports it as [`Summary::NoSensors`]).
    #[error("nothing to plot: the model has no sensors")]
    NoSensors,
    /// The results have no snapshots ([`summary`] reports it as [`Summary::NoSnapshots`]).
    #[error("nothing to plot: the results have no snapshots")]
    NoSnapshots,
    /// Drawing or writing the file failed.
    #[error("cannot draw `{}`: {message}", .path.display())]
    Draw { path: PathBuf, message: String },
}

fn sensor_list(names: &[String]) -> String {
    if names.is_empty() {
        "the model has no sensors".into()
    } else {
        format!("the sensors are: {}", names.join(", "))
    }
}

/// What [`summary`] did. Only `Written` wrote a file; the others say why there was nothing
/// to draw, as a note for the user ([`Summary::note`]), not as a failure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[must_use]
pub enum Summary {
    /// The file was written with `shown` of the `total` sensors (fewer when there are too
    /// many to read; the figure says so).
    Written { shown: usize, total: usize },
    /// The model has no sensors: no file was written.
    NoSensors,
    /// The results have no snapshots: no file was written.
    NoSnapshots,
}

impl Summary {
    /// A sentence for the user when the summary is not the whole story: nothing written, or
    /// not every sensor drawn.
    pub fn note(&self) -> Option<String> {
        match *self {
            Summary::Written { shown, total } if shown < total => Some(format!(
                "the summary plot shows {shown} of the {total} sensors"
            )),
            Summary::Written { .. } => None,
            Summary::NoSensors => Some("no summary plot: the model has no sensors".into()),
            Summary::NoSnapshots => Some("no summary plot: the results have no snapshots".into()),
        }
    }
}

/// At most this many panels in [`summary`], ...
pub const SUMMARY_MAX_PANELS: usize = 8;
/// ... this many lines in one of its panels ...
pub const SUMMARY_MAX_LINES_PER_PANEL: usize = 10;
/// ... and this many lines in all.
pub const SUMMARY_MAX_LINES: usize = 40;

/// Draws the histories of the sensors called `sensors` (all of them when the list is empty)
/// into `path`, a `.png` or `.svg` file, with the panels of `layout`.
pub fn plot(
    results: &Results,
    sensors: &[String],
    layout: Layout,
    path: &Path,
) -> Result<(), PlotError> {
    let format = Format::of(path)?;
    let all = &results.info.sensors;
    if all.is_empty() {
        return Err(PlotError::NoSensors);
    }
    let mut chosen: Vec<usize> = Vec::new();
    if sensors.is_empty() {
        chosen.extend(0..all.len());
    }
    for name in sensors {
        let k = results
            .info
            .sensor(name)
            .ok_or_else(|| PlotError::UnknownSensor {
                name: name.clone(),
                available: all.iter().map(|s| s.name.clone()).collect(),
            })?;
        if !chosen.contains(&k) {
            chosen.push(k);
        }
    }
    if results.snapshots.is_empty() {
        return Err(PlotError::NoSnapshots);
    }
    let one_unit = chosen.iter().all(|&k| all[k].unit == all[chosen[0]].unit);
    let stacked = match layout {
        Layout::Auto => !one_unit,
        Layout::Shared => false,
        Layout::Stacked => true,
    };
    let panels = if stacked {
        by_unit(results, &chosen)
    } else {
        vec![Panel {
            y_desc: if one_unit {
                bracketed(&all[chosen[0]].unit)
            } else {
                String::new()
            },
            lines: chosen
                .iter()
                .map(|&k| {
                    let mut line = line(results, k);
                    if !one_unit && !all[k].unit.is_empty() {
                        line.label = format!("{} [{}]", all[k].name, all[k].unit);
                    }
                    line
                })
                .collect(),
        }]
    };
    let figure = Figure::new(results, panels, None);
    figure.write(path, format)
}

/// Draws every sensor, one panel per unit, into `path` (`.png` or `.svg`): the summary a run
/// writes as `summary.png`. With many units or sensors only the first
/// [`SUMMARY_MAX_PANELS`] units, the first [`SUMMARY_MAX_LINES_PER_PANEL`] sensors of each
/// and [`SUMMARY_MAX_LINES`] sensors in all are drawn, and a note under the figure says so.
///
/// With no sensors or no snapshots nothing is written and the answer says which
/// ([`Summary::note`] words it for the user); a bad extension or a failure to draw is an
/// error.
pub fn summary(results: &Results, path: &Path) -> Result<Summary, PlotError> {
    let format = Format::of(path)?;
    let total = results.info.sensors.len();
    if total == 0 {
        return Ok(Summary::NoSensors);
    }
    if results.snapshots.is_empty() {
        return Ok(Summary::NoSnapshots);
    }
    let all: Vec<usize> = (0..total).collect();
    let mut panels = by_unit(results, &all);
    let units = panels.len();
    panels.truncate(SUMMARY_MAX_PANELS);
    let crowded = panels
        .iter()
        .any(|p| p.lines.len() > SUMMARY_MAX_LINES_PER_PANEL);
    let mut room = SUMMARY_MAX_LINES;
    for p in &mut panels {
        p.lines.truncate(SUMMARY_MAX_LINES_PER_PANEL.min(room));
        room -= p.lines.len();
    }
    panels.retain(|p| !p.lines.is_empty());
    let shown: usize = panels.iter().map(|p| p.lines.len()).sum();
    let note = (shown < total).then(|| {
        let mut how = vec![format!("{} of {units} units", panels.len())];
        if crowded {
            how.push(format!("at most {SUMMARY_MAX_LINES_PER_PANEL} per unit"));
        }
        format!(
            "Showing {shown} of {total} sensors ({}); plot the others by name.",
            how.join(", ")
        )
    });
    let figure = Figure::new(results, panels, note);
    figure.write(path, format)?;
    Ok(Summary::Written { shown, total })
}

/// `[unit]`, or nothing for a pure number.
fn bracketed(unit: &str) -> String {
    if unit.is_empty() {
        String::new()
    } else {
        format!("[{unit}]")
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Format {
    Png,
    Svg,
}

impl Format {
    fn of(path: &Path) -> Result<Self, PlotError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => Ok(Format::Png),
            Some("svg") => Ok(Format::Svg),
            _ => Err(PlotError::Extension { path: path.into() }),
        }
    }
}

/// One sensor's line.
struct Line {
    label: String,
    values: Vec<f64>,
}

fn line(results: &Results, k: usize) -> Line {
    let SensorInfo { name, .. } = &results.info.sensors[k];
    Line {
        label: name.clone(),
        // A snapshot short of sensor values (a damaged file) leaves a gap, not a panic.
        values: results
            .snapshots
            .iter()
            .map(|s| s.sensors.get(k).copied().unwrap_or(f64::NAN))
            .collect(),
    }
}

struct Panel {
    y_desc: String,
    lines: Vec<Line>,
}

/// The sensors `chosen`, one panel per unit in order of first appearance.
fn by_unit(results: &Results, chosen: &[usize]) -> Vec<Panel> {
    let mut units: Vec<&str> = Vec::new();
    let mut panels: Vec<Panel> = Vec::new();
    for &k in chosen {
        let unit = results.info.sensors[k].unit.as_str();
        let p = match units.iter().position(|u| *u == unit) {
            Some(p) => p,
            None => {
                units.push(unit);
                panels.push(Panel {
                    y_desc: bracketed(unit),
                    lines: Vec::new(),
                });
                panels.len() - 1
            }
        };
        panels[p].lines.push(line(results, k));
    }
    panels
}

const WIDTH: u32 = 1200;
/// Panel height up to [`FULL_PANELS`] panels; above, the panels share
/// `FULL_PANELS * PANEL_HEIGHT` down to [`MIN_PANEL_HEIGHT`] each.
const PANEL_HEIGHT: u32 = 350;
const FULL_PANELS: u32 = 6;
const MIN_PANEL_HEIGHT: u32 = 180;
/// Under the bottom panel: the x numbers and label.
const X_AXIS_HEIGHT: u32 = 55;
const NOTE_HEIGHT: u32 = 30;
const FONT: &str = "sans-serif";
const TITLE_SIZE: f64 = 24.0;
const DESC_SIZE: f64 = 16.0;
const TICK_SIZE: f64 = 13.0;
const LEGEND_SIZE: f64 = 14.0;
/// Height of a legend entry in pixels, at least.
const LEGEND_LINE: u32 = 18;
const MARGIN_RIGHT: u32 = 25;

/// Line colours: distinct from each other and readable on white.
const COLOURS: [RGBColor; 10] = [
    RGBColor(0, 114, 178),
    RGBColor(230, 130, 0),
    RGBColor(0, 150, 100),
    RGBColor(200, 40, 50),
    RGBColor(125, 85, 180),
    RGBColor(90, 180, 230),
    RGBColor(140, 90, 45),
    RGBColor(215, 110, 170),
    RGBColor(70, 70, 70),
    RGBColor(170, 165, 0),
];

/// A line's look: colour and dash pattern, from its index in the panel.
#[derive(Clone, Copy)]
struct Pen {
    style: ShapeStyle,
    /// Dash and gap lengths in pixels; none for a solid line.
    dash: Option<(u32, u32)>,
}

impl Pen {
    fn of(index: usize) -> Self {
        let colour = COLOURS[index % COLOURS.len()];
        let dash = match (index / COLOURS.len()) % 3 {
            0 => None,
            1 => Some((9, 5)),
            _ => Some((2, 4)),
        };
        Pen {
            style: colour.stroke_width(2),
            dash,
        }
    }
}

/// Everything that is drawn, with the sizes worked out.
struct Figure {
    title: String,
    x_desc: &'static str,
    x: Vec<f64>,
    x_range: (f64, f64),
    panels: Vec<Panel>,
    y_ranges: Vec<(f64, f64)>,
    note: Option<String>,
    /// Per panel, without the x axis under the bottom one.
    panel_heights: Vec<u32>,
}

impl Figure {
    fn new(results: &Results, panels: Vec<Panel>, note: Option<String>) -> Self {
        let x_desc = if results.info.first == "load_factor" {
            "load factor"
        } else {
            "time [s]"
        };
        let x = results.times();
        let x_range = axis_range(x.iter().copied(), false);
        let y_ranges = panels
            .iter()
            .map(|p| axis_range(p.lines.iter().flat_map(|l| l.values.iter().copied()), true))
            .collect();
        let n = panels.len() as u32;
        let panel_height = if n <= FULL_PANELS {
            PANEL_HEIGHT
        } else {
            (FULL_PANELS * PANEL_HEIGHT / n).max(MIN_PANEL_HEIGHT)
        };
        // A panel with a long legend grows to hold it.
        let panel_heights = panels
            .iter()
            .map(|p| panel_height.max(LEGEND_LINE * p.lines.len() as u32 + 60))
            .collect();
        Figure {
            title: results.info.title.clone(),
            x_desc,
            x,
            x_range,
            panels,
            y_ranges,
            note,
            panel_heights,
        }
    }

    fn title_height(&self) -> u32 {
        if self.title.is_empty() {
            10
        } else {
            45
        }
    }

    fn size(&self) -> (u32, u32) {
        let note = if self.note.is_some() { NOTE_HEIGHT } else { 0 };
        let panels: u32 = self.panel_heights.iter().sum();
        (WIDTH, self.title_height() + panels + X_AXIS_HEIGHT + note)
    }

    fn write(&self, path: &Path, format: Format) -> Result<(), PlotError> {
        register_bundled_font().map_err(|message| PlotError::Draw {
            path: path.into(),
            message,
        })?;
        let size = self.size();
        let drawn = match format {
            Format::Png => {
                // Drawn into memory, then encoded by `png` (plotters' own encoder would bring
                // in the `image` crate for this one call).
                let mut rgb = vec![0u8; 3 * size.0 as usize * size.1 as usize];
                self.draw(BitMapBackend::with_buffer(&mut rgb, size).into_drawing_area())
                    .and_then(|()| write_png(path, size, &rgb))
            }
            Format::Svg => self.draw(SVGBackend::new(path, size).into_drawing_area()),
        };
        drawn.map_err(|message| PlotError::Draw {
            path: path.into(),
            message,
        })
    }

    fn draw<DB: DrawingBackend>(&self, root: DrawingArea<DB, Shift>) -> Result<(), String> {
        let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
        root.fill(&WHITE).map_err(e)?;
        let (width, height) = root.dim_in_pixel();
        let (top, rest) = root.split_vertically(self.title_height());
        if !self.title.is_empty() {
            let style = TextStyle::from((FONT, TITLE_SIZE).into_font())
                .pos(Pos::new(HPos::Center, VPos::Center));
            top.draw_text(
                &self.title,
                &style,
                (width as i32 / 2, self.title_height() as i32 / 2 + 3),
            )
            .map_err(e)?;
        }
        let note_height = if self.note.is_some() { NOTE_HEIGHT } else { 0 };
        let (body, bottom) = rest.split_vertically(height - self.title_height() - note_height);
        if let Some(note) = &self.note {
            let style = TextStyle::from((FONT, LEGEND_SIZE).into_font())
                .color(&RGBColor(90, 90, 90))
                .pos(Pos::new(HPos::Left, VPos::Center));
            bottom
                .draw_text(note, &style, (15, NOTE_HEIGHT as i32 / 2))
                .map_err(e)?;
        }
        let breaks: Vec<i32> = self
            .panel_heights
            .iter()
            .scan(0, |top, h| {
                *top += *h as i32;
                Some(*top)
            })
            .take(self.panels.len().saturating_sub(1))
            .collect();
        let areas = body.split_by_breakpoints::<i32, i32, _, _>([], breaks);
        let y_label_width = self.y_label_width(&root).map_err(e)?;
        for (k, area) in areas.iter().enumerate() {
            let last = k + 1 == self.panels.len();
            self.draw_panel(area, k, last, y_label_width).map_err(e)?;
        }
        root.present().map_err(e)
    }

    /// The width left of the panels for the y numbers and label, the same for all panels so
    /// that they line up.
    fn y_label_width<DB: DrawingBackend>(
        &self,
        root: &DrawingArea<DB, Shift>,
    ) -> Result<u32, DrawingAreaErrorKind<DB::ErrorType>> {
        let style = TextStyle::from((FONT, TICK_SIZE).into_font());
        let mut widest = 0;
        for (k, &(lo, hi)) in self.y_ranges.iter().enumerate() {
            let ticks = Ticks::new(lo, hi, self.y_labels(k));
            for v in [lo, hi, 0.5 * (lo + hi)] {
                let (w, _) = root.estimate_text_size(&ticks.label(v), &style)?;
                widest = widest.max(w);
            }
        }
        let has_desc = self.panels.iter().any(|p| !p.y_desc.is_empty());
        let desc = if has_desc { DESC_SIZE as u32 + 12 } else { 0 };
        Ok(widest + 18 + desc)
    }

    /// How many numbers on the y axis of panel `k`, about.
    fn y_labels(&self, k: usize) -> usize {
        (self.panel_heights[k] as usize / 50).clamp(3, 8)
    }

    fn draw_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        k: usize,
        last: bool,
        y_label_width: u32,
    ) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
        let panel = &self.panels[k];
        let (x0, x1) = self.x_range;
        let (y0, y1) = self.y_ranges[k];
        let mut chart = ChartBuilder::on(area)
            .margin_top(8)
            .margin_bottom(if last { 0 } else { 8 })
            .margin_left(10)
            .margin_right(MARGIN_RIGHT)
            .x_label_area_size(if last { X_AXIS_HEIGHT } else { 0 })
            .y_label_area_size(y_label_width)
            .build_cartesian_2d(x0..x1, y0..y1)?;

        let x_ticks = Ticks::new(x0, x1, 10);
        let y_ticks = Ticks::new(y0, y1, self.y_labels(k));
        let x_format = |v: &f64| x_ticks.label(*v);
        let y_format = |v: &f64| y_ticks.label(*v);
        let tick_font = (FONT, TICK_SIZE).into_font();
        let desc_font = (FONT, DESC_SIZE).into_font();
        let mut mesh = chart.configure_mesh();
        mesh.x_labels(10)
            .y_labels(self.y_labels(k))
            .x_label_formatter(&x_format)
            .y_label_formatter(&y_format)
            .label_style(tick_font)
            .axis_desc_style(desc_font)
            .max_light_lines(4)
            .light_line_style(RGBColor(238, 238, 238))
            .bold_line_style(RGBColor(205, 205, 205));
        if last {
            mesh.x_desc(self.x_desc);
        }
        if !panel.y_desc.is_empty() {
            mesh.y_desc(panel.y_desc.as_str());
        }
        mesh.draw()?;

        for (i, line) in panel.lines.iter().enumerate() {
            let pen = Pen::of(i);
            let runs = finite_runs(&self.x, &line.values);
            // The legend entry goes with the first piece drawn (an empty one for a line with
            // no finite value, so that it is still listed).
            let mut labelled = false;
            for run in runs.iter().chain(std::iter::once(&Vec::new())) {
                if labelled && run.is_empty() {
                    continue;
                }
                let anno = if run.len() == 1 {
                    chart.draw_series(std::iter::once(Circle::new(
                        run[0],
                        2,
                        pen.style.filled(),
                    )))?
                } else {
                    match pen.dash {
                        None => chart.draw_series(LineSeries::new(run.clone(), pen.style))?,
                        Some((dash, gap)) => chart.draw_series(DashedLineSeries::new(
                            run.clone(),
                            dash,
                            gap,
                            pen.style,
                        ))?,
                    }
                };
                if !labelled {
                    labelled = true;
                    anno.label(line.label.as_str())
                        .legend(move |(x, y)| legend_mark(pen, x, y));
                }
            }
        }

        let corner = self.legend_corner(&chart, panel);
        chart
            .configure_series_labels()
            .position(corner)
            .label_font((FONT, LEGEND_SIZE).into_font())
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(160, 160, 160))
            .draw()
    }

    /// The place for the legend where it hides the fewest points of the lines (sampled
    /// along them): a corner of the plotting area or the middle of a side, in that order of
    /// preference on a tie (upper right first).
    fn legend_corner<DB: DrawingBackend>(
        &self,
        chart: &ChartContext<DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
        panel: &Panel,
    ) -> SeriesLabelPosition {
        let style = TextStyle::from((FONT, LEGEND_SIZE).into_font());
        let mut text = MultiLineText::<(i32, i32), &str>::new((0, 0), &style);
        for line in &panel.lines {
            text.push_line(line.label.as_str());
        }
        // (Should the font fail, plotters fails to draw the legend anyway.)
        let (tw, th) = text.estimate_dimension().unwrap_or((0, 0));
        // The legend's box as plotters lays it out: 30 px for the mark, 10 px margins, 5 px
        // from the area's edges.
        let (w, h) = (tw + 30 + 20, th + 20);
        let area = chart.plotting_area();
        let (aw, ah) = area.dim_in_pixel();
        let (aw, ah) = (aw as i32, ah as i32);
        let (bx, by) = area.get_base_pixel();
        let (left, centre, right) = (5, (aw - w) / 2, aw - w - 5);
        let (top, middle, bottom) = (5, (ah - h) / 2, ah - h - 5);
        let corners = [
            (SeriesLabelPosition::UpperRight, right, top),
            (SeriesLabelPosition::UpperLeft, left, top),
            (SeriesLabelPosition::LowerRight, right, bottom),
            (SeriesLabelPosition::LowerLeft, left, bottom),
            (SeriesLabelPosition::MiddleRight, right, middle),
            (SeriesLabelPosition::MiddleLeft, left, middle),
            (SeriesLabelPosition::UpperMiddle, centre, top),
            (SeriesLabelPosition::LowerMiddle, centre, bottom),
        ];
        let mut hidden = [0usize; 8];
        for line in &panel.lines {
            for run in finite_runs(&self.x, &line.values) {
                let pixels: Vec<(i32, i32)> = run
                    .iter()
                    .map(|p| {
                        let (px, py) = chart.backend_coord(p);
                        (px - bx, py - by)
                    })
                    .collect();
                let mut count = |(px, py): (i32, i32)| {
                    for (c, &(_, cx, cy)) in corners.iter().enumerate() {
                        if px >= cx - 4 && px <= cx + w + 4 && py >= cy - 4 && py <= cy + h + 4 {
                            hidden[c] += 1;
                        }
                    }
                };
                if let [p] = pixels[..] {
                    count(p);
                }
                for pair in pixels.windows(2) {
                    let (a, b) = (pair[0], pair[1]);
                    let steps = ((b.0 - a.0).abs().max((b.1 - a.1).abs()) / 4).clamp(1, 400);
                    for s in 0..steps {
                        let t = s as f64 / steps as f64;
                        count((
                            a.0 + ((b.0 - a.0) as f64 * t).round() as i32,
                            a.1 + ((b.1 - a.1) as f64 * t).round() as i32,
                        ));
                    }
                }
                if let Some(&p) = pixels.last() {
                    if pixels.len() > 1 {
                        count(p);
                    }
                }
            }
        }
        let best = (0..corners.len())
            .min_by_key(|&c| (hidden[c], c))
            .unwrap_or(0);
        corners[best].0.clone()
    }
}

/// The mark of a line in its legend: a short stretch of it.
fn legend_mark<DB: DrawingBackend>(
    pen: Pen,
    x: i32,
    y: i32,
) -> DynElement<'static, DB, (i32, i32)> {
    let points = vec![(x, y), (x + 22, y)];
    match pen.dash {
        None => PathElement::new(points, pen.style).into_dyn(),
        Some((dash, gap)) => DashedPathElement::new(points, dash, gap, pen.style).into_dyn(),
    }
}

/// The pieces of a line between values that are not finite.
fn finite_runs(x: &[f64], y: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let mut runs = Vec::new();
    let mut run = Vec::new();
    for (&x, &y) in x.iter().zip(y) {
        if x.is_finite() && y.is_finite() {
            run.push((x, y));
        } else if !run.is_empty() {
            runs.push(std::mem::take(&mut run));
        }
    }
    if !run.is_empty() {
        runs.push(run);
    }
    runs
}

/// The drawn range of finite `values` (−1 to 1 when there are none), with a margin of 5 %
/// each side when `margin`. A range narrower than a millionth of its magnitude is widened
/// to that (a constant to round-off is drawn flat), a constant one to ±5 % of its value
/// (±1 about zero).
fn axis_range(values: impl Iterator<Item = f64>, margin: bool) -> (f64, f64) {
    // Beyond this the span would overflow; such values are clipped at the edges.
    const BIG: f64 = 1e300;
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .map(|v| v.clamp(-BIG, BIG))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if lo > hi {
        return (-1.0, 1.0);
    }
    let magnitude = lo.abs().max(hi.abs());
    let mid = 0.5 * (lo + hi);
    let span = hi - lo;
    let (lo, hi) = if span <= 1e-12 * magnitude || magnitude < 1e-300 {
        let half = if magnitude < 1e-300 {
            1.0
        } else {
            0.05 * magnitude
        };
        (mid - half, mid + half)
    } else if span < 1e-6 * magnitude {
        let half = 0.5e-6 * magnitude;
        (mid - half, mid + half)
    } else if margin {
        (lo - 0.05 * span, hi + 0.05 * span)
    } else {
        (lo, hi)
    };
    (lo, hi)
}

/// How the numbers on an axis are written: with as many digits as the tick spacing needs
/// (trailing zeros dropped), in scientific notation for magnitudes under 1e-3 or from 1e5.
struct Ticks {
    /// Spacing of the ticks, about.
    step: f64,
    scientific: bool,
    /// Decimals (fixed) or decimals of the mantissa (scientific).
    digits: usize,
}

impl Ticks {
    fn new(lo: f64, hi: f64, count: usize) -> Self {
        let step = ((hi - lo) / count.max(1) as f64).abs();
        let step = if step > 0.0 && step.is_finite() {
            step
        } else {
            1.0
        };
        let step_exp = step.log10().floor() as i64;
        let magnitude = lo.abs().max(hi.abs());
        let scientific = magnitude > 0.0 && !(1e-3..1e5).contains(&magnitude);
        let digits = if scientific {
            let mag_exp = magnitude.log10().floor() as i64;
            (mag_exp - step_exp + 1).clamp(0, 10) as usize
        } else {
            (1 - step_exp).clamp(0, 12) as usize
        };
        Ticks {
            step,
            scientific,
            digits,
        }
    }

    fn label(&self, v: f64) -> String {
        if v.abs() < 1e-9 * self.step {
            return "0".into();
        }
        if self.scientific {
            let s = format!("{:.*e}", self.digits, v);
            match s.split_once('e') {
                Some((mantissa, exp)) => format!("{}e{exp}", trim_zeros(mantissa)),
                None => s,
            }
        } else {
            trim_zeros(&format!("{:.*}", self.digits, v)).into()
        }
    }
}

/// `1.2500` → `1.25`, `3.000` → `3`.
fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// DejaVu Sans, registered once as plotters' `sans-serif`.
fn register_bundled_font() -> Result<(), String> {
    static FONT_DATA: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| register_font(FONT, FontStyle::Normal, FONT_DATA).is_ok());
    if ok {
        Ok(())
    } else {
        Err("the bundled font DejaVu Sans could not be read".into())
    }
}

/// Writes 8-bit RGB pixels, row after row, as a PNG file.
fn write_png(path: &Path, (width, height): (u32, u32), rgb: &[u8]) -> Result<(), String> {
    let file = std::fs::File::create(path).map_err(|e| e.to_string())?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
    writer.write_image_data(rgb).map_err(|e| e.to_string())?;
    writer.finish().map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_have_the_digits_the_spacing_needs() {
        let t = Ticks::new(0.0, 2.0, 10);
        assert_eq!(t.label(0.2), "0.2");
        assert_eq!(t.label(0.25), "0.25");
        assert_eq!(t.label(1.0), "1");
        assert_eq!(t.label(1e-17), "0");
        let t = Ticks::new(0.0, 3e-13, 5);
        assert_eq!(t.label(1.5e-13), "1.5e-13");
        let t = Ticks::new(2e5, 4e5, 5);
        assert_eq!(t.label(2.5e5), "2.5e5");
        let t = Ticks::new(-150.0, 150.0, 6);
        assert_eq!(t.label(-100.0), "-100");
    }

    #[test]
    fn ranges_have_a_span_and_ignore_what_is_not_finite() {
        assert_eq!(axis_range([3.0, 3.0].into_iter(), true), (2.85, 3.15));
        assert_eq!(axis_range([0.0, 0.0].into_iter(), true), (-1.0, 1.0));
        assert_eq!(axis_range([f64::NAN].into_iter(), true), (-1.0, 1.0));
        let (lo, hi) = axis_range([0.0, f64::INFINITY, 1.0, f64::NAN].into_iter(), false);
        assert_eq!((lo, hi), (0.0, 1.0));
        let (lo, hi) = axis_range([150.0, 150.0 + 1e-10].into_iter(), true);
        assert!(hi - lo > 1e-4 && lo < 150.0 && hi > 150.0);
        let (lo, hi) = axis_range([-f64::MAX, f64::MAX].into_iter(), true);
        assert!(lo.is_finite() && hi.is_finite() && lo < hi);
    }

    #[test]
    fn runs_break_at_values_that_are_not_finite() {
        let x = [0.0, 1.0, 2.0, 3.0, 4.0];
        let y = [1.0, f64::NAN, 2.0, 3.0, f64::INFINITY];
        assert_eq!(
            finite_runs(&x, &y),
            vec![vec![(0.0, 1.0)], vec![(2.0, 2.0), (3.0, 3.0)]]
        );
    }

    #[test]
    fn layouts_read_from_their_names() {
        for l in [Layout::Auto, Layout::Shared, Layout::Stacked] {
            assert_eq!(l.to_string().parse::<Layout>(), Ok(l));
        }
        assert!("grid".parse::<Layout>().is_err());
    }
}
