//! The greedy update of the PBT (see the module docs of [`crate::pbt`] for the objective and the
//! proof of termination): heaps of split and merge candidates with lazy deletion.
//!
//! Both heaps hold `(key, node, generation)` entries and are never searched: an entry whose
//! generation differs from its node's is stale and skipped when it reaches the top. Split keys
//! start *optimistic*: a leaf of estimate `a` can gain at most `a^2 / 4` (its halves' product
//! peaks when they are equal), which costs nothing to compute; only entries that reach the top
//! are made exact, with two cost-map queries. Each step is therefore O(log m) heap work plus
//! O(1) queries, amortised.

use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;
use std::mem::take;

use super::tree::Tree;
use crate::Update;
use crate::partition::Predictor;

/// Safety net on the number of split+merge moves one update makes, per leaf. Each move strictly
/// increases a potential over a finite set of trees, so the loop ends by itself; the cap exists
/// only so that a bug cannot hang a frame, and [`Update::capped`] reports if it ever bites.
const MOVES_PER_LEAF: usize = 8;

/// The heaps' storage, kept between updates so that an update need not allocate.
#[derive(Clone, Debug, Default)]
pub(super) struct Scratch {
    splits: Vec<Entry>,
    merges: Vec<Reverse<Entry>>,
}

/// Brings `tree` to `target` leaves (as near as the image allows), then trades splits for
/// merges while that lowers the variance of the leaf estimates. Leaf estimates must be current.
pub(super) fn restructure(
    tree: &mut Tree,
    predictor: &Predictor,
    target: usize,
    scratch: &mut Scratch,
) -> Update {
    let mut greedy = Greedy::new(tree, predictor, scratch);
    let mut update = Update::default();
    while greedy.tree.leaf_count() < target {
        let Some(split) = greedy.best_split(None) else {
            break;
        };
        greedy.split(split);
        update.splits += 1;
    }
    while greedy.tree.leaf_count() > target {
        let Some((node, _)) = greedy.best_merge(None) else {
            break;
        };
        greedy.merge(node);
        update.merges += 1;
    }
    let cap = MOVES_PER_LEAF * greedy.tree.leaf_count() + 64;
    let mut moves = 0;
    while let Some((split, merge)) = greedy.best_pair() {
        if moves >= cap {
            update.capped = true;
            break;
        }
        greedy.split(split);
        greedy.merge(merge);
        update.splits += 1;
        update.merges += 1;
        moves += 1;
    }
    greedy.finish(scratch);
    update
}

/// A split candidate made exact: the leaf and its halves' product.
#[derive(Clone, Copy)]
struct Split {
    node: u32,
    gain: f64,
}

struct Greedy<'a> {
    tree: &'a mut Tree,
    predictor: &'a Predictor,
    /// Keys are products of estimates scaled by `1 / root estimate`, so they cannot overflow.
    scale: f64,
    splits: BinaryHeap<Entry>,
    merges: BinaryHeap<Reverse<Entry>>,
}

impl<'a> Greedy<'a> {
    fn new(tree: &'a mut Tree, predictor: &'a Predictor, scratch: &mut Scratch) -> Self {
        let root = predictor.estimate(tree.node(0).rect);
        let scale = if root > 0.0 { 1.0 / root } else { 1.0 };
        let (mut splits, mut merges) = (take(&mut scratch.splits), take(&mut scratch.merges));
        for node in tree.live() {
            if tree.splittable(node) {
                splits.push(Entry::optimistic(tree, node, scale));
            } else if tree.mergeable(node) {
                merges.push(Reverse(Entry::merge(tree, node, scale)));
            }
        }
        Greedy {
            tree,
            predictor,
            scale,
            splits: splits.into(),
            merges: merges.into(),
        }
    }

    /// Hands the heaps' storage back, emptied.
    fn finish(self, scratch: &mut Scratch) {
        scratch.splits = self.splits.into_vec();
        scratch.splits.clear();
        scratch.merges = self.merges.into_vec();
        scratch.merges.clear();
    }

    /// The split+merge pair that lowers the variance most, if any lowers it: the best split
    /// and the best merge, unless the merge would undo the split's leaf (its parent), in which
    /// case the better of (best split, second merge) and (second split, best merge).
    fn best_pair(&mut self) -> Option<(Split, u32)> {
        let split = self.best_split(None)?;
        let (merge, loss) = self.best_merge(None)?;
        let (split, merge, loss) = if self.tree.parent(split.node) != Some(merge) {
            (split, merge, loss)
        } else {
            let with_next_merge = self.best_merge(Some(merge)).map(|(q, l)| (split, q, l));
            let with_next_split = self.best_split(Some(merge)).map(|s| (s, merge, loss));
            [with_next_merge, with_next_split]
                .into_iter()
                .flatten()
                .max_by(|x, y| (x.0.gain - x.2).total_cmp(&(y.0.gain - y.2)))?
        };
        (split.gain > loss).then_some((split, merge))
    }

    /// The leaf whose split gains most (not a child of `not_under`), made exact; its entry
    /// stays in the heap.
    fn best_split(&mut self, not_under: Option<u32>) -> Option<Split> {
        let mut held = Vec::new();
        let found = loop {
            let top = *self.splits.peek()?;
            let node = self.tree.node(top.node);
            if top.generation != node.generation {
                self.splits.pop();
            } else if !top.exact {
                self.splits.pop();
                let [a, b] = self.halves(top.node);
                let key = (a * self.scale) * (b * self.scale);
                self.splits.push(Entry {
                    key,
                    exact: true,
                    ..top
                });
            } else if not_under.is_some() && self.tree.parent(top.node) == not_under {
                held.extend(self.splits.pop());
            } else {
                break Some(Split {
                    node: top.node,
                    gain: top.key,
                });
            }
        };
        self.splits.extend(held);
        found
    }

    /// The mergeable node whose merge costs least (other than `except`), with that cost; its
    /// entry stays in the heap.
    fn best_merge(&mut self, except: Option<u32>) -> Option<(u32, f64)> {
        let mut held = None;
        let found = loop {
            let Reverse(top) = *self.merges.peek()?;
            if top.generation != self.tree.node(top.node).generation {
                self.merges.pop();
            } else if Some(top.node) == except {
                held = self.merges.pop();
            } else {
                break Some((top.node, top.key));
            }
        };
        self.merges.extend(held);
        found
    }

    fn split(&mut self, split: Split) {
        let estimates = self.halves(split.node);
        let halves = self.tree.split(split.node, estimates);
        self.refresh(split.node);
        for half in halves {
            self.refresh(half);
        }
        if let Some(parent) = self.tree.parent(split.node) {
            self.refresh(parent);
        }
    }

    fn merge(&mut self, node: u32) {
        let estimate = self.predictor.estimate(self.tree.node(node).rect);
        self.tree.merge(node, estimate);
        self.refresh(node);
        if let Some(parent) = self.tree.parent(node) {
            self.refresh(parent);
        }
    }

    /// The estimates of splittable leaf `node`'s halves.
    fn halves(&self, node: u32) -> [f64; 2] {
        // Invariant: only splittable leaves, of two or more pixels, are asked for their halves.
        let (a, b) = self
            .tree
            .node(node)
            .rect
            .halves()
            .expect("split candidates have 2+ pixels");
        [self.predictor.estimate(a), self.predictor.estimate(b)]
    }

    /// Invalidates `node`'s old entries and files it as whatever candidate it now is.
    fn refresh(&mut self, node: u32) {
        self.tree.bump(node);
        if self.tree.splittable(node) {
            self.splits
                .push(Entry::optimistic(self.tree, node, self.scale));
        } else if self.tree.mergeable(node) {
            self.merges
                .push(Reverse(Entry::merge(self.tree, node, self.scale)));
        }
    }
}

/// A heap entry. Ordered by key, then by node index, so that pops are deterministic.
#[derive(Clone, Copy, Debug)]
struct Entry {
    key: f64,
    node: u32,
    generation: u32,
    /// For split entries: whether `key` is the halves' product rather than its upper bound.
    exact: bool,
}

impl Entry {
    /// A split entry keyed by the bound `(a / 2)^2` on the halves' product.
    fn optimistic(tree: &Tree, node: u32, scale: f64) -> Entry {
        let half = 0.5 * tree.node(node).estimate * scale;
        Entry {
            key: half * half,
            node,
            generation: tree.node(node).generation,
            exact: false,
        }
    }

    /// A merge entry keyed by the product of the two leaf children's estimates.
    fn merge(tree: &Tree, node: u32, scale: f64) -> Entry {
        // Invariant: merge entries are only made for mergeable nodes, which have children.
        let [a, b] = tree.children(node).expect("merge candidates have children");
        let key = (tree.node(a).estimate * scale) * (tree.node(b).estimate * scale);
        Entry {
            key,
            node,
            generation: tree.node(node).generation,
            exact: true,
        }
    }
}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        self.key
            .total_cmp(&other.key)
            .then_with(|| other.node.cmp(&self.node))
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Entry {}
