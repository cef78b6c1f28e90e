//! Where a ray met a surface and what it looks like there: the hit point and its error bound,
//! the shading frame (normals bent by normal and height maps), the material's look with its
//! textures read, made into the lobes of [`super::bsdf`]; and the directions a mirror and a
//! transparent surface pass a ray on in.

use glam::Vec3;

use super::Tracer;
use super::bsdf::{Bsdf, Bump, Coat, DielectricLayer, Ggx, Gloss, Phong, Sheen};
use crate::geometry::{Ray, interpolation_error, offset_ray_origin};
use crate::scene::pbr::{Lobes, Texels};
use crate::scene::{Material, Scene, face_normal};

/// Where a ray met a surface.
pub(super) struct Surface<'a> {
    pub(super) p: Vec3,
    /// Bound on the rounding error of `p`, per coordinate.
    pub(super) p_err: Vec3,
    /// Geometric normal facing the incoming ray.
    pub(super) ng: Vec3,
    /// `p` moved off the surface on the side of `ng` ([`offset_ray_origin`]): where shadow
    /// rays, bounces and reflections leave from, made once for all of them.
    pub(super) origin: Vec3,
    /// True when the ray arrived on the side the triangle's winding calls outside.
    pub(super) entering: bool,
    pub(super) material: &'a Material,
    /// The material's emitted radiance here (its texture applied).
    pub(super) emission: Vec3,
    /// The material's opacity here (its texture's alpha applied, for `BLEND` and `MASK`).
    pub(super) opacity: f32,
    /// The material's mirror reflectance here (zero: no reflection ray).
    pub(super) mirror: Vec3,
    /// What the surface reflects here, about its shading normal `n`: the material's diffuse
    /// colour (its texture applied), glossy lobe, sheen ([`Sheen::NONE`]: none) and clear
    /// coat ([`Coat::NONE`]: none) here, and the shadowing of a normal a map bent
    /// ([`Bump::NONE`]: none, or not softened). Kept whole, so that each use borrows it.
    pub(super) bsdf: Bsdf,
}

impl Surface<'_> {
    /// What the surface reflects here, about its shading normal.
    pub(super) fn bsdf(&self) -> &Bsdf {
        &self.bsdf
    }

    /// Shading normal on the same side as `ng` (the BSDF's).
    pub(super) fn n(&self) -> Vec3 {
        self.bsdf.n
    }

    /// True when the surface reflects like a mirror here.
    pub(super) fn is_mirror(&self) -> bool {
        self.mirror.max_element() > 0.0
    }

    /// What the mirror reflects of light arriving from `wo`'s mirror direction: its
    /// reflectance (at most 1), less what a clear coat over it reflects away, `1 - k F(wo.n)`,
    /// and dimmed by a sheen's albedo scaling (the coat's and the sheen's own reflection are
    /// their lobes in [`Surface::bsdf`]).
    pub(super) fn mirror_tint(&self, wo: Vec3) -> Vec3 {
        let b = &self.bsdf;
        let c = wo.dot(b.n);
        let shadowing = b.bump.shadowing(reflect(-wo, b.n));
        self.mirror.min(Vec3::ONE) * (1.0 - b.coat.reflects(c)) * b.sheen.scaling(c, c) * shadowing
    }
}

impl Tracer<'_> {
    pub(super) fn surface(&self, ray: &Ray, prim: u32, u: f32, v: f32) -> Surface<'_> {
        let scene = self.scene;
        let tri = &scene.triangle(prim);
        let ns = &scene.normals(prim);
        let b = [1.0 - u - v, u, v];
        let p = tri[0] * b[0] + tri[1] * b[1] + tri[2] * b[2];
        let p_err = interpolation_error(tri, b);
        let outward = face_normal(tri);
        let entering = outward.dot(ray.dir) < 0.0;
        let ng = if entering { outward } else { -outward };
        let material = scene.material_of(prim);
        let interpolated = ns[0] * (1.0 - u - v) + ns[1] * u + ns[2] * v;
        let mut n = interpolated.try_normalize().unwrap_or(ng);
        // Both turned towards the ray when the interpolated normal faces away from it: a
        // normal map bends the normal of the side the ray sees as it does the other's.
        let side = if n.dot(ng) < 0.0 { -1.0 } else { 1.0 };
        n *= side;
        // The normal before any map bends it (a clear coat's own normal starts from it).
        let plain = n;
        if let Some(mapped) = self
            .plan
            .normal_maps
            .then(|| {
                normal_mapped(scene, material, prim, u, v, interpolated)
                    .or_else(|| bump_mapped(scene, material, prim, u, v, interpolated))
            })
            .flatten()
        {
            // A map bending the normal past the surface's horizon is not followed there.
            if (mapped * side).dot(ng) > 0.0 {
                n = mapped * side;
            }
        }
        let bump = if n != plain && self.plan.soft_terminator {
            Bump::new(plain, n)
        } else {
            Bump::NONE
        };
        let Look {
            diffuse,
            emission,
            opacity,
            gloss,
            sheen,
            mut coat,
            mirror,
        } = self.look(prim, u, v);
        let gloss = match gloss {
            Gloss::Ggx(g) if self.plan.energy_compensation => Gloss::Ggx(Ggx {
                compensate: true,
                ..g
            }),
            g => g,
        };
        if coat.weight > 0.0 {
            // The coat's own normal: the interpolated one, or its own map's about it.
            coat.n = plain;
            let cc = material.pbr.as_ref().and_then(|p| p.clearcoat.as_ref());
            if let Some(c) = cc.filter(|_| self.plan.normal_maps)
                && let Some(map) = &c.normal_map
                && let Some(mapped) =
                    normal_mapped_by(scene, map, c.normal_scale, prim, u, v, interpolated)
                && (mapped * side).dot(ng) > 0.0
            {
                coat.n = mapped * side;
            }
        }
        Surface {
            p,
            p_err,
            ng,
            origin: offset_ray_origin(p, p_err, ng),
            entering,
            material,
            emission,
            opacity,
            mirror,
            bsdf: Bsdf {
                n,
                diffuse,
                gloss,
                sheen,
                coat,
                bump,
            },
        }
    }
}

/// What a material looks like at one point of a surface.
#[derive(Clone, Copy)]
pub(super) struct Look {
    pub(super) diffuse: Vec3,
    pub(super) emission: Vec3,
    pub(super) opacity: f32,
    pub(super) gloss: Gloss,
    pub(super) sheen: Sheen,
    pub(super) coat: Coat,
    pub(super) mirror: Vec3,
}

/// The look of `m` at barycentric `(u, v)` of triangle `prim`: the material's factors times
/// its textures, read at the triangle's texture coordinates (the diffuse texture's alpha for
/// the opacity, as its alpha mode says). A glTF material's base colour and
/// metallic-roughness textures vary its base colour, metalness and roughness, from which its
/// lobes are made here ([`crate::scene::pbr`]), and its clear coat's textures vary the coat;
/// other materials' textures multiply the diffuse colour.
pub(super) fn textured(scene: &Scene, m: &Material, prim: u32, u: f32, v: f32) -> Look {
    // Each texture reads its own coordinate set (glTF's TEXCOORD_0 or TEXCOORD_1).
    let sample = |t: &crate::scene::Texture| t.sample(scene.uv_at(t.uv_set, prim, u, v));
    let coat = m
        .pbr
        .as_ref()
        .and_then(|p| p.clearcoat.as_ref())
        .map_or(Coat::NONE, |c| {
            let (weight, alpha) = c.at(
                c.map.as_deref().map(sample),
                c.roughness_map.as_deref().map(sample),
            );
            // The normal is the surface's: set by `Tracer::surface`.
            Coat {
                weight,
                alpha,
                n: Vec3::Z,
            }
        });
    let sheen = m
        .pbr
        .as_ref()
        .and_then(|p| p.sheen.as_ref())
        .map_or(Sheen::NONE, |s| {
            let (color, roughness) = s.at(
                s.color_map.as_deref().map(sample),
                s.roughness_map.as_deref().map(sample),
            );
            Sheen::new(color, roughness)
        });
    if !m.is_textured() {
        let (gloss, mirror) = match &m.pbr {
            Some(pbr) => {
                let lobes = pbr.lobes_at(Texels::default());
                (ggx(&lobes), lobes.mirror)
            }
            None => (phong(m), m.mirror),
        };
        return Look {
            diffuse: m.diffuse,
            emission: m.emission,
            opacity: m.opacity_at(1.0),
            gloss,
            sheen,
            coat,
            mirror,
        };
    }
    let base = m.diffuse_map.as_deref().map(sample);
    let emission = m
        .emission_map
        .as_deref()
        .map_or(m.emission, |t| m.emission * sample(t).truncate());
    let opacity = m.opacity_at(base.map_or(1.0, |b| b.w));
    match &m.pbr {
        Some(pbr) => {
            let lobes = pbr.lobes_at(Texels {
                base: base.map(|b| b.truncate()),
                mr: pbr.map.as_deref().map(sample),
                specular: pbr.specular.map.as_deref().map(sample),
                specular_color: pbr.specular.color_map.as_deref().map(sample),
            });
            Look {
                diffuse: lobes.diffuse,
                emission,
                opacity,
                gloss: ggx(&lobes),
                sheen,
                coat,
                mirror: lobes.mirror,
            }
        }
        None => Look {
            diffuse: base.map_or(m.diffuse, |b| m.diffuse * b.truncate()),
            emission,
            opacity,
            gloss: phong(m),
            sheen,
            coat,
            mirror: m.mirror,
        },
    }
}

/// The GGX lobe of metallic-roughness lobes (none where the point is a mirror).
fn ggx(lobes: &Lobes) -> Gloss {
    if lobes.f0 == Vec3::ZERO {
        Gloss::None
    } else {
        Gloss::Ggx(Ggx {
            f0: lobes.f0,
            f90: lobes.f90,
            alpha: lobes.alpha,
            dielectric: DielectricLayer {
                f0: lobes.dielectric.f0.max_element(),
                weight: lobes.dielectric.weight,
            },
            // Set where the plan says (`Tracer::surface`).
            compensate: false,
        })
    }
}

/// The Blinn-Phong lobe of a material without metallic-roughness parameters.
fn phong(m: &Material) -> Gloss {
    if m.specular == Vec3::ZERO {
        Gloss::None
    } else {
        Gloss::Phong(Phong {
            color: m.specular,
            exponent: m.shininess,
        })
    }
}

/// The shading normal a material's normal map gives at barycentric `(u, v)` of triangle
/// `prim`, about the interpolated normal `n` (`None` without a map, without a tangent there,
/// or where the frame is degenerate: the caller keeps `n`). The map bends the normal on the
/// side of the surface `n` is on; [`Tracer::surface`] then turns the result towards the ray
/// as it does `n`.
pub(super) fn normal_mapped(
    scene: &Scene,
    m: &Material,
    prim: u32,
    u: f32,
    v: f32,
    n: Vec3,
) -> Option<Vec3> {
    let map = m.normal_map.as_ref()?;
    normal_mapped_by(scene, map, m.normal_scale, prim, u, v, n)
}

/// [`normal_mapped`] by the map `map` of scale `scale` (a material's, or its clear coat's).
fn normal_mapped_by(
    scene: &Scene,
    map: &crate::scene::Texture,
    scale: f32,
    prim: u32,
    u: f32,
    v: f32,
    n: Vec3,
) -> Option<Vec3> {
    let t = scene.tangent_at(prim, u, v);
    if t == glam::Vec4::ZERO {
        return None;
    }
    let texel = map.sample(scene.uv_at(map.uv_set, prim, u, v)).truncate();
    crate::scene::tangents::perturbed(n, t, texel, scale)
}

/// The shading normal a material's height map gives at barycentric `(u, v)` of triangle
/// `prim`, about the interpolated normal `n` (`None` without a map, or where the triangle's
/// texture coordinates or the result are degenerate: the caller keeps `n`), on `n`'s side.
///
/// The surface is taken as displaced along `n` by `height_scale` times the map's value
/// (its luminance), and the normal is that of the displaced surface, the normal's own change
/// across the triangle left out: with `dp/du`, `dp/dv` the triangle's derivatives by its
/// texture coordinates made tangent to `n`, and `g` the displacement's gradient in texture
/// space, `normalize((dp/du + g.x n) x (dp/dv + g.y n))`. This is Mitsuba's `bumpmap`
/// (which flips by the geometric normal; the reference scenes' meshes have face normals, where
/// the two agree).
pub(super) fn bump_mapped(
    scene: &Scene,
    m: &Material,
    prim: u32,
    u: f32,
    v: f32,
    n: Vec3,
) -> Option<Vec3> {
    let map = m.height_map.as_ref()?;
    let tri = &scene.triangle(prim);
    let uv = |a: f32, b: f32| scene.uv_at(map.uv_set, prim, a, b);
    let (t0, d1, d2) = (uv(0.0, 0.0), uv(1.0, 0.0), uv(0.0, 1.0));
    let (d1, d2) = (d1 - t0, d2 - t0);
    let det = d1.x * d2.y - d1.y * d2.x;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let (e1, e2) = (tri[1] - tri[0], tri[2] - tri[0]);
    let dp_du = (e1 * d2.y - e2 * d1.y) / det;
    let dp_dv = (e2 * d1.x - e1 * d2.x) / det;
    let n = n.try_normalize()?;
    let g = map.luminance_gradient(uv(u, v)) * m.height_scale;
    let du = dp_du + n * (g.x - n.dot(dp_du));
    let dv = dp_dv + n * (g.y - n.dot(dp_dv));
    let bent = du.cross(dv).try_normalize()?;
    Some(if bent.dot(n) < 0.0 { -bent } else { bent })
}

/// Barycentric `(u, v)` (the weights of the second and third vertex) of a point `p` lying on
/// triangle `t` (Ericson, Real-Time Collision Detection, 3.4).
pub(super) fn barycentric(t: &[Vec3; 3], p: Vec3) -> (f32, f32) {
    let (e1, e2, d) = (t[1] - t[0], t[2] - t[0], p - t[0]);
    let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d1, d2) = (d.dot(e1), d.dot(e2));
    let den = d11 * d22 - d12 * d12;
    if den == 0.0 || !den.is_finite() {
        return (0.0, 0.0);
    }
    ((d22 * d1 - d12 * d2) / den, (d11 * d2 - d12 * d1) / den)
}

/// The surface's reflectance from `wi` towards `wo` at the shading point (its textures
/// applied): Lambertian plus its glossy lobe ([`super::bsdf`]).
pub(super) fn brdf(s: &Surface, wi: Vec3, wo: Vec3) -> Vec3 {
    s.bsdf().eval(wi, wo)
}

/// Mirror direction of `d` about the normal `n`.
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - 2.0 * d.dot(n) * n
}

/// Direction through a transparent surface (refracted by its index of refraction, or totally
/// reflected) and the side of the surface the new ray leaves from.
pub(super) fn transmit(d: Vec3, s: &Surface) -> (Vec3, Vec3) {
    let ior = s.material.ior;
    if ior == 1.0 || ior.is_nan() || ior <= 0.0 {
        return (d, -s.ng);
    }
    let eta = if s.entering { 1.0 / ior } else { ior };
    let dn = d.normalize();
    let cos_i = -dn.dot(s.n());
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        (reflect(dn, s.n()), s.ng) // total internal reflection
    } else {
        (eta * dn + (eta * cos_i - k.sqrt()) * s.n(), -s.ng)
    }
}

/// `exp(-sigma d)` per channel.
pub fn beer_lambert(sigma: Vec3, d: f32) -> Vec3 {
    Vec3::new(
        (-sigma.x * d).exp(),
        (-sigma.y * d).exp(),
        (-sigma.z * d).exp(),
    )
}
