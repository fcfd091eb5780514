//! Motion within and across frames: the camera's shutter, and objects that move by keyframes.
//!
//! Time is measured in frames: frame `f` is the instant `f`, and a sample of frame `f` is taken
//! at `f + open + u (close - open)` for a `u` of its own ([`crate::sampler::PixelSampler::time`]).
//! Why frames and not seconds: keys are given at frames, a scene has no frame rate, and a
//! shutter given as a fraction of the frame interval (`[0, 0.5]` is a 180-degree shutter) keeps
//! its meaning whatever rate the frames are played at.
//!
//! A moving object keeps its triangles in object space, with a [`TransformTrack`] that places
//! them at any time; the accelerator for such objects is `crate::geometry::motion`. An object
//! whose keys are all the same does not move and is placed once, as if it had no keys, so its
//! triangles are the bits of an object without keys.
//!
//! The placement at a time interpolates scale, the three rotation angles and translation
//! linearly between the two keys around it (and holds before the first key and after the last,
//! as the camera does). Why the angles and not a quaternion: the keys state angles, and a spin of
//! 720 degrees between two keys is a spin of 720 degrees, which no interpolation of orientations
//! can tell from standing still. The matrices are composed in f64 from f64 sines and cosines
//! ([`crate::math::sin_cos_f64`]), so that the transform and its inverse agree to about 1e-16,
//! far below the 32-bit floats they act on (the error bounds of `geometry::motion` rely on it).

use super::Triangle;
use crate::math::sin_cos_f64;
use glam::{DMat3, DVec3, Vec3};

/// When the shutter is open, relative to the frame, in frames: `open <= close`, both in
/// `[-1, 1]`, open for at most one frame. The default `[0, 0]` takes every sample at the frame's
/// own instant: no motion blur.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Shutter {
    /// When the shutter opens, in frames after the frame's own instant (negative: before it).
    pub open: f32,
    /// When the shutter closes, in frames after the frame's own instant; `close >= open`.
    pub close: f32,
}

impl Shutter {
    /// Whether the shutter stays open for a while (rather than an instant).
    pub fn is_open(&self) -> bool {
        self.close > self.open
    }

    /// The time of frame `frame` at fraction `u` of the exposure: `frame + open + u (close -
    /// open)`, in f64, so that frame numbers up to 2^52 keep their fractions. With `u` zero (or
    /// a shutter of no length) it is `frame + open` exactly.
    pub fn time(&self, frame: u32, u: f32) -> f64 {
        let length = f64::from(self.close) - f64::from(self.open);
        f64::from(frame) + f64::from(self.open) + f64::from(u) * length
    }
}

/// A pose of an object at a frame: scale, then rotation about x, y and z (degrees), then
/// translation, as `[[object]]`'s keys say.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransformKey {
    /// The frame at which the object has this pose exactly.
    pub frame: u32,
    /// Scale along the object-space x, y and z axes, applied first.
    pub scale: Vec3,
    /// Rotation about the x, then y, then z axis, in degrees, applied after the scale; angles are
    /// interpolated as given, so several turns between two keys are several turns.
    pub rotate_degrees: Vec3,
    /// Translation in world space, applied last.
    pub translate: Vec3,
}

/// Keyframes sorted by frame, two at least, not all alike (else the object does not move).
#[derive(Clone, Debug, PartialEq)]
pub struct TransformTrack {
    keys: Vec<TransformKey>,
    /// Each key's rotation matrix, so that a segment that does not turn costs no sines.
    rotations: Vec<DMat3>,
}

/// An affine placement `x -> linear x + translation` in f64, with what rays and normals need:
/// the inverse of `linear` (which takes rays into object space) and its transpose (normals).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    /// Scale and rotation: object space to world space, before the translation.
    pub linear: DMat3,
    /// The inverse of `linear`: takes ray directions (and origins, less the translation) from
    /// world space into object space.
    pub inverse: DMat3,
    /// The transpose of `inverse`: takes object-space normals to world space, perpendicular to
    /// the placed surface (not unit length unless the scale is 1).
    pub normal: DMat3,
    /// Where the object-space origin lands, in world space.
    pub translation: DVec3,
}

/// An object that moves: its triangles in object space and where they are when.
#[derive(Clone, Debug, PartialEq)]
pub struct MovingObject {
    /// Object-space triangles, zero-area ones dropped.
    pub triangles: Vec<Triangle>,
    /// Their shading normals (in object space) and texture coordinates, by the same index:
    /// empty where none has any, else one each.
    pub attributes: Vec<super::VertexAttributes>,
    /// The object's keyframed poses, which place `triangles` in world space at any time.
    pub track: TransformTrack,
}

impl TransformTrack {
    /// A track from keys sorted by strictly increasing frame; `None` unless there are two keys
    /// at least, in order, and some two differ (the loader names what is wrong).
    pub fn new(keys: Vec<TransformKey>) -> Option<Self> {
        let ordered = keys.windows(2).all(|w| w[0].frame < w[1].frame);
        let moves = keys.windows(2).any(|w| !w[0].same_pose(&w[1]));
        let rotations = keys
            .iter()
            .map(|k| rotation(k.rotate_degrees.as_dvec3()))
            .collect();
        (keys.len() >= 2 && ordered && moves).then_some(Self { keys, rotations })
    }

    /// The keys, sorted by strictly increasing frame.
    pub fn keys(&self) -> &[TransformKey] {
        &self.keys
    }

    /// The keyframe segment holding `time`: 0 before the first key, `i` between keys `i - 1`
    /// and `i`, `keys.len()` after the last. Segments are what swept bounds are kept per.
    pub fn segment(&self, time: f64) -> usize {
        self.keys.partition_point(|k| f64::from(k.frame) <= time)
    }

    /// [`TransformTrack::segment`], tried first at `hint`: a frame's samples mostly fall in one
    /// segment, so a path placing its objects where the buffer's last path placed them checks
    /// that segment's two keys (branches it predicts) instead of searching the keys (a search
    /// whose branches on random times were mispredicted: 6 to 8 % of `cornell-blur`'s camera
    /// rays). The same segment either way: the one whose keys bracket `time`.
    #[inline]
    pub fn segment_near(&self, hint: usize, time: f64) -> usize {
        let keys = self.keys.len();
        let holds = hint <= keys
            && (hint == 0 || f64::from(self.keys[hint - 1].frame) <= time)
            && (hint == keys || time < f64::from(self.keys[hint].frame));
        if holds { hint } else { self.segment(time) }
    }

    /// The number of segments: one more than keys.
    pub fn segments(&self) -> usize {
        self.keys.len() + 1
    }

    /// The keys bounding segment `segment`: the same key twice for the segments that hold.
    pub fn segment_keys(&self, segment: usize) -> (&TransformKey, &TransformKey) {
        let last = self.keys.len() - 1;
        match segment {
            0 => (&self.keys[0], &self.keys[0]),
            s if s > last => (&self.keys[last], &self.keys[last]),
            s => (&self.keys[s - 1], &self.keys[s]),
        }
    }

    /// The placement at `time` (frames).
    pub fn at(&self, time: f64) -> Placement {
        let mut placed = Placement::IDENTITY;
        self.place_in(self.segment(time), time, &mut placed);
        placed
    }

    /// [`TransformTrack::at`], where the caller has `segment` (which is `self.segment(time)`)
    /// already, written over `out` field by field: a path's start places every object of a
    /// few, keeps each one's segment too, and refills its placements in place, where a
    /// placement (240 bytes) built aside and copied in took 3 % of `cornell-blur`'s render in
    /// `memmove`.
    #[inline]
    pub fn place_in(&self, segment: usize, time: f64, out: &mut Placement) {
        let (a, b) = self.segment_keys(segment);
        let first = segment.saturating_sub(1).min(self.keys.len() - 1);
        if a.frame == b.frame {
            let (scale, translate) = (a.scale.as_dvec3(), a.translate.as_dvec3());
            return place(scale, self.rotations[first], translate, out);
        }
        let s = (time - f64::from(a.frame)) / (f64::from(b.frame) - f64::from(a.frame));
        let lerp = |x: Vec3, y: Vec3| x.as_dvec3() + s * (y.as_dvec3() - x.as_dvec3());
        let rotate = if a.rotate_degrees == b.rotate_degrees {
            self.rotations[first]
        } else {
            rotation(lerp(a.rotate_degrees, b.rotate_degrees))
        };
        place(
            lerp(a.scale, b.scale),
            rotate,
            lerp(a.translate, b.translate),
            out,
        );
    }
}

impl TransformKey {
    fn same_pose(&self, other: &TransformKey) -> bool {
        (self.scale, self.rotate_degrees, self.translate)
            == (other.scale, other.rotate_degrees, other.translate)
    }

    /// The placement of this key alone.
    pub fn placement(&self) -> Placement {
        placement(
            self.scale.as_dvec3(),
            rotation(self.rotate_degrees.as_dvec3()),
            self.translate.as_dvec3(),
        )
    }
}

/// The rotation about x, then y, then z by `degrees`, in f64. An angle of zero costs nothing
/// (objects mostly turn about one axis, and placements are computed per sample).
// Always inlined: a turning object's placement is made at every path's start, and the matrix
// returned through memory was read back in wider loads than its stores (a stall the profile of
// `cornell-blur`'s camera rays put at a tenth of `place_in`).
#[inline(always)]
fn rotation(degrees: DVec3) -> DMat3 {
    let r = degrees * (std::f64::consts::PI / 180.0);
    let about = |axis: usize, angle: f64| {
        let (sin, cos) = sin_cos_f64(angle);
        match axis {
            0 => DMat3::from_cols_array(&[1.0, 0.0, 0.0, 0.0, cos, sin, 0.0, -sin, cos]),
            1 => DMat3::from_cols_array(&[cos, 0.0, -sin, 0.0, 1.0, 0.0, sin, 0.0, cos]),
            _ => DMat3::from_cols_array(&[cos, sin, 0.0, -sin, cos, 0.0, 0.0, 0.0, 1.0]),
        }
    };
    [(2, r.z), (1, r.y), (0, r.x)]
        .into_iter()
        .filter(|&(_, angle)| angle != 0.0)
        .fold(None, |turned: Option<DMat3>, (axis, angle)| {
            let next = about(axis, angle);
            Some(turned.map_or(next, |m| m * next))
        })
        .unwrap_or(DMat3::IDENTITY)
}

/// Scale, then rotate by `rotate`, then translate; in f64.
fn placement(scale: DVec3, rotate: DMat3, translation: DVec3) -> Placement {
    let mut placed = Placement::IDENTITY;
    place(scale, rotate, translation, &mut placed);
    placed
}

/// [`placement`], written over `out` field by field.
#[inline(always)]
fn place(scale: DVec3, rotate: DMat3, translation: DVec3, out: &mut Placement) {
    // The inverse of a rotation is its transpose, and of a scale its reciprocal: composing
    // them, rather than inverting the product, keeps the inverse to the rounding of one
    // product. A diagonal factor scales columns (or rows), so no full product is needed.
    let scaled =
        |m: DMat3, s: DVec3| DMat3::from_cols(m.x_axis * s.x, m.y_axis * s.y, m.z_axis * s.z);
    // An object keyed without a scale (most are) skips the divisions, whose latency every
    // other entry waited on: a product by 1 and the reciprocal of 1 are exact, so its
    // placement is the same bits either way.
    if scale == DVec3::ONE {
        out.linear = rotate;
        out.inverse = rotate.transpose();
        out.normal = rotate;
        out.translation = translation;
        return;
    }
    // diag(1 / s) R^T is (R diag(1 / s))^T.
    let inverse_transposed = scaled(rotate, scale.recip());
    out.linear = scaled(rotate, scale);
    out.inverse = inverse_transposed.transpose();
    // The transpose of the inverse the rays use, exactly: the normal of the plane that rays
    // meet.
    out.normal = inverse_transposed;
    out.translation = translation;
}

impl Placement {
    /// The placement that moves nothing.
    pub const IDENTITY: Placement = Placement {
        linear: DMat3::IDENTITY,
        inverse: DMat3::IDENTITY,
        normal: DMat3::IDENTITY,
        translation: DVec3::ZERO,
    };

    /// `p` placed, in f64.
    pub fn point(&self, p: DVec3) -> DVec3 {
        self.linear * p + self.translation
    }

    /// The world point `p` taken into object space, in f64.
    pub fn unplace_point(&self, p: DVec3) -> DVec3 {
        self.inverse * (p - self.translation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(frame: u32, x: f32, turn: f32) -> TransformKey {
        TransformKey {
            frame,
            scale: Vec3::ONE,
            rotate_degrees: Vec3::new(0.0, turn, 0.0),
            translate: Vec3::new(x, 0.0, 0.0),
        }
    }

    #[test]
    fn tracks_interpolate_between_keys_and_hold_outside() {
        let track = TransformTrack::new(vec![key(2, 0.0, 0.0), key(6, 4.0, 720.0)]).unwrap();
        assert_eq!(track.at(0.0).translation.x, 0.0);
        assert_eq!(track.at(3.0).translation.x, 1.0);
        assert_eq!(track.at(9.5).translation.x, 4.0);
        // Half way through a spin of two turns is a whole turn: back where it started.
        let turned = track.at(4.0).linear;
        assert!((turned - DMat3::IDENTITY).abs_diff_eq(DMat3::ZERO, 1e-12));
        let quarter = track.at(2.5).point(DVec3::X);
        assert!(
            (quarter - DVec3::new(0.5, 0.0, -1.0)).length() < 1e-12,
            "{quarter}"
        );
        assert_eq!(
            (track.segment(1.0), track.segment(2.0), track.segment(7.0)),
            (0, 1, 2)
        );
    }

    /// Whatever segment the search starts from, in range or not, it finds the one `segment`
    /// finds: at the keys themselves, between them, before the first, after the last, and for
    /// a time that is not a number.
    #[test]
    fn a_segment_looked_for_from_any_hint_is_the_searched_one() {
        let keys = [2, 3, 7, 8, 20]
            .map(|frame| key(frame, frame as f32, 0.0))
            .to_vec();
        let track = TransformTrack::new(keys).unwrap();
        let mut times: Vec<f64> = vec![f64::NAN, f64::NEG_INFINITY, f64::INFINITY, -1.0, 0.0];
        for frame in [2.0f64, 3.0, 7.0, 8.0, 20.0] {
            times.extend([
                frame,
                frame - 0.5,
                frame + 0.25,
                frame.next_down(),
                frame.next_up(),
            ]);
        }
        for time in times {
            for hint in 0..=track.segments() + 1 {
                assert_eq!(
                    track.segment_near(hint, time),
                    track.segment(time),
                    "time {time}, hint {hint}"
                );
            }
        }
    }

    /// An object keyed without a scale skips the scaling (`place`): its placement must be the
    /// general one's at a scale of one, bit for bit (signed zeros included), which is written
    /// out here; for rotations, and for a matrix with zeros of both signs.
    #[test]
    fn an_unscaled_placement_is_the_scaled_one_at_a_scale_of_one() {
        let by_columns =
            |m: DMat3, s: DVec3| DMat3::from_cols(m.x_axis * s.x, m.y_axis * s.y, m.z_axis * s.z);
        let bits = |m: DMat3| m.to_cols_array().map(f64::to_bits);
        let mut matrices: Vec<DMat3> = [
            [0.0, 0.0, 0.0],
            [0.0, 37.5, 0.0],
            [10.0, 200.0, -33.0],
            [1e-9, 0.0, 89.0],
        ]
        .into_iter()
        .map(|degrees| rotation(DVec3::from_array(degrees)))
        .collect();
        matrices.push(DMat3::from_cols_array(&[
            -0.0, 0.0, 1.0, 0.0, -1.0, -0.0, 1.0, -0.0, 0.0,
        ]));
        for rotate in matrices {
            let translation = DVec3::new(1e5, -7.0, 3.0);
            let placed = placement(DVec3::ONE, rotate, translation);
            let inverse_transposed = by_columns(rotate, DVec3::ONE.recip());
            let name = format!("{rotate:?}");
            assert_eq!(
                bits(placed.linear),
                bits(by_columns(rotate, DVec3::ONE)),
                "{name}"
            );
            assert_eq!(
                bits(placed.inverse),
                bits(inverse_transposed.transpose()),
                "{name}"
            );
            assert_eq!(bits(placed.normal), bits(inverse_transposed), "{name}");
            assert_eq!(placed.translation, translation);
        }
    }

    #[test]
    fn a_placement_and_its_inverse_agree_to_f64_rounding() {
        let p = placement(
            DVec3::new(2.0, -0.5, 3.0),
            rotation(DVec3::new(10.0, 200.0, -33.0)),
            DVec3::new(1e5, -7.0, 3.0),
        );
        let x = DVec3::new(0.3, -1.7, 2.2);
        assert!((p.unplace_point(p.point(x)) - x).length() < 1e-10);
        let n = DVec3::new(0.1, 0.7, -0.2);
        let tangent = n.cross(DVec3::X);
        // Normals stay perpendicular to the placed tangents.
        assert!((p.normal * n).dot(p.linear * tangent).abs() < 1e-12);
    }

    #[test]
    fn tracks_need_two_ordered_keys_that_differ() {
        assert!(TransformTrack::new(vec![key(0, 0.0, 0.0)]).is_none());
        assert!(TransformTrack::new(vec![key(3, 0.0, 0.0), key(1, 1.0, 0.0)]).is_none());
        assert!(TransformTrack::new(vec![key(1, 0.0, 0.0), key(1, 1.0, 0.0)]).is_none());
        assert!(TransformTrack::new(vec![key(0, 1.0, 5.0), key(9, 1.0, 5.0)]).is_none());
    }

    #[test]
    fn the_shutter_time_is_the_frame_plus_its_fraction_of_the_exposure() {
        let shutter = Shutter {
            open: -0.25,
            close: 0.25,
        };
        assert_eq!(shutter.time(10, 0.0), 9.75);
        assert_eq!(shutter.time(10, 0.5), 10.0);
        assert!(!Shutter::default().is_open() && shutter.is_open());
        assert_eq!(Shutter::default().time(7, 0.9), 7.0);
    }
}
