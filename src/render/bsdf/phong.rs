//! The normalised Blinn-Phong lobe (MTL `Ks`/`Ns`, scene files' `specular`/`shininess`):
//! `Ks (Ns + 8) / (8 pi) cos^Ns(theta_h)`, sampled by its half vector, `cos^Ns` about the
//! normal (density `(Ns + 1) / (2 pi) cos^Ns(theta_h)`, over `4 wo.h` for the reflected
//! direction).

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use super::{Lobe, luminance};

/// A Blinn-Phong lobe.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Phong {
    /// Highlight colour (`Ks`).
    pub color: Vec3,
    /// Exponent (`Ns`), at least 0.
    pub exponent: f32,
}

impl Lobe for Phong {
    #[inline]
    fn eval(&self, n: Vec3, _wi: Vec3, _wo: Vec3, h: Vec3) -> Option<Vec3> {
        if self.color == Vec3::ZERO {
            return None;
        }
        let c = n.dot(h).max(0.0);
        let e = self.exponent.max(0.0);
        Some(self.color * (e + 8.0) / (8.0 * PI) * c.powf(e))
    }

    fn pdf(&self, n: Vec3, _wi: Vec3, wo: Vec3, h: Vec3) -> f32 {
        let (nh, vh) = (n.dot(h), wo.dot(h));
        if h == Vec3::ZERO || nh <= 0.0 || vh <= 0.0 {
            return 0.0;
        }
        let e = self.exponent.max(0.0);
        (e + 1.0) / (2.0 * PI) * nh.powf(e) / (4.0 * vh)
    }

    fn sample(&self, n: Vec3, wo: Vec3, u: Vec2) -> Option<Vec3> {
        let (t, b) = n.any_orthonormal_pair();
        let cos = u.x.powf(1.0 / (self.exponent.max(0.0) + 1.0));
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        let h = t * (sin * phi.cos()) + b * (sin * phi.sin()) + n * cos;
        let vh = wo.dot(h);
        if vh <= 0.0 {
            return None;
        }
        Some((2.0 * vh * h - wo).normalize())
    }

    fn reflectance(&self, _c: f32) -> f32 {
        luminance(self.color)
    }
}
