//! Time from the TOML: the camera's track (`[[camera.keys]]`) and shutter, and a moving
//! object's track (`[[object.keys]]`), each key completed from its table's own values, with
//! errors that name the key's line (the shutter's own checks run as it is parsed, in
//! `values.rs`, where the value's line is known).

use super::error::{SceneError, line_of};
use super::format::{self, ObjectSpec, SceneSpec};
use super::motion::{Shutter, TransformKey, TransformTrack};
use super::{Camera, CameraKey, CameraTrack};
use glam::Vec3;
use std::collections::BTreeMap;

pub(super) fn camera_track(
    file: &str,
    text: &str,
    spec: &SceneSpec,
) -> Result<CameraTrack, SceneError> {
    let c = spec.camera.get_ref();
    if c.keys.is_empty() {
        let line = line_of(text, spec.camera.span().start);
        return Ok(CameraTrack::fixed(camera(file, line, c.pose())?));
    }
    let mut keys = Vec::with_capacity(c.keys.len());
    let mut frames = BTreeMap::new();
    for key in &c.keys {
        let k = key.get_ref();
        let line = line_of(text, key.span().start);
        if k.frame >= super::MAX_FRAMES {
            return Err(SceneError::at_line(
                file,
                line,
                past_last_frame("camera", k.frame),
            ));
        }
        if let Some(first) = frames.insert(k.frame, line) {
            let detail = format!(
                "camera: two keys at frame {} (the other at line {first})",
                k.frame
            );
            return Err(SceneError::at_line(file, line, detail));
        }
        let camera = camera(file, line, k.pose().or(c.pose()))?;
        keys.push(CameraKey {
            frame: k.frame,
            camera,
        });
    }
    Ok(
        CameraTrack::new(keys)
            .expect("keys are non-empty and their frames distinct: checked above"),
    )
}

/// Why a key at `frame` is refused: past the last frame a render may have.
fn past_last_frame(what: &str, frame: u32) -> String {
    format!(
        "{what} keys: frame {frame} is past the last a render may have, {} (2^24 - 1: time is \
         counted in frames, exactly only up to there)",
        super::MAX_FRAMES - 1
    )
}

/// The camera of a complete pose; `line` is where the pose is given.
fn camera(file: &str, line: usize, pose: format::Pose) -> Result<Camera, SceneError> {
    let err = |detail: &str| SceneError::at_line(file, line, format!("camera: {detail}"));
    let position = pose.position.ok_or_else(|| err("needs `position`"))?.0;
    let look_at = pose.look_at.ok_or_else(|| err("needs `look_at`"))?.0;
    let up = pose.up.map_or(Vec3::Y, |u| u.0);
    let forward = look_at - position;
    if forward == Vec3::ZERO {
        return Err(err("`look_at` equals `position`"));
    }

    // Whether `up` is parallel is a question of angle, asked in f64 where nothing overflows:
    // the camera's f32 basis below sin(angle) = 1e-4 would roll by rounding.
    let (f, u) = (forward.as_dvec3(), up.as_dvec3());
    if u == glam::DVec3::ZERO {
        return Err(err("`up` is zero"));
    }
    if f.cross(u).length() < 1e-4 * f.length() * u.length() {
        return Err(err(
            "`up` is parallel to the view direction (within 0.006 degrees)",
        ));
    }
    // The camera's basis as `Camera::rays` works it out in f32: where a length squared
    // overflows or underflows there, a normalised axis comes out zero or NaN.
    let unit = |v: Vec3| {
        let n = v.normalize();
        n.is_finite() && n.length_squared() > 0.5
    };
    if !forward.is_finite() || !unit(forward) {
        return Err(err(
            "the distance from `position` to `look_at` overflows 32-bit floats",
        ));
    }
    if !unit(forward.normalize().cross(up)) {
        return Err(err(
            "the cross product of the view direction and `up` is out of 32-bit floats' range; \
             give `up` an ordinary length, such as 1",
        ));
    }
    let vfov_degrees = pose.vfov.map_or(40.0, |v| v.0);
    // In focus by default at the point looked at, as photographers aim.
    // Finite: the view's length squared is (checked above).
    let focus_distance = pose.focus_distance.map_or(forward.length(), |f| f.0);
    Ok(Camera {
        position,
        look_at,
        up,
        vfov_degrees,
        aperture_radius: pose.aperture_radius.map_or(0.0, |a| a.0),
        focus_distance,
    })
}

/// The keys of a moving object, in order, each completed from the object's own transform;
/// `None` when the object stands still (no keys, or keys that all say the same).
pub(super) fn object_track(
    file: &str,
    text: &str,
    o: &ObjectSpec,
) -> Result<Option<TransformTrack>, SceneError> {
    let mut keys: Vec<TransformKey> = Vec::with_capacity(o.keys.len());
    let mut lines: Vec<usize> = Vec::with_capacity(o.keys.len());
    for spanned in &o.keys {
        let k = spanned.get_ref();
        let line = line_of(text, spanned.span().start);
        let err = |detail: String| SceneError::at_line(file, line, detail);
        if k.frame >= super::MAX_FRAMES {
            return Err(err(past_last_frame("object", k.frame)));
        }
        if let (Some(last), Some(&last_line)) = (keys.last(), lines.last()) {
            if k.frame == last.frame {
                return Err(err(format!(
                    "object keys: two keys at frame {} (the other at line {last_line})",
                    k.frame
                )));
            }
            if k.frame < last.frame {
                return Err(err(format!(
                    "object keys out of order: frame {} comes after frame {} (line \
                     {last_line}); give keys in increasing frame order",
                    k.frame, last.frame
                )));
            }
        }
        let key = key_pose(o, Some(k));
        // Signs compared, not a product, which underflows to zero for tiny scales.
        let changes_sign = |a: f32, b: f32| a == 0.0 || b == 0.0 || (a < 0.0) != (b < 0.0);
        if let Some(last) = keys.last()
            && (0..3).any(|axis| changes_sign(key.scale[axis], last.scale[axis]))
        {
            return Err(err(format!(
                "object keys: `scale` changes sign between frames {} and {}, so it would \
                 pass through zero and flatten the object",
                last.frame, key.frame
            )));
        }
        keys.push(key);
        lines.push(line);
    }
    Ok(TransformTrack::new(keys))
}

/// The pose of key `key` of object `o` (its frame, 0 without a key): each transform key the
/// key gives, else the object's own, else the identity's.
pub(super) fn key_pose(o: &ObjectSpec, key: Option<&format::ObjectKeySpec>) -> TransformKey {
    let pick = |key: Option<format::Finite>, object: Option<format::Finite>| {
        key.or(object).map_or(0.0, |r| r.0)
    };
    TransformKey {
        frame: key.map_or(0, |k| k.frame),
        scale: key
            .and_then(|k| k.scale)
            .or(o.scale)
            .map_or(Vec3::ONE, |s| s.0),
        rotate_degrees: Vec3::new(
            pick(key.and_then(|k| k.rotate_x), o.rotate_x),
            pick(key.and_then(|k| k.rotate_y), o.rotate_y),
            pick(key.and_then(|k| k.rotate_z), o.rotate_z),
        ),
        translate: key
            .and_then(|k| k.translate)
            .or(o.translate)
            .map_or(Vec3::ZERO, |t| t.0),
    }
}

/// The camera's shutter: the instant `[0, 0]` unless `[camera]` gives one.
pub(super) fn shutter(spec: &SceneSpec) -> Shutter {
    spec.camera
        .get_ref()
        .shutter
        .map_or(Shutter::default(), |s| {
            let [open, close] = s.0;
            Shutter { open, close }
        })
}
