//! On-disk structures of `scene.tw`, version 2, as specified in `docs/FORMAT.md`.
//!
//! Every structure is little-endian with a fixed size and is (de)serialized field by field with
//! checked reads: nothing is transmuted from file bytes. [`validate_tables`] (module `tables`)
//! holds the structural invariants shared by the writer (which refuses to write a store that
//! breaks them) and the reader (which refuses to open one).

mod tables;

pub use tables::{validate_tables, GroupLinks, Tables};

/// The first 8 bytes of every store.
pub const MAGIC: [u8; 8] = *b"TERAWALK";
/// The format version this crate reads and writes.
pub const FORMAT_VERSION: u32 = 3;
/// Size of the header in bytes.
pub const HEADER_LEN: usize = 344;
/// Byte offset of the header checksum (CRC-32C of bytes `0..HEADER_CRC_AT`).
pub const HEADER_CRC_AT: usize = 340;
/// Byte offset of the section directory in the header.
pub const SECTIONS_AT: usize = 160;
/// Size of one section directory entry.
pub const SECTION_ENTRY_LEN: usize = 24;
/// Number of sections (entries of the section directory).
pub const SECTION_COUNT: usize = 7;
/// Size of one object table entry.
pub const OBJECT_LEN: usize = 24;
/// Size of one skeleton node.
pub const NODE_LEN: usize = 48;
/// Size of one group entry.
pub const GROUP_LEN: usize = 48;
/// Size of one page table entry.
pub const PAGE_ENTRY_LEN: usize = 32;
/// Size of one entry of the group sources (a `u32` group index).
pub const SOURCE_LEN: usize = 4;
/// Tables start at multiples of this (the gap is zero-filled).
pub const SECTION_ALIGN: u64 = 8;

/// Largest scene-space coordinate (grid coordinate × grid step) a store may hold. Scene space is
/// f32 on the render side, which squares distances (sphere tests, projected errors): with
/// coordinates up to 2^60 those squares stay far below `f32::MAX` (≈ 3.4e38). A store beyond
/// it (say a grid step of 1e300) would render as infinities and NaNs, so it is refused.
pub const MAX_SCENE_COORD: f64 = (1u64 << 60) as f64;
/// Smallest grid step: below the smallest normal f32 every scene-space position of a unit grid
/// coordinate rounds to a subnormal or to zero, and the scene collapses to a point.
pub const MIN_GRID_STEP: f64 = f32::MIN_POSITIVE as f64;

/// Page flag: the page holds the coarsest levels and should stay resident.
pub const PAGE_ROOT: u8 = 1;
/// Header flag: every cluster of every page is followed by its ray-tracing tree
/// (`terawalk build --rt-bvh`; docs/FORMAT.md, "Ray-tracing trees").
pub const HEADER_RT_TREES: u32 = 1;
/// The header flags this version defines.
pub const HEADER_FLAGS: u32 = HEADER_RT_TREES;
/// Object flag: the object has a colour.
pub const OBJECT_HAS_COLOR: u32 = 1;

/// CRC-32C (Castagnoli), the checksum of the header, the tables and every page.
pub fn checksum(bytes: &[u8]) -> u32 {
    crc32c::crc32c(bytes)
}

/// The sections of a store, in the order of the header's section directory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SectionKind {
    Objects = 0,
    Nodes = 1,
    Groups = 2,
    PageTable = 3,
    Pages = 4,
    Strings = 5,
    /// The sources of every group (the finer groups it was simplified from), as `u32` group
    /// indices, group after group.
    GroupSources = 6,
}

impl SectionKind {
    pub const ALL: [SectionKind; SECTION_COUNT] = [
        SectionKind::Objects,
        SectionKind::Nodes,
        SectionKind::Groups,
        SectionKind::PageTable,
        SectionKind::Pages,
        SectionKind::Strings,
        SectionKind::GroupSources,
    ];

    pub fn name(self) -> &'static str {
        match self {
            SectionKind::Objects => "object table",
            SectionKind::Nodes => "skeleton nodes",
            SectionKind::Groups => "group table",
            SectionKind::PageTable => "page table",
            SectionKind::Pages => "pages region",
            SectionKind::Strings => "string table",
            SectionKind::GroupSources => "group sources",
        }
    }
}

/// One entry of the header's section directory.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Section {
    /// Absolute byte offset in the file.
    pub offset: u64,
    /// Length in bytes.
    pub length: u64,
    /// CRC-32C of the section's bytes; 0 for the pages region (each page has its own).
    pub checksum: u32,
}

impl Section {
    pub fn end(&self) -> u64 {
        self.offset.saturating_add(self.length)
    }
}

/// A string in the string table: `len` bytes of UTF-8 from `offset` (relative to the table).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StrRef {
    pub offset: u32,
    pub len: u32,
}

/// The fixed 344-byte header at offset 0.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    pub version: u32,
    /// Feature flags: [`HEADER_RT_TREES`] or 0.
    pub flags: u32,
    /// Up axis of the input: 0 x, 1 y, 2 z.
    pub up_axis: u8,
    /// Scene bounds in input coordinates.
    pub bounds_min: [f64; 3],
    pub bounds_max: [f64; 3],
    /// Input coordinates of grid point (0, 0, 0).
    pub grid_origin: [f64; 3],
    /// Size of one grid step in input units.
    pub grid_step: f64,
    /// Units of the input coordinates (e.g. "m"; may be empty).
    pub units: StrRef,
    /// The build options, as `key=value` lines.
    pub build_options: StrRef,
    pub object_count: u32,
    pub node_count: u32,
    pub group_count: u32,
    pub page_count: u32,
    /// Triangles in the input (after degenerate filtering).
    pub input_triangles: u64,
    /// Clusters over all pages.
    pub cluster_count: u64,
    /// Triangles over all clusters (all LOD levels).
    pub triangle_count: u64,
    /// Section directory, indexed by [`SectionKind`].
    pub sections: [Section; SECTION_COUNT],
}

impl Header {
    /// The header of a store that holds nothing: a scene frame (bounds, grid origin and step,
    /// z up) for code that needs one without a store file (tests, fuzz targets).
    pub fn empty(
        bounds_min: [f64; 3],
        bounds_max: [f64; 3],
        grid_origin: [f64; 3],
        grid_step: f64,
    ) -> Header {
        Header {
            version: FORMAT_VERSION,
            flags: 0,
            up_axis: 2,
            bounds_min,
            bounds_max,
            grid_origin,
            grid_step,
            units: Default::default(),
            build_options: Default::default(),
            object_count: 0,
            node_count: 1,
            group_count: 0,
            page_count: 0,
            input_triangles: 0,
            cluster_count: 0,
            triangle_count: 0,
            sections: Default::default(),
        }
    }

    pub fn section(&self, kind: SectionKind) -> &Section {
        &self.sections[kind as usize]
    }

    /// Serializes the header, checksum included.
    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let mut w = Vec::with_capacity(HEADER_LEN);
        w.extend_from_slice(&MAGIC);
        put_u32(&mut w, self.version);
        put_u32(&mut w, HEADER_LEN as u32);
        put_u32(&mut w, self.flags);
        w.push(self.up_axis);
        w.extend_from_slice(&[0; 3]);
        for v in self.bounds_min.iter().chain(&self.bounds_max).chain(&self.grid_origin) {
            put_f64(&mut w, *v);
        }
        put_f64(&mut w, self.grid_step);
        for s in [self.units, self.build_options] {
            put_u32(&mut w, s.offset);
            put_u32(&mut w, s.len);
        }
        for v in [self.object_count, self.node_count, self.group_count, self.page_count] {
            put_u32(&mut w, v);
        }
        for v in [self.input_triangles, self.cluster_count, self.triangle_count] {
            put_u64(&mut w, v);
        }
        for s in &self.sections {
            put_u64(&mut w, s.offset);
            put_u64(&mut w, s.length);
            put_u32(&mut w, s.checksum);
            put_u32(&mut w, 0);
        }
        w.resize(HEADER_CRC_AT, 0);
        let crc = checksum(&w);
        put_u32(&mut w, crc);
        let mut out = [0u8; HEADER_LEN];
        out.copy_from_slice(&w);
        out
    }

    /// Parses and checks a header (magic, version, checksum, field ranges). `bytes` must hold at
    /// least [`HEADER_LEN`] bytes; the caller checks the magic and version first to give the
    /// dedicated errors. Errors are `(byte offset, message)`.
    pub fn parse(bytes: &[u8], verify_checksum: bool) -> Result<Header, (u64, String)> {
        if bytes.len() < HEADER_LEN {
            return Err((bytes.len() as u64, format!("header needs {HEADER_LEN} bytes")));
        }
        let mut r = Reader::new(bytes, 0);
        let version = read_preamble(&mut r)?;
        if verify_checksum {
            check_header_checksum(bytes)?;
        }
        let (flags, up_axis) = read_flags_and_up_axis(&mut r)?;
        let frame = SceneFrame::read(&mut r)?;
        let header = Header {
            version,
            flags,
            up_axis,
            bounds_min: frame.bounds_min,
            bounds_max: frame.bounds_max,
            grid_origin: frame.grid_origin,
            grid_step: frame.grid_step,
            units: r.str_ref()?,
            build_options: r.str_ref()?,
            object_count: r.u32()?,
            node_count: r.u32()?,
            group_count: r.u32()?,
            page_count: r.u32()?,
            input_triangles: r.u64()?,
            cluster_count: r.u64()?,
            triangle_count: r.u64()?,
            sections: read_section_directory(&mut r)?,
        };
        r.zeros(HEADER_CRC_AT - r.pos)?;
        Ok(header)
    }
}

/// The magic, the version and the header length (bytes 0..16); returns the version (the caller
/// compares it with [`FORMAT_VERSION`]).
fn read_preamble(r: &mut Reader) -> Result<u32, (u64, String)> {
    let magic = r.bytes(8)?;
    if magic != MAGIC {
        return Err((0, "bad magic".into()));
    }
    let version = r.u32()?;
    let header_len = r.u32()?;
    if header_len as usize != HEADER_LEN {
        return Err((12, format!("header length {header_len}, expected {HEADER_LEN}")));
    }
    Ok(version)
}

/// The stored CRC-32C of the header's first [`HEADER_CRC_AT`] bytes is theirs.
fn check_header_checksum(bytes: &[u8]) -> Result<(), (u64, String)> {
    let stored = u32::from_le_bytes([
        bytes[HEADER_CRC_AT],
        bytes[HEADER_CRC_AT + 1],
        bytes[HEADER_CRC_AT + 2],
        bytes[HEADER_CRC_AT + 3],
    ]);
    let actual = checksum(&bytes[..HEADER_CRC_AT]);
    if stored != actual {
        return Err((
            HEADER_CRC_AT as u64,
            format!("header checksum mismatch (stored {stored:#010x}, computed {actual:#010x})"),
        ));
    }
    Ok(())
}

/// The feature flags (only [`HEADER_FLAGS`]) and the up axis (0, 1 or 2) with its 3 reserved
/// bytes.
fn read_flags_and_up_axis(r: &mut Reader) -> Result<(u32, u8), (u64, String)> {
    let flags = r.u32()?;
    if flags & !HEADER_FLAGS != 0 {
        return Err((16, format!("unknown header flags {flags:#x}")));
    }
    let up_axis = r.u8()?;
    if up_axis > 2 {
        return Err((20, format!("up axis {up_axis}, expected 0 (x), 1 (y) or 2 (z)")));
    }
    r.zeros(3)?;
    Ok((flags, up_axis))
}

/// The header's scene frame (bytes 24..104): bounds, grid origin and grid step, in input
/// coordinates.
struct SceneFrame {
    bounds_min: [f64; 3],
    bounds_max: [f64; 3],
    grid_origin: [f64; 3],
    grid_step: f64,
}

impl SceneFrame {
    /// Reads the frame and checks that it is finite, ordered and renderable.
    fn read(r: &mut Reader) -> Result<SceneFrame, (u64, String)> {
        let frame = SceneFrame {
            bounds_min: r.f64x3()?,
            bounds_max: r.f64x3()?,
            grid_origin: r.f64x3()?,
            grid_step: r.f64()?,
        };
        frame.check_finite()?;
        frame.check_renderable()?;
        Ok(frame)
    }

    /// Finite coordinates, bounds min ≤ max, a positive grid step.
    fn check_finite(&self) -> Result<(), (u64, String)> {
        let coords = self.bounds_min.iter().chain(&self.bounds_max).chain(&self.grid_origin);
        for (i, v) in coords.enumerate() {
            if !v.is_finite() {
                return Err((24 + 8 * i as u64, format!("coordinate {v} is not finite")));
            }
        }
        if (0..3).any(|i| self.bounds_min[i] > self.bounds_max[i]) {
            return Err((24, "scene bounds min > max".into()));
        }
        let grid_step = self.grid_step;
        if !(grid_step.is_finite() && grid_step > 0.0) {
            return Err((96, format!("grid step {grid_step} is not positive")));
        }
        Ok(())
    }

    /// The runtime frames cameras and paths by the scene bounds in scene space (relative to the
    /// grid origin, as f32): they must be representable there too, and so must the grid step.
    fn check_renderable(&self) -> Result<(), (u64, String)> {
        for (i, v) in self.bounds_min.iter().chain(&self.bounds_max).enumerate() {
            let scene = v - self.grid_origin[i % 3];
            if scene.abs() > MAX_SCENE_COORD {
                return Err((
                    24 + 8 * i as u64,
                    format!(
                        "scene bound {v:e} lies {scene:e} from the grid origin: beyond the \
                         {MAX_SCENE_COORD:e} that f32 rendering can hold"
                    ),
                ));
            }
        }
        let grid_step = self.grid_step;
        if !(MIN_GRID_STEP..=MAX_SCENE_COORD).contains(&grid_step) {
            return Err((
                96,
                format!(
                    "grid step {grid_step:e} cannot be rendered: scene space is f32, so the step must lie \
                     within {MIN_GRID_STEP:e}..={MAX_SCENE_COORD:e}"
                ),
            ));
        }
        Ok(())
    }
}

/// The section directory: offset, length and checksum of each section, then 4 reserved bytes.
fn read_section_directory(r: &mut Reader) -> Result<[Section; SECTION_COUNT], (u64, String)> {
    let mut sections = [Section::default(); SECTION_COUNT];
    for s in &mut sections {
        s.offset = r.u64()?;
        s.length = r.u64()?;
        s.checksum = r.u32()?;
        r.zeros(4)?;
    }
    Ok(sections)
}

/// One object table entry (an input object: name, colour, triangle count).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjectEntry {
    pub name: StrRef,
    /// sRGB colour with alpha; `None` when the input gave none.
    pub color: Option<[u8; 4]>,
    /// Input triangles of this object.
    pub triangles: u64,
}

impl ObjectEntry {
    pub fn write(&self, w: &mut Vec<u8>) {
        put_u32(w, self.name.offset);
        put_u32(w, self.name.len);
        w.extend_from_slice(&self.color.unwrap_or([0; 4]));
        put_u32(w, if self.color.is_some() { OBJECT_HAS_COLOR } else { 0 });
        put_u64(w, self.triangles);
    }

    pub fn parse(r: &mut Reader) -> Result<ObjectEntry, (u64, String)> {
        let name = StrRef { offset: r.u32()?, len: r.u32()? };
        let rgba = r.bytes(4)?;
        let rgba = [rgba[0], rgba[1], rgba[2], rgba[3]];
        let at = r.offset();
        let flags = r.u32()?;
        let triangles = r.u64()?;
        let color = match flags {
            0 if rgba == [0; 4] => None,
            0 => return Err((at - 4, "colour bytes set on an object without colour".into())),
            OBJECT_HAS_COLOR => Some(rgba),
            f => return Err((at, format!("unknown object flags {f:#x}"))),
        };
        Ok(ObjectEntry { name, color, triangles })
    }
}

/// One node of the skeleton: the spatial hierarchy (one tree, root = node 0).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Node {
    /// Inclusive grid box of everything under this node.
    pub min: [u32; 3],
    pub max: [u32; 3],
    /// Children are nodes `first_child .. first_child + child_count`, all with a larger index
    /// than this node.
    pub first_child: u32,
    /// 0 for a leaf (a cell).
    pub child_count: u32,
    /// LOD / HLOD groups attached to this node: `first_group .. first_group + group_count`.
    pub first_group: u32,
    pub group_count: u32,
    /// Largest `error` of the groups attached to this node or any node below it (may be
    /// infinite): the runtime can skip the subtree once this projects below its threshold.
    pub max_error: f32,
}

impl Node {
    pub fn write(&self, w: &mut Vec<u8>) {
        for v in self.min.iter().chain(&self.max) {
            put_u32(w, *v);
        }
        for v in [self.first_child, self.child_count, self.first_group, self.group_count] {
            put_u32(w, v);
        }
        put_f32(w, self.max_error);
        put_u32(w, 0);
    }

    pub fn parse(r: &mut Reader) -> Result<Node, (u64, String)> {
        let n = Node {
            min: [r.u32()?, r.u32()?, r.u32()?],
            max: [r.u32()?, r.u32()?, r.u32()?],
            first_child: r.u32()?,
            child_count: r.u32()?,
            first_group: r.u32()?,
            group_count: r.u32()?,
            max_error: r.f32()?,
        };
        r.zeros(4)?;
        Ok(n)
    }
}

/// One group of the cluster DAG: clusters that were simplified together and are replaced
/// together. All its clusters are consecutive in one page.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Group {
    /// Bounding sphere (scene space: centre xyz, radius) of the group's geometry.
    pub sphere: [f32; 4],
    /// Object-space error of the coarser clusters that replace this group; infinite for a root
    /// group (nothing replaces it).
    pub error: f32,
    /// The skeleton node this group is attached to.
    pub node: u32,
    /// Simplification level of the member clusters (the largest if mixed).
    pub level: u8,
    /// The page holding the group's clusters.
    pub page: u32,
    /// Index of the group's first cluster within the page.
    pub first_cluster: u32,
    pub cluster_count: u32,
    /// Triangles over the group's clusters.
    pub triangles: u32,
    /// Number of the group's sources: the finer groups its clusters were simplified from. They
    /// are the next `source_count` entries of the group sources section (the sources of the
    /// groups before this one come first); see [`GroupLinks`].
    pub source_count: u32,
}

impl Group {
    pub fn write(&self, w: &mut Vec<u8>) {
        for v in self.sphere {
            put_f32(w, v);
        }
        put_f32(w, self.error);
        for v in [self.node, self.page, self.first_cluster, self.cluster_count, self.triangles] {
            put_u32(w, v);
        }
        w.push(self.level);
        w.extend_from_slice(&[0; 3]);
        put_u32(w, self.source_count);
    }

    pub fn parse(r: &mut Reader) -> Result<Group, (u64, String)> {
        let g = Group {
            sphere: [r.f32()?, r.f32()?, r.f32()?, r.f32()?],
            error: r.f32()?,
            node: r.u32()?,
            page: r.u32()?,
            first_cluster: r.u32()?,
            cluster_count: r.u32()?,
            triangles: r.u32()?,
            level: r.u8()?,
            source_count: 0,
        };
        r.zeros(3)?;
        let source_count = r.u32()?;
        Ok(Group { source_count, ..g })
    }
}

/// One page table entry.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PageEntry {
    /// Absolute byte offset of the page's encoded bytes.
    pub offset: u64,
    /// Length of the encoded bytes.
    pub compressed_len: u32,
    /// Decoded size: Σ over clusters of 12·vertices + 7·triangles (positions as `[u32; 3]`,
    /// indices as `u8`, object ids as `u32`); a memory budget hint, checked on decode.
    pub uncompressed_len: u32,
    pub cluster_count: u32,
    pub triangle_count: u32,
    /// CRC-32C of the encoded bytes.
    pub checksum: u32,
    /// Smallest and largest cluster level in the page.
    pub level_min: u8,
    pub level_max: u8,
    /// Bit 0 ([`PAGE_ROOT`]): a root page, kept resident.
    pub flags: u8,
}

impl PageEntry {
    pub fn is_root(&self) -> bool {
        self.flags & PAGE_ROOT != 0
    }

    pub fn write(&self, w: &mut Vec<u8>) {
        put_u64(w, self.offset);
        for v in [self.compressed_len, self.uncompressed_len, self.cluster_count, self.triangle_count] {
            put_u32(w, v);
        }
        put_u32(w, self.checksum);
        w.extend_from_slice(&[self.level_min, self.level_max, self.flags, 0]);
    }

    pub fn parse(r: &mut Reader) -> Result<PageEntry, (u64, String)> {
        let p = PageEntry {
            offset: r.u64()?,
            compressed_len: r.u32()?,
            uncompressed_len: r.u32()?,
            cluster_count: r.u32()?,
            triangle_count: r.u32()?,
            checksum: r.u32()?,
            level_min: r.u8()?,
            level_max: r.u8()?,
            flags: r.u8()?,
        };
        if p.flags & !PAGE_ROOT != 0 {
            return Err((r.offset() - 1, format!("unknown page flags {:#x}", p.flags)));
        }
        r.zeros(1)?;
        Ok(p)
    }
}

/// The string `s` of the string table, checked.
pub fn str_at(strings: &[u8], s: StrRef) -> Result<&str, String> {
    let end = s.offset as u64 + s.len as u64;
    let bytes = strings.get(s.offset as usize..end as usize).ok_or_else(|| {
        format!("string {}..{end} beyond the {}-byte string table", s.offset, strings.len())
    })?;
    std::str::from_utf8(bytes).map_err(|e| format!("string is not UTF-8: {e}"))
}

/// Checked little-endian reads from a byte slice that starts at absolute file offset `base`.
/// Errors carry the absolute offset of the read that failed.
pub struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
    base: u64,
}

impl<'a> Reader<'a> {
    pub fn new(bytes: &'a [u8], base: u64) -> Reader<'a> {
        Reader { bytes, pos: 0, base }
    }

    /// Absolute offset of the next read.
    pub fn offset(&self) -> u64 {
        self.base + self.pos as u64
    }

    pub fn bytes(&mut self, n: usize) -> Result<&'a [u8], (u64, String)> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        match end {
            Some(end) => {
                let s = &self.bytes[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => Err((self.offset(), format!("{n} bytes needed, {} left", self.bytes.len() - self.pos))),
        }
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], (u64, String)> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.bytes(N)?);
        Ok(a)
    }

    pub fn u8(&mut self) -> Result<u8, (u64, String)> {
        Ok(self.array::<1>()?[0])
    }

    pub fn u32(&mut self) -> Result<u32, (u64, String)> {
        self.array().map(u32::from_le_bytes)
    }

    pub fn u64(&mut self) -> Result<u64, (u64, String)> {
        self.array().map(u64::from_le_bytes)
    }

    pub fn f32(&mut self) -> Result<f32, (u64, String)> {
        self.array().map(f32::from_le_bytes)
    }

    pub fn f64(&mut self) -> Result<f64, (u64, String)> {
        self.array().map(f64::from_le_bytes)
    }

    fn f64x3(&mut self) -> Result<[f64; 3], (u64, String)> {
        Ok([self.f64()?, self.f64()?, self.f64()?])
    }

    /// A string reference: offset, then length.
    fn str_ref(&mut self) -> Result<StrRef, (u64, String)> {
        Ok(StrRef { offset: self.u32()?, len: self.u32()? })
    }

    /// Reserved bytes: must be zero.
    pub fn zeros(&mut self, n: usize) -> Result<(), (u64, String)> {
        let at = self.offset();
        let b = self.bytes(n)?;
        match b.iter().position(|&x| x != 0) {
            None => Ok(()),
            Some(i) => Err((at + i as u64, "reserved byte is not zero".into())),
        }
    }
}

pub fn put_u32(w: &mut Vec<u8>, v: u32) {
    w.extend_from_slice(&v.to_le_bytes());
}

pub fn put_u64(w: &mut Vec<u8>, v: u64) {
    w.extend_from_slice(&v.to_le_bytes());
}

pub fn put_f32(w: &mut Vec<u8>, v: f32) {
    w.extend_from_slice(&v.to_le_bytes());
}

pub fn put_f64(w: &mut Vec<u8>, v: f64) {
    w.extend_from_slice(&v.to_le_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;

    pub(super) fn header() -> Header {
        Header {
            version: FORMAT_VERSION,
            flags: 0,
            up_axis: 2,
            bounds_min: [-1.0, -2.0, -3.0],
            bounds_max: [1.0, 2.0, 3.0],
            grid_origin: [-1.0, -2.0, -3.0],
            grid_step: 6.0 / 16777215.0,
            units: StrRef { offset: 0, len: 1 },
            build_options: StrRef { offset: 1, len: 3 },
            object_count: 1,
            node_count: 2,
            group_count: 3,
            page_count: 4,
            input_triangles: 5,
            cluster_count: 6,
            triangle_count: 7,
            sections: [Section { offset: 344, length: 8, checksum: 9 }; SECTION_COUNT],
        }
    }

    #[test]
    fn header_round_trips_and_has_documented_layout() {
        let h = header();
        let b = h.to_bytes();
        assert_eq!(&b[..8], b"TERAWALK");
        assert_eq!(u32::from_le_bytes(b[8..12].try_into().unwrap()), 3);
        assert_eq!(u32::from_le_bytes(b[12..16].try_into().unwrap()), HEADER_LEN as u32);
        assert_eq!(b[20], 2);
        assert_eq!(f64::from_le_bytes(b[96..104].try_into().unwrap()), h.grid_step);
        assert_eq!(u32::from_le_bytes(b[132..136].try_into().unwrap()), 4);
        assert_eq!(u64::from_le_bytes(b[160..168].try_into().unwrap()), 344);
        // The group sources entry is the 7th of the directory; 12 reserved bytes follow it.
        assert_eq!(u64::from_le_bytes(b[304..312].try_into().unwrap()), 344);
        assert!(b[328..340].iter().all(|&x| x == 0));
        assert_eq!(u32::from_le_bytes(b[340..344].try_into().unwrap()), checksum(&b[..340]));
        assert_eq!(Header::parse(&b, true).unwrap(), h);
    }

    #[test]
    fn header_rejects_bad_checksum_flags_and_reserved() {
        let mut b = header().to_bytes();
        b[100] ^= 1;
        assert!(Header::parse(&b, true).unwrap_err().1.contains("checksum"));
        let mut b = header().to_bytes();
        b[21] = 1;
        assert_eq!(Header::parse(&b, false).unwrap_err().0, 21);
        let mut b = header().to_bytes();
        b[16] = 4;
        assert!(Header::parse(&b, false).unwrap_err().1.contains("flags"));
        let h = Header { flags: HEADER_RT_TREES, ..header() };
        assert_eq!(Header::parse(&h.to_bytes(), true).unwrap().flags, HEADER_RT_TREES);
    }

    #[test]
    fn entries_have_their_documented_sizes() {
        let mut w = Vec::new();
        ObjectEntry::default().write(&mut w);
        assert_eq!(w.len(), OBJECT_LEN);
        w.clear();
        Node::default().write(&mut w);
        assert_eq!(w.len(), NODE_LEN);
        w.clear();
        Group::default().write(&mut w);
        assert_eq!(w.len(), GROUP_LEN);
        w.clear();
        PageEntry::default().write(&mut w);
        assert_eq!(w.len(), PAGE_ENTRY_LEN);
    }

    #[test]
    fn group_entry_has_its_documented_layout() {
        let g = Group { level: 3, source_count: 0x0102_0304, triangles: 7, ..Group::default() };
        let mut w = Vec::new();
        g.write(&mut w);
        assert_eq!(w[40], 3);
        assert_eq!(&w[41..44], &[0, 0, 0]);
        assert_eq!(u32::from_le_bytes(w[44..48].try_into().unwrap()), 0x0102_0304);
        assert_eq!(Group::parse(&mut Reader::new(&w, 0)).unwrap(), g);
        w[42] = 1;
        assert_eq!(Group::parse(&mut Reader::new(&w, 1000)).unwrap_err().0, 1042);
    }

    #[test]
    fn reader_reports_the_offset_of_a_short_read() {
        let mut r = Reader::new(&[1, 2, 3], 100);
        assert_eq!(r.u8().unwrap(), 1);
        assert_eq!(r.u32().unwrap_err().0, 101);
    }
}
