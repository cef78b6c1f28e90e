use glam::{Vec3, Vec3A};

use super::{PreparedRay, gamma};

/// An axis-aligned bounding box. The empty box has `min = +inf`, `max = -inf`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Vec3A,
    /// Largest corner.
    pub max: Vec3A,
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    /// The empty box: growing it by anything gives that thing's box.
    pub const EMPTY: Aabb = Aabb {
        min: Vec3A::INFINITY,
        max: Vec3A::NEG_INFINITY,
    };

    /// The box spanning two corners.
    pub fn new(min: Vec3, max: Vec3) -> Self {
        Self {
            min: min.into(),
            max: max.into(),
        }
    }

    /// The box around the finite points of `points` (empty when none is).
    pub fn of_finite_points(points: impl IntoIterator<Item = Vec3>) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in points.into_iter().filter(|p| p.is_finite()) {
            b.grow_point(p.into());
        }
        b
    }

    /// Grows the box to hold `p`.
    #[inline]
    pub fn grow_point(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    /// Grows the box to hold `other`.
    #[inline]
    pub fn grow(&mut self, other: &Aabb) {
        self.min = self.min.min(other.min);
        self.max = self.max.max(other.max);
    }

    /// The union of two boxes.
    #[inline]
    pub fn union(&self, other: &Aabb) -> Aabb {
        let mut b = *self;
        b.grow(other);
        b
    }

    /// True for the empty box (or any box with `min > max` on some axis).
    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    /// `max - min`, zero for an empty box.
    pub fn extent(&self) -> Vec3A {
        if self.is_empty() {
            Vec3A::ZERO
        } else {
            self.max - self.min
        }
    }

    /// Midpoint, computed so that it cannot overflow for finite corners.
    pub fn center(&self) -> Vec3A {
        self.min * 0.5 + self.max * 0.5
    }

    /// Half the surface area, in f64 so that boxes with coordinates near `f32::MAX` give a
    /// finite, exact-enough number for the SAH.
    #[inline]
    pub fn half_area(&self) -> f64 {
        if self.is_empty() {
            return 0.0;
        }
        let e = self.max - self.min;
        let (x, y, z) = (e.x as f64, e.y as f64, e.z as f64);
        x * y + y * z + z * x
    }

    /// The axis (0, 1, 2) along which the box is longest.
    pub fn longest_axis(&self) -> usize {
        let e = self.extent();
        if e.x >= e.y && e.x >= e.z {
            0
        } else if e.y >= e.z {
            1
        } else {
            2
        }
    }

    /// The slab test. Returns the entry distance (clamped to `>= 0`) when the ray meets the
    /// closed box at some `t` in `[0, t_max]`, otherwise `None`.
    ///
    /// Robustness: a zero direction component (either sign) gives an infinite reciprocal; when
    /// the origin also lies on that slab's plane, `0 * inf = NaN` for that plane, and the NaN is
    /// ignored, which is the right answer because a ray lying in the plane of a closed slab is
    /// inside it. The far distance is enlarged by `1 + 2 gamma(3)` (Ize, "Robust BVH Ray
    /// Traversal", 2013), so rounding can never make the test miss a box the exact ray meets.
    #[inline(always)]
    pub fn intersect(&self, ray: &PreparedRay, t_max: f32) -> Option<f32> {
        let (t_near, t_far) = self.slab(ray);
        let t_near = t_near.max(0.0);
        let t_far = t_far.min(t_max);
        (t_near <= t_far).then_some(t_near)
    }

    /// Raw slab distances `(t_near, t_far)` over the whole line, `t_far` already conservative.
    /// `t_near > t_far` when the line misses the box.
    #[inline(always)]
    pub fn slab(&self, ray: &PreparedRay) -> (f32, f32) {
        const FAR_SCALE: f32 = if cfg!(feature = "no-conservative-slab") {
            1.0
        } else {
            1.0 + 2.0 * gamma(3)
        };
        let t0 = (self.min - ray.origin) * ray.inv_dir;
        let t1 = (self.max - ray.origin) * ray.inv_dir;
        // Near plane by the direction's sign bit, so `+0` and `-0` give the same answer.
        let near = Vec3A::select(ray.neg_mask, t1, t0);
        let far = Vec3A::select(ray.neg_mask, t0, t1) * FAR_SCALE;
        // A NaN lane (origin on the plane of a slab the ray runs parallel to) constrains
        // nothing: it is replaced by the infinity explicitly (`x == x` is false only for NaN),
        // not left to `max`/`min`, whose NaN rule differs between targets (SSE's `maxps`
        // returns its second operand, NEON's `vmaxq` returns NaN).
        let near = Vec3A::select(near.cmpeq(near), near, Vec3A::NEG_INFINITY);
        let far = Vec3A::select(far.cmpeq(far), far, Vec3A::INFINITY);
        (near.max_element(), far.min_element())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The box of the finite points only: NaN and infinite ones are left out, and none at all
    /// is the empty box.
    #[test]
    fn of_finite_points_leaves_out_the_rest() {
        let b = Aabb::of_finite_points([
            Vec3::new(1.0, -2.0, 3.0),
            Vec3::new(f32::NAN, 100.0, 0.0),
            Vec3::new(-1.0, 0.5, f32::INFINITY),
            Vec3::new(0.0, 4.0, -5.0),
        ]);
        assert_eq!(Vec3::from(b.min), Vec3::new(0.0, -2.0, -5.0));
        assert_eq!(Vec3::from(b.max), Vec3::new(1.0, 4.0, 3.0));
        assert!(Aabb::of_finite_points([Vec3::splat(f32::NAN)]).is_empty());
        assert!(Aabb::of_finite_points([]).is_empty());
    }
}
