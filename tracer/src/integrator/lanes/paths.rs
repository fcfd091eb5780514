//! The lanes' paths: the knob that chooses lanes or one path at a time ([`PathLanes`]), the
//! feed the lanes take their paths from and hand them back to ([`PathFeed`]), and each lane's
//! state between bounces ([`Paths`]).

use super::LANES;
use super::shade::Points;
use crate::geometry::{Hit, Ray, SetUpRows, UNUSED_RAY};
use crate::integrator::PathStats;
use crate::sampler::PixelSampler;
use glam::Vec3;

/// How a tile's paths are advanced (a comparison knob: both give the same bits).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum PathLanes {
    /// Eight paths a bounce at a time, their shading in vector instructions, where the
    /// world allows it ([`World::lanes_fit`](crate::World::lanes_fit)); one by one
    /// elsewhere.
    #[default]
    Lanes,
    /// One path after another, each bounce by bounce.
    OneByOne,
}

impl PathLanes {
    /// Both ways, the default first.
    pub const ALL: [PathLanes; 2] = [PathLanes::Lanes, PathLanes::OneByOne];

    /// The name in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            PathLanes::Lanes => "lanes",
            PathLanes::OneByOne => "one-by-one",
        }
    }
}

/// A lane's slots for a new path, which [`PathFeed::next_path`] fills in place (returned by
/// value, a path's start went through narrow stores read back by wider loads, a stall the
/// processor cannot forward).
pub(crate) struct NewPath<'a> {
    /// The camera ray.
    pub ray: &'a mut Ray,
    /// The camera ray's closest hit in the still tree, where the feed found it already (a camera
    /// packet; the lane asks its moving objects after).
    pub first: &'a mut Option<Option<Hit>>,
    /// The sample's numbers, the camera's already drawn.
    pub sampler: &'a mut PixelSampler,
    /// The sample's time, where the path's moving objects are (frames).
    pub time: &'a mut f64,
    /// The work the lane has counted since the feed last took it: a lane's paths go on
    /// counting into it, and the feed takes it where the new path's work goes elsewhere (to
    /// another block of the cost map) and when it has no more paths, so that the lanes
    /// neither clear a lane's counts at every path nor hand them over at every end (a path's
    /// 104 bytes of counts, stored in eight-byte steps and read back in wider ones, a stall
    /// the processor cannot forward).
    pub stats: &'a mut PathStats,
    /// Which block of the feed's `stats` were counted for (the feed's own mark), or
    /// [`NOT_COUNTED`] where the lane owes none.
    pub counted_for: &'a mut u32,
}

/// What a lane's [`NewPath::counted_for`] holds where it owes the feed no work.
pub(crate) const NOT_COUNTED: u32 = u32::MAX;

/// Where [`World::radiance_stream`](crate::World::radiance_stream)'s paths come from and where
/// their results go.
pub(crate) trait PathFeed {
    /// Fills `lane` with the next path to render and returns the feed's name for it, or
    /// `None` when there are no more; either way takes the lane's counted work
    /// ([`NewPath::stats`]) where the new path's is not the feed's to add to it, and always
    /// when there are no more paths, so that none is left in the lanes.
    fn next_path(&mut self, lane: NewPath<'_>) -> Option<u64>;
    /// The radiance of the path named `tag`, as it ends (paths end in any order).
    fn path_done(&mut self, tag: u64, radiance: Vec3);
}

/// The lanes' paths, a value of every lane at a time: the state the scalar path keeps in its
/// locals. The last scattering's density, whether it was a delta and where it was are three
/// arrays rather than one of tuples: a 17-byte tuple's copies went through unaligned,
/// overlapping stores the processor could not forward (docs/bench.md, issue 12,
/// thirty-second round).
pub(super) struct Paths {
    pub(super) alive: [bool; LANES],
    pub(super) tag: [u64; LANES],
    pub(super) ray: [Ray; LANES],
    pub(super) first: [Option<Option<Hit>>; LANES],
    pub(super) sampler: [PixelSampler; LANES],
    pub(super) time: [f64; LANES],
    pub(super) depth: [u32; LANES],
    pub(super) beta: Points,
    pub(super) radiance: [Vec3; LANES],
    pub(super) last_pdf: [f32; LANES],
    pub(super) last_delta: [bool; LANES],
    pub(super) last_point: [Vec3; LANES],
    /// The closest hit of the lane's current ray, between its walk and its surface.
    pub(super) hit: [Hit; LANES],
    /// The walks' set-ups of the lanes' next rays, made after the shading, and whether the
    /// lane's current ray is the one its set-up was made for (not a new path's camera ray).
    pub(super) set_up: SetUpRows,
    pub(super) set_up_ready: [bool; LANES],
    /// Each lane's counted work since its feed last took it, and the feed's mark for it
    /// ([`NewPath::stats`]).
    pub(super) stats: [PathStats; LANES],
    pub(super) counted_for: [u32; LANES],
}

impl Default for Paths {
    fn default() -> Self {
        Paths {
            alive: [false; LANES],
            tag: [0; LANES],
            ray: [UNUSED_RAY; LANES],
            first: [None; LANES],
            sampler: std::array::from_fn(|_| PixelSampler::placeholder()),
            time: [0.0; LANES],
            depth: [0; LANES],
            beta: Points::default(),
            radiance: [Vec3::ZERO; LANES],
            last_pdf: [0.0; LANES],
            last_delta: [true; LANES],
            last_point: [Vec3::ZERO; LANES],
            hit: [Hit {
                t: 0.0,
                triangle: 0,
                b1: 0.0,
                b2: 0.0,
            }; LANES],
            set_up: SetUpRows::default(),
            set_up_ready: [false; LANES],
            stats: [PathStats::default(); LANES],
            counted_for: [NOT_COUNTED; LANES],
        }
    }
}

impl Paths {
    /// Starts the feed's next path in lane `i`, as the scalar path starts a camera ray (the
    /// camera counts as a delta); `false` where the feed has none.
    #[inline(always)]
    pub(super) fn admit(&mut self, i: usize, feed: &mut impl PathFeed) -> bool {
        let lane = NewPath {
            ray: &mut self.ray[i],
            first: &mut self.first[i],
            sampler: &mut self.sampler[i],
            time: &mut self.time[i],
            stats: &mut self.stats[i],
            counted_for: &mut self.counted_for[i],
        };
        let Some(tag) = feed.next_path(lane) else {
            return false;
        };
        self.alive[i] = true;
        self.tag[i] = tag;
        self.set_up_ready[i] = false;
        self.depth[i] = 0;
        self.beta.set(i, Vec3::ONE);
        self.radiance[i] = Vec3::ZERO;
        (self.last_pdf[i], self.last_delta[i], self.last_point[i]) =
            (0.0, true, self.ray[i].origin);
        true
    }

    /// Lane `i`'s last scattering as the scalar path's helpers take it: its density, whether
    /// it was a delta, and where it was.
    #[inline(always)]
    pub(super) fn last(&self, i: usize) -> (f32, bool, Vec3) {
        (self.last_pdf[i], self.last_delta[i], self.last_point[i])
    }

    /// Ends lane `i`'s path and hands its result over.
    #[inline(always)]
    pub(super) fn end(&mut self, i: usize, feed: &mut impl PathFeed) {
        self.alive[i] = false;
        feed.path_done(self.tag[i], self.radiance[i]);
    }
}
