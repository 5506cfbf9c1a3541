//! DAgger's take-over episodes: the policy's steps recorded unlabelled, the expert's after them,
//! only finished episodes kept, a re-run resumes, and the base dataset joins them in one index.

use eval::dagger::{DaggerConfig, TakeOver, collect, episode_path, join_base};
use eval::{EvalError, Policy, ZeroPolicy};

fn zero() -> Result<Box<dyn Policy>, EvalError> {
    Ok(Box::new(ZeroPolicy))
}

#[test]
fn a_zero_policy_handed_over_to_the_expert_gives_labelled_suffixes_and_one_dataset() {
    let task = sim::task::registry::resolve("libero_mem/t1").unwrap();
    let out = tempfile::tempdir().unwrap();
    let cfg = DaggerConfig {
        episodes: 2,
        take_over: (0.1, 0.3),
        ..DaggerConfig::default()
    };
    // One collection into `out`: its episodes, and how many it ran.
    let run = || -> (Vec<TakeOver>, usize) {
        let ran = std::sync::atomic::AtomicUsize::new(0);
        let eps = collect(
            std::slice::from_ref(&task),
            &zero,
            &cfg,
            out.path(),
            &|_| {
                ran.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
            },
        )
        .unwrap();
        (eps, ran.into_inner())
    };
    let (runs, ran) = run();
    assert_eq!(ran, 2);
    assert_eq!(runs.len(), 2);
    for r in &runs {
        // Within the asked share of T1's 200-step budget, drawn from the episode's seed.
        assert!((20..60).contains(&r.at), "take-over at {}", r.at);
        assert_eq!(r.satisfied_at, 0, "standing still satisfies nothing");
        assert!(
            r.kept,
            "the expert finishes T1 from where the zero policy left it: {r:?}"
        );
        let file = data::EpisodeReader::open(episode_path(out.path(), &task, r.episode)).unwrap();
        assert_eq!(file.meta().labelled_from(), Ok(r.at));
        assert_eq!(file.meta().seed, r.seed);
        assert_eq!(file.len(), r.at + r.expert_steps);
        let steps = file.read_raw_steps(0..file.len()).unwrap();
        assert!(
            steps[..r.at].iter().all(|s| s.action == [0.0; 7]),
            "the policy's actions"
        );
        assert!(
            steps[r.at..].iter().any(|s| s.action != [0.0; 7]),
            "the expert's"
        );
        let last = &steps.last().unwrap().progress;
        assert_eq!(last.satisfied, 1);
    }
    assert_ne!(runs[0].at, runs[1].at, "each episode draws its own step");
    // A second collection finds both in its ledger and runs nothing: the same records.
    assert_eq!(run(), (runs.clone(), 0));
    // A kept episode whose file is gone is run again, to the same file.
    let first = episode_path(out.path(), &task, 0);
    let bytes = std::fs::read(&first).unwrap();
    std::fs::remove_file(&first).unwrap();
    assert_eq!(run(), (runs.clone(), 1));
    assert_eq!(
        std::fs::read(&first).unwrap(),
        bytes,
        "same seed, same episode"
    );
    // The ledger: its header and three records.
    let ledger = std::fs::read_to_string(out.path().join(eval::dagger::LEDGER)).unwrap();
    assert_eq!(ledger.lines().count(), 4, "{ledger}");
    // A collection killed mid-line leaves a torn record: it is dropped, the whole ones kept.
    std::fs::write(
        out.path().join(eval::dagger::LEDGER),
        format!("{ledger}{{\"task\": \"libero_mem/t1\", \"epi"),
    )
    .unwrap();
    assert_eq!(run(), (runs.clone(), 0));

    // Another take-over share into the same folder: one error naming the settings file.
    let other = DaggerConfig {
        take_over: (0.2, 0.3),
        ..cfg.clone()
    };
    let err = collect(
        std::slice::from_ref(&task),
        &zero,
        &other,
        out.path(),
        &|_| {},
    )
    .unwrap_err();
    assert!(
        err.to_string().contains(eval::dagger::SETTINGS)
            && err.to_string().contains("take-over share"),
        "{err}"
    );
    assert_eq!(err.exit_code(), 2);

    // The base dataset joins them: one index over both, with the base's split settings.
    let base = tempfile::tempdir().unwrap();
    sim::generate::generate(
        &task,
        base.path(),
        &sim::generate::GenerateConfig {
            episodes: 2,
            val: 1,
            image_size: 32,
            expert: sim::generate::plain_expert(),
            ..Default::default()
        },
        &|_| {},
    )
    .unwrap();
    let index = join_base(out.path(), base.path()).unwrap();
    assert_eq!(index.episodes.len(), 4);
    assert_eq!(index.val_fraction, 0.5);
    let files: Vec<&str> = index.episodes.iter().map(|e| e.file.as_str()).collect();
    assert_eq!(
        files,
        [
            "dagger_libero_mem_t1/episode_00000.mcap",
            "dagger_libero_mem_t1/episode_00001.mcap",
            "episode_00000.mcap",
            "episode_00001.mcap",
        ]
    );
    // Joining again keeps the files and gives the same index.
    assert_eq!(join_base(out.path(), base.path()).unwrap(), index);
}
