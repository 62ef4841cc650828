//! The measures of [`super`] over a square grid of foot positions: the workspace of one
//! assembly branch, found by continuation from an assembled pose (each node's pose is
//! solved from a neighbour's, so the branch never changes), and the singularity curves
//! drawn through it.
//!
//! A spatial leg's foot moves in space: its grid lies in a [`SlicePlane`] through the
//! stance foot (sagittal by default), each node a foot position in that plane solved by
//! the same continuation, its curves and area those of the slice.
//!
//! In foot space the foot's rank loss ("type I") is where the branch ends: the edge of the
//! workspace. The passive joints' rank loss ("type II") is inside it, where the signed
//! [`PointMeasures::passive_rank`] changes sign between neighbouring nodes.

use std::collections::VecDeque;

use nalgebra::{SVector, Vector3};

use super::{passive_rank, point_measures, AnalysisError, LegFrame, MotorLimits, PointMeasures};
use crate::assembly::{foot_inverse_holding, Tolerance};
use crate::model::contract::{LegDynamics, LegModel};

/// The plane a spatial leg's workspace grid lies in: through the stance foot, spanned by
/// two orthogonal unit axes of the base frame. Grid coordinates are the foot's components
/// along them (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SlicePlane {
    /// The grid's first (`a`) and second (`b`) axis, unit and orthogonal.
    pub axes: [[f64; 3]; 2],
}

impl SlicePlane {
    /// The sagittal plane: `x` forward, `z` up (the default).
    pub const SAGITTAL: SlicePlane = SlicePlane {
        axes: [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
    };
    /// The frontal plane: `y` to the side, `z` up.
    pub const FRONTAL: SlicePlane = SlicePlane {
        axes: [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    };
    /// The transverse (horizontal) plane: `x`, `y`.
    pub const TRANSVERSE: SlicePlane = SlicePlane {
        axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
    };

    /// The plane spanned by `a` and `b` (made unit; they must be finite, not zero and
    /// orthogonal to 1e-9).
    pub fn new(a: [f64; 3], b: [f64; 3]) -> Result<SlicePlane, AnalysisError> {
        let (u, w) = (Vector3::from(a), Vector3::from(b));
        for v in [&u, &w] {
            if !v.iter().all(|x| x.is_finite()) || v.norm() == 0.0 {
                return Err(AnalysisError::Grid {
                    what: "slice axes that are finite and not zero",
                    value: v.norm(),
                });
            }
        }
        let (u, w) = (u.normalize(), w.normalize());
        if u.dot(&w).abs() > 1e-9 {
            return Err(AnalysisError::Grid {
                what: "orthogonal slice axes (their cosine)",
                value: u.dot(&w),
            });
        }
        Ok(SlicePlane {
            axes: [u.into(), w.into()],
        })
    }

    fn checked(&self) -> Result<SlicePlane, AnalysisError> {
        SlicePlane::new(self.axes[0], self.axes[1])
    }
}

/// How the grid is laid out and what limits apply.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridOptions<const NU: usize> {
    /// Nodes per side (the grid has `nodes²`).
    pub nodes: usize,
    /// The grid's centre (grid coordinates) and half-width (m); `None`: centred on the hip
    /// of the foot's chain, as wide as that chain is long.
    pub window: Option<([f64; 2], f64)>,
    /// A spatial leg's slice ([`SlicePlane`]); `None`: sagittal. A planar leg's grid is
    /// its own plane and takes none.
    pub plane: Option<SlicePlane>,
    /// Motor angle range `(low, high)` per motor (rad, a revolute motor's modulo a turn;
    /// m on a slider); `None`: no limit.
    pub motor_range: Option<[(f64, f64); NU]>,
    /// Torque and speed limits of the force and speed measures.
    pub limits: MotorLimits<f64, NU>,
}

/// The fewest and the most nodes per side a grid takes: a grid of 2000² nodes is
/// 4·10⁶ continuation solves and about 200 MB of poses on a five-joint leg.
pub const GRID_NODES: core::ops::RangeInclusive<usize> = 2..=2000;

impl<const NU: usize> GridOptions<NU> {
    /// The options' rules, checked before anything is allocated: nodes per side in
    /// [`GRID_NODES`], a finite window with a positive half-width, each motor range finite
    /// with `low < high` (no limit is `None`; a revolute range a turn wide limits nothing).
    pub fn check(&self) -> Result<(), AnalysisError> {
        let bad = |what, value| Err(AnalysisError::Grid { what, value });
        if !GRID_NODES.contains(&self.nodes) {
            return bad("from 2 to 2000 nodes per side", self.nodes as f64);
        }
        if let Some((centre, half)) = self.window {
            if let Some(&c) = centre.iter().find(|c| !c.is_finite()) {
                return bad("a finite centre", c);
            }
            if !(half.is_finite() && half > 0.0) {
                return bad("a positive, finite half-width", half);
            }
        }
        if let Some(plane) = &self.plane {
            plane.checked()?;
        }
        for &(low, high) in self.motor_range.iter().flatten() {
            if !low.is_finite() {
                return bad("each motor range (low, high) finite", low);
            }
            if !(high.is_finite() && low < high) {
                return bad(
                    "each motor range (low, high) finite with low below high",
                    high,
                );
            }
        }
        Ok(())
    }
}

/// What happened at a node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NodeState {
    /// Not reached from the start (outside the branch's connected workspace).
    Unvisited,
    /// On the branch: the foot can be put here.
    Reached,
    /// Next to a reached node but not reachable on the branch (the branch ends).
    BranchEnds,
    /// Reachable, but a motor is outside its range.
    OutOfRange,
}

impl NodeState {
    /// The state's name in the written grids (`reached`, `branch_ends`, `out_of_range`,
    /// `unvisited`).
    pub fn name(self) -> &'static str {
        match self {
            NodeState::Reached => "reached",
            NodeState::BranchEnds => "branch_ends",
            NodeState::OutOfRange => "out_of_range",
            NodeState::Unvisited => "unvisited",
        }
    }
}

/// A line segment in the base frame (m).
pub type Segment = [[f64; 2]; 2];

/// The measures over the grid (of a planar leg's plane, or of a spatial leg's slice: its
/// foot has `ND` coordinates).
#[derive(Clone, Debug)]
pub struct Workspace<const NQ: usize, const NU: usize, const ND: usize = 2> {
    /// Nodes per side.
    pub nodes: usize,
    /// A spatial leg's slice (the plane's axes and its offset along their normal, m);
    /// `None` on a planar leg.
    pub slice: Option<(SlicePlane, f64)>,
    /// The node `(0, 0)` (lowest `a`, lowest `b`: `x` and `y` on a planar leg), grid
    /// coordinates (m).
    pub origin: [f64; 2],
    /// Node spacing (m).
    pub step: f64,
    /// Each node's state, row by row (`index = iy · nodes + ix`).
    pub states: Vec<NodeState>,
    /// Each reached node's pose (zero elsewhere).
    pub poses: Vec<SVector<f64, NQ>>,
    /// Each reached node's measures; `Err` where they cannot be computed there (a
    /// singular pose), `None` at nodes not reached.
    pub measures: Vec<Option<Result<PointMeasures<f64, NQ, NU, ND>, AnalysisError>>>,
    /// The passive rank measure at each reached node (NaN elsewhere).
    pub passive_rank: Vec<f64>,
    /// Which joints are revolute (compared modulo a turn by [`Workspace::joined`]).
    pub revolute: [bool; NQ],
    /// Whether [`Workspace::passive_rank`] is signed (its zero crossings are curves).
    pub passive_signed: bool,
    /// Workspace area (of the slice, on a spatial leg): reached nodes × step² (m²).
    pub area: f64,
    /// Where the passive joints lose rank ("type II"), as segments.
    pub passive_curves: Vec<Segment>,
    /// Where the foot loses a direction ("type I"): the edge where the branch ends, and
    /// sign changes of the foot's rank measure inside.
    pub foot_curves: Vec<Segment>,
}

impl<const NQ: usize, const NU: usize, const ND: usize> Workspace<NQ, NU, ND> {
    /// The foot position of node `(ix, iy)`, in grid coordinates.
    pub fn node(&self, ix: usize, iy: usize) -> [f64; 2] {
        [
            self.origin[0] + ix as f64 * self.step,
            self.origin[1] + iy as f64 * self.step,
        ]
    }

    /// Whether nodes `a` and `b` are joined on the branch: both reached, no joint
    /// differing by more than a branch step ([`JUMP`]; angles modulo a turn, since going
    /// round a hole of the workspace adds 2π). Two fronts of the continuation that met on
    /// different solutions are not joined: a seam, not a singularity.
    pub fn joined(&self, a: usize, b: usize) -> bool {
        if self.states[a] != NodeState::Reached || self.states[b] != NodeState::Reached {
            return false;
        }
        (0..NQ).all(|j| {
            let mut d = self.poses[a][j] - self.poses[b][j];
            if self.revolute[j] {
                d = (d + core::f64::consts::PI).rem_euclid(core::f64::consts::TAU)
                    - core::f64::consts::PI;
            }
            d.abs() <= JUMP
        })
    }

    /// The foot position (base frame) at grid coordinates `ab`.
    pub fn foot_at(&self, ab: [f64; 2]) -> SVector<f64, ND> {
        embed(self.slice.as_ref(), ab)
    }

    /// The grid coordinates of the foot position `foot` (base frame): its components
    /// along the slice's axes.
    pub fn grid_coordinates(&self, foot: &SVector<f64, ND>) -> [f64; 2] {
        project(self.slice.as_ref(), foot)
    }

    /// The distance (m) from `point` (grid coordinates) to the nearest singularity curve
    /// (either kind); `None` when there is none in the grid.
    pub fn distance_to_singularity(&self, point: [f64; 2]) -> Option<f64> {
        self.passive_curves
            .iter()
            .chain(&self.foot_curves)
            .map(|s| segment_distance(point, s))
            .fold(None, |best, d| Some(best.map_or(d, |b: f64| b.min(d))))
    }
}

/// The foot at grid coordinates `ab`: `(a, b)` in the plane; `a u + b w + d n` on a slice
/// (`n = u × w`, `d` its offset).
fn embed<const ND: usize>(slice: Option<&(SlicePlane, f64)>, ab: [f64; 2]) -> SVector<f64, ND> {
    match slice {
        Some((plane, offset)) if ND == 3 => {
            let (u, w) = (Vector3::from(plane.axes[0]), Vector3::from(plane.axes[1]));
            let p = u * ab[0] + w * ab[1] + u.cross(&w) * *offset;
            SVector::from_fn(|r, _| p[r])
        }
        _ => SVector::from_fn(|r, _| if r < 2 { ab[r] } else { 0.0 }),
    }
}

/// The grid coordinates of `foot`: [`embed`]'s inverse on the slice.
fn project<const ND: usize>(
    slice: Option<&(SlicePlane, f64)>,
    foot: &SVector<f64, ND>,
) -> [f64; 2] {
    match slice {
        Some((plane, _)) if ND == 3 => {
            let p = Vector3::new(foot[0], foot[1], foot[2]);
            [
                Vector3::from(plane.axes[0]).dot(&p),
                Vector3::from(plane.axes[1]).dot(&p),
            ]
        }
        _ => [foot[0], foot[1]],
    }
}

/// Distance from `p` to the segment `s`.
pub fn segment_distance(p: [f64; 2], s: &Segment) -> f64 {
    let (a, b) = (s[0], s[1]);
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// The hip of the foot's chain (base frame) and the chain's length at pose `q` (the
/// joints that move the foot in the tree, without held ones): the default window.
pub fn reach<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    params: &L::Params<f64>,
    q: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
) -> (SVector<f64, ND>, f64)
where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    let jf = L::foot_jacobian(q, params);
    let joints = L::joint_positions(q, params);
    let foot = L::foot_position(q, params);
    let size = crate::assembly::leg_size::<L, f64, NQ, NC, NU>(params, q);
    let in_chain = |j: usize| !frame.held[j] && jf.column(j).amax() > 0.0;
    // The chain from the hip down: each chain joint's depth in the tree.
    let depth = |j: usize| {
        let (mut d, mut k) = (0, L::PARENTS[j]);
        while let Some(p) = k {
            d += 1;
            k = L::PARENTS[p];
        }
        d
    };
    let mut chain: Vec<usize> = (0..NQ).filter(|&j| in_chain(j)).collect();
    chain.sort_by_key(|&j| depth(j));
    let Some(&hip) = chain.first() else {
        return (foot, size.max(f64::EPSILON));
    };
    let point = |j: usize| joints.column(j).into_owned();
    let mut length = 0.0;
    let mut last = point(hip);
    for &j in chain.iter().skip(1) {
        let p = point(j);
        length += (p - last).norm();
        last = p;
    }
    length += (foot - last).norm();
    // A slider's reach is not fixed by its pose: allow the leg's size for each.
    let sliders = chain
        .iter()
        .filter(|&&j| L::JOINT_KINDS[j] == crate::model::contract::JointKind::Prismatic)
        .count();
    (point(hip), length + sliders as f64 * size)
}

/// The workspace of the branch of `start` (an assembled pose) over the grid, with every
/// measure at every node. Allocates the grid; each node's work allocates nothing.
pub fn workspace<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    params: &L::Params<f64>,
    start: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    options: &GridOptions<NU>,
) -> Result<Workspace<NQ, NU, ND>, AnalysisError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    options.check()?;
    if ND == 2 && options.plane.is_some() {
        return Err(super::Inapplicable::PlanarSlice.into());
    }
    frame.foot_spans(ND)?;
    let n = options.nodes;
    let foot = L::foot_position(start, params);
    // The slice through the stance foot, its axes made unit (longer ones, which check()
    // accepts, would scale the grid).
    let plane = options
        .plane
        .map_or(Ok(SlicePlane::SAGITTAL), |p| p.checked())?;
    let slice = (ND == 3).then(|| {
        let (u, w) = (Vector3::from(plane.axes[0]), Vector3::from(plane.axes[1]));
        let offset = u.cross(&w).dot(&Vector3::new(foot[0], foot[1], foot[2]));
        (plane, offset)
    });
    let (center, half) = options.window.unwrap_or_else(|| {
        let (hip, length) = reach::<L, NQ, NC, NU, ND, NP>(params, start, frame);
        (project(slice.as_ref(), &hip), length)
    });
    let step = 2.0 * half / (n - 1) as f64;
    let origin = [center[0] - half, center[1] - half];
    let at = |i: usize| -> SVector<f64, ND> {
        embed(
            slice.as_ref(),
            [
                origin[0] + (i % n) as f64 * step,
                origin[1] + (i / n) as f64 * step,
            ],
        )
    };
    start_in_range::<L, NQ, NC, NU>(start, options.motor_range.as_ref())?;
    // The node nearest the start's foot, solved from the start.
    let stance = project(slice.as_ref(), &foot);
    let ix = (((stance[0] - origin[0]) / step).round().max(0.0) as usize).min(n - 1);
    let iy = (((stance[1] - origin[1]) / step).round().max(0.0) as usize).min(n - 1);
    let neighbours = |i: usize| {
        let (x, y) = (i % n, i / n);
        [
            (x > 0).then(|| i - 1),
            (x + 1 < n).then(|| i + 1),
            (y > 0).then(|| i - n),
            (y + 1 < n).then(|| i + n),
            None,
            None,
        ]
    };
    let (states, poses) = continuation::<L, NQ, NC, NU, ND, NP>(
        params,
        start,
        frame,
        options.motor_range.as_ref(),
        n * n,
        iy * n + ix,
        at,
        neighbours,
    )?;
    let fixed: [bool; NQ] = core::array::from_fn(|c| frame.held[c] || L::ACTUATED.contains(&c));
    // Curves in foot space need the pose to be a function of the foot on the branch (two
    // motors that determine the leg): with more, the pose at a foot depends on the path.
    let passive_signed = NU == ND && NC > 0 && super::passive_square::<L, NQ, NC, NU>(frame);
    let mut measures = vec![None; n * n];
    let mut ranks = vec![f64::NAN; n * n];
    let mut foot_ranks = vec![f64::NAN; n * n];
    for i in 0..n * n {
        if states[i] == NodeState::Reached {
            let q = &poses[i];
            ranks[i] = passive_rank(
                &L::constraint_jacobian(q, params),
                &fixed,
                L::REDUNDANT_ROWS,
            );
            let m = point_measures::<L, f64, NQ, NC, NU, ND, NP>(params, q, frame, &options.limits);
            if let Ok(m) = &m {
                foot_ranks[i] = m.foot_rank;
            }
            measures[i] = Some(m);
        }
    }
    let reached = states.iter().filter(|&&s| s == NodeState::Reached).count();
    let node = |i: usize| {
        [
            origin[0] + (i % n) as f64 * step,
            origin[1] + (i / n) as f64 * step,
        ]
    };
    let mut ws = Workspace {
        nodes: n,
        slice,
        origin,
        step,
        states,
        poses,
        measures,
        passive_rank: ranks,
        revolute: core::array::from_fn(|j| {
            L::JOINT_KINDS[j] == crate::model::contract::JointKind::Revolute
        }),
        passive_signed,
        area: reached as f64 * step * step,
        passive_curves: Vec::new(),
        foot_curves: Vec::new(),
    };
    let joined = |a: usize, b: usize| ws.joined(a, b);
    let passive_curves = if passive_signed {
        contour(n, &ws.passive_rank, node, joined)
    } else {
        Vec::new()
    };
    // The branch's edge: +1 reached, −1 where the branch ends, no value elsewhere.
    let edge: Vec<f64> = ws
        .states
        .iter()
        .map(|s| match s {
            NodeState::Reached => 1.0,
            NodeState::BranchEnds => -1.0,
            _ => f64::NAN,
        })
        .collect();
    let mut foot_curves = contour(n, &edge, node, |_, _| true);
    if NU == ND {
        foot_curves.extend(contour(n, &foot_ranks, node, joined));
    }
    ws.passive_curves = passive_curves;
    ws.foot_curves = foot_curves;
    Ok(ws)
}

/// Whether motor joint `a` at `x` is within `(lo, hi)`: a revolute one modulo a turn (the
/// fronts of a continuation can reach one node with angles a turn apart, around a hole in
/// the workspace, and both are the same pose); a range a turn wide limits nothing.
fn motor_in<L, const NQ: usize, const NC: usize, const NU: usize>(
    a: usize,
    x: f64,
    (lo, hi): (f64, f64),
) -> bool
where
    L: LegDynamics<NQ, NC, NU>,
{
    if L::JOINT_KINDS[a] == crate::model::contract::JointKind::Revolute {
        // A turn or more limits nothing (and keeps an infinite bound out of the sum).
        hi - lo >= core::f64::consts::TAU || lo + (x - lo).rem_euclid(core::f64::consts::TAU) <= hi
    } else {
        x >= lo && x <= hi
    }
}

/// Every motor of `q` within `range` (none: no limit).
fn in_range<L, const NQ: usize, const NC: usize, const NU: usize>(
    q: &SVector<f64, NQ>,
    range: Option<&[(f64, f64); NU]>,
) -> bool
where
    L: LegDynamics<NQ, NC, NU>,
{
    range.is_none_or(|r| {
        L::ACTUATED
            .iter()
            .zip(r.iter())
            .all(|(&a, &range)| motor_in::<L, NQ, NC, NU>(a, q[a], range))
    })
}

/// The start's motors within `range`, or the first outside it.
fn start_in_range<L, const NQ: usize, const NC: usize, const NU: usize>(
    start: &SVector<f64, NQ>,
    range: Option<&[(f64, f64); NU]>,
) -> Result<(), AnalysisError>
where
    L: LegDynamics<NQ, NC, NU>,
{
    for (k, (&a, &range)) in L::ACTUATED
        .iter()
        .zip(range.into_iter().flatten())
        .enumerate()
    {
        if !motor_in::<L, NQ, NC, NU>(a, start[a], range) {
            return Err(AnalysisError::StartOutOfRange {
                motor: k,
                angle: start[a],
                range,
            });
        }
    }
    Ok(())
}

/// The branch of `start` over `count` nodes of foot positions `at(i)`: node `first` solved
/// from `start`, then breadth first, each node from a reached neighbour ([`follow`], so
/// the branch never changes). Each node's state and pose (zero where not reached).
#[allow(clippy::too_many_arguments)]
fn continuation<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    params: &L::Params<f64>,
    start: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    range: Option<&[(f64, f64); NU]>,
    count: usize,
    first: usize,
    at: impl Fn(usize) -> SVector<f64, ND>,
    neighbours: impl Fn(usize) -> [Option<usize>; 6],
) -> Result<(Vec<NodeState>, Vec<SVector<f64, NQ>>), AnalysisError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    let tol = Tolerance {
        max_iterations: 30,
        ..Tolerance::default()
    };
    let mut states = vec![NodeState::Unvisited; count];
    let mut poses = vec![SVector::<f64, NQ>::zeros(); count];
    let q0 = foot_inverse_holding::<L, f64, NQ, NC, NU, ND, NP>(
        params,
        &at(first),
        start,
        &tol,
        &frame.held,
    )?;
    if (q0 - start).amax() > 4.0 * JUMP || !in_range::<L, NQ, NC, NU>(&q0, range) {
        return Err(AnalysisError::Assembly(
            crate::assembly::AssemblyError::BranchEnds { fraction: 0.0 },
        ));
    }
    states[first] = NodeState::Reached;
    poses[first] = q0;
    let mut queue = VecDeque::from([first]);
    while let Some(i) = queue.pop_front() {
        for k in neighbours(i).into_iter().flatten() {
            if matches!(states[k], NodeState::Reached | NodeState::OutOfRange) {
                continue;
            }
            match follow::<L, NQ, NC, NU, ND, NP>(
                params,
                &poses[i],
                &at(i),
                &at(k),
                frame,
                &tol,
                GRID_FLOOR,
            ) {
                Ok(q) if in_range::<L, NQ, NC, NU>(&q, range) => {
                    states[k] = NodeState::Reached;
                    poses[k] = q;
                    queue.push_back(k);
                }
                Ok(_) => states[k] = NodeState::OutOfRange,
                _ => states[k] = NodeState::BranchEnds,
            }
        }
    }
    Ok((states, poses))
}

/// The most nodes per side of [`workspace_volume`]'s cube (a million nodes).
pub const VOLUME_NODES: core::ops::RangeInclusive<usize> = 2..=100;

/// A spatial leg's workspace as a volume ([`workspace_volume`]).
#[derive(Clone, Debug)]
pub struct WorkspaceVolume {
    /// Nodes per side of the cube.
    pub nodes: usize,
    /// The node `(0, 0, 0)` (lowest `x`, `y`, `z`), base frame (m).
    pub origin: [f64; 3],
    /// Node spacing (m).
    pub step: f64,
    /// Each node's state (`index = (iz · nodes + iy) · nodes + ix`).
    pub states: Vec<NodeState>,
    /// Nodes reached on the branch.
    pub reached: usize,
    /// Reached nodes × step³ (m³).
    pub volume: f64,
}

/// The workspace of the branch of `start` as a volume: the continuation of [`workspace`]
/// over a cube of `nodes³` foot positions centred on the hip of the foot's chain, as wide
/// as the chain is long ([`reach`]), motors within `motor_range`; no measures at the nodes.
pub fn workspace_volume<L, const NQ: usize, const NC: usize, const NU: usize, const NP: usize>(
    params: &L::Params<f64>,
    start: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    nodes: usize,
    motor_range: Option<&[(f64, f64); NU]>,
) -> Result<WorkspaceVolume, AnalysisError>
where
    L: LegModel<NQ, NC, NU, 3, NP>,
{
    if !VOLUME_NODES.contains(&nodes) {
        return Err(AnalysisError::Grid {
            what: "from 2 to 100 nodes per side of a volume",
            value: nodes as f64,
        });
    }
    let limits = MotorLimits {
        torque: SVector::repeat(1.0),
        speed: SVector::repeat(1.0),
    };
    GridOptions {
        nodes,
        window: None,
        plane: None,
        motor_range: motor_range.copied(),
        limits,
    }
    .check()?;
    frame.foot_spans(3)?;
    start_in_range::<L, NQ, NC, NU>(start, motor_range)?;
    let n = nodes;
    let (hip, half) = reach::<L, NQ, NC, NU, 3, NP>(params, start, frame);
    let step = 2.0 * half / (n - 1) as f64;
    let origin = [hip[0] - half, hip[1] - half, hip[2] - half];
    let index = |c: [usize; 3]| (c[2] * n + c[1]) * n + c[0];
    let cell = |i: usize| [i % n, (i / n) % n, i / (n * n)];
    let at = |i: usize| {
        let c = cell(i);
        SVector::<f64, 3>::from_fn(|r, _| origin[r] + c[r] as f64 * step)
    };
    let foot = L::foot_position(start, params);
    let nearest: [usize; 3] = core::array::from_fn(|r| {
        (((foot[r] - origin[r]) / step).round().max(0.0) as usize).min(n - 1)
    });
    let neighbours = |i: usize| {
        let c = cell(i);
        let mut out = [None; 6];
        for axis in 0..3 {
            if c[axis] > 0 {
                let mut d = c;
                d[axis] -= 1;
                out[2 * axis] = Some(index(d));
            }
            if c[axis] + 1 < n {
                let mut d = c;
                d[axis] += 1;
                out[2 * axis + 1] = Some(index(d));
            }
        }
        out
    };
    let (states, _) = continuation::<L, NQ, NC, NU, 3, NP>(
        params,
        start,
        frame,
        motor_range,
        n * n * n,
        index(nearest),
        at,
        neighbours,
    )?;
    let reached = states.iter().filter(|&&s| s == NodeState::Reached).count();
    Ok(WorkspaceVolume {
        nodes: n,
        origin,
        step,
        states,
        reached,
        volume: reached as f64 * step * step * step,
    })
}

/// Steps of a branch change each joint by at most this much (rad, or m): a larger change
/// means the solver landed on another branch.
pub const JUMP: f64 = 0.35;

/// The shortest step [`workspace`] lets [`follow`] take between neighbouring nodes, as a
/// fraction of the way: a sixteenth, enough to tell whether a node is reached (a node a
/// small fraction of a cell inside a fold may be counted as past it). [`FOLD_FLOOR`]
/// finds the fold itself, at a cost: each halving aimed past a fold is a solve that runs
/// all its iterations.
pub const GRID_FLOOR: f64 = 1.0 / 16.0;

/// A floor for [`follow`] that finds where a branch ends to within about 1e-7 of the way
/// (as [`crate::assembly::assemble_along`] does).
pub const FOLD_FLOOR: f64 = 1e-7;

/// The most foot solves one [`follow`] makes, whatever the floor (bounded work): a
/// straight way with no fold takes one; a way that ends at a fold takes one or two per
/// halving down to the floor (23 halvings to [`FOLD_FLOOR`]).
pub const FOLLOW_SOLVES: usize = 2000;

/// Moves the foot of the assembled pose `from` (its foot at `from_foot`) on a straight
/// line to `to`, staying on `from`'s branch: each step is solved from the previous pose
/// and may change no joint by more than [`JUMP`]; a step that would, or whose solve
/// fails, is halved, down to `floor` of the way, and after two steps in a row that hold
/// the next is doubled (up to the whole way).
///
/// Fails where the branch ends (or folds back) on the way, and may fail up to a few
/// `floor`s of the way before that: near a fold the pose moves as the square root of the
/// foot's distance to it, so a joint can turn by more than [`JUMP`] over the last
/// fraction of a millimetre (a short toe crank near its dead centre does) and a step no
/// shorter than `floor` cannot follow it. [`workspace`] uses [`GRID_FLOOR`];
/// [`FOLD_FLOOR`] puts the failure at the fold. A `floor` that is not positive (or NaN)
/// is taken as `f64::EPSILON`; at most [`FOLLOW_SOLVES`] solves.
pub fn follow<
    L,
    const NQ: usize,
    const NC: usize,
    const NU: usize,
    const ND: usize,
    const NP: usize,
>(
    params: &L::Params<f64>,
    from: &SVector<f64, NQ>,
    from_foot: &SVector<f64, ND>,
    to: &SVector<f64, ND>,
    frame: &LegFrame<NQ>,
    tol: &Tolerance<f64>,
    floor: f64,
) -> Result<SVector<f64, NQ>, AnalysisError>
where
    L: LegModel<NQ, NC, NU, ND, NP>,
{
    use crate::assembly::AssemblyError;
    let floor = if floor > 0.0 {
        floor.min(1.0)
    } else {
        f64::EPSILON
    };
    let ends = |done: f64| AnalysisError::Assembly(AssemblyError::BranchEnds { fraction: done });
    // `held`: steps in a row that held at the current length.
    let (mut q, mut done, mut h, mut held): (_, f64, f64, u32) = (*from, 0.0, 1.0, 1);
    for _ in 0..FOLLOW_SOLVES {
        if done >= 1.0 {
            return Ok(q);
        }
        let h_now = h.min(1.0 - done);
        let t = done + h_now;
        let target = from_foot + (to - from_foot) * t;
        match foot_inverse_holding::<L, f64, NQ, NC, NU, ND, NP>(
            params,
            &target,
            &q,
            tol,
            &frame.held,
        ) {
            Ok(next) if (next - q).amax() <= JUMP => {
                (q, done, held) = (next, t, held + 1);
                if held >= 2 {
                    h = (h_now + h_now).min(1.0);
                }
            }
            Err(AssemblyError::NonFinite) => return Err(AssemblyError::NonFinite.into()),
            Ok(_) | Err(_) if h_now > floor => (h, held) = (0.5 * h_now, 0),
            Ok(_) => return Err(ends(done)),
            Err(e) => return Err(e.into()),
        }
    }
    if done >= 1.0 {
        Ok(q)
    } else {
        Err(ends(done))
    }
}

/// Marching squares: the segments where `values` (row by row, `n` per row; NaN: no
/// value) changes sign, each crossing placed by linear interpolation along its edge.
///
/// A square whose corners are not `joined` (their poses not continuous with each other,
/// where two continuation fronts met on different solutions around a hole of the
/// workspace) gives no segment: a sign change there is a seam, not a singularity.
pub fn contour(
    n: usize,
    values: &[f64],
    node: impl Fn(usize) -> [f64; 2],
    joined: impl Fn(usize, usize) -> bool,
) -> Vec<Segment> {
    let mut out = Vec::new();
    for y in 0..n.saturating_sub(1) {
        for x in 0..n - 1 {
            let corners = [
                y * n + x,
                y * n + x + 1,
                (y + 1) * n + x + 1,
                (y + 1) * n + x,
            ];
            if corners.iter().any(|&c| !values[c].is_finite())
                || (0..4).any(|e| !joined(corners[e], corners[(e + 1) % 4]))
            {
                continue;
            }
            let mut crossings = [[0.0; 2]; 4];
            let mut count = 0;
            for e in 0..4 {
                let (a, b) = (corners[e], corners[(e + 1) % 4]);
                let (va, vb) = (values[a], values[b]);
                if (va > 0.0) != (vb > 0.0) {
                    let t = va / (va - vb);
                    let (pa, pb) = (node(a), node(b));
                    crossings[count] = [pa[0] + t * (pb[0] - pa[0]), pa[1] + t * (pb[1] - pa[1])];
                    count += 1;
                }
            }
            if count >= 2 {
                out.push([crossings[0], crossings[1]]);
            }
            if count == 4 {
                out.push([crossings[2], crossings[3]]);
            }
        }
    }
    out
}

/// The foot's path over one motor's turn: what a one-motor linkage's workspace is.
#[derive(Clone, Debug)]
pub struct FootPath<const NQ: usize> {
    /// Motor angles (rad), increasing.
    pub angles: Vec<f64>,
    /// The poses there, on the branch of the start.
    pub poses: Vec<SVector<f64, NQ>>,
    /// The foot there (base frame, m).
    pub feet: Vec<[f64; 2]>,
    /// Whether the motor turned a full revolution (a crank).
    pub full_turn: bool,
    /// The path's length (m).
    pub length: f64,
}

/// The foot's path while the one motor of a one-motor leg turns from the start's angle,
/// a full revolution each way at most (or within `range`), following the start's branch
/// in `samples` steps a revolution ([`crate::assembly::assemble_along`]); where the
/// branch ends the path stops there. Legs with more motors have a workspace instead.
pub fn foot_path<L, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<f64>,
    start: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    samples: usize,
    range: Option<(f64, f64)>,
) -> Result<FootPath<NQ>, AnalysisError>
where
    L: LegModel<NQ, NC, NU>,
{
    frame.motor_coordinates()?;
    if NU != 1 {
        return Err(super::Inapplicable::NotOneMotor { motors: NU }.into());
    }
    let tau = core::f64::consts::TAU;
    let a = L::ACTUATED[0];
    let theta0 = start[a];
    let (lo, hi) = range.unwrap_or((theta0 - tau, theta0 + tau));
    let step = tau / samples.max(8) as f64;
    let tol = Tolerance::default();
    let walk = |direction: f64| {
        let mut out = Vec::new();
        let mut q = *start;
        let mut theta = theta0;
        loop {
            let next = theta + direction * step;
            if next < lo - 1e-12 || next > hi + 1e-12 || (next - theta0).abs() > tau + 1e-9 {
                break;
            }
            let target = SVector::<f64, NU>::from_element(next);
            match crate::assembly::assemble_along::<L, f64, NQ, NC, NU>(
                params, &q, &target, 0.05, &tol,
            ) {
                Ok(p) => {
                    q = p;
                    theta = next;
                    out.push((theta, q));
                }
                Err(_) => break,
            }
        }
        out
    };
    let forward = walk(1.0);
    let full_turn = forward
        .last()
        .is_some_and(|(t, _)| (t - theta0 - tau).abs() < 1e-9);
    let backward = if full_turn { Vec::new() } else { walk(-1.0) };
    let mut points: Vec<(f64, SVector<f64, NQ>)> = backward.into_iter().rev().collect();
    points.push((theta0, *start));
    points.extend(forward);
    let feet: Vec<[f64; 2]> = points
        .iter()
        .map(|(_, q)| {
            let f = L::foot_position(q, params);
            [f[0], f[1]]
        })
        .collect();
    let length = feet
        .windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum();
    Ok(FootPath {
        angles: points.iter().map(|p| p.0).collect(),
        poses: points.iter().map(|p| p.1).collect(),
        feet,
        full_turn,
        length,
    })
}

/// The assembly modes of a leg at the motor angles (and held body joints) of the
/// assembled pose `start`: `start` first, then every other closed pose found from
/// `tries` guesses of the passive joints (deterministic: revolute ones spread over a
/// turn, sliders over the leg's size), each once (poses equal modulo a turn on revolute
/// joints are one). Each is the start of a branch for [`workspace`].
pub fn assembly_modes<L, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<f64>,
    start: &SVector<f64, NQ>,
    frame: &LegFrame<NQ>,
    tries: usize,
) -> Vec<SVector<f64, NQ>>
where
    L: LegDynamics<NQ, NC, NU>,
{
    use crate::model::contract::JointKind;
    // Without motor coordinates (an under-actuated leg's passive joints are free, an
    // over-actuated one's motors cannot all be held) the motors do not pick out a
    // finite set of poses.
    if frame.motor_coordinates().is_err() {
        return vec![*start];
    }
    let fixed: [bool; NQ] = core::array::from_fn(|c| frame.held[c] || L::ACTUATED.contains(&c));
    let size = crate::assembly::leg_size::<L, f64, NQ, NC, NU>(params, start).max(1e-3);
    let same = |a: &SVector<f64, NQ>, b: &SVector<f64, NQ>| {
        (0..NQ).all(|j| {
            let d = a[j] - b[j];
            if L::JOINT_KINDS[j] == JointKind::Revolute {
                (d - core::f64::consts::TAU * (d / core::f64::consts::TAU).round()).abs() < 1e-6
            } else {
                d.abs() < 1e-6 * size
            }
        })
    };
    let tol = Tolerance {
        max_iterations: 60,
        ..Tolerance::default()
    };
    let mut modes = vec![*start];
    // A low-discrepancy sequence per joint (golden-ratio steps), deterministic.
    let mut phase = [0.0f64; NQ];
    for (j, p) in phase.iter_mut().enumerate() {
        *p = (j as f64 * 0.618_033_988_749_895).fract();
    }
    for t in 0..tries {
        let mut guess = *start;
        for j in 0..NQ {
            if fixed[j] {
                continue;
            }
            let u =
                (phase[j] + (t as f64 + 1.0) * (0.754_877_666_246_692_7 + 0.1 * j as f64)).fract();
            guess[j] = match L::JOINT_KINDS[j] {
                JointKind::Revolute => start[j] + (u - 0.5) * core::f64::consts::TAU,
                _ => start[j] + (u - 0.5) * 2.0 * size,
            };
        }
        let mut q = guess;
        if crate::assembly::assemble_holding::<L, f64, NQ, NC, NU>(params, &mut q, &fixed, &tol)
            .is_ok()
            && q.iter().all(|x| x.is_finite())
            && !modes.iter().any(|m| same(m, &q))
        {
            modes.push(q);
        }
    }
    modes
}
