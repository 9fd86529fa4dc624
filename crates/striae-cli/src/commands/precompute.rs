//! `striae precompute`: trace a scratch profile and write its BRDF table (METHOD.md 2-4).

use anyhow::Context;
use std::path::PathBuf;
use std::time::Instant;
use striae::optics::fresnel::FresnelLaw;
use striae::precompute::profile::Profile;
use striae::precompute::table::{ScratchTable, TableParams};
use striae::precompute::trace2d::{Estimator, FresnelMode, TraceSettings, Walls};

#[derive(clap::Args)]
pub struct Args {
    /// Profile: v:depth=D, v:angle=DEG, round:depth=D[,segments=K], trapezoid:depth=D,bottom=B,
    /// flat, file:PATH (see docs/table-format.md).
    #[arg(long, default_value = "v:angle=90")]
    profile: String,
    /// Wall micro-BRDF.
    #[arg(long, value_enum, default_value_t = WallsArg::Diffuse)]
    walls: WallsArg,
    /// Angle bins M [default: 256].
    #[arg(long)]
    m: Option<usize>,
    /// Entry points per incident angle N [default: 10000].
    #[arg(long)]
    n: Option<usize>,
    /// Walks per entry point N_r (diffuse walls) [default: 100].
    #[arg(long)]
    nr: Option<usize>,
    /// Index of refraction for schlick / dielectric.
    #[arg(long, default_value_t = 1.5)]
    ior: f64,
    /// Where Fresnel is applied [default: seed; walls with --groove-slices].
    #[arg(long, value_enum)]
    fresnel: Option<ModeArg>,
    /// Fresnel law: schlick, dielectric, conductor:ETA,K or none (F = 1) [default: schlick].
    #[arg(long)]
    fresnel_law: Option<String>,
    /// Facet albedo per bounce [default: 1].
    #[arg(long)]
    albedo: Option<f64>,
    /// Bounce cap [default: 64].
    #[arg(long)]
    max_bounces: Option<usize>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Diffuse-wall estimator. `walks`: the seed's N_r scheme (METHOD.md 3.1). `kernel`: a
    /// departure from the seed, same expectation, lower variance and much faster: the exit
    /// distribution from each wall position is tabulated once (256 nodes per wall, walks per
    /// node sized so that no row is noisier than with the N_r scheme) and every entry point
    /// adds the interpolated row of its first hit. Only for diffuse walls, --fresnel seed and
    /// convex profiles (see docs/table-format.md).
    #[arg(long, value_enum, default_value_t = EstimatorArg::Walks)]
    estimator: EstimatorArg,
    /// Also tabulate the exact groove (the 2.5D goniometer, N N_r paths per slice and phi_i)
    /// at this many theta_i slices, 1 to 32; the renderer then evaluates them instead of
    /// eq. (3) (diffuse walls, Fresnel at every wall hit; docs/table-format.md).
    #[arg(long)]
    groove_slices: Option<usize>,
    /// GGX roughness (alpha, in [0, 1]) of dielectric walls, or of specular walls (> 0: the
    /// rough conductor walls' table of METHOD.md 8.1, --fresnel-law at every wall hit).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    roughness: f64,
    /// Dielectric and rough specular walls: also trace N off-grid incident directions per
    /// side exactly and print the table's error against them.
    #[arg(long, default_value_t = 0)]
    check: usize,
    /// Wall tables (dielectric, rough specular): the incident grid, `theta_i` x `phi_i` bins, e.g. `16x32`
    /// [default: 16x32; smooth dielectric walls: 32x128].
    #[arg(long, value_parser = parse_grid)]
    incident: Option<(usize, usize)>,
    /// Wall tables: exit bins per angle, `theta_o` and `phi_o` (smooth dielectric walls:
    /// `phi_o` only, the exit `theta_o` is exact) [default: 32; smooth dielectric walls: 128].
    #[arg(long)]
    exit_bins: Option<usize>,
    /// Wall tables: paths per incident direction and side [default: 20000; smooth dielectric
    /// walls: 5000].
    #[arg(long)]
    wall_paths: Option<u64>,
    /// Worker threads, 1 to 4096 (default: all cores).
    #[arg(long, value_parser = super::render::parse_threads)]
    threads: Option<usize>,
    /// Output table (.npz).
    #[arg(short, long)]
    output: PathBuf,
    /// Refuse the job if its estimated memory exceeds this (bytes, or with K, M, G, T); the
    /// memory available is always a limit.
    #[arg(long, value_parser = striae::memory::parse_size)]
    max_memory: Option<u64>,
}

/// `TxP`: an incident grid of `T` `theta_i` and `P` `phi_i` bins.
fn parse_grid(text: &str) -> Result<(usize, usize), String> {
    let bad = || format!("`{text}`: expected THETAxPHI bin counts, e.g. 16x32");
    let (t, p) = text.split_once('x').ok_or_else(bad)?;
    Ok((
        t.trim().parse().map_err(|_| bad())?,
        p.trim().parse().map_err(|_| bad())?,
    ))
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum WallsArg {
    Specular,
    Diffuse,
    /// Glass walls of index --ior (optionally GGX-rough, --roughness): the four-lobe table of
    /// METHOD.md 8.1 from the exact 2.5D trace (docs/table-format.md).
    Dielectric,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum EstimatorArg {
    Walks,
    Kernel,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum ModeArg {
    Seed,
    Walls,
}

/// Parse `--fresnel-law` (the syntax is shared with the scene files' `fresnel_law`), `schlick`
/// where it is not given.
fn parse_law(s: Option<&str>, ior: f64) -> anyhow::Result<FresnelLaw> {
    FresnelLaw::parse(s.unwrap_or("schlick"), ior)
        .map_err(|e| anyhow::anyhow!("--fresnel-law: {e}"))
}

pub fn run(a: Args) -> anyhow::Result<()> {
    check_output(&a)?;
    let profile =
        Profile::parse(&a.profile).with_context(|| format!("--profile `{}`", a.profile))?;
    use striae::precompute::wall_table::WallTableParams;
    match a.walls {
        WallsArg::Dielectric => {
            refuse_2d_flags(&a, "dielectric-wall tables (exact Fresnel at --ior)", false)?;
            return wall_table(WallTableParams::new(profile, a.ior, a.roughness), &a);
        }
        WallsArg::Specular if a.roughness != 0.0 => {
            refuse_2d_flags(&a, "rough specular-wall tables", true)?;
            let law = parse_law(a.fresnel_law.as_deref(), a.ior)?;
            return wall_table(WallTableParams::specular(profile, law, a.roughness), &a);
        }
        WallsArg::Diffuse if a.roughness != 0.0 => anyhow::bail!(
            "--roughness {}: applies to dielectric and specular walls, not diffuse ones",
            a.roughness
        ),
        _ => {}
    }
    refuse_wall_flags(&a)?;
    let params = TableParams::new(profile, trace_settings(&a)?);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()?;
    let total = params.trace.total_paths() + params.trace.groove_paths();
    let bar = progress_bar(total);
    let start = Instant::now();
    let table = pool.install(|| ScratchTable::compute(&params, &|k| bar.inc(k)))?;
    let secs = start.elapsed().as_secs_f64();
    bar.finish_and_clear();
    table
        .save(&a.output)
        .with_context(|| format!("writing {}", a.output.display()))?;
    report(&params, &table, secs, pool.current_num_threads());
    println!(
        "wrote {} (params hash {})",
        a.output.display(),
        &params.hash()[..16]
    );
    Ok(())
}

/// `-o` is a file that may be written and not the profile file read.
fn check_output(a: &Args) -> anyhow::Result<()> {
    striae::io::check_destination(&a.output)
        .with_context(|| format!("-o {}", a.output.display()))?;
    if let Some(file) = a.profile.strip_prefix("file:") {
        if striae::io::same_file(std::path::Path::new(file), &a.output) {
            anyhow::bail!(
                "-o {} would overwrite the profile file it reads",
                a.output.display()
            );
        }
    }
    Ok(())
}

/// Refuse the 2D table's options that a wall table (`what`) does not read, naming the first
/// one given; `--fresnel-law` is read by rough specular walls (`law_read`).
fn refuse_2d_flags(a: &Args, what: &str, law_read: bool) -> anyhow::Result<()> {
    let ignored = [
        ("--m", a.m.is_some()),
        ("--n", a.n.is_some()),
        ("--nr", a.nr.is_some()),
        ("--albedo", a.albedo.is_some()),
        ("--max-bounces", a.max_bounces.is_some()),
        ("--fresnel", a.fresnel.is_some()),
        ("--fresnel-law", a.fresnel_law.is_some() && !law_read),
        (
            "--estimator kernel",
            matches!(a.estimator, EstimatorArg::Kernel),
        ),
        ("--groove-slices", a.groove_slices.is_some()),
    ];
    match ignored.iter().find(|(_, given)| *given) {
        Some((flag, _)) => anyhow::bail!(
            "{flag}: applies to the 2D table (--walls diffuse, or specular without \
             --roughness), not to {what}; leave it out"
        ),
        None => Ok(()),
    }
}

/// Refuse the wall tables' options for a 2D table.
fn refuse_wall_flags(a: &Args) -> anyhow::Result<()> {
    for (flag, given) in [
        ("--incident", a.incident.is_some()),
        ("--exit-bins", a.exit_bins.is_some()),
        ("--wall-paths", a.wall_paths.is_some()),
        ("--check", a.check != 0),
    ] {
        if given {
            anyhow::bail!(
                "{flag} applies to wall tables only (--walls dielectric, or specular with --roughness)"
            );
        }
    }
    Ok(())
}

/// The 2D table's trace settings from the flags, its memory checked.
fn trace_settings(a: &Args) -> anyhow::Result<TraceSettings> {
    if a.groove_slices == Some(0) {
        anyhow::bail!("--groove-slices 0: must be in 1..=32 (leave it out for the seed's eq. (3))");
    }
    let d = TraceSettings::default();
    let m = a.m.unwrap_or(d.m) as u64;
    // The slices: rho and its ratio to F, and the goniometer's two M x M histograms per thread.
    let groove = a
        .groove_slices
        .map_or(0, |s| (16 * s as u64 + 16 * 64) * m * m);
    striae::memory::check(&format!("--m {m}"), 80 * m * m + groove, a.max_memory)?;
    let trace = TraceSettings {
        walls: match a.walls {
            WallsArg::Specular => Walls::Specular,
            WallsArg::Diffuse => Walls::Diffuse,
            WallsArg::Dielectric => unreachable!("a wall table"),
        },
        m: a.m.unwrap_or(d.m),
        n: a.n.unwrap_or(d.n),
        nr: a.nr.unwrap_or(d.nr),
        albedo: a.albedo.unwrap_or(d.albedo),
        max_bounces: a.max_bounces.unwrap_or(d.max_bounces),
        seed: a.seed,
        fresnel_mode: match a.fresnel {
            Some(ModeArg::Seed) => FresnelMode::Seed,
            Some(ModeArg::Walls) => FresnelMode::Walls,
            None if a.groove_slices.is_some() => FresnelMode::Walls,
            None => FresnelMode::Seed,
        },
        fresnel_law: parse_law(a.fresnel_law.as_deref(), a.ior)?,
        estimator: match a.estimator {
            EstimatorArg::Walks => Estimator::Walks,
            EstimatorArg::Kernel => Estimator::Kernel,
        },
        groove_slices: a.groove_slices.unwrap_or(0),
    };
    trace.validate().context("invalid precompute parameters")?;
    Ok(trace)
}

/// A progress bar of `total` paths with its rate and the time left.
fn progress_bar(total: u64) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(total);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {percent}% ({per_sec}, eta {eta})",
        )
        .expect("template"),
    );
    bar
}

/// What a 2D table took and holds: its sizes, the time and rate, the albedo range and the
/// energy the bounce cap dropped.
fn report(params: &TableParams, table: &ScratchTable, secs: f64, threads: usize) {
    let alb = table.albedo_2d();
    let (lo, hi) = alb
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
            (l.min(x), h.max(x))
        });
    let dropped = table.dropped.iter().cloned().fold(0.0, f64::max);
    println!(
        "profile {}  walls {:?}  M {}  N {}  N_r {}",
        params.profile.spec, params.trace.walls, table.m, params.trace.n, params.trace.nr
    );
    if params.trace.groove_slices > 0 {
        println!(
            "exact-groove slices {} (theta_i), {} goniometer paths",
            params.trace.groove_slices,
            params.trace.groove_paths()
        );
    }
    let estimator = match params.trace.estimator {
        Estimator::Walks => "",
        Estimator::Kernel => " (kernel estimator: equivalent N_r-scheme paths)",
    };
    let total = params.trace.total_paths() + params.trace.groove_paths();
    println!(
        "wall time {secs:.3} s, {total} paths, {:.3e} paths/s ({threads} threads){estimator}",
        total as f64 / secs,
    );
    println!(
        "2D albedo range [{lo:.6}, {hi:.6}]; max energy dropped by the bounce cap {dropped:.3e}"
    );
}

/// The most paths a wall table may trace (incident directions x sides x `--wall-paths`):
/// 10^11, 8 hours on one core at the 3.5 million paths a second the groove tracer runs on a V
/// groove, 40 on a 64-segment round one (0.7 million); the shipped sizes trace 4 x 10^7.
const MAX_WALL_PATHS: u64 = 100_000_000_000;

/// `--walls dielectric` or `--walls specular --roughness A`: the wall table
/// (`striae::precompute::wall_table`; four lobes, or rough specular walls' one), and with `--check N` its
/// error against the exact trace at N off-grid incident directions.
fn wall_table(
    params: striae::precompute::wall_table::WallTableParams,
    a: &Args,
) -> anyhow::Result<()> {
    use striae::precompute::wall_table::{WallTable, WallTableParams, LOBES};
    let (theta_bins, phi_bins) = a.incident.unwrap_or((params.theta_bins, params.phi_bins));
    let params = WallTableParams {
        seed: a.seed,
        theta_bins,
        phi_bins,
        bins: a.exit_bins.unwrap_or(params.bins),
        paths: a.wall_paths.unwrap_or(params.paths),
        ..params
    };
    params.validate().map_err(|e| {
        // The sizes' checks are the table's own; name the flag that set them.
        let flag = match e.key {
            "theta-bins" | "phi-bins" => "--incident",
            "bins" => "--exit-bins",
            "paths" => "--wall-paths",
            _ => return anyhow::Error::new(e).context("invalid precompute parameters"),
        };
        anyhow::anyhow!("{flag}: {} {}: {}", e.key, e.value, e.why)
    })?;
    let total = params.total_paths();
    if total > MAX_WALL_PATHS {
        anyhow::bail!(
            "--wall-paths {} x --incident {}x{} x {} side(s) is {total} paths, more than \
             {MAX_WALL_PATHS} (hours to days: the groove tracer runs 1 to 4 million paths a \
             second a core); lower --wall-paths or --incident",
            params.paths,
            params.theta_bins,
            params.phi_bins,
            params.walls.sides().len()
        );
    }
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()?;
    striae::memory::check(
        &format!(
            "--exit-bins {} --incident {}x{}",
            params.bins, params.theta_bins, params.phi_bins
        ),
        params.memory_estimate(pool.current_num_threads()),
        a.max_memory,
    )?;
    let bar = progress_bar(total);
    let start = Instant::now();
    let table = pool.install(|| WallTable::compute_with(&params, &|k| bar.inc(k)))?;
    let secs = start.elapsed().as_secs_f64();
    bar.finish_and_clear();
    table
        .save(&a.output)
        .with_context(|| format!("writing {}", a.output.display()))?;
    let incident = params.theta_bins * params.phi_bins;
    let (walls, sides) = (params.walls_label(), params.walls.sides().len());
    println!(
        "{walls}: profile {}  roughness {}  {} x {} incident directions x {sides} side(s), {} x {} exit bins, {} paths each",
        params.profile.spec, params.roughness, params.theta_bins, params.phi_bins,
        params.exit_rows(), params.bins, params.paths
    );
    println!(
        "wall time {secs:.3} s ({} paths, {} threads)",
        sides as u64 * incident as u64 * params.paths,
        pool.current_num_threads()
    );
    for k in 0..a.check {
        // Off-grid directions: quasi-random (golden ratio) in (-80, 80) degrees.
        let g = |x: f64| ((x * 0.618_033_988_749_895).fract() - 0.5) * 160f64.to_radians();
        let (ti, pi) = (g(k as f64 + 0.37), g(k as f64 * 1.7 + 0.11));
        let err = pool.install(|| table.error_against_trace(ti, pi, 200_000))?;
        let row: Vec<String> = LOBES[..params.walls.lobe_count()]
            .iter()
            .zip(err)
            .map(|(n, e)| {
                format!(
                    "{n}: dalbedo {:+.4} L1 {:.3} phi-L1 {:.3} dtheta {:+.2} deg",
                    e.albedo,
                    e.l1,
                    e.phi_l1,
                    e.theta_shift.to_degrees()
                )
            })
            .collect();
        println!(
            "check theta_i {:+6.1} phi_i {:+6.1}:\n  {}",
            ti.to_degrees(),
            pi.to_degrees(),
            row.join("\n  ")
        );
    }
    println!("wrote {}", a.output.display());
    Ok(())
}
