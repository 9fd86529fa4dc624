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
use striae::math::{Rgb, Vec2};
use striae::render::scene::{Overrides, Scene};

fn luminance(c: Rgb) -> f64 {
    (0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z) as f64
}

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

fn read_exr(path: &Path, w: usize, h: usize) -> Result<Vec<Rgb>, Box<dyn Error>> {
    let image = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![Rgb::ZERO; res.width() * res.height()]),
        |(width, px): &mut (usize, Vec<Rgb>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *width + pos.x()] = Rgb::new(r, g, b)
        },
    )
    .map_err(|e| format!("{}: {e}", path.display()))?;
    let (width, pixels) = image.layer_data.channel_data.pixels;
    if width != w || pixels.len() != w * h {
        return Err(format!("{}: not the scene's {w} x {h} pixels", path.display()).into());
    }
    Ok(pixels)
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
        let pixels = read_exr(Path::new(image), w, h)?;
        let all = pixels.iter().map(|&c| luminance(c)).sum::<f64>() / pixels.len() as f64;
        let face = pixels
            .iter()
            .zip(&mask)
            .filter(|(_, &m)| m)
            .map(|(&c, _)| luminance(c))
            .sum::<f64>()
            / n.max(1) as f64;
        println!("{image}, {all:.6}, {face:.6}");
    }
    Ok(())
}
