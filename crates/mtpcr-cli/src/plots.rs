//! The two figures of a results folder, drawn with plotters into an RGB buffer and encoded
//! with the png crate. Text uses the embedded DejaVu Sans (assets/, licence beside it), so
//! the charts are readable on machines without fonts.

use crate::error::{CliResult, Failure};
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use std::io::BufWriter;
use std::path::Path;
use std::sync::OnceLock;

static DEJAVU_SANS: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");
/// The family name the embedded font is registered under.
const FONT: &str = "sans-serif";

/// The colour of view `i` (the palette of the 3-D view, so every output agrees; also used in
/// `merged.ply`).
pub fn view_color(i: usize) -> [u8; 3] {
    crate::viewer::scan_color(i)
}

/// One colour per edge (J1, J2, J3, ...) in the convergence chart.
const TASK_COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(140, 86, 75),
];
/// Points drawn per panel of `views.png` (all three clouds together), at most.
const POINTS_PER_PANEL: usize = 20_000;

fn rgb(c: [u8; 3]) -> RGBColor {
    RGBColor(c[0], c[1], c[2])
}

fn ensure_font() -> CliResult<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    if *REGISTERED.get_or_init(|| register_font(FONT, FontStyle::Normal, DEJAVU_SANS).is_ok()) {
        Ok(())
    } else {
        Err(Failure("the embedded font cannot be loaded".to_string()))
    }
}

/// Draws into a fresh white `width x height` RGB image and writes it to `path` as PNG.
fn render_png<F>(path: &Path, (width, height): (u32, u32), draw: F) -> CliResult<()>
where
    F: FnOnce(&DrawingArea<BitMapBackend<'_>, Shift>) -> Result<(), String>,
{
    ensure_font()?;
    let failed = |what: &str, e: &dyn std::fmt::Display| {
        Failure(format!("{}: cannot {what}: {e}", path.display()))
    };
    let mut buf = vec![255u8; width as usize * height as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (width, height)).into_drawing_area();
        draw(&root).map_err(|e| failed("draw the figure", &e))?;
        root.present().map_err(|e| failed("draw the figure", &e))?;
    }
    let file =
        std::fs::File::create(path).map_err(|e| Failure(format!("{}: {e}", path.display())))?;
    let mut encoder = png::Encoder::new(BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(|e| failed("write", &e))?;
    writer
        .write_image_data(&buf)
        .map_err(|e| failed("write", &e))?;
    writer.finish().map_err(|e| failed("write", &e))
}

fn text(e: impl std::fmt::Display) -> String {
    e.to_string()
}

/// `convergence.png`: the best cost of each task per generation (row 0 is the initial
/// population) of the kept restart `histories[kept]`, the other restarts in thin grey;
/// aiding tasks J1-a, J2-a, ... on the left, original tasks J1-o, J2-o, ... on the right.
pub fn convergence_png(
    histories: &[Vec<Vec<f64>>],
    kept: usize,
    task_names: &[String],
    title: &str,
    path: &Path,
) -> CliResult<()> {
    let history = histories.get(kept).map_or(&[][..], Vec::as_slice);
    if history.is_empty() {
        return Err(Failure(format!(
            "{}: the run has no history to plot",
            path.display()
        )));
    }
    render_png(path, (1400, 600), |root| {
        root.fill(&WHITE).map_err(text)?;
        let root = root
            .margin(6, 0, 0, 0)
            .titled(title, (FONT, 26))
            .map_err(text)?;
        let panels = root.split_evenly((1, 2));
        let titles = [
            "Aiding tasks: mean capped distance (data units)",
            "Original tasks: 1 - inlier fraction + loop term",
        ];
        let edges = task_names.len() / 2;
        for (k, panel) in panels.iter().enumerate() {
            draw_costs(
                panel,
                histories,
                kept,
                task_names,
                (edges * k, edges),
                titles[k],
            )
            .map_err(text)?;
        }
        Ok(())
    })
}

fn draw_costs<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    histories: &[Vec<Vec<f64>>],
    kept: usize,
    task_names: &[String],
    (first, count): (usize, usize),
    title: &str,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let mut series = Vec::new();
    for (_, history) in histories.iter().enumerate().filter(|(r, _)| *r != kept) {
        for k in 0..count {
            series.push(Series {
                label: if series.is_empty() {
                    format!("other restarts ({})", histories.len() - 1)
                } else {
                    String::new()
                },
                color: RGBColor(185, 185, 185),
                values: history.iter().map(|row| row[first + k]).collect(),
                thin: true,
            });
        }
    }
    let history = &histories[kept];
    series.extend((0..count).map(|k| Series {
        label: task_names[first + k].clone(),
        color: TASK_COLORS[k % TASK_COLORS.len()],
        values: history.iter().map(|row| row[first + k]).collect(),
        thin: false,
    }));
    draw_series(area, &series, title, (20, 17, 3))
}

/// One line of a chart: a value per generation (index 0 is the initial population).
struct Series {
    /// Legend text; empty: no legend entry.
    label: String,
    color: RGBColor,
    values: Vec<f64>,
    /// Drawn one pixel wide (context lines).
    thin: bool,
}

/// Lines over generations with a legend; `(caption, legend, stroke)` sizes in pixels.
fn draw_series<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    series: &[Series],
    title: &str,
    (caption_size, legend_size, stroke): (u32, u32, u32),
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let values = series
        .iter()
        .flat_map(|s| s.values.iter().copied())
        .filter(|v| v.is_finite());
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    let pad = ((hi - lo) * 0.06).max(hi.abs().max(1e-12) * 0.02);
    let longest = series.iter().map(|s| s.values.len()).max().unwrap_or(0);
    let last = (longest as i32 - 1).max(1);
    let ticks = tick_format(hi - lo + 2.0 * pad, lo.abs().max(hi.abs()));
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, caption_size))
        .margin(18)
        .margin_right(30)
        .x_label_area_size(50)
        .y_label_area_size(85)
        .build_cartesian_2d(0..last, (lo - pad)..(hi + pad))?;
    chart
        .configure_mesh()
        .x_desc("generation")
        .y_desc("best cost")
        .axis_desc_style((FONT, 18))
        .label_style((FONT, 15))
        .y_label_formatter(&ticks)
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;
    for s in series {
        let color = s.color;
        let width = if s.thin { 1 } else { stroke };
        let drawn = chart.draw_series(LineSeries::new(
            s.values.iter().enumerate().map(|(g, &v)| (g as i32, v)),
            color.stroke_width(width),
        ))?;
        if !s.label.is_empty() {
            drawn.label(s.label.clone()).legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(width))
            });
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.9))
        .border_style(RGBColor(160, 160, 160))
        .label_font((FONT, legend_size))
        .draw()?;
    Ok(())
}

/// One colour per method in the method-comparison chart (tab10).
const METHOD_COLORS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

/// A convergence chart comparing methods: one row per edge k, aiding task J<k>-a on the
/// left and original task J<k>-o on the right; one line per method (`(label, history)`, the
/// history already averaged over runs).
pub(crate) fn methods_convergence_png(
    methods: &[(String, Vec<Vec<f64>>)],
    task_names: &[String],
    title: &str,
    path: &Path,
) -> CliResult<()> {
    if methods.iter().all(|(_, h)| h.is_empty()) {
        return Err(Failure(format!("{}: no history to plot", path.display())));
    }
    let edges = task_names.len() / 2;
    render_png(path, (1400, 500 * edges.max(1) as u32), |root| {
        root.fill(&WHITE).map_err(text)?;
        let root = root
            .margin(6, 0, 0, 0)
            .titled(title, (FONT, 26))
            .map_err(text)?;
        let panels = root.split_evenly((edges, 2));
        for pair in 0..edges {
            for (col, (first, kind)) in [(0, "aiding"), (edges, "original")].into_iter().enumerate()
            {
                let task = first + pair;
                let series: Vec<Series> = methods
                    .iter()
                    .enumerate()
                    .map(|(m, (label, history))| Series {
                        label: label.clone(),
                        color: METHOD_COLORS[m % METHOD_COLORS.len()],
                        values: history.iter().map(|row| row[task]).collect(),
                        thin: false,
                    })
                    .collect();
                let caption = format!("{} ({kind} task), mean over runs", task_names[task]);
                draw_series(&panels[2 * pair + col], &series, &caption, (18, 14, 2))
                    .map_err(text)?;
            }
        }
        Ok(())
    })
}

/// One panel of [`categories_log_png`]: a line per `(label, one value per category)`.
pub(crate) struct CategoryPanel {
    pub title: String,
    pub y_desc: String,
    pub series: Vec<(String, Vec<f64>)>,
}

/// A sensitivity chart: one panel per measure, one line per series, x the categories
/// `x_labels` evenly spaced, y logarithmic (errors of failed runs are orders of magnitude
/// above the others). Values <= 0 or not finite are left out. The legend sits lower left,
/// where error curves (high at small ratios, falling to the right) leave room.
pub(crate) fn categories_log_png(
    x_desc: &str,
    x_labels: &[String],
    panels: &[CategoryPanel],
    title: &str,
    path: &Path,
) -> CliResult<()> {
    let positive = |v: &f64| v.is_finite() && *v > 0.0;
    if x_labels.is_empty()
        || !panels
            .iter()
            .any(|p| p.series.iter().any(|(_, vs)| vs.iter().any(positive)))
    {
        return Err(Failure(format!("{}: nothing to plot", path.display())));
    }
    let width = 700 * panels.len().max(1) as u32;
    render_png(path, (width, 620), |root| {
        root.fill(&WHITE).map_err(text)?;
        let root = root
            .margin(6, 0, 0, 0)
            .titled(title, (FONT, 26))
            .map_err(text)?;
        let areas = root.split_evenly((1, panels.len()));
        for (area, panel) in areas.iter().zip(panels) {
            let (caption, y_desc, series) = (&panel.title, &panel.y_desc, &panel.series);
            let values = series.iter().flat_map(|(_, vs)| vs.iter().copied());
            let (lo, hi) = values
                .filter(positive)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                    (lo.min(v), hi.max(v))
                });
            let (lo, hi) = if lo.is_finite() {
                (lo / 1.5, hi * 1.5)
            } else {
                (0.1, 10.0)
            };
            let last = x_labels.len() as i32 - 1;
            let labels = x_labels.to_vec();
            let mut chart = ChartBuilder::on(area)
                .caption(caption, (FONT, 20))
                .margin(18)
                .margin_right(30)
                .x_label_area_size(50)
                .y_label_area_size(85)
                .build_cartesian_2d(-0.3f64..last as f64 + 0.3, (lo..hi).log_scale())
                .map_err(text)?;
            chart
                .configure_mesh()
                .x_desc(x_desc)
                .y_desc(y_desc.as_str())
                .axis_desc_style((FONT, 18))
                .label_style((FONT, 15))
                .x_labels(x_labels.len())
                .x_label_formatter(&|x: &f64| {
                    let i = x.round();
                    if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < labels.len() {
                        labels[i as usize].clone()
                    } else {
                        String::new()
                    }
                })
                .y_label_formatter(&|v: &f64| format!("{v}"))
                .light_line_style(RGBColor(235, 235, 235))
                .draw()
                .map_err(text)?;
            for (m, (label, vs)) in series.iter().enumerate() {
                let color = METHOD_COLORS[m % METHOD_COLORS.len()];
                let points: Vec<(f64, f64)> = vs
                    .iter()
                    .enumerate()
                    .filter(|(_, v)| positive(v))
                    .map(|(i, &v)| (i as f64, v))
                    .collect();
                chart
                    .draw_series(LineSeries::new(points.clone(), color.stroke_width(2)))
                    .map_err(text)?
                    .label(label.clone())
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(2))
                    });
                chart
                    .draw_series(points.iter().map(|&p| Circle::new(p, 4, color.filled())))
                    .map_err(text)?;
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::LowerLeft)
                .background_style(WHITE.mix(0.9))
                .border_style(RGBColor(160, 160, 160))
                .label_font((FONT, 15))
                .draw()
                .map_err(text)?;
        }
        Ok(())
    })
}

/// Tick labels for an axis spanning `span`: one number of decimals for the whole axis (enough
/// for about ten ticks), scientific notation for very small or large values, and a clean `0`
/// for rounding noise.
fn tick_format(span: f64, largest: f64) -> impl Fn(&f64) -> String {
    let span = if span.is_finite() && span > 0.0 {
        span
    } else {
        1.0
    };
    let step = span / 8.0;
    let decimals = (-step.log10()).ceil().clamp(0.0, 12.0) as usize;
    let scientific = largest.abs() >= 1e5 || (largest.abs() < 1e-3 && largest != 0.0);
    move |v: &f64| {
        if v.abs() < span * 1e-9 {
            "0".to_string()
        } else if scientific {
            format!("{v:.2e}")
        } else {
            format!("{v:.decimals$}")
        }
    }
}

/// One orthographic viewpoint: screen axes and depth as functions of a point.
struct Viewpoint {
    name: &'static str,
    x_desc: &'static str,
    y_desc: &'static str,
    /// `(screen x, screen y, depth towards the viewer)`.
    project: fn(&[f64; 3]) -> (f64, f64, f64),
}

const VIEWPOINTS: [Viewpoint; 2] = [
    Viewpoint {
        name: "seen from +z",
        x_desc: "x",
        y_desc: "y",
        project: |p| (p[0], p[1], p[2]),
    },
    Viewpoint {
        name: "seen from +x",
        x_desc: "-z",
        y_desc: "y",
        project: |p| (-p[2], p[1], p[0]),
    },
];

/// Every `k`-th point so that about `budget` remain.
fn subsample(points: &[[f64; 3]], budget: usize) -> impl Iterator<Item = &[f64; 3]> {
    let step = points.len().div_ceil(budget.max(1)).max(1);
    points.iter().step_by(step)
}

/// Legend entries per row of `views.png`.
const LEGEND_COLUMNS: usize = 4;

/// `views.png`: a 2x2 grid, rows before (each cloud as given, in its own frame) and after
/// registration (merged in the frame of cloud `reference`, numbered from 0), columns two
/// orthographic viewpoints; points drawn far to near, coloured per view. `labels` name the
/// clouds in the legend.
pub fn views_png(
    before: &[&[[f64; 3]]],
    after: &[&[[f64; 3]]],
    reference: usize,
    labels: &[String],
    path: &Path,
) -> CliResult<()> {
    let legend_rows = labels.len().div_ceil(LEGEND_COLUMNS).max(1) as u32;
    let (width, height) = (1300u32, 1340 + 50 * legend_rows);
    render_png(path, (width, height), |root| {
        root.fill(&WHITE).map_err(text)?;
        let root = root
            .margin(6, 0, 0, 0)
            .titled(
                &format!("The {} views before and after registration", labels.len()),
                (FONT, 26),
            )
            .map_err(text)?;
        let (grid, legend) =
            root.split_vertically(root.dim_in_pixel().1 as i32 - 50 * legend_rows as i32);
        let panels = grid.split_evenly((2, 2));
        let merged = format!("after: merged in cloud {}'s frame", reference + 1);
        for (row, (clouds, what)) in [
            (before, "before: as given, each in its own frame"),
            (after, merged.as_str()),
        ]
        .into_iter()
        .enumerate()
        {
            for (col, view) in VIEWPOINTS.iter().enumerate() {
                let caption = format!("{what}, {}", view.name);
                draw_view(&panels[2 * row + col], clouds, view, &caption).map_err(text)?;
            }
        }
        draw_legend(&legend, labels).map_err(text)
    })
}

fn draw_view<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    clouds: &[&[[f64; 3]]],
    view: &Viewpoint,
    caption: &str,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let area = area.titled(caption, (FONT, 19))?;
    let budget = POINTS_PER_PANEL / clouds.len().max(1);
    let mut points: Vec<(f64, f64, f64, usize)> = Vec::with_capacity(POINTS_PER_PANEL + 3);
    for (i, cloud) in clouds.iter().enumerate() {
        points.extend(subsample(cloud, budget).map(|p| {
            let (x, y, depth) = (view.project)(p);
            (x, y, depth, i)
        }));
    }
    // Painter's order: the farthest points first, so nearer surfaces hide them.
    points.sort_by(|a, b| a.2.total_cmp(&b.2));
    let bounds = points.iter().fold(
        [
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ],
        |b, &(x, y, _, _)| [b[0].min(x), b[1].max(x), b[2].min(y), b[3].max(y)],
    );
    let (cx, cy) = if points.is_empty() {
        (0.0, 0.0)
    } else {
        ((bounds[0] + bounds[1]) / 2.0, (bounds[2] + bounds[3]) / 2.0)
    };
    let (dx, dy) = if points.is_empty() {
        (1.0, 1.0)
    } else {
        (bounds[1] - bounds[0], bounds[3] - bounds[2])
    };
    let build = |x: std::ops::Range<f64>, y: std::ops::Range<f64>| {
        ChartBuilder::on(&area)
            .margin(12)
            .margin_right(32)
            .x_label_area_size(45)
            .y_label_area_size(75)
            .build_cartesian_2d(x, y)
    };
    // Equal scale on both axes: size the ranges to the plotting area's pixels.
    let (pw, ph) = build(0.0..1.0, 0.0..1.0)?.plotting_area().dim_in_pixel();
    let (pw, ph) = (f64::from(pw.max(1)), f64::from(ph.max(1)));
    let per_pixel = (dx / pw).max(dy / ph).max(1e-12) * 1.06;
    let (hw, hh) = (per_pixel * pw / 2.0, per_pixel * ph / 2.0);
    let mut chart = build((cx - hw)..(cx + hw), (cy - hh)..(cy + hh))?;
    let x_ticks = tick_format(2.0 * hw, cx.abs() + hw);
    let y_ticks = tick_format(2.0 * hh, cy.abs() + hh);
    chart
        .configure_mesh()
        .x_desc(format!("{} (data units)", view.x_desc))
        .y_desc(format!("{} (data units)", view.y_desc))
        .axis_desc_style((FONT, 17))
        .label_style((FONT, 14))
        .x_label_formatter(&x_ticks)
        .y_label_formatter(&y_ticks)
        // No minor grid: the points are the picture.
        .light_line_style(WHITE)
        .bold_line_style(RGBColor(225, 225, 225))
        .draw()?;
    chart.draw_series(
        points
            .iter()
            .map(|&(x, y, _, i)| Circle::new((x, y), 2, rgb(view_color(i)).filled())),
    )?;
    Ok(())
}

fn draw_legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    labels: &[String],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let (w, _) = area.dim_in_pixel();
    let slot = w as i32 / LEGEND_COLUMNS.min(labels.len()).max(1) as i32;
    for (i, label) in labels.iter().enumerate() {
        let x = slot * (i % LEGEND_COLUMNS) as i32 + 40;
        let y = 25 + 50 * (i / LEGEND_COLUMNS) as i32;
        area.draw(&Circle::new((x, y), 8, rgb(view_color(i)).filled()))?;
        let style =
            TextStyle::from((FONT, 19).into_font()).pos(plotters::style::text_anchor::Pos::new(
                plotters::style::text_anchor::HPos::Left,
                plotters::style::text_anchor::VPos::Center,
            ));
        area.draw(&Text::new(label.clone(), (x + 16, y), style))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_share_their_decimals_and_hide_rounding_noise() {
        let f = tick_format(0.012, 0.014);
        assert_eq!(
            (f(&0.008), f(&0.01)),
            ("0.008".to_string(), "0.010".to_string())
        );
        let f = tick_format(0.85, 1.0);
        assert_eq!((f(&0.9), f(&1.0)), ("0.9".to_string(), "1.0".to_string()));
        let f = tick_format(0.2, 0.1);
        assert_eq!(
            (f(&1.39e-17), f(&-0.08)),
            ("0".to_string(), "-0.08".to_string())
        );
        assert_eq!(tick_format(1e-4, 2e-5)(&2e-5), "2.00e-5");
    }

    #[test]
    fn subsampling_keeps_about_the_budget() {
        let pts = vec![[0.0; 3]; 10_001];
        let n = subsample(&pts, 1000).count();
        assert!((900..=1000).contains(&n), "{n}");
        assert_eq!(subsample(&pts[..5], 1000).count(), 5);
    }

    #[test]
    fn figures_are_png_files() {
        let dir = std::env::temp_dir().join(format!("mtpcr-cli-plots-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let history: Vec<Vec<f64>> = (0..6).map(|g| vec![1.0 / (g + 1) as f64; 6]).collect();
        let names = mtpcr_core::ViewGraph::ring(3).unwrap().task_names();
        let restarts = vec![history.clone(), history.clone()];
        convergence_png(&restarts, 1, &names, "t", &dir.join("c.png")).unwrap();
        let methods = vec![
            ("a".to_string(), history.clone()),
            ("b".to_string(), history),
        ];
        methods_convergence_png(&methods, &names, "t", &dir.join("m.png")).unwrap();
        let labels: Vec<String> = ["0.01", "0.1", "0.5"].map(String::from).to_vec();
        let panel = |name: &str| CategoryPanel {
            title: name.to_string(),
            y_desc: "error".to_string(),
            series: vec![("p".to_string(), vec![900.0, 2.0, 1.5])],
        };
        categories_log_png(
            "ratio",
            &labels,
            &[panel("R"), panel("T")],
            "t",
            &dir.join("s.png"),
        )
        .unwrap();
        assert!(categories_log_png("ratio", &labels, &[], "t", &dir.join("none.png")).is_err());
        let cloud: Vec<[f64; 3]> = (0..500).map(|i| [i as f64, (i % 7) as f64, 0.5]).collect();
        let labels = ["a".to_string(), "b".to_string(), "c".to_string()];
        views_png(
            &[&cloud, &cloud, &cloud],
            &[&cloud, &cloud, &cloud],
            0,
            &labels,
            &dir.join("v.png"),
        )
        .unwrap();
        for f in ["c.png", "v.png", "m.png", "s.png"] {
            let bytes = std::fs::read(dir.join(f)).unwrap();
            assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "{f}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
