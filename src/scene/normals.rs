//! Shading normals for meshes whose file gives none.
//!
//! The rule, by source (docs/formats.md, "Normals", says the same):
//! - A file's own normals (OBJ `vn`, PLY `nx ny nz`) are used as they are.
//! - OBJ without normals: faces are flat, except inside a smoothing group (`s 1`, `s 2`, ...;
//!   `s off` and `s 0` end smoothing), where a vertex's normal averages the faces of its group
//!   that share it.
//! - PLY without normals: smooth across an edge when the two faces meet at less than
//!   [`DEFAULT_CREASE_DEG`] (sharper edges stay sharp).
//! - glTF without `NORMAL`: flat, as the glTF specification asks.
//! - Generated meshes: the sphere has its exact normals, cubes and quads are flat.
//! - A scene file may override any mesh's rule with `crease_angle` (degrees; 0 is flat).
//!
//! Averages are area-weighted, per corner: a corner's normal sums the (unnormalized) normals
//! of the faces around its vertex that its own face may be smoothed with, so a vertex on a
//! box's edge has one normal per side of the crease.

use glam::Vec3;

use super::face_normal;

/// Crease angle for PLY meshes without normals, in degrees: faces meeting at a smaller angle
/// are shaded smooth across their edge. Scanned meshes (bunny, dragon) have neighbouring faces
/// within a few degrees of each other; modelled boxes have 90-degree edges.
pub const DEFAULT_CREASE_DEG: f32 = 60.0;

/// How to compute normals where a file gives none.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NormalRule {
    /// Smooth only among faces of the same nonzero group (OBJ `s`); group 0 is flat.
    Groups,
    /// Smooth across edges where the faces' normals differ by less than this many degrees.
    Crease(f32),
}

/// Per-corner shading normals of an indexed triangle list. `groups` gives each face's smoothing
/// group for [`NormalRule::Groups`] (ignored for [`NormalRule::Crease`]; missing entries count
/// as group 0). Indices must be in range. Corners that average to nothing (a degenerate face
/// alone) get the face normal.
pub fn corner_normals(
    positions: &[Vec3],
    indices: &[[u32; 3]],
    rule: NormalRule,
    groups: &[u32],
) -> Vec<[Vec3; 3]> {
    // Area-weighted face normals (the cross product's length is twice the area).
    let weighted: Vec<Vec3> = indices
        .iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| positions[i as usize]);
            let n = (b - a).cross(c - a);
            if n.is_finite() { n } else { Vec3::ZERO }
        })
        .collect();
    let unit: Vec<Vec3> = weighted.iter().map(|n| n.normalize_or_zero()).collect();
    let group = |f: usize| groups.get(f).copied().unwrap_or(0);
    let cos_crease = match rule {
        NormalRule::Crease(deg) if deg > 0.0 => Some(deg.min(180.0).to_radians().cos()),
        _ => None,
    };

    // Faces around each vertex, as a compressed adjacency list.
    let mut start = vec![0u32; positions.len() + 1];
    for f in indices {
        for &i in f {
            start[i as usize + 1] += 1;
        }
    }
    for i in 0..positions.len() {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut around = vec![0u32; start[positions.len()] as usize];
    for (fi, f) in indices.iter().enumerate() {
        for &i in f {
            around[fill[i as usize] as usize] = fi as u32;
            fill[i as usize] += 1;
        }
    }

    indices
        .iter()
        .enumerate()
        .map(|(fi, f)| {
            let flat = face_normal(&f.map(|i| positions[i as usize]));
            let smooth_with = |g: usize| -> bool {
                match rule {
                    NormalRule::Groups => {
                        let grp = group(fi);
                        grp != 0 && group(g) == grp
                    }
                    NormalRule::Crease(_) => match cos_crease {
                        // Strictly below the angle: faces at exactly the crease stay sharp.
                        Some(c) => unit[fi].dot(unit[g]) > c,
                        None => false,
                    },
                }
            };
            f.map(|v| {
                let v = v as usize;
                let mut sum = weighted[fi];
                for &g in &around[start[v] as usize..start[v + 1] as usize] {
                    let g = g as usize;
                    if g != fi && smooth_with(g) {
                        sum += weighted[g];
                    }
                }
                sum.try_normalize().unwrap_or(flat)
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two faces of a box meeting at a right angle along the edge (0,0,0)-(0,1,0).
    fn right_angle() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ];
        // Face 0 in the plane z = 0 (normal -z), face 1 in the plane x = 0 (normal +x... or -x).
        (p, vec![[0, 1, 2], [0, 3, 1]])
    }

    #[test]
    fn a_right_angle_stays_sharp_below_a_60_degree_crease() {
        let (p, f) = right_angle();
        let n = corner_normals(&p, &f, NormalRule::Crease(60.0), &[]);
        for (fi, face) in f.iter().enumerate() {
            let flat = face_normal(&face.map(|i| p[i as usize]));
            assert_eq!(n[fi], [flat; 3]);
        }
    }

    #[test]
    fn a_right_angle_is_smoothed_at_a_larger_crease_and_in_one_group() {
        let (p, f) = right_angle();
        for n in [
            corner_normals(&p, &f, NormalRule::Crease(100.0), &[]),
            corner_normals(&p, &f, NormalRule::Groups, &[1, 1]),
        ] {
            // Shared corners average both faces; the corners off the edge keep their face.
            let shared = n[0][0];
            assert!((shared.length() - 1.0).abs() < 1e-6);
            assert_eq!(n[0][0], n[1][0]);
            assert_eq!(n[0][1], n[1][2]);
            let flat0 = face_normal(&f[0].map(|i| p[i as usize]));
            assert!(shared.dot(flat0) > 0.7 && shared.dot(flat0) < 0.71);
            assert_eq!(n[0][2], flat0);
        }
    }

    #[test]
    fn group_zero_and_different_groups_stay_flat() {
        let (p, f) = right_angle();
        for groups in [[0, 0], [1, 2], [0, 1]] {
            let n = corner_normals(&p, &f, NormalRule::Groups, &groups);
            for (fi, face) in f.iter().enumerate() {
                assert_eq!(n[fi], [face_normal(&face.map(|i| p[i as usize])); 3]);
            }
        }
    }
}
