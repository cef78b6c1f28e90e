use glam::{DVec3, Vec3, Vec3A};

use super::PreparedRay;

/// Where a ray meets a triangle: distance and barycentric coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleHit {
    /// Distance along the ray, in units of the direction's length.
    pub t: f32,
    /// Barycentric weight of the second vertex.
    pub u: f32,
    /// Barycentric weight of the third vertex.
    pub v: f32,
}

/// Watertight ray/triangle distance (Woop, Benthin and Wald, "Watertight Ray/Triangle
/// Intersection", JCGT 2013). Returns the distance `t` with `0 < t < t_max`, or `+inf` on a miss.
///
/// Two extensions keep the result exact at the places the f32 arithmetic cannot decide:
/// - An edge function that is exactly zero in f32 is recomputed in f64, where the products of
///   f32 values are exact and the sign is right (each edge on its own, so two triangles that
///   share an edge always agree on its sign).
/// - When it is still zero, the ray passes exactly through the edge (or a vertex). A tie rule
///   gives the edge to exactly one of the two triangles on either side of it: the one lying in
///   the direction `(1, +0)` from the edge in the sheared ray plane, as if the ray were nudged
///   an infinitesimal step that way. A ray through a shared edge or a fan vertex therefore
///   reports exactly one triangle: no crack, no double hit.
#[inline(always)]
pub fn intersect_triangle_t(ray: &PreparedRay, tri: &[Vec3A; 3], t_max: f32) -> f32 {
    match intersect(ray, tri, t_max) {
        Some((t, _, _)) => t,
        None => f32::INFINITY,
    }
}

/// Like [`intersect_triangle_t`], also returning the barycentric coordinates.
#[inline]
pub fn intersect_triangle(ray: &PreparedRay, tri: &[Vec3A; 3], t_max: f32) -> Option<TriangleHit> {
    intersect(ray, tri, t_max).map(|(t, u, v)| TriangleHit { t, u, v })
}

#[inline(always)]
fn intersect(ray: &PreparedRay, tri: &[Vec3A; 3], t_max: f32) -> Option<(f32, f32, f32)> {
    // Dispatch once on the axis permutation so that lane indices are constants (a runtime
    // index would send every vertex through memory). The branch is the same for every
    // triangle a ray meets, so it is predicted.
    match ray.k {
        [1, 2, 0] => sheared::<1, 2, 0>(ray, tri, t_max),
        [2, 1, 0] => sheared::<2, 1, 0>(ray, tri, t_max),
        [2, 0, 1] => sheared::<2, 0, 1>(ray, tri, t_max),
        [0, 2, 1] => sheared::<0, 2, 1>(ray, tri, t_max),
        [0, 1, 2] => sheared::<0, 1, 2>(ray, tri, t_max),
        _ => sheared::<1, 0, 2>(ray, tri, t_max),
    }
}

#[inline(always)]
fn sheared<const KX: usize, const KY: usize, const KZ: usize>(
    ray: &PreparedRay,
    tri: &[Vec3A; 3],
    t_max: f32,
) -> Option<(f32, f32, f32)> {
    let [sx, sy, sz] = ray.shear;
    // Vertices relative to the origin, then sheared so that the ray runs along +z.
    let a = tri[0] - ray.origin;
    let b = tri[1] - ray.origin;
    let c = tri[2] - ray.origin;
    let (a_z, b_z, c_z) = (a[KZ], b[KZ], c[KZ]);
    let ax = a[KX] - sx * a_z;
    let ay = a[KY] - sy * a_z;
    let bx = b[KX] - sx * b_z;
    let by = b[KY] - sy * b_z;
    let cx = c[KX] - sx * c_z;
    let cy = c[KY] - sy * c_z;

    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    // Non-short-circuit `|`: one well-predicted branch instead of several random ones.
    if !cfg!(feature = "no-watertight-fallback") && (u == 0.0) | (v == 0.0) | (w == 0.0) {
        return intersect_exact(
            [(ax, ay), (bx, by), (cx, cy)],
            [a_z, b_z, c_z],
            ray.shear,
            t_max,
        );
    }
    let any_neg = (u < 0.0) | (v < 0.0) | (w < 0.0);
    let any_pos = (u > 0.0) | (v > 0.0) | (w > 0.0);
    if any_neg & any_pos {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let t_scaled = (u * a_z + v * b_z + w * c_z) * sz;
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    // Products of three coordinates beyond f32's range (an object ~1e13 across or more): the
    // f32 distance or its error bound is infinite (or NaN), so the f64 path decides.
    let overflow = || {
        intersect_exact(
            [(ax, ay), (bx, by), (cx, cy)],
            [a_z, b_z, c_z],
            ray.shear,
            t_max,
        )
    };
    if !t_scaled.is_finite() {
        return overflow();
    }
    if !(t > 0.0 && t < t_max) {
        return None;
    }
    let bound = t_error_bound(
        [ax, bx, cx],
        [ay, by, cy],
        [a_z, b_z, c_z],
        ray.shear,
        [u, v, w],
        inv,
    );
    if !bound.is_finite() {
        return overflow();
    }
    if t <= bound {
        return None;
    }
    Some((t, v * inv, w * inv))
}

/// The arithmetic [`t_error_bound`] needs, so that one statement of the bound serves the f32
/// fast path and the f64 exact path.
trait BoundFloat:
    Copy + PartialOrd + std::ops::Add<Output = Self> + std::ops::Mul<Output = Self>
{
    fn abs(self) -> Self;
    fn max(self, other: Self) -> Self;
    /// `gamma(n)` (the f32 rounding bound: the coordinates were rounded in f32 either way).
    fn gamma(n: u32) -> Self;
    fn from_f32(x: f32) -> Self;
}

/// The two implementations differ only in type (and `gamma`, an f32 bound either way).
macro_rules! bound_float {
    ($t:ty) => {
        impl BoundFloat for $t {
            #[inline(always)]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline(always)]
            fn max(self, other: Self) -> Self {
                <$t>::max(self, other)
            }
            #[inline(always)]
            fn gamma(n: u32) -> Self {
                super::gamma(n) as $t
            }
            #[inline(always)]
            fn from_f32(x: f32) -> Self {
                x as $t
            }
        }
    };
}
bound_float!(f32);
bound_float!(f64);

/// Bound on the rounding error of the test's distance `t` (Pharr, Jakob and Humphreys, pbrt
/// 3rd ed., 3.9.6): a hit closer than this may lie at `t <= 0`, so it is not taken. Without
/// it, a ray leaving a surface (the offset origin of a shadow ray is a single float off a plane
/// at `x = 0`) could hit the surface it leaves through the rounding of the sheared
/// coordinates, when the surface's normal is not the ray's major axis: the lower half of the
/// Cornell box's green wall shadowed itself for a quarter of its shadow rays that way.
///
/// `x`, `y` are the sheared vertex coordinates, `z` the unscaled ones along the ray's major
/// axis, `shear` the ray's `[sx, sy, sz]`, `e` the edge functions and `inv_det` their sum's
/// reciprocal. pbrt bounds the sheared coordinates' error by `gamma(5) (max|x| + max|z|)`; the
/// `z` part comes from the shear `x - sx z`, so it is weighted here by `|sx|` (twice: the
/// difference `v - o` before the shear is rounded too). An axis-aligned ray (`sx = sy = 0`)
/// then keeps a tight bound, and a needle of aspect 1e6 hit head-on is not rejected.
#[inline(always)]
fn t_error_bound<F: BoundFloat>(
    x: [F; 3],
    y: [F; 3],
    z: [F; 3],
    shear: [F; 3],
    e: [F; 3],
    inv_det: F,
) -> F {
    let max3 = |a: [F; 3]| a[0].abs().max(a[1].abs()).max(a[2].abs());
    let [sx, sy, sz] = shear;
    let two = F::from_f32(2.0);
    let max_z = max3(z);
    let max_zt = max_z * sz.abs();
    let max_x = max3(x);
    let max_y = max3(y);
    let delta_z = F::gamma(3) * max_zt;
    let delta_x = F::gamma(5) * (max_x + two * sx.abs() * max_z);
    let delta_y = F::gamma(5) * (max_y + two * sy.abs() * max_z);
    let delta_e = two * (F::gamma(2) * max_x * max_y + delta_y * max_x + delta_x * max_y);
    let max_e = max3(e);
    F::from_f32(3.0)
        * (F::gamma(3) * max_e * max_zt + delta_e * max_zt + delta_z * max_e)
        * inv_det.abs()
}

/// The rare path: some edge function was exactly zero in f32, or the f32 distance overflowed.
#[cold]
#[inline(never)]
fn intersect_exact(
    p: [(f32, f32); 3],
    z_unscaled: [f32; 3],
    shear: [f32; 3],
    t_max: f32,
) -> Option<(f32, f32, f32)> {
    let z = z_unscaled.map(|z| z * shear[2]);
    // Edge functions in the same form as the fast path: the edge opposite vertex i.
    let edge = |i: usize| {
        let (q, r) = (p[(i + 1) % 3], p[(i + 2) % 3]);
        // Products of two f32 are exact in f64; the difference is rounded once, sign exact.
        let e = (r.0 as f64) * (q.1 as f64) - (r.1 as f64) * (q.0 as f64);
        (e, q, r)
    };
    let mut e = [0.0f64; 3];
    let mut pos = false;
    let mut neg = false;
    for (i, ei) in e.iter_mut().enumerate() {
        let (val, q, r) = edge(i);
        *ei = val;
        if val > 0.0 {
            pos = true;
        } else if val < 0.0 {
            neg = true;
        } else if !owns_edge(q, r, p[i]) {
            return None;
        }
    }
    if pos && neg {
        return None;
    }
    let det = e[0] + e[1] + e[2];
    if det == 0.0 {
        return None;
    }
    let t = (e[0] * z[0] as f64 + e[1] * z[1] as f64 + e[2] * z[2] as f64) / det;
    if !(t > 0.0 && t < t_max as f64) {
        return None;
    }
    // The edge functions are exact here, the sheared coordinates are not: the same bound, in
    // f64 (its products of three coordinates may overflow f32).
    let wide = |a: [f32; 3]| a.map(f64::from);
    let (x, y) = (p.map(|q| q.0), p.map(|q| q.1));
    let bound = t_error_bound(
        wide(x),
        wide(y),
        wide(z_unscaled),
        wide(shear),
        e,
        1.0 / det,
    );
    if t <= bound {
        return None;
    }
    let t = t as f32;
    if !(t > 0.0 && t < t_max) {
        return None;
    }
    Some((t, (e[1] / det) as f32, (e[2] / det) as f32))
}

/// Tie rule for a ray passing exactly through the edge `q`-`r` (in the sheared 2D ray plane,
/// where the ray is the origin): the edge belongs to the triangle whose interior lies in the
/// direction `(1, +0)` from it. The two triangles sharing an edge lie on opposite sides, so
/// exactly one owns it, whatever their winding.
fn owns_edge(q: (f32, f32), r: (f32, f32), opposite: (f32, f32)) -> bool {
    let (ex, ey) = (r.0 as f64 - q.0 as f64, r.1 as f64 - q.1 as f64);
    // Normal of the edge line, turned towards the opposite vertex.
    let (mut nx, mut ny) = (-ey, ex);
    let side = nx * (opposite.0 as f64 - q.0 as f64) + ny * (opposite.1 as f64 - q.1 as f64);
    if side < 0.0 {
        nx = -nx;
        ny = -ny;
    } else if side == 0.0 {
        return false; // degenerate in the ray plane: no area to hit
    }
    nx > 0.0 || (nx == 0.0 && ny > 0.0)
}

/// True when the triangle has exactly zero area: its vertices are collinear or coincide. The
/// edge cross product is taken in f64, where differences of f32 coordinates are exact, so
/// only truly flat triangles count. Such a triangle has no surface to hit, and the BVH leaves
/// it out (a ray could otherwise "hit" it through rounding in the sheared ray space).
///
/// The three conversions are written out: `t.map(..)` stayed a call of its own (`try_map`),
/// whose result the build's reference loop read back from memory with wider loads than it was
/// written with, a store-forwarding stall per triangle (a few percent of a build).
#[inline]
pub fn is_degenerate(t: &[Vec3; 3]) -> bool {
    let (a, b, c) = (t[0].as_dvec3(), t[1].as_dvec3(), t[2].as_dvec3());
    (b - a).cross(c - a) == DVec3::ZERO
}
