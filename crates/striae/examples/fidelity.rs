//! The SV-BRDF against explicit grooves (METHOD.md 8.3, `docs/fidelity.md`): renders each scene
//! both ways, the scene file as written (`scratches.explicit = false`) and with the flag turned
//! on (nothing else differs), each with two seeds, and prints a Markdown table row per scene:
//! the image means, the 16 x 16 block differences against the noise, and writes the two
//! images and their difference side by side as a PNG.
//!
//! ```sh
//! cargo run --release -p striae --example fidelity -- OUT_DIR EXPLICIT_SPP_FACTOR SCENE.toml...
//! ```
//!
//! The explicit render takes `EXPLICIT_SPP_FACTOR` times the scene's samples per pixel (it has
//! to resolve the grooves inside each pixel that the SV-BRDF filters analytically). The noise
//! of a block mean is estimated from the two seeds' difference, pooled over the blocks.

use std::error::Error;
use std::path::{Path, PathBuf};
use striae::render::film::Image;
use striae::render::scene::{Overrides, Scene};

const BLOCK: u32 = 16;

fn render(text: &str, file: &Path, spp: Option<u32>, seed: u64) -> Result<Image, Box<dyn Error>> {
    let base = file.parent().unwrap_or(Path::new("."));
    let o = Overrides {
        spp,
        seed: Some(seed),
        ..Overrides::default()
    };
    let scene = Scene::parse(text, file, base, &o)?;
    let start = std::time::Instant::now();
    let (image, _) = striae::render::integrator::render(&scene, &|_| {});
    eprintln!(
        "  {} spp, seed {seed}: {:.1} s",
        scene.settings.spp,
        start.elapsed().as_secs_f64()
    );
    Ok(image)
}

/// [`striae::math::luminance`] as `f64`, for sums over an image.
fn luminance(c: striae::math::Rgb) -> f64 {
    striae::math::luminance(c) as f64
}

/// Block means of the luminance, row by row.
fn blocks(img: &Image) -> Vec<f64> {
    let (bw, bh) = (img.width / BLOCK, img.height / BLOCK);
    let mut out = Vec::new();
    for by in 0..bh {
        for bx in 0..bw {
            let mut s = 0.0;
            for y in by * BLOCK..(by + 1) * BLOCK {
                for x in bx * BLOCK..(bx + 1) * BLOCK {
                    s += luminance(img.get(x, y));
                }
            }
            out.push(s / (BLOCK * BLOCK) as f64);
        }
    }
    out
}

/// Two renders (seeds 0 and 1) averaged, their block means and the pooled variance of a block
/// mean of the average.
fn both_seeds(
    text: &str,
    file: &Path,
    spp: Option<u32>,
) -> Result<(Image, Vec<f64>, f64), Box<dyn Error>> {
    let (a, b) = (render(text, file, spp, 0)?, render(text, file, spp, 1)?);
    let (ba, bb) = (blocks(&a), blocks(&b));
    let var = ba
        .iter()
        .zip(&bb)
        .map(|(x, y)| (x - y).powi(2) / 4.0)
        .sum::<f64>()
        / ba.len() as f64;
    let mut avg = Image::new(a.width, a.height);
    for (p, (x, y)) in avg.pixels.iter_mut().zip(a.pixels.iter().zip(&b.pixels)) {
        *p = 0.5 * (*x + *y);
    }
    let blocks = ba.iter().zip(&bb).map(|(x, y)| 0.5 * (x + y)).collect();
    Ok((avg, blocks, var))
}

/// `model | explicit | |difference| x 4`, sRGB at `exposure`.
fn side_by_side(m: &Image, e: &Image, exposure: f32, path: &Path) -> Result<(), Box<dyn Error>> {
    let (w, h) = (m.width, m.height);
    let mut diff = Image::new(w, h);
    for (p, (a, b)) in diff.pixels.iter_mut().zip(m.pixels.iter().zip(&e.pixels)) {
        *p = 4.0 * (*a - *b).abs();
    }
    let mut out = image::RgbImage::new(3 * w + 8, h);
    for (k, img) in [m, e, &diff].into_iter().enumerate() {
        let px = img.to_srgb8(exposure);
        for y in 0..h {
            for x in 0..w {
                let i = 3 * (y * w + x) as usize;
                let p = image::Rgb([px[i], px[i + 1], px[i + 2]]);
                out.put_pixel(k as u32 * (w + 4) + x, y, p);
            }
        }
    }
    out.save(path)?;
    Ok(())
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 3 {
        return Err("usage: fidelity OUT_DIR EXPLICIT_SPP_FACTOR SCENE.toml...".into());
    }
    let out = PathBuf::from(&args[0]);
    let factor: u32 = args[1].parse()?;
    std::fs::create_dir_all(&out)?;
    println!("| scene | mean SV-BRDF | mean explicit | ratio | block RMS diff | block noise | blocks beyond 3 sigma |");
    println!("|---|---|---|---|---|---|---|");
    for file in &args[2..] {
        let file = Path::new(file);
        let text = std::fs::read_to_string(file)?;
        if !text.contains("explicit = false") {
            return Err(format!("{}: no `explicit = false` to turn on", file.display()).into());
        }
        let name = file.file_stem().unwrap().to_string_lossy().to_string();
        eprintln!("{name}: SV-BRDF");
        let (m, bm, vm) = both_seeds(&text, file, None)?;
        let explicit = text.replace("explicit = false", "explicit = true");
        let spp = Scene::parse(&text, file, Path::new("."), &Overrides::default())?
            .settings
            .spp;
        eprintln!("{name}: explicit");
        let (e, be, ve) = both_seeds(&explicit, file, Some(spp * factor))?;
        let sigma = (vm + ve).sqrt();
        let d: Vec<f64> = be.iter().zip(&bm).map(|(e, m)| e - m).collect();
        let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
        let beyond = d.iter().filter(|x| x.abs() > 3.0 * sigma).count();
        let (mm, me) = (luminance(m.mean()), luminance(e.mean()));
        println!(
            "| {name} | {mm:.4} | {me:.4} | {:.3} | {rms:.4} | {sigma:.4} | {beyond} of {} |",
            me / mm,
            d.len()
        );
        side_by_side(&m, &e, 0.0, &out.join(format!("{name}.png")))?;
    }
    Ok(())
}
