//! The model tree as plain data: the store's objects (names and ids from its object table) as a
//! hierarchy when names carry one (IFC, glTF node paths: `site/building/storey/wall`), else a
//! flat list, a case-insensitive substring search over the full names, and the rows shown now
//! ([`ModelTree::rows`]: the matches while searching, else the tree with its collapsed nodes'
//! children left out). The rows are computed once per change of the search or of the
//! expanded nodes, not per frame, so that the panel ([`crate::tree_panel`]) only lays out the
//! rows on screen and stays fast with 10^5 and more objects.

use std::collections::HashMap;

/// A node of the tree: a name segment, or a whole name in a flat list.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Node {
    pub label: String,
    pub depth: u32,
    /// The object whose name ends at this node (a leaf, or a group that is an object too).
    pub object: Option<u32>,
    pub children: Vec<u32>,
}

/// The store's objects as a tree, with the search and the expanded nodes.
#[derive(Clone, Debug, Default)]
pub struct ModelTree {
    names: Vec<String>,
    /// The names in lower case, for the search.
    lower: Vec<String>,
    nodes: Vec<Node>,
    roots: Vec<u32>,
    /// The node of each object.
    node_of: Vec<u32>,
    expanded: Vec<bool>,
    query: String,
    rows: Vec<u32>,
}

/// The separator of a name's path (IFC and glTF importers write `parent/child`).
const SEP: char = '/';

impl ModelTree {
    /// The tree of `names` (object `i` is `names[i]`); a hierarchy when a name has a `/`
    /// between non-empty parts, else a flat list. The top level starts expanded.
    pub fn new(names: Vec<String>) -> ModelTree {
        let mut t =
            ModelTree { lower: names.iter().map(|n| n.to_lowercase()).collect(), ..Default::default() };
        let hierarchical = names.iter().any(|n| n.trim_matches(SEP).contains(SEP));
        let mut index: HashMap<(u32, &str), u32> = HashMap::new();
        for (id, name) in names.iter().enumerate() {
            let node = if hierarchical {
                t.insert_path(name, &mut index)
            } else {
                t.add_node(u32::MAX, name.clone())
            };
            t.nodes[node as usize].object.get_or_insert(id as u32);
            t.node_of.push(node);
        }
        t.expanded = t.nodes.iter().map(|n| n.depth == 0).collect();
        t.names = names;
        t.refresh();
        t
    }

    /// The node of path `name`, adding its missing segments under their parents.
    fn insert_path<'a>(&mut self, name: &'a str, index: &mut HashMap<(u32, &'a str), u32>) -> u32 {
        let mut parent = u32::MAX;
        let mut segments = name.split(SEP).filter(|s| !s.is_empty()).peekable();
        if segments.peek().is_none() {
            // An empty name (or only separators): a node of its own at the top.
            return self.add_node(u32::MAX, name.to_string());
        }
        for seg in segments {
            parent = match index.get(&(parent, seg)) {
                Some(&n) => n,
                None => {
                    let n = self.add_node(parent, seg.to_string());
                    index.insert((parent, seg), n);
                    n
                }
            };
        }
        parent
    }

    fn add_node(&mut self, parent: u32, label: String) -> u32 {
        let n = self.nodes.len() as u32;
        let depth = match self.nodes.get(parent as usize) {
            Some(p) => p.depth + 1,
            None => 0,
        };
        self.nodes.push(Node { label, depth, object: None, children: Vec::new() });
        match self.nodes.get_mut(parent as usize) {
            Some(p) => p.children.push(n),
            None => self.roots.push(n),
        }
        n
    }

    pub fn objects(&self) -> usize {
        self.names.len()
    }

    pub fn name(&self, object: u32) -> Option<&str> {
        self.names.get(object as usize).map(String::as_str)
    }

    pub fn node(&self, n: u32) -> &Node {
        &self.nodes[n as usize]
    }

    pub fn query(&self) -> &str {
        &self.query
    }

    /// The nodes shown, in order: while searching, the matching objects' nodes (shown with their
    /// full names); else the tree down to the collapsed nodes.
    pub fn rows(&self) -> &[u32] {
        &self.rows
    }

    pub fn is_searching(&self) -> bool {
        !self.query.trim().is_empty()
    }

    pub fn is_expanded(&self, n: u32) -> bool {
        self.expanded.get(n as usize).copied().unwrap_or(false)
    }

    /// Searches for `query` (case-insensitive substring of the full name; empty: the tree).
    pub fn set_query(&mut self, query: &str) {
        if query != self.query {
            self.query = query.to_string();
            self.refresh();
        }
    }

    /// Opens or closes node `n`.
    pub fn toggle(&mut self, n: u32) {
        if let Some(e) = self.expanded.get_mut(n as usize) {
            *e = !*e;
            self.refresh();
        }
    }

    /// Opens the groups above `object` so that its row is shown (a pick in the scene).
    pub fn reveal(&mut self, object: u32) {
        let Some(&target) = self.node_of.get(object as usize) else { return };
        let mut path = Vec::new();
        if !self.path_to(&self.roots.clone(), target, &mut path) {
            return;
        }
        let closed: Vec<u32> = path.into_iter().filter(|&n| n != target && !self.is_expanded(n)).collect();
        if !closed.is_empty() {
            for n in closed {
                self.expanded[n as usize] = true;
            }
            self.refresh();
        }
    }

    /// Whether `target` lies under one of `from`; `path` gets the nodes down to it.
    fn path_to(&self, from: &[u32], target: u32, path: &mut Vec<u32>) -> bool {
        for &n in from {
            path.push(n);
            if n == target || self.path_to(&self.nodes[n as usize].children, target, path) {
                return true;
            }
            path.pop();
        }
        false
    }

    /// The row of `object`'s node among the rows shown.
    pub fn row_of(&self, object: u32) -> Option<usize> {
        let node = *self.node_of.get(object as usize)?;
        self.rows.iter().position(|&r| r == node)
    }

    /// The object whose name is `name` (case-insensitive), the first when several are.
    pub fn find(&self, name: &str) -> Option<u32> {
        let lower = name.to_lowercase();
        self.lower.iter().position(|n| *n == lower).map(|i| i as u32)
    }

    fn refresh(&mut self) {
        self.rows.clear();
        if self.is_searching() {
            let q = self.query.trim().to_lowercase();
            let hits = self.lower.iter().enumerate().filter(|(_, n)| n.contains(&q));
            self.rows.extend(hits.map(|(i, _)| self.node_of[i]));
            return;
        }
        // Depth first, children in input order, skipping below collapsed nodes.
        let mut stack: Vec<u32> = self.roots.iter().rev().copied().collect();
        while let Some(n) = stack.pop() {
            self.rows.push(n);
            if self.expanded[n as usize] {
                stack.extend(self.nodes[n as usize].children.iter().rev());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    fn labels(t: &ModelTree) -> Vec<String> {
        t.rows()
            .iter()
            .map(|&n| format!("{}{}", " ".repeat(t.node(n).depth as usize), t.node(n).label))
            .collect()
    }

    #[test]
    fn plain_names_make_a_flat_list() {
        let t = ModelTree::new(names(&["left", "middle", "right"]));
        assert_eq!(labels(&t), ["left", "middle", "right"]);
        assert_eq!(t.node(t.rows()[1]).object, Some(1));
        assert_eq!(t.find("MIDDLE"), Some(1));
        assert_eq!(t.find("mid"), None);
    }

    #[test]
    fn paths_make_a_tree_that_opens_and_closes() {
        let mut t = ModelTree::new(names(&["site/a/wall", "site/a/door", "site/b", "/lone/"]));
        // The top level is open: its children show, theirs do not.
        assert_eq!(labels(&t), ["site", " a", " b", "lone"]);
        let a = t.rows()[1];
        t.toggle(a);
        assert_eq!(labels(&t), ["site", " a", "  wall", "  door", " b", "lone"]);
        assert_eq!(t.node(t.rows()[3]).object, Some(1));
        assert_eq!(t.node(a).object, None, "a group, not an object");
        t.toggle(t.rows()[0]);
        assert_eq!(labels(&t), ["site", "lone"]);
        // A pick reveals its row.
        t.reveal(1);
        assert_eq!(t.row_of(1), Some(3));
    }

    #[test]
    fn search_is_a_case_insensitive_substring_of_the_whole_name() {
        let mut t = ModelTree::new(names(&["Site/Pump-1", "site/pipe", "Site/PUMP-2"]));
        t.set_query("pump");
        assert!(t.is_searching());
        let found: Vec<_> = t.rows().iter().map(|&n| t.node(n).object.unwrap()).collect();
        assert_eq!(found, [0, 2]);
        t.set_query("site/pi");
        assert_eq!(t.rows().len(), 1);
        t.set_query("nothing");
        assert!(t.rows().is_empty() && t.row_of(0).is_none());
        t.set_query("  ");
        // Segments are matched as written: `Site` and `site` are two groups.
        assert_eq!(labels(&t), ["Site", " Pump-1", " PUMP-2", "site", " pipe"]);
    }

    #[test]
    fn a_group_that_is_an_object_and_empty_names() {
        let t = ModelTree::new(names(&["a", "a/b", ""]));
        assert_eq!(labels(&t), ["a", " b", ""]);
        assert_eq!(t.node(t.rows()[0]).object, Some(0));
        assert_eq!(t.objects(), 3);
    }

    /// 10^5 objects in 100 groups: the rows are ready at once and a search takes one pass.
    #[test]
    fn large_trees_build_and_search_quickly() {
        let n = 100_000;
        let mut t = ModelTree::new((0..n).map(|i| format!("plant/unit-{}/part-{i}", i % 100)).collect());
        assert_eq!(t.rows().len(), 101);
        t.set_query("PART-9999");
        assert_eq!(t.rows().len(), 11, "9999 and 99990..99999");
    }
}
