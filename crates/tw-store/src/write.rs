//! [`StoreWriter`]: writes a store atomically, streaming pages as they come (docs/FORMAT.md).
//!
//! Layout written: a zeroed header placeholder, then each page as it is added (the pages
//! region), then on [`StoreWriter::finish`] the tables (objects, nodes, groups, group sources,
//! page table, strings), then the header is patched in place. Everything goes to a temporary file in the
//! destination directory, which is fsynced and renamed over the destination only when `finish`
//! succeeds; a writer dropped before that leaves nothing behind. The bytes depend only on the
//! input (no timestamps, no hash-map order).

use std::fs::File;
use std::io::{Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use tw_core::direct_io::AlignedWriter;

use crate::codec::{self, EncodedCluster, PageCluster};
use crate::error::StoreError;
use crate::format::{
    checksum, validate_tables, Group, Header, Node, ObjectEntry, PageEntry, Section, SectionKind, StrRef,
    Tables, FORMAT_VERSION, HEADER_LEN, HEADER_RT_TREES, PAGE_ROOT, SECTION_ALIGN, SECTION_COUNT,
};

/// Scene-wide facts for the header.
#[derive(Clone, Debug, PartialEq)]
pub struct StoreInfo {
    /// Scene bounds in input coordinates.
    pub bounds_min: [f64; 3],
    pub bounds_max: [f64; 3],
    /// The quantization grid: input coordinates of grid point 0 and the step.
    pub grid_origin: [f64; 3],
    pub grid_step: f64,
    /// Units of the input coordinates (free text, e.g. "m"; may be empty).
    pub units: String,
    /// 0 x, 1 y, 2 z.
    pub up_axis: u8,
    /// Build options as `key=value` lines (for `terawalk info` and reproducibility).
    pub build_options: String,
    /// Input triangles (after degenerate filtering).
    pub input_triangles: u64,
}

/// One input object.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Object {
    pub name: String,
    /// sRGB colour with alpha; `None` when the input gave none.
    pub color: Option<[u8; 4]>,
    /// Input triangles of this object.
    pub triangles: u64,
}

/// What [`StoreWriter::finish`] wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WriteSummary {
    pub file_bytes: u64,
    pub page_bytes: u64,
    pub pages: u32,
    pub clusters: u64,
    pub triangles: u64,
}

/// Writes one store file; see the module documentation.
pub struct StoreWriter {
    path: PathBuf,
    /// Pages and tables, written past the page cache where the file system allows (the runtime
    /// reads pages on demand; see `tw_core::direct_io`); the header goes through `tmp` last.
    out: AlignedWriter,
    tmp: tempfile::NamedTempFile,
    pos: u64,
    pages: Vec<PageEntry>,
    scratch: Vec<u8>,
    /// Header flags ([`StoreWriter::set_rt_trees`]).
    flags: u32,
    /// Removes the temporary file if the process is interrupted ([`crate::cleanup`]).
    _cleanup: crate::cleanup::TempGuard,
}

/// The name prefix of the temporary file a store named `name` is written to before it is
/// renamed into place (hidden, beside the destination).
pub fn temporary_prefix(name: &str) -> String {
    format!(".{name}.tmp")
}

impl StoreWriter {
    /// Starts a store that will appear at `path` when [`finish`](Self::finish) succeeds.
    pub fn create(path: impl AsRef<Path>) -> Result<StoreWriter, StoreError> {
        let path = path.as_ref().to_path_buf();
        let io = |source| StoreError::Io { path: path.clone(), source };
        // The finished file is renamed over `path`: refuse anything but a regular file there (a
        // rename over /dev/null or a directory would replace it).
        tw_core::output::check_replaceable(&path)
            .map_err(|e| io(std::io::Error::new(std::io::ErrorKind::InvalidInput, e.to_string())))?;
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let prefix = temporary_prefix(&name);
        let mut builder = tempfile::Builder::new();
        builder.prefix(&prefix);
        // The usual permissions of a new file (0666 less the umask), not a temp file's 0600.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            builder.permissions(std::fs::Permissions::from_mode(0o666));
        }
        let tmp = builder.tempfile_in(&dir).map_err(io)?;
        let cleanup = crate::cleanup::register(tmp.path());
        crate::cleanup::lock(tmp.as_file()).map_err(io)?;
        let mut out = AlignedWriter::open(tmp.path(), 1 << 20).map_err(io)?;
        out.write_all(&[0u8; HEADER_LEN]).map_err(io)?;
        Ok(StoreWriter {
            path,
            out,
            tmp,
            pos: HEADER_LEN as u64,
            pages: Vec::new(),
            scratch: Vec::new(),
            flags: 0,
            _cleanup: cleanup,
        })
    }

    fn io(&self, source: std::io::Error) -> StoreError {
        StoreError::Io { path: self.path.clone(), source }
    }

    /// Encodes `clusters` as the next page and writes it; returns its index. `root` marks a page
    /// of the coarsest levels that the runtime keeps resident.
    pub fn add_page(&mut self, clusters: &[PageCluster], root: bool) -> Result<u32, StoreError> {
        self.add_page_with(clusters.len(), root, |out| codec::encode_page(clusters, out))
    }

    /// [`StoreWriter::add_page`] for clusters encoded beforehand ([`EncodedCluster::new`], on
    /// any thread): writes the same bytes as `add_page` of the clusters they encode.
    pub fn add_encoded_page(&mut self, clusters: &[EncodedCluster], root: bool) -> Result<u32, StoreError> {
        self.add_page_with(clusters.len(), root, |out| codec::encoded_page(clusters, out))
    }

    /// Writes the page that `encode` appends to an empty buffer and records it in the page table.
    fn add_page_with(
        &mut self,
        cluster_count: usize,
        root: bool,
        encode: impl FnOnce(&mut Vec<u8>) -> Result<codec::PageSummary, String>,
    ) -> Result<u32, StoreError> {
        let index =
            u32::try_from(self.pages.len()).map_err(|_| StoreError::Invalid("too many pages".into()))?;
        self.scratch.clear();
        let s = encode(&mut self.scratch).map_err(|m| StoreError::Invalid(format!("page {index}: {m}")))?;
        let too_big = || StoreError::Invalid(format!("page {index}: more than 4 GiB"));
        let entry = PageEntry {
            offset: self.pos,
            compressed_len: u32::try_from(s.encoded_len).map_err(|_| too_big())?,
            uncompressed_len: u32::try_from(s.decoded_len).map_err(|_| too_big())?,
            cluster_count: cluster_count as u32,
            triangle_count: s.triangles as u32,
            checksum: checksum(&self.scratch),
            level_min: s.level_min,
            level_max: s.level_max,
            flags: if root { PAGE_ROOT } else { 0 },
        };
        if let Err(e) = self.out.write_all(&self.scratch) {
            return Err(self.io(e));
        }
        self.pos += s.encoded_len as u64;
        self.pages.push(entry);
        Ok(index)
    }

    /// Declares that every cluster of every page is followed by its ray-tracing tree
    /// ([`crate::RtTree::encode`], appended to the cluster's [`EncodedCluster::bytes`] by the
    /// caller): sets [`crate::format::HEADER_RT_TREES`]. Call it before [`StoreWriter::finish`].
    pub fn set_rt_trees(&mut self, on: bool) {
        self.flags = if on { HEADER_RT_TREES } else { 0 };
    }

    /// Pages added so far.
    pub fn page_count(&self) -> u32 {
        self.pages.len() as u32
    }

    /// Writes the tables and the header, fsyncs and renames the file into place. Fails without
    /// leaving a file when the tables break an invariant of docs/FORMAT.md (the error says
    /// which). Node 0 is the root; children must come after their parent. `group_sources` holds
    /// the sources of every group, group after group (`groups[i].source_count` of them for group
    /// `i`, increasing, each a smaller group index than `i`).
    pub fn finish(
        mut self,
        info: &StoreInfo,
        objects: &[Object],
        nodes: &[Node],
        groups: &[Group],
        group_sources: &[u32],
    ) -> Result<WriteSummary, StoreError> {
        let tables = self.encode_tables(info, objects, nodes, groups, group_sources)?;
        let header = self.header(info, &tables, nodes.len(), groups.len())?;
        let header_bytes = header.to_bytes();
        // The reader's checks, run before anything is written.
        Header::parse(&header_bytes, true).map_err(|(_, m)| StoreError::Invalid(format!("header: {m}")))?;
        validate_tables(&Tables {
            header: &header,
            objects: &tables.objects,
            nodes,
            groups,
            pages: &self.pages,
            strings: &tables.bodies[SectionKind::Strings as usize],
            sources: group_sources,
        })
        .map_err(|(_, m)| StoreError::Invalid(m))?;
        self.write_tables(&header, &tables.bodies)?;
        let summary = WriteSummary {
            file_bytes: self.pos,
            page_bytes: header.section(SectionKind::Pages).length,
            pages: header.page_count,
            clusters: header.cluster_count,
            triangles: header.triangle_count,
        };
        let path = self.persist(&header_bytes)?;
        tracing::debug!("{}: wrote {} bytes, {} pages", path.display(), summary.file_bytes, summary.pages);
        Ok(summary)
    }

    /// The strings and the tables after the pages region, as bytes.
    fn encode_tables(
        &self,
        info: &StoreInfo,
        objects: &[Object],
        nodes: &[Node],
        groups: &[Group],
        group_sources: &[u32],
    ) -> Result<EncodedTables, StoreError> {
        let StringTable { bytes: strings, units, build_options, objects } = StringTable::new(info, objects)?;
        let mut bodies: [Vec<u8>; SECTION_COUNT] = Default::default();
        objects.iter().for_each(|o| o.write(&mut bodies[SectionKind::Objects as usize]));
        nodes.iter().for_each(|n| n.write(&mut bodies[SectionKind::Nodes as usize]));
        groups.iter().for_each(|g| g.write(&mut bodies[SectionKind::Groups as usize]));
        let links = &mut bodies[SectionKind::GroupSources as usize];
        links.reserve(group_sources.len() * 4);
        group_sources.iter().for_each(|&s| links.extend_from_slice(&s.to_le_bytes()));
        self.pages.iter().for_each(|p| p.write(&mut bodies[SectionKind::PageTable as usize]));
        bodies[SectionKind::Strings as usize] = strings;
        Ok(EncodedTables { units, build_options, objects, bodies })
    }

    /// The header of the finished store: `info`'s scene frame, the counts, and the canonical
    /// section layout of the pages written and the `tables`.
    fn header(
        &self,
        info: &StoreInfo,
        tables: &EncodedTables,
        nodes: usize,
        groups: usize,
    ) -> Result<Header, StoreError> {
        let bodies = &tables.bodies;
        let sections = layout_sections(
            self.pos - HEADER_LEN as u64,
            |k| bodies[k as usize].len() as u64,
            |k| checksum(&bodies[k as usize]),
        );
        Ok(Header {
            version: FORMAT_VERSION,
            flags: self.flags,
            up_axis: info.up_axis,
            bounds_min: info.bounds_min,
            bounds_max: info.bounds_max,
            grid_origin: info.grid_origin,
            grid_step: info.grid_step,
            units: tables.units,
            build_options: tables.build_options,
            object_count: count(tables.objects.len(), "objects")?,
            node_count: count(nodes, "nodes")?,
            group_count: count(groups, "groups")?,
            page_count: self.page_count(),
            input_triangles: info.input_triangles,
            cluster_count: self.pages.iter().map(|p| p.cluster_count as u64).sum(),
            triangle_count: self.pages.iter().map(|p| p.triangle_count as u64).sum(),
            sections,
        })
    }

    /// Writes the tables after the pages region, each at its offset in `header` (zero padding
    /// before it).
    fn write_tables(&mut self, header: &Header, bodies: &[Vec<u8>; SECTION_COUNT]) -> Result<(), StoreError> {
        for kind in TABLE_ORDER {
            let s = header.section(kind);
            let pad = (s.offset - self.pos) as usize;
            let res = self
                .out
                .write_all(&[0u8; SECTION_ALIGN as usize][..pad])
                .and_then(|_| self.out.write_all(&bodies[kind as usize]));
            res.map_err(|e| self.io(e))?;
            self.pos = s.end();
        }
        Ok(())
    }

    /// Flushes the file, writes the header in place, fsyncs the file and renames it over the
    /// destination (then fsyncs its directory); returns the destination.
    fn persist(self, header_bytes: &[u8; HEADER_LEN]) -> Result<PathBuf, StoreError> {
        let path = self.path.clone();
        let io = |source| StoreError::Io { path: path.clone(), source };
        drop(self.out.finish().map_err(io)?);
        let mut tmp = self.tmp;
        let f: &mut File = tmp.as_file_mut();
        f.seek(SeekFrom::Start(0)).map_err(io)?;
        f.write_all(header_bytes).map_err(io)?;
        f.sync_all().map_err(io)?;
        tmp.persist(&path).map_err(|e| io(e.error))?;
        #[cfg(unix)]
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            // Make the rename durable; failure here does not undo a complete, renamed store.
            if let Err(e) = File::open(dir).and_then(|d| d.sync_all()) {
                tracing::warn!("{}: could not fsync the directory: {e}", dir.display());
            }
        }
        Ok(path)
    }
}

/// `n` as a `u32` count of `what`; an error when there are 2^32 or more.
fn count(n: usize, what: &str) -> Result<u32, StoreError> {
    u32::try_from(n).map_err(|_| StoreError::Invalid(format!("{n} {what}: more than 2^32")))
}

/// The string table of a store, and the references to its strings.
struct StringTable {
    bytes: Vec<u8>,
    units: StrRef,
    build_options: StrRef,
    /// The object table, each name in the string table.
    objects: Vec<ObjectEntry>,
}

impl StringTable {
    /// The units, the build options, then every object name, one after the other.
    fn new(info: &StoreInfo, objects: &[Object]) -> Result<StringTable, StoreError> {
        let mut t = StringTable {
            bytes: Vec::new(),
            units: StrRef::default(),
            build_options: StrRef::default(),
            objects: Vec::with_capacity(objects.len()),
        };
        t.units = t.add(&info.units)?;
        t.build_options = t.add(&info.build_options)?;
        for o in objects {
            let name = t.add(&o.name)?;
            t.objects.push(ObjectEntry { name, color: o.color, triangles: o.triangles });
        }
        count(t.bytes.len(), "string bytes")?;
        Ok(t)
    }

    fn add(&mut self, s: &str) -> Result<StrRef, StoreError> {
        let r =
            StrRef { offset: count(self.bytes.len(), "string bytes")?, len: count(s.len(), "string bytes")? };
        self.bytes.extend_from_slice(s.as_bytes());
        Ok(r)
    }
}

/// The tables [`StoreWriter::finish`] writes after the pages region.
struct EncodedTables {
    units: StrRef,
    build_options: StrRef,
    /// The object table's entries.
    objects: Vec<ObjectEntry>,
    /// Each table's bytes, indexed by [`SectionKind`] (the pages region's stays empty).
    bodies: [Vec<u8>; SECTION_COUNT],
}

/// Tables in file order, after the pages region.
pub(crate) const TABLE_ORDER: [SectionKind; SECTION_COUNT - 1] = [
    SectionKind::Objects,
    SectionKind::Nodes,
    SectionKind::Groups,
    SectionKind::GroupSources,
    SectionKind::PageTable,
    SectionKind::Strings,
];

/// The canonical section layout: the pages region right after the header, then the tables in
/// [`TABLE_ORDER`], each at the next multiple of [`SECTION_ALIGN`].
pub(crate) fn layout_sections(
    pages_len: u64,
    len: impl Fn(SectionKind) -> u64,
    crc: impl Fn(SectionKind) -> u32,
) -> [Section; SECTION_COUNT] {
    let mut sections = [Section::default(); SECTION_COUNT];
    sections[SectionKind::Pages as usize] =
        Section { offset: HEADER_LEN as u64, length: pages_len, checksum: 0 };
    let mut pos = HEADER_LEN as u64 + pages_len;
    for kind in TABLE_ORDER {
        let offset = pos.next_multiple_of(SECTION_ALIGN);
        let length = len(kind);
        sections[kind as usize] = Section { offset, length, checksum: crc(kind) };
        pos = offset + length;
    }
    sections
}
