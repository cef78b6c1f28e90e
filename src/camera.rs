//! Camera rays: pinhole and thin lens, pixel row 0 at the top.

use glam::{Mat3, Quat, Vec2, Vec3};

use crate::geometry::Ray;
use crate::scene::Camera;

/// A camera's orthonormal frame and image plane, ready to make rays for a `width x height`
/// image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraRays {
    /// Eye position (centre of the lens).
    pub eye: Vec3,
    /// Unit view direction.
    pub forward: Vec3,
    /// Unit direction of increasing pixel x.
    pub right: Vec3,
    /// Unit direction of decreasing pixel y (image up).
    pub up: Vec3,
    /// Half-height of the image plane at distance 1: `tan(vfov / 2)`.
    pub tan_half: f32,
    /// Width over height.
    pub aspect: f32,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Lens radius (0: pinhole).
    pub lens_radius: f32,
    /// Distance to the plane in focus.
    pub focus_distance: f32,
}

impl CameraRays {
    /// Frames `camera` for a `width x height` image. A view direction parallel to `up` (or a
    /// zero or non-finite one) falls back to a valid frame instead of producing NaN. The frame
    /// is that of [`look_rotation`], turned as [`CameraRays::from_pose`] turns it: the viewer,
    /// which places its camera at that rotation, traces the same rays bit for bit.
    pub fn new(camera: &Camera, width: u32, height: u32) -> Self {
        let (forward, right, up) = frame(look_rotation(camera));
        let vfov = camera.vfov_deg.clamp(1e-3, 179.0).to_radians();
        let focus = valid_focus(camera.focus_distance);
        Self {
            eye: camera.position,
            forward,
            right,
            up,
            tan_half: (vfov * 0.5).tan(),
            aspect: width.max(1) as f32 / height.max(1) as f32,
            width,
            height,
            lens_radius: valid_lens(camera.lens_radius),
            focus_distance: focus,
        }
    }

    /// Frames a camera given as a pose: position `eye` and orientation `rotation` of a camera
    /// that looks down its local `-z` with `+y` up (Bevy's convention), a vertical field of
    /// view in radians, and a lens. Rays through the image match what a 3D view with the same
    /// transform and perspective projection shows, pixel for pixel.
    #[allow(clippy::too_many_arguments)]
    pub fn from_pose(
        eye: Vec3,
        rotation: Quat,
        vfov_rad: f32,
        width: u32,
        height: u32,
        lens_radius: f32,
        focus_distance: f32,
    ) -> Self {
        let (forward, right, up) = frame(rotation);
        let vfov = if vfov_rad.is_finite() {
            vfov_rad.clamp(1e-5, 3.12)
        } else {
            std::f32::consts::FRAC_PI_4
        };
        Self {
            eye,
            forward,
            right,
            up,
            tan_half: (vfov * 0.5).tan(),
            aspect: width.max(1) as f32 / height.max(1) as f32,
            width,
            height,
            lens_radius: valid_lens(lens_radius),
            focus_distance: valid_focus(focus_distance),
        }
    }

    /// Direction (not normalized) through the image point `(px, py)` in pixel units, where
    /// `(0, 0)` is the top-left corner of the image and `(width, height)` the bottom-right.
    #[inline]
    pub fn direction(&self, px: f32, py: f32) -> Vec3 {
        let sx = (2.0 * px / self.width as f32 - 1.0) * self.tan_half * self.aspect;
        let sy = (1.0 - 2.0 * py / self.height as f32) * self.tan_half;
        self.forward + sx * self.right + sy * self.up
    }

    /// Where the direction `v` from the eye meets the image: `(px, py)` in pixel units (the
    /// inverse of [`CameraRays::direction`]), or `None` when it points beside or behind the
    /// camera.
    #[inline]
    pub fn pixel_of(&self, v: Vec3) -> Option<(f32, f32)> {
        let z = v.dot(self.forward);
        // (NaN is not in front either.)
        if z.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            return None;
        }
        let sx = v.dot(self.right) / z;
        let sy = v.dot(self.up) / z;
        let px = (sx / (self.tan_half * self.aspect) + 1.0) * 0.5 * self.width as f32;
        let py = (1.0 - sy / self.tan_half) * 0.5 * self.height as f32;
        (px.is_finite() && py.is_finite()).then_some((px, py))
    }

    /// The pinhole ray through `(px, py)`, with a unit direction.
    #[inline]
    pub fn pinhole(&self, px: f32, py: f32) -> Ray {
        Ray::new(self.eye, self.direction(px, py).normalize())
    }

    /// The thin-lens ray through `(px, py)` from lens point `lens` in the unit disk. With a
    /// lens radius of 0 this is exactly [`CameraRays::pinhole`].
    #[inline]
    pub fn thin_lens(&self, px: f32, py: f32, lens: Vec2) -> Ray {
        if self.lens_radius == 0.0 {
            return self.pinhole(px, py);
        }
        let d = self.direction(px, py);
        let offset = self.lens_radius * (lens.x * self.right + lens.y * self.up);
        // Towards the point in focus, eye + d f / (d . forward), written divided by the focus
        // distance f: a focus at infinity gives the pixel's own direction from every lens
        // point (no inf - inf), and a huge lens stays finite.
        let dir = d / d.dot(self.forward) - offset / self.focus_distance;
        let dir = dir / dir.abs().max_element();
        Ray::new(self.eye + offset, dir.normalize())
    }

    /// The rays through every pixel centre, row by row from the top (the benchmark rays).
    pub fn pixel_center_rays(&self) -> Vec<Ray> {
        let mut rays = Vec::with_capacity(self.width as usize * self.height as usize);
        for y in 0..self.height {
            for x in 0..self.width {
                rays.push(self.pinhole(x as f32 + 0.5, y as f32 + 0.5));
            }
        }
        rays
    }
}

/// The orientation of `camera` as a rotation of a camera that looks down its local `-z` with
/// `+y` up (Bevy's convention): its view direction towards `look_at`, its up as close to `up`
/// as the view allows. A view direction parallel to `up` (or a zero or non-finite one) falls
/// back to a valid rotation instead of producing NaN.
pub fn look_rotation(camera: &Camera) -> Quat {
    let forward = (camera.look_at - camera.position)
        .try_normalize()
        .unwrap_or(Vec3::NEG_Z);
    let right = forward
        .cross(camera.up)
        .try_normalize()
        .or_else(|| forward.cross(Vec3::Z).try_normalize())
        .or_else(|| forward.cross(Vec3::X).try_normalize())
        .unwrap_or(Vec3::X);
    let up = right.cross(forward);
    Quat::from_mat3(&Mat3::from_cols(right, up, -forward))
}

/// The view direction, right and up of a camera turned by `rotation` (normalised first; not
/// finite or zero: no turn).
fn frame(rotation: Quat) -> (Vec3, Vec3, Vec3) {
    let rotation = if rotation.is_finite() && rotation.length_squared() > 1e-12 {
        rotation.normalize()
    } else {
        Quat::IDENTITY
    };
    (
        rotation * Vec3::NEG_Z,
        rotation * Vec3::X,
        rotation * Vec3::Y,
    )
}

/// A lens radius the arithmetic can take: negative or NaN is a pinhole, and larger radii
/// (even infinite) are held to 1e30 so lens points stay finite.
fn valid_lens(r: f32) -> f32 {
    if r.is_nan() || r <= 0.0 {
        0.0
    } else {
        r.min(1e30)
    }
}

/// A focus distance: positive, possibly infinite (everything far away in focus); zero,
/// negative or NaN fall back to 1.
fn valid_focus(f: f32) -> f32 {
    if f > 0.0 { f } else { 1.0 }
}
