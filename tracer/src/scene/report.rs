//! What the loader noticed without rejecting a scene ([`LoadReport`]): per object, what it kept
//! and dropped and where its triangles lie; and the scene's texture files.

/// What the loader noticed without rejecting the scene.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LoadReport {
    /// One entry per `[[object]]`, in file order. The still objects' triangles follow one
    /// another in [`super::Scene::triangles`] in this order, each object's [`ObjectReport::triangles`]
    /// of them; the moving ones are [`super::Scene::moving`], in this order too.
    pub objects: Vec<ObjectReport>,
    /// Each texture's file, relative to the scene file's folder, in the order of
    /// [`super::Scene::textures`].
    pub textures: Vec<String>,
}

/// What the loader made of one `[[object]]`: the counts a user needs to see that it loaded
/// as meant.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ObjectReport {
    /// The OBJ file (relative to the scene's folder) or the shape's name (`"sphere"`, ...).
    pub source: String,
    /// Triangles kept.
    pub triangles: usize,
    /// Zero-area triangles dropped.
    pub degenerate: usize,
    /// Whether the object moves (keyframes that differ): its triangles are then a
    /// [`super::MovingObject`] of their own, in object space, rather than in [`super::Scene::triangles`].
    pub moving: bool,
    /// The object's farthest coordinate from the origin over its median edge, rounded, when
    /// that is past the loader's `MAX_DISTANCE_PER_FEATURE` (2^20; and the loader warned).
    pub too_far: Option<u64>,
}

impl LoadReport {
    /// Zero-area triangles dropped over the whole scene.
    pub fn degenerate(&self) -> usize {
        self.objects.iter().map(|o| o.degenerate).sum()
    }

    /// Each still object's place among the `[[object]]` tables and the range of its triangles
    /// in [`super::Scene::triangles`], in file order: the ranges follow one another from 0 and cover
    /// the array, which the loader fills object by object; moving objects have none.
    pub fn still_objects(&self) -> impl Iterator<Item = (usize, std::ops::Range<usize>)> + '_ {
        let mut start = 0;
        self.objects
            .iter()
            .enumerate()
            .filter(|(_, o)| !o.moving)
            .map(move |(object, o)| {
                start += o.triangles;
                (object, start - o.triangles..start)
            })
    }
}
