//! 3-vectors, rotation matrices and rigid poses for the importer (a few lines each; the
//! generator has no linear-algebra dependency and needs none for this).

pub type Vec3 = [f64; 3];
pub type Mat3 = [[f64; 3]; 3];

pub const IDENTITY: Mat3 = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];

pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

pub fn add(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub fn sub(a: Vec3, b: Vec3) -> Vec3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub fn scale(a: Vec3, s: f64) -> Vec3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a / |a|`, or `None` for a zero vector.
pub fn normalize(a: Vec3) -> Option<Vec3> {
    let n = dot(a, a).sqrt();
    (n > 0.0 && n.is_finite()).then(|| scale(a, 1.0 / n))
}

pub fn mat_mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, x) in row.iter_mut().enumerate() {
            *x = (0..3).map(|k| a[r][k] * b[k][c]).sum();
        }
    }
    out
}

pub fn mat_vec(a: &Mat3, v: Vec3) -> Vec3 {
    [dot(a[0], v), dot(a[1], v), dot(a[2], v)]
}

pub fn transpose(a: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, x) in row.iter_mut().enumerate() {
            *x = a[c][r];
        }
    }
    out
}

/// Rodrigues' rotation by `angle` about the unit `axis`.
pub fn rot_axis(axis: Vec3, angle: f64) -> Mat3 {
    let (s, c) = angle.sin_cos();
    let [x, y, z] = axis;
    let t = 1.0 - c;
    [
        [c + x * x * t, x * y * t - z * s, x * z * t + y * s],
        [y * x * t + z * s, c + y * y * t, y * z * t - x * s],
        [z * x * t - y * s, z * y * t + x * s, c + z * z * t],
    ]
}

/// The rotation of a unit quaternion `[w, x, y, z]` (the spec's convention).
pub fn quat_to_mat(q: [f64; 4]) -> Mat3 {
    crate::gen::model::quaternion_matrix(q)
}

/// A frame: `x_parent = pos + rot x_child`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub pos: Vec3,
    pub rot: Mat3,
}

impl Pose {
    pub const IDENTITY: Pose = Pose {
        pos: [0.0; 3],
        rot: IDENTITY,
    };

    pub fn then(&self, child: &Pose) -> Pose {
        Pose {
            pos: add(self.pos, mat_vec(&self.rot, child.pos)),
            rot: mat_mul(&self.rot, &child.rot),
        }
    }

    pub fn inverse(&self) -> Pose {
        let rt = transpose(&self.rot);
        Pose {
            pos: scale(mat_vec(&rt, self.pos), -1.0),
            rot: rt,
        }
    }

    pub fn apply(&self, x: Vec3) -> Vec3 {
        add(self.pos, mat_vec(&self.rot, x))
    }
}

/// The angles `(α, β, γ)` of `R = R_x(α) R_y(β) R_z(γ)` (a ball joint's coordinates).
pub fn xyz_angles(r: &Mat3) -> Vec3 {
    let beta = r[0][2].clamp(-1.0, 1.0).asin();
    let alpha = (-r[1][2]).atan2(r[2][2]);
    let gamma = (-r[0][1]).atan2(r[0][0]);
    [alpha, beta, gamma]
}
