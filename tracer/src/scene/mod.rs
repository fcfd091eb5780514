//! The in-memory scene: what the loader produces and the integrator consumes.
//!
//! Everything is resolved (materials by index, textures decoded, read as linear RGB), and placed in
//! world space but for moving objects, which keep object space and a track (`motion.rs`), so
//! that rendering never touches the filesystem. The loader ([`load()`]) reads a TOML scene
//! file and the OBJ/MTL meshes and textures it references through a [`SceneFiles`] source, so the
//! same code loads from disk or from the in-memory file set a peer received over the network.

mod camera;
mod error;
mod files;
mod format;
mod keys;
mod load;
mod materials;
mod media;
mod motion;
mod mtl;
mod nesting;
mod obj;
mod report;
mod shapes;
mod texture;
mod values;

pub use camera::{Camera, CameraKey, CameraRays, CameraTrack};

/// The most frames a render may have, so also one past the last frame a key may name: 2^24.
/// Time is counted in frames, and up to 2^24 every frame is a whole number in `f32` and every
/// key's fraction is exact (`CameraTrack::at_time`); past it, frames would blur into each
/// other. Far beyond any animation (a week at 24 frames a second is 14.5 million frames).
pub const MAX_FRAMES: u32 = 1 << 24;

/// The most radiance (or a point light's intensity) a scene may emit, per channel, including an
/// environment map's texels times its `scale`. A pixel sums its samples, each an emission times
/// a path's weight, and `f32` ends at 3.4e38: from 3e38 a render wrote infinite pixels. 1e30
/// leaves eight orders of magnitude for the sums, and is far above any light measured in
/// physical units (the sun's radiance is about 1e7 W/(m^2 sr)).
pub const MAX_RADIANCE: f32 = 1e30;
pub use error::{Location, SceneError};
pub use files::{DiskFiles, MemoryFiles, SceneFiles, normalize};
pub use load::{load, load_file_with_report, load_from, load_str, load_with_report};
pub use motion::{MovingObject, Placement, Shutter, TransformKey, TransformTrack};
pub use report::{LoadReport, ObjectReport};
pub use texture::Texture;

use crate::environment::{Environment, Portal};
use crate::material::Material;
use crate::medium::{MediaSampling, Medium};
use glam::{Vec2, Vec3};

/// A scene ready to render.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Image size, samples, path depth, seed and frame count (`[render]`, with the command
    /// line's overrides applied by the caller).
    pub settings: RenderSettings,
    /// Where the camera is and looks at each frame: one fixed pose or keyframes.
    pub camera: CameraTrack,
    /// When the camera's shutter is open around each frame (`[camera] shutter`).
    pub shutter: Shutter,
    /// Every triangle of every object that stays still, in world space, degenerate ones
    /// already dropped.
    pub triangles: Vec<Triangle>,
    /// The shading normals and texture coordinates of [`Scene::triangles`] (in world space), by
    /// the same index: empty where no still triangle has any, else one each (those of a
    /// triangle without any empty). Read by a hit beside its triangle, from its index alone.
    pub attributes: Vec<VertexAttributes>,
    /// The objects that move by keyframes, in object space with their tracks, in file order.
    /// Their triangles are numbered after [`Scene::triangles`] (see `geometry::motion`).
    pub moving: Vec<MovingObject>,
    /// Every material in use, indexed by [`Triangle::material`].
    pub materials: Vec<Material>,
    /// Every decoded texture, as linear RGB, indexed by the materials that sample one.
    pub textures: Vec<Texture>,
    /// The point lights; area lights are the emissive triangles instead.
    pub point_lights: Vec<PointLight>,
    /// The radiance arriving along directions that escape the scene (constant or a map), if any.
    pub environment: Option<Environment>,
    /// The rectangles through which the environment reaches the scene's interior (`[environment]
    /// portals`): where next-event estimation looks for it besides its own sampling.
    pub portals: Vec<Portal>,
    /// The media that materials bind ([`Material::interior`]) and the camera starts in, in
    /// first-use order.
    pub media: Vec<Medium>,
    /// The medium outside every object, where camera rays start (global fog); `None` is vacuum.
    pub camera_medium: Option<u32>,
    /// Every file the scene was read from (the TOML first), relative to the TOML's folder, so a
    /// frame owner can ship the scene to peers that share no filesystem with it.
    pub files: Vec<String>,
}

/// Render settings; the TOML's `[render]` table. See `scenes/README.md` for the defaults.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Image width in pixels, at least 1.
    pub width: u32,
    /// Image height in pixels, at least 1.
    pub height: u32,
    /// Samples averaged per pixel, at least 1; each is one camera path.
    pub samples_per_pixel: u32,
    /// Maximum number of scattering events, as pbrt counts depth: 0 shows emitters only, 1 adds
    /// direct lighting, and a path has at most `max_depth + 1` segments. `None` means unlimited,
    /// ended by Russian roulette alone.
    pub max_depth: Option<u32>,
    /// The depth from which Russian roulette may end paths; `None` turns it off.
    pub russian_roulette_depth: Option<u32>,
    /// The seed of every pixel's counter-based random streams: with the scene, the frame, the
    /// pixel and the sample index it decides a sample's value.
    pub seed: u64,
    /// How many frames the animation has (frames 0 to `frames - 1`).
    pub frames: u32,
    /// How media are sampled: a comparison knob for `tessera accuracy`, not in the scene format;
    /// the default is what every image is rendered with ([`MediaSampling`]).
    pub media: MediaSampling,
}

/// One triangle: its vertices and its material.
///
/// Its normals and texture coordinates live apart, in an array beside its own
/// ([`Scene::attributes`], [`MovingObject::attributes`]), empty where no triangle has any, so
/// that a triangle takes 40 bytes where room for both took 108: on the Cornell dragon, whose
/// 871k triangles have neither, the largest array the scene keeps and the one every hit reads.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Triangle {
    /// Vertices in world space. The winding defines the geometric normal
    /// `(p[1] - p[0]) x (p[2] - p[0])`, which is the emitting side of an area light.
    pub p: [Vec3; 3],
    /// Index into [`Scene::materials`].
    pub material: u32,
}

/// A triangle's per-vertex shading normals and texture coordinates, as its mesh gives them.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct VertexAttributes {
    /// Per-vertex shading normals (unit length; world space for a still triangle, object
    /// space for a moving one), when the mesh has them.
    pub n: Option<[Vec3; 3]>,
    /// Per-vertex texture coordinates, when the mesh has them.
    pub uv: Option<[Vec2; 3]>,
}

impl VertexAttributes {
    /// Whether there is nothing to keep: no normals and no texture coordinates.
    pub fn is_empty(&self) -> bool {
        self.n.is_none() && self.uv.is_none()
    }
}

/// Triangles and their attributes (empty where none has any, else one each): a mesh as the
/// loader makes it.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Mesh {
    pub triangles: Vec<Triangle>,
    pub attributes: Vec<VertexAttributes>,
}

impl Mesh {
    /// Appends a triangle with its attributes.
    pub(crate) fn push(&mut self, p: [Vec3; 3], material: u32, attributes: VertexAttributes) {
        if !attributes.is_empty() || !self.attributes.is_empty() {
            // The first triangle with attributes gives those before it empty ones, and room
            // for as many as the triangles have (a mesh's are sized to its count).
            if self.attributes.is_empty() {
                self.attributes.reserve_exact(self.triangles.capacity());
            }
            self.attributes
                .resize(self.triangles.len(), VertexAttributes::default());
            self.attributes.push(attributes);
        }
        self.triangles.push(Triangle::new(p, material));
    }

    /// Appends `other`'s triangles and attributes. The attributes stay empty while no triangle
    /// has any; once one has, every triangle has an entry, empty where it has none.
    pub(crate) fn append(&mut self, mut other: Mesh) {
        if self.triangles.is_empty() {
            // Moved, not copied: a scene of one large mesh never holds it twice.
            *self = other;
            return;
        }
        if !self.attributes.is_empty() || !other.attributes.is_empty() {
            let (before, count) = (self.triangles.len(), other.triangles.len());
            self.attributes.resize(before, VertexAttributes::default());
            if other.attributes.is_empty() {
                self.attributes
                    .resize(before + count, VertexAttributes::default());
            } else {
                self.attributes.append(&mut other.attributes);
            }
        }
        self.triangles.append(&mut other.triangles);
    }
}

impl Triangle {
    /// A triangle of vertices `p` and material `material`.
    pub fn new(p: [Vec3; 3], material: u32) -> Self {
        Triangle { p, material }
    }

    /// Twice the area vector: its direction is the geometric normal, its length twice the area.
    pub fn area_vector(&self) -> Vec3 {
        (self.p[1] - self.p[0]).cross(self.p[2] - self.p[0])
    }

    /// The triangle's area, in the scene's units squared; 0 for a degenerate triangle.
    pub fn area(&self) -> f32 {
        0.5 * self.area_vector().length()
    }
}

/// An isotropic point light: radiant intensity in W/sr per channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    /// Where the light is, in world space.
    pub position: Vec3,
    /// Radiant intensity per RGB channel, in W/sr: irradiance falls off as intensity / d^2.
    pub intensity: Vec3,
}

const _: () = assert!(
    std::mem::size_of::<Triangle>() == 40,
    "the record every hit reads"
);

impl Scene {
    /// Whether some triangle, still or moving, has shading normals.
    pub fn has_shading_normals(&self) -> bool {
        let moving = self.moving.iter().flat_map(|o| &o.attributes);
        self.attributes.iter().chain(moving).any(|a| a.n.is_some())
    }

    /// Every triangle, still and moving (the moving ones in object space), for what asks only
    /// which materials are in use.
    pub fn all_triangles(&self) -> impl Iterator<Item = &Triangle> {
        let moving = self.moving.iter().flat_map(|o| &o.triangles);
        self.triangles.iter().chain(moving)
    }

    /// Whether anything moves while the shutter is open: the camera between two keys that
    /// differ, or an object (objects with keys that are all alike are placed still).
    pub fn moves(&self) -> bool {
        self.camera.moves() || !self.moving.is_empty()
    }

    /// The triangles whose material emits: the scene's area lights, in triangle order, with
    /// their global index: the still triangles first, then the moving objects' (in object
    /// space), numbered after them in object order as hits on them are (`geometry::motion`).
    pub fn emissive_triangles(&self) -> impl Iterator<Item = (u32, &Triangle)> {
        self.triangles
            .iter()
            .chain(self.moving.iter().flat_map(|o| &o.triangles))
            .enumerate()
            .filter(|(_, t)| self.materials[t.material as usize].emission != Vec3::ZERO)
            .map(|(i, t)| (i as u32, t))
    }
}
