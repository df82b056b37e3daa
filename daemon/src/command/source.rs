//! The dancer flags shared by the commands that dance (`run`, `demo`, `bench live`, `generate`).

use std::path::PathBuf;

use crate::dancer::SourceKind;
use crate::live::config::Config;

/// Which dancer, from which files, and where on the floor it dances.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct SourceArgs {
    /// Motion source (default: the configuration's, else the built-in default).
    #[arg(long, value_enum)]
    pub source: Option<SourceKind>,
    /// Neural model file (default: the built-in configs/models/default.dnn).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Clip library file of the retrieval source (default: the built-in one); repeat it to
    /// hold several, switched live by /danced/control/moves (the first dances first).
    #[arg(long)]
    pub library: Vec<PathBuf>,
    /// Depth of the neural dancer's beat accent, 0–0.9 (0: the network's own timing).
    #[arg(long)]
    pub beat_accent: Option<f32>,
    /// Dance style: auto (from the music's meter and tempo), cha-cha, rumba, tango or waltz.
    #[arg(long, value_parser = parse_style)]
    pub style: Option<String>,
    /// Where the neural dancer sends key poses: overlay (shown over the dance, the default) or
    /// network (the network dances to them itself).
    #[arg(long, value_parser = parse_key_route)]
    pub key_route: Option<String>,
    /// Where on the floor it dances: bounded (within --stage-radius of the centre, turning back
    /// before the edge), in_place (the hips' travel removed) or free (wherever the dance goes).
    #[arg(long, value_parser = parse_stage_mode)]
    pub stage: Option<String>,
    /// Radius of the stage, metres (default 1.5).
    #[arg(long)]
    pub stage_radius: Option<f32>,
    /// Centre of the stage on the floor, metres: X,Z (e.g. 0,-1).
    #[arg(long, value_parser = parse_centre, allow_hyphen_values = true)]
    pub stage_centre: Option<[f32; 2]>,
    /// Direction the audience is in, degrees about the vertical (0: +z, towards the view's
    /// camera; 90: +x).
    #[arg(long, allow_hyphen_values = true)]
    pub stage_facing: Option<f32>,
}

/// Reads a stage mode's name (for clap).
pub fn parse_stage_mode(s: &str) -> Result<String, String> {
    model::stage::StageMode::parse(s)
        .map(|m| m.name().to_string())
        .ok_or_else(|| format!("{s:?}: expected bounded, in_place or free"))
}

/// The default stage in mode `mode` (a name [`parse_stage_mode`] accepted; anything else is
/// the default mode).
pub fn stage_in_mode(mode: &str) -> model::stage::StageSettings {
    model::stage::StageSettings {
        mode: model::stage::StageMode::parse(mode).unwrap_or_default(),
        ..Default::default()
    }
}

fn parse_centre(s: &str) -> Result<[f32; 2], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    match parts.as_slice() {
        [x, z] => match (x.parse::<f32>(), z.parse::<f32>()) {
            (Ok(x), Ok(z)) if x.is_finite() && z.is_finite() => Ok([x, z]),
            _ => Err(format!("{s:?}: expected two numbers X,Z in metres")),
        },
        _ => Err(format!("{s:?}: expected X,Z in metres, e.g. 0,-1")),
    }
}

fn parse_key_route(s: &str) -> Result<String, String> {
    model::source::KeyPoseRoute::parse(s)
        .map(|r| r.name().to_string())
        .ok_or_else(|| format!("{s:?}: expected overlay or network"))
}

fn parse_style(s: &str) -> Result<String, String> {
    model::style::StyleRequest::parse(s)
        .map(|r| r.name().to_string())
        .ok_or_else(|| format!("{s:?}: expected auto, cha-cha, rumba, tango or waltz"))
}

impl SourceArgs {
    /// Applies the flags to `config`; a model file implies the neural source and a library
    /// the retrieval source unless a source is named.
    pub fn apply(&self, config: &mut Config) {
        let implied = match (&self.model, self.library.is_empty()) {
            (Some(_), true) => Some(SourceKind::Neural),
            (None, false) => Some(SourceKind::Retrieval),
            _ => None,
        };
        if let Some(k) = self.source.or(implied) {
            config.dancer.source = k.name().into();
            if self.source.is_some() || implied.is_some() {
                // Files of the other source from the configuration no longer apply.
                match k {
                    SourceKind::Neural => config.dancer.libraries.clear(),
                    SourceKind::Retrieval => config.dancer.model = None,
                }
            }
        }
        if self.model.is_some() {
            config.dancer.model = self.model.clone();
        }
        if !self.library.is_empty() {
            config.dancer.libraries = self
                .library
                .iter()
                .map(crate::dancer::LibraryChoice::file)
                .collect();
        }
        if let Some(a) = self.beat_accent {
            config.dancer.beat_accent = a;
        }
        if let Some(s) = &self.style {
            config.dancer.style = s.clone();
        }
        if let Some(r) = &self.key_route {
            config.dancer.key_route = r.clone();
        }
        if let Some(m) = &self.stage {
            config.stage.mode = m.clone();
        }
        if let Some(r) = self.stage_radius {
            config.stage.radius_m = r;
        }
        if let Some(c) = self.stage_centre {
            config.stage.centre = c;
        }
        if let Some(f) = self.stage_facing {
            config.stage.facing_deg = f;
        }
    }
}
