//! The camera a scene is seen through, and what rays that leave the scene see.

use std::path::PathBuf;

use glam::Vec3;

use crate::geometry::Aabb;

/// A pinhole or thin-lens camera.
#[derive(Clone, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub position: Vec3,
    /// Point the camera looks at.
    pub look_at: Vec3,
    /// Up direction (need not be orthogonal to the view direction).
    pub up: Vec3,
    /// Vertical field of view in degrees.
    pub vfov_deg: f32,
    /// Lens radius; 0 is a pinhole.
    pub lens_radius: f32,
    /// Distance to the plane in focus.
    pub focus_distance: f32,
}

impl Camera {
    /// The benchmark camera of DESIGN.md for a scene with bounds `b`: center `c`, radius
    /// `r = |max - min| / 2`, eye `c + (0, 0.25 r, 2.2 r)`, looking at `c`, up `+y`, 45 degrees.
    pub fn canonical(b: &Aabb) -> Self {
        let (c, r) = if b.is_empty() {
            (Vec3::ZERO, 1.0)
        } else {
            let c = Vec3::from(b.center());
            let r = (Vec3::from(b.max) - Vec3::from(b.min)).length() * 0.5;
            (c, if r > 0.0 && r.is_finite() { r } else { 1.0 })
        };
        let position = c + Vec3::new(0.0, 0.25 * r, 2.2 * r);
        Self {
            position,
            look_at: c,
            up: Vec3::Y,
            vfov_deg: 45.0,
            lens_radius: 0.0,
            focus_distance: (position - c).length(),
        }
    }
}

/// What rays that leave the scene see.
#[derive(Clone, Debug, PartialEq)]
pub enum Environment {
    /// Black.
    None,
    /// One colour in every direction.
    Color(Vec3),
    /// The procedural sky (no files).
    Sky {
        /// Brightness scale.
        intensity: f32,
        /// Rotation about +y in degrees.
        rotation_deg: f32,
    },
    /// Six images, in the order +x, -x, +y, -y, +z, -z.
    CubeMap {
        /// The face images.
        faces: [PathBuf; 6],
        /// Brightness scale.
        intensity: f32,
        /// Rotation about +y in degrees.
        rotation_deg: f32,
    },
    /// One equirectangular image (HDR, EXR, PNG or JPEG).
    Equirect {
        /// The image.
        path: PathBuf,
        /// Brightness scale.
        intensity: f32,
        /// Rotation about +y in degrees.
        rotation_deg: f32,
    },
}
