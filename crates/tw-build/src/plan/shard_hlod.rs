//! A `cells` job's HLOD: the hierarchy nodes whose cells all lie in the job's shard, built as
//! the shard's cells come in, as phase 5's consumer builds them in a plain build
//! (`crate::pipeline`, `LodState`), and written to the shard's file for `pack`.
//!
//! The roots handed up carry provisional group ids (`crate::provisional`), so a node built here
//! is the node a plain build makes, byte for byte, once `pack` resolves its ids; nodes that
//! span shards are left to `pack`, which builds them from the roots of the shards' top nodes.

use std::collections::{HashMap, VecDeque};
use std::sync::Arc;

use crate::error::BuildError;
use crate::hierarchy::{Hierarchy, TreeIndex};
use crate::hlod::Roots;
use crate::hlod_jobs::{HlodInput, HlodJob, HlodJobs};
use crate::pipeline::HLOD_LAG;
use crate::seams::SeamTable;
use crate::types::LodDag;

use super::records::ShardWriter;

/// The shard's HLOD in progress.
pub(crate) struct ShardHlod<'a> {
    hierarchy: &'a Hierarchy,
    index: TreeIndex,
    /// The shard's cells, `first..last + 1`.
    cells: (u32, u32),
    /// Roots (and their seams) of completed subtrees whose parent is not started yet.
    roots: HashMap<u32, (Roots, SeamTable)>,
    jobs: &'a HlodJobs<'a>,
    /// Nodes started, with the cell after which each is taken (as the plain build's consumer
    /// does, so the pool has time to build them).
    pending: VecDeque<(usize, Arc<HlodJob>)>,
    pub nodes: u64,
}

impl<'a> ShardHlod<'a> {
    pub fn new(hierarchy: &'a Hierarchy, cells: (u32, u32), jobs: &'a HlodJobs<'a>) -> ShardHlod<'a> {
        let index = TreeIndex::new(hierarchy);
        ShardHlod { hierarchy, index, cells, roots: HashMap::new(), jobs, pending: VecDeque::new(), nodes: 0 }
    }

    /// Whether `pack` reads the roots of cell `i`'s leaf: when its parent spans shards (a node
    /// `pack` builds from them).
    pub fn pack_needs_roots_of_cell(&self, i: u32) -> bool {
        self.pack_needs_roots(self.index.leaf_of_cell[i as usize])
    }

    fn pack_needs_roots(&self, node: u32) -> bool {
        let parent = self.index.parent[node as usize];
        parent != u32::MAX && !self.inside(parent)
    }

    /// Whether `node`'s cells all lie in the shard.
    fn inside(&self, node: u32) -> bool {
        let range = self.index.cell_range[node as usize];
        self.cells.0 <= range.0 && range.1 <= self.cells.1
    }

    /// Cell `i` built (`seams`: its bucket's): its roots up, its parent started if complete.
    pub fn add_cell(&mut self, i: u32, dag: &LodDag, seams: &SeamTable) -> Result<(), BuildError> {
        let leaf = self.index.leaf_of_cell[i as usize];
        let range = self.index.cell_range[leaf as usize];
        let handed_up = self.index.subtree_roots(self.hierarchy, leaf, dag, seams, range)?;
        self.roots.insert(leaf, handed_up);
        self.start_parent(leaf, i as usize + HLOD_LAG);
        Ok(())
    }

    /// Starts the HLOD of `node`'s parent when the parent lies in the shard and all its
    /// children are complete.
    fn start_parent(&mut self, node: u32, due: usize) {
        let parent = self.index.parent[node as usize];
        if parent == u32::MAX {
            return;
        }
        let range = self.index.cell_range[parent as usize];
        let children = self.hierarchy.nodes[parent as usize].children();
        if !self.inside(parent) || children.clone().any(|c| !self.roots.contains_key(&(c as u32))) {
            return;
        }
        let (children, child_seams): (Vec<Roots>, Vec<SeamTable>) =
            children.map(|c| self.roots.remove(&(c as u32)).expect("checked above")).unzip();
        let job = self.jobs.start(HlodInput { node: parent, children, child_seams, range });
        self.pending.push_back((due, job));
    }

    /// Writes the started nodes due once cell `cell` was taken (`None`: all, and the ancestors
    /// they complete), handing their roots up.
    pub fn write_due(&mut self, cell: Option<usize>, out: &mut ShardWriter) -> Result<(), BuildError> {
        while let Some((due, _)) = self.pending.front() {
            if cell.is_some_and(|c| *due > c) {
                return Ok(());
            }
            let (_, job) = self.pending.pop_front().expect("checked above");
            let built = self.jobs.result(&job).map_err(BuildError::Internal)?;
            let node = built.node;
            let handed_up =
                self.index.subtree_roots(self.hierarchy, node, &built.hl.dag, &built.seams, built.range)?;
            let mut built = *built;
            strip_geometry(&mut built.hl.dag, self.pack_needs_roots(node));
            out.append_node(built)?;
            self.nodes += 1;
            self.roots.insert(node, handed_up);
            self.start_parent(node, cell.unwrap_or(0) + HLOD_LAG);
        }
        Ok(())
    }
}

/// Drops the geometry `pack` does not read from a DAG before it is written: `pack` emits groups
/// from the encoded clusters and reads a DAG's groups, its clusters' levels and sources; it
/// needs the geometry of the root clusters only when `keep_roots` (the node's parent spans
/// shards and `pack` builds it from them). Cuts the shards' files to about a third.
pub(crate) fn strip_geometry(dag: &mut LodDag, keep_roots: bool) {
    let LodDag { clusters, groups } = dag;
    for c in clusters.iter_mut() {
        if keep_roots && groups[c.group as usize].error == f32::INFINITY {
            continue;
        }
        c.positions = Vec::new();
        c.indices = Vec::new();
        c.objects = Vec::new();
    }
}
