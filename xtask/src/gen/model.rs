//! A validated spec in the form the derivation reads: every geometric quantity named by
//! the run-time parameter that stands for it, links and points by index.

use serde::{Deserialize, Serialize};

use crate::gen::spec::{JointKind, PointSpec, Spec, SpecError, Vec2};
use toml::Spanned;

/// One run-time parameter: a field of the generated `Params` struct.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Param {
    pub name: String,
    /// The spec's value (the generated `Default`).
    pub default: f64,
    /// What it is, with its unit; written from templates, never from spec text.
    pub doc: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct Link {
    pub name: String,
    pub parent: Option<usize>,
    /// `"revolute"` or `"prismatic"`.
    pub joint: &'static str,
    /// The unit sliding direction of a prismatic joint (parent frame). A direction, not a
    /// size: fixed at generation, not a run-time parameter.
    pub axis: Option<[f64; 2]>,
    pub origin: [String; 2],
    pub length: [String; 2],
    pub com: [String; 2],
    pub mass: String,
    pub inertia: String,
    pub damping: String,
    /// `[rotor_inertia, gear_ratio]` of an actuated joint.
    pub rotor: Option<[String; 2]>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Point {
    /// The link, or `None` for a point fixed in the base frame (a closure to the base).
    pub link: Option<usize>,
    pub point: [String; 2],
}

#[derive(Clone, Debug, Serialize)]
pub struct Closure {
    pub name: String,
    pub a: Point,
    pub b: Point,
}

/// `½ k (q_a − q_b − rest)²`, or `½ k (q_a − rest)²` without `b`.
#[derive(Clone, Debug, Serialize)]
pub struct Spring {
    pub name: String,
    pub a: usize,
    pub b: Option<usize>,
    pub stiffness: String,
    pub rest: String,
}

/// A point that can touch the ground.
#[derive(Clone, Debug, Serialize)]
pub struct Contact {
    pub name: String,
    pub point: Point,
    /// Coulomb μ (the generated model's default; the simulator's to change).
    pub friction: f64,
}

/// What `derive.py` reads on stdin.
#[derive(Clone, Debug, Serialize)]
pub struct Model {
    pub name: String,
    pub spec_text: String,
    pub params: Vec<Param>,
    pub links: Vec<Link>,
    pub closures: Vec<Closure>,
    pub foot: Point,
    pub gravity: [String; 2],
    pub actuated: Vec<usize>,
    /// The home pose (rad, or m for a prismatic joint).
    pub home: Vec<f64>,
    pub springs: Vec<Spring>,
    pub contacts: Vec<Contact>,
    /// The ground line `normal · x = offset`, unit normal (base frame).
    pub ground_normal: [f64; 2],
    pub ground_offset: f64,
}

impl Model {
    pub fn joint_names(&self) -> Vec<String> {
        self.links.iter().map(|l| l.name.clone()).collect()
    }
}

struct Builder<'a> {
    spec: &'a Spec,
    params: Vec<Param>,
    /// Which spec name each parameter comes from: its field and byte offset.
    owners: Vec<(String, usize)>,
    /// The spec name whose parameters are being made.
    owner: (String, usize),
}

impl Builder<'_> {
    /// From now on, parameters come from the name `at`, the field `field`.
    fn owned_by(&mut self, field: String, at: &Spanned<String>) {
        self.owner = (field, at.span().start);
    }

    fn scalar(&mut self, name: String, value: f64, doc: String) -> Result<String, SpecError> {
        if let Some(i) = self.params.iter().position(|p| p.name == name) {
            // Reported at the second name, naming the first.
            let (first, first_at) = &self.owners[i];
            let (first_line, _) = crate::gen::spec::line_column(&self.spec.text, *first_at);
            let (line, column) = crate::gen::spec::line_column(&self.spec.text, self.owner.1);
            return Err(SpecError {
                file: self.spec.path.clone(),
                line,
                column,
                field: self.owner.0.clone(),
                message: format!(
                    "this name and {first} (line {first_line}) would both make the parameter `{name}`; rename one"
                ),
            });
        }
        self.params.push(Param {
            name: name.clone(),
            default: value,
            doc,
        });
        self.owners.push(self.owner.clone());
        Ok(name)
    }

    fn vector(&mut self, prefix: &str, v: &Vec2, doc: &str) -> Result<[String; 2], SpecError> {
        Ok([
            self.scalar(format!("{prefix}_x"), v.value[0], format!("{doc}, x [m]."))?,
            self.scalar(format!("{prefix}_y"), v.value[1], format!("{doc}, y [m]."))?,
        ])
    }

    /// A point on a link: its own parameters when the spec gives one, else the link's tip.
    fn point(
        &mut self,
        prefix: &str,
        p: &PointSpec,
        doc: &str,
        links: &[Link],
    ) -> Result<Point, SpecError> {
        let link = self.spec.link_index(p.link.get_ref());
        let point = match (&p.point, link) {
            (Some(v), _) => self.vector(prefix, v.get_ref(), doc)?,
            (None, Some(link)) => links[link].length.clone(),
            (None, None) => unreachable!("validated: a base point has its coordinates"),
        };
        Ok(Point { link, point })
    }
}

/// Builds the derivation's model from a validated spec.
pub fn build(spec: &Spec) -> Result<Model, SpecError> {
    let mut b = Builder {
        spec,
        params: Vec::new(),
        owners: Vec::new(),
        owner: ("gravity".into(), spec.file.gravity.span().start),
    };
    let f = &spec.file;
    let gravity = [
        b.scalar(
            "gravity_x".into(),
            f.gravity.get_ref().value[0],
            "Gravity in the base frame, x [m/s²].".into(),
        )?,
        b.scalar(
            "gravity_y".into(),
            f.gravity.get_ref().value[1],
            "Gravity in the base frame, y [m/s²].".into(),
        )?,
    ];
    let mut links: Vec<Link> = Vec::new();
    let mut actuated = Vec::new();
    for (i, link) in f.links.iter().enumerate() {
        let l = link.get_ref();
        let name = l.name.get_ref().clone();
        b.owned_by(format!("links[{i}].name"), &l.name);
        let parent = match l.parent.get_ref().as_str() {
            "base" => None,
            p => Some(spec.link_index(p).expect("validated")),
        };
        let origin = match (&l.origin, parent) {
            (Some(o), None) => b.vector(
                &format!("{name}_origin"),
                o.get_ref(),
                &format!("Joint of `{name}` in the base frame"),
            )?,
            (Some(o), Some(_)) => b.vector(
                &format!("{name}_origin"),
                o.get_ref(),
                &format!("Joint of `{name}` in its parent's frame"),
            )?,
            (None, None) => b.vector(
                &format!("{name}_origin"),
                &Vec2 {
                    value: [0.0, 0.0],
                    source: None,
                },
                &format!("Joint of `{name}` in the base frame"),
            )?,
            (None, Some(p)) => links[p].length.clone(),
        };
        let length = b.vector(
            &format!("{name}_length"),
            l.length.get_ref(),
            &format!("Tip of `{name}` from its joint, link frame"),
        )?;
        let mass = b.scalar(
            format!("{name}_mass"),
            l.mass.get_ref().value,
            format!("Mass of `{name}` [kg]."),
        )?;
        let com = b.vector(
            &format!("{name}_com"),
            l.com.get_ref(),
            &format!("Centre of mass of `{name}` from its joint, link frame"),
        )?;
        let inertia = b.scalar(
            format!("{name}_inertia"),
            l.inertia.get_ref().value,
            format!("Inertia of `{name}` about its centre of mass [kg m²]."),
        )?;
        let damping = b.scalar(
            format!("{name}_damping"),
            l.damping.as_ref().map_or(0.0, |d| d.get_ref().value),
            format!("Viscous damping of the joint of `{name}` [N m s/rad]."),
        )?;
        let rotor = match &l.actuator {
            None => None,
            Some(a) => {
                actuated.push(i);
                let a = a.get_ref();
                Some([
                    b.scalar(
                        format!("{name}_rotor_inertia"),
                        a.rotor_inertia.get_ref().value,
                        format!("Rotor inertia of the motor of `{name}` [kg m²]."),
                    )?,
                    b.scalar(
                        format!("{name}_gear_ratio"),
                        a.gear_ratio.get_ref().value,
                        format!("Gear ratio of the motor of `{name}` (reflected inertia I·N²)."),
                    )?,
                ])
            }
        };
        let (joint, axis) = match l.kind() {
            JointKind::Revolute => ("revolute", None),
            JointKind::Prismatic => {
                let [x, y] = l.axis.as_ref().expect("validated").get_ref().value;
                let norm = x.hypot(y);
                ("prismatic", Some([x / norm, y / norm]))
            }
        };
        links.push(Link {
            name,
            parent,
            joint,
            axis,
            origin,
            length,
            com,
            mass,
            inertia,
            damping,
            rotor,
        });
    }
    let mut closures = Vec::new();
    for (k, c) in f.closures.iter().enumerate() {
        let c = c.get_ref();
        let name = c.name.get_ref().clone();
        b.owned_by(format!("closures[{k}].name"), &c.name);
        let a = b.point(
            &format!("{name}_a"),
            c.a.get_ref(),
            &format!("Point a of closure `{name}`, link frame"),
            &links,
        )?;
        let bp = b.point(
            &format!("{name}_b"),
            c.b.get_ref(),
            &format!("Point b of closure `{name}`, link frame"),
            &links,
        )?;
        closures.push(Closure { name, a, b: bp });
    }
    b.owned_by("foot.link".into(), &f.foot.get_ref().link);
    let foot = b.point("foot", f.foot.get_ref(), "Foot point, link frame", &links)?;
    let mut springs = Vec::new();
    for (k, s) in f.springs.iter().enumerate() {
        let s = s.get_ref();
        let name = s.name.get_ref().clone();
        b.owned_by(format!("springs[{k}].name"), &s.name);
        let a = spec.link_index(s.a.get_ref()).expect("validated");
        let bl =
            s.b.as_ref()
                .map(|b| spec.link_index(b.get_ref()).expect("validated"));
        let on = match bl {
            None => format!("the joint of `{}`", links[a].name),
            Some(bl) => format!("`{}` minus `{}`", links[a].name, links[bl].name),
        };
        let unit = |rad: &str, m: &str| {
            if links[a].joint == "prismatic" {
                m.to_string()
            } else {
                rad.to_string()
            }
        };
        let stiffness = b.scalar(
            format!("{name}_stiffness"),
            s.stiffness.get_ref().value,
            format!(
                "Stiffness of spring `{name}` on {on} [{}].",
                unit("N m/rad", "N/m")
            ),
        )?;
        let rest = b.scalar(
            format!("{name}_rest"),
            s.rest.as_ref().map_or(0.0, |r| r.get_ref().value),
            format!(
                "Rest value of spring `{name}` on {on} [{}].",
                unit("rad", "m")
            ),
        )?;
        springs.push(Spring {
            name,
            a,
            b: bl,
            stiffness,
            rest,
        });
    }
    let mut contacts = Vec::new();
    for (k, c) in f.contacts.iter().enumerate() {
        let c = c.get_ref();
        let name = c.name.get_ref().clone();
        b.owned_by(format!("contacts[{k}].name"), &c.name);
        let point = b.point(
            &name,
            &PointSpec {
                link: c.link.clone(),
                point: c.point.clone(),
            },
            &format!("Contact point `{name}`, link frame"),
            &links,
        )?;
        contacts.push(Contact {
            name,
            point,
            friction: c.friction.get_ref().value,
        });
    }
    let (ground_normal, ground_offset) = match &f.ground {
        None => ([0.0, 1.0], 0.0),
        Some(g) => {
            let g = g.get_ref();
            let [x, y] = g.normal.as_ref().map_or([0.0, 1.0], |n| n.get_ref().value);
            let norm = x.hypot(y);
            (
                [x / norm, y / norm],
                g.offset.as_ref().map_or(0.0, |o| o.get_ref().value),
            )
        }
    };
    Ok(Model {
        name: spec.name.clone(),
        spec_text: spec.text.clone(),
        params: b.params,
        links,
        closures,
        foot,
        gravity,
        actuated,
        home: f
            .home
            .as_ref()
            .map_or_else(|| vec![0.0; f.links.len()], |h| h.get_ref().clone()),
        springs,
        contacts,
        ground_normal,
        ground_offset,
    })
}
