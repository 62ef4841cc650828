//! A whole-body balance controller for a floating robot standing on its feet: each tick a
//! quadratic program, solved by Clarabel (pure Rust, exact second-order friction cones),
//! picks the motor torques.
//!
//! With the held contacts and the closures, the stance dynamics are linear in what is
//! applied: one factorization of the stance system ([`super::stance_dynamics`]) gives
//! the chart's accelerations and every ground force as affine maps of the torques,
//!
//! ```text
//! q̈ = q̈₀ + A u,   λ = λ₀ + F u,
//! ```
//!
//! so the QP over joint accelerations, ground forces and torques is solved in the
//! torques alone, with the other two eliminated exactly (the equality rows of the
//! dynamics, the closures and the held contacts are then satisfied by construction, and,
//! where no springs are held rigid (below), the forces the controller plans are the ones
//! the simulator applies):
//!
//! ```text
//! min ½ |W (S q̈ − a*)|² + ½ w_t |λ_t / m|² + ½ r |u|²
//! s.t. |λ_t,k| ≤ μ_k λ_n,k for every held contact k   (second-order cones)
//!      |u_i| ≤ u_max,i                                (when limits are given)
//! ```
//!
//! The tasks `a*` are a PD on the body's pose (its position in the world, its
//! orientation by the rotation vector of `R*ᵀ R`, both critically damped by default)
//! and, with a small weight, a PD on every joint towards a posture: the motions the body
//! task leaves free (the legs' internal ones) would otherwise drift; the tangential
//! forces over the robot's mass `m` (from its mass matrix's body block), with a small
//! weight, keep the feet's forces off their cones' edges; the ridge `r` is `w_u` times the
//! mean of the others' curvature per torque. Angular rows and joint rows are scaled by
//! the robot's size, so that the body's rows and the revolute joints' are accelerations
//! in m/s².
//!
//! Where the legs carry springs (Cassie's shin and heel springs), the controller's model
//! holds them rigid, as controllers of sprung robots do: a virtual generalized force
//! along each spring's deflection holds the deflection's acceleration at zero, and the
//! maps above become the rigid model's (`σ = −(S A_σ)⁻¹ S (q̈₀ + A u)` substituted, `A_σ`
//! the accelerations under a unit virtual force, `S` the deflections' rows). The spring
//! modes the rigid model leaves out are damped by a servo the QP does not see (it would
//! cancel it): a motor PD towards the posture, `−k (q_a − q_a*) − k d q̇_a` with `k`
//! [`BalanceGains::servo_stiffness`] `m g ℓ` per rad, added to the QP's torques (and
//! clipped to the limits). Both are needed on Cassie (measured at its standing pose, 1 ms
//! steps, `cargo run --release -p leg-tests --example balance`): planned with the springs
//! as they are, a forward push of 0.51 N for 0.1 s puts a toe out of its cone in 40 ms;
//! held rigid without the servo, the spring modes grow (|q̇| 1.5e-2 after 1 s unpushed);
//! with both it survives pushes of about a tenth of its weight (see docs/figures.md). The
//! command's stance is the true (sprung) model's under the torques sent, so its forces
//! are what the simulator applies, and may leave the cones the QP planned by the servo's
//! share.
//!
//! The problem's sparsity is fixed by the held contacts: the solver is set up once and
//! its data updated in place while they stay the same (a new set of held contacts sets
//! it up again).
//!
//! Where held contacts repeat each other (two points of one rigid foot: Cassie's toe and
//! heel), part of their forces moves nothing: the foot's two points can push apart or
//! together along their line ([`internal_forces`], a basis `N`). The stance solve gives
//! the least of the forces that act, and a foot holds if some split of its load between
//! its points is inside their cones: [`deepest_split`] finds the split that puts every
//! held contact deepest inside its cone (a simulator's forces judged as a rigid foot
//! holds). Both allocate (an SVD, a cone program): they are for judging and analysis.
//! The QP itself puts its cones on the least split; taking `z` in `λ = λ₀ + F u + N z`
//! as variables, allocation-free, is the next step (a first version that did, on heap
//! matrices, broke the controller's allocation bound).

use core::fmt;
use std::vec::Vec;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::{DMatrix, SMatrix, SVector, UnitQuaternion, Vector3};

use super::{
    chart_params, forces_in_world, free_joint, ground_in_chart, stance_system, velocity_derivative,
    RobotDynamicsError, RobotState, Stance,
};
use crate::dynamics::actuation;
use crate::dynamics::contact::{ContactMode, Ground, Modes};
use crate::model::contract::ContactModel;
use crate::model::linalg::Lu;

/// The controller's gains: natural frequencies (rad/s), damping ratio and weights.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BalanceGains {
    /// The body pose's natural frequency `ω_n`: stiffness `ω_n²`, damping `2 ζ ω_n`.
    pub body_frequency: f64,
    /// `ζ` of the body's and the posture's PD.
    pub damping_ratio: f64,
    /// The posture's natural frequency.
    pub posture_frequency: f64,
    /// The posture task's weight beside the body's (1).
    pub posture_weight: f64,
    /// The ground forces' tangential parts' weight, per `m g`-sized force beside a `g`-sized
    /// acceleration: it keeps the forces inside their cones where the tasks allow (the
    /// internal forces between feet cost no acceleration, and the least torques load the
    /// feet sideways up to the cones' edges).
    pub tangential_weight: f64,
    /// The torques' weight, relative to the tasks' mean curvature per torque.
    pub torque_weight: f64,
    /// Where the model has springs: hold them rigid in the controller's model (their
    /// deflections' accelerations zero), as controllers of sprung robots such as Cassie
    /// do. `false` plans with the springs as they are (on Cassie that fails under a push
    /// of 0.51 N: see the module's doc).
    pub rigid_springs: bool,
    /// Where the springs are held rigid: the stiffness of the motor PD towards the
    /// target's posture added to the QP's torques, which damps the spring modes the rigid
    /// model leaves out, per rad in units of `m g ℓ` (0 turns it off).
    pub servo_stiffness: f64,
    /// That PD's damping over its stiffness (s).
    pub servo_damping: f64,
}

impl Default for BalanceGains {
    fn default() -> Self {
        BalanceGains {
            body_frequency: 10.0,
            damping_ratio: 1.0,
            posture_frequency: 10.0,
            posture_weight: 1e-2,
            tangential_weight: 1e-4,
            torque_weight: 1e-8,
            rigid_springs: true,
            servo_stiffness: 0.3,
            servo_damping: 0.1,
        }
    }
}

/// Where the controller holds the robot: the body's pose in the world and the joints'
/// posture (the free joint's six entries of `posture` are not read).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BalanceTarget<const NQ: usize> {
    /// The body frame's origin in the world (m).
    pub position: Vector3<f64>,
    /// The body frame's orientation.
    pub orientation: UnitQuaternion<f64>,
    /// The joints' coordinates.
    pub posture: SVector<f64, NQ>,
}

impl<const NQ: usize> BalanceTarget<NQ> {
    /// The pose and posture of `state`: hold the robot where it stands.
    pub fn holding(state: &RobotState<f64, NQ>) -> Self {
        BalanceTarget {
            position: state.position,
            orientation: state.orientation,
            posture: state.q,
        }
    }
}

/// One tick's command: the torques and what the stance dynamics give under them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BalanceCommand<const NQ: usize, const NC: usize, const NU: usize, const NK: usize> {
    /// The motor torques.
    pub torques: SVector<f64, NU>,
    /// `q̈`, closure and ground forces under `torques`, the ground forces in the world:
    /// the robot's model (springs as they are), so what a simulator applies.
    pub stance: Stance<f64, NQ, NC, NK>,
    /// The ground forces the QP planned inside their cones, in the world: its model's
    /// under its own torques. Where the springs are held rigid, the rigid model's and
    /// without the servo's torques, so they differ from `stance`'s; elsewhere the same.
    pub planned_forces: SVector<f64, NK>,
    /// Clarabel's interior-point iterations.
    pub iterations: u32,
}

/// Why the controller has no command.
#[derive(Clone, Debug, PartialEq)]
pub enum BalanceError {
    /// The stance dynamics failed (or the model is not a floating robot).
    Dynamics(RobotDynamicsError),
    /// No contact is held: there is nothing to balance on.
    NoStance,
    /// Contact `contact` slides: the controller plans for held (sticking) contacts only.
    Sliding {
        /// The contact's index.
        contact: usize,
    },
    /// A torque limit is not a positive finite number.
    TorqueLimit {
        /// The motor's index.
        motor: usize,
        /// Its limit.
        limit: f64,
    },
    /// Clarabel did not solve the QP: `status` is its verdict (`PrimalInfeasible` means
    /// no torques within their limits keep every held contact's force in its cone: the
    /// robot cannot stay on its feet as they are).
    NotSolved {
        /// Clarabel's status.
        status: String,
    },
    /// A gain of the servo is not a finite non-negative number.
    Gain {
        /// The gain's field in [`BalanceGains`].
        gain: &'static str,
        /// Its value.
        value: f64,
    },
    /// The springs cannot be held rigid in the controller's model: `spring`'s
    /// deflection is already held still by the stance (or, `(several)`, some
    /// combination of the springs' is). Plan with the springs as they are
    /// ([`BalanceGains::rigid_springs`] `false`).
    SpringHeld {
        /// The spring's name in the spec.
        spring: &'static str,
    },
    /// [`deepest_split`]'s input is not what it takes: `internal` with other than `NK`
    /// rows, or a force, internal force or friction coefficient that is not finite.
    SplitInput {
        /// What is wrong.
        why: &'static str,
    },
}

impl From<RobotDynamicsError> for BalanceError {
    fn from(e: RobotDynamicsError) -> Self {
        BalanceError::Dynamics(e)
    }
}

impl fmt::Display for BalanceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BalanceError::Dynamics(e) => write!(f, "balance: {e}"),
            BalanceError::NoStance => write!(f, "balance: no contact is held"),
            BalanceError::Sliding { contact } => write!(
                f,
                "balance: contact {contact} slides; the controller plans for held contacts"
            ),
            BalanceError::TorqueLimit { motor, limit } => write!(
                f,
                "balance: motor {motor}'s torque limit {limit} is not a positive finite number"
            ),
            BalanceError::NotSolved { status } => {
                write!(f, "balance: the QP was not solved ({status})")
            }
            BalanceError::SplitInput { why } => write!(f, "deepest split: {why}"),
            BalanceError::Gain { gain, value } => write!(
                f,
                "balance: the gain {gain} = {value} is not a finite non-negative number"
            ),
            BalanceError::SpringHeld { spring } => write!(
                f,
                "balance: spring {spring} cannot be held rigid: the stance already holds its deflection (plan with rigid_springs false)"
            ),
        }
    }
}

impl std::error::Error for BalanceError {}

/// The balance controller of a robot with `NQ` coordinates, `NC` closure rows, `NU`
/// motors and `NK` contact rows (three per contact).
pub struct BalanceController<const NQ: usize, const NC: usize, const NU: usize, const NK: usize> {
    /// Where it holds the robot.
    pub target: BalanceTarget<NQ>,
    /// Its gains.
    pub gains: BalanceGains,
    /// `|u_i| ≤ torque_limit[i]` when given.
    pub torque_limit: Option<SVector<f64, NU>>,
    /// The solver, and the held contacts and constraint rows it was set up for.
    qp: Option<(DefaultSolver<f64>, Modes<NK, 3>, usize)>,
    /// The QP's data, refilled each tick (dense, in the solver's column order).
    p: Vec<f64>,
    q: Vec<f64>,
    a: Vec<f64>,
    b: Vec<f64>,
    /// The force rows in the cones, `(row, scale)`: `(μ λ_n, λ_t₁, λ_t₂)` per contact.
    cone_rows: Vec<(usize, f64)>,
}

impl<const NQ: usize, const NC: usize, const NU: usize, const NK: usize>
    BalanceController<NQ, NC, NU, NK>
{
    /// A controller holding `target` with `gains`.
    pub fn new(
        target: BalanceTarget<NQ>,
        gains: BalanceGains,
        torque_limit: Option<SVector<f64, NU>>,
    ) -> Self {
        BalanceController {
            target,
            gains,
            torque_limit,
            qp: None,
            p: Vec::new(),
            q: Vec::new(),
            a: Vec::new(),
            b: Vec::new(),
            cone_rows: Vec::new(),
        }
    }

    /// The torques for `state`, the contacts in `modes` held on `ground` with friction
    /// `mu` (per row, as [`crate::dynamics::contact::spec_friction`]).
    pub fn command<L>(
        &mut self,
        params: &L::Params<f64>,
        state: &RobotState<f64, NQ>,
        modes: &Modes<NK, 3>,
        ground: &Ground<f64, 3>,
        mu: &SVector<f64, NK>,
    ) -> Result<BalanceCommand<NQ, NC, NU, NK>, BalanceError>
    where
        L: ContactModel<NQ, NC, NU, NK, 3>,
    {
        let contacts = NK / 3;
        let mut held = 0;
        for k in 0..contacts {
            match modes.get(k) {
                ContactMode::Stick => held += 1,
                ContactMode::Slide { .. } => return Err(BalanceError::Sliding { contact: k }),
                ContactMode::Flight => {}
            }
        }
        if held == 0 {
            return Err(BalanceError::NoStance);
        }
        if let Some(lim) = &self.torque_limit {
            if let Some((motor, &limit)) = lim
                .iter()
                .enumerate()
                .find(|(_, l)| !(l.is_finite() && **l > 0.0))
            {
                return Err(BalanceError::TorqueLimit { motor, limit });
            }
        }
        let g = &self.gains;
        for (gain, value) in [
            ("servo_stiffness", g.servo_stiffness),
            ("servo_damping", g.servo_damping),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(BalanceError::Gain { gain, value });
            }
        }
        let f = free_joint::<L, NQ, NC, NU>().map_err(RobotDynamicsError::from)?;
        let mut s = *state;
        s.recentre(f);
        let (system, local, orientation) =
            stance_system::<L, f64, NQ, NC, NU, NK>(params, &s, modes, ground, mu)?;
        let solve_applied = |applied: &SVector<f64, NQ>| {
            system
                .solve(applied)
                .map_err(|e| BalanceError::Dynamics(e.into()))
        };
        let solve = |u: &SVector<f64, NU>| solve_applied(&actuation::<L, f64, NQ, NC, NU>(u));
        // The affine maps q̈ = q̈₀ + A u, λ = λ₀ + F u.
        let free = solve(&SVector::zeros())?;
        let mut accel = SMatrix::<f64, NQ, NU>::zeros();
        let mut force = SMatrix::<f64, NK, NU>::zeros();
        for i in 0..NU {
            let mut e = SVector::<f64, NU>::zeros();
            e[i] = 1.0;
            let x = solve(&e)?;
            accel.set_column(i, &(x.x - free.x));
            force.set_column(i, &(x.contact - free.contact));
        }
        // Where the legs carry springs, the controller's model holds them rigid: a
        // virtual generalized force `σ_j` along each spring's deflection holds the
        // deflection's acceleration at zero, `S (q̈₀ + A u + A_σ σ) = 0`, and `σ`
        // substituted gives the rigid model's maps (`A_σ`, `F_σ` from one solve each).
        let mut free = free;
        let springs = L::SPRINGS.len();
        let rigid = self.gains.rigid_springs && springs > 0;
        if rigid {
            // A spring's deflection: q_a, or q_a − q_b for a coupling spring.
            let deflection = |j: usize, x: &dyn Fn(usize) -> f64| {
                let sp = &L::SPRINGS[j];
                x(sp.a) - sp.b.map_or(0.0, x)
            };
            let mut a_s = SMatrix::<f64, NQ, NQ>::zeros();
            let mut f_s = SMatrix::<f64, NK, NQ>::zeros();
            for (j, sp) in L::SPRINGS.iter().enumerate() {
                let mut along = SVector::<f64, NQ>::zeros();
                along[sp.a] = 1.0;
                if let Some(b) = sp.b {
                    along[b] = -1.0;
                }
                let x = solve_applied(&along)?;
                a_s.set_column(j, &(x.x - free.x));
                f_s.set_column(j, &(x.contact - free.contact));
            }
            // `S A_σ`, padded to NQ × NQ with a multiple of the identity; `S q̈₀` and `S A`
            // beside it.
            let mut a_ss = SMatrix::<f64, NQ, NQ>::zeros();
            let mut rhs = SMatrix::<f64, NQ, NU>::zeros();
            let mut rhs0 = SVector::<f64, NQ>::zeros();
            for i in 0..springs {
                for j in 0..springs {
                    a_ss[(i, j)] = deflection(i, &|r| a_s[(r, j)]);
                }
                for j in 0..NU {
                    rhs[(i, j)] = deflection(i, &|r| accel[(r, j)]);
                }
                rhs0[i] = deflection(i, &|r| free.x[r]);
            }
            // A spring the stance already holds still has no virtual force to find (its
            // diagonal, a mobility, is zero to rounding against the others').
            let largest = (0..springs).fold(0.0f64, |m, j| m.max(a_ss[(j, j)].abs()));
            let still = |d: f64| d.is_nan() || d <= 1e-12 * largest;
            if let Some(j) = (0..springs).find(|&j| still(a_ss[(j, j)])) {
                return Err(BalanceError::SpringHeld {
                    spring: L::SPRINGS[j].name,
                });
            }
            for j in springs..NQ {
                a_ss[(j, j)] = largest;
            }
            let Some(lu) = Lu::new(&a_ss) else {
                return Err(BalanceError::SpringHeld {
                    spring: "(several)",
                });
            };
            let k0 = lu.solve(&rhs0);
            let ka = lu.solve(&rhs);
            free.x -= a_s * k0;
            free.contact -= f_s * k0;
            accel -= a_s * ka;
            force -= f_s * ka;
        }

        // The tasks: the desired q̈ of each coordinate and its row's scale.
        let size = L::leg_size(&s.q, params);
        let (kp, kd) = (
            g.body_frequency * g.body_frequency,
            2.0 * g.damping_ratio * g.body_frequency,
        );
        let (jp, jd) = (
            g.posture_frequency * g.posture_frequency,
            2.0 * g.damping_ratio * g.posture_frequency,
        );
        let mut desired = SVector::<f64, NQ>::zeros();
        let mut scale = SVector::<f64, NQ>::zeros();
        // The body: p̈* in the world, which is R₀ q̈_δ in the chart centred on it.
        let velocity = orientation.transform_vector(&Vector3::new(s.v[f], s.v[f + 1], s.v[f + 2]));
        let linear = orientation
            .inverse_transform_vector(&(-(s.position - self.target.position) * kp - velocity * kd));
        // ω̇* in the body frame, then the angles' q̈ = ω̇ − Ė θ̇ at the centre.
        let error = (self.target.orientation.inverse() * orientation).scaled_axis();
        let omega = Vector3::new(s.v[f + 3], s.v[f + 4], s.v[f + 5]);
        let bias = velocity_derivative(f, &s.v, &SVector::zeros());
        let angular = -error * kp - omega * kd;
        for k in 0..3 {
            desired[f + k] = linear[k];
            scale[f + k] = 1.0;
            desired[f + 3 + k] = angular[k] - bias[f + 3 + k];
            scale[f + 3 + k] = size;
        }
        let posture_scale = g.posture_weight.sqrt() * size;
        for i in (0..NQ).filter(|&i| i < f || i >= f + 6) {
            desired[i] = -jp * (s.q[i] - self.target.posture[i]) - jd * s.v[i];
            scale[i] = posture_scale;
        }
        // ½|W(q̈₀ + A u − a*)|² + ½ w_u |u|²: P = (WA)ᵀ WA + w_u I, c = (WA)ᵀ W(q̈₀ − a*),
        // and the tangential forces' term likewise.
        let wa = SMatrix::<f64, NQ, NQ>::from_diagonal(&scale) * accel;
        let residual = (free.x - desired).component_mul(&scale);
        let mut hessian = wa.transpose() * wa;
        let mut linear_cost = wa.transpose() * residual;
        // The tangential forces of the held contacts, over the mass (an acceleration).
        let mass = system.mass_matrix[(f, f)];
        let wt = g.tangential_weight.sqrt() / mass;
        for k in (0..contacts).filter(|&k| modes.get(k) == ContactMode::Stick) {
            for r in [3 * k, 3 * k + 1] {
                let row = force.row(r) * wt;
                hessian += row.transpose() * row;
                linear_cost += row.transpose() * (free.contact[r] * wt);
            }
        }
        let mean = hessian.trace() / NU as f64;
        let ridge = g.torque_weight * mean.max(f64::MIN_POSITIVE);
        for i in 0..NU {
            hessian[(i, i)] += ridge;
        }

        // Constraints s = b − A u ∈ K: per held contact (μ λ_n, λ_t₁, λ_t₂) in the
        // second-order cone, then the torque limits.
        let limits = self.torque_limit.is_some();
        let rows = 3 * held + if limits { 2 * NU } else { 0 };
        self.p.clear();
        for j in 0..NU {
            for i in 0..=j {
                self.p.push(hessian[(i, j)]);
            }
        }
        self.q.clear();
        self.q.extend(linear_cost.iter());
        self.b.clear();
        let cone_rows = &mut self.cone_rows;
        cone_rows.clear();
        for k in (0..contacts).filter(|&k| modes.get(k) == ContactMode::Stick) {
            let m = mu[3 * k + 2];
            cone_rows.push((3 * k + 2, m));
            cone_rows.push((3 * k, 1.0));
            cone_rows.push((3 * k + 1, 1.0));
        }
        for &(r, m) in cone_rows.iter() {
            self.b.push(m * free.contact[r]);
        }
        if let Some(lim) = &self.torque_limit {
            self.b.extend(lim.iter());
            self.b.extend(lim.iter());
        }
        self.a.clear();
        for j in 0..NU {
            for &(r, m) in cone_rows.iter() {
                self.a.push(-m * force[(r, j)]);
            }
            if limits {
                for i in 0..NU {
                    self.a.push(if i == j { 1.0 } else { 0.0 });
                }
                for i in 0..NU {
                    self.a.push(if i == j { -1.0 } else { 0.0 });
                }
            }
        }

        // Set up again where the held contacts or the rows (torque limits on or off)
        // changed: the data's pattern is the solver's.
        let setup = !matches!(&self.qp, Some((_, m, r)) if m == modes && *r == rows);
        if setup {
            let p = CscMatrix::new(
                NU,
                NU,
                (0..=NU).map(|j| j * (j + 1) / 2).collect(),
                (0..NU).flat_map(|j| 0..=j).collect(),
                self.p.clone(),
            );
            let a = CscMatrix::new(
                rows,
                NU,
                (0..=NU).map(|j| j * rows).collect(),
                (0..NU).flat_map(|_| 0..rows).collect(),
                self.a.clone(),
            );
            let mut cones = Vec::with_capacity(held + 1);
            cones.extend((0..held).map(|_| SupportedConeT::SecondOrderConeT(3)));
            if limits {
                cones.push(SupportedConeT::NonnegativeConeT(2 * NU));
            }
            let solver =
                DefaultSolver::new(&p, &self.q, &a, &self.b, &cones, settings()).map_err(|e| {
                    BalanceError::NotSolved {
                        status: format!("set-up: {e}"),
                    }
                })?;
            self.qp = Some((solver, *modes, rows));
        }
        let Some((solver, _, _)) = self.qp.as_mut() else {
            unreachable!("set up above")
        };
        if !setup {
            if let Err(e) = solver.update_data(&self.p, &self.q, &self.a, &self.b) {
                self.qp = None;
                return Err(BalanceError::NotSolved {
                    status: format!("update: {e}"),
                });
            }
        }
        solver.solve();
        let out = &solver.solution;
        match out.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {}
            status => {
                // Set up afresh next time: an interrupted solve leaves nothing to reuse.
                let status = format!("{status:?}");
                self.qp = None;
                return Err(BalanceError::NotSolved { status });
            }
        }
        let mut torques = SVector::<f64, NU>::from_column_slice(&out.x);
        let planned_forces =
            forces_in_world(&local, &orientation, &(free.contact + force * torques));
        if rigid && g.servo_stiffness > 0.0 {
            // The servo the QP does not see (it would cancel it): its torques are outside
            // the QP's plan, and the limits clip their sum.
            let gravity = super::world_gravity::<L, f64, NQ, NC, NU>(params)
                .map_err(RobotDynamicsError::from)?
                .norm();
            let k = g.servo_stiffness * mass * gravity * size;
            for (j, &a) in L::ACTUATED.iter().enumerate() {
                torques[j] -= k * ((s.q[a] - self.target.posture[a]) + g.servo_damping * s.v[a]);
            }
            if let Some(lim) = &self.torque_limit {
                for j in 0..NU {
                    torques[j] = torques[j].clamp(-lim[j], lim[j]);
                }
            }
        }
        let iterations = out.iterations;
        let solution = solve(&torques)?;
        Ok(BalanceCommand {
            torques,
            stance: Stance {
                world_forces: forces_in_world(&local, &orientation, &solution.contact),
                solution,
            },
            planned_forces,
            iterations,
        })
    }
}

/// The held contacts' internal forces at `state`: an orthonormal basis (columns) of the
/// ground forces on the contacts in `modes` that sticking hold and that move nothing,
/// their generalized force taken up by the closures alone (`Cᵀ λ + Jᵀ μ = 0` for some
/// closure forces `μ`). Rows as [`crate::dynamics::contact::ContactSolution::contact`]:
/// `(λ_t₁, λ_t₂, λ_n)` per contact in the frame of the ground seen from the chart centred
/// on the body. None (zero columns) where no held rows repeat each other; one for each
/// rigid foot held at two points (they may push apart or together along their line).
pub fn internal_forces<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<f64>,
    state: &RobotState<f64, NQ>,
    modes: &Modes<NK, 3>,
    ground: &Ground<f64, 3>,
) -> Result<DMatrix<f64>, RobotDynamicsError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let f = free_joint::<L, NQ, NC, NU>()?;
    let mut s = *state;
    s.recentre(f);
    let chart = chart_params::<L, f64, NQ, NC, NU>(params, &s.orientation)?;
    let frame = ground_in_chart(ground, &s.position, &s.orientation).frame();
    let contact = L::contact_jacobian(&s.q, &chart);
    let closure = L::constraint_jacobian(&s.q, &chart);
    let held: Vec<usize> = (0..NK)
        .filter(|&r| modes.get(r / 3) == ContactMode::Stick)
        .collect();
    let (nh, n) = (held.len(), held.len() + NC);
    // A = [Cᵀ Jᵀ] (NQ × n), padded with zero rows to be at least square so that the SVD
    // gives all of V; its null space is V's columns whose singular values are below
    // 1e-9 of the largest.
    let a = DMatrix::<f64>::from_fn(NQ.max(n), n, |i, j| {
        if i >= NQ {
            0.0
        } else if j < nh {
            let r = held[j];
            let (k, row) = (r / 3, r % 3);
            (0..3)
                .map(|c| frame[(row, c)] * contact[(3 * k + c, i)])
                .sum()
        } else {
            closure[(j - nh, i)]
        }
    });
    if nh == 0 || !a.iter().all(|x| x.is_finite()) {
        return Ok(DMatrix::zeros(NK, 0));
    }
    let svd = a.svd(false, true);
    let v_t = svd.v_t.expect("asked for");
    let top = svd.singular_values.amax();
    let null: Vec<usize> = (0..n)
        .filter(|&i| svd.singular_values[i] <= 1e-9 * top)
        .collect();
    if null.is_empty() {
        return Ok(DMatrix::zeros(NK, 0));
    }
    // Their contact parts (unit null vectors whose contact part is nothing are closure
    // rows repeating each other), made orthonormal.
    let parts = v_t.select_rows(&null).transpose().rows(0, nh).into_owned();
    let svd = parts.svd(true, false);
    let u = svd.u.expect("asked for");
    let keep: Vec<usize> = (0..svd.singular_values.len())
        .filter(|&i| svd.singular_values[i] > 1e-6)
        .collect();
    let mut out = DMatrix::<f64>::zeros(NK, keep.len());
    for (c, &i) in keep.iter().enumerate() {
        for (j, &r) in held.iter().enumerate() {
            out[(r, c)] = u[(j, i)];
        }
    }
    Ok(out)
}

/// The split of the held contacts' internal forces (`internal`, from [`internal_forces`])
/// that puts every held contact deepest inside its friction cone: `forces + N z` with
/// `z` maximizing the least margin `μ_k λ_n,k − |λ_t,k|` (N) over the contacts in
/// `modes` that stick, and that margin, negative where no split keeps every held contact
/// in its cone (the feet slip whatever the split). `forces` and the result are in the
/// ground's frame per contact (`(λ_t₁, λ_t₂, λ_n)`); with no internal forces they are
/// `forces` unchanged. A second-order cone program, by Clarabel. Refuses (`SplitInput`)
/// `internal` with other than `NK` rows and non-finite input.
pub fn deepest_split<const NK: usize>(
    forces: &SVector<f64, NK>,
    internal: &DMatrix<f64>,
    modes: &Modes<NK, 3>,
    mu: &SVector<f64, NK>,
) -> Result<(SVector<f64, NK>, f64), BalanceError> {
    if internal.nrows() != NK {
        return Err(BalanceError::SplitInput {
            why: "the internal forces have other than one row per contact row",
        });
    }
    let finite = |x: &f64| x.is_finite();
    if !(forces.iter().all(finite) && internal.iter().all(finite) && mu.iter().all(finite)) {
        return Err(BalanceError::SplitInput {
            why: "a force, internal force or friction coefficient is not finite",
        });
    }
    let held: Vec<usize> = (0..NK / 3)
        .filter(|&k| modes.get(k) == ContactMode::Stick)
        .collect();
    let margin = |l: &SVector<f64, NK>| {
        held.iter().fold(f64::INFINITY, |m, &k| {
            m.min(mu[3 * k + 2] * l[3 * k + 2] - l[3 * k].hypot(l[3 * k + 1]))
        })
    };
    let nz = internal.ncols();
    if nz == 0 || held.is_empty() {
        return Ok((*forces, margin(forces)));
    }
    // Variables (z, t); minimize −t; per held contact (μ λ_n − t, λ_t₁, λ_t₂) ∈ SOC,
    // as s = b − A x with λ = forces + N z.
    let nx = nz + 1;
    let rows = 3 * held.len();
    let mut b = Vec::with_capacity(rows);
    let mut a = vec![0.0; rows * nx];
    for (i, &k) in held.iter().enumerate() {
        let m = mu[3 * k + 2];
        for (o, (r, scale)) in [(3 * k + 2, m), (3 * k, 1.0), (3 * k + 1, 1.0)]
            .into_iter()
            .enumerate()
        {
            let row = 3 * i + o;
            b.push(scale * forces[r]);
            for c in 0..nz {
                a[c * rows + row] = -scale * internal[(r, c)];
            }
            if o == 0 {
                a[nz * rows + row] = 1.0;
            }
        }
    }
    let p = CscMatrix::new(nx, nx, vec![0; nx + 1], Vec::new(), Vec::new());
    let mut q = vec![0.0; nx];
    q[nz] = -1.0;
    let a = CscMatrix::new(
        rows,
        nx,
        (0..=nx).map(|j| j * rows).collect(),
        (0..nx).flat_map(|_| 0..rows).collect(),
        a,
    );
    let cones: Vec<_> = held
        .iter()
        .map(|_| SupportedConeT::SecondOrderConeT(3))
        .collect();
    let mut solver = DefaultSolver::new(&p, &q, &a, &b, &cones, settings()).map_err(|e| {
        BalanceError::NotSolved {
            status: format!("set-up: {e}"),
        }
    })?;
    solver.solve();
    match solver.solution.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => {}
        status => {
            return Err(BalanceError::NotSolved {
                status: format!("{status:?}"),
            })
        }
    }
    let mut out = *forces;
    for c in 0..nz {
        let z = solver.solution.x[c];
        for r in 0..NK {
            out[r] += internal[(r, c)] * z;
        }
    }
    Ok((out, margin(&out)))
}

/// Clarabel's settings: quiet, and no presolve (it would forbid updating the data in
/// place).
fn settings() -> DefaultSettings<f64> {
    DefaultSettingsBuilder::default()
        .verbose(false)
        .presolve_enable(false)
        .build()
        .expect("valid settings")
}

/// What [`cone_reading`] reads of one contact's force.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConeReading {
    /// The force (N, world).
    pub force: Vector3<f64>,
    /// Along the ground's normal (N).
    pub normal: f64,
    /// Along the ground (N).
    pub tangential: f64,
    /// `‖λ_t‖ / (μ λ_n)`: at most 1 inside the friction cone, 0 for a contact that bears
    /// nothing, infinite where it pulls or slides on no load.
    pub ratio: f64,
}

/// Contact `k`'s force from `world_forces` (three a contact, in the world), its normal
/// and tangential parts on `ground`, and how far it is into its friction cone.
pub fn cone_reading<const NK: usize>(
    world_forces: &SVector<f64, NK>,
    ground: &Ground<f64, 3>,
    mu: &SVector<f64, NK>,
    k: usize,
) -> ConeReading {
    let force = Vector3::new(
        world_forces[3 * k],
        world_forces[3 * k + 1],
        world_forces[3 * k + 2],
    );
    let normal = force.dot(&ground.normal);
    let tangential = (force - ground.normal * normal).norm();
    let ratio = if normal > 0.0 {
        tangential / (mu[3 * k + 2] * normal)
    } else if normal == 0.0 && tangential == 0.0 {
        0.0
    } else {
        f64::INFINITY
    };
    ConeReading {
        force,
        normal,
        tangential,
        ratio,
    }
}

/// The ground forces of `stance` (a step from `before` on `ground`) in the world, with
/// their internal part split as puts every held contact deepest inside its cone
/// ([`deepest_split`]): two points of one rigid foot hold if any split of its load
/// between them does, whatever split the stance solve reports (the least). Where no held
/// rows repeat each other, the stance's own forces.
pub fn judged_forces<L, const NQ: usize, const NC: usize, const NU: usize, const NK: usize>(
    params: &L::Params<f64>,
    before: &RobotState<f64, NQ>,
    stance: &Stance<f64, NQ, NC, NK>,
    modes: &Modes<NK, 3>,
    ground: &Ground<f64, 3>,
    mu: &SVector<f64, NK>,
) -> Result<SVector<f64, NK>, BalanceError>
where
    L: ContactModel<NQ, NC, NU, NK, 3>,
{
    let internal = internal_forces::<L, NQ, NC, NU, NK>(params, before, modes, ground)?;
    if internal.ncols() == 0 {
        return Ok(stance.world_forces);
    }
    let (split, _) = deepest_split(&stance.solution.contact, &internal, modes, mu)?;
    let local = ground_in_chart(ground, &before.position, &before.orientation);
    Ok(forces_in_world(&local, &before.orientation, &split))
}
