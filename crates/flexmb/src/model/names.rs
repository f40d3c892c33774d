//! Name look-up of nodes and joints: hash maps kept by `Model::add_node` and
//! `Model::add_joint`, so that reading a model of n joints costs O(n), not O(n^2).

use std::collections::HashMap;
use std::fmt;

/// Name -> index of the nodes and of the joints, first of each name.
///
/// The items are public fields of the model, so the maps may be stale: a hit is checked
/// against the item's name, and a miss falls back to a scan.
#[derive(Clone, Default)]
pub(super) struct NameIndex {
    nodes: HashMap<String, usize>,
    joints: HashMap<String, usize>,
}

impl NameIndex {
    pub fn add_node(&mut self, name: &str, index: usize) {
        self.nodes.entry(name.to_string()).or_insert(index);
    }

    pub fn add_joint(&mut self, name: &str, index: usize) {
        self.joints.entry(name.to_string()).or_insert(index);
    }

    pub fn node<T>(&self, name: &str, items: &[T], name_of: impl Fn(&T) -> &str) -> Option<usize> {
        find(&self.nodes, name, items, name_of)
    }

    pub fn joint<T>(&self, name: &str, items: &[T], name_of: impl Fn(&T) -> &str) -> Option<usize> {
        find(&self.joints, name, items, name_of)
    }
}

fn find<T>(
    map: &HashMap<String, usize>,
    name: &str,
    items: &[T],
    name_of: impl Fn(&T) -> &str,
) -> Option<usize> {
    match map.get(name) {
        Some(&i) if items.get(i).is_some_and(|item| name_of(item) == name) => Some(i),
        _ => items.iter().position(|item| name_of(item) == name),
    }
}

/// Derived data: two models with the same items are equal whatever their maps hold.
impl PartialEq for NameIndex {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl fmt::Debug for NameIndex {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "NameIndex({} node names, {} joint names)",
            self.nodes.len(),
            self.joints.len()
        )
    }
}
