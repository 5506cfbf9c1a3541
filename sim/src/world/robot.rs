//! The built-in Franka Panda (robosuite's `MountedPanda` + `PandaGripper`, rebuilt from primitives).
//!
//! Kinematic chain, joint limits, damping, armature, friction loss, actuator limits, the gripper and the
//! frames (`robot0_right_hand`, `gripper0_grip_site`, `robot0_eye_in_hand`) follow LIBERO (libero.md §5.1).
//! Geometry is capsules and boxes of the Panda's proportions; link masses and inertias are robosuite's.
//! Names carry robosuite's prefixes (`robot0_`, `gripper0_`, `mount0_`) so task files and tools agree.
//!
//! Collision bits: arm links have `contype = 2, conaffinity = 0` (they never collide with each other);
//! fingertip pads `1/1`; finger bodies `0/1`. Scene objects must use [`ENV_CONTYPE`] / [`ENV_CONAFFINITY`]
//! so that both the arm and the fingers touch them.

use std::fmt::Write;

use crate::engine::mujoco::{MjError, Model, ObjType};

/// `contype` for table, fixtures and objects.
pub const ENV_CONTYPE: u32 = 1;
/// `conaffinity` for table, fixtures and objects (touches pads, fingers and arm links).
pub const ENV_CONAFFINITY: u32 = 3;

/// World position of `robot0_link0` (LIBERO's mounted Panda on the tabletop arenas).
pub const BASE_POS: [f64; 3] = [-0.66, 0.0, 0.912];

/// LIBERO's nominal arm configuration at reset (rad).
pub const INIT_QPOS: [f64; 7] = [
    0.0,
    -0.161_037_389,
    0.0,
    -2.444_597_47,
    0.0,
    2.226_752_2,
    std::f64::consts::FRAC_PI_4,
];

/// Finger joint positions at reset (m): half open.
pub const INIT_FINGERS: [f64; 2] = [0.020_833, -0.020_833];

/// Arm joint ranges (rad).
pub const JOINT_RANGES: [[f64; 2]; 7] = [
    [-2.8973, 2.8973],
    [-1.7628, 1.7628],
    [-2.8973, 2.8973],
    [-3.0718, -0.0698],
    [-2.8973, 2.8973],
    [-0.0175, 3.7525],
    [-2.8973, 2.8973],
];

/// Arm torque limits (N·m).
pub const TORQUE_LIMITS: [f64; 7] = [80.0, 80.0, 80.0, 80.0, 80.0, 12.0, 12.0];

/// Arm joint damping.
const DAMPING: [f64; 7] = [0.1, 0.1, 0.1, 0.1, 0.1, 0.01, 0.01];

/// Link frames: (body pos in parent, body quat wxyz in parent), robosuite's Panda. The literal 0.707107
/// is robosuite's own rounding (kept so that the kinematics match it to the last digit).
#[allow(clippy::approx_constant)]
const LINKS: [([f64; 3], [f64; 4]); 7] = [
    ([0.0, 0.0, 0.333], [1.0, 0.0, 0.0, 0.0]),
    ([0.0, 0.0, 0.0], [0.707107, -0.707107, 0.0, 0.0]),
    ([0.0, -0.316, 0.0], [0.707107, 0.707107, 0.0, 0.0]),
    ([0.0825, 0.0, 0.0], [0.707107, 0.707107, 0.0, 0.0]),
    ([-0.0825, 0.384, 0.0], [0.707107, -0.707107, 0.0, 0.0]),
    ([0.0, 0.0, 0.0], [0.707107, 0.707107, 0.0, 0.0]),
    ([0.088, 0.0, 0.0], [0.707107, 0.707107, 0.0, 0.0]),
];

/// Link inertials: (mass kg, centre of mass in the link frame, diagonal inertia), robosuite's Panda.
const INERTIALS: [(f64, [f64; 3], f64); 7] = [
    (4.0, [0.0, 0.0, -0.07], 0.7),
    (3.0, [0.0, -0.1, 0.0], 0.3),
    (2.0, [0.04, 0.0, -0.05], 0.2),
    (2.0, [-0.04, 0.05, 0.0], 0.2),
    (2.0, [0.0, 0.0, -0.15], 0.2),
    (1.5, [0.06, 0.0, 0.0], 0.1),
    (0.5, [0.0, 0.0, 0.08], 0.05),
];

/// Primitive link shapes: capsule segments (from, to, radius) in each link's frame.
/// A capsule segment: from, to, radius.
type Capsule = ([f64; 3], [f64; 3], f64);

const SHAPES: [&[Capsule]; 7] = [
    &[([0.0, 0.0, -0.19], [0.0, 0.0, -0.02], 0.06)],
    &[
        ([0.0, 0.0, -0.06], [0.0, 0.0, 0.06], 0.06),
        ([0.0, 0.0, 0.0], [0.0, -0.2, 0.0], 0.06),
    ],
    &[
        ([0.0, 0.0, -0.12], [0.0, 0.0, -0.02], 0.055),
        ([0.0, 0.0, 0.0], [0.0825, 0.0, 0.0], 0.055),
    ],
    &[
        ([0.0, 0.0, -0.05], [0.0, 0.0, 0.05], 0.055),
        ([0.0, 0.0, 0.0], [-0.0825, 0.06, 0.0], 0.055),
    ],
    &[
        ([0.0, 0.0, -0.3], [0.0, 0.0, -0.22], 0.055),
        ([0.0, 0.08, -0.22], [0.0, 0.08, -0.04], 0.035),
    ],
    &[
        ([0.0, 0.0, -0.03], [0.0, 0.0, 0.02], 0.05),
        ([0.0, 0.0, 0.0], [0.088, 0.0, 0.0], 0.045),
    ],
    &[([0.0, 0.0, -0.02], [0.0, 0.0, 0.07], 0.045)],
];

pub(crate) fn v3(v: [f64; 3]) -> String {
    format!("{} {} {}", v[0], v[1], v[2])
}

pub(crate) fn v4(v: [f64; 4]) -> String {
    format!("{} {} {} {}", v[0], v[1], v[2], v[3])
}

/// MJCF fragments for the Panda, to be placed in a scene's `<worldbody>` and `<actuator>`.
#[derive(Debug, Clone)]
pub struct PandaXml {
    /// `<default>` classes used by the robot (goes inside `<default>`).
    pub defaults: String,
    /// The robot body tree (goes inside `<worldbody>`), rooted at `robot0_base`.
    pub body: String,
    /// Actuators: 7 arm motors then 2 finger position servos (goes inside `<actuator>`).
    pub actuators: String,
}

/// Builds the Panda MJCF with its base at `base_pos` (world frame, identity orientation).
pub fn panda_xml(base_pos: [f64; 3]) -> PandaXml {
    let defaults = r#"<default class="panda_link"><geom type="capsule" contype="2" conaffinity="0" group="1" rgba="0.95 0.95 0.95 1" condim="3"/></default>
<default class="panda_dark"><geom type="capsule" contype="2" conaffinity="0" group="1" rgba="0.25 0.25 0.27 1" condim="3"/></default>
<default class="panda_visual"><geom contype="0" conaffinity="0" group="1"/></default>
"#
    .to_string();

    let mut b = String::new();
    let _ = writeln!(b, r#"<body name="robot0_base" pos="{}">"#, v3(base_pos));
    // Mount (RethinkMount): a pedestal down to the floor, visual only; no joints, so qpos is unaffected.
    let _ = writeln!(
        b,
        r#"<body name="mount0_base" pos="0 0 0"><geom name="mount0_pedestal" class="panda_visual" type="cylinder" fromto="0 0 {} 0 0 -0.02" size="0.11" rgba="0.15 0.15 0.15 1"/><geom name="mount0_foot" class="panda_visual" type="cylinder" fromto="0 0 {} 0 0 {}" size="0.2" rgba="0.15 0.15 0.15 1"/></body>"#,
        -base_pos[2],
        -base_pos[2],
        -base_pos[2] + 0.04
    );
    let _ = writeln!(
        b,
        r#"<body name="robot0_link0" pos="0 0 0"><inertial pos="0 0 0.05" mass="4" diaginertia="0.4 0.4 0.4"/><geom name="robot0_link0_g" class="panda_link" type="cylinder" fromto="0 0 0 0 0 0.14" size="0.07"/>"#
    );
    for i in 0..7 {
        let (pos, quat) = LINKS[i];
        let (mass, com, inertia) = INERTIALS[i];
        let [lo, hi] = JOINT_RANGES[i];
        let _ = writeln!(
            b,
            r#"<body name="robot0_link{n}" pos="{}" quat="{}"><inertial pos="{}" mass="{mass}" diaginertia="{inertia} {inertia} {inertia}"/><joint name="robot0_joint{n}" type="hinge" axis="0 0 1" range="{lo} {hi}" limited="true" damping="{}" armature="{}" frictionloss="0.1"/>"#,
            v3(pos),
            v4(quat),
            v3(com),
            DAMPING[i],
            5.0 / (i as f64 + 1.0),
            n = i + 1,
        );
        for (k, (from, to, r)) in SHAPES[i].iter().enumerate() {
            let class = if k == 0 && i % 2 == 1 {
                "panda_dark"
            } else {
                "panda_link"
            };
            let _ = writeln!(
                b,
                r#"<geom name="robot0_link{}_g{k}" class="{class}" fromto="{} {}" size="{r}"/>"#,
                i + 1,
                v3(*from),
                v3(*to)
            );
        }
    }
    // Hand and gripper, in link7 (frames and inertials as robosuite's PandaGripper).
    b.push_str(r#"<body name="robot0_right_hand" pos="0 0 0.1065" quat="0.924 0 0 -0.383">
<inertial pos="0 0 0" mass="0.5" diaginertia="0.05 0.05 0.05"/>
<camera name="robot0_eye_in_hand" pos="0.05 0 0" quat="0 0.707108 0.707108 0" fovy="75"/>
<body name="gripper0_right_gripper" pos="0 0 0" quat="0.707107 0 0 -0.707107">
<inertial pos="0 0 0.17" mass="0.3" diaginertia="0.09 0.07 0.05"/>
<geom name="gripper0_hand_g" type="box" pos="0 0 0.03" size="0.1 0.03 0.025" contype="2" conaffinity="0" group="1" rgba="0.95 0.95 0.95 1"/>
<geom name="gripper0_flange_g" type="cylinder" fromto="0 0 -0.01 0 0 0.005" size="0.04" contype="0" conaffinity="0" group="1" rgba="0.25 0.25 0.27 1"/>
<body name="gripper0_eef" pos="0 0 0.097">
<site name="gripper0_grip_site" pos="0 0 0" size="0.005" rgba="1 0 0 0" group="2"/>
<site name="gripper0_grip_site_cylinder" pos="0 0 0" size="0.005 10" type="cylinder" rgba="0 1 0 0" group="2"/>
</body>
<body name="gripper0_leftfinger" pos="0 0 0.0524" quat="0.707107 0 0 0.707107">
<inertial pos="0 0 0.05" mass="0.1" diaginertia="0.01 0.01 0.005"/>
<joint name="gripper0_finger_joint1" type="slide" axis="0 1 0" range="0 0.04" limited="true" damping="100" armature="1" frictionloss="1"/>
<geom name="gripper0_finger1_g" type="box" pos="0 0.014 0.025" size="0.01 0.006 0.025" contype="0" conaffinity="13" condim="4" friction="1 0.005 0.0001" solref="0.02 1" group="1" rgba="0.25 0.25 0.27 1"/>
<body name="gripper0_finger_joint1_tip" pos="0 0.0085 0.056">
<inertial pos="0 0 0" mass="0.01" diaginertia="0.01 0.01 0.01"/>
<geom name="gripper0_finger1_pad_g" type="box" pos="0 -0.005 -0.015" size="0.008 0.004 0.008" contype="1" conaffinity="1" friction="2 0.05 0.0001" solref="0.01 0.5" group="1" rgba="0.4 0.4 0.42 1"/>
</body>
</body>
<body name="gripper0_rightfinger" pos="0 0 0.0524" quat="0.707107 0 0 0.707107">
<inertial pos="0 0 0.05" mass="0.1" diaginertia="0.01 0.01 0.005"/>
<joint name="gripper0_finger_joint2" type="slide" axis="0 1 0" range="-0.04 0" limited="true" damping="100" armature="1" frictionloss="1"/>
<geom name="gripper0_finger2_g" type="box" pos="0 -0.014 0.025" size="0.01 0.006 0.025" contype="0" conaffinity="13" condim="4" friction="1 0.005 0.0001" solref="0.02 1" group="1" rgba="0.25 0.25 0.27 1"/>
<body name="gripper0_finger_joint2_tip" pos="0 -0.0085 0.056">
<inertial pos="0 0 0" mass="0.01" diaginertia="0.01 0.01 0.01"/>
<geom name="gripper0_finger2_pad_g" type="box" pos="0 0.005 -0.015" size="0.008 0.004 0.008" contype="1" conaffinity="1" friction="2 0.05 0.0001" solref="0.01 0.5" group="1" rgba="0.4 0.4 0.42 1"/>
</body>
</body>
</body>
</body>
"#);
    for _ in 0..7 {
        b.push_str("</body>\n");
    }
    b.push_str("</body>\n</body>\n");

    let mut a = String::new();
    for (i, &t) in TORQUE_LIMITS.iter().enumerate() {
        let _ = writeln!(
            a,
            r#"<motor name="robot0_torq_j{n}" joint="robot0_joint{n}" ctrllimited="true" ctrlrange="{} {t}" gear="1"/>"#,
            -t,
            n = i + 1
        );
    }
    a.push_str(r#"<position name="gripper0_finger1" joint="gripper0_finger_joint1" kp="1000" ctrllimited="true" ctrlrange="0 0.04" forcelimited="true" forcerange="-20 20"/>
<position name="gripper0_finger2" joint="gripper0_finger_joint2" kp="1000" ctrllimited="true" ctrlrange="-0.04 0" forcelimited="true" forcerange="-20 20"/>
"#);
    PandaXml {
        defaults,
        body: b,
        actuators: a,
    }
}

/// [`panda_xml`] dressed in robosuite's visual meshes (LIBERO's look): the builtin shapes keep their
/// collision role but move to group 3 (never drawn), and each
/// body gets the visual geoms of `visuals` (`(body name, <geom> elements)`). Bodies, joints,
/// inertials and actuators are unchanged, so the dynamics and the qpos layout are the builtin ones.
pub fn panda_xml_dressed(base_pos: [f64; 3], visuals: &[(String, String)]) -> PandaXml {
    let mut p = panda_xml(base_pos);
    p.defaults = p.defaults.replace(r#"group="1""#, r#"group="3""#);
    let mut body = p.body.replace(r#"group="1""#, r#"group="3""#);
    for (name, geoms) in visuals {
        let open = format!(r#"<body name="{name}""#);
        if let Some(at) = body.find(&open) {
            let end = at + body[at..].find('>').expect("an opening tag ends") + 1;
            body.insert_str(end, &format!("\n{geoms}"));
        }
    }
    p.body = body;
    p
}

/// Indices of the Panda's joints, actuators, frames and cameras in a compiled model.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PandaIds {
    /// qpos addresses of the 7 arm joints.
    pub arm_qpos: [usize; 7],
    /// dof (qvel) addresses of the 7 arm joints.
    pub arm_dof: [usize; 7],
    /// qpos addresses of the two finger joints.
    pub finger_qpos: [usize; 2],
    /// dof addresses of the two finger joints.
    pub finger_dof: [usize; 2],
    /// Actuator ids of the 7 arm motors.
    pub arm_act: [usize; 7],
    /// Actuator ids of the two finger servos.
    pub finger_act: [usize; 2],
    /// Site controlled by OSC (`gripper0_grip_site`).
    pub grip_site: usize,
    /// Body whose orientation is reported as the end-effector orientation (`robot0_right_hand`).
    pub hand_body: usize,
}

impl PandaIds {
    /// Looks up every Panda element in `model`.
    pub fn find(model: &Model) -> Result<PandaIds, MjError> {
        let joint = |n: &str| model.require(ObjType::Joint, n);
        let mut arm_qpos = [0; 7];
        let mut arm_dof = [0; 7];
        let mut arm_act = [0; 7];
        for i in 0..7 {
            let j = joint(&format!("robot0_joint{}", i + 1))?;
            arm_qpos[i] = model.joint_qpos_adr(j);
            arm_dof[i] = model.joint_dof_adr(j);
            arm_act[i] = model.require(ObjType::Actuator, &format!("robot0_torq_j{}", i + 1))?;
        }
        let f1 = joint("gripper0_finger_joint1")?;
        let f2 = joint("gripper0_finger_joint2")?;
        Ok(PandaIds {
            arm_qpos,
            arm_dof,
            finger_qpos: [model.joint_qpos_adr(f1), model.joint_qpos_adr(f2)],
            finger_dof: [model.joint_dof_adr(f1), model.joint_dof_adr(f2)],
            arm_act,
            finger_act: [
                model.require(ObjType::Actuator, "gripper0_finger1")?,
                model.require(ObjType::Actuator, "gripper0_finger2")?,
            ],
            grip_site: model.require(ObjType::Site, "gripper0_grip_site")?,
            hand_body: model.require(ObjType::Body, "robot0_right_hand")?,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::mujoco::Data;
    use std::sync::Arc;

    fn robot_only() -> String {
        let p = panda_xml(BASE_POS);
        format!(
            "<mujoco><compiler angle=\"radian\" autolimits=\"true\"/><option timestep=\"0.002\"/><default>{}</default><worldbody>{}</worldbody><actuator>{}</actuator></mujoco>",
            p.defaults, p.body, p.actuators
        )
    }

    #[test]
    fn compiles_with_the_expected_layout() {
        let model = Model::from_xml_str(&robot_only()).unwrap();
        assert_eq!(model.nq(), 9);
        assert_eq!(model.nv(), 9);
        assert_eq!(model.nu(), 9);
        let ids = PandaIds::find(&model).unwrap();
        assert_eq!(ids.arm_qpos, [0, 1, 2, 3, 4, 5, 6]);
        assert_eq!(ids.finger_qpos, [7, 8]);
        assert_eq!(model.joint_range(3), JOINT_RANGES[3]);
        assert_eq!(model.actuator_ctrl_range(5), [-12.0, 12.0]);
        assert!(model.id(ObjType::Camera, "robot0_eye_in_hand").is_some());
    }

    #[test]
    fn forward_kinematics_match_the_panda() {
        // At q = 0 the Panda's flange is at (0.088, 0, 0.333 + 0.316 + 0.384 - 0.107) from link0;
        // the hand frame sits 0.1065 below link7 along its z axis, which points down at q = 0.
        let model = Arc::new(Model::from_xml_str(&robot_only()).unwrap());
        let ids = PandaIds::find(&model).unwrap();
        let mut d = Data::new(model).unwrap();
        d.qpos_mut()[..7].fill(0.0);
        d.forward().unwrap();
        let hand = d.body_pos(ids.hand_body);
        let expect = [
            BASE_POS[0] + 0.088,
            BASE_POS[1],
            BASE_POS[2] + 0.333 + 0.316 + 0.384 - 0.1065,
        ];
        for k in 0..3 {
            assert!(
                (hand[k] - expect[k]).abs() < 1e-4,
                "hand {hand:?} vs {expect:?}"
            );
        }
        // Grip site a further 0.097 down.
        let site = d.site_pos(ids.grip_site);
        assert!((site[2] - (expect[2] - 0.097)).abs() < 1e-4, "{site:?}");
    }
}
