//! Sequential file I/O that bypasses the page cache (`O_DIRECT` on Linux), for the gigabytes the
//! build streams through its working files and reads from its inputs once.
//!
//! Why: on virtual machines that hand freed guest memory back to the host (Firecracker and most
//! clouds report free pages), every page-cache page a new file needs is a page the host must
//! fault in again. Measured on the 2-core CI-like machine: writing a new 4 GB file through the
//! page cache took 28 s of system time, reading one cold 10.6 s; with `O_DIRECT` the same write
//! took 2.6 s (0.4 s system) and the read 1.6–2.4 s. The build writes about 9 GB of working
//! files at 10^8 triangles, so this was a quarter of its CPU time.
//!
//! Direct transfers need their buffer address, file offset and length aligned to the device's
//! block size; [`DIRECT_ALIGN`] (4 KiB) satisfies every Linux file system that supports
//! `O_DIRECT`. Where a file system refuses it (tmpfs, some network file systems) at open or at
//! the first transfer, these types fall back to ordinary buffered I/O, silently and correctly:
//! bytes and their order never depend on which path was taken. Everything here is safe code
//! except one `fcntl` call.

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Write};
use std::path::Path;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::thread::JoinHandle;

/// Alignment of buffer addresses, file offsets and lengths of direct transfers.
pub const DIRECT_ALIGN: usize = 4096;

/// A byte buffer of fixed capacity whose first byte is aligned to [`DIRECT_ALIGN`].
pub struct AlignedBuf {
    raw: Vec<u8>,
    start: usize,
    len: usize,
    cap: usize,
}

impl AlignedBuf {
    /// A buffer of at least `capacity` bytes, rounded up to a multiple of [`DIRECT_ALIGN`].
    pub fn new(capacity: usize) -> AlignedBuf {
        let cap = capacity.div_ceil(DIRECT_ALIGN).max(1) * DIRECT_ALIGN;
        let raw = vec![0u8; cap + DIRECT_ALIGN];
        let start = raw.as_ptr().align_offset(DIRECT_ALIGN);
        assert!(start < DIRECT_ALIGN, "cannot align a byte buffer");
        AlignedBuf { raw, start, len: 0, cap }
    }

    /// A buffer without storage (capacity 0), to be replaced before use.
    pub fn empty() -> AlignedBuf {
        AlignedBuf { raw: Vec::new(), start: 0, len: 0, cap: 0 }
    }

    pub fn capacity(&self) -> usize {
        self.cap
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Bytes that still fit.
    pub fn room(&self) -> usize {
        self.cap - self.len
    }

    pub fn clear(&mut self) {
        self.len = 0;
    }

    /// The bytes held.
    pub fn as_slice(&self) -> &[u8] {
        &self.raw[self.start..self.start + self.len]
    }

    /// Appends `bytes`, which must fit ([`AlignedBuf::room`]).
    pub fn extend_from_slice(&mut self, bytes: &[u8]) {
        assert!(bytes.len() <= self.room(), "AlignedBuf overflow");
        let at = self.start + self.len;
        self.raw[at..at + bytes.len()].copy_from_slice(bytes);
        self.len += bytes.len();
    }

    /// The whole capacity, for reading into; set the length with [`AlignedBuf::set_len`].
    fn storage(&mut self) -> &mut [u8] {
        &mut self.raw[self.start..self.start + self.cap]
    }

    fn set_len(&mut self, len: usize) {
        assert!(len <= self.cap);
        self.len = len;
    }
}

/// True for the error a file system gives when it does not support a direct transfer.
fn refused(e: &io::Error) -> bool {
    #[cfg(target_os = "linux")]
    {
        e.raw_os_error() == Some(libc::EINVAL)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = e;
        false
    }
}

/// Opens `options` on `path` with `O_DIRECT` where the file system accepts it; the flag says
/// whether it did.
fn open_maybe_direct(options: &OpenOptions, path: &Path) -> io::Result<(File, bool)> {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::OpenOptionsExt;
        let mut direct = options.clone();
        direct.custom_flags(libc::O_DIRECT);
        match direct.open(path) {
            Ok(f) => return Ok((f, true)),
            Err(e) if refused(&e) => {}
            Err(e) => return Err(e),
        }
    }
    Ok((options.open(path)?, false))
}

/// Turns `O_DIRECT` off on an open file, after the file system refused a direct transfer.
fn stop_direct(file: &File) -> io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let fd = file.as_raw_fd();
        // SAFETY: fcntl with F_GETFL / F_SETFL on a descriptor we own has no memory effects.
        #[allow(unsafe_code)]
        let ok = unsafe {
            let flags = libc::fcntl(fd, libc::F_GETFL);
            flags >= 0 && libc::fcntl(fd, libc::F_SETFL, flags & !libc::O_DIRECT) >= 0
        };
        if !ok {
            return Err(io::Error::last_os_error());
        }
    }
    let _ = file;
    Ok(())
}

/// Fills `buf` from `file` at `offset` (positional: concurrent readers of one handle need no
/// lock); an end of file before `buf` is full is an `UnexpectedEof` error.
pub fn read_exact_at(file: &File, mut buf: &mut [u8], mut offset: u64) -> io::Result<()> {
    while !buf.is_empty() {
        match read_at(file, buf, offset) {
            Ok(0) => return Err(io::ErrorKind::UnexpectedEof.into()),
            Ok(n) => {
                buf = &mut buf[n..];
                offset += n as u64;
            }
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

#[cfg(unix)]
fn read_at(file: &File, buf: &mut [u8], offset: u64) -> io::Result<usize> {
    std::os::unix::fs::FileExt::read_at(file, buf, offset)
}

/// Writes all of `buf` to `file` at `offset` (positional, like [`read_exact_at`]).
#[cfg(unix)]
pub fn write_all_at(file: &File, buf: &[u8], offset: u64) -> io::Result<()> {
    std::os::unix::fs::FileExt::write_all_at(file, buf, offset)
}

#[cfg(not(unix))]
fn read_at(file: &File, buf: &mut [u8], offset: u64) -> io::Result<usize> {
    std::os::windows::fs::FileExt::seek_read(file, buf, offset)
}

/// Writes all of `buf` to `file` at `offset` (positional, like [`read_exact_at`]).
#[cfg(not(unix))]
pub fn write_all_at(file: &File, mut buf: &[u8], mut offset: u64) -> io::Result<()> {
    while !buf.is_empty() {
        let n = std::os::windows::fs::FileExt::seek_write(file, buf, offset)?;
        if n == 0 {
            return Err(io::ErrorKind::WriteZero.into());
        }
        buf = &buf[n..];
        offset += n as u64;
    }
    Ok(())
}

/// Buffers a [`DirectReader`] keeps in flight: one being read into, one queued, one being
/// handed out.
const READS_IN_FLIGHT: usize = 3;

/// A sequential reader of a whole file, direct where possible. A background thread reads the
/// next buffers while the caller consumes this one, so the device's latency (direct reads are
/// synchronous) overlaps the caller's work. Memory: three buffers.
///
/// [`DirectReader::open_ranges`] reads only some byte ranges of the file, one after the other,
/// as if they were one stream: each range costs one read per buffer it fills, never more than
/// its own bytes rounded out to [`DIRECT_ALIGN`].
pub struct DirectReader {
    len: u64,
    direct: bool,
    /// Filled buffers from the reader thread, each with the count of bytes at its start that
    /// come before its range (alignment); an error ends the stream.
    filled: Option<Receiver<io::Result<(AlignedBuf, usize)>>>,
    recycle: Option<SyncSender<AlignedBuf>>,
    thread: Option<JoinHandle<()>>,
    buf: AlignedBuf,
    /// Next byte of `buf` to hand out.
    pos: usize,
}

impl DirectReader {
    /// Opens `path` for reading with buffers of `buffer` bytes (rounded up to 4 KiB).
    pub fn open(path: &Path, buffer: usize) -> io::Result<DirectReader> {
        DirectReader::open_at(path, buffer, 0)
    }

    /// Opens `path` for reading from byte `offset` on (any offset: the reads start at the
    /// aligned offset below it and the bytes before `offset` are skipped). Reading stops where
    /// the caller stops: at most three buffers are read past what it took.
    pub fn open_at(path: &Path, buffer: usize, offset: u64) -> io::Result<DirectReader> {
        DirectReader::open_ranges(path, buffer, std::iter::once(offset..u64::MAX).collect())
    }

    /// Opens `path` for reading the bytes of `ranges` (any offsets), in the order given, as one
    /// stream. A range that runs past the end of the file gives the bytes up to the end.
    pub fn open_ranges(
        path: &Path,
        buffer: usize,
        ranges: Vec<std::ops::Range<u64>>,
    ) -> io::Result<DirectReader> {
        let (file, direct) = open_maybe_direct(OpenOptions::new().read(true), path)?;
        let len = file.metadata()?.len();
        let (to_reader, recycled) = sync_channel::<AlignedBuf>(READS_IN_FLIGHT);
        for _ in 0..READS_IN_FLIGHT {
            to_reader.send(AlignedBuf::new(buffer)).expect("the channel has room");
        }
        let (to_caller, filled) = sync_channel::<io::Result<(AlignedBuf, usize)>>(READS_IN_FLIGHT);
        let ranges = ranges.into_iter().filter(|r| r.start < r.end).collect();
        let thread = std::thread::Builder::new().name("tw-direct-reader".into()).spawn(move || {
            let mut source = Source { file, direct, ranges };
            while !source.ranges.is_empty() {
                let Ok(mut buf) = recycled.recv() else { return }; // the caller stopped
                let r = source.fill(&mut buf).map(|skip| (buf, skip));
                let failed = r.is_err();
                if to_caller.send(r).is_err() || failed {
                    return;
                }
            }
        })?;
        Ok(DirectReader {
            len,
            direct,
            filled: Some(filled),
            recycle: Some(to_reader),
            thread: Some(thread),
            buf: AlignedBuf::empty(),
            pos: 0,
        })
    }

    /// Whether the file was opened for direct reads (the file system may still refuse them).
    pub fn is_direct(&self) -> bool {
        self.direct
    }

    /// The file's length when it was opened.
    pub fn file_len(&self) -> u64 {
        self.len
    }
}

/// The reading end of a [`DirectReader`]'s thread.
struct Source {
    file: File,
    direct: bool,
    /// Byte ranges still to read, the first one partly read perhaps (never empty ones).
    ranges: std::collections::VecDeque<std::ops::Range<u64>>,
}

impl Source {
    /// Fills `buf` from the first range: as much of it as fits, read from the aligned offset at
    /// or below its start and cut at its end (or the file's). Returns the count of bytes before
    /// the range's start at the front of `buf`.
    fn fill(&mut self, buf: &mut AlignedBuf) -> io::Result<usize> {
        let Some(range) = self.ranges.front_mut() else {
            buf.set_len(0);
            return Ok(0);
        };
        let aligned = range.start - range.start % DIRECT_ALIGN as u64;
        let skip = (range.start - aligned) as usize;
        let cap = buf.capacity();
        // Only the range's bytes, rounded out to whole blocks.
        let want = (range.end - aligned).div_ceil(DIRECT_ALIGN as u64).saturating_mul(DIRECT_ALIGN as u64);
        let want = want.min(cap as u64) as usize;
        let mut filled = 0;
        let mut eof = false;
        // A direct read must start aligned, and only the file's end may leave a buffer short.
        while filled < want {
            let offset = aligned + filled as u64;
            match read_at(&self.file, &mut buf.storage()[filled..want], offset) {
                Ok(0) => {
                    eof = true;
                    break;
                }
                Ok(n) => {
                    filled += n;
                    if self.direct && !filled.is_multiple_of(DIRECT_ALIGN) {
                        eof = true; // only the last block of a file is short
                        break;
                    }
                }
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) if self.direct && refused(&e) => {
                    stop_direct(&self.file)?;
                    self.direct = false;
                }
                Err(e) => return Err(e),
            }
        }
        let end = aligned + filled as u64;
        if eof || end >= range.end {
            buf.set_len(((range.end.min(end) - aligned) as usize).max(skip.min(filled)));
            self.ranges.pop_front();
        } else {
            buf.set_len(filled);
            range.start = end;
        }
        Ok(skip.min(buf.len()))
    }
}

impl Read for DirectReader {
    fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
        while self.pos == self.buf.len() {
            let Some(filled) = &self.filled else { return Ok(0) };
            let (next, skip) = match filled.recv() {
                Ok(Ok(next)) => next,
                Ok(Err(e)) => {
                    self.filled = None;
                    return Err(e);
                }
                Err(_) => {
                    // The thread ended after the file's last buffer.
                    self.filled = None;
                    return Ok(0);
                }
            };
            let done = std::mem::replace(&mut self.buf, next);
            self.pos = skip;
            if done.capacity() > 0 {
                if let Some(tx) = &self.recycle {
                    let _ = tx.try_send(done);
                }
            }
        }
        let have = &self.buf.as_slice()[self.pos..];
        let n = have.len().min(out.len());
        out[..n].copy_from_slice(&have[..n]);
        self.pos += n;
        Ok(n)
    }
}

impl Drop for DirectReader {
    fn drop(&mut self) {
        // Closing both channels stops the thread at its next send or receive.
        self.recycle = None;
        self.filled = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// A sequential writer of a new file, direct where possible. The caller hands it aligned
/// buffers whose lengths are multiples of [`DIRECT_ALIGN`], except the last one
/// ([`DirectWriter::write_last`]), which is padded for the transfer and cut back after.
pub struct DirectWriter {
    file: File,
    direct: bool,
    /// Bytes written so far (the logical length of the file).
    len: u64,
}

impl DirectWriter {
    /// Opens the existing file `path` (typically a fresh temporary file) for writing from its
    /// start, truncating it.
    pub fn open(path: &Path) -> io::Result<DirectWriter> {
        let (file, direct) = open_maybe_direct(OpenOptions::new().write(true).truncate(true), path)?;
        Ok(DirectWriter { file, direct, len: 0 })
    }

    /// A writer over an already open file, buffered (no direct transfers).
    pub fn buffered(file: File) -> DirectWriter {
        DirectWriter { file, direct: false, len: 0 }
    }

    /// Whether writes currently bypass the page cache.
    pub fn is_direct(&self) -> bool {
        self.direct
    }

    /// Bytes written so far.
    pub fn len(&self) -> u64 {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Appends `buf`; its length must be a multiple of [`DIRECT_ALIGN`] while the file is
    /// direct (use [`DirectWriter::write_last`] for the end of the file).
    pub fn write(&mut self, buf: &AlignedBuf) -> io::Result<()> {
        let bytes = buf.as_slice();
        if self.direct && !bytes.len().is_multiple_of(DIRECT_ALIGN) {
            return Err(io::Error::new(io::ErrorKind::InvalidInput, "unaligned direct write"));
        }
        self.transfer(bytes)?;
        self.len += bytes.len() as u64;
        Ok(())
    }

    /// Appends the file's last bytes, of any length: padded to [`DIRECT_ALIGN`] with zeros for
    /// a direct transfer, then the file is cut back to its logical length.
    pub fn write_last(&mut self, buf: &mut AlignedBuf) -> io::Result<()> {
        let real = buf.len();
        if self.direct && !real.is_multiple_of(DIRECT_ALIGN) {
            let padded = real.next_multiple_of(DIRECT_ALIGN);
            buf.storage()[real..padded].fill(0);
            buf.set_len(padded);
            let r = self.transfer(buf.as_slice());
            buf.set_len(real);
            r?;
            self.len += real as u64;
            return self.file.set_len(self.len);
        }
        self.transfer(buf.as_slice())?;
        self.len += real as u64;
        Ok(())
    }

    fn transfer(&mut self, bytes: &[u8]) -> io::Result<()> {
        crate::disk_space::check(&self.file, bytes.len() as u64)?;
        match write_all_at(&self.file, bytes, self.len) {
            Err(e) if self.direct && refused(&e) => {
                stop_direct(&self.file)?;
                self.direct = false;
                write_all_at(&self.file, bytes, self.len)
            }
            r => r,
        }
    }

    /// The file, once everything is written.
    pub fn into_file(self) -> File {
        self.file
    }
}

/// A [`Write`] over a [`DirectWriter`] through one aligned buffer: appends of any size, direct
/// where the file system allows. [`AlignedWriter::finish`] writes the rest and returns the file.
/// Memory: one buffer.
pub struct AlignedWriter {
    out: DirectWriter,
    buf: AlignedBuf,
}

impl AlignedWriter {
    /// Writes the existing file `path` from its start (truncating it) with a buffer of `buffer`
    /// bytes (rounded up to 4 KiB).
    pub fn open(path: &Path, buffer: usize) -> io::Result<AlignedWriter> {
        Ok(AlignedWriter { out: DirectWriter::open(path)?, buf: AlignedBuf::new(buffer) })
    }

    /// Bytes written so far, buffered ones included.
    pub fn position(&self) -> u64 {
        self.out.len() + self.buf.len() as u64
    }

    /// Writes the buffered bytes and returns the file, its length exactly what was written.
    pub fn finish(mut self) -> io::Result<File> {
        self.out.write_last(&mut self.buf)?;
        Ok(self.out.into_file())
    }
}

impl Write for AlignedWriter {
    fn write(&mut self, bytes: &[u8]) -> io::Result<usize> {
        if self.buf.room() == 0 {
            self.out.write(&self.buf)?;
            self.buf.clear();
        }
        let n = bytes.len().min(self.buf.room());
        self.buf.extend_from_slice(&bytes[..n]);
        Ok(n)
    }

    /// Does nothing: a direct file can only take whole blocks before its end, so the buffer is
    /// written when full and by [`AlignedWriter::finish`].
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pattern(n: usize) -> Vec<u8> {
        (0..n).map(|i| (i * 7 + i / 4093) as u8).collect()
    }

    #[test]
    fn aligned_buffers_are_aligned() {
        for cap in [1, 4096, 5000, 1 << 20] {
            let mut b = AlignedBuf::new(cap);
            assert_eq!(b.as_slice().as_ptr() as usize % DIRECT_ALIGN, 0);
            assert_eq!(b.capacity() % DIRECT_ALIGN, 0);
            assert!(b.capacity() >= cap);
            b.extend_from_slice(&[1, 2, 3]);
            assert_eq!(b.as_slice(), &[1, 2, 3]);
        }
    }

    #[test]
    fn write_then_read_round_trips_any_length() {
        let dir = tempfile_dir();
        for len in [0, 1, 4095, 4096, 4097, 3 * 4096 + 17, 300_001] {
            let path = dir.join(format!("f{len}"));
            std::fs::write(&path, b"old contents that must go").unwrap();
            let data = pattern(len);
            let mut w = DirectWriter::open(&path).unwrap();
            let chunk = 8192;
            let mut b = AlignedBuf::new(chunk);
            let whole = len / chunk * chunk;
            for c in data[..whole].chunks(chunk) {
                b.clear();
                b.extend_from_slice(c);
                w.write(&b).unwrap();
            }
            b.clear();
            b.extend_from_slice(&data[whole..]);
            w.write_last(&mut b).unwrap();
            assert_eq!(w.len(), len as u64);
            drop(w.into_file());
            assert_eq!(std::fs::read(&path).unwrap(), data, "length {len}");
            for buffer in [4096, 10_000, 1 << 20] {
                let mut r = DirectReader::open(&path, buffer).unwrap();
                let mut back = Vec::new();
                r.read_to_end(&mut back).unwrap();
                assert_eq!(back, data, "length {len}, buffer {buffer}");
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unaligned_middle_writes_are_refused_when_direct() {
        let dir = tempfile_dir();
        let path = dir.join("f");
        std::fs::write(&path, b"").unwrap();
        let mut w = DirectWriter::open(&path).unwrap();
        let mut b = AlignedBuf::new(4096);
        b.extend_from_slice(&[1; 10]);
        let r = w.write(&b);
        assert_eq!(r.is_err(), w.is_direct());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn open_at_starts_at_any_offset() {
        let dir = tempfile_dir();
        let path = dir.join("f");
        let data: Vec<u8> = (0..3 * DIRECT_ALIGN as u32 + 123).map(|i| (i * 7 % 251) as u8).collect();
        std::fs::write(&path, &data).unwrap();
        for offset in [0, 1, 4095, 4096, 4097, 8191, data.len() - 1, data.len(), data.len() + 5] {
            for buffer in [4096, 1 << 20] {
                let mut r = DirectReader::open_at(&path, buffer, offset as u64).unwrap();
                let mut got = Vec::new();
                r.read_to_end(&mut got).unwrap();
                assert_eq!(got, data[offset.min(data.len())..], "offset {offset}, buffer {buffer}");
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn open_ranges_reads_exactly_the_ranges_in_order() {
        let dir = tempfile_dir();
        let path = dir.join("f");
        let data: Vec<u8> = (0..5 * DIRECT_ALIGN as u32 + 321).map(|i| (i * 13 % 251) as u8).collect();
        std::fs::write(&path, &data).unwrap();
        let n = data.len() as u64;
        let cases: Vec<Vec<std::ops::Range<u64>>> = vec![
            vec![],
            vec![0..0, 5..5],
            vec![0..n],
            vec![1..2, 3..4095, 4095..4097, 8192..8193],
            vec![100..9000, 9000..9001, 12_000..n],
            // Out of order, repeated, across the end of the file.
            vec![9000..9100, 10..20, 10..20, n - 3..n + 100, n + 5..n + 9],
        ];
        for ranges in cases {
            let expected: Vec<u8> = ranges
                .iter()
                .flat_map(|r| data[(r.start.min(n) as usize)..(r.end.min(n) as usize)].iter().copied())
                .collect();
            for buffer in [4096, 10_000, 1 << 20] {
                let mut r = DirectReader::open_ranges(&path, buffer, ranges.clone()).unwrap();
                let mut got = Vec::new();
                r.read_to_end(&mut got).unwrap();
                assert_eq!(got, expected, "{ranges:?}, buffer {buffer}");
            }
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_reader_dropped_midway_stops_its_thread() {
        let dir = tempfile_dir();
        let path = dir.join("f");
        std::fs::write(&path, pattern(1 << 20)).unwrap();
        for _ in 0..20 {
            let mut r = DirectReader::open(&path, 4096).unwrap();
            let mut first = [0u8; 10];
            r.read_exact(&mut first).unwrap();
            assert_eq!(first[..], pattern(10)[..]);
            drop(r); // joins the thread: must not hang
        }
        assert!(DirectReader::open(&dir.join("missing"), 4096).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn the_aligned_writer_takes_appends_of_any_size() {
        let dir = tempfile_dir();
        let path = dir.join("f");
        std::fs::write(&path, b"stale").unwrap();
        let data = pattern(100_003);
        let mut w = AlignedWriter::open(&path, 4096).unwrap();
        let mut at = 0;
        for k in 0.. {
            if at == data.len() {
                break;
            }
            let n = (k * 37 % 9000).min(data.len() - at);
            w.write_all(&data[at..at + n]).unwrap();
            at += n;
            assert_eq!(w.position(), at as u64);
        }
        drop(w.finish().unwrap());
        assert_eq!(std::fs::read(&path).unwrap(), data);
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A fresh directory in std's temporary directory (direct where its file system allows).
    fn tempfile_dir() -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!(
            "tw-direct-{}-{:?}",
            std::process::id(),
            std::thread::current().id()
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }
}
