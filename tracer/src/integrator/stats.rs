//! Per-sample counters: the counted work that becomes a tile's cost, and what the tests read
//! to see that absent effects cost nothing.

use crate::geometry::TraversalStats;

/// Per-sample counters: the counted work that becomes a tile's cost, and the effect counters the
/// tests read to check that absent effects cost nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PathStats {
    /// BVH nodes and triangles the traversals of closest-hit and shadow rays visited.
    pub traversal: TraversalStats,
    /// Closest-hit rays (camera and bounce rays).
    pub rays: u64,
    /// Of those, the ones that hit a surface (and were shaded); the rest escaped.
    pub hits: u64,
    /// Occlusion rays towards sampled lights (and the closest-hit queries that stand in for
    /// them where shadows cross interfaces).
    pub shadow_rays: u64,
    /// Lights sampled by next-event estimation (each may or may not need a shadow ray).
    pub light_samples: u64,
    /// BSDF samples that crossed a surface (refraction through glass).
    pub refractions: u64,
    /// Escaped rays that looked up the environment.
    pub environment_lookups: u64,
    /// Samples whose radiance came out non-finite and were dropped (a bug if ever non-zero).
    pub invalid_samples: u64,
    /// Free flights sampled through a medium (one per ray where media are tracked, vacuum
    /// included).
    pub flights: u64,
    /// Of those, the ones that scattered in the medium (and were shaded there).
    pub medium_scatters: u64,
    /// Paths that ended spectral (met dispersive glass, or sampled wavelengths from the start).
    pub spectral_paths: u64,
}

impl PathStats {
    /// Adds `other`'s counts to these, as a tile sums its samples'.
    pub fn add(&mut self, other: &PathStats) {
        self.traversal.nodes += other.traversal.nodes;
        self.traversal.triangles += other.traversal.triangles;
        self.rays += other.rays;
        self.hits += other.hits;
        self.shadow_rays += other.shadow_rays;
        self.light_samples += other.light_samples;
        self.refractions += other.refractions;
        self.environment_lookups += other.environment_lookups;
        self.invalid_samples += other.invalid_samples;
        self.flights += other.flights;
        self.medium_scatters += other.medium_scatters;
        self.spectral_paths += other.spectral_paths;
    }

    /// The deterministic cost of the work counted here, in abstract units of about one BVH node
    /// visit: one per node visited and per triangle tested, 12 per ray that is shaded (a
    /// closest-hit ray that hits a surface, or a scattering in a medium: BSDF or phase sampling
    /// and light choice) and per shadow ray
    /// (light sampling and the any-hit query's set-up), 4 per ray that escapes. The weights come
    /// from timing every 16x16 tile of the shipped and shared scenes alone
    /// (`cargo run --release -p sim --example fit_work`): a single charge of 16 for every ray
    /// priced escaping rays like shaded ones, and the 95th-percentile tile of scenes with much
    /// sky or background came out more than twice as slow as predicted; with these weights it is
    /// within about +30% in every scene.
    pub fn work(&self) -> u64 {
        const SHADED: u64 = 12;
        const ESCAPED: u64 = 4;
        let escaped = self.rays - self.hits;
        self.traversal.nodes
            + self.traversal.triangles
            + SHADED * (self.hits + self.shadow_rays + self.medium_scatters)
            + ESCAPED * escaped
    }
}
