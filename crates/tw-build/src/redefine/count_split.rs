//! Pass D: the count split of the cells still above `max_cell_triangles`.

use super::assign::{Assigner, CountSplit, KdNode, Route, LEAF};
use super::geometry::FBox;
use super::pieces::Pieces;
use super::scan::{joined_spans, map_records};
use super::{CellInfo, RedefineParams, RedefineReport};
use crate::error::BuildError;
use crate::ingest::{Ingested, WorkTri, RECORD_BYTES};
use crate::workio::SUB_CHUNK;

/// Whether a leaf of the kd plan below `root` satisfies `f`.
fn plan_has_leaf(kd: &[KdNode], root: u32, f: impl Fn(u32) -> bool) -> bool {
    let mut stack = vec![root];
    while let Some(n) = stack.pop() {
        let k = kd[n as usize];
        if k.axis == LEAF {
            if f(k.a) {
                return true;
            }
        } else {
            stack.extend([k.a, k.b]);
        }
    }
    false
}

/// One block of consecutive working-file triangles of a cell being cut: how many of them are
/// the cell's, and their box.
#[derive(Clone, Copy, Debug)]
struct BlockStats {
    block: u64,
    count: u64,
    bounds: FBox,
}

/// Pass D: cuts every cell above `max_cell_triangles` into parts of at most that many, by
/// count rather than by space: its triangles in working-file order, in runs of whole blocks of
/// `block` consecutive file positions (at most half the cap, so a part closes above half the
/// cap and a cell of `n` makes at most about `2 n / max` parts; with the parts' target the
/// cell's count over the fewest parts that fit, they come out nearly even). This is what is
/// left when space cannot split a cell: triangles whose centroids coincide (a part inserted
/// many times at one spot) have no plane between them, and for them the file order is as good
/// an order as any; it also takes the overshoot of plans made from samples.
///
/// Deterministic: blocks are fixed by file position, counts and boxes (minima and maxima) do not
/// depend on the order of accumulation. Only the file spans of objects that reach a cut cell
/// are read; nothing is read when no cell is above the cap (the cells are then unchanged).
/// Part 0 keeps the cell's id; the other parts get new ids after the last cell.
pub(super) fn split_by_count(
    ing: &Ingested,
    params: &RedefineParams,
    pieces: &Pieces,
    piece_object: &[u32],
    assign: &mut Assigner,
    mut cells: Vec<CellInfo>,
    report: &mut RedefineReport,
) -> Result<Vec<CellInfo>, BuildError> {
    let max = params.max_cell_triangles;
    // Slot of each cut cell in `blocks`, or u32::MAX.
    let mut slot = vec![u32::MAX; cells.len()];
    let mut cut = 0u32;
    for (c, info) in cells.iter().enumerate() {
        if info.triangles > max {
            slot[c] = cut;
            cut += 1;
        }
    }
    if cut == 0 {
        return Ok(cells);
    }
    report.count_split_cells = cut as u64;
    let block = (max / 2).clamp(1, SUB_CHUNK as u64);
    let objects = objects_reaching(assign, pieces, piece_object, &slot);
    let joined = joined_spans(&objects, |o| ing.objects[o as usize].span.clone());
    let read: u64 = joined.iter().map(|r| r.end - r.start).sum();
    tracing::debug!(cells = cut, spans = joined.len(), triangles = read, "pass D reads");
    let blocks = read_blocks(ing, assign, &joined, &slot, cut as usize, block)?;
    let mut count_split = vec![u32::MAX; cells.len()];
    let mut splits = Vec::with_capacity(cut as usize);
    for c in 0..slot.len() {
        let s = slot[c];
        if s == u32::MAX {
            continue;
        }
        let list = &blocks[s as usize];
        let total: u64 = list.iter().map(|e| e.count).sum();
        if total != cells[c].triangles {
            return Err(BuildError::Corrupt {
                path: ing.work.path().to_path_buf(),
                message: format!("cell {c}: {total} triangles read again, {} counted", cells[c].triangles),
            });
        }
        let split = cut_into_runs(ing, &mut cells, c, list, block, total.div_ceil(total.div_ceil(max)));
        count_split[c] = splits.len() as u32;
        splits.push(split);
    }
    count_split.resize(cells.len(), u32::MAX);
    assign.count_split = count_split;
    assign.splits = splits;
    Ok(cells)
}

/// The objects (sorted, each once) with a piece that may reach a cut cell (`slot[c]` not
/// `u32::MAX`): placed in one whole, or cut by a plan with such a leaf.
fn objects_reaching(assign: &Assigner, pieces: &Pieces, piece_object: &[u32], slot: &[u32]) -> Vec<u32> {
    let reaches = |c: u32| slot.get(c as usize).is_some_and(|&s| s != u32::MAX);
    let mut objects: Vec<u32> = (0..pieces.count.len())
        .filter(|&q| pieces.count[q] > 0)
        .filter(|&q| match assign.piece_cell[q] {
            Route::Fixed(c) => reaches(c),
            Route::Plan(root) => plan_has_leaf(&assign.plan2, root, reaches),
        })
        .map(|q| piece_object[q])
        .collect();
    objects.sort_unstable();
    objects.dedup();
    objects
}

/// Reads `joined` and returns, per cut cell (by slot, of `cut`), the count and box of its
/// triangles in each block of `block` consecutive working-file triangles that has some, in file
/// order (the spans are sorted and read in order).
fn read_blocks(
    ing: &Ingested,
    assign: &Assigner,
    joined: &[std::ops::Range<u64>],
    slot: &[u32],
    cut: usize,
    block: u64,
) -> Result<Vec<Vec<BlockStats>>, BuildError> {
    let mut blocks: Vec<Vec<BlockStats>> = vec![Vec::new(); cut];
    let mut ids = Vec::new();
    ing.work.scan_ranges_raw(joined, |first, bytes| {
        map_records(first, bytes, &mut ids, |t, i| assign.cell(t, i));
        for (k, &c) in ids.iter().enumerate() {
            let Some(&s) = slot.get(c as usize).filter(|&&s| s != u32::MAX) else { continue };
            let b = (first + k as u64) / block;
            let list = &mut blocks[s as usize];
            if list.last().is_none_or(|e| e.block != b) {
                list.push(BlockStats { block: b, count: 0, bounds: FBox::EMPTY });
            }
            if let Some(e) = list.last_mut() {
                e.count += 1;
                for v in WorkTri::decode(&bytes[k * RECORD_BYTES..(k + 1) * RECORD_BYTES]).p {
                    e.bounds.grow(v);
                }
            }
        }
        Ok(())
    })?;
    Ok(blocks)
}

/// Cuts cell `c`, whose triangles are in the blocks `list`, into runs of whole blocks of about
/// `target` triangles (a run closes before the block that would take it above `target`); part
/// 0 keeps `c`'s id, the others are appended to `cells`.
fn cut_into_runs(
    ing: &Ingested,
    cells: &mut Vec<CellInfo>,
    c: usize,
    list: &[BlockStats],
    block: u64,
    target: u64,
) -> CountSplit {
    let mut split = CountSplit::default();
    let (mut count, mut bounds) = (0u64, FBox::EMPTY);
    for (j, e) in list.iter().enumerate() {
        if count > 0 && count + e.count > target {
            split.starts.push(e.block * block);
            let info = CellInfo { triangles: count, bounds: bounds.to_grid(&ing.work, &ing.grid) };
            split.cells.push(part_cell(cells, c, split.cells.len(), info));
            (count, bounds) = (0, FBox::EMPTY);
        }
        count += e.count;
        bounds.union(&e.bounds);
        if j + 1 == list.len() {
            let info = CellInfo { triangles: count, bounds: bounds.to_grid(&ing.work, &ing.grid) };
            split.cells.push(part_cell(cells, c, split.cells.len(), info));
        }
    }
    split
}

/// The cell id of part `j` of cut cell `c`, with its figures: part 0 replaces `c`, the others
/// are appended.
fn part_cell(cells: &mut Vec<CellInfo>, c: usize, j: usize, info: CellInfo) -> u32 {
    if j == 0 {
        cells[c] = info;
        c as u32
    } else {
        cells.push(info);
        cells.len() as u32 - 1
    }
}
