//! Ownership: a depth-first walk from the root's placements, one element at a time (root
//! placements carry their element), stamps every node it reaches; a node reached by one element
//! belongs to it, a node reached by several is **shared** and remembers the set (so a subset's
//! cost counts each shared node once, when any of its users is selected). The walk follows the
//! graph's BLAS counts, so it is O(Σ distinct edges reachable per element), not O(instances);
//! owners and stamps are dense tables indexed by node.

use std::collections::HashMap;

use motu_abi::NONE_U32;

use crate::cost::{Graph, Node};

/// Owner labels in [`Ownership`].
pub(crate) const UNSEEN: u32 = NONE_U32;
pub(crate) const SHARED: u32 = NONE_U32 - 1;

/// Dense node numbering: TLASes, then BLASes, meshes, LOD selectors.
struct Numbering {
    tlases: usize,
    blases: usize,
    meshes: usize,
    lods: usize,
}

impl Numbering {
    fn of(g: &Graph<'_>) -> Self {
        Numbering {
            tlases: g.view.tlases.len(),
            blases: g.view.blases.len(),
            meshes: g.view.meshes.len(),
            lods: g.view.lod_selectors.len(),
        }
    }

    fn len(&self) -> usize {
        self.tlases + self.blases + self.meshes + self.lods
    }

    fn index(&self, n: Node) -> usize {
        match n {
            Node::Tlas(t) => t as usize,
            Node::Blas(b) => self.tlases + b as usize,
            Node::Mesh(m) => self.tlases + self.blases + m as usize,
            Node::Lod(s) => self.tlases + self.blases + self.meshes + s as usize,
        }
    }

    fn node(&self, i: usize) -> Node {
        let mut i = i;
        if i < self.tlases {
            return Node::Tlas(i as u32);
        }
        i -= self.tlases;
        if i < self.blases {
            return Node::Blas(i as u32);
        }
        i -= self.blases;
        if i < self.meshes {
            return Node::Mesh(i as u32);
        }
        Node::Lod((i - self.meshes) as u32)
    }
}

/// Which element owns each node (see the module docs).
pub(crate) struct Ownership {
    numbering: Numbering,
    /// Per node: its element label, [`SHARED`], or [`UNSEEN`].
    owner: Vec<u32>,
    /// Sorted element sets of shared nodes.
    pub shared_sets: HashMap<Node, Vec<u32>>,
}

impl Ownership {
    /// `labelled_roots`: (element label, BLAS a root placement places), any order, repeats
    /// allowed.
    pub fn compute(g: &Graph<'_>, labelled_roots: &[(u32, u32)]) -> Self {
        let numbering = Numbering::of(g);
        let mut roots = labelled_roots.to_vec();
        roots.sort_unstable();
        roots.dedup();
        let mut owner = vec![UNSEEN; numbering.len()];
        let mut stamp = vec![UNSEEN; numbering.len()];
        let mut shared_sets: HashMap<Node, Vec<u32>> = HashMap::new();
        let mut stack = Vec::new();
        let mut kids = Vec::new();
        for &(label, blas) in &roots {
            stack.push(Node::Blas(blas));
            while let Some(n) = stack.pop() {
                let i = numbering.index(n);
                if stamp[i] == label {
                    continue;
                }
                stamp[i] = label;
                let o = &mut owner[i];
                if *o == UNSEEN {
                    *o = label;
                } else if *o != label {
                    let set = shared_sets.entry(n).or_default();
                    if *o != SHARED {
                        set.push(*o);
                        *o = SHARED;
                    }
                    set.push(label);
                }
                kids.clear();
                g.children(n, &mut kids);
                stack.extend(
                    kids.iter()
                        .copied()
                        .filter(|&k| stamp[numbering.index(k)] != label),
                );
            }
        }
        for set in shared_sets.values_mut() {
            set.sort_unstable();
            set.dedup();
        }
        Ownership {
            numbering,
            owner,
            shared_sets,
        }
    }

    /// Node `n`'s owner, if any walk reached it.
    pub fn get(&self, n: Node) -> Option<u32> {
        Some(self.owner[self.numbering.index(n)]).filter(|&o| o != UNSEEN)
    }

    /// Gives `n` to `label` unless a walk reached it.
    pub fn claim(&mut self, n: Node, label: u32) {
        let o = &mut self.owner[self.numbering.index(n)];
        if *o == UNSEEN {
            *o = label;
        }
    }

    /// Every reached node and its owner, in node order.
    pub fn iter(&self) -> impl Iterator<Item = (Node, u32)> + '_ {
        self.owner
            .iter()
            .enumerate()
            .filter(|(_, &o)| o != UNSEEN)
            .map(|(i, &o)| (self.numbering.node(i), o))
    }
}
