//! Windows: edge padding, action chunks, normalisation, determinism of augmentation.

use data::synth::{SynthOptions, synthetic_meta, synthetic_steps};
use data::window::ActionNorm;
use data::*;

fn dataset(lens: &[usize]) -> (tempfile::TempDir, Vec<Vec<StepRecord>>) {
    dataset_with(lens, |_, _| {})
}

/// Synthetic episodes of `lens` steps, each edited by `edit(episode, steps)` before it is written.
fn dataset_with(
    lens: &[usize],
    edit: impl Fn(usize, &mut [StepRecord]),
) -> (tempfile::TempDir, Vec<Vec<StepRecord>>) {
    let dir = tempfile::tempdir().unwrap();
    let mut all = vec![];
    for (e, &n) in lens.iter().enumerate() {
        let mut steps = synthetic_steps(
            n,
            e as u64,
            &SynthOptions {
                size: 16,
                segmentation: false,
                depth: false,
            },
        );
        edit(e, &mut steps);
        let mut w = EpisodeWriter::create(
            dir.path().join(format!("ep{e}.mcap")),
            synthetic_meta(e as u64),
            WriterOptions::default(),
        )
        .unwrap();
        for s in &steps {
            w.write_step(s).unwrap();
        }
        w.finish().unwrap();
        all.push(steps);
    }
    build_index(
        dir.path(),
        &IndexOptions {
            val_fraction: 0.0,
            seed: 0,
        },
    )
    .unwrap();
    (dir, all)
}

/// The train split of `dir` in chunks of 4 frames (p = 3) with 2-step action chunks and no images,
/// and the same with `variant` applied to that config.
fn plain_and(
    dir: &std::path::Path,
    variant: impl FnOnce(WindowConfig) -> WindowConfig,
) -> (WindowDataset, WindowDataset) {
    let cfg = WindowConfig {
        past: 3,
        future: 0,
        chunk: 2,
        image_size: 16,
        images: false,
        ..Default::default()
    };
    let open = |c| WindowDataset::open(dir, Split::Train, c).unwrap();
    (open(cfg.clone()), open(variant(cfg)))
}

#[test]
fn normalisation_is_exact() {
    let n = ActionNorm {
        q01: [0.0, -1.0, -2.0, 0.0, 0.0, 0.0, 0.0],
        q99: [2.0, 1.0, 2.0, 1.0, 1.0, 1.0, 1.0],
        mask: [true, true, true, true, true, true, false],
    };
    let a = [1.5, 0.25, 3.0, -5.0, 0.5, 0.0, -1.0];
    assert_eq!(n.normalize(&a), [0.5, 0.25, 1.0, -1.0, 0.0, -1.0, -1.0]);
    assert_eq!(
        n.denormalize(&[0.5, 0.25, 1.0, -1.0, 0.0, -1.0, -1.0]),
        [1.5, 0.25, 2.0, 0.0, 0.5, 0.0, -1.0]
    );
}

#[test]
fn edge_frames_are_repeated_with_mask() {
    let (dir, eps) = dataset(&[10, 7]);
    let cfg = WindowConfig {
        past: 3,
        future: 2,
        chunk: 3,
        image_size: 16,
        ..Default::default()
    };
    let ds = WindowDataset::open(dir.path(), Split::Train, cfg).unwrap();
    assert_eq!(ds.len(), 17);
    let norm = ds.action_norm().clone();
    // first step of episode 0
    let s = ds.get(0).unwrap();
    assert_eq!((s.episode, s.t), (0, 0));
    assert_eq!(s.frame_steps, vec![0, 0, 0, 0, 1, 2]);
    assert_eq!(s.frame_mask, vec![false, false, false, true, true, true]);
    assert_eq!(s.images.len(), 6 * 3 * 16 * 16);
    // image of frame j = step frame_steps[j], [3, H, W] in [0, 1], exact (PNG, no resize)
    let hw = 16 * 16;
    for j in 0..6 {
        let src = &eps[0][s.frame_steps[j]].agentview;
        let px = 5 * 16 + 7;
        for ch in 0..3 {
            assert_eq!(
                s.images[j * 3 * hw + ch * hw + px],
                src.data[px * 3 + ch] as f32 / 255.0
            );
        }
    }
    // last step of episode 0
    let s = ds.get(9).unwrap();
    assert_eq!(s.frame_steps, vec![6, 7, 8, 9, 9, 9]);
    assert_eq!(s.frame_mask, vec![true, true, true, true, false, false]);
    // chunks: frame 8 → actions 8, 9, 9 (mask T, T, F); frame 9 → 9, 9, 9 (T, F, F)
    let chunk = |j: usize, h: usize| &s.actions[(j * 3 + h) * 7..(j * 3 + h + 1) * 7];
    assert_eq!(chunk(2, 0), norm.normalize(&eps[0][8].action));
    assert_eq!(chunk(2, 1), norm.normalize(&eps[0][9].action));
    assert_eq!(chunk(2, 2), norm.normalize(&eps[0][9].action));
    assert_eq!(
        &s.action_mask[6..12],
        &[true, true, false, true, false, false]
    );
    assert_eq!(&s.states[3 * 8..4 * 8], &eps[0][9].state);
    // The goal a frame observes is the one recorded with the step before it (recorded after
    // that step's action): frame 6 sees step 5's progress.
    assert_eq!(s.goals[0], eps[0][5].progress);
    assert_eq!(s.goals[3], eps[0][8].progress);
    assert_eq!(s.objects[3], eps[0][9].objects);
    // gripper untouched by normalisation
    assert_eq!(chunk(0, 0)[6], eps[0][6].action[6]);
    // second episode, middle
    let s = ds.get(10 + 4).unwrap();
    assert_eq!((s.episode, s.t), (1, 4));
    assert_eq!(s.frame_steps, vec![1, 2, 3, 4, 5, 6]);
    assert!(s.frame_mask.iter().all(|m| *m));
    assert_eq!(s.goals[1], eps[1][1].progress);
    // Step 0 observes the reset's progress: nothing satisfied yet.
    let s = ds.get(10).unwrap();
    assert_eq!(s.frame_steps[..3], [0, 0, 0]);
    assert_eq!(s.goals[0].satisfied, 0);
    assert!(s.goals[0].satisfied_subgoals.is_empty());
}

#[test]
fn observed_progress_at_step_zero_undoes_an_early_satisfaction() {
    use data::window::observed_progress;
    let after = GoalProgress {
        satisfied: 1,
        total: 3,
        satisfied_subgoals: vec!["one: bowl 1 on plate 1".into()],
        current_subgoal: "bowl 2 on plate 1".into(),
    };
    let seen = observed_progress(None, &after);
    assert_eq!(seen.satisfied, 0);
    assert_eq!(seen.total, 3);
    assert!(seen.satisfied_subgoals.is_empty());
    assert_eq!(seen.current_subgoal, "one: bowl 1 on plate 1");
    assert_eq!(
        observed_progress(Some(&after), &GoalProgress::default()),
        after
    );
}

#[test]
fn augmentation_is_seeded_and_resize_works() {
    let (dir, _) = dataset(&[12]);
    let cfg = WindowConfig {
        past: 4,
        future: 0,
        chunk: 2,
        image_size: 8,
        augment: Some(Augment::default()),
        seed: 5,
        ..Default::default()
    };
    let ds = WindowDataset::open(dir.path(), Split::Train, cfg.clone()).unwrap();
    let a = ds.get_with_epoch(6, 0).unwrap();
    assert_eq!(a.images.len(), 5 * 3 * 8 * 8);
    assert!(a.images.iter().all(|v| (0.0..=1.0).contains(v)));
    let ds2 = WindowDataset::open(dir.path(), Split::Train, cfg.clone()).unwrap();
    assert_eq!(
        ds2.get_with_epoch(6, 0).unwrap(),
        a,
        "same seed → same sample"
    );
    let b = ds.get_with_epoch(6, 1).unwrap();
    assert_ne!(a.images, b.images, "another epoch → another augmentation");
    let ds3 = WindowDataset::open(
        dir.path(),
        Split::Train,
        WindowConfig {
            augment: None,
            ..cfg
        },
    )
    .unwrap();
    assert_ne!(ds3.get(6).unwrap().images, a.images);
    // parallel batch equals sequential samples
    let many = ds.get_many(&[0, 3, 6, 11]).unwrap();
    assert_eq!(many[2], a);
    assert!(ds.get(12).is_err());
}

#[test]
fn zero_jitter_augmentation_is_identity() {
    let (dir, _) = dataset(&[5]);
    let still = Augment {
        brightness: 0.0,
        contrast: 0.0,
        saturation: 0.0,
        hue: 0.0,
        max_shift: 0,
    };
    let cfg = WindowConfig {
        past: 1,
        future: 0,
        chunk: 1,
        image_size: 16,
        augment: Some(still),
        ..Default::default()
    };
    let a = WindowDataset::open(dir.path(), Split::Train, cfg.clone())
        .unwrap()
        .get(3)
        .unwrap();
    let b = WindowDataset::open(
        dir.path(),
        Split::Train,
        WindowConfig {
            augment: None,
            ..cfg
        },
    )
    .unwrap()
    .get(3)
    .unwrap();
    let max = a
        .images
        .iter()
        .zip(&b.images)
        .map(|(x, y)| (x - y).abs())
        .fold(0f32, f32::max);
    assert!(max < 1e-5, "max difference {max}");
}

#[test]
fn chunks_walk_an_episode_and_mask_past_its_end() {
    let (dir, eps) = dataset(&[10, 7]);
    let cfg = WindowConfig {
        past: 3,
        future: 0,
        chunk: 2,
        image_size: 16,
        ..Default::default()
    };
    let ds = WindowDataset::open(dir.path(), Split::Train, cfg.clone()).unwrap();
    assert_eq!(ds.num_episodes(), 2);
    assert_eq!((ds.episode_len(0), ds.episode_len(1)), (10, 7));
    // A chunk from step 4 is the window ending at step 7.
    let c = ds.chunk(0, 4, 0).unwrap();
    assert_eq!(c.frame_steps, vec![4, 5, 6, 7]);
    assert!(c.frame_mask.iter().all(|m| *m));
    assert_eq!(c, ds.get(7).unwrap());
    // The last chunk of episode 1 (steps 4..8) runs past its end: masked, last frame repeated.
    let c = ds.chunk(1, 4, 0).unwrap();
    assert_eq!(c.frame_steps, vec![4, 5, 6, 6]);
    assert_eq!(c.frame_mask, vec![true, true, true, false]);
    assert_eq!(c.goals[1], eps[1][4].progress);
    assert!(ds.chunk(1, 7, 0).is_err());
    assert!(ds.chunk(2, 0, 0).is_err());
    // With augmentation, every chunk of one episode pass is augmented alike.
    let aug = WindowDataset::open(
        dir.path(),
        Split::Train,
        WindowConfig {
            augment: Some(Augment::default()),
            seed: 3,
            ..cfg
        },
    )
    .unwrap();
    let plain = |start: usize| ds.chunk(0, start, 0).unwrap().images;
    let (a0, a4) = (aug.chunk(0, 0, 0).unwrap(), aug.chunk(0, 4, 0).unwrap());
    // The same step seen through two chunk starts gets the same augmentation.
    let a2 = aug.chunk(0, 2, 0).unwrap();
    let frame = |s: &WindowSample, j: usize| s.images[j * 3 * 256..(j + 1) * 3 * 256].to_vec();
    assert_eq!(
        frame(&a0, 2),
        frame(&a2, 0),
        "step 2 augmented alike in both chunks"
    );
    assert_eq!(
        frame(&a2, 2),
        frame(&a4, 0),
        "step 4 augmented alike in both chunks"
    );
    assert_ne!(a0.images, plain(0));
    assert_ne!(
        aug.chunk(0, 0, 1).unwrap().images,
        a0.images,
        "another pass, another draw"
    );
}

/// A dataset opened once ([`data::OpenedDataset`]) gives the same windows as each split
/// opening its own, and the first damaged file in index order is the error whatever order the
/// threads read in.
#[test]
fn windows_of_a_dataset_opened_once_equal_windows_of_the_split() {
    let (dir, _) = dataset(&[6, 9, 4, 7]);
    let index = DatasetIndex::load(dir.path()).unwrap();
    let cfg = WindowConfig {
        past: 2,
        future: 0,
        chunk: 2,
        image_size: 8,
        ..Default::default()
    };
    let opened = data::OpenedDataset::open(dir.path()).unwrap();
    assert_eq!(opened.index, index);
    let files: Vec<_> = opened
        .episodes()
        .into_iter()
        .map(|(_, p, r)| (p, r.len()))
        .collect();
    assert_eq!(files.len(), 4);
    assert_eq!(files[1].0, dir.path().join(&index.episodes[1].file));
    assert_eq!(files.iter().map(|f| f.1).collect::<Vec<_>>(), [6, 9, 4, 7]);
    let a = WindowDataset::from_opened(&opened, Split::Train, cfg.clone()).unwrap();
    let b = WindowDataset::from_index(dir.path(), &index, Split::Train, cfg.clone()).unwrap();
    assert_eq!(a.len(), 26);
    assert_eq!(a.len(), b.len());
    for k in 0..a.len() {
        assert_eq!(a.get(k).unwrap(), b.get(k).unwrap(), "sample {k}");
    }
    // Damage the second and the fourth episode: the second is named.
    for e in [&index.episodes[1], &index.episodes[3]] {
        let p = dir.path().join(&e.file);
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    }
    let err = data::OpenedDataset::open(dir.path())
        .unwrap_err()
        .to_string();
    assert!(err.contains(&index.episodes[1].file), "{err}");
    assert!(!err.contains(&index.episodes[3].file), "{err}");
}

#[test]
fn idle_tail_is_the_still_suffix_with_one_gripper_command() {
    use data::window::idle_tail_start;
    let mv = [0.1, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0];
    let still = |g: f32| [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, g];
    let tiny = [5e-5, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0];
    assert_eq!(idle_tail_start(&[]), 0);
    assert_eq!(
        idle_tail_start(&[mv, mv]),
        2,
        "the last step moves: no tail"
    );
    assert_eq!(idle_tail_start(&[still(-1.0); 3]), 0, "all still: all tail");
    assert_eq!(
        idle_tail_start(&[mv, still(1.0), still(-1.0), tiny, still(-1.0)]),
        2,
        "a gripper change ends the tail; arm norms ≤ 1e-4 count as still"
    );
    assert_eq!(
        idle_tail_start(&[mv, still(-1.0), [2e-4, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0]]),
        3
    );
}

#[test]
fn masked_idle_tail_leaves_the_frames_but_drops_their_actions() {
    // Two episodes of 12 steps; episode 0 stands still (gripper open) from step 8 on.
    let (dir, _) = dataset_with(&[12, 12], |e, steps| {
        for s in steps.iter_mut() {
            s.action[0] = 0.5; // every synthetic step moves
        }
        if e == 0 {
            for s in &mut steps[8..] {
                s.action = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0];
            }
        }
    });
    let (plain, masked) = plain_and(dir.path(), |c| WindowConfig {
        mask_idle_tail: true,
        ..c
    });
    let ep0 = (0..2)
        .find(|&k| masked.chunk(k, 0, 0).unwrap().episode == 0)
        .unwrap();
    assert_eq!(masked.idle_tail(ep0), Some(8));
    assert_eq!(masked.idle_tail(1 - ep0), Some(12));
    assert_eq!(plain.idle_tail(ep0), None, "not read unless masked");
    // The chunk of steps 6..10: frames 6, 7, 8, 9 with actions (f, f+1).
    let (p, m) = (
        plain.chunk(ep0, 6, 0).unwrap(),
        masked.chunk(ep0, 6, 0).unwrap(),
    );
    assert_eq!(m.frame_steps, vec![6, 7, 8, 9]);
    assert_eq!(p.action_mask, vec![true; 8]);
    assert_eq!(
        m.action_mask,
        vec![true, true, true, false, false, false, false, false]
    );
    assert_eq!(p.action_weights, vec![1.0; 8]);
    assert_eq!(
        m.action_weights,
        vec![1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    );
    assert_eq!(
        (m.frame_mask, m.actions, m.states),
        (p.frame_mask, p.actions, p.states)
    );
    // The other episode has no tail: nothing changes.
    assert_eq!(
        masked.chunk(1 - ep0, 6, 0).unwrap(),
        plain.chunk(1 - ep0, 6, 0).unwrap()
    );
}

#[test]
fn a_weighted_idle_tail_keeps_its_actions_at_that_weight_and_nothing_past_the_end() {
    // One episode of 12 steps standing still (gripper closed) from step 7 on.
    let (dir, _) = dataset_with(&[12], |_, steps| {
        for s in steps.iter_mut() {
            s.action[0] = 0.5;
        }
        for s in &mut steps[7..] {
            s.action = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        }
    });
    let (_, weighted) = plain_and(dir.path(), |c| WindowConfig {
        mask_idle_tail: true,
        idle_tail_weight: 0.25,
        ..c
    });
    let masked = WindowDataset::open(
        dir.path(),
        Split::Train,
        WindowConfig {
            idle_tail_weight: 0.0,
            ..weighted.config().clone()
        },
    )
    .unwrap();
    assert_eq!(weighted.idle_tail(0), Some(7));
    // Frames 6..10 with actions (f, f+1): step 6 moves, 7..11 stand still.
    let (m, w) = (
        masked.chunk(0, 6, 0).unwrap(),
        weighted.chunk(0, 6, 0).unwrap(),
    );
    assert_eq!(w.action_mask, m.action_mask);
    assert_eq!(
        w.action_mask,
        vec![true, false, false, false, false, false, false, false]
    );
    assert_eq!(
        w.action_weights,
        vec![1.0, 0.25, 0.25, 0.25, 0.25, 0.25, 0.25, 0.25]
    );
    assert_eq!(
        m.action_weights,
        vec![1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    );
    assert_eq!((&w.actions, &w.states), (&m.actions, &m.states));
    // Frames 10, 11 and two past the end (frame 11 repeated, masked as frames): step 12 and on
    // weigh nothing, as the action mask leaves them out.
    let e = weighted.chunk(0, 10, 0).unwrap();
    assert_eq!(e.frame_mask, vec![true, true, false, false]);
    assert_eq!(e.frame_steps, vec![10, 11, 11, 11]);
    assert_eq!(
        e.action_weights,
        vec![0.25, 0.25, 0.25, 0.0, 0.25, 0.0, 0.25, 0.0]
    );
}

#[test]
fn gripper_switches_weigh_their_step_and_its_neighbours() {
    // One episode of 12 steps: the gripper closes at step 4 and opens at step 9.
    let (dir, _) = dataset_with(&[12], |_, steps| {
        for (i, s) in steps.iter_mut().enumerate() {
            s.action[0] = 0.5;
            s.action[6] = if (4..9).contains(&i) { 1.0 } else { -1.0 };
        }
    });
    let actions: Vec<[f32; 7]> = (0..12)
        .map(|i| {
            let g = if (4..9).contains(&i) { 1.0 } else { -1.0 };
            [0.5, 0.0, 0.0, 0.0, 0.0, 0.0, g]
        })
        .collect();
    assert_eq!(data::window::gripper_switches(&actions), vec![4, 9]);
    assert!(data::window::gripper_switches(&actions[..4]).is_empty());
    let (plain, weighted) = plain_and(dir.path(), |c| WindowConfig {
        switch_weight: 3.0,
        ..c
    });
    // Frames 2..6 with actions (f, f+1): steps 3, 4, 5 are the close's.
    let (p, w) = (
        plain.chunk(0, 2, 0).unwrap(),
        weighted.chunk(0, 2, 0).unwrap(),
    );
    assert_eq!(w.frame_steps, vec![2, 3, 4, 5]);
    assert_eq!(p.action_weights, vec![1.0; 8]);
    //                         f=2: 2, 3   f=3: 3, 4   f=4: 4, 5   f=5: 5, 6
    assert_eq!(
        w.action_weights,
        vec![1.0, 3.0, 3.0, 3.0, 3.0, 3.0, 3.0, 1.0]
    );
    assert_eq!(
        (&w.actions, &w.action_mask, &w.states),
        (&p.actions, &p.action_mask, &p.states)
    );
    // With the idle tail weighted too, a switch's factor multiplies the tail's weight. The
    // open at 9 stands still from then on (the tail: steps 9..12 once the arm stops there).
    let (dir, _) = dataset_with(&[12], |_, steps| {
        for (i, s) in steps.iter_mut().enumerate() {
            s.action[0] = 0.5;
            s.action[6] = if (4..9).contains(&i) { 1.0 } else { -1.0 };
            if i >= 9 {
                s.action = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0];
            }
        }
    });
    let (_, both) = plain_and(dir.path(), |c| WindowConfig {
        mask_idle_tail: true,
        idle_tail_weight: 0.5,
        switch_weight: 3.0,
        ..c
    });
    assert_eq!(both.idle_tail(0), Some(9));
    let b = both.chunk(0, 7, 0).unwrap();
    assert_eq!(b.frame_steps, vec![7, 8, 9, 10]);
    //                         f=7: 7, 8   f=8: 8, 9   f=9: 9, 10  f=10: 10, 11
    assert_eq!(
        b.action_weights,
        vec![1.0, 3.0, 3.0, 1.5, 1.5, 1.5, 1.5, 0.5]
    );
}

#[test]
fn state_noise_moves_positions_only_and_is_the_same_for_a_frame_in_every_chunk() {
    // Give one object an articulated part, so parts are perturbed too.
    let (dir, _) = dataset_with(&[12], |_, steps| {
        for s in steps.iter_mut() {
            let o = s
                .objects
                .iter_mut()
                .find(|o| o.pose.is_some())
                .expect("synthetic steps have a posed object");
            o.parts = vec![PartState {
                name: "handle".into(),
                pose: [0.3, 0.2, 1.0, 1.0, 0.0, 0.0, 0.0],
                joint: 0.05,
            }];
        }
    });
    let sigma = 0.01;
    let (plain, noisy) = plain_and(dir.path(), |c| WindowConfig {
        state_noise: sigma,
        ..c
    });
    let (p, m) = (plain.chunk(0, 4, 0).unwrap(), noisy.chunk(0, 4, 0).unwrap());
    // Same seed, same noise; actions, masks and labels untouched.
    assert_eq!(m, noisy.chunk(0, 4, 0).unwrap());
    assert_eq!(
        (&m.actions, &m.action_mask, &m.frame_mask),
        (&p.actions, &p.action_mask, &p.frame_mask)
    );
    let mut deltas = vec![];
    for (f, (ps, ms)) in p.states.chunks(8).zip(m.states.chunks(8)).enumerate() {
        // The eef moves, the rest of the proprio state does not.
        assert_eq!(&ps[3..], &ms[3..], "frame {f}");
        deltas.extend((0..3).map(|d| ms[d] - ps[d]));
        for (po, mo) in p.objects[f].iter().zip(&m.objects[f]) {
            assert_eq!(
                (&po.name, po.bbox, &po.subgoal_label),
                (&mo.name, mo.bbox, &mo.subgoal_label)
            );
            match (po.pose, mo.pose) {
                (Some(a), Some(b)) => {
                    assert_eq!(a[3..], b[3..], "orientation kept");
                    deltas.extend((0..3).map(|d| b[d] - a[d]));
                    let (pa, pb) = (&po.parts[0], &mo.parts[0]);
                    assert_eq!(
                        (pa.joint, pa.pose[3..].to_vec()),
                        (pb.joint, pb.pose[3..].to_vec())
                    );
                    deltas.extend((0..3).map(|d| pb.pose[d] - pa.pose[d]));
                }
                (None, None) => {}
                other => panic!("pose presence changed: {other:?}"),
            }
        }
    }
    assert!(
        deltas.iter().all(|d| *d != 0.0 && d.abs() < 6.0 * sigma),
        "{deltas:?}"
    );
    // Chunks starting at 4 and at 6 share frames 6 and 7 (the second's past): same noise there.
    let later = noisy.chunk(0, 6, 0).unwrap();
    let at = |s: &WindowSample, step: usize| s.frame_steps.iter().position(|&f| f == step).unwrap();
    for step in [6, 7] {
        let (i, j) = (at(&m, step), at(&later, step));
        assert_eq!(m.states[i * 8..i * 8 + 8], later.states[j * 8..j * 8 + 8]);
        assert_eq!(m.objects[i], later.objects[j]);
    }
    // Another epoch draws other noise.
    assert_ne!(noisy.chunk(0, 4, 1).unwrap().states, m.states);
}

#[test]
fn perturbed_positions_have_the_asked_spread() {
    let mut d = vec![];
    for seed in 0..2000u64 {
        let mut s = [0.0f32; 8];
        data::window::perturb_positions(0.02, seed, &mut s, &mut []);
        d.extend_from_slice(&s[..3]);
        assert_eq!(s[3..], [0.0; 5]);
    }
    let n = d.len() as f32;
    let mean = d.iter().sum::<f32>() / n;
    let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f32>() / n).sqrt();
    assert!(
        mean.abs() < 0.001 && (sd - 0.02).abs() < 0.001,
        "mean {mean}, sd {sd}"
    );
}

#[test]
fn pointer_targets_reach_the_grasped_object_then_aim_at_the_place() {
    // The bowl (object 0) is held at steps 4..=7 and let go 5 cm from the plate (object 1).
    let (dir, _) = dataset_with(&[12], |_, steps| {
        for (k, s) in steps.iter_mut().enumerate() {
            s.objects[0].grasped = Some((4..=7).contains(&k));
            s.objects[1].pose = Some([0.1, 0.12, 0.9, 1.0, 0.0, 0.0, 0.0]);
        }
    });
    let (plain, ptr) = plain_and(dir.path(), |c| WindowConfig {
        pointer_targets: true,
        ..c
    });
    assert!(
        plain.chunk(0, 0, 0).unwrap().targets.is_empty(),
        "off by default"
    );
    // Off beside another per-episode scan (the idle tail's): still none.
    let (_, tail) = plain_and(dir.path(), |c| WindowConfig {
        mask_idle_tail: true,
        ..c
    });
    assert!(tail.chunk(0, 0, 0).unwrap().targets.is_empty());
    // Frames 2..=5: reaching (0) at 2 and 3, carrying towards the plate (1) at 4 and 5.
    let c = ptr.chunk(0, 2, 0).unwrap();
    assert_eq!(c.frame_steps, vec![2, 3, 4, 5]);
    assert_eq!(c.targets, vec![Some(0), Some(0), Some(1), Some(1)]);
    // After the last grasp: none.
    assert_eq!(ptr.chunk(0, 8, 0).unwrap().targets, vec![None; 4]);
}

#[test]
fn pointer_targets_on_episodes_without_grasps_are_an_error() {
    // The synthetic bowl is touched for single steps only: brushes, not grasps.
    let (dir, _) = dataset_with(&[12], |_, _| {});
    let cfg = WindowConfig {
        past: 3,
        chunk: 2,
        image_size: 16,
        images: false,
        pointer_targets: true,
        ..Default::default()
    };
    let e = WindowDataset::open(dir.path(), Split::Train, cfg)
        .err()
        .expect("no grasps")
        .to_string();
    assert!(
        e.contains("ep0.mcap") && e.contains("record no grasps"),
        "{e}"
    );
}

/// Writes `steps` as `dir/name` with `labelled_from` in the metadata (none: key absent).
fn write_labelled(dir: &std::path::Path, name: &str, steps: &[StepRecord], from: Option<&str>) {
    let mut meta = synthetic_meta(0);
    if let Some(v) = from {
        meta.extra.insert(LABELLED_FROM.into(), v.into());
    }
    let mut w = EpisodeWriter::create(dir.join(name), meta, WriterOptions::default()).unwrap();
    for s in steps {
        w.write_step(s).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn steps_before_a_take_over_weigh_nothing_and_stay_out_of_the_statistics() {
    let opts = SynthOptions {
        size: 16,
        segmentation: false,
        depth: false,
    };
    let steps = synthetic_steps(12, 0, &opts);
    // The same episode twice: as demonstrated, and with a policy's (wild) actions before step 5.
    let mut taken_over = steps.clone();
    for s in &mut taken_over[..5] {
        s.action[0] = 50.0;
    }
    // The statistics see what a dataset of the demonstration and the labelled suffix would.
    let plain_dir = tempfile::tempdir().unwrap();
    write_labelled(plain_dir.path(), "a.mcap", &steps, None);
    let mut suffix = steps[5..].to_vec();
    for (i, s) in suffix.iter_mut().enumerate() {
        s.step = i as u64;
    }
    write_labelled(plain_dir.path(), "b.mcap", &suffix, None);
    let dir = tempfile::tempdir().unwrap();
    write_labelled(dir.path(), "a.mcap", &steps, None);
    write_labelled(dir.path(), "b.mcap", &taken_over, Some("5"));
    let opts = IndexOptions {
        val_fraction: 0.0,
        seed: 0,
    };
    let (plain, both) = (
        build_index(plain_dir.path(), &opts).unwrap(),
        build_index(dir.path(), &opts).unwrap(),
    );
    assert!(both.stats.action.max[0] < 50.0);
    assert_eq!(both.stats.action, plain.stats.action);
    assert_eq!(both.stats.num_transitions, plain.stats.num_transitions);
    // Frames 1–4 of each with actions (f, f + 1): the taken-over one's weights are 0 below step 5.
    let (_, ds) = plain_and(dir.path(), |c| c);
    let (a, b) = (ds.chunk(0, 1, 0).unwrap(), ds.chunk(1, 1, 0).unwrap());
    assert_eq!(b.frame_steps, vec![1, 2, 3, 4]);
    assert_eq!(a.action_weights, vec![1.0; 8]);
    assert_eq!(
        b.action_weights,
        vec![0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    );
    assert_eq!(b.action_mask, a.action_mask, "the frames stay real steps");
    assert_eq!(ds.chunk(1, 5, 0).unwrap().action_weights, vec![1.0; 8]);
    // Not a step number: one error naming the file and the key.
    write_labelled(dir.path(), "c.mcap", &steps, Some("five"));
    let err = build_index(dir.path(), &opts).unwrap_err().to_string();
    assert!(
        err.contains("c.mcap") && err.contains("labelled_from = \"five\""),
        "{err}"
    );
}
