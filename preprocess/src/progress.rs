//! Progress reporting for long work: the [`Progress`] trait every stage of mdlod reports
//! through lives in `mdlod-format` (the crate the converter and the renderer share), so
//! that one reporter, the command line's progress bar, serves both.

pub use mdlod_format::progress::{NoProgress, Progress};
