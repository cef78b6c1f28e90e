use glam::{BVec3A, Vec3, Vec3A};

/// A ray `origin + t * dir`. The direction need not be normalized; `t` is measured in units of
/// its length.
///
/// Laid out as six floats (origin then direction), which the AVX-512 kernel reads a packet of
/// rays as.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Ray {
    /// Where the ray starts.
    pub origin: Vec3,
    /// Which way it goes (not necessarily unit length, never zero for a valid ray).
    pub dir: Vec3,
}

impl Ray {
    /// A ray from `origin` along `dir`.
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self { origin, dir }
    }

    /// The point at distance `t` along the ray.
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.dir * t
    }

    /// True when the origin and direction are finite and the direction is not zero.
    pub fn is_valid(&self) -> bool {
        self.origin.is_finite() && self.dir.is_finite() && self.dir != Vec3::ZERO
    }
}

/// A ray with everything the box and triangle tests need precomputed once per ray.
#[derive(Clone, Copy, Debug)]
pub struct PreparedRay {
    /// Ray origin.
    pub origin: Vec3A,
    /// `1 / dir` per component: `+inf` for `+0`, `-inf` for `-0`.
    pub inv_dir: Vec3A,
    /// Per axis: the direction's sign bit is set (so `-0` counts as negative).
    pub neg_mask: BVec3A,
    /// Triangle test: the axis where `|dir|` is largest, and the two others (Woop et al. 2013).
    pub(crate) k: [usize; 3],
    /// Triangle test shear constants `Sx`, `Sy`, `Sz`.
    pub(crate) shear: [f32; 3],
}

/// The triangle test's axis for the direction `d` (Woop et al. 2013): the one where `|d|` is
/// largest (the first of equals; the last for a NaN direction), and whether `d` points down
/// it, which swaps the other two.
#[inline(always)]
pub(crate) fn shear_axis(d: Vec3) -> (usize, bool) {
    let a = d.abs();
    let kz = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    (kz, d[kz] < 0.0)
}

impl PreparedRay {
    /// Precomputes the per-ray constants of `ray`.
    #[inline(always)]
    pub fn new(ray: &Ray) -> Self {
        let d = ray.dir;
        let inv_dir = Vec3A::ONE / Vec3A::from(d);
        let neg = [
            d.x.is_sign_negative(),
            d.y.is_sign_negative(),
            d.z.is_sign_negative(),
        ];
        let (kz, negative) = shear_axis(d);
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if negative {
            std::mem::swap(&mut kx, &mut ky);
        }
        // One reciprocal (already computed) and two products instead of three divisions: the
        // shear only has to be the same for every triangle the ray meets.
        let sz = inv_dir[kz];
        let shear = [d[kx] * sz, d[ky] * sz, sz];
        Self {
            origin: ray.origin.into(),
            inv_dir,
            neg_mask: BVec3A::new(neg[0], neg[1], neg[2]),
            k: [kx, ky, kz],
            shear,
        }
    }

    /// A prepared ray from its parts as [`PreparedRay::new`] made them (the packet traversal
    /// keeps them component by component). Only the triangle test's parts are used by the
    /// test; the box test's are recomputed from nothing here and left neutral.
    pub(crate) fn from_parts(origin: Vec3A, k: [usize; 3], shear: [f32; 3]) -> Self {
        Self {
            origin,
            inv_dir: Vec3A::ZERO,
            neg_mask: BVec3A::FALSE,
            k,
            shear,
        }
    }
}

/// Bound, per coordinate, on the rounding error of a surface point interpolated from the
/// triangle's vertices with barycentric weights `b` (`b[0] v0 + b[1] v1 + b[2] v2`; Pharr,
/// Jakob and Humphreys, pbrt 3rd ed., 3.9.4). The computed point lies within this box of a point
/// on the triangle's plane; errors in the weights only slide it along the plane.
pub fn interpolation_error(tri: &[Vec3; 3], b: [f32; 3]) -> Vec3 {
    ((tri[0] * b[0]).abs() + (tri[1] * b[1]).abs() + (tri[2] * b[2]).abs()) * super::gamma(7)
}

/// Moves a surface point `p` off its surface along the unit normal `n`, by just more than the
/// point's error bound `err` projected on the normal (twice it, for the rounding in the
/// intersection test the new ray meets), then one float further in each coordinate the normal
/// points along (pbrt 3rd ed., 3.9.5). The step is as small as the point's precision allows,
/// so it neither re-hits the surface nor skips thin geometry: a fixed step in ulps (Waechter
/// and Binder 2019, used before) moved points 2 units at coordinates of 1e5, past a unit box
/// resting on the surface. Pass the normal facing the side the new ray leaves towards.
pub fn offset_ray_origin(p: Vec3, err: Vec3, n: Vec3) -> Vec3 {
    let d = 2.0 * n.abs().dot(err);
    let o = p + n * d;
    let away = |o: f32, n: f32| {
        if n > 0.0 {
            o.next_up()
        } else if n < 0.0 {
            o.next_down()
        } else {
            o
        }
    };
    let out = Vec3::new(away(o.x, n.x), away(o.y, n.y), away(o.z, n.z));
    if out.is_finite() { out } else { p }
}
