//! Working-file I/O off the calling thread: the build's early phases stream gigabytes through
//! their working files (40 bytes per triangle, the buckets 35). [`SpillWriter`] hands full
//! buffers to a writer thread; `read_ahead` reads and decodes the next chunks of a record file
//! on a reader thread. Both bypass the page cache where the file system allows
//! ([`tw_core::direct_io`]: on this project's VMs, page-cache pages of new files cost ~7 s of
//! system time per GB). Both keep the bytes and their order exactly as a plain buffered writer
//! or reader would, so builds stay byte-identical; memory is a fixed number of buffers.

use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

use tempfile::TempPath;
use tw_core::direct_io::{AlignedBuf, DirectReader, DirectWriter};

use crate::error::BuildError;

/// Full buffers queued for the writer thread beyond the ones being filled.
pub const WRITES_IN_FLIGHT: usize = 4;

/// Buffer of `read_ahead`'s direct reads.
const READ_BUFFER: usize = 4 << 20;

/// What the writer thread gives back: the files, or the index of the file that failed and why.
type WriterResult = Result<Vec<File>, (usize, std::io::Error)>;

/// A buffer for the writer thread: the file, the bytes, and whether they end the file.
type Job = (usize, AlignedBuf, bool);

/// Buffered appends to several files, written on a background thread in the order given,
/// bypassing the page cache where the file system allows ([`SpillWriter::direct`]; see
/// [`tw_core::direct_io`] for why).
///
/// Memory: one buffer per file being filled plus at most [`WRITES_IN_FLIGHT`] full ones queued
/// or being written, `buffer` bytes each (rounded up to 4 KiB).
pub struct SpillWriter {
    paths: Vec<PathBuf>,
    filling: Vec<AlignedBuf>,
    buffer: usize,
    to_writer: Option<SyncSender<Job>>,
    recycled: Receiver<AlignedBuf>,
    thread: Option<JoinHandle<WriterResult>>,
    /// The writer thread's error, once it stopped on one: every later call reports it again
    /// (file index, kind, text), rather than a "stopped" that hides what happened.
    failed: Option<(usize, std::io::ErrorKind, String)>,
}

impl SpillWriter {
    /// A writer over open `files` (named by `paths`, for errors), written from their start
    /// through the page cache, with buffers of `buffer` bytes.
    #[cfg(test)]
    pub fn new(files: Vec<File>, paths: Vec<PathBuf>, buffer: usize) -> SpillWriter {
        assert_eq!(files.len(), paths.len());
        SpillWriter::spawn(files.into_iter().map(DirectWriter::buffered).collect(), paths, buffer)
    }

    /// A writer over the existing files `paths` (truncated), written with direct I/O where the
    /// file system allows, with buffers of `buffer` bytes.
    pub fn direct(paths: Vec<PathBuf>, buffer: usize) -> Result<SpillWriter, BuildError> {
        let writers = paths
            .iter()
            .map(|p| DirectWriter::open(p).map_err(|e| BuildError::io(p, e)))
            .collect::<Result<Vec<_>, _>>()?;
        Ok(SpillWriter::spawn(writers, paths, buffer))
    }

    fn spawn(writers: Vec<DirectWriter>, paths: Vec<PathBuf>, buffer: usize) -> SpillWriter {
        let buffer = AlignedBuf::new(buffer.max(4096)).capacity();
        let (to_writer, queued) = sync_channel::<Job>(WRITES_IN_FLIGHT);
        let (give_back, recycled) = sync_channel::<AlignedBuf>(WRITES_IN_FLIGHT + 1);
        let thread = std::thread::Builder::new()
            .name("tw-spill-writer".into())
            .spawn(move || {
                let mut writers = writers;
                for (i, mut bytes, last) in queued.iter() {
                    let w = &mut writers[i];
                    if last { w.write_last(&mut bytes) } else { w.write(&bytes) }.map_err(|e| (i, e))?;
                    bytes.clear();
                    // A full return queue only means the producer has buffers enough.
                    let _ = give_back.try_send(bytes);
                }
                Ok(writers.into_iter().map(DirectWriter::into_file).collect())
            })
            .expect("spawning the spill writer thread");
        SpillWriter {
            filling: (0..paths.len()).map(|_| AlignedBuf::empty()).collect(),
            paths,
            buffer,
            to_writer: Some(to_writer),
            recycled,
            thread: Some(thread),
            failed: None,
        }
    }

    /// Appends `bytes` to file `file`.
    #[inline]
    pub fn write(&mut self, file: usize, bytes: &[u8]) -> Result<(), BuildError> {
        let buf = &mut self.filling[file];
        if bytes.len() <= buf.room() {
            buf.extend_from_slice(bytes);
            return Ok(());
        }
        self.write_slow(file, bytes)
    }

    /// [`SpillWriter::write`] when the buffer is missing or full: only whole buffers (a multiple
    /// of 4 KiB) go to the writer before the last, as direct transfers need.
    #[cold]
    fn write_slow(&mut self, file: usize, mut bytes: &[u8]) -> Result<(), BuildError> {
        loop {
            if self.filling[file].capacity() == 0 {
                self.filling[file] =
                    self.recycled.try_recv().unwrap_or_else(|_| AlignedBuf::new(self.buffer));
            }
            let buf = &mut self.filling[file];
            let room = buf.room();
            if bytes.len() <= room {
                buf.extend_from_slice(bytes);
                return Ok(());
            }
            buf.extend_from_slice(&bytes[..room]);
            bytes = &bytes[room..];
            self.send(file, false)?;
        }
    }

    fn send(&mut self, file: usize, last: bool) -> Result<(), BuildError> {
        if self.filling[file].is_empty() {
            return Ok(());
        }
        let full = std::mem::replace(&mut self.filling[file], AlignedBuf::empty());
        let sent = self.to_writer.as_ref().map(|tx| tx.send((file, full, last)).is_ok()).unwrap_or(false);
        if !sent {
            // The writer stopped on an error: report it.
            return Err(self.join().err().unwrap_or_else(|| {
                BuildError::io(&self.paths[file], std::io::Error::other("the writer thread stopped"))
            }));
        }
        Ok(())
    }

    fn join(&mut self) -> Result<Vec<File>, BuildError> {
        self.to_writer = None;
        let Some(thread) = self.thread.take() else {
            let (i, kind, text) = self.failed.clone().unwrap_or_else(|| {
                (
                    0,
                    std::io::ErrorKind::Other,
                    "the writer thread ended before its files were finished".into(),
                )
            });
            return Err(BuildError::io(&self.paths[i], std::io::Error::new(kind, text)));
        };
        match thread.join() {
            Ok(Ok(files)) => Ok(files),
            Ok(Err((i, e))) => {
                self.failed = Some((i, e.kind(), e.to_string()));
                Err(BuildError::io(&self.paths[i], e))
            }
            Err(panic) => std::panic::resume_unwind(panic),
        }
    }

    /// Writes what is buffered and waits for the writer: the files, in the order given.
    pub fn finish(mut self) -> Result<Vec<File>, BuildError> {
        for f in 0..self.filling.len() {
            self.send(f, true)?;
        }
        self.join()
    }
}

impl Drop for SpillWriter {
    fn drop(&mut self) {
        self.to_writer = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A new empty working file `PREFIX….work` in `dir`, deleted when the path is dropped.
/// A working file: temporary (deleted when dropped: a plain build's) or kept (a build plan's
/// prepared files, read by later jobs, and deleted with the plan directory).
#[derive(Debug)]
pub enum WorkPath {
    Temp(TempPath),
    Kept(std::path::PathBuf),
}

impl WorkPath {
    /// Keeps the file past this value's life; returns its path.
    pub fn keep(self) -> Result<std::path::PathBuf, BuildError> {
        match self {
            WorkPath::Temp(t) => {
                let path = t.to_path_buf();
                t.keep().map_err(|e| BuildError::io(&path, e.error))
            }
            WorkPath::Kept(p) => Ok(p),
        }
    }

    /// Deletes a temporary file now (its data is no longer needed; frees the disk early). A
    /// kept file stays.
    pub fn discard(&self) {
        if let WorkPath::Temp(t) = self {
            drop(std::fs::remove_file(t));
        }
    }
}

impl std::ops::Deref for WorkPath {
    type Target = Path;
    fn deref(&self) -> &Path {
        match self {
            WorkPath::Temp(t) => t,
            WorkPath::Kept(p) => p,
        }
    }
}

pub fn temp_path(dir: &Path, prefix: &str) -> Result<TempPath, BuildError> {
    let f = tempfile::Builder::new()
        .prefix(prefix)
        .suffix(".work")
        .tempfile_in(dir)
        .map_err(|e| BuildError::io(dir, e))?;
    Ok(f.into_temp_path())
}

/// Reads `path`, `records` records of `size` bytes, in chunks of up to `chunk` records decoded
/// with `decode` on a reader thread, and calls `f(first record index, records)` for each chunk
/// in order on the calling thread, with direct reads where the file system allows. Memory: three
/// chunks, raw and decoded, and three read buffers of up to 4 MiB.
#[cfg(test)]
pub fn read_ahead<T, D, F>(
    path: &Path,
    records: u64,
    size: usize,
    chunk: usize,
    decode: D,
    mut f: F,
) -> Result<(), BuildError>
where
    T: Send,
    D: Fn(&[u8]) -> T + Send,
    F: FnMut(u64, &[T]) -> Result<(), BuildError>,
{
    // Small files (a bucket's seams) get a buffer their size.
    let buffer = (records * size as u64).clamp(1, READ_BUFFER as u64) as usize;
    let mut file = DirectReader::open(path, buffer).map_err(|e| BuildError::io(path, e))?;
    check_length(path, file.file_len(), records, size)?;
    let chunk = chunk.max(1);
    std::thread::scope(|scope| {
        let (tx, rx) = sync_channel::<Result<(u64, Vec<T>), std::io::Error>>(1);
        let (give_back, recycled) = sync_channel::<Vec<T>>(2);
        let reader = scope.spawn(move || {
            let mut bytes = vec![0u8; chunk * size];
            let mut done = 0u64;
            while done < records {
                let n = (records - done).min(chunk as u64) as usize;
                let buf = &mut bytes[..n * size];
                if let Err(e) = file.read_exact(buf) {
                    let _ = tx.send(Err(e));
                    return;
                }
                let mut out = recycled.try_recv().unwrap_or_else(|_| Vec::with_capacity(chunk));
                out.clear();
                out.extend(buf.chunks_exact(size).map(&decode));
                if tx.send(Ok((done, out))).is_err() {
                    return; // the consumer stopped
                }
                done += n as u64;
            }
        });
        let result = drain_chunks(path, rx, &give_back, |first, items: &Vec<T>| f(first, items));
        let _ = reader.join();
        result
    })
}

/// Like `read_ahead`, but hands out the raw bytes of each chunk (whole records, `size` bytes
/// each) without decoding them, so that the caller can decode and process a chunk in parallel
/// ([`map_sub_chunks`], [`for_each_lane`]) while the reader thread only reads. Memory: three
/// chunks of bytes and three read buffers of up to 4 MiB.
pub fn read_ahead_raw<F>(path: &Path, records: u64, size: usize, chunk: usize, f: F) -> Result<(), BuildError>
where
    F: FnMut(u64, &[u8]) -> Result<(), BuildError>,
{
    read_range_raw(path, records, 0..records, size, chunk, f)
}

/// [`read_ahead_raw`] over the records `range` of a file of `file_records` records: `f` gets
/// the index (in the file) of each chunk's first record.
pub fn read_range_raw<F>(
    path: &Path,
    file_records: u64,
    range: std::ops::Range<u64>,
    size: usize,
    chunk: usize,
    f: F,
) -> Result<(), BuildError>
where
    F: FnMut(u64, &[u8]) -> Result<(), BuildError>,
{
    read_ranges_raw(path, file_records, std::slice::from_ref(&range), size, chunk, f)
}

/// [`read_range_raw`] over several record ranges, in the order given, through one reader: a
/// chunk never spans two ranges, and each range is read from the device alone (its bytes
/// rounded out to whole blocks; nothing between the ranges), so that many small ranges cost
/// little more than their bytes.
pub fn read_ranges_raw<F>(
    path: &Path,
    file_records: u64,
    ranges: &[std::ops::Range<u64>],
    size: usize,
    chunk: usize,
    mut f: F,
) -> Result<(), BuildError>
where
    F: FnMut(u64, &[u8]) -> Result<(), BuildError>,
{
    for range in ranges {
        assert!(range.start <= range.end && range.end <= file_records, "{range:?} of {file_records} records");
    }
    let total: u64 = ranges.iter().map(|r| r.end - r.start).sum();
    let buffer = (total * size as u64).clamp(1, READ_BUFFER as u64) as usize;
    let bytes = ranges.iter().map(|r| r.start * size as u64..r.end * size as u64).collect();
    let mut file = DirectReader::open_ranges(path, buffer, bytes).map_err(|e| BuildError::io(path, e))?;
    check_length(path, file.file_len(), file_records, size)?;
    let chunk = chunk.max(1);
    std::thread::scope(|scope| {
        let (tx, rx) = sync_channel::<Result<(u64, Vec<u8>), std::io::Error>>(1);
        let (give_back, recycled) = sync_channel::<Vec<u8>>(2);
        let reader = scope.spawn(move || {
            for range in ranges {
                let mut at = range.start;
                while at < range.end {
                    let n = (range.end - at).min(chunk as u64) as usize;
                    let mut bytes = recycled.try_recv().unwrap_or_default();
                    bytes.resize(n * size, 0);
                    if let Err(e) = file.read_exact(&mut bytes) {
                        let _ = tx.send(Err(e));
                        return;
                    }
                    if tx.send(Ok((at, bytes))).is_err() {
                        return; // the consumer stopped
                    }
                    at += n as u64;
                }
            }
        });
        let result = drain_chunks(path, rx, &give_back, |first, bytes: &Vec<u8>| f(first, bytes));
        let _ = reader.join();
        result
    })
}

/// A working file of `records` records of `size` bytes must be `len` bytes long.
fn check_length(path: &Path, len: u64, records: u64, size: usize) -> Result<(), BuildError> {
    if len != records * size as u64 {
        return Err(BuildError::Corrupt {
            path: path.to_path_buf(),
            message: format!("{len} bytes, expected {records} records of {size} bytes"),
        });
    }
    Ok(())
}

/// The consumer side of the read-ahead functions: hands each chunk from the reader thread to
/// `f` in order and gives its buffer back for reuse; stops at the first error of either side.
/// Dropping `rx` on return stops the reader.
fn drain_chunks<B>(
    path: &Path,
    rx: std::sync::mpsc::Receiver<Result<(u64, B), std::io::Error>>,
    give_back: &std::sync::mpsc::SyncSender<B>,
    mut f: impl FnMut(u64, &B) -> Result<(), BuildError>,
) -> Result<(), BuildError> {
    for item in rx.iter() {
        let (first, chunk) = item.map_err(|e| BuildError::io(path, e))?;
        f(first, &chunk)?;
        let _ = give_back.try_send(chunk);
    }
    Ok(())
}

/// Records per task of [`map_sub_chunks`]: a fixed number, so that what each task sees (and
/// so any per-task result) does not depend on the number of threads.
pub const SUB_CHUNK: usize = 4096;

/// Splits `bytes` (whole records of `size` bytes) into sub-chunks of [`SUB_CHUNK`] records,
/// calls `f(index of the sub-chunk's first record, its bytes)` for each on the current rayon
/// pool, and returns the results in record order. `bytes.len()` must be a multiple of `size`.
pub fn map_sub_chunks<T, F>(bytes: &[u8], size: usize, f: F) -> Vec<T>
where
    T: Send,
    F: Fn(usize, &[u8]) -> T + Sync,
{
    use rayon::prelude::*;
    debug_assert!(size > 0 && bytes.len().is_multiple_of(size));
    bytes.par_chunks(SUB_CHUNK * size).enumerate().map(|(k, b)| f(k * SUB_CHUNK, b)).collect()
}

/// Work split by key, for accumulations that must happen in input order per key (floating-point
/// sums): lane `l` of `lanes.len()` owns the keys `k` with `k % lanes.len() == l` and calls
/// `f(its state, position in keys, key)` for each of them, in input order. Lanes run in
/// parallel on the current rayon pool, so per key the calls are exactly those of a serial loop
/// over `keys`, whatever the number of threads. Keys `u32::MAX` (no key) are skipped.
pub fn for_each_lane<S, F>(lanes: &mut [S], keys: &[u32], f: F)
where
    S: Send,
    F: Fn(&mut S, usize, u32) + Sync,
{
    use rayon::prelude::*;
    let n = lanes.len() as u32;
    if n == 0 {
        return;
    }
    // Every lane tests every key: a mask rather than a division when the count allows (the
    // division was a third of pass B of the redefinition on the 24 M-triangle assembly).
    let mask = n.is_power_of_two().then(|| n - 1);
    lanes.par_iter_mut().enumerate().for_each(|(l, state)| {
        let l = l as u32;
        for (i, &k) in keys.iter().enumerate() {
            let lane = match mask {
                Some(m) => k & m,
                None => k % n,
            };
            if k != u32::MAX && lane == l {
                f(state, i, k);
            }
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp_files(dir: &Path, n: usize) -> (Vec<File>, Vec<PathBuf>) {
        (0..n)
            .map(|i| {
                let p = dir.join(format!("f{i}"));
                (File::create(&p).unwrap(), p)
            })
            .unzip()
    }

    #[test]
    fn spill_writer_keeps_every_byte_in_order_per_file() {
        let dir = tempfile::tempdir().unwrap();
        let (files, paths) = temp_files(dir.path(), 3);
        let mut w = SpillWriter::new(files, paths.clone(), 4096);
        let mut expected = vec![Vec::new(); 3];
        for k in 0..20_000u32 {
            let f = (k % 7 % 3) as usize;
            let rec = k.to_le_bytes();
            w.write(f, &rec[..1 + (k % 4) as usize]).unwrap();
            expected[f].extend_from_slice(&rec[..1 + (k % 4) as usize]);
        }
        let files = w.finish().unwrap();
        drop(files);
        for (p, e) in paths.iter().zip(expected) {
            assert_eq!(std::fs::read(p).unwrap(), e);
        }
    }

    #[test]
    fn spill_writer_reports_a_failing_file_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("read-only");
        std::fs::write(&path, b"").unwrap();
        let file = File::open(&path).unwrap(); // opened for reading: writes fail
        let mut w = SpillWriter::new(vec![file], vec![path.clone()], 4096);
        let mut failed = None;
        for _ in 0..100 {
            if let Err(e) = w.write(0, &[0u8; 1000]) {
                failed = Some(e);
                break;
            }
        }
        let e = failed.unwrap_or_else(|| w.finish().unwrap_err());
        assert!(e.to_string().contains("read-only"), "{e}");
    }

    /// After the writer stopped on an error, every later call repeats that error (a full disk
    /// must read as a full disk, not as "the writer thread stopped").
    #[test]
    fn spill_writer_repeats_its_first_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("read-only");
        std::fs::write(&path, b"").unwrap();
        let file = File::open(&path).unwrap();
        let mut w = SpillWriter::new(vec![file], vec![path.clone()], 4096);
        let first = (0..100).find_map(|_| w.write(0, &[0u8; 1000]).err()).expect("a write fails");
        let later = (0..10).find_map(|_| w.write(0, &[0u8; 5000]).err()).expect("still failing");
        assert_eq!(later.to_string(), first.to_string());
        assert!(!later.to_string().contains("stopped"), "{later}");
        assert_eq!(w.finish().unwrap_err().to_string(), first.to_string());
    }

    #[test]
    fn read_ahead_hands_out_every_record_in_order_and_checks_the_length() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("recs");
        let data: Vec<u8> = (0..10_000u32).flat_map(|k| k.to_le_bytes()).collect();
        std::fs::write(&path, &data).unwrap();
        let mut seen = Vec::new();
        read_ahead(
            &path,
            10_000,
            4,
            333,
            |b| u32::from_le_bytes(b.try_into().unwrap()),
            |first, c| {
                assert_eq!(first, seen.len() as u64);
                seen.extend_from_slice(c);
                Ok(())
            },
        )
        .unwrap();
        assert_eq!(seen, (0..10_000).collect::<Vec<u32>>());
        let e = read_ahead(&path, 10_001, 4, 333, |b| b[0], |_, _| Ok(())).unwrap_err();
        assert!(e.to_string().contains("expected 10001 records"), "{e}");
    }

    #[test]
    fn read_ahead_stops_at_the_consumers_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("recs");
        std::fs::write(&path, vec![0u8; 4 * 100_000]).unwrap();
        let mut calls = 0;
        let e = read_ahead(
            &path,
            100_000,
            4,
            10,
            |b| b[0],
            |_, _| {
                calls += 1;
                if calls == 3 {
                    Err(BuildError::Empty)
                } else {
                    Ok(())
                }
            },
        )
        .unwrap_err();
        assert!(matches!(e, BuildError::Empty));
        assert_eq!(calls, 3);
    }

    fn records_file(dir: &Path, n: u32) -> (PathBuf, Vec<u8>) {
        let path = dir.join("raw");
        let data: Vec<u8> = (0..n).flat_map(|k| [k.to_le_bytes(), (k * 7).to_le_bytes()].concat()).collect();
        std::fs::write(&path, &data).unwrap();
        (path, data)
    }

    #[test]
    fn read_ahead_raw_hands_out_every_byte_in_whole_records() {
        let dir = tempfile::tempdir().unwrap();
        for (n, chunk) in [(0u32, 5usize), (1, 5), (5, 5), (6, 5), (10_000, 333), (10_000, 1)] {
            let (path, data) = records_file(dir.path(), n);
            let mut seen = Vec::new();
            read_ahead_raw(&path, n as u64, 8, chunk, |first, b| {
                assert_eq!(first * 8, seen.len() as u64);
                assert!(b.len() % 8 == 0 && b.len() <= chunk * 8 && !b.is_empty());
                seen.extend_from_slice(b);
                Ok(())
            })
            .unwrap();
            assert_eq!(seen, data, "{n} records in chunks of {chunk}");
        }
        let (path, data) = records_file(dir.path(), 3000);
        for range in [0..0, 0..1, 5..5, 511..513, 512..1024, 7..3000, 2999..3000, 0..3000] {
            let mut seen = Vec::new();
            read_range_raw(&path, 3000, range.clone(), 8, 100, |first, b| {
                assert_eq!(first, range.start + seen.len() as u64 / 8);
                seen.extend_from_slice(b);
                Ok(())
            })
            .unwrap();
            assert_eq!(seen, data[range.start as usize * 8..range.end as usize * 8], "{range:?}");
        }
        // Several ranges through one reader: chunks never span two, indices are the file's.
        let ranges = [0..0, 3..250, 250..251, 700..1400, 2990..3000];
        let mut seen = Vec::new();
        let mut firsts = Vec::new();
        read_ranges_raw(&path, 3000, &ranges, 8, 100, |first, b| {
            firsts.push((first, b.len() as u64 / 8));
            seen.extend_from_slice(b);
            Ok(())
        })
        .unwrap();
        let expected: Vec<u8> = ranges
            .iter()
            .flat_map(|r| data[r.start as usize * 8..r.end as usize * 8].iter().copied())
            .collect();
        assert_eq!(seen, expected);
        for (first, n) in firsts {
            assert!(ranges.iter().any(|r| r.start <= first && first + n <= r.end), "chunk {first}+{n}");
        }
        let (path, _) = records_file(dir.path(), 10);
        let e = read_ahead_raw(&path, 11, 8, 4, |_, _| Ok(())).unwrap_err();
        assert!(e.to_string().contains("expected 11 records"), "{e}");
    }

    #[test]
    fn map_sub_chunks_equals_the_serial_map_at_every_size_and_thread_count() {
        let size = 3;
        for records in [0, 1, SUB_CHUNK - 1, SUB_CHUNK, SUB_CHUNK + 1, 3 * SUB_CHUNK + 17] {
            let bytes: Vec<u8> = (0..records * size).map(|i| (i * 31 % 251) as u8).collect();
            let serial: Vec<(usize, u64)> = bytes
                .chunks(SUB_CHUNK * size)
                .enumerate()
                .map(|(k, b)| (k * SUB_CHUNK, b.iter().map(|&x| x as u64).sum()))
                .collect();
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
                let par = pool.install(|| {
                    map_sub_chunks(&bytes, size, |first, b| {
                        assert!(b.len() % size == 0 && b.len() <= SUB_CHUNK * size);
                        (first, b.iter().map(|&x| x as u64).sum::<u64>())
                    })
                });
                assert_eq!(par, serial, "{records} records, {threads} threads");
            }
        }
    }

    #[test]
    fn lanes_see_each_key_in_input_order_like_a_serial_loop() {
        // An order-sensitive accumulation (each key's list of positions), per key.
        let keys: Vec<u32> =
            (0..5000u32).map(|i| if i % 97 == 0 { u32::MAX } else { i * 7919 % 13 }).collect();
        let mut serial = vec![Vec::new(); 13];
        for (i, &k) in keys.iter().enumerate() {
            if k != u32::MAX {
                serial[k as usize].push(i);
            }
        }
        for lanes in [1usize, 2, 4, 5] {
            let mut state: Vec<Vec<Vec<usize>>> = (0..lanes).map(|_| vec![Vec::new(); 13]).collect();
            let pool = rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap();
            pool.install(|| for_each_lane(&mut state, &keys, |s, i, k| s[k as usize].push(i)));
            for k in 0..13 {
                assert_eq!(state[k % lanes][k], serial[k], "key {k}, {lanes} lanes");
                for (l, s) in state.iter().enumerate() {
                    assert!(l == k % lanes || s[k].is_empty(), "key {k} only in its lane");
                }
            }
        }
        for_each_lane(&mut Vec::<u32>::new(), &keys, |_, _, _| unreachable!());
        let mut one = vec![0usize];
        for_each_lane(&mut one, &[], |_, _, _| unreachable!());
    }
}
