//! The measurements of `danced bench`, each on annotated songs: beat tracking ([`beats`]), the
//! motion lag a receiver sees ([`lag`]) and how the dancer's beat recovers from a tempo change
//! ([`beat_recovery`]), key poses cued on the next bar ([`cues`]) and how far a dancer wanders
//! on its stage ([`stage`]), how a library cut from your own dances dances ([`moves`]); the
//! songs they share are in [`sets`].

pub mod beat_recovery;
pub mod beats;
pub mod cues;
pub mod lag;
pub mod moves;
pub mod sets;
pub mod stage;
