//! URDF (the ROS robot description) read into the importer's robot, the same one an MJCF
//! file gives ([`super::mjcf::Robot`]).
//!
//! Each `<link>` is a body, placed in its parent link's frame by the `<origin xyz rpy>` of
//! the `<joint>` that carries it. URDF puts a joint's frame at its child link's origin, so
//! the joint's anchor is the child's origin and its `<axis>` is in the child's frame (the
//! default `1 0 0`). `revolute` and `continuous` joints are hinges, `prismatic` ones
//! slides, `fixed` ones weld their child to the parent; `<limit lower upper>` gives a
//! revolute or prismatic joint's range, `<dynamics damping>` its damping. `<inertial>`
//! gives the mass, the centre of mass (`<origin xyz>`) and the six entries of
//! `<inertia>` in the frame `<origin rpy>` turns to; a link without one has no mass. A
//! `<transmission>` makes its joint a motor, its `<mechanicalReduction>` the gear
//! (default 1) and Drake's `<drake:rotor_inertia>`, where given, its rotor inertia. The root link (the one no joint carries) is the base. URDF has no gravity
//! (it is `0 0 −9.81`), no keyframes (the home pose is every joint at 0) and no loops:
//! closures are named on the command line, and so are motors where the file has no
//! transmissions. What a spec cannot represent (`floating` and `planar` joints, joint
//! friction, `<mimic>`) is an error at its line.

use std::collections::HashMap;

use roxmltree::{Document, Node};

use super::linalg::{mat_mul, normalize, rot_axis, Mat3, Vec3, IDENTITY};
use super::mjcf::{Body, Inertial, Joint, JointKind, Located, Motor, Robot};

type Result<T> = std::result::Result<T, Located>;

fn at(node: Node, message: impl Into<String>) -> Located {
    Located {
        line: node.document().text_pos_at(node.range().start).row,
        message: message.into(),
    }
}

fn numbers<const N: usize>(node: Node, attr: &str, default: [f64; N]) -> Result<[f64; N]> {
    let Some(text) = node.attribute(attr) else {
        return Ok(default);
    };
    let values: Vec<f64> = text
        .split_whitespace()
        .map(str::parse::<f64>)
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| at(node, format!("{attr}=\"{text}\": not {N} numbers")))?;
    let values: [f64; N] = values
        .try_into()
        .map_err(|_| at(node, format!("{attr}=\"{text}\": not {N} numbers")))?;
    if values.iter().any(|v| !v.is_finite()) {
        return Err(at(node, format!("{attr}=\"{text}\": not finite")));
    }
    Ok(values)
}

fn number(node: Node, attr: &str) -> Result<Option<f64>> {
    Ok(node
        .attribute(attr)
        .map(|_| numbers::<1>(node, attr, [0.0]))
        .transpose()?
        .map(|[v]| v))
}

fn child<'a, 'i>(node: Node<'a, 'i>, tag: &str) -> Option<Node<'a, 'i>> {
    node.children().find(|c| c.has_tag_name(tag))
}

/// URDF's `rpy`: about the fixed x, then y, then z axes, `R = R_z(y) R_y(p) R_x(r)`.
pub fn rpy_matrix([r, p, y]: [f64; 3]) -> Mat3 {
    mat_mul(
        &rot_axis([0.0, 0.0, 1.0], y),
        &mat_mul(&rot_axis([0.0, 1.0, 0.0], p), &rot_axis([1.0, 0.0, 0.0], r)),
    )
}

/// `<origin xyz rpy>` of `node` (identity where absent).
fn origin(node: Node) -> Result<(Vec3, Mat3)> {
    match child(node, "origin") {
        None => Ok(([0.0; 3], IDENTITY)),
        Some(o) => Ok((
            numbers(o, "xyz", [0.0; 3])?,
            rpy_matrix(numbers(o, "rpy", [0.0; 3])?),
        )),
    }
}

fn inertial(link: Node) -> Result<Option<Inertial>> {
    let Some(i) = child(link, "inertial") else {
        return Ok(None);
    };
    let (com, rot) = origin(i)?;
    let mass = match child(i, "mass") {
        Some(m) => number(m, "value")?.ok_or_else(|| at(m, "<mass> without value"))?,
        None => return Err(at(i, "<inertial> without <mass>")),
    };
    let inertia = match child(i, "inertia") {
        None => [[0.0; 3]; 3],
        Some(n) => {
            let e = |a: &str| number(n, a).map(|v| v.unwrap_or(0.0));
            let (xx, xy, xz, yy, yz, zz) = (
                e("ixx")?,
                e("ixy")?,
                e("ixz")?,
                e("iyy")?,
                e("iyz")?,
                e("izz")?,
            );
            let local = [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]];
            let rt = [
                [rot[0][0], rot[1][0], rot[2][0]],
                [rot[0][1], rot[1][1], rot[2][1]],
                [rot[0][2], rot[1][2], rot[2][2]],
            ];
            mat_mul(&mat_mul(&rot, &local), &rt)
        }
    };
    if mass < 0.0 {
        return Err(at(i, format!("<mass value=\"{mass}\">: negative")));
    }
    Ok(Some(Inertial { mass, com, inertia }))
}

/// The robot of a URDF file: its tree, and its transmissions as motors.
pub fn read(text: &str) -> Result<Robot> {
    let doc = Document::parse(text).map_err(|e| Located {
        line: e.pos().row,
        message: format!("not well-formed XML: {e}"),
    })?;
    let root = doc.root_element();
    if !root.has_tag_name("robot") {
        return Err(at(
            root,
            format!(
                "the root element is <{}>, not <robot>",
                root.tag_name().name()
            ),
        ));
    }
    let links: Vec<Node> = root.children().filter(|c| c.has_tag_name("link")).collect();
    let mut link_index = HashMap::new();
    for (i, l) in links.iter().enumerate() {
        let name = l
            .attribute("name")
            .ok_or_else(|| at(*l, "<link> without a name"))?;
        if link_index.insert(name, i).is_some() {
            return Err(at(*l, format!("link `{name}` is named twice")));
        }
    }
    // The joint that carries each link.
    let mut carrier: Vec<Option<Node>> = vec![None; links.len()];
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); links.len()];
    let mut joint_names = HashMap::new();
    for j in root.children().filter(|c| c.has_tag_name("joint")) {
        let name = j
            .attribute("name")
            .ok_or_else(|| at(j, "<joint> without a name"))?;
        if joint_names.insert(name, j).is_some() {
            return Err(at(j, format!("joint `{name}` is named twice")));
        }
        let end = |tag: &str| -> Result<usize> {
            let n = child(j, tag).ok_or_else(|| at(j, format!("joint `{name}` has no <{tag}>")))?;
            let l = n
                .attribute("link")
                .ok_or_else(|| at(n, format!("<{tag}> without link")))?;
            link_index
                .get(l)
                .copied()
                .ok_or_else(|| at(n, format!("joint `{name}`: no link `{l}`")))
        };
        let (parent, child_link) = (end("parent")?, end("child")?);
        if let Some(other) = carrier[child_link] {
            return Err(at(
                j,
                format!(
                    "joint `{name}`: link `{}` is carried by joint `{}` already (a URDF is a tree; name a loop's closure with --closure)",
                    links[child_link].attribute("name").unwrap_or(""),
                    other.attribute("name").unwrap_or("")
                ),
            ));
        }
        carrier[child_link] = Some(j);
        children[parent].push(child_link);
    }
    let roots: Vec<usize> = (0..links.len()).filter(|&i| carrier[i].is_none()).collect();
    let top = match roots.as_slice() {
        [r] => *r,
        [] => {
            return Err(at(
                root,
                "every link is carried by a joint: the joints make a loop",
            ))
        }
        [_, second, ..] => {
            return Err(at(
                links[*second],
                format!(
                    "link `{}` is carried by no joint, as is the root `{}`: a URDF has one root",
                    links[*second].attribute("name").unwrap_or(""),
                    links[roots[0]].attribute("name").unwrap_or("")
                ),
            ))
        }
    };
    let mut robot = Robot {
        model: root.attribute("name").unwrap_or("urdf").to_string(),
        format: "URDF",
        gravity: [0.0, 0.0, -9.81],
        ..Robot::default()
    };
    // Depth first from the root, parents before children.
    let mut stack = vec![(top, None::<usize>)];
    let mut seen = vec![false; links.len()];
    while let Some((l, parent)) = stack.pop() {
        if std::mem::replace(&mut seen[l], true) {
            return Err(at(links[l], "the joints make a loop"));
        }
        let node = links[l];
        let (pos, rot, joints) = match carrier[l] {
            None => ([0.0; 3], IDENTITY, Vec::new()),
            Some(j) => {
                let (pos, rot) = origin(j)?;
                (pos, rot, read_joint(j)?)
            }
        };
        let index = robot.bodies.len();
        robot.bodies.push(Body {
            name: node.attribute("name").unwrap_or("").to_string(),
            line: node.document().text_pos_at(node.range().start).row,
            parent,
            pos,
            rot,
            joints,
            inertial: inertial(node)?,
            // A URDF link without <inertial> has no mass, drawn or not (as Pinocchio
            // reads it): its geoms give it none.
            has_geoms: false,
        });
        for &c in children[l].iter().rev() {
            stack.push((c, Some(index)));
        }
    }
    if let Some(l) = (0..links.len()).find(|&l| !seen[l]) {
        return Err(at(
            links[l],
            format!(
                "link `{}` is not reached from the root `{}`: its joints make a loop or hang it from no link of the tree",
                links[l].attribute("name").unwrap_or(""),
                links[top].attribute("name").unwrap_or("")
            ),
        ));
    }
    for t in root.children().filter(|c| c.has_tag_name("transmission")) {
        for j in t.children().filter(|c| c.has_tag_name("joint")) {
            let name = j
                .attribute("name")
                .ok_or_else(|| at(j, "<joint> without a name"))?;
            if !joint_names.contains_key(name) {
                return Err(at(j, format!("<transmission>: no joint `{name}`")));
            }
            let reduction = t
                .descendants()
                .find(|d| d.has_tag_name("mechanicalReduction"))
                .map(|r| {
                    r.text()
                        .unwrap_or("")
                        .trim()
                        .parse::<f64>()
                        .ok()
                        .filter(|g| g.is_finite() && *g != 0.0)
                        .ok_or_else(|| at(r, "<mechanicalReduction>: not a nonzero number"))
                })
                .transpose()?
                .unwrap_or(1.0);
            // The rotor inertia Drake's extension gives (our exports write it): MuJoCo's
            // armature, reflected through the gear, as the MJCF path reads it.
            let rotor = t
                .descendants()
                .find(|d| d.tag_name().name() == "rotor_inertia")
                .map(|r| number(r, "value"))
                .transpose()?
                .flatten();
            if let Some(rotor) = rotor {
                if let Some(joint) = robot
                    .bodies
                    .iter_mut()
                    .flat_map(|b| b.joints.iter_mut())
                    .find(|jt| jt.name == name)
                {
                    joint.armature = rotor * reduction * reduction;
                }
            }
            robot.motors.push(Motor {
                line: j.document().text_pos_at(j.range().start).row,
                joint: name.to_string(),
                gear: reduction,
            });
        }
    }
    Ok(robot)
}

fn read_joint(j: Node) -> Result<Vec<Joint>> {
    let name = j.attribute("name").unwrap_or("");
    let kind = match j.attribute("type") {
        Some("fixed") => return Ok(Vec::new()),
        Some("revolute" | "continuous") => JointKind::Hinge,
        Some("prismatic") => JointKind::Slide,
        Some(t @ ("floating" | "planar")) => {
            return Err(at(
                j,
                format!("joint `{name}` is {t}: not representable in a leg's spec (a floating base comes with whole robots)"),
            ))
        }
        Some(t) => return Err(at(j, format!("joint `{name}`: unknown type `{t}`"))),
        None => return Err(at(j, format!("joint `{name}` has no type"))),
    };
    if let Some(m) = child(j, "mimic") {
        return Err(at(m, format!("joint `{name}`: <mimic> couples joints, which a spec cannot hold (write the coupling as a closure)")));
    }
    let axis = match child(j, "axis") {
        None => [1.0, 0.0, 0.0],
        Some(a) => normalize(numbers(a, "xyz", [1.0, 0.0, 0.0])?)
            .ok_or_else(|| at(a, format!("joint `{name}`: a zero axis")))?,
    };
    let range = match (j.attribute("type"), child(j, "limit")) {
        (Some("revolute" | "prismatic"), Some(l)) => {
            let lower = number(l, "lower")?.unwrap_or(0.0);
            let upper = number(l, "upper")?.unwrap_or(0.0);
            (lower < upper).then_some([lower, upper])
        }
        _ => None,
    };
    let mut damping = 0.0;
    if let Some(d) = child(j, "dynamics") {
        damping = number(d, "damping")?.unwrap_or(0.0);
        let friction = number(d, "friction")?.unwrap_or(0.0);
        if friction != 0.0 {
            return Err(at(
                d,
                format!("joint `{name}`: friction {friction} (Coulomb friction in a joint is not representable in a spec; damping is)"),
            ));
        }
    }
    Ok(vec![Joint {
        name: name.to_string(),
        line: j.document().text_pos_at(j.range().start).row,
        kind,
        axis,
        pos: [0.0; 3],
        reference: 0.0,
        range,
        stiffness: 0.0,
        springref: 0.0,
        damping,
        armature: 0.0,
    }])
}
