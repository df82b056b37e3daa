//! The browser view: `--view` serves a page that shows the dancer on a VRM avatar, live, with
//! a HUD and controls. The page applies the VMC bundles a VMC receiver gets, exactly as a VMC
//! Marionette does, so it is also the check that our VMC bones are right on a real VRM.

pub mod assets;
pub mod client;
pub mod counters;
pub mod http;
pub mod hud;
pub mod mannequin;
pub mod playback;
pub mod server;
pub mod sink;

pub use counters::{ViewCounters, ViewReport};
pub use hud::ViewHello;
pub use server::{DEFAULT_VIEW_ADDR, LiveFeed, ViewServer};
pub use sink::{SinkPair, ViewSink};
