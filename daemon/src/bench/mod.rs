//! The measurements of `danced bench`, each on annotated songs: beat tracking ([`beats`]), the
//! motion lag a receiver sees ([`lag`]) and how the dancer's beat recovers from a tempo change
//! ([`beat_recovery`]), key poses cued on the next bar ([`cues`]) and how far a dancer wanders
//! on its stage ([`stage`]), how a library cut from your own dances dances ([`moves`]), the
//! show's clocks followed and led ([`clock`], and Link in builds with it); the songs they
//! share are in [`sets`].

pub mod beat_recovery;
pub mod beats;
pub mod clock;
pub mod cues;
pub mod lag;
#[cfg(feature = "link")]
pub mod link;
pub mod moves;
pub mod private_network;
pub mod sets;
pub mod stage;
