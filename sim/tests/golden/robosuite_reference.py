"""Records robosuite 1.4.0's Panda + OSC_POSE response to fixed action sequences (the golden file
`robosuite_osc.json` used by sim/tests/fidelity.rs). Reference only: the product never runs Python.

Set-up (a throwaway venv):
    python3 -m venv /tmp/rs && /tmp/rs/bin/pip install "robosuite==1.4.0" "mujoco==2.3.7" "numpy<2" termcolor scipy numba
    MUJOCO_GL=egl /tmp/rs/bin/python sim/tests/golden/robosuite_reference.py > sim/tests/golden/robosuite_osc.json

The arm starts at LIBERO's init_qpos (LIBERO overrides robosuite's stock Panda pose), no init noise,
control at 20 Hz, as in LIBERO's ControlEnv. Positions are reported relative to robot0_link0.
"""
import json

import numpy as np
import robosuite as suite
from robosuite import load_controller_config
from robosuite.models.robots import Panda

LIBERO_INIT = [0, -0.161037389, 0, -2.44459747, 0, 2.2267522, np.pi / 4]
Panda.init_qpos = property(lambda self: np.array(LIBERO_INIT))

SEQUENCES = {
    "zero_100": [[0, 0, 0, 0, 0, 0, 0]] * 100,
    "plus_x_10": [[1, 0, 0, 0, 0, 0, -1]] * 10,
    "minus_y_half_8": [[0, -0.5, 0, 0, 0, 0, 0]] * 8,
    "plus_z_half_8": [[0, 0, 0.5, 0, 0, 0, 0]] * 8,
    "yaw_5_then_hold_5": [[0, 0, 0, 0, 0, 0.3, 0]] * 5 + [[0, 0, 0, 0, 0, 0, 0]] * 5,
    "roll_pitch_6": [[0, 0, 0, 0.3, -0.2, 0, 0]] * 6,
    "open_10_close_14": [[0, 0, 0, 0, 0, 0, -1]] * 10 + [[0, 0, 0, 0, 0, 0, 1]] * 14,
    "mixed_20": [[0.5 * np.sin(0.3 * t), 0.3, -0.2, 0.0, 0.1, 0.0, -1.0 if t < 7 else 1.0] for t in range(20)],
}


def main():
    cfg = load_controller_config(default_controller="OSC_POSE")
    env = suite.make("Lift", robots="Panda", controller_configs=cfg, has_renderer=False,
                     has_offscreen_renderer=False, use_camera_obs=False, initialization_noise=None,
                     control_freq=20, horizon=1000)
    out = {"source": "robosuite 1.4.0, mujoco 2.3.7, Panda + PandaGripper, OSC_POSE, LIBERO init_qpos",
           "sequences": {}}
    for name, actions in SEQUENCES.items():
        obs = env.reset()
        base = env.sim.data.get_body_xpos("robot0_link0").copy()
        rec = {"actions": [list(map(float, a)) for a in actions], "eef_pos": [], "eef_quat_wxyz": [],
               "gripper_qpos": [], "joint_pos": []}

        def log(o):
            rec["eef_pos"].append([float(v) for v in o["robot0_eef_pos"] - base])
            x, y, z, w = o["robot0_eef_quat"]
            rec["eef_quat_wxyz"].append([float(w), float(x), float(y), float(z)])
            rec["gripper_qpos"].append([float(v) for v in o["robot0_gripper_qpos"]])
            rec["joint_pos"].append([float(v) for v in env.sim.data.qpos[:7]])

        log(obs)
        for a in actions:
            obs, *_ = env.step(np.array(a, dtype=float))
            log(obs)
        out["sequences"][name] = rec
    print(json.dumps(out))


if __name__ == "__main__":
    main()
