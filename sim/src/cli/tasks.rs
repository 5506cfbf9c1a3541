//! `sim tasks`: the shipped tasks with goal length, step budget and instruction.

/// Prints one line per shipped task.
pub fn run() -> anyhow::Result<()> {
    data::outln!("{:<58} {:>4} {:>6}  instruction", "id", "goal", "steps");
    for t in sim::task::list() {
        data::outln!(
            "{:<58} {:>4} {:>6}  {}",
            t.id,
            t.goal_len,
            t.max_steps,
            t.instruction
        );
    }
    Ok(())
}
