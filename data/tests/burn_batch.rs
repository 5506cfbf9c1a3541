//! Burn adapters (run with `--features burn`).
#![cfg(feature = "burn")]

use burn::data::dataloader::batcher::Batcher;
use burn::data::dataset::Dataset;
use burn::tensor::Device;
use data::burn_adapter::WindowBatcher;
use data::synth::{SynthOptions, synthetic_meta, synthetic_steps};
use data::*;

#[test]
fn batch_has_documented_shapes_and_values() {
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
    let batcher = WindowBatcher::new(index.vocab(), 10, 3);
    let dev = Device::flex();
    let b = batcher.batch(items.clone(), &dev);
    assert_eq!(b.images.dims(), [3, 4, 3, 8, 8]);
    assert_eq!(b.actions.dims(), [3, 4, 3, 7]);
    assert_eq!(b.action_mask.dims(), [3, 4, 3]);
    assert_eq!(b.frame_mask.dims(), [3, 4]);
    assert_eq!(b.states.dims(), [3, 4, 8]);
    assert_eq!(b.instruction_ids.dims(), [3, 10]);
    assert_eq!(b.subgoal_ids.dims(), [3, 4, 10]);
    assert_eq!(b.boxes.dims(), [3, 4, 3, 4]);
    assert_eq!(b.object_mask.dims(), [3, 4, 3]);
    let acts = b.actions.into_data().try_to_vec::<f32>().unwrap();
    let want: Vec<f32> = items
        .iter()
        .flat_map(|s| s.actions.iter().copied())
        .collect();
    assert_eq!(acts, want);
    let fm = b.frame_mask.into_data().try_to_vec::<bool>().unwrap();
    assert_eq!(&fm[..4], &[false, false, true, true]);
}
