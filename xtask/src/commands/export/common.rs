//! What the exporters share: the names they add, exact numbers, MJCF's closures and
//! coupling springs, and URDF's added frames and transmissions.

use std::fmt::Write;

use crate::gen::model::{Model, Param, Point};

/// The names the exporters add beside the spec's: each holds a `.`, which a spec name
/// (a plain identifier) cannot, so none can clash with a link, joint, closure or contact.
pub mod added {
    /// The foot point's frame (URDF link, MJCF site).
    pub const FOOT: &str = "foot.point";

    /// Point `side` (`a` or `b`) of closure `closure`.
    pub fn closure_point(closure: &str, side: &str) -> String {
        format!("{closure}.{side}")
    }

    /// A revolute closure's second point on side `side`, [`AXIS_LEVER`] along its axis:
    /// MJCF holds the closure as two `connect`s, at its point and there (six rows, one
    /// of them implied by the others: a hinge).
    pub fn closure_axis_point(closure: &str, side: &str) -> String {
        format!("{closure}.{side}.axis")
    }

    /// How far along a revolute closure's axis MJCF's second `connect` sits (m).
    pub const AXIS_LEVER: f64 = 0.05;

    /// A contact point's frame (URDF link, MJCF site).
    pub fn contact_point(contact: &str) -> String {
        format!("{contact}.point")
    }

    /// A contact point's collision sphere (MJCF geom).
    pub fn contact_geom(contact: &str) -> String {
        format!("{contact}.geom")
    }

    /// A rod (distance closure) as MJCF's spatial tendon between its two sites.
    pub fn rod(closure: &str) -> String {
        format!("{closure}.rod")
    }

    /// The fixed joint that holds an added URDF frame.
    pub fn frame_joint(frame: &str) -> String {
        format!("{frame}.joint")
    }
}

/// The radius of the MJCF spheres at the contact points [m].
pub const CONTACT_RADIUS: f64 = 0.002;

/// MJCF's `<option>` attributes for contact (after the integrator's) and its body:
/// contact disabled where the spec has no contact points; where it has, MuJoCo's elliptic
/// cone (ours is the exact cone; MuJoCo's default is a pyramid, which slid a thrown block
/// 56 mm off its line) with `impratio` 10, MuJoCo's advice for friction that holds
/// (with its default of 1 a soft contact creeps under load: `atrias_hopper`'s third apex
/// moved 10.3 mm from ours, 8.2 mm with it).
pub fn mjcf_contact_option(m: &Model) -> (&'static str, &'static str) {
    if m.contacts.is_empty() {
        ("", "\n    <flag contact=\"disable\"/>\n  ")
    } else {
        (" cone=\"elliptic\" impratio=\"10\"", "")
    }
}

/// MJCF's floor: the spec's ground `n·x = d` as a plane lowered by the spheres' radius,
/// so that a contact's sphere touches it when its centre (the contact point) reaches the
/// ground; it collides with the contact spheres only. Its friction is zero: MuJoCo gives a
/// contact the larger of its two geoms' coefficients, so the floor's default of 1 would
/// override every contact's own (a block thrown at 2 m/s with μ 0.5 stopped after 5.6 cm
/// of slide in MuJoCo instead of Coulomb's 23 cm). Nothing without contact points.
pub fn mjcf_floor(m: &Model, out: &mut String) {
    if m.contacts.is_empty() {
        return;
    }
    let d = m.ground_offset - CONTACT_RADIUS;
    let n = &m.ground_normal;
    let triple = |f: &dyn Fn(f64) -> f64| {
        // A planar leg's ground has no z: its plane stands along z.
        (0..3)
            .map(|k| n.get(k).map_or("0".to_string(), |&x| num(f(x))))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let _ = writeln!(
        out,
        "    <geom name=\"floor\" type=\"plane\" size=\"0 0 1\" pos=\"{}\" zaxis=\"{}\" contype=\"0\" conaffinity=\"1\" friction=\"0 0 0\"/>",
        triple(&|x| x * d),
        triple(&|x| x)
    );
}

/// MJCF's contact point `name` at `pos` (the site `<contact>.point`) and its collision
/// sphere: MuJoCo's contact is soft, a sphere that collides with the floor only, with the
/// spec's sliding friction `mu` (MuJoCo's default torsional and rolling).
pub fn mjcf_contact(name: &str, pos: &str, mu: f64, pad: &str, out: &mut String) {
    let _ = writeln!(
        out,
        "{pad}<site name=\"{}\" pos=\"{pos}\"/>",
        added::contact_point(name)
    );
    let _ = writeln!(
        out,
        "{pad}<geom name=\"{}\" type=\"sphere\" size=\"{}\" pos=\"{pos}\" contype=\"1\" conaffinity=\"0\" condim=\"3\" friction=\"{} 0.005 0.0001\" mass=\"0\"/>",
        added::contact_geom(name),
        num(CONTACT_RADIUS),
        num(mu)
    );
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

/// A point's position in the base frame at `q = 0` (every joint at zero, a ball joint at
/// the identity), from the spec's values: what MuJoCo computes at `qpos0`.
fn rest_position(m: &Model, p: &Point) -> [f64; 3] {
    let coordinate = |names: &[String], k: usize| names.get(k).map_or(0.0, |n| value(&m.params, n));
    let mut x = [0, 1, 2].map(|k| coordinate(&p.point, k));
    let mut link = p.link;
    while let Some(l) = link {
        let l = &m.links[l];
        let r = l
            .orientation
            .unwrap_or([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]);
        let turned = [0, 1, 2].map(|i| (0..3).map(|j| r[i][j] * x[j]).sum::<f64>());
        x = [0, 1, 2].map(|i| coordinate(&l.origin, i) + turned[i]);
        link = l.parent;
    }
    x
}

/// MJCF's `<equality>` (a `<connect>` between the two sites of a point closure; a rod's
/// spatial tendon between them held at its length by a tendon equality) and `<tendon>`
/// (a coupling spring on `q_a − q_b` is a fixed tendon of length `q_a − q_b` with a
/// spring; the rods' spatial tendons), for planar and spatial legs alike.
pub(crate) fn closures_and_couplings(m: &Model, out: &mut String) {
    if !m.closures.is_empty() {
        let _ = writeln!(out, "  <equality>");
        for c in &m.closures {
            let (a, b) = (
                added::closure_point(&c.name, "a"),
                added::closure_point(&c.name, "b"),
            );
            // Stiffer than MuJoCo's default soft constraint (time constant 2 dt).
            let soft = "solref=\"0.002 1\" solimp=\"0.95 0.99 0.001\"";
            match &c.distance {
                None => {
                    let _ = writeln!(
                        out,
                        "    <connect name=\"{}\" site1=\"{a}\" site2=\"{b}\" {soft}/>",
                        c.name
                    );
                    if c.revolute.is_some() {
                        let _ = writeln!(
                            out,
                            "    <connect name=\"{}.axis\" site1=\"{}\" site2=\"{}\" {soft}/>",
                            c.name,
                            added::closure_axis_point(&c.name, "a"),
                            added::closure_axis_point(&c.name, "b")
                        );
                    }
                }
                Some(length) => {
                    // MuJoCo holds `length − length(qpos0) = polycoef[0]`: the rod's length
                    // less the sites' distance at q = 0.
                    let (pa, pb) = (rest_position(m, &c.a), rest_position(m, &c.b));
                    let rest = (0..3).map(|k| (pa[k] - pb[k]).powi(2)).sum::<f64>().sqrt();
                    let _ = writeln!(
                        out,
                        "    <tendon name=\"{}\" tendon1=\"{}\" polycoef=\"{} 0 0 0 0\" {soft}/>",
                        c.name,
                        added::rod(&c.name),
                        num(value(&m.params, length) - rest)
                    );
                }
            }
        }
        let _ = writeln!(out, "  </equality>");
    }
    let couplings: Vec<_> = m.springs.iter().filter(|s| s.b.is_some()).collect();
    let rods: Vec<_> = m.closures.iter().filter(|c| c.distance.is_some()).collect();
    if !couplings.is_empty() || !rods.is_empty() {
        let _ = writeln!(out, "  <tendon>");
        for c in rods {
            let _ = writeln!(
                out,
                "    <spatial name=\"{}\" width=\"0.003\">\n      <site site=\"{}\"/>\n      <site site=\"{}\"/>\n    </spatial>",
                added::rod(&c.name),
                added::closure_point(&c.name, "a"),
                added::closure_point(&c.name, "b")
            );
        }
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

/// URDF's fixed frames at the closure points (`<closure>.a`, `.b`), the foot and the
/// contact points, each on its link; `at` writes a point's `xyz`.
pub(crate) fn urdf_frames(m: &Model, at: impl Fn(&Point) -> String, out: &mut String) {
    let mut frame = |name: &str, link: Option<usize>, xyz: String| {
        let _ = writeln!(out, "  <link name=\"{name}\"/>");
        let _ = writeln!(
            out,
            "  <joint name=\"{}\" type=\"fixed\">",
            added::frame_joint(name)
        );
        let _ = writeln!(
            out,
            "    <parent link=\"{}\"/>\n    <child link=\"{name}\"/>",
            link.map_or("base", |l| m.links[l].name.as_str())
        );
        let _ = writeln!(out, "    <origin xyz=\"{xyz}\" rpy=\"0 0 0\"/>");
        let _ = writeln!(out, "  </joint>");
    };
    for c in &m.closures {
        frame(&added::closure_point(&c.name, "a"), c.a.link, at(&c.a));
        frame(&added::closure_point(&c.name, "b"), c.b.link, at(&c.b));
        // A revolute closure's points on its axes, as in MJCF (a URDF tool that holds
        // the two pairs together holds the hinge).
        if let Some(r) = &c.revolute {
            for (side, p, axis) in [("a", &c.a, r.a), ("b", &c.b, r.axis_b())] {
                let xyz: Vec<String> = (0..3)
                    .map(|k| {
                        let x = p.point.get(k).map_or(0.0, |n| value(&m.params, n));
                        num(x + added::AXIS_LEVER * axis[k])
                    })
                    .collect();
                frame(
                    &added::closure_axis_point(&c.name, side),
                    p.link,
                    xyz.join(" "),
                );
            }
        }
    }
    frame(added::FOOT, m.foot.link, at(&m.foot));
    for c in &m.contacts {
        frame(&added::contact_point(&c.name), c.point.link, at(&c.point));
    }
}

/// URDF's transmission per motor: its gear as `mechanicalReduction`, and the rotor inertia
/// and gear as Drake's extension elements (a URDF joint has no armature).
pub(crate) fn urdf_transmissions(m: &Model, out: &mut String) {
    for &a in &m.actuated {
        let l = &m.links[a];
        let r = l.rotor.as_ref().expect("actuated links have a rotor");
        let (ir, n) = (value(&m.params, &r[0]), value(&m.params, &r[1]));
        let _ = writeln!(out, "  <transmission name=\"{}_motor\">", l.name);
        let _ = writeln!(
            out,
            "    <type>transmission_interface/SimpleTransmission</type>"
        );
        let _ = writeln!(
            out,
            "    <joint name=\"{}\"><hardwareInterface>hardware_interface/EffortJointInterface</hardwareInterface></joint>",
            l.name
        );
        let _ = writeln!(out, "    <actuator name=\"{}_motor\">", l.name);
        let _ = writeln!(
            out,
            "      <mechanicalReduction>{}</mechanicalReduction>",
            num(n)
        );
        let _ = writeln!(
            out,
            "      <drake:rotor_inertia value=\"{}\"/>\n      <drake:gear_ratio value=\"{}\"/>",
            num(ir),
            num(n)
        );
        let _ = writeln!(out, "    </actuator>");
        let _ = writeln!(
            out,
            "    <!-- rotor inertia {} kg m^2, reflected {} kg m^2 -->",
            num(ir),
            num(ir * n * n)
        );
        let _ = writeln!(out, "  </transmission>");
    }
}
