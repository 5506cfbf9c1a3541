//! The environment and the OSC_POSE controller against LIBERO's behaviour.

use sim::controller::axis_angle_to_mat;
use sim::{Env, EnvConfig};

fn state_only() -> Env {
    Env::new(EnvConfig {
        render: false,
        ..EnvConfig::default()
    })
    .unwrap()
}

#[test]
fn reset_puts_the_arm_at_liberos_init_pose() {
    let mut env = state_only();
    let obs = env.reset(0).unwrap();
    let init = sim::robot::INIT_QPOS;
    for (q, q0) in obs.joint_state.iter().zip(init) {
        assert!((*q as f64 - q0).abs() < 1e-6);
    }
    assert!((obs.state[6] - 0.020833).abs() < 1e-6 && (obs.state[7] + 0.020833).abs() < 1e-6);
    // LIBERO's init pose puts the gripper above the table, in front of the robot, pointing down.
    let p = obs.eef_pos;
    assert!(p[0] > -0.35 && p[0] < 0.0, "{p:?}");
    assert!(p[1].abs() < 0.01, "{p:?}");
    assert!(p[2] > 1.0 && p[2] < 1.3, "{p:?}");
}

#[test]
fn zero_action_drifts_less_than_2mm_over_100_steps() {
    let mut env = state_only();
    let start = env.reset(1).unwrap().eef_pos;
    let mut last = start;
    for _ in 0..100 {
        last = env.step(&[0.0; 7]).unwrap().eef_pos;
    }
    let d = ((last[0] - start[0]).powi(2)
        + (last[1] - start[1]).powi(2)
        + (last[2] - start[2]).powi(2))
    .sqrt();
    assert!(d < 0.002, "drift {d} m");
}

#[test]
fn every_axis_moves_the_right_way() {
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut env = state_only();
            let o0 = env.reset(3).unwrap();
            let mut a = [0.0f32; 7];
            a[axis] = sign * 0.5;
            let mut o = o0.clone();
            for _ in 0..8 {
                o = env.step(&a).unwrap();
            }
            let d = (o.eef_pos[axis] - o0.eef_pos[axis]) * sign as f64;
            assert!(d > 0.02, "axis {axis} sign {sign}: moved {d}");
        }
    }
}

#[test]
fn rotation_action_rotates_about_world_z() {
    let mut env = state_only();
    let o0 = env.reset(4).unwrap();
    let mut o = o0.clone();
    for _ in 0..5 {
        o = env.step(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.3, 0.0]).unwrap();
    }
    // Compare with the expected pre-multiplied rotation about world z (5 × 0.15 rad, if fully tracked).
    let r0 = quat_to_mat(o0.eef_quat);
    let r1 = quat_to_mat(o.eef_quat);
    let rel = r1 * r0.transpose();
    let angle_z = rel[(1, 0)].atan2(rel[(0, 0)]);
    // OSC re-anchors the goal 0.15 rad ahead each step; with kp 150 and critical damping the hand turns
    // at ~kp·0.15/kd ≈ 0.9 rad/s, i.e. ~0.045 rad per step once moving.
    assert!(angle_z > 0.12 && angle_z < 0.3, "yaw change {angle_z}");
    // …and about world z only: the residual rotation is small.
    let residual = rel * axis_angle_to_mat([0.0, 0.0, -angle_z]);
    let res_angle = ((residual.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos();
    assert!(res_angle < 0.02, "off-axis rotation {res_angle}");
}

fn quat_to_mat(q: [f64; 4]) -> nalgebra::Matrix3<f64> {
    let uq = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
        q[0], q[1], q[2], q[3],
    ));
    uq.to_rotation_matrix().into_inner()
}

/// LIBERO's gripper: the command ramps over 8 steps (200 substeps) and the fingers (position servos,
/// kp 1000, damping 100, armature 1, friction loss 1 N) follow with a ~90 ms lag; friction leaves ~1 mm.
#[test]
fn gripper_opens_and_closes_fully_within_10_steps() {
    let mut env = state_only();
    env.reset(5).unwrap();
    let mut s = [0.0f32; 8];
    for _ in 0..10 {
        s = env
            .step(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0])
            .unwrap()
            .state;
    }
    assert!(s[6] > 0.037 && s[7] < -0.037, "open fingers {:?}", &s[6..]);
    for _ in 0..10 {
        s = env
            .step(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
            .unwrap()
            .state;
    }
    // ≥ 89 % of the 0.04 m travel within 10 steps…
    assert!(
        s[6] < 0.0045 && s[7] > -0.0045,
        "closed fingers after 10 steps {:?}",
        &s[6..]
    );
    for _ in 0..4 {
        s = env
            .step(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
            .unwrap()
            .state;
    }
    // …and within the friction band (< 1.5 mm) a few steps later.
    assert!(
        s[6] < 0.0015 && s[7] > -0.0015,
        "closed fingers after 14 steps {:?}",
        &s[6..]
    );
    // The hold command (0) keeps the fingers where they are.
    let held = env.step(&[0.0; 7]).unwrap().state;
    assert!((held[6] - s[6]).abs() < 5e-4, "{held:?}");
}

#[test]
fn bad_actions_are_errors() {
    let mut env = state_only();
    env.reset(0).unwrap();
    assert!(
        env.step(&[0.0; 6])
            .unwrap_err()
            .to_string()
            .contains("expected 7")
    );
    assert!(env.step(&[0.0, f32::NAN, 0.0, 0.0, 0.0, 0.0, 0.0]).is_err());
}

#[test]
fn same_seed_same_actions_identical_observations_with_images() {
    let cfg = EnvConfig {
        image_size: 64,
        depth: true,
        segmentation: true,
        ..EnvConfig::default()
    };
    let mut a = Env::new(cfg.clone()).unwrap();
    let mut b = Env::new(cfg).unwrap();
    let mut oa = a.reset(42).unwrap();
    let mut ob = b.reset(42).unwrap();
    assert_eq!(oa, ob);
    for t in 0..15 {
        let act = [
            0.5 * ((t as f32) * 0.3).sin(),
            0.3,
            -0.2,
            0.0,
            0.1,
            0.0,
            if t < 7 { -1.0 } else { 1.0 },
        ];
        oa = a.step(&act).unwrap();
        ob = b.step(&act).unwrap();
    }
    assert_eq!(oa.agentview_rgb.len(), 64 * 64 * 3);
    assert_eq!(oa.agentview_rgb, ob.agentview_rgb);
    assert_eq!(oa.eye_in_hand_rgb, ob.eye_in_hand_rgb);
    assert_eq!(oa, ob);
    // A different seed moves the box.
    let oc = b.reset(43).unwrap();
    let od = a.reset(42).unwrap();
    assert_ne!(oc.agentview_rgb, od.agentview_rgb);
}

#[test]
fn segmentation_sees_the_table_robot_and_box() {
    let mut env = Env::new(EnvConfig {
        image_size: 128,
        segmentation: true,
        ..EnvConfig::default()
    })
    .unwrap();
    let obs = env.reset(7).unwrap();
    let seg = obs.agentview_segmentation.unwrap();
    let model = env.model().clone();
    let id = |n: &str| model.id(sim::mujoco::ObjType::Body, n).unwrap() as i32;
    for name in ["main_table", "robot0_base", "cube"] {
        let n = seg.iter().filter(|&&s| s == id(name)).count();
        assert!(n > 10, "{name}: {n} pixels");
    }
}

#[test]
fn the_box_rests_on_the_table_with_contacts() {
    let mut env = state_only();
    env.reset(9).unwrap();
    for _ in 0..20 {
        env.step(&[0.0; 7]).unwrap();
    }
    let model = env.model().clone();
    let cube = model.id(sim::mujoco::ObjType::Geom, "cube_g").unwrap();
    let table = model
        .id(sim::mujoco::ObjType::Geom, "main_table_collision")
        .unwrap();
    let contacts = env.data().contacts();
    let touching: Vec<_> = contacts
        .iter()
        .filter(|c| (c.geom1 == cube && c.geom2 == table) || (c.geom1 == table && c.geom2 == cube))
        .collect();
    assert!(
        !touching.is_empty(),
        "no cube–table contact among {contacts:?}"
    );
    for c in &touching {
        assert!(
            c.dist.abs() < 0.002 && (c.pos[2] - 0.90).abs() < 0.003,
            "{c:?}"
        );
        assert!(c.normal[2].abs() > 0.99, "{c:?}");
    }
    let z = env.cube_pos().unwrap()[2];
    assert!((z - 0.92).abs() < 0.002, "cube centre at z = {z}");
}
