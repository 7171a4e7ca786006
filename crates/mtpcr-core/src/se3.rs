//! Rigid transforms: the six-number individual of the evolution and its 4x4 matrix, composition,
//! and the error measures of the evaluation protocol.
//!
//! An individual is `[rx, ry, rz, tx, ty, tz]` with the angles in degrees (as in the authors'
//! reference) and `R = Rz(rz) Ry(ry) Rx(rx)`, `T = [R t; 0 1]`.

use nalgebra::{Matrix3, Matrix4, Quaternion, UnitQuaternion, Vector3};
use rand::{Rng, RngExt};
use rand_distr::StandardNormal;

/// A rigid transform as a homogeneous 4x4 matrix (`x' = T x`).
pub type Transform = Matrix4<f64>;

/// Degrees of freedom of a rigid motion: the length of an [`Individual`].
pub const DOF: usize = 6;

/// One individual: three angles in degrees, then three translations in the data's units.
pub type Individual = [f64; DOF];

/// Matrix of an individual: `R = Rz(rz) Ry(ry) Rx(rx)`, translation `(tx, ty, tz)`.
pub fn decode(x: &Individual) -> Transform {
    Rigid::from_individual(x).to_matrix()
}

/// Individual of a rigid matrix (the inverse of [`decode`]), handling the gimbal case
/// `cos(ry) ~ 0` by setting `rz = 0`.
pub fn encode(t: &Transform) -> Individual {
    let sy = (t[(0, 0)] * t[(0, 0)] + t[(1, 0)] * t[(1, 0)]).sqrt();
    let (rx, ry, rz) = if sy >= 1e-6 {
        (
            t[(2, 1)].atan2(t[(2, 2)]),
            (-t[(2, 0)]).atan2(sy),
            t[(1, 0)].atan2(t[(0, 0)]),
        )
    } else {
        ((-t[(1, 2)]).atan2(t[(1, 1)]), (-t[(2, 0)]).atan2(sy), 0.0)
    };
    [
        rx.to_degrees(),
        ry.to_degrees(),
        rz.to_degrees(),
        t[(0, 3)],
        t[(1, 3)],
        t[(2, 3)],
    ]
}

/// A rigid transform in the form the hot loops use: row-major rotation and translation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    /// Rotation, row-major.
    pub r: [[f64; 3]; 3],
    /// Translation.
    pub t: [f64; 3],
}

impl Rigid {
    /// The transform of an individual.
    pub fn from_individual(x: &Individual) -> Self {
        let (sx, cx) = x[0].to_radians().sin_cos();
        let (sy, cy) = x[1].to_radians().sin_cos();
        let (sz, cz) = x[2].to_radians().sin_cos();
        // Rz * Ry * Rx written out.
        Rigid {
            r: [
                [cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
                [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
                [-sy, cy * sx, cy * cx],
            ],
            t: [x[3], x[4], x[5]],
        }
    }

    /// From the upper 3x4 block of a homogeneous matrix (assumed rigid).
    pub fn from_matrix(m: &Transform) -> Self {
        let mut r = [[0.0; 3]; 3];
        for (i, row) in r.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = m[(i, j)];
            }
        }
        Rigid {
            r,
            t: [m[(0, 3)], m[(1, 3)], m[(2, 3)]],
        }
    }

    /// As a homogeneous matrix.
    pub fn to_matrix(&self) -> Transform {
        let r = &self.r;
        let t = &self.t;
        Matrix4::new(
            r[0][0], r[0][1], r[0][2], t[0], r[1][0], r[1][1], r[1][2], t[1], r[2][0], r[2][1],
            r[2][2], t[2], 0.0, 0.0, 0.0, 1.0,
        )
    }

    /// The inverse transform `[R^T, -R^T t]`.
    pub fn inverse(&self) -> Self {
        let r = &self.r;
        let rt = [
            [r[0][0], r[1][0], r[2][0]],
            [r[0][1], r[1][1], r[2][1]],
            [r[0][2], r[1][2], r[2][2]],
        ];
        let t = &self.t;
        let ti = [
            -(rt[0][0] * t[0] + rt[0][1] * t[1] + rt[0][2] * t[2]),
            -(rt[1][0] * t[0] + rt[1][1] * t[1] + rt[1][2] * t[2]),
            -(rt[2][0] * t[0] + rt[2][1] * t[1] + rt[2][2] * t[2]),
        ];
        Rigid { r: rt, t: ti }
    }

    /// `R p + t`.
    #[inline(always)]
    pub fn apply(&self, p: &[f64; 3]) -> [f64; 3] {
        let r = &self.r;
        [
            r[0][0] * p[0] + r[0][1] * p[1] + r[0][2] * p[2] + self.t[0],
            r[1][0] * p[0] + r[1][1] * p[1] + r[1][2] * p[2] + self.t[1],
            r[2][0] * p[0] + r[2][1] * p[1] + r[2][2] * p[2] + self.t[2],
        ]
    }
}

/// Inverse of a rigid homogeneous matrix, computed exactly as `[R^T, -R^T t]`.
pub fn invert_rigid(t: &Transform) -> Transform {
    Rigid::from_matrix(t).inverse().to_matrix()
}

/// The pure translation by `v`.
pub fn translation(v: [f64; 3]) -> Transform {
    let mut t = Transform::identity();
    t[(0, 3)] = v[0];
    t[(1, 3)] = v[1];
    t[(2, 3)] = v[2];
    t
}

/// Checks that `t` is a finite rigid transform (orthonormal rotation with det +1, last row
/// `0 0 0 1`) to within `tol`.
pub fn is_rigid(t: &Transform, tol: f64) -> bool {
    if t.iter().any(|v| !v.is_finite()) {
        return false;
    }
    let r: Matrix3<f64> = t.fixed_view::<3, 3>(0, 0).into_owned();
    let orth = (r.transpose() * r - Matrix3::identity()).norm();
    let last =
        (t[(3, 0)].abs() + t[(3, 1)].abs() + t[(3, 2)].abs() + (t[(3, 3)] - 1.0).abs()).max(0.0);
    orth <= tol && (r.determinant() - 1.0).abs() <= tol && last <= tol
}

/// The rigid transform nearest to `t`: its rotation block replaced by the nearest rotation
/// (polar decomposition by SVD, determinant +1), its translation kept, last row `0 0 0 1`.
pub fn nearest_rigid(t: &Transform) -> Transform {
    let r: Matrix3<f64> = t.fixed_view::<3, 3>(0, 0).into_owned();
    let svd = r.svd(true, true);
    let (u, v_t) = (
        svd.u.expect("u was requested"),
        svd.v_t.expect("v_t was requested"),
    );
    let mut d = Matrix3::identity();
    d[(2, 2)] = (u * v_t).determinant().signum();
    let rot = u * d * v_t;
    let mut out = Transform::identity();
    out.fixed_view_mut::<3, 3>(0, 0).copy_from(&rot);
    for i in 0..3 {
        out[(i, 3)] = t[(i, 3)];
    }
    out
}

/// Frobenius norm of the difference of the rotation blocks, `||R_a - R_b||_F` (the paper's
/// Err_R for one pair).
pub fn rotation_error_fro(a: &Transform, b: &Transform) -> f64 {
    let ra = a.fixed_view::<3, 3>(0, 0);
    let rb = b.fixed_view::<3, 3>(0, 0);
    (ra - rb).norm()
}

/// Angle in degrees of the relative rotation `R_a^T R_b` (0..180).
pub fn rotation_error_deg(a: &Transform, b: &Transform) -> f64 {
    let ra: Matrix3<f64> = a.fixed_view::<3, 3>(0, 0).into_owned();
    let rb: Matrix3<f64> = b.fixed_view::<3, 3>(0, 0).into_owned();
    let d = ra.transpose() * rb;
    let c = ((d.trace() - 1.0) / 2.0).clamp(-1.0, 1.0);
    c.acos().to_degrees()
}

/// Euclidean distance of the translation columns, `||t_a - t_b||` (the paper's Err_T for one pair).
pub fn translation_error(a: &Transform, b: &Transform) -> f64 {
    let ta = Vector3::new(a[(0, 3)], a[(1, 3)], a[(2, 3)]);
    let tb = Vector3::new(b[(0, 3)], b[(1, 3)], b[(2, 3)]);
    (ta - tb).norm()
}

/// Whether two poses agree: rotations closer than `degrees`, translations closer than
/// `shift` (the test of loops, joins, bridges and restarts).
pub(crate) fn poses_agree(a: &Transform, b: &Transform, degrees: f64, shift: f64) -> bool {
    rotation_error_deg(a, b) < degrees && translation_error(a, b) < shift
}

/// A rigid motion with a rotation uniform over SO(3) and a translation uniform in
/// `[-max_translation, max_translation]^3`.
pub fn random_rigid<R: Rng + ?Sized>(rng: &mut R, max_translation: f64) -> Transform {
    let q = loop {
        let v: [f64; 4] = [
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
            rng.sample(StandardNormal),
        ];
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2] + v[3] * v[3]).sqrt();
        if n > 1e-9 {
            break UnitQuaternion::from_quaternion(Quaternion::new(v[0], v[1], v[2], v[3]));
        }
    };
    let mut t = q.to_homogeneous();
    for i in 0..3 {
        t[(i, 3)] = if max_translation > 0.0 {
            rng.random_range(-max_translation..=max_translation)
        } else {
            0.0
        };
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn decode_matches_the_product_of_axis_rotations() {
        let x: Individual = [30.0, -40.0, 110.0, 0.1, -0.2, 0.3];
        let rx = nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), x[0].to_radians());
        let ry = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), x[1].to_radians());
        let rz = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), x[2].to_radians());
        let r = (rz * ry * rx).into_inner();
        let t = decode(&x);
        assert!((t.fixed_view::<3, 3>(0, 0) - r).norm() < 1e-12);
        assert_eq!([t[(0, 3)], t[(1, 3)], t[(2, 3)]], [0.1, -0.2, 0.3]);
    }

    #[test]
    fn encode_inverts_decode_inside_the_principal_range() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for _ in 0..1000 {
            let x = [
                rng.random_range(-179.0..179.0),
                rng.random_range(-89.0..89.0),
                rng.random_range(-179.0..179.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ];
            let y = encode(&decode(&x));
            for k in 0..6 {
                assert!((x[k] - y[k]).abs() < 1e-7, "{x:?} -> {y:?}");
            }
        }
    }

    #[test]
    fn encode_then_decode_gives_the_same_matrix_for_any_rotation() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for _ in 0..1000 {
            let t = random_rigid(&mut rng, 2.0);
            let back = decode(&encode(&t));
            assert!((back - t).norm() < 1e-9);
        }
    }

    #[test]
    fn gimbal_case_round_trips() {
        for ry in [90.0, -90.0] {
            let t = decode(&[25.0, ry, 40.0, 0.0, 1.0, 2.0]);
            let x = encode(&t);
            assert_eq!(x[2], 0.0, "rz is set to zero in the gimbal case");
            assert!((decode(&x) - t).norm() < 1e-9);
        }
    }

    #[test]
    fn inverse_composes_to_identity() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let t = random_rigid(&mut rng, 1.0);
        assert!((invert_rigid(&t) * t - Transform::identity()).norm() < 1e-12);
        assert!(is_rigid(&t, 1e-9));
        let mut bad = t;
        bad[(0, 0)] *= 2.0;
        assert!(!is_rigid(&bad, 1e-6));
    }

    #[test]
    fn errors_of_a_known_rotation() {
        let a = Transform::identity();
        let b = decode(&[0.0, 0.0, 10.0, 3.0, 4.0, 0.0]);
        assert!((rotation_error_deg(&a, &b) - 10.0).abs() < 1e-9);
        let theta = 10f64.to_radians();
        let fro = 2.0 * 2f64.sqrt() * (theta / 2.0).sin();
        assert!((rotation_error_fro(&a, &b) - fro).abs() < 1e-12);
        assert!((translation_error(&a, &b) - 5.0).abs() < 1e-12);
    }

    #[test]
    fn poses_agree_only_when_both_rotation_and_translation_are_within_bounds() {
        let turned = |deg: f64, shift: f64| {
            let mut t = Transform::identity();
            let r = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), deg.to_radians());
            t.fixed_view_mut::<3, 3>(0, 0).copy_from(r.matrix());
            t[(0, 3)] = shift;
            t
        };
        let a = Transform::identity();
        assert!(poses_agree(&a, &turned(4.0, 0.9), 5.0, 1.0));
        assert!(!poses_agree(&a, &turned(6.0, 0.9), 5.0, 1.0));
        assert!(!poses_agree(&a, &turned(4.0, 1.1), 5.0, 1.0));
        assert!(poses_agree(
            &turned(30.0, 2.0),
            &turned(33.0, 2.5),
            5.0,
            1.0
        ));
    }
}
