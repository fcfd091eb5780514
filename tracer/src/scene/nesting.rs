//! Whether what each boundary says surrounds it is what the geometry puts there.
//!
//! A glass or interface names the medium and the index of refraction just outside its surface
//! (`outside_medium`, `outside_ior`; left out, the camera's medium and index 1). The renderer
//! trusts them: a path crossing the surface outward enters that medium and refracts by that
//! index, whatever object really encloses the surface. A key that contradicts the geometry
//! (a glass ball inside a fog-filled room that does not say so, an ice cube in water whose
//! `outside_ior` is the air's) renders plausible but wrong light, silently. This check finds
//! such contradictions before rendering, so that the loader can refuse them.
//!
//! **How.** From a few points on each boundary material's surface (the centroids of up to
//! [`PROBES`] of its triangles, spread over its list) a probe ray leaves along the triangle's
//! winding normal, the side the renderer calls outside. The first boundary surface it meets
//! tells what lies between: met from its front, that surface's own outside; met from its back,
//! its inside; met nowhere, the camera's medium and index 1, where an escaping ray is taken to be.
//! Other surfaces (walls, tables) are passed through, as media pass them: only glass and
//! interfaces change the medium a path is in.
//!
//! **Conservative.** Geometry can be ambiguous: open sheets, coincident surfaces, a concave
//! object whose probe meets itself. A probe that meets its own material tells nothing and is
//! dropped; the check speaks only when every remaining probe of a material
//! agrees, and only about what they agree on. An index the surroundings leave unknown (inside a
//! dispersive glass, whose index varies, or across an interface, which does not refract) is not
//! compared. Moving objects are neither probed nor met: they move through what surrounds them.

use super::Triangle;
use super::error::SceneError;
use super::materials::MaterialTable;
use crate::geometry::{Ray, intersect_triangle};
use crate::material::{Bsdf, Material};
use glam::Vec3;

/// Probe rays per boundary material, at most.
pub(crate) const PROBES: usize = 8;

/// The indices of refraction on a boundary's two sides, as the scene gave them; `None` where
/// the surface does not fix one (a dispersive glass's inside, both sides of an interface).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Indices {
    pub inside: Option<f32>,
    pub outside: Option<f32>,
}

impl Indices {
    /// What a material's BSDF says of its sides, for materials whose absolute indices were not
    /// recorded separately: an MTL glass (air outside, so its relative index is its own), a
    /// dispersive glass, an interface; `None` for surfaces that are not boundaries.
    pub(crate) fn of(bsdf: &Bsdf) -> Option<Indices> {
        match *bsdf {
            Bsdf::Dielectric { ior, .. } => Some(Indices {
                inside: Some(ior),
                outside: Some(1.0),
            }),
            Bsdf::DispersiveGlass { outside_ior, .. } => Some(Indices {
                inside: None,
                outside: Some(outside_ior),
            }),
            Bsdf::Interface => Some(Indices {
                inside: None,
                outside: None,
            }),
            _ => None,
        }
    }
}

/// What lies on one side of a boundary: a medium (`None`, vacuum) and an index, if known.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Surroundings {
    pub medium: Option<u32>,
    pub index: Option<f32>,
}

/// A material whose outside keys the geometry contradicts, with what the probes found.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Contradiction {
    /// The material's id.
    pub material: u32,
    /// What the material says (or its defaults say) surrounds it.
    pub declared: Surroundings,
    /// What every informative probe found, where they agree.
    pub found: Surroundings,
    /// Where one probe started, for the message.
    pub at: Vec3,
    /// The material whose surface the probes met first and whether from its front, or `None`
    /// where they escaped.
    pub met: Option<(u32, bool)>,
}

/// The first contradiction among the still `triangles`' boundary materials, in material order.
/// `indices[m]` holds material `m`'s indices where it is a boundary.
pub(crate) fn check(
    triangles: &[Triangle],
    materials: &[Material],
    indices: &[Option<Indices>],
    camera_medium: Option<u32>,
) -> Option<Contradiction> {
    let boundary = |t: &Triangle| indices[t.material as usize].is_some();
    let walls: Vec<usize> = (0..triangles.len())
        .filter(|&i| boundary(&triangles[i]))
        .collect();
    let escaped = Surroundings {
        medium: camera_medium,
        index: Some(1.0),
    };
    (0u32..).zip(indices).find_map(|(material, sides)| {
        let sides = (*sides)?;
        let own: Vec<usize> = walls
            .iter()
            .copied()
            .filter(|&i| triangles[i].material == material)
            .collect();
        let declared = Surroundings {
            medium: materials[material as usize].exterior,
            index: sides.outside,
        };
        let mut agreed: Option<(Surroundings, Option<(u32, bool)>)> = None;
        let mut at = Vec3::ZERO;
        for k in 0..own.len().min(PROBES) {
            let start = own[k * own.len() / own.len().min(PROBES)];
            let t = &triangles[start];
            let origin = (t.p[0] + t.p[1] + t.p[2]) / 3.0;
            let ray = Ray {
                origin,
                dir: t.area_vector(),
                t_max: f32::INFINITY,
            };
            let found = match first_wall(triangles, &walls, start, &ray) {
                None => (escaped, None),
                Some((hit, _)) if triangles[hit].material == material => continue,
                Some((hit, from_front)) => {
                    let other = triangles[hit].material;
                    let sides = indices[other as usize].expect("walls are boundaries");
                    let m = &materials[other as usize];
                    let side = if from_front {
                        Surroundings {
                            medium: m.exterior,
                            index: sides.outside,
                        }
                    } else {
                        Surroundings {
                            medium: m.interior,
                            index: sides.inside,
                        }
                    };
                    (side, Some((other, from_front)))
                }
            };
            match agreed {
                None => {
                    agreed = Some(found);
                    at = origin;
                }
                // Probes that meet different objects agree when those say the same.
                Some((seen, _)) if seen == found.0 => {}
                // The probes disagree: the geometry does not say one thing.
                Some(_) => return None,
            }
        }
        let (found, met) = agreed?;
        let medium_differs = found.medium != declared.medium;
        let index_differs = matches!((found.index, declared.index), (Some(a), Some(b)) if a != b);
        (medium_differs || index_differs).then_some(Contradiction {
            material,
            declared,
            found,
            at,
            met,
        })
    })
}

/// The loader's refusal of `c`, at the material's table (or its MTL file), naming the keys
/// to change and what the geometry puts around the material.
pub(crate) fn refusal(table: &MaterialTable, c: &Contradiction) -> SceneError {
    let describe = |s: &Surroundings| {
        let medium = s.medium.map_or("vacuum".to_owned(), |m| {
            format!("medium `{}`", table.media.name(m))
        });
        match s.index {
            Some(index) => format!("{medium} of index {index}"),
            None => medium,
        }
    };
    let mut keys = Vec::new();
    if c.found.medium != c.declared.medium {
        keys.push("`outside_medium`");
    }
    if matches!((c.found.index, c.declared.index), (Some(a), Some(b)) if a != b) {
        keys.push("`outside_ior`");
    }
    let how = match c.met {
        None => "escapes to infinity, which is the camera's medium".to_owned(),
        Some((m, true)) => format!(
            "first meets the outside of material `{}`",
            table.materials[m as usize].name
        ),
        Some((m, false)) => format!(
            "first meets material `{}` from its inside",
            table.materials[m as usize].name
        ),
    };
    let name = &table.materials[c.material as usize].name;
    let (file, line) = table.place(c.material);
    let fix = match line {
        Some(_) => format!("set {} to match", keys.join(" and ")),
        None => format!(
            "MTL cannot say it: add a [materials.{name}] table setting {}",
            keys.join(" and ")
        ),
    };
    let at = c.at;
    let verb = if keys.len() > 1 { "say" } else { "says" };
    let detail = format!(
        "[materials.{name}]: the geometry puts {found} around it, but its {keys} {verb} \
         {declared} (left out, the camera's medium and index 1): a ray leaving its surface at \
         ({:.4}, {:.4}, {:.4}) along the outward normal {how}; {fix}",
        at.x,
        at.y,
        at.z,
        found = describe(&c.found),
        declared = describe(&c.declared),
        keys = keys.join(" and "),
    );
    match line {
        Some(line) => SceneError::at_line(file, line, detail),
        None => SceneError::in_file(file, detail),
    }
}

/// The nearest boundary triangle along `ray` other than `start`, and whether the ray meets it
/// from its front (against its winding normal).
fn first_wall(
    triangles: &[Triangle],
    walls: &[usize],
    start: usize,
    ray: &Ray,
) -> Option<(usize, bool)> {
    let mut nearest: Option<(f32, usize)> = None;
    for &i in walls {
        if i == start {
            continue;
        }
        let reach = nearest.map_or(ray.t_max, |(t, _)| t);
        let probe = Ray {
            t_max: reach,
            ..*ray
        };
        if let Some(hit) = intersect_triangle(&probe, &triangles[i].p) {
            nearest = Some((hit.t, i));
        }
    }
    nearest.map(|(_, i)| (i, triangles[i].area_vector().dot(ray.dir) < 0.0))
}
