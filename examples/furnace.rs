//! The white furnace: what a surface reflects of a uniform white environment, seen at view
//! cosines 0.1 to 1 (columns) for roughness 0.1 to 1 (rows), each from 2^16 stratified samples
//! of its BSDF ([`tracery::render::bsdf::Bsdf::reflectance_from`]). Three surfaces: a white
//! GGX conductor (Fresnel 1) without and with energy compensation, and glTF's dielectric layer
//! (`f0` 0.04) over a white base, with compensation on its GGX lobe. Prints Markdown tables.
//!
//! `cargo run --release --example furnace`
use glam::Vec3;
use tracery::render::bsdf::{Bsdf, Bump, Coat, DielectricLayer, Ggx, Gloss, MIN_ALPHA, Sheen};

/// A surface of `diffuse` colour under a GGX lobe of `f0` and `roughness`.
fn surface(diffuse: Vec3, f0: Vec3, roughness: f32, compensate: bool) -> Bsdf {
    Bsdf {
        n: Vec3::Z,
        diffuse,
        gloss: Gloss::Ggx(Ggx {
            f0,
            f90: 1.0,
            alpha: (roughness * roughness).max(MIN_ALPHA),
            dielectric: DielectricLayer {
                f0: 0.04,
                weight: 1.0,
            },
            compensate,
        }),
        sheen: Sheen::NONE,
        coat: Coat::NONE,
        bump: Bump::NONE,
    }
}

fn table(title: &str, make: impl Fn(f32) -> Bsdf) {
    println!("\n{title}\n");
    let cosines: Vec<f32> = (1..=10).map(|c| c as f32 / 10.0).collect();
    print!("| roughness |");
    for c in &cosines {
        print!(" {c:.1} |");
    }
    println!("\n|---:|{}", "---:|".repeat(cosines.len()));
    for r in 1..=10 {
        let roughness = r as f32 / 10.0;
        let bsdf = make(roughness);
        print!("| {roughness:.1} |");
        for &c in &cosines {
            let wo = Vec3::new((1.0 - c * c).sqrt(), 0.0, c);
            print!(" {:.3} |", bsdf.reflectance_from(wo, 256).x);
        }
        println!();
    }
}

fn main() {
    table("White GGX conductor, no compensation", |r| {
        surface(Vec3::ZERO, Vec3::ONE, r, false)
    });
    table("White GGX conductor, energy compensation", |r| {
        surface(Vec3::ZERO, Vec3::ONE, r, true)
    });
    table(
        "glTF dielectric layer (f0 0.04) over a white base, compensation on its GGX lobe",
        |r| surface(Vec3::ONE, Vec3::splat(0.04), r, true),
    );
}
