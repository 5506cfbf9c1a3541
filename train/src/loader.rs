//! Batches prepared ahead of the optimiser step on a background thread.
//!
//! The loader thread owns a copy of the run's sampler (window or episode sampler, as it stood
//! when the loop started) and draws, reads, augments and batches the next `depth` batches while
//! the step runs; the training loop advances its own sampler (the one saved in checkpoints) in
//! lockstep and checks that both drew the same windows. Reading a window is a function of the
//! draw only (seeded augmentation), so the batches are the ones the loop would have made
//! itself, and a resumed run still ends bit for bit where the uninterrupted one ends.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;
use std::time::Instant;

use burn::prelude::*;

use crate::config::{Sampling, TrainSection};
use crate::dataset::{ChunkSpan, EpisodeSampler, RunData, Sampler};
use crate::error::{Result, TrainError};

/// The samplers of a run, as the checkpoint's state holds them: with an episode sampler it
/// draws the batches, else the window sampler does.
#[derive(Clone, Debug)]
pub struct Draw {
    /// Independent windows.
    pub windows: Sampler,
    /// Consecutive chunks of whole episodes (episode sampling).
    pub episodes: Option<EpisodeSampler>,
}

/// What one batch was drawn from: the (window, epoch) pairs or the episode chunks.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum DrawKey {
    /// Window indices and their epochs.
    Windows(Vec<(usize, u64)>),
    /// Episode chunks.
    Episodes(Vec<ChunkSpan>),
}

/// Draws the next batch of `batch_size` windows (chunks of `window` frames): from `episodes`
/// when the run samples episodes, else from `windows`.
pub fn draw_next(
    episodes: Option<&mut EpisodeSampler>,
    windows: &mut Sampler,
    data: &RunData,
    batch_size: usize,
    window: usize,
) -> DrawKey {
    match episodes {
        Some(e) => {
            DrawKey::Episodes(e.next_batch(batch_size, window, |k| data.train.episode_len(k)))
        }
        None => DrawKey::Windows(windows.next_batch(batch_size)),
    }
}

impl Draw {
    /// The samplers of a new run of `train` over `data`'s training split.
    pub fn new(train: &TrainSection, data: &RunData) -> Self {
        Draw {
            windows: Sampler::new(train.seed, data.train.len()),
            episodes: (train.sampling == Sampling::Episodes).then(|| {
                EpisodeSampler::new(train.seed, data.train.num_episodes(), train.stagger)
                    .with_start_jitter(train.start_jitter)
                    .with_prefix_lanes(train.prefix_lanes, train.prefix_steps)
                    .with_lane_pool(train.lane_pool)
                    .with_memory_reset(train.memory_reset)
            }),
        }
    }

    /// Draws the next batch ([`draw_next`]).
    pub fn next(&mut self, data: &RunData, batch_size: usize, window: usize) -> DrawKey {
        draw_next(
            self.episodes.as_mut(),
            &mut self.windows,
            data,
            batch_size,
            window,
        )
    }
}

/// One data-parallel shard of a batch: a contiguous group of its lanes.
pub struct Shard {
    /// The model batch of these lanes (`[B / N, T, …]`).
    pub batch: model::WindowBatch,
    /// Lanes that start an episode (`[B / N]`), episode sampling only.
    pub fresh: Option<Tensor<1, Bool>>,
}

/// One prepared batch, in `N` shards of consecutive lanes (one shard without data parallelism).
pub struct Prepared {
    /// What it was drawn from.
    pub key: DrawKey,
    /// Whether its idle tails are in the action loss.
    pub idle_tail: bool,
    /// The batch's lanes in `N` groups of `B / N`, in lane order.
    pub shards: Vec<Shard>,
    /// Seconds the loader spent making it.
    pub prepare_s: f64,
}

/// Makes the batch of `key` from the training split on `device`, in `shards` groups of
/// consecutive lanes (`shards` divides the batch size; 1 = the whole batch), the idle tails
/// weighted (`idle_tail`, see [`crate::stages::idle_tail`]) or left out of the action loss.
pub fn prepare(
    data: &RunData,
    key: DrawKey,
    idle_tail: bool,
    shards: usize,
    device: &Device,
) -> Result<Prepared> {
    let started = Instant::now();
    let shards = shards.max(1);
    let parts = match &key {
        DrawKey::Windows(indices) => indices
            .chunks(indices.len().div_ceil(shards).max(1))
            .map(|part| {
                Ok(Shard {
                    batch: data.batch_with(&data.train, part, idle_tail, device)?,
                    fresh: None,
                })
            })
            .collect::<Result<Vec<_>>>()?,
        DrawKey::Episodes(spans) => spans
            .chunks(spans.len().div_ceil(shards).max(1))
            .map(|part| {
                let (batch, fresh) = data.chunk_batch_with(part, idle_tail, device)?;
                Ok(Shard {
                    batch,
                    fresh: Some(fresh),
                })
            })
            .collect::<Result<Vec<_>>>()?,
    };
    Ok(Prepared {
        key,
        idle_tail,
        shards: parts,
        prepare_s: started.elapsed().as_secs_f64(),
    })
}

/// A background thread that keeps up to `depth` prepared batches ready.
pub struct Prefetcher {
    rx: Option<Receiver<Result<Prepared>>>,
    handle: Option<JoinHandle<()>>,
}

impl Prefetcher {
    /// Starts preparing the batches of steps `steps` (0-based steps done before each) drawn by
    /// `draw` (a copy of the loop's sampler), each in `shards` lane groups, their idle tails
    /// as `stages` say.
    #[allow(clippy::too_many_arguments)]
    pub fn spawn(
        data: Arc<RunData>,
        mut draw: Draw,
        batch_size: usize,
        window: usize,
        shards: usize,
        steps: std::ops::Range<u64>,
        stages: Vec<crate::stages::Stage>,
        depth: usize,
        device: Device,
    ) -> Self {
        let (tx, rx): (SyncSender<Result<Prepared>>, _) = sync_channel(depth.max(1));
        let handle = std::thread::Builder::new()
            .name("train-loader".into())
            .spawn(move || {
                for step in steps {
                    let key = draw.next(&data, batch_size, window);
                    let tail = crate::stages::idle_tail(&stages, step);
                    let item = prepare(&data, key, tail, shards, &device);
                    let failed = item.is_err();
                    // The receiver is gone when the loop stopped early (an error, stop_at).
                    if tx.send(item).is_err() || failed {
                        return;
                    }
                }
            })
            .expect("spawn the loader thread");
        Prefetcher {
            rx: Some(rx),
            handle: Some(handle),
        }
    }

    /// The next prepared batch; waits while the loader is still making it.
    pub fn next(&self) -> Result<Prepared> {
        self.rx
            .as_ref()
            .and_then(|rx| rx.recv().ok())
            .unwrap_or_else(|| {
                Err(TrainError::Other(
                    "the data loader thread stopped before the last step".into(),
                ))
            })
    }
}

impl Drop for Prefetcher {
    fn drop(&mut self) {
        // Hang up first so that a loader blocked on a full channel returns, then wait for it.
        drop(self.rx.take());
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}
