//! Round trips, seeking and damaged-file handling of episode mcap files.

use data::synth::{SynthOptions, synthetic_meta, synthetic_steps};
use data::*;

fn write(path: &std::path::Path, steps: &[StepRecord], opts: WriterOptions) -> std::path::PathBuf {
    let mut w = EpisodeWriter::create(path, synthetic_meta(7), opts).unwrap();
    for s in steps {
        w.write_step(s).unwrap();
    }
    w.finish().unwrap()
}

fn small_chunks() -> WriterOptions {
    WriterOptions {
        chunk_size: 16 * 1024,
        ..WriterOptions::default()
    }
}

#[test]
fn png_round_trip_is_lossless() {
    let dir = tempfile::tempdir().unwrap();
    let steps = synthetic_steps(30, 1, &SynthOptions::default());
    let p = write(&dir.path().join("ep.mcap"), &steps, small_chunks());
    let r = EpisodeReader::open(&p).unwrap();
    assert_eq!(r.len(), 30);
    assert_eq!(r.meta(), &synthetic_meta(7));
    assert!(
        r.chunk_count() > 1,
        "expected several chunks, got {}",
        r.chunk_count()
    );
    let back = r.read_all().unwrap();
    assert_eq!(back, steps);
    // only the final file remains: no temporary left behind
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("ep.mcap")]);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        assert_eq!(
            std::fs::metadata(&p).unwrap().permissions().mode() & 0o777,
            0o644
        );
    }
}

#[test]
fn jpeg_round_trip_within_tolerance() {
    let dir = tempfile::tempdir().unwrap();
    let o = SynthOptions {
        size: 64,
        segmentation: false,
        depth: false,
    };
    let steps = synthetic_steps(5, 2, &o);
    let opts = WriterOptions {
        image_compression: ImageCompression::Jpeg { quality: 95 },
        ..WriterOptions::default()
    };
    let p = write(&dir.path().join("ep.mcap"), &steps, opts);
    let r = EpisodeReader::open(&p).unwrap();
    assert_eq!(r.has_segmentation_depth(), (false, false));
    for (a, b) in steps.iter().zip(r.read_all().unwrap()) {
        assert_eq!(a.state, b.state);
        assert_eq!(a.action, b.action);
        assert_eq!(a.segmentation, None);
        for (x, y) in [
            (&a.agentview, &b.agentview),
            (&a.eye_in_hand, &b.eye_in_hand),
        ] {
            assert_eq!((x.width, x.height), (y.width, y.height));
            let mae: f64 = x
                .data
                .iter()
                .zip(&y.data)
                .map(|(p, q)| (*p as f64 - *q as f64).abs())
                .sum::<f64>()
                / x.data.len() as f64;
            assert!(mae < 3.0, "JPEG mean abs error {mae}");
        }
    }
}

#[test]
fn seeking_to_step_k_returns_step_k() {
    let dir = tempfile::tempdir().unwrap();
    let steps = synthetic_steps(
        60,
        3,
        &SynthOptions {
            size: 24,
            ..Default::default()
        },
    );
    let p = write(&dir.path().join("ep.mcap"), &steps, small_chunks());
    let r = EpisodeReader::open(&p).unwrap();
    for k in [59, 0, 31, 17, 45, 1] {
        let s = r.read_step(k).unwrap();
        assert_eq!(s.step, k as u64);
        assert_eq!(s, steps[k]);
    }
    let raw = r.read_raw_steps(10..20).unwrap();
    assert_eq!(
        raw.iter().map(|s| s.step).collect::<Vec<_>>(),
        (10..20).collect::<Vec<u64>>()
    );
    assert!(r.read_raw_steps(55..61).is_err());
}

#[test]
fn writer_rejects_bad_steps_and_leaves_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ep.mcap");
    let steps = synthetic_steps(3, 4, &SynthOptions::default());
    let mut w = EpisodeWriter::create(&path, synthetic_meta(1), WriterOptions::default()).unwrap();
    w.write_step(&steps[0]).unwrap();
    let e = w.write_step(&steps[2]).unwrap_err().to_string();
    assert!(e.contains("consecutive"), "{e}");
    let mut bad = steps[1].clone();
    bad.action[2] = f32::NAN;
    assert!(
        w.write_step(&bad)
            .unwrap_err()
            .to_string()
            .contains("non-finite")
    );
    drop(w); // abandoned: no output, no temporary
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

fn written(dir: &tempfile::TempDir) -> (std::path::PathBuf, Vec<u8>) {
    let steps = synthetic_steps(20, 5, &SynthOptions::default());
    let p = write(&dir.path().join("ep.mcap"), &steps, small_chunks());
    let b = std::fs::read(&p).unwrap();
    (p, b)
}

#[test]
fn truncated_file_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let (p, b) = written(&dir);
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &b[..b.len() * 2 / 3]).unwrap();
    let e = EpisodeReader::open(&cut).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("cut.mcap") && msg.contains("byte offset") && msg.contains("truncated"),
        "{msg}"
    );
    assert_eq!(e.exit_code(), 2);
    let _ = p;
}

#[test]
fn flipped_byte_inside_a_chunk_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let (p, b) = written(&dir);
    let r = EpisodeReader::open(&p).unwrap();
    drop(r);
    // find the first chunk record (opcode 0x06) after the header and flip a byte in its data
    let summary = mcap::Summary::read(&b).unwrap().unwrap();
    let c = &summary.chunk_indexes[1];
    let mut bad = b.clone();
    let pos = (c.chunk_start_offset + c.chunk_length - 100) as usize;
    bad[pos] ^= 0x40;
    let f = dir.path().join("flip.mcap");
    std::fs::write(&f, &bad).unwrap();
    let r = EpisodeReader::open(&f).unwrap(); // summary intact: opens
    let e = r.verify().unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("flip.mcap"), "{msg}");
    assert!(
        msg.contains(&format!("byte offset {}", c.chunk_start_offset)),
        "{msg}"
    );
    assert!(matches!(e, DataError::Corrupt { .. }));
}

#[test]
fn wrong_schema_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("other.mcap");
    let mut w =
        mcap::Writer::new(std::io::BufWriter::new(std::fs::File::create(&f).unwrap())).unwrap();
    let s = w
        .add_schema(data::SCHEMA_STATE, "jsonschema", b"{}")
        .unwrap();
    let c = w
        .add_channel(s, data::TOPIC_AGENTVIEW, "json", &Default::default())
        .unwrap();
    w.write_to_known_channel(
        &mcap::records::MessageHeader {
            channel_id: c,
            sequence: 0,
            log_time: 0,
            publish_time: 0,
        },
        b"{}",
    )
    .unwrap();
    let meta = synthetic_meta(1);
    w.write_metadata(&mcap::records::Metadata {
        name: "episode".into(),
        metadata: meta.to_map(),
    })
    .unwrap();
    w.finish().unwrap();
    drop(w);
    let msg = EpisodeReader::open(&f).unwrap_err().to_string();
    assert!(
        msg.contains("other.mcap")
            && msg.contains("wrong schema at byte offset")
            && msg.contains("/agentview/image"),
        "{msg}"
    );
    // a file that is not mcap at all
    let g = dir.path().join("junk.mcap");
    std::fs::write(&g, b"hello world, definitely not an mcap file").unwrap();
    let msg = EpisodeReader::open(&g).unwrap_err().to_string();
    assert!(
        msg.contains("junk.mcap") && msg.contains("byte offset 0"),
        "{msg}"
    );
}

mod prop {
    use super::*;
    use proptest::prelude::*;
    use std::sync::{Arc, OnceLock};

    fn base() -> &'static Vec<u8> {
        static B: OnceLock<Vec<u8>> = OnceLock::new();
        B.get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let steps = synthetic_steps(
                6,
                9,
                &SynthOptions {
                    size: 8,
                    ..Default::default()
                },
            );
            let p = write(
                &dir.path().join("ep.mcap"),
                &steps,
                WriterOptions {
                    chunk_size: 2048,
                    ..Default::default()
                },
            );
            std::fs::read(p).unwrap()
        })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        /// Any single damaged byte or truncation gives Ok or a clean Err, never a panic.
        #[test]
        fn damaged_files_never_panic(pos in 0usize..100_000, xor in 1u8..=255, cut in proptest::bool::ANY) {
            let mut b = base().clone();
            let pos = pos % b.len();
            if cut { b.truncate(pos); } else { b[pos] ^= xor; }
            if let Ok(r) = EpisodeReader::from_bytes("x.mcap".into(), Arc::from(b)) {
                let _ = r.read_all();
            }
        }
    }
}

mod json_floats {
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(20000))]
        /// Every finite f32 survives our JSON messages bit for bit.
        #[test]
        fn f32_round_trips_through_json(bits in any::<u32>()) {
            let v = f32::from_bits(bits);
            prop_assume!(v.is_finite());
            let m = data::StateMsg { step: 3, state: [v; 8] };
            let back: data::StateMsg = serde_json::from_slice(&serde_json::to_vec(&m).unwrap()).unwrap();
            prop_assert_eq!(back.state[0].to_bits(), bits);
        }
    }
}

#[test]
fn same_steps_give_identical_files() {
    let dir = tempfile::tempdir().unwrap();
    let steps = synthetic_steps(12, 11, &SynthOptions::default());
    let a = std::fs::read(write(&dir.path().join("a.mcap"), &steps, small_chunks())).unwrap();
    let b = std::fs::read(write(&dir.path().join("b.mcap"), &steps, small_chunks())).unwrap();
    assert!(a == b, "episode files differ for identical input");
    assert_eq!(synthetic_steps(12, 11, &SynthOptions::default()), steps);
}

/// Schema 2 added object poses and grasp flags, schema 3 articulated parts; version-1 and -2
/// metadata and annotations without them still read, other versions are refused naming the
/// readable ones.
#[test]
fn schema_version_1_still_reads_and_others_are_refused() {
    let mut m = EpisodeMeta::default().to_map();
    assert_eq!(m["schema_version"], "libero-mem-rs/episode/3");
    for old in ["libero-mem-rs/episode/1", "libero-mem-rs/episode/2"] {
        m.insert("schema_version".into(), old.into());
        assert!(EpisodeMeta::from_map(&m).is_ok());
    }
    m.insert("schema_version".into(), "libero-mem-rs/episode/4".into());
    let e = EpisodeMeta::from_map(&m).unwrap_err();
    assert!(
        e.contains("episode/4")
            && e.contains("episode/1")
            && e.contains("episode/2")
            && e.contains("episode/3"),
        "{e}"
    );
    let v1: ObjectAnnotation = serde_json::from_str(
        r#"{"instance_id":1,"name":"bowl","box":[0,0,0.5,0.5],"visible":true,"subgoal_label":"0"}"#,
    )
    .unwrap();
    assert_eq!((v1.pose, v1.grasped), (None, None));
    let v2 = ObjectAnnotation {
        pose: Some([0.1, 0.2, 0.9, 1.0, 0.0, 0.0, 0.0]),
        grasped: Some(true),
        parts: Vec::new(),
        ..v1.clone()
    };
    let back: ObjectAnnotation =
        serde_json::from_str(&serde_json::to_string(&v2).unwrap()).unwrap();
    assert_eq!(back, v2);
    assert!(
        !serde_json::to_string(&v1).unwrap().contains("pose"),
        "absent fields are not written"
    );
    assert!(!serde_json::to_string(&v2).unwrap().contains("parts"));
    let v3 = ObjectAnnotation {
        parts: vec![PartState {
            name: "knob".into(),
            pose: [0.1, 0.2, 0.95, 0.9, 0.0, 0.0, 0.43],
            joint: 0.75,
        }],
        ..v2.clone()
    };
    let json = serde_json::to_string(&v3).unwrap();
    assert!(
        json.contains(
            r#""parts":[{"name":"knob","pose":[0.1,0.2,0.95,0.9,0.0,0.0,0.43],"joint":0.75}]"#
        ),
        "{json}"
    );
    assert_eq!(serde_json::from_str::<ObjectAnnotation>(&json).unwrap(), v3);
}
