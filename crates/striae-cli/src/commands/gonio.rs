//! `striae gonio`: the exact BSDF of an extruded groove by 2.5D tracing (METHOD.md 8.1).

use anyhow::Context;
use std::path::PathBuf;
use std::time::Instant;
use striae::optics::fresnel::FresnelLaw;
use striae::precompute::groove::{trace_groove, GonioSettings, GrooveWalls, LightSide};
use striae::precompute::profile::Profile;

#[derive(clap::Args)]
pub struct Args {
    /// Profile: v:depth=D, v:angle=DEG, round:depth=D[,segments=K], trapezoid:depth=D,bottom=B,
    /// flat, file:PATH (as `striae precompute`).
    #[arg(long, default_value = "v:angle=90")]
    profile: String,
    /// Wall BSDF: diffuse (3D Lambert) or specular (mirror), each times the Fresnel law per
    /// hit; dielectric: smooth glass walls of index --ior (reflection and refraction).
    #[arg(long, value_enum, default_value_t = WallsArg::Diffuse)]
    walls: WallsArg,
    /// GGX alpha of the walls in [0, 1] (0: smooth): a rough conductor (specular walls) or a
    /// rough dielectric (dielectric walls).
    #[arg(long, default_value_t = 0.0)]
    roughness: f64,
    /// Rough walls scatter once per wall hit (the single-scattering GGX BSDF, which loses the
    /// light that would meet a second microfacet) instead of walking the microsurface
    /// (METHOD.md 9.7, lossless where the facets are).
    #[arg(long)]
    single_scatter: bool,
    /// Fresnel law of diffuse and specular walls: schlick, dielectric (both with --ior),
    /// conductor:ETA,K or none (F = 1). Dielectric walls always use the exact equations.
    #[arg(long)]
    fresnel_law: Option<String>,
    /// Index of refraction of the object (>= 1).
    #[arg(long, default_value_t = 1.5)]
    ior: f64,
    /// Incident theta (degrees, METHOD.md section 1), in (-90, 90).
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.0)]
    theta_i: f64,
    /// Incident phi (degrees), in (-90, 90).
    #[arg(long, allow_negative_numbers = true, default_value_t = 0.0)]
    phi_i: f64,
    /// Where the light comes from: outside (the air) or inside (the object; dielectric walls).
    #[arg(long, value_enum, default_value_t = SideArg::Outside)]
    side: SideArg,
    /// With `--side inside`: also trace the light aimed beside the opening that meets the
    /// groove (a groove seen from inside is a ridge, wider than its opening at grazing
    /// incidence), on its way to the flat surface or, totally reflected there, right after;
    /// fractions stay per unit opening, and the npz gains `intercept`.
    #[arg(long)]
    beside: bool,
    /// Paths (entry points stratified over the opening, or the band of --beside).
    #[arg(long, default_value_t = 200_000)]
    paths: u64,
    /// Bins per angle (theta and phi over [-90, 90] degrees).
    #[arg(long, default_value_t = 32)]
    bins: usize,
    /// Surface interactions per path before it is dropped.
    #[arg(long, default_value_t = 256)]
    max_bounces: usize,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads, 1 to 4096 (default: all cores).
    #[arg(long, value_parser = super::render::parse_threads)]
    threads: Option<usize>,
    /// Heat maps of the two histograms (.png).
    #[arg(long)]
    plot: Option<PathBuf>,
    /// Output (.npz): theta, phi, reflected, transmitted, albedo_r, albedo_t (and intercept
    /// with --beside).
    #[arg(short, long)]
    output: PathBuf,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum WallsArg {
    Diffuse,
    Specular,
    Dielectric,
}

#[derive(Clone, Copy, Debug, clap::ValueEnum)]
enum SideArg {
    Outside,
    Inside,
}

fn settings(a: &Args) -> anyhow::Result<GonioSettings> {
    let walls = match a.walls {
        WallsArg::Diffuse => GrooveWalls::Diffuse,
        WallsArg::Specular => GrooveWalls::Specular,
        WallsArg::Dielectric => GrooveWalls::Dielectric,
    };
    if walls == GrooveWalls::Dielectric && a.fresnel_law.is_some() {
        anyhow::bail!(
            "--fresnel-law: dielectric walls use the exact dielectric equations with --ior; \
             the law applies to diffuse and specular walls only"
        );
    }
    let law = a.fresnel_law.as_deref().unwrap_or("schlick");
    let fresnel_law =
        FresnelLaw::parse(law, a.ior).map_err(|e| anyhow::anyhow!("--fresnel-law: {e}"))?;
    let s = GonioSettings {
        walls,
        roughness: a.roughness,
        single_scatter: a.single_scatter,
        fresnel_law,
        ior: a.ior,
        theta_i: a.theta_i.to_radians(),
        phi_i: a.phi_i.to_radians(),
        side: match a.side {
            SideArg::Outside => LightSide::Outside,
            SideArg::Inside => LightSide::Inside,
        },
        beside: a.beside,
        paths: a.paths,
        bins: a.bins,
        max_bounces: a.max_bounces,
        seed: a.seed,
    };
    s.validate()?;
    Ok(s)
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let profile =
        Profile::parse(&a.profile).with_context(|| format!("--profile `{}`", a.profile))?;
    let s = settings(&a)?;
    super::check_output_file("-o", &a.output)?;
    if let Some(plot) = &a.plot {
        striae::lab::plot::check_png_name(plot).map_err(|e| anyhow::anyhow!("--plot {e}"))?;
        super::check_output_file("--plot", plot)?;
    }
    let bar = indicatif::ProgressBar::new(s.paths);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{elapsed_precise}] {wide_bar} {percent}% ({per_sec}, eta {eta})",
        )
        .expect("template"),
    );
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()?;
    let threads = pool.current_num_threads();
    striae::memory::check(
        &format!("--bins {} (on {threads} threads, --threads)", s.bins),
        striae::lab::gonio::memory_estimate(s.bins, threads, s.paths),
        None,
    )?;
    let start = Instant::now();
    let out = pool.install(|| trace_groove(&profile, &s, &|k| bar.inc(k)))?;
    let secs = start.elapsed().as_secs_f64();
    bar.finish_and_clear();
    striae::lab::gonio::save_npz(&out, &a.output)
        .with_context(|| format!("writing {}", a.output.display()))?;
    let title = format!(
        "{}: {:?} walls{}, {}, theta_i {} phi_i {} deg, from {:?}, {} paths",
        profile.spec,
        s.walls,
        if s.roughness > 0.0 {
            format!(" (GGX alpha {})", s.roughness)
        } else {
            String::new()
        },
        match s.walls {
            GrooveWalls::Dielectric => format!("ior {}", s.ior),
            _ => format!("{:?}", s.fresnel_law),
        },
        a.theta_i,
        a.phi_i,
        s.side,
        s.paths
    );
    if let Some(p) = &a.plot {
        striae::lab::plot::plot_gonio(&out, &title, p)?;
    }
    println!("{title}");
    println!(
        "wall time {secs:.3} s, {:.3e} paths/s ({} threads)",
        s.paths as f64 / secs,
        pool.current_num_threads()
    );
    println!(
        "albedo_r {:.6}  albedo_t {:.6}  dropped by the bounce cap {:.3e}  lost {:.3e}",
        out.albedo_r, out.albedo_t, out.dropped, out.lost
    );
    if let Some(k) = out.intercept {
        println!("intercept {k:.6} (the light meeting the groove per unit through its opening)");
    }
    println!("wrote {}", a.output.display());
    if let Some(p) = &a.plot {
        println!("wrote {}", p.display());
    }
    Ok(())
}
