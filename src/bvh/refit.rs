//! Refitting: a built tree made to fit the same triangles after their vertices moved (an
//! animation's skin or morph, a deforming mesh), keeping its shape. Every box of the tree of
//! record and of the traversal layout ([`super::wide`]) is made again bottom-up from the
//! triangles (children are stored after their parents, so one backward pass does it), and the
//! layout's triangle blocks and visiting orders are made again. This costs
//! a fraction of a build, and the tree answers every query exactly (it holds the moved
//! triangles); what it loses is quality: the triangles were grouped where they were, and as
//! they move apart the boxes grow and overlap. [`Refit::sah_cost`] measures that against the
//! build's cost, and [`Bvh::refit_or_rebuild`] rebuilds past a bound.

use std::time::Instant;

use glam::Vec3;

use super::stats::TreeCounts;
use super::{Bvh, BvhStats};
use crate::geometry::{Aabb, is_degenerate};

/// Largest SAH cost of a refitted tree, as a multiple of its build's, before
/// [`Bvh::refit_or_rebuild`] builds again: past it, the time a rebuild takes is soon won back
/// by faster queries.
pub const REFIT_SAH_BOUND: f64 = 1.5;

/// What a refit did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Refit {
    /// Wall-clock time of the refit, milliseconds.
    pub ms: f64,
    /// SAH cost of the refitted tree.
    pub sah_cost: f64,
}

/// Why a tree cannot be refitted to a triangle list: it must be built again.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum RefitError {
    /// Not the list the tree was built from: another number of triangles.
    Count {
        /// Triangles the tree was built from (those left out included).
        built: usize,
        /// Triangles given.
        given: usize,
    },
    /// A triangle of the tree has a NaN or infinite vertex now.
    NotFinite(u32),
    /// A triangle the build left out (no area, or not finite) has an area now: the tree
    /// does not hold it.
    LeftOut(u32),
}

impl std::fmt::Display for RefitError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RefitError::Count { built, given } => {
                write!(f, "the tree was built from {built} triangles, not {given}")
            }
            RefitError::NotFinite(i) => write!(f, "triangle {i} has a vertex that is not finite"),
            RefitError::LeftOut(i) => write!(
                f,
                "triangle {i}, left out of the build (no area or not finite), has an area now"
            ),
        }
    }
}

impl std::error::Error for RefitError {}

/// What [`Bvh::refit_or_rebuild`] did.
#[derive(Clone, Debug, PartialEq)]
pub enum Update {
    /// The tree was refitted.
    Refitted(Refit),
    /// The tree was built again: why (a refit's cost past the bound, or why it could not be
    /// refitted).
    Rebuilt(String),
}

impl Bvh {
    /// Makes the tree fit `triangles`, the list it was built from with its vertices moved:
    /// every box made again from the triangles, the traversal layout made again from the
    /// tree, the statistics' SAH cost updated. Queries then answer for the moved triangles
    /// exactly as a tree built over them would (only slower, as the tree's quality drops).
    /// An error, leaving the tree as it was, when the list has another length, a triangle of
    /// the tree is no longer finite, or one the build left out has an area now.
    pub fn refit(&mut self, triangles: &[[Vec3; 3]]) -> Result<Refit, RefitError> {
        let start = Instant::now();
        let built = self.stats.triangles + self.stats.excluded + self.stats.degenerate;
        if triangles.len() != built {
            return Err(RefitError::Count {
                built,
                given: triangles.len(),
            });
        }
        // The tree's triangles must be finite; the others (left out by the build) must
        // still have no area, or not be finite. One pass in the list's order.
        let mut held = vec![false; triangles.len()];
        for &id in &self.prim_ids {
            held[id as usize] = true;
        }
        for (i, t) in triangles.iter().enumerate() {
            let finite = t[0].is_finite() && t[1].is_finite() && t[2].is_finite();
            if held[i] && !finite {
                return Err(RefitError::NotFinite(i as u32));
            }
            if !held[i] && finite && !is_degenerate(t) {
                return Err(RefitError::LeftOut(i as u32));
            }
        }
        if self.is_empty() {
            return Ok(Refit {
                ms: 0.0,
                sah_cost: self.stats.sah_cost,
            });
        }
        // The layout first: its blocks then hold the moved triangles in leaf order, which the
        // tree of record's leaves read back (not the caller's scattered list again).
        super::wide::refit(&mut self.wide, triangles);
        // Children follow their parents: backwards, every child's box is made before its
        // parent's. Slot 1 is unused.
        for i in (0..self.nodes.len()).rev() {
            if i == 1 {
                continue;
            }
            let n = self.nodes[i];
            let b = if n.is_leaf() {
                let mut b = Aabb::EMPTY;
                for (_, tri) in self.leaf_triangles(i as u32) {
                    for v in tri {
                        b.grow_point(v);
                    }
                }
                b
            } else {
                let (l, r) = (n.first as usize, n.first as usize + 1);
                self.nodes[l].aabb().union(&self.nodes[r].aabb())
            };
            self.nodes[i].set_aabb(&b);
        }
        let sah_cost = sah_cost(self);
        let ms = start.elapsed().as_secs_f64() * 1e3;
        self.stats = BvhStats {
            sah_cost,
            wide_nodes: self.wide.nodes.len(),
            blocks: self.wide.blocks.len(),
            wide_bytes: self.wide.bytes(),
            ..self.stats
        };
        Ok(Refit { ms, sah_cost })
    }

    /// Refits the tree to `triangles` ([`Bvh::refit`]), or builds it again with its options
    /// when it cannot be refitted or when the refitted tree's SAH cost is more than
    /// [`REFIT_SAH_BOUND`] times `built_cost` (the cost of the tree as last built).
    pub fn refit_or_rebuild(&mut self, triangles: &[[Vec3; 3]], built_cost: f64) -> Update {
        let why = match self.refit(triangles) {
            Ok(r) if r.sah_cost <= built_cost * REFIT_SAH_BOUND => return Update::Refitted(r),
            Ok(r) => format!(
                "the refitted tree's SAH cost {:.2} is past {REFIT_SAH_BOUND} times the build's {built_cost:.2}",
                r.sah_cost
            ),
            Err(e) => e.to_string(),
        };
        *self = Bvh::build(triangles, &self.options);
        Update::Rebuilt(why)
    }
}

/// The SAH cost of a tree, by walking it (the builder counts it as it goes instead).
fn sah_cost(bvh: &Bvh) -> f64 {
    TreeCounts::walk(bvh).sah_cost(bvh.bounds().half_area(), bvh.triangle_count())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::BuildOptions;
    use crate::geometry::shapes;

    /// Refitted to the triangles it was built from, a tree is the built tree: same boxes,
    /// same layout, same SAH cost (the builder's boxes are the triangles' exact bounds).
    #[test]
    fn refitting_to_the_same_triangles_changes_nothing() {
        let tris = shapes::icosphere(3);
        let built = Bvh::build(&tris, &BuildOptions::sah());
        let mut refitted = built.clone();
        let r = refitted.refit(&tris).unwrap();
        assert_eq!(refitted.nodes, built.nodes);
        assert_eq!(refitted.wide.nodes, built.wide.nodes);
        // (Unused lanes hold NaN, which compares unequal to itself: compared as printed.)
        assert_eq!(
            format!("{:?}", refitted.wide.blocks),
            format!("{:?}", built.wide.blocks)
        );
        assert!((r.sah_cost - built.stats.sah_cost).abs() < 1e-9 * built.stats.sah_cost);
    }

    /// Another number of triangles, a vertex gone NaN, and a left-out triangle that has an
    /// area now are refused, and the tree is left as it was.
    #[test]
    fn what_a_refit_cannot_hold_is_refused() {
        let mut tris = shapes::icosphere(2);
        let flat = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        tris.push(flat);
        let mut bvh = Bvh::build(&tris, &BuildOptions::sah());
        let before = bvh.nodes.clone();
        assert!(matches!(
            bvh.refit(&tris[1..]),
            Err(RefitError::Count { .. })
        ));
        let mut nan = tris.clone();
        nan[3][1].y = f32::NAN;
        assert_eq!(bvh.refit(&nan), Err(RefitError::NotFinite(3)));
        let mut grown = tris.clone();
        let last = grown.len() - 1;
        grown[last][2] = Vec3::Y;
        assert_eq!(bvh.refit(&grown), Err(RefitError::LeftOut(last as u32)));
        assert_eq!(bvh.nodes, before);
        assert!(matches!(
            bvh.refit_or_rebuild(&grown, bvh.stats.sah_cost),
            Update::Rebuilt(_)
        ));
        assert_eq!(bvh.triangle_count(), tris.len());
    }
}
