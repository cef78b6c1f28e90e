//! Tangent frames for normal maps.
//!
//! A normal map stores, per texel, a normal in the tangent space of the surface: `+X` along
//! increasing `u`, `+Y` "up" in the image (towards decreasing `v`, since `v = 0` is the image's
//! top row here, as in glTF), `+Z` along the surface normal. Turning it into a world normal
//! needs each corner's tangent: a unit vector along `+u` in the surface, and a sign `w` that
//! says which way the bitangent runs (`bitangent = w * cross(normal, tangent)`, glTF's rule).
//!
//! - A glTF primitive's own `TANGENT` attribute is used as it is (turned by the node's
//!   transform, its sign flipped by a mirroring one).
//! - Where a file gives none, the tangents are MikkTSpace's (Mikkelsen 2008, the
//!   `bevy_mikktspace` crate), as the glTF specification asks: the algorithm normal-map bakers
//!   use, so a baked map reads back as it was baked. MikkTSpace takes OpenGL's texture
//!   convention (`v` up), so it is given `(u, 1 - v)`.
//!
//! Tangents are kept only for triangles whose material has a normal map (the others, and
//! meshes without any, store none: see [`super::Mesh::tangents`]).

use glam::{Vec2, Vec3, Vec4};

/// The corners of `triangles` (with their shading `normals` and texture coordinates `uvs`)
/// picked by `wanted`, given MikkTSpace tangents; the others, and corners MikkTSpace leaves
/// without one (a degenerate triangle with no neighbour to borrow from), are
/// [`Vec4::ZERO`] (no tangent: the normal map is not applied there).
pub fn mikktspace(
    triangles: &[[Vec3; 3]],
    normals: &[[Vec3; 3]],
    uvs: &[[Vec2; 3]],
    wanted: impl Fn(usize) -> bool,
) -> Vec<[Vec4; 3]> {
    let faces: Vec<usize> = (0..triangles.len()).filter(|&i| wanted(i)).collect();
    let mut out = vec![[Vec4::ZERO; 3]; triangles.len()];
    if faces.is_empty() || uvs.len() != triangles.len() {
        return out;
    }
    let mut g = Geometry {
        triangles,
        normals,
        uvs,
        faces: &faces,
        out: &mut out,
    };
    // MikkTSpace only fails on meshes without faces, which were returned above.
    if bevy_mikktspace::generate_tangents(&mut g).is_err() {
        return vec![[Vec4::ZERO; 3]; triangles.len()];
    }
    out
}

/// The mesh as MikkTSpace reads it: the wanted faces only, in their order.
struct Geometry<'a> {
    triangles: &'a [[Vec3; 3]],
    normals: &'a [[Vec3; 3]],
    uvs: &'a [[Vec2; 3]],
    faces: &'a [usize],
    out: &'a mut [[Vec4; 3]],
}

impl bevy_mikktspace::Geometry for Geometry<'_> {
    fn num_faces(&self) -> usize {
        self.faces.len()
    }
    fn num_vertices_of_face(&self, _face: usize) -> usize {
        3
    }
    fn position(&self, face: usize, vert: usize) -> [f32; 3] {
        self.triangles[self.faces[face]][vert].to_array()
    }
    fn normal(&self, face: usize, vert: usize) -> [f32; 3] {
        self.normals[self.faces[face]][vert].to_array()
    }
    fn tex_coord(&self, face: usize, vert: usize) -> [f32; 2] {
        let uv = self.uvs[self.faces[face]][vert];
        [uv.x, 1.0 - uv.y]
    }
    fn set_tangent(
        &mut self,
        tangent: Option<bevy_mikktspace::TangentSpace>,
        face: usize,
        vert: usize,
    ) {
        let t = tangent.map_or(Vec4::ZERO, |t| Vec4::from(t.tangent_encoded()));
        self.out[self.faces[face]][vert] = if t.is_finite() { t } else { Vec4::ZERO };
    }
}

/// The world normal a normal map's texel `rgb` (linear, in `[0, 1]`) gives at a point whose
/// interpolated shading normal is `n` and tangent `t` (xyz the tangent, w the bitangent's
/// sign), with the map's `scale` applied to the texel's X and Y (glTF `normalTexture.scale`).
/// `None` when the frame or the result is degenerate (no tangent, a tangent along the normal,
/// a texel of zero length): the caller keeps `n`.
pub fn perturbed(n: Vec3, t: Vec4, rgb: Vec3, scale: f32) -> Option<Vec3> {
    let n = n.try_normalize()?;
    let tangent = t.truncate();
    // Gram-Schmidt: the interpolated tangent made perpendicular to the interpolated normal.
    let tangent = (tangent - n * n.dot(tangent)).try_normalize()?;
    let bitangent = n.cross(tangent) * if t.w < 0.0 { -1.0 } else { 1.0 };
    let m = rgb * 2.0 - Vec3::ONE;
    let m = Vec3::new(m.x * scale, m.y * scale, m.z);
    (tangent * m.x + bitangent * m.y + n * m.z).try_normalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A quad in the xy plane facing +z, its texture's top row (`v = 0`) along +y, as a
    /// glTF exporter writes it: MikkTSpace's tangent runs along +u (+x), and the bitangent
    /// it implies along the image's up (+y).
    #[test]
    fn a_quad_gets_u_as_tangent_and_image_up_as_bitangent() {
        let p = [
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ];
        let uv = [
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(0.0, 0.0),
        ];
        let tris = [[p[0], p[1], p[2]], [p[0], p[2], p[3]]];
        let uvs = [[uv[0], uv[1], uv[2]], [uv[0], uv[2], uv[3]]];
        let normals = [[Vec3::Z; 3]; 2];
        let t = mikktspace(&tris, &normals, &uvs, |_| true);
        for corner in t.iter().flatten() {
            assert!(corner.truncate().abs_diff_eq(Vec3::X, 1e-6), "{corner}");
            let b = Vec3::Z.cross(corner.truncate()) * corner.w;
            assert!(b.abs_diff_eq(Vec3::Y, 1e-6), "bitangent {b}");
        }
        // A texel leaning towards the image's up tilts the normal towards +y.
        let up = perturbed(Vec3::Z, t[0][0], Vec3::new(0.5, 0.75, 0.9), 1.0).unwrap();
        assert!(up.y > 0.2 && up.x.abs() < 1e-6 && up.z > 0.0, "{up}");
        // Only the wanted faces get tangents.
        let some = mikktspace(&tris, &normals, &uvs, |i| i == 1);
        assert_eq!(some[0], [Vec4::ZERO; 3]);
        assert_ne!(some[1][0], Vec4::ZERO);
    }

    /// A placed mesh's tangents turn with it, and a mirror flips their sign, so that the
    /// bitangent `w * cross(n, t)` is the mirrored one; meshes appended keep theirs, and
    /// triangles without get none.
    #[test]
    fn tangents_turn_with_transforms_and_survive_appends() {
        use crate::scene::Mesh;
        let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let mut m = Mesh::from_triangles(vec![tri], 0);
        m.tangents = vec![[Vec4::new(1.0, 0.0, 0.0, 1.0); 3]];
        let b = |m: &Mesh| m.normals[0][0].cross(m.tangents[0][0].truncate()) * m.tangents[0][0].w;
        assert!(b(&m).abs_diff_eq(Vec3::Y, 1e-6));
        let mut turned = m.clone();
        turned.transform(&glam::DAffine3::from_rotation_z(
            std::f64::consts::FRAC_PI_2,
        ));
        assert!(turned.tangents[0][0].abs_diff_eq(Vec4::new(0.0, 1.0, 0.0, 1.0), 1e-6));
        assert!(b(&turned).abs_diff_eq(-Vec3::X, 1e-6), "{}", b(&turned));
        let mut mirrored = m.clone();
        mirrored.transform(&glam::DAffine3::from_scale(glam::DVec3::new(
            1.0, -1.0, 1.0,
        )));
        assert_eq!(mirrored.tangents[0][0], Vec4::new(1.0, 0.0, 0.0, -1.0));
        // The mirror image of the bitangent +y.
        assert!(b(&mirrored).abs_diff_eq(-Vec3::Y, 1e-6), "{}", b(&mirrored));
        let mut both = Mesh::from_triangles(vec![tri], 0);
        both.append(m.clone(), 0);
        both.append(Mesh::from_triangles(vec![tri], 0), 0);
        assert_eq!(both.tangents.len(), 3);
        assert_eq!(both.tangents[0], [Vec4::ZERO; 3]);
        assert_eq!(both.tangents[1], m.tangents[0]);
        assert_eq!(both.tangents[2], [Vec4::ZERO; 3]);
        assert_eq!(both.tangent_at(1, 0.2, 0.3), Vec4::new(1.0, 0.0, 0.0, 1.0));
        assert_eq!(
            Mesh::from_triangles(vec![tri], 0).tangent_at(0, 0.2, 0.3),
            Vec4::ZERO
        );
    }

    /// MikkTSpace on meshes of special values (NaN, infinities, zeros, denormals, huge and
    /// tiny numbers) in positions, normals and texture coordinates, vertices shared between
    /// triangles (so that it welds them and borrows between neighbours): no panic, and every
    /// tangent finite or none (without the filter in `set_tangent`, some come out NaN).
    #[test]
    fn mikktspace_on_special_values_panics_never_and_gives_finite_tangents() {
        let specials = [
            0.0f32,
            -0.0,
            1.0,
            -1.0,
            1e-30,
            1e30,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::MAX,
            f32::MIN_POSITIVE,
            1e-45,
        ];
        let mut seed = 12345u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for case in 0..5000 {
            // Half the cases plain numbers only, half with one value in five special.
            let special = if case % 2 == 0 { 0 } else { 20 };
            let mut value = || {
                let r = next();
                if r % 100 < special {
                    specials[(r >> 8) as usize % specials.len()]
                } else {
                    (r >> 8) as f32 % 7.0 * 0.5 - 1.5
                }
            };
            let positions: Vec<Vec3> = (0..6)
                .map(|_| Vec3::new(value(), value(), value()))
                .collect();
            let normals: Vec<Vec3> = (0..3)
                .map(|_| Vec3::new(value(), value(), value()))
                .collect();
            let uvs: Vec<Vec2> = (0..4).map(|_| Vec2::new(value(), value())).collect();
            let faces: Vec<[usize; 3]> = (0..4 + next() % 40)
                .map(|_| std::array::from_fn(|_| (next() % 6) as usize))
                .collect();
            let t = mikktspace(
                &faces
                    .iter()
                    .map(|f| f.map(|i| positions[i]))
                    .collect::<Vec<_>>(),
                &faces
                    .iter()
                    .map(|f| f.map(|i| normals[i % 3]))
                    .collect::<Vec<_>>(),
                &faces
                    .iter()
                    .map(|f| f.map(|i| uvs[i % 4]))
                    .collect::<Vec<_>>(),
                |_| true,
            );
            assert_eq!(t.len(), faces.len());
            assert!(t.iter().flatten().all(|v| v.is_finite()), "case {case}");
        }
    }

    /// The texel (0.5, 0.5, 1) is the unperturbed normal; scale 0 flattens any texel to it;
    /// a mirrored frame (w = -1) turns Y the other way; degenerate frames give `None`.
    #[test]
    fn perturbed_follows_the_frame_and_the_scale() {
        let t = Vec4::new(1.0, 0.0, 0.0, 1.0);
        let flat = perturbed(Vec3::Z, t, Vec3::new(0.5, 0.5, 1.0), 1.0).unwrap();
        assert!(flat.abs_diff_eq(Vec3::Z, 1e-6), "{flat}");
        let texel = Vec3::new(0.9, 0.2, 0.6);
        let none = perturbed(Vec3::Z, t, texel, 0.0).unwrap();
        assert!(none.abs_diff_eq(Vec3::Z, 1e-6), "{none}");
        let a = perturbed(Vec3::Z, t, texel, 1.0).unwrap();
        let b = perturbed(Vec3::Z, Vec4::new(1.0, 0.0, 0.0, -1.0), texel, 1.0).unwrap();
        assert!(a.x > 0.0 && a.y < 0.0 && b.y > 0.0, "{a} {b}");
        assert!((a.x - b.x).abs() < 1e-6 && (a.y + b.y).abs() < 1e-6);
        // A tangent not quite perpendicular to the normal is straightened, not refused.
        let leaning = perturbed(Vec3::Z, Vec4::new(1.0, 0.0, 0.5, 1.0), texel, 1.0).unwrap();
        assert!(leaning.abs_diff_eq(a, 1e-6), "{leaning} {a}");
        assert_eq!(perturbed(Vec3::Z, Vec4::ZERO, texel, 1.0), None);
        assert_eq!(
            perturbed(Vec3::Z, Vec4::new(0.0, 0.0, 1.0, 1.0), texel, 1.0),
            None
        );
        assert_eq!(perturbed(Vec3::ZERO, t, texel, 1.0), None);
        assert_eq!(perturbed(Vec3::Z, t, Vec3::splat(0.5), 1.0), None);
    }
}
