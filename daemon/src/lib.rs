//! danced library.
