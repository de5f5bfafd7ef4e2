//! Learning curves: PNG plots of a run's `metrics.csv`, drawn with plotters' bitmap backend.
//!
//! [`plot_run`] draws one image, `learning_curves.png`, with a grid of [`GRID_COLUMNS`] panels per row,
//! each [`PANEL_WIDTH`] × [`PANEL_HEIGHT`] pixels. The panels, in order, each drawn only when the CSV
//! has at least one of its columns:
//!
//! | panel            | columns                                                      |
//! |------------------|--------------------------------------------------------------|
//! | mean reward      | `reward/mean`                                                |
//! | episode return   | `episode/return`                                             |
//! | success rate     | `episode/success_rate`                                       |
//! | episode length   | `episode/length`                                             |
//! | object error against the reference (m), (deg) | `tracking/obj_pos_err_m`, `tracking/obj_rot_err_deg` (reference kinds) |
//! | reward terms     | every other `reward/<term>`, one line each, with a legend    |
//! | loss: NAME       | one panel per `loss/NAME` but `loss/entropy`, each its own y scale |
//! | learning rate    | `lr`, log y                                                  |
//! | KL               | `kl`                                                         |
//! | entropy          | `loss/entropy`, `entropy`, `policy/entropy`                  |
//! | policy std       | `policy/std`                                                 |
//! | fps              | `fps`                                                        |
//! | student vs teacher | `distill/eval_student_success`, `distill/eval_teacher_success` (sparse) |
//!
//! x is the iteration, or the env steps when the CSV has an `env_steps` column. Non-finite values (and
//! non-positive ones on a log axis) are skipped: a line breaks around them, but in a sparse panel
//! (columns written every few iterations, `nan` between) it joins the finite points. Text uses DejaVu Sans,
//! embedded from assets/ (licence: assets/DejaVuSans-LICENSE.txt), registered with plotters' `ab_glyph`
//! font table, so no system font is needed.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use anyhow::{Context, Result, anyhow, bail};
use plotters::prelude::*;
use plotters::style::FontStyle;

use crate::metrics::columns::*;
use crate::metrics::read_csv;

/// Width of one panel, pixels.
pub const PANEL_WIDTH: u32 = 640;
/// Height of one panel, pixels.
pub const PANEL_HEIGHT: u32 = 400;
/// Panels per row of the grid (fewer when there are fewer panels).
pub const GRID_COLUMNS: u32 = 3;
/// The file [`plot_run`] writes.
pub const LEARNING_CURVES_PNG: &str = "learning_curves.png";

/// DejaVu Sans 2.37 (Bitstream Vera licence + Arev licence, see assets/DejaVuSans-LICENSE.txt).
pub(crate) static FONT: &[u8] = include_bytes!("../assets/DejaVuSans.ttf");

/// Size in pixels (width, height) of the grid image holding `panels` panels.
pub fn grid_size(panels: usize) -> (u32, u32) {
    let n = panels.max(1) as u32;
    let cols = n.min(GRID_COLUMNS);
    let rows = n.div_ceil(GRID_COLUMNS);
    (cols * PANEL_WIDTH, rows * PANEL_HEIGHT)
}

/// Reads dir/metrics.csv and writes PNGs into `out_dir` (created): `learning_curves.png` with a grid of
/// panels: mean reward, success rate, episode length, the tracking errors (reference kinds), every
/// column starting with "reward/" on one panel (one line each, with a legend), each loss
/// ("loss/...") on a panel of its own, learning rate (log y), KL, entropy,
/// fps; x = iteration (or env steps if an "env_steps" column exists). Panels for columns that are
/// absent are skipped (see the module docs for the full list). Returns the written paths.
///
/// Fails with a one-line error naming the file when `metrics_csv` cannot be read or has none of the
/// plotted columns. A CSV with a header and no rows gives empty panels.
pub fn plot_run(metrics_csv: &Path, out_dir: &Path) -> Result<Vec<PathBuf>> {
    let (columns, rows) = read_csv(metrics_csv)?;
    let panels = panels(&columns);
    if panels.is_empty() {
        bail!(
            "{}: none of its columns [{}] is plotted (expected e.g. reward/mean, episode/success_rate, loss/..., lr, fps)",
            metrics_csv.display(),
            columns.join(", ")
        );
    }
    register_font()?;
    std::fs::create_dir_all(out_dir).with_context(|| format!("creating {}", out_dir.display()))?;

    // x: env steps when logged, else the iteration
    let steps_col = columns.iter().position(|c| c == "env_steps");
    let xs: Vec<f64> = rows.iter().map(|(it, v)| steps_col.map_or(*it as f64, |k| v[k])).collect();
    let x_desc = if steps_col.is_some() { "env steps" } else { "iteration" };

    let out = out_dir.join(LEARNING_CURVES_PNG);
    // drawn under a temporary name (the extension picks the encoder), then renamed into place
    let tmp = out_dir.join(".learning_curves.tmp.png");
    let size = grid_size(panels.len());
    {
        let root = BitMapBackend::new(&tmp, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| draw_err(&out, e))?;
        let cols = (panels.len() as u32).min(GRID_COLUMNS) as usize;
        let rows_n = panels.len().div_ceil(GRID_COLUMNS as usize);
        let areas = root.split_evenly((rows_n, cols));
        for (panel, area) in panels.iter().zip(&areas) {
            let series: Vec<(String, Vec<f64>)> = panel
                .columns
                .iter()
                .map(|&k| (panel.label(&columns[k]), rows.iter().map(|(_, v)| v[k]).collect()))
                .collect();
            draw_panel(area, panel, x_desc, &xs, &series).map_err(|e| draw_err(&out, e))?;
        }
        root.present().map_err(|e| draw_err(&out, e))?;
    }
    std::fs::rename(&tmp, &out).with_context(|| format!("renaming {} to {}", tmp.display(), out.display()))?;
    Ok(vec![out])
}

fn draw_err(path: &Path, e: impl std::fmt::Display) -> anyhow::Error {
    anyhow!("drawing {}: {e}", path.display())
}

/// Registers the embedded font as plotters' "sans-serif" (once per process).
fn register_font() -> Result<()> {
    static DONE: OnceLock<bool> = OnceLock::new();
    let ok = *DONE.get_or_init(|| plotters::style::register_font("sans-serif", FontStyle::Normal, FONT).is_ok());
    if ok { Ok(()) } else { Err(anyhow!("the embedded font assets/DejaVuSans.ttf could not be parsed")) }
}

/// One panel of the grid: a title, the CSV columns it draws, and its y scale.
struct Panel {
    title: String,
    /// indices into the CSV's columns
    columns: Vec<usize>,
    log_y: bool,
    /// draw a legend (groups of columns)
    legend: bool,
    /// prefix stripped from legend labels
    strip: &'static str,
    /// the columns hold a value every few rows (`nan` between): join the finite points
    sparse: bool,
}

impl Panel {
    fn label(&self, column: &str) -> String {
        column.strip_prefix(self.strip).unwrap_or(column).to_string()
    }
}

/// The panels that `columns` can fill, in display order. Each loss has a panel and a y scale of
/// its own: PPO's surrogate (~0.01) beside its value loss (~100s), or distillation's action loss
/// beside its latent loss, would be a flat line at zero on a shared axis.
fn panels(columns: &[String]) -> Vec<Panel> {
    let find =
        |names: &[&str]| -> Vec<usize> { names.iter().filter_map(|n| columns.iter().position(|c| c == n)).collect() };
    let group = |prefix: &str, except: &str| -> Vec<usize> {
        (0..columns.len()).filter(|&k| columns[k].starts_with(prefix) && columns[k] != except).collect()
    };
    let single = |title: &str, names: &[&str]| Panel {
        title: title.to_string(),
        columns: find(names),
        log_y: false,
        legend: names.len() > 1 && find(names).len() > 1,
        strip: "",
        sparse: false,
    };
    let mut all = vec![
        single("mean reward", &[REWARD_MEAN]),
        single("episode return", &[EPISODE_RETURN]),
        single("success rate", &[EPISODE_SUCCESS_RATE]),
        single("episode length", &[EPISODE_LENGTH]),
        single("object error against the reference (m)", &[TRACKING_OBJ_POS_ERR_M]),
        single("object error against the reference (deg)", &[TRACKING_OBJ_ROT_ERR_DEG]),
        Panel {
            title: "reward terms".to_string(),
            columns: group(REWARD_PREFIX, REWARD_MEAN),
            log_y: false,
            legend: true,
            strip: REWARD_PREFIX,
            sparse: false,
        },
    ];
    // one panel per loss ("loss: value"), entropy apart (its own panel below)
    for k in group(LOSS_PREFIX, LOSS_ENTROPY) {
        let name = columns[k].strip_prefix(LOSS_PREFIX).unwrap_or(&columns[k]);
        all.push(Panel { title: format!("loss: {name}"), columns: vec![k], log_y: false, legend: false, strip: LOSS_PREFIX, sparse: false });
    }
    all.extend([
        Panel { title: "learning rate".to_string(), columns: find(&[LR]), log_y: true, legend: false, strip: "", sparse: false },
        single("KL", &[KL]),
        single("entropy", &[LOSS_ENTROPY, "entropy", POLICY_ENTROPY]),
        single("policy std", &[POLICY_STD]),
        single("fps", &[FPS]),
        Panel {
            title: "student vs teacher, same episodes".to_string(),
            columns: find(&[DISTILL_EVAL_STUDENT_SUCCESS, DISTILL_EVAL_TEACHER_SUCCESS]),
            log_y: false,
            legend: true,
            strip: DISTILL_EVAL_PREFIX,
            sparse: true,
        },
    ]);
    all.into_iter().filter(|p| !p.columns.is_empty()).collect()
}

/// The titles of the panels that a CSV with `columns` gets, in display order (a log axis says so).
pub fn panel_titles(columns: &[String]) -> Vec<String> {
    panels(columns).into_iter().map(|p| if p.log_y { format!("{} (log)", p.title) } else { p.title }).collect()
}

/// Splits a series into runs of drawable points (finite x and y; y > 0 on a log axis), y mapped to
/// log10 on a log axis; `sparse`: one run of all the drawable points.
fn segments(xs: &[f64], ys: &[f64], log_y: bool, sparse: bool) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut cur = Vec::new();
    for (&x, &y) in xs.iter().zip(ys) {
        let y = if log_y { if y > 0.0 { y.log10() } else { f64::NAN } } else { y };
        if x.is_finite() && y.is_finite() {
            cur.push((x, y));
        } else if !cur.is_empty() && !sparse {
            out.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        out.push(cur);
    }
    out
}

/// [lo, hi] of the values with a 5 % margin; a unit-ish range around a single value; 0..1 if empty.
fn padded_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() || !hi.is_finite() {
        return 0.0..1.0;
    }
    let span = hi - lo;
    if span <= 1e-12 * lo.abs().max(hi.abs()) || span == 0.0 {
        let pad = if lo == 0.0 { 0.5 } else { 0.05 * lo.abs() };
        return (lo - pad)..(hi + pad);
    }
    (lo - 0.05 * span)..(hi + 0.05 * span)
}

/// Line colours (matplotlib's "tab10"), cycled.
const COLORS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

type Area<'a> = DrawingArea<BitMapBackend<'a>, plotters::coord::Shift>;

fn draw_panel(
    area: &Area<'_>,
    panel: &Panel,
    x_desc: &str,
    xs: &[f64],
    series: &[(String, Vec<f64>)],
) -> std::result::Result<(), DrawingAreaErrorKind<<BitMapBackend<'static> as DrawingBackend>::ErrorType>> {
    let segs: Vec<Vec<Vec<(f64, f64)>>> = series.iter().map(|(_, ys)| segments(xs, ys, panel.log_y, panel.sparse)).collect();
    let points = || segs.iter().flatten().flatten();
    let x_range = padded_range(points().map(|p| p.0));
    let y_range = padded_range(points().map(|p| p.1));

    let title = if panel.log_y { format!("{} (log)", panel.title) } else { panel.title.clone() };
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 20))
        .margin(8)
        .x_label_area_size(40)
        .y_label_area_size(64)
        .build_cartesian_2d(x_range.clone(), y_range.clone())?;
    let (x_span, y_span) = (x_range.end - x_range.start, y_range.end - y_range.start);
    let x_fmt = |v: &f64| fmt_tick(*v, x_span);
    let y_fmt = |v: &f64| if panel.log_y { fmt_tick(10f64.powf(*v), 0.0) } else { fmt_tick(*v, y_span) };
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .x_labels(6)
        .y_labels(6)
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 14))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;

    for (i, ((label, _), runs)) in series.iter().zip(&segs).enumerate() {
        let color = COLORS[i % COLORS.len()];
        let style = ShapeStyle::from(&color).stroke_width(2);
        // lines for runs of >= 2 points, a dot for an isolated point; the first drawn (or, with
        // nothing drawable, an empty series) carries the legend entry
        let legend = move |(x, y): (i32, i32)| PathElement::new(vec![(x, y), (x + 20, y)], style);
        if runs.is_empty() && panel.legend {
            chart.draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())?.label(label.clone()).legend(legend);
        }
        for (k, run) in runs.iter().enumerate() {
            let anno = if run.len() >= 2 {
                chart.draw_series(LineSeries::new(run.iter().copied(), style))?
            } else {
                chart.draw_series(run.iter().map(|&p| Circle::new(p, 3, style.filled())))?
            };
            if k == 0 && panel.legend {
                anno.label(label.clone()).legend(legend);
            }
        }
    }
    if panel.legend {
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font(("sans-serif", 13))
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
    }
    Ok(())
}

/// A short tick label: up to 4 significant digits, k/M/G above 10 000, scientific below 0.001, and
/// "0" for values within rounding noise (1e-9 of the axis `span`) of zero.
fn fmt_tick(v: f64, span: f64) -> String {
    let a = v.abs();
    if a <= 1e-9 * span || !v.is_finite() {
        return if v.is_finite() { "0".to_string() } else { format!("{v}") };
    }
    for (from, scale, suffix) in [(1e9, 1e9, "G"), (1e6, 1e6, "M"), (1e4, 1e3, "k")] {
        if a >= from {
            return format!("{}{suffix}", trim(format!("{:.2}", v / scale)));
        }
    }
    if a < 1e-3 {
        let s = format!("{v:.2e}");
        let (mantissa, exp) = s.split_once('e').unwrap_or((&s, "0"));
        return format!("{}e{exp}", trim(mantissa.to_string()));
    }
    let decimals = (3 - a.log10().floor() as i32).clamp(0, 6) as usize;
    trim(format!("{v:.decimals$}"))
}

/// Drops trailing zeros (and a trailing '.') of a fixed-point number.
fn trim(s: String) -> String {
    if !s.contains('.') {
        return s;
    }
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}
