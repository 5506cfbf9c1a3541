//! One input path: a recorded episode replayed through the training batcher (`train`'s
//! `RunData::batch` over `data`'s windows) and through eval's policy input path
//! (`eval::policy::model_input` on the live simulator observations of the same seed and
//! actions) gives the same model tensors, bit for bit: frames (or in state mode the object
//! tokens and their categories), instruction ids and the oracle subgoal ids of every step
//! (the per-object labels; with pixels also the objects' boxes from the segmentation, which
//! the model matches to its slots), and the progress loss's target is the subgoals done as the
//! live environment reports them.

use burn::prelude::*;
use model::Frames;

fn ints(t: Tensor<2, Int>) -> Vec<i64> {
    t.try_to_vec_as::<i64>().unwrap()
}

fn floats<const D: usize>(t: Tensor<D>) -> Vec<u32> {
    // Bit patterns: equality of every f32 bit, not within a tolerance.
    t.try_to_vec_as::<f32>()
        .unwrap()
        .into_iter()
        .map(f32::to_bits)
        .collect()
}

/// Replays episode 0 of a generated T2 dataset through both paths in `obs` mode.
fn replay(obs: train::config::ObsMode) {
    let tmp = tempfile::tempdir().unwrap();
    let data_dir = tmp.path().join("data");
    // T2 has several subgoals, so the subgoal input changes during the episode.
    let task = sim::task::resolve("t2").unwrap();
    let gen_cfg = sim::generate::GenerateConfig {
        episodes: 1,
        val: 0,
        seed: 3,
        workers: 1,
        ..Default::default()
    };
    let index = sim::generate::generate(&task, &data_dir, &gen_cfg, &|_| {}).unwrap();
    let episode = data::EpisodeReader::open(data_dir.join(&index.episodes[0].file)).unwrap();
    let n = episode.len();

    // The training side, as `train` builds it (oracle variant: it reads the subgoal too).
    let mut cfg = e2e::tiny_config(&data_dir, 1);
    cfg.model.variant = "e_slotssm_oracle".into();
    cfg.model.obs = obs;
    if obs == train::config::ObsMode::State {
        // With the squashed relative and neighbour features and the cabinet's drawer handles as
        // tokens of their own, so both sides compute those too.
        cfg.model.state_relative_cm = vec![2.0, 8.0];
        cfg.model.state_neighbour_cm = vec![3.0];
        cfg.model.state_distances = true;
        cfg.model.state_parts = true;
    }
    cfg.data.augment = false;
    let vocab = train::dataset::RunData::model_vocab(&index).unwrap();
    let mut mcfg = cfg.model_config(vocab).unwrap();
    let opened = data::OpenedDataset::from_index(&data_dir, index).unwrap();
    let spec = (obs == train::config::ObsMode::State).then(|| {
        train::dataset::state_spec(
            &opened,
            &cfg.model.state_relative_cm,
            &cfg.model.state_neighbour_cm,
            cfg.model.state_distances,
            cfg.model.state_fingers,
            cfg.model.state_parts,
        )
        .unwrap()
    });
    if let Some(s) = &spec {
        assert!(
            s.categories
                .iter()
                .any(|c| c == "wooden_cabinet/top_handle"),
            "{:?}",
            s.categories
        );
        mcfg = mcfg.with_state(s.tokens(), s.num_categories(), s.features());
    }
    let run_data = train::dataset::RunData::open(&cfg, &mcfg, spec, &opened).unwrap();
    let device = Device::flex();
    let w = cfg.window_len();

    // The eval side: the model policy's input path on the recorded actions replayed live from
    // the recorded seed.
    let mut env = sim::Env::from_task(
        &task,
        sim::EnvConfig {
            image_size: gen_cfg.image_size,
            render: obs == train::config::ObsMode::Pixels,
            segmentation: obs == train::config::ObsMode::Pixels,
            ..Default::default()
        },
    )
    .unwrap();
    let model = model::PolicyModel::new(&mcfg, &device).unwrap();
    let mut policy =
        eval::policy::ModelPolicy::new(model, run_data.processor.clone(), &device).unwrap();
    let seed = episode.meta().seed;
    eval::policy::Policy::reset(&mut policy, &task, seed).unwrap();
    let mut obs_t = env.reset(seed).unwrap();
    let mut subgoal_changes = 0;
    let mut seen_boxes = 0;
    let mut previous_subgoal = None;
    let mut max_done = 0;
    for t in 0..n {
        let live = policy.input(&env, &obs_t).unwrap();
        // Window ending at step t (past = w − 1, future = 0): its last frame is step t.
        let batch = run_data.batch(&run_data.train, &[(t, 0)], &device).unwrap();
        match (batch.obs.narrow(w - 1, 1), live.obs) {
            (Frames::Pixels(a), Frames::Pixels(b)) => {
                assert_eq!(floats(a), floats(b), "step {t}: frames differ")
            }
            (Frames::State(a, ca), Frames::State(b, cb)) => {
                assert_eq!(floats(a), floats(b), "step {t}: object tokens differ");
                let [_, _, k] = ca.dims();
                assert_eq!(
                    ints(ca.reshape([1, k])),
                    ints(cb.reshape([1, k])),
                    "step {t}"
                );
            }
            _ => panic!("step {t}: the two paths observe differently"),
        }
        assert_eq!(ints(batch.instruction), ints(live.instruction), "step {t}");
        let sub_train = batch.subgoal.expect("the oracle variant reads subgoals");
        let sub_live = live.subgoal.expect("subgoal");
        let [_, _, g, l] = sub_train.ids.dims();
        match (sub_train.boxes, sub_live.boxes) {
            (Some(a), Some(b)) => {
                let [_, _, j, _] = a.dims();
                let a = floats(a.narrow(1, w - 1, 1).reshape([j, 4]));
                assert_eq!(
                    a,
                    floats(b.reshape([j, 4])),
                    "step {t}: object boxes differ"
                );
                seen_boxes += a.chunks(4).filter(|x| x[2] != 0).count();
            }
            (None, None) => assert_eq!(obs, train::config::ObsMode::State, "step {t}"),
            _ => panic!("step {t}: one path gives object boxes, the other not"),
        }
        let sub_train = ints(sub_train.ids.narrow(1, w - 1, 1).reshape([g, l]));
        let sub_live = ints(sub_live.ids.reshape([g, l]));
        assert_eq!(sub_train, sub_live, "step {t}: subgoal ids differ");
        if previous_subgoal.as_ref() != Some(&sub_live) {
            subgoal_changes += 1;
            previous_subgoal = Some(sub_live);
        }
        // The progress loss's target: the subgoals done as the live environment reports them
        // with this observation.
        let done = batch.progress.expect("windows with goal progress");
        let live_done = obs_t.goal.as_ref().map_or(0, |g| g.satisfied as i64);
        assert_eq!(ints(done.narrow(1, w - 1, 1))[0], live_done, "step {t}");
        max_done = max_done.max(live_done);
        let step = episode.read_step(t).unwrap();
        obs_t = env.step(&step.action).unwrap();
    }
    assert!(subgoal_changes >= 2, "the subgoal input never changed");
    assert!(max_done >= 1, "the progress target never moved from 0");
    if obs == train::config::ObsMode::Pixels {
        assert!(
            seen_boxes >= n,
            "{seen_boxes} boxes of seen objects in {n} steps"
        );
    }
}

#[test]
fn recorded_episode_gives_equal_tensors_in_training_and_in_eval() {
    replay(train::config::ObsMode::Pixels);
}

#[test]
fn recorded_episode_gives_equal_state_tokens_and_labels_in_training_and_in_eval() {
    replay(train::config::ObsMode::State);
}

/// The idle tail reaches the training batch at `data.idle_tail_weight`: the action weights of a
/// window on a demo recorded with a 30-step hold are 1 on the moves, the weight on the standstill and 0
/// past the episode's end, as the action loss reads them.
#[test]
fn the_idle_tail_reaches_the_batch_at_its_weight() {
    let tmp = tempfile::tempdir().unwrap();
    let data_dir = tmp.path().join("data");
    let task = sim::task::resolve("t1").unwrap();
    let gen_cfg = sim::generate::GenerateConfig {
        episodes: 1,
        val: 0,
        seed: 5,
        workers: 1,
        image_size: 32,
        // 30 idle steps after the release and the retreat, as `sim generate --hold-steps 30`.
        expert: sim::generate::expert_config(false, Some(30)),
        ..Default::default()
    };
    let index = sim::generate::generate(&task, &data_dir, &gen_cfg, &|_| {}).unwrap();
    let episode = data::EpisodeReader::open(data_dir.join(&index.episodes[0].file)).unwrap();
    let n = episode.len();
    let actions: Vec<[f32; 7]> = episode
        .read_raw_steps(0..n)
        .unwrap()
        .iter()
        .map(|s| s.action)
        .collect();
    let tail = data::window::idle_tail_start(&actions);
    assert!(tail + 30 <= n && tail > 0, "tail at {tail} of {n}");

    let mut cfg = e2e::tiny_config(&data_dir, 1);
    cfg.model.variant = "e_slotssm_oracle".into();
    cfg.model.obs = train::config::ObsMode::State;
    cfg.data.augment = false;
    cfg.data.mask_idle_tail = true;
    cfg.data.idle_tail_weight = 0.5;
    let vocab = train::dataset::RunData::model_vocab(&index).unwrap();
    let opened = data::OpenedDataset::from_index(&data_dir, index).unwrap();
    let spec = train::dataset::state_spec(&opened, &[], &[], false, true, false).unwrap();
    let mcfg = cfg.model_config(vocab).unwrap().with_state(
        spec.tokens(),
        spec.num_categories(),
        spec.features(),
    );
    let run_data = train::dataset::RunData::open(&cfg, &mcfg, Some(spec), &opened).unwrap();
    let device = Device::flex();
    let (w, ha) = (cfg.window_len(), mcfg.decoder.horizon);
    // The last frame's chunk of the window ending at step t: one weight per chunk step (the
    // seven action dims of a step share it).
    let weights_with = |t: usize, idle_tail: bool| -> Vec<f32> {
        let batch = run_data
            .batch_with(&run_data.train, &[(t, 0)], idle_tail, &device)
            .unwrap();
        let m = batch.action_mask.expect("the batcher weighs the actions");
        let v = m.narrow(1, w - 1, 1).try_to_vec_as::<f32>().unwrap();
        v.chunks(7)
            .map(|c| {
                assert!(c.iter().all(|&x| x == c[0]), "{c:?}");
                c[0]
            })
            .collect()
    };
    let expect = |t: usize| -> Vec<f32> {
        (t..t + ha)
            .map(|s| {
                if s < tail {
                    1.0
                } else if s < n {
                    0.5
                } else {
                    0.0
                }
            })
            .collect()
    };
    let weights = |t: usize| weights_with(t, true);
    for t in [tail - 2, tail - 1, tail, n - 2, n - 1] {
        assert_eq!(weights(t), expect(t), "window ending at step {t} of {n}");
        // A stage with `idle_tail = false`: the moves keep their weight, the tail gets none.
        let without: Vec<f32> = expect(t)
            .iter()
            .map(|&x| if x == 1.0 { 1.0 } else { 0.0 })
            .collect();
        assert_eq!(weights_with(t, false), without, "step {t}, no idle tail");
    }
    assert!(weights(tail - 1).contains(&1.0) && weights(tail - 1).contains(&0.5));
}
