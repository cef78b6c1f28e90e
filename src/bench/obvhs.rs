//! The `obvhs` crate's BVH2 and CWBVH, each with triangles reordered into leaf order (as its
//! examples recommend) and its own Möller-Trumbore triangle test.

use std::time::Duration;

use glam_obvhs::Vec3A;
use obvhs::ray::{Ray as ORay, RayHit};
use obvhs::triangle::Triangle as OTri;

use super::HitRecord;
use super::engines::Engine;
use crate::geometry::Ray;

fn to_otris(tris: &[[glam::Vec3; 3]]) -> Vec<OTri> {
    let v = |p: glam::Vec3| Vec3A::new(p.x, p.y, p.z);
    tris.iter()
        .map(|t| OTri {
            v0: v(t[0]),
            v1: v(t[1]),
            v2: v(t[2]),
        })
        .collect()
}

fn oray(r: &Ray) -> ORay {
    ORay::new_inf(
        Vec3A::new(r.origin.x, r.origin.y, r.origin.z),
        Vec3A::new(r.dir.x, r.dir.y, r.dir.z),
    )
}

/// An obvhs BVH with its triangles in leaf order. Both kinds have the same traversal methods
/// but no shared trait, hence the macro.
macro_rules! obvhs_engine {
    ($name:ident, $bvh:ty, $build:path) => {
        pub(super) struct $name {
            bvh: $bvh,
            tris: Vec<OTri>,
        }

        impl $name {
            /// Builds with the medium preset, then puts the triangles in leaf order.
            pub(super) fn build(triangles: &[[glam::Vec3; 3]]) -> Self {
                let o = to_otris(triangles);
                let bvh = $build(
                    &o,
                    obvhs::BvhBuildParams::medium_build(),
                    &mut Duration::default(),
                );
                let tris = bvh
                    .primitive_indices
                    .iter()
                    .map(|&i| o[i as usize])
                    .collect();
                Self { bvh, tris }
            }
        }

        impl Engine for $name {
            fn closest(&self, ray: &Ray) -> HitRecord {
                let mut hit = RayHit::none();
                if self
                    .bvh
                    .ray_traverse(oray(ray), &mut hit, |r, id| self.tris[id].intersect(r))
                {
                    HitRecord {
                        t: hit.t,
                        prim: self.bvh.primitive_indices[hit.primitive_id as usize],
                    }
                } else {
                    HitRecord::MISS
                }
            }
            fn occluded(&self, ray: &Ray) -> bool {
                !self
                    .bvh
                    .ray_traverse_miss(oray(ray), |r, id| self.tris[id].intersect(r))
            }
        }
    };
}

obvhs_engine!(
    Bvh2,
    obvhs::bvh2::Bvh2,
    obvhs::bvh2::builder::build_bvh2_from_tris
);
obvhs_engine!(
    Cwbvh,
    obvhs::cwbvh::CwBvh,
    obvhs::cwbvh::builder::build_cwbvh_from_tris
);
