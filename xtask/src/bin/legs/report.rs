//! The self-contained HTML report of a simulation: plots drawn by plotters (SVG, inlined)
//! and an animation of the linkage (the frames as JSON, drawn by a few lines of script).
//! Nothing is fetched: no network, no external file.

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
}

impl Series {
    pub fn new(title: &str, t: &[f64], lines: Vec<(String, Vec<f64>)>) -> Series {
        Series {
            title: title.to_string(),
            t: t.to_vec(),
            lines,
            log: false,
            shade: Vec::new(),
        }
    }

    /// The intervals `[t0, t1]` shaded grey behind the curves.
    pub fn shaded(mut self, intervals: &[(f64, f64)]) -> Series {
        self.shade = intervals.to_vec();
        self
    }

    /// Magnitudes on a log scale; exact zeros are drawn on the axis's floor, a decade
    /// below the smallest positive value.
    pub fn log(title: &str, t: &[f64], lines: Vec<(String, Vec<f64>)>) -> Series {
        Series {
            log: true,
            ..Series::new(title, t, lines)
        }
    }
}

/// The linkage at one instant: each link as a segment (joint → tip), the closure
/// points, the foot and its reference.
pub struct Frame {
    pub t: f64,
    /// Each link's points (joint, tip, children's joints, closure points, foot), drawn as
    /// a filled outline (their convex hull).
    pub bodies: Vec<Vec<[f64; 2]>>,
    pub links: Vec<[f64; 4]>,
    pub closures: Vec<[f64; 2]>,
    pub foot: [f64; 2],
    pub reference: Option<[f64; 2]>,
}

pub struct Report<'a> {
    pub title: String,
    pub summary: &'a Value,
    pub plots: &'a [Series],
    pub frames: &'a [Frame],
    /// The ground line `n · x = d` as `[n_x, n_y, d]`, drawn under a leg with contacts.
    pub ground: Option<[f64; 3]>,
}

const COLORS: [RGBColor; 4] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
];

fn plot(series: &Series) -> Result<String, String> {
    if series.log {
        return plot_log(series);
    }
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (640, 260)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
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
        let pad = ((hi - lo) * 0.05)
            .max(hi.abs().max(lo.abs()) * 1e-9)
            .max(1e-300);
        let legend_room = if series.lines.len() > 1 {
            (hi - lo).max(pad) * 0.35
        } else {
            0.0
        };
        let tiny = (hi.abs().max(lo.abs())) * 1e-9;
        let mut chart = ChartBuilder::on(&root)
            .caption(&series.title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(70)
            // Headroom above the curves for the legend of several lines.
            .build_cartesian_2d(0.0..t_end, (lo - pad)..(hi + pad + legend_room))
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("t (s)")
            .y_desc(series.title.as_str())
            .y_label_formatter(&|v| {
                if v.abs() <= tiny {
                    "0".to_string()
                } else {
                    format!("{v:.2e}")
                }
            })
            .draw()
            .map_err(|e| e.to_string())?;
        let (bottom, top) = (lo - pad, hi + pad + legend_room);
        chart
            .draw_series(
                series.shade.iter().map(|&(a, b)| {
                    Rectangle::new([(a, bottom), (b, top)], BLACK.mix(0.08).filled())
                }),
            )
            .map_err(|e| e.to_string())?;
        for (i, (name, values)) in series.lines.iter().enumerate() {
            let color = COLORS[i % COLORS.len()];
            chart
                .draw_series(LineSeries::new(
                    series
                        .t
                        .iter()
                        .copied()
                        .zip(values.iter().copied())
                        .filter(|(_, v)| v.is_finite()),
                    color.stroke_width(2),
                ))
                .map_err(|e| e.to_string())?
                .label(name.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
                });
        }
        if series.lines.len() > 1 {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
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

fn plot_log(series: &Series) -> Result<String, String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (640, 260)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let t_end = series.t.last().copied().unwrap_or(1.0).max(1e-9);
        let (lo, hi) = positive_range(series);
        let floor = lo / 10.0;
        let top = if series.lines.len() > 1 {
            hi * 1e3
        } else {
            hi * 3.0
        };
        let mut chart = ChartBuilder::on(&root)
            .caption(&series.title, ("sans-serif", 16))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..t_end, (floor..top).log_scale())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("t (s)")
            .y_desc(format!("{} (log)", series.title))
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()
            .map_err(|e| e.to_string())?;
        for (i, (name, values)) in series.lines.iter().enumerate() {
            let color = COLORS[i % COLORS.len()];
            chart
                .draw_series(LineSeries::new(
                    series
                        .t
                        .iter()
                        .copied()
                        .zip(values.iter().copied())
                        .filter(|(_, v)| v.is_finite())
                        .map(|(t, v)| (t, v.abs().max(floor))),
                    color.stroke_width(2),
                ))
                .map_err(|e| e.to_string())?
                .label(name.clone())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 16, y)], color.stroke_width(2))
                });
        }
        if series.lines.len() > 1 {
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::UpperRight)
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .draw()
                .map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

/// Escapes text for HTML (the summary is ours, but it names models and errors).
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

/// The summary as table rows, nested objects flattened to `a.b` keys; `null`s left out.
fn summary_rows(v: &Value) -> String {
    fn walk(prefix: &str, v: &Value, out: &mut String) {
        match v {
            Value::Object(m) => {
                for (k, x) in m {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    walk(&key, x, out);
                }
            }
            Value::Null => {}
            Value::String(s) => out.push_str(&format!(
                "<tr><td>{}</td><td>{}</td></tr>",
                escape(prefix),
                escape(s)
            )),
            other => out.push_str(&format!(
                "<tr><td>{}</td><td>{}</td></tr>",
                escape(prefix),
                escape(&other.to_string())
            )),
        }
    }
    let mut out = String::new();
    walk("", v, &mut out);
    out
}

pub fn html(r: &Report) -> Result<String, String> {
    let plots: Vec<String> = r.plots.iter().map(plot).collect::<Result<_, _>>()?;
    let frames = json!({
        "t": r.frames.iter().map(|f| f.t).collect::<Vec<_>>(),
        "links": r.frames.iter().map(|f| f.links.clone()).collect::<Vec<_>>(),
        "bodies": r.frames.iter().map(|f| f.bodies.clone()).collect::<Vec<_>>(),
        "closures": r.frames.iter().map(|f| f.closures.clone()).collect::<Vec<_>>(),
        "foot": r.frames.iter().map(|f| f.foot).collect::<Vec<_>>(),
        "reference": r.frames.iter().map(|f| f.reference).collect::<Vec<_>>(),
        "ground": r.ground,
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
body {{ font-family: sans-serif; margin: 24px; color: #222; }}
.row {{ display: flex; flex-wrap: wrap; gap: 24px; align-items: flex-start; }}
#leg {{ border: 1px solid #ccc; background: #fafafa; }}
pre {{ background: #f4f4f4; padding: 12px; font-size: 12px; max-width: 640px; overflow-x: auto; }}
.plots {{ display: grid; grid-template-columns: repeat(auto-fill, minmax(640px, 1fr)); gap: 8px; }}
.plots svg {{ display: block; }}
table.summary {{ border-collapse: collapse; font-size: 13px; max-width: 640px; }}
table.summary td {{ border-bottom: 1px solid #e4e4e4; padding: 3px 10px 3px 0; vertical-align: top; }}
table.summary td:first-child {{ color: #555; white-space: nowrap; }}
</style>
</head>
<body>
<h1>{title}</h1>
<div class="row">
<div>
<svg id="leg" width="520" height="520" viewBox="0 0 520 520"></svg>
<div><button id="play">pause</button> <input id="scrub" type="range" min="0" value="0" style="width:380px"> <span id="time"></span></div>
<p>Links as rigid bodies (blue outlines through every point of a link), joints (dots), closure points (red), foot path (green), reference (dashed grey), base (grey disc), the ground (brown) under a leg with contacts; scale bar below.</p>
</div>
<table class="summary">{summary}</table>
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
  const xs = [], ys = [];
  d.bodies.forEach(f => f.forEach(b => b.forEach(p => {{ xs.push(p[0]); ys.push(p[1]); }})));
  d.reference.forEach(p => {{ if (p) {{ xs.push(p[0]); ys.push(p[1]); }} }});
  const minx = Math.min(...xs), maxx = Math.max(...xs), miny = Math.min(...ys), maxy = Math.max(...ys);
  const span = Math.max(maxx - minx, maxy - miny, 1e-6) * 1.15;
  const cx = (minx + maxx) / 2, cy = (miny + maxy) / 2;
  const X = x => 260 + (x - cx) / span * 500, Y = y => 260 - (y - cy) / span * 500;
  function el(name, attrs) {{ const e = document.createElementNS(ns, name); for (const k in attrs) e.setAttribute(k, attrs[k]); svg.appendChild(e); return e; }}
  const path = pts => pts.filter(p => p).map((p, i) => (i ? 'L' : 'M') + X(p[0]).toFixed(1) + ' ' + Y(p[1]).toFixed(1)).join(' ');
  el('path', {{ d: path(d.reference), fill: 'none', stroke: '#999', 'stroke-dasharray': '4 3' }});
  if (d.ground) {{
    // The ground n·x = d: a brown line through the view, hatched below.
    const [gx, gy, off] = d.ground, tx = gy, ty = -gx, px = gx * off, py = gy * off;
    const a = [px - tx * 10 * span, py - ty * 10 * span], b = [px + tx * 10 * span, py + ty * 10 * span];
    const below = [[b[0] - gx * span, b[1] - gy * span], [a[0] - gx * span, a[1] - gy * span]];
    el('path', {{ d: path([a, b, below[0], below[1]]) + ' Z', fill: '#d9c7a7', stroke: 'none' }});
    el('path', {{ d: path([a, b]), stroke: '#8c6d3f', 'stroke-width': 2 }});
  }}
  const trail = el('path', {{ fill: 'none', stroke: '#2ca02c', 'stroke-width': 1.5 }});
  // A scale bar of a round length near a fifth of the view, at the bottom left.
  const decade = Math.pow(10, Math.floor(Math.log10(span / 5)));
  const bar = [5, 2, 1].map(m => m * decade).find(b => b <= span / 5) || decade;
  el('line', {{ x1: 20, y1: 500, x2: 20 + bar / span * 500, y2: 500, stroke: '#222', 'stroke-width': 2 }});
  const label = el('text', {{ x: 20, y: 492, 'font-size': 12 }});
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
  const links = d.bodies[0].map(() => el('path', {{ fill: '#aec7e8', 'fill-opacity': 0.6, stroke: '#1f77b4', 'stroke-width': 5, 'stroke-linejoin': 'round', 'stroke-linecap': 'round' }}));
  const joints = d.links[0].map(() => el('circle', {{ r: 4, fill: '#222' }}));
  const closures = d.closures[0].map(() => el('circle', {{ r: 5, fill: 'none', stroke: '#d62728', 'stroke-width': 2 }}));
  const foot = el('circle', {{ r: 4, fill: '#2ca02c' }});
  const ref = el('circle', {{ r: 4, fill: 'none', stroke: '#666' }});
  el('circle', {{ cx: X(0), cy: Y(0), r: 6, fill: '#444' }});
  const scrub = document.getElementById('scrub'), time = document.getElementById('time'), play = document.getElementById('play');
  scrub.max = n - 1;
  let k = 0, playing = true;
  function draw(i) {{
    d.bodies[i].forEach((b, j) => {{ links[j].setAttribute('d', path(hull(b)) + ' Z'); }});
    d.links[i].forEach((l, j) => {{ joints[j].setAttribute('cx', X(l[0])); joints[j].setAttribute('cy', Y(l[1])); }});
    d.closures[i].forEach((p, j) => {{ closures[j].setAttribute('cx', X(p[0])); closures[j].setAttribute('cy', Y(p[1])); }});
    foot.setAttribute('cx', X(d.foot[i][0])); foot.setAttribute('cy', Y(d.foot[i][1]));
    const r = d.reference[i];
    ref.setAttribute('visibility', r ? 'visible' : 'hidden');
    if (r) {{ ref.setAttribute('cx', X(r[0])); ref.setAttribute('cy', Y(r[1])); }}
    trail.setAttribute('d', path(d.foot.slice(Math.max(0, i - 50), i + 1)));
    scrub.value = i; time.textContent = 't = ' + d.t[i].toFixed(3) + ' s';
  }}
  let last = null;
  function tick(now) {{
    if (playing && last !== null && now - last > 20) {{ k = (k + 1) % n; draw(k); last = now; }}
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
        summary = summary_rows(r.summary),
        plots = plots.join("\n"),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn residuals_are_drawn_on_decades_with_zeros_on_the_floor() {
        let t = [0.0, 0.5, 1.0, 1.5];
        let s = Series::log(
            "closure residual max |φ| (m)",
            &t,
            vec![("residual".into(), vec![0.0, 2e-16, 3e-14, 1e-12])],
        );
        // The floor is a decade below the smallest positive value.
        assert_eq!(positive_range(&s), (2e-16, 1e-12));
        let svg = plot(&s).unwrap();
        // A tick at every decade the values span.
        for tick in ["1e-15", "1e-14", "1e-13", "1e-12"] {
            assert!(
                svg.contains(&format!("\n{tick}\n")),
                "no tick {tick}: {svg}"
            );
        }
        assert!(svg.contains("(log)") && !svg.contains("NaN"));
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
