//! `cargo xtask analyze`: design measures of legs over their workspaces
//! (`leg_models::analysis`), side by side or along a parameter sweep; writes
//! `analysis.json`, one CSV per design's grid and a self-contained `report.html`.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use leg_models::analysis::summary::{
    default_body, default_limits, gear_ratio, limit_out_of_range, summary, COLUMNS, MAX_LIMIT,
    MOTOR_SPEED, MOTOR_TORQUE,
};
use leg_models::analysis::workspace::{
    assembly_modes, workspace_volume, GridOptions, NodeState, Segment, SlicePlane, Workspace,
};
use leg_models::analysis::{
    capacity_sets, AnalysisError, BodyCoupling, CapacitySets, LegFrame, MotorKinematics,
    MotorLimits,
};
use leg_models::assembly::{project_position, Tolerance};
use leg_models::nalgebra::{SMatrix, SVector};
use leg_models::{LegDynamics, LegModel, ParameterError, Parameters};
use rayon::prelude::*;
use serde_json::{json, Value};
use xtask::cli::args::AnalyzeArgs;
use xtask::cli::progress::Progress;
use xtask::cli::{check_targets, write_all, Error};

pub use design::{table, Design, View};

mod design;
mod report;

/// The command's settings, checked.
pub struct Settings {
    sets: Vec<(String, f64)>,
    sweep: Option<Sweep>,
    torque: Option<Vec<f64>>,
    speed: Option<Vec<f64>>,
    body_mass: Option<f64>,
    motor_range: Option<(f64, f64)>,
    nodes: usize,
    branches: bool,
    /// A spatial leg's slice (`--slice`).
    slice: Option<SlicePlane>,
    /// Nodes per side of a spatial leg's volume (`--volume`).
    volume: Option<usize>,
    /// Grid nodes the run's designs hold (checked against [`MAX_NODES`]).
    planned_nodes: AtomicUsize,
    pub out: PathBuf,
}

#[derive(Clone, Debug)]
struct Sweep {
    /// The parameters swept together (`lower_a_length_x,lower_b_length_x=…`), and how
    /// they are shown.
    names: Vec<String>,
    name: String,
    from: f64,
    to: f64,
    count: usize,
}

impl Sweep {
    /// The swept values, rounded to 12 significant digits (`0.22`, not
    /// `0.22000000000000003`).
    fn values(&self) -> Vec<f64> {
        (0..self.count)
            .map(|i| {
                let x = self.from + (self.to - self.from) * i as f64 / (self.count - 1) as f64;
                format!("{x:.11e}").parse().unwrap_or(x)
            })
            .collect()
    }
}

/// Guesses of the passive joints that look for a leg's other assembly branches.
const BRANCH_TRIES: usize = 64;

/// The most grid nodes over all the designs of one run.
const MAX_NODES: usize = 10_000_000;

fn finite(flag: &str, text: &str, what: &str) -> Result<f64, Error> {
    match text.trim().parse::<f64>() {
        Ok(x) if x.is_finite() => Ok(x),
        _ => Err(Error::usage(format!(
            "`{flag}`: `{}` is not a finite number ({what})",
            xtask::gen::spec::shown(text)
        ))),
    }
}

impl Settings {
    pub fn from_args(a: &AnalyzeArgs, root: &std::path::Path) -> Result<Settings, Error> {
        let mut sets = Vec::new();
        for s in &a.sets {
            let Some((name, value)) = s.split_once('=') else {
                return Err(Error::usage(format!(
                    "`--set {}`: expected NAME=VALUE (e.g. lower_a_length_x=0.22)",
                    xtask::gen::spec::shown(s)
                )));
            };
            let value = finite("--set", value, "the parameter's value")?;
            parameter_value("--set", name.trim(), value)?;
            sets.push((name.trim().to_string(), value));
        }
        let sweep = match &a.sweep {
            None => None,
            Some(s) => {
                let bad = || {
                    Error::usage(format!(
                        "`--sweep {}`: expected NAME=FROM:TO:N (e.g. lower_a_length_x=0.16:0.26:6), N from 2 to 200",
                        xtask::gen::spec::shown(s)
                    ))
                };
                let (name, range) = s.split_once('=').ok_or_else(bad)?;
                let parts: Vec<&str> = range.split(':').collect();
                let [from, to, n] = parts[..] else {
                    return Err(bad());
                };
                let from = finite("--sweep", from, "FROM")?;
                let to = finite("--sweep", to, "TO")?;
                let count: usize = n.trim().parse().map_err(|_| bad())?;
                if !(2..=200).contains(&count) || from == to {
                    return Err(bad());
                }
                if a.models.len() > 1 {
                    return Err(Error::usage(
                        "`--sweep` sweeps one model's parameter: give one model",
                    ));
                }
                if a.branches {
                    return Err(Error::usage(
                        "`--branches` and `--sweep` do not go together: sweep one branch (the home pose's), or compare the branches of one design",
                    ));
                }
                let names: Vec<String> = name
                    .split(',')
                    .map(|n| n.trim().to_string())
                    .filter(|n| !n.is_empty())
                    .collect();
                if names.is_empty() {
                    return Err(bad());
                }
                for n in &names {
                    parameter_value("--sweep", n, from.min(to))?;
                    parameter_value("--sweep", n, from.max(to))?;
                    if sets.iter().any(|(set, _)| set == n) {
                        return Err(Error::usage(format!(
                            "`{n}` is both set (`--set`) and swept (`--sweep`): the sweep gives its values; drop the `--set`"
                        )));
                    }
                }
                let sweep = Sweep {
                    names,
                    name: name.trim().to_string(),
                    from,
                    to,
                    count,
                };
                // Every design is a real one, and its own: a range narrower than the
                // labels' 12 digits made designs of one label whose CSVs overwrote each
                // other. (Its ends obey the parameters' bound, checked above, so every
                // value between them is finite: a range of 1e308 made NaN and inf.)
                let values = sweep.values();
                if values.windows(2).any(|w| w[0] == w[1]) {
                    return Err(Error::usage(format!(
                        "`--sweep {}`: {count} values from {from} to {to} are not distinct at 12 significant digits; widen the range or sweep fewer values",
                        xtask::cli::shown(s)
                    )));
                }
                Some(sweep)
            }
        };
        let list = |flag: &str,
                    text: &Option<String>,
                    what: &str|
         -> Result<Option<Vec<f64>>, Error> {
            let Some(text) = text else { return Ok(None) };
            let values = text
                .split(',')
                .map(|v| finite(flag, v, what))
                .collect::<Result<Vec<_>, _>>()?;
            if values.iter().any(|&v| v <= 0.0) {
                return Err(Error::usage(format!(
                    "`{flag}`: every {what} must be positive"
                )));
            }
            // A limit of 1e308 overflowed the polygons and was reported as physics.
            if let Some(v) = values.iter().find(|&&v| v > MAX_LIMIT) {
                return Err(Error::usage(format!(
                        "`{flag}`: {v:e} is beyond {MAX_LIMIT:e}: a {what} must be in (0, {MAX_LIMIT:e}] (larger ones overflow the force and speed polygons)"
                    )));
            }
            Ok(Some(values))
        };
        let motor_range = match &a.motor_range {
            None => None,
            Some(r) => {
                let bad = || {
                    Error::usage(format!(
                        "`--motor-range {}`: expected LO:HI in rad with LO < HI (e.g. -3.2:0.5)",
                        xtask::gen::spec::shown(r)
                    ))
                };
                let (lo, hi) = r.split_once(':').ok_or_else(bad)?;
                let (lo, hi) = (
                    finite("--motor-range", lo, "LO")?,
                    finite("--motor-range", hi, "HI")?,
                );
                if lo >= hi {
                    return Err(bad());
                }
                Some((lo, hi))
            }
        };
        if let Some(m) = a
            .models
            .iter()
            .enumerate()
            .find_map(|(i, m)| a.models[..i].contains(m).then_some(m))
        {
            return Err(Error::usage(format!(
                "`{m}` is given twice: each design once"
            )));
        }
        // Every design's grid and CSV are held until all are done (nothing is written
        // before): bound their total, about 250 bytes a node.
        let designs = sweep.as_ref().map_or(a.models.len(), |s| s.count);
        let total =
            ((a.nodes as usize).pow(2) + a.volume.map_or(0, |n| (n as usize).pow(3))) * designs;
        if total > MAX_NODES {
            return Err(Error::usage(format!(
                "`--nodes {}` for {designs} designs is {:.1} million grid nodes; one run takes at most {} million (held in memory until every design is done): fewer nodes or designs",
                a.nodes,
                total as f64 / 1e6,
                MAX_NODES / 1_000_000
            )));
        }
        Ok(Settings {
            sets,
            sweep,
            torque: list("--torque-limit", &a.torque_limit, "torque limit")?,
            speed: list("--speed-limit", &a.speed_limit, "speed limit")?,
            body_mass: a.body_mass,
            motor_range,
            nodes: a.nodes as usize,
            branches: a.branches,
            slice: a.slice.as_deref().map(|s| match s {
                "yz" => SlicePlane::FRONTAL,
                "xy" => SlicePlane::TRANSVERSE,
                _ => SlicePlane::SAGITTAL,
            }),
            volume: a.volume.map(|n| n as usize),
            planned_nodes: AtomicUsize::new(total),
            out: a
                .out
                .clone()
                .unwrap_or_else(|| xtask::cli::target_dir(root).join("analyze")),
        })
    }

    /// `--slice` and `--volume` are for spatial legs: refused for the planar `model`.
    pub fn spatial_only(&self, model: &str) -> Result<(), Error> {
        for (flag, given) in [
            ("--slice", self.slice.is_some()),
            ("--volume", self.volume.is_some()),
        ] {
            if given {
                return Err(Error::usage(format!(
                    "`{flag}` is for spatial legs: `{model}` is planar (its workspace is its own plane)"
                )));
            }
        }
        Ok(())
    }

    pub fn sweeping(&self) -> Option<&str> {
        self.sweep.as_ref().map(|s| s.name.as_str())
    }
}

fn index_of<L, const NQ: usize, const NC: usize, const NU: usize>(
    name: &str,
) -> Result<usize, Error>
where
    L: LegDynamics<NQ, NC, NU>,
{
    L::Params::<f64>::NAMES
        .iter()
        .position(|n| *n == name)
        .ok_or_else(|| {
            let e = ParameterError::Unknown {
                name,
                leg: L::NAME,
                known: L::Params::<f64>::NAMES,
            };
            match e.suggestion() {
                Some(_) => Error::usage(e.to_string()),
                // Nothing close: the names themselves, so that the next try can be right.
                None => Error::usage(format!(
                    "leg `{}` has no parameter `{}`; its parameters: {}",
                    L::NAME,
                    xtask::cli::shown(name),
                    L::Params::<f64>::NAMES.join(", ")
                )),
            }
        })
}

/// A parameter's value obeys the spec's rules (the runtime's check, `Leg::set_parameter`'s):
/// finite, at most 1e6, masses, inertias and dampings not negative, gear ratios positive.
fn parameter_value(flag: &str, name: &str, value: f64) -> Result<(), Error> {
    leg_models::check_parameter(name, value).map_err(|e| Error::usage(format!("`{flag}`: {e}")))
}

fn number(x: f64) -> Value {
    if x.is_finite() {
        json!(x)
    } else {
        Value::Null
    }
}

/// Analyses model `L` under `settings`: one design, or one per swept value (in parallel).
pub fn run<L, const NQ: usize, const NC: usize, const NU: usize, const ND: usize, const NP: usize>(
    settings: &Settings,
    progress: &Mutex<(Progress, u64)>,
    grid: Grid<L::Params<f64>, NQ, NU, ND>,
) -> Result<Vec<Design>, Error>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
    L::Params<f64>: Send + Sync,
{
    // A target in the way is found before the designs are computed, not after.
    check_targets(&settings.out, &["analysis.json", "report.html"]).map_err(Error::Failed)?;
    let mut base = L::Params::<f64>::default();
    for (name, value) in &settings.sets {
        let i = index_of::<L, NQ, NC, NU>(name)?;
        base.set(i, *value);
    }
    let sweep = match &settings.sweep {
        Some(s) => Some((
            s.names
                .iter()
                .map(|n| index_of::<L, NQ, NC, NU>(n))
                .collect::<Result<Vec<_>, _>>()?,
            s,
        )),
        None => None,
    };
    if ND == 2 {
        settings.spatial_only(L::NAME)?;
    }
    for list in [&settings.torque, &settings.speed].into_iter().flatten() {
        if list.len() != 1 && list.len() != NU {
            return Err(Error::usage(format!(
                "`{}` has {} motors: give one limit or {NU} (got {})",
                L::NAME,
                NU,
                list.len()
            )));
        }
    }
    if settings.branches {
        let frame = LegFrame::of::<L, NC, NU>();
        let mut q = SVector::from(L::HOME);
        let modes =
            match project_position::<L, f64, NQ, NC, NU>(&base, &mut q, &Tolerance::default()) {
                Ok(()) => assembly_modes::<L, NQ, NC, NU>(&base, &q, &frame, BRANCH_TRIES),
                // The one design says why the home pose does not assemble.
                Err(_) => Vec::new(),
            };
        // The budget counted one design a model: the branches add theirs.
        let extra = modes.len().saturating_sub(1) * settings.nodes * settings.nodes;
        let planned = settings.planned_nodes.fetch_add(extra, Ordering::Relaxed) + extra;
        if planned > MAX_NODES {
            return Err(Error::usage(format!(
                "`--branches`: `{}` has {} branches; with `--nodes {}` the run would hold {:.1} million grid nodes, at most {} million: fewer nodes or models",
                L::NAME,
                modes.len(),
                settings.nodes,
                planned as f64 / 1e6,
                MAX_NODES / 1_000_000
            )));
        }
        let designs: Vec<Design> = if modes.is_empty() {
            vec![design::<L, NQ, NC, NU, ND, NP>(
                &base, settings, None, None, grid,
            )]
        } else {
            modes
                .par_iter()
                .enumerate()
                .map(|(b, q)| {
                    design::<L, NQ, NC, NU, ND, NP>(&base, settings, None, Some((b, q)), grid)
                })
                .collect()
        };
        tick(progress);
        return Ok(designs);
    }
    let values: Vec<Option<f64>> = match &sweep {
        Some((_, s)) => s.values().into_iter().map(Some).collect(),
        None => vec![None],
    };
    let designs = values
        .par_iter()
        .map(|&v| {
            let mut p = base;
            if let (Some((indices, _)), Some(v)) = (&sweep, v) {
                for &i in indices {
                    p.set(i, v);
                }
            }
            let d = design::<L, NQ, NC, NU, ND, NP>(
                &p,
                settings,
                sweep.as_ref().map(|(_, s)| (*s, v.unwrap_or(f64::NAN))),
                None,
                grid,
            );
            tick(progress);
            d
        })
        .collect();
    Ok(designs)
}

/// One more unit of the progress bar done.
fn tick(progress: &Mutex<(Progress, u64)>) {
    let mut guard = progress.lock().unwrap_or_else(|e| e.into_inner());
    guard.1 += 1;
    let done = guard.1;
    guard.0.set(done);
}

fn design<L, const NQ: usize, const NC: usize, const NU: usize, const ND: usize, const NP: usize>(
    p: &L::Params<f64>,
    settings: &Settings,
    swept: Option<(&Sweep, f64)>,
    branch: Option<(usize, &SVector<f64, NQ>)>,
    grid: Grid<L::Params<f64>, NQ, NU, ND>,
) -> Design
where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    let label = match (swept, branch) {
        (Some((s, v)), _) => format!("{} {}={v}", L::NAME, s.name),
        (None, Some((0, _))) => format!("{} branch 1 (home)", L::NAME),
        (None, Some((b, _))) => format!("{} branch {}", L::NAME, b + 1),
        (None, None) => L::NAME.to_string(),
    };
    let file_stem = match swept {
        Some((s, v)) => format!(
            "{}_{}_{}",
            L::NAME,
            s.names[0],
            format!("{v}").replace(['-', '.'], "_")
        ),
        None => match branch {
            Some((b, _)) => format!("{}_branch_{}", L::NAME, b + 1),
            None => L::NAME.to_string(),
        },
    };
    let frame = LegFrame::of::<L, NC, NU>();
    let pick = |given: &Option<Vec<f64>>, k: usize, default: f64| match given {
        Some(v) if v.len() == 1 => v[0],
        Some(v) => v[k],
        None => default,
    };
    let defaults = default_limits::<L, NQ, NC, NU>(p);
    let limits = MotorLimits {
        torque: SVector::<f64, NU>::from_fn(|k, _| pick(&settings.torque, k, defaults.torque[k])),
        speed: SVector::<f64, NU>::from_fn(|k, _| pick(&settings.speed, k, defaults.speed[k])),
    };
    let mut changed = serde_json::Map::new();
    for (name, value) in &settings.sets {
        changed.insert(name.clone(), json!(value));
    }
    if let Some((s, v)) = swept {
        for name in &s.names {
            changed.insert(name.clone(), json!(v));
        }
    }
    let coupling = BodyCoupling::new::<L, f64, NQ, NC, NU>(p);
    let body = default_body(&frame, coupling.as_ref(), settings.body_mass);
    let body_mass = match body {
        leg_models::analysis::Body::Translating { mass } => Some(mass),
        leg_models::analysis::Body::Fixed => None,
    };
    let held: Vec<&str> = (0..NQ)
        .filter(|&j| frame.held[j])
        .map(|j| L::JOINT_NAMES[j])
        .collect();
    let mut json = json!({
        "model": L::NAME,
        "label": label,
        "parameters": changed,
        "frame": {
            "body_joints_held": held,
            "mobility": frame.mobility,
            "motors": NU,
            "actuated": L::ACTUATED.iter().map(|&a| L::JOINT_NAMES[a]).collect::<Vec<_>>(),
        },
        "torque_limit": limits.torque.as_slice(),
        "speed_limit": limits.speed.as_slice(),
        "body": if frame.has_body() {
            json!({"kind": "the spec's own body joints", "joints": held})
        } else {
            json!({"kind": "translating", "mass_kg": body_mass.map_or(Value::Null, number),
                   "leg_mass_kg": coupling.as_ref().map_or(Value::Null, |c| number(c.leg_mass))})
        },
    });
    let mut why = serde_json::Map::new();
    // A default limit from a gear ratio out of range (1e-200 made a speed limit of 1e202
    // rad/s and a dash with no reason): the design says so and computes nothing.
    {
        if let Some((kind, unit, k, v)) = limit_out_of_range(&limits) {
            json["error"] = json!(format!(
                "the {kind} limit of motor {} ({}) is {v:.3e} {unit}, from its gear ratio {:e}: beyond (0, {MAX_LIMIT:e}]; give --{kind}-limit or a gear ratio in range",
                k + 1,
                L::JOINT_NAMES[L::ACTUATED[k]],
                gear_ratio::<L, NQ, NC, NU>(p, k)
            ));
            return Design {
                label,
                file_stem,
                swept: swept.map(|s| s.1),
                json,
                csv: None,
                view: None,
            };
        }
    }
    let mut q = branch.map_or(SVector::from(L::HOME), |(_, q)| *q);
    if let Err(e) = project_position::<L, f64, NQ, NC, NU>(p, &mut q, &Tolerance::default()) {
        json["error"] = json!(format!(
            "the home pose does not assemble with these parameters: {e}"
        ));
        return Design {
            label,
            file_stem,
            swept: swept.map(|s| s.1),
            json,
            csv: None,
            view: None,
        };
    }
    let foot = L::foot_position(&q, p);
    json["stance"] = json!({
        "q": q.as_slice(),
        "foot": foot.as_slice(),
        "what": match branch {
            Some((b, _)) if b > 0 => format!("assembly branch {} at the home pose's motor angles", b + 1),
            _ => "the spec's home pose, assembled".to_string(),
        },
    });
    let options = GridOptions {
        nodes: settings.nodes,
        window: None,
        plane: settings.slice,
        motor_range: settings.motor_range.map(|r| [r; NU]),
        limits,
    };
    let s = summary::<L, NQ, NC, NU, ND, NP>(p, &q, &frame, &body, coupling.as_ref(), &options);
    // The row and the reasons for its dashes are the library's (a sweep in Python gives
    // the same).
    let mut table = serde_json::Map::new();
    for (key, value) in COLUMNS.iter().zip(s.row(&frame)) {
        table.insert((*key).into(), number(value));
    }
    for (key, reason) in COLUMNS.iter().zip(s.reasons(&frame)) {
        if let Some(reason) = reason {
            why.insert((*key).into(), json!(reason));
        }
    }
    // The foot's inertia needs no motor coordinates: a leg its motors do not determine
    // (springs, a free rod) still has it.
    if let Some(inv) = &s.inverse_inertia {
        json["stance"]["inverse_inertia_free"] = matrix(inv);
    }
    if let Ok(m) = &s.measures {
        json["stance"]["inverse_inertia_locked"] = matrix(&m.inverse_inertia_locked);
        json["stance"]["foot_jacobian_motor"] = matrix(&m.kinematics.foot_jacobian);
        capacity_json::<L, NQ, NC, NU, ND>(p, &q, &frame, &m.kinematics, &limits, &mut json);
    }
    let seconds = s.workspace_seconds;
    let part = grid(p, &q, &frame, settings, s.workspace, seconds, &file_stem);
    table.extend(part.table);
    why.extend(part.why);
    for (key, value) in part.json {
        json[key] = value;
    }
    // A dash always has its reason: a measure that is not a number and has none overflowed.
    for (key, value) in &table {
        if value.is_null() && !why.contains_key(key) {
            why.insert(
                key.clone(),
                json!("overflow: beyond f64's range with these parameters and limits"),
            );
        }
    }
    json["table"] = Value::Object(table);
    json["not_computed"] = Value::Object(why);
    Design {
        label,
        file_stem,
        swept: swept.map(|s| s.1),
        json,
        csv: part.csv,
        view: part.view,
    }
}

/// A small matrix as rows.
fn matrix<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> Value {
    json!((0..R)
        .map(|r| (0..C).map(|c| m[(r, c)]).collect::<Vec<_>>())
        .collect::<Vec<_>>())
}

/// The force and speed sets at the stance pose: polygons in the plane, the force
/// polytope and the speed zonotope's volume in space.
fn capacity_json<L, const NQ: usize, const NC: usize, const NU: usize, const ND: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    kin: &MotorKinematics<f64, NQ, NU, ND>,
    limits: &MotorLimits<f64, NU>,
    json: &mut Value,
) where
    L: LegDynamics<NQ, NC, NU>,
{
    match capacity_sets::<L, f64, NQ, NC, NU, ND>(p, q, frame, kin, limits) {
        Ok(CapacitySets::Planar { force, speed }) => {
            let rows = |poly: &leg_models::analysis::Polygon<f64>| {
                json!(poly
                    .vertices()
                    .iter()
                    .map(|v| [v[0], v[1]])
                    .collect::<Vec<_>>())
            };
            json["stance"]["force_polygon_n"] = rows(&force);
            json["stance"]["speed_polygon_m_s"] = rows(&speed);
        }
        Ok(CapacitySets::Spatial {
            force,
            speed_volume,
        }) => {
            json["stance"]["force_polytope_n"] = json!(force
                .vertices()
                .iter()
                .map(|v| [v[0], v[1], v[2]])
                .collect::<Vec<_>>());
            json["stance"]["force_polytope_volume_n3"] = number(force.volume());
            json["stance"]["speed_zonotope_volume_m3_s3"] = number(speed_volume);
        }
        // The table says why (its push and speed have the same reason).
        Err(_) => {}
    }
}

/// What a design's grid adds to it: measures for the table (or their reasons), fields of
/// its JSON, its CSV and what the report draws.
pub struct GridPart {
    table: serde_json::Map<String, Value>,
    why: serde_json::Map<String, Value>,
    json: Vec<(&'static str, Value)>,
    csv: Option<String>,
    view: Option<View>,
}

/// How a design's grid is computed, by the leg's dimension ([`planar_grid`], [`spatial_grid`]).
/// It is handed the workspace grid the design's summary computed, and its time (s).
pub type Grid<P, const NQ: usize, const NU: usize, const ND: usize> = fn(
    &P,
    &SVector<f64, NQ>,
    &LegFrame<NQ>,
    &Settings,
    Result<Workspace<NQ, NU, ND>, AnalysisError>,
    f64,
    &str,
) -> GridPart;

/// A spatial leg's workspace: the grid of [`mapped`] in its slice (`--slice`, sagittal by
/// default), or the reason it has none.
pub fn spatial_grid<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    settings: &Settings,
    ws: Result<Workspace<NQ, NU, 3>, AnalysisError>,
    seconds: f64,
    file_stem: &str,
) -> GridPart
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    let mut part = ws
        .map(|ws| mapped::<L, NQ, NC, NU, 3, NP>(p, q, ws, seconds, file_stem))
        .unwrap_or_else(|e| unmapped(&e));
    if let Some(nodes) = settings.volume {
        let range = settings.motor_range.map(|r| [r; NU]);
        let started = Instant::now();
        match workspace_volume::<L, NQ, NC, NU, NP>(p, q, frame, nodes, range.as_ref()) {
            Ok(v) => {
                part.table
                    .insert("workspace_volume_m3".into(), number(v.volume));
                part.json.push((
                    "volume",
                    json!({
                        "nodes_per_side": v.nodes,
                        "origin": v.origin,
                        "step_m": v.step,
                        "reached": v.reached,
                        "volume_m3": v.volume,
                        "seconds": started.elapsed().as_secs_f64(),
                    }),
                ));
            }
            Err(e) => {
                part.table.insert("workspace_volume_m3".into(), Value::Null);
                part.why
                    .insert("workspace_volume_m3".into(), json!(e.to_string()));
            }
        }
    }
    part
}

/// A planar leg's workspace: the grid of [`mapped`], or a one-motor leg's foot path.
pub fn planar_grid<L, const NQ: usize, const NC: usize, const NU: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    settings: &Settings,
    ws: Result<Workspace<NQ, NU>, AnalysisError>,
    seconds: f64,
    file_stem: &str,
) -> GridPart
where
    L: LegModel<NQ, NC, NU>,
{
    let e = match ws {
        Ok(ws) => return mapped::<L, NQ, NC, NU, 2, NC>(p, q, ws, seconds, file_stem),
        Err(e) => e,
    };
    let mut part = unmapped(&e);
    // A one-motor linkage's workspace is the path of its foot.
    let path = leg_models::analysis::workspace::foot_path::<L, NQ, NC, NU>(
        p,
        q,
        frame,
        360,
        settings.motor_range,
    );
    if let Ok(path) = path {
        part.json.push((
            "foot_path",
            json!({
                "full_turn": path.full_turn,
                "length_m": path.length,
                "motor_angles": path.angles,
                "feet": path.feet,
            }),
        ));
        let mut v = view::<L, NQ, NC, NU, 2, NC>(p, q, None);
        v.path = path.feet;
        part.view = Some(v);
    }
    part
}

/// No grid, and why.
fn unmapped(e: &leg_models::analysis::AnalysisError) -> GridPart {
    let mut table = serde_json::Map::new();
    let mut why = serde_json::Map::new();
    for key in ["workspace_area_m2", "singularity_distance_m"] {
        table.insert(key.into(), Value::Null);
        why.insert(key.into(), json!(e.to_string()));
    }
    GridPart {
        table,
        why,
        json: Vec::new(),
        csv: None,
        view: None,
    }
}

/// The measures over a grid of foot positions (a spatial leg's in its slice), its
/// singularity curves and area.
fn mapped<L, const NQ: usize, const NC: usize, const NU: usize, const ND: usize, const NP: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    ws: Workspace<NQ, NU, ND>,
    seconds: f64,
    file_stem: &str,
) -> GridPart
where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    // The area and the distance, and their reasons, are in the table already (the
    // summary's row).
    let table = serde_json::Map::new();
    let why = serde_json::Map::new();
    let mut fields = Vec::new();
    let reached = ws
        .states
        .iter()
        .filter(|&&s| s == NodeState::Reached)
        .count();
    let singular = ws
        .measures
        .iter()
        .filter(|m| matches!(m, Some(Err(_))))
        .count();
    let mut grid = json!({
        "nodes_per_side": ws.nodes,
        "origin": ws.origin,
        "step_m": ws.step,
        "reached": reached,
        "singular_nodes": singular,
        "seconds": seconds,
        "csv": format!("{file_stem}.csv"),
    });
    if let Some((plane, offset)) = ws.slice {
        grid["slice"] = json!({
            "axes": plane.axes,
            "through_m": L::foot_position(q, p).as_slice(),
            "offset_m": offset,
            "what": "grid coordinates (origin, curves, area) are along the slice's two axes; the plane is a·axes[0] + b·axes[1] + offset·(axes[0] × axes[1]), through the stance foot",
        });
    }
    fields.push(("grid", grid));
    let seg = |s: &[Segment]| {
        s.iter()
            .map(|s| [s[0][0], s[0][1], s[1][0], s[1][1]])
            .collect::<Vec<_>>()
    };
    let mut curves = json!({
        "passive": seg(&ws.passive_curves),
        "passive_located": ws.passive_signed,
        "foot": seg(&ws.foot_curves),
    });
    if !ws.passive_signed {
        curves["passive_note"] = json!(
            "the passive rank measure is unsigned here (redundant rows, a body's held joints or more motors than the foot has coordinates): its curves are not located, and the distance to a singularity counts the foot's (type I) only"
        );
    }
    fields.push(("curves", curves));
    GridPart {
        table,
        why,
        json: fields,
        csv: Some(csv::<L, NQ, NC, NU, ND, NP>(&ws)),
        view: Some(view::<L, NQ, NC, NU, ND, NP>(p, q, Some(&ws))),
    }
}

fn csv<L, const NQ: usize, const NC: usize, const NU: usize, const ND: usize, const NP: usize>(
    ws: &Workspace<NQ, NU, ND>,
) -> String
where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    // Each node's foot in the base frame: x, y (and z on a spatial leg's slice).
    let mut out = String::from(if ND == 3 { "x,y,z,state" } else { "x,y,state" });
    for name in L::JOINT_NAMES {
        write!(out, ",q_{name}").unwrap();
    }
    out.push_str(
        ",passive_rank,foot_rank,condition,vertical_force,vertical_speed,effective_mass\n",
    );
    let cell = |x: Option<f64>| {
        x.filter(|v| v.is_finite())
            .map_or(String::new(), |v| v.to_string())
    };
    for i in 0..ws.states.len() {
        let foot = ws.foot_at(ws.node(i % ws.nodes, i / ws.nodes));
        for x in foot.iter() {
            write!(out, "{x},").unwrap();
        }
        write!(out, "{}", ws.states[i].name()).unwrap();
        let reached = ws.states[i] == NodeState::Reached;
        for j in 0..NQ {
            write!(out, ",{}", cell(reached.then(|| ws.poses[i][j]))).unwrap();
        }
        let m = match &ws.measures[i] {
            Some(Ok(m)) => Some(m),
            _ => None,
        };
        writeln!(
            out,
            ",{},{},{},{},{},{}",
            cell(reached.then(|| ws.passive_rank[i])),
            cell(m.map(|m| m.foot_rank)),
            cell(m.map(|m| m.condition)),
            cell(m.and_then(|m| m.vertical_force)),
            cell(m.map(|m| m.vertical_speed)),
            cell(m.map(|m| m.effective_mass)),
        )
        .unwrap();
    }
    out
}

fn view<L, const NQ: usize, const NC: usize, const NU: usize, const ND: usize, const NP: usize>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    ws: Option<&Workspace<NQ, NU, ND>>,
) -> View
where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    let values =
        |f: &dyn Fn(&leg_models::analysis::PointMeasures<f64, NQ, NU, ND>) -> Option<f64>| {
            let Some(ws) = ws else { return Vec::new() };
            ws.measures
                .iter()
                .map(|m| match m {
                    Some(Ok(m)) => f(m).filter(|v| v.is_finite()).unwrap_or(f64::NAN),
                    _ => f64::NAN,
                })
                .collect::<Vec<f64>>()
        };
    let mut maps = vec![
        (
            "vertical force capacity (downward push)".to_string(),
            "N".to_string(),
            values(&|m| m.vertical_force),
        ),
        (
            "conditioning: log₁₀ κ(J_θ)".to_string(),
            "".to_string(),
            values(&|m| Some(m.condition.log10())),
        ),
        (
            "effective mass at the foot, vertical".to_string(),
            "kg".to_string(),
            values(&|m| Some(m.effective_mass)),
        ),
    ];
    if ws.is_none() {
        maps.clear();
    }
    // The leg drawn in the grid's coordinates: a spatial leg projected onto its slice.
    let flat = |x: SVector<f64, ND>| match ws {
        Some(ws) => ws.grid_coordinates(&x),
        None => [x[0], x[1]],
    };
    let joints = L::joint_positions(q, p);
    let tips = L::link_tips(q, p);
    let (joint, tip) = (
        |j: usize| flat(joints.column(j).into_owned()),
        |j: usize| flat(tips.column(j).into_owned()),
    );
    let mut links: Vec<[f64; 4]> = (0..NQ)
        .map(|j| {
            let (a, b) = (joint(j), tip(j));
            [a[0], a[1], b[0], b[1]]
        })
        .collect();
    // A child joint off its parent's tip, and closure points inside links: joined too.
    for j in 0..NQ {
        if let Some(parent) = L::PARENTS[j] {
            let (a, b) = (tip(parent), joint(j));
            links.push([a[0], a[1], b[0], b[1]]);
        }
    }
    let axes = match ws.and_then(|w| w.slice) {
        Some((plane, _)) => plane.axes.map(|a| axis_name(&a)),
        None => ["x".to_string(), "y".to_string()],
    };
    View {
        nodes: ws.map_or(0, |w| w.nodes),
        origin: ws.map_or([0.0; 2], |w| w.origin),
        step: ws.map_or(0.0, |w| w.step),
        maps,
        passive: ws.map_or_else(Vec::new, |w| w.passive_curves.clone()),
        foot: ws.map_or_else(Vec::new, |w| w.foot_curves.clone()),
        links,
        stance: flat(L::foot_position(q, p)),
        path: Vec::new(),
        axes,
    }
}

/// A slice axis's name: `x`, `y` or `z` for a base axis, its components otherwise.
fn axis_name(a: &[f64; 3]) -> String {
    match a {
        [1.0, 0.0, 0.0] => "x".into(),
        [0.0, 1.0, 0.0] => "y".into(),
        [0.0, 0.0, 1.0] => "z".into(),
        _ => format!("({:.3}, {:.3}, {:.3})", a[0], a[1], a[2]),
    }
}

/// Writes `analysis.json`, the CSVs and `report.html` into `settings.out`, only once
/// every design is computed (a failure before leaves nothing).
pub fn write(settings: &Settings, designs: &[Design], command: &str) -> Result<(), Error> {
    let out = &settings.out;
    let json = json!({
        "command": command,
        "sweep": settings.sweep.as_ref().map(|s| json!({"parameters": s.names, "from": s.from, "to": s.to, "designs": s.count})),
        "motor_range": settings.motor_range.map(|r| [r.0, r.1]),
        "defaults": {
            "torque_limit": format!("{MOTOR_TORQUE} N m at the motor times its gear ratio"),
            "speed_limit": format!("{MOTOR_SPEED} rad/s at the motor over its gear ratio"),
            "body_mass": "ten times the leg's mass (a leg with body joints uses its own body)",
        },
        "designs": designs.iter().map(|d| d.json.clone()).collect::<Vec<_>>(),
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| Error::Failed(e.to_string()))?;
    let html = report::html(designs, settings.sweeping(), command).map_err(Error::Failed)?;
    let mut files: Vec<(String, String)> = designs
        .iter()
        .filter_map(|d| Some((format!("{}.csv", d.file_stem), d.csv.clone()?)))
        .collect();
    files.push(("analysis.json".into(), text));
    files.push(("report.html".into(), html));
    let earlier = earlier_csvs(out);
    write_all(out, &files).map_err(Error::Failed)?;
    // A rerun into the same folder kept the earlier run's sweep CSVs beside the new ones:
    // the CSVs the earlier analysis.json named and this run did not write go.
    for name in earlier
        .iter()
        .filter(|n| !files.iter().any(|(f, _)| f == *n))
    {
        if let Err(e) = std::fs::remove_file(out.join(name)) {
            if e.kind() != std::io::ErrorKind::NotFound {
                eprintln!(
                    "warning: could not remove {}, a CSV of the earlier run: {e}",
                    out.join(name).display()
                );
            }
        }
    }
    Ok(())
}

/// The CSVs an earlier run's `analysis.json` in `out` names (its designs' `grid.csv`), only
/// plain file names: nothing outside `out` is ever removed.
fn earlier_csvs(out: &std::path::Path) -> Vec<String> {
    let Ok(text) = std::fs::read_to_string(out.join("analysis.json")) else {
        return Vec::new();
    };
    let Ok(json) = serde_json::from_str::<serde_json::Value>(&text) else {
        return Vec::new();
    };
    json["designs"]
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(|d| d["grid"]["csv"].as_str())
        .filter(|n| {
            n.ends_with(".csv")
                && !n.contains(['/', '\\'])
                && !n.starts_with('.')
                && std::path::Path::new(n).components().count() == 1
        })
        .map(str::to_string)
        .collect()
}
