//! The shipped neural dancer end to end: the model built into danced, the streaming analysis of
//! a song fed with the model's look-ahead, and the motion it samples.

mod common;

#[global_allocator]
static ALLOCATOR: daemon::alloc_counter::CountingAllocator =
    daemon::alloc_counter::CountingAllocator;

use model::metrics::{ContactParams, FreezeParams, JointTrack, detect_freezes, foot_skating};
use model::neural::dancer::NeuralDancer;
use model::rig::{JOINT_COUNT, Pose, Skeleton};
use model::source::{Controls, MotionSource};

/// Held by each allocation proof of this file: the counter's tallies are per kind of thread,
/// not per test, so one proof's planted allocation would land in another's count when the
/// test harness runs them at once.
static ALLOCATION_PROOF: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Dances `seconds` of the demo song with the shipped model at `temperature`; returns the poses
/// (25 fps) and the held (non-finite or exploding) frames.
fn dance_to_demo(seconds: f64, temperature: f32, seed: u64) -> (Vec<Pose>, u64) {
    dance_to_demo_with(seconds, temperature, seed, |_| {})
}

/// [`dance_to_demo`] with the dancer's settings changed by `configure`.
fn dance_to_demo_with(
    seconds: f64,
    temperature: f32,
    seed: u64,
    configure: impl FnOnce(&mut NeuralDancer),
) -> (Vec<Pose>, u64) {
    let model = daemon::dancer::load_model(None).expect("the built-in model loads");
    let mut dancer: NeuralDancer = daemon::dancer::neural_dancer(&model, seed).unwrap();
    configure(&mut dancer);
    let (poses, _) = common::dance_to_demo(&mut dancer, seconds, temperature, seed);
    (poses, dancer.report().safety.map_or(0, |c| c.held))
}

#[test]
fn shipped_model_says_what_it_was_trained_on() {
    let bytes = daemon::dancer::SHIPPED_MODEL;
    assert!(bytes.len() <= 20 << 20, "{} bytes", bytes.len());
    let model = daemon::dancer::load_model(None).unwrap();
    let t = &model.training;
    assert!(t.data.contains("tang2018"), "{t:?}");
    assert!(t.recipe.starts_with("danced-train dancer "), "{t:?}");
    assert_eq!(t.dances, 30, "{t:?}");
    assert!(t.frames > 40_000 && t.steps > 1000, "{t:?}");
    // Trained on the music as live delivers it: predicted over the data horizon, no look-ahead.
    assert_eq!(
        t.horizon_frames,
        model::horizon::data_horizon(25.0),
        "{t:?}"
    );
    assert_eq!(model.config.lookahead, 0);
}

#[test]
fn damaged_model_file_is_named_in_the_error() {
    let dir = std::env::temp_dir().join(format!("danced-model-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("cut.dnn");
    let bytes = daemon::dancer::SHIPPED_MODEL;
    std::fs::write(&path, &bytes[..bytes.len() / 2]).unwrap();
    let err = format!("{:#}", daemon::dancer::load_model(Some(&path)).unwrap_err());
    assert!(
        err.contains("cut.dnn") && err.contains("truncated"),
        "{err}"
    );
    let mut flipped = bytes.to_vec();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x40;
    std::fs::write(&path, &flipped).unwrap();
    let err = format!("{:#}", daemon::dancer::load_model(Some(&path)).unwrap_err());
    assert!(err.contains("corrupted"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn shipped_model_dances_the_demo_song_with_hardly_a_held_frame() {
    // A held frame (a sample the flow blew up, replaced by the last good pose) is a safety
    // net acting: rare, counted, never a freeze. Over 12 seeds at T = 0.5 and 1 (18 000
    // frames) D held 8, K2 1, K2R (shipped now) 8; more than 1 in 1 000 is a regression.
    let skeleton = Skeleton::default_adult();
    let mut held = 0;
    let mut frames = 0;
    for seed in 1..=12 {
        for temperature in [0.5, 1.0] {
            let (poses, h) = dance_to_demo(30.0, temperature, seed);
            assert!(poses.iter().all(Pose::is_finite));
            held += h;
            frames += poses.len() as u64;
            let positions = skeleton.trajectory(&poses);
            // Hips stay at a standing dancer's height (the rig's hips are at 0.93 m).
            for f in positions.chunks_exact(JOINT_COUNT) {
                assert!((0.6..1.3).contains(&f[0].y), "hips at {} m", f[0].y);
            }
            let track = JointTrack::new(&positions, JOINT_COUNT, 25.0).unwrap();
            let freezes = detect_freezes(&track, FreezeParams::default()).unwrap();
            assert_eq!(
                freezes.freezes, 0,
                "seed {seed}, T {temperature}: {freezes:?}"
            );
        }
    }
    assert!(held * 1000 <= frames, "{held} held of {frames} frames");
}

#[test]
fn temperature_and_seed_shape_the_samples() {
    let (a, _) = dance_to_demo(8.0, 0.0, 1);
    let (b, _) = dance_to_demo(8.0, 0.0, 2);
    let (c, _) = dance_to_demo(8.0, 1.0, 1);
    let (d, _) = dance_to_demo(8.0, 1.0, 2);
    let (e, _) = dance_to_demo(8.0, 1.0, 2);
    let differ = |x: &[Pose], y: &[Pose]| common::frames_differing(x, y, 0.9999);
    assert_eq!(
        differ(&a, &b),
        0,
        "T = 0 is the mode path, whatever the seed"
    );
    assert_eq!(differ(&d, &e), 0, "a seed reproduces");
    assert!(differ(&c, &d) > 100, "T = 1 depends on the seed");
}

#[test]
fn the_network_alone_moves_on_the_beat() {
    // Every safety net off (the beat accent with them): the shipped network learned to slow
    // into the beat from the beat phase it hears, on a song it never trained on. At T = 0,
    // where it dances without a held frame (at T = 0.5 and above, alone, some seeds run off
    // the data within the 40 s; the restart net is there for that).
    let (alone, held) = dance_to_demo_with(40.0, 0.0, 1, |d| {
        d.set_safety_nets(model::neural::safety::SafetyNets::NETWORK_ONLY)
    });
    let (_, beats) = common::demo_music(40.0, 25.0);
    let (on, off) = common::beat_align_on_and_off(&alone, &beats);
    eprintln!("BeatAlign of the network alone on / off the beat: {on:.3} / {off:.3}, {held} held");
    assert_eq!(held, 0);
    assert!(on > off + 0.1, "on {on:.3} vs off {off:.3}");
}

#[test]
fn beat_accent_puts_the_moves_on_the_beat() {
    let (accented, _) = dance_to_demo_with(40.0, 0.5, 3, |d| d.set_beat_accent(0.3));
    let (_, beats) = common::demo_music(40.0, 25.0);
    let (on, off) = common::beat_align_on_and_off(&accented, &beats);
    let (own, _) = dance_to_demo_with(40.0, 0.5, 3, |d| d.set_beat_accent(0.0));
    let (own_on, own_off) = common::beat_align_on_and_off(&own, &beats);
    eprintln!(
        "BeatAlign on / off the beat: accented {on:.3} / {off:.3}, own timing {own_on:.3} / {own_off:.3}"
    );
    assert!(on > off + 0.1, "on {on:.3} vs off {off:.3}");
    assert!(
        on > own_on + 0.05,
        "accented {on:.3} vs own timing {own_on:.3}"
    );
}

#[test]
fn foot_lock_keeps_planted_feet_from_skating() {
    let skate = |poses: &[Pose]| {
        let positions = Skeleton::default_adult().trajectory(poses);
        let track = JointTrack::new(&positions, JOINT_COUNT, 25.0).unwrap();
        let toes = [
            model::rig::Joint::LeftToes.index(),
            model::rig::Joint::RightToes.index(),
        ];
        foot_skating(&track, &toes, ContactParams::default())
            .unwrap()
            .mean_speed_mps
    };
    let (locked, _) = dance_to_demo(30.0, 0.5, 3);
    let (free, _) = dance_to_demo_with(30.0, 0.5, 3, |d| d.set_foot_lock(0.0));
    let (locked, free) = (skate(&locked), skate(&free));
    eprintln!("foot skating {locked:.3} m/s locked, {free:.3} m/s free");
    assert!(
        locked < 0.85 * free,
        "locked {locked:.3} vs free {free:.3} m/s"
    );
}

/// Steps `dancer` over `seconds` of the demo song inside the counted callback (alone among
/// the allocation proofs), frame i's controls from `controls`: the allocations counted and
/// the last pose.
fn allocations_stepping(
    dancer: &mut NeuralDancer,
    seconds: f64,
    controls: impl Fn(usize) -> Controls,
) -> (u64, Pose) {
    let (music, _) = common::demo_music(seconds, 25.0);
    let look = dancer.lookahead_frames();
    let mut pose = Pose::rest();
    let _alone = ALLOCATION_PROOF.lock().unwrap_or_else(|e| e.into_inner());
    let before = daemon::alloc_counter::callback_allocations();
    daemon::alloc_counter::in_callback(|| {
        for i in 0..music.len() - look {
            dancer.step(&music[i..=i + look], &controls(i), &mut pose);
        }
    });
    (daemon::alloc_counter::callback_allocations() - before, pose)
}

/// The key pose of frame i: the rest pose, pending over the second half of every 60 frames
/// and due at its end.
fn key_cycle(i: usize) -> Option<model::source::KeyPoseTarget> {
    (i % 60 > 30).then_some(model::source::KeyPoseTarget {
        rotations: Pose::rest().local_rotations,
        frames_to_go: (60 - i % 60) as u32,
    })
}

#[test]
fn stepping_the_dancer_does_not_allocate() {
    let model = daemon::dancer::load_model(None).unwrap();
    let mut dancer = daemon::dancer::neural_dancer(&model, 5).unwrap();
    let (allocations, pose) = allocations_stepping(&mut dancer, 12.0, |i| {
        Controls {
            temperature: if i % 100 < 50 { 1.0 } else { 0.3 },
            key_pose: key_cycle(i),
            // The accent knob turned live, as a performer would.
            beat_accent: Some((i % 90) as f32 / 100.0),
            // And the style switched live, through every style and auto.
            style: match i % 250 / 50 {
                4 => model::style::StyleRequest::Auto,
                k => model::style::StyleRequest::Style(model::style::DanceStyle::ALL[k]),
            },
            // And the key route switched live.
            key_route: Some(if i % 400 < 200 {
                model::source::KeyPoseRoute::Overlay
            } else {
                model::source::KeyPoseRoute::Network
            }),
        }
    });
    assert_eq!(allocations, 0);
    assert!(pose.is_finite());
}

#[test]
fn switching_styles_with_their_own_seed_clips_does_not_allocate() {
    use model::neural::config::NetConfig;
    use model::neural::file::{NeuralModel, TrainingSummary};
    use model::style::{DanceStyle, StyleRequest};
    // A network with a style input and a seed clip per style (the shipped model has neither).
    let config = NetConfig::tiny();
    let mut model = NeuralModel {
        config,
        tensors: model::neural::tensors::init_net(&config, 3),
        training: TrainingSummary::default(),
    };
    let (motion, music) = model.seed_clip().unwrap();
    let (motion, music) = (motion.to_vec(), music.to_vec());
    for style in DanceStyle::ALL {
        model.set_style_seed_clip(style.index(), motion.clone(), music.clone());
    }
    let mut dancer = NeuralDancer::new(&model).unwrap();
    let (music, _) = common::demo_music(8.0, 25.0);
    let look = dancer.lookahead_frames();
    let mut pose = Pose::rest();
    let _alone = ALLOCATION_PROOF.lock().unwrap_or_else(|e| e.into_inner());
    // The counter counts on this thread (the proof would be empty otherwise).
    let before = daemon::alloc_counter::callback_allocations();
    daemon::alloc_counter::in_callback(|| drop(std::hint::black_box(vec![0u8; 64])));
    assert!(daemon::alloc_counter::callback_allocations() > before);
    let before = daemon::alloc_counter::callback_allocations();
    let mut switches = 0;
    daemon::alloc_counter::in_callback(|| {
        let mut last = None;
        for i in 0..music.len() - look {
            // A new style every 20 frames, through every style and auto.
            let style = match i % 100 / 20 {
                4 => StyleRequest::Auto,
                k => StyleRequest::Style(DanceStyle::ALL[k]),
            };
            dancer.step(
                &music[i..=i + look],
                &Controls {
                    temperature: 0.5,
                    style,
                    ..Controls::default()
                },
                &mut pose,
            );
            switches += usize::from(last.is_some_and(|s| s != dancer.style()));
            last = Some(dancer.style());
        }
    });
    assert_eq!(daemon::alloc_counter::callback_allocations() - before, 0);
    assert!(switches >= 8, "{switches} style changes");
    assert!(pose.is_finite());
}

#[test]
fn a_styled_network_handed_key_poses_does_not_allocate() {
    use model::neural::config::NetConfig;
    use model::neural::file::{NeuralModel, TrainingSummary};
    use model::source::KeyPoseRoute;
    use model::style::{DanceStyle, StyleRequest};
    // A network with a style input, its style changing and key poses handed to the network.
    let config = NetConfig::tiny();
    let model = NeuralModel {
        config,
        tensors: model::neural::tensors::init_net(&config, 3),
        training: TrainingSummary::default(),
    };
    let mut dancer = NeuralDancer::new(&model).unwrap();
    dancer.set_key_pose_route(KeyPoseRoute::Network);
    let (allocations, pose) = allocations_stepping(&mut dancer, 8.0, |i| Controls {
        temperature: 0.5,
        key_pose: key_cycle(i),
        style: StyleRequest::Style(DanceStyle::ALL[i % 200 / 50]),
        ..Controls::default()
    });
    assert_eq!(allocations, 0);
    assert!(pose.is_finite());
}
