//! Pixels from a scene. No async, no network, and no clock of its own: the cost of a tile is
//! counted work (BVH nodes visited, triangles tested, shading events), which is deterministic;
//! callers that want wall time measure it around [`render_tile`] (or each tile of
//! [`render_frame_by`]).
//!
//! Module map:
//! - [`scene`]: the in-memory scene ([`Scene`]) and its loader from TOML + OBJ/MTL files, with
//!   validation that names file, line and problem.
//! - [`geometry`]: rays, the watertight triangle test, the BVH (built by obvhs, collapsed into
//!   8-wide nodes, traversed by our own robust slab test with eight boxes and four triangles per
//!   SIMD step, each lane exactly the scalar test), the spawn-offset rule for secondary rays,
//!   and moving objects, traced in their own space at each sample's time.
//! - [`material`]: the closed set of materials ([`Material`]) and their BSDFs in a local frame.
//! - [`effects`]: the light-transport effects a scene calls for, so absent ones cost nothing.
//! - [`spectrum`]: spectral paths, only where dispersive glass is met: hero wavelengths from a
//!   stream of their own, RGB to spectrum and back, and what a spectral path sees of RGB values.
//! - [`medium`]: homogeneous participating media (absorption, Henyey-Greenstein scattering),
//!   their free-flight sampling (spectral MIS over the RGB channels) and transmittance.
//! - [`lights`]: area, point and environment lights and their power-proportional sampling.
//! - [`environment`]: the constant or lat-long map environment and the map's importance sampling,
//!   on the piecewise-constant densities of [`distribution`].
//! - [`sampler`]: the deterministic per-pixel random stream: a pure function of
//!   (seed, frame, pixel, sample index, dimension).
//! - [`integrator`]: the path tracer with next-event estimation and multiple importance sampling.
//! - [`tile`]: the unit of work: render a rectangle of a frame, get its pixels and its cost map.
//! - [`frame`]: a whole frame on one machine: a grid of tiles on a given rayon pool, into a film.
//! - [`output`]: OpenEXR (linear float RGB) and tone-mapped sRGB PNG writers.

pub mod distribution;
pub mod effects;
pub mod environment;
pub mod frame;
pub mod geometry;
pub mod integrator;
pub mod lights;
pub mod material;
pub mod math;
pub mod medium;
pub mod output;
pub mod sampler;
pub mod scene;
pub mod spectrum;
pub mod tile;

pub use material::Material;
pub use scene::{Scene, SceneError};

pub use effects::Effects;
pub use frame::{FrameConfig, render_frame, render_frame_by, tile_grid};
pub use integrator::{CameraRays, PathLanes, PathStats, World};
pub use tile::{BLOCK_SIZE, Film, Rect, TileCost, TileOutput, render_tile};
