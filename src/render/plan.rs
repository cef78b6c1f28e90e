//! The render plan: what a scene and its settings need, decided once before rendering, so
//! that nothing a scene does not use is loaded, sampled or traced.

use std::fmt;

use crate::scene::{Environment, Integrator, Light, Scene};

use super::RenderSettings;

/// The features a render uses. Each `false` means that work is skipped entirely.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RenderPlan {
    /// How light is gathered: `direct` traces no diffuse bounces at all.
    pub integrator: Integrator,
    /// Rays that leave the scene sample the environment (else they see black).
    pub environment: bool,
    /// Shadow rays are traced towards the lights (and emissive triangles); else every light is
    /// seen unblocked: no shadows, and no shadow rays.
    pub shadows: bool,
    /// Shadow rays pass through transparent surfaces and are attenuated by them (else a
    /// shadow ray is a plain any-hit occlusion test).
    pub transparent_shadows: bool,
    /// Mirror surfaces spawn reflection rays (up to [`RenderSettings::max_depth`]).
    pub reflections: bool,
    /// Transparent surfaces let camera and reflection rays continue through them.
    pub transmission: bool,
    /// Closed transparent meshes absorb light with distance (Beer-Lambert).
    pub absorption: bool,
    /// Camera rays start on a thin lens (else a pinhole).
    pub thin_lens: bool,
    /// Materials' normal and height maps bend the shading normal (else the interpolated
    /// normal is used, and no such map is read).
    pub normal_maps: bool,
    /// A normal a map bent is given a microfacet shadowing term that softens the hard shadow
    /// terminator of a smooth mesh (as Mitsuba 3's `normalmap` and `bumpmap` do by default;
    /// see [`super::bsdf::Bump`]); else the bent normal shades as it is.
    pub soft_terminator: bool,
    /// GGX lobes put back the light lost between their microfacets
    /// ([`super::bsdf::compensation`]; the scene file's `[render] energy_compensation`, on by
    /// default).
    pub energy_compensation: bool,
    /// At most this many shadow samples per area light and shading point (`None`: each
    /// light's own count). The viewer's moving preview takes 1: noisier, several times cheaper.
    pub max_light_samples: Option<u32>,
}

impl RenderPlan {
    /// Derives the plan from the scene and settings.
    pub fn new(scene: &Scene, settings: &RenderSettings) -> Self {
        Self::with_integrator(scene, scene.integrator, settings)
    }

    /// [`RenderPlan::new`] with another integrator than the scene's.
    pub fn with_integrator(
        scene: &Scene,
        integrator: Integrator,
        settings: &RenderSettings,
    ) -> Self {
        let transparent = scene.materials.iter().any(|m| m.is_transparent());
        let absorbing = scene
            .materials
            .iter()
            .any(|m| m.is_transparent() && m.absorption.max_element() > 0.0);
        let bounces = settings.max_depth > 0;
        Self {
            integrator,
            environment: !matches!(scene.environment, Environment::None),
            // Both integrators also sample emissive triangles as lights.
            shadows: !scene.lights.is_empty() || scene.materials.iter().any(|m| m.is_emissive()),
            transparent_shadows: transparent,
            reflections: bounces && scene.materials.iter().any(|m| m.may_mirror()),
            transmission: bounces && transparent,
            absorption: absorbing,
            thin_lens: scene.camera.lens_radius > 0.0,
            normal_maps: scene
                .materials
                .iter()
                .any(|m| m.has_normal_map() || m.has_height_map()),
            soft_terminator: settings.soft_terminator,
            energy_compensation: scene.energy_compensation,
            max_light_samples: None,
        }
    }

    /// Everything on, with the direct integrator: the reference the tests compare a pruned
    /// plan against.
    pub fn everything() -> Self {
        Self {
            integrator: Integrator::Direct,
            environment: true,
            shadows: true,
            transparent_shadows: true,
            reflections: true,
            transmission: true,
            absorption: true,
            thin_lens: true,
            normal_maps: true,
            soft_terminator: true,
            energy_compensation: true,
            max_light_samples: None,
        }
    }
}

/// The plan as `tracery render --explain` prints it, with the lights of `scene`.
pub struct Explain<'a>(pub &'a RenderPlan, pub &'a Scene, pub &'a RenderSettings);

impl fmt::Display for Explain<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (p, scene, s) = (self.0, self.1, self.2);
        let on = |b: bool| if b { "yes" } else { "no, skipped" };
        writeln!(f, "render plan for {}:", scene.name)?;
        match p.integrator {
            Integrator::Direct => writeln!(
                f,
                "  integrator           direct: light from the lights and emissive triangles only, no bounces \
                 off diffuse surfaces (glossy ones also look for rectangle lights along their lobes: MIS)"
            )?,
            Integrator::Path => writeln!(
                f,
                "  integrator           path: up to {} diffuse bounces (the last collects emission only), \
                 Russian roulette, light samples weighted against bounces by MIS",
                s.max_depth
            )?,
        }
        let set = super::light::LightSet::new(scene);
        if set.sampled_triangles() > 0 {
            writeln!(
                f,
                "  emissive triangles   {} sampled as lights by area",
                set.sampled_triangles()
            )?;
        }
        writeln!(
            f,
            "  environment          {}",
            if p.environment {
                format!("yes ({})", env_name(&scene.environment))
            } else {
                "no, nothing loaded or sampled".into()
            }
        )?;
        writeln!(
            f,
            "  shadows              {}",
            if p.shadows {
                "yes"
            } else {
                "no, lights are never blocked"
            }
        )?;
        writeln!(
            f,
            "  transparent shadows  {}",
            if p.transparent_shadows {
                "yes (shadow rays pass transparent surfaces)"
            } else {
                "no transparent material: occlusion-only shadow rays"
            }
        )?;
        writeln!(f, "  absorption           {}", on(p.absorption))?;
        writeln!(
            f,
            "  reflections          {}",
            if p.reflections {
                format!("yes, up to {} bounces", s.max_depth)
            } else {
                "no mirror (or depth 0): no reflection rays".into()
            }
        )?;
        writeln!(
            f,
            "  transmission         {}",
            if p.transmission {
                format!("yes, up to {} surfaces", s.max_depth)
            } else {
                "no transparent material: camera rays stop at the first hit".into()
            }
        )?;
        writeln!(
            f,
            "  normal maps          {}",
            if p.normal_maps {
                let n = scene
                    .materials
                    .iter()
                    .filter(|m| m.has_normal_map() || m.has_height_map())
                    .count();
                let terminator = if p.soft_terminator {
                    "shadow terminator softened"
                } else {
                    "hard shadow terminator"
                };
                format!(
                    "yes, {n} material(s) bend the shading normal (normal or height maps), {terminator}"
                )
            } else {
                "no normal or height map: interpolated normals".into()
            }
        )?;
        writeln!(
            f,
            "  lens                 {}",
            if p.thin_lens {
                format!(
                    "thin lens, radius {}, focus at {}",
                    scene.camera.lens_radius, scene.camera.focus_distance
                )
            } else {
                "pinhole".into()
            }
        )?;
        for (i, l) in scene.lights.iter().enumerate() {
            match l {
                Light::Spot { .. } => writeln!(
                    f,
                    "  light {i}              spot: 1 shadow ray (none outside its cone)"
                )?,
                Light::Point { .. } => writeln!(f, "  light {i}              point: 1 shadow ray")?,
                Light::Rect { samples, .. } => {
                    let shown = if p.integrator == Integrator::Path
                        && super::light::LightSet::new(scene).is_visible(i)
                    {
                        " (its emissive triangles are found by bounces: MIS)"
                    } else {
                        ""
                    };
                    let deeper = if p.integrator == Integrator::Path {
                        " at the first hit, 1 deeper"
                    } else {
                        ""
                    };
                    writeln!(
                        f,
                        "  light {i}              rectangle: {samples} shadow rays{deeper}{shown}"
                    )?
                }
            }
        }
        write!(
            f,
            "  samples              {} per pixel, {}x{}",
            s.spp, s.width, s.height
        )
    }
}

fn env_name(e: &Environment) -> &'static str {
    match e {
        Environment::None => "none",
        Environment::Color(_) => "constant colour",
        Environment::Sky { .. } => "procedural sky",
        Environment::CubeMap { .. } => "cube map",
        Environment::Equirect { .. } => "equirectangular image",
    }
}
