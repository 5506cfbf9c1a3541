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
//! Run: `cargo bench -p model` (add `--profile dev` to reuse the dev build: dependencies are
//! optimised there too). Environment: `BENCH_QUICK=1` runs fewer repetitions.

use std::time::Instant;

use burn::prelude::*;
use burn::tensor::Distribution;
use model::{ModelConfig, PolicyModel, StreamingPolicy, Tokenizer, Variant, WindowBatch};

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

/// Forward + backward of one window batch, ms (median of `reps`).
fn train_step_ms(variant: &str, reps: usize) -> f64 {
    let device = Device::flex().autodiff();
    device.seed(0);
    let cfg = config(variant);
    let model = PolicyModel::new(&cfg, &device).expect("model");
    let (b, t) = (8, 16);
    let tok = Tokenizer::new(&cfg.text);
    let texts = vec![INSTRUCTION; b];
    let batch = WindowBatch {
        obs: Tensor::random([b, t, 3, 64, 64], Distribution::Uniform(0.0, 1.0), &device).into(),
        actions: Tensor::random([b, t, 4, 7], Distribution::Uniform(-1.0, 1.0), &device),
        frame_mask: Tensor::ones([b, t], &device),
        action_mask: None,
        instruction: tok.encode_batch(&texts, &device),
        subgoal: None,
    };
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

fn main() {
    // One core for the per-step figures (flex parallelises with rayon).
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build_global()
        .expect("rayon pool");
    let quick = std::env::var("BENCH_QUICK").is_ok();
    let (train_reps, step_reps) = if quick { (1, 5) } else { (3, 25) };

    let only = std::env::var("BENCH_ONLY").ok();
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
}
