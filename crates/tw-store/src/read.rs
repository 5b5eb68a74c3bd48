//! [`Store`]: opens a store (a file, or a byte buffer), validates it and decodes pages on demand; [`Store::verify`] checks a whole store (docs/FORMAT.md, "Invariants").
//!
//! `open` reads only the header and the tables (O(objects + nodes + groups + links + pages)) and
//! checks their checksums and structural invariants, so a store that opens can be traversed
//! without further checks; it also derives each group's parents from the stored sources
//! ([`Store::group_parents`]). `page` checks the page's checksum and decodes it; `verify` decodes
//! every page and checks the invariants that need the clusters.
//!
//! Memory. The header and tables are parsed from a temporary memory map that is dropped once
//! they are copied into the store's vectors; a page is read with one positioned read into a
//! buffer that lives while it is decoded. Pages are not read through a long-lived map because
//! the kernel maps more than the bytes touched (fault-around, large page-cache folios), and those
//! neighbouring file pages stayed in the process's resident set even after `MADV_DONTNEED` of the
//! page's range: ~200 MB after a 100-frame walk of a 10^8-triangle store (measured). With reads,
//! the resident set holds decoded pages only, which is what the runtime's budget counts.

use std::fs::File;
use std::path::{Path, PathBuf};

use crate::codec::{self, PageCluster};
use crate::error::StoreError;
use crate::format::{
    checksum, str_at, validate_tables, Group, GroupLinks, Header, Node, ObjectEntry, PageEntry, Reader,
    SectionKind, Tables, FORMAT_VERSION, GROUP_LEN, HEADER_LEN, HEADER_RT_TREES, MAGIC, NODE_LEN, OBJECT_LEN,
    PAGE_ENTRY_LEN, SECTIONS_AT, SECTION_ALIGN, SECTION_ENTRY_LEN, SOURCE_LEN,
};
use crate::rt::RtTree;
use crate::write::{Object, TABLE_ORDER};

/// Checksums are skipped only when fuzzing, so that the fuzzer reaches the parsers behind them.
const CHECK_CRC: bool = !cfg!(fuzzing);

/// Where the bytes of the store are.
enum Data {
    /// An open file of `len` bytes: pages are read with positioned reads.
    File { file: File, len: u64 },
    /// The whole store in memory.
    Vec(Vec<u8>),
}

impl Data {
    fn len(&self) -> u64 {
        match self {
            Data::File { len, .. } => *len,
            Data::Vec(v) => v.len() as u64,
        }
    }

    /// `len` bytes at `offset` (in bounds: checked by `open`).
    fn read(&self, offset: u64, len: usize) -> std::io::Result<std::borrow::Cow<'_, [u8]>> {
        match self {
            Data::Vec(v) => Ok(std::borrow::Cow::Borrowed(
                v.get(offset as usize..offset as usize + len).unwrap_or_default(),
            )),
            Data::File { file, .. } => {
                let mut buf = vec![0u8; len];
                read_exact_at(file, &mut buf, offset)?;
                Ok(std::borrow::Cow::Owned(buf))
            }
        }
    }
}

#[cfg(unix)]
fn read_exact_at(file: &File, buf: &mut [u8], offset: u64) -> std::io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, offset)
}

#[cfg(windows)]
fn read_exact_at(file: &File, mut buf: &mut [u8], mut offset: u64) -> std::io::Result<()> {
    while !buf.is_empty() {
        match std::os::windows::fs::FileExt::seek_read(file, buf, offset) {
            Ok(0) => return Err(std::io::ErrorKind::UnexpectedEof.into()),
            Ok(n) => {
                buf = &mut buf[n..];
                offset += n as u64;
            }
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(())
}

/// The parsed header and tables of a store: everything but its bytes.
struct Parsed {
    header: Header,
    units: String,
    build_options: String,
    objects: Vec<Object>,
    nodes: Vec<Node>,
    groups: Vec<Group>,
    links: GroupLinks,
    pages: Vec<PageEntry>,
}

/// An open store. Cheap to query; pages are decoded on demand.
pub struct Store {
    path: PathBuf,
    data: Data,
    t: Parsed,
}

/// What [`Store::verify`] found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VerifyReport {
    pub file_bytes: u64,
    pub page_bytes: u64,
    pub pages: u32,
    pub root_pages: u32,
    pub nodes: u32,
    pub groups: u32,
    pub objects: u32,
    /// Links between groups (Σ of the groups' source counts).
    pub group_links: u64,
    pub clusters: u64,
    /// Triangles over all levels.
    pub triangles: u64,
    /// Triangles of level-0 (full-resolution) clusters.
    pub level0_triangles: u64,
    /// Highest cluster level.
    pub max_level: u8,
    /// File bytes per input triangle (the header's count; 0 when there is none).
    pub bytes_per_input_triangle: f64,
}

impl std::fmt::Debug for Store {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Store")
            .field("path", &self.path)
            .field("bytes", &self.data.len())
            .field("pages", &self.t.pages.len())
            .field("nodes", &self.t.nodes.len())
            .field("groups", &self.t.groups.len())
            .finish()
    }
}

impl Store {
    /// Opens and validates the store at `path` (header and tables are read now, pages on
    /// demand).
    ///
    /// Only a regular file is opened: a FIFO would block the open, and a device such as
    /// `/dev/zero` reports length 0 and never ends. Every read is bounded by the file's length
    /// as opened: the header's sizes are checked against it before anything they describe is
    /// read or allocated.
    pub fn open(path: impl AsRef<Path>) -> Result<Store, StoreError> {
        let path = path.as_ref().to_path_buf();
        let io = |source| StoreError::Io { path: path.clone(), source };
        let (file, meta) = tw_core::regular_file::open_regular(&path).map_err(io)?;
        let len = meta.len();
        if len < HEADER_LEN as u64 {
            // Too small to be a store (and zero-length maps fail on some systems): its bytes,
            // at most a header's worth whatever the file does meanwhile, for the error message.
            let mut bytes = Vec::with_capacity(HEADER_LEN);
            std::io::Read::read_to_end(&mut std::io::Read::take(&file, HEADER_LEN as u64), &mut bytes)
                .map_err(io)?;
            return Store::from_vec(path.clone(), bytes);
        }
        let parsed = {
            // SAFETY: the map is read-only and every byte is read through checked accessors, so
            // any content is safe to read. As with any mmap, another process truncating the file
            // meanwhile can fault the reader; stores are written once and renamed into place,
            // never modified. The map lives only while the tables are parsed.
            #[allow(unsafe_code)]
            let map = unsafe { memmap2::Mmap::map(&file) }.map_err(io)?;
            Store::parse(&path, &map)?
        };
        Ok(Store { path, data: Data::File { file, len }, t: parsed })
    }

    /// Opens and validates a store held in memory (tests, fuzzing, embedded stores).
    pub fn from_bytes(bytes: Vec<u8>) -> Result<Store, StoreError> {
        Store::from_vec(PathBuf::from("<memory>"), bytes)
    }

    fn from_vec(path: PathBuf, bytes: Vec<u8>) -> Result<Store, StoreError> {
        let t = Store::parse(&path, &bytes)?;
        Ok(Store { path, data: Data::Vec(bytes), t })
    }

    /// Checks the header and the tables, in the order that gives the dedicated errors first
    /// (not a store, version, truncation), and copies them out of `bytes`.
    fn parse(path: &Path, bytes: &[u8]) -> Result<Parsed, StoreError> {
        let p = Parser { path, bytes };
        let header = p.header()?;
        p.check_table_sizes(&header)?;
        p.check_layout(&header)?;
        p.check_padding_and_checksums(&header)?;
        let raw = p.tables(&header)?;
        let links = validate_tables(&raw.as_tables(&header)).map_err(|e| p.corrupt(e))?;
        Ok(raw.into_parsed(header, links))
    }

    /// The file this store was opened from (`<memory>` for [`from_bytes`](Self::from_bytes)).
    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn header(&self) -> &Header {
        &self.t.header
    }

    pub fn units(&self) -> &str {
        &self.t.units
    }

    /// Metres per unit of the recorded units ([`crate::units::metres_per_unit`]); `None` for
    /// units it does not know.
    pub fn metres_per_unit(&self) -> Option<f64> {
        crate::units::metres_per_unit(&self.t.units)
    }

    pub fn build_options(&self) -> &str {
        &self.t.build_options
    }

    pub fn objects(&self) -> &[Object] {
        &self.t.objects
    }

    /// The skeleton; node 0 is the root.
    pub fn nodes(&self) -> &[Node] {
        &self.t.nodes
    }

    pub fn groups(&self) -> &[Group] {
        &self.t.groups
    }

    pub fn pages(&self) -> &[PageEntry] {
        &self.t.pages
    }

    /// The sources of `group`: the finer groups its clusters were simplified from (sorted, each
    /// with a smaller index than `group`). Empty for a group of input clusters, or for an index
    /// beyond the group table.
    pub fn group_sources(&self, group: u32) -> &[u32] {
        self.t.links.sources(group)
    }

    /// The parents of `group`: the coarser groups whose clusters were simplified from it (sorted,
    /// each with a larger index than `group`). Empty exactly for the root groups (error = +∞),
    /// or for an index beyond the group table.
    pub fn group_parents(&self, group: u32) -> &[u32] {
        self.t.links.parents(group)
    }

    /// Both relations, for callers that keep them apart from the store.
    pub fn group_links(&self) -> &GroupLinks {
        &self.t.links
    }

    /// Size of the store in bytes.
    pub fn file_len(&self) -> u64 {
        self.data.len()
    }

    fn page_entry(&self, index: u32) -> Result<&PageEntry, StoreError> {
        self.t.pages.get(index as usize).ok_or_else(|| StoreError::Page {
            path: self.path.clone(),
            page: index,
            offset: 0,
            msg: format!("no such page (the store has {})", self.t.pages.len()),
        })
    }

    /// The encoded bytes of page `index`, after checking its checksum.
    pub fn page_bytes(&self, index: u32) -> Result<std::borrow::Cow<'_, [u8]>, StoreError> {
        let p = self.page_entry(index)?;
        // In bounds: open checked that the pages fill the pages region, inside the file.
        let bytes = self.data.read(p.offset, p.compressed_len as usize).map_err(|e| StoreError::Page {
            path: self.path.clone(),
            page: index,
            offset: p.offset,
            msg: format!("reading {} bytes: {e}", p.compressed_len),
        })?;
        let actual = checksum(&bytes);
        if CHECK_CRC && actual != p.checksum {
            return Err(StoreError::Page {
                path: self.path.clone(),
                page: index,
                offset: p.offset,
                msg: format!("checksum mismatch (stored {:#010x}, computed {actual:#010x})", p.checksum),
            });
        }
        Ok(bytes)
    }

    /// Decodes page `index` (checksum, then every cluster; see [`codec::decode_page`]) and
    /// checks it against its page table entry.
    pub fn page(&self, index: u32) -> Result<Vec<PageCluster>, StoreError> {
        self.page_with_trees(index).map(|(clusters, _)| clusters)
    }

    /// True when every cluster carries its ray-tracing tree ([`HEADER_RT_TREES`]; `terawalk
    /// build --rt-bvh`).
    pub fn has_rt_trees(&self) -> bool {
        self.header().flags & HEADER_RT_TREES != 0
    }

    /// [`Store::page`] with the clusters' ray-tracing trees, one per cluster, validated
    /// ([`RtTree::validate`]); none when the store has no trees ([`Store::has_rt_trees`]).
    pub fn page_with_trees(&self, index: u32) -> Result<(Vec<PageCluster>, Vec<RtTree>), StoreError> {
        let bytes = self.page_bytes(index)?;
        let p = self.page_entry(index)?;
        let err =
            |offset: u64, msg: String| StoreError::Page { path: self.path.clone(), page: index, offset, msg };
        let (clusters, trees) =
            codec::decode_page_with_trees(&bytes, p.cluster_count as usize, self.has_rt_trees())
                .map_err(|e| err(p.offset + e.offset as u64, e.msg))?;
        drop(bytes);
        let triangles: usize = clusters.iter().map(|c| c.triangle_count()).sum();
        let decoded: usize =
            clusters.iter().map(|c| codec::decoded_len(c.positions.len(), c.triangle_count())).sum();
        let lmin = clusters.iter().map(|c| c.level).min().unwrap_or(0);
        let lmax = clusters.iter().map(|c| c.level).max().unwrap_or(0);
        if triangles != p.triangle_count as usize
            || decoded != p.uncompressed_len as usize
            || (lmin, lmax) != (p.level_min, p.level_max)
        {
            return Err(err(
                p.offset,
                format!(
                    "decoded {triangles} triangles / {decoded} bytes / levels {lmin}..={lmax}, the page table \
                     says {} / {} / {}..={}",
                    p.triangle_count, p.uncompressed_len, p.level_min, p.level_max
                ),
            ));
        }
        Ok((clusters, trees))
    }

    /// Checks every page (checksum, decoding) and the invariants that need the clusters: each
    /// cluster's group lists it (same page, within the group's cluster range) and the group's
    /// counts match; `self_error ≤ group.error`; the self sphere lies in the group's sphere;
    /// the cluster's level ≤ the group's level; positions lie in the group's node bounds; each
    /// node's `max_error` ≥ the errors of the groups in its subtree; the group sources agree
    /// with the clusters: a cluster with `self_error > 0` has a source in its group's sources
    /// whose error and sphere equal its self error and self sphere, every source of a group is
    /// matched so by one of its clusters, and sources of a group with equal error and sphere (one
    /// simplification step) have the same parents.
    /// `progress(done, total)` is called after each page. Stops at the first problem.
    pub fn verify(&self, mut progress: impl FnMut(u32, u32)) -> Result<VerifyReport, StoreError> {
        let mut v = Verifier::new(self);
        let total = self.t.pages.len() as u32;
        for (pi, p) in self.t.pages.iter().enumerate() {
            v.check_page(pi as u32, p)?;
            progress(pi as u32 + 1, total);
        }
        v.check_group_counts()?;
        v.check_every_source_used()?;
        self.check_step_parents()?;
        self.check_node_errors()?;
        Ok(v.report())
    }

    fn invariant(&self, msg: String) -> StoreError {
        StoreError::Invariant { path: self.path.clone(), msg }
    }

    /// The sources of one simplification step (those of a group with equal error and sphere)
    /// have the same parents, so that the runtime's availability rule treats them alike.
    fn check_step_parents(&self) -> Result<(), StoreError> {
        let step_key = |s: u32| {
            let g = &self.t.groups[s as usize];
            (g.error.to_bits(), g.sphere.map(f32::to_bits))
        };
        let mut step: Vec<u32> = Vec::new();
        for group in 0..self.t.groups.len() as u32 {
            step.clear();
            step.extend_from_slice(self.t.links.sources(group));
            step.sort_by_key(|&s| (step_key(s), s));
            for w in step.windows(2) {
                if step_key(w[0]) == step_key(w[1])
                    && self.t.links.parents(w[0]) != self.t.links.parents(w[1])
                {
                    return Err(self.invariant(format!(
                        "group {group}: sources {} and {} have the same error and sphere (one simplification \
                         step) but different parents {:?} and {:?}",
                        w[0],
                        w[1],
                        self.t.links.parents(w[0]),
                        self.t.links.parents(w[1])
                    )));
                }
            }
        }
        Ok(())
    }

    /// Each node's `max_error` is at least the largest error of the groups in its subtree.
    /// Children come after their parent (checked at open): one backward pass.
    fn check_node_errors(&self) -> Result<(), StoreError> {
        let mut subtree = vec![0f32; self.t.nodes.len()];
        for i in (0..self.t.nodes.len()).rev() {
            let n = &self.t.nodes[i];
            let mut m = 0f32;
            let groups = n.first_group as usize..n.first_group as usize + n.group_count as usize;
            for g in self.t.groups.get(groups).unwrap_or_default() {
                m = m.max(g.error);
            }
            let children = n.first_child as usize..n.first_child as usize + n.child_count as usize;
            for &c in subtree.get(children).unwrap_or_default() {
                m = m.max(c);
            }
            if n.max_error < m {
                return Err(self.invariant(format!(
                    "node {i}: max error {} < {m}, the largest group error in its subtree",
                    n.max_error
                )));
            }
            subtree[i] = m;
        }
        Ok(())
    }
}

/// What [`Store::verify`] gathers page after page, and the checks of each cluster.
struct Verifier<'s> {
    store: &'s Store,
    rep: VerifyReport,
    /// Whether some cluster of the group was made from that source, by link.
    link_used: Vec<bool>,
    /// Clusters found of each group.
    claimed: Vec<u32>,
    /// Triangles found of each group.
    group_tris: Vec<u64>,
}

impl<'s> Verifier<'s> {
    fn new(store: &'s Store) -> Verifier<'s> {
        let t = &store.t;
        let rep = VerifyReport {
            file_bytes: store.file_len(),
            page_bytes: t.header.section(SectionKind::Pages).length,
            pages: t.pages.len() as u32,
            nodes: t.nodes.len() as u32,
            groups: t.groups.len() as u32,
            objects: t.objects.len() as u32,
            group_links: t.links.link_count() as u64,
            ..Default::default()
        };
        Verifier {
            store,
            rep,
            link_used: vec![false; t.links.link_count()],
            claimed: vec![0u32; t.groups.len()],
            group_tris: vec![0u64; t.groups.len()],
        }
    }

    fn invariant(&self, msg: String) -> StoreError {
        self.store.invariant(msg)
    }

    /// Decodes page `pi` (checksum, decoding, page table counts) and checks each cluster.
    fn check_page(&mut self, pi: u32, p: &PageEntry) -> Result<(), StoreError> {
        let clusters = self.store.page(pi)?;
        self.rep.root_pages += p.is_root() as u32;
        for (k, c) in clusters.iter().enumerate() {
            self.check_cluster(pi, k, c)?;
        }
        Ok(())
    }

    /// Cluster `k` of page `pi` against its group, its group's sources and its group's node;
    /// counts it.
    fn check_cluster(&mut self, pi: u32, k: usize, c: &PageCluster) -> Result<(), StoreError> {
        let at = format!("page {pi} cluster {k}");
        let g = self.group_listing(&at, pi, k, c)?;
        self.claimed[c.group as usize] += 1;
        self.group_tris[c.group as usize] += c.triangle_count() as u64;
        if c.self_error > g.error {
            return Err(self.invariant(format!(
                "{at}: self error {} > error {} of its group {}",
                c.self_error, g.error, c.group
            )));
        }
        // A simplified cluster (self error > 0) carries the error and sphere of the
        // source(s) it was made from.
        if c.self_error > 0.0 {
            self.match_sources(&at, c)?;
        }
        self.check_within_group(&at, c, g)?;
        self.count(c);
        Ok(())
    }

    /// The cluster's group, which must list it: same page, within the group's cluster range.
    fn group_listing(&self, at: &str, pi: u32, k: usize, c: &PageCluster) -> Result<&'s Group, StoreError> {
        let groups = &self.store.t.groups;
        let g = groups.get(c.group as usize).ok_or_else(|| {
            self.invariant(format!("{at}: group {} beyond {} groups", c.group, groups.len()))
        })?;
        let k = k as u64;
        if g.page != pi || k < g.first_cluster as u64 || k >= g.first_cluster as u64 + g.cluster_count as u64
        {
            return Err(self.invariant(format!(
                "{at}: says group {}, which lists clusters {}..{} of page {}",
                c.group,
                g.first_cluster,
                g.first_cluster as u64 + g.cluster_count as u64,
                g.page
            )));
        }
        Ok(g)
    }

    /// A simplified cluster's self error and sphere are those of some source of its group;
    /// marks every source they match as used.
    fn match_sources(&mut self, at: &str, c: &PageCluster) -> Result<(), StoreError> {
        let t = &self.store.t;
        let range = t.links.source_range(c.group);
        let mut matched = false;
        for (k, &s) in range.clone().zip(t.links.sources(c.group)) {
            let src = &t.groups[s as usize];
            if src.error == c.self_error && src.sphere == c.self_sphere {
                self.link_used[k] = true;
                matched = true;
            }
        }
        if !matched {
            return Err(self.invariant(format!(
                "{at}: self error {} and sphere {:?} match none of the sources {:?} of its group {}",
                c.self_error,
                c.self_sphere,
                t.links.sources(c.group),
                c.group
            )));
        }
        Ok(())
    }

    /// The cluster lies within its group `g`: self sphere inside the group's sphere, level ≤
    /// the group's, every vertex inside the bounds of the group's node.
    fn check_within_group(&self, at: &str, c: &PageCluster, g: &Group) -> Result<(), StoreError> {
        if !sphere_contains(g.sphere, c.self_sphere) {
            return Err(self.invariant(format!(
                "{at}: self sphere {:?} not inside the sphere {:?} of its group {}",
                c.self_sphere, g.sphere, c.group
            )));
        }
        if c.level > g.level {
            return Err(self.invariant(format!("{at}: level {} > level {} of its group", c.level, g.level)));
        }
        // group.node < nodes.len(): checked at open.
        let node = &self.store.t.nodes[g.node as usize];
        if let Some(q) = c.positions.iter().find(|q| (0..3).any(|a| q[a] < node.min[a] || q[a] > node.max[a]))
        {
            return Err(self.invariant(format!(
                "{at}: vertex {q:?} outside the bounds {:?}..={:?} of node {} (its group's node)",
                node.min, node.max, g.node
            )));
        }
        Ok(())
    }

    /// Adds a checked cluster to the report's counts.
    fn count(&mut self, c: &PageCluster) {
        self.rep.clusters += 1;
        self.rep.triangles += c.triangle_count() as u64;
        if c.level == 0 {
            self.rep.level0_triangles += c.triangle_count() as u64;
        }
        self.rep.max_level = self.rep.max_level.max(c.level);
    }

    /// Each group's clusters and triangles, as found in the pages, are those it lists.
    fn check_group_counts(&self) -> Result<(), StoreError> {
        for (i, g) in self.store.t.groups.iter().enumerate() {
            if self.claimed[i] != g.cluster_count || self.group_tris[i] != g.triangles as u64 {
                return Err(self.invariant(format!(
                    "group {i} lists {} clusters / {} triangles, its clusters are {} / {}",
                    g.cluster_count, g.triangles, self.claimed[i], self.group_tris[i]
                )));
            }
        }
        Ok(())
    }

    /// Every source of a group was matched by one of the group's clusters (some cluster was
    /// simplified from it).
    fn check_every_source_used(&self) -> Result<(), StoreError> {
        let t = &self.store.t;
        if let Some(k) = self.link_used.iter().position(|&u| !u) {
            let group = (0..t.groups.len() as u32)
                .find(|&g| t.links.source_range(g).contains(&k))
                .unwrap_or_default();
            let s = t.links.sources(group)[k - t.links.source_range(group).start];
            return Err(self.invariant(format!(
                "group {group}: source {s} (error {}, sphere {:?}) matches none of the group's clusters \
                 (no cluster was simplified from it)",
                t.groups[s as usize].error, t.groups[s as usize].sphere
            )));
        }
        Ok(())
    }

    /// The report, with the file's bytes per input triangle.
    fn report(self) -> VerifyReport {
        let mut rep = self.rep;
        let input_triangles = self.store.t.header.input_triangles;
        if input_triangles > 0 {
            rep.bytes_per_input_triangle = rep.file_bytes as f64 / input_triangles as f64;
        }
        rep
    }
}

/// Byte offset of the section directory's entry for `kind`.
fn dir_at(kind: SectionKind) -> u64 {
    (SECTIONS_AT + SECTION_ENTRY_LEN * kind as usize) as u64
}

/// The steps of [`Store::parse`] over a store's bytes; errors name `path`.
struct Parser<'a> {
    path: &'a Path,
    bytes: &'a [u8],
}

impl<'a> Parser<'a> {
    fn len(&self) -> u64 {
        self.bytes.len() as u64
    }

    fn corrupt(&self, (offset, msg): (u64, String)) -> StoreError {
        StoreError::Corrupt { path: self.path.to_path_buf(), offset, msg }
    }

    fn truncated(&self, what: &str, needed: u64) -> StoreError {
        StoreError::Truncated { path: self.path.to_path_buf(), what: what.into(), needed, len: self.len() }
    }

    /// The magic and the version first (their own errors: not a store, rebuild), then the
    /// whole header and its checks.
    fn header(&self) -> Result<Header, StoreError> {
        let bytes = self.bytes;
        let n = bytes.len().min(MAGIC.len());
        if bytes[..n] != MAGIC[..n] {
            return Err(StoreError::NotAStore { path: self.path.to_path_buf() });
        }
        if bytes.len() < 12 {
            return Err(self.truncated("the header", HEADER_LEN as u64));
        }
        let version = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
        if version != FORMAT_VERSION {
            return Err(StoreError::Version { path: self.path.to_path_buf(), found: version });
        }
        if bytes.len() < HEADER_LEN {
            return Err(self.truncated("the header", HEADER_LEN as u64));
        }
        Header::parse(&bytes[..HEADER_LEN], CHECK_CRC).map_err(|e| self.corrupt(e))
    }

    /// Section directory: the tables of fixed-size entries as long as their counts say, the
    /// group sources whole entries, the string table within 4 GiB.
    fn check_table_sizes(&self, h: &Header) -> Result<(), StoreError> {
        let fixed = [
            (SectionKind::Objects, h.object_count, OBJECT_LEN),
            (SectionKind::Nodes, h.node_count, NODE_LEN),
            (SectionKind::Groups, h.group_count, GROUP_LEN),
            (SectionKind::PageTable, h.page_count, PAGE_ENTRY_LEN),
        ];
        for (kind, count, size) in fixed {
            if h.section(kind).length != count as u64 * size as u64 {
                return Err(self.corrupt((
                    dir_at(kind),
                    format!(
                        "{} is {} bytes, expected {count} entries of {size}",
                        kind.name(),
                        h.section(kind).length
                    ),
                )));
            }
        }
        let sources_len = h.section(SectionKind::GroupSources).length;
        if !sources_len.is_multiple_of(SOURCE_LEN as u64) {
            return Err(self.corrupt((
                dir_at(SectionKind::GroupSources),
                format!("group sources are {sources_len} bytes, not a multiple of {SOURCE_LEN}"),
            )));
        }
        let strings_len = h.section(SectionKind::Strings).length;
        if strings_len > u32::MAX as u64 {
            return Err(self.corrupt((dir_at(SectionKind::Strings), "string table over 4 GiB".into())));
        }
        Ok(())
    }

    /// The canonical layout: the pages region right after the header, then the tables in
    /// [`TABLE_ORDER`] at their aligned offsets, all within the file and nothing after them.
    fn check_layout(&self, h: &Header) -> Result<(), StoreError> {
        let len = self.len();
        let pages = h.section(SectionKind::Pages);
        if pages.offset != HEADER_LEN as u64 || pages.checksum != 0 {
            return Err(self.corrupt((
                dir_at(SectionKind::Pages),
                format!(
                    "pages region at byte {} with checksum {}, expected {HEADER_LEN} and 0",
                    pages.offset, pages.checksum
                ),
            )));
        }
        // The lengths come from the file: each section must end within it before the next
        // offset is computed from its end (which cannot overflow then).
        if pages.length > len {
            return Err(self.truncated("the pages region", pages.offset.saturating_add(pages.length)));
        }
        let mut pos = pages.end();
        for kind in TABLE_ORDER {
            let s = h.section(kind);
            let offset = pos.next_multiple_of(SECTION_ALIGN);
            if s.offset != offset {
                return Err(self.corrupt((
                    dir_at(kind),
                    format!("{} at byte {}, expected {offset}", kind.name(), s.offset),
                )));
            }
            pos = s.end();
            if pos > len {
                return Err(self.truncated("the tables", pos));
            }
        }
        if pos < len {
            return Err(self.corrupt((pos, format!("{} unexpected bytes after the last table", len - pos))));
        }
        Ok(())
    }

    /// The padding before each table is zero and each table's checksum matches (the layout is
    /// checked: every range lies in the file).
    fn check_padding_and_checksums(&self, h: &Header) -> Result<(), StoreError> {
        let mut prev_end = h.section(SectionKind::Pages).end();
        for kind in TABLE_ORDER {
            let s = h.section(kind);
            if let Some(i) = self.bytes[prev_end as usize..s.offset as usize].iter().position(|&b| b != 0) {
                return Err(self.corrupt((prev_end + i as u64, "padding byte is not zero".into())));
            }
            prev_end = s.end();
            let actual = checksum(self.section(h, kind));
            if CHECK_CRC && actual != s.checksum {
                return Err(self.corrupt((
                    s.offset,
                    format!(
                        "{} checksum mismatch (stored {:#010x}, computed {actual:#010x})",
                        kind.name(),
                        s.checksum
                    ),
                )));
            }
        }
        Ok(())
    }

    /// The bytes of section `kind` (within the file: checked by [`Parser::check_layout`]).
    fn section(&self, h: &Header, kind: SectionKind) -> &'a [u8] {
        let s = h.section(kind);
        &self.bytes[s.offset as usize..s.end() as usize]
    }

    /// `count` entries of the table `kind`, each read by `parse`.
    fn entries<T>(
        &self,
        h: &Header,
        kind: SectionKind,
        count: u64,
        mut parse: impl FnMut(&mut Reader<'a>) -> Result<T, (u64, String)>,
    ) -> Result<Vec<T>, StoreError> {
        let mut r = Reader::new(self.section(h, kind), h.section(kind).offset);
        (0..count).map(|_| parse(&mut r)).collect::<Result<Vec<_>, _>>().map_err(|e| self.corrupt(e))
    }

    /// Every table, entry by entry (each entry's own checks; the relations between them are
    /// [`validate_tables`]'s).
    fn tables(&self, h: &Header) -> Result<RawTables<'a>, StoreError> {
        let objects = self.entries(h, SectionKind::Objects, h.object_count as u64, ObjectEntry::parse)?;
        let nodes = self.entries(h, SectionKind::Nodes, h.node_count as u64, Node::parse)?;
        let groups = self.entries(h, SectionKind::Groups, h.group_count as u64, Group::parse)?;
        let pages = self.entries(h, SectionKind::PageTable, h.page_count as u64, PageEntry::parse)?;
        // The section lies inside the file (checked above): its length bounds this allocation.
        let source_count = h.section(SectionKind::GroupSources).length / SOURCE_LEN as u64;
        let sources = self.entries(h, SectionKind::GroupSources, source_count, |r| r.u32())?;
        let strings = self.section(h, SectionKind::Strings);
        Ok(RawTables { objects, nodes, groups, pages, sources, strings })
    }
}

/// The tables as stored, parsed but not yet validated as a whole.
struct RawTables<'a> {
    objects: Vec<ObjectEntry>,
    nodes: Vec<Node>,
    groups: Vec<Group>,
    pages: Vec<PageEntry>,
    sources: Vec<u32>,
    strings: &'a [u8],
}

impl RawTables<'_> {
    fn as_tables<'t>(&'t self, header: &'t Header) -> Tables<'t> {
        Tables {
            header,
            objects: &self.objects,
            nodes: &self.nodes,
            groups: &self.groups,
            pages: &self.pages,
            strings: self.strings,
            sources: &self.sources,
        }
    }

    /// The store's own copy of the validated tables: strings resolved, the group sources
    /// replaced by `links` (dropped before the object names are copied).
    fn into_parsed(self, header: Header, links: GroupLinks) -> Parsed {
        let RawTables { objects, nodes, groups, pages, sources, strings } = self;
        drop(sources);
        // Validated: these cannot fail.
        let text = |r| str_at(strings, r).unwrap_or_default().to_owned();
        let units = text(header.units);
        let build_options = text(header.build_options);
        let objects = objects
            .iter()
            .map(|o| Object { name: text(o.name), color: o.color, triangles: o.triangles })
            .collect();
        Parsed { header, units, build_options, objects, nodes, groups, links, pages }
    }
}

/// `inner` lies in `outer`, with a relative tolerance for f32 rounding.
fn sphere_contains(outer: [f32; 4], inner: [f32; 4]) -> bool {
    let d = (0..3).map(|a| (outer[a] as f64 - inner[a] as f64).powi(2)).sum::<f64>().sqrt();
    let scale =
        (0..3).map(|a| (outer[a] as f64).abs().max((inner[a] as f64).abs())).fold(outer[3] as f64, f64::max);
    d + inner[3] as f64 <= outer[3] as f64 + 1e-5 * scale + 1e-30
}
