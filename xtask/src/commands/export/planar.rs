//! A planar leg in MJCF and URDF.
//!
//! The leg lies in the x–y plane; every revolute joint is a hinge about z at the link's
//! joint and every prismatic joint a slide along its axis, and each body's frame is its
//! parent's turned (or moved) by the joint value, as in the generated model, so `qpos`
//! (by joint name) is `q`. A spring on one joint is MuJoCo's joint `stiffness` about
//! `springref`; a coupling spring on `q_a − q_b` a fixed tendon with a spring (URDF has
//! no springs: its checker adds them). Masses, centres of mass and inertias are
//! written exactly (shortest round-trip decimals); the inertia about z is the spec's, the
//! x and y moments (which a z-hinge never sees) are set equal to it so that MuJoCo's
//! triangle inequality holds. Reflected rotor inertia `I·N²` is MuJoCo's joint
//! `armature`; motors are joint-torque actuators (`gear = 1`: `ctrl` is the joint torque
//! `u` of the runtime). In MJCF a closure is an `<equality><connect>` between two sites;
//! URDF holds only the spanning tree, with one fixed, massless frame per closure point,
//! named `<closure>.a` and `<closure>.b`, a `foot.point` frame and a `<contact>.point`
//! frame per contact, so that tools reading URDF can rebuild the loop. URDF has no rotor inertia: each motor's transmission carries
//! Drake's extension elements `<drake:rotor_inertia>` and `<drake:gear_ratio>` (read by
//! Drake; other parsers skip them) and a comment with the reflected inertia `I·N²`.
//! A leg with contact points gets MuJoCo's contact: a small sphere at each point (the only
//! geoms that collide) against a floor plane at the spec's ground, with the spec's
//! friction; without contacts, contact stays disabled.
//! Every name the exporters add holds a `.` (`foot.point`, `<closure>.a`, `<frame>.joint`,
//! `<contact>.geom`), which a spec's names cannot: a user may name a link `foot` (Cassie
//! has a body `left-foot`) and nothing clashes. See [`super::added`].

use std::fmt::Write;

use super::common::{
    added, closures_and_couplings, joint_spring, mjcf_contact, mjcf_contact_option, mjcf_floor,
    num, urdf_frames, urdf_transmissions, value,
};
use crate::gen::model::{self, Model, Param, Point};

/// A planar link's inertia (exports are planar only: [`run`] refuses a spatial leg).
fn planar_inertia(params: &[Param], inertia: &model::Inertia) -> f64 {
    value(params, inertia.planar().unwrap_or_default())
}

fn pair(m: &Model, names: &[String]) -> (f64, f64) {
    (value(&m.params, &names[0]), value(&m.params, &names[1]))
}

/// A point of a link, in the link's frame.
fn at(m: &Model, p: &Point) -> String {
    let (x, y) = pair(m, &p.point);
    format!("{} {} 0", num(x), num(y))
}

fn children(m: &Model, parent: Option<usize>) -> Vec<usize> {
    (0..m.links.len())
        .filter(|&i| m.links[i].parent == parent)
        .collect()
}

/// The model as MJCF.
pub fn mjcf(m: &Model) -> String {
    let mut out = String::new();
    let g = pair(m, &m.gravity);
    let _ = writeln!(
        out,
        "<!-- {}: exported from its spec by `cargo xtask export {}`, format mjcf. -->",
        m.name, m.name
    );
    let _ = writeln!(out, "<mujoco model=\"{}\">", m.name);
    // MuJoCo refuses a moving body without mass; a floating base's massless sliders get
    // the least mass it accepts instead (1e-9 kg, 1e-12 kg m²: invisible beside the body).
    let massless = m
        .links
        .iter()
        .any(|l| value(&m.params, &l.mass) == 0.0 || planar_inertia(&m.params, &l.inertia) == 0.0);
    let bounds = if massless {
        " boundmass=\"1e-9\" boundinertia=\"1e-12\""
    } else {
        ""
    };
    let _ = writeln!(
        out,
        "  <compiler angle=\"radian\" autolimits=\"true\"{bounds}/>"
    );
    // Contact only where the spec has contact points: a small sphere at each (the only
    // geoms that collide) against the floor, the spec's ground.
    let (attributes, flag) = mjcf_contact_option(m);
    let _ = writeln!(
        out,
        "  <option gravity=\"{} {} 0\" timestep=\"0.001\" integrator=\"RK4\"{attributes}>{flag}</option>",
        num(g.0),
        num(g.1),
    );
    let _ = writeln!(out, "  <worldbody>");
    mjcf_floor(m, &mut out);
    sites(m, None, "    ", &mut out);
    for i in children(m, None) {
        mjcf_body(m, i, 2, &mut out);
    }
    let _ = writeln!(out, "  </worldbody>");
    closures_and_couplings(m, &mut out);
    // The spec's home pose (near assembled) as a keyframe: MuJoCo starts at q = 0 otherwise,
    // where a closure may be open by centimetres. MuJoCo orders qpos as the bodies are
    // written, depth first.
    let mut order = Vec::new();
    fn depth_first(m: &Model, i: usize, order: &mut Vec<usize>) {
        order.push(i);
        for c in children(m, Some(i)) {
            depth_first(m, c, order);
        }
    }
    for i in children(m, None) {
        depth_first(m, i, &mut order);
    }
    let qpos: Vec<String> = order.iter().map(|&i| num(m.home[i])).collect();
    let _ = writeln!(
        out,
        "  <keyframe>\n    <key name=\"home\" qpos=\"{}\"/>\n  </keyframe>",
        qpos.join(" ")
    );
    if !m.actuated.is_empty() {
        let _ = writeln!(out, "  <actuator>");
        for &a in &m.actuated {
            let _ = writeln!(
                out,
                "    <motor name=\"{0}\" joint=\"{0}\" gear=\"1\"/>",
                m.links[a].name
            );
        }
        let _ = writeln!(out, "  </actuator>");
    }
    let _ = writeln!(out, "</mujoco>");
    out
}

/// The sites on link `link` (`None`: the base): closure points, the foot, contacts.
fn sites(m: &Model, link: Option<usize>, pad: &str, out: &mut String) {
    for c in &m.closures {
        for (side, p) in [("a", &c.a), ("b", &c.b)] {
            if p.link == link {
                let _ = writeln!(
                    out,
                    "{pad}<site name=\"{}\" pos=\"{}\"/>",
                    added::closure_point(&c.name, side),
                    at(m, p)
                );
            }
        }
    }
    if m.foot.link == link {
        let _ = writeln!(
            out,
            "{pad}<site name=\"{}\" pos=\"{}\"/>",
            added::FOOT,
            at(m, &m.foot)
        );
    }
    for c in &m.contacts {
        if c.point.link == link {
            mjcf_contact(&c.name, &at(m, &c.point), c.friction, pad, out);
        }
    }
}

fn mjcf_body(m: &Model, i: usize, depth: usize, out: &mut String) {
    let l = &m.links[i];
    let pad = "  ".repeat(depth);
    let (ox, oy) = pair(m, &l.origin);
    let (lx, ly) = pair(m, &l.length);
    let (cx, cy) = pair(m, &l.com);
    let (mass, inertia, damping) = (
        value(&m.params, &l.mass),
        planar_inertia(&m.params, &l.inertia),
        value(&m.params, &l.damping),
    );
    let armature = l.rotor.as_ref().map_or(0.0, |r| {
        let (ir, n) = pair(m, r);
        ir * n * n
    });
    let _ = writeln!(
        out,
        "{pad}<body name=\"{}\" pos=\"{} {} 0\">",
        l.name,
        num(ox),
        num(oy)
    );
    let (kind, axis) = match l.axis {
        Some(ref a) => ("slide", format!("{} {} 0", num(a[0]), num(a[1]))),
        None => ("hinge", "0 0 1".to_string()),
    };
    let spring = joint_spring(m, i);
    let _ = writeln!(
        out,
        "{pad}  <joint name=\"{}\" type=\"{kind}\" axis=\"{axis}\" damping=\"{}\" armature=\"{}\"{spring}/>",
        l.name,
        num(damping),
        num(armature)
    );
    let _ = writeln!(
        out,
        "{pad}  <inertial pos=\"{} {} 0\" mass=\"{}\" diaginertia=\"{i} {i} {i}\"/>",
        num(cx),
        num(cy),
        num(mass),
        i = num(inertia)
    );
    if lx == 0.0 && ly == 0.0 {
        // A link of no length (a slider, a body's joint): a dot, for the eye.
        let _ = writeln!(
            out,
            "{pad}  <geom type=\"sphere\" size=\"0.01\" contype=\"0\" conaffinity=\"0\" mass=\"0\"/>"
        );
    } else {
        let _ = writeln!(
            out,
            "{pad}  <geom type=\"capsule\" fromto=\"0 0 0 {} {} 0\" size=\"0.006\" contype=\"0\" conaffinity=\"0\" mass=\"0\"/>",
            num(lx),
            num(ly)
        );
    }
    sites(m, Some(i), &format!("{pad}  "), out);
    for c in children(m, Some(i)) {
        mjcf_body(m, c, depth + 1, out);
    }
    let _ = writeln!(out, "{pad}</body>");
}

/// The spanning tree as URDF, with fixed frames at the closure points and the foot.
pub fn urdf(m: &Model) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "<?xml version=\"1.0\"?>");
    let _ = writeln!(
        out,
        "<!-- {}: exported from its spec by `cargo xtask export {}`, format urdf.",
        m.name, m.name
    );
    let _ = writeln!(
        out,
        "     Planar leg in the x-y plane, joints about z. URDF holds the spanning tree only:"
    );
    let _ = writeln!(
        out,
        "     each closure k joins the frames k.a and k.b (they must coincide). Gravity of the"
    );
    let _ = writeln!(
        out,
        "     spec: {} {} 0 m/s^2. Reflected rotor inertia: see the transmissions. -->",
        num(pair(m, &m.gravity).0),
        num(pair(m, &m.gravity).1)
    );
    let _ = writeln!(
        out,
        "<robot name=\"{}\" xmlns:drake=\"http://drake.mit.edu\">",
        m.name
    );
    let _ = writeln!(out, "  <link name=\"base\"/>");
    for l in &m.links {
        let (cx, cy) = pair(m, &l.com);
        let (lx, ly) = pair(m, &l.length);
        let (mass, inertia) = (
            value(&m.params, &l.mass),
            planar_inertia(&m.params, &l.inertia),
        );
        let _ = writeln!(out, "  <link name=\"{}\">", l.name);
        let _ = writeln!(out, "    <inertial>");
        let _ = writeln!(
            out,
            "      <origin xyz=\"{} {} 0\" rpy=\"0 0 0\"/>",
            num(cx),
            num(cy)
        );
        let _ = writeln!(out, "      <mass value=\"{}\"/>", num(mass));
        let _ = writeln!(
            out,
            "      <inertia ixx=\"{i}\" ixy=\"0\" ixz=\"0\" iyy=\"{i}\" iyz=\"0\" izz=\"{i}\"/>",
            i = num(inertia)
        );
        let _ = writeln!(out, "    </inertial>");
        let len = (lx * lx + ly * ly).sqrt();
        let _ = writeln!(
            out,
            "    <visual>\n      <origin xyz=\"{} {} 0\" rpy=\"0 {} {}\"/>\n      <geometry><cylinder radius=\"0.006\" length=\"{}\"/></geometry>\n    </visual>",
            num(lx / 2.0),
            num(ly / 2.0),
            num(std::f64::consts::FRAC_PI_2),
            num(ly.atan2(lx)),
            num(len)
        );
        let _ = writeln!(out, "  </link>");
        let parent = l.parent.map_or("base", |p| m.links[p].name.as_str());
        let (ox, oy) = pair(m, &l.origin);
        let kind = if l.axis.is_some() {
            "prismatic"
        } else {
            "continuous"
        };
        let _ = writeln!(out, "  <joint name=\"{}\" type=\"{kind}\">", l.name);
        let _ = writeln!(
            out,
            "    <parent link=\"{parent}\"/>\n    <child link=\"{}\"/>",
            l.name
        );
        let axis = l.axis.as_ref().map_or("0 0 1".to_string(), |a| {
            format!("{} {} 0", num(a[0]), num(a[1]))
        });
        let _ = writeln!(
            out,
            "    <origin xyz=\"{} {} 0\" rpy=\"0 0 0\"/>\n    <axis xyz=\"{axis}\"/>",
            num(ox),
            num(oy)
        );
        if l.axis.is_some() {
            // URDF requires limits on a prismatic joint; these never bind.
            let _ = writeln!(
                out,
                "    <limit lower=\"-1000\" upper=\"1000\" effort=\"1e9\" velocity=\"1e9\"/>"
            );
        }
        let _ = writeln!(
            out,
            "    <dynamics damping=\"{}\" friction=\"0\"/>",
            num(value(&m.params, &l.damping))
        );
        let _ = writeln!(out, "  </joint>");
    }
    urdf_frames(m, |p| at(m, p), &mut out);
    urdf_transmissions(m, &mut out);
    let _ = writeln!(out, "</robot>");
    out
}
