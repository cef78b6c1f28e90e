//! Energy compensation for the GGX conductor (Kulla and Conty 2017, "Revisiting Physically
//! Based Shading at Imageworks"). A single-scattering microfacet BRDF loses the light that
//! bounces between its microfacets: a white rough metal seen from its normal reflects 0.69 of
//! what it receives at roughness 0.7. The compensation puts it back as a lobe of its own,
//!
//! `f_ms(wi, wo) = F_ms (1 - E(cos_o)) (1 - E(cos_i)) / (pi (1 - E_avg))`,
//!
//! where `E` is the lobe's directional albedo with a Fresnel of 1 ([`albedo`], read from the
//! table `examples/ggx_albedo.rs` integrates), `E_avg = 2 int E(mu) mu dmu` its cosine-weighted
//! mean ([`average`]), and `F_ms = F_avg^2 E_avg / (1 - F_avg (1 - E_avg))` what a coloured
//! metal's Fresnel keeps of it over the bounces, with Schlick's mean
//! `F_avg = f0 + (f90 - f0) / 21`. With a Fresnel of 1 the two add up to 1 from every
//! direction (`bsdf/tests.rs`: the white furnace). The bounces are sampled by the lobe's own
//! visible normals, which cover the hemisphere: unbiased, and the compensation is largest where
//! the lobe is widest.
//!
//! It is on by default; a scene file's `[render] energy_compensation = false` turns it off
//! (Mitsuba 3's `roughconductor` has none, so the reference scenes do).

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use super::MIN_ALPHA;
use super::ggx_albedo::{ALBEDO, AVERAGE, COSINES, ROUGHNESSES};
use super::microfacet::{reflect_about_visible_normal, smith_g1};

/// Smallest cosine the table holds (a direction closer to the horizon is read as this one).
pub const MIN_COSINE: f32 = 1e-3;

/// The cosine the table's column `j` holds.
pub fn table_cosine(j: usize) -> f32 {
    (j as f32 / (COSINES - 1) as f32).max(MIN_COSINE)
}

/// The GGX width (`roughness^2`, at least [`MIN_ALPHA`]) the table's row `i` holds: rows are
/// evenly spaced in roughness.
pub fn table_alpha(i: usize) -> f32 {
    let r = i as f32 / (ROUGHNESSES - 1) as f32;
    (r * r).max(MIN_ALPHA)
}

/// Row and weight of the next row for width `alpha` (rows by roughness, its square root).
fn row_of(alpha: f32) -> (usize, f32) {
    let r = if alpha.is_nan() {
        0.0
    } else {
        alpha.clamp(0.0, 1.0).sqrt()
    };
    let x = r * (ROUGHNESSES - 1) as f32;
    let i = (x as usize).min(ROUGHNESSES - 2);
    (i, x - i as f32)
}

/// The GGX lobe's directional albedo with a Fresnel of 1, seen at cosine `cos`, for width
/// `alpha`: the table read between its entries (bilinearly).
pub fn albedo(cos: f32, alpha: f32) -> f32 {
    let (i, fr) = row_of(alpha);
    let c = if cos.is_nan() {
        0.0
    } else {
        cos.clamp(0.0, 1.0)
    } * (COSINES - 1) as f32;
    let j = (c as usize).min(COSINES - 2);
    let fc = c - j as f32;
    let row = |i: usize| ALBEDO[i][j] * (1.0 - fc) + ALBEDO[i][j + 1] * fc;
    row(i) * (1.0 - fr) + row(i + 1) * fr
}

/// The albedo's cosine-weighted mean over the hemisphere, `2 int E(mu) mu dmu`, for width
/// `alpha` (the table read between its rows).
pub fn average(alpha: f32) -> f32 {
    let (i, fr) = row_of(alpha);
    AVERAGE[i] * (1.0 - fr) + AVERAGE[i + 1] * fr
}

/// The compensation lobe `f_ms` (see the module docs) of a GGX conductor of width `alpha`
/// (at least [`MIN_ALPHA`]) and Fresnel from `f0` to `f90`, between directions at cosines `ci`
/// and `co` to the normal (both above it).
#[inline]
pub(super) fn multiple_scattering(f0: Vec3, f90: f32, alpha: f32, ci: f32, co: f32) -> Vec3 {
    let e_avg = average(alpha);
    if e_avg >= 1.0 {
        return Vec3::ZERO;
    }
    let f_avg = f0 + (Vec3::splat(f90) - f0) / 21.0;
    let f_ms = f_avg * f_avg * e_avg / (Vec3::ONE - f_avg * (1.0 - e_avg));
    let k = (1.0 - albedo(co, alpha)) * (1.0 - albedo(ci, alpha)) / (PI * (1.0 - e_avg));
    f_ms * k
}

/// The GGX lobe's directional albedo with a Fresnel of 1 at cosine `co` and width `alpha`,
/// integrated over the lobe's visible normals by the midpoint rule on `n x n` points of the
/// unit square: the mean of `G1(wi)` over the reflected directions (the lobe's own weight
/// `f cos / pdf`), in f64 sums. What `examples/ggx_albedo.rs` tabulates.
pub fn integrate_albedo(co: f32, alpha: f32, n: usize) -> f64 {
    let co = co.clamp(MIN_COSINE, 1.0);
    let a = alpha.max(MIN_ALPHA);
    let wo = Vec3::new((1.0 - co * co).max(0.0).sqrt(), 0.0, co);
    let mut sum = 0.0f64;
    for y in 0..n {
        for x in 0..n {
            let u = Vec2::new((x as f32 + 0.5) / n as f32, (y as f32 + 0.5) / n as f32);
            if let Some(wi) = reflect_about_visible_normal(Vec3::Z, wo, a, u)
                && wi.z > 0.0
            {
                sum += smith_g1(wi.z, a) as f64;
            }
        }
    }
    sum / (n * n) as f64
}

/// [`average`] integrated: `2 int E(mu) mu dmu` by the midpoint rule on `rings` cosines, each
/// albedo by [`integrate_albedo`] on `n x n` points.
pub fn integrate_average(alpha: f32, rings: usize, n: usize) -> f64 {
    (0..rings)
        .map(|k| {
            let mu = (k as f64 + 0.5) / rings as f64;
            integrate_albedo(mu as f32, alpha, n) * mu
        })
        .sum::<f64>()
        * 2.0
        / rings as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quadrature `examples/ggx_albedo.rs` wrote the table with.
    const N: usize = 256;
    const RINGS: usize = 64;

    #[test]
    fn the_table_is_what_the_integral_gives() {
        for i in (0..ROUGHNESSES).step_by(8).chain([ROUGHNESSES - 1]) {
            for j in (0..COSINES).step_by(8).chain([COSINES - 1]) {
                let (a, c) = (table_alpha(i), table_cosine(j));
                let e = integrate_albedo(c, a, N) as f32;
                assert!(
                    (ALBEDO[i][j] - e).abs() <= 1e-5,
                    "alpha {a}, cosine {c}: table {} against {e}",
                    ALBEDO[i][j]
                );
            }
            let e = integrate_average(table_alpha(i), RINGS, N) as f32;
            assert!(
                (AVERAGE[i] - e).abs() <= 1e-5,
                "alpha {}: {} against {e}",
                table_alpha(i),
                AVERAGE[i]
            );
        }
    }

    #[test]
    fn a_smooth_lobe_loses_nothing_and_a_rough_one_about_a_third() {
        // Nearly a mirror: every reflected direction escapes.
        assert!(albedo(0.9, MIN_ALPHA) > 0.999, "{}", albedo(0.9, MIN_ALPHA));
        assert!(average(MIN_ALPHA) > 0.99);
        // Roughness 0.7 from the normal: about 0.69 (the compensation's reason).
        let e = albedo(1.0, 0.49);
        assert!((0.66..0.72).contains(&e), "{e}");
        // Every entry is a share of the light.
        assert!(
            ALBEDO
                .iter()
                .flatten()
                .chain(&AVERAGE)
                .all(|&e| e > 0.0 && e <= 1.0)
        );
    }
}
