//! `danced train` and `danced train-beats`, gone to the training binary: old scripts are told
//! where, with their own arguments.

use anyhow::{Result, bail};

/// Arguments of a moved command, whatever they are.
#[derive(clap::Args, Debug)]
pub struct MovedArgs {
    /// Passed on unread.
    #[arg(trailing_var_arg = true, allow_hyphen_values = true, num_args = 0..)]
    pub args: Vec<String>,
}

/// Fails, naming the `danced-train` subcommand that replaced `danced old`.
pub fn moved(old: &str, new: &str, args: &MovedArgs) -> Result<()> {
    let rest: String = args.args.iter().map(|a| format!(" {a}")).collect();
    bail!(
        "`danced {old}` moved to the training binary (danced no longer links burn): run \
         `danced-train {new}{rest}`, e.g. `cargo run --release -p training -- {new}{rest}`"
    )
}
