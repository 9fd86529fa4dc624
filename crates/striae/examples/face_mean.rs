//! The mean luminance of renders of one scene over the pixels that see only the face of its
//! scratched pane that faces up (`docs/fidelity.md`, "Crossings"): the pixels whose centre
//! camera ray, and those of their eight neighbours, first meet a surface whose geometric
//! normal is within 1 degree of `+y`. So the pane's rims (its side faces, where explicit
//! grooves end) and the pixels along them are left out.
//!
//! ```sh
//! cargo run --release -p striae --example face_mean -- SCENE.toml IMAGE.exr...
//! ```
//!
//! Prints, for each image, its mean over all pixels and over the face's pixels.

use std::error::Error;
use std::path::Path;
use striae::math::{luminance, Vec2};
use striae::render::scene::{Overrides, Scene};
use striae::render::texture::RgbImage;

/// Whether each pixel (row by row) sees only the up-facing face.
fn face_mask(scene: &Scene) -> (usize, usize, Vec<bool>) {
    let (w, h) = scene.camera.resolution();
    let (w, h) = (w as usize, h as usize);
    let up = |x: usize, y: usize| {
        let film = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
        let ray = scene.camera.generate_ray_only(film, Vec2::splat(0.5));
        scene
            .geometry
            .intersect(&ray)
            .is_some_and(|hit| hit.ng.y > 1.0f32.to_radians().cos())
    };
    let sees: Vec<bool> = (0..w * h).map(|i| up(i % w, i / w)).collect();
    let mask = (0..w * h)
        .map(|i| {
            let (x, y) = ((i % w) as i64, (i / w) as i64);
            (-1..=1).all(|dy| {
                (-1..=1).all(|dx| {
                    let (nx, ny) = (x + dx, y + dy);
                    nx >= 0
                        && ny >= 0
                        && (nx as usize) < w
                        && (ny as usize) < h
                        && sees[ny as usize * w + nx as usize]
                })
            })
        })
        .collect();
    (w, h, mask)
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        return Err("usage: face_mean SCENE.toml IMAGE.exr...".into());
    }
    let file = Path::new(&args[0]);
    let text = std::fs::read_to_string(file).map_err(|e| format!("{}: {e}", file.display()))?;
    let base = file.parent().unwrap_or(Path::new("."));
    let scene = Scene::parse(&text, file, base, &Overrides::default())?;
    let (w, h, mask) = face_mask(&scene);
    let n = mask.iter().filter(|&&m| m).count();
    println!("{n} of {} pixels see only the up-facing face", w * h);
    println!("image, mean, face mean");
    for image in &args[1..] {
        let img = RgbImage::load(Path::new(image), None).map_err(|e| e.to_string())?;
        if (img.width, img.height) != (w, h) {
            return Err(format!("{image}: not the scene's {w} x {h} pixels").into());
        }
        let lum = |c| luminance(c) as f64;
        let all = img.pixels.iter().map(|&c| lum(c)).sum::<f64>() / img.pixels.len() as f64;
        let face = img
            .pixels
            .iter()
            .zip(&mask)
            .filter(|(_, &m)| m)
            .map(|(&c, _)| lum(c))
            .sum::<f64>()
            / n.max(1) as f64;
        println!("{image}, {all:.6}, {face:.6}");
    }
    Ok(())
}
