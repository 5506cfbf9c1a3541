//! Burn adapters (run with `--features burn`).
#![cfg(feature = "burn")]

use burn::data::dataset::Dataset;
use data::synth::{SynthOptions, synthetic_meta, synthetic_steps};
use data::*;

#[test]
fn window_dataset_is_a_burn_dataset() {
    let dir = tempfile::tempdir().unwrap();
    for e in 0..2u64 {
        let steps = synthetic_steps(
            6,
            e,
            &SynthOptions {
                size: 16,
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
    let index = build_index(
        dir.path(),
        &IndexOptions {
            val_fraction: 0.0,
            seed: 0,
        },
    )
    .unwrap();
    let cfg = WindowConfig {
        past: 2,
        future: 1,
        chunk: 3,
        image_size: 8,
        ..Default::default()
    };
    let ds = WindowDataset::open(dir.path(), Split::Train, cfg).unwrap();
    assert_eq!(Dataset::len(&ds), 12);
    let items: Vec<WindowSample> = (0..3).map(|i| Dataset::get(&ds, i).unwrap()).collect();
    assert_eq!(items[2], ds.get(2).unwrap());
    assert_eq!(index.episodes.len(), 2);
    assert!(Dataset::get(&ds, 12).is_err());
}
