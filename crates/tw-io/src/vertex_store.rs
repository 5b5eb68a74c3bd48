//! An append-only array of fixed-size vertex records that stays within a memory budget.
//!
//! OBJ and PLY faces refer to vertices defined earlier in the file, possibly gigabytes earlier.
//! A [`VertexStore`] keeps records in blocks; while the resident blocks fit in the budget nothing
//! touches the disk. Beyond it, the least recently used full blocks are written once to an
//! anonymous temporary file (deleted by the OS when dropped) and read back on demand with
//! positioned reads. Faces in real files mostly refer to recent vertices, so an LRU over blocks
//! keeps the hit rate high. Peak memory is the budget plus one block, whatever the file size.

use std::fs::File;
use std::io;
use std::path::PathBuf;

use tw_core::Rgba8;

/// A fixed-size record that can be written to and read from bytes.
pub trait Record: Copy + Default {
    const SIZE: usize;
    fn write_to(&self, out: &mut [u8]);
    fn read_from(bytes: &[u8]) -> Self;
}

impl Record for [f64; 3] {
    const SIZE: usize = 24;
    fn write_to(&self, out: &mut [u8]) {
        for (i, v) in self.iter().enumerate() {
            out[i * 8..i * 8 + 8].copy_from_slice(&v.to_le_bytes());
        }
    }
    fn read_from(b: &[u8]) -> Self {
        let f = |i: usize| f64::from_le_bytes(b[i * 8..i * 8 + 8].try_into().unwrap());
        [f(0), f(1), f(2)]
    }
}

impl Record for [f32; 3] {
    const SIZE: usize = 12;
    fn write_to(&self, out: &mut [u8]) {
        for (i, v) in self.iter().enumerate() {
            out[i * 4..i * 4 + 4].copy_from_slice(&v.to_le_bytes());
        }
    }
    fn read_from(b: &[u8]) -> Self {
        let f = |i: usize| f32::from_le_bytes(b[i * 4..i * 4 + 4].try_into().unwrap());
        [f(0), f(1), f(2)]
    }
}

impl Record for Rgba8 {
    const SIZE: usize = 4;
    fn write_to(&self, out: &mut [u8]) {
        out[..4].copy_from_slice(&self.0);
    }
    fn read_from(b: &[u8]) -> Self {
        Rgba8(b[..4].try_into().unwrap())
    }
}

/// Records per block: 4096 (96 KiB of f64 positions).
pub const BLOCK_SHIFT: u32 = 12;
const BLOCK_LEN: usize = 1 << BLOCK_SHIFT;

struct Block<T> {
    /// The records while resident.
    data: Option<Box<[T]>>,
    /// True once written to the spill file (blocks are immutable once full, so once is enough).
    on_disk: bool,
    last_use: u64,
    /// Index in [`VertexStore::resident`] while resident.
    slot: usize,
}

/// Statistics of a store, for logs and tests.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StoreStats {
    pub len: u64,
    pub blocks_spilled: u64,
    pub blocks_loaded: u64,
    pub peak_resident_bytes: u64,
}

/// An append-only vector of `T` with bounded memory. See the module documentation.
pub struct VertexStore<T: Record> {
    blocks: Vec<Block<T>>,
    len: u64,
    max_resident: usize,
    /// The resident blocks, in no order (eviction looks at these only, not at every block).
    resident: Vec<usize>,
    tick: u64,
    spill_dir: Option<PathBuf>,
    spill: Option<File>,
    scratch: Vec<u8>,
    stats: StoreStats,
}

impl<T: Record> VertexStore<T> {
    /// A store that keeps at most `budget_bytes` of records in memory (at least two blocks), and
    /// spills to a temporary file in `spill_dir` (the system's temp dir when `None`).
    pub fn new(budget_bytes: usize, spill_dir: Option<PathBuf>) -> Self {
        let block_bytes = BLOCK_LEN * std::mem::size_of::<T>().max(1);
        VertexStore {
            blocks: Vec::new(),
            len: 0,
            max_resident: (budget_bytes / block_bytes).max(2),
            resident: Vec::new(),
            tick: 0,
            spill_dir,
            spill: None,
            scratch: Vec::new(),
            stats: StoreStats::default(),
        }
    }

    pub fn len(&self) -> u64 {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    pub fn stats(&self) -> StoreStats {
        StoreStats { len: self.len, ..self.stats }
    }

    /// Appends a record; fails only when spilling to disk fails.
    pub fn push(&mut self, value: T) -> io::Result<()> {
        let slot = (self.len & (BLOCK_LEN as u64 - 1)) as usize;
        if slot == 0 {
            self.make_room()?;
            self.tick += 1;
            self.blocks.push(Block {
                data: Some(vec![T::default(); BLOCK_LEN].into_boxed_slice()),
                on_disk: false,
                last_use: self.tick,
                slot: self.resident.len(),
            });
            self.resident.push(self.blocks.len() - 1);
            self.note_peak();
        }
        let block = self.blocks.last_mut().expect("a block was just ensured");
        block.data.as_mut().expect("the last block is always resident")[slot] = value;
        self.len += 1;
        Ok(())
    }

    /// The record at `index`; `index < len()` is the caller's to check (it panics otherwise).
    pub fn get(&mut self, index: u64) -> io::Result<T> {
        assert!(index < self.len, "vertex {index} out of range {}", self.len);
        let b = (index >> BLOCK_SHIFT) as usize;
        let slot = (index & (BLOCK_LEN as u64 - 1)) as usize;
        self.tick += 1;
        if self.blocks[b].data.is_none() {
            self.load(b)?;
        }
        let block = &mut self.blocks[b];
        block.last_use = self.tick;
        Ok(block.data.as_ref().expect("loaded above")[slot])
    }

    /// Most blocks the store keeps in memory at once (at least two).
    pub fn max_resident_blocks(&self) -> usize {
        self.max_resident
    }

    /// Makes block `b` (the records `b << BLOCK_SHIFT ..`) resident and most recently used,
    /// reading it back from the spill file if needed, so that [`VertexStore::get_resident`] can
    /// read it from shared references. Blocks touched since the last push stay resident for as
    /// long as fewer than [`VertexStore::max_resident_blocks`] of them have been touched: each
    /// load evicts the least recently used block.
    pub fn touch(&mut self, b: usize) -> io::Result<()> {
        assert!(b < self.blocks.len(), "block {b} out of range {}", self.blocks.len());
        self.tick += 1;
        if self.blocks[b].data.is_none() {
            self.load(b)?;
        }
        self.blocks[b].last_use = self.tick;
        Ok(())
    }

    /// The record at `index`, whose block must be resident ([`VertexStore::touch`]); panics
    /// otherwise, or when `index >= len()`. Does not update the LRU order.
    #[inline]
    pub fn get_resident(&self, index: u64) -> T {
        assert!(index < self.len, "vertex {index} out of range {}", self.len);
        let b = (index >> BLOCK_SHIFT) as usize;
        let slot = (index & (BLOCK_LEN as u64 - 1)) as usize;
        self.blocks[b].data.as_ref().expect("the block was touched")[slot]
    }

    fn note_peak(&mut self) {
        let bytes = (self.resident.len() * BLOCK_LEN * std::mem::size_of::<T>()) as u64;
        self.stats.peak_resident_bytes = self.stats.peak_resident_bytes.max(bytes);
    }

    /// Evicts least recently used blocks until one more fits.
    fn make_room(&mut self) -> io::Result<()> {
        while self.resident.len() >= self.max_resident {
            // The last block may still be filling (a spilled copy would go stale): keep it
            // unless it is full.
            let last = self.blocks.len().saturating_sub(1);
            let last_full = self.len.is_multiple_of(BLOCK_LEN as u64);
            let victim = self
                .resident
                .iter()
                .filter(|&&i| i != last || last_full)
                .min_by_key(|&&i| self.blocks[i].last_use)
                .copied();
            let Some(v) = victim else { break };
            self.evict(v)?;
        }
        Ok(())
    }

    fn spill_file(&mut self) -> io::Result<&File> {
        if self.spill.is_none() {
            let f = match &self.spill_dir {
                Some(d) => tempfile::tempfile_in(d)?,
                None => tempfile::tempfile()?,
            };
            self.spill = Some(f);
        }
        Ok(self.spill.as_ref().expect("created above"))
    }

    fn evict(&mut self, b: usize) -> io::Result<()> {
        let data = self.blocks[b].data.take().expect("victims are resident");
        if !self.blocks[b].on_disk {
            self.scratch.resize(BLOCK_LEN * T::SIZE, 0);
            for (i, r) in data.iter().enumerate() {
                r.write_to(&mut self.scratch[i * T::SIZE..(i + 1) * T::SIZE]);
            }
            let offset = (b * BLOCK_LEN * T::SIZE) as u64;
            let scratch = std::mem::take(&mut self.scratch);
            let file = self.spill_file()?;
            // Spilled vertices count against the process's disk limits like the build's
            // working files (a small .gz can hold billions of vertices).
            let result = tw_core::disk_space::check(file, scratch.len() as u64)
                .and_then(|()| tw_core::direct_io::write_all_at(file, &scratch, offset));
            self.scratch = scratch;
            result?;
            self.blocks[b].on_disk = true;
            self.stats.blocks_spilled += 1;
        }
        let slot = self.blocks[b].slot;
        self.resident.swap_remove(slot);
        if let Some(&moved) = self.resident.get(slot) {
            self.blocks[moved].slot = slot;
        }
        Ok(())
    }

    fn load(&mut self, b: usize) -> io::Result<()> {
        self.make_room()?;
        self.scratch.resize(BLOCK_LEN * T::SIZE, 0);
        let offset = (b * BLOCK_LEN * T::SIZE) as u64;
        let mut scratch = std::mem::take(&mut self.scratch);
        let spill = self.spill.as_ref().expect("a non-resident block was spilled");
        let result = tw_core::direct_io::read_exact_at(spill, &mut scratch, offset);
        self.scratch = scratch;
        result?;
        let data: Box<[T]> =
            (0..BLOCK_LEN).map(|i| T::read_from(&self.scratch[i * T::SIZE..(i + 1) * T::SIZE])).collect();
        self.blocks[b].data = Some(data);
        self.blocks[b].slot = self.resident.len();
        self.resident.push(b);
        self.stats.blocks_loaded += 1;
        self.note_peak();
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_store_never_spills() {
        let mut s = VertexStore::<[f64; 3]>::new(1 << 20, None);
        for i in 0..1000 {
            s.push([i as f64, 0.0, 1.0]).unwrap();
        }
        assert_eq!(s.get(999).unwrap(), [999.0, 0.0, 1.0]);
        assert_eq!(s.stats().blocks_spilled, 0);
    }

    #[test]
    fn large_store_spills_and_reads_back_every_record() {
        // Budget of two blocks, ten blocks of data.
        let n = 10 * BLOCK_LEN as u64 + 17;
        let mut s = VertexStore::<[f64; 3]>::new(0, None);
        for i in 0..n {
            s.push([i as f64, -(i as f64), 0.5]).unwrap();
        }
        assert!(s.stats().blocks_spilled >= 8);
        // Forward, backward and strided access all see the right values.
        for i in (0..n).chain((0..n).rev()).chain((0..n).step_by(4099)) {
            assert_eq!(s.get(i).unwrap(), [i as f64, -(i as f64), 0.5]);
        }
        let st = s.stats();
        assert!(st.peak_resident_bytes <= 3 * (BLOCK_LEN * 24) as u64, "{st:?}");
        assert!(st.blocks_loaded > 0);
    }

    #[test]
    fn interleaved_push_and_get_keep_the_filling_block() {
        let mut s = VertexStore::<Rgba8>::new(0, None);
        for i in 0..(5 * BLOCK_LEN as u32) {
            s.push(Rgba8(i.to_le_bytes())).unwrap();
            if i % 1000 == 999 {
                assert_eq!(s.get(0).unwrap(), Rgba8([0, 0, 0, 0]));
                assert_eq!(s.get(i as u64).unwrap(), Rgba8(i.to_le_bytes()));
            }
        }
    }

    #[test]
    fn touched_blocks_stay_resident_for_shared_reads() {
        // Budget of two blocks, six blocks of data: touching one block at a time (fewer than
        // the two the store keeps) makes each readable through a shared reference.
        let n = 6 * BLOCK_LEN as u64 - 5;
        let mut s = VertexStore::<[f32; 3]>::new(0, None);
        for i in 0..n {
            s.push([i as f32, 1.0, 2.0]).unwrap();
        }
        assert_eq!(s.max_resident_blocks(), 2);
        for b in [0, 5, 2, 2, 4, 1, 3, 0] {
            s.touch(b).unwrap();
            let first = (b << BLOCK_SHIFT) as u64;
            let last = (first + BLOCK_LEN as u64 - 1).min(n - 1);
            let shared = &s;
            assert_eq!(shared.get_resident(first), [first as f32, 1.0, 2.0]);
            assert_eq!(shared.get_resident(last), [last as f32, 1.0, 2.0]);
        }
        assert!(s.stats().blocks_loaded >= 5);
    }
}
