//! `sim`: the simulator's command line. Subcommands: info, tasks, assets (install, status, tasks),
//! generate, sheet, render, expert-eval, aliasing, bench; each lives in its own file under `cli/`.
//! All logic lives in the `sim` library; this parses, dispatches and maps errors to exit codes
//! through the workspace's one contract, `data::exit` (2 for bad input, 1 for other failures).

mod cli;

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    match cli::run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => data::exit::report::<cli::BadInput>(&e),
    }
}
