//! Page codec: a page is a list of clusters, each encoded as described in docs/FORMAT.md
//! ("Page encoding").
//!
//! Per cluster: a 40-byte header (counts, level, modes, group, self error and sphere, position
//! origin), then the positions (grid coordinates relative to the origin, bit-packed with the
//! minimal width per axis, absolute or as deltas, or through meshoptimizer's vertex codec: the
//! encoder picks the smallest), then the triangles through meshoptimizer's meshlet codec, then
//! the object ids (one varint when the cluster has one object, else a sorted id table and a
//! bit-packed index per triangle).
//!
//! The encoder stores a cluster in *canonical form* ([`PageCluster::canonical`]): vertices in
//! order of first use, each triangle rotated so that its index triple is lexicographically
//! smallest (winding and triangle order are kept). `decode(encode(c)) == c.canonical()`.
//!
//! The decoder never trusts the bytes: every count, length and index is checked before it is
//! used (including the sizes the meshoptimizer decoders assert on) and errors carry the byte
//! offset within the page.

use crate::error::CodecError;
use crate::rt::RtTree;

/// Most triangles in one cluster.
pub const MAX_TRIANGLES: usize = 128;
/// Most vertices in one cluster (local indices are `u8`).
pub const MAX_VERTICES: usize = 255;
/// Size of the fixed cluster header.
pub const CLUSTER_HEADER_LEN: usize = 40;
/// A lower bound on the encoded size of any cluster (header, 3 width bytes, a 1-byte length and
/// the 16-byte minimum of the meshlet codec, a 1-byte object id).
pub const MIN_CLUSTER_BYTES: usize = CLUSTER_HEADER_LEN + 3 + 1 + 16 + 1;
/// Decoded size of the largest cluster (see [`decoded_len`]).
pub const MAX_DECODED_CLUSTER: usize = 12 * MAX_VERTICES + 7 * MAX_TRIANGLES;

/// Mode bits of the cluster header byte 3.
const POS_MODE_MASK: u8 = 0b11;
const MULTI_OBJECT: u8 = 0b100;

/// How a cluster's positions are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PositionMode {
    /// Bit-packed offsets from the origin (the cluster's minimum corner).
    Packed = 0,
    /// Bit-packed zigzag deltas from the previous vertex; the origin is the first vertex.
    Delta = 1,
    /// meshoptimizer vertex codec (version 1) over `[u32; 3]` offsets from the origin.
    Meshopt = 2,
}

/// One decoded cluster: ≤ 128 triangles over ≤ 255 grid-point vertices.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PageCluster {
    /// Grid coordinates of the vertices.
    pub positions: Vec<[u32; 3]>,
    /// Three local indices per triangle.
    pub indices: Vec<u8>,
    /// Input object id per triangle.
    pub objects: Vec<u32>,
    /// Error (scene units) of the simplification that produced this cluster; 0 at level 0.
    pub self_error: f32,
    /// Sphere (scene space: centre xyz, radius) `self_error` is measured from.
    pub self_sphere: [f32; 4],
    /// Global index of the group this cluster belongs to.
    pub group: u32,
    /// 0 for full resolution, +1 per simplification step.
    pub level: u8,
}

/// A cluster's fields, borrowed: what [`EncodedCluster::from_parts`] encodes, so that a builder
/// that holds its clusters in another form need not copy them into a [`PageCluster`].
#[derive(Clone, Copy, Debug)]
pub struct ClusterParts<'a> {
    pub positions: &'a [[u32; 3]],
    pub indices: &'a [u8],
    pub objects: &'a [u32],
    pub self_error: f32,
    pub self_sphere: [f32; 4],
    pub group: u32,
    pub level: u8,
}

impl PageCluster {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// The cluster's fields, borrowed.
    pub fn parts(&self) -> ClusterParts<'_> {
        ClusterParts {
            positions: &self.positions,
            indices: &self.indices,
            objects: &self.objects,
            self_error: self.self_error,
            self_sphere: self.self_sphere,
            group: self.group,
            level: self.level,
        }
    }

    /// Checks the limits the codec relies on; the message says what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        self.parts().validate()
    }

    /// The same cluster in canonical form: vertices in order of first use (unused vertices last,
    /// in their order), each triangle rotated to its lexicographically smallest rotation.
    pub fn canonical(&self) -> PageCluster {
        let (mut positions, mut indices) = (Vec::new(), Vec::new());
        self.parts().canonical_into(&mut positions, &mut indices);
        PageCluster {
            positions,
            indices,
            objects: self.objects.clone(),
            self_error: self.self_error,
            self_sphere: self.self_sphere,
            group: self.group,
            level: self.level,
        }
    }
}

impl ClusterParts<'_> {
    fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// See [`PageCluster::validate`].
    pub fn validate(&self) -> Result<(), String> {
        let t = self.indices.len() / 3;
        if !self.indices.len().is_multiple_of(3) || t == 0 || t > MAX_TRIANGLES {
            return Err(format!(
                "{} indices: need 3 per triangle, 1..={MAX_TRIANGLES} triangles",
                self.indices.len()
            ));
        }
        let v = self.positions.len();
        if v > MAX_VERTICES {
            return Err(format!("{v} vertices, at most {MAX_VERTICES}"));
        }
        if let Some(i) = self.indices.iter().find(|&&i| i as usize >= v) {
            return Err(format!("index {i} out of range ({v} vertices)"));
        }
        if self.objects.len() != t {
            return Err(format!("{} object ids for {t} triangles", self.objects.len()));
        }
        if !(self.self_error.is_finite() && self.self_error >= 0.0) {
            return Err(format!("self error {} is not finite and ≥ 0", self.self_error));
        }
        if self.self_sphere.iter().any(|x| !x.is_finite()) || self.self_sphere[3] < 0.0 {
            return Err(format!("invalid self sphere {:?}", self.self_sphere));
        }
        Ok(())
    }

    /// Replaces the contents of `positions` and `indices` with the canonical form's
    /// ([`PageCluster::canonical`]).
    fn canonical_into(&self, positions: &mut Vec<[u32; 3]>, indices: &mut Vec<u8>) {
        let mut remap = [u8::MAX; 256];
        positions.clear();
        for &i in self.indices {
            if remap[i as usize] == u8::MAX {
                remap[i as usize] = positions.len() as u8;
                positions.push(self.positions.get(i as usize).copied().unwrap_or_default());
            }
        }
        for (i, p) in self.positions.iter().enumerate() {
            if remap[i] == u8::MAX {
                remap[i] = positions.len() as u8;
                positions.push(*p);
            }
        }
        indices.clear();
        indices.extend(self.indices.iter().map(|&i| remap[i as usize]));
        rotate_triangles(indices);
    }
}

/// Rotates each triangle to its lexicographically smallest rotation (keeps the winding).
fn rotate_triangles(indices: &mut [u8]) {
    for t in indices.chunks_exact_mut(3) {
        let (a, b, c) = (t[0], t[1], t[2]);
        // Distinct indices (all but degenerate triangles): the rotation that starts at the
        // smallest. Otherwise compare the three rotations whole.
        let best = if a != b && b != c && a != c {
            if a < b && a < c {
                [a, b, c]
            } else if b < c {
                [b, c, a]
            } else {
                [c, a, b]
            }
        } else {
            [[a, b, c], [b, c, a], [c, a, b]].into_iter().min().unwrap_or([a, b, c])
        };
        t.copy_from_slice(&best);
    }
}

/// Decoded size of a cluster: 12 bytes per vertex, 3 index bytes and a 4-byte object id per
/// triangle. The page table's `uncompressed_len` is the sum over the page.
pub fn decoded_len(vertices: usize, triangles: usize) -> usize {
    12 * vertices + 7 * triangles
}

/// What [`encode_page`] appended.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PageSummary {
    pub encoded_len: usize,
    pub decoded_len: usize,
    pub triangles: usize,
    pub level_min: u8,
    pub level_max: u8,
}

/// Appends the encoding of `clusters` to `out`. Fails (with the cluster index) on a cluster that
/// breaks the limits of [`PageCluster::validate`].
pub fn encode_page(clusters: &[PageCluster], out: &mut Vec<u8>) -> Result<PageSummary, String> {
    encode_page_with(clusters, out, None)
}

/// One cluster encoded on its own, as it will appear in a page: a page's bytes are its clusters'
/// encodings one after the other, so clusters can be encoded on any thread, long before the
/// page they go into is known, and concatenated later ([`encoded_page`]). The group id is the
/// one field a builder may learn only later; [`EncodedCluster::set_group`] rewrites it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct EncodedCluster {
    pub bytes: Vec<u8>,
    /// The cluster's [`decoded_len`].
    pub decoded_len: usize,
    pub triangles: usize,
    pub level: u8,
}

/// Buffers the encoder reuses from one cluster to the next on a thread (a build encodes millions
/// of clusters on its workers; allocating these for each one made the workers queue on the heap).
#[derive(Default)]
struct Scratch {
    positions: Vec<[u32; 3]>,
    indices: Vec<u8>,
    rel: Vec<[u32; 3]>,
    objects: Vec<u32>,
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// Where the group id sits in a cluster's header (after counts, level and modes).
const GROUP_OFFSET: usize = 4;

impl EncodedCluster {
    /// Encodes `c` (in canonical form, like [`encode_page`]); fails on a cluster that breaks the
    /// limits of [`PageCluster::validate`].
    pub fn new(c: &PageCluster) -> Result<EncodedCluster, String> {
        EncodedCluster::with_mode(c.parts(), None)
    }

    /// [`EncodedCluster::new`] of a cluster's borrowed fields.
    pub fn from_parts(c: ClusterParts<'_>) -> Result<EncodedCluster, String> {
        EncodedCluster::with_mode(c, None)
    }

    /// [`EncodedCluster::new`], with the position encoding forced (tests) or chosen (`None`).
    fn with_mode(c: ClusterParts<'_>, force: Option<PositionMode>) -> Result<EncodedCluster, String> {
        c.validate()?;
        let mut bytes = Vec::with_capacity(CLUSTER_HEADER_LEN + 8 * c.triangle_count());
        SCRATCH.with(|scratch| {
            let scratch = &mut *scratch.borrow_mut();
            c.canonical_into(&mut scratch.positions, &mut scratch.indices);
            let canonical = ClusterParts { positions: &scratch.positions, indices: &scratch.indices, ..c };
            encode_cluster(canonical, &mut bytes, force, &mut scratch.rel, &mut scratch.objects)
        })?;
        Ok(EncodedCluster {
            bytes,
            decoded_len: decoded_len(c.positions.len(), c.triangle_count()),
            triangles: c.triangle_count(),
            level: c.level,
        })
    }

    /// The group id stored in the cluster's header.
    pub fn group(&self) -> u32 {
        let b = &self.bytes[GROUP_OFFSET..GROUP_OFFSET + 4];
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }

    /// Rewrites the group id; the bytes are then those of the cluster encoded with that id.
    pub fn set_group(&mut self, group: u32) {
        self.bytes[GROUP_OFFSET..GROUP_OFFSET + 4].copy_from_slice(&group.to_le_bytes());
    }
}

/// Appends the page made of `clusters` (each from [`EncodedCluster::new`]) to `out`: the same
/// bytes as [`encode_page`] of the clusters they encode.
pub fn encoded_page(clusters: &[EncodedCluster], out: &mut Vec<u8>) -> Result<PageSummary, String> {
    if clusters.is_empty() {
        return Err("a page needs at least one cluster".into());
    }
    let start = out.len();
    let mut s = PageSummary { level_min: u8::MAX, ..Default::default() };
    for c in clusters {
        out.extend_from_slice(&c.bytes);
        s.decoded_len += c.decoded_len;
        s.triangles += c.triangles;
        s.level_min = s.level_min.min(c.level);
        s.level_max = s.level_max.max(c.level);
    }
    s.encoded_len = out.len() - start;
    Ok(s)
}

pub(crate) fn encode_page_with(
    clusters: &[PageCluster],
    out: &mut Vec<u8>,
    force: Option<PositionMode>,
) -> Result<PageSummary, String> {
    let encoded = clusters
        .iter()
        .enumerate()
        .map(|(i, c)| {
            EncodedCluster::with_mode(c.parts(), force).map_err(|m| format!("cluster {i} of the page: {m}"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    encoded_page(&encoded, out)
}

fn bits32(x: u32) -> u32 {
    32 - x.leading_zeros()
}

fn bits64(x: u64) -> u32 {
    64 - x.leading_zeros()
}

fn zigzag(d: i64) -> u64 {
    ((d << 1) ^ (d >> 63)) as u64
}

fn unzigzag(z: u64) -> i64 {
    ((z >> 1) as i64) ^ -((z & 1) as i64)
}

fn packed_len(count: usize, bits_each: u32) -> usize {
    (count * bits_each as usize).div_ceil(8)
}

/// Appends the encoding of `c` (in canonical form) to `out`: the header, the positions in the
/// smallest of their encodings, the triangles, the object ids. `rel` and `objects` are the
/// thread's reused buffers ([`Scratch`]).
fn encode_cluster(
    c: ClusterParts<'_>,
    out: &mut Vec<u8>,
    force: Option<PositionMode>,
    rel: &mut Vec<[u32; 3]>,
    objects: &mut Vec<u32>,
) -> Result<(), String> {
    let plan = PositionPlan::new(c, force, rel)?;
    let multi = distinct_objects(c.objects, objects);
    put_cluster_header(c, &plan, multi, out);
    plan.put_positions(c.positions, rel, out)?;
    put_triangles(c.indices, out)?;
    put_objects(c.objects, objects, multi, out);
    Ok(())
}

/// How a cluster's positions will be written: the encoding picked and what it needs.
struct PositionPlan {
    mode: PositionMode,
    /// The origin stored in the header: the first vertex for deltas, else the minimum corner.
    origin: [u32; 3],
    /// Bits per axis of the offsets from the minimum corner ([`PositionMode::Packed`]).
    packed_w: [u32; 3],
    /// Bits per axis of the zigzag deltas ([`PositionMode::Delta`]).
    delta_w: [u32; 3],
    /// meshoptimizer's encoding of the offsets, when it was a candidate.
    meshopt_bytes: Option<Vec<u8>>,
}

impl PositionPlan {
    /// Sizes every candidate position encoding (or only the forced one) and picks the smallest
    /// (ties: the lower mode number). Leaves the offsets from the minimum corner in `rel`.
    fn new(
        c: ClusterParts<'_>,
        force: Option<PositionMode>,
        rel: &mut Vec<[u32; 3]>,
    ) -> Result<PositionPlan, String> {
        let v = c.positions.len();
        let (min, max) = grid_bounds(c.positions);
        let packed_w: [u32; 3] = std::array::from_fn(|a| bits32(max[a] - min[a]));
        let packed_size = 3 + packed_len(v, packed_w.iter().sum());
        let delta_w = delta_widths(c.positions);
        let delta_size = 3 + packed_len(v.saturating_sub(1), delta_w.iter().sum());
        rel.clear();
        rel.extend(c.positions.iter().map(|p| [p[0] - min[0], p[1] - min[1], p[2] - min[2]]));
        // Compression level 0 of the vertex codec: on the 10^7-triangle plant it cut the build's CPU
        // time by ~10% (20.9 -> 18.7 user-seconds) for a store 1.3% larger than level 2 (115.2 vs
        // 113.8 MB); the decoder reads every level.
        let meshopt_bytes = match force {
            None | Some(PositionMode::Meshopt) if v > 0 => Some(
                meshopt::encode_vertex_buffer_level(rel, 0, Some(1))
                    .map_err(|e| format!("meshopt: {e:?}"))?,
            ),
            _ => None,
        };
        let meshopt_size = meshopt_bytes.as_ref().map(|b| varint_len(b.len() as u32) + b.len());
        let mode = force.unwrap_or_else(|| smallest_mode(v, packed_size, delta_size, meshopt_size));
        let mode = if v == 0 { PositionMode::Packed } else { mode };
        let origin = if mode == PositionMode::Delta { c.positions[0] } else { min };
        Ok(PositionPlan { mode, origin, packed_w, delta_w, meshopt_bytes })
    }

    /// Appends the position block in the planned encoding; `rel` holds the offsets from the
    /// minimum corner.
    fn put_positions(
        self,
        positions: &[[u32; 3]],
        rel: &[[u32; 3]],
        out: &mut Vec<u8>,
    ) -> Result<(), String> {
        let PositionPlan { mode, packed_w, delta_w, meshopt_bytes, .. } = self;
        match mode {
            PositionMode::Packed => {
                out.extend(packed_w.iter().map(|&w| w as u8));
                let mut bw = BitWriter::new(out);
                for p in rel.iter() {
                    for a in 0..3 {
                        bw.put(p[a] as u64, packed_w[a]);
                    }
                }
                bw.finish();
            }
            PositionMode::Delta => {
                out.extend(delta_w.iter().map(|&w| w as u8));
                let mut bw = BitWriter::new(out);
                for w in positions.windows(2) {
                    for a in 0..3 {
                        bw.put(zigzag(w[1][a] as i64 - w[0][a] as i64), delta_w[a]);
                    }
                }
                bw.finish();
            }
            PositionMode::Meshopt => {
                let b = meshopt_bytes.ok_or("meshopt vertex encoding missing")?;
                put_varint(out, b.len() as u32);
                out.extend_from_slice(&b);
            }
        }
        Ok(())
    }
}

/// The inclusive grid box of `positions`; all zeros for no positions.
fn grid_bounds(positions: &[[u32; 3]]) -> ([u32; 3], [u32; 3]) {
    let mut min = [u32::MAX; 3];
    let mut max = [0u32; 3];
    for p in positions {
        for a in 0..3 {
            min[a] = min[a].min(p[a]);
            max[a] = max[a].max(p[a]);
        }
    }
    if positions.is_empty() {
        min = [0; 3];
    }
    (min, max)
}

/// Bits per axis of the zigzag deltas from each vertex to the next.
fn delta_widths(positions: &[[u32; 3]]) -> [u32; 3] {
    let mut delta_w = [0u32; 3];
    for w in positions.windows(2) {
        for a in 0..3 {
            delta_w[a] = delta_w[a].max(bits64(zigzag(w[1][a] as i64 - w[0][a] as i64)));
        }
    }
    delta_w
}

/// The position encoding with the fewest bytes for `v` vertices; ties go to the lower mode
/// number.
fn smallest_mode(
    v: usize,
    packed_size: usize,
    delta_size: usize,
    meshopt_size: Option<usize>,
) -> PositionMode {
    let mut best = (packed_size, PositionMode::Packed);
    if delta_size < best.0 && v > 0 {
        best = (delta_size, PositionMode::Delta);
    }
    if let Some(m) = meshopt_size.filter(|&m| m < best.0) {
        best = (m, PositionMode::Meshopt);
    }
    best.1
}

/// Replaces `distinct` with the sorted distinct ids of `objects`; true when there are several.
fn distinct_objects(objects: &[u32], distinct: &mut Vec<u32>) -> bool {
    distinct.clear();
    distinct.extend_from_slice(objects);
    distinct.sort_unstable();
    distinct.dedup();
    distinct.len() > 1
}

/// Appends the fixed [`CLUSTER_HEADER_LEN`]-byte header: counts, level, modes, group, self
/// error and sphere, position origin.
fn put_cluster_header(c: ClusterParts<'_>, plan: &PositionPlan, multi: bool, out: &mut Vec<u8>) {
    out.push(c.triangle_count() as u8);
    out.push(c.positions.len() as u8);
    out.push(c.level);
    out.push(plan.mode as u8 | if multi { MULTI_OBJECT } else { 0 });
    out.extend_from_slice(&c.group.to_le_bytes());
    out.extend_from_slice(&c.self_error.to_le_bytes());
    for x in c.self_sphere {
        out.extend_from_slice(&x.to_le_bytes());
    }
    for x in plan.origin {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

/// Appends the triangles through meshoptimizer's meshlet codec, after their length.
fn put_triangles(indices: &[u8], out: &mut Vec<u8>) -> Result<(), String> {
    let tri = meshopt::encode_meshlet(meshopt::Meshlet { vertices: &[], triangles: indices })
        .map_err(|e| format!("meshopt: {e:?}"))?;
    if tri.len() < 16 {
        return Err(format!("meshlet codec produced {} bytes, expected at least 16", tri.len()));
    }
    put_varint(out, tri.len() as u32);
    out.extend_from_slice(&tri);
    Ok(())
}

/// Appends the object ids: one varint for a single object, else the sorted id table (as gaps)
/// and a bit-packed slot per triangle. `distinct` is from [`distinct_objects`].
fn put_objects(objects: &[u32], distinct: &[u32], multi: bool, out: &mut Vec<u8>) {
    if !multi {
        put_varint(out, distinct[0]);
        return;
    }
    put_varint(out, distinct.len() as u32);
    put_varint(out, distinct[0]);
    for w in distinct.windows(2) {
        put_varint(out, w[1] - w[0] - 1);
    }
    let width = bits32(distinct.len() as u32 - 1);
    let mut bw = BitWriter::new(out);
    for o in objects {
        // `distinct` holds every id of `objects`, so the search succeeds.
        let k = distinct.binary_search(o).unwrap_or(0);
        bw.put(k as u64, width);
    }
    bw.finish();
}
/// Decodes a page of `cluster_count` clusters. `bytes` must be exactly the page's bytes.
pub fn decode_page(bytes: &[u8], cluster_count: usize) -> Result<Vec<PageCluster>, CodecError> {
    decode_page_with_trees(bytes, cluster_count, false).map(|(clusters, _)| clusters)
}

/// [`decode_page`] of a page whose clusters are each followed by a ray-tracing tree when
/// `trees` (a store with [`crate::format::HEADER_RT_TREES`]); returns the trees too, one per
/// cluster (none when not `trees`).
pub fn decode_page_with_trees(
    bytes: &[u8],
    cluster_count: usize,
    trees: bool,
) -> Result<(Vec<PageCluster>, Vec<RtTree>), CodecError> {
    // Each cluster takes at least MIN_CLUSTER_BYTES: this bounds the allocation.
    if cluster_count.saturating_mul(MIN_CLUSTER_BYTES) > bytes.len() {
        return Err(CodecError::new(
            0,
            format!("{cluster_count} clusters cannot fit in {} bytes", bytes.len()),
        ));
    }
    let mut clusters = Vec::with_capacity(cluster_count);
    let mut rt = Vec::with_capacity(if trees { cluster_count } else { 0 });
    let mut pos = 0usize;
    for k in 0..cluster_count {
        let in_cluster = |e: CodecError| CodecError { msg: format!("cluster {k}: {}", e.msg), ..e };
        let (c, next) = decode_cluster(bytes, pos).map_err(in_cluster)?;
        pos = next;
        if trees {
            let (tree, next) = crate::rt::decode(bytes, pos, c.triangle_count()).map_err(in_cluster)?;
            rt.push(tree);
            pos = next;
        }
        clusters.push(c);
    }
    if pos != bytes.len() {
        return Err(CodecError::new(pos, format!("{} bytes after the last cluster", bytes.len() - pos)));
    }
    Ok((clusters, rt))
}

struct Cursor<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], CodecError> {
        match self.pos.checked_add(n).filter(|&e| e <= self.bytes.len()) {
            Some(end) => {
                let s = &self.bytes[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => Err(CodecError::new(
                self.pos,
                format!("{n} bytes needed, {} left in the page", self.bytes.len() - self.pos),
            )),
        }
    }

    fn u8(&mut self) -> Result<u8, CodecError> {
        Ok(self.take(1)?[0])
    }

    fn u32(&mut self) -> Result<u32, CodecError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn f32(&mut self) -> Result<f32, CodecError> {
        self.u32().map(f32::from_bits)
    }

    fn varint(&mut self) -> Result<u32, CodecError> {
        let at = self.pos;
        let mut v: u64 = 0;
        for i in 0..5 {
            let b = self.u8()?;
            v |= ((b & 0x7f) as u64) << (7 * i);
            if b & 0x80 == 0 {
                return u32::try_from(v).map_err(|_| CodecError::new(at, "varint overflows u32"));
            }
        }
        Err(CodecError::new(at, "varint longer than 5 bytes"))
    }
}

/// Decodes the cluster that starts at byte `start` of the page; returns it and the byte after
/// it. Every step checks what it reads before it uses it.
fn decode_cluster(bytes: &[u8], start: usize) -> Result<(PageCluster, usize), CodecError> {
    let mut r = Cursor { bytes, pos: start };
    let head = ClusterHead::read(&mut r)?;
    let positions = decode_positions(&mut r, &head)?;
    let indices = decode_triangles(&mut r, head.triangles, head.vertices)?;
    let objects = decode_objects(&mut r, head.modes & MULTI_OBJECT != 0, head.triangles)?;
    let ClusterHead { level, group, self_error, self_sphere, .. } = head;
    Ok((PageCluster { positions, indices, objects, self_error, self_sphere, group, level }, r.pos))
}

/// The fixed header of an encoded cluster, checked.
struct ClusterHead {
    /// Byte of the page where the cluster starts (error offsets are relative to it).
    start: usize,
    triangles: usize,
    vertices: usize,
    level: u8,
    /// The position mode and the [`MULTI_OBJECT`] bit.
    modes: u8,
    group: u32,
    self_error: f32,
    self_sphere: [f32; 4],
    origin: [u32; 3],
}

impl ClusterHead {
    /// Reads the header at the cursor: counts within the codec's limits, known mode bits, a
    /// finite self error ≥ 0 and a valid self sphere.
    #[inline]
    fn read(r: &mut Cursor<'_>) -> Result<ClusterHead, CodecError> {
        let start = r.pos;
        let t = r.u8()? as usize;
        let v = r.u8()? as usize;
        if t == 0 || t > MAX_TRIANGLES {
            return Err(CodecError::new(start, format!("{t} triangles, expected 1..={MAX_TRIANGLES}")));
        }
        let level = r.u8()?;
        let modes = r.u8()?;
        if modes & !(POS_MODE_MASK | MULTI_OBJECT) != 0 {
            return Err(CodecError::new(start + 3, format!("unknown mode bits {modes:#x}")));
        }
        let group = r.u32()?;
        let self_error = r.f32()?;
        let self_sphere = [r.f32()?, r.f32()?, r.f32()?, r.f32()?];
        if !(self_error.is_finite() && self_error >= 0.0) {
            return Err(CodecError::new(start + 8, format!("self error {self_error} is not finite and ≥ 0")));
        }
        if self_sphere.iter().any(|x| !x.is_finite()) || self_sphere[3] < 0.0 {
            return Err(CodecError::new(start + 12, format!("invalid self sphere {self_sphere:?}")));
        }
        let origin = [r.u32()?, r.u32()?, r.u32()?];
        let (triangles, vertices) = (t, v);
        Ok(ClusterHead { start, triangles, vertices, level, modes, group, self_error, self_sphere, origin })
    }
}

/// The position block, in the encoding the header's mode names.
#[inline]
fn decode_positions(r: &mut Cursor<'_>, head: &ClusterHead) -> Result<Vec<[u32; 3]>, CodecError> {
    match head.modes & POS_MODE_MASK {
        0 => decode_bit_packed(r, head, false),
        1 => decode_bit_packed(r, head, true),
        2 => decode_vertex_codec(r, head),
        m => Err(CodecError::new(head.start + 3, format!("unknown position mode {m}"))),
    }
}

/// Positions bit-packed as offsets from the origin ([`PositionMode::Packed`]) or, with `delta`,
/// as zigzag deltas from the previous vertex after the origin as the first vertex
/// ([`PositionMode::Delta`]).
#[inline]
fn decode_bit_packed(
    r: &mut Cursor<'_>,
    head: &ClusterHead,
    delta: bool,
) -> Result<Vec<[u32; 3]>, CodecError> {
    let (v, origin, pos_at) = (head.vertices, head.origin, r.pos);
    let mut positions = Vec::with_capacity(v);
    let w = r.take(3)?;
    let w = [w[0] as u32, w[1] as u32, w[2] as u32];
    let limit = if delta { 33 } else { 32 };
    if w.iter().any(|&x| x > limit) {
        return Err(CodecError::new(pos_at, format!("position bit widths {w:?} exceed {limit}")));
    }
    let count = if delta { v.saturating_sub(1) } else { v };
    let data = r.take(packed_len(count, w.iter().sum()))?;
    let mut br = BitReader::new(data);
    if delta && v > 0 {
        positions.push(origin);
    }
    for _ in 0..count {
        let mut p = [0u32; 3];
        for a in 0..3 {
            let x = br.get(w[a]);
            let value = if delta {
                positions.last().map_or(0, |q: &[u32; 3]| q[a] as i64) + unzigzag(x)
            } else {
                origin[a] as i64 + x as i64
            };
            p[a] = u32::try_from(value).map_err(|_| outside_grid(pos_at))?;
        }
        positions.push(p);
    }
    Ok(positions)
}

/// Positions through meshoptimizer's vertex codec, as offsets from the origin
/// ([`PositionMode::Meshopt`]).
#[inline]
fn decode_vertex_codec(r: &mut Cursor<'_>, head: &ClusterHead) -> Result<Vec<[u32; 3]>, CodecError> {
    let (v, origin, pos_at) = (head.vertices, head.origin, r.pos);
    let mut positions = Vec::with_capacity(v);
    let len = r.varint()? as usize;
    let data = r.take(len)?;
    if v == 0 {
        return Err(CodecError::new(pos_at, "vertex codec used for a cluster without vertices"));
    }
    let rel: Vec<[u32; 3]> = meshopt::decode_vertex_buffer(data, v)
        .map_err(|e| CodecError::new(pos_at, format!("vertex codec: {e:?}")))?;
    for q in rel {
        let mut p = [0u32; 3];
        for a in 0..3 {
            p[a] = origin[a].checked_add(q[a]).ok_or_else(|| outside_grid(pos_at))?;
        }
        positions.push(p);
    }
    Ok(positions)
}

/// The error of a decoded position beyond the `u32` grid (the position block starts at `at`).
fn outside_grid(at: usize) -> CodecError {
    CodecError::new(at, "vertex position outside the u32 grid")
}

/// The `t` triangles through meshoptimizer's meshlet codec, each index below `v`, each
/// triangle rotated to its canonical rotation.
#[inline]
fn decode_triangles(r: &mut Cursor<'_>, t: usize, v: usize) -> Result<Vec<u8>, CodecError> {
    let idx_at = r.pos;
    let len = r.varint()? as usize;
    let data = r.take(len)?;
    // meshopt_decodeMeshlet asserts that the buffer holds codes (+ control) + gap ≥ 16 bytes.
    if len < 16.max(t.div_ceil(2)) {
        return Err(CodecError::new(
            idx_at,
            format!("{len}-byte triangle block is too short for {t} triangles"),
        ));
    }
    let (_, mut indices) = meshopt::decode_meshlet(data, 0, t)
        .map_err(|e| CodecError::new(idx_at, format!("meshlet codec: {e:?}")))?;
    if indices.len() != 3 * t {
        return Err(CodecError::new(idx_at, "meshlet codec returned the wrong number of indices"));
    }
    if let Some(i) = indices.iter().find(|&&i| i as usize >= v) {
        return Err(CodecError::new(idx_at, format!("index {i} out of range ({v} vertices)")));
    }
    rotate_triangles(&mut indices);
    Ok(indices)
}

/// The object id of each of the `t` triangles: one id for them all, or (`multi`) a table of
/// 2..=t distinct ids and a bit-packed slot of it per triangle.
#[inline]
fn decode_objects(r: &mut Cursor<'_>, multi: bool, t: usize) -> Result<Vec<u32>, CodecError> {
    if !multi {
        return Ok(vec![r.varint()?; t]);
    }
    let obj_at = r.pos;
    let n = r.varint()? as usize;
    if n < 2 || n > t {
        return Err(CodecError::new(obj_at, format!("{n} distinct objects for {t} triangles")));
    }
    let table = decode_object_table(r, n)?;
    let width = bits32(n as u32 - 1);
    let data = r.take(packed_len(t, width))?;
    let mut br = BitReader::new(data);
    let mut objects = Vec::with_capacity(t);
    for _ in 0..t {
        let k = br.get(width) as usize;
        objects
            .push(*table.get(k).ok_or_else(|| CodecError::new(obj_at, format!("object slot {k} of {n}")))?);
    }
    Ok(objects)
}

/// The `n` increasing distinct object ids, stored as the first id and then each gap less one.
#[inline]
fn decode_object_table(r: &mut Cursor<'_>, n: usize) -> Result<Vec<u32>, CodecError> {
    let mut table = Vec::with_capacity(n);
    table.push(r.varint()?);
    for _ in 1..n {
        let at = r.pos;
        let d = r.varint()?;
        let prev = table.last().copied().unwrap_or(0);
        let next = prev.checked_add(d).and_then(|x| x.checked_add(1));
        table.push(next.ok_or_else(|| CodecError::new(at, "object id overflows u32"))?);
    }
    Ok(table)
}
fn varint_len(v: u32) -> usize {
    (bits32(v).max(1) as usize).div_ceil(7)
}

fn put_varint(out: &mut Vec<u8>, mut v: u32) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

/// LSB-first bit packing; values are at most 33 bits wide.
struct BitWriter<'a> {
    out: &'a mut Vec<u8>,
    acc: u64,
    n: u32,
}

impl<'a> BitWriter<'a> {
    fn new(out: &'a mut Vec<u8>) -> Self {
        BitWriter { out, acc: 0, n: 0 }
    }

    fn put(&mut self, v: u64, width: u32) {
        debug_assert!(width <= 33 && (width == 64 || v >> width == 0));
        self.acc |= v << self.n;
        self.n += width;
        while self.n >= 8 {
            self.out.push(self.acc as u8);
            self.acc >>= 8;
            self.n -= 8;
        }
    }

    fn finish(self) {
        if self.n > 0 {
            self.out.push(self.acc as u8);
        }
    }
}

/// Reads what [`BitWriter`] wrote; the caller sized `bytes` for every read (missing bytes read
/// as zero).
struct BitReader<'a> {
    bytes: &'a [u8],
    pos: usize,
    acc: u64,
    n: u32,
}

impl<'a> BitReader<'a> {
    fn new(bytes: &'a [u8]) -> Self {
        BitReader { bytes, pos: 0, acc: 0, n: 0 }
    }

    fn get(&mut self, width: u32) -> u64 {
        if width == 0 {
            return 0;
        }
        while self.n < width {
            let b = self.bytes.get(self.pos).copied().unwrap_or(0);
            self.pos += 1;
            self.acc |= (b as u64) << self.n;
            self.n += 8;
        }
        let v = self.acc & ((1u64 << width) - 1);
        self.acc >>= width;
        self.n -= width;
        v
    }
}

#[cfg(test)]
mod tests;
