//! Episodes on disk for LIBERO-Mem research: the episode schema and its mcap I/O, the dataset
//! index with action/state statistics, RLDS (TFRecord) import, and windowed training samples
//! (with Burn `Dataset`/`Batcher` adapters behind the `burn` feature).
//!
//! Recording and reading an episode (the file format is described in `data/SCHEMA.md`):
//!
//! ```
//! use data::{EpisodeMeta, EpisodeReader, EpisodeWriter, GoalProgress, Image, StepRecord, WriterOptions};
//!
//! let dir = tempfile::tempdir().unwrap();
//! let meta = EpisodeMeta { task_id: "libero_mem/t1".into(), instruction: "put the bowl on the plate".into(), ..Default::default() };
//! let mut w = EpisodeWriter::create(dir.path().join("ep.mcap"), meta, WriterOptions::default()).unwrap();
//! for k in 0..3u64 {
//!     let rgb = Image::new(4, 2, 3, vec![k as u8; 4 * 2 * 3]).unwrap(); // [H=2, W=4, 3], upright
//!     w.write_step(&StepRecord {
//!         step: k,
//!         agentview: rgb.clone(),
//!         eye_in_hand: rgb,
//!         segmentation: None,
//!         depth: None,
//!         state: [0.0; 8],
//!         joint_state: [0.0; 7],
//!         action: [0.0, 0.0, 0.1, 0.0, 0.0, 0.0, -1.0],
//!         objects: vec![],
//!         progress: GoalProgress::default(),
//!     })
//!     .unwrap();
//! }
//! let path = w.finish().unwrap();
//! let r = EpisodeReader::open(&path).unwrap();
//! assert_eq!(r.len(), 3);
//! assert_eq!(r.read_step(2).unwrap().agentview.data[0], 2);
//! ```

#![warn(missing_docs)]

pub mod alloc;
pub mod bench;
pub mod draw;
pub mod episode;
pub mod error;
pub mod example;
pub mod exit;
pub mod fsio;
pub mod imageio;
pub mod index;
pub mod lerobot;
pub mod pool;
pub mod procs;
pub mod rlds;
pub mod schema;
pub mod shard;
pub mod synth;
pub mod text;
pub mod tfrecord;
pub mod video;
pub mod window;

pub use episode::{EncodedImage, EpisodeReader, EpisodeWriter, RawStep, WriterOptions};
pub use error::{DataError, Result};
pub use imageio::{Flip, ImageCompression};
pub use index::{DatasetIndex, EpisodeEntry, IndexOptions, Split, build_index};
pub use schema::*;
pub use text::Vocab;
pub use window::{ActionNorm, Augment, OpenedDataset, WindowConfig, WindowDataset, WindowSample};

/// Burn `Dataset`/`Batcher` adapters (feature `burn`).
#[cfg(feature = "burn")]
pub mod burn_adapter;
