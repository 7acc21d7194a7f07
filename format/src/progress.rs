//! Progress reporting for long work, decoupled from any terminal library.
//!
//! Libraries report through [`Progress`] (the converter's reading and building, the
//! renderer's drawing of large cuts); the command-line program implements it with a
//! progress bar on a terminal and nothing in a pipe; tests and benchmarks pass
//! [`NoProgress`]. It lives here, in the crate both depend on, so that one reporter
//! serves both.

/// Receives progress of long-running library work. Implementations must be cheap and
/// thread-safe: `advance` may be called from many worker threads.
pub trait Progress: Sync {
    /// A new stage begins; `total` is in `unit`s (e.g. "particles", "bytes") when known.
    fn stage(&self, name: &str, total: Option<u64>, unit: &'static str);
    /// `amount` more units of the current stage are done.
    fn advance(&self, amount: u64);
    /// The current stage is complete.
    fn finish_stage(&self) {}
}

/// Reports nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn stage(&self, _name: &str, _total: Option<u64>, _unit: &'static str) {}
    fn advance(&self, _amount: u64) {}
}
