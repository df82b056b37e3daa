//! `danced bvh`: a tang2018 dance fitted to the rig, exported as BVH.

use std::path::PathBuf;

use anyhow::{Context, Result};

/// Options of `danced bvh`.
#[derive(clap::Args, Debug)]
pub struct BvhArgs {
    /// Dance folder name, e.g. DANCE_W_1.
    #[arg(long)]
    pub dance: String,
    /// Output BVH file.
    #[arg(long)]
    pub out: PathBuf,
    /// The shared data folder.
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
}

/// Runs `danced bvh`.
pub fn bvh_export(args: &BvhArgs) -> Result<()> {
    let BvhArgs { dance, out, data } = args;
    let dir = data.join("tang2018").join(dance);
    let d = model::tang2018::load_dance(&dir)
        .with_context(|| format!("reading dance {}", dir.display()))?;
    let fit =
        model::tang_fit::fit_dance(&d).with_context(|| format!("fitting the rig to {dance}"))?;
    let bvh = model::bvh::export(&fit.skeleton, &fit.poses, fit.fps);
    bvh.write(out)
        .with_context(|| format!("writing {}", out.display()))?;
    println!(
        "{dance}: {} frames at {} fps, fit error {:.2} cm → {}",
        fit.poses.len(),
        fit.fps,
        fit.mean_error_cm,
        out.display()
    );
    Ok(())
}
