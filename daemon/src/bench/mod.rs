//! The measurements of `danced bench`, each on annotated songs: beat tracking ([`beats`]), the
//! motion lag a receiver sees ([`lag`]) and how the dancer's beat recovers from a tempo change
//! ([`beat_recovery`]), and key poses cued on the next bar ([`cues`]); the songs they share are
//! in [`sets`].

pub mod beat_recovery;
pub mod beats;
pub mod cues;
pub mod lag;
pub mod sets;
