//! `striae fidelity`: the scratch model's 3D BRDF against the exact groove (docs/fidelity.md).

use anyhow::Context;
use std::path::PathBuf;
use std::time::Instant;
use striae::lab::fidelity::study::{run_study, write_csv, StudySettings};
use striae::lab::plot::plot_fidelity_case;
use striae::optics::fresnel::FresnelLaw;
use striae::precompute::profile::Profile;
use striae::precompute::trace2d::TraceSettings;

/// The profiles of docs/fidelity.md.
const PROFILES: &str = "v90=v:angle=90;v60=v:angle=60;round=round:depth=0.5;\
trapezoid=trapezoid:depth=0.3,bottom=0.3";

#[derive(clap::Args)]
pub struct Args {
    /// Profiles as NAME=SPEC separated by `;` (NAME goes into the CSV).
    #[arg(long, default_value = PROFILES)]
    profiles: String,
    /// Incident theta, degrees, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "0,15,30,45,60,75")]
    theta_i: Vec<f64>,
    /// Incident phi, degrees, comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        allow_negative_numbers = true,
        default_value = "0,30,60"
    )]
    phi_i: Vec<f64>,
    /// Goniometer bins per angle.
    #[arg(long, default_value_t = 32)]
    bins: usize,
    /// Goniometer paths per run.
    #[arg(long, default_value_t = 250_000)]
    paths: u64,
    /// Independent goniometer runs per incident direction (their spread is the noise).
    #[arg(long, default_value_t = 4)]
    runs: usize,
    /// The tables' M,N,N_r: angle bins, entry points and walks per entry (the seed's).
    #[arg(long, value_delimiter = ',', default_value = "256,10000,100")]
    table: Vec<usize>,
    /// Index of refraction of the walls' Schlick law.
    #[arg(long, default_value_t = 1.5)]
    ior: f64,
    /// theta_i slices of the exact-groove table (0: none), its phi bins and paths per slice
    /// and phi_i.
    #[arg(long, default_value_t = 6)]
    slices: usize,
    #[arg(long, default_value_t = 64)]
    slice_m: usize,
    #[arg(long, default_value_t = 50_000)]
    slice_paths: u64,
    /// Skip the lossless Lambertian control.
    #[arg(long)]
    no_lossless: bool,
    /// Cases to plot, NAME@THETA,PHI (degrees), repeatable.
    #[arg(long)]
    plot: Vec<String>,
    /// Models drawn in each plot, comma-separated: seed, seed_theta_exact, walls,
    /// groove_slicesS (with --slices S > 0), lossless (default: seed, walls and, with
    /// --slices S > 0, groove_slicesS).
    #[arg(long, value_delimiter = ',')]
    plot_models: Vec<String>,
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Worker threads, 1 to 4096 (default: all cores).
    #[arg(long, value_parser = super::render::parse_threads)]
    threads: Option<usize>,
    /// Output folder: fidelity.csv and the plots.
    #[arg(short, long)]
    output: PathBuf,
}

fn profiles(spec: &str) -> anyhow::Result<Vec<(String, Profile)>> {
    spec.split(';')
        .filter(|s| !s.trim().is_empty())
        .map(|item| {
            let (name, p) = item
                .split_once('=')
                .with_context(|| format!("--profiles: `{item}` is not NAME=SPEC"))?;
            let name = name.trim();
            if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
                anyhow::bail!("--profiles: name `{name}` must be letters, digits or `_`");
            }
            let profile = Profile::parse(p.trim()).with_context(|| format!("--profiles `{p}`"))?;
            Ok((name.to_string(), profile))
        })
        .collect()
}

fn settings(a: &Args) -> anyhow::Result<StudySettings> {
    if !(a.ior.is_finite() && a.ior >= 1.0) {
        anyhow::bail!("--ior {}: must be finite and >= 1", a.ior);
    }
    if a.runs < 2 {
        anyhow::bail!(
            "--runs {}: at least 2 runs are needed to measure the noise",
            a.runs
        );
    }
    let [m, n, nr] = a.table[..] else {
        anyhow::bail!("--table: expected M,N,N_r (three integers)");
    };
    let table = TraceSettings {
        m,
        n,
        nr,
        fresnel_law: FresnelLaw::Schlick { n: a.ior },
        ..TraceSettings::default()
    };
    table.validate()?;
    Ok(StudySettings {
        profiles: profiles(&a.profiles)?,
        theta_i_deg: a.theta_i.clone(),
        phi_i_deg: a.phi_i.clone(),
        bins: a.bins,
        paths: a.paths,
        runs: a.runs,
        table,
        slices: a.slices,
        slice_m: a.slice_m,
        slice_paths: a.slice_paths,
        lossless: !a.no_lossless,
        quad: 4,
        seed: a.seed,
    })
}

/// `NAME@THETA,PHI`: a case of the study `study` (a profile of `--profiles`, a `--theta-i`
/// and a `--phi-i`), checked before anything is computed.
fn plot_case_key(s: &str, study: &StudySettings) -> anyhow::Result<(String, f64, f64)> {
    let bad = || format!("--plot `{s}`: expected NAME@THETA,PHI");
    let (name, angles) = s.split_once('@').with_context(bad)?;
    let (t, f) = angles.split_once(',').with_context(bad)?;
    let (name, t, f): (String, f64, f64) = (
        name.to_string(),
        t.trim().parse().with_context(bad)?,
        f.trim().parse().with_context(bad)?,
    );
    let list = |v: &[f64]| v.iter().map(f64::to_string).collect::<Vec<_>>().join(", ");
    if !study.profiles.iter().any(|(n, _)| *n == name) {
        let names: Vec<&str> = study.profiles.iter().map(|(n, _)| n.as_str()).collect();
        anyhow::bail!(
            "--plot `{s}`: no profile `{name}` in --profiles (names: {})",
            names.join(", ")
        );
    }
    if !study.theta_i_deg.contains(&t) {
        anyhow::bail!(
            "--plot `{s}`: theta {t} is not one of --theta-i ({})",
            list(&study.theta_i_deg)
        );
    }
    if !study.phi_i_deg.contains(&f) {
        anyhow::bail!(
            "--plot `{s}`: phi {f} is not one of --phi-i ({})",
            list(&study.phi_i_deg)
        );
    }
    Ok((name, t, f))
}

/// `--plot-models`, each a model the study compares, or the default.
fn plot_models(models: &[String], study: &StudySettings) -> anyhow::Result<Vec<String>> {
    let known = study.model_names();
    if let Some(m) = models.iter().find(|m| !known.contains(m)) {
        anyhow::bail!(
            "--plot-models `{m}`: not a model of this study (models: {})",
            known.join(", ")
        );
    }
    if !models.is_empty() {
        return Ok(models.to_vec());
    }
    let mut default = vec!["seed".to_string(), "walls".into()];
    if study.slices > 0 {
        default.push(format!("groove_slices{}", study.slices));
    }
    Ok(default)
}

pub fn run(a: Args) -> anyhow::Result<()> {
    let s = settings(&a)?;
    // Every flag checked before anything is computed or written.
    s.validate()?;
    let plots = a
        .plot
        .iter()
        .map(|p| plot_case_key(p, &s))
        .collect::<anyhow::Result<Vec<_>>>()?;
    let models = plot_models(&a.plot_models, &s)?;
    if a.output.exists() && !a.output.is_dir() {
        anyhow::bail!("-o {}: exists and is not a folder", a.output.display());
    }
    let threads = a.threads.unwrap_or_else(rayon::current_num_threads);
    striae::memory::check(
        &format!(
            "--bins {} (with --table M {}, --runs {}, --slice-m {}, {threads} threads)",
            s.bins, s.table.m, s.runs, s.slice_m
        ),
        s.memory_estimate(threads),
        None,
    )?;
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("creating {}", a.output.display()))?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(a.threads.unwrap_or(0))
        .build()?;
    let start = Instant::now();
    let cases = pool.install(|| run_study(&s, &|line| eprintln!("fidelity: {line}")))?;
    let csv = a.output.join("fidelity.csv");
    write_csv(&cases, &csv)?;
    println!(
        "wrote {} ({:.1} s)",
        csv.display(),
        start.elapsed().as_secs_f64()
    );
    let models: Vec<&str> = models.iter().map(|m| m.as_str()).collect();
    for (name, t, f) in plots {
        let case = cases
            .iter()
            .find(|c| c.profile == name && c.theta_i_deg == t && c.phi_i_deg == f)
            .with_context(|| format!("--plot {name}@{t},{f}: no such case in the study"))?;
        let path = a.output.join(format!("{name}_t{t}_p{f}.png"));
        plot_fidelity_case(case, &models, &path)?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
