//! The self-contained HTML report of `cargo xtask analyze`: the table of designs, heat
//! maps over each design's workspace with its singularity curves and the leg at its
//! stance pose, and for a sweep each measure against the swept parameter. The data go
//! in as JSON, drawn on canvases by a few lines of script; nothing is fetched.

use serde_json::{json, Value};

use crate::analyze::design::{columns, Design};

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
    let columns = columns(designs);
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
                "axes": v.axes,
                // Where the type II curves are not located the reader is told so.
                "note": d.json["curves"]["passive_note"].as_str().filter(|_| v.nodes > 0),
            })
        })
        .collect();
    let rows: Vec<Value> = designs
        .iter()
        .map(|d| {
            json!({
                "label": d.label,
                "swept": d.swept,
                "values": columns.iter().map(|(key, _, scale, _)| {
                    d.json["table"].get(*key).and_then(Value::as_f64).map(|v| v * scale)
                }).collect::<Vec<_>>(),
            })
        })
        .collect();
    let data = json!({
        "maps": maps,
        "rows": rows,
        "columns": columns.iter().map(|c| c.1).collect::<Vec<_>>(),
        "sweep": sweep,
    });
    let data = serde_json::to_string(&data)
        .map_err(|e| e.to_string())?
        .replace("</", "<\\/");
    let mut table = String::from("<table><tr><th>design</th>");
    for c in &columns {
        table.push_str(&format!("<th>{}</th>", escape(c.1)));
    }
    table.push_str("</tr>");
    for d in designs {
        table.push_str(&format!("<tr><td>{}</td>", escape(&d.label)));
        for &(key, _, scale, digits) in &columns {
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
body {{ font-family: sans-serif; font-size: 15px; margin: 1.5em; color: #222; }}
.note {{ color: #555; }}
table {{ border-collapse: collapse; margin: 1em 0; }}
td, th {{ border: 1px solid #ccc; padding: 0.3em 0.6em; text-align: right; }}
td:first-child, th:first-child {{ text-align: left; }}
.design {{ margin: 1.5em 0; }}
.maps {{ display: flex; flex-wrap: wrap; gap: 12px; }}
.map {{ font-size: 14px; max-width: 384px; }}

.legend span {{ display: inline-block; margin-right: 1.2em; }}
code {{ background: #f4f4f4; padding: 0 0.2em; }}
</style></head><body>
<h1>Leg designs compared</h1>
<p><code>{command}</code></p>
<p>Each leg in its assembly branch of the home pose (continuation over a grid of foot
positions); measures in motor coordinates, the stance pose is the spec's home. A spatial
leg's grid is a slice through its stance foot (its axes label the map), the leg drawn
projected onto it. Hover a dash in the table for why a measure does not apply.</p>
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
// Round ticks (1, 2 or 5 times a power of ten apart, about n of them) over [lo, hi].
function ticks(lo, hi, n) {{
  // About n round ticks, at least three: a window of ±0.49 m took a step of 0.5 and had
  // one tick, 0.
  const raw = (hi - lo) / n || 1, dec = Math.pow(10, Math.floor(Math.log10(raw)));
  const steps = [0.1, 0.2, 0.5, 1, 2, 5, 10].map(m => m * dec);
  for (let k = steps.findIndex(s => s >= raw * 0.999); ; k--) {{
    const step = steps[k], out = [];
    for (let i = Math.ceil(lo / step - 1e-9); i * step <= hi + step * 1e-9; i++) out.push(i * step);
    if (out.length >= 3 || k === 0) return {{ values: out, step }};
  }}
}}
function tickText(v, step) {{
  const dec = Math.max(0, Math.ceil(-Math.log10(step) - 1e-9));
  return Math.abs(v) < step * 1e-6 ? '0' : v.toFixed(dec).replace('-', '\u2212');
}}
const FONT = '13px sans-serif';
function drawMap(d, m) {{
  // The map (240 px square) with axes in metres, the colour bar to its right.
  const L = 58, T = 10, S = 240, W = L + S + 20 + 14 + 52, H = T + S + 46;
  const c = document.createElement('canvas'); c.width = W; c.height = H;
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
  g.imageSmoothingEnabled = false; g.drawImage(tmp, L, T, S, S);
  const span = d.step * (n - 1), half = d.step / 2;
  const x0 = d.origin[0] - half, y0 = d.origin[1] - half, ext = span + d.step;
  const X = x => L + (x - x0) / ext * S;
  const Y = y => T + S - (y - y0) / ext * S;
  g.save(); g.beginPath(); g.rect(L, T, S, S); g.clip();
  const lines = (segs, style, w) => {{ g.strokeStyle = style; g.lineWidth = w; g.beginPath();
    for (const s of segs) {{ g.moveTo(X(s[0]), Y(s[1])); g.lineTo(X(s[2]), Y(s[3])); }} g.stroke(); }};
  lines(d.foot, '#000', 1.5); lines(d.passive, '#d62728', 2); lines(d.links, '#1f3b73', 3);
  g.strokeStyle = '#fff'; g.lineWidth = 2; g.beginPath();
  g.arc(X(d.stance[0]), Y(d.stance[1]), 5, 0, 2 * Math.PI); g.stroke();
  g.restore();
  // Axes: ticks in metres on both.
  g.strokeStyle = '#444'; g.lineWidth = 1; g.strokeRect(L + 0.5, T + 0.5, S, S);
  g.fillStyle = '#222'; g.font = FONT;
  const tx = ticks(x0, x0 + ext, 4), ty = ticks(y0, y0 + ext, 4);
  g.textAlign = 'center'; g.textBaseline = 'top';
  for (const v of tx.values) {{ const x = X(v); g.beginPath(); g.moveTo(x, T + S); g.lineTo(x, T + S + 5); g.stroke(); g.fillText(tickText(v, tx.step), x, T + S + 7); }}
  g.fillText(d.axes[0] + ' (m)', L + S / 2, T + S + 26);
  g.textAlign = 'right'; g.textBaseline = 'middle';
  for (const v of ty.values) {{ const y = Y(v); g.beginPath(); g.moveTo(L, y); g.lineTo(L - 5, y); g.stroke(); g.fillText(tickText(v, ty.step), L - 7, y); }}
  g.save(); g.translate(12, T + S / 2); g.rotate(-Math.PI / 2); g.textAlign = 'center'; g.fillText(d.axes[1] + ' (m)', 0, 0); g.restore();
  // The colour bar: the map's colours from lo to hi, ticked in the measure's unit.
  const BX = L + S + 20, BW = 14;
  if (vals.length) {{
    for (let k = 0; k < S; k++) {{ const [r, gg, b] = colour(1 - k / (S - 1)); g.fillStyle = `rgb(${{r}},${{gg}},${{b}})`; g.fillRect(BX, T + k, BW, 1); }}
    g.strokeStyle = '#444'; g.strokeRect(BX + 0.5, T + 0.5, BW, S);
    const tc = ticks(lo, hi, 6), B = v => T + S - (v - lo) / ((hi - lo) || 1) * S;
    g.fillStyle = '#222'; g.textAlign = 'left'; g.textBaseline = 'middle';
    for (const v of tc.values) {{ const y = B(v); g.beginPath(); g.moveTo(BX + BW, y); g.lineTo(BX + BW + 4, y); g.stroke(); g.fillText(tickText(v, tc.step), BX + BW + 6, y); }}
    g.save(); g.translate(W - 6, T + S / 2); g.rotate(-Math.PI / 2); g.textAlign = 'center'; g.fillText(m.unit, 0, 0); g.restore();
  }}
  const box = document.createElement('div'); box.className = 'map';
  box.innerHTML = '<b>' + m.title + '</b>' + (m.unit ? ' (' + m.unit + ')' : '') + '<br><span class="note">' + (vals.length ? 'colours clipped to the 2nd–98th percentile; grey: outside' : 'no value') + '</span><br>';
  box.appendChild(c);
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
  if (d.note) {{ const p = document.createElement('p'); p.className = 'note'; p.textContent = 'No type II curves drawn: ' + d.note + '.'; sec.appendChild(p); }}
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
    const w = 340, hgt = 240, c = document.createElement('canvas'); c.width = w; c.height = hgt;
    const g = c.getContext('2d'); const box = document.createElement('div'); box.className = 'map';
    box.innerHTML = '<b>' + title + '</b><br>'; box.appendChild(c); row.appendChild(box);
    g.font = FONT;
    if (pts.length < 2) {{ g.fillText('not computed', 10, 20); return; }}
    const xs = pts.map(p => p[0]), ys = pts.map(p => p[1]);
    const x0 = Math.min(...xs), x1 = Math.max(...xs); let y0 = Math.min(...ys), y1 = Math.max(...ys);
    if (y1 === y0) {{ y0 -= 1; y1 += 1; }}
    const pad = (y1 - y0) * 0.08; y0 -= pad; y1 += pad;
    const L = 62, R = 14, T = 10, B = 46;
    const X = x => L + (x - x0) / (x1 - x0) * (w - L - R), Y = y => hgt - B - (y - y0) / (y1 - y0) * (hgt - B - T);
    const tx = ticks(x0, x1, 5), ty = ticks(y0, y1, 5);
    g.strokeStyle = '#e4e4e4'; g.lineWidth = 1;
    for (const v of ty.values) {{ g.beginPath(); g.moveTo(L, Y(v)); g.lineTo(w - R, Y(v)); g.stroke(); }}
    g.strokeStyle = '#444'; g.strokeRect(L + 0.5, T + 0.5, w - L - R, hgt - B - T);
    g.fillStyle = '#222';
    g.textAlign = 'center'; g.textBaseline = 'top';
    for (const v of tx.values) {{ const x = X(v); g.beginPath(); g.moveTo(x, hgt - B); g.lineTo(x, hgt - B + 5); g.stroke(); g.fillText(tickText(v, tx.step), x, hgt - B + 7); }}
    g.fillText(DATA.sweep, L + (w - L - R) / 2, hgt - B + 26);
    g.textAlign = 'right'; g.textBaseline = 'middle';
    for (const v of ty.values) {{ const y = Y(v); g.beginPath(); g.moveTo(L, y); g.lineTo(L - 5, y); g.stroke(); g.fillText(tickText(v, ty.step), L - 7, y); }}
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
