//! Quick look at a hair source: ray casts it with simple Kajiya–Kay shading and a shadow ray,
//! and writes a PNG.
//!
//! ```text
//! cargo run --release -p tress-accel --example preview -- 'File("straight.hair")' out.png
//! cargo run --release -p tress-accel --example preview -- \
//!     'Procedural((style: Curly(amplitude: 0.04, frequency: 5.0), points_per_strand: 48))' \
//!     curly.png '(basis: CatmullRom)'
//! ```
//!
//! Arguments: a `HairSource` in RON, the output PNG, optionally `HairOptions` in RON and the
//! direction toward the camera as a RON tuple (default `(0.35, 0.15, 1)`).
//! Procedural scalp hair is shown on its scalp sphere.

// A program of its own, not library code: it reads its command line (clippy.toml).
#![allow(clippy::disallowed_methods)]

use tress_accel::{HairOptions, SceneBuilder};
use tress_core::limits::Limits;
use tress_core::math::{Vec2, Vec3};
use tress_core::rng::Pcg32;
use tress_core::{Accel, Camera, HitKind, Image, Ray};
use tress_groom::{HairSource, HairStyle};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        return Err("usage: preview <HairSource RON> <out.png> [HairOptions RON]".into());
    }
    let source: HairSource = ron::from_str(&args[0])?;
    let options: HairOptions = match args.get(2) {
        Some(s) => ron::from_str(s)?,
        None => HairOptions::default(),
    };
    let view: Vec3 = match args.get(3) {
        Some(s) => ron::from_str(s)?,
        None => Vec3::new(0.35, 0.15, 1.0),
    };
    let hair = source.load(&Limits::default())?;
    let mut builder = SceneBuilder::new()?.add_hair(&hair, &options, 0)?;
    if let HairSource::Procedural(p) = &source {
        if p.style != HairStyle::Ball {
            builder = builder.add_sphere(p.center, p.sphere_radius, 1)?;
        }
    }
    let accel = builder.build()?;
    println!("{}", accel.info());

    let b = accel.bounds();
    let (center, size) = (b.center(), b.extent().max_element());
    let camera = Camera::perspective(
        center + view.normalize() * 2.2 * size,
        center,
        Vec3::Y,
        30.0,
        0.0,
        None,
    );
    let light = Vec3::new(-0.5, 1.0, 0.8).normalize();
    let (w, h, spp) = (512u32, 512u32, 4);
    let mut image = Image::new(w, h);
    let mut rng = Pcg32::new(1, 1);
    for y in 0..h {
        for x in 0..w {
            let mut sum = Vec3::ZERO;
            for _ in 0..spp {
                let (px, py) = (x as f32 + rng.next_f32(), y as f32 + rng.next_f32());
                let ray = camera.generate_ray(px, py, w, h, Vec2::ZERO);
                sum += shade(&accel, &ray, light);
            }
            image.set(x, y, sum / spp as f32);
        }
    }
    tress_core::output_file::write(
        std::path::Path::new(&args[1]),
        &tress_core::output_file::Inputs::default(),
        |out| {
            tress_core::image_io::write_png(out, &image, 0.0)
                .map_err(Box::<dyn std::error::Error>::from)
        },
    )?;
    println!("wrote {}", args[1]);
    Ok(())
}

fn shade(accel: &impl Accel, ray: &Ray, light: Vec3) -> Vec3 {
    let Some(hit) = accel.intersect(ray) else {
        return Vec3::splat(0.15);
    };
    let lit = !accel.occluded(&Ray::leaving(hit.p, light, hit.prim));
    let shadow = if lit { 1.0 } else { 0.25 };
    match hit.kind {
        HitKind::Fiber { tangent, .. } => {
            // Kajiya–Kay: diffuse ∝ sin(t, l), specular around the cone of the view direction.
            let tl = tangent.dot(light);
            let tv = tangent.dot(-ray.dir);
            let diffuse = (1.0 - tl * tl).max(0.0).sqrt();
            let spec = (tl * tv
                + (1.0 - tl * tl).max(0.0).sqrt() * (1.0 - tv * tv).max(0.0).sqrt())
            .max(0.0)
            .powf(40.0);
            let blond = Vec3::new(0.85, 0.65, 0.35);
            (blond * (0.15 + 0.7 * diffuse * shadow)) + Vec3::splat(0.4 * spec * shadow)
        }
        HitKind::Surface { normal } => {
            Vec3::new(0.8, 0.6, 0.5) * (0.15 + 0.8 * normal.dot(light).max(0.0) * shadow)
        }
    }
}
