//! The dielectric-wall scratch table (METHOD.md 8.1-8.2): the four lobes of a groove cut into
//! glass, R and T for light from outside and R and T for light from inside, per unit area of the
//! opening, tabulated from the exact 2.5D trace ([`crate::precompute::groove`]).
//!
//! Representation. Incident directions on a grid of `Bt x Bp` bin centres in
//! `(theta_i, phi_i)` over `(-pi/2, pi/2)^2` (METHOD.md section 1 angles, an `Inside` source
//! mirrored up as in [`crate::precompute::groove`]); for each, and each side, the groove's exit
//! histograms in `B x B` bins of `(theta_o, phi_o)`: the fraction of the energy arriving on the
//! opening that leaves through each bin, reflected or transmitted. A lookup between grid points
//! interpolates bilinearly in `(theta_i, phi_i)` ([`WallTable::lobes_at`]); its error against the
//! exact trace is measured by [`WallTable::error_against_trace`] and reported in
//! `docs/fidelity.md`.
//!
//! Smooth walls keep `beta = n w.y` (METHOD.md 8.1): each lobe leaves at one exact `theta_o`
//! ([`exit_theta`]), so the table holds only the `phi_o` marginals (one `theta_o` row, `1 x B`
//! bins), and finely: a polygonal profile's flat walls send light into a few sharp `phi_o`
//! peaks, and 32 bins smear them enough to render a back-lit pane 2 % dark (docs/fidelity.md),
//! so smooth tables default to 128 `phi_o` bins. A lookup puts the marginal back at its exact
//! `theta_o` row; the renderer puts `theta_o` at its exact value
//! ([`crate::render::bsdf::scratched_glass`]). Files with full `B x B` smooth lobes are read as their
//! marginals (the same table: only the marginals were ever rendered).
//!
//! Rough metal walls ([`WallKind::Specular`], GGX conductor walls with the metal's Fresnel law
//! at every microfacet hit) give one lobe, R from outside; it depends on `theta_o`, which the
//! seed's 2D table cannot hold, so it takes this 4D form with the other three lobes zero.
//!
//! Files (`.npz`, `docs/table-format.md`): `kind` ("dielectric-walls" or "specular-walls"),
//! `profile`, `ior`, `roughness`, `paths`, `seed`, `theta_i[Bt]`, `phi_i[Bp]`, `theta_o[B]`,
//! `phi_o[B]` and the four lobes `r_out`, `t_out`, `r_in`, `t_in`, each `[Bt, Bp, Bo, B]` with
//! `Bo = B` `theta_o` bins, or `Bo = 1` for smooth walls (`theta_o = [0]`, the marginals);
//! specular-wall files hold `r_out` only and the walls' Fresnel law as JSON (`fresnel_law`).

use crate::optics::fresnel::FresnelLaw;
use crate::precompute::groove::{trace_groove, GonioError, GonioSettings, GrooveWalls, LightSide};
use crate::precompute::profile::Profile;
use crate::precompute::table::check_npz_sizes;
use ndarray::{arr0, Array1, Array2, Array4, ArrayView4};
use ndarray_npy::NpzWriter;
use rayon::prelude::*;
use sha2::{Digest, Sha256};
use std::f64::consts::PI;
use std::path::Path;

/// The walls a table is traced with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WallKind {
    /// Glass of the table's `ior`, smooth or GGX-rough: the four lobes.
    Dielectric,
    /// GGX-rough conductor walls (`roughness > 0`), `law` at every microfacet hit (the metal's
    /// per-wall-hit Fresnel, as its mirror-wall 2D table has it): `r_out` only.
    Specular { law: FresnelLaw },
}

impl WallKind {
    /// The file's `kind` text.
    pub fn name(&self) -> &'static str {
        match self {
            WallKind::Dielectric => "dielectric-walls",
            WallKind::Specular { .. } => "specular-walls",
        }
    }

    /// How many of [`LOBES`] the trace fills (the first ones; the others are zero).
    pub fn lobe_count(&self) -> usize {
        match self {
            WallKind::Dielectric => 4,
            WallKind::Specular { .. } => 1,
        }
    }

    /// The sides light is traced from.
    pub fn sides(&self) -> &'static [LightSide] {
        match self {
            WallKind::Dielectric => &[LightSide::Outside, LightSide::Inside],
            WallKind::Specular { .. } => &[LightSide::Outside],
        }
    }
}

/// What a wall table is computed from.
#[derive(Clone, Debug, PartialEq)]
pub struct WallTableParams {
    pub profile: Profile,
    pub walls: WallKind,
    /// The glass's index (walls and flat surface), `>= 1`; 1 for specular walls (unused).
    pub ior: f64,
    /// GGX `alpha` of the walls, in `[0, 1]`; 0: smooth.
    pub roughness: f64,
    /// Rough walls scatter once instead of walking the microsurface (METHOD.md 9.7): only
    /// tables read from files written before the walk, which have no `wall_scattering` array.
    pub single_scatter: bool,
    /// Incident grid: `theta_i` and `phi_i` bins.
    pub theta_bins: usize,
    pub phi_bins: usize,
    /// Exit bins per angle (`phi_o` only, for smooth walls: [`Self::exit_rows`]).
    pub bins: usize,
    /// Paths per incident direction and side.
    pub paths: u64,
    pub seed: u64,
}

impl WallTableParams {
    /// The sizes the shipped scenes use: rough walls a 16 x 32 incident grid, 32 x 32 exit
    /// bins and 20 000 paths each (about 20 million paths in all); smooth walls a 32 x 128
    /// grid, 128 `phi_o` bins and 5 000 paths each (40 million). Smooth walls split R and T
    /// sharply with the incident direction, which a coarse grid blurs: renders of a back-lit
    /// pane move by several per cent from grid to grid up to 32 x 128 and agree beyond it
    /// (docs/fidelity.md); fewer paths a direction cost no accuracy there, since a render
    /// averages over many directions.
    pub fn new(profile: Profile, ior: f64, roughness: f64) -> Self {
        let smooth = roughness == 0.0;
        WallTableParams {
            profile,
            walls: WallKind::Dielectric,
            ior,
            roughness,
            single_scatter: false,
            theta_bins: if smooth { 32 } else { 16 },
            phi_bins: if smooth { 128 } else { 32 },
            bins: if smooth { SMOOTH_EXIT_BINS } else { 32 },
            paths: if smooth { 5_000 } else { 20_000 },
            seed: 0,
        }
    }

    /// The `theta_o` rows of a lobe: 1 for smooth dielectric walls (the `phi_o` marginal; the
    /// exit `theta` is exact), [`Self::bins`] otherwise.
    pub fn exit_rows(&self) -> usize {
        if self.smooth() {
            1
        } else {
            self.bins
        }
    }

    /// Smooth dielectric walls: `beta` conserved, one exact exit `theta` per lobe.
    pub fn smooth(&self) -> bool {
        self.walls == WallKind::Dielectric && self.roughness == 0.0
    }

    /// Rough conductor walls of `roughness` in `(0, 1]` with `law` at every hit, at the sizes
    /// of [`Self::new`].
    pub fn specular(profile: Profile, law: FresnelLaw, roughness: f64) -> Self {
        WallTableParams {
            walls: WallKind::Specular { law },
            ..Self::new(profile, 1.0, roughness)
        }
    }

    /// Paths traced in all: [`Self::paths`] per incident direction and side.
    pub fn total_paths(&self) -> u64 {
        let directions = (self.theta_bins * self.phi_bins * self.walls.sides().len()) as u64;
        directions.saturating_mul(self.paths)
    }

    /// The memory [`WallTable::compute`] and [`WallTable::save`] take on `threads` threads: 64
    /// bytes per cell of the table (`Bt Bp Bo B` cells of four `f64` lobes, held once as the
    /// traced directions' results, whose many small blocks the allocator keeps after they are
    /// freed, and once as the table, which `save` writes without a copy), and per thread 96
    /// bytes per `B x B` exit bin (up to five of the groove tracer's accumulators, 16 bytes a
    /// bin as for `striae gonio`, and a trace's output). Measured as the peak resident size
    /// (`/usr/bin/time -f %M`) of `striae precompute --walls dielectric`: with `--roughness 0.3
    /// --exit-bins 64 --wall-paths 50`, 269 MB at `--incident 32x32` and 531 MB at `32x64`
    /// (64.1 bytes a cell between them); with `--incident 2x2 --exit-bins 1024 --wall-paths
    /// 200000`, 56, 122 and 277 MB on 1, 2 and 4 threads (66 MB, 63 bytes a bin, a thread).
    pub fn memory_estimate(&self, threads: usize) -> u64 {
        let cells = (self.theta_bins * self.phi_bins * self.exit_rows()) as u64 * self.bins as u64;
        let bins2 = (self.bins as u64).pow(2);
        (64 * cells).saturating_add(96 * bins2 * threads as u64)
    }

    /// The walls in words, for titles and reports.
    pub fn walls_label(&self) -> String {
        match self.walls {
            WallKind::Dielectric => format!("dielectric walls, ior {}", self.ior),
            WallKind::Specular { law } => format!("specular walls, Fresnel {law:?}"),
        }
    }

    /// The trace settings for one incident direction and side.
    fn settings(&self, theta_i: f64, phi_i: f64, side: LightSide) -> GonioSettings {
        let (walls, fresnel_law) = match self.walls {
            WallKind::Dielectric => (
                GrooveWalls::Dielectric,
                GonioSettings::default().fresnel_law,
            ),
            WallKind::Specular { law } => (GrooveWalls::Specular, law),
        };
        GonioSettings {
            walls,
            fresnel_law,
            roughness: self.roughness,
            single_scatter: self.single_scatter,
            ior: self.ior,
            theta_i,
            phi_i,
            side,
            // Seen from inside, a groove is a ridge that meets light aimed beside its opening
            // too: the inside lobes are per unit of the light it intercepts.
            beside: side == LightSide::Inside && self.walls == WallKind::Dielectric,
            paths: self.paths,
            bins: self.bins,
            seed: self.seed,
            ..GonioSettings::default()
        }
    }

    /// Reject what the tracer cannot honour (errors name the key) and empty grids.
    pub fn validate(&self) -> Result<(), GonioError> {
        for (key, n) in [("theta-bins", self.theta_bins), ("phi-bins", self.phi_bins)] {
            if !(1..=256).contains(&n) {
                return Err(GonioError {
                    key,
                    value: n.to_string(),
                    why: "must be in 1..=256",
                });
            }
        }
        if matches!(self.walls, WallKind::Specular { .. }) && self.roughness == 0.0 {
            return Err(GonioError {
                key: "roughness",
                value: self.roughness.to_string(),
                why:
                    "specular-wall tables have rough walls, in (0, 1] (mirror walls: the 2D table)",
            });
        }
        let side = *self.walls.sides().last().expect("a side");
        self.settings(0.0, 0.0, side).validate()
    }

    /// A SHA-256 of every parameter, naming the table in the cache ([`Self::hash_text`]).
    pub fn hash(&self) -> String {
        let d = Sha256::digest(self.hash_text().as_bytes());
        d.iter().map(|b| format!("{b:02x}")).collect()
    }

    /// How rough walls scatter, as the `wall_scattering` array of a table file names it.
    pub fn scattering_name(&self) -> &'static str {
        if self.single_scatter {
            "single"
        } else {
            "microsurface-walk"
        }
    }

    /// The text [`Self::hash`] digests: the kind, the profile, the walls (dielectric: the
    /// index and `beside-reflected`, their inside lobes being per intercepted light, beside the
    /// opening on the way to the surface and after total internal reflection there; specular:
    /// the law; rough: how they scatter), the roughness, the sizes, the paths and the seed.
    pub fn hash_text(&self) -> String {
        let mut walls = match self.walls {
            WallKind::Dielectric => format!("{:016x}|beside-reflected", self.ior.to_bits()),
            WallKind::Specular { law } => format!("law {}", law_json(&law)),
        };
        if self.roughness > 0.0 {
            walls = format!("{walls}|{}", self.scattering_name());
        }
        format!(
            "{}|{:?}|{:?}|{walls}|{:016x}|{}|{}|{}|{}|{}",
            self.walls.name(),
            self.profile.spec,
            self.profile.points,
            self.roughness.to_bits(),
            self.theta_bins,
            self.phi_bins,
            self.bins,
            self.paths,
            self.seed
        )
    }
}

/// A Fresnel law as the JSON of the 2D tables' parameters (floats written to round-trip).
fn law_json(law: &FresnelLaw) -> String {
    serde_json::to_string(law).expect("a Fresnel law serialises")
}

/// Bin centres of `n` bins over `(-pi/2, pi/2)`.
pub fn centres(n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| -PI / 2.0 + (k as f64 + 0.5) * PI / n as f64)
        .collect()
}

/// Bilinear weights at `x` between the [`centres`] of `n` bins: the two neighbouring centres
/// and their weights, clamped to the first and last centre.
pub fn grid_weights(n: usize, x: f64) -> [(usize, f64); 2] {
    if n == 1 {
        return [(0, 1.0), (0, 0.0)];
    }
    let f = ((x + PI / 2.0) / (PI / n as f64) - 0.5).clamp(0.0, (n - 1) as f64);
    let i = (f.floor() as usize).min(n - 2);
    let w = f - i as f64;
    [(i, 1.0 - w), (i + 1, w)]
}

/// The exit `theta_o` of lobe `l` ([`LOBES`]) for smooth walls at incident `theta_i`: `beta = n
/// w.y` is conserved (METHOD.md 8.1), so reflection gives `-theta_i`, transmission into the
/// glass `-asin(sin theta_i / n)` and out of it `-asin(n sin theta_i)` (clamped at grazing,
/// where total internal reflection leaves no transmitted light).
pub fn exit_theta(l: usize, theta_i: f64, n: f64) -> f64 {
    let s = theta_i.sin();
    match l {
        1 => -(s / n).asin(),
        3 => -(n * s).clamp(-1.0, 1.0).asin(),
        _ => -theta_i,
    }
}

/// The default `phi_o` bins of smooth walls' marginals (the module notes).
pub const SMOOTH_EXIT_BINS: usize = 128;

/// The four lobes, in the order of the file: R and T from outside, R and T from inside.
pub const LOBES: [&str; 4] = ["r_out", "t_out", "r_in", "t_in"];

/// A computed wall table.
#[derive(Clone, Debug)]
pub struct WallTable {
    pub params: WallTableParams,
    pub theta_i: Vec<f64>,
    pub phi_i: Vec<f64>,
    /// Exit bin centres: `Bo` rows of `theta_o` ([`WallTableParams::exit_rows`]), `B` of `phi_o`.
    pub theta_o: Vec<f64>,
    pub phi_o: Vec<f64>,
    /// `lobes[l][((ti * Bp + pi) * Bo + to) * B + po]`, `l` as [`LOBES`]; the inside lobes
    /// per unit of the light the groove intercepts (through its opening and beside it).
    pub lobes: [Vec<f64>; 4],
    /// `[ti * Bp + pi]`: the light a groove intercepts from inside per unit crossing its
    /// opening (`GonioOutput::intercept`: at least 1 up to its Monte Carlo error); 1 for opaque
    /// walls and files without it.
    pub intercept: Vec<f64>,
}

impl WallTable {
    /// Trace every incident direction of the grid from each side of the walls' kind.
    pub fn compute(params: &WallTableParams) -> Result<Self, GonioError> {
        Self::compute_with(params, &|_| {})
    }

    /// [`Self::compute`], calling `progress(paths)` from worker threads as paths finish (of
    /// [`WallTableParams::total_paths`] in all).
    pub fn compute_with(
        params: &WallTableParams,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Result<Self, GonioError> {
        params.validate()?;
        let (theta_i, phi_i) = (centres(params.theta_bins), centres(params.phi_bins));
        let sides = params.walls.sides();
        let jobs: Vec<(usize, usize, LightSide)> = (0..theta_i.len())
            .flat_map(|t| (0..phi_i.len()).flat_map(move |p| sides.iter().map(move |&s| (t, p, s))))
            .collect();
        let (rows, b) = (params.exit_rows(), params.bins);
        // Each run is parallel inside; runs are many and short, so run them in parallel too.
        let outs = jobs
            .par_iter()
            .map(|&(t, p, side)| {
                let out = trace_groove(
                    &params.profile,
                    &params.settings(theta_i[t], phi_i[p], side),
                    progress,
                )?;
                let k = out.intercept.unwrap_or(1.0);
                let lobes = [out.reflected, out.transmitted].map(|h| {
                    let h = if rows == 1 { phi_marginal(&h, b) } else { h };
                    h.into_iter().map(|m| m / k).collect::<Vec<_>>()
                });
                Ok((lobes, k))
            })
            .collect::<Result<Vec<_>, GonioError>>()?;
        let len = theta_i.len() * phi_i.len() * rows * b;
        let mut lobes: [Vec<f64>; 4] = std::array::from_fn(|_| Vec::with_capacity(len));
        let mut intercept = vec![1.0; theta_i.len() * phi_i.len()];
        for (&(t, p, side), ([r, tr], k)) in jobs.iter().zip(&outs) {
            let base = if side == LightSide::Outside { 0 } else { 2 };
            lobes[base].extend_from_slice(r);
            lobes[base + 1].extend_from_slice(tr);
            if side == LightSide::Inside {
                intercept[t * phi_i.len() + p] = *k;
            }
        }
        // Opaque walls: the lobes no side fills (and `t_out`, nothing through metal) are zero.
        for lobe in &mut lobes[params.walls.lobe_count()..] {
            *lobe = vec![0.0; len];
        }
        Ok(WallTable {
            params: params.clone(),
            theta_o: centres(rows),
            phi_o: centres(b),
            theta_i,
            phi_i,
            lobes,
            intercept,
        })
    }

    /// The `Bo x B` histogram of lobe `l` at incident grid point `(t, p)`.
    pub fn slice(&self, l: usize, t: usize, p: usize) -> &[f64] {
        let n = self.theta_o.len() * self.phi_o.len();
        let k = (t * self.phi_i.len() + p) * n;
        &self.lobes[l][k..k + n]
    }

    /// The four lobes at incident `(theta_i, phi_i)` into `out[l]` (each `B x B`): bilinear in
    /// `(theta_i, phi_i)` between the grid's centres (clamped at its edges), each slice first
    /// moved along `theta_o` by the change of its smooth-wall exit angle ([`exit_theta`]), so
    /// that the peak of nearly smooth walls lands where it belongs instead of being split
    /// between the two slices' places (displacement interpolation). Smooth walls' marginals go
    /// to the row of their exact exit `theta_o`.
    pub fn lobes_at(&self, theta_i: f64, phi_i: f64, out: &mut [Vec<f64>; 4]) {
        let (wt, wp) = (
            grid_weights(self.theta_i.len(), theta_i),
            grid_weights(self.phi_i.len(), phi_i),
        );
        let b = self.params.bins;
        let bin = PI / b as f64;
        let n = self.params.ior;
        for (l, o) in out.iter_mut().enumerate() {
            o.clear();
            o.resize(b * b, 0.0);
            if self.params.smooth() {
                let row = (((exit_theta(l, theta_i, n) + PI / 2.0) / bin) as usize).min(b - 1);
                for &(t, a) in &wt {
                    for &(p, c) in &wp {
                        let dst = &mut o[row * b..(row + 1) * b];
                        for (x, y) in dst.iter_mut().zip(self.slice(l, t, p)) {
                            *x += a * c * y;
                        }
                    }
                }
                continue;
            }
            for &(t, a) in &wt {
                let shift = (exit_theta(l, theta_i, n) - exit_theta(l, self.theta_i[t], n)) / bin;
                let (whole, frac) = (shift.floor(), shift - shift.floor());
                for &(p, c) in &wp {
                    if a * c == 0.0 {
                        continue;
                    }
                    let slice = self.slice(l, t, p);
                    for (row, src) in slice.chunks_exact(b).enumerate() {
                        // Row `row` moves to `row + shift`: split between two rows, clamped.
                        let to = row as f64 + whole;
                        for (k, f) in [(to, 1.0 - frac), (to + 1.0, frac)] {
                            let k = k.clamp(0.0, (b - 1) as f64) as usize;
                            let wgt = a * c * f;
                            for (x, y) in o[k * b..(k + 1) * b].iter_mut().zip(src) {
                                *x += wgt * y;
                            }
                        }
                    }
                }
            }
        }
    }

    /// Write the table as `.npz` (atomically; the arrays of the module notes).
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        let p = &self.params;
        let shape = (
            self.theta_i.len(),
            self.phi_i.len(),
            self.theta_o.len(),
            p.bins,
        );
        let err = |e: ndarray_npy::WriteNpzError| std::io::Error::other(e.to_string());
        // Views of the lobes, not copies: a copy would double the table's memory.
        let arrays = self.lobes[..p.walls.lobe_count()]
            .iter()
            .map(|v| ArrayView4::from_shape(shape, v).map_err(std::io::Error::other))
            .collect::<Result<Vec<_>, _>>()?;
        crate::io::write_atomically(path, |tmp| {
            let file = std::fs::File::create(tmp)?;
            let mut w = NpzWriter::new(std::io::BufWriter::new(file));
            let text = |s: &str| Array1::from(s.bytes().collect::<Vec<u8>>());
            w.add_array("kind", &text(p.walls.name())).map_err(err)?;
            if let WallKind::Specular { law } = p.walls {
                w.add_array("fresnel_law", &text(&law_json(&law)))
                    .map_err(err)?;
            }
            w.add_array("profile", &text(&p.profile.spec))
                .map_err(err)?;
            w.add_array("ior", &arr0(p.ior)).map_err(err)?;
            w.add_array("roughness", &arr0(p.roughness)).map_err(err)?;
            if p.roughness > 0.0 {
                w.add_array("wall_scattering", &text(p.scattering_name()))
                    .map_err(err)?;
            }
            w.add_array("paths", &arr0(p.paths)).map_err(err)?;
            w.add_array("seed", &arr0(p.seed)).map_err(err)?;
            w.add_array("theta_i", &Array1::from(self.theta_i.clone()))
                .map_err(err)?;
            w.add_array("phi_i", &Array1::from(self.phi_i.clone()))
                .map_err(err)?;
            w.add_array("theta_o", &Array1::from(self.theta_o.clone()))
                .map_err(err)?;
            w.add_array("phi_o", &Array1::from(self.phi_o.clone()))
                .map_err(err)?;
            for (name, a) in LOBES.iter().zip(&arrays) {
                w.add_array(*name, a).map_err(err)?;
            }
            if p.walls == WallKind::Dielectric {
                let k = Array2::from_shape_vec(
                    (self.theta_i.len(), self.phi_i.len()),
                    self.intercept.clone(),
                )
                .map_err(std::io::Error::other)?;
                w.add_array("intercept_in", &k).map_err(err)?;
            }
            w.finish().map_err(err)?;
            Ok(())
        })
    }

    /// Read a table written by [`Self::save`]; `None` where the file is not a wall table (no
    /// `kind` array saying so), an error where it is one but unreadable, or holds values no
    /// trace can give (negative or non-finite fractions, more energy out than in). Smooth
    /// walls' full `B x B` lobes are read as their `phi_o` marginals.
    pub fn load(path: &Path) -> std::io::Result<Option<Self>> {
        use ndarray::{Array0, Ix0, Ix1, OwnedRepr};
        let Some((mut r, kind)) = open_kind(path)? else {
            return Ok(None);
        };
        let err = |e: ndarray_npy::ReadNpzError| std::io::Error::other(e.to_string());
        check_keys(&r.names().map_err(err)?, &kind)?;
        let walls = match kind.as_str() {
            "specular-walls" => {
                let json = read_text(&mut r, "fresnel_law")?;
                let law = serde_json::from_str(&json)
                    .map_err(|e| std::io::Error::other(format!("`fresnel_law` {json:?}: {e}")))?;
                WallKind::Specular { law }
            }
            _ => WallKind::Dielectric,
        };
        let spec = read_text(&mut r, "profile")?;
        let profile = Profile::parse(&spec).map_err(|e| std::io::Error::other(e.to_string()))?;
        let mut f64s = |k: &str| -> std::io::Result<f64> {
            let a: Array0<f64> = r.by_name::<OwnedRepr<f64>, Ix0>(k).map_err(err)?;
            Ok(a.into_scalar())
        };
        let (ior, roughness) = (f64s("ior")?, f64s("roughness")?);
        let single_scatter = read_scattering(&mut r, roughness)?;
        if matches!(walls, WallKind::Specular { .. }) && ior != 1.0 {
            return Err(std::io::Error::other(format!(
                "`ior` is {ior}: a specular-walls table has no index (its walls' law is \
                 `fresnel_law`), it stores 1"
            )));
        }
        let mut u64s = |k: &str| -> std::io::Result<u64> {
            let a: Array0<u64> = r.by_name::<OwnedRepr<u64>, Ix0>(k).map_err(err)?;
            Ok(a.into_scalar())
        };
        let (paths, seed) = (u64s("paths")?, u64s("seed")?);
        let mut vec = |k: &str| -> std::io::Result<Vec<f64>> {
            let a: Array1<f64> = r.by_name::<OwnedRepr<f64>, Ix1>(k).map_err(err)?;
            Ok(a.to_vec())
        };
        let (theta_i, phi_i) = (vec("theta_i")?, vec("phi_i")?);
        let (theta_o, phi_o) = (vec("theta_o")?, vec("phi_o")?);
        let bad = std::io::Error::other;
        // Lookups find grid points from the bin counts: the grids must be the bins' centres.
        for (name, grid) in [
            ("theta_i", &theta_i),
            ("phi_i", &phi_i),
            ("theta_o", &theta_o),
            ("phi_o", &phi_o),
        ] {
            let want = centres(grid.len());
            if want
                .iter()
                .zip(grid.iter())
                .any(|(a, b)| (a - b).abs() > 1e-9)
            {
                return Err(bad(format!(
                    "`{name}` is not the centres of {} equal bins over (-pi/2, pi/2)",
                    grid.len()
                )));
            }
        }
        let params = WallTableParams {
            profile,
            walls,
            ior,
            roughness,
            single_scatter,
            theta_bins: theta_i.len(),
            phi_bins: phi_i.len(),
            bins: phi_o.len(),
            paths,
            seed,
        };
        params
            .validate()
            .map_err(|e| bad(format!("bad parameters: {e}")))?;
        let rows = params.exit_rows();
        if theta_o.len() != rows && theta_o.len() != phi_o.len() {
            return Err(bad(format!(
                "`theta_o` has {} bins: {rows} or as many as `phi_o` ({}) for these walls",
                theta_o.len(),
                phi_o.len()
            )));
        }
        let shape = (theta_i.len(), phi_i.len(), theta_o.len(), phi_o.len());
        let mut lobes: [Vec<f64>; 4] = std::array::from_fn(|_| Vec::new());
        for (l, (name, lobe)) in LOBES.iter().zip(&mut lobes).enumerate() {
            let full = if l < walls.lobe_count() {
                read_lobe(&mut r, name, shape)?
            } else {
                vec![0.0; shape.0 * shape.1 * shape.2 * shape.3]
            };
            *lobe = if shape.2 == rows {
                full
            } else {
                full.chunks_exact(shape.2 * shape.3)
                    .flat_map(|h| phi_marginal(h, shape.3))
                    .collect()
            };
        }
        let intercept = read_intercept(&mut r, (shape.0, shape.1))?;
        let table = WallTable {
            params,
            theta_i,
            phi_i,
            theta_o: centres(rows),
            phi_o,
            lobes,
            intercept,
        };
        table.check_energy().map_err(bad)?;
        Ok(Some(table))
    }

    /// Every incident direction's R + T from either side is at most 1 (lossless walls give
    /// exactly 1; a rounding margin of `1e-6`).
    fn check_energy(&self) -> Result<(), String> {
        for t in 0..self.theta_i.len() {
            for p in 0..self.phi_i.len() {
                for side in [0, 2] {
                    let e: f64 = [side, side + 1]
                        .iter()
                        .map(|&l| self.slice(l, t, p).iter().sum::<f64>())
                        .sum();
                    if e > 1.0 + 1e-6 {
                        return Err(format!(
                            "`{}` + `{}` at incident ({t}, {p}) send out {e} of the energy that arrives",
                            LOBES[side],
                            LOBES[side + 1]
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// The table against a fresh exact trace at incident `(theta_i, phi_i)` (off the grid, with
    /// `paths` paths and another seed), per lobe ([`LobeError`]).
    pub fn error_against_trace(
        &self,
        theta_i: f64,
        phi_i: f64,
        paths: u64,
    ) -> Result<[LobeError; 4], GonioError> {
        let mut table = std::array::from_fn(|_| Vec::new());
        self.lobes_at(theta_i, phi_i, &mut table);
        let b = self.params.bins;
        let mut out = [LobeError::default(); 4];
        for (s, side) in self.params.walls.sides().iter().enumerate() {
            let mut set = self.params.settings(theta_i, phi_i, *side);
            set.paths = paths;
            set.seed = self.params.seed ^ 0x005e_ed0f_7e57;
            let exact = trace_groove(&self.params.profile, &set, &|_| {})?;
            // Per unit of intercepted light, as the table's inside lobes.
            let per = 1.0 / exact.intercept.unwrap_or(1.0);
            for (k, hist) in [&exact.reflected, &exact.transmitted].iter().enumerate() {
                let l = 2 * s + k;
                let theirs: Vec<f64> = hist.iter().map(|m| m * per).collect();
                let (mine, theirs) = (&table[l], &theirs[..]);
                let mean_theta = |h: &[f64]| {
                    let e: f64 = h.iter().sum();
                    let m: f64 = h
                        .chunks_exact(b)
                        .zip(&centres(b))
                        .map(|(r, t)| r.iter().sum::<f64>() * t)
                        .sum();
                    if e > 0.0 {
                        m / e
                    } else {
                        0.0
                    }
                };
                let (ea, eb) = (mine.iter().sum::<f64>(), theirs.iter().sum::<f64>());
                out[l] = LobeError {
                    albedo: ea - eb,
                    l1: mine.iter().zip(theirs).map(|(x, y)| (x - y).abs()).sum(),
                    phi_l1: phi_marginal(mine, b)
                        .iter()
                        .zip(phi_marginal(theirs, b))
                        .map(|(x, y)| (x - y).abs())
                        .sum(),
                    theta_shift: if ea > 1e-3 && eb > 1e-3 {
                        mean_theta(mine) - mean_theta(theirs)
                    } else {
                        0.0
                    },
                };
            }
        }
        Ok(out)
    }
}

/// The `phi_o` marginal of a histogram of rows of `b` `phi_o` bins (the column sums).
fn phi_marginal(h: &[f64], b: usize) -> Vec<f64> {
    (0..b).map(|j| h.iter().skip(j).step_by(b).sum()).collect()
}

type Reader = ndarray_npy::NpzReader<std::fs::File>;

/// A rough table's `wall_scattering`: `microsurface-walk`, or `single` (also where the array
/// is absent: files written before the walk); smooth tables have none.
fn read_scattering(r: &mut Reader, roughness: f64) -> std::io::Result<bool> {
    let present = r
        .names()
        .map_err(|e| std::io::Error::other(e.to_string()))?
        .iter()
        .any(|n| n.strip_suffix(".npy").unwrap_or(n) == "wall_scattering");
    if !present {
        return Ok(roughness > 0.0);
    }
    match read_text(r, "wall_scattering")?.as_str() {
        _ if roughness == 0.0 => Err(std::io::Error::other(
            "`wall_scattering` in a table of smooth walls (roughness 0), which scatter once",
        )),
        "microsurface-walk" => Ok(false),
        "single" => Ok(true),
        other => Err(std::io::Error::other(format!(
            "`wall_scattering` is {other:?}: \"microsurface-walk\" or \"single\""
        ))),
    }
}

/// The arrays of every wall table; [`LOBES`] and `intercept_in` beside them for dielectric
/// walls, `fresnel_law` and `r_out` for specular ones.
const COMMON_KEYS: [&str; 10] = [
    "kind",
    "profile",
    "ior",
    "roughness",
    "paths",
    "seed",
    "theta_i",
    "phi_i",
    "theta_o",
    "phi_o",
];

/// Refuse an array that a table of `kind` does not hold (an unknown key, or a lobe its walls
/// cannot have: `t_out` in a specular-walls table), naming it.
fn check_keys(names: &[String], kind: &str) -> std::io::Result<()> {
    let own: &[&str] = match kind {
        "specular-walls" => &["fresnel_law", "r_out", "wall_scattering"],
        _ => &[
            "r_out",
            "t_out",
            "r_in",
            "t_in",
            "intercept_in",
            "wall_scattering",
        ],
    };
    let name = |n: &String| n.strip_suffix(".npy").unwrap_or(n).to_string();
    match names
        .iter()
        .map(name)
        .find(|n| !COMMON_KEYS.contains(&n.as_str()) && !own.contains(&n.as_str()))
    {
        Some(key) => Err(std::io::Error::other(format!(
            "key `{key}` is not an array of a {kind} table (docs/table-format.md)"
        ))),
        None => Ok(()),
    }
}

/// Whether an `.npz`'s array names (`NpzReader::names`) hold `key`.
fn holds(names: &[String], key: &str) -> bool {
    names
        .iter()
        .any(|n| n.strip_suffix(".npy").unwrap_or(n) == key)
}

/// The file as an `.npz` reader, and its kind, when its `kind` array says it is a wall table.
/// Every entry's declared size is checked against the bytes it holds before anything is
/// decoded ([`crate::precompute::table`]'s check: a hostile header is an error, not a huge
/// allocation).
fn open_kind(path: &Path) -> std::io::Result<Option<(Reader, String)>> {
    use ndarray_npy::NpzReader;
    use std::io::Seek;
    let err = |e: ndarray_npy::ReadNpzError| std::io::Error::other(e.to_string());
    let mut file = crate::io::open_regular(path, crate::io::MAX_BINARY_BYTES)?;
    check_npz_sizes(&file).map_err(std::io::Error::other)?;
    file.rewind()?;
    let mut r = NpzReader::new(file).map_err(err)?;
    let names = r.names().map_err(err)?;
    if !holds(&names, "kind") {
        return Ok(None);
    }
    let kind = read_text(&mut r, "kind")?;
    Ok(matches!(kind.as_str(), "dielectric-walls" | "specular-walls").then_some((r, kind)))
}

/// One lobe array of the file, of the grids' `shape`, every value finite and `>= 0`.
fn read_lobe(
    r: &mut Reader,
    name: &str,
    shape: (usize, usize, usize, usize),
) -> std::io::Result<Vec<f64>> {
    use ndarray::{Ix4, OwnedRepr};
    let bad = std::io::Error::other;
    let a: Array4<f64> = r
        .by_name::<OwnedRepr<f64>, Ix4>(name)
        .map_err(|e| bad(e.to_string()))?;
    if a.dim() != shape {
        return Err(bad(format!(
            "`{name}` has shape {:?}, the grids ask for {shape:?}",
            a.dim()
        )));
    }
    if let Some((i, v)) = a
        .iter()
        .enumerate()
        .find(|(_, v)| !(**v >= 0.0 && v.is_finite()))
    {
        return Err(bad(format!("`{name}` holds {v} at flat index {i}")));
    }
    Ok(a.iter().copied().collect())
}

/// `intercept_in` of the file, `[Bt, Bp]`, each finite and positive; all 1 where the file
/// has none (opaque walls, or a table traced through the opening only).
fn read_intercept(r: &mut Reader, shape: (usize, usize)) -> std::io::Result<Vec<f64>> {
    use ndarray::{Ix2, OwnedRepr};
    let err = |e: ndarray_npy::ReadNpzError| std::io::Error::other(e.to_string());
    if !holds(&r.names().map_err(err)?, "intercept_in") {
        return Ok(vec![1.0; shape.0 * shape.1]);
    }
    let a: Array2<f64> = r
        .by_name::<OwnedRepr<f64>, Ix2>("intercept_in")
        .map_err(err)?;
    if a.dim() != shape {
        return Err(std::io::Error::other(format!(
            "`intercept_in` has shape {:?}, the grids ask for {shape:?}",
            a.dim()
        )));
    }
    if let Some(k) = a.iter().find(|k| !(k.is_finite() && **k > 0.0)) {
        return Err(std::io::Error::other(format!(
            "`intercept_in` holds {k}: an intercept is positive"
        )));
    }
    Ok(a.iter().copied().collect())
}

/// A text array (bytes) of the file.
fn read_text(r: &mut Reader, key: &str) -> std::io::Result<String> {
    use ndarray::{Ix1, OwnedRepr};
    let a: Array1<u8> = r
        .by_name::<OwnedRepr<u8>, Ix1>(key)
        .map_err(|e| std::io::Error::other(e.to_string()))?;
    String::from_utf8(a.to_vec()).map_err(std::io::Error::other)
}

/// Whether `path` is an `.npz` whose `kind` says it is a wall table (its other arrays
/// unread).
pub fn declares_kind(path: &Path) -> bool {
    matches!(open_kind(path), Ok(Some(_)))
}

/// A lobe of the table against the exact trace ([`WallTable::error_against_trace`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LobeError {
    /// Albedo, table less trace.
    pub albedo: f64,
    /// L1 distance of the `B x B` histograms (fractions of the incident energy, at most 2;
    /// a delta one bin off counts 2).
    pub l1: f64,
    /// L1 distance of the `phi_o` marginals.
    pub phi_l1: f64,
    /// Mean `theta_o` (radians), table less trace (where both lobes hold energy).
    pub theta_shift: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small(roughness: f64) -> WallTable {
        let p = WallTableParams {
            theta_bins: 3,
            phi_bins: 4,
            bins: 8,
            paths: 4000,
            ..WallTableParams::new(Profile::parse("round:depth=0.5").unwrap(), 1.5, roughness)
        };
        WallTable::compute(&p).unwrap()
    }

    /// A lossless groove reflects plus transmits what arrives, from either side, at every
    /// incident direction of the grid: smooth walls to round-off, rough walls walking their
    /// microsurface within 1e-3 (METHOD.md 9.7); rough walls scattering once lose light.
    #[test]
    fn lossless_groove_conserves_energy() {
        let mut single = WallTableParams {
            single_scatter: true,
            ..small(0.3).params
        };
        single.paths = 4000;
        let single = WallTable::compute(&single).unwrap();
        for t in [small(0.0), small(0.3), single] {
            let mut worst = 1.0f64;
            for ti in 0..t.theta_i.len() {
                for pi in 0..t.phi_i.len() {
                    for side in [0, 2] {
                        let r: f64 = t.slice(side, ti, pi).iter().sum();
                        let tr: f64 = t.slice(side + 1, ti, pi).iter().sum();
                        let p = &t.params;
                        let tolerance = if p.roughness == 0.0 { 1e-6 } else { 1e-3 };
                        assert!(
                            p.single_scatter || (r + tr - 1.0).abs() < tolerance,
                            "{p:?} side {side} ({ti}, {pi}): R {r} + T {tr}"
                        );
                        worst = worst.min(r + tr);
                    }
                }
            }
            if t.params.single_scatter {
                assert!(worst < 0.95, "single scattering loses light: {worst}");
            }
        }
    }

    #[test]
    fn save_load_round_trip_and_plot() {
        let t = small(0.2);
        let dir = std::env::temp_dir().join(format!("striae-walls-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("w.npz");
        t.save(&path).unwrap();
        let back = WallTable::load(&path).unwrap().unwrap();
        assert_eq!(back.params, t.params);
        assert_eq!(back.lobes, t.lobes);
        assert_eq!(back.intercept, t.intercept);
        assert!(t.intercept.iter().any(|&k| k > 1.01), "{:?}", t.intercept);
        // Scattering once is another table, and the file says so.
        let mut single = t.clone();
        single.params.single_scatter = true;
        single.save(&dir.join("single.npz")).unwrap();
        let back = WallTable::load(&dir.join("single.npz")).unwrap().unwrap();
        assert!(back.params.single_scatter);
        assert_ne!(back.params.hash(), t.params.hash());
        // Grids that are not the bins' centres are refused (lookups assume them).
        let mut odd = t.clone();
        odd.phi_i[1] += 0.01;
        odd.save(&dir.join("odd.npz")).unwrap();
        let e = WallTable::load(&dir.join("odd.npz"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`phi_i`"), "{e}");
        crate::lab::plot::plot_wall_table(&t, 0.3, -0.2, &dir.join("w.png")).unwrap();
        let img = image::open(dir.join("w.png")).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (1500, 1400));
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Rough specular walls: one lobe traced (R from outside), the others zero; the file says
    /// its kind and law and reads back the same table; it plots; mirror walls are refused.
    #[test]
    fn specular_walls_round_trip() {
        let law = FresnelLaw::Conductor {
            eta: 0.1431189626455307,
            k: 3.9831604957580566,
        };
        let p = WallTableParams {
            theta_bins: 2,
            phi_bins: 3,
            bins: 8,
            paths: 2000,
            ..WallTableParams::specular(Profile::parse("v:angle=100").unwrap(), law, 0.3)
        };
        let t = WallTable::compute(&p).unwrap();
        assert!(t.lobes[0].iter().sum::<f64>() > 0.5);
        assert!(t.lobes[1..].iter().all(|l| l.iter().all(|&m| m == 0.0)));
        let dir = std::env::temp_dir().join(format!("striae-spec-walls-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("s.npz");
        t.save(&path).unwrap();
        assert!(declares_kind(&path));
        let back = WallTable::load(&path).unwrap().unwrap();
        assert_eq!(back.params, t.params);
        assert_eq!(back.params.hash(), p.hash());
        assert_eq!(back.lobes, t.lobes);
        let err = back.error_against_trace(0.3, -0.2, 2000).unwrap();
        assert!(
            err[0].albedo.abs() < 0.05 && err[1..].iter().all(|e| e.l1 == 0.0),
            "{err:?}"
        );
        crate::lab::plot::plot_wall_table(&t, 0.3, -0.2, &dir.join("s.png")).unwrap();
        assert!(image::open(dir.join("s.png")).is_ok());
        std::fs::remove_dir_all(&dir).ok();
        // Another law or kind is another table.
        let none = WallTableParams::specular(p.profile.clone(), FresnelLaw::None, 0.3);
        let glass = WallTableParams::new(p.profile.clone(), 1.0, 0.3);
        assert_ne!(
            none.hash(),
            WallTableParams {
                walls: p.walls,
                ..none.clone()
            }
            .hash()
        );
        assert_ne!(
            glass.hash(),
            WallTableParams {
                walls: none.walls,
                ..glass.clone()
            }
            .hash()
        );
        let mirror = WallTableParams::specular(p.profile.clone(), law, 0.0);
        assert_eq!(mirror.validate().unwrap_err().key, "roughness");
    }

    /// A dielectric table's hash digests every parameter and says that its inside lobes are
    /// per intercepted light, the light the flat surface reflects into the groove included
    /// (`beside-reflected`), so tables traced otherwise are not taken from the cache for it.
    #[test]
    fn dielectric_hash_text() {
        let p = WallTableParams {
            theta_bins: 8,
            phi_bins: 16,
            bins: 32,
            paths: 20_000,
            ..WallTableParams::new(Profile::parse("v:depth=0.5").unwrap(), 1.5, 0.0)
        };
        assert_eq!(
            p.hash_text(),
            "dielectric-walls|\"v:depth=0.5\"|[[-0.5, 0.0], [0.0, -0.5], [0.5, 0.0]]|\
             3ff8000000000000|beside-reflected|0000000000000000|8|16|32|20000|0"
        );
        let d = Sha256::digest(p.hash_text().as_bytes());
        assert_eq!(p.hash(), format!("{d:x}"));
    }

    /// Smooth walls keep the `phi_o` marginal of the traced histogram (one row); a lookup at a
    /// grid point puts it at the row of the exact exit `theta_o`, where the trace has it.
    #[test]
    fn smooth_walls_keep_the_traced_marginal() {
        let t = small(0.0);
        let b = t.params.bins;
        assert_eq!((t.theta_o.len(), t.phi_o.len()), (1, b));
        let (ti, pi) = (1, 2);
        let mut out = std::array::from_fn(|_| Vec::new());
        t.lobes_at(t.theta_i[ti], t.phi_i[pi], &mut out);
        for side in [LightSide::Outside, LightSide::Inside] {
            let set = t.params.settings(t.theta_i[ti], t.phi_i[pi], side);
            let exact = trace_groove(&t.params.profile, &set, &|_| {}).unwrap();
            let base = if side == LightSide::Outside { 0 } else { 2 };
            // Inside: per unit of the light the groove intercepts.
            let k = exact.intercept.unwrap_or(1.0);
            if side == LightSide::Inside {
                assert_eq!(k, t.intercept[ti * t.phi_i.len() + pi]);
            }
            let hists = [&exact.reflected, &exact.transmitted]
                .map(|h| h.iter().map(|m| m / k).collect::<Vec<_>>());
            for (k, hist) in hists.iter().enumerate() {
                let l = base + k;
                let marginal = phi_marginal(hist, b);
                assert_eq!(t.slice(l, ti, pi), &marginal[..], "lobe {l}");
                // Every traced path leaves in one `theta_o` row, the exact exit angle's.
                let row = (((exit_theta(l, t.theta_i[ti], 1.5) + PI / 2.0) / (PI / b as f64))
                    as usize)
                    .min(b - 1);
                let rows: Vec<f64> = hist.chunks_exact(b).map(|r| r.iter().sum()).collect();
                let total: f64 = rows.iter().sum();
                assert!(
                    (rows[row] - total).abs() < 1e-9 * total.max(1.0),
                    "lobe {l}"
                );
                for (j, (x, y)) in out[l].iter().zip(hist.iter()).enumerate() {
                    assert!((x - y).abs() < 1e-12, "lobe {l} bin {j}: {x} against {y}");
                }
            }
        }
    }

    /// A file holding smooth walls' full `B x B` lobes reads back as the same table.
    #[test]
    fn full_smooth_lobes_read_as_marginals() {
        let t = small(0.0);
        let mut full = t.clone();
        let b = t.params.bins;
        full.theta_o = centres(b);
        // Each marginal spread over the rows; its column sums are unchanged.
        full.lobes = t.lobes.clone().map(|lobe| {
            lobe.chunks_exact(b)
                .flat_map(|m| {
                    (0..b).flat_map(move |r| {
                        m.iter()
                            .map(move |x| x * (r + 1) as f64 * 2.0 / (b * (b + 1)) as f64)
                    })
                })
                .collect()
        });
        let dir = std::env::temp_dir().join(format!("striae-full-walls-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("f.npz");
        full.save(&path).unwrap();
        let back = WallTable::load(&path).unwrap().unwrap();
        assert_eq!(back.params, t.params);
        assert_eq!(back.theta_o, t.theta_o);
        for (x, y) in back.lobes.iter().flatten().zip(t.lobes.iter().flatten()) {
            assert!((x - y).abs() < 1e-12 * y.max(1.0), "{x} against {y}");
        }
        // Rough walls' rows must be all there.
        let rough = small(0.2);
        let mut short = rough.clone();
        short.theta_o = centres(1);
        short.lobes = rough
            .lobes
            .clone()
            .map(|l| rows_of_each(&l, rough.params.bins));
        short.save(&path).unwrap();
        let e = WallTable::load(&path).unwrap_err().to_string();
        assert!(e.contains("`theta_o`"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Copy entry `from` of the `.npz` at `path` into a new entry `to`.
    fn add_entry(path: &Path, from: &str, to: &str) {
        use std::io::{Read, Write};
        let mut bytes = Vec::new();
        zip::ZipArchive::new(std::fs::File::open(path).unwrap())
            .unwrap()
            .by_name(&format!("{from}.npy"))
            .unwrap()
            .read_to_end(&mut bytes)
            .unwrap();
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .unwrap();
        let mut z = zip::ZipWriter::new_append(file).unwrap();
        let stored = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored);
        z.start_file(format!("{to}.npy"), stored).unwrap();
        z.write_all(&bytes).unwrap();
        z.finish().unwrap();
    }

    /// Files whose kind or parameters contradict their arrays, that carry arrays no wall table
    /// has, or whose headers declare more data than they hold, are refused naming the key.
    #[test]
    fn contradicting_unknown_or_hostile_files_are_refused() {
        let dir = std::env::temp_dir().join(format!("striae-bad-walls-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let glass = small(0.2);
        let law = FresnelLaw::Conductor { eta: 0.2, k: 3.9 };
        let metal = WallTable::compute(&WallTableParams {
            theta_bins: 2,
            phi_bins: 2,
            bins: 4,
            paths: 200,
            ..WallTableParams::specular(Profile::parse("v:angle=100").unwrap(), law, 0.3)
        })
        .unwrap();
        let refused = |name: &str, t: &WallTable, edit: &dyn Fn(&Path), key: &str| {
            let path = dir.join(name);
            t.save(&path).unwrap();
            WallTable::load(&path).unwrap().unwrap();
            edit(&path);
            let e = WallTable::load(&path).unwrap_err().to_string();
            assert!(e.contains(&format!("`{key}")), "{name}: {e}");
        };
        // Arrays no wall table holds, or that the kind's walls cannot have.
        refused(
            "extra.npz",
            &glass,
            &|p| add_entry(p, "seed", "extra"),
            "extra",
        );
        refused(
            "t_out.npz",
            &metal,
            &|p| add_entry(p, "r_out", "t_out"),
            "t_out",
        );
        refused(
            "law.npz",
            &glass,
            &|p| add_entry(p, "profile", "fresnel_law"),
            "fresnel_law",
        );
        // A specular-wall table's index is 1: any other contradicts its kind.
        let mut indexed = metal.clone();
        indexed.params.ior = 1.5;
        indexed.save(&dir.join("ior.npz")).unwrap();
        let e = WallTable::load(&dir.join("ior.npz"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("`ior` is 1.5"), "{e}");
        // A lobe's header declaring 80 GB: an error, not an allocation that aborts.
        let huge = |p: &Path| {
            let mut bytes = std::fs::read(p).unwrap();
            let at = |needle: &[u8], from: usize| {
                from + bytes[from..]
                    .windows(needle.len())
                    .position(|w| w == needle)
                    .unwrap()
            };
            let start = at(b"'shape': (3, 4, 8, 8)", 0);
            let end = at(b"\n", start);
            let mut header = b"'shape': (3, 4, 100000, 100000)}".to_vec();
            header.resize(end - start, b' ');
            bytes[start..end].copy_from_slice(&header);
            std::fs::write(p, bytes).unwrap();
        };
        refused(
            "huge.npz",
            &glass,
            &huge,
            "r_out.npy` declares 960000000000 bytes",
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    /// The marginal of each `B x B` slice of a lobe.
    fn rows_of_each(lobe: &[f64], b: usize) -> Vec<f64> {
        lobe.chunks_exact(b * b)
            .flat_map(|h| phi_marginal(h, b))
            .collect()
    }

    /// Interpolation: at a grid point the lookup is the stored slice; and bad parameters name
    /// their key.
    #[test]
    fn lookup_and_validation() {
        let t = small(0.3);
        let mut out = std::array::from_fn(|_| Vec::new());
        t.lobes_at(t.theta_i[1], t.phi_i[2], &mut out);
        for (l, lobe) in out.iter().enumerate() {
            for (a, b) in lobe.iter().zip(t.slice(l, 1, 2)) {
                assert!((a - b).abs() < 1e-12);
            }
        }
        let mut p = t.params.clone();
        p.roughness = 1.5;
        assert_eq!(p.validate().unwrap_err().key, "roughness");
        p.roughness = 0.0;
        p.ior = 0.9;
        assert_eq!(p.validate().unwrap_err().key, "ior");
    }
}
