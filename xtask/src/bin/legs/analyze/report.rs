//! The self-contained HTML report of `cargo xtask analyze`: the table of designs, heat
//! maps over each design's workspace with its singularity curves and the leg at its
//! stance pose, and for a sweep each measure against the swept parameter. The data go
//! in as JSON, drawn on canvases by a few lines of script; nothing is fetched.

use serde_json::{json, Value};

use crate::analyze::design::{Design, COLUMNS};

/// Heat maps are drawn from at most this many nodes per side (every k-th node).
const MAX_SHOWN: usize = 120;
/// A sweep shows the maps of at most this many designs (first, last, evenly between).
const MAX_MAPS: usize = 5;

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn round(x: f64) -> Value {
    if x.is_finite() {
        // Four significant digits are plenty for a colour.
        let s = format!("{x:.4e}");
        json!(s.parse::<f64>().unwrap_or(x))
    } else {
        Value::Null
    }
}

pub fn html(designs: &[Design], sweep: Option<&str>, command: &str) -> Result<String, String> {
    let mut shown: Vec<usize> = (0..designs.len())
        .filter(|&i| designs[i].view.is_some())
        .collect();
    if shown.len() > MAX_MAPS {
        let n = shown.len();
        shown = (0..MAX_MAPS)
            .map(|k| shown[k * (n - 1) / (MAX_MAPS - 1)])
            .collect();
    }
    let maps: Vec<Value> = shown
        .iter()
        .map(|&i| {
            let d = &designs[i];
            let v = d.view.as_ref().expect("shown designs have a view");
            let stride = v.nodes.div_ceil(MAX_SHOWN).max(1);
            let side = v.nodes.div_ceil(stride);
            let pick = |values: &[f64]| {
                let mut out = Vec::with_capacity(side * side);
                for iy in (0..v.nodes).step_by(stride) {
                    for ix in (0..v.nodes).step_by(stride) {
                        out.push(round(values[iy * v.nodes + ix]));
                    }
                }
                out
            };
            let seg = |s: &[[[f64; 2]; 2]]| {
                s.iter()
                    .map(|s| [s[0][0], s[0][1], s[1][0], s[1][1]])
                    .collect::<Vec<_>>()
            };
            json!({
                "label": d.label,
                "side": side,
                "origin": v.origin,
                "step": v.step * stride as f64,
                "maps": v.maps.iter().map(|(t, u, values)| json!({"title": t, "unit": u, "values": pick(values)})).collect::<Vec<_>>(),
                "passive": seg(&v.passive),
                "foot": seg(&v.foot),
                "links": v.links,
                "stance": v.stance,
                "path": v.path,
            })
        })
        .collect();
    let rows: Vec<Value> = designs
        .iter()
        .map(|d| {
            json!({
                "label": d.label,
                "swept": d.swept,
                "values": COLUMNS.iter().map(|(key, _, scale, _)| {
                    d.json["table"].get(*key).and_then(Value::as_f64).map(|v| v * scale)
                }).collect::<Vec<_>>(),
            })
        })
        .collect();
    let data = json!({
        "maps": maps,
        "rows": rows,
        "columns": COLUMNS.iter().map(|c| c.1).collect::<Vec<_>>(),
        "sweep": sweep,
    });
    let data = serde_json::to_string(&data)
        .map_err(|e| e.to_string())?
        .replace("</", "<\\/");
    let mut table = String::from("<table><tr><th>design</th>");
    for c in COLUMNS {
        table.push_str(&format!("<th>{}</th>", escape(c.1)));
    }
    table.push_str("</tr>");
    for d in designs {
        table.push_str(&format!("<tr><td>{}</td>", escape(&d.label)));
        for (key, _, scale, digits) in COLUMNS {
            let cell = match d.json["table"].get(key).and_then(Value::as_f64) {
                Some(v) => format!("{:.*}", digits, v * scale),
                None => {
                    let why = d.json["not_computed"]
                        .get(key)
                        .and_then(Value::as_str)
                        .or_else(|| d.json["error"].as_str())
                        .unwrap_or("not computed");
                    format!("<span title=\"{}\">–</span>", escape(why))
                }
            };
            table.push_str(&format!("<td>{cell}</td>"));
        }
        table.push_str("</tr>");
    }
    table.push_str("</table>");
    Ok(format!(
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>Leg designs compared</title>
<style>
body {{ font-family: sans-serif; margin: 1.5em; color: #222; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
td, th {{ border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: right; }}
td:first-child, th:first-child {{ text-align: left; }}
.design {{ margin: 1.5em 0; }}
.maps {{ display: flex; flex-wrap: wrap; gap: 12px; }}
.map {{ font-size: 13px; }}
canvas {{ border: 1px solid #ddd; }}
.legend span {{ display: inline-block; margin-right: 1.2em; }}
code {{ background: #f4f4f4; padding: 0 0.2em; }}
</style></head><body>
<h1>Leg designs compared</h1>
<p><code>{command}</code></p>
<p>Each leg in its assembly branch of the home pose (continuation over a grid of foot
positions); measures in motor coordinates, the stance pose is the spec's home. Hover a
dash in the table for why a measure does not apply.</p>
{table}
<div id="sweep"></div>
<p class="legend"><span style="color:#d62728">━ passive joints lose rank (type II)</span>
<span>━ foot loses a direction (type I): where the branch ends</span>
<span style="color:#1f3b73">━ the leg at stance</span><span>○ the foot at stance</span></p>
<div id="designs"></div>
<script>
const DATA = {data};
function colour(t) {{
  // viridis, five stops
  const s = [[68,1,84],[59,82,139],[33,145,140],[94,201,98],[253,231,37]];
  t = Math.max(0, Math.min(1, t)) * 4; const i = Math.min(3, Math.floor(t)), f = t - i;
  return s[i].map((c, k) => Math.round(c + f * (s[i + 1][k] - c)));
}}
function drawMap(d, m) {{
  const px = 270, c = document.createElement('canvas'); c.width = px; c.height = px;
  const g = c.getContext('2d'), n = d.side;
  const vals = m.values.filter(v => v !== null).sort((a, b) => a - b);
  const lo = vals.length ? vals[Math.floor(0.02 * (vals.length - 1))] : 0;
  const hi = vals.length ? vals[Math.floor(0.98 * (vals.length - 1))] : 1;
  const img = g.createImageData(n, n);
  for (let iy = 0; iy < n; iy++) for (let ix = 0; ix < n; ix++) {{
    const v = m.values[iy * n + ix], o = 4 * ((n - 1 - iy) * n + ix);
    if (v === null) {{ img.data.set([245, 245, 245, 255], o); continue; }}
    const [r, gg, b] = colour(hi > lo ? (v - lo) / (hi - lo) : 0.5);
    img.data.set([r, gg, b, 255], o);
  }}
  const tmp = document.createElement('canvas'); tmp.width = n; tmp.height = n;
  tmp.getContext('2d').putImageData(img, 0, 0);
  g.imageSmoothingEnabled = false; g.drawImage(tmp, 0, 0, px, px);
  const span = d.step * (n - 1), half = d.step / 2;
  const X = x => (x - d.origin[0] + half) / (span + d.step) * px;
  const Y = y => px - (y - d.origin[1] + half) / (span + d.step) * px;
  const lines = (segs, style, w) => {{ g.strokeStyle = style; g.lineWidth = w; g.beginPath();
    for (const s of segs) {{ g.moveTo(X(s[0]), Y(s[1])); g.lineTo(X(s[2]), Y(s[3])); }} g.stroke(); }};
  lines(d.foot, '#000', 1.5); lines(d.passive, '#d62728', 2); lines(d.links, '#1f3b73', 3);
  g.strokeStyle = '#fff'; g.lineWidth = 2; g.beginPath();
  g.arc(X(d.stance[0]), Y(d.stance[1]), 5, 0, 2 * Math.PI); g.stroke();
  const box = document.createElement('div'); box.className = 'map';
  const fmt = v => Math.abs(v) >= 1e4 || (Math.abs(v) < 1e-2 && v !== 0) ? v.toExponential(2) : v.toPrecision(3);
  box.innerHTML = '<b>' + m.title + '</b><br>' + (vals.length ? 'colour from ' + fmt(lo) + ' to ' + fmt(hi) + ' ' + m.unit + ' (2nd to 98th percentile)' : 'no value') + '<br>';
  box.appendChild(c);
  box.appendChild(document.createElement('br'));
  box.appendChild(document.createTextNode('x from ' + d.origin[0].toFixed(3) + ' to ' + (d.origin[0] + span).toFixed(3) + ' m, y from ' + d.origin[1].toFixed(3) + ' to ' + (d.origin[1] + span).toFixed(3) + ' m'));
  return box;
}}
function drawPath(d) {{
  // A one-motor leg: its foot's path over the motor's turn, and the leg at stance.
  const px = 270, c = document.createElement('canvas'); c.width = px; c.height = px;
  const g = c.getContext('2d'); const pts = d.path.concat(d.links.flatMap(l => [[l[0], l[1]], [l[2], l[3]]]));
  const xs = pts.map(p => p[0]), ys = pts.map(p => p[1]);
  const x0 = Math.min(...xs), y0 = Math.min(...ys);
  const span = Math.max(Math.max(...xs) - x0, Math.max(...ys) - y0) * 1.1 || 1;
  const X = x => 10 + (x - x0) / span * (px - 20), Y = y => px - 10 - (y - y0) / span * (px - 20);
  g.strokeStyle = '#1f3b73'; g.lineWidth = 3; g.beginPath();
  for (const s of d.links) {{ g.moveTo(X(s[0]), Y(s[1])); g.lineTo(X(s[2]), Y(s[3])); }} g.stroke();
  g.strokeStyle = '#d62728'; g.lineWidth = 2; g.beginPath();
  d.path.forEach((p, i) => i ? g.lineTo(X(p[0]), Y(p[1])) : g.moveTo(X(p[0]), Y(p[1]))); g.stroke();
  const box = document.createElement('div'); box.className = 'map';
  box.innerHTML = '<b>the foot\'s path over a turn of the motor</b> (red)<br>'; box.appendChild(c);
  return box;
}}
for (const d of DATA.maps) {{
  const sec = document.createElement('div'); sec.className = 'design';
  const h = document.createElement('h2'); h.textContent = d.label; sec.appendChild(h);
  const row = document.createElement('div'); row.className = 'maps';
  for (const m of d.maps) row.appendChild(drawMap(d, m));
  if (d.path.length) row.appendChild(drawPath(d));
  sec.appendChild(row); document.getElementById('designs').appendChild(sec);
}}
if (DATA.sweep) {{
  const host = document.getElementById('sweep');
  const h = document.createElement('h2'); h.textContent = 'Against ' + DATA.sweep; host.appendChild(h);
  const row = document.createElement('div'); row.className = 'maps'; host.appendChild(row);
  DATA.columns.forEach((title, k) => {{
    const pts = DATA.rows.filter(r => r.values[k] !== null && r.swept !== null).map(r => [r.swept, r.values[k]]);
    const w = 300, hgt = 200, c = document.createElement('canvas'); c.width = w; c.height = hgt;
    const g = c.getContext('2d'); const box = document.createElement('div'); box.className = 'map';
    box.innerHTML = '<b>' + title + '</b><br>'; box.appendChild(c); row.appendChild(box);
    if (pts.length < 2) {{ g.fillText('not computed', 10, 20); return; }}
    const xs = pts.map(p => p[0]), ys = pts.map(p => p[1]);
    const x0 = Math.min(...xs), x1 = Math.max(...xs); let y0 = Math.min(...ys), y1 = Math.max(...ys);
    if (y1 === y0) {{ y0 -= 1; y1 += 1; }}
    const X = x => 50 + (x - x0) / (x1 - x0) * (w - 60), Y = y => hgt - 25 - (y - y0) / (y1 - y0) * (hgt - 40);
    g.strokeStyle = '#999'; g.strokeRect(50, 15, w - 60, hgt - 40);
    g.fillStyle = '#222'; g.font = '11px sans-serif';
    g.fillText(y1.toPrecision(3), 2, 20); g.fillText(y0.toPrecision(3), 2, hgt - 25);
    g.fillText(x0.toPrecision(3), 50, hgt - 8); g.fillText(x1.toPrecision(3), w - 40, hgt - 8);
    g.strokeStyle = '#1f77b4'; g.lineWidth = 2; g.beginPath();
    pts.forEach((p, i) => i ? g.lineTo(X(p[0]), Y(p[1])) : g.moveTo(X(p[0]), Y(p[1]))); g.stroke();
    g.fillStyle = '#1f77b4'; for (const p of pts) {{ g.beginPath(); g.arc(X(p[0]), Y(p[1]), 3, 0, 7); g.fill(); }}
  }});
}}
</script></body></html>
"#,
        command = escape(command),
    ))
}
