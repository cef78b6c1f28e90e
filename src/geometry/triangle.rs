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

/// `N` rays at once, component by component, as the triangle test of
/// [`intersect_triangle_lanes`] needs them: each ray's origin, axis permutation and shear, as
/// [`PreparedRay::new`] made them.
#[derive(Clone, Copy, Debug)]
pub(crate) struct RayLanes<const N: usize> {
    /// Origins, `[axis][lane]`.
    pub origin: [[f32; N]; 3],
    /// The axis permutation `[kx, ky, kz]` as selects: `[which][lane]` is whether the axis is
    /// x (`is_x`) or y (`is_y`), else z.
    pub is_x: [[bool; N]; 3],
    pub is_y: [[bool; N]; 3],
    /// Shear constants `[sx, sy, sz]`, `[which][lane]`.
    pub shear: [[f32; N]; 3],
}

impl<const N: usize> RayLanes<N> {
    /// No ray in any lane (every lane's parts zero, its axes x, y, z).
    pub const EMPTY: Self = {
        let mut is_x = [[false; N]; 3];
        let mut is_y = [[false; N]; 3];
        let mut i = 0;
        while i < N {
            is_x[0][i] = true;
            is_y[1][i] = true;
            i += 1;
        }
        RayLanes {
            origin: [[0.0; N]; 3],
            is_x,
            is_y,
            shear: [[0.0; N]; 3],
        }
    };

    /// Lane `i`'s parts from a prepared ray.
    #[inline(always)]
    pub fn set(&mut self, i: usize, r: &PreparedRay) {
        for a in 0..3 {
            self.origin[a][i] = r.origin[a];
            self.is_x[a][i] = r.k[a] == 0;
            self.is_y[a][i] = r.k[a] == 1;
            self.shear[a][i] = r.shear[a];
        }
    }
}

/// What [`intersect_triangle_lanes`] found: per lane the distance and barycentric
/// coordinates of a hit (bit `i` of `hit`), or that the lane needs the scalar test's exact
/// path (bit `i` of `exact`: an edge function exactly zero, or an overflow).
#[derive(Clone, Copy, Debug)]
pub(crate) struct LaneHits<const N: usize> {
    pub t: [f32; N],
    pub u: [f32; N],
    pub v: [f32; N],
    pub hit: u32,
    pub exact: u32,
}

/// One triangle against `N` rays, a ray a lane: the fast path of [`intersect_triangle`],
/// operation for operation (no fused multiply-adds, the same order), so a lane's hit is the
/// scalar test's to the bit. The axis permutation is a ray's own, so each lane picks its
/// vertex coordinates by selects. A lane the fast path cannot decide is marked `exact`: the
/// caller runs [`intersect_triangle`] for it (which takes the f64 path). `limit[i]` is lane
/// `i`'s `t_max`; only the lanes of `lanes` count. Written as loops over the lanes that the
/// compiler vectorises: the edge functions first, and the distance and its error bound only
/// when some lane's signs agree.
#[inline(always)]
pub(crate) fn intersect_triangle_lanes<const N: usize>(
    rays: &RayLanes<N>,
    tri: &[Vec3A; 3],
    limit: &[f32; N],
    lanes: u32,
) -> LaneHits<N> {
    let mut out = LaneHits {
        t: [0.0; N],
        u: [0.0; N],
        v: [0.0; N],
        hit: 0,
        exact: 0,
    };
    let [p, q, r] = tri.map(|v| v.to_array());
    // Sheared x and y, unscaled z, and edge functions, per vertex or edge and lane.
    let mut x = [[0.0f32; N]; 3];
    let mut y = [[0.0f32; N]; 3];
    let mut z = [[0.0f32; N]; 3];
    let mut e = [[0.0f32; N]; 3];
    let mut on = 0u32;
    let mut zero = 0u32;
    for i in 0..N {
        let o = [rays.origin[0][i], rays.origin[1][i], rays.origin[2][i]];
        let rel = |v: [f32; 3]| [v[0] - o[0], v[1] - o[1], v[2] - o[2]];
        let (a, b, c) = (rel(p), rel(q), rel(r));
        let pick = |v: [f32; 3], which: usize| {
            if rays.is_x[which][i] {
                v[0]
            } else if rays.is_y[which][i] {
                v[1]
            } else {
                v[2]
            }
        };
        let (sx, sy) = (rays.shear[0][i], rays.shear[1][i]);
        let (a_z, b_z, c_z) = (pick(a, 2), pick(b, 2), pick(c, 2));
        let ax = pick(a, 0) - sx * a_z;
        let ay = pick(a, 1) - sy * a_z;
        let bx = pick(b, 0) - sx * b_z;
        let by = pick(b, 1) - sy * b_z;
        let cx = pick(c, 0) - sx * c_z;
        let cy = pick(c, 1) - sy * c_z;
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let is_zero = (u == 0.0) | (v == 0.0) | (w == 0.0);
        let any_neg = (u < 0.0) | (v < 0.0) | (w < 0.0);
        let any_pos = (u > 0.0) | (v > 0.0) | (w > 0.0);
        zero |= (is_zero as u32) << i;
        on |= ((!is_zero & !(any_neg & any_pos)) as u32) << i;
        (x[0][i], x[1][i], x[2][i]) = (ax, bx, cx);
        (y[0][i], y[1][i], y[2][i]) = (ay, by, cy);
        (z[0][i], z[1][i], z[2][i]) = (a_z, b_z, c_z);
        (e[0][i], e[1][i], e[2][i]) = (u, v, w);
    }
    out.exact = zero & lanes;
    if on & lanes == 0 {
        return out;
    }
    // The scalar test's decisions in its order after the signs: miss by a zero determinant,
    // exact path on overflow, miss by the range, exact path on an infinite bound, miss within
    // the bound, hit.
    let mut exact = 0u32;
    let mut hit = 0u32;
    for i in 0..N {
        let (u, v, w) = (e[0][i], e[1][i], e[2][i]);
        let (a_z, b_z, c_z) = (z[0][i], z[1][i], z[2][i]);
        let sz = rays.shear[2][i];
        let det = u + v + w;
        let t_scaled = (u * a_z + v * b_z + w * c_z) * sz;
        let inv = 1.0 / det;
        let t = t_scaled * inv;
        let bound = t_error_bound(
            [x[0][i], x[1][i], x[2][i]],
            [y[0][i], y[1][i], y[2][i]],
            [a_z, b_z, c_z],
            [rays.shear[0][i], rays.shear[1][i], sz],
            [u, v, w],
            inv,
        );
        let signs = (on >> i) & 1 == 1;
        let decided = signs & (det != 0.0);
        let scaled_ok = t_scaled.is_finite();
        let in_range = (t > 0.0) & (t < limit[i]);
        let bound_ok = bound.is_finite();
        exact |= ((decided & (!scaled_ok | (in_range & !bound_ok))) as u32) << i;
        hit |= ((decided & scaled_ok & in_range & bound_ok & (t > bound)) as u32) << i;
        out.t[i] = t;
        out.u[i] = v * inv;
        out.v[i] = w * inv;
    }
    out.exact |= exact & lanes;
    out.hit = hit & lanes;
    out
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
