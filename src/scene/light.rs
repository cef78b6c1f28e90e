//! Light sources: points, spots, rectangles (and the emissive triangles of the materials).

use glam::{Affine3A, Vec3};

/// A light source.
#[derive(Clone, Debug, PartialEq)]
pub enum Light {
    /// A point light: radiant intensity `color * intensity`, falling off with the squared
    /// distance.
    Point {
        /// Where the light is.
        position: Vec3,
        /// Colour (linear RGB).
        color: Vec3,
        /// Scale of the colour.
        intensity: f32,
    },
    /// A point light limited to a cone around `direction` (glTF's spot light): full
    /// intensity within `cos_inner` of the axis, none beyond `cos_outer`, a smooth fall-off
    /// between ([`spot_falloff`]).
    Spot {
        /// Where the light is.
        position: Vec3,
        /// Unit axis of the cone: the way the light shines.
        direction: Vec3,
        /// Colour (linear RGB).
        color: Vec3,
        /// Scale of the colour: radiant intensity on the axis.
        intensity: f32,
        /// Cosine of the angle from the axis within which the intensity is full.
        cos_inner: f32,
        /// Cosine of the angle from the axis beyond which there is no light
        /// (`cos_outer < cos_inner`).
        cos_outer: f32,
    },
    /// A one-sided rectangle `corner + s * edge_u + t * edge_v` (`s, t` in `[0, 1]`) emitting
    /// radiance `color * intensity` on the side `edge_u x edge_v` points to.
    Rect {
        /// One corner.
        corner: Vec3,
        /// First edge from the corner.
        edge_u: Vec3,
        /// Second edge from the corner.
        edge_v: Vec3,
        /// Colour (linear RGB).
        color: Vec3,
        /// Scale of the colour.
        intensity: f32,
        /// Shadow rays per shading point.
        samples: u32,
    },
}

/// Relative tolerance for a triangle lying in a rectangle light's plane and inside it.
const COINCIDE: f32 = 1e-4;

impl Light {
    /// True when the light is a rectangle and all of `tri` lies in its plane and inside it
    /// (within a relative `1e-4`): emissive triangles that show the rectangle, such as the
    /// Cornell box's ceiling light, are one light with it.
    pub fn holds_triangle(&self, tri: &[Vec3; 3]) -> bool {
        let Light::Rect {
            corner,
            edge_u,
            edge_v,
            ..
        } = *self
        else {
            return false;
        };
        let n = edge_u.cross(edge_v);
        let size = edge_u.length() + edge_v.length();
        let Some(nu) = n.try_normalize() else {
            return false;
        };
        // Coordinates along the edges by the dual basis (the edges need not be perpendicular).
        let du = edge_v.cross(n);
        let dv = n.cross(edge_u);
        let (su, sv) = (edge_u.dot(du), edge_v.dot(dv));
        let inside = |x: f32| (-COINCIDE..=1.0 + COINCIDE).contains(&x);
        tri.iter().all(|&p| {
            let d = p - corner;
            d.dot(nu).abs() <= COINCIDE * size && inside(d.dot(du) / su) && inside(d.dot(dv) / sv)
        })
    }

    /// The light carried by `by`: its position, direction, corner and edges transformed (a
    /// spot's axis made unit length again).
    pub fn moved(&self, by: Affine3A) -> Light {
        let mut l = self.clone();
        match &mut l {
            Light::Point { position, .. } => *position = by.transform_point3(*position),
            Light::Spot {
                position,
                direction,
                ..
            } => {
                *position = by.transform_point3(*position);
                *direction = by.transform_vector3(*direction).normalize_or(*direction);
            }
            Light::Rect {
                corner,
                edge_u,
                edge_v,
                ..
            } => {
                *corner = by.transform_point3(*corner);
                *edge_u = by.transform_vector3(*edge_u);
                *edge_v = by.transform_vector3(*edge_v);
            }
        }
        l
    }

    /// Where a point or spot light is and the radiant intensity it sends towards `p` (a
    /// spot's scaled by its cone's fall-off, [`spot_falloff`]); `None` where a spot sends
    /// nothing (no shadow ray is needed there) and for a rectangle light, which is not a point.
    pub fn point_towards(&self, p: Vec3) -> Option<(Vec3, Vec3)> {
        match *self {
            Light::Point {
                position,
                color,
                intensity,
            } => Some((position, color * intensity)),
            Light::Spot {
                position,
                direction,
                color,
                intensity,
                cos_inner,
                cos_outer,
            } => {
                let share =
                    spot_falloff(direction, cos_inner, cos_outer, (p - position).normalize());
                (share > 0.0).then(|| (position, color * intensity * share))
            }
            Light::Rect { .. } => None,
        }
    }

    /// Centre of the light (its position for a point light).
    pub fn center(&self) -> Vec3 {
        match self {
            Light::Point { position, .. } | Light::Spot { position, .. } => *position,
            Light::Rect {
                corner,
                edge_u,
                edge_v,
                ..
            } => *corner + 0.5 * (*edge_u + *edge_v),
        }
    }
}

/// The share of a spot light's intensity sent along unit direction `d` (from the light): 1
/// within `cos_inner` of the axis `direction`, 0 beyond `cos_outer`, and between them the
/// square of the linear ramp in the cosine, the fall-off the glTF specification suggests for
/// `KHR_lights_punctual`.
pub fn spot_falloff(direction: Vec3, cos_inner: f32, cos_outer: f32, d: Vec3) -> f32 {
    let scale = 1.0 / (cos_inner - cos_outer).max(1e-3);
    let t = ((direction.dot(d) - cos_outer) * scale).clamp(0.0, 1.0);
    t * t
}
