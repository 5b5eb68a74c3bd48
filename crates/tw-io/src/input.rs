//! Opening an input file: transparent gzip (detected by its magic bytes, not its name), a large
//! read buffer, and a count of the bytes read from disk for progress bars.

use std::io::{self, BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

use tw_core::direct_io::DirectReader;
use tw_core::regular_file::open_regular;

use crate::error::{ImportError, Position};

/// Size of the read buffer in front of every parser.
pub const READ_BUFFER: usize = 1 << 20;

/// An opened input file, decompressed if it was gzip'ed.
pub struct Input {
    pub path: PathBuf,
    /// True when the file is gzip (the reader yields the decompressed bytes).
    pub gzip: bool,
    /// Size of the file on disk.
    pub file_len: u64,
    /// Bytes read from disk so far (compressed bytes for gzip); shared with the reader.
    disk_bytes: Arc<AtomicU64>,
    reader: BufReader<Box<dyn Read + Send>>,
}

impl Input {
    /// Opens `path`, detecting gzip by the magic bytes 1f 8b.
    ///
    /// Only a regular file is read: its length drives the progress bars and the readers' size
    /// checks, the glTF reader reads it at offsets, and a FIFO would block the open. A pipe, a
    /// device or a directory is refused with a message naming the path and what it is (there is
    /// no standard-input mode: copy the stream to a file first).
    pub fn open(path: &Path) -> Result<Input, ImportError> {
        let io_err = |e| ImportError::io(path, Position::File, e);
        let (mut file, meta) = open_regular(path).map_err(|e| match e.kind() {
            io::ErrorKind::InvalidInput => ImportError::parse(path, Position::File, e.to_string()),
            _ => io_err(e),
        })?;
        let mut magic = [0u8; 2];
        let got = read_up_to(&mut file, &mut magic).map_err(io_err)?;
        let gzip = got == 2 && magic == [0x1f, 0x8b];
        drop(file);
        // Read once, front to back: bypass the page cache (see tw_core::direct_io).
        let file = DirectReader::open(path, READ_BUFFER).map_err(io_err)?;
        let disk_bytes = Arc::new(AtomicU64::new(0));
        let counted = CountingReader { inner: file, count: disk_bytes.clone() };
        let inner: Box<dyn Read + Send> = if gzip {
            Box::new(flate2::read::MultiGzDecoder::new(BufReader::with_capacity(1 << 16, counted)))
        } else {
            Box::new(counted)
        };
        Ok(Input {
            path: path.to_path_buf(),
            gzip,
            file_len: meta.len(),
            disk_bytes,
            reader: BufReader::with_capacity(READ_BUFFER, inner),
        })
    }

    /// An input over bytes in memory (fuzzing, tests). `path` is only used in messages and to
    /// resolve relative references (glTF buffers). Gzip is detected as for files.
    pub fn from_bytes(path: &Path, bytes: Vec<u8>) -> Input {
        let gzip = bytes.starts_with(&[0x1f, 0x8b]);
        let file_len = bytes.len() as u64;
        let disk_bytes = Arc::new(AtomicU64::new(0));
        let counted = CountingReader { inner: io::Cursor::new(bytes), count: disk_bytes.clone() };
        let inner: Box<dyn Read + Send> =
            if gzip { Box::new(flate2::read::MultiGzDecoder::new(counted)) } else { Box::new(counted) };
        Input {
            path: path.to_path_buf(),
            gzip,
            file_len,
            disk_bytes,
            reader: BufReader::with_capacity(READ_BUFFER, inner),
        }
    }

    /// Bytes read from disk so far (compressed bytes for gzip).
    pub fn disk_bytes(&self) -> u64 {
        self.disk_bytes.load(Ordering::Relaxed)
    }

    /// A handle that keeps reporting [`Input::disk_bytes`] after the reader is moved away.
    pub fn disk_counter(&self) -> DiskCounter {
        DiskCounter(self.disk_bytes.clone())
    }

    /// The first bytes of the (decompressed) content without consuming them; fewer than `n`
    /// only when the file is shorter. An invalid gzip stream is an error here.
    pub fn peek(&mut self, n: usize) -> Result<&[u8], ImportError> {
        let n = n.min(READ_BUFFER);
        // BufReader::fill_buf only reads when its buffer is empty, so loop until we have n bytes
        // or the stream ends: gzip may yield a few bytes per call.
        loop {
            let have = self.reader.buffer().len();
            if have >= n {
                break;
            }
            if have > 0 {
                // We cannot top up a BufReader's buffer; what it has is what we can peek.
                break;
            }
            let got =
                self.reader.fill_buf().map_err(|e| ImportError::io(&self.path, Position::Byte(0), e))?.len();
            if got == 0 {
                break;
            }
        }
        let buf = self.reader.buffer();
        Ok(&buf[..buf.len().min(n)])
    }

    /// The buffered reader over the decompressed content.
    pub fn reader(&mut self) -> &mut BufReader<Box<dyn Read + Send>> {
        &mut self.reader
    }

    pub fn into_reader(self) -> BufReader<Box<dyn Read + Send>> {
        self.reader
    }
}

/// Reports how many bytes an [`Input`] has read from disk.
#[derive(Clone, Debug)]
pub struct DiskCounter(Arc<AtomicU64>);

impl DiskCounter {
    pub fn get(&self) -> u64 {
        self.0.load(Ordering::Relaxed)
    }
}

struct CountingReader<R> {
    inner: R,
    count: Arc<AtomicU64>,
}

impl<R: Read> Read for CountingReader<R> {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        let n = self.inner.read(buf)?;
        self.count.fetch_add(n as u64, Ordering::Relaxed);
        Ok(n)
    }
}

/// Reads until `buf` is full or the stream ends; returns the bytes read.
pub fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(got)
}

/// The file name without a trailing `.gz`, lower-cased: "Plant.PLY.gz" gives "plant.ply".
pub fn logical_name(path: &Path) -> String {
    let name = path.file_name().map(|n| n.to_string_lossy().to_lowercase()).unwrap_or_default();
    name.strip_suffix(".gz").map(str::to_string).unwrap_or(name)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn gzip_is_detected_by_magic_not_name() {
        let dir = tempfile::tempdir().unwrap();
        let plain = dir.path().join("a.gz"); // misleading name, plain content
        std::fs::write(&plain, b"solid x\nendsolid x\n").unwrap();
        let mut i = Input::open(&plain).unwrap();
        assert!(!i.gzip);
        assert_eq!(i.peek(5).unwrap(), b"solid");

        let gz = dir.path().join("b.stl"); // gzip content, no .gz in the name
        let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
        enc.write_all(b"solid y\nendsolid y\n").unwrap();
        std::fs::write(&gz, enc.finish().unwrap()).unwrap();
        let mut i = Input::open(&gz).unwrap();
        assert!(i.gzip);
        assert_eq!(i.peek(7).unwrap(), b"solid y");
        let mut s = String::new();
        i.reader().read_to_string(&mut s).unwrap();
        assert_eq!(s, "solid y\nendsolid y\n");
        assert!(i.disk_bytes() > 0);
    }

    #[test]
    fn broken_gzip_is_an_error_not_a_panic() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.ply.gz");
        std::fs::write(&p, [0x1f, 0x8b, 0x08, 0x00, 0xde, 0xad, 0xbe, 0xef, 1, 2, 3]).unwrap();
        let mut i = Input::open(&p).unwrap();
        assert!(i.peek(4).is_err());
    }

    #[test]
    fn missing_file_names_the_path() {
        let e = Input::open(Path::new("/nonexistent/x.obj")).err().unwrap();
        assert!(e.to_string().contains("/nonexistent/x.obj"), "{e}");
    }

    /// Regression: `stats` on a FIFO blocked forever in the open, and build/preview on a device
    /// failed later with "Illegal seek". Both are refused at the open, naming the path.
    #[test]
    fn fifos_devices_and_directories_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let e = Input::open(dir.path()).err().unwrap().to_string();
        assert!(e.contains("is a directory, not a regular file"), "{e}");
        #[cfg(unix)]
        {
            let fifo = dir.path().join("model.ply");
            assert!(std::process::Command::new("mkfifo").arg(&fifo).status().unwrap().success());
            let (tx, rx) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                let _ = tx.send(Input::open(&fifo).err().map(|e| e.to_string()));
            });
            let e = rx.recv_timeout(std::time::Duration::from_secs(20)).expect("no hang").unwrap();
            assert!(
                e.contains("model.ply: is a FIFO (named pipe), not a regular file; copy it to a file first"),
                "{e}"
            );
            let e = Input::open(Path::new("/dev/zero")).err().unwrap().to_string();
            assert!(e.contains("/dev/zero: is a character device, not a regular file"), "{e}");
        }
    }

    #[test]
    fn logical_name_strips_gz() {
        assert_eq!(logical_name(Path::new("/a/Plant.PLY.gz")), "plant.ply");
        assert_eq!(logical_name(Path::new("x.obj")), "x.obj");
    }
}
