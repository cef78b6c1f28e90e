use glam::{BVec3A, Vec3, Vec3A};

/// A ray `origin + t * dir`. The direction need not be normalized; `t` is measured in units of
/// its length.
#[derive(Clone, Copy, Debug, PartialEq)]
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

impl PreparedRay {
    /// Precomputes the per-ray constants of `ray`.
    #[inline]
    pub fn new(ray: &Ray) -> Self {
        let d = ray.dir;
        let inv_dir = Vec3A::ONE / Vec3A::from(d);
        let neg = [
            d.x.is_sign_negative(),
            d.y.is_sign_negative(),
            d.z.is_sign_negative(),
        ];
        let a = d.abs();
        let kz = if a.x >= a.y && a.x >= a.z {
            0
        } else if a.y >= a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
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
}

/// Moves a surface point `p` off the surface along the geometric normal `n`, by an amount that
/// scales with the magnitude of `p`'s coordinates (Waechter and Binder, "A Fast and Robust
/// Method for Avoiding Self-Intersection", Ray Tracing Gems, 2019). Pass the normal facing the
/// side the new ray leaves towards.
pub fn offset_ray_origin(p: Vec3, n: Vec3) -> Vec3 {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    let mut out = [0.0f32; 3];
    for i in 0..3 {
        let of_i = (INT_SCALE * n[i]) as i32;
        let pi = p[i];
        // Step the bit pattern: for negative numbers the magnitude grows the other way.
        let bits = pi.to_bits() as i32;
        let stepped = if pi < 0.0 { bits - of_i } else { bits + of_i };
        let p_i = f32::from_bits(stepped as u32);
        out[i] = if pi.abs() < ORIGIN {
            pi + FLOAT_SCALE * n[i]
        } else if p_i.is_finite() {
            p_i
        } else {
            pi
        };
    }
    Vec3::from(out)
}
