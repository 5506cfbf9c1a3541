//! Dataset index: statistics as numpy/OpenVLA compute them, split, determinism.

use data::index::{ArrayStats, quantile_sorted};
use data::synth::{SynthOptions, synthetic_meta, synthetic_steps};
use data::*;

#[test]
fn quantiles_match_numpy_linear() {
    // numpy.quantile([1, 2, 3, 4], 0.01) = 1.03; 0.99 → 3.97
    let v = [1.0, 2.0, 3.0, 4.0];
    assert!((quantile_sorted(&v, 0.01) - 1.03).abs() < 1e-12);
    assert!((quantile_sorted(&v, 0.99) - 3.97).abs() < 1e-12);
    assert_eq!(quantile_sorted(&[5.0], 0.99), 5.0);
    let rows: Vec<[f32; 2]> = (0..101).map(|i| [i as f32, -(i as f32)]).collect();
    let s = ArrayStats::compute(&rows, [true, false]);
    assert_eq!(s.q01, vec![1.0, -99.0]);
    assert_eq!(s.q99, vec![99.0, -1.0]);
    assert_eq!(s.mean, vec![50.0, -50.0]);
    assert_eq!(s.min, vec![0.0, -100.0]);
    // population std of 0..=100 = sqrt(850)
    assert!((s.std[0] - 850f32.sqrt()).abs() < 1e-4);
}

#[test]
fn index_build_is_deterministic_and_splits() {
    let dir = tempfile::tempdir().unwrap();
    for e in 0..6u64 {
        let steps = synthetic_steps(
            10 + e as usize,
            e,
            &SynthOptions {
                size: 8,
                segmentation: false,
                depth: false,
            },
        );
        let mut w = EpisodeWriter::create(
            dir.path().join(format!("ep{e}.mcap")),
            synthetic_meta(e),
            WriterOptions::default(),
        )
        .unwrap();
        for s in &steps {
            w.write_step(s).unwrap();
        }
        w.finish().unwrap();
    }
    let opts = IndexOptions {
        val_fraction: 0.34,
        seed: 3,
    };
    let a = build_index(dir.path(), &opts).unwrap();
    let text_a = std::fs::read(dir.path().join("index.json")).unwrap();
    let b = build_index(dir.path(), &opts).unwrap();
    assert_eq!(a, b);
    assert_eq!(
        text_a,
        std::fs::read(dir.path().join("index.json")).unwrap()
    );
    assert_eq!(DatasetIndex::load(dir.path()).unwrap(), a);
    assert_eq!(a.split(Split::Val).len(), 2);
    assert_eq!(a.split(Split::Train).len(), 4);
    let train_steps: usize = a.split(Split::Train).iter().map(|(_, e)| e.length).sum();
    assert_eq!(a.stats.num_transitions, train_steps);
    assert_eq!(
        a.episodes.iter().map(|e| e.length).collect::<Vec<_>>(),
        vec![10, 11, 12, 13, 14, 15]
    );
    let v = a.vocab();
    assert_eq!(&v.words()[..2], &["<pad>".to_string(), "<unk>".to_string()]);
    let (ids, mask) = v.encode("Put the bowl on the zebra", 8);
    assert_eq!(ids[5], data::text::UNK);
    assert_eq!(mask, vec![true, true, true, true, true, true, false, false]);
    assert_eq!(v.words()[ids[0] as usize], "put");
}

/// A suite dataset: one subfolder per task, one index over all of them (paths relative, `/`).
#[test]
fn suite_index_covers_subfolders_with_relative_paths() {
    let dir = tempfile::tempdir().unwrap();
    for (task, n) in [("libero_mem_t1", 2usize), ("libero_mem_t3", 3)] {
        let sub = dir.path().join(task);
        data::synth::write_synthetic_dataset(&sub, n, 6, 8).unwrap();
    }
    let index = build_index(
        dir.path(),
        &IndexOptions {
            val_fraction: 0.2,
            seed: 0,
        },
    )
    .unwrap();
    let files: Vec<&str> = index.episodes.iter().map(|e| e.file.as_str()).collect();
    assert_eq!(files.len(), 5);
    assert!(
        files[..2].iter().all(|f| f.starts_with("libero_mem_t1/")),
        "{files:?}"
    );
    assert!(
        files[2..].iter().all(|f| f.starts_with("libero_mem_t3/")),
        "{files:?}"
    );
    // Every entry opens relative to the suite folder, and the windows read them.
    for f in &files {
        EpisodeReader::open(dir.path().join(f)).unwrap();
    }
    let ds = WindowDataset::open(
        dir.path(),
        Split::Train,
        WindowConfig {
            image_size: 8,
            ..Default::default()
        },
    )
    .unwrap();
    assert!(ds.num_episodes() >= 3);
}

#[test]
fn episodes_are_checked_against_the_index_when_opened() {
    let dir = tempfile::tempdir().unwrap();
    let opts = SynthOptions {
        size: 8,
        segmentation: false,
        depth: false,
    };
    let path = dir.path().join("ep0.mcap");
    let mut w = EpisodeWriter::create(&path, synthetic_meta(0), WriterOptions::default()).unwrap();
    for s in &synthetic_steps(12, 0, &opts) {
        w.write_step(s).unwrap();
    }
    w.finish().unwrap();
    let idx = build_index(dir.path(), &IndexOptions::default()).unwrap();
    let e = &idx.episodes[0];
    let good = std::fs::read(&path).unwrap();
    assert_eq!(e.bytes, Some(good.len() as u64));
    assert_eq!(e.crc32, Some(crc32fast::hash(&good)));
    assert_eq!(e.open(dir.path()).unwrap().len(), 12);
    let err = |bytes: &[u8]| {
        std::fs::write(&path, bytes).unwrap();
        let e = e.open(dir.path()).unwrap_err();
        assert_eq!(e.exit_code(), 2, "{e}");
        e.to_string()
    };
    // One flipped bit anywhere (here in the header record, which the readers never revisit).
    let mut flipped = good.clone();
    flipped[20] ^= 0x01;
    let m = err(&flipped);
    assert!(
        m.contains("ep0.mcap") && m.contains("the file is corrupt"),
        "{m}"
    );
    assert!(
        m.contains(&format!("index.json says {:08x}", crc32fast::hash(&good))),
        "{m}"
    );
    // Truncated.
    let m = err(&good[..good.len() - 10]);
    assert!(
        m.contains(&format!(
            "{} bytes, index.json says {}",
            good.len() - 10,
            good.len()
        )),
        "{m}"
    );
    // An index written before the checks: size and CRC are not known, the structure still is.
    let mut legacy = e.clone();
    (legacy.bytes, legacy.crc32) = (None, None);
    std::fs::write(&path, &flipped[..flipped.len() - 10]).unwrap();
    assert!(legacy.open(dir.path()).is_err());
    std::fs::write(&path, &good).unwrap();
    assert!(legacy.open(dir.path()).is_ok());
}
