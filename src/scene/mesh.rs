//! Triangles with per-corner normals, texture coordinates and tangents, and a material each,
//! in a local frame whose origin is kept in f64.

use glam::{DVec3, Vec2, Vec3, Vec4};

use super::NormalRule;
use crate::geometry::Aabb;

/// Triangles with their shading normals and materials, in file order.
///
/// Positions are f32 relative to `origin`, an f64 point in world coordinates: files are read in
/// f64 and placed near their own centre, so a mesh a million units from the world's origin keeps
/// the precision it has at the origin (a float at 1e6 is 1/16 apart).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions relative to `origin`, three per triangle.
    pub triangles: Vec<[Vec3; 3]>,
    /// Shading normals, three per triangle (computed when the file has none).
    pub normals: Vec<[Vec3; 3]>,
    /// Index into [`Scene::materials`] per triangle.
    pub material_ids: Vec<u32>,
    /// Texture coordinates, three per triangle; empty when no triangle has any (a triangle
    /// without them among others that have them gets `(0, 0)`).
    pub uvs: Vec<[Vec2; 3]>,
    /// A second set of texture coordinates (glTF `TEXCOORD_1`), read by textures whose
    /// [`Texture::uv_set`] is 1; empty unless a triangle's material has such a texture.
    pub uvs1: Vec<[Vec2; 3]>,
    /// Tangents for normal maps, three per triangle (xyz along `+u`, w the bitangent's sign:
    /// see [`tangents`]); empty when no triangle has any, [`Vec4::ZERO`] for a triangle
    /// without (its material has no normal map).
    pub tangents: Vec<[Vec4; 3]>,
    /// World position of the mesh's local origin (what the user sees is `origin + position`).
    pub origin: DVec3,
}

/// Appends per-triangle values that a mesh may leave empty (texture coordinates, tangents):
/// `mine` holds them for triangles `..before` or is empty, `other` for the triangles appended
/// (up to `after`) or is empty; an empty side is filled with `none` when the other has some.
fn append_optional<T: Copy>(
    mine: &mut Vec<T>,
    other: Vec<T>,
    before: usize,
    after: usize,
    none: T,
) {
    if mine.is_empty() && other.is_empty() {
        return;
    }
    mine.resize(before, none);
    if other.is_empty() {
        mine.resize(after, none);
    } else {
        mine.extend(other);
    }
}

impl Mesh {
    /// Appends another mesh, shifting its material ids by `material_offset`.
    pub fn append(&mut self, mut other: Mesh, material_offset: u32) {
        if self.triangles.is_empty() && self.normals.is_empty() && self.material_ids.is_empty() {
            // Nothing to keep: the other mesh taken whole, not copied.
            other
                .material_ids
                .iter_mut()
                .for_each(|m| *m += material_offset);
            *self = other;
            return;
        }
        let delta = other.origin - self.origin;
        if delta == DVec3::ZERO {
            self.triangles.extend(other.triangles);
        } else {
            // Rebased in f64: each vertex rounds once, to the float nearest its position here.
            self.triangles.extend(
                other
                    .triangles
                    .iter()
                    .map(|t| t.map(|v| (delta + v.as_dvec3()).as_vec3())),
            );
        }
        let before = self.normals.len();
        self.normals.extend(other.normals);
        let after = self.normals.len();
        append_optional(&mut self.uvs, other.uvs, before, after, [Vec2::ZERO; 3]);
        append_optional(&mut self.uvs1, other.uvs1, before, after, [Vec2::ZERO; 3]);
        append_optional(
            &mut self.tangents,
            other.tangents,
            before,
            after,
            [Vec4::ZERO; 3],
        );
        self.material_ids
            .extend(other.material_ids.into_iter().map(|m| m + material_offset));
    }

    /// The texture coordinate of set `set` (0, or 1 for [`Mesh::uvs1`]) at barycentric
    /// `(u, v)` of triangle `prim` (`(0, 0)` when the mesh has none).
    pub fn uv_at(&self, set: u8, prim: u32, u: f32, v: f32) -> Vec2 {
        let uvs = if set == 0 { &self.uvs } else { &self.uvs1 };
        match uvs.get(prim as usize) {
            Some(t) => t[0] * (1.0 - u - v) + t[1] * u + t[2] * v,
            None => Vec2::ZERO,
        }
    }

    /// The tangent at barycentric `(u, v)` of triangle `prim` ([`Vec4::ZERO`] when it has
    /// none): the corners' tangents interpolated, the sign that of the first corner (a
    /// triangle's corners share one unless the texture is mirrored across it).
    pub fn tangent_at(&self, prim: u32, u: f32, v: f32) -> Vec4 {
        match self.tangents.get(prim as usize) {
            Some(t) => {
                let xyz =
                    t[0].truncate() * (1.0 - u - v) + t[1].truncate() * u + t[2].truncate() * v;
                xyz.extend(t[0].w)
            }
            None => Vec4::ZERO,
        }
    }

    /// Builds a mesh from an indexed triangle list, with normals computed by `rule`
    /// ([`normals`]; `groups` holds each face's smoothing group for [`NormalRule::Groups`]).
    /// Indices must be in range.
    pub fn from_indexed(
        positions: &[Vec3],
        indices: &[[u32; 3]],
        material: u32,
        rule: NormalRule,
        groups: &[u32],
    ) -> Mesh {
        let normals = super::normals::corner_normals(positions, indices, rule, groups);
        let triangles = indices
            .iter()
            .map(|f| f.map(|i| positions[i as usize]))
            .collect();
        Mesh {
            triangles,
            normals,
            material_ids: vec![material; indices.len()],
            uvs: Vec::new(),
            uvs1: Vec::new(),
            tangents: Vec::new(),
            origin: DVec3::ZERO,
        }
    }

    /// Builds a mesh from a triangle soup with flat normals.
    pub fn from_triangles(triangles: Vec<[Vec3; 3]>, material: u32) -> Mesh {
        let normals = triangles.iter().map(|t| [face_normal(t); 3]).collect();
        let material_ids = vec![material; triangles.len()];
        Mesh {
            triangles,
            normals,
            material_ids,
            uvs: Vec::new(),
            uvs1: Vec::new(),
            tangents: Vec::new(),
            origin: DVec3::ZERO,
        }
    }

    /// A sphere mesh about the origin (material 0) with normals pointing out of the centre,
    /// for smooth shading of a tessellated sphere such as [`crate::geometry::shapes::icosphere`]'s.
    pub fn smooth_sphere(triangles: Vec<[Vec3; 3]>) -> Mesh {
        let normals = triangles.iter().map(|t| t.map(|p| p.normalize())).collect();
        Mesh {
            normals,
            ..Mesh::from_triangles(triangles, 0)
        }
    }

    /// Applies an affine transform to positions, normals and tangents; a mirroring one swaps
    /// corners 1 and 2 of every triangle, so the front face stays the front face.
    pub fn transform(&mut self, m: &glam::DAffine3) {
        // World position T(origin + v) = T(origin) + L v: the origin moves in f64, the local
        // positions only turn and scale.
        let linear = m.matrix3.as_mat3();
        let normal_m = glam::Mat3A::from(linear).inverse().transpose();
        self.origin = m.transform_point3(self.origin);
        for t in &mut self.triangles {
            *t = t.map(|v| linear * v);
        }
        for n in &mut self.normals {
            *n = n.map(|v| Vec3::from(normal_m * glam::Vec3A::from(v)).normalize_or_zero());
        }
        // Tangents lie in the surface: they turn as positions do; a mirroring transform turns
        // the bitangent's handedness.
        let sign = if linear.determinant() < 0.0 {
            -1.0
        } else {
            1.0
        };
        for t in &mut self.tangents {
            *t = t.map(|v| {
                if v == Vec4::ZERO {
                    return v;
                }
                (linear * v.truncate())
                    .normalize_or_zero()
                    .extend(v.w * sign)
            });
        }
        if sign < 0.0 {
            // A mirror turns each triangle's winding around: corners 1 and 2 swapped back, so
            // the front face stays the front face (as glTF asks of its nodes).
            fn swap<T>(list: &mut [[T; 3]]) {
                list.iter_mut().for_each(|c| c.swap(1, 2));
            }
            swap(&mut self.triangles);
            swap(&mut self.normals);
            swap(&mut self.uvs);
            swap(&mut self.uvs1);
            swap(&mut self.tangents);
        }
    }

    /// Moves the local frame to `origin` (world coordinates), each vertex rounded once.
    pub fn rebase(&mut self, origin: DVec3) {
        let delta = self.origin - origin;
        if delta != DVec3::ZERO {
            for t in &mut self.triangles {
                *t = t.map(|v| (delta + v.as_dvec3()).as_vec3());
            }
        }
        self.origin = origin;
    }

    /// Puts the local frame back at the world's origin when the mesh spans or nears it (the
    /// rule of [`local_frame`]), so a scene near the origin has the coordinates it is given.
    pub fn settle_origin(&mut self) {
        let b = self.bounds();
        if self.origin == DVec3::ZERO || b.is_empty() {
            return;
        }
        let (lo, hi) = (Vec3::from(b.min).as_dvec3(), Vec3::from(b.max).as_dvec3());
        let centre = self.origin + 0.5 * (lo + hi);
        if centre.abs().max_element() <= (hi - lo).max_element().max(1.0) {
            self.rebase(DVec3::ZERO);
        }
    }

    /// Box around all finite vertices.
    pub fn bounds(&self) -> Aabb {
        Aabb::of_finite_points(self.triangles.iter().flatten().copied())
    }

    /// Takes triangles `range` out (with everything they have: normals, materials, texture
    /// coordinates, tangents) into a mesh of the same origin; the triangles after them move
    /// down.
    pub fn split_off(&mut self, range: std::ops::Range<usize>) -> Mesh {
        fn take<T>(v: &mut Vec<T>, range: &std::ops::Range<usize>) -> Vec<T> {
            if v.is_empty() {
                Vec::new()
            } else {
                v.drain(range.clone()).collect()
            }
        }
        Mesh {
            triangles: take(&mut self.triangles, &range),
            normals: take(&mut self.normals, &range),
            material_ids: take(&mut self.material_ids, &range),
            uvs: take(&mut self.uvs, &range),
            uvs1: take(&mut self.uvs1, &range),
            tangents: take(&mut self.tangents, &range),
            origin: self.origin,
        }
    }

    /// The bounding box in the frame of another local origin `origin` (world coordinates):
    /// where this mesh lies as seen by a mesh placed at `origin`.
    pub fn bounds_around(&self, origin: DVec3) -> Aabb {
        let shift = (self.origin - origin).as_vec3();
        Aabb::of_finite_points(self.triangles.iter().flatten().map(|&v| v + shift))
    }
}

/// Unit normal of a triangle (`+z` for a degenerate one).
pub fn face_normal(t: &[Vec3; 3]) -> Vec3 {
    (t[1] - t[0])
        .cross(t[2] - t[0])
        .try_normalize()
        .unwrap_or(Vec3::Z)
}

/// A local frame for positions read in f64: an origin near the finite ones' centre (the world
/// origin for a mesh near it), and every position relative to it in f32 (non-finite ones stay
/// non-finite).
pub fn local_frame(positions: &[DVec3]) -> (DVec3, Vec<Vec3>) {
    let (lo, hi) = positions
        .iter()
        .filter(|p| p.is_finite())
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(*p), hi.max(*p))
        });
    if !lo.cmple(hi).all() {
        return (DVec3::ZERO, positions.iter().map(|p| p.as_vec3()).collect());
    }
    let (centre, extent) = (0.5 * (lo + hi), (hi - lo).max_element());
    // A mesh that already spans or nears the origin stays where it is (nothing to gain, and
    // the same floats as ever); one farther away is placed about its centre, rounded to a
    // power of two no smaller than its size so local coordinates stay short.
    let centre = if centre.abs().max_element() <= extent.max(1.0) {
        DVec3::ZERO
    } else {
        let step = extent.max(f64::MIN_POSITIVE).log2().ceil().exp2();
        (centre / step).round() * step
    };
    (
        centre,
        positions.iter().map(|p| (*p - centre).as_vec3()).collect(),
    )
}
