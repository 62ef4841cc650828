//! The committed IR file of one geometry (`generated/ir/NAME.json`): what the model is and
//! its derived terms as straight-line programs. Written one instruction per line so that
//! a change reviews as a readable diff; floats round-trip exactly.

use codegen::ir::Program;
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::gen::model::Param;

pub const FORMAT: u32 = 3;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct IrFile {
    pub format: u32,
    pub model: ModelInfo,
    pub functions: Vec<Program>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelInfo {
    pub name: String,
    /// The spec, relative to the workspace root.
    pub spec: String,
    pub spec_sha256: String,
    pub casadi_version: String,
    /// Link names, in coordinate order.
    pub joints: Vec<String>,
    pub actuated: Vec<usize>,
    /// The home pose (rad), in coordinate order.
    pub home: Vec<f64>,
    pub closures: Vec<String>,
    /// The closures that are rods (one row, the distance), by index (left out when none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub distance_closures: Vec<usize>,
    /// The revolute closures (five rows: the point's three, then two keeping the axes
    /// parallel), by index (left out when none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub revolute_closures: Vec<usize>,
    /// Closure rows implied by the others at the assembled home pose (their forces are
    /// held at zero), found by the derivation.
    pub redundant_rows: Vec<usize>,
    /// `NQ − rank J` at the assembled home pose.
    pub mobility: usize,
    pub params: Vec<Param>,
    /// `"revolute"` or `"prismatic"`, in coordinate order.
    pub joint_kinds: Vec<String>,
    /// Each joint's parent joint (`None`: the base), in coordinate order.
    pub parents: Vec<Option<usize>>,
    pub springs: Vec<SpringInfo>,
    /// Contact point names, in the order of the contact terms' columns.
    pub contacts: Vec<String>,
    /// Coulomb μ of each contact (the spec's).
    pub contact_friction: Vec<f64>,
    /// The ground `normal · x = offset`, unit normal in the base frame (`dimension`
    /// entries).
    pub ground_normal: Vec<f64>,
    pub ground_offset: f64,
    /// 2 (planar, left out of the file) or 3 (spatial): the rows of every point term.
    #[serde(default = "planar", skip_serializing_if = "is_planar")]
    pub dimension: usize,
    /// The first coordinate of each ball joint's three angles (left out when none).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ball_joints: Vec<usize>,
    /// The first coordinate of the free joint of a floating robot's body (its
    /// translation; its angles are a ball joint's), left out on a leg with a fixed base.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub free_joint: Option<usize>,
}

fn planar() -> usize {
    2
}

fn is_planar(d: &usize) -> bool {
    *d == 2
}

impl ModelInfo {
    /// Closure rows: one per coordinate of each point closure's a minus b, one per rod.
    pub fn closure_rows(&self) -> usize {
        (0..self.closures.len())
            .map(|k| {
                if self.distance_closures.contains(&k) {
                    1
                } else if self.revolute_closures.contains(&k) {
                    5
                } else {
                    self.dimension
                }
            })
            .sum()
    }

    /// Closure points, two per closure (`NP`).
    pub fn closure_points(&self) -> usize {
        2 * self.closures.len()
    }

    /// Contact rows: one per coordinate of each contact point.
    pub fn contact_rows(&self) -> usize {
        self.dimension * self.contacts.len()
    }
}

/// A spring on joint `a`, or on `q_a − q_b`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpringInfo {
    pub name: String,
    pub a: usize,
    pub b: Option<usize>,
}

impl IrFile {
    pub fn parse(text: &str) -> Result<IrFile, String> {
        let ir: IrFile = serde_json::from_str(text).map_err(|e| e.to_string())?;
        if ir.format != FORMAT {
            return Err(format!(
                "IR format {} (this generator reads {FORMAT})",
                ir.format
            ));
        }
        Ok(ir)
    }

    /// The canonical text: objects that hold lists of objects are spread over lines,
    /// everything else (an instruction, a parameter, an output) stays on one line.
    pub fn to_text(&self) -> String {
        let value = serde_json::to_value(self).expect("IR serializes");
        let mut out = String::new();
        write_value(&value, 0, &mut out);
        out.push('\n');
        out
    }
}

fn holds_object_list(v: &Value) -> bool {
    match v {
        Value::Array(items) => items.iter().any(|i| i.is_object() || holds_object_list(i)),
        Value::Object(map) => map.values().any(holds_object_list),
        _ => false,
    }
}

fn write_value(v: &Value, indent: usize, out: &mut String) {
    let pad = |n: usize| "  ".repeat(n);
    if !holds_object_list(v) {
        out.push_str(&serde_json::to_string(v).expect("JSON value serializes"));
        return;
    }
    match v {
        Value::Array(items) => {
            out.push_str("[\n");
            for (i, item) in items.iter().enumerate() {
                out.push_str(&pad(indent + 1));
                write_value(item, indent + 1, out);
                out.push_str(if i + 1 < items.len() { ",\n" } else { "\n" });
            }
            out.push_str(&pad(indent));
            out.push(']');
        }
        Value::Object(map) => {
            out.push_str("{\n");
            for (i, (k, item)) in map.iter().enumerate() {
                out.push_str(&pad(indent + 1));
                out.push_str(&serde_json::to_string(k).expect("key serializes"));
                out.push_str(": ");
                write_value(item, indent + 1, out);
                out.push_str(if i + 1 < map.len() { ",\n" } else { "\n" });
            }
            out.push_str(&pad(indent));
            out.push('}');
        }
        _ => unreachable!("scalars hold no lists"),
    }
}
