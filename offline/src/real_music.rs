//! Real recordings with beat and downbeat references (`data/real-music`, and more of the same
//! layout): which of them are kept out of training, so the benches measure on music no
//! network has heard.
//!
//! Files are named `<source>__<track>...`, `<source>` being the package or collection the
//! recording came from. The split is by source, not by file: tracks of one soundtrack share a
//! composer, a studio and a mix, and a network that heard one of them has half heard the rest.

use std::path::Path;

/// Sources whose recordings are held out of every training run, chosen once (every third of
/// `data/real-music`'s 24 sources in name order, from the second) for a spread of orchestral,
/// live-band rock, world music in 3/4, electronic, pop and reggae: 15 of its 50 clips.
/// `tools/real_music/build_extra.py` reads this list too.
pub const HELD_OUT_SOURCES: [&str; 8] = [
    "flare-game",
    "fretsonfire-songs-sectoid",
    "hyperrogue-music",
    "megaglest-data",
    "nexuiz-music",
    "rrootage-data",
    "supertux-data",
    "warzone2100-music",
];

/// The source of a recording named `<source>__<track>...` (`None` for another name).
pub fn source_of(path: &Path) -> Option<&str> {
    let stem = path.file_name()?.to_str()?;
    stem.split_once("__").map(|(source, _)| source)
}

/// Whether the recording at `path` comes from a held-out source.
pub fn is_held_out(path: &Path) -> bool {
    source_of(path).is_some_and(|s| HELD_OUT_SOURCES.contains(&s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_split_is_by_source() {
        assert!(is_held_out(Path::new("x/nexuiz-music__ninesix.flac")));
        assert!(is_held_out(Path::new("nexuiz-music__other__120.beats")));
        assert!(!is_held_out(Path::new("x/xmoto-data__ridealong.flac")));
        assert!(!is_held_out(Path::new("x/song-1000.flac")));
        assert_eq!(source_of(Path::new("a/b__c.flac")), Some("b"));
        assert_eq!(source_of(Path::new("a/bc.flac")), None);
    }
}
