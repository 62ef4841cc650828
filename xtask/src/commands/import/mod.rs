//! `cargo xtask import FILE --name NAME`: a spatial spec from a MuJoCo MJCF file or a
//! URDF (docs/spec-format.md#importing-mjcf; URDF through `urdf.rs`, its loops and extra
//! motors named on the command line).
//!
//! The tree: every body with one joint is a link; a body without a joint is welded to the
//! link above it (its inertia merged into that link's) or to the base; `--fix-base` holds
//! the body of the file's free joint as the base. Each link's frame sits at its joint's
//! anchor, turned so that the link's coordinate is MuJoCo's `qpos` (a hinge's frame at
//! `q = 0` is the written frame turned back by `ref`, a slide's moved back by it), so
//! `q` maps to MuJoCo by joint name with no offset; a ball joint's three angles are those
//! of its quaternion (`R_x(α) R_y(β) R_z(γ)`). A `connect` is a point closure, its second
//! point by MuJoCo's rule (the first anchor's place in body2's frame at `qpos0`, the pose
//! as written); a motor's joint is actuated, its `armature` the reflected rotor inertia
//! `I·N²` with `N` its `gear`; a joint's `stiffness` is a spring about `springref`.
//! Names become identifiers by [`identifier`]. What the spec cannot represent is an error
//! naming the element and its line, and nothing is written.

mod linalg;
mod mjcf;
mod urdf;

use std::collections::HashMap;
use std::fmt::Write;
use std::path::Path;

use linalg::{rot_axis, scale, sub, xyz_angles, Mat3, Pose, Vec3};
use mjcf::{Anchor, Body, Connect, JointKind, Motor, Robot};

use crate::cli::{self, args::ImportArgs};
use crate::gen::{self, spec};

/// A name of the file as a spec identifier: lower case, every character other than a
/// letter, digit or `_` replaced by `_` (`left-hip-roll` → `left_hip_roll`), `n_` before
/// one that does not start with a letter, `_` after a Rust keyword.
pub fn identifier(name: &str) -> String {
    let mut out: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    if !out.starts_with(|c: char| c.is_ascii_lowercase()) {
        out = format!("n_{out}");
    }
    if spec::check_name(&out).is_err() && out.len() <= 47 {
        out.push('_');
    }
    out
}

fn num(x: f64) -> String {
    // Round-trip decimals; a negative zero written as zero.
    format!("{:?}", if x == 0.0 { 0.0 } else { x })
}

fn triple(v: Vec3) -> String {
    format!("[{}, {}, {}]", num(v[0]), num(v[1]), num(v[2]))
}

/// What the imported leg is, before it is written as a spec.
struct Link {
    name: String,
    source: String,
    parent: Option<usize>,
    kind: JointKind,
    axis: Vec3,
    origin: Vec3,
    orientation: Mat3,
    length: Vec3,
    mass: f64,
    com: Vec3,
    inertia: Mat3,
    damping: f64,
    /// `(rotor inertia, gear)`.
    motor: Option<(f64, f64)>,
    spring: Option<(f64, f64)>,
    range: Option<[f64; 2]>,
    /// The MJCF body.
    body: usize,
}

struct Point {
    link: Option<usize>,
    at: Vec3,
}

struct Imported {
    links: Vec<Link>,
    closures: Vec<(String, Point, Point)>,
    /// `--contact`s: name and point.
    contacts: Vec<(String, Point)>,
    foot: Point,
    gravity: Vec3,
    home: Vec<f64>,
    notes: Vec<String>,
}

fn err(file: &Path, line: u32, message: impl Into<String>) -> cli::Error {
    cli::Error::usage(format!("{}:{line}: {}", file.display(), message.into()))
}

fn body_named(robot: &Robot, name: &str) -> Option<usize> {
    robot.bodies.iter().position(|b| b.name == name)
}

fn quaternion_to_matrix(q: &[f64]) -> Mat3 {
    let n = q.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300);
    linalg::quat_to_mat([q[0] / n, q[1] / n, q[2] / n, q[3] / n])
}

/// The 3 × 3 inertia of several bodies about their common centre of mass, all in one
/// frame: `(mass, com, inertia)`.
fn combined(parts: &[(f64, Vec3, Mat3)]) -> (f64, Vec3, Mat3) {
    let mass: f64 = parts.iter().map(|p| p.0).sum();
    if mass == 0.0 {
        return (0.0, [0.0; 3], [[0.0; 3]; 3]);
    }
    let mut com = [0.0; 3];
    for (m, c, _) in parts {
        com = linalg::add(com, scale(*c, m / mass));
    }
    let mut inertia = [[0.0; 3]; 3];
    for (m, c, i) in parts {
        let d = sub(*c, com);
        let dd = linalg::dot(d, d);
        for r in 0..3 {
            for k in 0..3 {
                let delta = if r == k { 1.0 } else { 0.0 };
                inertia[r][k] += i[r][k] + m * (dd * delta - d[r] * d[k]);
            }
        }
    }
    (mass, com, inertia)
}

fn import(file: &Path, robot: &Robot, args: &ImportArgs) -> Result<Imported, cli::Error> {
    let n = robot.bodies.len();
    let mut notes = Vec::new();
    // Poses of the bodies as written (qpos0), in the world.
    let mut world = vec![Pose::IDENTITY; n];
    for (i, b) in robot.bodies.iter().enumerate() {
        let own = Pose {
            pos: b.pos,
            rot: b.rot,
        };
        world[i] = match b.parent {
            Some(p) => world[p].then(&own),
            None => own,
        };
    }
    // The base: the world, or the body of the free joint held by --fix-base.
    let free: Vec<usize> = (0..n)
        .filter(|&i| {
            robot.bodies[i]
                .joints
                .iter()
                .any(|j| j.kind == JointKind::Free)
        })
        .collect();
    // Without --fix-base, a file whose top body floats is imported as a floating robot:
    // that body becomes the spec's first link, on a free joint.
    let base_body = match (free.as_slice(), args.fix_base) {
        ([], false) => None,
        ([], true) => {
            return Err(cli::Error::usage(format!(
                "--fix-base: {} has no free joint to hold",
                file.display()
            )))
        }
        ([b], _) if robot.bodies[*b].parent.is_none() => Some(*b),
        ([b, ..], true) => {
            return Err(err(
                file,
                robot.bodies[*b].line,
                format!(
                    "body `{}`: --fix-base holds one free body at the top of the tree",
                    robot.bodies[*b].name
                ),
            ))
        }
        ([b, ..], false) => {
            let j = robot.bodies[*b]
                .joints
                .iter()
                .find(|j| j.kind == JointKind::Free)
                .expect("free");
            return Err(err(
                file,
                j.line,
                format!(
                    "body `{}`: a robot floats on one free joint, at the top of the tree (this one is below another body, or there are several)",
                    robot.bodies[*b].name
                ),
            ));
        }
    };
    let floating = base_body.is_some() && !args.fix_base;
    if floating && args.root.is_some() {
        return Err(cli::Error::usage(format!(
            "--root: {} floats (its top body has a free joint): import one leg with --fix-base --root, or the whole robot without --root",
            file.display()
        )));
    }
    if let (true, Some(b)) = (floating, base_body) {
        let j = &robot.bodies[b].joints[0];
        if robot.bodies[b].joints.len() > 1 || j.pos != [0.0; 3] || j.damping != 0.0 {
            return Err(err(
                file,
                j.line,
                format!(
                    "body `{}`: a floating robot's free joint is its body's only joint, at its frame's origin, undamped",
                    robot.bodies[b].name
                ),
            ));
        }
    }
    let base = base_body.map_or(Pose::IDENTITY, |b| world[b]);
    // Which bodies move (one joint), which are welded to the base, which to a link.
    #[derive(Clone, Copy, PartialEq)]
    enum Role {
        Base,
        Link,
        WeldedTo(usize),
    }
    let mut role = vec![Role::Base; n];
    for (i, b) in robot.bodies.iter().enumerate() {
        if Some(i) == base_body {
            // A floating robot's body is its first link; a held one is the base.
            if floating {
                role[i] = Role::Link;
            }
            continue;
        }
        let parent_role = b.parent.map_or(Role::Base, |p| role[p]);
        role[i] = match b.joints.len() {
            0 => match parent_role {
                Role::Base => Role::Base,
                Role::Link => Role::WeldedTo(b.parent.expect("a link above")),
                Role::WeldedTo(k) => Role::WeldedTo(k),
            },
            1 if b.joints[0].kind == JointKind::Free => {
                return Err(err(
                    file,
                    b.joints[0].line,
                    format!(
                        "body `{}`: a free joint below the base (a robot floats on one, at the top of the tree)",
                        b.name
                    ),
                ))
            }
            1 => Role::Link,
            k => {
                return Err(err(
                    file,
                    b.joints[1].line,
                    format!(
                    "body `{}` has {k} joints: a spec's link has one (split the body into a chain)",
                    b.name
                ),
                ))
            }
        };
    }
    // --root: one subtree (a leg of a robot).
    let mut kept: Vec<bool> = role.iter().map(|r| *r == Role::Link).collect();
    if let Some(root) = &args.root {
        let r = body_named(robot, root).ok_or_else(|| {
            cli::Error::usage(format!(
                "--root {}: no body of that name in {}",
                spec::shown(root),
                file.display()
            ))
        })?;
        if role[r] != Role::Link
            || robot.bodies[r]
                .parent
                .is_some_and(|p| role[p] != Role::Base)
        {
            return Err(cli::Error::usage(format!(
                "--root {root}: a body with a joint hanging from the base (or from a body welded to it)"
            )));
        }
        for (i, keep) in kept.iter_mut().enumerate() {
            let mut k = Some(i);
            let mut under = false;
            while let Some(x) = k {
                if x == r {
                    under = true;
                    break;
                }
                k = robot.bodies[x].parent;
            }
            *keep = *keep && under;
        }
    }
    // The link that owns each body (itself, or the link it is welded to); None: the base.
    let owner = |i: usize| -> Option<usize> {
        match role[i] {
            Role::Link => Some(i),
            Role::WeldedTo(k) => Some(k),
            Role::Base => None,
        }
    };
    let order: Vec<usize> = (0..n).filter(|&i| kept[i]).collect();
    let link_of: HashMap<usize, usize> = order.iter().enumerate().map(|(k, &b)| (b, k)).collect();
    // A link's frame as written (q = qpos0): the body's frame moved to the joint's anchor.
    let written = |b: usize| -> Pose {
        let j = &robot.bodies[b].joints[0];
        world[b].then(&Pose {
            pos: j.pos,
            rot: linalg::IDENTITY,
        })
    };
    let mut names: HashMap<String, String> = HashMap::new();
    let mut name_of = |source: &str, line: u32| -> Result<String, cli::Error> {
        let id = identifier(source);
        spec::check_name(&id)
            .map_err(|m| err(file, line, format!("name `{source}` → `{id}`: {m}")))?;
        if let Some(first) = names.get(&id) {
            if first != source {
                return Err(err(
                    file,
                    line,
                    format!("`{source}` and `{first}` both become `{id}`: rename one"),
                ));
            }
        }
        names.insert(id.clone(), source.to_string());
        Ok(id)
    };
    // Points of a body (its frame) in the frame of the link that owns it, or the base's.
    let to_link = |body: Option<usize>, x: Vec3| -> Point {
        let world_x = body.map_or(x, |b| world[b].apply(x));
        match body.and_then(owner).filter(|k| kept[*k]) {
            Some(k) => Point {
                link: Some(link_of[&k]),
                at: written(k).inverse().apply(world_x),
            },
            None => Point {
                link: None,
                at: base.inverse().apply(world_x),
            },
        }
    };
    let mut links: Vec<Link> = Vec::new();
    for &b in &order {
        let body: &Body = &robot.bodies[b];
        let j = &body.joints[0];
        // Named for its joint: the coordinate is that joint's qpos.
        let name = name_of(&j.name, j.line)?;
        let parent_body = body.parent.and_then(owner);
        let parent_pose = match parent_body {
            Some(p) if kept[p] => written(p),
            Some(_) => unreachable!("a kept link's parent link is kept"),
            None => base,
        };
        // At q = 0: the written frame turned back by `ref` (hinge) or moved back (slide).
        let back = match j.kind {
            JointKind::Hinge => Pose {
                pos: [0.0; 3],
                rot: rot_axis(j.axis, -j.reference),
            },
            JointKind::Slide => Pose {
                pos: scale(j.axis, -j.reference),
                rot: linalg::IDENTITY,
            },
            _ => Pose::IDENTITY,
        };
        if j.kind == JointKind::Ball && j.stiffness != 0.0 {
            return Err(err(file, j.line, format!("joint `{}`: a ball joint's spring is not representable (a spring acts on one coordinate)", j.name)));
        }
        let rel = parent_pose.inverse().then(&written(b).then(&back));
        // The link's inertia: its body's and every body welded to it, in the link frame.
        let mut parts = Vec::new();
        for (w, wb) in robot.bodies.iter().enumerate() {
            if owner(w) != Some(b) {
                continue;
            }
            match wb.inertial {
                Some(inr) => {
                    let pose = written(b).inverse().then(&world[w]);
                    let rot = pose.rot;
                    let i = linalg::mat_mul(&linalg::mat_mul(&rot, &inr.inertia), &linalg::transpose(&rot));
                    parts.push((inr.mass, pose.apply(inr.com), i));
                }
                None if wb.has_geoms => {
                    return Err(err(
                        file,
                        wb.line,
                        format!("body `{}` has no <inertial>: its inertia would come from its geoms, which the importer does not compute (give it an <inertial>)", wb.name),
                    ))
                }
                None => {}
            }
        }
        let (mass, com, inertia) = combined(&parts);
        if j.kind == JointKind::Ball && j.damping != 0.0 {
            // MuJoCo damps a ball joint's angular velocity ω = E q̇ (a force Eᵀ b E q̇ on
            // the angles); a spec damps each angle. Equal where E is a rotation (β = 0).
            notes.push(format!(
                "ball joint `{}`: damping {} acts on each of its angles' rates, MuJoCo's on its angular velocity; the two agree where its second angle is 0",
                j.name,
                num(j.damping)
            ));
        }
        links.push(Link {
            name,
            source: body.name.clone(),
            parent: parent_body.map(|p| link_of[&p]),
            kind: j.kind,
            axis: j.axis,
            origin: rel.pos,
            orientation: rel.rot,
            length: [0.0; 3],
            mass,
            com,
            inertia,
            damping: j.damping,
            motor: None,
            spring: (j.stiffness != 0.0).then_some((j.stiffness, j.springref)),
            range: j.range,
            body: b,
        });
    }
    // Motors.
    for m in &robot.motors {
        let found = order
            .iter()
            .position(|&b| robot.bodies[b].joints[0].name == m.joint);
        let Some(k) = found else {
            let anywhere = robot
                .bodies
                .iter()
                .any(|b| b.joints.iter().any(|j| j.name == m.joint));
            if anywhere {
                notes.push(format!(
                    "motor on `{}` left out: its joint is outside --root",
                    m.joint
                ));
                continue;
            }
            return Err(err(
                file,
                m.line,
                format!("<motor joint=\"{}\">: no such joint", m.joint),
            ));
        };
        let j = &robot.bodies[links[k].body].joints[0];
        if j.kind == JointKind::Ball {
            return Err(err(file, m.line, format!("<motor joint=\"{}\">: a motor on a ball joint is not representable (a motor drives one axis)", m.joint)));
        }
        if m.gear.is_nan() || m.gear <= 0.0 {
            return Err(err(
                file,
                m.line,
                format!(
                    "<motor joint=\"{}\"> gear {}: a gear ratio is positive",
                    m.joint, m.gear
                ),
            ));
        }
        if links[k].motor.is_some() {
            return Err(err(
                file,
                m.line,
                format!("joint `{}` has two motors: a spec's joint has one", m.joint),
            ));
        }
        links[k].motor = Some((j.armature / (m.gear * m.gear), m.gear));
    }
    for l in &links {
        let j = &robot.bodies[l.body].joints[0];
        if j.armature != 0.0 && l.motor.is_none() {
            return Err(err(file, j.line, format!("joint `{}`: armature on a joint without a motor is not representable (the spec's rotor inertia belongs to a motor)", j.name)));
        }
    }
    if links.iter().all(|l| l.motor.is_none()) {
        return Err(cli::Error::usage(format!(
            "{}: no <motor> drives a joint of the imported leg: a leg needs at least one motor",
            file.display()
        )));
    }
    // Closures.
    let mut closures = Vec::new();
    for (k, c) in robot.connects.iter().enumerate() {
        let Anchor::Body {
            body: b1,
            point: p1,
        } = c.a.clone();
        let (b2, p2) = match &c.b {
            Some(Anchor::Body { body, point }) => (*body, *point),
            None => {
                // MuJoCo's rule: the first anchor's place at qpos0, in body2's frame.
                let w = b1.map_or(p1, |b| world[b].apply(p1));
                (c.body2, c.body2.map_or(w, |b| world[b].inverse().apply(w)))
            }
        };
        let inside = |b: Option<usize>| b.and_then(owner).is_none_or(|o| kept[o]);
        let label = c.name.clone().unwrap_or_else(|| {
            let name =
                |b: Option<usize>| b.map_or("world".to_string(), |b| robot.bodies[b].name.clone());
            format!("{}_{}", name(b1), name(b2))
        });
        if !c.active {
            notes.push(format!(
                "connect `{label}` (line {}) left out: it is inactive",
                c.line
            ));
            continue;
        }
        if !inside(b1) || !inside(b2) {
            notes.push(format!(
                "connect `{label}` (line {}) left out: it reaches outside --root",
                c.line
            ));
            continue;
        }
        let (a, b) = (to_link(b1, p1), to_link(b2, p2));
        if a.link.is_none() && b.link.is_none() {
            notes.push(format!(
                "connect `{label}` (line {}) left out: both ends are on the base",
                c.line
            ));
            continue;
        }
        let mut name = name_of(&label, c.line)?;
        if closures
            .iter()
            .any(|(n, _, _): &(String, Point, Point)| *n == name)
        {
            name = format!("{name}_{k}");
        }
        closures.push((name, a, b));
    }
    // Lengths (drawn, and the tips the runtime scales its tolerances with): the first
    // child's joint, else a closure point or the foot on the link, else twice the
    // centre of mass.
    let foot_body = body_named(robot, &args.foot).ok_or_else(|| {
        cli::Error::usage(format!(
            "--foot {}: no body of that name in {}",
            spec::shown(&args.foot),
            file.display()
        ))
    })?;
    let foot_point = match &args.foot_point {
        None => [0.0; 3],
        Some(t) => {
            let v = cli::numbers("--foot-point", t, 3, "x, y, z in the foot body's frame (m)")?;
            [v[0], v[1], v[2]]
        }
    };
    let foot = to_link(Some(foot_body), foot_point);
    if foot.link.is_none() {
        return Err(cli::Error::usage(format!(
            "--foot {}: that body does not move with the imported leg",
            args.foot
        )));
    }
    for k in 0..links.len() {
        let child = links.iter().find(|l| l.parent == Some(k)).map(|l| l.origin);
        let point = closures
            .iter()
            .flat_map(|(_, a, b)| [a, b])
            .chain([&foot])
            .find(|p| p.link == Some(k))
            .map(|p| p.at);
        links[k].length = child.or(point).unwrap_or(scale(links[k].com, 2.0));
    }
    // Home: qpos0 (the pose as written, where MuJoCo's rule closes every connect), or a key.
    let mut home = Vec::new();
    let key = match &args.keyframe {
        None => None,
        Some(k) => Some(
            robot
                .keys
                .iter()
                .find(|(n, _)| n == k)
                .map(|(_, q)| q)
                .ok_or_else(|| {
                    cli::Error::usage(format!(
                        "--keyframe {}: no key of that name",
                        spec::shown(k)
                    ))
                })?,
        ),
    };
    let mut address = HashMap::new();
    let mut next = 0;
    for b in &robot.bodies {
        for j in &b.joints {
            address.insert(j.name.clone(), next);
            next += match j.kind {
                JointKind::Free => 7,
                JointKind::Ball => 4,
                _ => 1,
            };
        }
    }
    if let Some(q) = key {
        if q.len() != next {
            return Err(cli::Error::usage(format!(
                "--keyframe {}: its qpos has {} values for the file's {next}",
                args.keyframe.as_deref().unwrap_or_default(),
                q.len()
            )));
        }
    }
    for l in &links {
        let j = &robot.bodies[l.body].joints[0];
        let a = address[&j.name];
        match (j.kind, key) {
            // The chart's centre: the body's pose is the state, not a coordinate.
            (JointKind::Free, _) => home.extend([0.0; 6]),
            (JointKind::Ball, Some(q)) => {
                home.extend(xyz_angles(&quaternion_to_matrix(&q[a..a + 4])))
            }
            (JointKind::Ball, None) => home.extend([0.0; 3]),
            (_, Some(q)) => home.push(q[a]),
            (_, None) => home.push(j.reference),
        }
    }
    // A floating robot's spec holds the world's gravity (the runtime turns it into the
    // body's chart); a held base's, gravity in the base frame.
    let gravity = if floating {
        robot.gravity
    } else {
        linalg::mat_vec(&linalg::transpose(&base.rot), robot.gravity)
    };
    if floating {
        let pose = match key {
            Some(q) => {
                let a = address[&robot.bodies[base_body.expect("floating")].joints[0].name];
                q[a..a + 7].to_vec()
            }
            None => {
                let r = crate::commands::export::spatial::quaternion(&base.rot);
                vec![
                    base.pos[0],
                    base.pos[1],
                    base.pos[2],
                    r[0],
                    r[1],
                    r[2],
                    r[3],
                ]
            }
        };
        notes.push(format!(
            "`{}` floats: its pose ({}) is the robot's state in leg_models::robot (position, then quaternion w x y z), not a coordinate; home's first six values are the chart's centre",
            robot.bodies[base_body.expect("floating")].name,
            pose.iter().map(|&x| num(x)).collect::<Vec<_>>().join(", ")
        ));
    }
    // Contacts named on the command line.
    let mut contacts = Vec::new();
    for given in &args.contact {
        let bad = |why: &str| {
            cli::Error::usage(format!(
                "--contact {}: {why} (expected NAME=BODY:X,Y,Z, the point in BODY's frame)",
                spec::shown(given)
            ))
        };
        let (name, rest) = given.split_once('=').ok_or_else(|| bad("no `=`"))?;
        let (body, point) = rest
            .split_once(':')
            .ok_or_else(|| bad("no `:` before the point"))?;
        spec::check_name(name).map_err(|m| bad(&m))?;
        let b = body_named(robot, body).ok_or_else(|| bad(&format!("no body `{body}`")))?;
        let v = cli::numbers("--contact", point, 3, "x, y, z in the body's frame (m)")?;
        let at = to_link(Some(b), [v[0], v[1], v[2]]);
        if at.link.is_none() {
            return Err(bad("that body does not move with the imported leg"));
        }
        contacts.push((name.to_string(), at));
    }
    Ok(Imported {
        links,
        closures,
        contacts,
        foot,
        gravity,
        home,
        notes,
    })
}

/// `file` from `dir`, both absolute, where it lies below `dir` (`a/b.xml`) or beside it,
/// under `dir`'s parent (`../x/b.xml`: a clone such as Menagerie's next to this one);
/// `None` elsewhere, so that no other path of this machine goes into a spec.
fn relative_to(file: &Path, dir: &Path) -> Option<String> {
    let (f, d): (Vec<_>, Vec<_>) = (file.components().collect(), dir.components().collect());
    let common = f.iter().zip(&d).take_while(|(a, b)| a == b).count();
    let up = d.len() - common;
    if up > 1 || common == 0 {
        return None;
    }
    let mut parts: Vec<String> = vec!["..".into(); up];
    parts.extend(
        f[common..]
            .iter()
            .map(|c| c.as_os_str().to_string_lossy().into_owned()),
    );
    Some(parts.join("/"))
}

/// Whether a spec header's source (as [`header_args`] resolves it) lies outside the
/// repository (`../…`): such a file is checked where it is present and its absence is
/// said, not failed; a file in the repository must be there.
pub fn outside_repository(root: &Path, file: &Path) -> bool {
    file.strip_prefix(root)
        .map_or(true, |r| r.starts_with(".."))
}

/// The command that imports with these arguments, for the spec's header: the file by its
/// path from the repository's root where it lies in it or beside it, else by its name
/// alone.
fn command_line(root: &Path, a: &ImportArgs) -> String {
    let file = std::fs::canonicalize(&a.file)
        .ok()
        .and_then(|f| relative_to(&f, &std::fs::canonicalize(root).ok()?))
        .unwrap_or_else(|| {
            a.file
                .file_name()
                .map_or(String::new(), |f| f.to_string_lossy().into_owned())
        });
    let mut c = format!("cargo xtask import {file} --name {}", a.name);
    if a.fix_base {
        c.push_str(" --fix-base");
    }
    if let Some(r) = &a.root {
        let _ = write!(c, " --root {r}");
    }
    let _ = write!(c, " --foot {}", a.foot);
    if let Some(p) = &a.foot_point {
        let _ = write!(c, " --foot-point {p}");
    }
    if let Some(k) = &a.keyframe {
        let _ = write!(c, " --keyframe {k}");
    }
    if let Some(h) = &a.home {
        let _ = write!(c, " --home {h}");
    }
    for closure in &a.closure {
        let _ = write!(c, " --closure {closure}");
    }
    for motor in &a.motor {
        let _ = write!(c, " --motor {motor}");
    }
    for contact in &a.contact {
        let _ = write!(c, " --contact {contact}");
    }
    c
}

fn write_spec(file: &Path, command: &str, robot: &Robot, leg: &Imported) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "# Imported by `{command}`");
    let _ = writeln!(
        out,
        "# from `{}` (model \"{}\"). A link's frame is at its joint's anchor and its coordinate is\n# {} of the same joint (a ball joint: the angles of R_x R_y R_z of its quaternion).",
        file.file_name().map_or(String::new(), |f| f.to_string_lossy().into_owned()),
        robot.model.replace('\n', " "),
        if robot.format == "URDF" {
            "the URDF's position"
        } else {
            "MuJoCo's qpos"
        }
    );
    for n in &leg.notes {
        let _ = writeln!(out, "# Note: {n}");
    }
    let _ = writeln!(
        out,
        "description = \"{}, imported from {}\"",
        robot
            .model
            .chars()
            .filter(|c| c.is_ascii_alphanumeric() || " -_.".contains(*c))
            .collect::<String>(),
        robot.format
    );
    let _ = writeln!(out, "gravity = {}", triple(leg.gravity));
    let _ = writeln!(
        out,
        "home = [{}]",
        leg.home
            .iter()
            .map(|&x| num(x))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for l in &leg.links {
        let joint = &robot.bodies[l.body].joints[0].name;
        let _ = writeln!(
            out,
            "\n[[links]]\n# MJCF body `{}`, joint `{joint}`",
            l.source
        );
        if let Some([lo, hi]) = l.range {
            let _ = writeln!(
                out,
                "# MJCF range [{}, {}] (rad or m) not imported: the spec has no joint limits",
                num(lo),
                num(hi)
            );
        }
        let _ = writeln!(out, "name = \"{}\"", l.name);
        let parent = l
            .parent
            .map_or("base".to_string(), |p| leg.links[p].name.clone());
        let _ = writeln!(out, "parent = \"{parent}\"");
        if l.kind == JointKind::Free {
            // Its frame is the base frame: no origin or orientation.
            let _ = writeln!(out, "joint = \"free\"");
        }
        match l.kind {
            JointKind::Free => {}
            JointKind::Ball => {
                let _ = writeln!(out, "joint = \"ball\"");
            }
            JointKind::Slide => {
                let _ = writeln!(out, "joint = \"prismatic\"\naxis = {}", triple(l.axis));
            }
            _ => {
                let _ = writeln!(out, "axis = {}", triple(l.axis));
            }
        }
        if l.kind != JointKind::Free {
            let _ = writeln!(out, "origin = {}", triple(l.origin));
        }
        if l.orientation != linalg::IDENTITY && l.kind != JointKind::Free {
            let q = crate::commands::export::spatial::quaternion(&l.orientation);
            let _ = writeln!(
                out,
                "orientation = [{}, {}, {}, {}]",
                num(q[0]),
                num(q[1]),
                num(q[2]),
                num(q[3])
            );
        }
        let _ = writeln!(out, "length = {}", triple(l.length));
        let _ = writeln!(out, "mass = {}", num(l.mass));
        let _ = writeln!(out, "com = {}", triple(l.com));
        let i = &l.inertia;
        let _ = writeln!(
            out,
            "inertia = [{}, {}, {}, {}, {}, {}]",
            num(i[0][0]),
            num(i[1][1]),
            num(i[2][2]),
            num(i[0][1]),
            num(i[0][2]),
            num(i[1][2])
        );
        if l.damping != 0.0 {
            let _ = writeln!(out, "damping = {}", num(l.damping));
        }
        if let Some((rotor, gear)) = l.motor {
            let _ = writeln!(
                out,
                "actuator = {{ rotor_inertia = {}, gear_ratio = {} }}",
                num(rotor),
                num(gear)
            );
        }
    }
    for (name, a, b) in &leg.closures {
        let point = |p: &Point| {
            let link = p
                .link
                .map_or("base".to_string(), |k| leg.links[k].name.clone());
            format!("{{ link = \"{link}\", point = {} }}", triple(p.at))
        };
        let _ = writeln!(
            out,
            "\n[[closures]]\nname = \"{name}\"\na = {}\nb = {}",
            point(a),
            point(b)
        );
    }
    for l in &leg.links {
        if let Some((k, rest)) = l.spring {
            let _ = writeln!(
                out,
                "\n[[springs]]\nname = \"{}_spring\"\na = \"{}\"\nstiffness = {}\nrest = {}",
                l.name,
                l.name,
                num(k),
                num(rest)
            );
        }
    }
    let foot = leg.links[leg.foot.link.expect("checked")].name.clone();
    let _ = writeln!(
        out,
        "\n[foot]\nlink = \"{foot}\"\npoint = {}",
        triple(leg.foot.at)
    );
    for (name, p) in &leg.contacts {
        let link = &leg.links[p.link.expect("checked")].name;
        let _ = writeln!(
            out,
            "\n[[contacts]]\nname = \"{name}\"\nlink = \"{link}\"\npoint = {}\nfriction = 1.0",
            triple(p.at)
        );
    }
    out
}

/// The spec that importing `args.file` gives, and the lines to print about it; nothing
/// is written.
fn import_text(root: &Path, args: &ImportArgs) -> Result<(String, Vec<String>), cli::Error> {
    let text = std::fs::read_to_string(&args.file)
        .map_err(|e| cli::Error::usage(format!("cannot read {}: {e}", args.file.display())))?;
    let command = command_line(root, args);
    import_str(&args.file, &text, args, &command)
}

fn import_str(
    file: &Path,
    text: &str,
    args: &ImportArgs,
    command: &str,
) -> Result<(String, Vec<String>), cli::Error> {
    spec::check_name(&args.name).map_err(|m| cli::Error::usage(format!("--name: {m}")))?;
    let robot = if text.contains("<mujoco") {
        for (given, flag) in [
            (!args.closure.is_empty(), "--closure"),
            (!args.motor.is_empty(), "--motor"),
        ] {
            if given {
                return Err(cli::Error::usage(format!(
                    "{flag}: {} is MJCF, which names its closures (<connect>) and motors (<motor>) itself; {flag} is for URDF",
                    file.display()
                )));
            }
        }
        mjcf::read(text).map_err(|e| err(file, e.line, e.message))?
    } else if text.contains("<robot") {
        for (given, flag, why) in [
            (
                args.fix_base,
                "--fix-base",
                "a URDF's root link is the base already",
            ),
            (
                args.keyframe.is_some(),
                "--keyframe",
                "a URDF has no keyframes (the home pose is every joint at 0)",
            ),
        ] {
            if given {
                return Err(cli::Error::usage(format!("{flag}: {why}")));
            }
        }
        let mut robot = urdf::read(text).map_err(|e| err(file, e.line, e.message))?;
        add_closures_and_motors(&mut robot, args)?;
        robot
    } else {
        return Err(cli::Error::usage(format!(
            "{}: neither MJCF (no <mujoco> element) nor URDF (no <robot>)",
            file.display()
        )));
    };
    let mut leg = import(file, &robot, args)?;
    if let Some(home) = &args.home {
        if args.keyframe.is_some() {
            return Err(cli::Error::usage(
                "--home and --keyframe: give the home pose one way".to_string(),
            ));
        }
        let values: Vec<f64> = home
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .ok()
            .filter(|v: &Vec<f64>| v.iter().all(|x| x.is_finite()))
            .ok_or_else(|| {
                cli::Error::usage(format!("--home {home}: not numbers separated by commas"))
            })?;
        if values.len() != leg.home.len() {
            return Err(cli::Error::usage(format!(
                "--home {home}: {} values for the leg's {} coordinates",
                values.len(),
                leg.home.len()
            )));
        }
        leg.home = values;
    }
    let spec_text = write_spec(file, command, &robot, &leg);
    // The spec must be one `gen` takes: checked before anything is written.
    let checked = spec::Spec::parse(Path::new(&format!("{}.toml", args.name)), spec_text.clone())
        .map_err(|e| e.to_string())
        .and_then(|s| gen::model::build(&s).map(|_| ()).map_err(|e| e.to_string()));
    if let Err(e) = checked {
        return Err(cli::Error::Failed(format!(
            "the imported spec does not validate: {e}"
        )));
    }
    let motors = leg.links.iter().filter(|l| l.motor.is_some()).count();
    let coordinates: usize = leg
        .links
        .iter()
        .map(|l| match l.kind {
            JointKind::Ball => 3,
            JointKind::Free => 6,
            _ => 1,
        })
        .sum();
    let mut lines = vec![format!(
        "{} links ({coordinates} coordinates), {} closures, {motors} motors",
        leg.links.len(),
        leg.closures.len()
    )];
    lines.extend(leg.notes.iter().map(|n| format!("note: {n}")));
    Ok((spec_text, lines))
}

/// A URDF's closures and extra motors, from the command line (`--closure`, `--motor`).
fn add_closures_and_motors(robot: &mut Robot, args: &ImportArgs) -> Result<(), cli::Error> {
    let usage =
        |flag: &str, given: &str, why: String| cli::Error::usage(format!("{flag} {given}: {why}"));
    let body = |robot: &Robot, flag: &str, given: &str, name: &str| {
        body_named(robot, name).ok_or_else(|| usage(flag, given, format!("no link `{name}`")))
    };
    let point = |flag: &str, given: &str, text: Option<&str>| -> Result<Option<Vec3>, cli::Error> {
        let Some(text) = text else { return Ok(None) };
        let v: Vec<f64> = text
            .split(',')
            .map(|x| x.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|_| usage(flag, given, format!("`{text}` is not x,y,z in m")))?;
        match v.as_slice() {
            [x, y, z] if v.iter().all(|c| c.is_finite()) => Ok(Some([*x, *y, *z])),
            _ => Err(usage(flag, given, format!("`{text}` is not x,y,z in m"))),
        }
    };
    let mut names = Vec::new();
    for given in &args.closure {
        let flag = "--closure";
        let (name, ends) = given
            .split_once('=')
            .ok_or_else(|| usage(flag, given, "not NAME=LINK_A[:X,Y,Z]/LINK_B[:X,Y,Z]".into()))?;
        let (a, b) = ends
            .split_once('/')
            .ok_or_else(|| usage(flag, given, "not NAME=LINK_A[:X,Y,Z]/LINK_B[:X,Y,Z]".into()))?;
        if name.is_empty() || names.contains(&name) {
            return Err(usage(
                flag,
                given,
                format!("the closure's name `{name}` is empty or given twice"),
            ));
        }
        names.push(name);
        let split = |end: &str| match end.split_once(':') {
            Some((link, at)) => (link.to_string(), Some(at.to_string())),
            None => (end.to_string(), None),
        };
        let ((la, pa), (lb, pb)) = (split(a), split(b));
        let (ba, bb) = (
            body(robot, flag, given, &la)?,
            body(robot, flag, given, &lb)?,
        );
        if ba == bb {
            return Err(usage(
                flag,
                given,
                "a closure joins two different links".into(),
            ));
        }
        let pa = point(flag, given, pa.as_deref())?.unwrap_or([0.0; 3]);
        let pb = point(flag, given, pb.as_deref())?;
        robot.connects.push(Connect {
            name: Some(name.to_string()),
            line: 0,
            a: Anchor::Body {
                body: Some(ba),
                point: pa,
            },
            b: pb.map(|point| Anchor::Body {
                body: Some(bb),
                point,
            }),
            body2: Some(bb),
            active: true,
        });
    }
    for given in &args.motor {
        let flag = "--motor";
        let (joint, gear) = match given.split_once(':') {
            Some((j, g)) => (
                j,
                g.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|g| g.is_finite() && *g != 0.0)
                    .ok_or_else(|| {
                        usage(flag, given, format!("gear `{g}` is not a nonzero number"))
                    })?,
            ),
            None => (given.as_str(), 1.0),
        };
        let moving = robot
            .bodies
            .iter()
            .flat_map(|b| &b.joints)
            .any(|j| j.name == joint);
        if !moving {
            return Err(usage(
                flag,
                given,
                format!("no revolute, continuous or prismatic joint `{joint}`"),
            ));
        }
        if robot.motors.iter().any(|m| m.joint == joint) {
            return Err(usage(flag, given, format!("joint `{joint}` has a motor already (its <transmission> or an earlier --motor)")));
        }
        robot.motors.push(Motor {
            line: 0,
            joint: joint.to_string(),
            gear,
        });
    }
    Ok(())
}

pub fn run(root: &Path, args: ImportArgs) -> Result<(), cli::Error> {
    spec::check_name(&args.name).map_err(|m| cli::Error::usage(format!("--name: {m}")))?;
    let out = args.out.clone().unwrap_or_else(|| {
        root.join(gen::SPECS_DIR)
            .join(format!("{}.toml", args.name))
    });
    if out.exists() && !args.force {
        return Err(cli::Error::usage(format!(
            "{} exists already: give --force to replace it, or another --name",
            out.display()
        )));
    }
    let (spec_text, lines) = import_text(root, &args)?;
    cli::write_atomic(&out, &spec_text).map_err(cli::Error::Failed)?;
    let mut lines = lines.into_iter();
    println!(
        "wrote {}: {}",
        out.display(),
        lines.next().unwrap_or_default()
    );
    for l in lines {
        println!("{l}");
    }
    println!("next: cargo xtask gen {}", args.name);
    Ok(())
}

/// The import arguments of a spec's header (`# Imported by `cargo xtask import …``), the
/// file resolved against `root`: how the freshness test imports again.
pub fn header_args(root: &Path, spec_text: &str) -> Option<ImportArgs> {
    let line = spec_text.lines().next()?;
    let command = line
        .strip_prefix("# Imported by `cargo xtask ")?
        .strip_suffix('`')?;
    #[derive(clap::Parser)]
    struct Words {
        #[command(subcommand)]
        command: Sub,
    }
    #[derive(clap::Subcommand)]
    enum Sub {
        Import(ImportArgs),
    }
    use clap::Parser;
    let Sub::Import(mut args) =
        Words::try_parse_from(std::iter::once("xtask").chain(command.split_whitespace()))
            .ok()?
            .command;
    args.file = root.join(&args.file);
    Some(args)
}

/// Every spec imported from a file in the repository, against importing it again.
pub fn check_imported(root: &Path) -> Result<usize, String> {
    let mut checked = 0;
    for path in gen::spec_paths(root)? {
        let text = std::fs::read_to_string(&path).map_err(|e| e.to_string())?;
        let Some(args) = header_args(root, &text) else {
            continue;
        };
        if !args.file.exists() && outside_repository(root, &args.file) {
            // A source kept outside the repository (Menagerie's `cassie.xml` beside the
            // clone) is checked where it is present.
            eprintln!(
                "note: {} not checked against its import: {} is not here",
                path.display(),
                args.file.display()
            );
            continue;
        }
        let (fresh, _) =
            import_text(root, &args).map_err(|e| format!("{}: {e}", path.display()))?;
        if fresh != text {
            return Err(format!(
                "{} is not what importing its file gives today: run `cargo xtask {} --force`",
                path.display(),
                text.lines()
                    .next()
                    .unwrap_or_default()
                    .trim_start_matches("# Imported by `cargo xtask ")
                    .trim_end_matches('`')
            ));
        }
        checked += 1;
    }
    Ok(checked)
}

#[cfg(test)]
mod tests;
