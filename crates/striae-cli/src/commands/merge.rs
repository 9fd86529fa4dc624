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
    let parts = args
        .parts
        .iter()
        .map(|path| Ok((path.clone(), Part::read(path)?)))
        .collect::<Result<Vec<_>, striae::render::parts::PartError>>()?;
    let (image, exposure) = merge(&parts)?;
    let (exr, png) = super::render::image_outputs(Some(&args.output), None)?;
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
