//! Light sources: points, spots, rectangles (and the emissive triangles of the materials).

use glam::Vec3;

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

impl Light {
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
