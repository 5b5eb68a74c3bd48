//! The tables' structural invariants (docs/FORMAT.md, "Invariants"), shared by the writer (which
//! refuses to write a store that breaks them) and the reader (which refuses to open one), and
//! the group links they describe ([`GroupLinks`]).
//!
//! [`validate_tables`] runs the checks in a fixed order (strings, pages, the skeleton, groups,
//! group links) and stops at the first problem: the hardening audit and the fuzz targets rely on
//! which error a damaged store gives.

use super::{
    str_at, Group, Header, Node, ObjectEntry, PageEntry, SectionKind, GROUP_LEN, MAX_SCENE_COORD, NODE_LEN,
    OBJECT_LEN, PAGE_ENTRY_LEN, SOURCE_LEN,
};
use crate::codec::{MAX_DECODED_CLUSTER, MAX_TRIANGLES, MIN_CLUSTER_BYTES};

/// An error of the checks: `(absolute byte offset of the offending entry, message)`.
type Found = (u64, String);

/// The tables a store is made of, as checked by [`validate_tables`].
pub struct Tables<'a> {
    pub header: &'a Header,
    pub objects: &'a [ObjectEntry],
    pub nodes: &'a [Node],
    pub groups: &'a [Group],
    pub pages: &'a [PageEntry],
    pub strings: &'a [u8],
    /// The group sources section: each group's sources, group after group.
    pub sources: &'a [u32],
}

/// The links of the cluster DAG between groups, in flat arrays (no allocation per group).
///
/// The *sources* of group `g` are the finer groups its clusters were simplified from; its
/// *parents* are the coarser groups whose clusters were simplified from `g` (the inverse
/// relation, derived when the store is opened). Both lists are sorted; sources have smaller
/// indices than their group, parents larger ones.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GroupLinks {
    /// Sources of group `g`: `sources[source_first[g]..source_first[g + 1]]`.
    source_first: Vec<u32>,
    sources: Vec<u32>,
    /// Parents of group `g`: `parents[parent_first[g]..parent_first[g + 1]]`.
    parent_first: Vec<u32>,
    parents: Vec<u32>,
}

impl GroupLinks {
    /// The sources of `group` (empty for a group of input clusters, or out of range).
    pub fn sources(&self, group: u32) -> &[u32] {
        range_of(&self.source_first, &self.sources, group)
    }

    /// The parents of `group` (empty for a root group, or out of range).
    pub fn parents(&self, group: u32) -> &[u32] {
        range_of(&self.parent_first, &self.parents, group)
    }

    /// Number of links (Σ source counts = Σ parent counts).
    pub fn link_count(&self) -> usize {
        self.sources.len()
    }

    /// Where the sources of `group` lie among all links (empty when out of range).
    pub(crate) fn source_range(&self, group: u32) -> std::ops::Range<usize> {
        let g = group as usize;
        match (self.source_first.get(g), self.source_first.get(g + 1)) {
            (Some(&a), Some(&b)) => a as usize..b as usize,
            _ => 0..0,
        }
    }
}

fn range_of<'a>(first: &[u32], items: &'a [u32], g: u32) -> &'a [u32] {
    let g = g as usize;
    match (first.get(g), first.get(g + 1)) {
        (Some(&a), Some(&b)) => items.get(a as usize..b as usize).unwrap_or_default(),
        _ => &[],
    }
}

/// Checks the structural invariants that need no page decoding (docs/FORMAT.md, "Invariants")
/// and returns the group links they describe. Errors are `(absolute byte offset of the offending
/// entry, message)`; offsets assume the header's section directory (the writer validates before
/// writing with the final offsets).
pub fn validate_tables(t: &Tables) -> Result<GroupLinks, (u64, String)> {
    check_strings(t)?;
    check_pages(t)?;
    check_root_box(t)?;
    let group_owner = check_nodes(t)?;
    check_groups(t, &group_owner)?;
    validate_links(t)
}

/// Absolute offset of entry `i` of the table `kind`, whose entries are `len` bytes.
fn entry_at(h: &Header, kind: SectionKind, i: usize, len: usize) -> u64 {
    h.section(kind).offset + (i * len) as u64
}

/// The header's strings and the object names lie in the string table and are UTF-8.
fn check_strings(t: &Tables) -> Result<(), Found> {
    let h = t.header;
    for (what, s, off) in [("units", h.units, 104u64), ("build options", h.build_options, 112)] {
        str_at(t.strings, s).map_err(|m| (off, format!("{what}: {m}")))?;
    }
    for (i, o) in t.objects.iter().enumerate() {
        str_at(t.strings, o.name).map_err(|m| {
            (entry_at(h, SectionKind::Objects, i, OBJECT_LEN), format!("object {i} name: {m}"))
        })?;
    }
    Ok(())
}

/// Pages: contiguous in file order, filling the pages region exactly, holding the header's
/// cluster and triangle counts.
fn check_pages(t: &Tables) -> Result<(), Found> {
    let h = t.header;
    let region = h.section(SectionKind::Pages);
    let mut next = region.offset;
    let (mut clusters, mut triangles) = (0u64, 0u64);
    for (i, p) in t.pages.iter().enumerate() {
        let off = entry_at(h, SectionKind::PageTable, i, PAGE_ENTRY_LEN);
        if p.offset != next {
            return Err((off, format!("page {i} starts at byte {}, expected {next}", p.offset)));
        }
        next = p.offset + p.compressed_len as u64;
        check_page_counts(i, p).map_err(|m| (off, m))?;
        clusters += p.cluster_count as u64;
        triangles += p.triangle_count as u64;
    }
    if next != region.end() {
        return Err((
            region.offset,
            format!("pages end at byte {next}, pages region ends at {}", region.end()),
        ));
    }
    if clusters != h.cluster_count || triangles != h.triangle_count {
        return Err((
            144,
            format!(
                "header counts {} clusters / {} triangles, pages hold {clusters} / {triangles}",
                h.cluster_count, h.triangle_count
            ),
        ));
    }
    Ok(())
}

/// Page `i` has clusters, a level range, and counts its encoded bytes can hold.
fn check_page_counts(i: usize, p: &PageEntry) -> Result<(), String> {
    if p.cluster_count == 0 {
        return Err(format!("page {i} has no clusters"));
    }
    if p.level_min > p.level_max {
        return Err(format!("page {i}: level range {}..={}", p.level_min, p.level_max));
    }
    // Every encoded cluster takes at least MIN_CLUSTER_BYTES; this also bounds decode allocations.
    if (p.cluster_count as u64) * MIN_CLUSTER_BYTES as u64 > p.compressed_len as u64
        || p.triangle_count as u64 > p.cluster_count as u64 * MAX_TRIANGLES as u64
        || (p.triangle_count as u64) < p.cluster_count as u64
        || p.uncompressed_len as u64 > p.cluster_count as u64 * MAX_DECODED_CLUSTER as u64
    {
        return Err(format!(
            "page {i}: {} clusters / {} triangles / {} decoded bytes do not fit {} encoded bytes",
            p.cluster_count, p.triangle_count, p.uncompressed_len, p.compressed_len
        ));
    }
    Ok(())
}

/// The skeleton has a root node, and the root's box stays within what f32 rendering can hold.
fn check_root_box(t: &Tables) -> Result<(), Found> {
    let h = t.header;
    let Some(root) = t.nodes.first() else {
        return Err((h.section(SectionKind::Nodes).offset, "the skeleton has no root node".into()));
    };
    // Every vertex lies in the root's box (children lie in their parents, vertices in their
    // group's node: checked here and by verify), so this bounds every scene-space position.
    let far = root.max.iter().map(|&g| g as f64 * h.grid_step).fold(0.0, f64::max);
    if far > MAX_SCENE_COORD {
        return Err((
            h.section(SectionKind::Nodes).offset,
            format!(
                "the root box reaches grid coordinate {:?}, {far:e} in scene space with grid step {:e}: \
                 beyond the {MAX_SCENE_COORD:e} that f32 rendering can hold",
                root.max, h.grid_step
            ),
        ));
    }
    Ok(())
}

/// Nodes: a tree rooted at node 0, children after their parent and inside its box, each node
/// with one parent, each group listed by at most one node. Returns the node that lists each
/// group (`u32::MAX` for none).
fn check_nodes(t: &Tables) -> Result<Vec<u32>, Found> {
    let mut parents = vec![0u8; t.nodes.len()];
    let mut group_owner = vec![u32::MAX; t.groups.len()];
    for (i, node) in t.nodes.iter().enumerate() {
        let off = entry_at(t.header, SectionKind::Nodes, i, NODE_LEN);
        check_node(i, node).map_err(|m| (off, m))?;
        count_children(t.nodes, i, node, &mut parents).map_err(|m| (off, m))?;
        claim_groups(i, node, &mut group_owner).map_err(|m| (off, m))?;
    }
    for (i, &p) in parents.iter().enumerate() {
        let expected = if i == 0 { 0 } else { 1 };
        if p != expected {
            return Err((
                entry_at(t.header, SectionKind::Nodes, i, NODE_LEN),
                format!("node {i} has {p} parents, expected {expected} (the skeleton must be one tree)"),
            ));
        }
    }
    Ok(group_owner)
}

/// Node `i` on its own: a box, a max error ≥ 0, a leaf's first child 0.
fn check_node(i: usize, node: &Node) -> Result<(), String> {
    if (0..3).any(|a| node.min[a] > node.max[a]) {
        return Err(format!("node {i}: bounds min > max"));
    }
    if node.max_error.is_nan() || node.max_error < 0.0 {
        return Err(format!("node {i}: max error {} is not ≥ 0", node.max_error));
    }
    if node.child_count == 0 && node.first_child != 0 {
        return Err(format!("node {i}: a leaf with first child {} (must be 0)", node.first_child));
    }
    Ok(())
}

/// Node `i`'s children lie after it, among the nodes, inside its box; counts one more parent
/// for each of them.
fn count_children(nodes: &[Node], i: usize, node: &Node, parents: &mut [u8]) -> Result<(), String> {
    if node.child_count == 0 {
        return Ok(());
    }
    let n = nodes.len();
    let end = node.first_child as u64 + node.child_count as u64;
    if node.first_child as usize <= i || end > n as u64 {
        return Err(format!(
            "node {i}: children {}..{end} must lie after the node and within {n} nodes",
            node.first_child
        ));
    }
    let first = node.first_child as usize;
    for (c, child) in nodes.iter().enumerate().take(end as usize).skip(first) {
        parents[c] = parents[c].saturating_add(1);
        if (0..3).any(|a| child.min[a] < node.min[a] || child.max[a] > node.max[a]) {
            return Err(format!("node {i}: bounds do not contain child {c}"));
        }
    }
    Ok(())
}

/// Node `i`'s groups lie among the groups and no other node listed them; records `i` as their
/// node.
fn claim_groups(i: usize, node: &Node, group_owner: &mut [u32]) -> Result<(), String> {
    let end = node.first_group as u64 + node.group_count as u64;
    if end > group_owner.len() as u64 {
        return Err(format!(
            "node {i}: groups {}..{end} beyond {} groups",
            node.first_group,
            group_owner.len()
        ));
    }
    for (g, owner) in group_owner.iter_mut().enumerate().take(end as usize).skip(node.first_group as usize) {
        if *owner != u32::MAX {
            return Err(format!("node {i}: group {g} is already listed by node {owner}"));
        }
        *owner = i as u32;
    }
    Ok(())
}

/// Groups: listed by their node, clusters within one page, together the header's clusters.
fn check_groups(t: &Tables, group_owner: &[u32]) -> Result<(), Found> {
    let h = t.header;
    let mut group_clusters = 0u64;
    for (i, g) in t.groups.iter().enumerate() {
        let off = entry_at(h, SectionKind::Groups, i, GROUP_LEN);
        check_group(t.pages, i, g, group_owner[i]).map_err(|m| (off, m))?;
        group_clusters += g.cluster_count as u64;
    }
    if group_clusters != h.cluster_count {
        return Err((
            h.section(SectionKind::Groups).offset,
            format!("groups list {group_clusters} clusters, the pages hold {}", h.cluster_count),
        ));
    }
    Ok(())
}

/// Group `i` on its own: `owner` (the node that lists it) is its node, its sphere and error are
/// valid, its clusters and level lie within its page's.
fn check_group(pages: &[PageEntry], i: usize, g: &Group, owner: u32) -> Result<(), String> {
    if owner != g.node {
        return Err(if owner == u32::MAX {
            format!("group {i} is not listed by any node (unreachable from the root)")
        } else {
            format!("group {i} says node {}, but node {owner} lists it", g.node)
        });
    }
    if g.sphere.iter().any(|v| !v.is_finite()) || g.sphere[3] < 0.0 {
        return Err(format!("group {i}: invalid sphere {:?}", g.sphere));
    }
    if g.error.is_nan() || g.error < 0.0 {
        return Err(format!("group {i}: error {} is not ≥ 0", g.error));
    }
    let Some(page) = pages.get(g.page as usize) else {
        return Err(format!("group {i}: page {} beyond {} pages", g.page, pages.len()));
    };
    if g.cluster_count == 0 || g.first_cluster as u64 + g.cluster_count as u64 > page.cluster_count as u64 {
        return Err(format!(
            "group {i}: clusters {}..{} not within the {} clusters of page {}",
            g.first_cluster,
            g.first_cluster as u64 + g.cluster_count as u64,
            page.cluster_count,
            g.page
        ));
    }
    if g.level < page.level_min || g.level > page.level_max {
        return Err(format!("group {i}: level {} outside page {}'s level range", g.level, g.page));
    }
    Ok(())
}

/// The group sources (docs/FORMAT.md, "Group sources"): each group's sources strictly increasing
/// and smaller than the group's index (so the links form a DAG and there is no self-link), of a
/// level ≤ and a finite error ≤ the group's; every group with a finite error is the source of at
/// least one group, a root group (error = +∞) of none. Builds the inverse relation (parents).
fn validate_links(t: &Tables) -> Result<GroupLinks, Found> {
    check_source_total(t)?;
    let (source_first, parent_count) = check_sources(t)?;
    check_finite_groups_have_parents(t, &parent_count)?;
    let (parent_first, parents) = invert_links(t, &source_first, &parent_count);
    Ok(GroupLinks { source_first, sources: t.sources.to_vec(), parent_first, parents })
}

/// The groups' source counts add up to the section's entries, and to at most 2^32 - 1.
fn check_source_total(t: &Tables) -> Result<(), Found> {
    let section = t.header.section(SectionKind::GroupSources);
    let total: u64 = t.groups.iter().map(|g| g.source_count as u64).sum();
    if total != t.sources.len() as u64 {
        return Err((
            section.offset,
            format!("the groups count {total} sources, the group sources section holds {}", t.sources.len()),
        ));
    }
    // The prefix sums of `check_sources` and `invert_links` are u32.
    if total > u32::MAX as u64 {
        return Err((section.offset, format!("{total} group sources: more than 2^32 - 1")));
    }
    Ok(())
}

/// Checks every group's sources ([`check_source`]); returns where each group's sources start
/// (one more entry for the end) and how many groups each group is a source of.
fn check_sources(t: &Tables) -> Result<(Vec<u32>, Vec<u32>), Found> {
    let section = t.header.section(SectionKind::GroupSources);
    let mut source_first = Vec::with_capacity(t.groups.len() + 1);
    let mut parent_count = vec![0u32; t.groups.len()];
    let mut next = 0usize;
    source_first.push(0u32);
    for (i, g) in t.groups.iter().enumerate() {
        let end = next + g.source_count as usize;
        let mut prev: Option<u32> = None;
        for (k, &s) in t.sources[next..end].iter().enumerate() {
            let at = section.offset + ((next + k) * SOURCE_LEN) as u64;
            check_source(t.groups, i, s, prev).map_err(|m| (at, m))?;
            prev = Some(s);
            parent_count[s as usize] += 1;
        }
        next = end;
        source_first.push(next as u32);
    }
    Ok((source_first, parent_count))
}

/// Source `s` of group `i` (after `prev`, the one before it): a group before `i`, after `prev`,
/// of a level ≤ and a finite error ≤ group `i`'s.
fn check_source(groups: &[Group], i: usize, s: u32, prev: Option<u32>) -> Result<(), String> {
    if s as usize >= i {
        return Err(format!("group {i}: source {s} is not a group before it (sources precede their group)"));
    }
    if prev.is_some_and(|p| p >= s) {
        return Err(format!("group {i}: sources are not strictly increasing ({prev:?}, {s})"));
    }
    let (g, src) = (&groups[i], &groups[s as usize]);
    if src.level > g.level {
        return Err(format!("group {i}: source {s} has level {} > {}", src.level, g.level));
    }
    if !src.error.is_finite() || src.error > g.error {
        return Err(format!(
            "group {i}: source {s} has error {} (must be finite and ≤ the group's {})",
            src.error, g.error
        ));
    }
    Ok(())
}

/// Every group with a finite error is the source of some group: a coarser group replaces it.
fn check_finite_groups_have_parents(t: &Tables, parent_count: &[u32]) -> Result<(), Found> {
    for (i, g) in t.groups.iter().enumerate() {
        let (finite, parents) = (g.error.is_finite(), parent_count[i]);
        if finite && parents == 0 {
            return Err((
                entry_at(t.header, SectionKind::Groups, i, GROUP_LEN),
                format!(
                    "group {i} has error {} but no group was simplified from it (a finite error needs a \
                     coarser group that replaces it)",
                    g.error
                ),
            ));
        }
        // Root groups are never sources (checked above: sources have finite errors).
        debug_assert!(finite || parents == 0);
    }
    Ok(())
}

/// The parents of every group, as `(parent_first, parents)` of [`GroupLinks`]: a counting sort
/// of the links by source, filled in group order, so each group's parents come out increasing.
fn invert_links(t: &Tables, source_first: &[u32], parent_count: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let mut parent_first = Vec::with_capacity(t.groups.len() + 1);
    let mut sum = 0u32;
    for &c in parent_count {
        parent_first.push(sum);
        sum += c;
    }
    parent_first.push(sum);
    let mut fill = parent_first.clone();
    let mut parents = vec![0u32; t.sources.len()];
    for i in 0..t.groups.len() {
        for &s in &t.sources[source_first[i] as usize..source_first[i + 1] as usize] {
            parents[fill[s as usize] as usize] = i as u32;
            fill[s as usize] += 1;
        }
    }
    (parent_first, parents)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::format::tests::header;

    /// Groups 0 and 1 (finite errors) are simplified into group 2; group 3 (error ∞) is made
    /// from 2; group 4 is a lone root.
    fn linked_groups() -> (Vec<Group>, Vec<u32>) {
        let g = |error: f32, level: u8, source_count: u32| Group {
            error,
            level,
            source_count,
            ..Group::default()
        };
        (
            vec![g(1.0, 0, 0), g(1.0, 0, 0), g(2.0, 1, 2), g(f32::INFINITY, 2, 1), g(f32::INFINITY, 0, 0)],
            vec![0, 1, 2],
        )
    }

    fn links_of(groups: &[Group], sources: &[u32]) -> Result<GroupLinks, (u64, String)> {
        let mut h = header();
        h.sections[SectionKind::Groups as usize].offset = 1000;
        h.sections[SectionKind::GroupSources as usize].offset = 2000;
        validate_links(&Tables {
            header: &h,
            objects: &[],
            nodes: &[],
            groups,
            pages: &[],
            strings: &[],
            sources,
        })
    }

    #[test]
    fn links_give_sources_and_parents() {
        let (groups, sources) = linked_groups();
        let links = links_of(&groups, &sources).unwrap();
        assert_eq!(links.link_count(), 3);
        let all = |f: &dyn Fn(u32) -> Vec<u32>| (0..5).map(f).collect::<Vec<_>>();
        assert_eq!(all(&|g| links.sources(g).to_vec()), vec![vec![], vec![], vec![0, 1], vec![2], vec![]]);
        assert_eq!(all(&|g| links.parents(g).to_vec()), vec![vec![2], vec![2], vec![3], vec![], vec![]]);
        assert!(links.sources(5).is_empty() && links.parents(u32::MAX).is_empty());
        assert_eq!(GroupLinks::default().sources(0), &[] as &[u32]);
    }

    #[test]
    fn broken_links_are_rejected_with_their_offset() {
        type Edit = fn(&mut Vec<Group>, &mut Vec<u32>);
        let cases: [(&str, Edit, u64, &str); 9] = [
            ("self link", |_, s| s[2] = 3, 2008, "not a group before it"),
            ("forward link", |_, s| s[1] = 4, 2004, "not a group before it"),
            ("out of range", |_, s| s[2] = 99, 2008, "not a group before it"),
            ("unsorted", |_, s| s.swap(0, 1), 2004, "strictly increasing"),
            ("duplicate", |_, s| s[1] = 0, 2004, "strictly increasing"),
            ("finer level", |g, _| g[0].level = 2, 2000, "level"),
            ("larger error", |g, _| g[1].error = 3.0, 2004, "error"),
            (
                "finite error, no parent",
                |g, s| {
                    g[2].source_count = 1;
                    s.remove(1);
                },
                1048,
                "no group was simplified from it",
            ),
            ("count mismatch", |g, _| g[3].source_count = 2, 2000, "sources"),
        ];
        for (name, edit, offset, msg) in cases {
            let (mut groups, mut sources) = linked_groups();
            edit(&mut groups, &mut sources);
            let (at, m) = links_of(&groups, &sources).expect_err(name);
            assert_eq!(at, offset, "{name}: {m}");
            assert!(m.contains(msg), "{name}: {m}");
        }
        // A root group (error ∞) is never a source.
        let (mut groups, sources) = linked_groups();
        groups[1].error = f32::INFINITY;
        groups[2].error = f32::INFINITY;
        let (_, m) = links_of(&groups, &sources).unwrap_err();
        assert!(m.contains("source 1 has error inf"), "{m}");
    }
}
