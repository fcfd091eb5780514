//! The PBT's arena: nodes in a `Vec`, linked by index; children allocated as adjacent pairs so a
//! node needs one child link, and freed pairs reused.

use crate::Rect;

/// No node: the root's parent, a leaf's children.
pub(super) const NONE: u32 = u32::MAX;

/// The PBT's aspect bound: tiles keep `long <= 2 * short + 1` ([`Rect::within_aspect`]).
pub(super) const MAX_ASPECT: f64 = 2.0;

#[derive(Clone, Debug)]
pub(super) struct Node {
    pub(super) rect: Rect,
    pub(super) parent: u32,
    /// The first child; the second is `first_child + 1`. [`NONE`] for a leaf.
    pub(super) first_child: u32,
    /// Bumped whenever the node's role changes (split, merged, freed, reused, a child split or
    /// merged), so heap entries made before the change can be recognised as stale.
    pub(super) generation: u32,
    /// The rectangle breaks the aspect bound, so the node must stay cut: the cuts a wide image
    /// forces.
    pub(super) forced: bool,
    /// Predicted cost; kept current for leaves only.
    pub(super) estimate: f64,
    /// In the tree, rather than a freed slot awaiting reuse.
    pub(super) live: bool,
}

#[derive(Clone, Debug)]
pub(super) struct Tree {
    nodes: Vec<Node>,
    /// First indices of freed child pairs.
    free: Vec<u32>,
    leaves: usize,
}

impl Tree {
    /// The root over `image` with every forced cut made: the smallest tree whose leaves all keep
    /// the aspect bound. Leaf estimates are zero.
    pub(super) fn new(image: Rect) -> Self {
        let mut tree = Tree {
            nodes: vec![Tree::fresh(image, NONE, 0)],
            free: Vec::new(),
            leaves: 1,
        };
        let mut stack = vec![0];
        while let Some(node) = stack.pop() {
            if tree.nodes[node as usize].forced {
                // A forced rectangle breaks the bound, so it has at least 4 pixels: splittable.
                let [first, second] = tree.split(node, [0.0, 0.0]);
                stack.extend([second, first]);
            }
        }
        tree
    }

    pub(super) fn leaf_count(&self) -> usize {
        self.leaves
    }

    pub(super) fn node(&self, node: u32) -> &Node {
        &self.nodes[node as usize]
    }

    pub(super) fn set_estimate(&mut self, node: u32, estimate: f64) {
        self.nodes[node as usize].estimate = estimate;
    }

    pub(super) fn children(&self, node: u32) -> Option<[u32; 2]> {
        let first = self.node(node).first_child;
        (first != NONE).then(|| [first, first + 1])
    }

    pub(super) fn parent(&self, node: u32) -> Option<u32> {
        let parent = self.node(node).parent;
        (parent != NONE).then_some(parent)
    }

    pub(super) fn is_leaf(&self, node: u32) -> bool {
        self.node(node).first_child == NONE
    }

    /// A leaf of at least two pixels.
    pub(super) fn splittable(&self, node: u32) -> bool {
        self.is_leaf(node) && self.node(node).rect.area() >= 2
    }

    /// An unforced node whose children are both leaves.
    pub(super) fn mergeable(&self, node: u32) -> bool {
        !self.node(node).forced
            && self
                .children(node)
                .is_some_and(|[a, b]| self.is_leaf(a) && self.is_leaf(b))
    }

    pub(super) fn bump(&mut self, node: u32) {
        let node = &mut self.nodes[node as usize];
        node.generation = node.generation.wrapping_add(1);
    }

    /// Cuts leaf `node` into its halves, with the given estimates; returns the halves.
    pub(super) fn split(&mut self, node: u32, estimates: [f64; 2]) -> [u32; 2] {
        debug_assert!(self.is_leaf(node));
        // Invariant: callers split only leaves of at least two pixels.
        let (a, b) = self
            .node(node)
            .rect
            .halves()
            .expect("only leaves of 2+ pixels are split");
        let first = match self.free.pop() {
            Some(first) => {
                for (slot, rect) in [(first, a), (first + 1, b)] {
                    let generation = self.nodes[slot as usize].generation.wrapping_add(1);
                    self.nodes[slot as usize] = Tree::fresh(rect, node, generation);
                }
                first
            }
            None => {
                // Invariant: `Pbt` keeps at most `MAX_LEAVES` (2^30) leaves, so fewer than 2^31
                // nodes, and indices fit a u32 that stays clear of `NONE`.
                let first = u32::try_from(self.nodes.len()).expect("fewer than 2^31 nodes");
                self.nodes
                    .extend([Tree::fresh(a, node, 0), Tree::fresh(b, node, 0)]);
                first
            }
        };
        self.nodes[first as usize].estimate = estimates[0];
        self.nodes[first as usize + 1].estimate = estimates[1];
        self.nodes[node as usize].first_child = first;
        self.leaves += 1;
        [first, first + 1]
    }

    /// Makes mergeable `node` a leaf again with the given estimate, freeing its children.
    pub(super) fn merge(&mut self, node: u32, estimate: f64) {
        debug_assert!(self.mergeable(node));
        let first = self.node(node).first_child;
        for child in [first, first + 1] {
            self.bump(child);
            self.nodes[child as usize].live = false;
        }
        self.free.push(first);
        let node = &mut self.nodes[node as usize];
        node.first_child = NONE;
        node.estimate = estimate;
        self.leaves -= 1;
    }

    /// The indices of the live nodes, in arena order: cheaper than [`Self::walk`] when the
    /// order does not matter.
    pub(super) fn live(&self) -> impl Iterator<Item = u32> + '_ {
        let live = self.nodes.iter().enumerate().filter(|(_, node)| node.live);
        live.map(|(index, _)| index as u32)
    }

    /// Visits every live node depth-first, first child before second, parents before children.
    pub(super) fn walk(&self, mut visit: impl FnMut(u32)) {
        let mut stack = vec![0];
        while let Some(node) = stack.pop() {
            visit(node);
            if let Some([first, second]) = self.children(node) {
                stack.extend([second, first]);
            }
        }
    }

    /// The leaves, depth-first: spatially coherent, as neighbours in the order share subtrees.
    pub(super) fn leaves(&self) -> Vec<u32> {
        let mut leaves = Vec::with_capacity(self.leaves);
        self.walk(|node| {
            if self.is_leaf(node) {
                leaves.push(node);
            }
        });
        leaves
    }

    fn fresh(rect: Rect, parent: u32, generation: u32) -> Node {
        let forced = !rect.within_aspect(MAX_ASPECT);
        Node {
            rect,
            parent,
            first_child: NONE,
            generation,
            forced,
            estimate: 0.0,
            live: true,
        }
    }
}
