//! Worker *processes*: N copies of the running program, each doing one shard of the work
//! (`--shard i/N`), for work that cannot share a process well (rendering: llvmpipe renders one
//! frame at a time per process). Used by `sim generate --workers N` and `eval --processes`.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// A worker process that failed (or could not start).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("worker process {index}/{count} failed: {message}")]
pub struct ProcFailure {
    /// Its index (its shard).
    pub index: usize,
    /// How many were started.
    pub count: usize,
    /// Its exit code (None: killed by a signal, or never started).
    pub code: Option<i32>,
    /// The last line it wrote to stderr (or why it did not start).
    pub message: String,
}

impl ProcFailure {
    /// True when the process exited with the workspace's bad-input code (2).
    pub fn is_bad_input(&self) -> bool {
        self.code == Some(2)
    }
}

/// This program's command-line arguments (without the program name), leaving out every argument
/// equal to one of `drop` (flags only: a value after a dropped flag stays).
pub fn own_args(drop: &[&str]) -> Vec<OsString> {
    std::env::args_os()
        .skip(1)
        .filter(|a| !drop.iter().any(|d| a == d))
        .collect()
}

/// Runs `count` processes of this program, process i with the arguments `args(i)`, its stdout
/// discarded and its stderr in `logs/worker_<i>.log`; calls `tick()` about every 200 ms while
/// they run. The first to fail stops the others (killed; what they finished stays on disk).
pub fn run_all(
    count: usize,
    logs: &Path,
    args: impl Fn(usize) -> Vec<OsString>,
    mut tick: impl FnMut(),
) -> Result<(), ProcFailure> {
    let fail = |index: usize, message: String| ProcFailure {
        index,
        count,
        code: None,
        message,
    };
    let exe = std::env::current_exe().map_err(|e| fail(0, format!("no program path: {e}")))?;
    std::fs::create_dir_all(logs).map_err(|e| fail(0, format!("{}: {e}", logs.display())))?;
    let mut children: Vec<(Child, PathBuf)> = Vec::with_capacity(count);
    let mut failed = None;
    for i in 0..count {
        let log = logs.join(format!("worker_{i}.log"));
        let started = std::fs::File::create(&log)
            .map_err(|e| format!("{}: {e}", log.display()))
            .and_then(|file| {
                Command::new(&exe)
                    .args(args(i))
                    .stdin(Stdio::null())
                    .stdout(Stdio::null())
                    .stderr(file)
                    .spawn()
                    .map_err(|e| format!("cannot start {}: {e}", exe.display()))
            });
        match started {
            Ok(child) => children.push((child, log)),
            Err(m) => {
                failed = Some(fail(i, m));
                break;
            }
        }
    }
    let mut running = children.len();
    while failed.is_none() && running > 0 {
        running = 0;
        for (i, (child, log)) in children.iter_mut().enumerate() {
            match child.try_wait() {
                Ok(None) => running += 1,
                Ok(Some(status)) if !status.success() => {
                    let text = std::fs::read_to_string(&*log).unwrap_or_default();
                    let last = text.lines().rev().find(|l| !l.trim().is_empty());
                    failed = Some(ProcFailure {
                        code: status.code(),
                        message: last.unwrap_or("no message").trim().to_string(),
                        ..fail(i, String::new())
                    });
                    break;
                }
                Ok(Some(_)) => {}
                Err(e) => {
                    failed = Some(fail(i, e.to_string()));
                    break;
                }
            }
        }
        tick();
        if failed.is_none() && running > 0 {
            std::thread::sleep(Duration::from_millis(200));
        }
    }
    if let Some(f) = failed {
        for (child, _) in &mut children {
            let _ = child.kill();
            let _ = child.wait();
        }
        return Err(f);
    }
    Ok(())
}
