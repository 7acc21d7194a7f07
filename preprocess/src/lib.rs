//! mdlod's offline stage: read particle dumps, build the PCA-split level-of-detail
//! hierarchy, quantize it and write it as a `.mdlod` file through `mdlod-format`.

pub mod batch;
pub mod chunked;
pub mod convert;
pub mod direct;
pub mod frame;
pub mod hierarchy;
pub mod progress;
pub mod readers;
pub mod species;

pub use frame::{Attribute, Frame, SpeciesName};
pub use progress::{NoProgress, Progress};
