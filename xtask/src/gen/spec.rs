//! Geometry specs: parsing (TOML with serde), validation, and every error with the
//! file, line, column and field it concerns.
//!
//! A spec describes a tree of rigid links on revolute and prismatic joints (each link hangs
//! from its parent link or from the base by one joint, whose value is relative to the
//! parent), any number of point-on-link closures, the actuated joints, the foot point and
//! gravity. Its dimension is its gravity's: a 2-vector makes a planar leg, a 3-vector a
//! spatial one, and every vector of the spec then has that many entries.
//! Every number may be written plain (`mass = 0.05`) or with its source
//! (`mass = { value = 0.05, source = "PyBullet minitaur.urdf" }`).

use std::fmt;
use std::marker::PhantomData;
use std::path::{Path, PathBuf};

use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::Deserialize;
use toml::Spanned;

/// A spec that cannot be used, and where.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SpecError {
    pub file: PathBuf,
    pub line: usize,
    pub column: usize,
    pub field: String,
    pub message: String,
}

impl fmt::Display for SpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}:{}:{}: {}: {}",
            self.file.display(),
            self.line,
            self.column,
            self.field,
            self.message
        )
    }
}

impl std::error::Error for SpecError {}

/// A number or vector, with the optional note of where it comes from.
#[derive(Clone, Debug, PartialEq)]
pub struct Noted<V> {
    pub value: V,
    pub source: Option<String>,
}

pub type Num = Noted<f64>;
/// A vector: 2 entries on a planar leg, 3 on a spatial one (checked on validation
/// against the gravity's), 4 for an orientation quaternion.
pub type Vector = Noted<Vec<f64>>;
/// A number or a list of numbers: a link's inertia (one number on a planar leg, 3 or 6
/// entries of the tensor on a spatial one).
pub type Entries = Noted<NumberList>;

/// One number or several (see [`Entries`]).
#[derive(Clone, Debug, PartialEq)]
pub struct NumberList(pub Vec<f64>);

/// Plain values a [`Noted`] can hold.
pub trait PlainValue: Sized {
    const EXPECTING: &'static str;
    fn from_number(v: f64) -> Option<Self>;
    fn from_seq<'de, A: SeqAccess<'de>>(seq: A) -> Result<Self, A::Error>;
    fn from_map_value<'de, A: MapAccess<'de>>(map: &mut A) -> Result<Self, A::Error>;
}

impl PlainValue for f64 {
    const EXPECTING: &'static str = "a number";
    fn from_number(v: f64) -> Option<Self> {
        Some(v)
    }
    fn from_seq<'de, A: SeqAccess<'de>>(_: A) -> Result<Self, A::Error> {
        Err(de::Error::invalid_type(
            de::Unexpected::Seq,
            &Self::EXPECTING,
        ))
    }
    fn from_map_value<'de, A: MapAccess<'de>>(map: &mut A) -> Result<Self, A::Error> {
        map.next_value()
    }
}

fn number_seq<'de, A: SeqAccess<'de>>(mut seq: A, what: &str) -> Result<Vec<f64>, A::Error> {
    let mut out = Vec::new();
    while let Some(x) = seq.next_element::<f64>()? {
        // A spec's vectors have 2 to 6 entries: a longer list is refused as it is read.
        if out.len() == 16 {
            return Err(de::Error::custom(format!(
                "expected {what}: too many entries"
            )));
        }
        out.push(x);
    }
    Ok(out)
}

impl PlainValue for Vec<f64> {
    const EXPECTING: &'static str =
        "a 2-vector [x, y] (planar leg) or a 3-vector [x, y, z] (spatial leg)";
    fn from_number(_: f64) -> Option<Self> {
        None
    }
    fn from_seq<'de, A: SeqAccess<'de>>(seq: A) -> Result<Self, A::Error> {
        number_seq(seq, "a vector")
    }
    fn from_map_value<'de, A: MapAccess<'de>>(map: &mut A) -> Result<Self, A::Error> {
        map.next_value()
    }
}

impl PlainValue for NumberList {
    const EXPECTING: &'static str =
        "a number (planar leg) or a list of the tensor's entries (spatial leg)";
    fn from_number(v: f64) -> Option<Self> {
        Some(NumberList(vec![v]))
    }
    fn from_seq<'de, A: SeqAccess<'de>>(seq: A) -> Result<Self, A::Error> {
        number_seq(seq, "a list of numbers").map(NumberList)
    }
    fn from_map_value<'de, A: MapAccess<'de>>(map: &mut A) -> Result<Self, A::Error> {
        struct Either;
        impl<'de> Visitor<'de> for Either {
            type Value = NumberList;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str(NumberList::EXPECTING)
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<NumberList, E> {
                Ok(NumberList(vec![v]))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<NumberList, E> {
                Ok(NumberList(vec![v as f64]))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<NumberList, E> {
                Ok(NumberList(vec![v as f64]))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<NumberList, A::Error> {
                number_seq(seq, "a list of numbers").map(NumberList)
            }
        }
        struct Value(NumberList);
        impl<'de> Deserialize<'de> for Value {
            fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                d.deserialize_any(Either).map(Value)
            }
        }
        map.next_value::<Value>().map(|v| v.0)
    }
}

impl<'de, V: PlainValue> Deserialize<'de> for Noted<V> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct NotedVisitor<V>(PhantomData<V>);
        impl<'de, V: PlainValue> Visitor<'de> for NotedVisitor<V> {
            type Value = Noted<V>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                write!(f, "{} or {{ value = …, source = \"…\" }}", V::EXPECTING)
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Self::Value, E> {
                V::from_number(v)
                    .map(|value| Noted {
                        value,
                        source: None,
                    })
                    .ok_or_else(|| E::invalid_type(de::Unexpected::Float(v), &self))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Self::Value, E> {
                V::from_number(v as f64)
                    .map(|value| Noted {
                        value,
                        source: None,
                    })
                    .ok_or_else(|| E::invalid_type(de::Unexpected::Signed(v), &self))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Self::Value, E> {
                self.visit_i64(v as i64)
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
                V::from_seq(seq).map(|value| Noted {
                    value,
                    source: None,
                })
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let (mut value, mut source) = (None, None);
                while let Some(key) = map.next_key::<String>()? {
                    match key.as_str() {
                        "value" => value = Some(V::from_map_value(&mut map)?),
                        "source" => source = Some(map.next_value::<String>()?),
                        other => return Err(de::Error::unknown_field(other, &["value", "source"])),
                    }
                }
                let value = value.ok_or_else(|| de::Error::missing_field("value"))?;
                Ok(Noted { value, source })
            }
        }
        d.deserialize_any(NotedVisitor(PhantomData))
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpecFile {
    /// What the leg is; for people, never emitted into code.
    #[serde(default)]
    pub description: Option<String>,
    /// Gravity in the base frame [m/s²]. Its length makes the spec's dimension: `[x, y]`
    /// a planar leg, `[x, y, z]` a spatial one.
    pub gravity: Spanned<Vector>,
    pub links: Vec<Spanned<LinkSpec>>,
    /// A typical assembled pose (one joint value per link in file order: rad, or m for a
    /// prismatic joint): the default
    /// guess of loop assembly, which picks the assembly mode (knee in or out), and the
    /// default initial state of simulations. Default: all zeros.
    #[serde(default)]
    pub home: Option<Spanned<Vec<f64>>>,
    #[serde(default)]
    pub closures: Vec<Spanned<ClosureSpec>>,
    pub foot: Spanned<PointSpec>,
    /// Joint springs and coupling springs (series-elastic actuators).
    #[serde(default)]
    pub springs: Vec<Spanned<SpringSpec>>,
    /// Points that can touch the ground.
    #[serde(default)]
    pub contacts: Vec<Spanned<ContactSpec>>,
    /// The ground line the contacts meet (default `y = 0`, normal up).
    #[serde(default)]
    pub ground: Option<Spanned<GroundSpec>>,
}

/// How a link moves relative to its parent.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum JointKind {
    /// Turns by `q` (rad) about the joint point.
    #[default]
    Revolute,
    /// Slides by `q` (m) along `axis` (parent frame), keeping the parent's orientation.
    Prismatic,
    /// Spatial legs: turns freely about its joint point, three coordinates (rad): the
    /// angles `(α, β, γ)` of `R = R_x(α) R_y(β) R_z(γ)` in the link's frame (turned by
    /// `orientation`), singular at `β = ±π/2` (docs/spec-format.md#ball-joints).
    Ball,
    /// Spatial robots: the body of a robot that floats, six coordinates in the chart the
    /// runtime keeps centred on the body's pose (its position and unit quaternion): a
    /// translation `(x, y, z)` (m) along the base frame's axes, then a ball joint's
    /// angles (rad). The first link, on `base`, and the only link there
    /// (docs/spec-format.md#free-joints).
    Free,
}

impl JointKind {
    /// How many coordinates of `q` the joint has.
    pub fn coordinates(self) -> usize {
        match self {
            JointKind::Ball => 3,
            JointKind::Free => 6,
            _ => 1,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpringSpec {
    pub name: Spanned<String>,
    /// The link whose joint the spring acts on.
    pub a: Spanned<String>,
    /// With a second link, a coupling spring on `q_a − q_b` (motor output and link of a
    /// series-elastic actuator); without, a spring on `q_a` alone.
    #[serde(default)]
    pub b: Option<Spanned<String>>,
    /// [N m/rad] (revolute) or [N/m] (prismatic).
    pub stiffness: Spanned<Num>,
    /// The value of `q_a` (or `q_a − q_b`) at which the spring is relaxed; default 0.
    #[serde(default)]
    pub rest: Option<Spanned<Num>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSpec {
    pub name: Spanned<String>,
    pub link: Spanned<String>,
    /// In the link frame, from its joint; default the link's tip.
    #[serde(default)]
    pub point: Option<Spanned<Vector>>,
    /// Coulomb friction coefficient μ with the ground.
    pub friction: Spanned<Num>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroundSpec {
    /// Points out of the ground, base frame; normalized. Default `[0, 1]`.
    #[serde(default)]
    pub normal: Option<Spanned<Vector>>,
    /// The ground is `normal · x = offset` \[m\]; default 0.
    #[serde(default)]
    pub offset: Option<Spanned<Num>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LinkSpec {
    pub name: Spanned<String>,
    /// `"base"` or a link defined above.
    pub parent: Spanned<String>,
    /// `"revolute"` (default) or `"prismatic"`.
    #[serde(default)]
    pub joint: Option<Spanned<JointKind>>,
    /// The sliding direction of a prismatic joint, in the parent's frame (the base frame
    /// for a base joint) turned by `orientation`; normalized. On a spatial leg also the
    /// axis a revolute joint turns about (default `[0, 0, 1]`, as MJCF's hinge).
    #[serde(default)]
    pub axis: Option<Spanned<Vector>>,
    /// Spatial legs: the link frame's orientation in its parent's frame at `q = 0`, a
    /// quaternion `[w, x, y, z]` (MJCF's `quat`), normalized; default the identity.
    #[serde(default)]
    pub orientation: Option<Spanned<Vector>>,
    /// Where the joint sits: on the base, in the base frame (default `[0, 0]`); on a
    /// parent link, in the parent's frame (default the parent's tip).
    #[serde(default)]
    pub origin: Option<Spanned<Vector>>,
    /// From the joint to the link's tip, in the link frame \[m\].
    pub length: Spanned<Vector>,
    /// \[kg\]; zero for the massless intermediate links of a floating base (the mass
    /// matrix must stay positive definite).
    pub mass: Spanned<Num>,
    /// Centre of mass, from the joint, in the link frame \[m\].
    pub com: Spanned<Vector>,
    /// About the centre of mass [kg m²]: one number on a planar leg; on a spatial leg the
    /// tensor in the link frame, `[ixx, iyy, izz]` (principal axes along the frame's) or
    /// `[ixx, iyy, izz, ixy, ixz, iyz]` (MJCF's `fullinertia`).
    pub inertia: Spanned<Entries>,
    /// Viscous joint damping [N m s/rad, or N s/m for a prismatic joint]; default 0.
    #[serde(default)]
    pub damping: Option<Spanned<Num>>,
    /// Present when a motor drives this link's joint.
    #[serde(default)]
    pub actuator: Option<Spanned<ActuatorSpec>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActuatorSpec {
    /// Rotor inertia on the motor side [kg m²]; reflected as `I · gear_ratio²`.
    pub rotor_inertia: Spanned<Num>,
    pub gear_ratio: Spanned<Num>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointSpec {
    pub link: Spanned<String>,
    /// In the link frame, from its joint; default the link's tip.
    #[serde(default)]
    pub point: Option<Spanned<Vector>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClosureSpec {
    pub name: Spanned<String>,
    pub a: Spanned<PointSpec>,
    pub b: Spanned<PointSpec>,
    /// A rod of this length between `a` and `b` \[m\] (ball or pin ends: one row, the
    /// distance); without it the points coincide (one row per coordinate).
    #[serde(default)]
    pub distance: Option<Spanned<Num>>,
    /// A revolute closure (spatial legs): the points coincide and this axis of link a
    /// (its frame) stays along `axis_b` of link b; five rows, where a point closure has
    /// three and leaves the two links free to turn about every axis through the point.
    #[serde(default)]
    pub axis: Option<Spanned<Vector>>,
    /// The revolute closure's axis in link b's frame (default: `axis`'s numbers).
    #[serde(default)]
    pub axis_b: Option<Spanned<Vector>>,
}

/// A parsed, validated spec with its source text.
#[derive(Debug)]
pub struct Spec {
    /// The file stem: the module name of the generated code.
    pub name: String,
    pub path: PathBuf,
    pub text: String,
    pub file: SpecFile,
}

const RUST_KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "self", "static", "struct", "super", "trait", "true", "try", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "typeof", "unsized", "virtual", "yield",
];

pub use crate::cli::shown;

/// Names in specs become module, field and constant names: lowercase snake case ASCII
/// identifiers that are not keywords.
pub fn check_name(name: &str) -> Result<(), String> {
    let ok = name.starts_with(|c: char| c.is_ascii_lowercase())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        && name.len() <= 48;
    if !ok {
        return Err(format!(
            "`{}` is not a plain identifier (lowercase letters, digits and `_`, starting with a letter, at most 48 characters)",
            shown(name)
        ));
    }
    if RUST_KEYWORDS.contains(&name) {
        return Err(format!("`{name}` is a Rust keyword"));
    }
    Ok(())
}

struct Ctx<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Ctx<'_> {
    fn at(&self, offset: usize, field: impl Into<String>, message: impl Into<String>) -> SpecError {
        let (line, column) = line_column(self.text, offset);
        SpecError {
            file: self.path.to_path_buf(),
            line,
            column,
            field: field.into(),
            message: message.into(),
        }
    }

    fn span<T>(
        &self,
        s: &Spanned<T>,
        field: impl Into<String>,
        msg: impl Into<String>,
    ) -> SpecError {
        self.at(s.span().start, field, msg)
    }
}

/// The offset of the innermost `[` still open at `offset` (strings and comments skipped),
/// if any: where a missing `]` belongs.
fn unclosed_bracket(text: &str, offset: usize) -> Option<usize> {
    let mut open = Vec::new();
    let mut quote: Option<char> = None;
    let mut comment = false;
    for (i, c) in text.char_indices().take_while(|&(i, _)| i < offset) {
        match (quote, c) {
            _ if comment => comment = c != '\n',
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '"' | '\'') => quote = Some(c),
            (None, '#') => comment = true,
            (None, '[') => open.push(i),
            (None, ']') => {
                open.pop();
            }
            _ => {}
        }
    }
    open.last().copied()
}

/// 1-based line and column (in characters) of a byte offset.
pub fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let offset = offset.min(text.len());
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// The field a syntax or type error at `offset` concerns, as a path such as
/// `links[1].com`: the enclosing table header (`[[links]]` counted, `[foot]`) and the key
/// written before `offset` on its line, or the field a "missing field" message names.
fn field_at(text: &str, offset: usize, message: &str) -> String {
    let offset = offset.min(text.len());
    let mut table = String::new();
    let mut counts: Vec<(String, usize)> = Vec::new();
    let line_start = text[..offset].rfind('\n').map_or(0, |i| i + 1);
    for line in text[..line_start]
        .lines()
        .chain(text[line_start..].lines().take(1))
    {
        let t = line.trim();
        if let Some(name) = t.strip_prefix("[[").and_then(|r| r.split("]]").next()) {
            let name = name.trim().to_string();
            let n = match counts.iter_mut().find(|(k, _)| *k == name) {
                Some((_, n)) => {
                    *n += 1;
                    *n
                }
                None => {
                    counts.push((name.clone(), 0));
                    0
                }
            };
            table = format!("{name}[{n}]");
        } else if let Some(name) = t.strip_prefix('[').and_then(|r| r.split(']').next()) {
            table = name.trim().to_string();
        }
    }
    let line_end = text[offset..].find('\n').map_or(text.len(), |i| offset + i);
    let line = &text[line_start..line_end];
    let key = line
        .split_once('=')
        .map(|(k, _)| k.trim().trim_matches('"').to_string())
        .filter(|k| !k.is_empty() && !k.starts_with('#') && !k.starts_with('['))
        .or_else(|| {
            let rest = message.split("missing field `").nth(1)?;
            Some(rest.split('`').next()?.to_string())
        });
    // Keys and table names come from the user's text: shown escaped and short.
    let (table, key) = (shown(&table), key.map(|k| shown(&k)));
    match (table.is_empty(), key) {
        (true, Some(k)) => k,
        (false, Some(k)) => format!("{table}.{k}"),
        (false, None) => table,
        (true, None) => "(document)".into(),
    }
}

impl LinkSpec {
    pub fn kind(&self) -> JointKind {
        self.joint
            .as_ref()
            .map_or(JointKind::Revolute, |j| *j.get_ref())
    }
}

impl Spec {
    /// Reads, parses and validates the spec at `path`.
    pub fn load(path: &Path) -> Result<Spec, SpecError> {
        let text = std::fs::read_to_string(path).map_err(|e| SpecError {
            file: path.to_path_buf(),
            line: 0,
            column: 0,
            field: "(file)".into(),
            message: format!("cannot read: {e}"),
        })?;
        Spec::parse(path, text)
    }

    /// Parses and validates `text` as the spec at `path` (whose stem names the model).
    pub fn parse(path: &Path, text: String) -> Result<Spec, SpecError> {
        let ctx = Ctx { path, text: &text };
        let name = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default()
            .to_string();
        check_name(&name).map_err(|m| ctx.at(0, "(file name)", m))?;
        let file: SpecFile = toml::from_str(&text).map_err(|e| {
            let offset = e.span().map_or(0, |s| s.start);
            // The parser's message can span lines (and quote the input): one line, escaped.
            let message = e
                .message()
                .lines()
                .map(str::trim)
                .filter(|l| !l.is_empty())
                .map(|l| {
                    l.chars()
                        .map(|c| {
                            if c.is_control() {
                                c.escape_default().collect()
                            } else {
                                c.to_string()
                            }
                        })
                        .collect::<String>()
                })
                .collect::<Vec<_>>()
                .join(": ");
            // A missing `]` is found where the next line begins, and blamed on that line's
            // key: point at the array that was left open instead.
            if message.contains("expected `]`") {
                if let Some(open) = unclosed_bracket(&text, offset) {
                    return ctx.at(
                        open,
                        field_at(&text, open, ""),
                        "this array is not closed: a `]` is missing".to_string(),
                    );
                }
            }
            ctx.at(offset, field_at(&text, offset, &message), message)
        })?;
        validate(&ctx, &file)?;
        Ok(Spec {
            name,
            path: path.to_path_buf(),
            text,
            file,
        })
    }

    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.file
            .links
            .iter()
            .position(|l| *l.get_ref().name.get_ref() == name)
    }
}

/// The most links a spec may have. Generation grows about as n³ with the links of a chain
/// (docs/figures.md: one chain of 16 links 5 s, of 32 links 28–42 s and 100,000
/// lines of Rust);
/// legs have a handful, and a larger spec is refused before anything runs.
pub const MAX_LINKS: usize = 32;

fn validate(ctx: &Ctx, file: &SpecFile) -> Result<(), SpecError> {
    if file.links.is_empty() {
        return Err(ctx.at(0, "links", "a spec needs at least one [[links]] table"));
    }
    if let Some(extra) = file.links.get(MAX_LINKS) {
        return Err(ctx.span(
            &extra.get_ref().name,
            format!("links[{MAX_LINKS}]"),
            format!(
                "a spec may have at most {MAX_LINKS} links, this one has {} (generation grows about as n³: {MAX_LINKS} links in one chain take 28 to 42 s and make 100,000 lines of Rust)",
                file.links.len()
            ),
        ));
    }
    let dim = file.gravity.get_ref().value.len();
    if dim != 2 && dim != 3 {
        return Err(ctx.span(
            &file.gravity,
            "gravity",
            format!(
                "gravity has {dim} entries: [x, y] makes a planar leg, [x, y, z] a spatial one"
            ),
        ));
    }
    check_vec(ctx, &file.gravity, "gravity", Sign::Any, dim)?;
    // Each name with the field and line that gave it, so that a duplicate names the first.
    let mut names: Vec<(String, String, usize)> = Vec::new();
    let mut check_new_name = |s: &Spanned<String>, field: &str| -> Result<(), SpecError> {
        let n = s.get_ref();
        check_name(n).map_err(|m| ctx.span(s, field, m))?;
        if n == "base" {
            return Err(ctx.span(
                s,
                field,
                format!("`{n}` is reserved: it is the fixed frame a first link's `parent` names"),
            ));
        }
        if let Some((_, first, line)) = names.iter().find(|(name, _, _)| name == n) {
            return Err(ctx.span(
                s,
                field,
                format!("duplicate name `{n}` (first given as {first}, line {line})"),
            ));
        }
        let (line, _) = line_column(ctx.text, s.span().start);
        names.push((n.clone(), field.to_string(), line));
        Ok(())
    };
    let link_names: Vec<&str> = file
        .links
        .iter()
        .map(|l| l.get_ref().name.get_ref().as_str())
        .collect();
    for (i, link) in file.links.iter().enumerate() {
        let l = link.get_ref();
        let f = |field: &str| format!("links[{i}].{field}");
        check_new_name(&l.name, &f("name"))?;
        let parent = l.parent.get_ref();
        if parent != "base" {
            match link_names.iter().position(|n| n == parent) {
                Some(p) if p < i => {}
                Some(_) => {
                    return Err(ctx.span(
                        &l.parent,
                        f("parent"),
                        format!(
                            "parent `{}` is defined below this link; list parents first",
                            shown(parent)
                        ),
                    ))
                }
                None => {
                    return Err(ctx.span(
                        &l.parent,
                        f("parent"),
                        format!(
                            "unknown parent `{}` (expected \"base\" or one of: {})",
                            shown(parent),
                            link_names[..i].join(", ")
                        ),
                    ))
                }
            }
        }
        if let Some(o) = &l.origin {
            check_vec(ctx, o, &f("origin"), Sign::Any, dim)?;
        }
        check_vec(ctx, &l.length, &f("length"), Sign::Any, dim)?;
        check_vec(ctx, &l.com, &f("com"), Sign::Any, dim)?;
        check_num(ctx, &l.mass, &f("mass"), Sign::NonNegative)?;
        if l.kind() == JointKind::Ball {
            check_ball(ctx, l, i, dim)?;
        }
        if l.kind() == JointKind::Free {
            check_free(ctx, file, l, i, dim)?;
        } else if i > 0 && file.links[0].get_ref().kind() == JointKind::Free && parent == "base" {
            return Err(ctx.span(
                &l.parent,
                f("parent"),
                format!(
                    "on a floating robot every link hangs from its body `{}` (the free joint), not from `base`",
                    file.links[0].get_ref().name.get_ref()
                ),
            ));
        }
        match (l.kind(), &l.axis) {
            (JointKind::Ball | JointKind::Free, _) => {}
            (JointKind::Prismatic, None) => {
                let at = l.joint.as_ref().expect("prismatic is written");
                return Err(ctx.span(
                    at,
                    f("axis"),
                    "a prismatic joint needs the `axis` it slides along (parent frame), e.g. `axis = [0.0, 1.0]`",
                ));
            }
            (JointKind::Revolute, Some(axis)) if dim == 2 => {
                return Err(ctx.span(
                    axis,
                    f("axis"),
                    "only a prismatic joint has an axis on a planar leg, where every revolute joint turns in the plane (add `joint = \"prismatic\"`, or remove `axis`)",
                ));
            }
            (_, Some(axis)) => {
                check_vec(ctx, axis, &f("axis"), Sign::Any, dim)?;
                if axis.get_ref().value.iter().all(|&x| x == 0.0) {
                    return Err(ctx.span(axis, f("axis"), "a joint's axis must not be zero"));
                }
            }
            (JointKind::Revolute, None) => {}
        }
        if let Some(o) = &l.orientation {
            if dim == 2 {
                return Err(ctx.span(
                    o,
                    f("orientation"),
                    "only a spatial leg's links have an orientation (a planar link's frame turns with its joint alone)",
                ));
            }
            let v = &o.get_ref().value;
            if v.len() != 4 {
                return Err(ctx.span(
                    o,
                    f("orientation"),
                    format!(
                        "has {} entries: an orientation is a quaternion [w, x, y, z]",
                        v.len()
                    ),
                ));
            }
            for &x in v {
                check_value(x, Sign::Any).map_err(|m| ctx.span(o, f("orientation"), m))?;
            }
            if v.iter().all(|&x| x == 0.0) {
                return Err(ctx.span(o, f("orientation"), "the quaternion must not be zero"));
            }
        }
        check_inertia(ctx, &l.inertia, &f("inertia"), dim)?;
        if let Some(d) = &l.damping {
            check_num(ctx, d, &f("damping"), Sign::NonNegative)?;
        }
        if let Some(a) = &l.actuator {
            let a = a.get_ref();
            check_num(
                ctx,
                &a.rotor_inertia,
                &f("actuator.rotor_inertia"),
                Sign::NonNegative,
            )?;
            check_num(
                ctx,
                &a.gear_ratio,
                &f("actuator.gear_ratio"),
                Sign::Positive,
            )?;
        }
    }
    if file.links.iter().all(|l| l.get_ref().actuator.is_none()) {
        return Err(ctx.span(
            &file.links[0].get_ref().name,
            "links",
            "no link has an `actuator`: a leg needs at least one motor (add `actuator = { rotor_inertia = …, gear_ratio = … }` to the links that have one)",
        ));
    }
    check_has_size(ctx, file)?;
    let check_point = |p: &PointSpec, field: &str, base: bool| -> Result<(), SpecError> {
        let link = p.link.get_ref();
        if base && link == "base" {
            // A point fixed in the base frame (a leg pinned to a stand, a foot held on the
            // ground): it has no tip to default to.
            return match &p.point {
                Some(pt) => check_vec(ctx, pt, &format!("{field}.point"), Sign::Any, dim),
                None => Err(ctx.span(
                    &p.link,
                    format!("{field}.point"),
                    "a point on the base needs its `point` (base frame)",
                )),
            };
        }
        if !link_names.contains(&link.as_str()) {
            return Err(ctx.span(
                &p.link,
                format!("{field}.link"),
                format!(
                    "unknown link `{}` (links: {})",
                    shown(link),
                    link_names.join(", ")
                ),
            ));
        }
        if let Some(pt) = &p.point {
            check_vec(ctx, pt, &format!("{field}.point"), Sign::Any, dim)?;
        }
        Ok(())
    };
    for (k, closure) in file.closures.iter().enumerate() {
        let c = closure.get_ref();
        check_new_name(&c.name, &format!("closures[{k}].name"))?;
        check_point(c.a.get_ref(), &format!("closures[{k}].a"), true)?;
        check_point(c.b.get_ref(), &format!("closures[{k}].b"), true)?;
        if let Some(d) = &c.distance {
            if dim == 2 {
                return Err(ctx.span(
                    d,
                    format!("closures[{k}].distance"),
                    "a distance (rod) closure is for spatial legs for now; on a planar leg a rod with pins at both ends is a link (give it a small mass) closed by a point closure",
                ));
            }
            check_num(ctx, d, &format!("closures[{k}].distance"), Sign::Positive)?;
        }
        if let (Some(_), Some(d)) = (&c.axis, &c.distance) {
            return Err(ctx.span(
                d,
                format!("closures[{k}].distance"),
                "a closure is a rod (distance) or a revolute joint (axis), not both",
            ));
        }
        if c.axis.is_none() {
            if let Some(ab) = &c.axis_b {
                return Err(ctx.span(
                    ab,
                    format!("closures[{k}].axis_b"),
                    "axis_b is the revolute closure's axis on link b: give `axis` (link a's) too",
                ));
            }
        }
        for (field, axis) in [("axis", &c.axis), ("axis_b", &c.axis_b)] {
            let Some(axis) = axis else { continue };
            if dim == 2 {
                return Err(ctx.span(
                    axis,
                    format!("closures[{k}].{field}"),
                    "a revolute closure is for spatial legs: on a planar leg every closure is a pin about the plane's normal already",
                ));
            }
            check_vec(ctx, axis, &format!("closures[{k}].{field}"), Sign::Any, dim)?;
            if axis.get_ref().value.iter().all(|&x| x == 0.0) {
                return Err(ctx.span(
                    axis,
                    format!("closures[{k}].{field}"),
                    "a revolute closure's axis must not be zero",
                ));
            }
        }
        if c.a.get_ref().link.get_ref() == c.b.get_ref().link.get_ref() {
            return Err(ctx.span(
                &c.b.get_ref().link,
                format!("closures[{k}].b.link"),
                "a closure joins points on two different links (or a link and the base)",
            ));
        }
    }
    check_point(file.foot.get_ref(), "foot", false)?;
    let check_link = |s: &Spanned<String>, field: String| -> Result<(), SpecError> {
        if link_names.contains(&s.get_ref().as_str()) {
            Ok(())
        } else {
            Err(ctx.span(
                s,
                field,
                format!(
                    "unknown link `{}` (links: {})",
                    shown(s.get_ref()),
                    link_names.join(", ")
                ),
            ))
        }
    };
    for (k, spring) in file.springs.iter().enumerate() {
        let s = spring.get_ref();
        let f = |field: &str| format!("springs[{k}].{field}");
        check_new_name(&s.name, &f("name"))?;
        check_link(&s.a, f("a"))?;
        let ball = |name: &Spanned<String>, field: String| -> Result<(), SpecError> {
            let kind = file
                .links
                .iter()
                .map(|l| l.get_ref())
                .find(|l| l.name.get_ref() == name.get_ref())
                .map(|l| l.kind());
            let many = match kind {
                Some(JointKind::Ball) => "a ball joint has three",
                Some(JointKind::Free) => "a free joint has six",
                _ => return Ok(()),
            };
            Err(ctx.span(
                name,
                field,
                format!("a spring acts on one coordinate: {many} (put it on a revolute joint)"),
            ))
        };
        ball(&s.a, f("a"))?;
        if let Some(b) = &s.b {
            check_link(b, f("b"))?;
            ball(b, f("b"))?;
            if b.get_ref() == s.a.get_ref() {
                return Err(ctx.span(
                    b,
                    f("b"),
                    "a coupling spring joins two different joints (leave out `b` for a spring on one joint)",
                ));
            }
        }
        check_num(ctx, &s.stiffness, &f("stiffness"), Sign::Positive)?;
        if let Some(r) = &s.rest {
            check_num(ctx, r, &f("rest"), Sign::Any)?;
        }
    }
    for (k, contact) in file.contacts.iter().enumerate() {
        let c = contact.get_ref();
        let f = |field: &str| format!("contacts[{k}].{field}");
        check_new_name(&c.name, &f("name"))?;
        check_link(&c.link, f("link"))?;
        if let Some(pt) = &c.point {
            check_vec(ctx, pt, &f("point"), Sign::Any, dim)?;
        }
        check_num(ctx, &c.friction, &f("friction"), Sign::NonNegative)?;
    }
    if let Some(g) = &file.ground {
        let g = g.get_ref();
        if let Some(n) = &g.normal {
            check_vec(ctx, n, "ground.normal", Sign::Any, dim)?;
            if n.get_ref().value.iter().all(|&x| x == 0.0) {
                return Err(ctx.span(n, "ground.normal", "the ground's normal must not be zero"));
            }
        }
        if let Some(o) = &g.offset {
            check_num(ctx, o, "ground.offset", Sign::Any)?;
        }
    }
    if let Some(home) = &file.home {
        let h = home.get_ref();
        let coordinates: usize = file
            .links
            .iter()
            .map(|l| l.get_ref().kind().coordinates())
            .sum();
        if h.len() != coordinates {
            let has = |k: JointKind| file.links.iter().any(|l| l.get_ref().kind() == k);
            let mut parts = vec![format!("{} links", file.links.len())];
            if has(JointKind::Free) {
                parts.push("six coordinates for the free joint".to_string());
            }
            if has(JointKind::Ball) {
                parts.push("three angles per ball joint".to_string());
            }
            let what = if coordinates > file.links.len() {
                format!("{coordinates} coordinates ({})", parts.join(", "))
            } else {
                format!("{} links", file.links.len())
            };
            return Err(ctx.span(
                home,
                "home",
                format!("lists {} joint values for {what}", h.len()),
            ));
        }
        for &v in h {
            check_value(v, Sign::Any).map_err(|m| ctx.span(home, "home", m))?;
        }
    }
    Ok(())
}

/// A ball joint: spatial legs only, with no axis (it turns about every axis), no motor
/// (a motor drives one axis) and no spring (a spring acts on one coordinate).
fn check_ball(ctx: &Ctx, l: &LinkSpec, i: usize, dim: usize) -> Result<(), SpecError> {
    let f = |field: &str| format!("links[{i}].{field}");
    let at = l.joint.as_ref().expect("ball is written");
    if dim == 2 {
        return Err(ctx.span(
            at,
            f("joint"),
            "a ball joint turns about three axes: only a spatial leg (gravity [x, y, z]) has one",
        ));
    }
    if let Some(axis) = &l.axis {
        return Err(ctx.span(
            axis,
            f("axis"),
            "a ball joint has no axis (it turns about every axis; turn its frame with `orientation`)",
        ));
    }
    if let Some(a) = &l.actuator {
        return Err(ctx.span(
            a,
            f("actuator"),
            "a motor drives one axis: put it on a revolute joint, not on a ball joint",
        ));
    }
    Ok(())
}

/// A free joint: the body of a spatial robot that floats. It is the first link and the
/// only one on `base` (checked at the other links), with no axis, motor or damping, and
/// no point of the spec is fixed in the base frame: the base frame is where the body's
/// chart is centred, not a place in the world.
fn check_free(
    ctx: &Ctx,
    file: &SpecFile,
    l: &LinkSpec,
    i: usize,
    dim: usize,
) -> Result<(), SpecError> {
    let f = |field: &str| format!("links[{i}].{field}");
    let at = l.joint.as_ref().expect("free is written");
    if dim == 2 {
        return Err(ctx.span(
            at,
            f("joint"),
            "a free joint moves in six coordinates: only a spatial robot (gravity [x, y, z]) has one (a planar body floats on two prismatic joints and a revolute one)",
        ));
    }
    if i > 0 {
        return Err(ctx.span(
            at,
            f("joint"),
            "a free joint is the robot's body: list it first, on `base`",
        ));
    }
    if l.parent.get_ref() != "base" {
        return Err(ctx.span(
            &l.parent,
            f("parent"),
            "a free joint is the robot's body: its parent is `base`",
        ));
    }
    if let Some(axis) = &l.axis {
        return Err(ctx.span(
            axis,
            f("axis"),
            "a free joint has no axis (it moves along and about every axis)",
        ));
    }
    if let Some(a) = &l.actuator {
        return Err(ctx.span(
            a,
            f("actuator"),
            "a free joint carries no motor: nothing in the world pushes the body but its legs and the ground",
        ));
    }
    if let Some(d) = &l.damping {
        if d.get_ref().value != 0.0 {
            return Err(ctx.span(
                d,
                f("damping"),
                "a free joint has no damping: it is not a joint to anything",
            ));
        }
    }
    if let Some(o) = &l.origin {
        return Err(ctx.span(
            o,
            f("origin"),
            "a free joint's position is the body's state (the runtime's position), not a constant of the spec",
        ));
    }
    if let Some(o) = &l.orientation {
        return Err(ctx.span(
            o,
            f("orientation"),
            "a free joint's orientation is the body's state (the runtime's quaternion), not a constant of the spec",
        ));
    }
    if let Some(g) = &file.ground {
        return Err(ctx.span(
            g,
            "ground",
            "a floating robot's ground is the world's, given at run time (leg_models::robot), not a plane of the spec's base frame",
        ));
    }
    let coordinates: usize = file
        .links
        .iter()
        .map(|l| l.get_ref().kind().coordinates())
        .sum();
    if let Some(h) = &file.home {
        // (A home of the wrong length is said below, counting the coordinates.)
        if h.get_ref().len() == coordinates && h.get_ref().iter().take(6).any(|&x| x != 0.0) {
            return Err(ctx.span(
                h,
                "home",
                "a free joint's six home values are the chart's centre: zeros (the body's pose is the state)",
            ));
        }
    }
    for (k, c) in file.closures.iter().enumerate() {
        for (end, p) in [("a", &c.get_ref().a), ("b", &c.get_ref().b)] {
            if p.get_ref().link.get_ref() == "base" {
                return Err(ctx.span(
                    &p.get_ref().link,
                    format!("closures[{k}].{end}.link"),
                    "a floating robot has no point fixed in the world: name the link this point is on",
                ));
            }
        }
    }
    Ok(())
}

/// A leg whose every length, origin, centre of mass and point is zero has all its points
/// at the base: nothing moves when a joint turns (J and M vanish).
fn check_has_size(ctx: &Ctx, file: &SpecFile) -> Result<(), SpecError> {
    let zero = |v: &Spanned<Vector>| v.get_ref().value.iter().all(|&x| x == 0.0);
    let point_zero = |p: &PointSpec| p.point.as_ref().is_none_or(zero);
    let all_zero = file.links.iter().all(|l| {
        let l = l.get_ref();
        zero(&l.length)
            && zero(&l.com)
            && l.origin.as_ref().is_none_or(zero)
            && l.kind() == JointKind::Revolute
    }) && file.closures.iter().all(|c| {
        let c = c.get_ref();
        point_zero(c.a.get_ref()) && point_zero(c.b.get_ref())
    }) && point_zero(file.foot.get_ref());
    if all_zero {
        return Err(ctx.span(
            &file.links[0].get_ref().length,
            "links[0].length",
            "every length, origin, centre of mass and point in the spec is zero: the leg has no size (every point is at the base, so no joint moves anything)",
        ));
    }
    Ok(())
}

#[derive(Clone, Copy)]
enum Sign {
    Any,
    NonNegative,
    Positive,
}

/// The largest magnitude a number in a spec may have (in its unit: m, kg, kg m², …).
/// Beyond it the derivation's products overflow; no leg comes near it.
pub const MAX_MAGNITUDE: f64 = 1e6;

fn check_value(v: f64, sign: Sign) -> Result<(), String> {
    if !v.is_finite() {
        return Err(format!("must be a finite number, got {v}"));
    }
    if v.abs() > MAX_MAGNITUDE {
        return Err(format!(
            "must be at most {MAX_MAGNITUDE:e} in magnitude, got {v:e}"
        ));
    }
    match sign {
        Sign::Positive if v <= 0.0 => Err(format!("must be positive, got {v}")),
        Sign::NonNegative if v < 0.0 => Err(format!("must not be negative, got {v}")),
        _ => Ok(()),
    }
}

fn check_num(ctx: &Ctx, n: &Spanned<Num>, field: &str, sign: Sign) -> Result<(), SpecError> {
    check_value(n.get_ref().value, sign).map_err(|m| ctx.span(n, field, m))
}

/// A link's inertia about its centre of mass: one number on a planar leg; on a spatial
/// leg three (principal) or six entries `[ixx, iyy, izz, ixy, ixz, iyz]` of a tensor that
/// a rigid body can have (positive semi-definite, each principal moment at most the sum
/// of the other two, as MuJoCo checks).
fn check_inertia(
    ctx: &Ctx,
    n: &Spanned<Entries>,
    field: &str,
    dim: usize,
) -> Result<(), SpecError> {
    let v = &n.get_ref().value.0;
    let allowed: &[usize] = if dim == 2 { &[1] } else { &[3, 6] };
    if !allowed.contains(&v.len()) {
        let why = if dim == 2 {
            "a planar link's inertia is one number (about the axis out of the plane)".to_string()
        } else {
            "a spatial link's inertia is [ixx, iyy, izz] or [ixx, iyy, izz, ixy, ixz, iyz] (link frame, about the centre of mass)".to_string()
        };
        return Err(ctx.span(n, field, format!("has {} entries: {why}", v.len())));
    }
    for (i, &x) in v.iter().enumerate() {
        let sign = if i < 3 { Sign::NonNegative } else { Sign::Any };
        check_value(x, sign).map_err(|m| ctx.span(n, field, m))?;
    }
    if v.len() > 1 {
        let (xy, xz, yz) = if v.len() == 6 {
            (v[3], v[4], v[5])
        } else {
            (0.0, 0.0, 0.0)
        };
        let moments = symmetric_eigenvalues([v[0], v[1], v[2]], [xy, xz, yz]);
        let scale = moments[2].abs().max(f64::MIN_POSITIVE);
        if moments[0] < -1e-12 * scale {
            return Err(ctx.span(
                n,
                field,
                format!(
                    "is not positive semi-definite (principal moments {:.6e}, {:.6e}, {:.6e})",
                    moments[0], moments[1], moments[2]
                ),
            ));
        }
        if moments[2] > (moments[0] + moments[1]) * (1.0 + 1e-9) {
            return Err(ctx.span(
                n,
                field,
                format!("no rigid body has it: its largest principal moment {:.6e} exceeds the sum of the other two ({:.6e} + {:.6e})", moments[2], moments[0], moments[1]),
            ));
        }
    }
    Ok(())
}

/// The eigenvalues, ascending, of the symmetric 3 × 3 matrix with diagonal `d` and
/// off-diagonal `[xy, xz, yz]` (the trigonometric closed form; the generator needs no
/// linear-algebra crate for it).
fn symmetric_eigenvalues(d: [f64; 3], o: [f64; 3]) -> [f64; 3] {
    let [xy, xz, yz] = o;
    let off = xy * xy + xz * xz + yz * yz;
    let mut e = if off == 0.0 {
        d
    } else {
        let mean = (d[0] + d[1] + d[2]) / 3.0;
        let (a, b, c) = (d[0] - mean, d[1] - mean, d[2] - mean);
        let p = ((a * a + b * b + c * c + 2.0 * off) / 6.0).sqrt();
        // det((A − mean I) / p) / 2, clamped to acos's domain against rounding.
        let det = a * (b * c - yz * yz) - xy * (xy * c - yz * xz) + xz * (xy * yz - b * xz);
        let r = (det / (2.0 * p * p * p)).clamp(-1.0, 1.0);
        let phi = r.acos() / 3.0;
        let largest = mean + 2.0 * p * phi.cos();
        let smallest = mean + 2.0 * p * (phi + 2.0 * std::f64::consts::PI / 3.0).cos();
        [smallest, 3.0 * mean - largest - smallest, largest]
    };
    e.sort_by(f64::total_cmp);
    e
}

/// `dim` entries (the spec's dimension), each a number of `sign`.
fn check_vec(
    ctx: &Ctx,
    n: &Spanned<Vector>,
    field: &str,
    sign: Sign,
    dim: usize,
) -> Result<(), SpecError> {
    let len = n.get_ref().value.len();
    if len != dim {
        let (kind, form) = if dim == 2 {
            ("planar", "[x, y]")
        } else {
            ("spatial", "[x, y, z]")
        };
        return Err(ctx.span(
            n,
            field,
            format!("has {len} entries: the leg is {kind} (its gravity has {dim}), so its vectors are {form}"),
        ));
    }
    for &v in &n.get_ref().value {
        check_value(v, sign).map_err(|m| ctx.span(n, field, m))?;
    }
    Ok(())
}
