//! A spatial foot's capacity sets: the force polytope (one slab per motor, cut from space)
//! and the speed zonotope (the motors' speed box mapped by `J_θ`), the 3-D counterparts of
//! [`force_polygon`](super::force_polygon) and [`speed_polygon`](super::speed_polygon).
//! On the stack, allocation-free.
//!
//! The force set `{f : lo_k ≤ a_kᵀ f ≤ hi_k}` of `NU` slabs is a convex polytope of at most
//! `2 NU` faces, so of at most `2 (2 NU) − 4` vertices (Euler's formula for a polyhedron
//! whose faces are at least triangles): [`Polytope`] holds `4 MAX_MOTORS`.

use nalgebra::{SMatrix, SVector, Vector3};

use super::{MotorKinematics, MAX_MOTORS};
use crate::model::contract::{LegDynamics, Real};

/// Room for the vertices: `4 MAX_MOTORS − 4` is the most a polytope of `2 MAX_MOTORS`
/// faces has; the rest is margin for vertices that rounding keeps apart.
const MAX_VERTICES: usize = 8 * MAX_MOTORS;
// A face is a set of vertices held in a u64 mask.
const _: () = assert!(MAX_VERTICES <= 64);

/// A convex polytope in space: its vertices and its volume, on the stack.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Polytope<T: Real> {
    vertices: [Vector3<T>; MAX_VERTICES],
    len: usize,
    volume: T,
}

impl<T: Real> Polytope<T> {
    /// The vertices (in no particular order).
    pub fn vertices(&self) -> &[Vector3<T>] {
        &self.vertices[..self.len]
    }

    /// The enclosed volume: zero where the slabs do not meet, infinite where they leave a
    /// direction free (`J_θ` has lost rank: the foot can push that way for free), NaN for
    /// a non-finite input or more than [`MAX_MOTORS`] slabs.
    pub fn volume(&self) -> T {
        self.volume
    }
}

/// `a · (b × c)`.
fn triple<T: Real>(a: &Vector3<T>, b: &Vector3<T>, c: &Vector3<T>) -> T {
    a.dot(&b.cross(c))
}

/// The polytope `{f : lo_k ≤ (Aᵀ f)_k ≤ hi_k}` (one slab per column `a_k` of `A`): its
/// vertices are the intersections of three slabs' planes that satisfy every slab, and
/// its volume the sum of the pyramids its faces make with an inner point. A face that two
/// slabs share (parallel columns with proportional limits) is counted once.
pub fn slab_polytope<T: Real, const NU: usize>(
    a: &SMatrix<T, 3, NU>,
    lo: &SVector<T, NU>,
    hi: &SVector<T, NU>,
) -> Polytope<T> {
    let mut poly = Polytope {
        vertices: [Vector3::zeros(); MAX_VERTICES],
        len: 0,
        volume: T::zero(),
    };
    let finite = a
        .iter()
        .chain(lo.iter())
        .chain(hi.iter())
        .all(|x| x.is_finite());
    if NU > MAX_MOTORS || !finite {
        poly.volume = T::zero() / T::zero();
        return poly;
    }
    let scale = a.amax() * (lo.amax().max(hi.amax()));
    let slack = scale * T::default_epsilon() * T::lit(1e4);
    let col = |k: usize| -> Vector3<T> { a.column(k).into_owned() };
    let mut independent = false;
    let mut overflow = false;
    for i in 0..NU {
        for j in i + 1..NU {
            for k in j + 1..NU {
                let (ai, aj, ak) = (col(i), col(j), col(k));
                let det = triple(&ai, &aj, &ak);
                if det.abs()
                    <= ai.norm() * aj.norm() * ak.norm() * T::default_epsilon() * T::lit(1e3)
                {
                    continue;
                }
                independent = true;
                let (jk, ki, ij) = (aj.cross(&ak), ak.cross(&ai), ai.cross(&aj));
                for bi in [lo[i], hi[i]] {
                    for bj in [lo[j], hi[j]] {
                        for bk in [lo[k], hi[k]] {
                            // [aᵢᵀ; aⱼᵀ; a_kᵀ] f = (bᵢ, bⱼ, b_k) by Cramer's rule.
                            let f = (jk * bi + ki * bj + ij * bk) / det;
                            let inside = (0..NU).all(|m| {
                                let v = a.column(m).dot(&f);
                                v >= lo[m] - slack && v <= hi[m] + slack
                            });
                            let seen = poly.vertices().iter().any(|p| (p - f).amax() <= slack);
                            if inside && !seen {
                                if poly.len == MAX_VERTICES {
                                    overflow = true;
                                } else {
                                    poly.vertices[poly.len] = f;
                                    poly.len += 1;
                                }
                            }
                        }
                    }
                }
            }
        }
    }
    poly.volume = if !independent {
        // No three motors span space: the set is a slab or a prism, unbounded.
        T::one() / T::zero()
    } else if overflow {
        T::zero() / T::zero()
    } else {
        faces_volume(&poly, a, lo, hi, slack)
    };
    poly
}

/// The volume of the polytope `poly` whose faces lie on the slabs' planes: each face (the
/// vertices on one plane, ordered by angle about their centroid) makes a pyramid with the
/// vertices' centroid, of volume area × height / 3.
fn faces_volume<T: Real, const NU: usize>(
    poly: &Polytope<T>,
    a: &SMatrix<T, 3, NU>,
    lo: &SVector<T, NU>,
    hi: &SVector<T, NU>,
    slack: T,
) -> T {
    let v = poly.vertices();
    if v.len() < 4 {
        return T::zero();
    }
    let mut centre = Vector3::zeros();
    for p in v {
        centre += p;
    }
    centre /= T::from_usize(v.len()).unwrap_or_else(T::one);
    // Distances to a face's plane in the vertices' own units (a slab given twice, scaled,
    // must find the same vertices on its planes), as far as vertices merged within `slack`
    // of each other (in each coordinate) can lie off it.
    let size = v.iter().fold(T::zero(), |s, p| s.max(p.amax()));
    let near = size * T::default_epsilon() * T::lit(1e4) + slack * T::lit(2.0);
    let mut seen_faces = [0u64; 2 * MAX_MOTORS];
    let mut faces = 0;
    let mut volume = T::zero();
    for m in 0..NU {
        let normal = a.column(m).into_owned();
        let length = normal.norm();
        if length == T::zero() {
            continue;
        }
        for (bound, outward) in [(lo[m], -T::one()), (hi[m], T::one())] {
            let mut on = [0usize; MAX_VERTICES];
            let mut count = 0;
            let mut mask = 0u64;
            for (i, p) in v.iter().enumerate() {
                if (normal.dot(p) - bound).abs() / length <= near {
                    on[count] = i;
                    count += 1;
                    mask |= 1 << i;
                }
            }
            if count < 3 || seen_faces[..faces].contains(&mask) {
                continue;
            }
            seen_faces[faces] = mask;
            faces += 1;
            let n = normal * (outward / length);
            // A basis of the face's plane, then its vertices by angle about their centroid.
            let axis = if n[0].abs() <= n[1].abs() && n[0].abs() <= n[2].abs() {
                Vector3::x()
            } else if n[1].abs() <= n[2].abs() {
                Vector3::y()
            } else {
                Vector3::z()
            };
            let u = n.cross(&axis).normalize();
            let w = n.cross(&u);
            let mut middle = Vector3::zeros();
            for &i in &on[..count] {
                middle += v[i];
            }
            middle /= T::from_usize(count).unwrap_or_else(T::one);
            let angle = |i: usize| {
                let d = v[i] - middle;
                d.dot(&w).atan2(d.dot(&u))
            };
            let face = &mut on[..count];
            // Insertion sort: a face has few vertices.
            for x in 1..count {
                let mut y = x;
                while y > 0 && angle(face[y - 1]) > angle(face[y]) {
                    face.swap(y - 1, y);
                    y -= 1;
                }
            }
            let mut twice_area = T::zero();
            for x in 0..count {
                let (p, r) = (v[face[x]] - middle, v[face[(x + 1) % count]] - middle);
                twice_area += p.cross(&r).dot(&n);
            }
            let height = n.dot(&(v[face[0]] - centre));
            volume += twice_area.abs() * T::lit(0.5) * height / T::lit(3.0);
        }
    }
    volume
}

/// The foot forces (N, on the ground, base frame) a spatial leg's motors hold at rest at
/// pose `q` within `torque` limits: `|Gᵀ G(q) + J_θᵀ f|_k ≤ τ_k`, gravity and springs
/// included; [`force_polygon`](super::force_polygon) in space. Where the motors cannot
/// hold the leg itself within their limits it is empty.
pub fn force_polytope<L, T, const NQ: usize, const NC: usize, const NU: usize>(
    params: &L::Params<T>,
    q: &SVector<T, NQ>,
    kin: &MotorKinematics<T, NQ, NU, 3>,
    torque: &SVector<T, NU>,
) -> Polytope<T>
where
    L: LegDynamics<NQ, NC, NU>,
    T: Real,
{
    let hold = super::holding_torque::<L, T, NQ, NC, NU, 3>(params, q, kin);
    slab_polytope(&kin.foot_jacobian, &(-torque - hold), &(torque - hold))
}

/// The volume (m³/s³) of the foot velocities reachable with motor speeds `|θ̇_k| ≤ ω_k`:
/// the zonotope `Σ [−1, 1] ω_k c_k` of `J_θ`'s columns `c_k`, whose volume is
/// `8 Σ_{i<j<k} |det(g_i, g_j, g_k)|` with `g_k = ω_k c_k` (Shephard 1974).
pub fn speed_zonotope_volume<T: Real, const NU: usize>(
    foot_jacobian: &SMatrix<T, 3, NU>,
    speed: &SVector<T, NU>,
) -> T {
    let g = |k: usize| -> Vector3<T> { foot_jacobian.column(k) * speed[k] };
    let mut sum = T::zero();
    for i in 0..NU {
        for j in i + 1..NU {
            for k in j + 1..NU {
                sum += triple(&g(i), &g(j), &g(k)).abs();
            }
        }
    }
    sum * T::lit(8.0)
}

/// How far the speed zonotope reaches from the origin along the unit direction `d`: the
/// fastest foot velocity `v d` the motors' speed limits allow with no motion across `d`.
/// Its faces' normals are the cross products of pairs of generators, each face at the
/// zonotope's support `h(n) = Σ_k |n · g_k|`, so the reach is the least `h(n) / |n · d|`.
/// Zero where the generators do not span space (the foot has lost a direction).
pub fn zonotope_reach<T: Real, const NU: usize>(
    foot_jacobian: &SMatrix<T, 3, NU>,
    speed: &SVector<T, NU>,
    d: &Vector3<T>,
) -> T {
    let g = |k: usize| -> Vector3<T> { foot_jacobian.column(k) * speed[k] };
    let size: T = (0..NU).map(|k| g(k).norm()).fold(T::zero(), |a, b| a + b);
    if !size.is_finite() || !d.iter().all(|x| x.is_finite()) {
        return T::zero() / T::zero();
    }
    let volume = speed_zonotope_volume(foot_jacobian, speed);
    if !volume.is_finite() || volume <= size * size * size * T::default_epsilon() * T::lit(1e3) {
        return T::zero();
    }
    let mut best = T::one() / T::zero();
    for i in 0..NU {
        for j in i + 1..NU {
            let n = g(i).cross(&g(j));
            let along = n.dot(d).abs();
            if along <= n.norm() * d.norm() * T::default_epsilon() * T::lit(1e3) {
                continue;
            }
            let h: T = (0..NU)
                .map(|k| n.dot(&g(k)).abs())
                .fold(T::zero(), |a, b| a + b);
            best = best.min(h / along);
        }
    }
    best
}
