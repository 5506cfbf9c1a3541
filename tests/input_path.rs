//! One input path: a recorded episode replayed through the training batcher (`train`'s
//! `RunData::batch` over `data`'s windows) and through eval's policy input path
//! (`eval::policy::model_input` on the live simulator observations of the same seed and
//! actions) gives the same model tensors, bit for bit: frames, instruction ids and the oracle
//! subgoal ids of every step.

use burn::prelude::*;

fn ints(t: Tensor<2, Int>) -> Vec<i64> {
    t.try_to_vec_as::<i64>().unwrap()
}

fn floats(t: Tensor<4>) -> Vec<u32> {
    // Bit patterns: equality of every f32 bit, not within a tolerance.
    t.try_to_vec_as::<f32>()
        .unwrap()
        .into_iter()
        .map(f32::to_bits)
        .collect()
}

#[test]
fn recorded_episode_gives_equal_tensors_in_training_and_in_eval() {
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
    cfg.data.augment = false;
    let vocab = train::dataset::RunData::model_vocab(&index).unwrap();
    let mcfg = cfg.model_config(vocab).unwrap();
    let run_data = train::dataset::RunData::open(&cfg, &mcfg).unwrap();
    let device = Device::flex();
    let w = cfg.window_len();
    let last = |t: Tensor<5>| {
        let [_, _, c, h, wd] = t.dims();
        t.narrow(1, w - 1, 1).reshape([1, c, h, wd])
    };

    // The eval side: replay the recorded actions from the recorded seed, live.
    let mut env = sim::Env::from_task(
        &task,
        sim::EnvConfig {
            image_size: gen_cfg.image_size,
            segmentation: true,
            ..Default::default()
        },
    )
    .unwrap();
    let mut obs = env.reset(episode.meta().seed).unwrap();
    let processor = &run_data.processor;
    let mut subgoal_changes = 0;
    let mut previous_subgoal = None;
    for t in 0..n {
        let live = eval::policy::model_input(processor, &task.instruction, &obs, &device).unwrap();
        // Window ending at step t (past = w − 1, future = 0): its last frame is step t.
        let batch = run_data.batch(&run_data.train, &[(t, 0)], &device).unwrap();
        assert_eq!(
            floats(last(batch.images)),
            floats(live.image),
            "step {t}: frames differ"
        );
        assert_eq!(ints(batch.instruction), ints(live.instruction), "step {t}");
        let sub_train = batch.subgoal.expect("the oracle variant reads subgoals");
        let [_, _, _, l] = sub_train.dims();
        let sub_train = ints(sub_train.narrow(1, w - 1, 1).reshape([1, l]));
        let sub_live = ints(live.subgoal.expect("subgoal").reshape([1, l]));
        assert_eq!(sub_train, sub_live, "step {t}: subgoal ids differ");
        if previous_subgoal.as_ref() != Some(&sub_live) {
            subgoal_changes += 1;
            previous_subgoal = Some(sub_live);
        }
        let step = episode.read_step(t).unwrap();
        obs = env.step(&step.action).unwrap();
    }
    assert!(subgoal_changes >= 2, "the subgoal input never changed");
}
