//! `danced eval`: the motion sources scored on the validation dances' music, next to the ground
//! truth.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Result;
use model::source::MotionSource;

use crate::eval::{KEY_HORIZONS_S, LONG_RUN_S};

/// Options of `danced eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// The shared data folder (holds tang2018/ and tang2018-beats/).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Clip library of the retrieval rows (default: the built-in one).
    #[arg(long)]
    pub library: Option<PathBuf>,
    /// Also score the retrieval dancer on the full library cut from the training split.
    #[arg(long)]
    pub full_library: bool,
    /// Neural model of the neural rows (default: the built-in one).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Only the table of the validation dances (no key poses, unseen songs or long runs).
    #[arg(long)]
    pub quick: bool,
    /// Only the ground-truth rows of the validation table (the data's own figures, and what
    /// the training retime makes of them); no dancer runs.
    #[arg(long)]
    pub ground_truth: bool,
    /// Only the table of the songs in no training dance (beat by tempo band, quiet parts),
    /// for the retrieval, shipped neural and network-only rows.
    #[arg(long, conflicts_with_all = ["quick", "ground_truth"])]
    pub music: bool,
    /// Only the shipped neural rows, danced to the training dances' songs and scored against
    /// the training dances: a checkpoint picked by this never saw the validation dances.
    #[arg(long, conflicts_with_all = ["quick", "ground_truth", "music"])]
    pub training_songs: bool,
    /// Only the key-pose tables (the error at the key frame by horizon, the transitions) of
    /// the neural rows: the shipped setting, without the final blend, and the network alone.
    #[arg(long, conflicts_with_all = ["quick", "ground_truth", "music", "training_songs"])]
    pub keys: bool,
    /// Random seed of the generated rows.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Worker threads for loading.
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
    /// Where on the floor the dancers dance: bounded (the default stage, 1.5 m), in_place or
    /// free (their own motion, untouched).
    #[arg(long, default_value = "bounded", value_parser = crate::command::source::parse_stage_mode)]
    pub stage: String,
}

impl EvalArgs {
    /// The stage the dancers dance on.
    fn stage(&self) -> model::stage::StageSettings {
        crate::command::source::stage_in_mode(&self.stage)
    }
}

const NO_ACCENT: &str = "neural, no beat accent";
const FRESH_NOISE: &str = "neural, independent noise";
const NO_FOOT_LOCK: &str = "neural, no foot lock";
const NETWORK_ONLY: &str = "neural, network only";

/// Whether a row is one of the neural dancer's ablations (one net changed).
fn ablation(name: &str) -> bool {
    [NO_ACCENT, FRESH_NOISE, NO_FOOT_LOCK].contains(&name)
}

/// The neural dancer on `model`, seeded as the options say.
fn eval_dancer(
    o: &EvalArgs,
    model: &model::neural::file::NeuralModel,
) -> Result<model::neural::dancer::NeuralDancer> {
    crate::dancer::neural_dancer(model, o.seed)
}

/// The dancers scored: retrieval (and on the full library), the neural dancer on `model` as
/// shipped, its ablations and the network alone.
fn sources(
    o: &EvalArgs,
    model: &model::neural::file::NeuralModel,
) -> Result<Vec<(String, Box<dyn MotionSource>)>> {
    let mut libraries = vec![(
        "retrieval",
        crate::dancer::load_library(o.library.as_deref())?.0,
    )];
    if o.full_library {
        libraries.push((
            "retrieval, full library",
            crate::dancer::training_library(&o.data, o.jobs)?.0,
        ));
    }
    let stage = o.stage();
    let staged = |s| -> Box<dyn MotionSource> { crate::dancer::on_stage(s, stage) };
    let mut sources: Vec<(String, Box<dyn MotionSource>)> = Vec::new();
    for (name, lib) in libraries {
        sources.push((
            name.to_string(),
            crate::dancer::on_stage(crate::eval::retrieval(lib)?, stage),
        ));
    }
    sources.push(("neural".into(), staged(eval_dancer(o, model)?)));
    // Ablations: the network's own timing, a fresh noise draw every frame, free feet.
    let mut own_timing = eval_dancer(o, model)?;
    own_timing.set_beat_accent(0.0);
    sources.push((NO_ACCENT.into(), staged(own_timing)));
    let mut fresh_noise = eval_dancer(o, model)?;
    fresh_noise.set_noise_correlation(0.0);
    sources.push((FRESH_NOISE.into(), staged(fresh_noise)));
    let mut free_feet = eval_dancer(o, model)?;
    free_feet.set_safety_nets(model::neural::safety::SafetyNets {
        foot_lock: false,
        ..model::neural::safety::SafetyNets::SHIPPED
    });
    sources.push((NO_FOOT_LOCK.into(), staged(free_feet)));
    // The network alone: every safety net off but the non-finite guard.
    let mut alone = eval_dancer(o, model)?;
    alone.set_safety_nets(model::neural::safety::SafetyNets::NETWORK_ONLY);
    sources.push((NETWORK_ONLY.into(), staged(alone)));
    Ok(sources)
}

/// The shipped neural dancer on the training dances' songs (`--training-songs`).
fn training_songs_table(o: &EvalArgs, temperatures: &[f32], started: Instant) -> Result<()> {
    let set =
        crate::eval::EvalSet::load_scoring(&o.data, o.jobs, crate::eval::ScoredDances::Training)?;
    eprintln!(
        "training dances scored: {} (loaded in {:.1} s)",
        set.validation_names().len(),
        started.elapsed().as_secs_f64()
    );
    let model = crate::dancer::load_model(o.model.as_deref())?;
    let mut dancer = crate::dancer::on_stage(eval_dancer(o, &model)?, o.stage());
    let mut rows = vec![set.score("ground truth, training dances", &set.ground_truth())?];
    for &t in temperatures {
        let (motions, _) = set.generate(dancer.as_mut(), t, o.seed);
        rows.push(set.score(&format!("neural T={t}, training songs"), &motions)?);
    }
    print!("{}", crate::eval::table(&rows));
    eprintln!("eval took {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

/// Runs `danced eval`.
pub fn eval(o: &EvalArgs) -> Result<()> {
    let started = Instant::now();
    let temperatures = [0.0f32, 0.5, 1.0];
    if o.music {
        let model = crate::dancer::load_model(o.model.as_deref())?;
        let mut sources = sources(o, &model)?;
        sources.retain(|(n, _)| !ablation(n));
        music_table(o, &mut sources, &temperatures)?;
        eprintln!("eval took {:.1} s", started.elapsed().as_secs_f64());
        return Ok(());
    }
    if o.training_songs {
        return training_songs_table(o, &temperatures, started);
    }
    let set = crate::eval::EvalSet::load(&o.data, o.jobs)?;
    eprintln!(
        "validation dances: {} (loaded in {:.1} s)",
        set.validation_names().join(" "),
        started.elapsed().as_secs_f64()
    );
    if o.keys {
        let model = crate::dancer::load_model(o.model.as_deref())?;
        let mut sources = sources(o, &model)?;
        sources.retain(|(n, _)| n == "neural" || n == NETWORK_ONLY);
        let mut key_sources: Vec<(String, &mut dyn MotionSource)> = sources
            .iter_mut()
            .map(|(n, d)| (n.clone(), d.as_mut() as &mut dyn MotionSource))
            .collect();
        key_tables(o, &set, &model, &mut key_sources)?;
        eprintln!("eval took {:.1} s", started.elapsed().as_secs_f64());
        return Ok(());
    }
    let gt = set.ground_truth();
    let mut rows = vec![set.score("ground truth", &gt)?];
    let mut styled = vec![("ground truth".to_string(), gt.clone())];
    // What `danced-train dancer --beat-retime` makes of the data: the cost of the retime in
    // FID_k, and the beat it puts in (and whether the style judge still names it).
    for depth in [0.2, 0.3] {
        let retimed = set.ground_truth_beat_retimed(depth);
        let label = format!("ground truth, beat-retimed {depth}");
        rows.push(set.score(&label, &retimed)?);
        styled.push((label, retimed));
    }
    if o.ground_truth {
        print!("{}", crate::eval::table(&rows));
        return Ok(());
    }
    let model = crate::dancer::load_model(o.model.as_deref())?;
    let mut sources = sources(o, &model)?;
    for (name, dancer) in sources.iter_mut() {
        for t in temperatures {
            let (motions, us) = set.generate(dancer.as_mut(), t, o.seed);
            let label = format!("{name} T={t}");
            eprintln!("{label}: {us:.1} µs per frame");
            if let Some(c) = dancer.report().safety {
                // Of the last validation song (the counts restart with each song).
                eprintln!("  {label}, last song: {}", c.summary());
            }
            rows.push(set.score(&label, &motions)?);
            if name == "neural" || name == "retrieval" || name == NETWORK_ONLY {
                styled.push((label.clone(), motions.clone()));
            }
        }
    }
    print!("{}", crate::eval::table(&rows));
    // Which style each 10 s window looks like, by a nearest-centroid judge fit on the
    // training dances: with the style chosen from the music (auto), rows are the song's style.
    for (label, motions) in &styled {
        if let Some(c) = set.style_confusion(motions) {
            print!("\n{}", crate::eval::style_table(label, &c));
        }
    }
    // What the judge reads: a dancer whose kinetics stay those of one style is named that
    // style whatever the song.
    let kinetics: Vec<_> = styled
        .iter()
        .filter(|(label, _)| label == "ground truth" || label.ends_with("T=0.5"))
        .map(|(label, motions)| (label.clone(), set.style_kinetics(motions)))
        .collect();
    print!("\n{}", crate::eval::kinetics_table(&kinetics));
    // With each style requested in turn on every song (models with a style input).
    let probe = eval_dancer(o, &model)?;
    if probe.has_style_input() {
        let mut alone = eval_dancer(o, &model)?;
        alone.set_safety_nets(model::neural::safety::SafetyNets::NETWORK_ONLY);
        for (label, mut dancer) in [
            ("neural T=0.5", probe),
            ("neural, network only T=0.5", alone),
        ] {
            if let Some(c) = set.requested_style_confusion(&mut dancer, 0.5, o.seed) {
                print!(
                    "\n{}",
                    crate::eval::style_table_of(label, "style requested", &c)
                );
            }
        }
    }
    if o.quick {
        eprintln!("eval took {:.1} s", started.elapsed().as_secs_f64());
        return Ok(());
    }
    let mut key_sources: Vec<(String, &mut dyn MotionSource)> = sources
        .iter_mut()
        .filter(|(n, _)| !n.contains("full") && !ablation(n))
        .map(|(n, d)| (n.clone(), d.as_mut() as &mut dyn MotionSource))
        .collect();
    key_tables(o, &set, &model, &mut key_sources)?;
    // Long runs: no freeze over five minutes on any song.
    println!(
        "\n| system | freezes in {:.0} min on each validation song (looped) | songs with a freeze |\n| --- | --- | --- |",
        LONG_RUN_S / 60.0
    );
    for (name, dancer) in sources
        .iter_mut()
        .filter(|(n, _)| !n.contains("full") && !ablation(n))
    {
        for t in temperatures {
            let r = set.long_run_freezes(dancer.as_mut(), t, o.seed)?;
            println!(
                "| {name} T={t} | {} | {} of {} |",
                r.freezes,
                r.songs_with_freezes,
                set.validation_names().len()
            );
        }
    }
    music_table(o, &mut sources, &temperatures)?;
    eprintln!("eval took {:.1} s", started.elapsed().as_secs_f64());
    Ok(())
}

/// The key-pose tables of `sources` and of the neural dancer on `model` without the final
/// blend and with the key handed to the network: the mean joint error at the key frame by
/// horizon, and the 2 s before and after key poses against the same windows danced free.
fn key_tables(
    o: &EvalArgs,
    set: &crate::eval::EvalSet,
    model: &model::neural::file::NeuralModel,
    sources: &mut [(String, &mut dyn MotionSource)],
) -> Result<()> {
    let bank: Vec<_> = crate::pose_bank::PoseBank::shipped()?
        .poses()
        .iter()
        .map(|p| p.rotations)
        .collect();
    let mut key_table =
        String::from("\n| system (key-pose error at the target frame, cm), announced");
    for h in KEY_HORIZONS_S {
        key_table += &format!(" | {h} s ahead");
    }
    key_table += " | cues |\n| --- |";
    key_table += &" --- |".repeat(KEY_HORIZONS_S.len() + 1);
    key_table += "\n";
    let mut unaided = eval_dancer(o, model)?;
    unaided.set_key_blend_frames(0);
    let unaided_name = "neural without the final blend".to_string();
    for (name, dancer) in sources
        .iter_mut()
        .map(|(n, d)| (&*n, &mut **d))
        .chain(std::iter::once((
            &unaided_name,
            &mut unaided as &mut dyn MotionSource,
        )))
    {
        for t in [0.0f32, 0.5] {
            key_table += &format!("| {name} T={t} |");
            let mut cues = 0;
            for h in KEY_HORIZONS_S {
                let (e, n) = set.key_pose_error(&mut *dancer, t, o.seed, &bank, h);
                key_table += &format!(" {e:.2} |");
                cues = n;
            }
            key_table += &format!(" {cues} |\n");
        }
    }
    print!("{key_table}");
    println!(
        "\n| system | FID_k of the {s} s before key poses ↓ | of the {s} s after them ↓ | of the same windows danced free ↓ | before / free (target ≤ 1.25) | after / free | joint speed before / free, m/s | windows |\n| --- | --- | --- | --- | --- | --- | --- | --- |",
        s = crate::eval::TRANSITION_S
    );
    let mut led = eval_dancer(o, model)?;
    led.set_key_pose_route(model::source::KeyPoseRoute::Network);
    let led_name = "neural, key to the network".to_string();
    for (name, dancer) in sources
        .iter_mut()
        .map(|(n, d)| (&*n, &mut **d))
        .chain(std::iter::once((
            &led_name,
            &mut led as &mut dyn MotionSource,
        )))
    {
        let t = 0.5;
        let f = set.transition_fid(dancer, t, o.seed, &bank)?;
        println!(
            "| {name} T={t} | {:.1} | {:.1} | {:.1} | {:.2} | {:.2} | {:.2} / {:.2} | {} |",
            f.before_key,
            f.after_key,
            f.free,
            f.before_key / f.free,
            f.after_key / f.free,
            f.before_key_speed,
            f.free_speed,
            f.windows
        );
    }
    Ok(())
}

/// Songs in no training dance, with exact beats: the music-side metrics only (skipped, with a
/// word on stderr, when the songs are missing).
fn music_table(
    o: &EvalArgs,
    sources: &mut [(String, Box<dyn MotionSource>)],
    temperatures: &[f32],
) -> Result<()> {
    match crate::eval::MusicSet::load(&o.data) {
        Ok(music) => {
            let mut music_rows = Vec::new();
            for (name, dancer) in sources.iter_mut().filter(|(n, _)| !n.contains("full")) {
                for &t in temperatures {
                    music_rows.push(music.score(
                        &format!("{name} T={t}"),
                        dancer.as_mut(),
                        t,
                        o.seed,
                    )?);
                }
            }
            println!(
                "\nsynth-beats ({} songs in no training dance, exact beats):",
                music_rows.first().map_or(0, |r| r.songs)
            );
            print!("{}", crate::eval::music_table(&music_rows));
        }
        Err(e) => eprintln!("synth-beats skipped: {e:#}"),
    }
    Ok(())
}
