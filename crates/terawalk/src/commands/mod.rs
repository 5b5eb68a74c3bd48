//! One module per subcommand.

pub mod bench;
pub mod build;
pub mod demo;
pub mod generate;
pub mod info;
pub mod path;
pub mod preview;
pub mod render;
pub mod stats;
pub mod view;
