//! The files a plan's jobs hand over: the prepared state, and each shard's built cells.
//!
//! Both are postcard-encoded (serde), behind a magic and a version; every cell record carries
//! a CRC-32C, so a damaged or truncated file on a shared file system is an error naming the
//! file, never a wrong store. A shard's cells go to `cells-K.bin` (records back to back) and its
//! index to `cells-K.idx` (each cell's offset and length), both written under temporary names and
//! renamed into place when the shard is complete.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::{de::DeserializeOwned, Deserialize, Serialize};
use tw_store::EncodedCluster;

use crate::cell_pass::BuiltCell;
use crate::error::BuildError;
use crate::hlod::HlodNode;
use crate::hlod_jobs::HlodBuilt;
use crate::seams::SeamTable;
use crate::types::LodDag;

/// The first bytes of every plan file, then a u32 version.
const MAGIC: &[u8; 8] = b"TWPLAN\0\x01";
/// Bumped whenever a record's layout changes: an older plan is refused, not misread.
const VERSION: u32 = 1;

/// Writes `value` to `path` atomically: a temporary file beside it, synced, then renamed.
pub(crate) fn write_value<T: Serialize>(path: &Path, value: &T) -> Result<(), BuildError> {
    let bytes = postcard::to_stdvec(value)
        .map_err(|e| BuildError::Internal(format!("encoding {}: {e}", path.display())))?;
    let tmp = temporary_name(path);
    let write = || -> std::io::Result<()> {
        let mut f = File::create(&tmp)?;
        f.write_all(MAGIC)?;
        f.write_all(&VERSION.to_le_bytes())?;
        f.write_all(&seal(&bytes))?;
        f.write_all(&bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    };
    write().map_err(|e| {
        drop(std::fs::remove_file(&tmp));
        BuildError::io(path, e)
    })
}

/// Reads what [`write_value`] wrote.
pub(crate) fn read_value<T: DeserializeOwned>(path: &Path) -> Result<T, BuildError> {
    let bytes = std::fs::read(path).map_err(|e| BuildError::io(path, e))?;
    let corrupt = |message: String| BuildError::Corrupt { path: path.to_path_buf(), message };
    let body = check_header(&bytes).map_err(corrupt)?;
    let payload = unseal(body).ok_or_else(|| {
        corrupt("checksum mismatch: the file is damaged or truncated; run the job that wrote it again".into())
    })?;
    postcard::from_bytes(payload).map_err(|e| corrupt(format!("cannot decode: {e}")))
}

/// What precedes a record's payload: its CRC-32C.
fn seal(payload: &[u8]) -> [u8; 4] {
    tw_store::format::checksum(payload).to_le_bytes()
}

/// The payload of a record (a [`seal`], then the payload), if its checksum holds.
fn unseal(record: &[u8]) -> Option<&[u8]> {
    let (sum, payload) = record.split_at_checked(4)?;
    (sum == seal(payload)).then_some(payload)
}

/// The bytes after a plan file's magic and version, or why the file is not one of ours.
fn check_header(bytes: &[u8]) -> Result<&[u8], String> {
    if bytes.len() < MAGIC.len() + 4 || &bytes[..MAGIC.len()] != MAGIC {
        return Err("not a terawalk build plan file".into());
    }
    let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if version != VERSION {
        return Err(format!(
            "plan file version {version}, this terawalk reads {VERSION}: write the plan again with this terawalk"
        ));
    }
    Ok(&bytes[12..])
}

/// `path` with `.tmp` added: where a file is written before it is renamed into place.
pub(crate) fn temporary_name(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".tmp");
    PathBuf::from(name)
}

/// An encoded cluster as the files hold it.
#[derive(Serialize, Deserialize)]
struct ClusterWire {
    bytes: Vec<u8>,
    decoded_len: u64,
    triangles: u64,
    level: u8,
}

/// One built cell as the files hold it.
#[derive(Serialize, Deserialize)]
struct CellWire {
    cell: u32,
    dag: LodDag,
    encoded: Vec<ClusterWire>,
    duplicates: u64,
}

/// One HLOD node as the files hold it (`crate::hlod_jobs::HlodBuilt`, its groups named by
/// provisional ids: `crate::provisional`).
#[derive(Serialize, Deserialize)]
struct NodeWire {
    node: u32,
    hl: HlodNode,
    encoded: Vec<ClusterWire>,
    seams: SeamTable,
    range: (u32, u32),
}

/// Where each cell and HLOD node of a shard lies in its `.bin` file.
#[derive(Serialize, Deserialize, Default)]
struct ShardIndex {
    /// (cell, offset, length), in cell order.
    cells: Vec<(u32, u64, u64)>,
    /// (hierarchy node, offset, length), in the order they were built.
    nodes: Vec<(u32, u64, u64)>,
}

fn to_wire(encoded: Vec<EncodedCluster>) -> Vec<ClusterWire> {
    encoded
        .into_iter()
        .map(|c| ClusterWire {
            bytes: c.bytes,
            decoded_len: c.decoded_len as u64,
            triangles: c.triangles as u64,
            level: c.level,
        })
        .collect()
}

fn from_wire(wire: Vec<ClusterWire>) -> Vec<EncodedCluster> {
    wire.into_iter()
        .map(|c| EncodedCluster {
            bytes: c.bytes,
            decoded_len: c.decoded_len as usize,
            triangles: c.triangles as usize,
            level: c.level,
        })
        .collect()
}

/// The files of shard `shard` in the plan's `cells` folder.
pub(crate) fn shard_paths(cells_dir: &Path, shard: u32) -> (PathBuf, PathBuf) {
    let stem = cells_dir.join(format!("cells-{shard:03}"));
    (stem.with_extension("bin"), stem.with_extension("idx"))
}

/// Writes a shard's built cells, in order.
pub(crate) struct ShardWriter {
    bin: PathBuf,
    idx: PathBuf,
    out: BufWriter<File>,
    offset: u64,
    index: ShardIndex,
}

impl ShardWriter {
    pub fn create(cells_dir: &Path, shard: u32) -> Result<ShardWriter, BuildError> {
        std::fs::create_dir_all(cells_dir).map_err(|e| BuildError::io(cells_dir, e))?;
        let (bin, idx) = shard_paths(cells_dir, shard);
        let tmp = temporary_name(&bin);
        let file = File::create(&tmp).map_err(|e| BuildError::io(&tmp, e))?;
        let mut out = BufWriter::with_capacity(4 << 20, file);
        out.write_all(MAGIC)
            .and_then(|()| out.write_all(&VERSION.to_le_bytes()))
            .map_err(|e| BuildError::io(&tmp, e))?;
        Ok(ShardWriter { bin, idx, out, offset: 12, index: ShardIndex::default() })
    }

    /// Appends cell `cell`.
    pub fn append(&mut self, cell: u32, built: BuiltCell) -> Result<(), BuildError> {
        let encoded = built.encoded.map_err(|m| BuildError::Internal(format!("cell {cell}: {m}")))?;
        let wire = CellWire { cell, dag: built.dag, encoded: to_wire(encoded), duplicates: built.duplicates };
        let at = self.record(&wire, &format!("cell {cell}"))?;
        self.index.cells.push((cell, at.0, at.1));
        Ok(())
    }

    /// Appends an HLOD node built from the shard's cells.
    pub fn append_node(&mut self, built: HlodBuilt) -> Result<(), BuildError> {
        let HlodBuilt { node, hl, encoded, seams, range } = built;
        let encoded = encoded.map_err(|m| BuildError::Internal(format!("hierarchy node {node}: {m}")))?;
        let wire = NodeWire { node, hl, encoded: to_wire(encoded), seams, range };
        let at = self.record(&wire, &format!("hierarchy node {node}"))?;
        self.index.nodes.push((node, at.0, at.1));
        Ok(())
    }

    /// Writes one record (a checksum, then the encoded value); returns its offset and length.
    fn record<T: Serialize>(&mut self, value: &T, what: &str) -> Result<(u64, u64), BuildError> {
        let bytes = postcard::to_stdvec(value).map_err(|e| BuildError::Internal(format!("{what}: {e}")))?;
        let tmp = temporary_name(&self.bin);
        self.out
            .write_all(&seal(&bytes))
            .and_then(|()| self.out.write_all(&bytes))
            .map_err(|e| BuildError::io(&tmp, e))?;
        let at = (self.offset, bytes.len() as u64 + 4);
        self.offset += at.1;
        Ok(at)
    }

    /// Syncs the cells and renames them into place, then the index (the index is what marks the
    /// shard complete to readers).
    pub fn finish(self) -> Result<(), BuildError> {
        let tmp = temporary_name(&self.bin);
        let file = self.out.into_inner().map_err(|e| BuildError::io(&tmp, e.into_error()))?;
        file.sync_all()
            .and_then(|()| std::fs::rename(&tmp, &self.bin))
            .map_err(|e| BuildError::io(&tmp, e))?;
        write_value(&self.idx, &self.index)
    }
}

/// Every shard's built cells, read back by cell on any thread (the pack job).
pub(crate) struct CellRecords {
    files: Vec<(PathBuf, File)>,
    /// Per cell: (shard, offset, length); cells absent from every shard are `None`.
    cells: Vec<Option<(u32, u64, u64)>>,
    /// The HLOD nodes the shards built: node → (shard, offset, length).
    nodes: std::collections::HashMap<u32, (u32, u64, u64)>,
}

impl CellRecords {
    /// Opens the `shards` shards' files in `cells_dir` for `cell_count` cells; every cell must
    /// be in exactly one shard.
    pub fn open(cells_dir: &Path, shards: u32, cell_count: usize) -> Result<CellRecords, BuildError> {
        let mut files = Vec::with_capacity(shards as usize);
        let mut cells = vec![None; cell_count];
        let mut nodes = std::collections::HashMap::new();
        for shard in 0..shards {
            let (bin, idx) = shard_paths(cells_dir, shard);
            let index: ShardIndex = read_value(&idx)?;
            let file = File::open(&bin).map_err(|e| BuildError::io(&bin, e))?;
            let mut header = [0u8; 12];
            tw_core::direct_io::read_exact_at(&file, &mut header, 0).map_err(|e| BuildError::io(&bin, e))?;
            check_header(&header).map_err(|message| BuildError::Corrupt { path: bin.clone(), message })?;
            for (cell, offset, len) in index.cells {
                let slot = cells.get_mut(cell as usize).ok_or_else(|| BuildError::Corrupt {
                    path: idx.clone(),
                    message: format!("cell {cell} is not in this plan ({cell_count} cells)"),
                })?;
                if slot.replace((shard, offset, len)).is_some() {
                    let message = format!("cell {cell} is in two shards");
                    return Err(BuildError::Corrupt { path: idx.clone(), message });
                }
            }
            for (node, offset, len) in index.nodes {
                if nodes.insert(node, (shard, offset, len)).is_some() {
                    let message = format!("hierarchy node {node} is in two shards");
                    return Err(BuildError::Corrupt { path: idx.clone(), message });
                }
            }
            files.push((bin, file));
        }
        if let Some(missing) = cells.iter().position(Option::is_none) {
            let message = format!("no shard has cell {missing}: a cells job did not finish");
            return Err(BuildError::Corrupt { path: cells_dir.to_path_buf(), message });
        }
        Ok(CellRecords { files, cells, nodes })
    }

    /// Whether a shard built HLOD node `node`.
    pub fn has_node(&self, node: u32) -> bool {
        self.nodes.contains_key(&node)
    }

    /// HLOD node `node`, as its shard built it.
    pub fn read_node(&self, node: u32) -> Result<HlodBuilt, BuildError> {
        let &(shard, offset, len) = self
            .nodes
            .get(&node)
            .ok_or_else(|| BuildError::Internal(format!("no shard built hierarchy node {node}")))?;
        let wire: NodeWire = self.record(shard, offset, len, &format!("hierarchy node {node}"))?;
        if wire.node != node {
            let (path, _) = &self.files[shard as usize];
            let message = format!("hierarchy node {} where the index says {node}", wire.node);
            return Err(BuildError::Corrupt { path: path.clone(), message });
        }
        let NodeWire { node, hl, encoded, seams, range } = wire;
        Ok(HlodBuilt { node, hl, encoded: Ok(from_wire(encoded)), seams, range })
    }

    /// Reads and checks one record.
    fn record<T: DeserializeOwned>(
        &self,
        shard: u32,
        offset: u64,
        len: u64,
        what: &str,
    ) -> Result<T, BuildError> {
        let (path, file) = &self.files[shard as usize];
        let corrupt = |message: String| BuildError::Corrupt { path: path.clone(), message };
        let mut bytes = vec![0u8; len as usize];
        tw_core::direct_io::read_exact_at(file, &mut bytes, offset).map_err(|e| BuildError::io(path, e))?;
        let payload = unseal(&bytes)
            .ok_or_else(|| corrupt(format!("{what}: checksum mismatch; run its cells job again")))?;
        postcard::from_bytes(payload).map_err(|e| corrupt(format!("{what}: {e}")))
    }

    /// Cell `cell`'s DAG and encoded clusters.
    pub fn read(&self, cell: u32) -> Result<BuiltCell, BuildError> {
        let (shard, offset, len) = self.cells[cell as usize].expect("checked when opened");
        let wire: CellWire = self.record(shard, offset, len, &format!("cell {cell}"))?;
        if wire.cell != cell {
            let (path, _) = &self.files[shard as usize];
            let message = format!("cell {} where the index says {cell}", wire.cell);
            return Err(BuildError::Corrupt { path: path.clone(), message });
        }
        Ok(BuiltCell { dag: wire.dag, encoded: Ok(from_wire(wire.encoded)), duplicates: wire.duplicates })
    }
}
