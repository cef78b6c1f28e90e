//! The samplers: pixel, lens and light samples drawn at random or from Owen-scrambled Sobol
//! points, reproducible per pixel and sample index (the generator itself is [`crate::rng`]).

use crate::rng::mix64;

/// How the pixel, lens and light samples are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SamplerKind {
    /// Independent uniform random numbers.
    Random,
    /// Owen-scrambled Sobol points, padded by 2D dimension pairs (Burley 2020): every 2D
    /// decision (pixel position, lens position, one light sample) is a (0, 2)-sequence in
    /// the sample index, scrambled per pixel and per dimension pair.
    Sobol,
}

impl std::fmt::Display for SamplerKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            SamplerKind::Random => "random",
            SamplerKind::Sobol => "sobol",
        })
    }
}

impl std::str::FromStr for SamplerKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "random" => Ok(SamplerKind::Random),
            "sobol" => Ok(SamplerKind::Sobol),
            other => Err(format!(
                "unknown sampler `{other}` (expected random or sobol)"
            )),
        }
    }
}

/// Fixed 2D dimensions: a decision always reads the same dimension whether or not the others
/// were drawn, so leaving out a feature never shifts the samples of the rest.
pub mod dim {
    /// Position inside the pixel.
    pub const PIXEL: u32 = 0;
    /// Position on the lens.
    pub const LENS: u32 = 1;
    /// First light sample; later ones follow.
    pub const LIGHT: u32 = 2;
}

/// The samples of one pixel: a 2D point for any (sample index, dimension) pair, computed
/// from a hash rather than drawn from a stream, so it does not depend on what was drawn
/// before (or on which thread).
#[derive(Clone, Copy, Debug)]
pub struct PixelSampler {
    kind: SamplerKind,
    seed: u64,
    index: u32,
    /// `index` bit-reversed, once per sample instead of once per dimension.
    index_rev: u32,
}

impl PixelSampler {
    /// The sampler of `pixel` for sample number `index`, from the render's `seed`.
    pub fn new(kind: SamplerKind, seed: u64, pixel: u64, index: u32) -> Self {
        Self {
            kind,
            seed: mix64(seed ^ mix64(pixel.wrapping_add(0x5851_F42D_4C95_7F2D))),
            index,
            index_rev: index.reverse_bits(),
        }
    }

    /// The same pixel's sampler for another sample index.
    pub fn with_index(self, index: u32) -> Self {
        Self {
            index,
            index_rev: index.reverse_bits(),
            ..self
        }
    }

    /// The 2D point of dimension pair `dim`, in `[0, 1)^2`.
    pub fn get_2d(&self, dim: u32) -> glam::Vec2 {
        let (x, y) = point(self.kind, self.seed, self.index, self.index_rev, dim);
        glam::Vec2::new(x, y)
    }
}

/// The 2D point of dimension pair `dim` for the sample `index` (bit-reversed: `index_rev`) of a
/// pixel whose stream is `seed`: what [`PixelSampler::get_2d`] returns, as a function of plain
/// numbers, so that many paths' points can be computed side by side
/// ([`PathSampler::parts`]).
#[inline(always)]
pub(crate) fn point(
    kind: SamplerKind,
    seed: u64,
    index: u32,
    index_rev: u32,
    dim: u32,
) -> (f32, f32) {
    let h = mix64(seed ^ (dim as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    match kind {
        SamplerKind::Random => {
            let r = mix64(h ^ (index as u64).wrapping_mul(0xD1B5_4A32_D192_ED03));
            (unit((r >> 32) as u32), unit(r as u32))
        }
        SamplerKind::Sobol => {
            // Shuffle the index (decorrelates dimension pairs), then scramble each axis:
            // with `i` the shuffled index, `x = nested_uniform_scramble(i.reverse_bits(),
            // sx)` and `y = nested_uniform_scramble(sobol_dim1(i), sy)`. Computed on the
            // reversed bits throughout, where the scrambles work (`i` reversed is `w`, and
            // `sobol_dim1(i)` reversed is a table lookup of `w`): two bit reversals a point
            // instead of seven, the same bits (`tests/sampling.rs`). The second reverses
            // both axes side by side in 64 bits: `x` in the high half comes back reversed
            // in the low half, `y` the other way round.
            let w = laine_karras(index_rev, h as u32);
            let x = laine_karras(w.reverse_bits(), (h >> 32) as u32 ^ 0x68bc_21eb);
            let y = laine_karras(sobol_dim1_reversed(w), (h >> 16) as u32 ^ 0x02e5_be93);
            let both = ((x as u64) << 32 | y as u64).reverse_bits();
            (unit(both as u32), unit((both >> 32) as u32))
        }
    }
}

/// Maps 32 random bits to `[0, 1)` (24 bits kept, so the result is never 1).
#[inline]
fn unit(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// The second Sobol dimension (the first is the bit-reversed index): with it, the first `2^k`
/// points form a (0, 2)-sequence, one point in every elementary interval. The generator
/// matrix is linear over GF(2), so the index is taken a byte at a time through tables of the
/// matrix's columns (the same bits as [`sobol_dim1_bitwise`], a fifth of the work).
#[inline]
pub fn sobol_dim1(i: u32) -> u32 {
    let t = &SOBOL_DIM1_TABLES;
    t[0][(i & 0xff) as usize]
        ^ t[1][((i >> 8) & 0xff) as usize]
        ^ t[2][((i >> 16) & 0xff) as usize]
        ^ t[3][(i >> 24) as usize]
}

/// `sobol_dim1(w.reverse_bits()).reverse_bits()`, by tables of the reversed columns: the
/// second Sobol dimension where the index and the point are both bit-reversed.
#[inline]
fn sobol_dim1_reversed(w: u32) -> u32 {
    let t = &SOBOL_DIM1_REVERSED_TABLES;
    t[0][(w & 0xff) as usize]
        ^ t[1][((w >> 8) & 0xff) as usize]
        ^ t[2][((w >> 16) & 0xff) as usize]
        ^ t[3][(w >> 24) as usize]
}

/// [`sobol_dim1`] one bit at a time: column `k + 1` is column `k` xor itself shifted right.
pub fn sobol_dim1_bitwise(mut i: u32) -> u32 {
    let mut v = 1u32 << 31;
    let mut r = 0;
    while i != 0 {
        if i & 1 != 0 {
            r ^= v;
        }
        i >>= 1;
        v ^= v >> 1;
    }
    r
}

/// For each byte of the index, the xor of the generator columns its set bits select.
static SOBOL_DIM1_TABLES: [[u32; 256]; 4] = sobol_dim1_tables(false);

/// The same for a bit-reversed index and point ([`sobol_dim1_reversed`]): bit `m` of the
/// reversed index is bit `31 - m` of the index, and selects column `31 - m` reversed.
static SOBOL_DIM1_REVERSED_TABLES: [[u32; 256]; 4] = sobol_dim1_tables(true);

const fn sobol_dim1_tables(reversed: bool) -> [[u32; 256]; 4] {
    let mut columns = [0u32; 32];
    let mut v = 1u32 << 31;
    let mut k = 0;
    while k < 32 {
        columns[k] = v;
        v ^= v >> 1;
        k += 1;
    }
    if reversed {
        let forward = columns;
        let mut m = 0;
        while m < 32 {
            columns[m] = forward[31 - m].reverse_bits();
            m += 1;
        }
    }
    let mut t = [[0u32; 256]; 4];
    let mut j = 0;
    while j < 4 {
        let mut b = 0;
        while b < 256 {
            let mut r = 0;
            let mut bit = 0;
            while bit < 8 {
                if b & (1 << bit) != 0 {
                    r ^= columns[8 * j + bit];
                }
                bit += 1;
            }
            t[j][b] = r;
            b += 1;
        }
        j += 1;
    }
    t
}

/// Owen scrambling by hashing (Laine-Karras permutation on the reversed bits, Burley 2020).
#[inline]
pub fn nested_uniform_scramble(x: u32, seed: u32) -> u32 {
    laine_karras(x.reverse_bits(), seed).reverse_bits()
}

/// The Laine-Karras permutation, on bit-reversed values: each bit flipped by a hash of the
/// bits below it (above it in the value's own order).
#[inline]
fn laine_karras(mut v: u32, seed: u32) -> u32 {
    v = v.wrapping_add(seed);
    v ^= v.wrapping_mul(0x6c50_b47c);
    v ^= v.wrapping_mul(0xb82f_1e52);
    v ^= v.wrapping_mul(0xc7af_e638);
    v ^= v.wrapping_mul(0x8d22_f6e6);
    v
}

/// Shirley-Chiu concentric map of the unit square onto the unit disk (keeps strata intact).
///
/// The point's angle is `pi/4 * o.y / o.x` where `|o.x| > |o.y|`, else `pi/2 - pi/4 * o.x /
/// o.y`; both come from the sine and cosine of `a = pi/4 * (the smaller over the larger)`,
/// `|a| <= pi/4` ([`sin_cos_octant`]), swapped for the second.
#[inline]
pub fn concentric_disk(u: glam::Vec2) -> glam::Vec2 {
    let o = 2.0 * u - glam::Vec2::ONE;
    if o == glam::Vec2::ZERO {
        return glam::Vec2::ZERO;
    }
    let steep = o.x.abs() <= o.y.abs();
    let (r, a) = if steep {
        (o.y, std::f32::consts::FRAC_PI_4 * (o.x / o.y))
    } else {
        (o.x, std::f32::consts::FRAC_PI_4 * (o.y / o.x))
    };
    let (sin, cos) = sin_cos_octant(a);
    // cos(pi/2 - a) = sin a, sin(pi/2 - a) = cos a.
    r * if steep {
        glam::Vec2::new(sin, cos)
    } else {
        glam::Vec2::new(cos, sin)
    }
}

/// `(sin a, cos a)` for `|a| <= pi/4`, by polynomials with no branch and no call, so that
/// loops over many angles (the plain step's sixteen lanes) vectorise: the odd polynomial of
/// degree 7 and the even one of degree 8 of Cephes' single-precision `sinf` and `cosf`
/// (Moshier), evaluated by Horner's rule without fused multiply-adds, so every build and vector
/// width gives the same bits. Within 0.76 ulp of the exact sine and 1.25 ulp of the cosine over
/// the range (a test checks 1.5 against f64).
#[inline(always)]
pub fn sin_cos_octant(a: f32) -> (f32, f32) {
    let z = a * a;
    let sin = a + a * z * (-1.666_665_5e-1 + z * (8.332_161e-3 + z * -1.951_529_6e-4));
    let cos = 1.0 - 0.5 * z + z * z * (4.166_664_6e-2 + z * (-1.388_731_6e-3 + z * 2.443_315_7e-5));
    (sin, cos)
}

/// Cosine-weighted direction about `n` (Malley's method on the concentric disk).
pub fn cosine_direction(n: glam::Vec3, u: glam::Vec2) -> glam::Vec3 {
    let d = concentric_disk(u);
    let z = (1.0 - d.length_squared()).max(0.0).sqrt();
    let (t, b) = n.any_orthonormal_pair();
    // Unit length already: an orthonormal frame and a point of the unit hemisphere.
    t * d.x + b * d.y + n * z
}

/// The light-sample dimensions of one camera path, handed out in the order the path asks for
/// them (after the fixed pixel and lens dimensions).
#[derive(Clone, Copy, Debug)]
pub struct PathSampler {
    pixel: PixelSampler,
    next: u32,
}

impl PathSampler {
    /// Light samples for the path of `pixel`'s current sample.
    pub fn new(pixel: PixelSampler) -> Self {
        Self {
            pixel,
            next: dim::LIGHT,
        }
    }

    /// The next 2D light sample.
    pub fn next_2d(&mut self) -> glam::Vec2 {
        let v = self.pixel.get_2d(self.next);
        self.next += 1;
        v
    }

    /// What [`point`] needs to give this path's samples: the sampler kind, the pixel's stream,
    /// the sample index and its bits reversed, and the next dimension pair.
    #[inline(always)]
    pub(crate) fn parts(&self) -> (SamplerKind, u64, u32, u32, u32) {
        let p = &self.pixel;
        (p.kind, p.seed, p.index, p.index_rev, self.next)
    }

    /// Moves on to dimension pair `next` (after [`point`] gave the ones before it).
    #[inline(always)]
    pub(crate) fn set_next(&mut self, next: u32) {
        self.next = next;
    }
}
