//! kill -9 at random moments, shared by the chaos tests of `sim` and `train` (each includes this
//! file with `#[path]`): the number of kills comes from `CHAOS_KILLS` (default 3) and the kill
//! schedule from `CHAOS_SEED`, so that `scripts/chaos.sh N SEED` can run more and replay one.

use std::path::Path;
use std::process::Child;
use std::time::{Duration, Instant};

use rand::{Rng, SeedableRng};

/// Kills per test: `CHAOS_KILLS`, default 3.
pub fn kills() -> usize {
    std::env::var("CHAOS_KILLS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3)
}

/// Starts `spawn()` and kills it with SIGKILL after a random wait below `full_ms` (an
/// uninterrupted run's duration; at least 50 ms), [`kills`] times. A run that ends before its kill
/// is started over from an empty `out`, so that every kill lands mid-run. `after_kill(k, wait)` is
/// called after kill `k` (1-based).
pub fn kill_at_random_moments(
    out: &Path,
    full_ms: u64,
    mut spawn: impl FnMut() -> Child,
    mut after_kill: impl FnMut(usize, Duration),
) {
    let seed = std::env::var("CHAOS_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0x5eed);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut killed = 0;
    while killed < kills() {
        let mut child = spawn();
        // Anywhere in the run: start-up, a step, a file being written, pruning.
        let wait = Duration::from_millis(rng.random_range(0..full_ms.max(50)));
        let t = Instant::now();
        let mut finished = false;
        while t.elapsed() < wait {
            if child.try_wait().unwrap().is_some() {
                finished = true;
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        if finished {
            std::fs::remove_dir_all(out).unwrap();
            continue;
        }
        child.kill().unwrap();
        child.wait().unwrap();
        killed += 1;
        after_kill(killed, wait);
    }
}
