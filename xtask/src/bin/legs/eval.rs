//! `cargo xtask eval MODEL --q … [--qd …] [--u …] [--json] [--assemble]`: every term at
//! one state.

use leg_models::assembly::{
    assemble, assemble_along, consistent_velocity, project_position, Tolerance,
};
use leg_models::control::actuated_reduction;
use leg_models::dynamics::forward_dynamics;
use leg_models::nalgebra::{SMatrix, SVector};
use leg_models::LegModel;
use serde_json::{json, Map, Value};
use xtask::cli::{numbers, Error, Flags};

pub const HELP: &str = "\
usage: cargo xtask eval MODEL --q Q1,Q2,… [--qd …] [--u …] [--json] [--assemble [--guess …]]

  --q         joint angles (rad), one per joint; with --assemble, the actuated angles only
  --qd        joint rates (rad/s), default zero; with --assemble, the actuated rates only
  --u         motor torques (N m), one per actuated joint, default zero
  --assemble  solve the loops for the passive joints first: by default following the
              assembly branch of the spec's home pose while the motors move from their
              home angles to --q (an error says where that branch ends); with --guess,
              from that pose (it picks the assembly mode)
  --guess     with --assemble: a starting pose, one angle per joint (rad)
  --json      one JSON object: q, qd, u, M, N, G, J, Jdot_qdot, qdd, F, A_tilde, b_tilde,
              foot, foot_jacobian, kinetic, potential, phi (matrices as arrays of rows);
              a term that cannot be computed at this state is null, and `errors` says why
";

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

pub fn run<L: LegModel<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize>(
    mut flags: Flags,
) -> Result<(), Error> {
    let p = L::Params::<f64>::default();
    let json_out = flags.switch("--json");
    let assembled = flags.switch("--assemble");
    let q_text = flags
        .take("--q")
        .ok_or_else(|| Error::usage("`--q` is required (see `cargo xtask eval --help`)"))?;
    let (q, qd) = if assembled {
        let theta = numbers("--q", &q_text, NU, "actuated angles with --assemble")?;
        let theta_dot = match flags.take("--qd") {
            Some(t) => numbers("--qd", &t, NU, "actuated rates with --assemble")?,
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
        let q = match flags.take("--guess") {
            Some(g) => {
                let guess = SVector::<f64, NQ>::from_column_slice(&numbers(
                    "--guess",
                    &g,
                    NQ,
                    "a starting pose, one angle per joint",
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
        let q =
            SVector::<f64, NQ>::from_column_slice(&numbers("--q", &q_text, NQ, "joint angles")?);
        let qd = match flags.take("--qd") {
            Some(t) => SVector::from_column_slice(&numbers("--qd", &t, NQ, "joint rates")?),
            None => SVector::zeros(),
        };
        (q, qd)
    };
    if flags.take("--guess").is_some() {
        return Err(Error::usage("`--guess` goes with `--assemble`"));
    }
    let u = match flags.take("--u") {
        Some(t) => SVector::<f64, NU>::from_column_slice(&numbers("--u", &t, NU, "motor torques")?),
        None => SVector::zeros(),
    };
    if let Some(extra) = flags.positionals.first() {
        return Err(Error::usage(format!("unexpected argument `{extra}`")));
    }

    let terms = L::dynamics_terms(&q, &qd, &p);
    let mut out = Map::new();
    let mut errors = Map::new();
    out.insert("model".into(), json!(L::NAME));
    out.insert("joints".into(), json!(L::JOINT_NAMES.to_vec()));
    out.insert("q".into(), vector(&q));
    out.insert("qd".into(), vector(&qd));
    out.insert("u".into(), vector(&u));
    out.insert("M".into(), matrix(&terms.mass_matrix));
    out.insert("N".into(), vector(&terms.bias_forces));
    out.insert("G".into(), vector(&L::gravity_forces(&q, &p)));
    out.insert("J".into(), matrix(&terms.constraint_jacobian));
    out.insert("Jdot_qdot".into(), vector(&terms.constraint_bias));
    match forward_dynamics::<L, f64, NQ, NC, NU>(&p, &q, &qd, &u, None) {
        Ok(a) => {
            out.insert("qdd".into(), vector(&a.qdd));
            out.insert("F".into(), vector(&a.forces));
        }
        Err(e) => {
            out.insert("qdd".into(), Value::Null);
            out.insert("F".into(), Value::Null);
            errors.insert("qdd".into(), json!(e.to_string()));
        }
    }
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
    out.insert("foot".into(), vector(&L::foot_position(&q, &p)));
    out.insert("foot_jacobian".into(), matrix(&L::foot_jacobian(&q, &p)));
    out.insert("kinetic".into(), json!(L::kinetic_energy(&q, &qd, &p)));
    out.insert("potential".into(), json!(L::potential_energy(&q, &p)));
    out.insert("phi".into(), vector(&L::closure_residual(&q, &p)));
    if !errors.is_empty() {
        out.insert("errors".into(), Value::Object(errors));
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
    Ok(())
}
