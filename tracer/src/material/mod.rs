//! Materials: the closed set of BSDFs ([`Bsdf`]) plus emission.
//!
//! BSDFs are evaluated in a local shading frame where the normal is +z; `wo` and `wi` both point
//! away from the surface. Sampling consumes exactly two random numbers for the direction and one
//! for any discrete choice (Fresnel reflect/refract), whatever the material, so the number of
//! random dimensions per bounce is fixed and pixel values stay a pure function of the sample index.

use glam::Vec3;

/// A surface material: how it scatters and what it emits.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// The MTL name (or the override's name), for messages and statistics.
    pub name: String,
    pub bsdf: Bsdf,
    /// Emitted radiance from the front face (the winding normal's side); zero when not a light.
    pub emission: Vec3,
}

/// The closed set of scattering models.
#[derive(Clone, Debug, PartialEq)]
pub enum Bsdf {
    /// Lambertian reflection; `texture` (an index into `Scene::textures`) multiplies `albedo`.
    Diffuse { albedo: Vec3, texture: Option<u32> },
    /// A perfect specular reflector.
    Mirror { reflectance: Vec3 },
    /// A rough conductor: GGX microfacets with Schlick Fresnel from `f0`, roughness `alpha` in (0, 1].
    Conductor { f0: Vec3, alpha: f32 },
    /// Smooth glass: Fresnel reflection and refraction with index `ior` (outside is vacuum), and a
    /// transmission `tint`.
    Dielectric { ior: f32, tint: Vec3 },
}
