//! The resident GPU cluster pool: decoded store clusters ([`tw_store::PageCluster`]) uploaded
//! once into one pooled GPU buffer and kept there across frames under a GPU-memory budget, with
//! LRU eviction of clusters not drawn in the current frame. This is docs/DESIGN.md's D4
//! ("out-of-core by pages": a budget, LRU eviction) applied to the GPU copy of the clusters the
//! runtime selected, the "streaming to the GPU" that the first renderer left for later.
//!
//! Layout. One buffer (usage VERTEX | INDEX) is the *arena*, allocated in units of 24 bytes
//! (one [`PoolVertex`]). A cluster takes one contiguous range: its vertices (24 bytes each:
//! scene-space position f32×3, object id u32, pool slot u32, packed normal u32), then its
//! triangles' u32 indices (12 bytes a triangle, rounded up to whole units). A draw is
//! `draw_indexed` with `base_vertex` = the range's first unit and `first_index` = 6 × the unit
//! after the vertices. Store vertices are shared by triangles of different objects at most
//! rarely (HLOD merges); such a vertex is duplicated per object so that every vertex of a
//! triangle carries the triangle's object id. Shading is flat and computed per vertex
//! (draw.wgsl): each triangle's provoking vertex — the one `flat` varyings come from: the first
//! on Vulkan (WGSL's rule), the last on wgpu's GL backend (measured on llvmpipe) — carries the
//! triangle's normal, so no two triangles may share a provoking vertex. Each triangle is
//! rotated (keeping its winding) so that a corner no other triangle provokes with takes that
//! place, or provokes with a copy of that corner. Triangle order is the store's, so the
//! primitive index of a draw is the triangle's index in its cluster (the item buffer uses it).
//! The slot is a small dense id of the resident cluster; a storage buffer indexed by slot holds
//! (page, index in page, LOD level, frame-local cluster number) for the debug colourings and
//! the item buffer.
//!
//! Budget. The arena grows by doubling (copying the old contents) up to the budget (at least
//! [`MIN_BUDGET`]) and never beyond it, so resident geometry bytes ≤ budget (while one
//! doubling copies, the old arena lives beside the new one: a transient peak of 1.5 × the
//! budget at the last step; the old one is freed as soon as the copy is done); the slot table
//! (16 bytes per resident cluster) and the per-frame indirect-argument buffer come on top and
//! are not counted. When a cluster does not fit, the least recently drawn cluster that was not
//! drawn in the current frame is evicted (first-fit allocation with coalescing of free ranges,
//! so fragmentation may evict more than the bytes needed). When every resident cluster was
//! drawn in this frame, [`ClusterPool::ensure`] reports [`Ensure::Full`]: the renderer then draws
//! what it has (a *batch*), releases the batch's clusters for eviction and continues, with the
//! depth and colour targets loaded, not cleared. A frame whose selection exceeds the budget is
//! therefore drawn correctly in several batches (same order of draws, so the same image),
//! re-uploading part of its geometry every frame.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use bytemuck::{Pod, Zeroable};
use tw_store::PageCluster;

/// The smallest budget: room for the largest possible cluster (128 triangles, 384 vertices
/// after duplication) with margin.
pub const MIN_BUDGET: u64 = 64 << 10;

/// Bytes per arena unit (one vertex).
pub const UNIT: u64 = std::mem::size_of::<PoolVertex>() as u64;

/// The first arena capacity (bytes), doubled as needed.
const INITIAL_ARENA: u64 = 4 << 20;

/// One pooled vertex.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct PoolVertex {
    pub position: [f32; 3],
    pub object: u32,
    pub slot: u32,
    /// Unit normal of the triangle this vertex is the first (provoking) vertex of, 10 bits a
    /// component ([`pack_normal`]); 0 for a vertex that provokes no triangle.
    pub normal: u32,
}

/// Packs the direction of `n` as three 10-bit signed-normalized components (x in the low
/// bits); a zero vector (a degenerate triangle) packs to 0, which unpacks to (0, 0, 0).
pub fn pack_normal(n: glam::Vec3) -> u32 {
    let n = n.normalize_or_zero();
    let q = |c: f32| ((c.clamp(-1.0, 1.0) * 511.0).round() as i32 as u32) & 0x3ff;
    q(n.x) | (q(n.y) << 10) | (q(n.z) << 20)
}

/// Identifies a cluster in the pool: (page, index in page).
pub type PoolKey = (u32, u32);

/// Per-slot record in the slot storage buffer.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct SlotInfo {
    pub page: u32,
    pub index_in_page: u32,
    pub level: u32,
    /// 1 + the cluster's position in the list drawn into the item buffer (0 otherwise).
    pub item: u32,
    /// The cluster's cross-fade word ([`crate::dither`]; 0: drawn whole).
    pub fade: u32,
}

/// Arguments of one cluster's indexed draw (the layout of `DrawIndexedIndirectArgs`).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct DrawArgs {
    pub index_count: u32,
    pub instance_count: u32,
    pub first_index: u32,
    pub base_vertex: i32,
    pub first_instance: u32,
}

/// What the pool did in the current frame (since [`ClusterPool::begin_frame`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PoolStats {
    pub uploaded_clusters: u64,
    pub uploaded_bytes: u64,
    pub evicted_clusters: u64,
    pub evicted_bytes: u64,
    /// Geometry bytes resident at the end of the frame (≤ the budget).
    pub resident_bytes: u64,
    pub resident_clusters: u64,
    /// Size of the arena buffer (≤ the budget).
    pub arena_bytes: u64,
    /// Batches the frame's draws were split into (1 when the selection fits the budget).
    pub batches: u64,
    /// Triangles skipped because their indices were out of range (bad data).
    pub bad_triangles: u64,
}

/// First-fit allocator of ranges of units with coalescing of free neighbours.
#[derive(Clone, Debug, Default)]
pub struct RangeAllocator {
    /// Free ranges: start → length.
    free: BTreeMap<u64, u64>,
    capacity: u64,
}

impl RangeAllocator {
    pub fn new(capacity: u64) -> RangeAllocator {
        let mut a = RangeAllocator { free: BTreeMap::new(), capacity: 0 };
        a.grow(capacity);
        a
    }

    pub fn capacity(&self) -> u64 {
        self.capacity
    }

    pub fn free_units(&self) -> u64 {
        self.free.values().sum()
    }

    /// The start of a free range of `len` units (the lowest that fits), or `None`.
    pub fn alloc(&mut self, len: u64) -> Option<u64> {
        let (&start, &free_len) = self.free.iter().find(|(_, &l)| l >= len)?;
        self.free.remove(&start);
        if free_len > len {
            self.free.insert(start + len, free_len - len);
        }
        Some(start)
    }

    /// Returns `[start, start + len)`, merging it with free neighbours.
    pub fn release(&mut self, start: u64, len: u64) {
        let mut start = start;
        let mut len = len;
        if let Some((&prev, &plen)) = self.free.range(..start).next_back() {
            if prev + plen == start {
                self.free.remove(&prev);
                start = prev;
                len += plen;
            }
        }
        if let Some(&nlen) = self.free.get(&(start + len)) {
            self.free.remove(&(start + len));
            len += nlen;
        }
        self.free.insert(start, len);
    }

    /// Extends the capacity to `capacity` units (no-op when smaller).
    pub fn grow(&mut self, capacity: u64) {
        if capacity > self.capacity {
            let old = self.capacity;
            self.capacity = capacity;
            self.release(old, capacity - old);
        }
    }
}

struct Resident {
    slot: u32,
    start: u64,
    units: u64,
    args: DrawArgs,
    last_used: u64,
}

/// The outcome of [`ClusterPool::ensure`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ensure {
    /// Resident (uploaded now or earlier): draw with these arguments; `slot` is its slot.
    Ready { args: DrawArgs, slot: u32 },
    /// The cluster has no valid triangle: nothing to draw.
    Empty,
    /// No room without evicting a cluster drawn in this frame: draw the batch so far first.
    Full,
}

/// The pool's layout of one cluster (see the module documentation): vertices duplicated per
/// object and where needed for a provoking vertex of their own, each triangle's corners
/// rotated so that its provoking vertex carries its normal. Plain data, reused between
/// clusters.
pub struct ClusterLayout {
    pub vertices: Vec<PoolVertex>,
    pub indices: Vec<u32>,
    /// Per local vertex: (object, pooled index) of its first copy; further objects of the same
    /// vertex (rare) go through `remap_more`.
    remap: Vec<(u32, u32)>,
    remap_more: HashMap<(u8, u32), u32>,
    /// Per pooled vertex: whether it is the provoking vertex of a triangle already.
    provoking: Vec<bool>,
    /// The corner (0 or 2) the backend takes flat varyings from.
    provoking_at: usize,
}

impl ClusterLayout {
    /// `provoking_last`: see [`ClusterPool::new`].
    pub fn new(provoking_last: bool) -> ClusterLayout {
        ClusterLayout {
            vertices: Vec::new(),
            indices: Vec::new(),
            remap: vec![(0, u32::MAX); 256],
            remap_more: HashMap::new(),
            provoking: Vec::new(),
            provoking_at: if provoking_last { 2 } else { 0 },
        }
    }

    /// Lays `cluster` out (positions: grid coordinates × `grid_step`); returns the number of
    /// triangles skipped for an index beyond the vertices. `slot` of every vertex is 0.
    pub fn build(&mut self, cluster: &PageCluster, grid_step: f64) -> u64 {
        self.vertices.clear();
        self.indices.clear();
        self.remap.fill((0, u32::MAX));
        self.remap_more.clear();
        self.provoking.clear();
        let mut bad = 0;
        for (t, tri) in cluster.indices.chunks_exact(3).enumerate() {
            if tri.iter().any(|&i| i as usize >= cluster.positions.len()) {
                bad += 1;
                continue;
            }
            let object = cluster.objects.get(t).copied().unwrap_or(0);
            let mut corners = [0u32; 3];
            for (k, &i) in tri.iter().enumerate() {
                let next = self.vertices.len() as u32;
                let first = &mut self.remap[i as usize];
                let v = if first.1 == u32::MAX {
                    *first = (object, next);
                    next
                } else if first.0 == object {
                    first.1
                } else {
                    *self.remap_more.entry((i, object)).or_insert(next)
                };
                if v == next {
                    let g = cluster.positions[i as usize];
                    let position = g.map(|c| (c as f64 * grid_step) as f32);
                    self.vertices.push(PoolVertex { position, object, slot: 0, normal: 0 });
                    self.provoking.push(false);
                }
                corners[k] = v;
            }
            // The provoking vertex carries the triangle's normal: a corner that provokes no
            // other triangle, rotated into place (the winding is kept), else a copy.
            let at = self.provoking_at;
            match (0..3).find(|&k| !self.provoking[corners[k] as usize]) {
                Some(k) => corners.rotate_left((k + 3 - at) % 3),
                None => {
                    let copy = self.vertices[corners[at] as usize];
                    corners[at] = self.vertices.len() as u32;
                    self.vertices.push(copy);
                    self.provoking.push(false);
                }
            }
            self.provoking[corners[at] as usize] = true;
            let p = corners.map(|v| glam::Vec3::from(self.vertices[v as usize].position));
            self.vertices[corners[at] as usize].normal = pack_normal((p[1] - p[0]).cross(p[2] - p[0]));
            self.indices.extend_from_slice(&corners);
        }
        bad
    }
}

/// The pool; see the module documentation.
pub struct ClusterPool {
    budget: u64,
    arena: Option<wgpu::Buffer>,
    alloc: RangeAllocator,
    resident: HashMap<PoolKey, Resident>,
    /// (last frame used, key) of every resident cluster.
    lru: BTreeSet<(u64, PoolKey)>,
    free_slots: Vec<u32>,
    slot_count: u32,
    slot_buffer: wgpu::Buffer,
    slot_capacity: u32,
    /// The fade word each slot's record holds (what [`ClusterPool::set_fade`] last wrote), so
    /// that only changes are written.
    slot_fades: Vec<u32>,
    /// Bumped whenever a buffer the bind groups hold is replaced.
    pub generation: u64,
    frame: u64,
    stats: PoolStats,
    layout: ClusterLayout,
    bytes: Vec<u8>,
}

fn slot_buffer(device: &wgpu::Device, slots: u32) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("pool slots"),
        size: slots as u64 * std::mem::size_of::<SlotInfo>() as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

impl ClusterPool {
    /// A pool of at most `budget` bytes of geometry (raised to [`MIN_BUDGET`] and limited to
    /// the device's `max_buffer_size`).
    ///
    /// `provoking_last`: the backend takes flat varyings from a triangle's last vertex (wgpu's
    /// GL backend, measured on llvmpipe) instead of the first (WGSL's rule; Vulkan).
    pub fn new(device: &wgpu::Device, budget: u64, provoking_last: bool) -> ClusterPool {
        let budget = budget.max(MIN_BUDGET).min(device.limits().max_buffer_size) / UNIT * UNIT;
        ClusterPool {
            budget,
            arena: None,
            alloc: RangeAllocator::default(),
            resident: HashMap::new(),
            lru: BTreeSet::new(),
            free_slots: Vec::new(),
            slot_count: 0,
            slot_buffer: slot_buffer(device, 1024),
            slot_capacity: 1024,
            slot_fades: Vec::new(),
            generation: 0,
            // Frame 0 is "before any frame": a batch drawn before the first `begin_frame` (a
            // shadow map drawn first) is released to frame 0, which must exist.
            frame: 1,
            stats: PoolStats::default(),
            layout: ClusterLayout::new(provoking_last),
            bytes: Vec::new(),
        }
    }

    pub fn budget(&self) -> u64 {
        self.budget
    }

    /// Starts a frame: clusters ensured from now on count as drawn in it; resets the stats.
    pub fn begin_frame(&mut self) {
        self.frame += 1;
        self.stats = PoolStats { batches: 0, ..Default::default() };
        self.update_stats();
    }

    pub fn stats(&self) -> PoolStats {
        self.stats
    }

    fn update_stats(&mut self) {
        self.stats.resident_clusters = self.resident.len() as u64;
        self.stats.resident_bytes = (self.alloc.capacity() - self.alloc.free_units()) * UNIT;
        self.stats.arena_bytes = self.alloc.capacity() * UNIT;
    }

    pub fn note_batch(&mut self) {
        self.stats.batches += 1;
    }

    /// The arena (vertex and index buffer) and the slot table; `None` before the first upload.
    pub fn arena(&self) -> Option<&wgpu::Buffer> {
        self.arena.as_ref()
    }

    pub fn slot_buffer(&self) -> &wgpu::Buffer {
        &self.slot_buffer
    }

    pub fn is_resident(&self, key: PoolKey) -> bool {
        self.resident.contains_key(&key)
    }

    /// Makes the clusters in `keys` (drawn in a submitted batch) evictable again in this frame.
    pub fn release_batch(&mut self, keys: &[PoolKey]) {
        for k in keys {
            if let Some(r) = self.resident.get_mut(k) {
                if r.last_used == self.frame {
                    self.lru.remove(&(r.last_used, *k));
                    r.last_used = self.frame - 1;
                    self.lru.insert((r.last_used, *k));
                }
            }
        }
    }

    /// Writes `item` into the slot record of `slot` (see [`SlotInfo::item`]).
    pub fn set_item(&self, queue: &wgpu::Queue, slot: u32, item: u32) {
        let offset = slot as u64 * std::mem::size_of::<SlotInfo>() as u64 + 12;
        queue.write_buffer(&self.slot_buffer, offset, bytemuck::bytes_of(&item));
    }

    /// Writes the cross-fade word `fade` ([`crate::dither`]) into the slot record of `slot`,
    /// when it differs from the one there.
    pub fn set_fade(&mut self, queue: &wgpu::Queue, slot: u32, fade: u32) {
        let i = slot as usize;
        if self.slot_fades.len() <= i {
            self.slot_fades.resize(i + 1, 0);
        }
        if self.slot_fades[i] != fade {
            self.slot_fades[i] = fade;
            let offset = slot as u64 * std::mem::size_of::<SlotInfo>() as u64 + 16;
            queue.write_buffer(&self.slot_buffer, offset, bytemuck::bytes_of(&fade));
        }
    }

    /// Makes `cluster` resident (uploading it if needed) and marks it drawn in this frame.
    pub fn ensure(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        key: PoolKey,
        grid_step: f64,
        cluster: &PageCluster,
    ) -> Ensure {
        if let Some(r) = self.resident.get_mut(&key) {
            self.lru.remove(&(r.last_used, key));
            r.last_used = self.frame;
            self.lru.insert((self.frame, key));
            return Ensure::Ready { args: r.args, slot: r.slot };
        }
        // Build the cluster's vertices (duplicated per object) and indices.
        self.stats.bad_triangles += self.layout.build(cluster, grid_step);
        if self.layout.indices.is_empty() {
            return Ensure::Empty;
        }
        let nv = self.layout.vertices.len() as u64;
        let index_units = (self.layout.indices.len() as u64 * 4).div_ceil(UNIT);
        let units = nv + index_units;
        let start = loop {
            if let Some(s) = self.alloc.alloc(units) {
                break s;
            }
            let cap = self.alloc.capacity();
            let max = self.budget / UNIT;
            if cap < max {
                self.grow_arena(device, queue, next_capacity(cap, units, max));
                continue;
            }
            match self.lru.first().copied() {
                Some((used, victim)) if used < self.frame => self.evict(victim),
                _ => return Ensure::Full,
            }
        };
        // The slot is taken only now: evictions above free slots.
        let slot = match self.free_slots.pop() {
            Some(s) => s,
            None => {
                self.slot_count += 1;
                if self.slot_count > self.slot_capacity {
                    self.grow_slots(device, queue, self.slot_capacity * 2);
                }
                self.slot_count - 1
            }
        };
        for v in &mut self.layout.vertices {
            v.slot = slot;
        }
        let Some(arena) = &self.arena else { return Ensure::Full };
        // Vertices and indices are contiguous: one write.
        self.bytes.clear();
        self.bytes.extend_from_slice(bytemuck::cast_slice(&self.layout.vertices));
        self.bytes.extend_from_slice(bytemuck::cast_slice(&self.layout.indices));
        self.bytes.resize((units * UNIT) as usize, 0);
        queue.write_buffer(arena, start * UNIT, &self.bytes);
        let info =
            SlotInfo { page: key.0, index_in_page: key.1, level: cluster.level as u32, item: 0, fade: 0 };
        if let Some(f) = self.slot_fades.get_mut(slot as usize) {
            *f = 0;
        }
        queue.write_buffer(
            &self.slot_buffer,
            slot as u64 * std::mem::size_of::<SlotInfo>() as u64,
            bytemuck::bytes_of(&info),
        );
        let args = DrawArgs {
            index_count: self.layout.indices.len() as u32,
            instance_count: 1,
            first_index: ((start + nv) * (UNIT / 4)) as u32,
            base_vertex: start as i32,
            first_instance: 0,
        };
        self.resident.insert(key, Resident { slot, start, units, args, last_used: self.frame });
        self.lru.insert((self.frame, key));
        self.stats.uploaded_clusters += 1;
        self.stats.uploaded_bytes += units * UNIT;
        self.update_stats();
        Ensure::Ready { args, slot }
    }

    fn evict(&mut self, key: PoolKey) {
        if let Some(r) = self.resident.remove(&key) {
            self.lru.remove(&(r.last_used, key));
            self.alloc.release(r.start, r.units);
            self.free_slots.push(r.slot);
            self.stats.evicted_clusters += 1;
            self.stats.evicted_bytes += r.units * UNIT;
            self.update_stats();
        }
    }

    /// Drops every resident cluster (e.g. when the store changes).
    pub fn clear(&mut self) {
        let keys: Vec<PoolKey> = self.resident.keys().copied().collect();
        for k in keys {
            self.evict(k);
        }
        self.free_slots.clear();
        self.slot_count = 0;
    }

    fn grow_arena(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, units: u64) {
        let buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("cluster pool"),
            size: units * UNIT,
            usage: wgpu::BufferUsages::VERTEX
                | wgpu::BufferUsages::INDEX
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        if let Some(old) = self.arena.take() {
            let mut enc = device.create_command_encoder(&Default::default());
            enc.copy_buffer_to_buffer(&old, 0, &buffer, 0, old.size());
            queue.submit([enc.finish()]);
            // Free the old arena now, not at some later poll: several doublings in one frame
            // would otherwise keep every smaller arena alive at once (measured: 4 + … + 128 MiB
            // beside a 256 MiB arena). Dropped, not destroyed: a caller's encoder that is not
            // submitted yet may still draw from it, and keeps it alive until then. The wait
            // happens once per doubling, a few times a run.
            drop(old);
            let _ = device.poll(wgpu::PollType::wait_indefinitely());
        }
        self.arena = Some(buffer);
        self.alloc.grow(units);
        self.generation += 1;
        self.update_stats();
    }

    fn grow_slots(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, slots: u32) {
        let buffer = slot_buffer(device, slots);
        let mut enc = device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&self.slot_buffer, 0, &buffer, 0, self.slot_buffer.size());
        queue.submit([enc.finish()]);
        self.slot_buffer = buffer;
        self.slot_capacity = slots;
        self.generation += 1;
    }
}

/// The arena capacity (units) after `cap` when `needed` more units do not fit, under `max`
/// (the budget): double, but go straight to `max` when a doubling would leave less than
/// another doubling below it. Growing copies the old arena into the new, both alive at once,
/// so each step must be a real one: doubling from 4 MiB reached 255.99 MiB of a 256 MiB budget,
/// and the last step of a few bytes held two 256 MiB arenas (measured at 10^8 triangles,
/// `--occlusion none` on the fly-over: 1.55–1.62 GB peak RSS instead of ≤ 1.35 GB).
fn next_capacity(cap: u64, needed: u64, max: u64) -> u64 {
    let want = (cap * 2).max(INITIAL_ARENA / UNIT).max(cap + needed);
    if want.saturating_mul(2) > max {
        max
    } else {
        want
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arena_growth_never_holds_more_than_one_and_a_half_budgets() {
        for budget in [4u64 << 20, 5 << 20, 100 << 20, 256 << 20, 1000 << 20, 1 << 30] {
            let max = budget / UNIT;
            let mut cap = 0;
            let mut steps = 0;
            while cap < max {
                let next = next_capacity(cap, 1, max);
                assert!(next > cap && next <= max);
                // Old and new arenas alive during the copy.
                assert!((cap + next) * 2 <= max * 3, "{cap} + {next} beyond 1.5 × {max}");
                // A real step: at least a doubling, or the budget.
                assert!(next >= 2 * cap || next == max);
                cap = next;
                steps += 1;
            }
            assert!(steps <= 12, "{steps} steps to {budget} bytes");
        }
        // A cluster bigger than a doubling gets room at once.
        assert_eq!(next_capacity(200_000, 300_000, 1 << 24), 500_000);
    }

    #[test]
    fn allocator_first_fit_and_coalescing() {
        let mut a = RangeAllocator::new(100);
        assert_eq!(a.alloc(30), Some(0));
        assert_eq!(a.alloc(30), Some(30));
        assert_eq!(a.alloc(30), Some(60));
        assert_eq!(a.alloc(30), None);
        a.release(30, 30);
        assert_eq!(a.free_units(), 40);
        assert_eq!(a.alloc(35), None, "free space is fragmented: 30 + 10");
        a.release(0, 30);
        assert_eq!(a.alloc(55), Some(0), "0..60 coalesced");
        a.release(0, 55);
        a.release(60, 30);
        assert_eq!(a.free_units(), 100);
        assert_eq!(a.alloc(100), Some(0), "everything coalesced back");
        a.grow(150);
        assert_eq!(a.alloc(50), Some(100));
    }

    #[test]
    fn units_hold_whole_vertices_and_indices() {
        assert_eq!(UNIT, 24);
        assert_eq!(UNIT % 4, 0);
    }

    fn unpack_normal(p: u32) -> glam::Vec3 {
        let c = |s: u32| ((((p >> s) & 0x3ff) << 22) as i32 >> 22) as f32 / 511.0;
        glam::Vec3::new(c(0), c(10), c(20))
    }

    /// A fan of 6 triangles around one vertex (more triangles than vertices), two objects, a
    /// degenerate triangle and a bad index.
    fn fan() -> PageCluster {
        let mut positions = vec![[10u32, 10, 0]];
        positions.extend((0..6).map(|i| {
            let a = i as f64 * std::f64::consts::TAU / 6.0;
            [(10.0 + 5.0 * a.cos()).round() as u32, (10.0 + 5.0 * a.sin()).round() as u32, i % 2]
        }));
        let mut indices = Vec::new();
        for i in 0..6u8 {
            indices.extend_from_slice(&[0, 1 + i, 1 + (i + 1) % 6]);
        }
        indices.extend_from_slice(&[1, 1, 2, 0, 1, 9]);
        let objects = vec![3, 3, 3, 4, 4, 4, 3, 3];
        PageCluster { positions, indices, objects, ..Default::default() }
    }

    #[test]
    fn every_triangle_has_its_own_provoking_vertex_with_its_normal() {
        let c = fan();
        for provoking_last in [false, true] {
            let mut l = ClusterLayout::new(provoking_last);
            assert_eq!(l.build(&c, 0.5), 1, "the bad index is skipped");
            let at = if provoking_last { 2 } else { 0 };
            let tris: Vec<[u32; 3]> = l.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
            assert_eq!(tris.len(), 7);
            let mut seen = std::collections::HashSet::new();
            for (t, pooled) in tris.iter().enumerate() {
                assert!(seen.insert(pooled[at]), "triangle {t} shares its provoking vertex");
                // Same corners, same winding: a rotation of the store's triangle.
                let store: Vec<[f32; 3]> = c.indices[3 * t..3 * t + 3]
                    .iter()
                    .map(|&i| c.positions[i as usize].map(|g| g as f32 * 0.5))
                    .collect();
                let got: Vec<[f32; 3]> = pooled.iter().map(|&v| l.vertices[v as usize].position).collect();
                let rotations: Vec<Vec<[f32; 3]>> =
                    (0..3).map(|r| (0..3).map(|k| store[(k + r) % 3]).collect()).collect();
                assert!(rotations.contains(&got), "triangle {t}: {got:?} is not a rotation of {store:?}");
                for &v in pooled {
                    assert_eq!(l.vertices[v as usize].object, c.objects[t], "triangle {t}'s object");
                }
                let p = got.iter().map(|&q| glam::Vec3::from(q)).collect::<Vec<_>>();
                let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
                let stored = unpack_normal(l.vertices[pooled[at] as usize].normal);
                assert!((stored - n).length() < 0.01, "triangle {t}: normal {stored} != {n}");
            }
            // The degenerate triangle (two equal corners) has no direction.
            assert_eq!(l.vertices[tris[6][at] as usize].normal, 0);
        }
    }
}
