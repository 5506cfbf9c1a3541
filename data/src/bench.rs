//! Window throughput benchmark (`data bench` and `cargo bench -p data`): windows/s for given
//! image sizes and worker counts on a synthetic JPEG dataset.

use std::path::Path;
use std::time::Instant;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::episode::{EpisodeWriter, WriterOptions};
use crate::error::{DataError, Result};
use crate::imageio::ImageCompression;
use crate::index::{IndexOptions, Split, build_index};
use crate::synth::{SynthOptions, synthetic_meta, synthetic_steps};
use crate::window::{Augment, WindowConfig, WindowDataset};

/// One benchmark measurement.
#[derive(Clone, Debug)]
pub struct BenchResult {
    /// Window length T.
    pub window: usize,
    /// Output image side.
    pub image_size: u32,
    /// Rayon worker threads.
    pub workers: usize,
    /// Windows produced.
    pub windows: usize,
    /// Windows per second.
    pub windows_per_s: f64,
}

/// Writes `episodes` synthetic episodes of `steps` steps with `source_size`² JPEG frames into
/// `dir` and indexes them.
pub fn make_bench_dataset(
    dir: &Path,
    episodes: usize,
    steps: usize,
    source_size: u32,
) -> Result<()> {
    let opts = WriterOptions {
        image_compression: ImageCompression::Jpeg { quality: 95 },
        ..WriterOptions::default()
    };
    (0..episodes)
        .into_par_iter()
        .try_for_each(|e| -> Result<()> {
            let recs = synthetic_steps(
                steps,
                e as u64,
                &SynthOptions {
                    size: source_size,
                    segmentation: false,
                    depth: false,
                },
            );
            let mut w = EpisodeWriter::create(
                dir.join(format!("bench_{e:03}.mcap")),
                synthetic_meta(e as u64),
                opts.clone(),
            )?;
            for r in &recs {
                w.write_step(r)?;
            }
            w.finish()?;
            Ok(())
        })?;
    build_index(
        dir,
        &IndexOptions {
            val_fraction: 0.0,
            seed: 0,
        },
    )?;
    Ok(())
}

/// Measures windows/s of T-frame windows (p = T−1, q = 0, H_a = 4, augmentation on) for every
/// (image size, workers) pair over `windows` seeded random samples of the dataset in `dir`.
pub fn bench_windows(
    dir: &Path,
    window: usize,
    sizes: &[u32],
    workers: &[usize],
    windows: usize,
) -> Result<Vec<BenchResult>> {
    let mut out = vec![];
    for &size in sizes {
        let cfg = WindowConfig {
            past: window.saturating_sub(1),
            future: 0,
            chunk: 4,
            image_size: size,
            wrist: false,
            images: true,
            augment: Some(Augment::default()),
            seed: 0,
            ..WindowConfig::default()
        };
        let ds = WindowDataset::open(dir, Split::Train, cfg)?;
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let idx: Vec<usize> = (0..windows)
            .map(|_| rng.random_range(0..ds.len()))
            .collect();
        for &w in workers {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(w)
                .build()
                .map_err(|e| DataError::Argument(format!("thread pool: {e}")))?;
            // warm-up (page cache, allocator)
            pool.install(|| ds.get_many(&idx[..idx.len().min(4)]))?;
            let t0 = Instant::now();
            let got = pool.install(|| ds.get_many(&idx))?;
            let dt = t0.elapsed().as_secs_f64();
            out.push(BenchResult {
                window,
                image_size: size,
                workers: w,
                windows: got.len(),
                windows_per_s: got.len() as f64 / dt,
            });
        }
    }
    Ok(out)
}
