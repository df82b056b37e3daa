//! `--view [ADDR]` of `danced run` and `danced demo`: serve the browser view.

use crate::live::config::Config;

/// The view flag.
#[derive(clap::Args, Debug, Default)]
pub struct ViewFlag {
    /// Serve a live 3D view of the dancer in the browser at this host:port (default
    /// 127.0.0.1:8080; `[view]` in the configuration).
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = crate::view::DEFAULT_VIEW_ADDR)]
    pub view: Option<String>,
}

impl ViewFlag {
    /// Turns the view on in `config` when the flag is given.
    pub fn apply(&self, config: &mut Config) {
        if let Some(addr) = &self.view {
            config.view.enabled = true;
            config.view.addr = addr.clone();
        }
    }
}
