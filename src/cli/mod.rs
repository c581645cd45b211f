//! The command line's edge: each command's arguments beside the code that runs it (anyhow
//! errors); the work itself is the library's.
pub mod bench;
pub mod eval;
pub mod export;
pub mod plot;
pub mod report;
pub mod rollout;
pub mod sweep;
pub mod train;
