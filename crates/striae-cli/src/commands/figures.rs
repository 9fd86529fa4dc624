//! `striae figures -o DIR [--spp N] [--res WxH]`: regenerate the seed's figures (Fig. 2, 4 a-c,
//! 6 a-b, 7 a-b, 8 a) as PNGs plus an `index.html` showing them side by side with their
//! parameters and render times (`striae::lab::figures`).

use anyhow::Context;
use std::path::PathBuf;
use std::time::Instant;
use striae::lab::figures::{generate, FigureOptions};

#[derive(clap::Args)]
pub struct Args {
    /// Output folder (created if missing).
    #[arg(short = 'o', long = "out")]
    pub out: PathBuf,
    /// Samples per pixel of the renders (Figs. 6-8).
    #[arg(long, default_value_t = FigureOptions::default().spp,
          value_parser = clap::value_parser!(u32).range(1..=striae::render::sampler::MAX_SPP as i64))]
    pub spp: u32,
    /// Render size as WIDTHxHEIGHT.
    #[arg(long, value_parser = super::render::parse_resolution, default_value = "384x288")]
    pub res: (u32, u32),
    /// Side of the Fig. 4 layer images in pixels.
    #[arg(long, default_value_t = FigureOptions::default().layer_resolution)]
    pub layer_res: usize,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = super::render::parse_threads)]
    pub threads: Option<usize>,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    // The figures are rendered: a bad `STRIAE_SIMD` stops them as it stops `striae render`.
    striae::render::integrator::LoopCopy::env_cap().map_err(anyhow::Error::msg)?;
    striae::layers::raster::check_resolution(args.layer_res)
        .with_context(|| format!("invalid --layer-res {}", args.layer_res))?;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    let opts = FigureOptions {
        spp: args.spp,
        resolution: args.res,
        layer_resolution: args.layer_res,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("starting the thread pool")?;
    let start = Instant::now();
    let figures = pool
        .install(|| generate(&args.out, &opts, &|line| eprintln!("{line}")))
        .with_context(|| format!("generating the figures in {}", args.out.display()))?;
    eprintln!(
        "{} figures in {} ({:.1} s wall, {} thread(s)); open {}",
        figures.len(),
        args.out.display(),
        start.elapsed().as_secs_f64(),
        threads,
        args.out.join("index.html").display()
    );
    Ok(())
}
