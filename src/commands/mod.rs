//! One module per subcommand.

pub mod batch;
pub mod convert;
pub mod demo;
pub mod generate;
pub mod info;
pub mod render;
pub mod sample;
pub mod shade;
pub mod verify;
pub mod view;
