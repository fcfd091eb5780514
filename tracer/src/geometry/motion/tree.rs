//! A tree over the moving objects' swept boxes: which objects a ray at a given time may meet,
//! found in time logarithmic in their number rather than by testing every object's box.
//!
//! Its leaves are keyframe segments: one per object and segment, with the segment's swept box
//! ([`SweptBox`]) and the times that fall in it. An inner node holds the union of its
//! children's boxes with the largest of their padding terms, and the span of their times. The
//! test of a ray against a node is then never stricter than against any leaf below it: the
//! padded box contains theirs, and every step of [`SweptBox::may_hit`] (the subtractions,
//! the products with the ray's reciprocal direction and the comparisons of the slab test, each
//! rounded) is monotone in the box's planes and padding. So the tree finds every object whose
//! own box the ray passes at its time, and no other; it only spares the tests of the boxes it
//! does not pass.
//!
//! The walk ([`ObjectTree::walk`]) hands the objects it finds to a visitor as it goes, nearer
//! half first by the ray's direction, and the visitor answers with the distance still worth
//! searching: a closest-hit query that has found a hit prunes what lies beyond it. What it may
//! not do is let the order decide a result: see [`MotionAccel::closest`](super::MotionAccel::closest),
//! which makes the closest hit the one of least distance, then least triangle index, whatever
//! the order, and gathers a shadow query's candidates to try them in object order.
//!
//! Built by splitting at the median of the segments along x, y, z or time, whichever leaves
//! halves least likely to be entered (surface area times time span times count): a scene moves
//! tens or thousands of objects, not millions, and each node must carry the padding and the
//! time span that a general-purpose builder (obvhs's) has no place for.

use super::bounds::{SweptBox, SweptRay};
use crate::scene::TransformTrack;
use smallvec::SmallVec;

/// Most segments in one leaf: a leaf's boxes are tested in turn, a node's two children too.
const LEAF_SIZE: usize = 2;

/// Up to this many objects a ray tests each one's box of its time in turn, as the tracer did
/// before the tree, which costs fewer box tests than a tree over their segments (one per
/// object and keyframe segment).
pub(super) const FLAT_OBJECTS: usize = 8;

/// Objects (with their segment) a query gathers without allocating; more spill to the heap.
pub(super) type Candidates = SmallVec<[(u32, u32); 16]>;

/// The tree; empty when nothing moves.
#[derive(Clone, Debug, Default)]
pub(super) struct ObjectTree {
    /// Depth-first: a node's first child follows it, its second at `second`.
    nodes: Vec<Node>,
    /// The leaves' segments, each leaf's a run of this.
    segments: Vec<Segment>,
}

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: SweptBox,
    /// The earliest and latest times of any segment below, inclusive: a conservative filter;
    /// a leaf's segment decides exactly by its object's track.
    earliest: f64,
    latest: f64,
    kind: Kind,
}

#[derive(Clone, Copy, Debug)]
enum Kind {
    /// The second child's index, and the axis the children were split along.
    Inner {
        second: u32,
        axis: u8,
    },
    Leaf {
        first: u32,
        count: u32,
    },
}

/// One keyframe segment of one object.
#[derive(Clone, Copy, Debug)]
struct Segment {
    object: u32,
    segment: u32,
    bounds: SweptBox,
    earliest: f64,
    latest: f64,
}

impl ObjectTree {
    /// The tree over every segment of every object, given each object's track and its swept
    /// boxes (one per segment, as [`super::bounds::swept_bounds`] makes them).
    pub(super) fn build<'a>(
        objects: impl Iterator<Item = (&'a TransformTrack, &'a [SweptBox])>,
    ) -> Self {
        let mut segments: Vec<Segment> = objects
            .enumerate()
            .flat_map(|(object, (track, boxes))| {
                boxes.iter().enumerate().map(move |(segment, &bounds)| {
                    let (earliest, latest) = times(track, segment);
                    Segment {
                        object: u32::try_from(object).expect("fewer than 2^32 moving objects"),
                        segment: u32::try_from(segment).expect("fewer than 2^32 keys"),
                        bounds,
                        earliest,
                        latest,
                    }
                })
            })
            .collect();
        let mut tree = ObjectTree::default();
        let objects = segments.last().map_or(0, |s| s.object as usize + 1);
        // Up to FLAT_OBJECTS objects there is no tree: see `is_flat`.
        if objects > FLAT_OBJECTS {
            // What the build weighs a node's time span by: its share of the keys' range, a
            // frame wider each way, so that the holds before the first key and after the last
            // count as a frame each rather than as forever.
            let finite = segments
                .iter()
                .flat_map(|s| [s.earliest, s.latest])
                .filter(|t| t.is_finite());
            let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), t| {
                (lo.min(t), hi.max(t))
            });
            let window = (lo - 1.0, hi + 1.0);
            let count = segments.len();
            tree.split(&mut segments, 0, count, window);
        }
        tree.segments = segments;
        tree
    }

    /// Whether there is no tree: a ray then tests each object's box of its time in turn.
    pub(super) fn is_flat(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Calls `visit(object, segment)` for every object whose box for its segment at `time`
    /// (`segment_of(object)`) `ray` may meet by the current bound (inclusive), each once; the
    /// bound starts at `t_max` and is what `visit` last returned; one below zero ends the
    /// walk. `tested` counts the boxes tested.
    pub(super) fn walk(
        &self,
        ray: &SweptRay,
        mut t_max: f32,
        time: f64,
        segment_of: impl Fn(usize) -> usize,
        mut visit: impl FnMut(u32, u32) -> f32,
        tested: &mut u64,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack: SmallVec<[u32; 32]> = SmallVec::new();
        stack.push(0);
        while let Some(index) = stack.pop() {
            let node = &self.nodes[index as usize];
            *tested += 1;
            // Written as negations so that a time that compares with nothing goes on down.
            if time < node.earliest || time > node.latest || !node.bounds.may_hit(ray, t_max) {
                continue;
            }
            match node.kind {
                Kind::Inner { second, axis } => {
                    // The half of lower centres along a split axis of space is nearer to a ray
                    // going up that axis: it goes on top. (Split in time, one half is
                    // usually passed over at once.)
                    let (near, far) = if axis < 3 && ray.goes_down(axis as usize) {
                        (second, index + 1)
                    } else {
                        (index + 1, second)
                    };
                    stack.push(far);
                    stack.push(near);
                }
                Kind::Leaf { first, count } => {
                    for segment in &self.segments[first as usize..(first + count) as usize] {
                        if segment_of(segment.object as usize) == segment.segment as usize
                            && (count == 1 || segment.bounds.may_hit(ray, t_max))
                        {
                            t_max = visit(segment.object, segment.segment);
                            if t_max < 0.0 {
                                return;
                            }
                        }
                    }
                }
            }
        }
    }

    /// Builds the subtree over `segments[start..end]`, reordering them, and returns its index.
    /// `window` is the time range spans are weighed within (see `build`).
    fn split(
        &mut self,
        segments: &mut [Segment],
        start: usize,
        end: usize,
        window: (f64, f64),
    ) -> u32 {
        let here = &mut segments[start..end];
        let (bounds, earliest, latest) = enclose(here);
        let index = u32::try_from(self.nodes.len()).expect("fewer than 2^32 tree nodes");
        let leaf = Kind::Leaf {
            first: start as u32,
            count: (end - start) as u32,
        };
        self.nodes.push(Node {
            bounds,
            earliest,
            latest,
            kind: leaf,
        });
        if end - start <= LEAF_SIZE {
            return index;
        }
        // The median along one of the three axes or time, whichever leaves halves that rays
        // are least likely to enter: each half's surface area times the share of the window
        // its times span (a ray at one time enters one half of a split in time), times the
        // segments it holds.
        let middle = here.len() / 2;
        let cost = |here: &mut [Segment], axis: usize| {
            here.select_nth_unstable_by(middle, |a, b| {
                centre(a, axis, window).total_cmp(&centre(b, axis, window))
            });
            let (left, right) = here.split_at(middle);
            let weigh = |half: &[Segment]| {
                let (bounds, earliest, latest) = enclose(half);
                let span = (latest.min(window.1) - earliest.max(window.0)) / (window.1 - window.0);
                f64::from(bounds.area()) * span.max(1e-6) * half.len() as f64
            };
            weigh(left) + weigh(right)
        };
        let axis = (0..4)
            .map(|axis| (axis, cost(here, axis)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("four axes")
            .0;
        cost(here, axis);
        self.split(segments, start, start + middle, window);
        let second = self.split(segments, start + middle, end, window);
        self.nodes[index as usize].kind = Kind::Inner {
            second,
            axis: axis as u8,
        };
        index
    }
}

/// The box holding `segments`' boxes, and the earliest and latest of their times.
fn enclose(segments: &[Segment]) -> (SweptBox, f64, f64) {
    let (first, rest) = segments.split_first().expect("a node holds segments");
    rest.iter().fold(
        (first.bounds, first.earliest, first.latest),
        |(bounds, earliest, latest), s| {
            (
                bounds.union(&s.bounds),
                earliest.min(s.earliest),
                latest.max(s.latest),
            )
        },
    )
}

/// Where a segment lies along `axis`: its box's centre (doubled) for the axes of space, the
/// middle of its times within `window` for time (axis 3).
fn centre(s: &Segment, axis: usize, window: (f64, f64)) -> f64 {
    match axis {
        3 => s.earliest.max(window.0) + s.latest.min(window.1),
        axis => f64::from(s.bounds.min[axis]) + f64::from(s.bounds.max[axis]),
    }
}

/// The times `track` puts in `segment`, as [`TransformTrack::segment`] assigns them: before the
/// first key for segment 0, from the last key on for the last, between two keys otherwise.
fn times(track: &TransformTrack, segment: usize) -> (f64, f64) {
    let keys = track.keys();
    let earliest = match segment {
        0 => f64::NEG_INFINITY,
        s => f64::from(keys[s - 1].frame),
    };
    let latest = keys
        .get(segment)
        .map_or(f64::INFINITY, |key| f64::from(key.frame));
    (earliest, latest)
}
