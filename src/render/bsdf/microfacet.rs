//! The microfacet functions the GGX lobes share: the GGX distribution of normals, Smith's
//! masking, Schlick's Fresnel, and sampling the normals visible from a direction.

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

/// GGX distribution of normals of width `a` at `cos_h = n.h`.
pub(super) fn ggx_d(cos_h: f32, a: f32) -> f32 {
    if cos_h <= 0.0 {
        return 0.0;
    }
    let a2 = a * a;
    let k = cos_h * cos_h * (a2 - 1.0) + 1.0;
    a2 / (PI * k * k)
}

/// Smith's masking of GGX width `a` for a direction at cosine `c` to the normal.
pub(super) fn smith_g1(c: f32, a: f32) -> f32 {
    if c <= 0.0 {
        return 0.0;
    }
    let a2 = a * a;
    2.0 * c / (c + (a2 + (1.0 - a2) * c * c).sqrt())
}

/// Schlick's Fresnel reflectance from `f0` to `f90` at cosine `c` between the view and the half
/// vector.
pub(super) fn schlick(f0: Vec3, f90: f32, c: f32) -> Vec3 {
    let k = (1.0 - c).clamp(0.0, 1.0).powi(5);
    f0 + (Vec3::splat(f90) - f0) * k
}

/// [`schlick`] for one channel, up to 1.
pub(super) fn schlick_scalar(f0: f32, c: f32) -> f32 {
    let k = (1.0 - c).clamp(0.0, 1.0).powi(5);
    f0 + (1.0 - f0) * k
}

/// `wo` reflected about a GGX normal of width `a` (about `n`) visible from it
/// ([`visible_normal`]), `None` when the normal turns away from `wo`.
pub(super) fn reflect_about_visible_normal(n: Vec3, wo: Vec3, a: f32, u: Vec2) -> Option<Vec3> {
    let (t, b) = n.any_orthonormal_pair();
    let local = Vec3::new(wo.dot(t), wo.dot(b), wo.dot(n));
    let m = visible_normal(local, a, u);
    let h = t * m.x + b * m.y + n * m.z;
    let vh = wo.dot(h);
    if vh <= 0.0 {
        return None;
    }
    Some((2.0 * vh * h - wo).normalize())
}

/// A GGX normal of width `a` visible from `wo` (in the frame whose `z` is the normal), drawn
/// in proportion to its projected area (Heitz 2018, "Sampling the GGX distribution of visible
/// normals").
fn visible_normal(wo: Vec3, a: f32, u: Vec2) -> Vec3 {
    // Stretch the view so that the distribution becomes the hemisphere of width 1.
    let v = Vec3::new(a * wo.x, a * wo.y, wo.z).normalize();
    let len2 = v.x * v.x + v.y * v.y;
    let t1 = if len2 > 0.0 {
        Vec3::new(-v.y, v.x, 0.0) / len2.sqrt()
    } else {
        Vec3::X
    };
    let t2 = v.cross(t1);
    // A point of the unit disk, squeezed onto the part of the hemisphere `v` sees.
    let r = u.x.sqrt();
    let phi = 2.0 * PI * u.y;
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + v.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * v;
    // Back to the ellipsoid of width `a`.
    Vec3::new(a * nh.x, a * nh.y, nh.z.max(0.0)).normalize()
}
