//! What the exporters share: the names they add, exact numbers, and MJCF's closures and
//! coupling springs.

use std::fmt::Write;

use crate::gen::model::{Model, Param};

/// The names the exporters add beside the spec's: each holds a `.`, which a spec name
/// (a plain identifier) cannot, so none can clash with a link, joint, closure or contact.
pub mod added {
    /// The foot point's frame (URDF link, MJCF site).
    pub const FOOT: &str = "foot.point";

    /// Point `side` (`a` or `b`) of closure `closure`.
    pub fn closure_point(closure: &str, side: &str) -> String {
        format!("{closure}.{side}")
    }

    /// A contact point's frame (URDF link, MJCF site).
    pub fn contact_point(contact: &str) -> String {
        format!("{contact}.point")
    }

    /// A contact point's collision sphere (MJCF geom).
    pub fn contact_geom(contact: &str) -> String {
        format!("{contact}.geom")
    }

    /// The fixed joint that holds an added URDF frame.
    pub fn frame_joint(frame: &str) -> String {
        format!("{frame}.joint")
    }
}

pub fn num(v: f64) -> String {
    format!("{v:?}")
}

pub fn value(params: &[Param], name: &str) -> f64 {
    params
        .iter()
        .find(|p| p.name == name)
        .map(|p| p.default)
        .expect("every quantity of a model is one of its parameters")
}

/// A spring on joint `i` alone as MJCF's joint attributes: `stiffness` about `springref`.
pub(crate) fn joint_spring(m: &Model, i: usize) -> String {
    m.springs
        .iter()
        .find(|s| s.a == i && s.b.is_none())
        .map_or(String::new(), |s| {
            format!(
                " stiffness=\"{}\" springref=\"{}\"",
                num(value(&m.params, &s.stiffness)),
                num(value(&m.params, &s.rest))
            )
        })
}

/// MJCF's `<equality>` (a `<connect>` between the two sites of each closure) and
/// `<tendon>` (a coupling spring on `q_a − q_b` is a fixed tendon of length `q_a − q_b`
/// with a spring), for planar and spatial legs alike.
pub(crate) fn closures_and_couplings(m: &Model, out: &mut String) {
    if !m.closures.is_empty() {
        let _ = writeln!(out, "  <equality>");
        for c in &m.closures {
            // Stiffer than MuJoCo's default soft constraint (time constant 2 dt).
            let _ = writeln!(
                out,
                "    <connect name=\"{}\" site1=\"{}\" site2=\"{}\" solref=\"0.002 1\" solimp=\"0.95 0.99 0.001\"/>",
                c.name,
                added::closure_point(&c.name, "a"),
                added::closure_point(&c.name, "b")
            );
        }
        let _ = writeln!(out, "  </equality>");
    }
    let couplings: Vec<_> = m.springs.iter().filter(|s| s.b.is_some()).collect();
    if !couplings.is_empty() {
        let _ = writeln!(out, "  <tendon>");
        for s in couplings {
            let b = s.b.expect("a coupling");
            let _ = writeln!(
                out,
                "    <fixed name=\"{}\" stiffness=\"{}\" springlength=\"{}\">\n      <joint joint=\"{}\" coef=\"1\"/>\n      <joint joint=\"{}\" coef=\"-1\"/>\n    </fixed>",
                s.name,
                num(value(&m.params, &s.stiffness)),
                num(value(&m.params, &s.rest)),
                m.links[s.a].name,
                m.links[b].name
            );
        }
        let _ = writeln!(out, "  </tendon>");
    }
}
