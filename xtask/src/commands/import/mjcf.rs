//! MJCF (MuJoCo's XML) read into the importer's tree of bodies ([`Robot`]), every number
//! in SI units and radians, every orientation a rotation matrix.
//!
//! Read: `compiler` (`angle`, `eulerseq`), `option/gravity`, `default` classes for joints
//! and motors (`class`, `childclass`), bodies (`pos`; `quat`, `axisangle`, `euler`,
//! `xyaxes`, `zaxis`), their `inertial` (`fullinertia`, or `diaginertia` turned by its
//! orientation), `joint` (`hinge`, `slide`, `ball`, `free`: `axis`, `pos`, `ref`,
//! `range`, `stiffness`, `springref`, `damping`, `armature`), `freejoint`, `site`s,
//! `equality/connect` (by bodies and `anchor`, or by `site1`/`site2`), `actuator/motor`
//! (`joint`, `gear`) and `keyframe/key`. Geoms, cameras, lights, assets, sensors,
//! `contact` and `visual` do not enter the dynamics and are passed over. Anything else
//! that would change the dynamics (tendons, welds and joint couplings, other
//! actuators, `frame`, `include`, composite bodies, a body's inertia left to its geoms)
//! is a located error naming the element.

use std::collections::HashMap;

use roxmltree::{Document, Node};

use super::linalg::{mat_mul, normalize, rot_axis, Mat3, Vec3, IDENTITY};

/// An error at a line of the file.
#[derive(Debug)]
pub struct Located {
    pub line: u32,
    pub message: String,
}

type Result<T> = std::result::Result<T, Located>;

fn at(node: Node, message: impl Into<String>) -> Located {
    let line = node.document().text_pos_at(node.range().start).row;
    Located {
        line,
        message: message.into(),
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum JointKind {
    Hinge,
    Slide,
    Ball,
    Free,
}

#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    pub line: u32,
    pub kind: JointKind,
    /// Unit axis, body frame.
    pub axis: Vec3,
    /// The joint's anchor, body frame.
    pub pos: Vec3,
    /// `ref` (rad or m): the joint's value in the body's pose as written.
    pub reference: f64,
    pub range: Option<[f64; 2]>,
    pub stiffness: f64,
    pub springref: f64,
    pub damping: f64,
    pub armature: f64,
}

#[derive(Clone, Copy, Debug)]
pub struct Inertial {
    pub mass: f64,
    /// Centre of mass, body frame.
    pub com: Vec3,
    /// About the centre of mass, body frame.
    pub inertia: Mat3,
}

#[derive(Clone, Debug)]
pub struct Body {
    pub name: String,
    pub line: u32,
    pub parent: Option<usize>,
    /// The body's frame in its parent's (the world's for a top body).
    pub pos: Vec3,
    pub rot: Mat3,
    pub joints: Vec<Joint>,
    pub inertial: Option<Inertial>,
    /// Whether it has geoms (from which MuJoCo would infer an inertia it lacks).
    pub has_geoms: bool,
}

#[derive(Clone, Debug)]
pub enum Anchor {
    /// A point in a body's frame (`None`: the world).
    Body { body: Option<usize>, point: Vec3 },
}

#[derive(Clone, Debug)]
pub struct Connect {
    pub name: Option<String>,
    pub line: u32,
    pub a: Anchor,
    /// `None`: MuJoCo's rule, the first anchor's place at `qpos0` in body2's frame.
    pub b: Option<Anchor>,
    pub body2: Option<usize>,
    pub active: bool,
}

#[derive(Clone, Debug)]
pub struct Motor {
    pub line: u32,
    pub joint: String,
    pub gear: f64,
}

#[derive(Debug, Default)]
pub struct Robot {
    pub model: String,
    /// `"MJCF"` or `"URDF"`: what the file was.
    pub format: &'static str,
    pub gravity: Vec3,
    pub bodies: Vec<Body>,
    pub connects: Vec<Connect>,
    pub motors: Vec<Motor>,
    /// Keyframes: name → qpos.
    pub keys: Vec<(String, Vec<f64>)>,
    /// Sites: name → (body or world, position in its frame).
    pub sites: HashMap<String, (Option<usize>, Vec3)>,
}

struct Units {
    degrees: bool,
    eulerseq: Vec<char>,
}

impl Units {
    fn angle(&self, x: f64) -> f64 {
        if self.degrees {
            x.to_radians()
        } else {
            x
        }
    }
}

fn numbers(node: Node, attr: &str, text: &str) -> Result<Vec<f64>> {
    text.split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| {
                    at(
                        node,
                        format!(
                            "<{}> {attr}=\"{text}\": `{t}` is not a finite number",
                            node.tag_name().name()
                        ),
                    )
                })
        })
        .collect()
}

fn fixed<const N: usize>(node: Node, attr: &str, text: &str) -> Result<[f64; N]> {
    let v = numbers(node, attr, text)?;
    v.as_slice().try_into().map_err(|_| {
        at(
            node,
            format!(
                "<{}> {attr}=\"{text}\": {} numbers where {N} are expected",
                node.tag_name().name(),
                v.len()
            ),
        )
    })
}

fn vec3(node: Node, attr: &str) -> Result<Option<Vec3>> {
    node.attribute(attr)
        .map(|t| fixed::<3>(node, attr, t))
        .transpose()
}

fn scalar(node: Node, attr: &str) -> Result<Option<f64>> {
    node.attribute(attr)
        .map(|t| fixed::<1>(node, attr, t).map(|v| v[0]))
        .transpose()
}

/// The frame orientation of an element: `quat`, `axisangle`, `euler`, `xyaxes` or `zaxis`.
fn orientation(node: Node, units: &Units) -> Result<Mat3> {
    let given: Vec<&str> = ["quat", "axisangle", "euler", "xyaxes", "zaxis"]
        .into_iter()
        .filter(|a| node.attribute(*a).is_some())
        .collect();
    if given.len() > 1 {
        return Err(at(
            node,
            format!(
                "<{}> has {}: give one orientation",
                node.tag_name().name(),
                given.join(" and ")
            ),
        ));
    }
    let Some(&attr) = given.first() else {
        return Ok(IDENTITY);
    };
    let text = node.attribute(attr).unwrap_or_default();
    let bad = |what: &str| {
        at(
            node,
            format!("<{}> {attr}=\"{text}\": {what}", node.tag_name().name()),
        )
    };
    match attr {
        "quat" => {
            let q = fixed::<4>(node, attr, text)?;
            let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
            if n == 0.0 {
                return Err(bad("a zero quaternion"));
            }
            Ok(super::linalg::quat_to_mat(q.map(|x| x / n)))
        }
        "axisangle" => {
            let v = fixed::<4>(node, attr, text)?;
            let axis = normalize([v[0], v[1], v[2]]).ok_or_else(|| bad("a zero axis"))?;
            Ok(rot_axis(axis, units.angle(v[3])))
        }
        "euler" => {
            let v = fixed::<3>(node, attr, text)?;
            let mut r = IDENTITY;
            for (k, &c) in units.eulerseq.iter().enumerate() {
                let axis = match c.to_ascii_lowercase() {
                    'x' => [1.0, 0.0, 0.0],
                    'y' => [0.0, 1.0, 0.0],
                    _ => [0.0, 0.0, 1.0],
                };
                let turn = rot_axis(axis, units.angle(v[k]));
                // Lower case: axes that turn with the frame (post-multiplied); upper case:
                // the fixed axes (pre-multiplied), as MuJoCo's compiler.
                r = if c.is_ascii_lowercase() {
                    mat_mul(&r, &turn)
                } else {
                    mat_mul(&turn, &r)
                };
            }
            Ok(r)
        }
        "xyaxes" => {
            let v = fixed::<6>(node, attr, text)?;
            let x = normalize([v[0], v[1], v[2]]).ok_or_else(|| bad("a zero x axis"))?;
            let y0 = [v[3], v[4], v[5]];
            let d = super::linalg::dot(x, y0);
            let y = normalize([y0[0] - d * x[0], y0[1] - d * x[1], y0[2] - d * x[2]])
                .ok_or_else(|| bad("the y axis is parallel to the x axis"))?;
            let z = super::linalg::cross(x, y);
            Ok([[x[0], y[0], z[0]], [x[1], y[1], z[1]], [x[2], y[2], z[2]]])
        }
        _ => {
            let v = fixed::<3>(node, attr, text)?;
            let z = normalize(v).ok_or_else(|| bad("a zero axis"))?;
            // The least rotation taking (0, 0, 1) to z.
            let c = z[2];
            let axis = normalize([-z[1], z[0], 0.0]);
            Ok(match axis {
                Some(a) => rot_axis(a, c.clamp(-1.0, 1.0).acos()),
                None if c > 0.0 => IDENTITY,
                None => rot_axis([1.0, 0.0, 0.0], std::f64::consts::PI),
            })
        }
    }
}

/// Attribute name → value.
type Attributes = HashMap<String, String>;

/// Joint and motor attributes of the default classes, by class name (`main` the root).
#[derive(Default)]
struct Defaults {
    /// class → (parent class, joint attributes, motor attributes)
    classes: HashMap<String, (Option<String>, Attributes, Attributes)>,
}

impl Defaults {
    fn read(node: Node, parent: Option<String>, out: &mut Defaults) -> Result<()> {
        let name = node
            .attribute("class")
            .unwrap_or(if parent.is_none() { "main" } else { "" })
            .to_string();
        if name.is_empty() {
            return Err(at(node, "a nested <default> needs a `class`"));
        }
        let mut joint = HashMap::new();
        let mut motor = HashMap::new();
        for child in node.children().filter(Node::is_element) {
            match child.tag_name().name() {
                "joint" => joint.extend(
                    child
                        .attributes()
                        .map(|a| (a.name().to_string(), a.value().to_string())),
                ),
                "motor" => motor.extend(
                    child
                        .attributes()
                        .map(|a| (a.name().to_string(), a.value().to_string())),
                ),
                "default" => Defaults::read(child, Some(name.clone()), out)?,
                "general" | "position" | "velocity" | "tendon" | "equality" | "geom" | "site"
                | "mesh" | "material" | "camera" | "light" | "pair" | "texture" => {}
                _ => {}
            }
        }
        out.classes.insert(name, (parent, joint, motor));
        Ok(())
    }

    /// The attribute `attr` of an element (joint or motor) of class `class`: its own, else
    /// its class's, else that class's parents'.
    fn value<'a>(
        &'a self,
        node: Node<'a, 'a>,
        class: &str,
        attr: &str,
        motor: bool,
    ) -> Option<String> {
        if let Some(v) = node.attribute(attr) {
            return Some(v.to_string());
        }
        let mut c = Some(class.to_string());
        while let Some(name) = c {
            let (parent, joint, motors) = self.classes.get(&name)?;
            let table = if motor { motors } else { joint };
            if let Some(v) = table.get(attr) {
                return Some(v.clone());
            }
            c = parent.clone();
        }
        None
    }
}

/// Reads an MJCF document.
pub fn read(text: &str) -> Result<Robot> {
    let doc = Document::parse(text).map_err(|e| Located {
        line: e.pos().row,
        message: format!("not well-formed XML: {e}"),
    })?;
    let root = doc.root_element();
    if root.tag_name().name() != "mujoco" {
        return Err(at(
            root,
            format!(
                "the root element is <{}>, not <mujoco>",
                root.tag_name().name()
            ),
        ));
    }
    let mut units = Units {
        degrees: true,
        eulerseq: vec!['x', 'y', 'z'],
    };
    let mut robot = Robot {
        model: root.attribute("model").unwrap_or("mjcf").to_string(),
        format: "MJCF",
        gravity: [0.0, 0.0, -9.81],
        ..Robot::default()
    };
    let mut defaults = Defaults::default();
    for section in root.children().filter(Node::is_element) {
        match section.tag_name().name() {
            "compiler" => {
                match section.attribute("angle") {
                    None | Some("degree") => {}
                    Some("radian") => units.degrees = false,
                    Some(other) => {
                        return Err(at(
                            section,
                            format!("<compiler angle=\"{other}\">: degree or radian"),
                        ))
                    }
                }
                if let Some(seq) = section.attribute("eulerseq") {
                    let chars: Vec<char> = seq.chars().collect();
                    if chars.len() != 3 || !chars.iter().all(|c| "xyzXYZ".contains(*c)) {
                        return Err(at(
                            section,
                            format!("<compiler eulerseq=\"{seq}\">: three of x, y, z, X, Y, Z"),
                        ));
                    }
                    units.eulerseq = chars;
                }
                for unsupported in ["inertiafromgeom"] {
                    if section.attribute(unsupported) == Some("true") {
                        return Err(at(
                            section,
                            "<compiler inertiafromgeom=\"true\">: inertias from geoms are not imported (give every moving body an <inertial>)",
                        ));
                    }
                }
            }
            "option" => {
                if let Some(g) = vec3(section, "gravity")? {
                    robot.gravity = g;
                }
            }
            "default" => Defaults::read(section, None, &mut defaults)?,
            "include" => {
                return Err(at(
                    section,
                    "<include> is not followed: import the file with everything in it",
                ))
            }
            "tendon" if section.children().any(|c| c.is_element()) => {
                return Err(at(section, "tendons are not imported (a fixed tendon's spring is a coupling spring in a spec, and a rod between two sites a `distance` closure, both written by hand)"));
            }
            "deformable" | "flexcomp" => {
                return Err(at(
                    section,
                    format!(
                        "<{}> is not representable in a spec",
                        section.tag_name().name()
                    ),
                ))
            }
            _ => {}
        }
    }
    for section in root.children().filter(Node::is_element) {
        if section.tag_name().name() == "worldbody" {
            read_children(section, None, "main", &units, &defaults, &mut robot)?;
        }
    }
    for section in root.children().filter(Node::is_element) {
        match section.tag_name().name() {
            "equality" => read_equality(section, &mut robot)?,
            "actuator" => read_actuators(section, &defaults, &mut robot)?,
            "keyframe" => {
                for key in section.children().filter(Node::is_element) {
                    let name = key.attribute("name").unwrap_or("").to_string();
                    if let Some(q) = key.attribute("qpos") {
                        robot.keys.push((name, numbers(key, "qpos", q)?));
                    }
                }
            }
            _ => {}
        }
    }
    Ok(robot)
}

fn read_children(
    node: Node,
    body: Option<usize>,
    class: &str,
    units: &Units,
    defaults: &Defaults,
    robot: &mut Robot,
) -> Result<()> {
    for child in node.children().filter(Node::is_element) {
        match child.tag_name().name() {
            "body" => read_body(child, body, class, units, defaults, robot)?,
            "site" => {
                if let Some(name) = child.attribute("name") {
                    let pos = vec3(child, "pos")?.unwrap_or([0.0; 3]);
                    robot.sites.insert(name.to_string(), (body, pos));
                }
            }
            "frame" | "replicate" | "composite" | "flexcomp" | "include" | "attach" => {
                return Err(at(
                    child,
                    format!(
                        "<{}> is not read by the importer (expand it into plain bodies first)",
                        child.tag_name().name()
                    ),
                ))
            }
            _ => {}
        }
    }
    Ok(())
}

fn read_body(
    node: Node,
    parent: Option<usize>,
    class: &str,
    units: &Units,
    defaults: &Defaults,
    robot: &mut Robot,
) -> Result<()> {
    let line = node.document().text_pos_at(node.range().start).row;
    let name = node
        .attribute("name")
        .map(str::to_string)
        .unwrap_or_else(|| format!("body{}", robot.bodies.len() + 1));
    let class = node.attribute("childclass").unwrap_or(class).to_string();
    let pos = vec3(node, "pos")?.unwrap_or([0.0; 3]);
    let rot = orientation(node, units)?;
    let mut joints = Vec::new();
    let mut inertial = None;
    let mut has_geoms = false;
    for child in node.children().filter(Node::is_element) {
        match child.tag_name().name() {
            "freejoint" => joints.push(Joint {
                name: child.attribute("name").unwrap_or(&name).to_string(),
                line: child.document().text_pos_at(child.range().start).row,
                kind: JointKind::Free,
                axis: [0.0, 0.0, 1.0],
                pos: [0.0; 3],
                reference: 0.0,
                range: None,
                stiffness: 0.0,
                springref: 0.0,
                damping: 0.0,
                armature: 0.0,
            }),
            "joint" => joints.push(read_joint(child, &name, &class, units, defaults)?),
            "inertial" => {
                let mass =
                    scalar(child, "mass")?.ok_or_else(|| at(child, "<inertial> needs its mass"))?;
                let com = vec3(child, "pos")?.unwrap_or([0.0; 3]);
                let inertia = if let Some(t) = child.attribute("fullinertia") {
                    let v = fixed::<6>(child, "fullinertia", t)?;
                    [[v[0], v[3], v[4]], [v[3], v[1], v[5]], [v[4], v[5], v[2]]]
                } else if let Some(d) = vec3(child, "diaginertia")? {
                    let r = orientation(child, units)?;
                    let diag = [[d[0], 0.0, 0.0], [0.0, d[1], 0.0], [0.0, 0.0, d[2]]];
                    mat_mul(&mat_mul(&r, &diag), &super::linalg::transpose(&r))
                } else {
                    return Err(at(child, "<inertial> needs diaginertia or fullinertia"));
                };
                if mass < 0.0 {
                    return Err(at(
                        child,
                        format!("<inertial> mass {mass}: a mass is not negative"),
                    ));
                }
                inertial = Some(Inertial { mass, com, inertia });
            }
            "geom" => has_geoms = true,
            _ => {}
        }
    }
    robot.bodies.push(Body {
        name,
        line,
        parent,
        pos,
        rot,
        joints,
        inertial,
        has_geoms,
    });
    let me = robot.bodies.len() - 1;
    read_children(node, Some(me), &class, units, defaults, robot)
}

fn read_joint(
    node: Node,
    body: &str,
    class: &str,
    units: &Units,
    defaults: &Defaults,
) -> Result<Joint> {
    let class = node.attribute("class").unwrap_or(class);
    let attr = |a: &str| defaults.value(node, class, a, false);
    let num = |a: &str| -> Result<Option<f64>> {
        attr(a)
            .map(|t| {
                t.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| at(node, format!("<joint> {a}=\"{t}\": not a finite number")))
            })
            .transpose()
    };
    let kind = match attr("type").as_deref().unwrap_or("hinge") {
        "hinge" => JointKind::Hinge,
        "slide" => JointKind::Slide,
        "ball" => JointKind::Ball,
        "free" => JointKind::Free,
        other => {
            return Err(at(
                node,
                format!("<joint type=\"{other}\">: hinge, slide, ball or free"),
            ))
        }
    };
    let angle = |x: f64| {
        if kind == JointKind::Hinge {
            units.angle(x)
        } else {
            x
        }
    };
    let axis = match attr("axis") {
        Some(t) => {
            let v = numbers(node, "axis", &t)?;
            let v: Vec3 = v
                .as_slice()
                .try_into()
                .map_err(|_| at(node, format!("<joint> axis=\"{t}\": three numbers")))?;
            normalize(v).ok_or_else(|| at(node, "<joint> axis is zero"))?
        }
        None => [0.0, 0.0, 1.0],
    };
    let pos = match attr("pos") {
        Some(t) => {
            let v = numbers(node, "pos", &t)?;
            v.as_slice()
                .try_into()
                .map_err(|_| at(node, format!("<joint> pos=\"{t}\": three numbers")))?
        }
        None => [0.0; 3],
    };
    let range = match attr("range") {
        Some(t) => {
            let v = numbers(node, "range", &t)?;
            if v.len() != 2 {
                return Err(at(node, format!("<joint> range=\"{t}\": two numbers")));
            }
            Some([angle(v[0]), angle(v[1])])
        }
        None => None,
    };
    Ok(Joint {
        name: attr("name").unwrap_or_else(|| body.to_string()),
        line: node.document().text_pos_at(node.range().start).row,
        kind,
        axis,
        pos,
        reference: angle(num("ref")?.unwrap_or(0.0)),
        range,
        stiffness: num("stiffness")?.unwrap_or(0.0),
        springref: angle(num("springref")?.unwrap_or(0.0)),
        damping: num("damping")?.unwrap_or(0.0),
        armature: num("armature")?.unwrap_or(0.0),
    })
}

fn body_index(robot: &Robot, node: Node, attr: &str) -> Result<Option<usize>> {
    match node.attribute(attr) {
        None | Some("world") => Ok(None),
        Some(name) => robot
            .bodies
            .iter()
            .position(|b| b.name == name)
            .map(Some)
            .ok_or_else(|| {
                at(
                    node,
                    format!(
                        "<{}> {attr}=\"{name}\": no such body",
                        node.tag_name().name()
                    ),
                )
            }),
    }
}

fn read_equality(section: Node, robot: &mut Robot) -> Result<()> {
    for e in section.children().filter(Node::is_element) {
        let line = e.document().text_pos_at(e.range().start).row;
        let active = e.attribute("active") != Some("false");
        match e.tag_name().name() {
            "connect" => {
                let name = e.attribute("name").map(str::to_string);
                let c = if let (Some(s1), Some(s2)) = (e.attribute("site1"), e.attribute("site2")) {
                    let site = |s: &str| {
                        robot
                            .sites
                            .get(s)
                            .copied()
                            .ok_or_else(|| at(e, format!("<connect> site \"{s}\": no such site")))
                    };
                    let (b1, p1) = site(s1)?;
                    let (b2, p2) = site(s2)?;
                    Connect {
                        name,
                        line,
                        a: Anchor::Body { body: b1, point: p1 },
                        b: Some(Anchor::Body { body: b2, point: p2 }),
                        body2: b2,
                        active,
                    }
                } else {
                    if e.attribute("body1").is_none() {
                        return Err(at(e, "<connect> needs body1 and anchor, or site1 and site2"));
                    }
                    let b1 = body_index(robot, e, "body1")?;
                    let b2 = body_index(robot, e, "body2")?;
                    let anchor = vec3(e, "anchor")?.ok_or_else(|| at(e, "<connect> with body1 needs its anchor"))?;
                    Connect {
                        name,
                        line,
                        a: Anchor::Body { body: b1, point: anchor },
                        b: None,
                        body2: b2,
                        active,
                    }
                };
                robot.connects.push(c);
            }
            other => {
                return Err(at(
                    e,
                    format!("<{other}> equalities are not representable in a spec (only <connect>, a point closure)"),
                ))
            }
        }
    }
    Ok(())
}

fn read_actuators(section: Node, defaults: &Defaults, robot: &mut Robot) -> Result<()> {
    for a in section.children().filter(Node::is_element) {
        let line = a.document().text_pos_at(a.range().start).row;
        match a.tag_name().name() {
            "motor" => {
                let class = a.attribute("class").unwrap_or("main");
                let attr = |n: &str| defaults.value(a, class, n, true);
                let joint = attr("joint").ok_or_else(|| {
                    at(a, "<motor> without joint= (a motor on a tendon, site or body is not representable)")
                })?;
                let gear = match attr("gear") {
                    Some(t) => {
                        let v = numbers(a, "gear", &t)?;
                        if v.iter().skip(1).any(|&g| g != 0.0) {
                            return Err(at(a, format!("<motor> gear=\"{t}\": one gear (a joint's motor)")));
                        }
                        v.first().copied().unwrap_or(1.0)
                    }
                    None => 1.0,
                };
                robot.motors.push(Motor {
                    line,
                    joint,
                    gear,
                });
            }
            other => {
                return Err(at(
                    a,
                    format!("<{other}> actuators are not representable in a spec (a <motor> on a joint is: its torque is the leg's input)"),
                ))
            }
        }
    }
    Ok(())
}
