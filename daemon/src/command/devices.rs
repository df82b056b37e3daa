//! `danced devices`: the audio and MIDI inputs.

use anyhow::Result;

/// Runs `danced devices`.
pub fn devices() -> Result<()> {
    println!("audio inputs:");
    for line in crate::live::devices::list_inputs() {
        println!("  {line}");
    }
    println!("MIDI inputs:");
    for line in crate::live::devices::list_midi() {
        println!("  {line}");
    }
    Ok(())
}
