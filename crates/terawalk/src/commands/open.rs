//! Opening a model file where a store is expected (`terawalk render plant.ply`, `terawalk view
//! scan.glb`): the model is built once into a cache folder by the very code `terawalk build`
//! runs ([`build_store_with`]: the same options and atomic write, so an interrupted build
//! leaves no half-written store; `build`'s progress bars, or the viewer's progress window when
//! the viewer opens a file), and the cached store is opened. A later run with the
//! same file and options finds it and opens it at once.
//!
//! The cache key is a hash of what decides the store's content: the input's canonical path,
//! size and modification time (a changed or touched file rebuilds), the build options that
//! shape the store (up axis, units, the LOD and paging parameters `BuildOptions::describe`
//! lists, less the memory budget, which changes how the build runs, not what it writes) and
//! the program and store format versions. The cache is bounded: after each open the least
//! recently used stores beyond `--cache-size` are removed (a store's modification time is its
//! last use: it is touched each time it is opened).
//!
//! `bench`, `info` and `path` keep asking for a store instead (`commands::open_store` prints
//! the `terawalk build` command): a benchmark should measure a store the user named and keeps,
//! not one that a cache may have evicted or rebuilt between runs (and a build of minutes would
//! hide inside the benchmark's run); `info` describes a store file, which a model is not; and
//! a path is made for the store it is played in.

use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

use anyhow::{Context, Result};
use clap::Parser;

use crate::cli::{BuildArgs, OpenArgs};
use crate::commands::build::{build_store_with, options, Bars};
use crate::units::fmt_bytes;
use tw_build::BuildProgress;
use tw_store::Store;

/// Opens the store for `input`: `input` itself unless it is a model file, else the cached store
/// built from it (built now when missing, or unreadable: a store of an older format). `up` is
/// the command's `--up`, which a model is built with. Returns the store's path with it.
pub fn open(input: &Path, up: Option<u8>, open: &OpenArgs, quiet: bool) -> Result<(PathBuf, Store)> {
    if !is_model(input) {
        return Ok((input.to_path_buf(), crate::commands::open_store(input)?));
    }
    let path = cached_store(input, up, open, quiet, &mut Bars::new(quiet))?;
    let store = crate::commands::open_store(&path)?;
    Ok((path, store))
}

/// The path of the store to open for `input`: `input` itself unless it is a model, else its
/// cached store, built now (reporting to `progress`) when missing or unreadable. The viewer's
/// opener (`commands::view`) runs this on its background thread.
pub fn store_for(
    input: &Path,
    up: Option<u8>,
    open: &OpenArgs,
    progress: &mut dyn BuildProgress,
) -> Result<PathBuf> {
    if !is_model(input) {
        return Ok(input.to_path_buf());
    }
    cached_store(input, up, open, true, progress)
}

/// Whether opening `input` would build a store: a model file whose cached store is missing or
/// unreadable (the viewer then opens its window at once and builds in the background, with
/// its progress window). An unreadable input or no cache folder is an error here, before
/// any window.
pub fn needs_build(input: &Path, up: Option<u8>, open: &OpenArgs) -> Result<bool> {
    if !is_model(input) {
        return Ok(false);
    }
    let args = build_args(input, up, open)?;
    let path = cache_dir(open)?.join(cached_name(input, &args)?);
    Ok(Store::open(&path).is_err())
}

/// The cached store of the model `input`, built when missing or unreadable; the cache is
/// trimmed to `--cache-size` after.
fn cached_store(
    input: &Path,
    up: Option<u8>,
    open: &OpenArgs,
    quiet: bool,
    progress: &mut dyn BuildProgress,
) -> Result<PathBuf> {
    let args = build_args(input, up, open)?;
    let cache = cache_dir(open)?;
    let path = cache.join(cached_name(input, &args)?);
    let cached = match Store::open(&path) {
        Ok(store) => Some(store),
        Err(e) if path.exists() => {
            outln!("cannot use cached store ({e}): building it again");
            None
        }
        Err(_) => None,
    };
    match cached {
        Some(_) => {
            outln!("using cached store {} (built from {})", path.display(), input.display());
            mark_used(&path);
        }
        None => build_into_cache(input, &args, &path, quiet, progress)?,
    }
    for (removed, bytes) in evict(&cache, open.cache_size, &path) {
        outln!(
            "removed cached store {} ({}): the cache keeps at most {} (--cache-size)",
            removed.display(),
            fmt_bytes(bytes),
            fmt_bytes(open.cache_size)
        );
    }
    Ok(path)
}

/// Builds `input` into `store` in the cache folder, reporting to `progress`.
fn build_into_cache(
    input: &Path,
    args: &BuildArgs,
    store: &Path,
    quiet: bool,
    progress: &mut dyn BuildProgress,
) -> Result<()> {
    if let Some(cache) = store.parent() {
        std::fs::create_dir_all(cache)
            .with_context(|| format!("cannot create the cache folder {}", cache.display()))?;
    }
    outln!("building {} into the cache: {} (once; later runs reuse it)", input.display(), store.display());
    let start = Instant::now();
    let report = build_store_with(args, store, quiet, progress)?;
    outln!(
        "built {} ({}) in {:.1} s",
        store.display(),
        fmt_bytes(report.file_bytes),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

/// A file the importers read (by its name, as `build` decides) that is not a store: a store
/// named like a model (`x.ply` written by `build -o`) is still opened as a store.
pub fn is_model(path: &Path) -> bool {
    // A format the importers read, or one `build` converts with an external tool first.
    let known = tw_io::format::Format::from_name(path).is_some()
        || tw_io::convert::Converter::for_name(path).is_some();
    if !known {
        return false;
    }
    let mut magic = [0u8; 8];
    let is_store = std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut magic))
        .is_ok_and(|_| &magic == b"TERAWALK");
    !is_store
}

/// The arguments `terawalk build INPUT` would get with the command's options: parsed by the
/// same parser, so every option the command does not set has `build`'s default.
fn build_args(input: &Path, up: Option<u8>, open: &OpenArgs) -> Result<BuildArgs> {
    #[derive(Parser)]
    struct Build {
        #[command(flatten)]
        args: BuildArgs,
    }
    let mut argv: Vec<std::ffi::OsString> = vec!["build".into(), input.into()];
    argv.push(format!("--memory={}", open.build_memory).into());
    argv.push(format!("--units={}", open.units).into());
    if let Some(axis) = up {
        argv.push(format!("--up={}", ["x", "y", "z"][axis.min(2) as usize]).into());
    }
    Build::try_parse_from(argv).map(|b| b.args).map_err(|e| anyhow::anyhow!("build options: {e}"))
}

/// `--cache-dir`, else `$TERAWALK_CACHE`, else `$XDG_CACHE_HOME/terawalk`, else
/// `~/.cache/terawalk` (the XDG base directory convention).
fn cache_dir(open: &OpenArgs) -> Result<PathBuf> {
    let var = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty()).map(PathBuf::from);
    resolve_cache_dir(open.cache_dir.clone(), var("TERAWALK_CACHE"), var("XDG_CACHE_HOME"), var("HOME"))
}

fn resolve_cache_dir(
    flag: Option<PathBuf>,
    terawalk_cache: Option<PathBuf>,
    xdg_cache_home: Option<PathBuf>,
    home: Option<PathBuf>,
) -> Result<PathBuf> {
    flag.or(terawalk_cache)
        .or(xdg_cache_home.map(|x| x.join("terawalk")))
        .or(home.map(|h| h.join(".cache").join("terawalk")))
        .ok_or_else(|| {
            anyhow::anyhow!("no cache folder for the store: give --cache-dir DIR (neither HOME nor XDG_CACHE_HOME is set)")
        })
}

/// `STEM-KEY.tw`: the model's name, to be recognised in the folder, and the key's 16 hex digits.
fn cached_name(input: &Path, args: &BuildArgs) -> Result<String> {
    let meta = std::fs::metadata(input).with_context(|| format!("cannot read {}", input.display()))?;
    let canonical =
        std::fs::canonicalize(input).with_context(|| format!("cannot read {}", input.display()))?;
    let mtime = meta.modified().ok().and_then(|t| t.duration_since(SystemTime::UNIX_EPOCH).ok());
    let shape: String = options(args).describe().lines().filter(|l| !l.starts_with("memory=")).collect();
    let key = format!(
        "terawalk {}\nstore format {}\n{}\n{} bytes\nmtime {:?}\nunits={}\n{shape}",
        env!("CARGO_PKG_VERSION"),
        tw_store::FORMAT_VERSION,
        canonical.display(),
        meta.len(),
        mtime,
        args.units,
    );
    let stem = crate::commands::store_name_for(input);
    let stem = stem.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    Ok(format!("{stem}-{:016x}.tw", fnv1a(key.as_bytes())))
}

/// FNV-1a, 64 bits: a stable hash (the standard library's may change between releases, and a
/// changed key would only rebuild, but needlessly).
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3))
}

/// Whether a file name is one [`cached_name`] makes: only those are ever evicted, so a cache
/// folder pointed at a folder of other stores leaves them alone.
fn is_cached_name(name: &str) -> bool {
    let Some(base) = name.strip_suffix(".tw") else { return false };
    base.rsplit_once('-')
        .is_some_and(|(_, key)| key.len() == 16 && key.bytes().all(|b| b.is_ascii_hexdigit()))
}

/// Records a use of a cached store: its modification time is the last use the eviction orders by
/// (access times are unreliable: relatime, noatime).
fn mark_used(store: &Path) {
    let touched =
        std::fs::File::options().write(true).open(store).and_then(|f| f.set_modified(SystemTime::now()));
    if let Err(e) = touched {
        tracing::debug!("cannot mark {} as used: {e}", store.display());
    }
}

/// Removes the least recently used cached stores while they take more than `cap` bytes, never
/// `keep` (the one being opened); returns what it removed. A store another process has open stays
/// readable to it until it closes it (Unix unlinks names, not open files).
fn evict(cache: &Path, cap: u64, keep: &Path) -> Vec<(PathBuf, u64)> {
    let Ok(entries) = std::fs::read_dir(cache) else { return Vec::new() };
    let mut stores: Vec<(SystemTime, u64, PathBuf)> = entries
        .flatten()
        .filter(|e| is_cached_name(&e.file_name().to_string_lossy()))
        .filter_map(|e| {
            let meta = e.metadata().ok().filter(|m| m.is_file())?;
            Some((meta.modified().unwrap_or(SystemTime::UNIX_EPOCH), meta.len(), e.path()))
        })
        .collect();
    let to_remove = over_cap(&mut stores, cap, keep);
    to_remove
        .into_iter()
        .filter(|(path, _)| match std::fs::remove_file(path) {
            Ok(()) => true,
            Err(e) => {
                tracing::warn!("cannot remove cached store {}: {e}", path.display());
                false
            }
        })
        .collect()
}

/// The stores beyond `cap` bytes, newest first kept: `keep` always counts first, then the others
/// by their last use, most recent first; every store from the one that crosses the cap on is
/// removed.
fn over_cap(stores: &mut [(SystemTime, u64, PathBuf)], cap: u64, keep: &Path) -> Vec<(PathBuf, u64)> {
    stores.sort_by(|a, b| (b.2 == keep).cmp(&(a.2 == keep)).then(b.0.cmp(&a.0)));
    let mut total = 0u64;
    let mut removed = Vec::new();
    for (_, bytes, path) in stores.iter() {
        total = total.saturating_add(*bytes);
        if total > cap && path != keep {
            removed.push((path.clone(), *bytes));
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn cache_folder_follows_flag_then_env_then_xdg_then_home() {
        let p = |s: &str| Some(PathBuf::from(s));
        assert_eq!(resolve_cache_dir(p("/f"), p("/t"), p("/x"), p("/h")).unwrap(), PathBuf::from("/f"));
        assert_eq!(resolve_cache_dir(None, p("/t"), p("/x"), p("/h")).unwrap(), PathBuf::from("/t"));
        assert_eq!(resolve_cache_dir(None, None, p("/x"), p("/h")).unwrap(), PathBuf::from("/x/terawalk"));
        assert_eq!(
            resolve_cache_dir(None, None, None, p("/h")).unwrap(),
            PathBuf::from("/h/.cache/terawalk")
        );
        let e = resolve_cache_dir(None, None, None, None).unwrap_err().to_string();
        assert!(e.contains("--cache-dir"), "{e}");
    }

    #[test]
    fn only_names_the_cache_makes_are_evictable() {
        assert!(is_cached_name("plant-0123456789abcdef.tw"));
        assert!(is_cached_name("my-scan-0123456789ABCDEF.tw"));
        for other in ["plant.tw", "plant-0123.tw", "plant-0123456789abcdeg.tw", "x-0123456789abcdef.tw.tmp"] {
            assert!(!is_cached_name(other), "{other}");
        }
    }

    #[test]
    fn eviction_removes_the_least_recently_used_beyond_the_cap_but_never_the_open_one() {
        let t = |s: u64| SystemTime::UNIX_EPOCH + Duration::from_secs(s);
        let mut stores = vec![
            (t(10), 40, PathBuf::from("old")),
            (t(30), 40, PathBuf::from("new")),
            (t(20), 40, PathBuf::from("mid")),
            (t(1), 40, PathBuf::from("open")),
        ];
        // The open store counts first although it is the oldest: 40 + 40 (new) fit in 100.
        let removed = over_cap(&mut stores, 100, Path::new("open"));
        assert_eq!(removed, vec![(PathBuf::from("mid"), 40), (PathBuf::from("old"), 40)]);
        // A cap below the open store itself removes all the others, and keeps it.
        let removed = over_cap(&mut stores, 10, Path::new("open"));
        assert_eq!(removed.len(), 3);
        assert!(over_cap(&mut stores, 1000, Path::new("open")).is_empty());
    }

    #[test]
    fn the_key_changes_with_the_options_that_shape_the_store_not_the_build_memory() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("m.ply");
        std::fs::write(&model, "ply\n").unwrap();
        let open = |units: &str, memory: u64| OpenArgs {
            cache_dir: None,
            cache_size: 1 << 30,
            units: units.into(),
            build_memory: memory,
        };
        let name =
            |up: Option<u8>, o: &OpenArgs| cached_name(&model, &build_args(&model, up, o).unwrap()).unwrap();
        let base = name(None, &open("", 1 << 30));
        assert!(base.starts_with("m-") && is_cached_name(&base), "{base}");
        assert_eq!(name(None, &open("", 2 << 30)), base, "the build's memory budget shapes nothing");
        assert_ne!(name(None, &open("mm", 1 << 30)), base);
        assert_ne!(name(Some(1), &open("", 1 << 30)), base);
        assert_ne!(name(Some(1), &open("", 1 << 30)), name(Some(2), &open("", 1 << 30)));
        std::fs::write(&model, "ply\nmore\n").unwrap();
        assert_ne!(name(None, &open("", 1 << 30)), base, "a changed file rebuilds");
    }

    #[test]
    fn only_a_model_missing_from_the_cache_needs_a_build() {
        let dir = tempfile::tempdir().unwrap();
        let (model, store) = (dir.path().join("m.ply"), dir.path().join("s.tw"));
        std::fs::write(&model, "ply\n").unwrap();
        std::fs::write(&store, b"TERAWALK\x02\0\0\0").unwrap();
        let open = |units: &str| OpenArgs {
            cache_dir: Some(dir.path().join("cache")),
            cache_size: 1 << 30,
            units: units.into(),
            build_memory: 1 << 30,
        };
        assert!(needs_build(&model, None, &open("")).unwrap());
        assert!(!needs_build(&store, None, &open("")).unwrap());
        // A cache entry that is not a readable store is built again.
        let cached = dir
            .path()
            .join("cache")
            .join(cached_name(&model, &build_args(&model, None, &open("")).unwrap()).unwrap());
        std::fs::create_dir_all(cached.parent().unwrap()).unwrap();
        std::fs::write(&cached, "not a store").unwrap();
        assert!(needs_build(&model, None, &open("")).unwrap());
    }

    #[test]
    fn a_store_named_like_a_model_is_opened_as_a_store() {
        let dir = tempfile::tempdir().unwrap();
        let store = dir.path().join("s.ply");
        std::fs::write(&store, b"TERAWALK\x02\0\0\0").unwrap();
        assert!(!is_model(&store));
        let model = dir.path().join("m.ply");
        std::fs::write(&model, "ply\n").unwrap();
        assert!(is_model(&model));
        assert!(!is_model(&dir.path().join("s.tw")));
    }
}
