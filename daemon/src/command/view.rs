//! `danced view`: play a dance file (a `generate` BVH, or any BVH rig) in the browser view,
//! with its song in sync when given.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use model::rig::Skeleton;

use crate::view::assets::{Assets, audio_content_type};
use crate::view::playback::{PLAYBACK_RATE_HZ, dance_packets};
use crate::view::{DEFAULT_VIEW_ADDR, ViewHello, ViewServer};

/// Options of `danced view`.
#[derive(clap::Args, Debug)]
pub struct ViewArgs {
    /// The dance (BVH; `danced generate` writes them).
    pub dance: PathBuf,
    /// The song, played by the page in sync with the dance.
    #[arg(long)]
    pub audio: Option<PathBuf>,
    /// host:port the page is served on.
    #[arg(long, default_value = DEFAULT_VIEW_ADDR)]
    pub addr: String,
    /// Stop after this many seconds (serves until Ctrl-C otherwise).
    #[arg(long)]
    pub duration: Option<f64>,
    /// How the file's joints and axes are read.
    #[command(flatten)]
    pub import: super::import_args::ImportArgs,
}

/// Runs `danced view`.
pub fn view(args: &ViewArgs) -> Result<()> {
    let skeleton = Skeleton::default_adult();
    let dance = offline::moves::read_dance(&args.dance, &args.import.settings()?)?;
    let (packets, frames) = dance_packets(&dance.poses, dance.fps);
    let mut assets = Assets::page(&skeleton);
    assets.insert(
        "/dance.vmc",
        "application/octet-stream",
        false,
        packets.into(),
    );
    if let Some(song) = &args.audio {
        let bytes = std::fs::read(song).with_context(|| format!("reading {}", song.display()))?;
        assets.insert("/audio", audio_content_type(song), false, bytes.into());
    }
    let hello = ViewHello {
        mode: "playback",
        dancer: args
            .dance
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default(),
        rate_hz: PLAYBACK_RATE_HZ,
        model_rate_hz: dance.fps,
        audio: args.audio.is_some(),
        frames,
        ..ViewHello::default()
    };
    let stop = Arc::new(AtomicBool::new(false));
    let (server, _) = ViewServer::start(&args.addr, assets, hello, None, stop.clone())?;
    {
        let stop = stop.clone();
        if let Err(e) = ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed)) {
            tracing::warn!("Ctrl-C handler not installed: {e}");
        }
    }
    eprintln!(
        "{}: {:.1} s of dance{}; open {} in a browser; Ctrl-C stops",
        args.dance.display(),
        frames as f64 / PLAYBACK_RATE_HZ,
        args.audio
            .as_ref()
            .map(|a| format!(" with {}", a.display()))
            .unwrap_or_default(),
        server.url()
    );
    let started = Instant::now();
    let limit = args.duration.map(Duration::from_secs_f64);
    while !stop.load(Ordering::Relaxed) && limit.is_none_or(|l| started.elapsed() < l) {
        std::thread::sleep(Duration::from_millis(100));
    }
    let report = server.stop();
    eprintln!(
        "view: {} files served, {} HTTP errors, {} browsers",
        report.http_served, report.http_errors, report.clients_accepted
    );
    Ok(())
}
