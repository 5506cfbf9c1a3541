//! TFRecord framing, Example parsing and RLDS → mcap conversion.

use data::example::Example;
use data::imageio::{Flip, ImageCompression, apply_flip, encode_rgb};
use data::rlds::*;
use data::tfrecord::*;
use data::*;
use proptest::prelude::*;

#[test]
fn masked_crc_known_value() {
    // CRC-32C check value of "123456789" is 0xE3069283; masked by hand:
    // ((c >> 15) | (c << 17)) + 0xa282ead8 = 0x2507C60D + 0xA282EAD8 = 0xC78AB0E5.
    assert_eq!(crc32c::crc32c(b"123456789"), 0xE306_9283);
    assert_eq!(masked_crc32c(b"123456789"), 0xC78A_B0E5);
}

proptest! {
    #[test]
    fn framing_round_trips(records in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..200), 0..8)) {
        let framed = frame_records(records.iter().map(|r| r.as_slice()));
        let back: Vec<(u64, Vec<u8>)> = TfRecordReader::from_slice("f", &framed).collect::<Result<_>>().unwrap();
        let mut off = 0u64;
        for ((o, d), r) in back.iter().zip(&records) {
            prop_assert_eq!(*o, off);
            prop_assert_eq!(d, r);
            off += 16 + r.len() as u64;
        }
        prop_assert_eq!(back.len(), records.len());
    }

    #[test]
    fn any_damage_is_detected_or_harmless(records in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 1..64), 1..5),
                                           pos in any::<usize>(), xor in 1u8..=255, cut in any::<bool>()) {
        let framed = frame_records(records.iter().map(|r| r.as_slice()));
        let mut bad = framed.clone();
        let pos = pos % bad.len();
        if cut { bad.truncate(pos); } else { bad[pos] ^= xor; }
        let res: Result<Vec<_>> = TfRecordReader::from_slice("shard.tfrecord-0", &bad).collect();
        // A flipped byte always breaks a CRC; a cut always ends inside a record, except at a record boundary.
        match res {
            Ok(v) => { prop_assert!(cut); prop_assert!(v.len() < records.len()); }
            Err(e) => prop_assert!(e.to_string().contains("shard.tfrecord-0") && e.to_string().contains("byte offset")),
        }
    }
}

#[test]
fn crc_mismatch_names_file_and_offset() {
    let framed = frame_records([b"first".as_slice(), b"second record".as_slice()]);
    let mut bad = framed.clone();
    bad[16 + 5 + 12 + 3] ^= 1; // inside the second record's data
    let e = TfRecordReader::from_slice("x.tfrecord-00000-of-00001", &bad)
        .collect::<Result<Vec<_>>>()
        .unwrap_err()
        .to_string();
    assert!(e.contains("x.tfrecord-00000-of-00001"), "{e}");
    assert!(
        e.contains(&format!("byte offset {}", 21 + 12 + 13)) && e.contains("data CRC mismatch"),
        "{e}"
    );
    let mut bad = framed;
    bad[9] ^= 1; // length CRC of the first record
    let e = TfRecordReader::from_slice("y", &bad)
        .next()
        .unwrap()
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("byte offset 0") && e.contains("length CRC"),
        "{e}"
    );
}

fn rgb(w: u32, h: u32, seed: u32) -> RgbImage {
    let data = (0..w * h * 3)
        .map(|i| ((i * 7 + seed * 31) % 251) as u8)
        .collect();
    Image {
        width: w,
        height: h,
        channels: 3,
        data,
    }
}

fn fixture_episode(t: usize, seed: u32, extras: bool) -> RldsEpisode {
    let png = |img: &RgbImage| encode_rgb(img, ImageCompression::Png).unwrap();
    let gray_png = |v: u8| {
        let mut out = vec![];
        image::ImageEncoder::write_image(
            image::codecs::png::PngEncoder::new(&mut out),
            &(0..16 * 16)
                .map(|i| if i % 16 < 8 { v } else { 0 })
                .collect::<Vec<u8>>(),
            16,
            16,
            image::ExtendedColorType::L8,
        )
        .unwrap();
        out
    };
    RldsEpisode {
        images: (0..t).map(|k| png(&rgb(16, 16, seed + k as u32))).collect(),
        wrist_images: (0..t)
            .map(|k| png(&rgb(16, 16, 100 + seed + k as u32)))
            .collect(),
        states: (0..t)
            .map(|k| std::array::from_fn(|i| (k * 8 + i) as f32 * 0.125 + seed as f32))
            .collect(),
        joint_states: (0..t)
            .map(|k| std::array::from_fn(|i| -((k * 7 + i) as f32) * 0.25))
            .collect(),
        actions: (0..t)
            .map(|k| {
                std::array::from_fn(|i| {
                    if i == 6 {
                        1.0
                    } else {
                        (k as f32 - i as f32) / 16.0
                    }
                })
            })
            .collect(),
        instruction: "put the black bowl on the plate".into(),
        rewards: (0..t).map(|k| (k + 1 == t) as u8 as f32).collect(),
        discounts: vec![1.0; t],
        is_first: (0..t).map(|k| k == 0).collect(),
        is_last: (0..t).map(|k| k + 1 == t).collect(),
        is_terminal: (0..t).map(|k| k + 1 == t).collect(),
        file_path: "/data/libero_goal/put_the_bowl_on_the_plate_demo.hdf5".into(),
        depth: extras.then(|| (0..t).map(|k| gray_png(k as u8 * 10)).collect()),
        segmentation: extras.then(|| (0..t).map(|_| gray_png(10)).collect()),
        reasoning: extras.then(|| {
            (0..t)
                .map(|k| {
                    let lab = if k >= 2 {
                        "one: bowl 1 on plate 1"
                    } else {
                        "0"
                    };
                    format!(
                        "bowl:10,[0 0 8 16],{lab}#plate:20,[8 0 4 4],0#robot:30,[0 0 0 0],{lab}"
                    )
                })
                .collect()
        }),
    }
}

#[test]
fn example_round_trips_through_protobuf() {
    let ep = fixture_episode(3, 1, true);
    let bytes = prost::Message::encode_to_vec(&ep.to_example());
    let ex: Example = prost::Message::decode(bytes.as_slice()).unwrap();
    assert_eq!(RldsEpisode::from_example(&ex).unwrap(), ep);
    let mut short = ep.to_example();
    short.insert(
        "steps/action",
        data::example::Kind::FloatList(data::example::FloatList {
            value: vec![0.0; 8],
        }),
    );
    let e = RldsEpisode::from_example(&short).unwrap_err();
    assert!(e.contains("steps/action"), "{e}");
}

#[test]
fn rlds_fixture_converts_to_the_same_numbers() {
    let tmp = tempfile::tempdir().unwrap();
    let eps = vec![
        vec![fixture_episode(5, 1, false), fixture_episode(4, 2, false)],
        vec![fixture_episode(6, 3, true)],
    ];
    write_rlds_dataset(tmp.path(), "libero_goal_no_noops", &eps).unwrap();
    let out = tmp.path().join("out");
    let opts = ConvertOptions {
        index: IndexOptions {
            val_fraction: 0.0,
            seed: 0,
        },
        ..Default::default()
    };
    let rep = convert_rlds(tmp.path(), &out, &opts).unwrap();
    assert_eq!((rep.shards, rep.episodes, rep.steps), (2, 3, 15));
    assert_eq!(rep.flip, Flip::Horizontal);
    assert_eq!(rep.index.episodes.len(), 3);
    let files = [
        ("libero_goal_no_noops_s00000_e0000.mcap", &eps[0][0]),
        ("libero_goal_no_noops_s00000_e0001.mcap", &eps[0][1]),
        ("libero_goal_no_noops_s00001_e0000.mcap", &eps[1][0]),
    ];
    for (f, src) in files {
        let r = EpisodeReader::open(out.join(f)).unwrap();
        assert_eq!(r.meta().task_id, "libero_goal/put_the_bowl_on_the_plate");
        assert_eq!(r.meta().instruction, src.instruction);
        assert_eq!(r.meta().extra["applied_flip"], "hflip");
        let steps = r.read_all().unwrap();
        assert_eq!(steps.len(), src.len());
        for (k, s) in steps.iter().enumerate() {
            assert_eq!(s.state, src.states[k]);
            assert_eq!(s.joint_state, src.joint_states[k]);
            assert_eq!(s.action, src.actions[k]);
            // PNG is lossless: stored pixels = source pixels mirrored left-right
            let mut want = data::imageio::decode_rgb(&src.images[k], "png").unwrap();
            apply_flip(&mut want.data, 16, 16, 3, Flip::Horizontal);
            assert_eq!(s.agentview, want);
        }
        if src.depth.is_some() {
            let s = &steps[3];
            let Some(Segmentation::U16(seg)) = &s.segmentation else {
                panic!("no segmentation")
            };
            // source column 0..8 = 10; mirrored → columns 8..16
            assert_eq!(
                &seg.data[..16],
                &[0, 0, 0, 0, 0, 0, 0, 0, 10, 10, 10, 10, 10, 10, 10, 10]
            );
            assert_eq!(s.depth.as_ref().unwrap().data[15], 30.0 / 255.0);
            assert_eq!(s.objects.len(), 3);
            assert_eq!(s.objects[0].name, "bowl");
            assert_eq!(s.objects[0].bbox, [0.5, 0.0, 0.5, 1.0]); // [0 0 8 16] mirrored
            assert_eq!(s.objects[0].subgoal_label, "one: bowl 1 on plate 1");
            assert_eq!(s.progress.satisfied, 1);
            assert_eq!(steps[1].progress.satisfied, 0);
        }
    }
    // index statistics over all 15 actions
    let a: Vec<f32> = eps
        .iter()
        .flatten()
        .flat_map(|e| e.actions.iter().map(|a| a[0]))
        .collect();
    let mean = a.iter().map(|v| *v as f64).sum::<f64>() / a.len() as f64;
    assert!((rep.index.stats.action.mean[0] as f64 - mean).abs() < 1e-6);
    assert_eq!(rep.index.stats.num_transitions, 15);
    assert_eq!(
        rep.index.stats.action.mask,
        vec![true, true, true, true, true, true, false]
    );
}

#[test]
fn convert_reports_bad_shard_with_offset() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = write_rlds_dataset(
        tmp.path(),
        "libero_mem",
        &[vec![fixture_episode(2, 1, false)]],
    )
    .unwrap();
    let shard = dir.join("libero_mem-train.tfrecord-00000-of-00001");
    let mut b = std::fs::read(&shard).unwrap();
    let n = b.len();
    b[n - 10] ^= 0xff;
    std::fs::write(&shard, b).unwrap();
    let out = tmp.path().join("out");
    let e = convert_rlds(tmp.path(), &out, &ConvertOptions::default()).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("libero_mem-train.tfrecord-00000-of-00001")
            && msg.contains("byte offset")
            && msg.contains("CRC"),
        "{msg}"
    );
    assert_eq!(e.exit_code(), 2);
    assert!(!out.join("index.json").exists());
}

#[test]
fn auto_flip_and_box_flip() {
    assert_eq!(auto_flip("libero_mem"), Flip::None);
    assert_eq!(auto_flip("libero_10_no_noops"), Flip::Horizontal);
    assert_eq!(auto_flip("bridge"), Flip::None);
    assert_eq!(
        flip_box([0.25, 0.5, 0.25, 0.25], Flip::Rotate180),
        [0.5, 0.25, 0.25, 0.25]
    );
    let objs = parse_reasoning(
        "bowl:10,[0 64 128 64],two: bowl 1 on plate 1#robot:30,[1 2 3 4],0",
        256,
        256,
    )
    .unwrap();
    assert_eq!(objs[0].bbox, [0.0, 0.25, 0.5, 0.25]);
    assert_eq!(objs[0].subgoal_label, "two: bowl 1 on plate 1");
    assert_eq!(objs[1].instance_id, 30);
    assert!(parse_reasoning("pick up the bowl", 256, 256).is_none());
    // 180° = vertical then horizontal
    let mut a: Vec<u8> = (0..12).collect();
    apply_flip(&mut a, 2, 2, 3, Flip::Rotate180);
    assert_eq!(a, vec![9, 10, 11, 6, 7, 8, 3, 4, 5, 0, 1, 2]);
}
