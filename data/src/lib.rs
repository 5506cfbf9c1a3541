//! Episodes on disk for LIBERO-Mem research: the episode schema and its mcap I/O, the dataset
//! index with action/state statistics, RLDS (TFRecord) import, and windowed training samples
//! (with Burn `Dataset`/`Batcher` adapters behind the `burn` feature).

#![warn(missing_docs)]

pub mod bench;
pub mod episode;
pub mod error;
pub mod example;
pub mod imageio;
pub mod index;
pub mod rlds;
pub mod schema;
pub mod synth;
pub mod text;
pub mod tfrecord;
pub mod window;

pub use episode::{EncodedImage, EpisodeReader, EpisodeWriter, RawStep, WriterOptions};
pub use error::{DataError, Result};
pub use imageio::{Flip, ImageCompression};
pub use index::{DatasetIndex, EpisodeEntry, IndexOptions, Split, build_index};
pub use schema::*;
pub use text::Vocab;
pub use window::{ActionNorm, Augment, WindowConfig, WindowDataset, WindowSample};

/// Burn `Dataset`/`Batcher` adapters (feature `burn`).
#[cfg(feature = "burn")]
pub mod burn_adapter;
