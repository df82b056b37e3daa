//! Progress bars of the long-running commands.

use indicatif::{ProgressBar, ProgressStyle};

/// A bar counting `len` items, with a message (the item at hand).
pub fn count_bar(len: u64) -> ProgressBar {
    let pb = ProgressBar::new(len);
    pb.set_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    pb
}
