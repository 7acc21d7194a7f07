//! Errors of reading and writing `.mdlod` files. Every message names the file and, where
//! there is one, the place in it (section, record index or byte offset).

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    /// An attribute the file does not keep (`names`: those it keeps).
    #[error(
        "{path}: no attribute named {name:?} (the file keeps {names}; `mdlod convert \
         --attribute A --attribute B` keeps several)"
    )]
    NoSuchAttribute {
        path: PathBuf,
        name: String,
        names: String,
    },

    /// The program is being interrupted (see [`crate::writer::refuse_new_outputs`]).
    #[error("no new output begins: the program is being interrupted")]
    OutputsRefused,

    #[error(
        "{path}: not an .mdlod file (the first 8 bytes are not the mdlod signature); a \
         particle dump is converted to one with `mdlod convert`"
    )]
    BadMagic { path: PathBuf },

    /// An S-NDF file where a `.mdlod` file is read: it holds no particles.
    #[error(
        "{path}: an S-NDF file (written by `mdlod sample`), not an .mdlod file: it holds no \
         particles; `mdlod shade` lights it and `mdlod info` describes it"
    )]
    SndfNotMdlod { path: PathBuf },

    #[error(
        "{path}: format version {major}.{minor} is not readable by this mdlod, which reads \
         major versions {readable_min} to {readable_max}; {hint}"
    )]
    UnsupportedVersion {
        path: PathBuf,
        major: u16,
        minor: u16,
        readable_min: u16,
        readable_max: u16,
        hint: &'static str,
    },

    #[error("{path}: {place}: checksum mismatch (stored {stored:016x}, computed {computed:016x}); the file is corrupt")]
    Checksum {
        path: PathBuf,
        place: String,
        stored: u64,
        computed: u64,
    },

    #[error("{path}: {place}: {problem}")]
    Corrupt {
        path: PathBuf,
        place: String,
        problem: String,
    },

    #[error("{path}: METADATA section: invalid JSON: {source}")]
    Metadata {
        path: PathBuf,
        #[source]
        source: serde_json::Error,
    },

    #[error("{path}: cannot write: {problem}")]
    Write { path: PathBuf, problem: String },
}

impl FormatError {
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        FormatError::Io {
            path: path.into(),
            source,
        }
    }

    pub(crate) fn corrupt(
        path: impl Into<PathBuf>,
        place: impl Into<String>,
        problem: impl Into<String>,
    ) -> Self {
        FormatError::Corrupt {
            path: path.into(),
            place: place.into(),
            problem: problem.into(),
        }
    }
}
