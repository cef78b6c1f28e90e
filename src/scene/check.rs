//! Mesh diagnostics for `tracery check-mesh`: what in a triangle soup a ray tracer should know
//! about before it renders it. Vertices are compared by exact position (bit patterns, with
//! `-0` folded into `+0`), the way the triangles themselves meet or fail to.

use std::collections::HashMap;

use glam::{DVec3, Vec3};
use serde::Serialize;

use crate::geometry::{Aabb, is_degenerate};

/// A triangle counts as a needle above this aspect ratio (longest edge squared over twice
/// the area: the longest edge over the height onto it).
pub const NEEDLE_ASPECT: f64 = 1e3;

/// What [`check_mesh`] found. Indices are triangle numbers in input order (at most
/// [`MeshReport::EXAMPLES`] kept per finding).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MeshReport {
    /// Triangles in the mesh.
    pub triangles: usize,
    /// Box around the finite vertices (`None` when there are none).
    pub bounds: Option<[[f32; 3]; 2]>,
    /// Distinct vertex positions (finite ones).
    pub vertices: usize,
    /// Triangles with a NaN or infinite coordinate (the BVH leaves them out).
    pub non_finite: Finding,
    /// Triangles of exactly zero area: collinear or coinciding vertices (left out too).
    pub degenerate: Finding,
    /// Triangles thinner than [`NEEDLE_ASPECT`]: legal, but a sign of broken geometry and the
    /// hardest case for watertight intersection.
    pub needles: Finding,
    /// Triangles that repeat an earlier one (same three vertices, any order or winding).
    pub duplicates: Finding,
    /// Edges used by exactly one triangle: holes or borders (a closed mesh has none).
    pub open_edges: Finding,
    /// Edges shared by more than two triangles.
    pub non_manifold_edges: Finding,
}

/// How many of something, and the first few of them.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Finding {
    /// How many.
    pub count: usize,
    /// The first triangle indices concerned.
    pub examples: Vec<usize>,
}

impl Finding {
    fn add(&mut self, index: usize) {
        self.count += 1;
        if self.examples.len() < MeshReport::EXAMPLES {
            self.examples.push(index);
        }
    }
}

impl MeshReport {
    /// Examples kept per finding.
    pub const EXAMPLES: usize = 5;

    /// True when nothing would make a renderer drop, double or leak through a triangle: no
    /// non-finite, degenerate or duplicate triangles and no non-manifold edges. Open edges
    /// and needles are reported but allowed (a floor quad is open; a needle is still exact).
    pub fn is_clean(&self) -> bool {
        self.non_finite.count == 0
            && self.degenerate.count == 0
            && self.duplicates.count == 0
            && self.non_manifold_edges.count == 0
    }

    /// True when the mesh is closed: every edge is shared by exactly two triangles.
    pub fn is_closed(&self) -> bool {
        self.triangles > 0 && self.open_edges.count == 0 && self.non_manifold_edges.count == 0
    }
}

/// Exact vertex key: the coordinate bit patterns, `-0` folded into `+0`.
fn key(v: Vec3) -> [u32; 3] {
    v.to_array().map(|c| (c + 0.0).to_bits())
}

/// Longest edge squared over twice the area, in f64 (infinite for zero area).
pub fn aspect_ratio(t: &[Vec3; 3]) -> f64 {
    let [a, b, c] = t.map(|v| v.as_dvec3());
    let longest = [(b - a), (c - b), (a - c)]
        .into_iter()
        .map(DVec3::length_squared)
        .fold(0.0, f64::max);
    let twice_area = (b - a).cross(c - a).length();
    if twice_area == 0.0 {
        f64::INFINITY
    } else {
        longest / twice_area
    }
}

/// Checks a triangle soup.
pub fn check_mesh(triangles: &[[Vec3; 3]]) -> MeshReport {
    let mut r = MeshReport {
        triangles: triangles.len(),
        ..MeshReport::default()
    };
    let mut bounds = Aabb::EMPTY;
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let mut seen: HashMap<[u32; 3], usize> = HashMap::new();
    // Edge (lower vertex id, higher) -> (triangles using it, first such triangle).
    let mut edges: HashMap<(u32, u32), (u32, usize)> = HashMap::new();
    for (i, t) in triangles.iter().enumerate() {
        if !t.iter().all(|v| v.is_finite()) {
            r.non_finite.add(i);
            continue;
        }
        for v in t {
            bounds.grow_point((*v).into());
        }
        let mut vid = [0u32; 3];
        for (k, v) in t.iter().enumerate() {
            let fresh = ids.len() as u32;
            vid[k] = *ids.entry(key(*v)).or_insert(fresh);
        }
        if is_degenerate(t) {
            r.degenerate.add(i);
            continue;
        }
        if aspect_ratio(t) > NEEDLE_ASPECT {
            r.needles.add(i);
        }
        let mut sorted = vid;
        sorted.sort_unstable();
        if seen.insert(sorted, i).is_some() {
            r.duplicates.add(i);
            continue;
        }
        for (a, b) in [(vid[0], vid[1]), (vid[1], vid[2]), (vid[2], vid[0])] {
            let e = edges.entry((a.min(b), a.max(b))).or_insert((0, i));
            e.0 += 1;
        }
    }
    let mut open: Vec<usize> = Vec::new();
    let mut non_manifold: Vec<usize> = Vec::new();
    for &(uses, first) in edges.values() {
        match uses {
            1 => open.push(first),
            2 => {}
            _ => non_manifold.push(first),
        }
    }
    // Report examples in input order, whatever the hash order.
    open.sort_unstable();
    non_manifold.sort_unstable();
    for i in open {
        r.open_edges.add(i);
    }
    for i in non_manifold {
        r.non_manifold_edges.add(i);
    }
    r.vertices = ids.len();
    if !bounds.is_empty() {
        r.bounds = Some([bounds.min, bounds.max].map(|v| Vec3::from(v).to_array()));
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::shapes;

    #[test]
    fn a_closed_icosphere_is_clean_and_closed() {
        let r = check_mesh(&shapes::icosphere(2));
        assert!(r.is_clean() && r.is_closed(), "{r:?}");
        assert_eq!(r.triangles, 320);
        assert_eq!(r.vertices, 162);
    }

    #[test]
    fn a_quad_is_clean_but_open() {
        let r = check_mesh(&shapes::quad());
        assert!(r.is_clean() && !r.is_closed());
        assert_eq!(r.open_edges.count, 4);
    }

    #[test]
    fn every_kind_of_trouble_is_counted_once() {
        let mut tris = shapes::icosphere(1);
        let n = tris.len();
        tris.push(tris[3]); // duplicate (same winding)
        tris.push([tris[5][0], tris[5][2], tris[5][1]]); // duplicate (flipped)
        tris.push([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]); // collinear
        tris.push([Vec3::ZERO, Vec3::NAN, Vec3::Y]); // non-finite
        tris.push([Vec3::ZERO, Vec3::X, Vec3::new(0.5, 1e-4, 0.0)]); // needle, open
        let r = check_mesh(&tris);
        assert_eq!(r.duplicates.count, 2);
        assert_eq!(r.duplicates.examples, vec![n, n + 1]);
        assert_eq!(r.degenerate.examples, vec![n + 2]);
        assert_eq!(r.non_finite.examples, vec![n + 3]);
        assert_eq!(r.needles.examples, vec![n + 4]);
        assert_eq!(r.open_edges.count, 3);
        assert_eq!(r.non_manifold_edges.count, 0);
        assert!(!r.is_clean());
        assert_eq!(r.bounds.unwrap()[1][0], 2.0);
    }

    #[test]
    fn a_fin_on_a_closed_mesh_makes_non_manifold_edges() {
        let mut tris = shapes::icosphere(1);
        let [a, b, _] = tris[0];
        tris.push([a, b, (a + b) * 2.0]);
        let r = check_mesh(&tris);
        assert_eq!(r.non_manifold_edges.count, 1);
        assert_eq!(r.open_edges.count, 2);
        assert!(!r.is_clean());
    }

    #[test]
    fn minus_zero_welds_with_plus_zero() {
        let a = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let b = [Vec3::new(-0.0, 0.0, -0.0), Vec3::Y, Vec3::X];
        assert_eq!(check_mesh(&[a, b]).duplicates.count, 1);
    }
}
