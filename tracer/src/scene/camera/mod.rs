//! The camera, a pinhole or a thin lens, and its keyframed animation.
//!
//! The thin lens is pbrt's: a disk of `aperture_radius` around `position`, perpendicular to the
//! view direction, focused on the plane `focus_distance` ahead. A ray aims at the point of that
//! plane the pinhole ray through the same image position would reach, from a point of the disk,
//! so everything on the plane is sharp and a point at distance `d` spreads into a disk of
//! diameter `2 aperture_radius |d - focus_distance| / d` measured on the focus plane. An aperture
//! of zero is the pinhole, and traces exactly the pinhole's rays (not a lens of size zero, whose
//! rounding would differ).

use crate::geometry::{PACKET, Ray};
use glam::{Vec2, Vec3};
use wide::f32x8;

/// A pinhole (`aperture_radius` zero) or thin-lens camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// The eye (the lens's centre), in world space.
    pub position: Vec3,
    /// A point in world space the camera looks at; only the direction to it matters.
    pub look_at: Vec3,
    /// Which way is up in the image: the world-space direction that, made perpendicular to the
    /// view direction, points to the top row. Need not be unit length; must not be parallel
    /// to the view direction.
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub vfov_degrees: f32,
    /// The radius of the lens, in scene units; zero is a pinhole.
    pub aperture_radius: f32,
    /// The distance along the view direction of the plane in focus, greater than zero.
    pub focus_distance: f32,
}

/// A camera pose at a frame; the track interpolates linearly between keys.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraKey {
    /// The frame at which the camera has exactly this pose.
    pub frame: u32,
    /// The pose at that frame.
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

    /// A camera that never moves: one key, at frame 0, held for every frame.
    pub fn fixed(camera: Camera) -> Self {
        Self {
            keys: vec![CameraKey { frame: 0, camera }],
        }
    }

    /// The keys, sorted by frame, at least one.
    pub fn keys(&self) -> &[CameraKey] {
        &self.keys
    }

    /// Whether the camera ever moves: two neighbouring keys differ.
    pub fn moves(&self) -> bool {
        self.keys.windows(2).any(|w| w[0].camera != w[1].camera)
    }

    /// The pinhole rays through the image positions (`x[k]`, `y[k]`) of an image of `width` x
    /// `height` pixels, each from the camera at its own time `times[k]`: each lane, to the
    /// bit, `self.at_time(times[k]).rays(width, height).ray(x[k], y[k])`, made together. For a
    /// moving camera's samples under motion blur, whose poses differ sample by sample: made one
    /// by one, each pose's set-up (its axes' two normalisations, the ray's third) was a chain
    /// of divisions and square roots that its ray waited on. Each pose is found lane by lane
    /// ([`CameraTrack::at_time`]) and its half-height's tangent too (once for a run of lanes
    /// with the same field of view, the common case); the axes and the rays are made a
    /// coordinate at a time in eight lanes, each operation as [`Camera::rays`]'s and
    /// [`CameraRays::ray`]'s (glam's `normalize`, `cross`), in their order. Only for pinholes:
    /// the poses' apertures are not looked at (a lens draws its own numbers, and its rays are
    /// made one by one).
    pub fn pinhole_rays_into(
        &self,
        times: &[f64; PACKET],
        (width, height): (u32, u32),
        (x, y): (&[f32; PACKET], &[f32; PACKET]),
        rays: &mut [Ray; PACKET],
    ) {
        let mut poses = [[[0.0f32; PACKET]; 3]; 3];
        let mut half_height = [0.0f32; PACKET];
        let mut last_fov: Option<(u32, f32)> = None;
        for (k, &time) in times.iter().enumerate() {
            let camera = self.at_time(time);
            for (pose, v) in poses
                .iter_mut()
                .zip([camera.position, camera.look_at, camera.up])
            {
                (pose[0][k], pose[1][k], pose[2][k]) = (v.x, v.y, v.z);
            }
            let fov = camera.vfov_degrees.to_bits();
            half_height[k] = match last_fov {
                Some((bits, tangent)) if bits == fov => tangent,
                _ => crate::math::tan(0.5 * camera.vfov_degrees.to_radians()),
            };
            last_fov = Some((fov, half_height[k]));
        }
        let lanes = |v: &[[f32; PACKET]; 3]| v.map(f32x8::from);
        let ([px, py, pz], [lx, ly, lz], up) =
            (lanes(&poses[0]), lanes(&poses[1]), lanes(&poses[2]));
        let half_height = f32x8::from(half_height);
        // glam's `cross`.
        let cross = |[ax, ay, az]: [f32x8; 3], [bx, by, bz]: [f32x8; 3]| {
            [ay * bz - by * az, az * bx - bz * ax, ax * by - bx * ay]
        };
        // `Camera::rays`.
        let forward = normalize_lanes([lx - px, ly - py, lz - pz]);
        let right = normalize_lanes(cross(forward, up));
        let up = cross(right, forward);
        let half_width = half_height * f32x8::splat(width as f32) / f32x8::splat(height as f32);
        let right = right.map(|r| r * half_width);
        // `-up` times one less than zero, not `wide`'s negation, which subtracts from zero and
        // so turns `-0.0` into `+0.0` where glam's flips the sign (an exact product either way).
        let down = up.map(|u| u * f32x8::splat(-1.0) * half_height);
        let size = (width as f32, height as f32);
        let origin = |k: usize| Vec3::new(poses[0][0][k], poses[0][1][k], poses[0][2][k]);
        lane_rays([forward, right, down], size, (x, y), origin, rays);
    }

    /// The camera at `frame`.
    pub fn at(&self, frame: u32) -> Camera {
        self.at_time(f64::from(frame))
    }

    /// The camera at `time`, in frames (motion blur takes samples between frames).
    ///
    /// The fraction between keys is computed in f64 and rounded once to f32. For a whole frame
    /// `f` that is the f32 quotient `(f - a) / (b - a)` the camera always used, to the bit, while
    /// the key gaps stay below 2^24 frames: both are then the correctly rounded quotient of the
    /// same integers, since rounding a quotient first to 53 bits and then to 24 is innocuous
    /// (Figueroa, 1995: 53 >= 2 * 24 + 2).
    pub fn at_time(&self, time: f64) -> Camera {
        let after = self.keys.partition_point(|k| f64::from(k.frame) <= time);
        if after == 0 {
            return self.keys[0].camera;
        }
        if after == self.keys.len() {
            return self.keys[after - 1].camera;
        }
        let (a, b) = (&self.keys[after - 1], &self.keys[after]);
        let s = ((time - f64::from(a.frame)) / (f64::from(b.frame) - f64::from(a.frame))) as f32;
        Camera {
            position: a.camera.position.lerp(b.camera.position, s),
            look_at: a.camera.look_at.lerp(b.camera.look_at, s),
            up: a.camera.up.lerp(b.camera.up, s),
            vfov_degrees: lerp(a.camera.vfov_degrees, b.camera.vfov_degrees, s),
            aperture_radius: lerp(a.camera.aperture_radius, b.camera.aperture_radius, s),
            focus_distance: lerp(a.camera.focus_distance, b.camera.focus_distance, s),
        }
    }
}

/// [`CameraRays::ray`] for eight image positions from eight sets of the view's axes (forward,
/// right scaled to the image's half width, down to its half height; one coordinate of all
/// eight in each vector) in an image of `width` x `height` pixels, lane `k`'s ray from
/// `origin(k)`: `towards`, then glam's `normalize`, a coordinate at a time, each operation as
/// theirs in their order (`wide`'s lanes round as scalar instructions do, and contract
/// nothing), so that the divisions and square roots of eight rays overlap where one ray's
/// waited on the last. The still pinhole's rays and the moving one's both end here.
#[inline(always)]
fn lane_rays(
    [forward, right, down]: [[f32x8; 3]; 3],
    (width, height): (f32, f32),
    (x, y): (&[f32; PACKET], &[f32; PACKET]),
    origin: impl Fn(usize) -> Vec3,
    rays: &mut [Ray; PACKET],
) {
    let splat = f32x8::splat;
    let sx = splat(2.0) * f32x8::from(*x) / splat(width) - splat(1.0);
    let sy = splat(2.0) * f32x8::from(*y) / splat(height) - splat(1.0);
    let towards = |axis: usize| forward[axis] + sx * right[axis] + sy * down[axis];
    let dir = normalize_lanes([towards(0), towards(1), towards(2)]).map(|d| d.to_array());
    for (k, ray) in rays.iter_mut().enumerate() {
        *ray = Ray {
            origin: origin(k),
            dir: Vec3::new(dir[0][k], dir[1][k], dir[2][k]),
            t_max: f32::INFINITY,
        };
    }
}

/// glam's `normalize` of eight vectors, a coordinate at a time: `v * (1 / sqrt(v . v))`, the
/// dot product summed left to right.
#[inline(always)]
fn normalize_lanes([x, y, z]: [f32x8; 3]) -> [f32x8; 3] {
    let recip = f32x8::splat(1.0) / (x * x + y * y + z * z).sqrt();
    [x * recip, y * recip, z * recip]
}

/// `a` moved a fraction `s` towards `b`; `a` itself at `s` = 0, so a key's own frame shows the
/// key's own values.
fn lerp(a: f32, b: f32, s: f32) -> f32 {
    a + s * (b - a)
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
    /// The lens's axes scaled by its radius (zero for a pinhole).
    lens_right: Vec3,
    lens_up: Vec3,
    focus_distance: f32,
}

impl Camera {
    /// What generating rays for an image of `width` x `height` pixels needs, computed once per
    /// camera pose rather than per ray: the view's axes, the image plane's extent, the lens.
    pub fn rays(&self, width: u32, height: u32) -> CameraRays {
        let forward = (self.look_at - self.position).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        let half_height = crate::math::tan(0.5 * self.vfov_degrees.to_radians());
        let half_width = half_height * width as f32 / height as f32;
        CameraRays {
            origin: self.position,
            forward,
            right: right * half_width,
            down: -up * half_height,
            width: width as f32,
            height: height as f32,
            lens_right: right * self.aperture_radius,
            lens_up: up * self.aperture_radius,
            focus_distance: self.focus_distance,
        }
    }
}

impl CameraRays {
    /// The primary ray through image position (`x`, `y`) in pixels, (0, 0) the top-left corner.
    pub fn ray(&self, x: f32, y: f32) -> Ray {
        Ray {
            origin: self.origin,
            dir: self.towards(x, y).normalize(),
            t_max: f32::INFINITY,
        }
    }

    /// The primary rays through the image positions (`x[k]`, `y[k]`), each [`CameraRays::ray`]'s
    /// to the bit, made together: written a coordinate at a time, the loop vectorises, and the
    /// divisions and square roots of eight rays overlap where one ray's waited on the last.
    #[inline]
    pub fn rays_into(&self, x: &[f32; PACKET], y: &[f32; PACKET], rays: &mut [Ray; PACKET]) {
        let axes = [self.forward, self.right, self.down].map(|a| a.to_array().map(f32x8::splat));
        let size = (self.width, self.height);
        lane_rays(axes, size, (x, y), |_| self.origin, rays);
    }

    /// Whether rays start across a lens rather than at one point.
    pub fn has_lens(&self) -> bool {
        self.lens_right != Vec3::ZERO
    }

    /// The ray through image position (`x`, `y`) from the point `lens` (in [0, 1)^2, mapped
    /// onto the disk) of the lens; the pinhole ray when there is no lens.
    // Always inlined (`ray`, smaller, the compiler inlines of itself): as a call, its ray came
    // back through memory, written field by field and read at once in 16-byte loads across
    // those stores, which the processor cannot forward (a stall per camera ray; docs/bench.md,
    // issue 12, twenty-sixth round).
    #[inline(always)]
    pub fn ray_through_lens(&self, x: f32, y: f32, lens: Vec2) -> Ray {
        if !self.has_lens() {
            return self.ray(x, y);
        }
        let disk = crate::math::concentric_disk(lens);
        let offset = disk.x * self.lens_right + disk.y * self.lens_up;
        // `towards` has a forward component of one, so this is the focus plane's point.
        let focus = self.towards(x, y) * self.focus_distance;
        Ray {
            origin: self.origin + offset,
            dir: (focus - offset).normalize(),
            t_max: f32::INFINITY,
        }
    }

    /// The pinhole direction through (`x`, `y`), unnormalised: forward plus the image offset.
    fn towards(&self, x: f32, y: f32) -> Vec3 {
        let sx = 2.0 * x / self.width - 1.0;
        let sy = 2.0 * y / self.height - 1.0;
        self.forward + sx * self.right + sy * self.down
    }
}

#[cfg(test)]
mod tests;
