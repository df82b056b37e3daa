//! The flags of every command that reads a dance file (`view`, `metrics`, `library build`): how
//! its joints and axes are read when the file itself does not say.

use std::path::PathBuf;

use anyhow::{Context, Result};
use model::bvh::AxisHints;
use offline::moves::{ImportSettings, read_joint_map};

/// How dance files are read.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ImportArgs {
    /// A joint map: a TOML file whose [joints] table names which of our joints each of the
    /// file's joints drives ("lfemur" = "LeftUpperLeg"), for names danced does not know.
    #[arg(long, value_name = "FILE")]
    pub joint_map: Option<PathBuf>,
    /// The file's up axis (x, y, z, -x, -y, -z); found from the motion when left out.
    #[arg(long, value_name = "AXIS", value_parser = parse_up)]
    pub up: Option<glam::Vec3>,
    /// The file's handedness (right or left); found from the motion when left out.
    #[arg(long, value_name = "HAND", value_parser = parse_handed)]
    pub handed: Option<bool>,
}

fn parse_up(text: &str) -> Result<glam::Vec3, String> {
    AxisHints::parse_up(text).ok_or_else(|| format!("{text:?}: one of x, y, z, -x, -y, -z"))
}

/// `true` for a left-handed file.
fn parse_handed(text: &str) -> Result<bool, String> {
    match text.trim().to_ascii_lowercase().as_str() {
        "right" => Ok(false),
        "left" => Ok(true),
        _ => Err(format!("{text:?}: right or left")),
    }
}

impl ImportArgs {
    /// The import settings the flags mean (reads the joint map).
    pub fn settings(&self) -> Result<ImportSettings> {
        let joint_map = match &self.joint_map {
            Some(path) => {
                read_joint_map(path).with_context(|| format!("reading {}", path.display()))?
            }
            None => Vec::new(),
        };
        Ok(ImportSettings {
            joint_map,
            hints: AxisHints {
                up: self.up,
                left_handed: self.handed,
            },
        })
    }
}
