//! Our files through the reference mcap reader (PyPI `mcap`). Runs when `DATA_MCAP_PYTHON` names a
//! Python with `mcap`, `mcap-protobuf-support` and `zstandard` installed; otherwise it says so and
//! passes, except under CI, where `scripts/test.sh` always provides it.

#[test]
fn reference_reader_accepts_our_files() {
    let Ok(python) = std::env::var("DATA_MCAP_PYTHON") else {
        // scripts/test.sh always sets it; CI must never skip this check silently.
        assert!(
            std::env::var_os("CI").is_none(),
            "CI must set DATA_MCAP_PYTHON (scripts/test.sh does)"
        );
        eprintln!("DATA_MCAP_PYTHON not set: reference-reader check not run here");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    data::synth::write_synthetic_dataset(dir.path(), 2, 12, 32).unwrap();
    // plus one episode converted from an RLDS fixture (JPEG frames)
    let steps = data::synth::synthetic_steps(6, 1, &Default::default());
    let png =
        |i: &data::RgbImage| data::imageio::encode_rgb(i, data::ImageCompression::Png).unwrap();
    let ep = data::rlds::RldsEpisode {
        images: steps.iter().map(|s| png(&s.agentview)).collect(),
        wrist_images: steps.iter().map(|s| png(&s.eye_in_hand)).collect(),
        states: steps.iter().map(|s| s.state).collect(),
        joint_states: steps.iter().map(|s| s.joint_state).collect(),
        actions: steps.iter().map(|s| s.action).collect(),
        instruction: "open the drawer".into(),
        ..Default::default()
    };
    let rlds = tempfile::tempdir().unwrap();
    data::rlds::write_rlds_dataset(rlds.path(), "libero_10_no_noops", &[vec![ep]]).unwrap();
    let opts = data::rlds::ConvertOptions {
        writer: data::WriterOptions {
            image_compression: data::ImageCompression::Jpeg { quality: 90 },
            ..Default::default()
        },
        ..Default::default()
    };
    data::rlds::convert_rlds(rlds.path(), dir.path(), &opts).unwrap();
    let script = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/validate_mcap.py");
    let out = std::process::Command::new(python)
        .arg(script)
        .arg(dir.path())
        .output()
        .unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("3/3 files pass"), "{text}");
}
