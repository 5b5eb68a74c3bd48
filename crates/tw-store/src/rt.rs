//! Stored ray-tracing trees (docs/FORMAT.md, "Ray-tracing trees"): the optional block that
//! follows every cluster of a store whose header has [`HEADER_RT_TREES`](crate::format::HEADER_RT_TREES).
//!
//! A block holds the *shape* of the cluster's binary BVH, not its boxes: the triangle order of
//! its leaves (`T` bytes, a permutation of `0..T`) and the tree in pre-order, one bit per node
//! (1 inner, 0 leaf) followed for a leaf by 2 bits of its triangle count − 1 (leaves hold 1 to
//! 4 triangles, taken in turn from the order). A reader computes the boxes from the triangles
//! (each node's box is the union of its triangles' boxes), which is exact: a ray tracer gets
//! the same tree, to the bit, as one that ran the builder's SAH on the decoded cluster, and a
//! tree read from a corrupt store can make traversal slower but never miss a triangle.
//!
//! The decoder checks everything it reads: the order is a permutation, the tree is complete,
//! its leaves hold exactly the `T` triangles, it is at most [`RT_MAX_DEPTH`] deep, and the
//! padding bits are zero. Nothing is allocated beyond `T` bytes and `2T − 1` nodes.

use crate::error::CodecError;

/// Deepest a stored tree may be (the root has depth 0). A SAH build of ≤ 128 triangles that
/// switches to median splits below depth 40 stays within 47; readers size stacks by this bound.
pub const RT_MAX_DEPTH: usize = 64;

/// Most triangles in one leaf.
pub const RT_LEAF_MAX: u8 = 4;

/// The shape of one cluster's ray-tracing BVH.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RtTree {
    /// Triangle indices (into the cluster's triangles) in leaf order: a permutation of `0..T`.
    pub order: Vec<u8>,
    /// The binary tree in pre-order: 0 for an inner node (its left subtree follows, then its
    /// right), 1..=4 for a leaf of that many triangles, the next ones of `order`.
    pub nodes: Vec<u8>,
}

impl RtTree {
    /// A valid tree for `triangles` triangles (1..=128) without any SAH: halves the order until
    /// leaves of at most 4 (tests and fuzz targets that need some tree).
    pub fn halving(triangles: usize) -> RtTree {
        fn split(n: usize, nodes: &mut Vec<u8>) {
            if n <= RT_LEAF_MAX as usize {
                nodes.push(n as u8);
            } else {
                nodes.push(0);
                split(n / 2, nodes);
                split(n - n / 2, nodes);
            }
        }
        let mut nodes = Vec::new();
        split(triangles.max(1), &mut nodes);
        RtTree { order: (0..triangles as u8).collect(), nodes }
    }

    /// Checks the tree against a cluster of `triangles` triangles: see the module documentation.
    pub fn validate(&self, triangles: usize) -> Result<(), String> {
        if self.order.len() != triangles {
            return Err(format!("order of {} triangles for a cluster of {triangles}", self.order.len()));
        }
        let mut seen = [false; 256];
        for &t in &self.order {
            if t as usize >= triangles || std::mem::replace(&mut seen[t as usize], true) {
                return Err(format!("order is not a permutation of 0..{triangles} (triangle {t})"));
            }
        }
        let mut walk = Walk::default();
        for &n in &self.nodes {
            walk.node(n)?;
        }
        walk.finish(triangles)
    }

    /// Appends the block (validated first) to `out`.
    pub fn encode(&self, triangles: usize, out: &mut Vec<u8>) -> Result<(), String> {
        self.validate(triangles)?;
        out.extend_from_slice(&self.order);
        let (mut acc, mut bits) = (0u32, 0u32);
        let mut put = |v: u32, n: u32, out: &mut Vec<u8>| {
            acc |= v << bits;
            bits += n;
            while bits >= 8 {
                out.push(acc as u8);
                acc >>= 8;
                bits -= 8;
            }
        };
        for &n in &self.nodes {
            match n {
                0 => put(1, 1, out),
                c => put((c as u32 - 1) << 1, 3, out),
            }
        }
        put(0, 7, out); // flush the last partial byte (zero padding)
        Ok(())
    }

    /// Bytes of the block of a cluster of `triangles` triangles with this tree.
    pub fn encoded_len(&self) -> usize {
        let bits: usize = self.nodes.iter().map(|&n| if n == 0 { 1 } else { 3 }).sum();
        self.order.len() + bits.div_ceil(8)
    }
}

/// Checks a pre-order node sequence as it arrives.
#[derive(Default)]
struct Walk {
    /// Depths of the subtrees still to read (the right children of the inner nodes on the path).
    pending: Vec<u8>,
    /// Depth of the next node; `None` once the tree is complete.
    next: Option<usize>,
    started: bool,
    leaf_triangles: usize,
    nodes: usize,
}

impl Walk {
    fn node(&mut self, n: u8) -> Result<(), String> {
        let depth = if self.started {
            self.next.ok_or("nodes after the end of the tree")?
        } else {
            self.started = true;
            0
        };
        self.nodes += 1;
        if self.nodes > 255 {
            return Err("more than 255 nodes".into());
        }
        if n == 0 {
            if depth >= RT_MAX_DEPTH {
                return Err(format!("deeper than {RT_MAX_DEPTH}"));
            }
            self.pending.push(depth as u8 + 1);
            self.next = Some(depth + 1);
        } else if n <= RT_LEAF_MAX {
            self.leaf_triangles += n as usize;
            self.next = self.pending.pop().map(usize::from);
        } else {
            return Err(format!("leaf of {n} triangles, expected 1..={RT_LEAF_MAX}"));
        }
        Ok(())
    }

    fn finish(&self, triangles: usize) -> Result<(), String> {
        if !self.started || self.next.is_some() {
            return Err("the tree ends early".into());
        }
        if self.leaf_triangles != triangles {
            return Err(format!("leaves hold {} triangles, the cluster {triangles}", self.leaf_triangles));
        }
        Ok(())
    }
}

/// Decodes the block at `bytes[pos..]` for a cluster of `triangles` triangles; returns the tree
/// and the byte after it. Offsets in errors are page offsets.
pub(crate) fn decode(bytes: &[u8], pos: usize, triangles: usize) -> Result<(RtTree, usize), CodecError> {
    let err = |at: usize, msg: String| CodecError::new(at, format!("ray-tracing tree: {msg}"));
    let order_end = pos
        .checked_add(triangles)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| err(pos, format!("{triangles} bytes of triangle order needed")))?;
    let mut tree = RtTree { order: bytes[pos..order_end].to_vec(), nodes: Vec::with_capacity(2 * triangles) };
    let mut walk = Walk::default();
    let mut at = order_end;
    let mut bit = 0u32;
    let read = |n: u32, at: &mut usize, bit: &mut u32| -> Result<u32, CodecError> {
        let mut v = 0;
        for k in 0..n {
            let byte = *bytes.get(*at).ok_or_else(|| err(*at, "the tree's bits are truncated".into()))?;
            v |= (((byte >> *bit) & 1) as u32) << k;
            *bit += 1;
            if *bit == 8 {
                *bit = 0;
                *at += 1;
            }
        }
        Ok(v)
    };
    loop {
        let node = if read(1, &mut at, &mut bit)? == 1 { 0 } else { read(2, &mut at, &mut bit)? as u8 + 1 };
        walk.node(node).map_err(|m| err(at, m))?;
        tree.nodes.push(node);
        if walk.next.is_none() {
            break;
        }
    }
    walk.finish(triangles).map_err(|m| err(at, m))?;
    if bit != 0 {
        if bytes[at] >> bit != 0 {
            return Err(err(at, "non-zero padding bits".into()));
        }
        at += 1;
    }
    tree.validate(triangles).map_err(|m| err(pos, m))?;
    Ok((tree, at))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trips_and_sizes() {
        for t in 1..=128 {
            let tree = RtTree::halving(t);
            tree.validate(t).unwrap();
            let mut out = vec![9];
            tree.encode(t, &mut out).unwrap();
            assert_eq!(out.len(), 1 + tree.encoded_len());
            out.push(7);
            let (back, end) = decode(&out, 1, t).unwrap();
            assert_eq!(back, tree);
            assert_eq!(end, out.len() - 1);
        }
    }

    #[test]
    fn rejects_bad_trees() {
        let ok = RtTree::halving(10);
        let bad = [
            RtTree { order: vec![0; 10], ..ok.clone() },
            RtTree { order: ok.order[..9].to_vec(), ..ok.clone() },
            RtTree { nodes: vec![0, 4, 4], ..ok.clone() },
            RtTree { nodes: vec![0, 4, 3, 3], ..ok.clone() },
            RtTree { nodes: vec![5, 5], ..ok.clone() },
            RtTree { nodes: vec![], ..ok.clone() },
        ];
        for b in bad {
            assert!(b.validate(10).is_err(), "{b:?}");
            assert!(b.encode(10, &mut Vec::new()).is_err());
        }
        // A chain deeper than the limit.
        let mut nodes = vec![0u8; RT_MAX_DEPTH + 1];
        nodes.extend(std::iter::repeat_n(1, RT_MAX_DEPTH + 2));
        let deep = RtTree { order: (0..(RT_MAX_DEPTH + 2) as u8).collect(), nodes };
        assert!(deep.validate(RT_MAX_DEPTH + 2).unwrap_err().contains("deeper"));
    }

    /// Every truncation and every single-byte change of encoded blocks is refused or decodes
    /// to a valid tree, without panicking.
    #[test]
    fn corrupt_blocks_never_panic() {
        for t in [1, 5, 37, 128] {
            let mut good = Vec::new();
            RtTree::halving(t).encode(t, &mut good).unwrap();
            for len in 0..good.len() {
                assert!(decode(&good[..len], 0, t).is_err());
            }
            for i in 0..good.len() {
                for x in [1u8, 0x80, 0xff] {
                    let mut b = good.clone();
                    b[i] ^= x;
                    if let Ok((tree, _)) = decode(&b, 0, t) {
                        tree.validate(t).unwrap();
                    }
                }
            }
        }
    }
}
