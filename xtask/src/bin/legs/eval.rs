//! `cargo xtask eval MODEL --q … [--qd …] [--u …] [--json] [--assemble] [--derivatives]`:
//! every term at one state.

use leg_models::assembly::{
    assemble, assemble_along, consistent_velocity, project_position, project_velocity, Tolerance,
};
use leg_models::control::actuated_reduction;
use leg_models::dynamics::contact::{
    forward_dynamics_with_contacts, impact_map, project_held_velocity, spec_friction, ContactMode,
    Ground, Modes,
};
use leg_models::dynamics::derivatives::forward_dynamics_derivatives;
use leg_models::dynamics::forward_dynamics_from_terms;
use leg_models::nalgebra::{SMatrix, SVector};
use leg_models::ContactModel;
use serde_json::{json, Map, Value};
use xtask::cli::args::EvalArgs;
use xtask::cli::{numbers, Error};

fn matrix<const R: usize, const C: usize>(m: &SMatrix<f64, R, C>) -> Value {
    Value::Array(
        (0..R)
            .map(|r| Value::Array((0..C).map(|c| json!(m[(r, c)])).collect()))
            .collect(),
    )
}

fn vector<const R: usize>(v: &SVector<f64, R>) -> Value {
    Value::Array(v.iter().map(|x| json!(x)).collect())
}

/// Whether a term holds a number beyond f64's range (serde_json writes `inf` and `NaN` as
/// `null`, so a `null` inside a computed term is one).
fn overflowed(v: &Value) -> bool {
    match v {
        Value::Null => true,
        Value::Array(xs) => xs.iter().any(overflowed),
        Value::Object(m) => m.values().any(overflowed),
        _ => false,
    }
}

/// The largest magnitude among the state and torques given, for the overflow message.
fn largest_input(q: &[f64], qd: &[f64], u: &[f64]) -> f64 {
    q.iter()
        .chain(qd)
        .chain(u)
        .fold(0.0_f64, |m, x| m.max(x.abs()))
}

pub fn run<
    L: ContactModel<NQ, NC, NU, NK> + leg_models::LegModel<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
>(
    args: &EvalArgs,
) -> Result<(), Error> {
    let p = L::Params::<f64>::default();
    // The contact to land, named before anything is computed.
    let impact_contact = impact_contact::<L, NQ, NC, NU, NK, 2>(args)?;
    stance_has_contacts::<NK>(args, L::NAME)?;
    let json_out = args.json;
    let assembled = args.assemble;
    let q_text = &args.q;
    let (q, qd) = if assembled {
        let theta = pose(
            "--q",
            numbers("--q", q_text, NU, "actuated angles with --assemble")?,
        )?;
        let theta_dot = match &args.qd {
            Some(t) => numbers("--qd", t, NU, "actuated rates with --assemble")?,
            None => vec![0.0; NU],
        };
        let theta = SVector::<f64, NU>::from_column_slice(&theta);
        let tol = Tolerance::default();
        let cannot = |how: &str, e: &dyn std::fmt::Display| {
            Error::usage(format!(
                "cannot assemble {} at θ = {:?} {how}: {e}",
                L::NAME,
                theta.as_slice()
            ))
        };
        let q = match &args.guess {
            Some(g) => {
                let guess = SVector::<f64, NQ>::from_column_slice(&pose(
                    "--guess",
                    numbers("--guess", g, NQ, "a starting pose, one angle per joint")?,
                )?);
                assemble::<L, f64, NQ, NC, NU>(&p, &theta, &guess, &tol)
                    .map_err(|e| cannot("from --guess", &e))?
            }
            None => {
                let mut home = SVector::<f64, NQ>::from_column_slice(&L::HOME);
                project_position::<L, f64, NQ, NC, NU>(&p, &mut home, &tol)
                    .map_err(|e| cannot("(the home pose does not assemble)", &e))?;
                assemble_along::<L, f64, NQ, NC, NU>(&p, &home, &theta, 0.05, &tol).map_err(
                    |e| {
                        cannot(
                            "on the home pose's branch",
                            &format!("{e}; give a starting pose in another mode with --guess"),
                        )
                    },
                )?
            }
        };
        let qd = consistent_velocity::<L, f64, NQ, NC, NU>(
            &p,
            &q,
            &SVector::from_column_slice(&theta_dot),
        )
        .map_err(|e| Error::usage(format!("no consistent rates at this pose: {e}")))?;
        (q, qd)
    } else {
        let q = SVector::<f64, NQ>::from_column_slice(&pose(
            "--q",
            numbers("--q", q_text, NQ, "joint values")?,
        )?);
        let mut qd = match &args.qd {
            Some(t) => SVector::from_column_slice(&numbers("--qd", t, NQ, "joint rates")?),
            None => SVector::zeros(),
        };
        let mut q = q;
        if args.project {
            project_position::<L, f64, NQ, NC, NU>(&p, &mut q, &Tolerance::default())
                .map_err(|e| Error::usage(format!("cannot project --q onto the closures: {e}")))?;
            project_velocity::<L, f64, NQ, NC, NU>(&p, &q, &mut qd)
                .map_err(|e| Error::usage(format!("cannot project --qd onto the closures: {e}")))?;
            if args.stance {
                hold_velocity::<L, NQ, NC, NU, NK, 2>(&p, &q, &mut qd)?;
            }
        }
        (q, qd)
    };
    let u = match &args.u {
        Some(t) => SVector::<f64, NU>::from_column_slice(&numbers("--u", t, NU, "motor torques")?),
        None => SVector::zeros(),
    };

    let terms = L::dynamics_terms(&q, &qd, &p);
    let (mut out, mut errors) =
        dynamics::<L, NQ, NC, NU>(&p, &terms, &q, &qd, &u, args.derivatives);
    let mut warnings = Map::new();
    match actuated_reduction::<L, f64, NQ, NC, NU>(&p, &terms, &qd) {
        Ok(r) => {
            out.insert("A_tilde".into(), matrix(&r.a_tilde));
            out.insert("b_tilde".into(), vector(&r.b_tilde));
        }
        Err(e) => {
            out.insert("A_tilde".into(), Value::Null);
            out.insert("b_tilde".into(), Value::Null);
            errors.insert("A_tilde".into(), json!(e.to_string()));
        }
    }
    points::<L, NQ, NC, NU, 2, NC>(
        &p,
        &q,
        &qd,
        &mut out,
        &mut warnings,
        "--assemble or --project",
    );
    contacts::<L, NQ, NC, NU, NK, 2>(
        &p,
        &q,
        &qd,
        impact_contact,
        &mut out,
        &mut errors,
        &mut warnings,
    );
    if args.stance {
        stance::<L, NQ, NC, NU, NK, 2>(&p, &q, &qd, &u, &mut out, &mut errors);
    }
    let big = largest_input(q.as_slice(), qd.as_slice(), u.as_slice());
    emit(out, errors, warnings, big, json_out);
    Ok(())
}

/// The contact `--impact` names, checked before anything is computed.
fn impact_contact<
    L: ContactModel<NQ, NC, NU, NK, ND>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    args: &EvalArgs,
) -> Result<Option<usize>, Error> {
    let Some(name) = &args.impact else {
        return Ok(None);
    };
    match L::CONTACT_NAMES.iter().position(|c| c == name) {
        Some(k) => Ok(Some(k)),
        None if L::CONTACT_NAMES.is_empty() => Err(Error::usage(format!(
            "--impact {}: {} has no contact points (add [[contacts]] to its spec)",
            xtask::gen::spec::shown(name),
            L::NAME
        ))),
        None => Err(Error::usage(format!(
            "--impact: unknown contact `{}` (contacts of {}: {})",
            xtask::gen::spec::shown(name),
            L::NAME,
            L::CONTACT_NAMES.join(", ")
        ))),
    }
}

/// `contacts` (each contact's position, its coordinates in the ground's frame: along the
/// ground, one number on a planar leg and two on a spatial one, and its gap) and, with
/// `--impact`, `impact`: contact `impact` landing at this state with the others in the
/// air (its impulses in the ground's frame, the tangential ones then the normal one).
#[allow(clippy::too_many_arguments)]
fn contacts<
    L: ContactModel<NQ, NC, NU, NK, ND>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    impact: Option<usize>,
    out: &mut Map<String, Value>,
    errors: &mut Map<String, Value>,
    warnings: &mut Map<String, Value>,
) {
    let ground = Ground::<f64, ND>::of::<L, NQ, NC, NU, NK>();
    let x = L::contact_positions(q, p);
    let coords = ground.coordinates(&x);
    // A planar leg's one tangential coordinate is a number, a spatial leg's two a list.
    let along = |k: usize, v: &SVector<f64, NK>| -> Value {
        if ND == 2 {
            json!(v[ND * k])
        } else {
            json!(v.rows(ND * k, ND - 1).iter().copied().collect::<Vec<_>>())
        }
    };
    let contacts: Vec<Value> = L::CONTACT_NAMES
        .iter()
        .enumerate()
        .map(|(k, name)| {
            json!({
                "name": name,
                "position": x.rows(ND * k, ND).iter().copied().collect::<Vec<_>>(),
                "tangential": along(k, &coords),
                "gap": coords[ND * k + ND - 1],
                "friction": L::CONTACT_FRICTION[k],
            })
        })
        .collect();
    out.insert("contacts".into(), Value::Array(contacts));
    let Some(k) = impact else {
        return;
    };
    let mut modes = Modes::<NK, ND>::flight();
    modes.set(k, ContactMode::Stick);
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, ND>();
    match impact_map::<L, f64, NQ, NC, NU, NK, ND>(p, q, qd, &mut modes, &ground, &mu) {
        Ok(imp) => {
            let mode = match modes.get(k) {
                ContactMode::Stick => "stick",
                _ => "slide",
            };
            // An impact happens at the ground: the map at a state away from it is
            // computed as asked, and said so.
            let gap = coords[ND * k + ND - 1];
            let size = leg_models::assembly::leg_size::<L, f64, NQ, NC, NU>(p, q);
            if gap.abs() > 1e-6 * size.max(1.0) {
                warnings.insert(
                    "impact".into(),
                    json!(format!(
                        "contact `{}` is {gap:.3e} m from the ground (its gap): an impact happens at the ground; this is the map at the state given",
                        L::CONTACT_NAMES[k]
                    )),
                );
            }
            let mut impact = json!({
                "contact": L::CONTACT_NAMES[k],
                "qd_plus": imp.qd_plus.as_slice(),
                "impulses": imp.impulses.rows(ND * k, ND).iter().copied().collect::<Vec<_>>(),
                "closure_impulses": imp.closure_impulses.as_slice(),
                "energy_lost": imp.energy_lost,
                "mode_after": mode,
            });
            // In 3-D a slide's direction is one of a circle: said with the impact.
            if ND == 3 && mode == "slide" {
                impact["slip_direction"] = along(k, &imp.slip);
            }
            out.insert("impact".into(), impact);
        }
        Err(e) => {
            out.insert("impact".into(), Value::Null);
            let why = match e {
                leg_models::dynamics::contact::ImpactError::Pulling { normal_impulse, .. } => format!(
                    "impact: contact `{}` would need a pulling normal impulse ({normal_impulse:.3e} N s): it separates instead",
                    L::CONTACT_NAMES[k]
                ),
                other => other.to_string(),
            };
            errors.insert("impact".into(), json!(why));
        }
    }
}

/// `--stance` on a model without contact points is refused before anything is computed.
fn stance_has_contacts<const NK: usize>(args: &EvalArgs, name: &str) -> Result<(), Error> {
    if args.stance && NK == 0 {
        return Err(Error::usage(format!(
            "--stance: {name} has no contact points to hold"
        )));
    }
    Ok(())
}

/// With `--stance --project`: `qd` moved onto the held contacts too (every contact
/// sticking, its velocity zero), the least change in the metric of `M`.
fn hold_velocity<
    L: ContactModel<NQ, NC, NU, NK, ND>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    qd: &mut SVector<f64, NQ>,
) -> Result<(), Error> {
    let ground = Ground::<f64, ND>::of::<L, NQ, NC, NU, NK>();
    project_held_velocity::<L, f64, NQ, NC, NU, NK, ND>(p, q, qd, &Modes::stick(), &ground)
        .map_err(|e| Error::usage(format!("cannot project --qd onto the held contacts: {e}")))
}

/// `stance` (with `--stance`): forward dynamics with every contact held where it is
/// (sticking, `dynamics::contact`), the closures closed, motor torques `u`: its qdd,
/// closure forces F and contact forces (per contact in the ground's frame, tangential
/// then normal). A floating robot's is in its chart, as `leg_models::robot::stance_dynamics`
/// gives it at the chart's centre with the body level (a held contact's q̈ does not depend
/// on where the ground is).
fn stance<
    L: ContactModel<NQ, NC, NU, NK, ND>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NK: usize,
    const ND: usize,
>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    u: &SVector<f64, NU>,
    out: &mut Map<String, Value>,
    errors: &mut Map<String, Value>,
) {
    let ground = Ground::<f64, ND>::of::<L, NQ, NC, NU, NK>();
    let mu = spec_friction::<L, f64, NQ, NC, NU, NK, ND>();
    let anchors = ground.coordinates(&L::contact_positions(q, p));
    match forward_dynamics_with_contacts::<L, f64, NQ, NC, NU, NK, ND>(
        p,
        q,
        qd,
        u,
        &Modes::stick(),
        &anchors,
        &ground,
        &mu,
        None,
    ) {
        Ok(s) => {
            out.insert(
                "stance".into(),
                json!({
                    "qdd": s.x.as_slice(),
                    "F": s.closure.as_slice(),
                    "contact": s.contact.as_slice(),
                }),
            );
        }
        Err(e) => {
            out.insert("stance".into(), Value::Null);
            errors.insert("stance".into(), json!(format!("stance: {e}")));
        }
    }
}

/// Prints the terms (JSON or text), every term that overflowed said by name in `errors`.
fn emit(
    mut out: Map<String, Value>,
    mut errors: Map<String, Value>,
    warnings: Map<String, Value>,
    big: f64,
    json_out: bool,
) {
    // A term that overflowed is said so by name, never left as a bare `null` (issue 29).
    let keys: Vec<String> = out.keys().cloned().collect();
    for key in keys {
        // The error that already explains a term left out (several terms share one).
        let explained_by = match key.as_str() {
            "F" => "qdd",
            "b_tilde" => "A_tilde",
            k if k.starts_with("dqdd_") || k.starts_with("dF_") => "derivatives",
            k => k,
        };
        let already = errors.contains_key(explained_by) && out[&key].is_null();
        if already || !overflowed(&out[&key]) {
            continue;
        }
        let parts = match &out[&key] {
            Value::Object(m) => {
                let bad: Vec<&str> = m
                    .iter()
                    .filter(|(_, v)| overflowed(v))
                    .map(|(k, _)| k.as_str())
                    .collect();
                format!("{key}.{}", bad.join(&format!(", {key}.")))
            }
            _ => key.clone(),
        };
        errors.insert(
            key.clone(),
            json!(format!(
                "overflow: {parts} is beyond f64's range at this state (inputs up to {big:.3e}): not computed"
            )),
        );
        out.insert(key, Value::Null);
    }
    if !errors.is_empty() {
        out.insert("errors".into(), Value::Object(errors));
    }
    if !warnings.is_empty() {
        out.insert("warnings".into(), Value::Object(warnings));
    }
    if json_out {
        println!("{}", Value::Object(out));
    } else {
        for (k, v) in &out {
            match v {
                Value::Array(rows) if rows.first().is_some_and(Value::is_array) => {
                    println!("{k} =");
                    for r in rows {
                        println!("  {r}");
                    }
                }
                _ => println!("{k} = {v}"),
            }
        }
    }
}

/// The terms every leg has, planar or spatial: the state, `M`, `N`, `G`, `J`, `J̇ q̇` (from
/// `terms`, evaluated once by the caller), forward dynamics and (asked) its derivatives;
/// and the errors of those that failed.
fn dynamics<
    L: leg_models::LegDynamics<NQ, NC, NU>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
>(
    p: &L::Params<f64>,
    terms: &leg_models::DynamicsTerms<f64, NQ, NC>,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    u: &SVector<f64, NU>,
    derivatives: bool,
) -> (Map<String, Value>, Map<String, Value>) {
    let mut out = Map::new();
    let mut errors = Map::new();
    out.insert("model".into(), json!(L::NAME));
    out.insert("joints".into(), json!(L::JOINT_NAMES.to_vec()));
    out.insert("q".into(), vector(q));
    out.insert("qd".into(), vector(qd));
    out.insert("u".into(), vector(u));
    out.insert("M".into(), matrix(&terms.mass_matrix));
    out.insert("N".into(), vector(&terms.bias_forces));
    out.insert("G".into(), vector(&L::gravity_forces(q, p)));
    out.insert("J".into(), matrix(&terms.constraint_jacobian));
    out.insert("Jdot_qdot".into(), vector(&terms.constraint_bias));
    match forward_dynamics_from_terms::<L, f64, NQ, NC, NU>(p, terms, q, qd, u, None) {
        Ok(a) => {
            out.insert("qdd".into(), vector(&a.qdd));
            out.insert("F".into(), vector(&a.forces));
        }
        Err(e) => {
            out.insert("qdd".into(), Value::Null);
            out.insert("F".into(), Value::Null);
            errors.insert("qdd".into(), json!(e.explained(q, qd, u).to_string()));
        }
    }
    if derivatives {
        let names = ["dqdd_dq", "dqdd_dqd", "dqdd_du", "dF_dq", "dF_dqd", "dF_du"];
        match forward_dynamics_derivatives::<L, f64, NQ, NC, NU>(p, q, qd, u, None) {
            Ok(d) => {
                let values = [
                    matrix(&d.qdd_q),
                    matrix(&d.qdd_qd),
                    matrix(&d.qdd_u),
                    matrix(&d.forces_q),
                    matrix(&d.forces_qd),
                    matrix(&d.forces_u),
                ];
                for (name, value) in names.into_iter().zip(values) {
                    out.insert(name.into(), value);
                }
            }
            Err(e) => {
                for name in names {
                    out.insert(name.into(), Value::Null);
                }
                errors.insert("derivatives".into(), json!(e.to_string()));
            }
        }
    }
    (out, errors)
}

/// The foot, the energies and the closure residual, in the leg's dimension; a state off
/// the closures is said (`fix`: the flags that put it on them).
fn points<
    L: leg_models::LegModel<NQ, NC, NU, ND, NP>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    p: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    out: &mut Map<String, Value>,
    warnings: &mut Map<String, Value>,
    fix: &str,
) {
    out.insert("foot".into(), vector(&L::foot_position(q, p)));
    out.insert("foot_jacobian".into(), matrix(&L::foot_jacobian(q, p)));
    out.insert("kinetic".into(), json!(L::kinetic_energy(q, qd, p)));
    out.insert("potential".into(), json!(L::potential_energy(q, p)));
    let phi = L::closure_residual(q, p);
    out.insert("phi".into(), vector(&phi));
    // Terms and derivatives off the closures are of a state the leg cannot be in: said.
    let size = leg_models::assembly::leg_size::<L, f64, NQ, NC, NU>(p, q);
    if NC > 0 && phi.amax() > 1e-9 * size.max(1e-300) {
        warnings.insert(
            "phi".into(),
            json!(format!(
                "the state is off the closures by {:.3e} m (phi): the terms are of a pose the leg cannot take; {fix} puts it on them",
                phi.amax()
            )),
        );
    }
}

/// Coordinates read as a pose obey the rule every pose does ([`leg_models::check_pose`]):
/// an angle of 1e308 rad was taken, and assembling towards it failed on a step size.
fn pose(flag: &str, values: Vec<f64>) -> Result<Vec<f64>, Error> {
    leg_models::check_pose(&values).map_err(|(k, x)| {
        Error::usage(format!(
            "`{flag}`: value {} is {}, more than {} in magnitude: a coordinate (rad, or m) that large has no precision left",
            k + 1,
            leg_models::ShownNumber(x),
            leg_models::ShownNumber(leg_models::MAX_COORDINATE)
        ))
    })?;
    Ok(values)
}

/// `eval` of a spatial leg (`LegModel<…, 3>`): the terms at `--q`, `--qd`, `--u` (with
/// `--project`, moved onto the closures first), with `--derivatives` those of forward
/// dynamics, the contacts and with `--impact` one's landing. Assembly from the motors'
/// angles and the reduction to the motors are planar only for now: their flags are
/// refused, naming why.
pub fn run_spatial<
    L: leg_models::LegModel<NQ, NC, NU, 3, NP> + ContactModel<NQ, NC, NU, NK, 3>,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const NP: usize,
    const NK: usize,
>(
    args: &EvalArgs,
) -> Result<(), Error> {
    let assembly = "its assembly from the motors' angles is planar only for now: give every coordinate with --q, and --project to put it on the closures";
    for (given, flag, why) in [
        (args.assemble, "--assemble", assembly),
        (args.guess.is_some(), "--guess", assembly),
    ] {
        if given {
            return Err(Error::usage(format!(
                "{flag}: {} is a spatial leg; {why}",
                L::NAME
            )));
        }
    }
    let impact_contact = impact_contact::<L, NQ, NC, NU, NK, 3>(args)?;
    stance_has_contacts::<NK>(args, L::NAME)?;
    // What --q holds: one value per joint, a ball joint's three angles named where the
    // leg has one.
    let balls: Vec<&str> = L::BALL_JOINTS
        .iter()
        .map(|&b| L::JOINT_NAMES[b].trim_end_matches(".x"))
        .collect();
    let what = if balls.is_empty() {
        "joint values, one per joint".to_string()
    } else {
        format!(
            "joint values, one per joint and three angles for the ball joint{} `{}`",
            if balls.len() == 1 { "" } else { "s" },
            balls.join("`, `")
        )
    };
    let p = L::Params::<f64>::default();
    let mut q =
        SVector::<f64, NQ>::from_column_slice(&pose("--q", numbers("--q", &args.q, NQ, &what)?)?);
    let mut qd = match &args.qd {
        Some(t) => SVector::from_column_slice(&numbers("--qd", t, NQ, "joint rates")?),
        None => SVector::zeros(),
    };
    if args.project {
        project_position::<L, f64, NQ, NC, NU>(&p, &mut q, &Tolerance::default())
            .map_err(|e| Error::usage(format!("cannot project --q onto the closures: {e}")))?;
        project_velocity::<L, f64, NQ, NC, NU>(&p, &q, &mut qd)
            .map_err(|e| Error::usage(format!("cannot project --qd onto the closures: {e}")))?;
        if args.stance {
            hold_velocity::<L, NQ, NC, NU, NK, 3>(&p, &q, &mut qd)?;
        }
    }
    let u = match &args.u {
        Some(t) => SVector::<f64, NU>::from_column_slice(&numbers("--u", t, NU, "motor torques")?),
        None => SVector::zeros(),
    };
    let terms = L::dynamics_terms(&q, &qd, &p);
    let (mut out, mut errors) =
        dynamics::<L, NQ, NC, NU>(&p, &terms, &q, &qd, &u, args.derivatives);
    let mut warnings = Map::new();
    out.insert("ball_joints".into(), json!(L::BALL_JOINTS));
    out.insert("free_joint".into(), json!(L::FREE_JOINT));
    points::<L, NQ, NC, NU, 3, NP>(&p, &q, &qd, &mut out, &mut warnings, "--project");
    contacts::<L, NQ, NC, NU, NK, 3>(
        &p,
        &q,
        &qd,
        impact_contact,
        &mut out,
        &mut errors,
        &mut warnings,
    );
    if args.stance {
        stance::<L, NQ, NC, NU, NK, 3>(&p, &q, &qd, &u, &mut out, &mut errors);
    }
    if let Ok(f) = leg_models::robot::free_joint::<L, NQ, NC, NU>() {
        body_rates(f, &q, &qd, &mut out, &mut errors);
    }
    let big = largest_input(q.as_slice(), qd.as_slice(), u.as_slice());
    emit(out, errors, warnings, big, args.json);
    Ok(())
}

/// A floating robot's `vdot` (and the stance's, with `--stance`): the body's velocity
/// derivative in its own frame, then the joints' `q̈`, from the chart's `q̈`
/// ([`leg_models::robot::velocity_derivative`]); what Pinocchio's free flyer returns.
/// Only at the chart's centre (the free joint's six `q` zero), where that map holds.
fn body_rates<const NQ: usize>(
    f: usize,
    q: &SVector<f64, NQ>,
    qd: &SVector<f64, NQ>,
    out: &mut Map<String, Value>,
    errors: &mut Map<String, Value>,
) {
    if q.rows(f, 6).iter().any(|&x| x != 0.0) {
        out.insert("vdot".into(), Value::Null);
        errors.insert(
            "vdot".into(),
            json!(format!(
                "the body's velocity derivative is given at the chart's centre only: the free joint's values {}..{} of q are not all zero (as given, or as --project moved them)",
                f + 1,
                f + 6
            )),
        );
        return;
    }
    let vdot = |qdd: &Value| -> Option<Value> {
        let qdd: Vec<f64> = qdd
            .as_array()?
            .iter()
            .map(Value::as_f64)
            .collect::<Option<_>>()?;
        (qdd.len() == NQ).then(|| {
            let qdd = SVector::<f64, NQ>::from_column_slice(&qdd);
            json!(leg_models::robot::velocity_derivative(f, qd, &qdd).as_slice())
        })
    };
    let flight = out.get("qdd").and_then(vdot).unwrap_or(Value::Null);
    out.insert("vdot".into(), flight);
    if let Some(held) = out.get("stance").and_then(|s| s.get("qdd")).and_then(vdot) {
        if let Some(Value::Object(s)) = out.get_mut("stance") {
            s.insert("vdot".into(), held);
        }
    }
}
