//! The Lambertian lobe: `diffuse / pi`, sampled by cosine-weighted directions.

use std::f32::consts::FRAC_1_PI;

use glam::{Vec2, Vec3};

use super::{Lobe, luminance};
use crate::sampling::cosine_direction;

/// A Lambertian lobe of the colour it holds (its reflectance, linear RGB).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lambert(pub Vec3);

impl Lobe for Lambert {
    #[inline]
    fn eval(&self, _n: Vec3, _wi: Vec3, _wo: Vec3, _h: Vec3) -> Option<Vec3> {
        Some(self.0 * FRAC_1_PI)
    }

    #[inline]
    fn pdf(&self, n: Vec3, wi: Vec3, _wo: Vec3, _h: Vec3) -> f32 {
        let cos = n.dot(wi);
        if cos > 0.0 { cos * FRAC_1_PI } else { 0.0 }
    }

    #[inline]
    fn sample(&self, n: Vec3, _wo: Vec3, u: Vec2) -> Option<Vec3> {
        Some(cosine_direction(n, u))
    }

    fn reflectance(&self, _c: f32) -> f32 {
        luminance(self.0)
    }
}
