//! Model benchmarks (no harness: prints tables).
//!
//! 1. Tiny forward+backward ms per batch (B = 8, T = 16, 64²) per variant, as a ratio to
//!    SlotVLA(h=1) measured in the same run.
//! 2. The token-scaling table of the paper's figure: per-step streaming latency and carried
//!    memory of SlotVLA(h) for h ∈ {1, 8, 32, 128} against e_slotssm at episode steps 1, 100 and
//!    700, on one thread (flex backend); every cell is timed round-robin so that load changes
//!    on a shared machine hit them alike. Target for e_slotssm: latency(700)/latency(1) ≤ 1.1 and
//!    ≤ 20 ms per step.
//!
//! 3. The full preset's memory (`BENCH_FULL=1`, or `BENCH_ONLY=full`): parameters, training
//!    state (weights, gradients, AdamW moments), and the activation memory of forward+backward
//!    measured as peak resident memory at batch 1 over 2, 4 and 8 frames (a fresh process each),
//!    extrapolated linearly to batch 1 and 8 over T = 32 (the GPU window).
//!
//! 4. A per-module breakdown of e_slotssm's training step (`BENCH_ONLY=breakdown`): each
//!    component's forward and backward at the training shapes (B = 8, T = 16, 64², one
//!    thread, autodiff on; inputs are leaves that need a gradient, as inside the whole graph;
//!    backward of the sum of the outputs), beside the whole step's, to line up with the PyTorch
//!    twin's `bench.py --breakdown`.
//!
//! Run: `cargo bench -p model` (add `--profile dev` to reuse the dev build: dependencies are
//! optimised there too). Environment: `BENCH_QUICK=1` runs fewer repetitions. The bench runs on
//! the `train` and `eval` binaries' allocator, mimalloc without purging
//! ([`data::alloc::keep_freed_pages`]; `MIMALLOC_PURGE_DELAY=1000` gives mimalloc's default).

use std::time::Instant;

use burn::prelude::*;
use burn::tensor::Distribution;
use model::{ModelConfig, PolicyModel, StreamingPolicy, Tokenizer, Variant, WindowBatch};

/// The binaries' allocator, so that the figures are the trainer's.
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

const INSTRUCTION: &str = "put the bowl on the plate";

fn config(variant: &str) -> ModelConfig {
    ModelConfig::tiny(Variant::from_name(variant).expect("known variant"))
        .with_vocab_from([INSTRUCTION])
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
    v[v.len() / 2]
}

fn sync(t: Tensor<1>) -> f32 {
    t.into_scalar::<f32>()
}

/// A training batch of `images` `[B, T, 3, 64, 64]`: random actions in [−1, 1], every frame valid,
/// the bench instruction for every window.
fn window_batch(cfg: &ModelConfig, images: Tensor<5>, device: &Device) -> WindowBatch {
    let [b, t, _, _, _] = images.dims();
    let texts = vec![INSTRUCTION; b];
    WindowBatch {
        obs: images.into(),
        actions: Tensor::random([b, t, 4, 7], Distribution::Uniform(-1.0, 1.0), device),
        frame_mask: Tensor::ones([b, t], device),
        action_mask: None,
        instruction: Tokenizer::new(&cfg.text).encode_instructions(&texts, device),
        subgoal: None,
        pointer_target: None,
        progress: None,
        done: None,
    }
}

/// Forward + backward of one window batch, ms (median of `reps`).
fn train_step_ms(variant: &str, reps: usize) -> f64 {
    let device = Device::flex().autodiff();
    device.seed(0);
    let cfg = config(variant);
    let model = PolicyModel::new(&cfg, &device).expect("model");
    let images = Tensor::random([8, 16, 3, 64, 64], Distribution::Uniform(0.0, 1.0), &device);
    let batch = window_batch(&cfg, images, &device);
    let mut times = Vec::new();
    for i in 0..=reps {
        let start = Instant::now();
        let (_, losses) = model.forward(&batch).expect("forward");
        let grads = losses.total.clone().backward();
        drop(grads);
        sync(losses.total);
        if i > 0 {
            times.push(start.elapsed().as_secs_f64() * 1e3);
        }
    }
    median(times)
}

struct StepFigures {
    ms: [f64; 3],
    min_ms: [f64; 3],
    floats: [usize; 3],
}

/// One variant's streaming policies at episode steps 1, 100 and 700, sharing the weights.
struct Stepper {
    instr: Tensor<2, Int>,
    frames: Vec<Tensor<4>>,
    /// Policy 0 is reset before every measured act (step 1); 1 and 2 sit at steps 100 and 700.
    policies: Vec<StreamingPolicy>,
    times: [Vec<f64>; 3],
}

impl Stepper {
    fn new(variant: &str) -> Self {
        let device = Device::flex();
        device.seed(0);
        let cfg = config(variant);
        let model = PolicyModel::new(&cfg, &device).expect("model");
        let instr = Tokenizer::new(&cfg.text).encode_batch(&[INSTRUCTION], &device);
        let frames: Vec<Tensor<4>> = (0..16)
            .map(|_| Tensor::random([1, 3, 64, 64], Distribution::Uniform(0.0, 1.0), &device))
            .collect();
        let mut policies: Vec<StreamingPolicy> = (0..3)
            .map(|_| StreamingPolicy::new(model.clone(), &device).expect("policy"))
            .collect();
        // Bring policies 1 and 2 to just before steps 100 and 700 (memory updates only).
        for (policy, target) in policies.iter_mut().zip([1usize, 100, 700]) {
            while policy.step_count() + 1 < target {
                let frame = frames[policy.step_count() % frames.len()].clone();
                policy.observe_tensor(frame, None).expect("observe");
            }
        }
        Stepper {
            instr,
            frames,
            policies,
            times: [Vec::new(), Vec::new(), Vec::new()],
        }
    }

    /// Times one act of policy `i`, ms.
    fn act(&mut self, i: usize, record: bool) {
        let policy = &mut self.policies[i];
        if i == 0 {
            policy.reset();
        }
        let frame = self.frames[policy.step_count() % self.frames.len()].clone();
        let start = Instant::now();
        let chunk = policy
            .act_tensor(frame, self.instr.clone(), None)
            .expect("act");
        let _ = chunk.into_data();
        if record {
            self.times[i].push(start.elapsed().as_secs_f64() * 1e3);
        }
    }

    fn figures(&self) -> StepFigures {
        let min = |v: &Vec<f64>| v.iter().cloned().fold(f64::INFINITY, f64::min);
        StepFigures {
            ms: [0, 1, 2].map(|i| median(self.times[i].clone())),
            min_ms: [0, 1, 2].map(|i| min(&self.times[i])),
            floats: [0, 1, 2].map(|i| self.policies[i].state_floats()),
        }
    }
}

/// Per-step streaming latency (ms) and carried floats at steps 1, 100 and 700 for every
/// variant. All acts of all variants are timed round-robin, `reps` rounds after one warm-up
/// round, so that changes of machine load hit every cell alike; medians are reported.
fn streaming_table(variants: &[&str], reps: usize) -> Vec<StepFigures> {
    let mut steppers: Vec<Stepper> = variants.iter().map(|v| Stepper::new(v)).collect();
    for round in 0..=reps {
        for stepper in &mut steppers {
            for i in 0..3 {
                stepper.act(i, round > 0);
            }
        }
    }
    steppers.iter().map(Stepper::figures).collect()
}

/// A line of this process's `/proc/self/status` in bytes (`VmHWM`: peak resident memory,
/// `VmRSS`: current), or None off Linux.
fn proc_status_bytes(key: &str) -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with(key))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// The full preset (e_slotssm) with its vocabulary.
fn full_config() -> ModelConfig {
    ModelConfig::full(Variant::from_name("e_slotssm").expect("known"))
        .with_vocab_from([INSTRUCTION])
}

/// Child process of [`full_memory`]: one forward+backward of the full preset at batch 1 over
/// `t` frames; prints `seconds peak_bytes_above_the_built_model`.
fn full_memory_child(t: usize) {
    let device = Device::flex().autodiff();
    device.seed(0);
    let cfg = full_config();
    let model = PolicyModel::new(&cfg, &device).expect("model");
    let tok = Tokenizer::new(&cfg.text);
    let batch = WindowBatch {
        obs: Tensor::random(
            [1, t, 3, 224, 224],
            Distribution::Uniform(0.0, 1.0),
            &device,
        )
        .into(),
        actions: Tensor::random([1, t, 8, 7], Distribution::Uniform(-1.0, 1.0), &device),
        frame_mask: Tensor::ones([1, t], &device),
        action_mask: None,
        instruction: tok.encode_batch(&[INSTRUCTION], &device),
        subgoal: None,
        pointer_target: None,
        progress: None,
        done: None,
    };
    let base = proc_status_bytes("VmRSS:").unwrap_or(0);
    let start = Instant::now();
    let (_, losses) = model.forward(&batch).expect("forward");
    let grads = losses.total.clone().backward();
    sync(losses.total);
    drop(grads);
    let peak = proc_status_bytes("VmHWM:").unwrap_or(0);
    println!(
        "{} {}",
        start.elapsed().as_secs_f64(),
        peak.saturating_sub(base)
    );
}

/// The full preset's parameters and memory: activations of forward+backward measured as the
/// peak resident memory above the built model, each window size in a fresh process (an
/// allocator keeps freed memory, so in one process a second measurement reads low), then a
/// line through the measurements extrapolated to T = 32 at batch 1 and 8.
fn full_memory() {
    let device = Device::flex();
    let model = PolicyModel::new(&full_config(), &device).expect("model");
    let params = model.num_params();
    let gib = |b: f64| b / (1u64 << 30) as f64;
    let state = params as f64 * 4.0 * 4.0;
    println!("# Full preset (e_slotssm, 224x224, K=16, D=512), flex CPU, 1 thread");
    println!(
        "parameters {params} ({:.2} GiB f32); weights + gradients + AdamW moments {:.2} GiB",
        gib(params as f64 * 4.0),
        gib(state)
    );
    let exe = std::env::current_exe().expect("bench executable");
    let mut points = Vec::new();
    for t in [2usize, 4, 8] {
        let out = std::process::Command::new(&exe)
            .env("BENCH_FULL_T", t.to_string())
            .output()
            .expect("child bench");
        let text = String::from_utf8_lossy(&out.stdout);
        let nums: Vec<f64> = text
            .split_whitespace()
            .filter_map(|w| w.parse().ok())
            .collect();
        let [secs, bytes] = nums[..] else {
            println!(
                "B=1 T={t}: not measured ({})",
                String::from_utf8_lossy(&out.stderr).trim()
            );
            return;
        };
        println!(
            "B=1 T={t}: forward+backward {secs:.1} s, peak resident memory above the model {:.2} GiB",
            gib(bytes)
        );
        points.push((t as f64, bytes));
    }
    // Least-squares line bytes = fixed + per_frame · T through the three points.
    let n = points.len() as f64;
    let (mt, mb) = (
        points.iter().map(|p| p.0).sum::<f64>() / n,
        points.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let per_frame = points.iter().map(|p| (p.0 - mt) * (p.1 - mb)).sum::<f64>()
        / points.iter().map(|p| (p.0 - mt).powi(2)).sum::<f64>();
    let fixed = (mb - per_frame * mt).max(0.0);
    println!(
        "activations ≈ {:.2} GiB + {:.3} GiB per frame (per batch element)",
        gib(fixed),
        gib(per_frame)
    );
    for b in [1usize, 8] {
        let act = b as f64 * (fixed + per_frame * 32.0);
        println!(
            "estimate B={b} T=32: activations {:.1} GiB + training state {:.2} GiB = {:.1} GiB",
            gib(act),
            gib(state),
            gib(act + state)
        );
    }
}

fn main() {
    data::alloc::keep_freed_pages();
    // One core for the per-step figures (flex parallelises with rayon).
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build_global()
        .expect("rayon pool");
    if let Some(t) = std::env::var("BENCH_FULL_T")
        .ok()
        .and_then(|t| t.parse().ok())
    {
        full_memory_child(t);
        return;
    }
    let quick = std::env::var("BENCH_QUICK").is_ok();
    let (train_reps, step_reps) = if quick { (1, 5) } else { (3, 25) };

    let only = std::env::var("BENCH_ONLY").ok();
    if only.as_deref() == Some("full") {
        full_memory();
        return;
    }
    if only.as_deref() == Some("breakdown") {
        breakdown(if quick { 3 } else { 7 });
        return;
    }
    if let Some(v) = &only {
        let f = streaming_table(&[v.as_str()], step_reps).remove(0);
        println!(
            "{v}: median ms {:?}, min ms {:?}, floats {:?}",
            f.ms, f.min_ms, f.floats
        );
        return;
    }
    println!("# Tiny forward+backward, B=8, T=16, 64x64, flex, 1 thread");
    println!(
        "{:<14} {:>10} {:>22}",
        "variant", "ms/batch", "ratio vs slotvla_h1"
    );
    let base = train_step_ms("slotvla_h1", train_reps);
    println!("{:<14} {:>10.1} {:>22.2}", "slotvla_h1", base, 1.0);
    for v in ["e_slotssm", "slotvla_h8", "dense"] {
        let ms = train_step_ms(v, train_reps);
        println!("{:<14} {:>10.1} {:>22.2}", v, ms, ms / base);
    }

    println!();
    println!("# Streaming per-step latency and carried state (tiny, flex, 1 thread)");
    println!(
        "(median of {step_reps} rounds; every cell timed round-robin; 700/1 also from the minima)"
    );
    println!(
        "{:<14} {:>9} {:>9} {:>9} {:>11} {:>11} {:>11} {:>8} {:>10}",
        "variant", "ms@1", "ms@100", "ms@700", "KiB@1", "KiB@100", "KiB@700", "700/1", "min 700/1"
    );
    let variants = [
        "slotvla_h1",
        "slotvla_h8",
        "slotvla_h32",
        "slotvla_h128",
        "e_slotssm",
    ];
    let table = streaming_table(&variants, step_reps);
    let kib = |n: usize| n as f64 * 4.0 / 1024.0;
    for (v, f) in variants.iter().zip(&table) {
        println!(
            "{:<14} {:>9.2} {:>9.2} {:>9.2} {:>11.1} {:>11.1} {:>11.1} {:>8.2} {:>10.2}",
            v,
            f.ms[0],
            f.ms[1],
            f.ms[2],
            kib(f.floats[0]),
            kib(f.floats[1]),
            kib(f.floats[2]),
            f.ms[2] / f.ms[0],
            f.min_ms[2] / f.min_ms[0]
        );
    }
    let ssm = table.last();
    let f = ssm.expect("measured");
    let ratio = f.ms[2] / f.ms[0];
    let min_ratio = f.min_ms[2] / f.min_ms[0];
    let constant = f.floats[0] == f.floats[2];
    println!();
    println!(
        "e_slotssm: latency(700)/latency(1) = {ratio:.2} (minima: {min_ratio:.2}; target ≤ 1.1: {}), \
         {:.2} ms/step at 700 (target ≤ 20: {}), state {} floats at step 1 and {} at step 700 ({})",
        if ratio <= 1.1 { "met" } else { "NOT met" },
        f.ms[2],
        if f.ms[2] <= 20.0 { "met" } else { "NOT met" },
        f.floats[0],
        f.floats[2],
        if constant { "constant" } else { "GROWS" }
    );
    if std::env::var("BENCH_FULL").is_ok() {
        println!();
        full_memory();
    }
}

/// A leaf copy of `x` that needs a gradient (an input of one component timed alone).
fn leaf<const D: usize>(x: &Tensor<D>) -> Tensor<D> {
    x.clone().detach().require_grad()
}

/// Forward ms and backward ms of one component (medians of `reps` after one untimed call):
/// `f` maps its leaves to its output, whose sum is differentiated. Every forward is followed by
/// its backward, so no graph is left behind.
fn component<const D: usize>(reps: usize, f: impl Fn() -> Tensor<D>) -> (f64, f64) {
    let (mut fwd, mut bwd) = (Vec::new(), Vec::new());
    for i in 0..=reps {
        let start = Instant::now();
        let out = f().sum();
        sync(out.clone());
        let mid = Instant::now();
        drop(out.backward());
        let end = Instant::now();
        if i > 0 {
            fwd.push((mid - start).as_secs_f64() * 1e3);
            bwd.push((end - mid).as_secs_f64() * 1e3);
        }
    }
    (median(fwd), median(bwd))
}

/// Section 4: e_slotssm's training step per module (see the header).
fn breakdown(reps: usize) {
    use model::variants::TokenBuilder;
    let device = Device::flex().autodiff();
    device.seed(0);
    let cfg = config("e_slotssm");
    let model = PolicyModel::new(&cfg, &device).expect("model");
    let (b, t) = (8, 16);
    let n = b * t;
    let images: Tensor<5> =
        Tensor::random([b, t, 3, 64, 64], Distribution::Uniform(0.0, 1.0), &device);
    let batch = window_batch(&cfg, images.clone(), &device);
    let TokenBuilder::SlotSsm(tokens) = &model.tokens else {
        unreachable!("e_slotssm builds SlotSsm tokens")
    };
    let feats = model
        .encoder
        .forward(images.clone().into())
        .expect("encoder")
        .detach();
    let [_, _, m, d_f] = feats.dims();
    let (slots, _, _) = tokens
        .core
        .window(feats.clone(), None, None)
        .expect("slots");
    let slots = slots.detach();
    let [_, _, k, d] = slots.dims();
    let (pred, _) = tokens.slot_ssm.forward(slots.clone(), None, None);
    let pred = pred.detach();
    let z = slots.clone().reshape([n, k, d]);
    let w = cfg.decoder.width;
    let visual: Tensor<3> = Tensor::random([n, 16, w], Distribution::Normal(0.0, 1.0), &device);
    let instr = batch
        .instruction
        .clone()
        .unsqueeze_dim::<3>(1)
        .repeat_dim(1, t)
        .reshape([n, batch.instruction.dims()[1]]);
    let (lang, lang_pad) = model.text.tokens(instr);
    let lang = lang.detach();
    let slot_decoder = tokens.core.slot_decoder.as_ref().expect("L_sa decoder");

    let rows: Vec<(&str, (f64, f64))> = vec![
        (
            "encoder",
            component(reps, || {
                model
                    .encoder
                    .forward(images.clone().into())
                    .expect("encoder")
            }),
        ),
        (
            "slot_attention",
            component(reps, || {
                tokens
                    .core
                    .window(leaf(&feats), None, None)
                    .expect("slots")
                    .0
            }),
        ),
        (
            "slotssm",
            component(reps, || tokens.slot_ssm.forward(leaf(&slots), None, None).0),
        ),
        (
            "window_head",
            component(reps, || {
                tokens.window_head.forward(leaf(&pred), leaf(&slots))
            }),
        ),
        (
            "relation_encoder",
            component(reps, || {
                tokens
                    .core
                    .relation
                    .forward(leaf(&feats).reshape([n, m, d_f]), leaf(&z))
            }),
        ),
        (
            "sa_decoder(L_sa)",
            component(reps, || slot_decoder.forward(leaf(&z)).0),
        ),
        (
            "action_decoder",
            component(reps, || {
                model
                    .decoder
                    .forward(leaf(&visual), None, leaf(&lang), lang_pad.clone())
                    .actions
            }),
        ),
        (
            "whole step",
            component(reps, || model.forward(&batch).expect("forward").1.total),
        ),
    ];
    println!("# e_slotssm training step per module: B={b}, T={t}, 64x64, flex, 1 thread, autodiff");
    println!(
        "(median of {reps}; backward of the sum of the module's outputs, its inputs needing gradients)"
    );
    println!(
        "{:<18} {:>11} {:>12}",
        "module", "forward ms", "backward ms"
    );
    for (name, (fwd, bwd)) in rows {
        println!("{name:<18} {fwd:>11.1} {bwd:>12.1}");
    }
}
