//! Our policy server round trip: a trained run served by `eval serve`'s server
//! (`eval::remote::server`) and evaluated through `eval --policy ws://`'s client
//! (`eval::remote::RemotePolicy`, one action per request) executes the same actions, bit for bit,
//! as the run evaluated directly (`eval --run`), in state mode and with pixels and the oracle's
//! boxes, and scores the same.

use std::sync::{Arc, Mutex};

use eval::remote::{RemoteConfig, RemotePolicy};
use eval::{EvalConfig, EvalError, Policy};

/// Every executed action's bit pattern, with its episode's seed.
type ActionLog = Arc<Mutex<Vec<(u64, [u32; 7])>>>;

/// Logs every action a policy returns, per episode seed.
struct Logged<P> {
    inner: P,
    log: ActionLog,
    seed: u64,
}

impl<P: Policy> Policy for Logged<P> {
    fn reset(&mut self, task: &sim::task::TaskSpec, seed: u64) -> Result<(), EvalError> {
        self.seed = seed;
        self.inner.reset(task, seed)
    }
    fn act(&mut self, env: &sim::Env, obs: &sim::Observation) -> Result<[f32; 7], EvalError> {
        let a = self.inner.act(env, obs)?;
        self.log
            .lock()
            .unwrap()
            .push((self.seed, a.map(f32::to_bits)));
        Ok(a)
    }
    fn needs_images(&self) -> bool {
        self.inner.needs_images()
    }
    fn needs_segmentation(&self) -> bool {
        self.inner.needs_segmentation()
    }
}

fn round_trip(obs: train::config::ObsMode) {
    let tmp = tempfile::tempdir().unwrap();
    let data_dir = tmp.path().join("data");
    let task = sim::task::resolve("t1").unwrap();
    let gen_cfg = sim::generate::GenerateConfig {
        episodes: 2,
        val: 0,
        seed: 5,
        workers: 1,
        image_size: 64,
        ..Default::default()
    };
    sim::generate::generate(&task, &data_dir, &gen_cfg, &|_| {}).unwrap();
    let mut cfg = e2e::tiny_config(&data_dir, 4);
    cfg.model.variant = "e_slotssm_oracle".into();
    cfg.model.obs = obs;
    let run_dir = tmp.path().join("run");
    train::train(
        &cfg,
        &train::TrainOptions {
            run_dir: Some(run_dir.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    let run = eval::RunDir::open(&run_dir).unwrap();
    let device = eval::run::device(&run, None).unwrap();
    let tasks = vec![task];
    let eval_cfg = EvalConfig {
        episodes: 2,
        seed: 17,
        image_size: 64,
        ..EvalConfig::default()
    };
    let direct_log = Arc::new(Mutex::new(Vec::new()));
    let make = || -> Result<Box<dyn Policy>, EvalError> {
        Ok(Box::new(Logged {
            inner: eval::run::policy(&run, &device)?,
            log: direct_log.clone(),
            seed: 0,
        }))
    };
    let direct = eval::evaluate(&tasks, &make, &eval_cfg, &|_| {}).unwrap();

    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("ws://{}", listener.local_addr().unwrap());
    let remote_log = Arc::new(Mutex::new(Vec::new()));
    let info = eval::remote::server::ServerInfo {
        run: run_dir.display().to_string(),
        step: run.step,
    };
    let remote = std::thread::scope(|s| {
        let serve_make = || eval::run::policy(&run, &device);
        let info = &info;
        s.spawn(move || {
            eval::remote::server::serve(listener, &serve_make, info, Some(1), &|_| {}).unwrap()
        });
        let make = || -> Result<Box<dyn Policy>, EvalError> {
            Ok(Box::new(Logged {
                inner: RemotePolicy::connect(RemoteConfig {
                    url: url.clone(),
                    replan_steps: 1,
                    ..RemoteConfig::default()
                })?,
                log: remote_log.clone(),
                seed: 0,
            }))
        };
        eval::evaluate(&tasks, &make, &eval_cfg, &|_| {}).unwrap()
    });
    let (a, b) = (direct_log.lock().unwrap(), remote_log.lock().unwrap());
    assert_eq!(
        a.len(),
        direct.episodes.iter().map(|e| e.steps).sum::<usize>()
    );
    assert!(
        a.iter().any(|(_, x)| x[..6].iter().any(|&v| v != 0)),
        "the policy moves"
    );
    assert_eq!(*a, *b, "every executed action, bit for bit");
    assert_eq!(direct.episodes, remote.episodes);
}

#[test]
fn served_state_policy_equals_the_run() {
    round_trip(train::config::ObsMode::State);
}

#[test]
fn served_pixel_oracle_policy_equals_the_run() {
    round_trip(train::config::ObsMode::Pixels);
}
