//! The sRGB transfer function (IEC 61966-2-1) both ways, exact and by table: the encoding of
//! every 8-bit picture and the decoding of every sRGB texture and environment.

/// Entries of the [`srgb8_fast`] table over `[0, 1]`.
const SRGB_LUT_SIZE: usize = 8192;

/// [`srgb8`] by table lookup: never more than one level off the exact value (a test checks).
#[inline]
pub fn srgb8_fast(x: f32) -> u8 {
    srgb8_lookup(srgb8_lut(), x)
}

/// The [`srgb8_fast`] table, built on first use (with [`srgb8_lookup`], for loops that
/// encode many values).
pub fn srgb8_lut() -> &'static [u8] {
    static LUT: std::sync::OnceLock<Vec<u8>> = std::sync::OnceLock::new();
    LUT.get_or_init(|| {
        (0..SRGB_LUT_SIZE)
            .map(|i| srgb8(i as f32 / (SRGB_LUT_SIZE - 1) as f32))
            .collect()
    })
}

/// `x` (linear, clamped to `[0, 1]`; NaN as 0) encoded through `lut`, the table of
/// [`srgb8_lut`].
#[inline(always)]
pub fn srgb8_lookup(lut: &[u8], x: f32) -> u8 {
    let x = if x.is_nan() { 0.0 } else { x.clamp(0.0, 1.0) };
    lut[(x * (SRGB_LUT_SIZE - 1) as f32 + 0.5) as usize]
}

/// Linear `[0, 1]` to an 8-bit sRGB value.
pub fn srgb8(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// The sRGB transfer function's inverse (IEC 61966-2-1): an encoded value in `[0, 1]` to
/// linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// [`srgb_to_linear`] of every sRGB-encoded byte, by byte.
pub fn srgb8_table() -> &'static [f32; 256] {
    static TABLE: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)))
}
