//! A validated spec in the form the derivation reads: every geometric quantity named by
//! the run-time parameter that stands for it, links and points by index.

use serde::{Deserialize, Serialize};

use crate::gen::spec::{JointKind, PointSpec, Spec, SpecError, Vector};
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
    /// The unit sliding direction of a prismatic joint (parent frame turned by
    /// `orientation`), and on a spatial leg the unit axis of a revolute one (link frame).
    /// A direction, not a size: fixed at generation, not a run-time parameter.
    pub axis: Option<Vec<f64>>,
    /// Spatial legs: the link frame in its parent's at `q = 0`, a rotation matrix (rows),
    /// from the spec's unit quaternion; `None` for the identity. Fixed at generation.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub orientation: Option<[[f64; 3]; 3]>,
    pub origin: Vec<String>,
    pub length: Vec<String>,
    pub com: Vec<String>,
    pub mass: String,
    /// A planar link's inertia parameter; on a spatial leg the tensor's
    /// `[xx, yy, zz, xy, xz, yz]`, `None` for an entry the spec leaves zero.
    pub inertia: Inertia,
    pub damping: String,
    /// `[rotor_inertia, gear_ratio]` of an actuated joint.
    pub rotor: Option<[String; 2]>,
    /// The first two of a ball joint's three coordinates (`R_x(α)`, `R_y(β)`): frames
    /// that carry no mass, at their parent's joint point (`origin` and `length` empty:
    /// zero), named `<link>.x`, `<link>.y`; the third, `R_z(γ)`, carries the link.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub massless: bool,
    /// The spec's link this coordinate belongs to (its index in `[[links]]`).
    #[serde(skip)]
    pub spec_link: usize,
    /// That spec link's joint: a ball joint's three coordinates and a free joint's six
    /// all say theirs.
    #[serde(skip)]
    pub spec_kind: JointKind,
}

/// A link's inertia about its centre of mass (see [`Link::inertia`]).
#[derive(Clone, Debug, Serialize)]
#[serde(untagged)]
pub enum Inertia {
    Planar(String),
    Spatial([Option<String>; 6]),
}

impl Inertia {
    /// The parameter of a planar link's inertia (`None` on a spatial leg).
    pub fn planar(&self) -> Option<&str> {
        match self {
            Inertia::Planar(name) => Some(name),
            Inertia::Spatial(_) => None,
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Point {
    /// The link, or `None` for a point fixed in the base frame (a closure to the base).
    pub link: Option<usize>,
    pub point: Vec<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Closure {
    pub name: String,
    pub a: Point,
    pub b: Point,
    /// A distance closure's rod length (its parameter): one row, `|a − b| = L`; without
    /// it a point closure, one row per coordinate.
    pub distance: Option<String>,
    /// A revolute closure's axes, fixed at generation: `a` on link a (unit, its frame) and
    /// `u`, `w` on link b (unit, its frame, perpendicular to its axis and to each other).
    /// Its rows are the point closure's three and `(R_a a)·(R_b u)`, `(R_a a)·(R_b w)`:
    /// zero while the axes stay parallel.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub revolute: Option<RevoluteAxes>,
}

/// See [`Closure::revolute`].
#[derive(Clone, Debug, Serialize)]
pub struct RevoluteAxes {
    pub a: [f64; 3],
    pub u: [f64; 3],
    pub w: [f64; 3],
}

impl RevoluteAxes {
    /// Link b's axis, `u × w`.
    pub fn axis_b(&self) -> [f64; 3] {
        let (u, w) = (self.u, self.w);
        [
            u[1] * w[2] - u[2] * w[1],
            u[2] * w[0] - u[0] * w[2],
            u[0] * w[1] - u[1] * w[0],
        ]
    }

    /// From link a's axis and link b's (any length, not zero): `u` is the base axis least
    /// along b's axis, made perpendicular to it; `w = b × u`.
    pub fn new(a: [f64; 3], b: [f64; 3]) -> Self {
        let unit = |v: [f64; 3]| {
            let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            [v[0] / n, v[1] / n, v[2] / n]
        };
        let (a, b) = (unit(a), unit(b));
        let least = (0..3)
            .min_by(|&i, &j| b[i].abs().total_cmp(&b[j].abs()))
            .expect("three axes");
        let mut e = [0.0; 3];
        e[least] = 1.0;
        let along = b[least];
        let u = unit([
            e[0] - along * b[0],
            e[1] - along * b[1],
            e[2] - along * b[2],
        ]);
        let w = [
            b[1] * u[2] - b[2] * u[1],
            b[2] * u[0] - b[0] * u[2],
            b[0] * u[1] - b[1] * u[0],
        ];
        RevoluteAxes { a, u, w }
    }
}

impl Model {
    /// The rows of `φ`, closure by closure.
    pub fn closure_rows(&self) -> usize {
        self.closures.iter().map(|c| c.rows(self.dimension)).sum()
    }
}

impl Closure {
    /// Its rows in `φ`: one for a rod, one per coordinate for a point closure, five for
    /// a revolute closure.
    pub fn rows(&self, dimension: usize) -> usize {
        if self.distance.is_some() {
            1
        } else if self.revolute.is_some() {
            5
        } else {
            dimension
        }
    }
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
    /// 2 (a planar leg) or 3 (spatial): the length of every vector here.
    pub dimension: usize,
    pub gravity: Vec<String>,
    pub actuated: Vec<usize>,
    /// The home pose (rad, or m for a prismatic joint).
    pub home: Vec<f64>,
    pub springs: Vec<Spring>,
    pub contacts: Vec<Contact>,
    /// The ground `normal · x = offset` (a line in the plane, a plane in space), unit
    /// normal (base frame, `dimension` entries).
    pub ground_normal: Vec<f64>,
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

    fn vector(&mut self, prefix: &str, v: &Vector, doc: &str) -> Result<Vec<String>, SpecError> {
        self.vector_in(prefix, v, doc, "m")
    }

    fn vector_in(
        &mut self,
        prefix: &str,
        v: &Vector,
        doc: &str,
        unit: &str,
    ) -> Result<Vec<String>, SpecError> {
        v.value
            .iter()
            .zip(["x", "y", "z"])
            .map(|(&x, axis)| {
                self.scalar(
                    format!("{prefix}_{axis}"),
                    x,
                    format!("{doc}, {axis} [{unit}]."),
                )
            })
            .collect()
    }

    /// A point on a link: its own parameters when the spec gives one, else the link's tip.
    fn point(
        &mut self,
        prefix: &str,
        p: &PointSpec,
        doc: &str,
        links: &[Link],
    ) -> Result<Point, SpecError> {
        let link = self
            .spec
            .link_index(p.link.get_ref())
            .map(|i| links.iter().rposition(|l| l.spec_link == i).expect("built"));
        let point = match (&p.point, link) {
            (Some(v), _) => self.vector(prefix, v.get_ref(), doc)?,
            (None, Some(link)) => links[link].length.clone(),
            (None, None) => unreachable!("validated: a base point has its coordinates"),
        };
        Ok(Point { link, point })
    }
}

/// The rotation matrix (rows) of a unit quaternion `[w, x, y, z]`.
pub fn quaternion_matrix([w, x, y, z]: [f64; 4]) -> [[f64; 3]; 3] {
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
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
    let dimension = f.gravity.get_ref().value.len();
    let gravity = b.vector_in(
        "gravity",
        f.gravity.get_ref(),
        "Gravity in the base frame",
        "m/s²",
    )?;
    let mut links: Vec<Link> = Vec::new();
    let mut actuated = Vec::new();
    // The coordinate of each spec link (a ball joint's last, which carries the link).
    let mut index: Vec<usize> = Vec::new();
    for (i, link) in f.links.iter().enumerate() {
        let l = link.get_ref();
        let name = l.name.get_ref().clone();
        b.owned_by(format!("links[{i}].name"), &l.name);
        let parent = match l.parent.get_ref().as_str() {
            "base" => None,
            p => Some(index[spec.link_index(p).expect("validated")]),
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
                &Vector {
                    value: vec![0.0; dimension],
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
        let given = &l.inertia.get_ref().value.0;
        let inertia = if dimension == 2 {
            Inertia::Planar(b.scalar(
                format!("{name}_inertia"),
                given[0],
                format!("Inertia of `{name}` about its centre of mass [kg m²]."),
            )?)
        } else {
            let mut entries: [Option<String>; 6] = Default::default();
            for (k, (&value, part)) in given
                .iter()
                .zip(["xx", "yy", "zz", "xy", "xz", "yz"])
                .enumerate()
            {
                entries[k] = Some(b.scalar(
                    format!("{name}_inertia_{part}"),
                    value,
                    format!(
                        "Inertia of `{name}` about its centre of mass, link frame, {part} [kg m²]."
                    ),
                )?);
            }
            Inertia::Spatial(entries)
        };
        let damping = b.scalar(
            format!("{name}_damping"),
            l.damping.as_ref().map_or(0.0, |d| d.get_ref().value),
            format!("Viscous damping of the joint of `{name}` [N m s/rad]."),
        )?;
        let rotor = match &l.actuator {
            None => None,
            Some(a) => {
                actuated.push(links.len() + l.kind().coordinates() - 1);
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
        let unit = |v: &[f64]| {
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            v.iter().map(|x| x / norm).collect::<Vec<f64>>()
        };
        let axis = l.axis.as_ref().map(|a| unit(&a.get_ref().value));
        let (joint, axis) = match l.kind() {
            JointKind::Revolute if dimension == 3 => (
                "revolute",
                Some(axis.unwrap_or_else(|| vec![0.0, 0.0, 1.0])),
            ),
            JointKind::Revolute => ("revolute", None),
            JointKind::Prismatic => ("prismatic", Some(axis.expect("validated"))),
            JointKind::Ball | JointKind::Free => ("revolute", Some(vec![0.0, 0.0, 1.0])),
        };
        let orientation = l.orientation.as_ref().map(|o| {
            let q = unit(&o.get_ref().value);
            quaternion_matrix([q[0], q[1], q[2], q[3]])
        });
        let kind = l.kind();
        let (parent, orientation, origin, name) =
            if matches!(kind, JointKind::Ball | JointKind::Free) {
                // A free joint: slides along the base's x, y and z on massless frames, then
                // turns as a ball joint. A ball joint: R_x(α) then R_y(β) on massless frames
                // at the joint point, then the link on R_z(γ): the damping acts on each angle.
                let mut parent = parent;
                let (mut orientation, mut origin) = (orientation, origin);
                let x = [1.0, 0.0, 0.0];
                let y = [0.0, 1.0, 0.0];
                let z = [0.0, 0.0, 1.0];
                let frames: &[(&str, &str, [f64; 3])] = if kind == JointKind::Free {
                    &[
                        ("tx", "prismatic", x),
                        ("ty", "prismatic", y),
                        ("tz", "prismatic", z),
                        ("x", "revolute", x),
                        ("y", "revolute", y),
                    ]
                } else {
                    &[("x", "revolute", x), ("y", "revolute", y)]
                };
                for &(suffix, joint, axis) in frames {
                    links.push(Link {
                        name: format!("{name}.{suffix}"),
                        parent,
                        joint,
                        axis: Some(axis.to_vec()),
                        orientation: orientation.take(),
                        origin: std::mem::take(&mut origin),
                        length: Vec::new(),
                        com: Vec::new(),
                        mass: String::new(),
                        inertia: Inertia::Spatial(Default::default()),
                        damping: damping.clone(),
                        rotor: None,
                        massless: true,
                        spec_link: i,
                        spec_kind: kind,
                    });
                    parent = Some(links.len() - 1);
                }
                (parent, None, Vec::new(), format!("{name}.z"))
            } else {
                (parent, orientation, origin, name)
            };
        index.push(links.len());
        links.push(Link {
            name,
            parent,
            joint,
            axis,
            orientation,
            origin,
            length,
            com,
            mass,
            inertia,
            damping,
            rotor,
            massless: false,
            spec_link: i,
            spec_kind: kind,
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
        let distance = c
            .distance
            .as_ref()
            .map(|d| {
                b.scalar(
                    format!("{name}_distance"),
                    d.get_ref().value,
                    format!("Length of the rod of closure `{name}`: the distance from point a to point b [m]."),
                )
            })
            .transpose()?;
        let revolute = c.axis.as_ref().map(|axis| {
            let v =
                |x: &Spanned<Vector>| -> [f64; 3] { std::array::from_fn(|i| x.get_ref().value[i]) };
            RevoluteAxes::new(v(axis), v(c.axis_b.as_ref().unwrap_or(axis)))
        });
        closures.push(Closure {
            name,
            a,
            b: bp,
            distance,
            revolute,
        });
    }
    b.owned_by("foot.link".into(), &f.foot.get_ref().link);
    let foot = b.point("foot", f.foot.get_ref(), "Foot point, link frame", &links)?;
    let mut springs = Vec::new();
    for (k, s) in f.springs.iter().enumerate() {
        let s = s.get_ref();
        let name = s.name.get_ref().clone();
        b.owned_by(format!("springs[{k}].name"), &s.name);
        let a = index[spec.link_index(s.a.get_ref()).expect("validated")];
        let bl =
            s.b.as_ref()
                .map(|b| index[spec.link_index(b.get_ref()).expect("validated")]);
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
    // Level ground by default: normal +y in the plane, +z in space.
    let up = if dimension == 3 {
        vec![0.0, 0.0, 1.0]
    } else {
        vec![0.0, 1.0]
    };
    let (ground_normal, ground_offset) = match &f.ground {
        None => (up, 0.0),
        Some(g) => {
            let g = g.get_ref();
            let n = g.normal.as_ref().map_or(up, |n| n.get_ref().value.clone());
            // The planar norm as `hypot` (the planar legs' bits unchanged).
            let norm = if n.len() == 2 {
                n[0].hypot(n[1])
            } else {
                n.iter().map(|x| x * x).sum::<f64>().sqrt()
            };
            (
                n.iter().map(|x| x / norm).collect(),
                g.offset.as_ref().map_or(0.0, |o| o.get_ref().value),
            )
        }
    };
    let home = f
        .home
        .as_ref()
        .map_or_else(|| vec![0.0; links.len()], |h| h.get_ref().clone());
    Ok(Model {
        name: spec.name.clone(),
        spec_text: spec.text.clone(),
        params: b.params,
        links,
        closures,
        foot,
        dimension,
        gravity,
        actuated,
        home,
        springs,
        contacts,
        ground_normal,
        ground_offset,
    })
}
