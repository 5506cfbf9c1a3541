#!/usr/bin/env python
"""Reference outputs from Python LIBERO (hf-libero 0.1.4 + robosuite 1.4.0 + mujoco 2.3.7)
for libero_goal/put_the_bowl_on_the_plate, compared by `sim/examples/libero_parity.rs`.
A one-off measurement; the product never runs Python.

Set-up (a throwaway venv; versions.txt is its `pip freeze`):
  python3 -m venv venv
  venv/bin/pip install mujoco==2.3.7 robosuite==1.4.0 numpy==1.26.4 numba==0.60.0 scipy==1.13.1 \
      opencv-python==4.10.0.84
  venv/bin/pip install --no-deps hf-libero==0.1.4
  venv/bin/pip install bddl==1.0.1 easydict pyyaml termcolor future "matplotlib<3.10" cloudpickle "gymnasium<1.0"
  # hf-libero looks for its assets inside the package: link the pack's merged assets there
  ln -s ~/.cache/libero-mem-rs/libero/assets venv/lib/python3.11/site-packages/libero/libero/assets
  # a config.yaml in $LIBERO_CONFIG_PATH naming the package's bddl_files and init_files folders
Run (writes ./out/; copy the *_upright.png and JSON files to docs/parity/):
  LIBERO_CONFIG_PATH=. MUJOCO_GL=egl PYOPENGL_PLATFORM=egl venv/bin/python libero_reference.py
"""
import json
import os
import pickle
import sys
import zipfile

import numpy as np
from PIL import Image

import mujoco
from libero.libero import get_libero_path
from libero.libero.envs import OffScreenRenderEnv

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "out")
os.makedirs(OUT, exist_ok=True)

SUITE, TASK = "libero_goal", "put_the_bowl_on_the_plate"
BDDL = os.path.join(get_libero_path("bddl_files"), SUITE, TASK + ".bddl")
INIT = os.path.join(get_libero_path("init_states"), SUITE, TASK + ".pruned_init")
H = W = 128
SEED = 0


def load_init_states(path):
    """torch.save zip -> archive/data.pkl is a protocol-2 pickle of a plain numpy
    array (numpy.core.multiarray._reconstruct), so plain pickle + numpy reads it."""
    with zipfile.ZipFile(path) as z:
        name = [n for n in z.namelist() if n.endswith("data.pkl")][0]
        arr = pickle.loads(z.read(name))
    return np.asarray(arr, dtype=np.float64)


def tolist(x):
    return np.asarray(x).tolist()


def name_of(m, objtype, i):
    return mujoco.mj_id2name(m, objtype, i)


def fixture_poses(env):
    """World pose of the fixture root bodies (not stored in init states)."""
    sim = env.sim
    m = sim.model._model
    d = sim.data._data
    res = {}
    for i in range(m.nbody):
        n = name_of(m, mujoco.mjtObj.mjOBJ_BODY, i)
        if n and n.endswith("_main") and any(
            n.startswith(f) for f in ("wooden_cabinet_1", "flat_stove_1", "wine_rack_1")
        ):
            res[n] = {
                "model_body_pos": tolist(m.body_pos[i]),
                "model_body_quat_wxyz": tolist(m.body_quat[i]),
                "xpos": tolist(d.xpos[i]),
                "xquat_wxyz": tolist(d.xquat[i]),
            }
    return res


def fresh(env, init_states, k=0):
    """OpenVLA-style: env.seed(0); env.reset(); obs = env.set_init_state(init_states[k])."""
    env.seed(SEED)
    env.reset()
    obs = env.set_init_state(init_states[k])
    return obs


def save_img(arr, stem):
    arr = np.asarray(arr, dtype=np.uint8)
    Image.fromarray(arr).save(os.path.join(OUT, stem + "_raw.png"))
    Image.fromarray(np.ascontiguousarray(arr[::-1])).save(os.path.join(OUT, stem + "_upright.png"))


def main():
    init_states = load_init_states(INIT)
    print("init_states", init_states.shape)

    env = OffScreenRenderEnv(bddl_file_name=BDDL, camera_heights=H, camera_widths=W)
    obs = fresh(env, init_states, 0)
    sim = env.sim
    m = sim.model._model
    d = sim.data._data
    renv = env.env  # the robosuite/LIBERO problem env

    # ---------------- 1. model.xml + layout.json ----------------
    with open(os.path.join(OUT, "model.xml"), "w") as f:
        f.write(sim.model.get_xml())  # mujoco.mj_saveLastXML of the compiled model
    with open(os.path.join(OUT, "model_source_mjcf.xml"), "w") as f:
        f.write(renv.model.get_xml())  # robosuite's MJCF string that was compiled (before fixture pose edits)

    joints = []
    for j in range(m.njnt):
        joints.append({
            "name": name_of(m, mujoco.mjtObj.mjOBJ_JOINT, j),
            "type": int(m.jnt_type[j]),  # 0 free, 1 ball, 2 slide, 3 hinge
            "qposadr": int(m.jnt_qposadr[j]),
            "dofadr": int(m.jnt_dofadr[j]),
            "body": name_of(m, mujoco.mjtObj.mjOBJ_BODY, int(m.jnt_bodyid[j])),
            "range": tolist(m.jnt_range[j]),
            "limited": int(m.jnt_limited[j]),
        })
    joints.sort(key=lambda x: x["qposadr"])
    cams = []
    for c in range(m.ncam):
        cams.append({
            "name": name_of(m, mujoco.mjtObj.mjOBJ_CAMERA, c),
            "parent_body": name_of(m, mujoco.mjtObj.mjOBJ_BODY, int(m.cam_bodyid[c])),
            "pos": tolist(m.cam_pos[c]),
            "quat_wxyz": tolist(m.cam_quat[c]),
            "fovy": float(m.cam_fovy[c]),
            "mode": int(m.cam_mode[c]),
            "world_xpos_at_init0": tolist(d.cam_xpos[c]),
            "world_xmat_at_init0": tolist(d.cam_xmat[c].reshape(3, 3)),
        })
    lights = []
    for li in range(m.nlight):
        lights.append({
            "name": name_of(m, mujoco.mjtObj.mjOBJ_LIGHT, li),
            "body": name_of(m, mujoco.mjtObj.mjOBJ_BODY, int(m.light_bodyid[li])),
            "pos": tolist(m.light_pos[li]),
            "dir": tolist(m.light_dir[li]),
            "directional": int(m.light_directional[li]),
            "castshadow": int(m.light_castshadow[li]),
            "active": int(m.light_active[li]),
            "ambient": tolist(m.light_ambient[li]),
            "diffuse": tolist(m.light_diffuse[li]),
            "specular": tolist(m.light_specular[li]),
            "attenuation": tolist(m.light_attenuation[li]),
            "cutoff": float(m.light_cutoff[li]),
            "exponent": float(m.light_exponent[li]),
        })
    hl = m.vis.headlight
    layout = {
        "task": f"{SUITE}/{TASK}",
        "bddl_file": BDDL,
        "nq": int(m.nq), "nv": int(m.nv), "nu": int(m.nu), "nbody": int(m.nbody),
        "ngeom": int(m.ngeom), "nsite": int(m.nsite), "njnt": int(m.njnt),
        "nmesh": int(m.nmesh), "ntex": int(m.ntex), "nmat": int(m.nmat), "ncam": int(m.ncam),
        "nlight": int(m.nlight),
        "timestep": float(m.opt.timestep),
        "control_freq": float(renv.control_freq),
        "substeps_per_env_step": int(round(1.0 / (renv.control_freq * m.opt.timestep))),
        "horizon": int(renv.horizon),
        "opt": {
            "integrator": int(m.opt.integrator), "solver": int(m.opt.solver), "cone": int(m.opt.cone),
            "impratio": float(m.opt.impratio), "density": float(m.opt.density),
            "viscosity": float(m.opt.viscosity), "gravity": tolist(m.opt.gravity),
            "iterations": int(m.opt.iterations), "tolerance": float(m.opt.tolerance),
        },
        "joints_in_qpos_order": joints,
        "bodies": [name_of(m, mujoco.mjtObj.mjOBJ_BODY, i) for i in range(m.nbody)],
        "geoms": [name_of(m, mujoco.mjtObj.mjOBJ_GEOM, i) for i in range(m.ngeom)],
        "sites": [name_of(m, mujoco.mjtObj.mjOBJ_SITE, i) for i in range(m.nsite)],
        "actuators": [name_of(m, mujoco.mjtObj.mjOBJ_ACTUATOR, i) for i in range(m.nu)],
        "cameras": cams,
        "headlight": {
            "active": int(hl.active), "ambient": tolist(hl.ambient),
            "diffuse": tolist(hl.diffuse), "specular": tolist(hl.specular),
        },
        "lights": lights,
        "fixture_poses_seed0_first_reset": fixture_poses(env),
        "camera_names_in_env": list(renv.camera_names),
        "camera_hw": [H, W],
        "image_convention": __import__("robosuite").macros.IMAGE_CONVENTION,
    }
    with open(os.path.join(OUT, "layout.json"), "w") as f:
        json.dump(layout, f, indent=1)
    print("nq", m.nq, "nv", m.nv, "nbody", m.nbody, "ngeom", m.ngeom)

    # ---------------- 2. init0_qpos.json ----------------
    eef_site = renv.robots[0].eef_site_id  # gripper0_grip_site
    init0 = {
        "init_state_row0": tolist(init_states[0]),
        "qpos": tolist(d.qpos), "qvel": tolist(d.qvel), "time": float(d.time),
        "body_xpos": {name_of(m, mujoco.mjtObj.mjOBJ_BODY, i): tolist(d.xpos[i]) for i in range(m.nbody)},
        "body_xquat_wxyz": {name_of(m, mujoco.mjtObj.mjOBJ_BODY, i): tolist(d.xquat[i]) for i in range(m.nbody)},
        "eef_site_name": name_of(m, mujoco.mjtObj.mjOBJ_SITE, int(eef_site)),
        "eef_site_xpos": tolist(d.site_xpos[eef_site]),
        "obs_robot0_eef_pos": tolist(obs["robot0_eef_pos"]),
        "obs_robot0_eef_quat_xyzw": tolist(obs["robot0_eef_quat"]),
        "obs_robot0_gripper_qpos": tolist(obs["robot0_gripper_qpos"]),
        "obs_robot0_joint_pos": tolist(obs["robot0_joint_pos"]),
        "fixture_poses": fixture_poses(env),
        "check_success": bool(env.check_success()),
    }
    # also the settled state after 10 OpenVLA idle steps (filled below)

    # ---------------- 3. images at init0, then after 10 idle steps ----------------
    save_img(obs["agentview_image"], "theirs_agentview_128")
    save_img(obs["robot0_eye_in_hand_image"], "theirs_eye_in_hand_128")
    idle = np.array([0, 0, 0, 0, 0, 0, -1], dtype=np.float64)
    for _ in range(10):
        obs, r, done, info = env.step(idle)
    save_img(obs["agentview_image"], "theirs_settled_agentview_128")
    save_img(obs["robot0_eye_in_hand_image"], "theirs_settled_eye_in_hand_128")
    init0["settled_after_10_idle_steps"] = {
        "qpos": tolist(d.qpos), "qvel": tolist(d.qvel), "time": float(d.time),
        "body_xpos": {name_of(m, mujoco.mjtObj.mjOBJ_BODY, i): tolist(d.xpos[i]) for i in range(m.nbody)},
        "obs_robot0_eef_pos": tolist(obs["robot0_eef_pos"]),
        "obs_robot0_gripper_qpos": tolist(obs["robot0_gripper_qpos"]),
        "check_success": bool(env.check_success()),
    }
    with open(os.path.join(OUT, "init0_qpos.json"), "w") as f:
        json.dump(init0, f, indent=1)

    # ---------------- 4. ee_travel.json ----------------
    actions = {
        "a1_plus_x": [1, 0, 0, 0, 0, 0, -1],
        "a2_plus_z": [0, 0, 1, 0, 0, 0, -1],
        "a3_close": [0, 0, 0, 0, 0, 0, 1],
        "zero_open": [0, 0, 0, 0, 0, 0, -1],
    }
    travel = {"protocol": "each run: env.seed(0); env.reset(); obs=env.set_init_state(init_states[0]); "
                          "then 10x env.step(action); no settle steps",
              "runs": {}}
    for key, a in actions.items():
        obs = fresh(env, init_states, 0)
        sim = env.sim
        d = sim.data._data
        p0 = np.array(obs["robot0_eef_pos"])
        rec = {"action": a, "eef_pos": [tolist(p0)], "gripper_qpos": [tolist(d.qpos[7:9])],
               "obs_gripper_qpos": [tolist(obs["robot0_gripper_qpos"])],
               "arm_qpos": [tolist(d.qpos[0:7])],
               "fixture_poses": fixture_poses(env)}
        for _ in range(10):
            obs, r, done, info = env.step(np.array(a, dtype=np.float64))
            rec["eef_pos"].append(tolist(obs["robot0_eef_pos"]))
            rec["gripper_qpos"].append(tolist(d.qpos[7:9]))
            rec["obs_gripper_qpos"].append(tolist(obs["robot0_gripper_qpos"]))
            rec["arm_qpos"].append(tolist(d.qpos[0:7]))
        disp = np.array(rec["eef_pos"][-1]) - p0
        rec["displacement"] = tolist(disp)
        rec["displacement_norm"] = float(np.linalg.norm(disp))
        rec["per_step_displacement"] = tolist(np.diff(np.array(rec["eef_pos"]), axis=0))
        travel["runs"][key] = rec
        print(key, "disp", disp, "norm", np.linalg.norm(disp))
    with open(os.path.join(OUT, "ee_travel.json"), "w") as f:
        json.dump(travel, f, indent=1)

    env.close()
    print("done")


if __name__ == "__main__":
    main()
