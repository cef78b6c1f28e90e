//! The shadowing of a normal a normal or height map bent ([`super`]'s docs: the soft shadow
//! terminator).

use glam::Vec3;

/// The shadowing a normal or height map's bent normal is given (see the module docs): the
/// normal before the map, and the microfacet roughness the bend stands for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bump {
    /// Unit normal before the map bent it.
    pub n: Vec3,
    /// Squared roughness `min(tan^2(theta_d) / 8, 1)` (0: no shadowing at all).
    pub alpha2: f32,
}

impl Bump {
    /// No shadowing: the surface's normal is its own.
    pub const NONE: Bump = Bump {
        n: Vec3::Z,
        alpha2: 0.0,
    };

    /// The shadowing of `mapped`, the unit normal a map made of `plain` (unit, the same side).
    pub fn new(plain: Vec3, mapped: Vec3) -> Bump {
        let c2 = plain.dot(mapped).powi(2).min(1.0);
        let alpha2 = if c2 > 0.0 {
            (0.125 * (1.0 - c2) / c2).min(1.0)
        } else {
            1.0
        };
        Bump { n: plain, alpha2 }
    }

    /// The share of light from `wi` (unit, away from the surface) the bent normal's surface
    /// is not shadowed from: 1 without a bend, 0 from under the unbent normal.
    #[inline]
    pub fn shadowing(&self, wi: Vec3) -> f32 {
        if self.alpha2 <= 0.0 {
            return 1.0;
        }
        let c = self.n.dot(wi);
        if c <= 0.0 {
            return 0.0;
        }
        let c2 = (c * c).min(1.0);
        let tan2 = (1.0 - c2) / c2;
        2.0 / (1.0 + (1.0 + self.alpha2 * tan2).sqrt())
    }
}
