//! The pinhole camera and its keyframed animation.

use crate::geometry::Ray;
use glam::Vec3;

/// A pinhole camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub position: Vec3,
    pub look_at: Vec3,
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub vfov_degrees: f32,
}

/// A camera pose at a frame; the track interpolates linearly between keys.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraKey {
    pub frame: u32,
    pub camera: Camera,
}

/// Keyframes sorted by frame, at least one. Before the first key and after the last the camera
/// holds still.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraTrack {
    keys: Vec<CameraKey>,
}

impl CameraTrack {
    /// A track from keys in any order; `None` when there are none or two share a frame.
    pub fn new(mut keys: Vec<CameraKey>) -> Option<Self> {
        keys.sort_by_key(|k| k.frame);
        if keys.is_empty() || keys.windows(2).any(|w| w[0].frame == w[1].frame) {
            return None;
        }
        Some(Self { keys })
    }

    pub fn fixed(camera: Camera) -> Self {
        Self {
            keys: vec![CameraKey { frame: 0, camera }],
        }
    }

    pub fn keys(&self) -> &[CameraKey] {
        &self.keys
    }

    /// The camera at `frame`.
    pub fn at(&self, frame: u32) -> Camera {
        let after = self.keys.partition_point(|k| k.frame <= frame);
        if after == 0 {
            return self.keys[0].camera;
        }
        if after == self.keys.len() {
            return self.keys[after - 1].camera;
        }
        let (a, b) = (&self.keys[after - 1], &self.keys[after]);
        let s = (frame - a.frame) as f32 / (b.frame - a.frame) as f32;
        Camera {
            position: a.camera.position.lerp(b.camera.position, s),
            look_at: a.camera.look_at.lerp(b.camera.look_at, s),
            up: a.camera.up.lerp(b.camera.up, s),
            vfov_degrees: a.camera.vfov_degrees
                + s * (b.camera.vfov_degrees - a.camera.vfov_degrees),
        }
    }
}

/// A camera set up for one image size: generates primary rays.
#[derive(Clone, Copy, Debug)]
pub struct CameraRays {
    origin: Vec3,
    forward: Vec3,
    right: Vec3,
    down: Vec3,
    width: f32,
    height: f32,
}

impl Camera {
    pub fn rays(&self, width: u32, height: u32) -> CameraRays {
        let forward = (self.look_at - self.position).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        let half_height = (0.5 * self.vfov_degrees.to_radians()).tan();
        let half_width = half_height * width as f32 / height as f32;
        CameraRays {
            origin: self.position,
            forward,
            right: right * half_width,
            down: -up * half_height,
            width: width as f32,
            height: height as f32,
        }
    }
}

impl CameraRays {
    /// The primary ray through image position (`x`, `y`) in pixels, (0, 0) the top-left corner.
    pub fn ray(&self, x: f32, y: f32) -> Ray {
        let sx = 2.0 * x / self.width - 1.0;
        let sy = 2.0 * y / self.height - 1.0;
        let dir = (self.forward + sx * self.right + sy * self.down).normalize();
        Ray {
            origin: self.origin,
            dir,
            t_max: f32::INFINITY,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam(x: f32) -> Camera {
        Camera {
            position: Vec3::new(x, 0.0, 0.0),
            look_at: Vec3::new(x, 0.0, 1.0),
            up: Vec3::Y,
            vfov_degrees: 40.0,
        }
    }

    #[test]
    fn track_interpolates_and_holds() {
        let track = CameraTrack::new(vec![
            CameraKey {
                frame: 10,
                camera: cam(1.0),
            },
            CameraKey {
                frame: 0,
                camera: cam(0.0),
            },
        ])
        .unwrap();
        assert_eq!(track.at(5).position.x, 0.5);
        assert_eq!(track.at(20).position.x, 1.0);
        assert!(CameraTrack::new(vec![]).is_none());
    }

    #[test]
    fn centre_ray_looks_forward_and_corners_span_the_fov() {
        let rays = cam(0.0).rays(100, 50);
        assert!((rays.ray(50.0, 25.0).dir - Vec3::Z).length() < 1e-6);
        let top = rays.ray(50.0, 0.0).dir;
        assert!((top.y.atan2(top.z).to_degrees() - 20.0).abs() < 1e-4);
        // Image x grows to the right of the view: with up +y and forward +z, right is -x.
        assert!(rays.ray(100.0, 25.0).dir.x < 0.0);
    }
}
