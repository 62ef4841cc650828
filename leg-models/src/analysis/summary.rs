//! One design at a glance: the row of `cargo xtask analyze`'s table — the measures at
//! stance, the impact mitigation factor, the workspace's area and the stance's distance
//! to a singularity — with the command's defaults (motor limits from the gear ratios, a
//! body ten times the leg's mass). Computed here once for the command line and the Python
//! package, so that a sweep run anywhere (on a cluster's workers, say) gives the
//! command's numbers to the bit.

use std::string::{String, ToString};
use std::time::Instant;

use nalgebra::{SMatrix, SVector};

use super::workspace::{workspace, GridOptions, Workspace};
use super::{
    foot_inverse_inertia, impact_mitigation, point_measures, vertical_effective_mass,
    AnalysisError, Body, BodyCoupling, LegFrame, MotorLimits, PointMeasures,
};
use crate::model::contract::{LegDynamics, LegModel, Parameters};

/// A motor's torque at its shaft (N m) where the command is given none: times the gear.
pub const MOTOR_TORQUE: f64 = 1.0;
/// A motor's speed at its shaft (rad/s) where the command is given none: over the gear.
pub const MOTOR_SPEED: f64 = 100.0;
/// The largest torque (N m) or speed (rad/s) limit taken: beyond it the force and speed
/// sets' products overflow f64 (a limit of 1e308 was read as "unbounded").
pub const MAX_LIMIT: f64 = 1e9;
/// The body a leg on a fixed hip is put on for ξ, where none is given: its mass is this
/// many times the leg's.
pub const BODY_PER_LEG_MASS: f64 = 10.0;

/// Motor `k`'s gear ratio: the parameter `<joint>_gear_ratio` (its magnitude), 1 without
/// one (or with a zero or non-finite one).
pub fn gear_ratio<L, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<f64>,
    k: usize,
) -> f64
where
    L: LegDynamics<NQ, NC, NU>,
{
    let joint = L::JOINT_NAMES[L::ACTUATED[k]];
    L::Params::<f64>::NAMES
        .iter()
        .position(|n| n.strip_suffix("_gear_ratio") == Some(joint))
        .and_then(|i| params.get(i))
        .filter(|g| g.is_finite() && *g != 0.0)
        .map_or(1.0, f64::abs)
}

/// The command's motor limits: `MOTOR_TORQUE · gear` and `MOTOR_SPEED / gear` each.
pub fn default_limits<L, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<f64>,
) -> MotorLimits<f64, NU>
where
    L: LegDynamics<NQ, NC, NU>,
{
    MotorLimits {
        torque: SVector::from_fn(|k, _| MOTOR_TORQUE * gear_ratio::<L, NQ, NC, NU>(params, k)),
        speed: SVector::from_fn(|k, _| MOTOR_SPEED / gear_ratio::<L, NQ, NC, NU>(params, k)),
    }
}

/// A limit out of `(0, MAX_LIMIT]`: which (`"torque"` or `"speed"`), its unit, the motor
/// and the value (a gear ratio of 1e-200 made a speed limit of 1e202 rad/s).
pub fn limit_out_of_range<const NU: usize>(
    limits: &MotorLimits<f64, NU>,
) -> Option<(&'static str, &'static str, usize, f64)> {
    [
        ("torque", "N m", &limits.torque),
        ("speed", "rad/s", &limits.speed),
    ]
    .into_iter()
    .find_map(|(kind, unit, values)| {
        values
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && **v > 0.0 && **v <= MAX_LIMIT))
            .map(|(k, v)| (kind, unit, k, *v))
    })
}

/// The body of ξ: the spec's own where the leg has body joints, else one of `mass` (kg;
/// default [`BODY_PER_LEG_MASS`] times the leg's) that translates, else (a leg whose
/// parameters give no mass) the fixed hip.
pub fn default_body<P, const NQ: usize>(
    frame: &LegFrame<NQ>,
    coupling: Option<&BodyCoupling<P>>,
    mass: Option<f64>,
) -> Body<f64> {
    let mass = mass.or_else(|| coupling.map(|c| BODY_PER_LEG_MASS * c.leg_mass));
    match mass {
        Some(mass) if !frame.has_body() => Body::Translating { mass },
        _ => Body::Fixed,
    }
}

/// Everything a design's row is made of, each with its failure.
#[derive(Clone, Debug)]
pub struct Summary<const NQ: usize, const NU: usize, const ND: usize = 2> {
    /// The measures at stance.
    pub measures: Result<PointMeasures<f64, NQ, NU, ND>, AnalysisError>,
    /// `Λ⁻¹` with the motors free: the measures' where they exist, else the foot's own
    /// (it needs no motor coordinates: a leg its motors do not determine has one).
    pub inverse_inertia: Option<SMatrix<f64, ND, ND>>,
    /// The vertical effective mass from `inverse_inertia` (kg; infinite where the foot
    /// cannot move vertically).
    pub effective_mass: Option<f64>,
    /// ξ on the body given.
    pub impact_mitigation: Result<f64, AnalysisError>,
    /// The workspace grid through the stance (a spatial leg's in its slice).
    pub workspace: Result<Workspace<NQ, NU, ND>, AnalysisError>,
    /// The workspace grid's time (s).
    pub workspace_seconds: f64,
    /// From the stance foot to the nearest singularity curve in the grid (m).
    pub singularity_distance: Option<f64>,
}

/// The row's columns, in the order of `analysis.json`'s `table`.
pub const COLUMNS: [&str; 9] = [
    "vertical_force_n",
    "vertical_speed_m_s",
    "condition",
    "effective_mass_kg",
    "passive_rank",
    "foot_rank",
    "impact_mitigation",
    "workspace_area_m2",
    "singularity_distance_m",
];

impl<const NQ: usize, const NU: usize, const ND: usize> Summary<NQ, NU, ND> {
    /// The row, by [`COLUMNS`]: NaN where a measure is not computed (its reason is in the
    /// fields); the push is infinite where no motor takes a vertical force, the speed and
    /// κ NaN where the motors do not span the foot (`frame.foot_spans`).
    pub fn row(&self, frame: &LegFrame<NQ>) -> [f64; 9] {
        let spans = frame.foot_spans(ND).is_ok();
        let m = self.measures.as_ref().ok();
        let pick = |f: fn(&PointMeasures<f64, NQ, NU, ND>) -> f64, applies: bool| {
            m.filter(|_| applies).map_or(f64::NAN, f)
        };
        [
            m.and_then(|m| m.vertical_force).unwrap_or(f64::NAN),
            pick(|m| m.vertical_speed, spans),
            pick(|m| m.condition, spans),
            self.effective_mass.unwrap_or(f64::NAN),
            pick(|m| m.passive_rank, true),
            pick(|m| m.foot_rank, true),
            *self.impact_mitigation.as_ref().unwrap_or(&f64::NAN),
            self.workspace.as_ref().map_or(f64::NAN, |w| w.area),
            self.singularity_distance.unwrap_or(f64::NAN),
        ]
    }

    /// Why each of the row's measures (by [`COLUMNS`]) is not a finite number, where it
    /// is not: the analysis' error, the structure's reason, or what an infinite value
    /// means.
    pub fn reasons(&self, frame: &LegFrame<NQ>) -> [Option<String>; 9] {
        let spans = frame.foot_spans(ND);
        let failed = self.measures.as_ref().err().map(ToString::to_string);
        let unspanned = || spans.err().map(|why| why.to_string());
        let (force, speed) = match &self.measures {
            Err(_) => (failed.clone(), failed.clone()),
            Ok(m) => (
                match m.vertical_force {
                    None => Some(unspanned().unwrap_or_else(|| {
                        "the motors cannot hold the leg with the foot pushing down here".into()
                    })),
                    Some(f) if f.is_infinite() => Some(
                        "unbounded: no motor takes a vertical force at the foot here (the structure holds it)"
                            .into(),
                    ),
                    Some(_) => None,
                },
                unspanned(),
            ),
        };
        let effective_mass = match self.effective_mass {
            None => failed.clone(),
            Some(m) if m.is_infinite() => Some(
                "infinite: the foot cannot move vertically here (the leg stretched along the vertical, or its closures hold the foot)"
                    .into(),
            ),
            Some(_) => None,
        };
        let grid = self.workspace.as_ref().err().map(ToString::to_string);
        let distance = match (&grid, self.singularity_distance) {
            (Some(e), _) => Some(e.clone()),
            (None, None) => Some("no singularity in the grid".into()),
            (None, Some(_)) => None,
        };
        [
            force,
            speed.clone(),
            speed,
            effective_mass,
            failed.clone(),
            failed,
            self.impact_mitigation
                .as_ref()
                .err()
                .map(ToString::to_string),
            grid,
            distance,
        ]
    }
}

/// One design's summary at the assembled `stance`: its measures under `limits`, ξ on
/// `body`, and the workspace of `grid` (whose limits are `limits`).
#[allow(clippy::too_many_arguments)]
pub fn summary<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    params: &L::Params<f64>,
    stance: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    body: &Body<f64>,
    coupling: Option<&BodyCoupling<L::Params<f64>>>,
    grid: &GridOptions<NU>,
) -> Summary<NQ, NU, ND>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    let measures =
        point_measures::<L, f64, NQ, NC, NU, ND, NP>(params, stance, frame, &grid.limits);
    let (inverse_inertia, effective_mass) = match &measures {
        Ok(m) => (Some(m.inverse_inertia), Some(m.effective_mass)),
        Err(_) => {
            match foot_inverse_inertia::<L, f64, NQ, NC, NU, ND, NP>(params, stance, frame, false) {
                Ok(inv) => (
                    Some(inv),
                    Some(vertical_effective_mass::<L, f64, NQ, NC, NU, ND, NP>(
                        params, stance, &inv,
                    )),
                ),
                Err(_) => (None, None),
            }
        }
    };
    let impact =
        impact_mitigation::<L, f64, NQ, NC, NU, ND, NP>(params, stance, frame, body, coupling);
    let started = Instant::now();
    let workspace = workspace::<L, NQ, NC, NU, ND, NP>(params, stance, frame, grid);
    let workspace_seconds = started.elapsed().as_secs_f64();
    let singularity_distance = workspace.as_ref().ok().and_then(|w| {
        w.distance_to_singularity(w.grid_coordinates(&L::foot_position(stance, params)))
    });
    Summary {
        measures,
        inverse_inertia,
        effective_mass,
        impact_mitigation: impact,
        workspace,
        workspace_seconds,
        singularity_distance,
    }
}
