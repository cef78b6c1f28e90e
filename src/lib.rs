//! Tracery: an interactive CPU ray tracer with a BVH you can see into.
//!
//! The core (this library without the `viewer` feature) loads scenes, builds the BVH, traces
//! rays and renders images on all cores, with no window and no Bevy:
//!
//! - [`scene`]: OBJ/MTL, PLY and TOML scene files; the built-in Cornell box; generated meshes.
//! - [`geometry`]: rays, boxes, the watertight triangle test, robust ray origins.
//! - [`bvh`]: median and binned-SAH builders; closest-hit, any-hit, transmittance and visiting
//!   queries; brute force to check them against.
//! - [`camera`], [`render`], [`film`], [`sampling`]: from camera rays to an 8-bit image.
//! - [`mod@bench`]: the canonical benchmark rays, their file formats, and peers measured alike.
//! - [`convergence`]: image error against render time, per sampler, with a plot.
//! - [`denoise`]: Intel Open Image Denoise over a render and its albedo and normal layers
//!   (the `denoise` feature).
//!
//! ```
//! use glam::Vec3;
//! use tracery::bvh::{BuildOptions, Bvh};
//! use tracery::geometry::Ray;
//! use tracery::scene::Scene;
//!
//! let scene = Scene::cornell_box();
//! let bvh = Bvh::build(&scene.mesh.triangles, &BuildOptions::sah());
//! assert_eq!(bvh.stats.triangles, 32);
//!
//! // Straight down from the middle of the box, the first thing below is a block or the floor.
//! let ray = Ray::new(Vec3::new(2.78, 5.0, 2.8), Vec3::NEG_Y);
//! let hit = bvh.intersect(&ray, f32::INFINITY).expect("something is below");
//! assert!(hit.t > 0.0 && hit.t <= 5.0);
//! assert!(!bvh.occluded(&ray, hit.t * 0.5));
//! ```

pub mod bench;
pub mod bvh;
pub mod camera;
pub mod color;
pub mod convergence;
pub mod cpu;
pub mod denoise;
pub mod film;
pub mod geometry;
pub mod plot_font;
pub mod render;
pub mod rng;
pub mod sampling;
pub mod scene;
#[cfg(feature = "viewer")]
pub mod viewer;
