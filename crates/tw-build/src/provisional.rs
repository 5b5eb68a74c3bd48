//! Provisional group ids: how an HLOD node names the groups it replaces before their scene ids
//! are known.
//!
//! A group's scene id is its place in the store's group table, which only the ordered consumer
//! of phase 5 assigns (`crate::pipeline`). An HLOD node needs its children's root groups only as
//! names to carry through (`crate::hlod`: `replaced`, and its clusters' `refined_from`), so the
//! roots are handed to it under provisional ids — the child's slot among the node's children
//! and the group's index in the child's DAG — and the consumer resolves them when it emits the
//! node, from the children's first scene ids. A node can then be built where the scene ids are
//! not known at all: in a build plan's `cells` job, on another machine (`crate::plan`).

use crate::error::BuildError;

/// Bits of a provisional id that hold the group's index in its node's DAG.
const INDEX_BITS: u32 = 24;
const INDEX_MASK: u32 = (1 << INDEX_BITS) - 1;

/// The provisional id of group 0 of the child in slot `slot` (its index among its parent's
/// children); a node with no parent (the root) uses slot 0. Fails for a DAG with more groups
/// than the ids can name (2^24; a cell of at most 65,536 triangles has a few thousand).
pub fn base(slot: u32, groups: usize) -> Result<u32, BuildError> {
    if slot >= 1 << (32 - INDEX_BITS) || groups > INDEX_MASK as usize {
        return Err(BuildError::Internal(format!(
            "{groups} groups in child slot {slot}: too many for provisional ids"
        )));
    }
    Ok(slot << INDEX_BITS)
}

/// The scene id of provisional id `id`, given the scene id of each child's group 0.
pub fn resolve(id: u32, child_bases: &[u32]) -> Result<u32, BuildError> {
    let base = child_bases
        .get((id >> INDEX_BITS) as usize)
        .ok_or_else(|| BuildError::Internal(format!("provisional group id {id:#x} names no child")))?;
    Ok(base + (id & INDEX_MASK))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_resolve_to_each_childs_groups() {
        let bases = [1000, 17];
        let a = base(0, 5).unwrap();
        let b = base(1, 300).unwrap();
        assert_eq!(resolve(a + 4, &bases).unwrap(), 1004);
        assert_eq!(resolve(b + 299, &bases).unwrap(), 316);
        assert!(resolve(base(2, 1).unwrap(), &bases).is_err());
        assert!(base(0, 1 << 24).is_err() && base(256, 1).is_err());
    }
}
