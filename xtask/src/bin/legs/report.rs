//! The self-contained HTML report of a simulation: plots drawn by plotters (SVG, inlined)
//! and an animation of the linkage (the frames as JSON, drawn by a few lines of script).
//! Nothing is fetched: no network, no external file.

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use serde_json::{json, Value};

/// Named time series sharing one time axis, plotted together.
pub struct Series {
    title: String,
    t: Vec<f64>,
    lines: Vec<(String, Vec<f64>)>,
    /// A logarithmic y axis, for magnitudes that span decades (residuals).
    log: bool,
    /// Time intervals shaded behind the curves (a leg's stance phases).
    shade: Vec<(f64, f64)>,
    /// What the shaded intervals are, for the caption (`stance (a contact on the
    /// ground)` unless [`Series::shaded_as`] says).
    shade_meaning: String,
    /// The y axis: the quantity and its SI unit (`""` for a pure number); the unit gets
    /// the prefix that suits the data's range (mm, mN m).
    axis: Option<(String, String)>,
    /// What the figure's caption says after its title.
    caption: String,
}

impl Series {
    pub fn new(title: &str, t: &[f64], lines: Vec<(String, Vec<f64>)>) -> Series {
        Series {
            title: title.to_string(),
            t: t.to_vec(),
            lines,
            log: false,
            shade: Vec::new(),
            shade_meaning: "stance (a contact on the ground)".to_string(),
            axis: None,
            caption: String::new(),
        }
    }

    /// The intervals `[t0, t1]` shaded grey behind the curves.
    pub fn shaded(mut self, intervals: &[(f64, f64)]) -> Series {
        self.shade = intervals.to_vec();
        self
    }

    /// The intervals shaded grey, and what they are (for the caption).
    pub fn shaded_as(mut self, intervals: &[(f64, f64)], meaning: &str) -> Series {
        self.shade = intervals.to_vec();
        self.shade_meaning = meaning.to_string();
        self
    }

    /// The y axis's quantity and SI unit (`"m"`, `"N m"`, `""`).
    pub fn axis(mut self, quantity: &str, unit: &str) -> Series {
        self.axis = Some((quantity.to_string(), unit.to_string()));
        self
    }

    /// The caption's text after the title (plain text, escaped).
    pub fn caption(mut self, text: &str) -> Series {
        self.caption = text.to_string();
        self
    }

    /// Magnitudes on a log scale over at most [`LOG_DECADES`] decades below the largest;
    /// smaller values and exact zeros are drawn on the axis's floor, marked `≤`.
    pub fn log(title: &str, t: &[f64], lines: Vec<(String, Vec<f64>)>) -> Series {
        Series {
            log: true,
            ..Series::new(title, t, lines)
        }
    }
}

/// The linkage at one instant: each link as a segment (joint → tip), the closure
/// points, the foot and its reference. A point has the leg's two or three coordinates
/// (a spatial leg is drawn in 3-D, turned with the mouse).
pub struct Frame {
    pub t: f64,
    /// Each link's points (joint, tip, children's joints, closure points, foot), drawn as
    /// a filled outline (their convex hull, in the view).
    pub bodies: Vec<Vec<Vec<f64>>>,
    /// Each link's joint then its tip, `2 × dimension` numbers.
    pub links: Vec<Vec<f64>>,
    pub closures: Vec<Vec<f64>>,
    pub foot: Vec<f64>,
    pub reference: Option<Vec<f64>>,
}

pub struct Report<'a> {
    pub title: String,
    pub summary: &'a Value,
    pub plots: &'a [Series],
    pub frames: &'a [Frame],
    /// The ground `n · x = d` as the normal's entries then `d` (`[n_x, n_y, d]` on a
    /// planar leg, `[n_x, n_y, n_z, d]` on a spatial one), drawn under a leg with
    /// contacts: a line with the earth below it in the plane, a square of the plane under
    /// the leg in 3-D. Without it the leg hangs from a fixed base at the origin, drawn as
    /// a grey disc.
    pub ground: Option<Vec<f64>>,
    /// The closures that are rods ([`leg_models::LegDynamics::DISTANCE_CLOSURES`]): a line
    /// joins their two points, which stay the rod's length apart.
    pub rods: &'a [usize],
    /// A floating robot, drawn in the world (its body moves; the axes are the world's).
    pub robot: bool,
}

const COLORS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
];

/// A plot's size in pixels (two side by side in a 1280 px wide page).
const SIZE: (u32, u32) = (600, 300);
/// Tick labels and axis titles, px.
const TICK_FONT: u32 = 14;
const AXIS_FONT: u32 = 15;
/// A log axis spans at most this many decades below its top.
const LOG_DECADES: i32 = 5;
/// The running maximum of a log plot takes the largest value in windows of this share of
/// the run.
const ENVELOPE_SHARE: f64 = 1.0 / 150.0;

/// Whether a unit takes an SI prefix (not a pure number, not kg, not a compound `1/s`).
fn prefixable(unit: &str) -> bool {
    !unit.is_empty() && unit != "kg" && !unit.starts_with('1') && unit != "%"
}

/// The SI prefix for values up to `max_abs`: `(factor, prefix)`, the values divided by
/// the factor lying in [1, 1000) where a prefix from n to G allows it.
fn si_prefix(max_abs: f64) -> (f64, &'static str) {
    if !max_abs.is_finite() || max_abs == 0.0 {
        return (1.0, "");
    }
    // A hair above the boundary so that 0.001 is 1 m, not 1000 µ.
    let e = (((max_abs * (1.0 + 1e-12)).log10() / 3.0).floor() as i32).clamp(-3, 3);
    let p = ["n", "µ", "m", "", "k", "M", "G"][(e + 3) as usize];
    (10f64.powi(3 * e), p)
}

/// An exponent in superscript digits: `-14` → `⁻¹⁴`.
fn superscript(e: i32) -> String {
    e.to_string()
        .chars()
        .map(|c| match c {
            '-' => '⁻',
            d => ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'][d as usize - '0' as usize],
        })
        .collect()
}

/// `x` to `digits` significant digits, trailing zeros dropped.
pub(crate) fn significant(x: f64, digits: i32) -> String {
    if x == 0.0 || !x.is_finite() {
        return if x == 0.0 { "0".into() } else { x.to_string() };
    }
    let mag = x.abs().log10().floor() as i32;
    let decimals = (digits - 1 - mag).max(0) as usize;
    let s = format!("{x:.decimals$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" {
        "0".into()
    } else {
        s
    }
}

/// `x` as `m × 10ⁿ` with a four-digit mantissa.
fn scientific(x: f64) -> String {
    let e = x.abs().log10().floor() as i32;
    format!(
        "{} × 10{}",
        significant(x / 10f64.powi(e), 4),
        superscript(e)
    )
}

/// A quantity for a reader: four significant digits, the unit with the prefix that suits
/// the value (`0.0034 m` → `3.412 mm`), powers of ten beyond the prefixes.
pub fn quantity(x: f64, unit: &str) -> String {
    let with = |s: String, u: &str| {
        if u.is_empty() {
            s
        } else {
            format!("{s} {u}")
        }
    };
    if x == 0.0 || !x.is_finite() {
        return with(significant(x, 4), unit);
    }
    if prefixable(unit) && (1e-9..1e12).contains(&x.abs()) {
        let (f, p) = si_prefix(x.abs());
        return with(significant(x / f, 4), &format!("{p}{unit}"));
    }
    if (1e-3..1e6).contains(&x.abs()) {
        with(significant(x, 4), unit)
    } else {
        with(scientific(x), unit)
    }
}

fn svg_err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// The y axis's title and the factor the values are divided by for it.
fn y_axis(series: &Series, max_abs: f64, log: bool) -> (f64, String) {
    let scale = if log { ", log scale" } else { "" };
    match &series.axis {
        Some((q, u)) if prefixable(u) && !log => {
            let (f, p) = si_prefix(max_abs);
            (f, format!("{q} ({p}{u})"))
        }
        Some((q, u)) if u.is_empty() => {
            (1.0, format!("{q}{}", if log { " (log scale)" } else { "" }))
        }
        Some((q, u)) => (1.0, format!("{q} ({u}{scale})")),
        None => (1.0, series.title.clone()),
    }
}

/// Round ticks (1, 2 or 5 times a power of ten apart, about `target` of them) over
/// `[lo, hi]`, their step, and the minor ticks a fifth of a step apart.
fn nice_ticks(lo: f64, hi: f64, target: f64) -> (Vec<f64>, f64, Vec<f64>) {
    let range = (hi - lo).max(1e-300);
    let raw = range / target;
    let decade = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * decade)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * decade);
    let at = |s: f64| -> Vec<f64> {
        let first = (lo / s).ceil() as i64;
        let last = (hi / s).floor() as i64;
        (first..=last).map(|i| i as f64 * s).collect()
    };
    (at(step), step, at(step / 5.0))
}

/// An axis with ticks of our choosing (major for labels and bold lines, minor for faint
/// ones); plotters' own `WithKeyPoints` does not take a label formatter.
struct Ticked {
    range: RangedCoordf64,
    major: Vec<f64>,
    minor: Vec<f64>,
}

impl Ticked {
    fn new(lo: f64, hi: f64, major: Vec<f64>, minor: Vec<f64>) -> Ticked {
        Ticked {
            range: (lo..hi).into(),
            major,
            minor,
        }
    }
}

impl Ranged for Ticked {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;
    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        self.range.map(value, limit)
    }
    fn key_points<H: KeyPointHint>(&self, hint: H) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.minor.clone()
        } else {
            self.major.clone()
        }
    }
    fn range(&self) -> std::ops::Range<f64> {
        self.range.range()
    }
}

/// Decimals a tick label needs at this step.
fn decimals(step: f64) -> usize {
    if step <= 0.0 || !step.is_finite() {
        return 0;
    }
    (-step.log10() - 1e-9).ceil().clamp(0.0, 9.0) as usize
}

/// A tick label as a plain decimal, with a true minus sign.
fn plain(v: f64, decimals: usize, step: f64) -> String {
    if v.abs() <= step * 1e-6 {
        "0".to_string()
    } else {
        format!("{v:.decimals$}").replace('-', "−")
    }
}

fn plot(series: &Series) -> Result<String, String> {
    if series.log {
        return plot_log(series);
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(svg_err)?;
        let t_end = series.t.last().copied().unwrap_or(1.0).max(1e-9);
        let finite = series
            .lines
            .iter()
            .flat_map(|(_, v)| v.iter().copied())
            .filter(|v| v.is_finite());
        let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
        let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
        let (factor, y_desc) = y_axis(series, hi.abs().max(lo.abs()), false);
        let (lo, hi) = (lo / factor, hi / factor);
        let pad = ((hi - lo) * 0.05)
            .max(hi.abs().max(lo.abs()) * 1e-9)
            .max(1e-300);
        let (bottom, top) = (lo - pad, hi + pad);
        let (y_ticks, y_step, y_minor) = nice_ticks(bottom, top, 6.0);
        let (x_ticks, x_step, x_minor) = nice_ticks(0.0, t_end, 6.0);
        let (x_dec, y_dec) = (decimals(x_step), decimals(y_step));
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .margin_right(20)
            .x_label_area_size(44)
            .y_label_area_size(74)
            .build_cartesian_2d(
                Ticked::new(0.0, t_end, x_ticks, x_minor),
                Ticked::new(bottom, top, y_ticks, y_minor),
            )
            .map_err(svg_err)?;
        chart
            .configure_mesh()
            .light_line_style(BLACK.mix(0.04))
            .bold_line_style(BLACK.mix(0.12))
            .label_style(("sans-serif", TICK_FONT))
            .axis_desc_style(("sans-serif", AXIS_FONT))
            .x_desc("time (s)")
            .y_desc(y_desc)
            .x_label_formatter(&|v| plain(*v, x_dec, x_step))
            .y_label_formatter(&|v| plain(*v, y_dec, y_step))
            .draw()
            .map_err(svg_err)?;
        chart
            .draw_series(
                series.shade.iter().map(|&(a, b)| {
                    Rectangle::new([(a, bottom), (b, top)], BLACK.mix(0.08).filled())
                }),
            )
            .map_err(svg_err)?;
        for (i, (_, values)) in series.lines.iter().enumerate() {
            let color = COLORS[i % COLORS.len()];
            chart
                .draw_series(LineSeries::new(
                    thinned(
                        series
                            .t
                            .iter()
                            .copied()
                            .zip(values.iter().map(|v| v / factor))
                            .filter(|(_, v)| v.is_finite()),
                        t_end,
                        2 * SIZE.0 as usize,
                    ),
                    color.stroke_width(2),
                ))
                .map_err(svg_err)?;
        }
        root.present().map_err(svg_err)?;
    }
    Ok(svg)
}

/// The points a line is drawn through: all of them when there are few, else per column of
/// `columns` its first, lowest, highest and last point in time order, so the drawn curve
/// keeps every peak while a run of millions of samples makes a figure of kilobytes.
fn thinned(
    points: impl Iterator<Item = (f64, f64)>,
    t_end: f64,
    columns: usize,
) -> Vec<(f64, f64)> {
    let points: Vec<(f64, f64)> = points.collect();
    if points.len() <= 4 * columns {
        return points;
    }
    let column = |t: f64| ((t / t_end * columns as f64) as usize).min(columns - 1);
    let mut kept = Vec::with_capacity(4 * columns);
    let mut k = 0;
    while k < points.len() {
        let c = column(points[k].0);
        let mut j = k;
        let (mut lo, mut hi) = (k, k);
        while j < points.len() && column(points[j].0) == c {
            if points[j].1 < points[lo].1 {
                lo = j;
            }
            if points[j].1 > points[hi].1 {
                hi = j;
            }
            j += 1;
        }
        let mut picks = [k, lo, hi, j - 1];
        picks.sort_unstable();
        let mut last = usize::MAX;
        for i in picks {
            if i != last {
                kept.push(points[i]);
                last = i;
            }
        }
        k = j;
    }
    kept
}

/// The smallest positive and the largest value of the series' lines.
fn positive_range(series: &Series) -> (f64, f64) {
    let values = series
        .lines
        .iter()
        .flat_map(|(_, v)| v.iter().copied())
        .filter(|v| v.is_finite() && *v > 0.0);
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
    if lo.is_finite() {
        (lo, hi)
    } else {
        // Nothing positive (all exact zeros): a nominal decade.
        (1e-16, 1e-15)
    }
}

/// A log axis's decades `(floor, top)`: the top a decade at or above the largest value,
/// the floor at most [`LOG_DECADES`] below it (and no lower than the smallest value's).
fn log_decades(series: &Series) -> (i32, i32) {
    let (lo, hi) = positive_range(series);
    let top = (hi * 1.2).log10().ceil() as i32;
    let floor = (lo.log10().floor() as i32)
        .max(top - LOG_DECADES)
        .min(top - 1);
    (floor, top)
}

fn plot_log(series: &Series) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(svg_err)?;
        let t_end = series.t.last().copied().unwrap_or(1.0).max(1e-9);
        let (floor_e, top_e) = log_decades(series);
        // Drawn in decades (log10 of the value) on a linear axis: a tick at every decade.
        let floor = 10f64.powi(floor_e);
        let (bottom, top) = (floor_e as f64, top_e as f64);
        let (_, y_desc) = y_axis(series, 10f64.powi(top_e), true);
        let (x_ticks, x_step, x_minor) = nice_ticks(0.0, t_end, 6.0);
        let x_dec = decimals(x_step);
        let decades: Vec<f64> = (floor_e..=top_e).map(f64::from).collect();
        let minor: Vec<f64> = (floor_e..top_e)
            .flat_map(|e| (2..10).map(move |m| e as f64 + (m as f64).log10()))
            .collect();
        let mut chart = ChartBuilder::on(&root)
            .margin(10)
            .margin_right(20)
            .x_label_area_size(44)
            .y_label_area_size(84)
            .build_cartesian_2d(
                Ticked::new(0.0, t_end, x_ticks, x_minor),
                Ticked::new(bottom, top, decades, minor),
            )
            .map_err(svg_err)?;
        chart
            .configure_mesh()
            .light_line_style(BLACK.mix(0.04))
            .bold_line_style(BLACK.mix(0.12))
            .label_style(("sans-serif", TICK_FONT))
            .axis_desc_style(("sans-serif", AXIS_FONT))
            .x_desc("time (s)")
            .y_desc(y_desc)
            .x_label_formatter(&|v| plain(*v, x_dec, x_step))
            .y_label_formatter(&|e| {
                if (e - e.round()).abs() > 1e-6 {
                    String::new()
                } else if e.round() as i32 == floor_e {
                    format!("≤ 10{}", superscript(floor_e))
                } else {
                    format!("10{}", superscript(e.round() as i32))
                }
            })
            .draw()
            .map_err(svg_err)?;
        chart
            .draw_series(
                series.shade.iter().map(|&(a, b)| {
                    Rectangle::new([(a, bottom), (b, top)], BLACK.mix(0.08).filled())
                }),
            )
            .map_err(svg_err)?;
        // The samples as faint dots (one per pixel they fall on), their running maximum as
        // a line: a cloud of rounding noise reads as a level, not as a band of spikes.
        let window = (t_end * ENVELOPE_SHARE).max(1e-12);
        for (i, (_, values)) in series.lines.iter().enumerate() {
            let color = COLORS[i % COLORS.len()];
            let points: Vec<(f64, f64)> = series
                .t
                .iter()
                .copied()
                .zip(values.iter().copied())
                .filter(|(_, v)| v.is_finite())
                .map(|(t, v)| (t, v.abs().max(floor).log10()))
                .collect();
            let mut seen = std::collections::HashSet::new();
            let dots = points.iter().filter(|(t, v)| {
                let px = (t / t_end * SIZE.0 as f64).round() as i64;
                let py = ((v - bottom) * 40.0).round() as i64;
                seen.insert((px, py))
            });
            chart
                .draw_series(dots.map(|&(t, v)| Circle::new((t, v), 1.5, color.mix(0.3).filled())))
                .map_err(svg_err)?;
            let mut envelope: Vec<(f64, f64)> = Vec::new();
            let mut k = 0;
            while k < points.len() {
                let start = points[k].0;
                let mut m = bottom;
                let mut j = k;
                while j < points.len() && points[j].0 < start + window {
                    m = m.max(points[j].1);
                    j += 1;
                }
                envelope.push((start, m));
                envelope.push((points[j - 1].0, m));
                k = j;
            }
            chart
                .draw_series(LineSeries::new(envelope, color.stroke_width(2)))
                .map_err(svg_err)?;
        }
        root.present().map_err(svg_err)?;
    }
    Ok(svg)
}

/// Escapes text for HTML (the summary is ours, but it names models and errors).
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The unit a summary key ends in (`duration_s`), and the key without it.
fn unit_of(key: &str) -> (&str, &'static str) {
    const SUFFIXES: [(&str, &str); 10] = [
        ("_rad_s", "rad/s"),
        ("_m_s", "m/s"),
        ("_m2", "m²"),
        ("_nm", "N m"),
        ("_kg", "kg"),
        ("_j", "J"),
        ("_n", "N"),
        ("_s", "s"),
        ("_m", "m"),
        ("_rad", "rad"),
    ];
    for (suffix, unit) in SUFFIXES {
        if let Some(stem) = key.strip_suffix(suffix) {
            return (stem, unit);
        }
    }
    (key, "")
}

/// A reader's label for a summary key (without its unit suffix).
fn label_of(stem: &str) -> String {
    let known = match stem {
        "controller_choice" => "why this controller",
        "closure_rows" => "closure constraint rows",
        "redundant_rows" => "redundant constraint rows",
        "mobility" => "mobility (degrees of freedom)",
        "dt" => "time step",
        "gains" => "feedback gains",
        "torque_update" => "torque update",
        "samples" => "samples recorded",
        "steady_state_from" => "steady state from",
        "steady_state_max" => "max in steady state",
        "steady_state_rms" => "rms in steady state",
        "peak_torque" => "peak motor torque",
        "saturations" => "torque saturations",
        "saturations_per_motor" => "saturations per motor",
        "max_closure_residual" => "max closure residual |φ|",
        "max_contact_residual" => "max contact residual",
        "energy_drift_relative" => "energy drift max |E(t) − E(0)| / |E(0)|",
        "height_joint" => "body height joint",
        "apex_command" => "commanded apex height",
        "friction" => "friction coefficient μ",
        "impact_energy_lost" => "energy lost in impacts",
        "rebounds_within_10_ms" => "rebounds within 10 ms",
        "slips_within_1_ms_of_liftoff" => "slips within 1 ms of a liftoff",
        "cause" => "cause",
        "t" => "at t",
        _ => "",
    };
    if known.is_empty() {
        stem.replace('_', " ")
    } else {
        known.to_string()
    }
}

/// A summary value as text in `unit` (numbers to four significant digits; a list of
/// numbers in one common prefix).
fn value_text(v: &Value, unit: &str) -> String {
    match v {
        Value::String(s) => escape(s),
        Value::Number(n) if n.is_f64() => quantity(n.as_f64().unwrap_or(f64::NAN), unit),
        Value::Number(n) => {
            let s = n.to_string();
            if unit.is_empty() {
                s
            } else {
                format!("{s} {unit}")
            }
        }
        Value::Array(a) if a.iter().all(Value::is_number) => {
            let xs: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
            let floats = a.iter().any(|x| x.is_f64());
            let max = xs.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            let (f, p) = if floats && prefixable(unit) && (1e-9..1e12).contains(&max) {
                si_prefix(max)
            } else {
                (1.0, "")
            };
            let list: Vec<String> = a
                .iter()
                .map(|x| match x.as_f64() {
                    Some(y) if floats => significant(y / f, 4),
                    _ => x.to_string(),
                })
                .collect();
            let u = format!("{p}{unit}");
            if u.is_empty() {
                list.join(", ")
            } else {
                format!("{} {u}", list.join(", "))
            }
        }
        other => escape(&other.to_string()),
    }
}

/// The summary as a table: plain labels, units, four significant digits; each nested
/// object under a heading row (its `unit`, or its key's unit suffix, applies to its
/// numbers); `null`s left out.
fn summary_rows(v: &Value) -> String {
    fn rows(m: &serde_json::Map<String, Value>, inherited: &str, out: &mut String) {
        let own = m.get("unit").and_then(Value::as_str);
        // The plain values first, then each nested object under its heading.
        let (plain, nested): (Vec<_>, Vec<_>) = m.iter().partition(|(_, x)| !x.is_object());
        for (k, x) in plain.into_iter().chain(nested) {
            if k == "unit" && own.is_some() {
                continue;
            }
            let (stem, suffix) = unit_of(k);
            let unit = if !suffix.is_empty() {
                suffix
            } else {
                own.unwrap_or(inherited)
            };
            match x {
                Value::Null => {}
                Value::Object(inner) => {
                    out.push_str(&format!(
                        "<tr><th colspan=\"2\">{}</th></tr>",
                        escape(&label_of(stem))
                    ));
                    rows(inner, unit, out);
                }
                _ => out.push_str(&format!(
                    "<tr><td>{}</td><td>{}</td></tr>",
                    escape(&label_of(stem)),
                    value_text(x, unit)
                )),
            }
        }
    }
    let mut out = String::new();
    if let Value::Object(m) = v {
        rows(m, "", &mut out);
    }
    out
}

/// The animation's caption: only what this leg's drawing holds.
fn animation_caption(r: &Report) -> String {
    let mut parts = vec![
        format!(
            "The {} as simulated, played back in real time (scrub with the slider){}: each link a rigid body (blue outline through all its points)",
            if r.robot { "robot" } else { "leg" },
            match (r.frames.first().is_some_and(|f| f.foot.len() == 3), r.robot) {
                (true, true) => ", in 3-D in the world: drag it to turn the view (the world's axes at the bottom right: x red, y green, z blue)",
                (true, false) => ", in 3-D: drag it to turn the view (the base's axes at the bottom right: x red, y green, z blue)",
                _ => "",
            }
        ),
        "joints (black dots)".to_string(),
    ];
    if r.frames.iter().any(|f| !f.closures.is_empty()) {
        parts.push(if r.rods.is_empty() {
            "the closure points where the chains meet (red rings)".into()
        } else {
            "the closure points (red rings) where the chains meet, or at a rod's ends, joined by the rod (grey line)".into()
        });
    }
    parts.push(if r.robot {
        "the spec's foot (green dot) and its path over the last second (green)".into()
    } else {
        "the foot (green dot) and its path over the last second (green)".into()
    });
    if r.frames.iter().any(|f| f.reference.is_some()) {
        parts.push("the reference the foot tracks (grey ring, its path dashed)".into());
    }
    match &r.ground {
        Some(g) if g.len() == 4 => parts.push(format!(
            "the ground (a brown square of its plane under the {}, with a grid)",
            if r.robot { "robot" } else { "leg" }
        )),
        Some(_) => parts.push("the ground (brown line, earth below)".into()),
        None => parts.push("the fixed base at the origin (grey disc)".into()),
    }
    format!(
        "{}. The scale bar at the bottom left gives the length.",
        parts.join(", ")
    )
}

/// A plot's caption: its title, what it says, the key to its lines, and what its axis and
/// shading mean.
fn plot_caption(s: &Series, number: usize) -> String {
    let mut text = format!("<b>Figure {number}.</b> {}.", escape(&s.title));
    if !s.caption.is_empty() {
        text.push_str(&format!(" {}", escape(&s.caption)));
    }
    if !s.shade.is_empty() {
        text.push_str(&format!(" Grey bands: {}.", escape(&s.shade_meaning)));
    }
    if s.log {
        let (floor_e, _) = log_decades(s);
        let t_end = s.t.last().copied().unwrap_or(1.0);
        text.push_str(&format!(
            " Log scale; values below 10{0} (exact zeros included) are drawn on the bottom line, marked ≤ 10{0}. Faint dots: the samples; line: the largest value in each {1} window.",
            superscript(floor_e),
            quantity(t_end * ENVELOPE_SHARE, "s")
        ));
    }
    text
}

fn plot_key(s: &Series) -> String {
    if s.lines.len() < 2 {
        return "<div class=\"key\"></div>".to_string();
    }
    let keys: Vec<String> = s
        .lines
        .iter()
        .enumerate()
        .map(|(i, (name, _))| {
            let RGBColor(r, g, b) = COLORS[i % COLORS.len()];
            format!(
                "<span><i style=\"background:rgb({r},{g},{b})\"></i>{}</span>",
                escape(name)
            )
        })
        .collect();
    format!("<div class=\"key\">{}</div>", keys.join(""))
}

pub fn html(r: &Report) -> Result<String, String> {
    let mut plots = Vec::new();
    for (i, s) in r.plots.iter().enumerate() {
        plots.push(format!(
            "<figure>{}{}<figcaption>{}</figcaption></figure>",
            plot_key(s),
            plot(s)?,
            plot_caption(s, i + 2)
        ));
    }
    let frames = json!({
        "t": r.frames.iter().map(|f| f.t).collect::<Vec<_>>(),
        "links": r.frames.iter().map(|f| f.links.clone()).collect::<Vec<_>>(),
        "bodies": r.frames.iter().map(|f| f.bodies.clone()).collect::<Vec<_>>(),
        "closures": r.frames.iter().map(|f| f.closures.clone()).collect::<Vec<_>>(),
        "foot": r.frames.iter().map(|f| f.foot.clone()).collect::<Vec<_>>(),
        "reference": r.frames.iter().map(|f| f.reference.clone()).collect::<Vec<_>>(),
        "ground": r.ground,
        "rods": r.rods,
    });
    // `</` cannot appear inside a <script> element.
    let data = frames.to_string().replace("</", "<\\/");
    Ok(format!(
        r#"<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>
body {{ font-family: sans-serif; font-size: 15px; line-height: 1.4; margin: 24px; color: #222; max-width: 1240px; }}
h1 {{ font-size: 26px; margin: 0 0 16px; }}
.row {{ display: flex; flex-wrap: wrap; gap: 32px; align-items: flex-start; }}
#leg {{ border: 1px solid #ccc; background: #fafafa; }}
figure {{ margin: 0; }}
figcaption {{ font-size: 14px; color: #333; margin-top: 6px; }}
.anim figcaption, .anim .controls {{ max-width: 520px; }}
.controls {{ font-size: 15px; }}
.plots {{ display: grid; grid-template-columns: repeat(auto-fill, minmax(540px, 1fr)); gap: 28px 24px; margin-top: 28px; }}
.plots figure {{ max-width: 600px; margin: 0; }}
.plots svg {{ max-width: 100%; height: auto; }}
.plots svg {{ display: block; }}
.key {{ font-size: 14px; margin-bottom: 2px; min-height: 20px; }}
.key span {{ margin-right: 16px; white-space: nowrap; }}
.key i {{ display: inline-block; width: 22px; height: 3px; vertical-align: middle; margin-right: 6px; }}
table.summary {{ border-collapse: collapse; font-size: 15px; max-width: 640px; }}
table.summary caption {{ text-align: left; font-weight: bold; font-size: 16px; padding-bottom: 6px; }}
table.summary td {{ border-bottom: 1px solid #e4e4e4; padding: 3px 14px 3px 0; vertical-align: top; }}
table.summary td:first-child {{ color: #555; white-space: nowrap; }}
table.summary th {{ text-align: left; font-weight: bold; padding: 10px 0 3px; border-bottom: 1px solid #bbb; }}
</style>
</head>
<body>
<h1>{title}</h1>
<div class="row">
<figure class="anim">
<svg id="leg" width="520" height="520" viewBox="0 0 520 520"></svg>
<div class="controls"><button id="play">pause</button> <input id="scrub" type="range" min="0" value="0" style="width:360px"> <span id="time"></span></div>
<figcaption><b>Figure 1.</b> {anim_caption}</figcaption>
</figure>
<table class="summary"><caption>Summary</caption>{summary}</table>
</div>
<div class="plots">
{plots}
</div>
<script id="frames" type="application/json">{data}</script>
<script>
(function () {{
  const d = JSON.parse(document.getElementById('frames').textContent);
  const svg = document.getElementById('leg');
  const ns = 'http://www.w3.org/2000/svg';
  const n = d.t.length;
  // A spatial leg's points have three coordinates: it is drawn in an orthographic view
  // turned by dragging (yaw about the base's z, pitch over it); a planar leg's view is its
  // plane.
  const D = d.foot.length && d.foot[0].length === 3 ? 3 : 2;
  let yaw = -0.5, pitch = 0.35;
  function P(p) {{
    if (D === 2) return p;
    const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
    return [cy * p[0] + sy * p[1], -sp * sy * p[0] + sp * cy * p[1] + cp * p[2]];
  }}
  const all = [];
  d.bodies.forEach(f => f.forEach(b => b.forEach(p => all.push(p))));
  d.reference.forEach(p => {{ if (p) all.push(p); }});
  const lo = [0, 1, 2].slice(0, D).map(i => Math.min(...all.map(p => p[i])));
  const hi = [0, 1, 2].slice(0, D).map(i => Math.max(...all.map(p => p[i])));
  const mid = lo.map((l, i) => (l + hi[i]) / 2);
  // In 3-D the view's extent is the points' bounding sphere: it holds in every turn.
  const span = (D === 2 ? Math.max(hi[0] - lo[0], hi[1] - lo[1], 1e-6)
    : 2 * Math.max(1e-6, ...all.map(p => Math.hypot(p[0] - mid[0], p[1] - mid[1], p[2] - mid[2])))) * 1.15;
  let cx = 0, cy = 0;
  function centre() {{ const c = P(mid); cx = c[0]; cy = c[1]; }}
  centre();
  const X = p => 260 + (P(p)[0] - cx) / span * 500, Y = p => 260 - (P(p)[1] - cy) / span * 500;
  function el(name, attrs) {{ const e = document.createElementNS(ns, name); for (const k in attrs) e.setAttribute(k, attrs[k]); svg.appendChild(e); return e; }}
  const path = pts => pts.filter(p => p).map((p, i) => (i ? 'L' : 'M') + X(p).toFixed(1) + ' ' + Y(p).toFixed(1)).join(' ');
  const refPath = el('path', {{ fill: 'none', stroke: '#999', 'stroke-dasharray': '4 3' }});
  let groundPatch = null, groundGrid = null, groundSquare = null;
  if (d.ground && D === 2) {{
    // The ground n·x = d: a brown line through the view, earth below.
    const [gx, gy, off] = d.ground, tx = gy, ty = -gx, px = gx * off, py = gy * off;
    const a = [px - tx * 10 * span, py - ty * 10 * span], b = [px + tx * 10 * span, py + ty * 10 * span];
    const below = [[b[0] - gx * span, b[1] - gy * span], [a[0] - gx * span, a[1] - gy * span]];
    el('path', {{ d: path([a, b, below[0], below[1]]) + ' Z', fill: '#d9c7a7', stroke: 'none' }});
    el('path', {{ d: path([a, b]), stroke: '#8c6d3f', 'stroke-width': 2 }});
  }} else if (d.ground) {{
    // The ground n·x = d in 3-D: a square of the plane, a view's span wide, centred under
    // the leg (the points' centre projected on it), with a grid; redrawn as the view turns.
    const n = d.ground.slice(0, 3), off = d.ground[3];
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const unit = v => {{ const l = Math.hypot(...v); return v.map(x => x / l); }};
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const e = Math.abs(n[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
    const t1 = unit(e.map((x, i) => x - dot(e, n) * n[i])), t2 = cross(n, t1);
    const c = mid.map((x, i) => x - (dot(mid, n) - off) * n[i]);
    const at = (u, v) => c.map((x, i) => x + (u * t1[i] + v * t2[i]) * span / 2);
    groundSquare = [at(-1, -1), at(1, -1), at(1, 1), at(-1, 1)];
    groundGrid = [];
    for (let k = -1; k <= 1; k += 0.5) {{ groundGrid.push([at(k, -1), at(k, 1)], [at(-1, k), at(1, k)]); }}
    groundPatch = [el('path', {{ fill: '#d9c7a7', 'fill-opacity': 0.7, stroke: '#8c6d3f', 'stroke-width': 2 }}),
      el('path', {{ fill: 'none', stroke: '#8c6d3f', 'stroke-width': 0.5 }})];
  }}
  const trail = el('path', {{ fill: 'none', stroke: '#2ca02c', 'stroke-width': 1.5 }});
  // A scale bar of a round length near a fifth of the view, at the bottom left.
  const decade = Math.pow(10, Math.floor(Math.log10(span / 5)));
  const bar = [5, 2, 1].map(m => m * decade).find(b => b <= span / 5) || decade;
  el('line', {{ x1: 20, y1: 500, x2: 20 + bar / span * 500, y2: 500, stroke: '#222', 'stroke-width': 3 }});
  const label = el('text', {{ x: 20, y: 490, 'font-size': 15 }});
  const round = x => +x.toPrecision(3);
  label.textContent = (bar >= 1 ? round(bar) + ' m' : (bar * 100 >= 1 ? round(bar * 100) + ' cm' : round(bar * 1000) + ' mm'));
  function hull(pts) {{
    const p = pts.slice().sort((a, b) => a[0] - b[0] || a[1] - b[1]);
    if (p.length < 3) return p;
    const cross = (o, a, b) => (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    const lo = [], hi = [];
    for (const q of p) {{ while (lo.length >= 2 && cross(lo[lo.length - 2], lo[lo.length - 1], q) <= 0) lo.pop(); lo.push(q); }}
    for (const q of p.slice().reverse()) {{ while (hi.length >= 2 && cross(hi[hi.length - 2], hi[hi.length - 1], q) <= 0) hi.pop(); hi.push(q); }}
    return lo.slice(0, -1).concat(hi.slice(0, -1));
  }}
  // The hull is taken in the view (screen coordinates), so a body's outline is its
  // silhouette from wherever it is seen.
  const outline = b => {{ const h = hull(b.map(p => [X(p), Y(p)])); return h.map((q, i) => (i ? 'L' : 'M') + q[0].toFixed(1) + ' ' + q[1].toFixed(1)).join(' ') + ' Z'; }};
  const links = d.bodies[0].map(() => el('path', {{ fill: '#aec7e8', 'fill-opacity': 0.6, stroke: '#1f77b4', 'stroke-width': 5, 'stroke-linejoin': 'round', 'stroke-linecap': 'round' }}));
  const rods = (d.rods || []).map(() => el('line', {{ stroke: '#777', 'stroke-width': 3, 'stroke-linecap': 'round' }}));
  const joints = d.links[0].map(() => el('circle', {{ r: 4, fill: '#222' }}));
  // The foot under the closure rings: a closure at the foot stays visible.
  const foot = el('circle', {{ r: 5, fill: '#2ca02c' }});
  const closures = d.closures[0].map(() => el('circle', {{ r: 7, fill: 'none', stroke: '#d62728', 'stroke-width': 2 }}));
  const ref = el('circle', {{ r: 5, fill: 'none', stroke: '#666', 'stroke-width': 1.5 }});
  const origin = D === 2 ? [0, 0] : [0, 0, 0];
  const base = d.ground ? null : el('circle', {{ r: 7, fill: '#888' }});
  // In 3-D, the base's axes at the bottom right (x red, y green, z blue), turning with the view.
  const axes = D === 3 ? [0, 1, 2].map(i => [el('line', {{ stroke: ['#d62728', '#2ca02c', '#1f77b4'][i], 'stroke-width': 2 }}), el('text', {{ 'font-size': 13 }})]) : [];
  function place() {{
    refPath.setAttribute('d', path(d.reference));
    if (groundPatch) {{
      groundPatch[0].setAttribute('d', path(groundSquare) + ' Z');
      groundPatch[1].setAttribute('d', groundGrid.map(l => path(l)).join(' '));
    }}
    if (base) {{ base.setAttribute('cx', X(origin)); base.setAttribute('cy', Y(origin)); }}
    axes.forEach(([line, text], i) => {{
      const e = [0, 0, 0]; e[i] = 1; const q = P(e);
      const x2 = 470 + 30 * q[0], y2 = 470 - 30 * q[1];
      line.setAttribute('x1', 470); line.setAttribute('y1', 470); line.setAttribute('x2', x2); line.setAttribute('y2', y2);
      text.setAttribute('x', x2 + 3); text.setAttribute('y', y2 + 4); text.textContent = 'xyz'[i];
    }});
  }}
  const scrub = document.getElementById('scrub'), time = document.getElementById('time'), play = document.getElementById('play');
  scrub.max = n - 1;
  // The foot's path over the last second.
  const dtFrame = n > 1 ? (d.t[n - 1] - d.t[0]) / (n - 1) : 1;
  const trailFrames = Math.max(1, Math.round(1 / dtFrame));
  let k = 0, playing = true;
  function draw(i) {{
    d.bodies[i].forEach((b, j) => {{ links[j].setAttribute('d', outline(b)); }});
    d.links[i].forEach((l, j) => {{ joints[j].setAttribute('cx', X(l)); joints[j].setAttribute('cy', Y(l)); }});
    d.closures[i].forEach((p, j) => {{ closures[j].setAttribute('cx', X(p)); closures[j].setAttribute('cy', Y(p)); }});
    (d.rods || []).forEach((k, j) => {{
      const a = d.closures[i][2 * k], b = d.closures[i][2 * k + 1];
      rods[j].setAttribute('x1', X(a)); rods[j].setAttribute('y1', Y(a)); rods[j].setAttribute('x2', X(b)); rods[j].setAttribute('y2', Y(b));
    }});
    foot.setAttribute('cx', X(d.foot[i])); foot.setAttribute('cy', Y(d.foot[i]));
    const r = d.reference[i];
    ref.setAttribute('visibility', r ? 'visible' : 'hidden');
    if (r) {{ ref.setAttribute('cx', X(r)); ref.setAttribute('cy', Y(r)); }}
    trail.setAttribute('d', path(d.foot.slice(Math.max(0, i - trailFrames), i + 1)));
    scrub.value = i; time.textContent = 't = ' + d.t[i].toFixed(3) + ' s';
  }}
  if (D === 3) {{
    // Drag to turn: left–right turns about the base's z, up–down tilts the view.
    let from = null;
    svg.style.cursor = 'grab';
    // A touch drags the view, not the page.
    svg.style.touchAction = 'none';
    svg.addEventListener('pointerdown', e => {{ from = [e.clientX, e.clientY]; svg.setPointerCapture(e.pointerId); }});
    for (const end of ['pointerup', 'pointercancel', 'lostpointercapture']) svg.addEventListener(end, () => {{ from = null; }});
    svg.addEventListener('pointermove', e => {{
      if (!from) return;
      yaw += (e.clientX - from[0]) * 0.01;
      pitch = Math.max(-1.5, Math.min(1.5, pitch + (e.clientY - from[1]) * 0.01));
      from = [e.clientX, e.clientY];
      centre(); place(); draw(k);
    }});
  }}
  place();
  let last = null;
  function tick(now) {{
    if (playing && last !== null && now - last > dtFrame * 1000) {{ k = (k + 1) % n; draw(k); last = now; }}
    if (last === null) last = now;
    requestAnimationFrame(tick);
  }}
  play.onclick = () => {{ playing = !playing; play.textContent = playing ? 'pause' : 'play'; }};
  scrub.oninput = () => {{ k = +scrub.value; draw(k); }};
  draw(0);
  requestAnimationFrame(tick);
}})();
</script>
</body>
</html>
"#,
        title = escape(&r.title),
        anim_caption = escape(&animation_caption(r)),
        summary = summary_rows(r.summary),
        plots = plots.join("\n"),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_line_is_thinned_to_its_columns_keeping_every_peak() {
        // A million samples of a fast sine with one spike: at most four points per
        // column survive, in time order, and the spike and both extremes are among them.
        let n = 1_000_000;
        let points: Vec<(f64, f64)> = (0..n)
            .map(|k| {
                let t = k as f64 * 1e-5;
                let v = if k == 123_457 {
                    7.0
                } else {
                    (t * 3000.0).sin()
                };
                (t, v)
            })
            .collect();
        let t_end = points[n - 1].0;
        let kept = thinned(points.iter().copied(), t_end, 1200);
        assert!(kept.len() <= 4 * 1200, "{} points kept", kept.len());
        assert!(kept.windows(2).all(|w| w[0].0 < w[1].0));
        assert!(kept.contains(&points[123_457]));
        assert_eq!(kept.first(), points.first());
        assert_eq!(kept.last(), points.last());
        let lowest = points.iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        assert!(kept.iter().any(|p| p.1 == lowest));
        // A short line is drawn through every point.
        assert_eq!(
            thinned(points[..100].iter().copied(), 1.0, 1200),
            points[..100]
        );
    }

    #[test]
    fn residuals_are_drawn_on_decades_with_small_values_on_the_floor() {
        let t = [0.0, 0.5, 1.0, 1.5];
        let s = Series::log(
            "closure residual",
            &t,
            vec![("residual".into(), vec![0.0, 2e-16, 3e-14, 1e-12])],
        )
        .axis("max |φ|", "m");
        assert_eq!(positive_range(&s), (2e-16, 1e-12));
        // The top a decade above the largest value (with room), the floor at the
        // smallest value's decade (at most five below the top), marked as such.
        assert_eq!(log_decades(&s), (-16, -11));
        let svg = plot(&s).unwrap();
        for tick in ["≤ 10⁻¹⁶", "10⁻¹⁵", "10⁻¹²", "10⁻¹¹"] {
            assert!(
                svg.contains(&format!("\n{tick}\n")),
                "no tick {tick}: {svg}"
            );
        }
        assert!(svg.contains("log scale") && !svg.contains("NaN"));
        assert!(plot_caption(&s, 2).contains("below 10⁻¹⁶"));
    }

    #[test]
    fn quantities_read_plainly() {
        assert_eq!(quantity(0.0034122660742651185, "m"), "3.412 mm");
        assert_eq!(quantity(0.00003832595829718664, "m"), "38.33 µm");
        assert_eq!(quantity(0.1290293780730676, "N m"), "129 mN m");
        assert_eq!(quantity(1.0, "s"), "1 s");
        assert_eq!(quantity(0.001, "s"), "1 ms");
        assert_eq!(quantity(5.842548667089886e-14, "m"), "5.843 × 10⁻¹⁴ m");
        assert_eq!(quantity(0.8, ""), "0.8");
        let (f, p) = si_prefix(0.2);
        assert_eq!((f, p), (1e-3, "m"));
        assert_eq!(plain(0.5, decimals(0.5), 0.5), "0.5");
        assert_eq!(plain(-50.0, decimals(50.0), 50.0), "−50");
        let (ticks, step, _) = nice_ticks(-0.2, 3.7, 6.0);
        assert_eq!((ticks, step), (vec![0.0, 1.0, 2.0, 3.0], 1.0));
    }

    #[test]
    fn the_summary_has_labels_and_units() {
        let v = json!({"tracking_error": {"unit": "m", "max": 0.0034122660742651185, "steady_state_from_s": 1.0},
            "peak_torque_nm": 0.129, "saturations_per_motor": [0, 0], "apex_heights_m": [0.2772, 0.2995], "stopped": null});
        let rows = summary_rows(&v);
        assert!(
            rows.contains("<th colspan=\"2\">tracking error</th>"),
            "{rows}"
        );
        assert!(rows.contains("<td>max</td><td>3.412 mm</td>"), "{rows}");
        assert!(
            rows.contains("<td>steady state from</td><td>1 s</td>"),
            "{rows}"
        );
        assert!(
            rows.contains("<td>peak motor torque</td><td>129 mN m</td>"),
            "{rows}"
        );
        assert!(
            rows.contains("<td>0, 0</td>") && rows.contains("277.2, 299.5 mm"),
            "{rows}"
        );
        assert!(
            !rows.contains("stopped") && !rows.contains(">unit<"),
            "{rows}"
        );
    }

    #[test]
    fn shaded_intervals_are_drawn_behind_the_curves() {
        let t: Vec<f64> = (0..100).map(|i| i as f64 * 0.01).collect();
        let plain = Series::new("x", &t, vec![("x".into(), t.clone())]);
        let shaded =
            Series::new("x", &t, vec![("x".into(), t.clone())]).shaded(&[(0.1, 0.2), (0.5, 0.7)]);
        let rects = |svg: &str| svg.matches("<rect").count();
        let (a, b) = (plot(&plain).unwrap(), plot(&shaded).unwrap());
        assert_eq!(rects(&b), rects(&a) + 2, "{b}");
        // Behind: the rectangles come before the curve's path.
        let last_rect = b.rfind("<rect").unwrap();
        assert!(b.rfind("<polyline").unwrap() > last_rect, "{b}");
        // Nothing positive at all still draws (a nominal decade), never a NaN axis.
        let zeros = Series::log("r", &t, vec![("r".into(), vec![0.0; 4])]);
        assert!(!plot(&zeros).unwrap().contains("NaN"));
    }
}
