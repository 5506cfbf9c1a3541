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
    // Bad arguments.
    let e = generate(&task, a.path(), &GenerateConfig { val: 3, ..cfg }, &|_| {}).unwrap_err();
    assert!(e.to_string().contains("val < episodes"), "{e}");
}
