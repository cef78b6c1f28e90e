//! What rays that leave the scene see.

use glam::Vec3;

use crate::scene::Environment;

/// Radiance the environment sends along `dir` (image environments arrive with their loaders;
/// until then they count as black).
pub fn environment(env: &Environment, dir: Vec3) -> Vec3 {
    match env {
        Environment::None | Environment::CubeMap { .. } | Environment::Equirect { .. } => {
            Vec3::ZERO
        }
        Environment::Color(c) => *c,
        Environment::Sky { intensity, .. } => sky(dir) * *intensity,
    }
}

/// A simple procedural sky: a horizon-to-zenith gradient over a darker ground.
pub fn sky(dir: Vec3) -> Vec3 {
    let d = dir.try_normalize().unwrap_or(Vec3::Y);
    if d.y >= 0.0 {
        let t = d.y.powf(0.5);
        Vec3::new(0.85, 0.9, 1.0).lerp(Vec3::new(0.25, 0.45, 0.85), t)
    } else {
        let t = (-d.y).powf(0.5);
        Vec3::new(0.5, 0.47, 0.45).lerp(Vec3::new(0.2, 0.18, 0.16), t)
    }
}
