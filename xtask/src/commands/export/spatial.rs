//! Export a spatial leg to MuJoCo (MJCF) and URDF ([`urdf`]), from its spec.
//!
//! Each spec link is a body placed by its `origin` and `orientation` (the body's `pos` and
//! `quat`) in its parent's; a revolute joint is a `hinge` and a prismatic one a `slide`
//! about the link's `axis` (body frame), so `qpos` (by joint name) is `q`. A ball joint is
//! one MuJoCo `ball` joint named for its link: its `qpos` is the unit quaternion of
//! `R_x(α) R_y(β) R_z(γ)` and its `qvel` the angular velocity in the link's frame,
//! `ω = E(β, γ) (α̇, β̇, γ̇)` with `E`'s columns `R_z(γ)ᵀ R_y(β)ᵀ x̂`, `R_z(γ)ᵀ ŷ`, `ẑ`
//! (see [`ball_rate_map`]). Inertias are written whole (`fullinertia`, the spec's order);
//! reflected rotor inertia `I·N²` is the joint's `armature`; a spring on one joint its
//! `stiffness` about `springref`, a coupling spring a fixed tendon; point closures are
//! `<connect>`s between two sites (`<closure>.a`, `<closure>.b`), so MuJoCo's rule for a
//! second anchor from `qpos0` never applies; a rod (a distance closure) is a spatial tendon
//! between its two sites held by a tendon equality, whose offset follows MuJoCo's `qpos0`
//! rule: the rod's length less the sites' distance at `q = 0`. The foot is the site
//! `foot.point`. A leg with contact points gets MuJoCo's contact as a planar leg does: a
//! 2 mm sphere at each (`<contact>.geom`, the only geoms that collide, with the spec's
//! friction) against a floor plane at the spec's ground, with MuJoCo's elliptic cone (ours
//! is the exact cone; MuJoCo's default is a pyramid); without, contact stays disabled.
//! The time step
//! is 0.5 ms, Cassie's own: at 1 ms MuJoCo's RK4 diverged within 7 ms on Cassie's leg (its 1500 N m/rad shin
//! spring beside an achilles rod of 4e-6 kg m² about its axis).

use std::fmt::Write;

use super::common::{
    added, closures_and_couplings, joint_spring, mjcf_contact, mjcf_contact_option, mjcf_floor,
    num, urdf_frames, urdf_transmissions, value,
};
use crate::gen::model::{Inertia, Model, Point};

fn triple(m: &Model, names: &[String]) -> String {
    if names.is_empty() {
        return "0 0 0".into();
    }
    names
        .iter()
        .map(|n| num(value(&m.params, n)))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The unit quaternion `[w, x, y, z]` of a rotation matrix (Shepperd's method).
pub fn quaternion(r: &[[f64; 3]; 3]) -> [f64; 4] {
    let t = r[0][0] + r[1][1] + r[2][2];
    let q = if t > 0.0 {
        let s = (t + 1.0).sqrt() * 2.0;
        [
            0.25 * s,
            (r[2][1] - r[1][2]) / s,
            (r[0][2] - r[2][0]) / s,
            (r[1][0] - r[0][1]) / s,
        ]
    } else if r[0][0] > r[1][1] && r[0][0] > r[2][2] {
        let s = (1.0 + r[0][0] - r[1][1] - r[2][2]).sqrt() * 2.0;
        [
            (r[2][1] - r[1][2]) / s,
            0.25 * s,
            (r[0][1] + r[1][0]) / s,
            (r[0][2] + r[2][0]) / s,
        ]
    } else if r[1][1] > r[2][2] {
        let s = (1.0 + r[1][1] - r[0][0] - r[2][2]).sqrt() * 2.0;
        [
            (r[0][2] - r[2][0]) / s,
            (r[0][1] + r[1][0]) / s,
            0.25 * s,
            (r[1][2] + r[2][1]) / s,
        ]
    } else {
        let s = (1.0 + r[2][2] - r[0][0] - r[1][1]).sqrt() * 2.0;
        [
            (r[1][0] - r[0][1]) / s,
            (r[0][2] + r[2][0]) / s,
            (r[1][2] + r[2][1]) / s,
            0.25 * s,
        ]
    };
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
    q.map(|x| x / n)
}

/// The quaternion of a ball joint's angles: `q_x(α) ⊗ q_y(β) ⊗ q_z(γ)`.
pub fn ball_quaternion(alpha: f64, beta: f64, gamma: f64) -> [f64; 4] {
    let mul = |a: [f64; 4], b: [f64; 4]| {
        [
            a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3],
            a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2],
            a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1],
            a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0],
        ]
    };
    let (sa, ca) = (alpha / 2.0).sin_cos();
    let (sb, cb) = (beta / 2.0).sin_cos();
    let (sg, cg) = (gamma / 2.0).sin_cos();
    mul(
        mul([ca, sa, 0.0, 0.0], [cb, 0.0, sb, 0.0]),
        [cg, 0.0, 0.0, sg],
    )
}

/// `E(β, γ)` (rows), `ω = E (α̇, β̇, γ̇)` in the link's frame: columns `R_z(γ)ᵀ R_y(β)ᵀ x̂`,
/// `R_z(γ)ᵀ ŷ` and `ẑ`.
pub fn ball_rate_map(beta: f64, gamma: f64) -> [[f64; 3]; 3] {
    let (sb, cb) = beta.sin_cos();
    let (sg, cg) = gamma.sin_cos();
    [[cb * cg, sg, 0.0], [-cb * sg, cg, 0.0], [sb, 0.0, 1.0]]
}

/// The joint of MuJoCo's that coordinate `i` belongs to: a ball joint's three angles are
/// one joint named for its link.
pub fn joint_name(m: &Model, i: usize) -> String {
    let name = &m.links[i].name;
    match name.rsplit_once('.') {
        Some((link, "x" | "y" | "z")) if m.links[i].massless || link_is_ball_body(m, i) => {
            link.to_string()
        }
        Some((link, "tx" | "ty" | "tz")) if is_free(m, i) => link.to_string(),
        _ => name.clone(),
    }
}

fn link_is_ball_body(m: &Model, i: usize) -> bool {
    m.links[i].parent.is_some_and(|p| m.links[p].massless)
}

/// The bodies: spec links, i.e. coordinates that carry a link (not a ball's inner frames).
fn bodies_under(m: &Model, parent: Option<usize>) -> Vec<usize> {
    (0..m.links.len())
        .filter(|&i| !m.links[i].massless && body_parent(m, i) == parent)
        .collect()
}

/// The body a body hangs from (through a ball joint's inner frames).
fn body_parent(m: &Model, i: usize) -> Option<usize> {
    let mut p = m.links[i].parent;
    while let Some(k) = p {
        if !m.links[k].massless {
            return Some(k);
        }
        p = m.links[k].parent;
    }
    None
}

/// Coordinate `i` belongs to a free joint (a floating robot's body).
fn is_free(m: &Model, i: usize) -> bool {
    m.links[i].spec_kind == crate::gen::spec::JointKind::Free
}

/// The coordinate where a body's joint starts (a ball joint's `.x`, a free joint's
/// `.tx`).
fn first_coordinate(m: &Model, i: usize) -> usize {
    if is_free(m, i) {
        i - 5
    } else if link_is_ball_body(m, i) {
        i - 2
    } else {
        i
    }
}

fn sites(m: &Model, body: Option<usize>, pad: &str, out: &mut String) {
    let site = |out: &mut String, name: &str, p: &Point| {
        let _ = writeln!(
            out,
            "{pad}<site name=\"{name}\" pos=\"{}\"/>",
            triple(m, &p.point)
        );
    };
    for c in &m.closures {
        for (side, p) in [("a", &c.a), ("b", &c.b)] {
            if p.link == body {
                site(out, &added::closure_point(&c.name, side), p);
                // A revolute closure's second pair of points, on its axes.
                if let Some(r) = &c.revolute {
                    let axis = if side == "a" { r.a } else { r.axis_b() };
                    let at: Vec<String> = (0..3)
                        .map(|k| {
                            let x = p.point.get(k).map_or(0.0, |n| value(&m.params, n));
                            num(x + added::AXIS_LEVER * axis[k])
                        })
                        .collect();
                    let _ = writeln!(
                        out,
                        "{pad}<site name=\"{}\" pos=\"{}\"/>",
                        added::closure_axis_point(&c.name, side),
                        at.join(" ")
                    );
                }
            }
        }
    }
    if m.foot.link == body {
        site(out, added::FOOT, &m.foot);
    }
    for c in &m.contacts {
        if c.point.link == body {
            mjcf_contact(&c.name, &triple(m, &c.point.point), c.friction, pad, out);
        }
    }
}

fn body(m: &Model, i: usize, depth: usize, out: &mut String) {
    let pad = "  ".repeat(depth);
    let first = first_coordinate(m, i);
    let placed = &m.links[first];
    let l = &m.links[i];
    let quat = placed.orientation.as_ref().map_or(String::new(), |r| {
        let q = quaternion(r);
        format!(" quat=\"{}\"", q.map(num).join(" "))
    });
    let name = joint_name(m, i);
    let _ = writeln!(
        out,
        "{pad}<body name=\"{name}\" pos=\"{}\"{quat}>",
        triple(m, &placed.origin)
    );
    let damping = num(value(&m.params, &l.damping));
    let armature = l.rotor.as_ref().map_or(0.0, |r| {
        let (ir, n) = (value(&m.params, &r[0]), value(&m.params, &r[1]));
        ir * n * n
    });
    if is_free(m, i) {
        // MuJoCo's free joint: qpos the position and the quaternion of the ball joint's
        // angles, qvel the linear velocity in the world and ω in the body.
        let _ = writeln!(out, "{pad}  <freejoint name=\"{name}\"/>");
    } else if first != i {
        let _ = writeln!(
            out,
            "{pad}  <joint name=\"{name}\" type=\"ball\" damping=\"{damping}\"/>"
        );
    } else {
        let kind = if l.joint == "prismatic" {
            "slide"
        } else {
            "hinge"
        };
        let axis = l.axis.as_ref().expect("a spatial joint has its axis");
        let spring = joint_spring(m, i);
        let _ = writeln!(
            out,
            "{pad}  <joint name=\"{name}\" type=\"{kind}\" axis=\"{}\" damping=\"{damping}\" armature=\"{}\"{spring}/>",
            axis.iter().map(|&a| num(a)).collect::<Vec<_>>().join(" "),
            num(armature)
        );
    }
    let Inertia::Spatial(entries) = &l.inertia else {
        unreachable!("a spatial link's inertia is a tensor")
    };
    let tensor: Vec<String> = entries
        .iter()
        .map(|e| num(e.as_ref().map_or(0.0, |n| value(&m.params, n))))
        .collect();
    let _ = writeln!(
        out,
        "{pad}  <inertial pos=\"{}\" mass=\"{}\" fullinertia=\"{}\"/>",
        triple(m, &l.com),
        num(value(&m.params, &l.mass)),
        tensor.join(" ")
    );
    // A link of no length (a prismatic stage) is drawn as a dot: MuJoCo refuses a capsule
    // whose ends coincide.
    let length = triple(m, &l.length);
    if length.split(' ').all(|x| x.parse::<f64>() == Ok(0.0)) {
        let _ = writeln!(
            out,
            "{pad}  <geom type=\"sphere\" size=\"0.006\" contype=\"0\" conaffinity=\"0\" mass=\"0\"/>"
        );
    } else {
        let _ = writeln!(
            out,
            "{pad}  <geom type=\"capsule\" fromto=\"0 0 0 {length}\" size=\"0.006\" contype=\"0\" conaffinity=\"0\" mass=\"0\"/>"
        );
    }
    sites(m, Some(i), &format!("{pad}  "), out);
    for c in bodies_under(m, Some(i)) {
        body(m, c, depth + 1, out);
    }
    let _ = writeln!(out, "{pad}</body>");
}

/// The spatial model as MJCF.
pub fn mjcf(m: &Model) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "<!-- {}: exported from its spec by `cargo xtask export {}`, format mjcf. -->",
        m.name, m.name
    );
    let _ = writeln!(out, "<mujoco model=\"{}\">", m.name);
    // MuJoCo refuses a moving body without mass; massless stages (a prismatic x, y) get
    // a mass it accepts instead (mjMINVAL is 1e-15), small enough to stay below the
    // cross-check's 1e-9 beside a light leg.
    // (A ball joint's massless helper links are not bodies here.)
    let bounds = if m
        .links
        .iter()
        .any(|l| !l.massless && value(&m.params, &l.mass) == 0.0)
    {
        " boundmass=\"1e-12\" boundinertia=\"1e-14\""
    } else {
        ""
    };
    let _ = writeln!(
        out,
        "  <compiler angle=\"radian\" autolimits=\"true\"{bounds}/>"
    );
    let (attributes, flag) = mjcf_contact_option(m);
    let _ = writeln!(
        out,
        "  <option gravity=\"{}\" timestep=\"0.0005\" integrator=\"RK4\"{attributes}>{flag}</option>",
        triple(m, &m.gravity),
    );
    let _ = writeln!(out, "  <worldbody>");
    mjcf_floor(m, &mut out);
    sites(m, None, "    ", &mut out);
    for i in bodies_under(m, None) {
        body(m, i, 2, &mut out);
    }
    let _ = writeln!(out, "  </worldbody>");
    closures_and_couplings(m, &mut out);
    // The home pose as a keyframe, qpos in MuJoCo's order (bodies depth first; a ball
    // joint's quaternion).
    fn depth_first(m: &Model, i: usize, qpos: &mut Vec<String>) {
        let first = first_coordinate(m, i);
        let h = &m.home;
        if is_free(m, i) {
            qpos.extend(h[first..first + 3].iter().map(|&x| num(x)));
            qpos.extend(ball_quaternion(h[first + 3], h[first + 4], h[i]).map(num));
        } else if first != i {
            qpos.extend(ball_quaternion(h[first], h[first + 1], h[i]).map(num));
        } else {
            qpos.push(num(m.home[i]));
        }
        for c in bodies_under(m, Some(i)) {
            depth_first(m, c, qpos);
        }
    }
    let mut qpos = Vec::new();
    for i in bodies_under(m, None) {
        depth_first(m, i, &mut qpos);
    }
    let _ = writeln!(
        out,
        "  <keyframe>\n    <key name=\"home\" qpos=\"{}\"/>\n  </keyframe>",
        qpos.join(" ")
    );
    let _ = writeln!(out, "  <actuator>");
    for &a in &m.actuated {
        let _ = writeln!(
            out,
            "    <motor name=\"{0}\" joint=\"{0}\" gear=\"1\"/>",
            m.links[a].name
        );
    }
    let _ = writeln!(out, "  </actuator>");
    let _ = writeln!(out, "</mujoco>");
    out
}

/// URDF's `rpy` (fixed axes: `R = R_z(yaw) R_y(pitch) R_x(roll)`) of a rotation matrix.
pub fn rpy(r: &[[f64; 3]; 3]) -> [f64; 3] {
    let pitch = (-r[2][0]).atan2((r[0][0] * r[0][0] + r[1][0] * r[1][0]).sqrt());
    // Within √ε of the gimbal, roll and yaw from the normal branch divide rounding by
    // cos(pitch); the gimbal branch errs by cos(pitch) instead: both near 1e-8 here.
    if (r[0][0] * r[0][0] + r[1][0] * r[1][0]).sqrt() < 1e-8 {
        // Pitch ±90°: roll and yaw turn about the same axis; all of it as yaw.
        return [0.0, pitch, (-r[0][1]).atan2(r[1][1])];
    }
    [r[2][1].atan2(r[2][2]), pitch, r[1][0].atan2(r[0][0])]
}

/// The spatial model as URDF: the spanning tree, one link and joint per coordinate. A
/// ball joint is three `continuous` joints about x, y and z (named `<link>.x`, `.y`,
/// `.z`, the generated model's own coordinates) on two massless links, so a URDF tool's
/// configuration is `q` with no map. Each joint is placed by the link's `origin` and
/// `orientation` (`rpy`) in its parent, about the link's `axis`; inertias are whole, about
/// the centre of mass in the link's axes. Closures, the foot and the motors are as in the
/// planar URDF: fixed frames and transmissions. Springs have no URDF element: the spec
/// holds them. A floating robot's free joint is six joints here, the chart's coordinates
/// (`<body>.tx`, `.ty`, `.tz` prismatic, `.x`, `.y`, `.z` continuous): see
/// [`urdf_floating`] for the body as the root link.
pub fn urdf(m: &Model) -> String {
    write_urdf(m, false)
}

/// A floating robot's URDF with its body as the root link (`<body>.z`) and no joint for
/// the free joint, for a URDF tool that floats the root itself (Pinocchio's
/// `JointModelFreeFlyer`: its configuration the body's position and unit quaternion, its
/// velocity the body's linear and angular velocity in the body's frame). Everything else
/// is [`urdf`]'s. At the chart's centre the base frame is the body's, so every placement
/// is unchanged. Not for a model without a free joint.
pub fn urdf_floating(m: &Model) -> String {
    write_urdf(m, true)
}

fn write_urdf(m: &Model, floating_root: bool) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "<?xml version=\"1.0\"?>");
    let _ = writeln!(
        out,
        // An XML comment cannot hold two hyphens in a row: no `--format` here.
        "<!-- {}: exported from its spec by `cargo xtask export {}`, format urdf.",
        m.name, m.name
    );
    let rods: Vec<String> = m
        .closures
        .iter()
        .filter_map(|c| {
            c.distance
                .as_ref()
                .map(|l| format!("{} {} m", c.name, num(value(&m.params, l))))
        })
        .collect();
    let _ = writeln!(
        out,
        "     Spatial leg. URDF holds the spanning tree only: each closure k joins the frames\n     k.a and k.b (they must coincide{}). A ball joint is three continuous joints about x,\n     y, z on massless links. Gravity of the spec: {} m/s^2. Reflected rotor inertia: see\n     the transmissions. Springs: see the spec.{} -->",
        if rods.is_empty() {
            String::new()
        } else {
            format!(
                "; a rod's frames stay its length apart: {}",
                rods.join(", ")
            )
        },
        triple(m, &m.gravity),
        if floating_root {
            "\n     The root link is the body of a free joint: give it a floating root joint (Pinocchio's\n     JointModelFreeFlyer), whose velocity is the body's, in the body's frame."
        } else {
            ""
        }
    );
    let _ = writeln!(
        out,
        "<robot name=\"{}\" xmlns:drake=\"http://drake.mit.edu\">",
        m.name
    );
    if !floating_root {
        let _ = writeln!(out, "  <link name=\"base\"/>");
    }
    for (i, l) in m.links.iter().enumerate() {
        // The root link floats: no `base`, and nothing of the free joint but its body.
        let free = floating_root && is_free(m, i);
        if free && l.massless {
            continue;
        }
        if l.massless {
            let _ = writeln!(out, "  <link name=\"{}\"/>", l.name);
        } else {
            let _ = writeln!(out, "  <link name=\"{}\">", l.name);
            let Inertia::Spatial(e) = &l.inertia else {
                unreachable!("a spatial link's inertia is a tensor")
            };
            let i = |k: usize| num(e[k].as_ref().map_or(0.0, |n| value(&m.params, n)));
            let _ = writeln!(
                out,
                "    <inertial>\n      <origin xyz=\"{}\" rpy=\"0 0 0\"/>\n      <mass value=\"{}\"/>\n      <inertia ixx=\"{}\" ixy=\"{}\" ixz=\"{}\" iyy=\"{}\" iyz=\"{}\" izz=\"{}\"/>\n    </inertial>",
                triple(m, &l.com),
                num(value(&m.params, &l.mass)),
                i(0),
                i(3),
                i(4),
                i(1),
                i(5),
                i(2)
            );
            let _ = writeln!(out, "  </link>");
        }
        if free {
            continue;
        }
        let parent = l.parent.map_or("base", |p| m.links[p].name.as_str());
        let kind = if l.joint == "prismatic" {
            "prismatic"
        } else {
            "continuous"
        };
        let rpy = l.orientation.as_ref().map_or([0.0; 3], rpy);
        let axis = l.axis.as_ref().expect("a spatial joint has its axis");
        let _ = writeln!(out, "  <joint name=\"{}\" type=\"{kind}\">", l.name);
        let _ = writeln!(
            out,
            "    <parent link=\"{parent}\"/>\n    <child link=\"{}\"/>\n    <origin xyz=\"{}\" rpy=\"{}\"/>\n    <axis xyz=\"{}\"/>",
            l.name,
            triple(m, &l.origin),
            rpy.map(num).join(" "),
            axis.iter().map(|&a| num(a)).collect::<Vec<_>>().join(" ")
        );
        if kind == "prismatic" {
            // URDF requires limits on a prismatic joint; these never bind.
            let _ = writeln!(
                out,
                "    <limit lower=\"-1000\" upper=\"1000\" effort=\"1e9\" velocity=\"1e9\"/>"
            );
        }
        let _ = writeln!(
            out,
            "    <dynamics damping=\"{}\" friction=\"0\"/>\n  </joint>",
            num(value(&m.params, &l.damping))
        );
    }
    urdf_frames(m, |p| triple(m, &p.point), &mut out);
    urdf_transmissions(m, &mut out);
    let _ = writeln!(out, "</robot>");
    out
}

#[cfg(test)]
mod tests {
    use super::rpy;

    /// The floating URDF is the chart's URDF less the free joint: no `base`, none of the
    /// six joints or their massless links, the body the only link nothing is the child
    /// of, every other link and joint as they were (Pinocchio's free flyer on it is
    /// checked against our dynamics in `cargo xtask test`, urdf_check.py).
    #[test]
    fn a_floating_urdf_has_the_body_as_its_root() {
        let root = crate::gen::workspace_root();
        let spec = crate::gen::load_spec(
            &root,
            &root.join("leg-models/specs/minitaur_quadruped.toml"),
        )
        .unwrap();
        let m = crate::gen::model::build(&spec).unwrap();
        let f = (0..m.links.len()).find(|&i| super::is_free(&m, i)).unwrap();
        let body = &m.links[f + 5].name;
        let (chart, floating) = (super::urdf(&m), super::urdf_floating(&m));
        let names = |text: &str, tag: &str| -> Vec<String> {
            text.lines()
                .filter_map(|l| l.trim().strip_prefix(&format!("<{tag} name=\"")))
                .map(|l| l[..l.find('"').unwrap()].to_string())
                .collect()
        };
        let free: Vec<&String> = m.links[f..f + 6].iter().map(|l| &l.name).collect();
        let chart_links = names(&chart, "link");
        assert!(chart_links.contains(&"base".to_string()));
        let kept: Vec<String> = chart_links
            .into_iter()
            .filter(|n| n == body || (n != "base" && !free.contains(&n)))
            .collect();
        assert_eq!(names(&floating, "link"), kept);
        let joints: Vec<String> = names(&chart, "joint")
            .into_iter()
            .filter(|n| !free.contains(&n))
            .collect();
        assert_eq!(names(&floating, "joint"), joints);
        assert!(!floating.contains("\"base\""));
        let children: Vec<&str> = floating
            .lines()
            .filter_map(|l| l.trim().strip_prefix("<child link=\""))
            .map(|l| &l[..l.find('"').unwrap()])
            .collect();
        let roots: Vec<String> = names(&floating, "link")
            .into_iter()
            .filter(|n| !children.contains(&n.as_str()))
            .collect();
        assert_eq!(roots, vec![body.clone()]);
        // Every link and joint kept is the chart's to the attribute: inertias, parents,
        // placements (origins), axes and damping; the legs still hang from the body.
        let (chart_doc, floating_doc) = (
            roxmltree::Document::parse(&chart).unwrap(),
            roxmltree::Document::parse(&floating).unwrap(),
        );
        let element = |doc: &roxmltree::Document<'_>, tag: &str, name: &str| -> String {
            let node = doc
                .root_element()
                .children()
                .find(|n| n.has_tag_name(tag) && n.attribute("name") == Some(name))
                .unwrap_or_else(|| panic!("no {tag} {name}"));
            node.descendants()
                .filter(|n| n.is_element())
                .map(|n| {
                    let attrs: Vec<String> = n
                        .attributes()
                        .map(|a| format!("{}={}", a.name(), a.value()))
                        .collect();
                    format!("{}[{}]", n.tag_name().name(), attrs.join(" "))
                })
                .collect::<Vec<_>>()
                .join(" ")
        };
        // The robot's own links and joints (a transmission names its joint too).
        let top = |doc: &roxmltree::Document<'_>, tag: &str| -> Vec<String> {
            doc.root_element()
                .children()
                .filter(|n| n.has_tag_name(tag))
                .filter_map(|n| n.attribute("name").map(str::to_string))
                .collect()
        };
        let chart_joints: Vec<String> = top(&chart_doc, "joint")
            .into_iter()
            .filter(|n| !free.contains(&n))
            .collect();
        assert_eq!(top(&floating_doc, "joint"), chart_joints);
        for tag in ["link", "joint"] {
            for name in top(&floating_doc, tag) {
                let kept = element(&floating_doc, tag, &name);
                assert_eq!(kept, element(&chart_doc, tag, &name), "{tag} {name}");
                if tag == "joint" {
                    assert!(
                        kept.contains("origin[xyz="),
                        "joint {name} unplaced: {kept}"
                    );
                }
            }
        }
        // The legs hang from the body as the spec has them: each five-bar's two motor
        // links.
        let from_body: Vec<&str> = floating_doc
            .root_element()
            .children()
            .filter(|n| n.has_tag_name("joint"))
            .filter(|n| {
                n.children()
                    .any(|c| c.has_tag_name("parent") && c.attribute("link") == Some(body))
            })
            .filter_map(|n| n.attribute("name"))
            .collect();
        let motor_links: Vec<&str> = m
            .links
            .iter()
            .filter(|l| l.parent == Some(f + 5))
            .map(|l| l.name.as_str())
            .collect();
        assert_eq!(motor_links.len(), 8, "four five-bars, two motor links each");
        assert_eq!(from_body, motor_links);
    }

    /// `R_z(yaw) R_y(pitch) R_x(roll)` of the angles `rpy` finds gives the matrix back,
    /// at pitch ±90° too (where roll and yaw share an axis).
    #[test]
    fn rpy_composes_back_to_the_rotation() {
        let rot = |axis: usize, a: f64| {
            let (s, c) = a.sin_cos();
            let mut r = [[0.0; 3]; 3];
            let (i, j) = ((axis + 1) % 3, (axis + 2) % 3);
            r[axis][axis] = 1.0;
            r[i][i] = c;
            r[j][j] = c;
            r[i][j] = -s;
            r[j][i] = s;
            r
        };
        let mul = |a: [[f64; 3]; 3], b: [[f64; 3]; 3]| {
            let mut c = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    c[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
                }
            }
            c
        };
        let compose = |a: [f64; 3]| mul(mul(rot(2, a[2]), rot(1, a[1])), rot(0, a[0]));
        let half_pi = std::f64::consts::FRAC_PI_2;
        for (angles, tolerance) in [
            ([0.3, -0.2, 1.1], 1e-12),
            ([-2.0, 1.2, -3.0], 1e-12),
            ([0.4, half_pi, 0.7], 1e-12),
            ([0.4, -half_pi, -0.2], 1e-12),
            // Near the gimbal, on each side of the branch's threshold.
            ([0.4, half_pi - 1e-10, 0.7], 1e-9),
            ([0.3, half_pi - 1e-6, -0.4], 1e-9),
        ] {
            let r = compose(angles);
            let back = compose(rpy(&r));
            for i in 0..3 {
                for j in 0..3 {
                    assert!((r[i][j] - back[i][j]).abs() < tolerance, "{angles:?}");
                }
            }
        }
    }
}
