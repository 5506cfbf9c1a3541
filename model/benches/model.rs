//! Model benchmarks (no harness: prints tables).
//!
//! 1. Tiny forward+backward ms per batch (B = 8, T = 16, 64²) per variant, as a ratio to
//!    SlotVLA(h=1) measured in the same run.
//! 2. The token-scaling table of the paper's figure: per-step streaming latency and carried
//!    memory of SlotVLA(h) for h ∈ {1, 8, 32, 128} against e_slotssm at episode steps 1, 100 and
//!    700, on one thread (flex backend). Target for e_slotssm: latency(700)/latency(1) ≤ 1.1 and
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
        images: Tensor::random([b, t, 3, 64, 64], Distribution::Uniform(0.0, 1.0), &device),
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
    floats: [usize; 3],
}

/// Per-step streaming latency (ms, median over `reps` acts) and carried floats at steps 1, 100,
/// 700. Steps between measurements only update the memory (`observe`).
fn streaming_figures(variant: &str, reps: usize) -> StepFigures {
    let device = Device::flex();
    device.seed(0);
    let cfg = config(variant);
    let model = PolicyModel::new(&cfg, &device).expect("model");
    let tok = Tokenizer::new(&cfg.text);
    let instr = tok.encode_batch(&[INSTRUCTION], &device);
    let frames: Vec<Tensor<4>> = (0..16)
        .map(|_| Tensor::random([1, 3, 64, 64], Distribution::Uniform(0.0, 1.0), &device))
        .collect();
    let mut policy = StreamingPolicy::new(model, &device).expect("policy");
    let act_ms = |policy: &mut StreamingPolicy| {
        let frame = frames[policy.step_count() % frames.len()].clone();
        let start = Instant::now();
        let chunk = policy.act_tensor(frame, instr.clone(), None).expect("act");
        let _ = chunk.into_data();
        start.elapsed().as_secs_f64() * 1e3
    };
    // Step 1: the first act of fresh episodes.
    let mut first = Vec::new();
    for _ in 0..reps {
        policy.reset();
        first.push(act_ms(&mut policy));
    }
    let floats1 = policy.state_floats();
    let mut out = StepFigures {
        ms: [median(first), 0.0, 0.0],
        floats: [floats1, 0, 0],
    };
    for (i, target) in [(1usize, 100usize), (2, 700)] {
        while policy.step_count() + 1 < target {
            let frame = frames[policy.step_count() % frames.len()].clone();
            policy.observe_tensor(frame, None).expect("observe");
        }
        // Acts at steps target, target+1, … (the state stops growing for h < target).
        let times: Vec<f64> = (0..reps).map(|_| act_ms(&mut policy)).collect();
        out.ms[i] = median(times);
        out.floats[i] = policy.state_floats();
    }
    out
}

fn main() {
    // One core for the per-step figures (flex parallelises with rayon).
    rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build_global()
        .expect("rayon pool");
    let quick = std::env::var("BENCH_QUICK").is_ok();
    let (train_reps, step_reps) = if quick { (1, 3) } else { (3, 7) };

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
        "{:<14} {:>9} {:>9} {:>9} {:>11} {:>11} {:>11} {:>10}",
        "variant", "ms@1", "ms@100", "ms@700", "KiB@1", "KiB@100", "KiB@700", "700/1"
    );
    let mut ssm = None;
    for v in [
        "slotvla_h1",
        "slotvla_h8",
        "slotvla_h32",
        "slotvla_h128",
        "e_slotssm",
    ] {
        let f = streaming_figures(v, step_reps);
        let kib = |n: usize| n as f64 * 4.0 / 1024.0;
        println!(
            "{:<14} {:>9.2} {:>9.2} {:>9.2} {:>11.1} {:>11.1} {:>11.1} {:>10.2}",
            v,
            f.ms[0],
            f.ms[1],
            f.ms[2],
            kib(f.floats[0]),
            kib(f.floats[1]),
            kib(f.floats[2]),
            f.ms[2] / f.ms[0]
        );
        if v == "e_slotssm" {
            ssm = Some(f);
        }
    }
    let f = ssm.expect("measured");
    let ratio = f.ms[2] / f.ms[0];
    let constant = f.floats[0] == f.floats[2];
    println!();
    println!(
        "e_slotssm: latency(700)/latency(1) = {ratio:.2} (target ≤ 1.1: {}), {:.2} ms/step at 700 \
         (target ≤ 20: {}), state {} floats at step 1 and {} at step 700 ({})",
        if ratio <= 1.1 { "met" } else { "NOT met" },
        f.ms[2],
        if f.ms[2] <= 20.0 { "met" } else { "NOT met" },
        f.floats[0],
        f.floats[2],
        if constant { "constant" } else { "GROWS" }
    );
}
