//! Errors of the renderer. Every failure a user can cause or meet (no GPU, a bad view
//! file, a corrupt `.mdlod` file, an unwritable output) is a variant with a message that
//! says what to do; nothing in this crate panics on bad input.

use std::path::PathBuf;

/// What can go wrong while rendering.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// No graphics adapter could be opened with the requested backends.
    #[error(
        "no graphics adapter found (backends tried: {backends}{env}). Install a GPU driver, \
         or Mesa's software Vulkan driver (Debian/Ubuntu: `apt-get install mesa-vulkan-drivers \
         libvulkan1`), or set WGPU_BACKEND to a backend this machine has (e.g. `vulkan`, `gl`)"
    )]
    NoAdapter {
        /// The backend mask that was searched, e.g. `VULKAN | GL`.
        backends: String,
        /// `, WGPU_BACKEND=...` when the environment chose the backends, else empty.
        env: String,
    },
    /// The adapter refused to open a device.
    #[error("the adapter {adapter:?} could not open a device: {message}")]
    Device { adapter: String, message: String },
    /// The GPU reported an error (validation, out of memory, a failed readback).
    #[error("GPU error: {0}")]
    Gpu(String),
    /// The `.mdlod` file could not be opened or is invalid.
    #[error(transparent)]
    Format(#[from] mdlod_format::FormatError),
    /// The view file could not be read or parsed.
    #[error("view file {path}: {message}")]
    View { path: PathBuf, message: String },

    /// An `.sndf` file whose header the shading cannot use (its camera, its size).
    #[error("{path}: {message}")]
    Sndf { path: PathBuf, message: String },
    /// The file was rewritten in place while it was drawn
    /// ([`mdlod_format::MdlodFile::changed_on_disk`]).
    #[error("{path}: the file changed while it was read (another program rewrote it in place): the image would mix its old and new data, so none is written; render again once it is written whole")]
    Changed { path: PathBuf },
    /// Data no view can draw (bounds past what single precision holds).
    #[error("{path}: {message}")]
    Data { path: PathBuf, message: String },
    /// Options that cannot be rendered (zero size, zero samples, ...).
    #[error("invalid options: {0}")]
    InvalidOptions(String),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// Encoding or decoding a PNG failed (`action`: "writing" or "reading").
    #[error("{path}: {action} PNG: {message}")]
    Png {
        path: PathBuf,
        action: &'static str,
        message: String,
    },
}

impl RenderError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        RenderError::Io {
            path: path.into(),
            source,
        }
    }
}
