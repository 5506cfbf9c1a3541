//! `sim generate`: expert episodes on disk, resumable, byte-identical for the same seed.

use sim::generate::{GenerateConfig, episode_path, generate};
use sim::task::registry;

#[test]
fn generates_resumes_and_repeats_byte_for_byte() {
    let task = registry::resolve("t1").unwrap();
    let cfg = GenerateConfig {
        episodes: 3,
        val: 1,
        seed: 7,
        workers: 2,
        image_size: 32,
        ..GenerateConfig::default()
    };
    let a = tempfile::tempdir().unwrap();
    let index = generate(&task, a.path(), &cfg, &|_| {}).unwrap();
    assert_eq!(index.episodes.len(), 3);
    let reader = data::EpisodeReader::open(episode_path(a.path(), 0)).unwrap();
    assert_eq!(reader.meta().task_id, "libero_mem/t1");
    let last = reader.read_step(reader.len() - 1).unwrap();
    assert_eq!(
        last.progress.satisfied, 1,
        "the recorded demonstration completes the goal"
    );
    // Resume: delete one episode, rerun; the others are kept, the missing one comes back identical.
    let bytes1 = std::fs::read(episode_path(a.path(), 1)).unwrap();
    std::fs::remove_file(episode_path(a.path(), 1)).unwrap();
    generate(
        &task,
        a.path(),
        &GenerateConfig {
            workers: 1,
            ..cfg.clone()
        },
        &|_| {},
    )
    .unwrap();
    assert_eq!(std::fs::read(episode_path(a.path(), 1)).unwrap(), bytes1);
    // A fresh directory with the same seed gives the same files.
    let b = tempfile::tempdir().unwrap();
    generate(&task, b.path(), &cfg, &|_| {}).unwrap();
    for k in 0..3 {
        assert_eq!(
            std::fs::read(episode_path(a.path(), k)).unwrap(),
            std::fs::read(episode_path(b.path(), k)).unwrap()
        );
    }
    assert!(
        std::fs::read_dir(a.path()).unwrap().all(|e| !e
            .unwrap()
            .file_name()
            .to_string_lossy()
            .ends_with(".tmp"))
    );
    // A killed run's temporary file is removed by the next run.
    let stale = a.path().join(".episode-killed.mcap.tmp");
    std::fs::write(&stale, b"partial").unwrap();
    generate(&task, a.path(), &cfg, &|_| {}).unwrap();
    assert!(!stale.exists());
    // Another seed into the same directory: refused, naming what differs, nothing touched.
    let other = GenerateConfig {
        seed: 5,
        ..cfg.clone()
    };
    let e = generate(&task, a.path(), &other, &|_| {}).unwrap_err();
    assert!(matches!(e, sim::generate::GenerateError::Argument(_)));
    let m = e.to_string();
    assert!(m.contains("seed 7 → 5") && m.contains("--force"), "{m}");
    assert_eq!(std::fs::read(episode_path(a.path(), 1)).unwrap(), bytes1);
    // The same from a directory written before generation.json: its first episode tells.
    std::fs::remove_file(a.path().join(sim::generate::GENERATION_JSON)).unwrap();
    let m = generate(&task, a.path(), &other, &|_| {})
        .unwrap_err()
        .to_string();
    assert!(
        m.contains("episode 0's seed") && m.contains("seed 5"),
        "{m}"
    );
    // --force replaces the episodes: the directory equals a fresh seed-5 one.
    let forced = GenerateConfig {
        force: true,
        ..other.clone()
    };
    generate(&task, a.path(), &forced, &|_| {}).unwrap();
    let c = tempfile::tempdir().unwrap();
    generate(&task, c.path(), &other, &|_| {}).unwrap();
    for k in 0..3 {
        assert_eq!(
            std::fs::read(episode_path(a.path(), k)).unwrap(),
            std::fs::read(episode_path(c.path(), k)).unwrap()
        );
    }
    // More episodes with the same parameters is fine (episode k does not depend on the total).
    let more = GenerateConfig {
        episodes: 4,
        ..other
    };
    assert_eq!(
        generate(&task, c.path(), &more, &|_| {})
            .unwrap()
            .episodes
            .len(),
        4
    );
    // A record from before the branch rule existed reads as the destination rule; asking for the
    // gripper rule in that directory is refused, naming the difference.
    let rec = c.path().join(sim::generate::GENERATION_JSON);
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&rec).unwrap()).unwrap();
    assert_eq!(json["branch_rule"], "destination");
    json.as_object_mut().unwrap().remove("branch_rule");
    std::fs::write(&rec, json.to_string()).unwrap();
    generate(&task, c.path(), &more, &|_| {}).unwrap();
    let gripper = GenerateConfig {
        expert: sim::expert::ExpertConfig {
            branch_rule: sim::expert::BranchRule::Gripper,
            ..more.expert.clone()
        },
        ..more.clone()
    };
    let m = generate(&task, c.path(), &gripper, &|_| {})
        .unwrap_err()
        .to_string();
    assert!(
        m.contains("branch_rule \"destination\" → \"gripper\""),
        "{m}"
    );
    // Bad arguments.
    let e = generate(&task, a.path(), &GenerateConfig { val: 3, ..cfg }, &|_| {}).unwrap_err();
    assert!(e.to_string().contains("val < episodes"), "{e}");
}

#[test]
fn hold_steps_record_the_expert_standing_still_after_the_goal() {
    let task = registry::resolve("t1").unwrap();
    let cfg = |hold: Option<usize>| GenerateConfig {
        episodes: 2,
        val: 1,
        seed: 3,
        workers: 1,
        image_size: 32,
        expert: sim::generate::expert_config(false, hold),
        ..GenerateConfig::default()
    };
    let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    generate(&task, a.path(), &cfg(None), &|_| {}).unwrap();
    generate(&task, b.path(), &cfg(Some(30)), &|_| {}).unwrap();
    let short = data::EpisodeReader::open(episode_path(a.path(), 0)).unwrap();
    let long = data::EpisodeReader::open(episode_path(b.path(), 0)).unwrap();
    let first_done = |r: &data::EpisodeReader| {
        (0..r.len())
            .find(|&t| {
                let p = r.read_step(t).unwrap().progress;
                p.satisfied == p.total
            })
            .expect("the demonstration completes the goal")
    };
    let done = first_done(&long);
    assert_eq!(
        first_done(&short),
        done,
        "same demonstration up to the goal"
    );
    // The default stops recording 10 steps after the goal; a 30-step hold is recorded to its
    // end, after the release and the retreat.
    assert_eq!(short.len(), done + 11);
    assert!(long.len() > done + 31, "{} vs {done}", long.len());
    for t in 0..short.len() - 1 {
        assert_eq!(
            short.read_step(t).unwrap().action,
            long.read_step(t).unwrap().action,
            "step {t}"
        );
    }
    // The last 30 steps: the arm still, the gripper open, the goal kept.
    let idle = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0];
    for t in long.len() - 30..long.len() {
        let s = long.read_step(t).unwrap();
        assert_eq!(s.action, idle, "step {t}");
        assert_eq!(s.progress.satisfied, s.progress.total, "step {t}");
    }
}

#[test]
fn shards_together_record_what_one_run_records() {
    use data::shard::Shard;
    let task = registry::resolve("t1").unwrap();
    let cfg = GenerateConfig {
        episodes: 3,
        val: 1,
        seed: 11,
        image_size: 32,
        ..GenerateConfig::default()
    };
    let whole = tempfile::tempdir().unwrap();
    generate(&task, whole.path(), &cfg, &|_| {}).unwrap();
    let sharded = tempfile::tempdir().unwrap();
    // Another process's temporary file: a shard must leave it alone.
    let busy = sharded.path().join(".episode-other-shard.mcap.tmp");
    std::fs::create_dir_all(sharded.path()).unwrap();
    std::fs::write(&busy, b"being written").unwrap();
    for (index, owned) in [(1, 1), (0, 2)] {
        let shard = Shard::new(index, 2).unwrap();
        let n = sim::generate::generate_episodes(
            &task,
            sharded.path(),
            &GenerateConfig {
                shard,
                ..cfg.clone()
            },
            &|_| {},
        )
        .unwrap();
        assert_eq!(n, owned);
        assert!(busy.exists(), "shard {shard} removed another's temporary");
    }
    assert!(
        !sharded.path().join(data::index::INDEX_FILE).exists(),
        "a shard writes no index"
    );
    let refused = generate(
        &task,
        sharded.path(),
        &GenerateConfig {
            shard: Shard::new(0, 2).unwrap(),
            ..cfg.clone()
        },
        &|_| {},
    )
    .unwrap_err();
    assert!(refused.to_string().contains("writes no index"), "{refused}");
    // The unsharded pass finds every episode, records none, writes the index, cleans up.
    let index = generate(&task, sharded.path(), &cfg, &|_| {}).unwrap();
    assert_eq!(index.episodes.len(), 3);
    assert!(!busy.exists());
    for name in [
        "episode_00000.mcap",
        "episode_00001.mcap",
        "episode_00002.mcap",
        "index.json",
    ] {
        assert_eq!(
            std::fs::read(whole.path().join(name)).unwrap(),
            std::fs::read(sharded.path().join(name)).unwrap(),
            "{name}"
        );
    }
}

#[test]
fn videos_beside_the_episodes_change_no_episode() {
    let task = registry::resolve("t1").unwrap();
    let cfg = GenerateConfig {
        episodes: 2,
        val: 1,
        seed: 3,
        workers: 1,
        image_size: 32,
        ..GenerateConfig::default()
    };
    let (a, b, c) = (
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
        tempfile::tempdir().unwrap(),
    );
    let with = GenerateConfig {
        video: true,
        ..cfg.clone()
    };
    let index = generate(&task, a.path(), &with, &|_| {}).unwrap();
    generate(&task, b.path(), &cfg, &|_| {}).unwrap();
    generate(&task, c.path(), &with, &|_| {}).unwrap();
    // A leftover of a killed writer is cleaned up by the next run.
    std::fs::write(a.path().join(".video-x.mp4.tmp"), b"half").unwrap();
    generate(&task, a.path(), &with, &|_| {}).unwrap();
    assert!(!a.path().join(".video-x.mp4.tmp").exists());
    for (k, e) in index.episodes.iter().enumerate() {
        let mcap = episode_path(a.path(), k);
        assert_eq!(
            std::fs::read(&mcap).unwrap(),
            std::fs::read(episode_path(b.path(), k)).unwrap(),
            "the same episode with or without its video"
        );
        let mp4 = sim::generate::video_path(&mcap);
        let bytes = std::fs::read(&mp4).unwrap();
        assert_eq!(
            bytes,
            std::fs::read(sim::generate::video_path(&episode_path(c.path(), k))).unwrap(),
            "videos repeat byte for byte"
        );
        let size = bytes.len() as u64;
        let r = mp4::Mp4Reader::read_header(std::io::Cursor::new(bytes), size).unwrap();
        // A frame per recorded step and the last observation; 2·32 × (32 + 24).
        assert_eq!(r.sample_count(1).unwrap() as usize, e.length + 1);
        let t = &r.tracks()[&1];
        assert_eq!((t.width(), t.height()), (64, 56));
    }
    assert!(!episode_path(b.path(), 0).with_extension("mp4").exists());
}
