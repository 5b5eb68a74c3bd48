//! Hierarchical occlusion tests of a frame's candidates, breadth-first by level over the
//! skeleton: Govindaraju's occlusion switch (thesis Alg. 3.4.1) and Yoon et al. 2003 §5.3 test
//! the bounding boxes of hierarchy nodes level by level, and a node found hidden removes its
//! whole subtree, so a wall hides a room's clusters with one test instead of one each.
//!
//! Input: the skeleton's parent links, and per candidate (a cluster) the node its group is
//! attached to. The *candidate tree* is those nodes and their ancestors. Starting from its
//! roots, each round tests the boxes of a frontier of nodes in one batch (`test`, e.g. one
//! batch of hardware occlusion queries); a hidden node culls every candidate under it, a
//! visible one opens its children in the candidate tree for the next round. Two rules keep
//! the number of tests down:
//! - a node with fewer than [`NodeTestOptions::min_candidates`] candidates under it is not
//!   tested: its candidates go straight to the per-cluster test (a box per cluster is then as
//!   cheap and tighter);
//! - a node with no candidates of its own and a single child in the candidate tree is not
//!   tested either: its child's box, inside it, is tested instead.
//!
//! Conservative as long as a node's box contains every cluster of its subtree (the store's
//! node boxes are "inclusive grid boxes of everything under the node", docs/FORMAT.md): a
//! hidden box hides all it contains. Plain data in and out; the caller owns the GPU.

/// Parameters of [`test_hierarchy`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NodeTestOptions {
    /// Nodes with fewer candidates under them are not tested.
    pub min_candidates: usize,
}

impl Default for NodeTestOptions {
    fn default() -> Self {
        NodeTestOptions { min_candidates: 8 }
    }
}

/// What [`test_hierarchy`] found.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct NodeTestResult {
    /// Per candidate (input order): hidden behind a hidden node box.
    pub culled: Vec<bool>,
    /// Node boxes tested, over all rounds.
    pub nodes_tested: u64,
    /// Of those, found hidden.
    pub nodes_hidden: u64,
    /// Rounds (batches given to `test`).
    pub rounds: u64,
}

/// Tests the candidate tree of `candidate_nodes` (one node per candidate; `parent[n]` is
/// `u32::MAX` for a root) breadth-first. `test(nodes)` returns, per node, whether its box is
/// visible. Nodes out of range are treated as roots without a box: their candidates are kept.
pub fn test_hierarchy<E>(
    parent: &[u32],
    candidate_nodes: &[u32],
    options: &NodeTestOptions,
    mut test: impl FnMut(&[u32]) -> Result<Vec<bool>, E>,
) -> Result<NodeTestResult, E> {
    let n = parent.len();
    let mut result = NodeTestResult { culled: vec![false; candidate_nodes.len()], ..Default::default() };
    // Candidates under each node (its own and its descendants'), and own candidates.
    let mut under = vec![0usize; n];
    let mut own: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (i, &node) in candidate_nodes.iter().enumerate() {
        let node = node as usize;
        if node >= n {
            continue;
        }
        own[node].push(i);
        let mut m = node;
        loop {
            under[m] += 1;
            match parent[m] {
                p if (p as usize) < n => m = p as usize,
                _ => break,
            }
        }
    }
    // Children in the candidate tree, in node order (deterministic).
    let mut children: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut frontier: Vec<u32> = Vec::new();
    for m in 0..n {
        if under[m] == 0 {
            continue;
        }
        match parent[m] {
            p if (p as usize) < n => children[p as usize].push(m as u32),
            _ => frontier.push(m as u32),
        }
    }
    while !frontier.is_empty() {
        // Skip nodes that would not pay for a test, going down single-child chains.
        let mut to_test: Vec<u32> = Vec::new();
        let mut next: Vec<u32> = Vec::new();
        for &start in &frontier {
            let mut m = start as usize;
            while own[m].is_empty() && children[m].len() == 1 {
                m = children[m][0] as usize;
            }
            if under[m] >= options.min_candidates {
                to_test.push(m as u32);
            }
            // Nodes too small to test keep their candidates (nothing to do) and stop here.
        }
        if to_test.is_empty() {
            break;
        }
        let visible = test(&to_test)?;
        result.rounds += 1;
        result.nodes_tested += to_test.len() as u64;
        for (k, &m) in to_test.iter().enumerate() {
            if visible.get(k).copied().unwrap_or(true) {
                next.extend_from_slice(&children[m as usize]);
            } else {
                result.nodes_hidden += 1;
                cull_subtree(m as usize, &own, &children, &mut result.culled);
            }
        }
        frontier = next;
    }
    Ok(result)
}

fn cull_subtree(node: usize, own: &[Vec<usize>], children: &[Vec<u32>], culled: &mut [bool]) {
    let mut stack = vec![node];
    while let Some(m) = stack.pop() {
        for &i in &own[m] {
            culled[i] = true;
        }
        stack.extend(children[m].iter().map(|&c| c as usize));
    }
}

/// The parent of every node of a skeleton given as (first child, child count) per node, with
/// children after their parent (docs/FORMAT.md); `u32::MAX` for the root and for links out of
/// range.
pub fn parents(children: impl Iterator<Item = (u32, u32)>) -> Vec<u32> {
    let links: Vec<(u32, u32)> = children.collect();
    let mut parent = vec![u32::MAX; links.len()];
    for (i, &(first, count)) in links.iter().enumerate() {
        for c in first as usize..(first as usize).saturating_add(count as usize) {
            if c < parent.len() && c > i {
                parent[c] = i as u32;
            }
        }
    }
    parent
}

/// Whether node tests pay on the current scene and view, from what they cost and saved.
///
/// A round of node tests costs a wait for its results (one GPU round trip); it saves one
/// cluster query per candidate it culls. Deep in a plant (10^8 triangles, thousands of
/// candidates behind walls) that is a large win; on a small scene or a fly-over, where few
/// candidates are hidden, the round trips cost more than the queries saved (docs/benchmarks-log.md,
/// "Node tests for `queries`"). So a frame with node tests (a probe) compares their measured
/// time with the candidates they culled times the measured cost of one cluster query; when
/// they did not pay, the next [`NodeTestSwitch::PROBE_EVERY`]` − 1` frames go without them.
/// A switch between strategies from measurements, in the spirit of Govindaraju's occlusion
/// switch (thesis ch. 3), applied to the choice of testing nodes at all. The CPU HZB's node
/// tests ([`crate::occlusion::test_clusters_hierarchically`]) use it too, with box tests of
/// the pyramid for queries and no round trip: their node tests cost their own time only.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NodeTestSwitch {
    /// Frames left without node tests.
    skip: u32,
    /// Cost of one cluster query (seconds), a running average over frames that issued at least
    /// [`NodeTestSwitch::MIN_QUERIES_TO_MEASURE`] of them; `None` before the first.
    query_cost: Option<f64>,
}

impl NodeTestSwitch {
    /// A probe frame every this many frames while node tests do not pay.
    pub const PROBE_EVERY: u32 = 16;
    /// Cluster query batches smaller than this are dominated by their round trip: not used
    /// to measure the cost of a query.
    pub const MIN_QUERIES_TO_MEASURE: u64 = 256;
    /// The cost of a cluster query assumed before one was measured (lavapipe at 1280×720
    /// measured 5–10 µs).
    pub const DEFAULT_QUERY_COST: f64 = 10e-6;

    /// Whether this frame tests nodes.
    pub fn test_nodes(&self) -> bool {
        self.skip == 0
    }

    /// After the frame's cluster queries: `queries` of them took `time` (their round trip
    /// included); `node_tests`: `Some((time, culled))` when this frame tested nodes, their
    /// time (all rounds) and the candidates they culled.
    pub fn update(
        &mut self,
        queries: u64,
        time: std::time::Duration,
        node_tests: Option<(std::time::Duration, u64)>,
    ) {
        if queries >= Self::MIN_QUERIES_TO_MEASURE {
            let cost = time.as_secs_f64() / queries as f64;
            self.query_cost = Some(self.query_cost.map_or(cost, |c| 0.75 * c + 0.25 * cost));
        }
        match node_tests {
            Some((node_time, culled)) => {
                let saved = culled as f64 * self.query_cost.unwrap_or(Self::DEFAULT_QUERY_COST);
                self.skip = if saved < node_time.as_secs_f64() { Self::PROBE_EVERY - 1 } else { 0 };
            }
            None => self.skip = self.skip.saturating_sub(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 0 → {1, 2}; 1 → {3, 4}; 2 → {5}; 5 → {6}.
    fn tree() -> Vec<u32> {
        parents([(1, 2), (3, 2), (5, 1), (0, 0), (0, 0), (6, 1), (0, 0)].into_iter())
    }

    #[test]
    fn parents_from_child_ranges() {
        assert_eq!(tree(), vec![u32::MAX, 0, 0, 1, 1, 2, 5]);
        // A link to an earlier node or out of range is ignored.
        assert_eq!(parents([(0, 2), (0, 0)].into_iter()), vec![u32::MAX, 0]);
        assert_eq!(parents([(5, 3)].into_iter()), vec![u32::MAX]);
    }

    #[test]
    fn a_hidden_node_culls_its_subtree_and_nothing_else() {
        let parent = tree();
        // 10 candidates at node 3, 10 at 4, 10 at 6.
        let nodes: Vec<u32> = [3u32, 4, 6].iter().flat_map(|&n| std::iter::repeat_n(n, 10)).collect();
        let mut asked: Vec<Vec<u32>> = Vec::new();
        let r = test_hierarchy::<()>(&parent, &nodes, &NodeTestOptions { min_candidates: 5 }, |batch| {
            asked.push(batch.to_vec());
            Ok(batch.iter().map(|&m| m != 4 && m != 6).collect())
        })
        .unwrap();
        // Round 1: the root. Round 2: 1 and — down the chain 2 → 5 → 6 — node 6. Round 3: 3, 4.
        assert_eq!(asked, vec![vec![0], vec![1, 6], vec![3, 4]]);
        assert_eq!(r.rounds, 3);
        assert_eq!(r.nodes_tested, 5);
        assert_eq!(r.nodes_hidden, 2);
        let culled: Vec<u32> = nodes.iter().zip(&r.culled).filter(|(_, &c)| c).map(|(&n, _)| n).collect();
        assert_eq!(culled, [4u32; 10].iter().chain(&[6u32; 10]).copied().collect::<Vec<_>>());
    }

    #[test]
    fn small_subtrees_are_not_tested_and_keep_their_candidates() {
        let parent = tree();
        let nodes = vec![3, 3, 4, 6];
        let mut asked: Vec<Vec<u32>> = Vec::new();
        let r = test_hierarchy::<()>(&parent, &nodes, &NodeTestOptions { min_candidates: 3 }, |batch| {
            asked.push(batch.to_vec());
            Ok(batch.iter().map(|&m| m != 1).collect())
        })
        .unwrap();
        // The root (4 under it), then node 1 (3); node 6 (1 candidate) is left to its cluster.
        assert_eq!(asked, vec![vec![0], vec![1]]);
        assert_eq!(r.culled, vec![true, true, true, false]);
        let r = test_hierarchy::<()>(&parent, &nodes, &NodeTestOptions { min_candidates: 5 }, |_| {
            panic!("nothing is big enough to test")
        })
        .unwrap();
        assert_eq!(r.culled, vec![false; 4]);
        assert_eq!(r.rounds, 0);
    }

    #[test]
    fn node_tests_are_switched_off_while_they_do_not_pay_and_probed_again() {
        use std::time::Duration;
        let ms = Duration::from_millis;
        let mut s = NodeTestSwitch::default();
        assert!(s.test_nodes(), "the first frame probes");
        // 7,000 candidates culled at ~7 µs a query (measured: 7,000 queries in 49 ms) for 15 ms
        // of node tests: they pay.
        s.update(7_000, ms(49), None);
        s.update(150, ms(3), Some((ms(15), 7_000)));
        assert!(s.test_nodes());
        // 116 culled (too few queries to measure: the 7 µs stand) for 6 ms: they do not.
        s.update(30, ms(2), Some((ms(6), 116)));
        for _ in 1..NodeTestSwitch::PROBE_EVERY {
            assert!(!s.test_nodes());
            s.update(146, ms(3), None);
        }
        assert!(s.test_nodes(), "probed again after {} frames", NodeTestSwitch::PROBE_EVERY);
        // Without any measured query cost, the default decides.
        let mut s = NodeTestSwitch::default();
        s.update(10, ms(1), Some((ms(1), 1_000)));
        assert!(s.test_nodes(), "1,000 × 10 µs = 10 ms saved for 1 ms");
    }

    #[test]
    fn a_hidden_root_culls_everything_and_errors_pass_through() {
        let parent = tree();
        let nodes = vec![3, 4, 6, 1, 0];
        let r = test_hierarchy::<()>(&parent, &nodes, &NodeTestOptions { min_candidates: 1 }, |b| {
            Ok(vec![false; b.len()])
        })
        .unwrap();
        assert_eq!(r.culled, vec![true; 5]);
        assert_eq!(r.rounds, 1);
        let e = test_hierarchy(&parent, &nodes, &NodeTestOptions { min_candidates: 1 }, |_| Err("gpu lost"));
        assert_eq!(e.unwrap_err(), "gpu lost");
        // Out-of-range nodes are kept, never tested.
        let r = test_hierarchy::<()>(&parent, &[99, 99], &NodeTestOptions { min_candidates: 1 }, |_| {
            panic!("no node to test")
        })
        .unwrap();
        assert_eq!(r.culled, vec![false, false]);
    }
}
