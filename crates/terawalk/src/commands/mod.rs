//! One module per subcommand, and the policies several of them share.

pub mod bench;
pub mod build;
pub mod build_job;
pub mod build_plan;
pub mod build_submit;
pub mod collide;
pub mod cull_client;
pub mod cull_server;
pub mod damage;
pub mod demo;
pub mod export;
pub mod generate;
pub mod info;
pub mod open;
pub mod path;
pub mod preview;
pub mod render;
pub mod stats;
pub mod video;
pub mod view;

use std::path::Path;

/// Opens the store a command reads. The store's errors name the file; a model file given in
/// its place (`terawalk info model.glb`) gets the command that makes a store of it. `render`
/// and `view` build a model into a cache instead ([`open::open`], which says why `bench`,
/// `info` and `path` do not).
pub fn open_store(path: &Path) -> anyhow::Result<tw_store::Store> {
    tw_store::Store::open(path).map_err(|e| {
        let model = tw_io::format::Format::from_name(path).is_some();
        match (&e, model) {
            (tw_store::StoreError::NotAStore { .. }, true) => anyhow::anyhow!(
                "{e}\n  {} is a model file: build a store from it first, then open that:\n    \
                 terawalk build {} -o {}",
                path.display(),
                path.display(),
                store_name_for(path).display()
            ),
            _ => anyhow::Error::new(e).context("cannot open the store"),
        }
    })
}

/// `model.ply.gz` → `model.tw`, beside the model: the store `build` writes without `-o`.
pub fn store_name_for(model: &Path) -> std::path::PathBuf {
    let name = model.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let stem = name.trim_end_matches(".gz");
    let stem = stem.rsplit_once('.').map_or(stem, |(s, _)| s);
    model.with_file_name(format!("{stem}.tw"))
}
