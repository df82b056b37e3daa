//! The dancer flags shared by the commands that dance (`run`, `demo`, `bench live`, `generate`).

use std::path::PathBuf;

use crate::dancer::SourceKind;
use crate::live::config::Config;

/// Which dancer, and from which files.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct SourceArgs {
    /// Motion source (default: the configuration's, else the built-in default).
    #[arg(long, value_enum)]
    pub source: Option<SourceKind>,
    /// Neural model file (default: the built-in configs/models/default.dnn).
    #[arg(long)]
    pub model: Option<PathBuf>,
    /// Clip library file of the retrieval source (default: the built-in one).
    #[arg(long)]
    pub library: Option<PathBuf>,
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
        let implied = match (&self.model, &self.library) {
            (Some(_), None) => Some(SourceKind::Neural),
            (None, Some(_)) => Some(SourceKind::Retrieval),
            _ => None,
        };
        if let Some(k) = self.source.or(implied) {
            config.dancer.source = k.name().into();
            if self.source.is_some() || implied.is_some() {
                // Files of the other source from the configuration no longer apply.
                match k {
                    SourceKind::Neural => config.dancer.library = None,
                    SourceKind::Retrieval => config.dancer.model = None,
                }
            }
        }
        if self.model.is_some() {
            config.dancer.model = self.model.clone();
        }
        if self.library.is_some() {
            config.dancer.library = self.library.clone();
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
    }
}
