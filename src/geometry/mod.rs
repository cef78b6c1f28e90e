//! Rays, axis-aligned boxes and triangles: the exact, robust primitives the BVH is built on.
//!
//! The rules this module keeps, and why:
//! - The slab test ([`Aabb::intersect`]) is defined for `+0` and `-0` direction components and
//!   for an origin lying on a slab plane, and its far distance is made conservative (Ize 2013),
//!   so the BVH never culls a box that holds a triangle the ray hits.
//! - The ray/triangle test ([`intersect_triangle`]) is watertight (Woop, Benthin and Wald 2013):
//!   a ray through a shared edge or vertex hits exactly one of the triangles that meet there.
//! - Secondary rays leave a surface from [`offset_ray_origin`]: just past the hit point's
//!   rounding-error bound ([`interpolation_error`], pbrt 3.9), never a fixed epsilon.

mod aabb;
mod ray;
pub mod shapes;
mod triangle;

pub use aabb::Aabb;
pub(crate) use ray::shear_axis;
pub use ray::{PreparedRay, Ray, interpolation_error, offset_ray_origin};
pub use triangle::{TriangleHit, intersect_triangle, intersect_triangle_t, is_degenerate};

/// `gamma(n)` of Higham / pbrt: a bound on the relative error of `n` chained f32 roundings.
pub const fn gamma(n: u32) -> f32 {
    let e = f32::EPSILON * 0.5 * n as f32;
    e / (1.0 - e)
}
