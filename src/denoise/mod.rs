//! Denoising a noisy render with Intel Open Image Denoise (OIDN 1.4, its `RT` filter for
//! path-traced pictures), guided by the albedo and normal layers ([`crate::render::aov`]).
//!
//! Behind the cargo feature `denoise` (on by default), which links the library fetched by
//! `scripts/fetch-assets oidn` ([`library`]). A build without the feature still compiles this
//! module: [`Denoiser::new`] then answers with how to get it.

pub mod library;

use glam::Vec3;

/// True when this build has the denoiser.
pub const AVAILABLE: bool = cfg!(feature = "denoise");

/// What a build without the feature says when asked to denoise.
pub const NOT_BUILT: &str = "this build of tracery has no denoiser: fetch Intel Open Image \
    Denoise with `scripts/fetch-assets oidn` and build with the default features (or \
    `--features denoise`)";

/// The images a denoise takes: the noisy colour (linear radiance, row 0 at the top) and,
/// optionally, the albedo and normal layers of the same pixels.
#[derive(Clone, Copy, Debug)]
pub struct Inputs<'a> {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Mean radiance of each pixel.
    pub color: &'a [Vec3],
    /// Albedo of each pixel, in `[0, 1]`.
    pub albedo: Option<&'a [Vec3]>,
    /// Shading normal of each pixel (used only with the albedo, as OIDN does).
    pub normal: Option<&'a [Vec3]>,
}

/// An OIDN device on the CPU, made once and used for many pictures (making one loads the
/// library's kernels and starts its threads).
pub struct Denoiser {
    #[cfg(feature = "denoise")]
    device: oidn::Device,
}

impl Denoiser {
    /// A denoiser on the CPU, or the reason there is none (this build has no denoiser).
    pub fn new() -> anyhow::Result<Denoiser> {
        #[cfg(feature = "denoise")]
        {
            let device = oidn::Device::cpu();
            if let Err((_, message)) = device.get_error() {
                anyhow::bail!("Open Image Denoise cannot start: {message}");
            }
            Ok(Denoiser { device })
        }
        #[cfg(not(feature = "denoise"))]
        anyhow::bail!(NOT_BUILT)
    }

    /// The denoised picture of `inputs` (linear radiance, one value per pixel).
    pub fn run(&self, inputs: &Inputs) -> anyhow::Result<Vec<Vec3>> {
        let n = inputs.width as usize * inputs.height as usize;
        let sizes = [
            Some(inputs.color.len()),
            inputs.albedo.map(<[Vec3]>::len),
            inputs.normal.map(<[Vec3]>::len),
        ];
        if let Some(bad) = sizes.into_iter().flatten().find(|&len| len != n) {
            anyhow::bail!(
                "cannot denoise: an image of {bad} pixels given for {}x{}",
                inputs.width,
                inputs.height
            );
        }
        #[cfg(feature = "denoise")]
        {
            let flat = |v: &[Vec3]| -> Vec<f32> {
                v.iter()
                    .flat_map(|p| p.to_array())
                    .map(|x| if x.is_finite() { x } else { 0.0 })
                    .collect()
            };
            let color = flat(inputs.color);
            let albedo = inputs.albedo.map(flat);
            let normal = inputs.normal.map(flat);
            let mut out = vec![0.0f32; color.len()];
            let mut filter = oidn::RayTracing::new(&self.device);
            filter
                .hdr(true)
                .srgb(false)
                .image_dimensions(inputs.width as usize, inputs.height as usize);
            match (&albedo, &normal) {
                (Some(a), Some(nrm)) => {
                    filter.albedo_normal(a, nrm);
                }
                (Some(a), None) => {
                    filter.albedo(a);
                }
                _ => {}
            }
            filter
                .filter(&color, &mut out)
                .map_err(|e| anyhow::anyhow!("Open Image Denoise failed: {e:?}"))?;
            if let Err((_, message)) = self.device.get_error() {
                anyhow::bail!("Open Image Denoise failed: {message}");
            }
            Ok(out
                .chunks_exact(3)
                .map(|c| Vec3::new(c[0], c[1], c[2]).max(Vec3::ZERO))
                .collect())
        }
        #[cfg(not(feature = "denoise"))]
        anyhow::bail!(NOT_BUILT)
    }
}

#[cfg(test)]
mod tests {
    use super::library;

    /// The check build.rs runs names the missing file, the fetch script and the way to build
    /// without the denoiser; a folder holding the three files passes.
    #[test]
    fn a_missing_library_is_named_with_the_fetch_script() {
        let dir = std::env::temp_dir().join(format!("tracery-oidn-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("a temporary folder");
        let message = library::check(&dir).expect_err("an empty folder has no library");
        assert!(message.contains("libOpenImageDenoise.so"), "{message}");
        assert!(message.contains(&dir.display().to_string()), "{message}");
        assert!(message.contains(library::FETCH), "{message}");
        assert!(message.contains("--no-default-features"), "{message}");
        for name in library::FILES {
            std::fs::write(dir.join(name), b"").expect("a file");
        }
        assert_eq!(library::check(&dir), Ok(()));
        std::fs::remove_dir_all(&dir).expect("removed");
    }
}
