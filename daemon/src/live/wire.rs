//! The types the pipeline exchanges with the outside world, from the `protocols` crate.

pub use protocols::{AnalysisEvent, BodyFrame, BoneSample, ControlEvent, Quantize};
