//! Meshes placed more than once: each held once in its own frame, and placed by transforms
//! into the scene's frame. Their triangles are numbered after the scene's own
//! ([`super::Scene::mesh`]), placement by placement in order, so a hit's triangle number
//! names a placement and a triangle of its mesh; what shading reads of a triangle (corners,
//! normals, texture coordinates, tangents, material) is its mesh's, carried into the scene's
//! frame ([`Instances::triangle`] and the rest).

use std::sync::Arc;

use glam::{Affine3A, DAffine3, DVec3, Mat3A, Vec2, Vec3, Vec3A, Vec4};

use super::Mesh;
use crate::bvh::{Instance, MAX_PLACED};
use crate::geometry::Aabb;

/// Meshes placed more than once, and their placements.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Instances {
    /// The meshes, each in its own frame (positions relative to its `origin`, which
    /// placements ignore: a placement's transform starts from the mesh's stored positions).
    pub meshes: Vec<Arc<Mesh>>,
    /// The placements: a mesh (an index into `meshes`) and the transform from its positions
    /// to the scene's frame (positions relative to the scene mesh's origin).
    placements: Vec<Instance>,
    /// The number, among the placed triangles, of each placement's first one.
    first: Vec<u32>,
}

/// Why meshes cannot be placed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PlaceError {
    /// A placement names a mesh past the list.
    NoMesh(usize),
    /// A placement's transform is not finite or cannot be inverted.
    Singular(usize),
    /// The placements hold more triangles than one scene can number.
    TooManyTriangles(u64),
    /// An object past the scene's list ([`super::Scene::lifted`]).
    NoObject(usize),
}

impl std::fmt::Display for PlaceError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PlaceError::NoMesh(i) => write!(f, "placement {i} names a mesh that does not exist"),
            PlaceError::Singular(i) => write!(
                f,
                "placement {i}'s transform is not finite or cannot be inverted (a zero scale?)"
            ),
            PlaceError::NoObject(i) => write!(f, "the scene has no object {i}"),
            PlaceError::TooManyTriangles(n) => write!(
                f,
                "the placements make {n} triangles, more than the {MAX_PLACED} one scene can number"
            ),
        }
    }
}

impl std::error::Error for PlaceError {}

impl Instances {
    /// `placements` of `meshes`, checked: every mesh index in range, every transform finite
    /// and invertible, and the triangles placed (counted with repeats, `before` of them
    /// numbered first: the scene's own) within [`MAX_PLACED`].
    pub fn new(
        meshes: Vec<Arc<Mesh>>,
        placements: Vec<Instance>,
        before: u64,
    ) -> Result<Instances, PlaceError> {
        let mut first = Vec::with_capacity(placements.len());
        let mut placed = 0u64;
        for (i, p) in placements.iter().enumerate() {
            let mesh = meshes.get(p.mesh as usize).ok_or(PlaceError::NoMesh(i))?;
            if !invertible(&p.to_world) {
                return Err(PlaceError::Singular(i));
            }
            first.push(placed as u32);
            placed += mesh.triangles.len() as u64;
            if before + placed > MAX_PLACED {
                return Err(PlaceError::TooManyTriangles(before + placed));
            }
        }
        Ok(Instances {
            meshes,
            placements,
            first,
        })
    }

    /// The same placements with some moved: `(placement, its new transform)`, checked as
    /// [`Instances::new`] checks them; the meshes shared, not copied.
    pub fn moved(&self, moves: &[(usize, Affine3A)]) -> Result<Instances, PlaceError> {
        let mut placements = self.placements.clone();
        for &(i, m) in moves {
            let p = placements.get_mut(i).ok_or(PlaceError::NoMesh(i))?;
            if !invertible(&m) {
                return Err(PlaceError::Singular(i));
            }
            p.to_world = m;
        }
        Ok(Instances {
            meshes: self.meshes.clone(),
            placements,
            first: self.first.clone(),
        })
    }

    /// Whether nothing is placed.
    pub fn is_empty(&self) -> bool {
        self.placements.is_empty()
    }

    /// The placements.
    pub fn placements(&self) -> &[Instance] {
        &self.placements
    }

    /// Triangles placed, counted with repeats.
    pub fn triangle_count(&self) -> u64 {
        match (self.first.last(), self.placements.last()) {
            (Some(&f), Some(p)) => f as u64 + self.meshes[p.mesh as usize].triangles.len() as u64,
            _ => 0,
        }
    }

    /// The number, among the placed triangles, of placement `i`'s first one.
    pub fn first_triangle(&self, i: usize) -> u32 {
        self.first[i]
    }

    /// Bytes the placements take beyond their meshes.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(&self.placements[..]) + std::mem::size_of_val(&self.first[..])
    }

    /// The placement (its index) that placed triangle `k` belongs to.
    #[inline]
    pub fn placement_of(&self, k: u32) -> usize {
        self.first.partition_point(|&f| f <= k) - 1
    }

    /// The placement of placed triangle `k`, its mesh, and the triangle's index in the mesh.
    #[inline]
    pub fn locate(&self, k: u32) -> (&Instance, &Mesh, usize) {
        let i = self.placement_of(k);
        let p = &self.placements[i];
        (
            p,
            &self.meshes[p.mesh as usize],
            (k - self.first[i]) as usize,
        )
    }

    /// Corners of placed triangle `k`, in the scene's frame: under a mirroring placement,
    /// corners 1 and 2 swapped, so the front face stays the front face (a hit's barycentric
    /// `u` and `v` are swapped to match: [`crate::bvh::TwoLevel::global`]).
    #[inline]
    pub fn triangle(&self, k: u32) -> [Vec3; 3] {
        let (p, mesh, t) = self.locate(k);
        corners(&p.to_world, mesh.triangles[t]).map(|v| p.to_world.transform_point3(v))
    }

    /// Shading normals of placed triangle `k`'s corners (as [`Instances::triangle`] orders
    /// them), in the scene's frame (unit length).
    #[inline]
    pub fn normals(&self, k: u32) -> [Vec3; 3] {
        let (p, mesh, t) = self.locate(k);
        let m = normal_matrix(&p.to_world);
        corners(&p.to_world, mesh.normals[t])
            .map(|n| Vec3::from(m * Vec3A::from(n)).normalize_or_zero())
    }

    /// Material of placed triangle `k`.
    #[inline]
    pub fn material_id(&self, k: u32) -> u32 {
        let (_, mesh, t) = self.locate(k);
        mesh.material_ids[t]
    }

    /// Texture coordinate of set `set` at barycentric `(u, v)` of placed triangle `k`.
    #[inline]
    pub fn uv_at(&self, set: u8, k: u32, u: f32, v: f32) -> Vec2 {
        let (p, mesh, t) = self.locate(k);
        let (u, v) = if mirrors(&p.to_world) { (v, u) } else { (u, v) };
        mesh.uv_at(set, t as u32, u, v)
    }

    /// Tangent at barycentric `(u, v)` of placed triangle `k`, in the scene's frame: its
    /// direction turned as positions turn, its bitangent sign flipped by a mirroring placement
    /// ([`Vec4::ZERO`] when it has none).
    #[inline]
    pub fn tangent_at(&self, k: u32, u: f32, v: f32) -> Vec4 {
        let (p, mesh, t) = self.locate(k);
        let (u, v) = if mirrors(&p.to_world) { (v, u) } else { (u, v) };
        turn_tangent(&p.to_world, mesh.tangent_at(t as u32, u, v))
    }

    /// Box around every placed triangle, in the scene's frame.
    pub fn bounds(&self) -> Aabb {
        let boxes: Vec<Aabb> = self.meshes.iter().map(|m| m.bounds()).collect();
        placed_bounds(&boxes, &self.placements)
    }

    /// Placement `i`'s triangles as a mesh of their own in the scene's frame (origin
    /// `origin`), as [`Instances::triangle`] and the rest give them.
    pub fn placed_mesh(&self, i: usize, origin: DVec3) -> Mesh {
        let p = &self.placements[i];
        let mesh = &self.meshes[p.mesh as usize];
        let n = mesh.triangles.len() as u32;
        let k0 = self.first[i];
        let ks = || (0..n).map(|t| k0 + t);
        Mesh {
            triangles: ks().map(|k| self.triangle(k)).collect(),
            normals: ks().map(|k| self.normals(k)).collect(),
            material_ids: mesh.material_ids.clone(),
            uvs: mesh.uvs.iter().map(|c| corners(&p.to_world, *c)).collect(),
            uvs1: mesh.uvs1.iter().map(|c| corners(&p.to_world, *c)).collect(),
            tangents: mesh
                .tangents
                .iter()
                .map(|t| corners(&p.to_world, t.map(|v| turn_tangent(&p.to_world, v))))
                .collect(),
            origin,
        }
    }
}

/// The placement of a mesh whose positions are relative to `mesh_origin` (world
/// coordinates, f64) by `world` (the mesh's world positions to the world), into a scene whose
/// positions are relative to `scene_origin`: the linear part as it is, the translation found
/// in f64 and rounded once.
pub fn placing(world: &DAffine3, mesh_origin: DVec3, scene_origin: DVec3, mesh: u32) -> Instance {
    Instance {
        mesh,
        to_world: Affine3A {
            matrix3: Mat3A::from(world.matrix3.as_mat3()),
            translation: Vec3A::from(
                (world.transform_point3(mesh_origin) - scene_origin).as_vec3(),
            ),
        },
    }
}

/// Box around meshes of boxes `boxes` (in their own frames) placed by `placements`: around
/// each box's eight corners carried into the scene's frame.
pub fn placed_bounds(boxes: &[Aabb], placements: &[Instance]) -> Aabb {
    let mut b = Aabb::EMPTY;
    for p in placements {
        let mb = &boxes[p.mesh as usize];
        if mb.is_empty() {
            continue;
        }
        for c in 0..8 {
            let corner = Vec3A::new(
                if c & 1 == 0 { mb.min.x } else { mb.max.x },
                if c & 2 == 0 { mb.min.y } else { mb.max.y },
                if c & 4 == 0 { mb.min.z } else { mb.max.z },
            );
            b.grow_point(p.to_world.transform_point3a(corner));
        }
    }
    b
}

/// Copies of meshes (`placed`: a mesh of `shared` and its transform to the world) placed in the scene's frame (the frame of `mesh`, the entries placed
/// once); when there are none, the frame is put at the first copy, or at the
/// world's origin when the copies span or near it (the rule of [`Mesh::settle_origin`]).
pub(crate) fn place(
    mesh: &mut Mesh,
    shared: Vec<Mesh>,
    placed: &[(u32, DAffine3)],
) -> Result<Instances, PlaceError> {
    let make = |origin: DVec3| -> Vec<crate::bvh::Instance> {
        placed
            .iter()
            .map(|(m, w)| placing(w, shared[*m as usize].origin, origin, *m))
            .collect()
    };
    let mut list = make(mesh.origin);
    if mesh.triangles.is_empty()
        && let Some((m, w)) = placed.first()
    {
        let mut origin = w.transform_point3(shared[*m as usize].origin);
        list = make(origin);
        let boxes: Vec<_> = shared.iter().map(Mesh::bounds).collect();
        let b = placed_bounds(&boxes, &list);
        if !b.is_empty() {
            let (lo, hi) = (Vec3::from(b.min).as_dvec3(), Vec3::from(b.max).as_dvec3());
            let centre = origin + 0.5 * (lo + hi);
            if centre.abs().max_element() <= (hi - lo).max_element().max(1.0) {
                origin = DVec3::ZERO;
                list = make(origin);
            }
        }
        mesh.origin = origin;
    }
    let meshes = shared.into_iter().map(std::sync::Arc::new).collect();
    Instances::new(meshes, list, mesh.triangles.len() as u64)
}

/// Whether `m` and its inverse are finite and `m` does not flatten space: the placements the
/// top level takes ([`crate::bvh::TwoLevel::new`] checks the same).
fn invertible(m: &Affine3A) -> bool {
    let det = m.matrix3.determinant();
    m.is_finite() && det != 0.0 && det.is_finite() && m.inverse().is_finite()
}

/// Whether `m` mirrors (turns the winding of a triangle around).
#[inline]
fn mirrors(m: &Affine3A) -> bool {
    m.matrix3.determinant() < 0.0
}

/// A triangle's per-corner values in the order a placement by `m` shows them: corners 1
/// and 2 swapped when `m` mirrors.
#[inline]
fn corners<T: Copy>(m: &Affine3A, c: [T; 3]) -> [T; 3] {
    if mirrors(m) { [c[0], c[2], c[1]] } else { c }
}

/// The matrix that carries normals through `m`: the inverse transpose of its linear part.
#[inline]
fn normal_matrix(m: &Affine3A) -> Mat3A {
    m.matrix3.inverse().transpose()
}

/// A tangent carried through `m` (see [`Instances::tangent_at`]).
#[inline]
fn turn_tangent(m: &Affine3A, t: Vec4) -> Vec4 {
    if t == Vec4::ZERO {
        return t;
    }
    let sign = if m.matrix3.determinant() < 0.0 {
        -1.0
    } else {
        1.0
    };
    Vec3::from(m.matrix3 * Vec3A::from(t.truncate()))
        .normalize_or_zero()
        .extend(t.w * sign)
}
