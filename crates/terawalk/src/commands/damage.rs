//! What `render` and `bench` do when store pages fail their checksum or decoding while they draw:
//! the frames draw the best resident ancestor (tw-runtime's selection), and the command says so
//! in its summary and fails unless `--allow-damaged`, so that a script never takes a damaged
//! image for the store's true one.

use std::path::Path;

use anyhow::{bail, Result};

/// How many failed pages a summary lists by number (the report lists them all).
const LISTED: usize = 10;

/// Prints the summary line of `failed` (page, error) and returns an error unless `allow` or
/// nothing failed.
pub fn check(store: &Path, failed: &[(u32, String)], allow: bool) -> Result<()> {
    if failed.is_empty() {
        return Ok(());
    }
    let listed: Vec<String> = failed.iter().take(LISTED).map(|(p, _)| p.to_string()).collect();
    let more = failed.len() - listed.len();
    let more = if more > 0 { format!(" and {more} more") } else { String::new() };
    outln!(
        "damaged store: {} page(s) failed their checksum or decoding (pages {}{more}); their \
         geometry was drawn from coarser levels where the store has them, and is missing \
         otherwise. First error: {}",
        failed.len(),
        listed.join(", "),
        failed[0].1
    );
    if allow {
        return Ok(());
    }
    bail!(
        "{} is damaged ({} bad page(s)): the output is not the store's true image. `terawalk info \
         {} --verify` checks every page; rebuild the store, or pass --allow-damaged to accept \
         the output",
        store.display(),
        failed.len(),
        store.display()
    )
}
