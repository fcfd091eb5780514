//! The acceleration structure: a binary BVH built by obvhs and traversed by our own code.
//!
//! Why split the work this way: obvhs builds good trees fast (PLOC, reinsertion, leaf collapse),
//! but its traversal is tuned for speed, not for the guarantees a path tracer's tests rely on. Its
//! ray replaces tiny direction components by `1/f32::EPSILON`, its slab test has no error margin
//! and can cull a box on rounding alone, and its triangle test is Moller-Trumbore, which lets
//! rays slip between triangles sharing an edge. Our traversal (in `traverse.rs`) walks the same
//! `Bvh2` nodes with a conservative slab test and the watertight triangle test, so a ray never
//! misses a closed mesh and the BVH answers exactly as brute force over all triangles would.
//! obvhs's own traversal stays available ([`Traversal::Obvhs`]) so that the difference can be
//! measured on the same tree.
//!
//! The tree is deterministic: the same triangles and quality give the same tree (see `build.rs`).

use super::build::{build_bvh2, tree_depth};
use super::memory::on_huge_pages;
use super::offset::plane_normal;
use super::triangle::is_degenerate;
use super::wide::{BoxSimd, Bvh8, SetUp};
use super::{Hit, Ray, TraversalStats};
use crate::scene::Triangle;
use glam::{Vec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::bvh2::Bvh2;

/// How much time to spend building the tree, mapped to obvhs's presets. Slower builds give
/// trees that are cheaper to trace, but little: on the 871k-triangle Cornell dragon, random rays
/// from inside the box cost 22.7 box and 3.5 triangle tests each with a `Medium` tree (0.5 s to
/// build on one core), and 22.0 and 3.3 with a `VerySlow` one (6 s). Hence the default.
///
/// | quality    | obvhs preset        | PLOC search | reinsertion | spatial pre-splits |
/// |------------|---------------------|-------------|-------------|--------------------|
/// | `Fastest`  | `very_fast_build()` | minimum     | 1%          | no                 |
/// | `Fast`     | `fast_build()`      | low         | 2%          | no                 |
/// | `Medium`   | `medium_build()`    | medium      | 5% + 10%    | yes (ours)         |
/// | `Slow`     | `slow_build()`      | high        | 20% + 40%   | yes                |
/// | `VerySlow` | `very_slow_build()` | medium      | 100% + 100% | yes                |
///
/// obvhs's `fastest_build()` (one triangle per leaf, no reinsertion) is not offered: on the
/// dragon it saved 0.1 s of build time over `very_fast_build()` and made closest-hit rays 30%
/// and shadow rays 60% slower.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum BuildQuality {
    /// obvhs's `very_fast_build()`: the least build time, the most traversal work.
    Fastest,
    /// obvhs's `fast_build()`.
    Fast,
    /// obvhs's `medium_build()` with its spatial pre-splits turned on: the default, nearly the
    /// very slow build's tree at a twelfth of its time (the table above). Pre-splits cut only
    /// triangles whose boxes are large against the scene's average, so they leave trees of
    /// even meshes (the Cornell scenes, the dragon) as they were and cost no measurable build
    /// time, and they cut Sponza's long floor and wall triangles: 10% fewer box tests and 7%
    /// fewer triangle tests per ray there (docs/bench.md, issue 12, ninth round).
    #[default]
    Medium,
    /// obvhs's `slow_build()`, with spatial pre-splits of large triangles.
    Slow,
    /// obvhs's `very_slow_build()`: full reinsertion and pre-splits, for comparison.
    VerySlow,
}

impl BuildQuality {
    /// Every quality, fastest build first: the ladder `tessera accuracy --knobs bvh` walks.
    pub const ALL: [BuildQuality; 5] = [
        BuildQuality::Fastest,
        BuildQuality::Fast,
        BuildQuality::Medium,
        BuildQuality::Slow,
        BuildQuality::VerySlow,
    ];

    /// The obvhs build parameters this quality stands for.
    pub fn params(self) -> BvhBuildParams {
        match self {
            BuildQuality::Fastest => BvhBuildParams::very_fast_build(),
            BuildQuality::Fast => BvhBuildParams::fast_build(),
            BuildQuality::Medium => BvhBuildParams {
                pre_split: true,
                ..BvhBuildParams::medium_build()
            },
            BuildQuality::Slow => BvhBuildParams::slow_build(),
            BuildQuality::VerySlow => BvhBuildParams::very_slow_build(),
        }
    }
}

/// Which code walks the tree and tests triangles.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Traversal {
    /// Ours: conservative slab test (Ize 2013, pbrt-v4) and the watertight triangle test, over
    /// the binary tree collapsed into 8-wide nodes whose boxes are tested together (`wide.rs`).
    /// What the renderer uses.
    #[default]
    Robust,
    /// The same tests over obvhs's binary tree, two boxes per node: the traversal `Robust`
    /// replaced, kept to show that the wide one finds the same hits, bit for bit, and what
    /// it saves.
    RobustBinary,
    /// obvhs's `Bvh2` traversal with its `Ray` and Moller-Trumbore `Triangle::intersect`, for
    /// accuracy and speed comparisons. Its `TraversalStats::nodes` counts only the leaves obvhs
    /// hands back (it does not expose its inner-node tests), so compare triangle counts only.
    Obvhs,
}

impl Traversal {
    /// Every traversal, the default first: the ladder `tessera accuracy --knobs traversal`
    /// walks.
    pub const ALL: [Traversal; 3] = [Traversal::Robust, Traversal::RobustBinary, Traversal::Obvhs];
}

/// A BVH over a scene's triangles: the wide tree the renderer walks, with the triangles'
/// vertices copied into its leaves, and, where built by [`Accel::build`] (until
/// [`Accel::release_binary_tree`]), the binary tree it was collapsed from.
#[derive(Clone)]
pub struct Accel {
    /// The binary tree and its leaves' vertices: what the comparison traversals
    /// ([`Traversal::RobustBinary`], [`Traversal::Obvhs`]) and a tree too deep for the wide
    /// walk's stack walk. `None` once released.
    pub(super) binary: Option<BinaryTree>,
    /// Number of the binary tree's nodes (inner nodes and leaves), kept past its release.
    node_count: usize,
    /// Number of leaf entries, kept past the binary tree's release.
    leaf_entries: usize,
    /// Number of levels of the binary tree (a lone leaf is 1); bounds its traversal stack.
    pub(super) depth: usize,
    /// The same tree collapsed into 8-wide nodes, over the same leaves: what `Robust` walks.
    pub(super) wide: Bvh8,
    /// For every input triangle, degenerate ones included, by input index: its [`plane_normal`]
    /// (f64) and its `area_vector().normalize()` (f32, NaN without area), computed once here
    /// rather than at every hit, side by side so that a hit reads one cache line for both.
    pub(super) normals: Vec<[Vec3; 2]>,
    /// The caller's arrays, indexed by input triangle, that it reads at every closest hit (the
    /// integrator's `Triangle`, with its material, and the triangle's texture coordinates and
    /// normals), each as the address of the first and the size of one, set by
    /// [`Accel::prefetch_at_hits`]. Only ever prefetched, never read: a stale address costs a
    /// wasted hint, never a wrong value.
    pub(super) hit_records: [Option<(usize, usize)>; 2],
    /// The quality the tree was built with, for a rebuild that must give the same tree.
    quality: BuildQuality,
}

/// obvhs's binary tree, with the vertices and input triangle of each leaf entry in its leaf
/// order (leaf `first_index .. first_index + prim_count` indexes both). With spatial
/// pre-splits a triangle can appear in several leaves.
#[derive(Clone, Default)]
pub(super) struct BinaryTree {
    pub(super) bvh: Bvh2,
    pub(super) vertices: Vec<[Vec3; 3]>,
    pub(super) original: Vec<u32>,
}

impl Accel {
    /// Builds the BVH, keeping the binary tree for every [`Traversal`]. Degenerate triangles
    /// ([`is_degenerate`]) are left out, as they can never be hit; with no triangle left every
    /// ray misses.
    pub fn build(triangles: &[Triangle], quality: BuildQuality) -> Accel {
        Self::build_keeping(triangles, quality, true)
    }

    /// The tree a world renders with: what [`Accel::build`] and then
    /// [`Accel::release_binary_tree`] leave (the same wide tree, the binary tree kept only where
    /// the wide walk needs it), without ever holding the binary tree beside the wide one. The
    /// binary tree is freed as soon as it is collapsed, and its copy of the leaves' vertices is
    /// never made (the collapse reads them from `triangles`): on the Cornell dragon both sat
    /// beside the wide tree's arrays at the process's peak memory (docs/bench.md, issue 12,
    /// thirty-fourth round).
    pub fn build_for_rendering(triangles: &[Triangle], quality: BuildQuality) -> Accel {
        Self::build_keeping(triangles, quality, false)
    }

    /// The build, keeping the binary tree where `keep_binary` asks or the wide walk needs it.
    fn build_keeping(triangles: &[Triangle], quality: BuildQuality, keep_binary: bool) -> Accel {
        let kept: Vec<u32> = (0..triangles.len())
            .filter(|&i| !is_degenerate(&triangles[i].p))
            .map(|i| u32::try_from(i).expect("fewer than 2^32 triangles: Hit::triangle is a u32"))
            .collect();
        // Made after the binary tree, whose build sets the process's peak memory.
        let normals = || -> Vec<[Vec3; 2]> {
            triangles
                .iter()
                .map(|t| [plane_normal(&t.p), t.area_vector().normalize()])
                .collect()
        };
        if kept.is_empty() {
            return Accel {
                // An empty tree always fits the wide walk's stack: kept only where asked.
                binary: keep_binary.then(BinaryTree::default),
                node_count: 0,
                leaf_entries: 0,
                depth: 0,
                wide: Bvh8::default(),
                normals: normals(),
                hit_records: [None; 2],
                quality,
            };
        }
        let shapes: Vec<obvhs::triangle::Triangle> = kept
            .iter()
            .map(|&i| {
                let [v0, v1, v2] = triangles[i as usize].p.map(Vec3A::from);
                obvhs::triangle::Triangle { v0, v1, v2 }
            })
            .collect();
        let mut bvh = build_bvh2(shapes, quality.params());
        let depth = tree_depth(&bvh);
        // obvhs sizes its own traversal stack from max_depth, which reinsertion may outgrow.
        bvh.max_depth = bvh.max_depth.max(depth);
        let original: Vec<u32> = bvh
            .primitive_indices
            .iter()
            .map(|&k| kept[k as usize])
            .collect();
        drop(kept);
        let vertices_of = |i: u32| triangles[i as usize].p;
        let mut wide = Bvh8::collapse(&bvh, &original, vertices_of);
        let (node_count, leaf_entries) = (bvh.nodes.len(), original.len());
        let binary = (keep_binary || !wide.walkable()).then(|| {
            let vertices = original.iter().map(|&i| vertices_of(i)).collect();
            BinaryTree {
                bvh,
                vertices,
                original,
            }
        });
        // What the renderer's traversal and hits read, at random on large meshes.
        wide.nodes = on_huge_pages(wide.nodes);
        wide.quads = on_huge_pages(wide.quads);
        Accel {
            node_count,
            leaf_entries,
            binary,
            depth,
            wide,
            normals: on_huge_pages(normals()),
            hit_records: [None; 2],
            quality,
        }
    }

    /// Frees the binary tree and its copy of the leaves' vertices (on the Cornell dragon 45 MB
    /// of the 255 MB the scene keeps), where the wide walk alone answers every query: the
    /// renderer's traversal ([`Traversal::Robust`]) walks the wide tree, which holds its own
    /// copy of the vertices. Kept where the wide walks do not take the tree (`Bvh8::walkable`:
    /// too deep for their stack, or too large for the children's references), which is then
    /// walked through the binary tree. Returns whether it was freed; after that the comparison
    /// traversals are unavailable (asking for one panics) until a rebuild, which
    /// [`crate::integrator::World::set_traversal`] makes.
    pub fn release_binary_tree(&mut self) -> bool {
        if !self.wide.walkable() {
            return false;
        }
        self.binary = None;
        true
    }

    /// Whether the binary tree is here, so that every [`Traversal`] can walk it.
    pub fn has_binary_tree(&self) -> bool {
        self.binary.is_some()
    }

    /// The quality the tree was built with: a build of the same triangles at this quality
    /// gives the same tree.
    pub fn quality(&self) -> BuildQuality {
        self.quality
    }

    /// Moves the binary tree's leaf arrays onto huge pages, as the wide tree's are, for a
    /// comparison traversal that walks it ([`crate::integrator::World::set_traversal`]): the
    /// build leaves them where they are, since a world frees them.
    pub fn binary_tree_on_huge_pages(&mut self) {
        if let Some(tree) = &mut self.binary {
            tree.vertices = on_huge_pages(std::mem::take(&mut tree.vertices));
            tree.original = on_huge_pages(std::mem::take(&mut tree.original));
        }
    }

    /// The binary tree, for the traversals that walk it.
    #[inline(always)]
    pub(super) fn binary_tree(&self) -> &BinaryTree {
        self.binary.as_ref().expect(
            "a comparison traversal (RobustBinary, Obvhs) on an Accel whose binary tree was \
             released: World::set_traversal builds it again, Accel::build keeps it",
        )
    }

    /// The unit plane normal of input triangle `triangle`, as [`plane_normal`] computes it, for
    /// [`crate::geometry::SurfacePoint::on_triangle_with_normal`].
    #[inline]
    pub fn plane_normal(&self, triangle: u32) -> Vec3 {
        self.normals[triangle as usize][0]
    }

    /// Input triangle `triangle`'s `area_vector().normalize()`, as computed once at build.
    #[inline]
    pub fn unit_normal(&self, triangle: u32) -> Vec3 {
        self.normals[triangle as usize][1]
    }

    /// The closest hit in `(0, ray.t_max)`, by our robust traversal. Ties in `t` go to the lower
    /// triangle index.
    pub fn intersect(&self, ray: &Ray, stats: &mut TraversalStats) -> Option<Hit> {
        self.intersect_with(ray, Traversal::Robust, stats)
    }

    /// Whether anything is certainly hit in `(0, ray.t_max)`: at a `t` whose error bound keeps
    /// it below `t_max`. Stops at the first such hit. Why not every hit below `t_max`: a shadow
    /// ray ends a few ULPs in front of the light it aims at, and the rounding of `t` could
    /// otherwise report the light itself, or its neighbour, as blocking (see `offset.rs`).
    pub fn occluded(&self, ray: &Ray, stats: &mut TraversalStats) -> bool {
        self.occluded_with(ray, Traversal::Robust, stats)
    }

    /// [`Accel::intersect`] by the chosen traversal.
    ///
    /// # Panics
    /// With a comparison traversal on an `Accel` whose binary tree was released
    /// ([`Accel::release_binary_tree`]).
    #[inline]
    pub fn intersect_with(
        &self,
        ray: &Ray,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        self.closest_with::<false>(ray, None, traversal, stats)
    }

    /// [`Accel::intersect_with`], with the walk's set-up made ahead where `set_up` says so:
    /// lane `r` of rows made with this very ray as their ray `r` (any other lane's set-up
    /// walks another ray). The same hit and counts, bit for bit; the comparison traversals
    /// make their own set-up.
    #[inline]
    pub(crate) fn intersect_from(
        &self,
        ray: &Ray,
        set_up: SetUp<'_>,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        self.closest_with::<false>(ray, set_up, traversal, stats)
    }

    /// The closest hit among those a shadow ray must respect: [`Accel::intersect_with`] whose
    /// first accepted hit must be *certain*, as [`Accel::occluded_with`] counts it, so that
    /// `intersect_certain_with(..).is_some() == occluded_with(..)` to the bit. Transmittance
    /// along shadow rays needs the closest blocker (to see whether it is a boundary the ray may
    /// pass), where occlusion needs only any. obvhs's traversal has no certainty rule, for
    /// either query, so it gives its plain closest hit.
    /// Panics as [`Accel::intersect_with`] does.
    #[inline]
    pub fn intersect_certain_with(
        &self,
        ray: &Ray,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        self.closest_with::<true>(ray, None, traversal, stats)
    }

    /// The closest hit by `traversal`, whose first accepted hit must be certain with `CERTAIN`.
    /// Inlined, with the traversals it picks from kept out of line, so that the renderer's wide
    /// traversal hands its hit back in registers (`wide.rs`, `PackedHit`).
    #[inline(always)]
    fn closest_with<const CERTAIN: bool>(
        &self,
        ray: &Ray,
        set_up: SetUp<'_>,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) -> Option<Hit> {
        match traversal {
            Traversal::Robust => self.traverse_wide::<false, CERTAIN>(ray, set_up, stats),
            Traversal::RobustBinary => self.traverse_robust::<false, CERTAIN>(ray, stats),
            Traversal::Obvhs => self.traverse_obvhs::<false>(ray, stats),
        }
    }

    /// [`Accel::occluded`] by the chosen traversal.
    /// Panics as [`Accel::intersect_with`] does.
    pub fn occluded_with(
        &self,
        ray: &Ray,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) -> bool {
        self.occluded_from(ray, None, traversal, stats)
    }

    /// [`Accel::occluded_with`], with the walk's set-up made ahead where `set_up` says so, as
    /// [`Accel::intersect_from`] takes it.
    #[inline(always)]
    pub(crate) fn occluded_from(
        &self,
        ray: &Ray,
        set_up: SetUp<'_>,
        traversal: Traversal,
        stats: &mut TraversalStats,
    ) -> bool {
        match traversal {
            Traversal::Robust => self
                .traverse_wide::<true, true>(ray, set_up, stats)
                .is_some(),
            Traversal::RobustBinary => self.traverse_robust::<true, true>(ray, stats).is_some(),
            Traversal::Obvhs => self.traverse_obvhs::<true>(ray, stats).is_some(),
        }
    }

    /// The instructions the wide traversal tests boxes and triangles with: AVX where this
    /// processor has it.
    pub fn box_simd(&self) -> BoxSimd {
        self.wide.simd
    }

    /// Makes the wide traversal test boxes and triangles with `simd`, if this processor runs
    /// it (returns whether it does; if not, nothing changes). Every choice finds the same hits,
    /// bit for bit, and counts the same work: a knob for tests and speed comparisons, not for
    /// images.
    pub fn set_box_simd(&mut self, simd: BoxSimd) -> bool {
        let runs = match simd {
            BoxSimd::Sse => true,
            BoxSimd::Avx => super::node8::avx_available(),
        };
        if runs {
            self.wide.simd = simd;
        }
        runs
    }

    /// Number of tree nodes (inner nodes and leaves).
    pub fn node_count(&self) -> usize {
        self.node_count
    }

    /// Number of levels of the tree; 0 when it is empty.
    pub fn depth(&self) -> usize {
        self.depth
    }

    /// Number of leaf entries: the non-degenerate triangles, plus duplicates made by spatial
    /// pre-splits.
    pub fn leaf_entries(&self) -> usize {
        self.leaf_entries
    }
}

impl std::fmt::Debug for Accel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Accel")
            .field("nodes", &self.node_count())
            .field("leaf_entries", &self.leaf_entries())
            .field("depth", &self.depth)
            .finish()
    }
}

#[cfg(test)]
mod tests;
