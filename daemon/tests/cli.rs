//! The `danced` binary as a user runs it.

mod common;
use common::{danced, scratch, shared_data, succeed, write_wav};

#[test]
fn analyze_writes_beats_onsets_features_and_plot() {
    let dir = scratch("analyze");
    let wav = dir.join("demo.wav");
    let demo = daemon::demo_track::demo_track(20.0);
    write_wav(&wav, &demo.samples, daemon::demo_track::DEMO_RATE, 2);
    let (stdout, _) = succeed(
        danced()
            .args(["analyze", wav.to_str().unwrap(), "--rate", "25"])
            .arg("--beats-out")
            .arg(dir.join("b.txt"))
            .arg("--onsets-out")
            .arg(dir.join("o.txt"))
            .arg("--features-out")
            .arg(dir.join("f.npy"))
            .arg("--plot")
            .arg(dir.join("p.png")),
    );
    assert!(
        stdout.contains("124.0 BPM")
            || stdout.contains("123.9 BPM")
            || stdout.contains("124.1 BPM"),
        "{stdout}"
    );
    let beats = std::fs::read_to_string(dir.join("b.txt")).unwrap();
    let rows: Vec<Vec<f64>> = beats
        .lines()
        .map(|l| l.split('\t').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert!(rows.len() > 25, "{} beats", rows.len());
    for r in &rows {
        assert_eq!(r.len(), 3);
        assert!((1.0..=4.0).contains(&r[1]));
        assert!(
            r[2] >= r[0] - 0.05 && r[2] - r[0] <= 0.05,
            "decided {} for beat {}",
            r[2],
            r[0]
        );
    }
    assert!(
        std::fs::read_to_string(dir.join("o.txt"))
            .unwrap()
            .lines()
            .count()
            > 30
    );
    let npy = std::fs::read(dir.join("f.npy")).unwrap();
    assert!(npy.starts_with(b"\x93NUMPY"));
    let header = String::from_utf8_lossy(&npy[..128]);
    assert!(
        header.contains("'shape': (499, 84)") || header.contains("'shape': (500, 84)"),
        "{header}"
    );
    let sidecar = std::fs::read_to_string(dir.join("f.json")).unwrap();
    assert!(sidecar.contains("\"layout_version\": 2") && sidecar.contains("\"relative_level_db\""));
    let png = std::fs::read(dir.join("p.png")).unwrap();
    assert!(png.starts_with(b"\x89PNG") && png.len() > 20_000);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn analyze_without_a_file_uses_the_built_in_song() {
    let (stdout, _) = succeed(danced().arg("analyze"));
    assert!(stdout.contains("built-in demo song"), "{stdout}");
}

#[test]
fn bad_input_exits_non_zero_naming_the_file() {
    let dir = scratch("bad");
    let junk = dir.join("junk.ogg");
    std::fs::write(&junk, [0u8, 1, 2, 3, 255, 254].repeat(500)).unwrap();
    for p in [dir.join("nope.wav"), junk] {
        let out = danced().arg("analyze").arg(&p).output().unwrap();
        assert!(!out.status.success());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains(p.file_name().unwrap().to_str().unwrap()),
            "{stderr}"
        );
        assert!(!stderr.contains("panicked"), "{stderr}");
    }
    let out = danced()
        .args(["bench", "beats", "--data"])
        .arg(dir.join("no-data"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("no-data"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_fitted_dance_exports_as_bvh_and_scores_against_its_song() {
    let Some(data) = shared_data("tang2018/DANCE_W_22") else {
        return;
    };
    let dir = scratch("bvh");
    let out = dir.join("w22.bvh");
    succeed(
        danced()
            .args(["bvh", "--dance", "DANCE_W_22", "--data"])
            .arg(&data)
            .arg("--out")
            .arg(&out),
    );
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(
        text.starts_with("HIERARCHY")
            && text.contains("Frames: 1022")
            && text.contains("Frame Time: 0.04")
    );
    let (stdout, _) = succeed(
        danced()
            .arg("metrics")
            .arg(&out)
            .arg("--audio")
            .arg(data.join("tang2018/DANCE_W_22/audio.mp3")),
    );
    let ba: f64 = stdout
        .lines()
        .find_map(|l| l.strip_prefix("BeatAlign"))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no BeatAlign in {stdout}"));
    assert!((0.1..=1.0).contains(&ba), "BeatAlign {ba}");
    assert!(stdout.contains("freezes     0"), "{stdout}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn generate_dances_to_a_song_and_writes_bvh() {
    let Some(data) = shared_data("tang2018") else {
        return;
    };
    let dir = scratch("generate");
    let out = dir.join("gen.bvh");
    let (stdout, _) = succeed(
        danced()
            .arg("generate")
            .arg("--audio")
            .arg(data.join("tang2018/DANCE_W_16/audio.mp3"))
            .arg("--out")
            .arg(&out)
            .args([
                "--seconds",
                "10",
                "--stage-radius",
                "1.0",
                "--stage-centre",
                "2,-1",
            ])
            .arg("--data")
            .arg(&data),
    );
    assert!(stdout.contains("stage (bounded, radius 1 m)"), "{stdout}");
    let bvh = model::bvh::Bvh::read(&out).unwrap();
    assert_eq!(bvh.frames.len(), 250);
    assert!(bvh.frames.iter().flatten().all(|v| v.is_finite()));
    // The dancer moves (the hips travel over a metre) and stays on its 1 m stage.
    // BVH positions are in centimetres.
    let hips: Vec<glam::Vec3> = (0..250).map(|f| bvh.world_positions(f)[0] * 0.01).collect();
    let travelled: f32 = hips.windows(2).map(|w| (w[1] - w[0]).length()).sum();
    assert!(travelled > 1.0, "hips travelled {travelled} m");
    let centre = glam::Vec2::new(2.0, -1.0);
    for (f, h) in hips.iter().enumerate() {
        let d = (glam::Vec2::new(h.x, h.z) - centre).length();
        assert!(d <= 1.1, "frame {f}: hips {d:.2} m from the centre");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn network_only_switches_the_safety_nets_off_and_says_so() {
    let dir = scratch("network-only");
    let song = dir.join("clicks.wav");
    let (samples, _) = common::click_track(8.0, 120.0, 0.25, 44_100);
    common::write_wav(&song, &samples, 44_100, 2);
    let out = dir.join("d.bvh");
    let run = |extra: &[&str]| {
        danced()
            .arg("generate")
            .arg("--audio")
            .arg(&song)
            .arg("--out")
            .arg(&out)
            .args(extra)
            .output()
            .unwrap()
    };
    let shipped = String::from_utf8_lossy(&run(&[]).stdout).into_owned();
    assert!(shipped.contains("safety nets: held"), "{shipped}");
    // The shipped setting locks planted feet; it retimes the frames on the beat only when asked
    // (the shipped network learned its own accent).
    assert!(!shipped.contains("foot-locked 0.0 %"), "{shipped}");
    assert!(shipped.contains("beat-accented 0.0 %"), "{shipped}");
    let accented = String::from_utf8_lossy(&run(&["--beat-accent", "0.15"]).stdout).into_owned();
    assert!(!accented.contains("beat-accented 0.0 %"), "{accented}");
    let alone = run(&["--network-only"]);
    let text = String::from_utf8_lossy(&alone.stdout).into_owned();
    assert!(alone.status.success(), "{text}");
    assert!(
        text.contains("network only (nets off)")
            && text.contains("range-clamped 0.0 %")
            && text.contains("speed-limited 0.0 %, restarts 0, beat-accented 0.0 %, key-blended 0.0 %, foot-locked 0.0 %"),
        "{text}"
    );
    let retrieval = run(&["--network-only", "--source", "retrieval"]);
    assert!(!retrieval.status.success());
    assert!(String::from_utf8_lossy(&retrieval.stderr).contains("neural source"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_old_train_commands_name_their_new_home() {
    for (old, new) in [("train", "dancer"), ("train-beats", "beats")] {
        let out = danced()
            .args([old, "--minutes", "1", "--seed", "2"])
            .output()
            .unwrap();
        assert!(!out.status.success(), "danced {old} succeeded");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains(&format!("danced-train {new} --minutes 1 --seed 2")),
            "{stderr}"
        );
        assert!(
            stderr.contains(&format!("cargo run --release -p training -- {new}")),
            "{stderr}"
        );
    }
}

#[test]
fn a_style_the_dancer_cannot_honour_is_refused_at_start() {
    // The shipped model has no style input, and the retrieval dancer none either.
    for source in ["neural", "retrieval"] {
        let out = danced()
            .args([
                "demo",
                "--duration",
                "1",
                "--style",
                "rumba",
                "--source",
                source,
            ])
            .output()
            .unwrap();
        assert!(!out.status.success(), "{source}: a refused style ran");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(
            stderr.contains("style rumba: the loaded dancer has no style input"),
            "{source}: {stderr}"
        );
    }
}

#[test]
fn live_run_on_a_file_writes_stats_and_a_bad_config_names_the_key() {
    let dir = scratch("live");
    let wav = dir.join("clicks.wav");
    let rate = 22_050;
    let mut samples = vec![0.0f32; rate as usize * 3];
    for beat in 0..6 {
        let start = beat * rate as usize / 2;
        for (i, s) in samples[start..start + 400].iter_mut().enumerate() {
            *s = 0.8 * (-(i as f32) / 80.0).exp() * if i % 2 == 0 { 1.0 } else { -1.0 };
        }
    }
    write_wav(&wav, &samples, rate, 1);
    let stats = dir.join("stats.json");
    succeed(
        danced()
            .args(["run", "--input"])
            .arg(&wav)
            .args([
                "--speed",
                "4",
                "--duration",
                "2.5",
                "--control-port",
                "0",
                "--stats-json",
            ])
            .arg(&stats),
    );
    let json = std::fs::read_to_string(&stats).unwrap();
    for key in [
        "latency_ms_p99",
        "jitter_ms_p99",
        "cpu_percent",
        "callback_allocations",
    ] {
        assert!(json.contains(key), "{json}");
    }
    assert!(json.contains("\"callback_allocations\": 0"), "{json}");

    let config = dir.join("bad.toml");
    std::fs::write(&config, "[output]\nrate = 30\n").unwrap();
    let out = danced()
        .args(["run", "--config"])
        .arg(&config)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(err.contains("bad.toml") && err.contains("rate"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn devices_and_a_missing_input_fail_cleanly() {
    let (stdout, _) = succeed(danced().arg("devices"));
    assert!(!stdout.trim().is_empty());
    let out = danced()
        .args(["run", "--device", "no-such-device-xyz", "--duration", "1"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(!err.contains("panicked"), "{err}");
    assert!(err.contains("audio input"), "{err}");
}

/// Twenty seconds of the built-in dancer at 110 BPM as a BVH whose joints have names no table
/// knows (`part_00` … `part_21`), in centimetres, its Y-up skeleton stood up in a Z-up world by
/// its root (as AMASS's files are); returns the joint map it needs.
fn unknown_rig_dance(path: &std::path::Path) -> String {
    use model::source::MotionSource;
    let (library, _) = daemon::dancer::load_library(None).unwrap();
    let mut dancer = model::retrieval::RetrievalDancer::new(library, 1).unwrap();
    let mut out = model::rig::Pose::rest();
    let fps = model::retrieval::RETRIEVAL_FPS;
    let poses: Vec<_> = (0..(20.0 * fps) as usize)
        .map(|i| {
            let beats = i as f64 / fps * 110.0 / 60.0;
            let mut m = [0.0f32; dsp::feature::FEATURE_DIM];
            use dsp::feature::FeatureLayout as L;
            let b = (beats.fract() * std::f64::consts::TAU) as f32;
            let bar = ((beats / 4.0).fract() * std::f64::consts::TAU) as f32;
            (m[L::BEAT_SIN], m[L::BEAT_COS]) = (b.sin(), b.cos());
            (m[L::BAR_SIN], m[L::BAR_COS]) = (bar.sin(), bar.cos());
            m[L::TEMPO] = 110.0;
            m[L::ENERGY] = -15.0;
            dancer.step(&[m], &model::source::Controls::default(), &mut out);
            // Z up, facing −Y: (x, y, z) → (x, −z, y).
            let mut p = out;
            let r = p.root_position;
            p.root_position = glam::Vec3::new(r.x, -r.z, r.y);
            p.local_rotations[0] =
                glam::Quat::from_rotation_x(std::f32::consts::FRAC_PI_2) * p.local_rotations[0];
            p
        })
        .collect();
    let skeleton = model::rig::Skeleton::default_adult();
    let mut bvh = model::bvh::export(&skeleton, &poses, fps);
    let mut map = String::from("[joints]\n");
    for (i, j) in bvh.joints.iter_mut().enumerate() {
        let part = format!("part_{i:02}");
        map.push_str(&format!("{part} = \"{}\"\n", j.name));
        j.name = part;
    }
    bvh.write(path).unwrap();
    map
}

#[test]
fn a_folder_of_your_own_dances_becomes_a_library_and_unknown_joints_get_a_map() {
    let dir = scratch("moves");
    let folder = dir.join("my-moves");
    std::fs::create_dir_all(&folder).unwrap();
    let map = unknown_rig_dance(&folder.join("routine.bvh"));
    let out = dir.join("mine.danclips");
    // Joints it cannot name: a clear error naming them and how to write the map.
    let failed = danced()
        .args(["library", "build", "--bvh"])
        .arg(&folder)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(!failed.status.success());
    let stderr = String::from_utf8_lossy(&failed.stderr);
    assert!(
        stderr.contains("no joint of the file drives Hips")
            && stderr.contains("part_00")
            && stderr.contains("--joint-map")
            && stderr.contains("[joints]"),
        "{stderr}"
    );
    // With the map, it reads: Z up and centimetres found, the beat found from the motion.
    let map_file = dir.join("map.toml");
    std::fs::write(&map_file, map).unwrap();
    let (stdout, _) = succeed(
        danced()
            .args(["library", "build", "--bvh"])
            .arg(&folder)
            .arg("--out")
            .arg(&out)
            .arg("--joint-map")
            .arg(&map_file),
    );
    let row = stdout
        .lines()
        .find(|l| l.starts_with("| routine |"))
        .unwrap_or_else(|| panic!("{stdout}"));
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    let tempo: f64 = cells[3].parse().unwrap();
    assert!((80.0..140.0).contains(&tempo), "{row}");
    assert!(
        row.contains("Z up, right-handed") && row.contains("| cm |"),
        "{row}"
    );
    assert!(stdout.contains("library \"my-moves\""), "{stdout}");
    let (library, meta) =
        model::retrieval::ClipLibrary::from_bytes(&std::fs::read(&out).unwrap()).unwrap();
    assert!(library.clips.len() > 20, "{} clips", library.clips.len());
    assert!(meta.contains("\"name\": \"my-moves\""), "{meta}");

    // Its rhythm track: a WAV on the beat found, and the beats it plays; the analysis hears an
    // onset on each (this synthetic routine's beats are too uneven for a steady beat tracker:
    // the unit tests of the accompaniment check the beats and bars heard on dancers' grids).
    let tracks = dir.join("tracks");
    let (stdout, _) = succeed(
        danced()
            .args(["library", "accompany", "--bvh"])
            .arg(&folder)
            .arg("--out")
            .arg(&tracks)
            .arg("--joint-map")
            .arg(&map_file),
    );
    assert!(stdout.contains("| routine |"), "{stdout}");
    let beats = std::fs::read_to_string(tracks.join("routine.beats")).unwrap();
    assert!(beats.lines().count() > 10, "{beats}");
    let heard_file = dir.join("heard.onsets");
    succeed(
        danced()
            .arg("analyze")
            .arg(tracks.join("routine.wav"))
            .arg("--onsets-out")
            .arg(&heard_file),
    );
    let times = |text: &str| -> Vec<f64> {
        text.lines()
            .filter_map(|l| l.split_whitespace().next()?.parse().ok())
            .collect()
    };
    let heard = times(&std::fs::read_to_string(&heard_file).unwrap());
    let played = times(&beats);
    // Every beat played is heard as an onset within 50 ms (hats between beats are onsets too).
    let missed: Vec<f64> = played
        .iter()
        .copied()
        .filter(|b| !heard.iter().any(|h| (h - b).abs() <= 0.05))
        .collect();
    assert!(
        missed.is_empty(),
        "beats without an onset: {missed:?} (heard {heard:?})"
    );
}
