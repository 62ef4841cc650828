//! What `analyze` computes of one design and both its outputs read: the text table and
//! `report.html` (kept apart from the command, so that the report imports no command).

use leg_models::analysis::workspace::Segment;
use serde_json::Value;

/// What the report draws of one design.
pub struct View {
    pub nodes: usize,
    pub origin: [f64; 2],
    pub step: f64,
    /// `(title, unit, value per node (NaN where none))`.
    pub maps: Vec<(String, String, Vec<f64>)>,
    pub passive: Vec<Segment>,
    pub foot: Vec<Segment>,
    /// The leg at its stance pose: each link joint → tip, and the closures' points.
    pub links: Vec<[f64; 4]>,
    pub stance: [f64; 2],
    /// A one-motor leg's foot path (no maps then).
    pub path: Vec<[f64; 2]>,
    /// The names of the grid's two axes (`x`, `y` on a planar leg; a spatial leg's slice
    /// axes, its leg drawn projected onto them).
    pub axes: [String; 2],
}

/// One analysed design.
pub struct Design {
    pub label: String,
    pub file_stem: String,
    pub swept: Option<f64>,
    pub json: Value,
    pub csv: Option<String>,
    pub view: Option<View>,
}

/// The table's columns: key in `table`, heading, scale to the unit shown, decimals.
pub const COLUMNS: [(&str, &str, f64, usize); 7] = [
    ("workspace_area_m2", "workspace (cm²)", 1e4, 1),
    ("vertical_force_n", "push at stance (N)", 1.0, 2),
    (
        "vertical_speed_m_s",
        "vertical speed at stance (m/s)",
        1.0,
        3,
    ),
    ("effective_mass_kg", "effective mass at stance (kg)", 1.0, 4),
    ("impact_mitigation", "impact mitigation factor", 1.0, 3),
    (
        "singularity_distance_m",
        "stance to singularity (mm)",
        1e3,
        1,
    ),
    ("condition", "κ(J_θ) at stance", 1.0, 2),
];

/// A column of its own for a spatial leg's workspace volume (`--volume`).
const VOLUME: (&str, &str, f64, usize) = ("workspace_volume_m3", "workspace volume (cm³)", 1e6, 0);

/// The table's columns for these designs: [`COLUMNS`], and the volume where one was asked.
pub fn columns(designs: &[Design]) -> Vec<(&'static str, &'static str, f64, usize)> {
    let mut columns = COLUMNS.to_vec();
    if designs
        .iter()
        .any(|d| d.json["table"].get(VOLUME.0).is_some())
    {
        columns.insert(1, VOLUME);
    }
    columns
}

/// The table as text, one design a row.
pub fn table(designs: &[Design]) -> String {
    let columns = columns(designs);
    let mut rows = vec![std::iter::once("design".to_string())
        .chain(columns.iter().map(|c| c.1.to_string()))
        .collect::<Vec<_>>()];
    for d in designs {
        let mut row = vec![d.label.clone()];
        for &(key, _, scale, digits) in &columns {
            row.push(match d.json["table"].get(key).and_then(Value::as_f64) {
                Some(v) => format!("{:.*}", digits, v * scale),
                None => "–".to_string(),
            });
        }
        rows.push(row);
    }
    xtask::cli::text_table(&rows, |c| c > 0)
}
