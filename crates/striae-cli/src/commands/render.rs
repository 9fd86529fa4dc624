//! `striae render [SCENE.toml|SCENE.gltf|SCENE.glb]`: render a scene file (a glTF 2.0 file on
//! its own, chosen by its extension: `docs/scenes.md`, "glTF"), or the built-in default scene
//! (the glass teapot with the seed's setting-1 scratches,
//! `scenes/glass-teapot-setting1.toml`), to a
//! linear EXR and an sRGB PNG preview, with a progress bar (samples/s, time left) and a
//! summary (wall time, samples/s, rays/s).

use anyhow::{bail, Context};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use striae::memory::parse_size;
use striae::render::sampler::SamplerKind;
use striae::render::scene::{Overrides, Scene};

#[derive(clap::Args)]
pub struct Args {
    /// Scene file: TOML (docs/scenes.md), or glTF 2.0 (`.gltf`, `.glb`: its camera, meshes,
    /// materials and lights, black background, the default render settings). Without it the
    /// built-in default scene renders.
    pub scene: Option<PathBuf>,
    /// Samples per pixel (overrides `render.spp`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=striae::render::sampler::MAX_SPP as i64))]
    pub spp: Option<u32>,
    /// Image size as WIDTHxHEIGHT, e.g. 512x384 (overrides `render.width`, `render.height`).
    #[arg(long, value_parser = parse_resolution)]
    pub res: Option<(u32, u32)>,
    /// Random seed (overrides `render.seed`); the image is identical for any thread count.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Worker threads (default: all cores).
    #[arg(long, value_parser = parse_threads)]
    pub threads: Option<usize>,
    /// Longest path in segments, Mitsuba's convention; 0 = unlimited (overrides `render.max_depth`).
    #[arg(long)]
    pub max_depth: Option<u32>,
    /// Random numbers: `sobol` (Owen-scrambled Sobol points) or `independent` (overrides
    /// `render.sampler`).
    #[arg(long, value_parser = parse_sampler)]
    pub sampler: Option<SamplerKind>,
    /// The lane render loop (`--lanes`, `--lanes=true`: many paths in flight at once, stage by
    /// stage) or the one-path loop (`--lanes=false`; overrides `render.lanes`). The value takes
    /// `=`, so that `--lanes SCENE` still reads the scene.
    #[arg(
        long,
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "true",
        value_name = "BOOL"
    )]
    pub lanes: Option<bool>,
    /// PNG preview exposure in stops, within +-126 (overrides `render.exposure`).
    #[arg(long, allow_hyphen_values = true, value_parser = parse_exposure)]
    pub exposure: Option<f32>,
    /// Output path: `NAME.exr`, `NAME.png` or `NAME`; both NAME.exr and NAME.png are written.
    /// Default: `striae` for the built-in scene, the scene file's name otherwise.
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// Instead of rendering, write every mesh shape of the scene (teapot, rectangle, box, OBJ;
    /// in world space, transforms applied) to DIR/shape-<index>.obj, e.g. to describe the
    /// same geometry to Mitsuba 3. Spheres are analytic and are skipped.
    #[arg(long, value_name = "DIR")]
    pub export_meshes: Option<PathBuf>,
    /// Render only part I of N of the image (its tiles `t` with `t % N == I`, counting from
    /// 0) and write it as a part file (`-o`, default `NAME-I-of-N.part`) for `striae merge`.
    #[arg(long, value_name = "I/N", value_parser = parse_tile)]
    pub tile: Option<(u32, u32)>,
    /// Render only the samples A to B-1 (counting from 0, B at most the spp) of every pixel (of
    /// the `--tile` part's, with `--tile`) and write their sums as a part file (`-o`, default
    /// `NAME-samples-A-B.part` or `NAME-I-of-N-samples-A-B.part`) for `striae merge`; the merge
    /// is the whole render within Monte Carlo noise, not bit for bit (docs/distributed.md).
    #[arg(long, value_name = "A..B", value_parser = parse_samples)]
    pub samples: Option<[u32; 2]>,
    /// Refuse the job if its estimated memory exceeds this (bytes, or with K, M, G, T); what
    /// the machine leaves (MemAvailable, ulimit -v and -d, the cgroup's limit) always is one.
    #[arg(long, value_parser = parse_size)]
    pub max_memory: Option<u64>,
    /// A live view while it renders: `tev` or `tev:HOST:PORT` sends each finished tile, then
    /// the final image, to a running tev viewer (default 127.0.0.1:14158); `every=SECONDS`
    /// rewrites the PNG and EXR (atomically) with the tiles done so far. The image is the same
    /// bit for bit; a tev that is absent, closes or hangs costs a warning, never the render.
    #[arg(long, value_name = "tev[:HOST:PORT]|every=SECONDS", value_parser = crate::preview::parse_preview, conflicts_with_all = ["tile", "samples", "export_meshes"])]
    pub preview: Option<crate::preview::PreviewSpec>,
    /// No progress bar.
    #[arg(long, short = 'q')]
    pub quiet: bool,
}

/// `--tile I/N`: two counts; the range is checked against the image (`parts::part_tiles`).
fn parse_tile(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("`{s}` is not I/N (part I of N, counting from 0, e.g. 0/4)");
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let i: u32 = i.trim().parse().map_err(|_| bad())?;
    let n: u32 = n.trim().parse().map_err(|_| bad())?;
    if i >= n {
        return Err(format!(
            "`{s}`: the part index I must lie in 0..N (0 to N-1)"
        ));
    }
    Ok((i, n))
}

/// `--samples A..B`: two sample indices, `A < B`; `B` is checked against the spp
/// (`parts::check_samples`).
fn parse_samples(s: &str) -> Result<[u32; 2], String> {
    let range = striae::render::parts::parse_samples(s)?;
    if range[0] >= range[1] {
        return Err(format!("`{s}`: A must be less than B (A..B excludes B)"));
    }
    Ok(range)
}

/// Most worker threads a command accepts: more than any machine's cores, and few enough that a
/// typo (`--threads 1000000`) is an error instead of minutes spent starting threads.
const MAX_THREADS: usize = 4096;

/// `--threads`: a count from 1 to [`MAX_THREADS`].
pub(crate) fn parse_threads(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if (1..=MAX_THREADS).contains(&n) => Ok(n),
        _ => Err(format!("`{s}` is not a thread count (1 to {MAX_THREADS})")),
    }
}

/// `--exposure`: stops within [`striae::render::film::MAX_EXPOSURE`] either way; the error
/// quotes the value as written (`1e39` is not reported as `inf`).
fn parse_exposure(s: &str) -> Result<f32, String> {
    let max = striae::render::film::MAX_EXPOSURE;
    // The range checked in f64, the value read as f32 directly (no double rounding).
    match (s.parse::<f64>(), s.parse::<f32>()) {
        (Ok(wide), Ok(e)) if wide.abs() <= max as f64 => Ok(e),
        _ => Err(format!("`{s}` is not an exposure in stops within +-{max}")),
    }
}

fn parse_sampler(s: &str) -> Result<SamplerKind, String> {
    SamplerKind::from_name(s)
        .ok_or_else(|| format!("`{s}` is not {}", SamplerKind::allowed_names()))
}

pub(crate) fn parse_resolution(s: &str) -> Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("`{s}` is not WIDTHxHEIGHT (e.g. 512x384)"))?;
    let w: u32 = w
        .trim()
        .parse()
        .map_err(|_| format!("bad width in `{s}`"))?;
    let h: u32 = h
        .trim()
        .parse()
        .map_err(|_| format!("bad height in `{s}`"))?;
    if w == 0 || h == 0 {
        return Err(format!("`{s}`: width and height must be at least 1"));
    }
    Ok((w, h))
}

/// `NAME.exr` and `NAME.png` from `-o` or the default. Another extension (`.jpg`) is an
/// error, not a PNG written under a JPEG's name.
fn output_paths(output: Option<&Path>, scene: Option<&Path>) -> anyhow::Result<(PathBuf, PathBuf)> {
    let stem = match output {
        Some(o) => match o.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("exr") || e.eq_ignore_ascii_case("png") => {
                o.with_extension("")
            }
            Some(e) => bail!(
                "-o {}: striae writes OpenEXR and PNG only; give NAME.exr, NAME.png or NAME (both are written), not .{e}",
                o.display()
            ),
            None => o.to_path_buf(),
        },
        None => match scene.and_then(|s| s.file_stem()) {
            Some(s) => PathBuf::from(s),
            None => PathBuf::from("striae"),
        },
    };
    let mut exr = stem.clone().into_os_string();
    exr.push(".exr");
    let mut png = stem.into_os_string();
    png.push(".png");
    let (exr, png) = (PathBuf::from(exr), PathBuf::from(png));
    if let Some(input) =
        scene.filter(|s| striae::io::same_file(s, &exr) || striae::io::same_file(s, &png))
    {
        bail!("-o would overwrite the scene file {}", input.display());
    }
    Ok((exr, png))
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let overrides = Overrides {
        spp: args.spp,
        resolution: args.res,
        seed: args.seed,
        max_depth: args.max_depth,
        sampler: args.sampler,
        lanes: args.lanes,
    };
    striae::render::integrator::LoopCopy::env_cap().map_err(anyhow::Error::msg)?;
    super::print_library_messages(args.quiet);
    let (mut scene, scene_text) = match &args.scene {
        Some(path) => Scene::load_with_text(path, &overrides).context("cannot load the scene")?,
        None => (
            Scene::default_scene(&overrides).context("building the built-in default scene")?,
            striae::render::scene::DEFAULT_SCENE.to_string(),
        ),
    };
    if let Some(e) = args.exposure {
        scene.settings.exposure = e;
    }
    if let Some(dir) = &args.export_meshes {
        return export_meshes(&scene, dir);
    }
    let s = &scene.settings;
    if let Some(range) = args.samples {
        striae::render::parts::check_samples(range, s.spp).context("--samples")?;
    }
    let tile = args.tile.or(args.samples.map(|_| (0, 1)));
    let pixels = match tile {
        Some((i, n)) => striae::render::parts::part_pixel_count((s.width, s.height), i, n)? as u64,
        None => s.width as u64 * s.height as u64,
    };
    let size = match args.res {
        Some(_) => format!("--res {}x{}", s.width, s.height),
        None => format!(
            "--res (the scene's render.width x render.height, {}x{})",
            s.width, s.height
        ),
    };
    // A preview holds a second copy of the film: half as much again.
    let counted = match args.preview {
        Some(_) => pixels + pixels / 2,
        None => pixels,
    };
    striae::render::integrator::check_memory(&scene, counted, &size, args.max_memory)?;
    let total = pixels * args.samples.map_or(s.spp, |[a, b]| b - a) as u64;
    let threads = args.threads.unwrap_or_else(rayon::current_num_threads);
    eprintln!(
        "rendering {} at {}x{}, {} spp{}, max depth {}, seed {}, {} thread(s)",
        args.scene
            .as_ref()
            .map(|p| p.display().to_string())
            .unwrap_or_else(|| "the built-in scratched glass teapot (setting 1)".into()),
        s.width,
        s.height,
        s.spp,
        args.samples
            .map(|[a, b]| format!(" (samples {a}..{b})"))
            .unwrap_or_default(),
        s.max_depth,
        s.seed,
        threads
    );
    let bar = progress_bar(total, args.quiet);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .context("starting the thread pool")?;
    if let Some(tile) = tile {
        let path = part_path(&args, tile);
        let cancel = std::sync::atomic::AtomicBool::new(false);
        let (part, stats) = pool.install(|| {
            let progress = |n| bar.inc(n);
            striae::render::parts::Part::render(
                &scene,
                &scene_text,
                tile,
                args.samples,
                &progress,
                &cancel,
            )
        })?;
        bar.finish_and_clear();
        part.write(&path)?;
        print_summary(&stats);
        eprintln!("wrote {}", path.display());
        return Ok(());
    }
    let (exr_path, png_path) = image_outputs(args.output.as_deref(), args.scene.as_deref())?;
    let preview = match args.preview.clone() {
        Some(spec) => {
            let warn_bar = bar.clone();
            Some(crate::preview::Preview::start(
                spec,
                (s.width, s.height),
                exr_path.display().to_string(),
                (exr_path.clone(), png_path.clone()),
                s.exposure,
                std::sync::Arc::new(move |m: String| warn_bar.suspend(|| eprintln!("{m}"))),
            )?)
        }
        None => None,
    };
    let on_tile = |tile: u32, px: &[striae::math::Rgb]| {
        if let Some(p) = &preview {
            p.on_tile(tile, px)
        }
    };
    let (image, stats) = pool.install(|| {
        striae::render::integrator::try_render_observed(&scene, &|n| bar.inc(n), &on_tile, &size)
    })?;
    bar.finish_and_clear();
    let image = std::sync::Arc::new(image);
    // An `every=` preview stops before the final outputs are written, a tev preview after.
    let preview = match preview {
        Some(p) if matches!(args.preview, Some(crate::preview::PreviewSpec::Every(_))) => {
            p.finish(image.clone());
            None
        }
        p => p,
    };

    image
        .write_exr_and_png(&exr_path, &png_path, scene.settings.exposure)
        .with_context(|| format!("writing {} and {}", exr_path.display(), png_path.display()))?;
    if let Some(p) = preview {
        p.finish(image);
    }
    print_summary(&stats);
    eprintln!("wrote {} and {}", exr_path.display(), png_path.display());
    Ok(())
}

/// The EXR and PNG paths of `-o` ([`output_paths`]), each checked as a destination before
/// anything is rendered.
pub(crate) fn image_outputs(
    output: Option<&Path>,
    scene: Option<&Path>,
) -> anyhow::Result<(PathBuf, PathBuf)> {
    let (exr, png) = output_paths(output, scene)?;
    for path in [&exr, &png] {
        striae::io::check_destination(path).with_context(|| format!("-o {}", path.display()))?;
    }
    Ok((exr, png))
}

/// `-o` for a part file, or after the scene file's name (`striae` for the built-in scene)
/// `NAME-I-of-N.part`, `NAME-samples-A-B.part` or `NAME-I-of-N-samples-A-B.part`.
fn part_path(args: &Args, (i, n): (u32, u32)) -> PathBuf {
    args.output.clone().unwrap_or_else(|| {
        let stem = args
            .scene
            .as_deref()
            .and_then(|s| s.file_stem())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "striae".into());
        let tile = args
            .tile
            .map(|_| format!("-{i}-of-{n}"))
            .unwrap_or_default();
        let samples = args
            .samples
            .map(|[a, b]| format!("-samples-{a}-{b}"))
            .unwrap_or_default();
        PathBuf::from(format!("{stem}{tile}{samples}.part"))
    })
}

/// A progress bar over `total` camera samples (samples/s, time left); hidden when `quiet`.
fn progress_bar(total: u64, quiet: bool) -> ProgressBar {
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        ProgressBar::new(total)
    };
    bar.set_style(
        ProgressStyle::with_template(
            "{bar:40.cyan/blue} {percent:>3}%  {human_pos}/{human_len} samples  {rate}  elapsed {elapsed}  left {eta}",
        )
        .expect("valid template")
        .with_key("rate", |state: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
            let _ = write!(w, "{:.3} M samples/s", state.per_sec() / 1e6);
        })
        .progress_chars("=> "),
    );
    bar
}

/// The render's summary line: wall time, samples/s, rays/s.
fn print_summary(stats: &striae::render::integrator::RenderStats) {
    eprintln!(
        "done in {:.2} s: {:.3} M samples/s, {:.2} M rays/s ({} rays, {} render loop){}",
        stats.seconds,
        stats.samples_per_second() / 1e6,
        stats.rays_per_second() / 1e6,
        stats.rays,
        stats.copy.name(),
        if stats.nonfinite > 0 {
            format!(", {} non-finite samples dropped", stats.nonfinite)
        } else {
            String::new()
        }
    );
}

fn export_meshes(scene: &Scene, dir: &Path) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (i, shape) in scene.geometry.shapes().iter().enumerate() {
        match &shape.geometry {
            striae::render::geometry::ShapeGeometry::Mesh(mesh) => {
                let path = dir.join(format!("shape-{i}.obj"));
                mesh.write_obj(&path)
                    .with_context(|| format!("writing {}", path.display()))?;
                eprintln!(
                    "wrote {} ({} triangles)",
                    path.display(),
                    mesh.triangle_count()
                );
            }
            striae::render::geometry::ShapeGeometry::Sphere { centre, radius } => {
                eprintln!(
                    "shape {i}: analytic sphere, centre {centre}, radius {radius} (not exported)"
                );
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resolution_and_outputs() {
        assert_eq!(parse_resolution("512x384"), Ok((512, 384)));
        assert!(parse_resolution("512").is_err());
        assert!(parse_resolution("0x4").is_err());
        assert_eq!(
            output_paths(None, None).unwrap(),
            (PathBuf::from("striae.exr"), PathBuf::from("striae.png"))
        );
        assert_eq!(
            output_paths(Some(Path::new("out/a.png")), None).unwrap().0,
            PathBuf::from("out/a.exr")
        );
        assert_eq!(
            output_paths(None, Some(Path::new("scenes/glass-plate.toml")))
                .unwrap()
                .1,
            PathBuf::from("glass-plate.png")
        );
        let e = output_paths(Some(Path::new("a.jpg")), None).unwrap_err();
        assert!(e.to_string().contains("not .jpg"), "{e}");
    }
}
