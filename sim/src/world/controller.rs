//! LIBERO's OSC_POSE operational-space controller and the Panda gripper ramp (libero.md §5.3–5.5).
//!
//! Per env step (20 Hz) the goal is re-anchored: `p_goal = p_ee + 0.05·a[0:3]`, and, only if some rotation
//! input is non-zero, `R_goal = Rot(0.5·a[3:6]) · R_ee`. Every physics substep (0.002 s) computes
//! `τ = Jᵀ[Λ_pos(kp·e_p − kd·v); Λ_ori(kp·e_o − kd·ω)] + bias + Nᵀ M (10(q0 − q) − 2√10 q̇)`, clipped to the
//! actuator limits, with kp = 150 and critical damping.

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};

use crate::engine::mujoco::Data;
use crate::world::robot::{PandaIds, TORQUE_LIMITS};

type Mat7 = SMatrix<f64, 7, 7>;
type Mat6x7 = SMatrix<f64, 6, 7>;
type Mat3x7 = SMatrix<f64, 3, 7>;
type Vec7 = SVector<f64, 7>;

/// Metres per unit of translation action.
pub const POS_SCALE: f64 = 0.05;
/// Radians per unit of rotation action.
pub const ROT_SCALE: f64 = 0.5;
/// Position and orientation stiffness.
pub const KP: f64 = 150.0;
/// Nullspace posture stiffness.
pub const NULLSPACE_KP: f64 = 10.0;

/// Rotation matrix of the axis-angle vector `v` (angle = |v|).
pub fn axis_angle_to_mat(v: [f64; 3]) -> Matrix3<f64> {
    let v = Vector3::from(v);
    let angle = v.norm();
    if angle < 1e-12 {
        return Matrix3::identity();
    }
    nalgebra::Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(v), angle).into_inner()
}

/// Rotation matrix → quaternion (w, x, y, z) with w ≥ 0.
pub fn mat_to_quat(r: &Matrix3<f64>) -> [f64; 4] {
    let q = nalgebra::UnitQuaternion::from_matrix(r);
    let (w, x, y, z) = (q.w, q.i, q.j, q.k);
    if w < 0.0 {
        [-w, -x, -y, -z]
    } else {
        [w, x, y, z]
    }
}

/// Quaternion (w, x, y, z) → axis-angle 3-vector, as robosuite's `quat2axisangle` (angle = 2·acos(w), no
/// sign canonicalisation; zero when the rotation is the identity).
pub fn quat_to_axis_angle(q: [f64; 4]) -> [f64; 3] {
    let w = q[0].clamp(-1.0, 1.0);
    let den = (1.0 - w * w).sqrt();
    if den.abs() < 1e-12 {
        return [0.0; 3];
    }
    let angle = 2.0 * w.acos();
    [q[1] * angle / den, q[2] * angle / den, q[3] * angle / den]
}

/// Orientation error `½ Σ_i r_i × r_i^goal` between the columns of `current` and `goal`.
pub fn orientation_error(goal: &Matrix3<f64>, current: &Matrix3<f64>) -> Vector3<f64> {
    let mut e = Vector3::zeros();
    for i in 0..3 {
        e += current.column(i).cross(&goal.column(i));
    }
    0.5 * e
}

fn pinv3(m: Matrix3<f64>) -> Matrix3<f64> {
    // numpy's pinv cuts singular values below 1e-15 × the largest one.
    let eps = 1e-15 * m.norm().max(1e-300);
    m.pseudo_inverse(eps).unwrap_or_else(|_| Matrix3::zeros())
}

fn pinv6(m: SMatrix<f64, 6, 6>) -> SMatrix<f64, 6, 6> {
    let eps = 1e-15 * m.norm().max(1e-300);
    m.pseudo_inverse(eps).unwrap_or_else(|_| SMatrix::zeros())
}

/// The arm's operational-space controller state (goal pose and nullspace posture).
#[derive(Debug, Clone)]
pub struct OscPose {
    ids: PandaIds,
    goal_pos: Vector3<f64>,
    goal_ori: Matrix3<f64>,
    q0: Vec7,
    kd: f64,
    /// The state read when the controller was made, used by the first `set_goal` and the first
    /// `torques` after it (robosuite's update flag stays clear until the first control pass).
    cached: Option<Snapshot>,
    // scratch
    jacp: Vec<f64>,
    jacr: Vec<f64>,
    mass: Vec<f64>,
}

/// What the controller reads from the simulation for one torque computation.
#[derive(Debug, Clone)]
struct Snapshot {
    jp: Mat3x7,
    jo: Mat3x7,
    m: Mat7,
    q: Vec7,
    qd: Vec7,
    bias: Vec7,
    p: Vector3<f64>,
    r: Matrix3<f64>,
}

/// Pose and velocity of the controlled site, as the controller sees them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EefState {
    /// Site position (world).
    pub pos: [f64; 3],
    /// Site orientation (world), row-major 3×3.
    pub mat: [f64; 9],
}

impl OscPose {
    /// A controller whose goal is the current site pose and whose posture target is the current arm qpos
    /// (robosuite re-creates it at every `reset()`). `data` must be after a forward pass.
    ///
    /// As robosuite's, it keeps the state it read here until its first control pass: the first
    /// [`OscPose::set_goal`] anchors at the site pose read here and the first [`OscPose::torques`]
    /// uses the Jacobians, mass matrix, bias and velocities read here. When the state is unchanged
    /// in between (a normal reset) that is the same as reading it fresh; after LIBERO's
    /// `set_init_state`, which writes a new state without touching the controller, the first step
    /// pulls toward the reset pose (libero.md §5.5).
    pub fn new(ids: PandaIds, data: &mut Data) -> OscPose {
        let nv = data.model().nv();
        let mut q0 = Vec7::zeros();
        for i in 0..7 {
            q0[i] = data.qpos()[ids.arm_qpos[i]];
        }
        let site = ids.grip_site;
        let mut osc = OscPose {
            goal_pos: Vector3::from(data.site_pos(site)),
            goal_ori: Matrix3::from_row_slice(&data.site_mat(site)),
            q0,
            kd: 2.0 * KP.sqrt(),
            ids,
            cached: None,
            jacp: vec![0.0; 3 * nv],
            jacr: vec![0.0; 3 * nv],
            mass: vec![0.0; nv * nv],
        };
        osc.cached = Some(osc.snapshot(data));
        osc
    }

    /// Reads what one torque computation needs from `data`.
    fn snapshot(&mut self, data: &mut Data) -> Snapshot {
        let ids = &self.ids;
        let nv = data.model().nv();
        data.jac_site_into(ids.grip_site, &mut self.jacp, &mut self.jacr);
        data.mass_matrix_into(&mut self.mass);
        let mut s = Snapshot {
            jp: Mat3x7::zeros(),
            jo: Mat3x7::zeros(),
            m: Mat7::zeros(),
            q: Vec7::zeros(),
            qd: Vec7::zeros(),
            bias: Vec7::zeros(),
            p: Vector3::from(data.site_pos(ids.grip_site)),
            r: Matrix3::from_row_slice(&data.site_mat(ids.grip_site)),
        };
        for (c, &dof) in ids.arm_dof.iter().enumerate() {
            for r in 0..3 {
                s.jp[(r, c)] = self.jacp[r * nv + dof];
                s.jo[(r, c)] = self.jacr[r * nv + dof];
            }
            for (c2, &dof2) in ids.arm_dof.iter().enumerate() {
                s.m[(c, c2)] = self.mass[dof * nv + dof2];
            }
            s.q[c] = data.qpos()[ids.arm_qpos[c]];
            s.qd[c] = data.qvel()[dof];
            s.bias[c] = data.qfrc_bias()[dof];
        }
        s
    }

    /// Current goal position.
    pub fn goal_pos(&self) -> [f64; 3] {
        self.goal_pos.into()
    }

    /// Current goal orientation, row-major.
    pub fn goal_ori(&self) -> [f64; 9] {
        let mut out = [0.0; 9];
        for r in 0..3 {
            for c in 0..3 {
                out[3 * r + c] = self.goal_ori[(r, c)];
            }
        }
        out
    }

    /// Sets a new goal from a 6-D delta action (clipped to [−1, 1]), anchored at the current site pose
    /// (before the first control pass: the pose read when the controller was made).
    pub fn set_goal(&mut self, data: &Data, delta: [f64; 6]) {
        let a: Vec<f64> = delta.iter().map(|v| v.clamp(-1.0, 1.0)).collect();
        let site = self.ids.grip_site;
        let (p, r) = match &self.cached {
            Some(c) => (c.p, c.r),
            None => (
                Vector3::from(data.site_pos(site)),
                Matrix3::from_row_slice(&data.site_mat(site)),
            ),
        };
        self.goal_pos = p + Vector3::new(a[0], a[1], a[2]) * POS_SCALE;
        let rot = [a[3] * ROT_SCALE, a[4] * ROT_SCALE, a[5] * ROT_SCALE];
        // robosuite updates the goal orientation only when some rotation input is exactly non-zero.
        if rot.iter().any(|&x| x != 0.0) {
            self.goal_ori = axis_angle_to_mat(rot) * r;
        }
    }

    /// Computes the arm torques `[7]` for the current state (positions, velocities, `qM` and `qfrc_bias`
    /// must be current, e.g. after `mj_step1`), already clipped to the actuator limits.
    pub fn torques(&mut self, data: &mut Data) -> [f64; 7] {
        let s = match self.cached.take() {
            Some(c) => c,
            None => self.snapshot(data),
        };
        let Snapshot {
            jp,
            jo,
            m,
            q,
            qd,
            bias,
            p,
            r,
        } = s;
        let mut j = Mat6x7::zeros();
        j.fixed_view_mut::<3, 7>(0, 0).copy_from(&jp);
        j.fixed_view_mut::<3, 7>(3, 0).copy_from(&jo);
        let m_inv = m.try_inverse().unwrap_or_else(Mat7::zeros);

        let v = jp * qd;
        let w = jo * qd;
        let e_p = self.goal_pos - p;
        let e_o = orientation_error(&self.goal_ori, &r);
        let f = e_p * KP - v * self.kd;
        let t = e_o * KP - w * self.kd;

        let lambda_pos = pinv3(jp * m_inv * jp.transpose());
        let lambda_ori = pinv3(jo * m_inv * jo.transpose());
        let lambda = pinv6(j * m_inv * j.transpose());
        let mut tau = jp.transpose() * (lambda_pos * f) + jo.transpose() * (lambda_ori * t) + bias;

        // Nullspace posture control toward q0.
        let j_bar = m_inv * j.transpose() * lambda;
        let n = Mat7::identity() - j_bar * j;
        let kv = 2.0 * NULLSPACE_KP.sqrt();
        let posture = m * ((self.q0 - q) * NULLSPACE_KP - qd * kv);
        tau += n.transpose() * posture;

        let mut out = [0.0; 7];
        for i in 0..7 {
            out[i] = tau[i].clamp(-TORQUE_LIMITS[i], TORQUE_LIMITS[i]);
        }
        out
    }
}

/// The Panda gripper's command ramp: `c ← clip(c + [−1, +1]·0.01·sign(g), −1, 1)` every substep.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GripperRamp {
    c: [f64; 2],
}

impl GripperRamp {
    /// Advances one substep with gripper input `g` (+1 close, −1 open, 0 hold); returns the finger
    /// position targets `[0.02 + 0.02·c1, −0.02 + 0.02·c2]`.
    pub fn substep(&mut self, g: f64) -> [f64; 2] {
        let s = if g > 0.0 {
            1.0
        } else if g < 0.0 {
            -1.0
        } else {
            0.0
        };
        self.c[0] = (self.c[0] - 0.01 * s).clamp(-1.0, 1.0);
        self.c[1] = (self.c[1] + 0.01 * s).clamp(-1.0, 1.0);
        [0.02 + 0.02 * self.c[0], -0.02 + 0.02 * self.c[1]]
    }

    /// The command vector `c`.
    pub fn command(&self) -> [f64; 2] {
        self.c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_angle_round_trip() {
        let v = [0.3, -0.2, 0.5];
        let q = mat_to_quat(&axis_angle_to_mat(v));
        let back = quat_to_axis_angle(q);
        for k in 0..3 {
            assert!((back[k] - v[k]).abs() < 1e-9, "{back:?}");
        }
        assert_eq!(quat_to_axis_angle([1.0, 0.0, 0.0, 0.0]), [0.0; 3]);
    }

    #[test]
    fn orientation_error_is_the_rotation_vector_for_small_angles() {
        let goal = axis_angle_to_mat([0.0, 0.0, 0.01]);
        let e = orientation_error(&goal, &Matrix3::identity());
        assert!((e[2] - 0.01).abs() < 1e-6 && e[0].abs() < 1e-9, "{e:?}");
    }

    #[test]
    fn gripper_ramp_takes_200_substeps_from_open_to_closed() {
        let mut g = GripperRamp::default();
        let mut t = [0.0; 2];
        for _ in 0..100 {
            t = g.substep(-1.0);
        }
        assert!(
            (t[0] - 0.04).abs() < 1e-12 && (t[1] + 0.04).abs() < 1e-12,
            "open {t:?}"
        );
        for _ in 0..199 {
            t = g.substep(1.0);
        }
        assert!(t[0] > 1e-6, "not yet closed after 199 substeps: {t:?}");
        t = g.substep(1.0);
        assert!(t[0].abs() < 1e-12 && t[1].abs() < 1e-12, "closed {t:?}");
        assert_eq!(g.substep(0.0), t);
    }
}
