//! `data`: inspect episodes, (re)build dataset indexes, import RLDS, benchmark windows.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};
use data::rlds::{ConvertOptions, FlipChoice};
use data::{DataError, EpisodeReader, Flip, ImageCompression, IndexOptions, WriterOptions};

#[derive(Parser)]
#[command(
    name = "data",
    version,
    about = "Episodes on disk: inspect, index, import, bench"
)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Clone, Copy, ValueEnum)]
enum FlipArg {
    /// From the dataset name (libero_mem: none; other libero: hflip).
    Auto,
    None,
    Hflip,
    Vflip,
    Rot180,
}

#[derive(Subcommand)]
enum Cmd {
    /// (Re)build DIR/index.json: episode list, lengths, split, action/state statistics.
    Stats {
        /// Dataset directory with *.mcap episodes.
        dir: PathBuf,
        /// Fraction of episodes in the validation split.
        #[arg(long, default_value_t = 0.05)]
        val_fraction: f64,
        /// Seed of the split.
        #[arg(long, default_value_t = 0)]
        seed: u64,
    },
    /// Check every episode of a dataset as training opens them (size and CRC-32 against
    /// index.json, mcap structure, step count) and print what it cost.
    Verify {
        /// Dataset directory (with index.json).
        dir: PathBuf,
        /// Also decompress every chunk and check every message (CRCs, schemas), as `inspect --verify`.
        #[arg(long)]
        chunks: bool,
    },
    /// Print a human summary of one episode file.
    Inspect {
        /// Episode file.
        file: PathBuf,
        /// Also verify every chunk (CRC, schema of every message).
        #[arg(long)]
        verify: bool,
    },
    /// Convert TFDS/RLDS TFRecord shards (OpenVLA LIBERO layout) into a dataset directory.
    ConvertRlds {
        /// Directory holding the shards (searched 3 levels deep).
        #[arg(long)]
        src: PathBuf,
        /// Output dataset directory.
        #[arg(long)]
        out: PathBuf,
        /// Transform that makes the stored images upright.
        #[arg(long, value_enum, default_value_t = FlipArg::Auto)]
        flip: FlipArg,
        /// Store frames as PNG (lossless re-encode; files ~6x larger) instead of JPEG.
        #[arg(long)]
        png: bool,
        /// JPEG quality when not --png.
        #[arg(long, default_value_t = 95)]
        jpeg_quality: u8,
        /// Fraction of episodes in the validation split.
        #[arg(long, default_value_t = 0.05)]
        val_fraction: f64,
        /// Worker threads (default: all cores).
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Write synthetic episodes (seeded; for checks such as the reference-reader validation).
    Synth {
        /// Output directory.
        #[arg(long)]
        out: PathBuf,
        /// Number of episodes (even ones: PNG with segmentation and depth; odd ones: JPEG without).
        #[arg(long, default_value_t = 2)]
        episodes: usize,
        /// Steps per episode.
        #[arg(long, default_value_t = 30)]
        steps: usize,
        /// Image side.
        #[arg(long, default_value_t = 64)]
        size: u32,
    },
    /// Export dataset DIR (its index.json) as a LeRobotDataset v3.0 directory OUT (new; parquet
    /// tables, H.264 videos; what `lerobot`'s `LeRobotDataset(repo_id, root=OUT)` loads).
    ExportLerobot {
        /// Dataset directory (with index.json).
        dir: PathBuf,
        /// Output directory (must not exist).
        #[arg(long)]
        out: PathBuf,
        /// Transform applied to our upright frames (hflip: LeRobot's and openpi's LIBERO layout).
        #[arg(long, value_enum, default_value_t = FlipArg::Hflip)]
        flip: FlipArg,
        /// A key frame every N frames (and at every episode start).
        #[arg(long, default_value_t = 20)]
        keyframe_every: u32,
    },
    /// Import a LeRobotDataset v3.0 directory ROOT (LIBERO keys: observation.images.image,
    /// observation.images.wrist_image, observation.state, action) as mcap episodes in OUT.
    ImportLerobot {
        /// LeRobot dataset root (with meta/info.json).
        root: PathBuf,
        /// Output dataset directory.
        #[arg(long)]
        out: PathBuf,
        /// Transform that makes the stored images upright (auto: ours as exported, else hflip).
        #[arg(long, value_enum, default_value_t = FlipArg::Auto)]
        flip: FlipArg,
        /// Fraction of episodes in the validation split.
        #[arg(long, default_value_t = 0.05)]
        val_fraction: f64,
        /// The ffmpeg program that decodes the videos.
        #[arg(long, default_value = "ffmpeg")]
        ffmpeg: PathBuf,
    },
    /// Print windows/s for T-frame windows at the given sizes and worker counts.
    Bench {
        /// Window length T.
        #[arg(long, default_value_t = 16)]
        window: usize,
        /// Output image sizes.
        #[arg(long, value_delimiter = ',', default_value = "64,128")]
        sizes: Vec<u32>,
        /// Worker counts.
        #[arg(long, value_delimiter = ',', default_value = "1,2")]
        workers: Vec<usize>,
        /// Windows per measurement.
        #[arg(long, default_value_t = 128)]
        windows: usize,
        /// Use this dataset directory instead of a synthetic one (128² JPEG, 4 × 80 steps).
        #[arg(long)]
        dir: Option<PathBuf>,
    },
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.cmd {
        Cmd::Stats {
            dir,
            val_fraction,
            seed,
        } => {
            let idx = data::build_index(&dir, &IndexOptions { val_fraction, seed })?;
            let train = idx.split(data::Split::Train).len();
            data::outln!(
                "{}: {} episodes ({} train, {} val), {} train steps, vocabulary {} words",
                dir.join(data::index::INDEX_FILE).display(),
                idx.episodes.len(),
                train,
                idx.episodes.len() - train,
                idx.stats.num_transitions,
                idx.vocab.len()
            );
            let a = &idx.stats.action;
            for d in 0..7 {
                data::outln!(
                    "  action[{d}] mean {:+.4} std {:.4} q01 {:+.4} q99 {:+.4} {}",
                    a.mean[d],
                    a.std[d],
                    a.q01[d],
                    a.q99[d],
                    if a.mask[d] { "" } else { "(not normalised)" }
                );
            }
        }
        Cmd::Verify { dir, chunks } => {
            let idx = data::DatasetIndex::load(&dir)?;
            let (mut read_s, mut check_s, mut chunk_s, mut bytes) = (0.0, 0.0, 0.0, 0u64);
            for e in &idx.episodes {
                let t = std::time::Instant::now();
                let (path, b) = e.read(&dir)?;
                read_s += t.elapsed().as_secs_f64();
                bytes += b.len() as u64;
                let t = std::time::Instant::now();
                let r = e.check_bytes(path, b)?;
                check_s += t.elapsed().as_secs_f64();
                if chunks {
                    let t = std::time::Instant::now();
                    r.verify()?;
                    chunk_s += t.elapsed().as_secs_f64();
                }
            }
            let gb = bytes as f64 / 1e9;
            let legacy = idx.episodes.iter().filter(|e| e.crc32.is_none()).count();
            data::outln!(
                "{}: {} episodes, {:.3} GB verified; reading {:.0} ms, checking (size, CRC-32, mcap \
                 structure, length) {:.0} ms = {:.0} ms/GB on one thread{}",
                dir.display(),
                idx.episodes.len(),
                gb,
                read_s * 1e3,
                check_s * 1e3,
                check_s * 1e3 / gb.max(1e-9),
                if chunks {
                    format!(
                        ", every chunk decompressed and checked {:.0} ms = {:.0} ms/GB",
                        chunk_s * 1e3,
                        chunk_s * 1e3 / gb.max(1e-9)
                    )
                } else {
                    String::new()
                }
            );
            if legacy > 0 {
                data::outln!(
                    "  {legacy} episodes have no size and CRC-32 in index.json (written before the checks; \
                     `data stats` records them)"
                );
            }
        }
        Cmd::Inspect { file, verify } => {
            let r = EpisodeReader::open(&file)?;
            if verify {
                r.verify()?;
            }
            let m = r.meta();
            data::outln!("{}", file.display());
            data::outln!(
                "  size        {} bytes, {} chunks{}",
                r.file_size(),
                r.chunk_count(),
                if verify { ", verified" } else { "" }
            );
            data::outln!(
                "  steps       {} ({:.2} s at {} Hz)",
                r.len(),
                r.duration_s(),
                m.fps
            );
            data::outln!("  task        {}", m.task_id);
            data::outln!("  instruction {}", m.instruction);
            data::outln!("  seed        {}", m.seed);
            data::outln!(
                "  simulator   {} / assets {}",
                m.sim_version,
                m.asset_version
            );
            data::outln!("  orientation {}", m.image_orientation);
            data::outln!("  bddl        {} bytes", m.bddl.len());
            for (k, v) in &m.extra {
                data::outln!("  extra.{k} = {v}");
            }
            data::outln!("  channels:");
            for c in r.channels() {
                data::outln!(
                    "    {:<26} {:<26} {:<9} {:>6} msgs",
                    c.topic,
                    c.schema,
                    c.encoding,
                    c.count
                );
            }
            if !r.is_empty() {
                let s = r.read_step(0)?;
                data::outln!(
                    "  agentview {}x{}, eye-in-hand {}x{}, {} objects at step 0",
                    s.agentview.width,
                    s.agentview.height,
                    s.eye_in_hand.width,
                    s.eye_in_hand.height,
                    s.objects.len()
                );
            }
        }
        Cmd::ConvertRlds {
            src,
            out,
            flip,
            png,
            jpeg_quality,
            val_fraction,
            threads,
        } => {
            if let Some(n) = threads {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(n)
                    .build_global()
                    .context("thread pool")?;
            }
            let opts = ConvertOptions {
                flip: match flip {
                    FlipArg::Auto => FlipChoice::Auto,
                    FlipArg::None => FlipChoice::Fixed(Flip::None),
                    FlipArg::Hflip => FlipChoice::Fixed(Flip::Horizontal),
                    FlipArg::Vflip => FlipChoice::Fixed(Flip::Vertical),
                    FlipArg::Rot180 => FlipChoice::Fixed(Flip::Rotate180),
                },
                writer: WriterOptions {
                    image_compression: if png {
                        ImageCompression::Png
                    } else {
                        ImageCompression::Jpeg {
                            quality: jpeg_quality,
                        }
                    },
                    ..WriterOptions::default()
                },
                index: IndexOptions {
                    val_fraction,
                    seed: 0,
                },
                progress: true,
            };
            let rep = data::rlds::convert_rlds(&src, &out, &opts)?;
            data::outln!(
                "{}: {} shards → {} episodes, {} steps in {} (images: {} applied)",
                rep.name,
                rep.shards,
                rep.episodes,
                rep.steps,
                out.display(),
                rep.flip.name()
            );
        }
        Cmd::ExportLerobot {
            dir,
            out,
            flip,
            keyframe_every,
        } => {
            let opts = data::lerobot::ExportOptions {
                flip: fixed_flip(flip).unwrap_or(Flip::Horizontal),
                keyframe_every,
                progress: true,
                ..Default::default()
            };
            let r = data::lerobot::export(&dir, &out, &opts)?;
            data::outln!(
                "{}: {} episodes, {} frames, {} tasks ({} data files, {} video files per camera)",
                out.display(),
                r.episodes,
                r.frames,
                r.tasks,
                r.data_files,
                r.video_files
            );
        }
        Cmd::ImportLerobot {
            root,
            out,
            flip,
            val_fraction,
            ffmpeg,
        } => {
            let opts = data::lerobot::ImportOptions {
                flip: fixed_flip(flip),
                val_fraction,
                ffmpeg,
                ..Default::default()
            };
            let r = data::lerobot::import(&root, &out, &opts)?;
            data::outln!(
                "{}: {} episodes, {} steps from {}",
                out.display(),
                r.episodes,
                r.frames,
                root.display()
            );
        }
        Cmd::Synth {
            out,
            episodes,
            steps,
            size,
        } => {
            let paths = data::synth::write_synthetic_dataset(&out, episodes, steps, size)?;
            data::outln!(
                "wrote {} episodes of {steps} steps to {}",
                paths.len(),
                out.display()
            );
        }
        Cmd::Bench {
            window,
            sizes,
            workers,
            windows,
            dir,
        } => {
            let tmp = tempfile::tempdir().context("temporary directory")?;
            let dir = match dir {
                Some(d) => d,
                None => {
                    data::bench::make_bench_dataset(tmp.path(), 4, 80, 128)?;
                    tmp.path().to_path_buf()
                }
            };
            data::outln!(
                "{:>6} {:>6} {:>8} {:>9} {:>12}",
                "T",
                "size",
                "workers",
                "windows",
                "windows/s"
            );
            for r in data::bench::bench_windows(&dir, window, &sizes, &workers, windows)? {
                data::outln!(
                    "{:>6} {:>6} {:>8} {:>9} {:>12.1}",
                    r.window,
                    r.image_size,
                    r.workers,
                    r.windows,
                    r.windows_per_s
                );
            }
        }
    }
    Ok(())
}

/// The transform a flip argument names (None for `auto`).
fn fixed_flip(f: FlipArg) -> Option<Flip> {
    match f {
        FlipArg::Auto => None,
        FlipArg::None => Some(Flip::None),
        FlipArg::Hflip => Some(Flip::Horizontal),
        FlipArg::Vflip => Some(Flip::Vertical),
        FlipArg::Rot180 => Some(Flip::Rotate180),
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => data::exit::report::<DataError>(&e),
    }
}
