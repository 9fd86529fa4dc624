//! `striae merge PART... -o NAME`: the image of the part files of one render (`striae render
//! --tile I/N`, `--samples A..B`), as NAME.exr and NAME.png: identical bit for bit to the render
//! made at once where every part holds all its samples, within Monte Carlo noise where samples
//! are split (`striae::render::parts`).

use anyhow::Context;
use std::path::PathBuf;
use striae::render::parts::{merge, Part};

#[derive(clap::Args)]
pub struct Args {
    /// The part files, every part of one render once, in any order. Parts of sample ranges
    /// (`render --samples A..B`) must cover 0..spp without overlap, per tile part; their merge
    /// adds the ranges' sums in f64 and is not the one-machine render bit for bit: it differs
    /// by f32 rounding, and in the few pixels whose scratch-coverage footprint a range takes
    /// from its own first sample, by less than the noise (docs/distributed.md).
    #[arg(required = true)]
    pub parts: Vec<PathBuf>,
    /// Output path: `NAME.exr`, `NAME.png` or `NAME`; both NAME.exr and NAME.png are written.
    #[arg(short = 'o', long)]
    pub output: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let (exr, png) = super::render::image_outputs(Some(&args.output), None)?;
    if let Some(input) = args
        .parts
        .iter()
        .find(|p| striae::io::same_file(p, &exr) || striae::io::same_file(p, &png))
    {
        anyhow::bail!(
            "-o {}: would overwrite the part file {}",
            args.output.display(),
            input.display()
        );
    }
    // Every part is held while merging: the files' sizes, and the largest once more while it
    // is read.
    let sizes: Vec<u64> = args
        .parts
        .iter()
        .map(|p| std::fs::metadata(p).map_or(0, |m| m.len()))
        .collect();
    let reading = sizes.iter().copied().max().unwrap_or(0);
    striae::memory::check(
        "reading the part files",
        sizes.iter().sum::<u64>().saturating_add(reading),
        None,
    )?;
    let parts = args
        .parts
        .iter()
        .map(|path| Ok((path.clone(), Part::read(path)?)))
        .collect::<Result<Vec<_>, striae::render::parts::PartError>>()?;
    let (w, h) = parts.first().map_or((0, 0), |(_, p)| {
        (p.header.render.width, p.header.render.height)
    });
    striae::memory::check(
        &format!("merging {} parts into a {w}x{h} image", parts.len()),
        striae::render::parts::merge_memory_estimate(&parts),
        None,
    )?;
    let (image, exposure) = merge(&parts)?;
    image
        .write_exr_and_png(&exr, &png, exposure)
        .with_context(|| format!("writing {} and {}", exr.display(), png.display()))?;
    eprintln!(
        "merged {} parts into {} and {}",
        parts.len(),
        exr.display(),
        png.display()
    );
    Ok(())
}
