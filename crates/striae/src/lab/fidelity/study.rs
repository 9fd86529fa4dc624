//! The table of docs/fidelity.md: the model's lobes against the exact groove for a set of
//! profiles and incident directions, written as CSV and drawn as side-by-side heat maps.

use super::{compare, model_histogram, reference, Comparison, Reference};
use crate::math::Vec3;
use crate::optics::fresnel::FresnelLaw;
use crate::precompute::groove::{GonioError, GonioSettings, GrooveWalls};
use crate::precompute::profile::Profile;
use crate::precompute::table::{ScratchBrdf, ScratchTable, TableError, TableParams};
use crate::precompute::trace2d::{FresnelMode, TraceError, TraceSettings, Walls};
use std::fmt::Write as _;
use std::path::Path;

/// What the study compares.
#[derive(Clone, Debug)]
pub struct StudySettings {
    /// Short names (CSV-safe) and profiles.
    pub profiles: Vec<(String, Profile)>,
    /// Incident angles, degrees (every `theta_i` with every `phi_i`).
    pub theta_i_deg: Vec<f64>,
    pub phi_i_deg: Vec<f64>,
    /// Goniometer bins per angle, paths per run and runs per incident direction.
    pub bins: usize,
    pub paths: u64,
    pub runs: usize,
    /// The tables' trace settings (diffuse walls; `m`, `n`, `nr`, the Fresnel law); the study
    /// makes a `seed` and a `walls` table from them, and a lossless one (`FresnelLaw::None`).
    pub table: TraceSettings,
    /// A table with exact-groove slices ([`crate::precompute::groove_slices`], `groove_slices = S`): `S`
    /// (0: not computed), its `M` and the paths per slice and `phi_i` (its `N`, with `N_r = 1`).
    pub slices: usize,
    pub slice_m: usize,
    pub slice_paths: u64,
    /// Also compare the lossless Lambertian case (where the model is exact).
    pub lossless: bool,
    /// Sub-cells per bin and angle of [`model_histogram`].
    pub quad: usize,
    pub seed: u64,
}

/// One model's lobe and its comparison with the exact one.
#[derive(Clone, Debug)]
pub struct ModelResult {
    pub name: String,
    pub hist: Vec<f64>,
    pub cmp: Comparison,
    /// Which reference it was compared with: the walls' Fresnel law, or lossless.
    pub lossless: bool,
}

/// One profile and incident direction.
#[derive(Clone, Debug)]
pub struct Case {
    pub profile: String,
    pub theta_i_deg: f64,
    pub phi_i_deg: f64,
    pub exact: Reference,
    pub exact_lossless: Option<Reference>,
    pub models: Vec<ModelResult>,
}

/// Why the study failed.
#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    #[error(transparent)]
    Table(#[from] TableError),
    #[error(transparent)]
    Gonio(#[from] GonioError),
    #[error("the tables' trace settings: {0}")]
    Trace(TraceError),
    #[error("the exact-groove slices' table (slices {slices}, slice_m {slice_m}, slice_paths {slice_paths}): {error}")]
    Slices {
        slices: usize,
        slice_m: usize,
        slice_paths: u64,
        error: TraceError,
    },
    #[error("writing {path}: {source}")]
    Io {
        path: std::path::PathBuf,
        source: std::io::Error,
    },
}

/// The models of one profile.
struct Models {
    seed: ScratchBrdf,
    walls: ScratchBrdf,
    lossless: Option<ScratchBrdf>,
    slices: Option<ScratchBrdf>,
}

fn brdf(profile: &Profile, trace: &TraceSettings) -> Result<ScratchBrdf, TableError> {
    let p = TableParams::new(profile.clone(), trace.clone());
    Ok(ScratchBrdf::new(ScratchTable::compute(&p, &|_| {})?))
}

/// The renderer's BRDF ([`ScratchBrdf::eval`], `f32` directions) as a [`super::Model`].
pub fn table_model(b: &ScratchBrdf) -> impl Fn([f64; 3], [f64; 3]) -> f64 + Sync + '_ {
    let v = |w: [f64; 3]| Vec3::new(w[0] as f32, w[1] as f32, w[2] as f32);
    move |wo, wi| b.eval(v(wo), v(wi))
}

/// The seed's model with its `theta_o` law exact instead of sliced:
/// `(2/pi) rho_m(phi_o, phi_i) F(cos theta_o)`, the limit of ever more `theta_o` slices.
fn seed_theta_exact(b: &ScratchBrdf) -> impl Fn([f64; 3], [f64; 3]) -> f64 + Sync + '_ {
    let t = b.table();
    let law = t.params.trace.fresnel_law;
    move |wo, wi| {
        if wo[2] <= 0.0 || wi[2] <= 0.0 {
            return 0.0;
        }
        let (i, o) = (b.phi_bin(wi[0], wi[2]), b.phi_bin(wo[0], wo[2]));
        let cos_theta_o = (1.0 - wo[1] * wo[1]).max(0.0).sqrt();
        2.0 / std::f64::consts::PI * t.rho_m[i * t.m + o] * law.reflectance(cos_theta_o)
    }
}

impl StudySettings {
    /// The memory the study takes on `threads` threads: a goniometer run
    /// ([`crate::lab::gonio::memory_estimate`]) and the other runs' outputs of its incident
    /// direction (32 bytes a bin each), every case's histograms and references (72 bytes a
    /// bin), and one profile's tables while they are computed (80 bytes per `M^2`, as
    /// `striae precompute`, and the slices table's `16 S + 1024` more per `slice_m^2`).
    pub fn memory_estimate(&self, threads: usize) -> u64 {
        let cells = self.bins as u64 * self.bins as u64;
        let cases = (self.profiles.len() * self.theta_i_deg.len() * self.phi_i_deg.len()) as u64;
        let m = self.table.m as u64;
        let sm = self.slice_m as u64;
        let slices = if self.slices > 0 {
            (80 + 16 * self.slices as u64 + 1024).saturating_mul(sm * sm)
        } else {
            0
        };
        crate::lab::gonio::memory_estimate(self.bins, threads, self.paths)
            .saturating_add(cells.saturating_mul(32 * self.runs as u64 + 72 * cases))
            .saturating_add((3 * 80 * m).saturating_mul(m))
            .saturating_add(slices)
    }

    fn gonio(&self, law: FresnelLaw, theta_i_deg: f64, phi_i_deg: f64) -> GonioSettings {
        GonioSettings {
            walls: GrooveWalls::Diffuse,
            fresnel_law: law,
            theta_i: theta_i_deg.to_radians(),
            phi_i: phi_i_deg.to_radians(),
            paths: self.paths,
            bins: self.bins,
            seed: self.seed,
            ..GonioSettings::default()
        }
    }

    /// The exact-groove slices' table: the renderer's option, a `fresnel = "walls"` table
    /// with `groove_slices = S`.
    fn slice_table(&self) -> TraceSettings {
        TraceSettings {
            walls: Walls::Diffuse,
            fresnel_mode: FresnelMode::Walls,
            m: self.slice_m,
            n: self.slice_paths as usize,
            nr: 1,
            seed: self.seed,
            groove_slices: self.slices,
            ..self.table.clone()
        }
    }

    /// The names of the models each [`Case`] holds, in order ([`ModelResult::name`]).
    pub fn model_names(&self) -> Vec<String> {
        let mut names = vec![
            "seed".to_string(),
            "seed_theta_exact".into(),
            "walls".into(),
        ];
        if self.slices > 0 {
            names.push(format!("groove_slices{}", self.slices));
        }
        if self.lossless {
            names.push("lossless".into());
        }
        names
    }

    /// Every setting checked before anything is computed: the goniometer's at each incident
    /// direction (its errors name `--theta-i`, `--phi-i`, `--bins`, `--paths`) and the tables'.
    pub fn validate(&self) -> Result<(), StudyError> {
        for &t in &self.theta_i_deg {
            for &f in &self.phi_i_deg {
                self.gonio(self.table.fresnel_law, t, f).validate()?;
            }
        }
        self.table.validate().map_err(StudyError::Trace)?;
        if self.slices > 0 {
            self.slice_table()
                .validate()
                .map_err(|error| StudyError::Slices {
                    slices: self.slices,
                    slice_m: self.slice_m,
                    slice_paths: self.slice_paths,
                    error,
                })?;
        }
        Ok(())
    }

    fn models(&self, profile: &Profile) -> Result<Models, StudyError> {
        let seed = TraceSettings {
            walls: Walls::Diffuse,
            fresnel_mode: FresnelMode::Seed,
            ..self.table.clone()
        };
        let walls = TraceSettings {
            fresnel_mode: FresnelMode::Walls,
            ..seed.clone()
        };
        let lossless = TraceSettings {
            fresnel_law: FresnelLaw::None,
            ..seed.clone()
        };
        let groove = self.slice_table();
        let slices = (self.slices > 0)
            .then(|| brdf(profile, &groove))
            .transpose()?;
        Ok(Models {
            seed: brdf(profile, &seed)?,
            walls: brdf(profile, &walls)?,
            lossless: self
                .lossless
                .then(|| brdf(profile, &lossless))
                .transpose()?,
            slices,
        })
    }

    /// One incident direction of one profile.
    fn case(
        &self,
        name: &str,
        p: &Profile,
        ms: &Models,
        t: f64,
        f: f64,
    ) -> Result<Case, StudyError> {
        let law = self.table.fresnel_law;
        let exact = reference(p, &self.gonio(law, t, f), self.runs)?;
        let exact_lossless = self
            .lossless
            .then(|| reference(p, &self.gonio(FresnelLaw::None, t, f), self.runs))
            .transpose()?;
        let (ti, fi, b, q) = (t.to_radians(), f.to_radians(), self.bins, self.quad);
        let m = self.table.m;
        let mut hists = vec![
            (
                "seed".to_string(),
                model_histogram(&table_model(&ms.seed), ti, fi, b, m, q),
                false,
            ),
            (
                "seed_theta_exact".to_string(),
                model_histogram(&seed_theta_exact(&ms.seed), ti, fi, b, m, q),
                false,
            ),
            (
                "walls".to_string(),
                model_histogram(&table_model(&ms.walls), ti, fi, b, m, q),
                false,
            ),
        ];
        if let Some(g) = &ms.slices {
            let name = format!("groove_slices{}", self.slices);
            let hist = model_histogram(&table_model(g), ti, fi, b, self.slice_m, q);
            hists.push((name, hist, false));
        }
        if let Some(l) = &ms.lossless {
            hists.push((
                "lossless".into(),
                model_histogram(&table_model(l), ti, fi, b, m, q),
                true,
            ));
        }
        let models = hists
            .into_iter()
            .map(|(name, hist, lossless)| {
                let r = if lossless {
                    exact_lossless.as_ref().expect("lossless")
                } else {
                    &exact
                };
                let cmp = compare(&hist, r);
                ModelResult {
                    name,
                    hist,
                    cmp,
                    lossless,
                }
            })
            .collect();
        Ok(Case {
            profile: name.to_string(),
            theta_i_deg: t,
            phi_i_deg: f,
            exact,
            exact_lossless,
            models,
        })
    }
}

/// Run the study (on the current rayon pool); `log` hears one line per profile.
pub fn run_study(s: &StudySettings, log: &dyn Fn(&str)) -> Result<Vec<Case>, StudyError> {
    s.validate()?;
    let mut cases = Vec::new();
    for (name, p) in &s.profiles {
        log(&format!("{name} ({}): tables", p.spec));
        let ms = s.models(p)?;
        log(&format!("{name}: goniometer"));
        for &t in &s.theta_i_deg {
            for &f in &s.phi_i_deg {
                cases.push(s.case(name, p, &ms, t, f)?);
            }
        }
    }
    Ok(cases)
}

/// The CSV header of [`write_csv`] (`numpy.genfromtxt(path, delimiter=",", names=True,
/// dtype=None, encoding="utf-8")` reads it).
pub const CSV_HEADER: &str = "profile,model,theta_i,phi_i,l1,noise_l1,l1_over_noise,\
albedo_model,albedo_exact,albedo_err,albedo_se";

/// One line per case and model: angles in degrees, the rest fractions of the incident energy.
pub fn csv(cases: &[Case]) -> String {
    let mut out = String::from(CSV_HEADER);
    out.push('\n');
    for c in cases {
        for m in &c.models {
            let r = &m.cmp;
            let _ = writeln!(
                out,
                "{},{},{},{},{:.6e},{:.6e},{:.3},{:.6e},{:.6e},{:.6e},{:.3e}",
                c.profile,
                m.name,
                c.theta_i_deg,
                c.phi_i_deg,
                r.l1,
                r.noise_l1,
                r.l1 / r.noise_l1,
                r.albedo_model,
                r.albedo_exact,
                r.albedo_err(),
                r.albedo_se
            );
        }
    }
    out
}

/// Write [`csv`] atomically.
pub fn write_csv(cases: &[Case], path: &Path) -> Result<(), StudyError> {
    crate::io::write_atomically(path, |tmp| std::fs::write(tmp, csv(cases))).map_err(|source| {
        StudyError::Io {
            path: path.into(),
            source,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_study_writes_its_csv_and_plot() {
        let s = StudySettings {
            profiles: vec![("v90".into(), Profile::parse("v:angle=90").unwrap())],
            theta_i_deg: vec![0.0, 60.0],
            phi_i_deg: vec![30.0],
            bins: 8,
            paths: 4000,
            runs: 2,
            table: TraceSettings {
                m: 16,
                n: 400,
                nr: 4,
                ..TraceSettings::default()
            },
            slices: 2,
            slice_m: 8,
            slice_paths: 2000,
            lossless: true,
            quad: 2,
            seed: 0,
        };
        let cases = run_study(&s, &|_| {}).unwrap();
        assert_eq!(cases.len(), 2);
        let text = csv(&cases);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], CSV_HEADER);
        // Five models per case, eleven columns each.
        assert_eq!(lines.len(), 1 + 2 * 5);
        assert!(lines[1..].iter().all(|l| l.split(',').count() == 11));
        assert!(text.contains("v90,groove_slices2,60,30,"));
        let names: Vec<&str> = cases[0].models.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, s.model_names());
        let dir = std::env::temp_dir().join(format!("striae-fidelity-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let png = dir.join("case.png");
        crate::lab::plot::plot_fidelity_case(&cases[1], &["seed", "lossless"], &png).unwrap();
        let img = image::open(&png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (3 * 560, 2 * 420 + 40));
        std::fs::remove_dir_all(&dir).ok();
    }
}
