//! Links Debian's libmujoco (2.2.2); EGL and GL are opened at run time (see `render`).
fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    let candidates = [
        "/usr/lib/x86_64-linux-gnu/libmujoco.so",
        "/usr/lib/aarch64-linux-gnu/libmujoco.so",
        "/usr/lib/libmujoco.so",
        "/usr/local/lib/libmujoco.so",
    ];
    // Re-run when Debian's library folder changes (libmujoco-dev installed after the first build),
    // so a warning from a build made before `scripts/setup.sh` is not replayed from cargo's cache
    // (only the multiarch folders: cargo scans a watched folder recursively).
    for dir in candidates[..2]
        .iter()
        .filter_map(|p| std::path::Path::new(p).parent())
        .filter(|d| d.is_dir())
    {
        println!("cargo:rerun-if-changed={}", dir.display());
    }
    if !candidates.iter().any(|p| std::path::Path::new(p).exists()) {
        println!(
            "cargo:warning=libmujoco.so not found: install Debian's MuJoCo 2.2.2 with `apt-get install libmujoco-dev`"
        );
    }
    println!("cargo:rustc-link-lib=dylib=mujoco");
}
