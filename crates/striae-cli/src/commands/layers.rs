//! `striae layers`: scratch layers from Worley cell noise (METHOD.md section 5) written as
//! images: `layer-K.png` (anti-aliased coverage, white = scratch), `layers.png` (all layers
//! tinted by direction), `layers.json` (parameters, per-layer angle, direction and measured
//! coverage) and, with `--stages`, the three stages of the seed's Fig. 4 for layer 0.
//!
//! Pixel mapping: texel `(x, y)` (column, row; row 0 at the top) of an `R x R` image covers
//! `u in [x/R, (x+1)/R]`, `v in [1 - (y+1)/R, 1 - y/R]`: `u` to the right, `v` up.
//!
//! Everything is validated and computed in memory first; files are then written atomically,
//! and if one fails the ones already written (and a folder this run created) are removed.

use anyhow::{bail, Context, Result};
use std::path::{Path, PathBuf};
use striae::layers::raster::{self, CombinedImage};
use striae::layers::{LayerParams, LayerSet, Orientation};

#[derive(clap::Args)]
pub struct Args {
    /// The seed's scratch setting (Table 1): 1 = (L 0.3, W 0.001, tau 0.1), 2 = (L 0.6, W 0.010, tau 0.1).
    /// The default when neither a setting nor --length/--width/--threshold is given is 1.
    #[arg(long, conflicts_with_all = ["length", "width", "threshold"])]
    setting: Option<u32>,
    /// Scratch length scale L (texture units; scratches are 2 tau L long).
    #[arg(long, requires_all = ["width", "threshold"], allow_hyphen_values = true)]
    length: Option<f64>,
    /// Scratch width scale W (scratches are 2 tau W wide).
    #[arg(long, requires_all = ["length", "threshold"], allow_hyphen_values = true)]
    width: Option<f64>,
    /// Threshold tau on the cell noise's F1, in (0, 1]; coverage is about pi tau^2.
    #[arg(long, requires_all = ["length", "width"], allow_hyphen_values = true)]
    threshold: Option<f64>,
    /// Number of layers K.
    #[arg(long, default_value_t = LayerParams::DEFAULT_LAYERS, allow_hyphen_values = true)]
    layers: usize,
    /// Image side R in pixels.
    #[arg(long, default_value_t = 1024)]
    res: usize,
    /// `layer` (the seed: every scratch of a layer along the layer's direction) or `random`
    /// (each scratch along its own direction).
    #[arg(long, value_enum, default_value_t = OrientationArg::Layer)]
    orientation: OrientationArg,
    /// Seed of the layer set (angles and noise of every layer).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Also write the three stages of the seed's Fig. 4 for layer 0.
    #[arg(long)]
    stages: bool,
    /// Output folder (created if missing).
    #[arg(short = 'o', long = "out")]
    out: PathBuf,
    /// Refuse the job if its estimated memory exceeds this (bytes, or with K, M, G, T); what
    /// the machine leaves (MemAvailable, ulimit -v and -d, the cgroup's limit) always is one.
    #[arg(long, value_parser = striae::memory::parse_size)]
    max_memory: Option<u64>,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum OrientationArg {
    Layer,
    Random,
}

pub fn run(args: Args) -> Result<()> {
    let mut params = match (args.setting, args.length, args.width, args.threshold) {
        (Some(n), ..) => LayerParams::setting(n)?,
        (None, Some(length), Some(width), Some(threshold)) => LayerParams {
            length,
            width,
            threshold,
            layers: LayerParams::DEFAULT_LAYERS,
        },
        (None, None, None, None) => LayerParams::setting(1)?,
        _ => bail!("give either --setting or all of --length, --width and --threshold"),
    };
    params.layers = args.layers;
    let orientation = match args.orientation {
        OrientationArg::Layer => Orientation::Layer,
        OrientationArg::Random => Orientation::Random,
    };
    let set = LayerSet::with_orientation(params, args.seed, orientation)
        .context("invalid scratch layer parameters")?;
    let res = args.res;
    raster::check_resolution(res).context("invalid --res")?;
    let size = format!("--res {res}");
    let need = raster::images_bytes(res, set.len(), args.stages);
    striae::memory::check(&size, need, args.max_memory)?;
    if args.out.exists() && !args.out.is_dir() {
        bail!("output {} exists and is not a folder", args.out.display());
    }

    let mut files: Vec<(String, Vec<u8>)> = Vec::new();
    let mut combined = CombinedImage::new(res).context(size.clone())?;
    let mut entries = Vec::new();
    for (k, layer) in set.layers().iter().enumerate() {
        let r = set.rasterize(k, res).context(size.clone())?;
        let name = format!("layer-{k}.png");
        let png = r.to_png()?;
        if args.stages && k == 0 {
            files.push(("stage-c-threshold.png".into(), png.clone()));
        }
        files.push((name.clone(), png));
        combined.add(&r, layer.angle());
        let coverage = r.mean();
        entries.push(serde_json::json!({
            "index": k,
            "file": name,
            "angle_rad": layer.angle(),
            "direction": layer.direction(),
            "coverage": coverage,
        }));
        println!(
            "layer {k}: angle {:7.2} deg, direction ({:+.4}, {:+.4}), coverage {:.4}",
            layer.angle().to_degrees(),
            layer.direction()[0],
            layer.direction()[1],
            coverage
        );
    }
    files.push(("layers.png".into(), combined.to_png()?));
    if args.stages {
        let layer0 = &set.layers()[0];
        let a = raster::stage_noise(layer0, res).context(size.clone())?;
        files.push((
            "stage-a-noise.png".into(),
            raster::encode_png(res, &raster::to_u8(&a), 1, "stage a")?,
        ));
        let b = raster::stage_stretched(layer0, res).context(size.clone())?;
        files.push((
            "stage-b-stretched.png".into(),
            raster::encode_png(res, &raster::to_u8(&b), 1, "stage b")?,
        ));
    }
    let p = set.params();
    let json = serde_json::json!({
        "striae_version": striae::VERSION,
        "method": "METHOD.md section 5: q = S^-1 R(-alpha) (p - c), S = diag(L, W), c = (1/2, 1/2); scratch where F1(q) < tau",
        "seed": args.seed,
        "setting": args.setting,
        "params": { "length": p.length, "width": p.width, "threshold": p.threshold, "layers": p.layers },
        "resolution": res,
        "pixel_mapping": "texel (x, y), row 0 at the top, covers u in [x/R, (x+1)/R], v in [1-(y+1)/R, 1-y/R]; u right, v up; angles counter-clockwise from +u",
        "pixel_value": "coverage fraction of the texel, 0 = black, 1 = white (linear, 8 bit)",
        "expected_coverage": set.expected_coverage(),
        "pi_tau_squared": std::f64::consts::PI * p.threshold * p.threshold,
        "layers": entries,
    });
    files.push(("layers.json".into(), serde_json::to_vec_pretty(&json)?));
    write_all(&args.out, &files)?;
    println!("wrote {} files to {}", files.len(), args.out.display());
    Ok(())
}

/// Write every file, all or none ([`striae::io::write_all_atomically`]: a failure leaves the
/// folder's old files as they were), and remove the folder again if this call created it.
fn write_all(dir: &Path, files: &[(String, Vec<u8>)]) -> Result<()> {
    let created = !dir.exists();
    std::fs::create_dir_all(dir).with_context(|| format!("could not create {}", dir.display()))?;
    let paths: Vec<PathBuf> = files.iter().map(|(name, _)| dir.join(name)).collect();
    let outputs = paths
        .iter()
        .zip(files)
        .map(
            |(path, (_, bytes))| -> striae::io::Output<'_, std::io::Error> {
                let write = move |tmp: &Path| {
                    std::fs::write(tmp, bytes).map_err(|e| {
                        std::io::Error::new(e.kind(), format!("{}: {e}", path.display()))
                    })
                };
                (path, Box::new(write))
            },
        )
        .collect();
    if let Err(e) = striae::io::write_all_atomically(outputs) {
        if created {
            let _ = std::fs::remove_dir(dir);
        }
        return Err(e).with_context(|| format!("could not write the files to {}", dir.display()));
    }
    Ok(())
}
