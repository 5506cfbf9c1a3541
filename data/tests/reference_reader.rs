//! Our files through the reference mcap reader (PyPI `mcap`). Runs when `DATA_MCAP_PYTHON` names a
//! Python with `mcap`, `mcap-protobuf-support` and `zstandard` installed; otherwise it says so and
//! passes (CI runs `data/tests/validate_mcap.py` as its own step as well).

#[test]
fn reference_reader_accepts_our_files() {
    let Ok(python) = std::env::var("DATA_MCAP_PYTHON") else {
        eprintln!("DATA_MCAP_PYTHON not set: reference-reader check not run here");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    data::synth::write_synthetic_dataset(dir.path(), 2, 12, 32).unwrap();
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/validate_mcap.py");
    let out = std::process::Command::new(python)
        .arg(script)
        .arg(dir.path())
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("2/2 files pass"), "{text}");
}
