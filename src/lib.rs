//! Tracery: an interactive CPU ray tracer with a BVH you can see into.
//!
//! The core (this library without the `viewer` feature) loads scenes, builds the BVH, traces
//! rays and renders images on all cores, with no window and no Bevy:
//!
//! - [`geometry`]: rays, boxes and the watertight triangle test.
//! - [`bvh`]: median and binned-SAH builders, closest-hit, any-hit and transmittance queries.

pub mod bench;
pub mod bvh;
pub mod camera;
pub mod film;
pub mod geometry;
pub mod render;
pub mod sampling;
pub mod scene;
