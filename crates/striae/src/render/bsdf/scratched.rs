//! The scratched BSDF (`docs/METHOD.md` section 6, `docs/scratched.md`): a smooth
//! dielectric (glass) or smooth conductor (metal) base mixed with the precomputed scratch BRDF
//! of sections 3-4 by the footprint coverage of the scratch layers,
//! `f = (1 - c) f_base + c f_scratch` ([Raymond16]'s linear combination over a footprint).
//!
//! * Each scratch lobe lives in its own scratch frame, a rotation of the shading frame about
//!   the normal: `x = b = t x n` across the scratch, `y = t` along it, `z = n` (section 1). The
//!   rotation is stored as `(cos beta, sin beta)` of the angle from the shading frame's `s` axis
//!   to `t`, so the BSDF still works in the integrator's shading frame.
//! * **Glass** (seen from outside, `wo.z > 0`): the scratch lobe replaces the specular
//!   reflection; its directional albedo `a(wo) = integral f_s cos dwi` is reflected and
//!   `1 - a(wo)` is transmitted as the smooth refraction (a delta lobe with the `1/eta^2`
//!   radiance factor). That conserves energy exactly (up to the linear interpolation of the
//!   albedo table in `theta_o`, [`ScratchLobeTable::albedo`]). Seen from inside (`wo.z < 0`)
//!   the point is the base smooth dielectric: the scratches are on the outer side only, a
//!   departure from a two-sided scratch model (the seed does not say what happens inside).
//! * **Metal**: the same mixture with no transmission; the energy `1 - a(wo)` is absorbed by
//!   the walls and their Fresnel factors. The scratch value is scalar (the table's Fresnel law)
//!   times an RGB `tint` chosen by the material (see `scratched`).
//! * Mirror-wall tables give the delta-in-theta lobe of section 6 ([`ScratchBrdf::is_delta`]):
//!   then every lobe is a delta, light sampling is skipped and `eval`/`pdf` return 0.
//!
//! Sampling picks one component with probability proportional to its energy where that is
//! known exactly, so the delta components all carry weight 1 (glass) or their Fresnel factor
//! (metal): for glass from outside, base reflection `(1 - C) F`, transmission
//! `(1 - C)(1 - F) + sum_k c_k (1 - a_k)`, scratch lobe `k` `c_k a_k`; for metal, base mirror
//! `1 - C`, scratch lobe `k` `c_k` (`C = sum_k c_k`). A non-delta sample's weight is
//! `eval cos / pdf` with `pdf(wi) = sum_k P_k pdf_k(wi)` the probability of its lobe times its
//! density, the same value `pdf` returns, so MIS with light sampling is consistent.

use super::dielectric::{mirror_sample, refraction_sample};
use super::BsdfSample;
use crate::math::{reflect_z, Rgb, Vec2, Vec3};
use crate::optics::fresnel_f32;
use crate::precompute::table::{self, ScratchBrdf, ScratchTable, WoTerms};
use std::f64::consts::{FRAC_PI_2, PI};

/// Most scratch lobes one hit combines (`layer_mix = "sum"` keeps the largest coverages).
pub const MAX_SCRATCH_LOBES: usize = 8;

/// `theta_o` grid points of the albedo table over `[0, pi/2]`.
pub const ALBEDO_THETA_POINTS: usize = 65;

/// A scratch BRDF table ready for rendering: [`ScratchBrdf`] (eq. 3 evaluation and the section 6
/// sampler) plus its directional albedo `a(theta_o, phi_o)` tabulated per `phi_o` bin on
/// [`ALBEDO_THETA_POINTS`] values of `|theta_o|`.
#[derive(Debug)]
pub struct ScratchLobeTable {
    brdf: ScratchBrdf,
    /// `[phi_o bin][theta point]`.
    albedo: Vec<f32>,
    hash: String,
}

impl ScratchLobeTable {
    /// Precompute the albedo table: `a(theta_o, phi_o bin o) = sum_j rho_s(theta_o, o, j) w_j`
    /// with `w_j = integral over bin j of cos(phi) dphi = 2 sin(pi / 2M) cos(phi_j)`. This is
    /// `integral f_s cos dwi` exactly for the smooth lobe (`f_s = (2/pi) rho_s`, and
    /// `integral (2/pi) cos^2(theta_i) dtheta_i = 1`) and for the delta lobe (its expected
    /// sample weight, `table::ScratchBrdf::sample`).
    pub fn new(table: ScratchTable) -> Self {
        let hash = table.params.hash();
        let brdf = ScratchBrdf::new(table);
        let table = brdf.table();
        let m = table.m;
        let half = (PI / (2.0 * m as f64)).sin();
        let w: Vec<f64> = table.phi.iter().map(|p| 2.0 * half * p.cos()).collect();
        // `rho(theta_k, j, o)` for all theta points of one bin pair at once, eq. (4)'s `powf`
        // shared by the bins with the common `gamma` (the same values as `table.rho`; the sum
        // over `j` runs in the same order, so the table is bit for bit what a direct sum gives).
        const N: usize = ALBEDO_THETA_POINTS;
        let t: [f64; N] =
            std::array::from_fn(|k| table::eq4_t(FRAC_PI_2 * k as f64 / (N - 1) as f64));
        let gc = brdf.gamma_common();
        let r_common: [f64; N] = std::array::from_fn(|k| {
            if gc.is_nan() {
                0.0
            } else {
                table::eq4_r(t[k], gc)
            }
        });
        let mut albedo = vec![0.0f32; m * N];
        if let Some(g) = brdf.groove() {
            // Exact-groove slices: `f` does not depend on `theta_o`, one value per `phi_o`.
            let mean = g.mean_rho();
            for o in 0..m {
                let a: f64 = w
                    .iter()
                    .enumerate()
                    .map(|(j, wj)| mean[j * m + o] * wj)
                    .sum();
                albedo[o * N..(o + 1) * N].fill(a.max(0.0) as f32);
            }
            return ScratchLobeTable { brdf, albedo, hash };
        }
        let mut rho = [0.0f64; N];
        for o in 0..m {
            let mut acc = [0.0f64; N];
            for (j, &wj) in w.iter().enumerate() {
                table.rho_at_points(j, o, &t, gc, &r_common, &mut rho);
                for k in 0..N {
                    acc[k] += rho[k] * wj;
                }
            }
            for k in 0..N {
                albedo[o * N + k] = acc[k].max(0.0) as f32;
            }
        }
        ScratchLobeTable { brdf, albedo, hash }
    }

    pub fn brdf(&self) -> &ScratchBrdf {
        &self.brdf
    }

    pub fn table(&self) -> &ScratchTable {
        self.brdf.table()
    }

    /// The table's parameter hash (`TableParams::hash`).
    pub fn hash(&self) -> &str {
        &self.hash
    }

    pub fn is_delta(&self) -> bool {
        self.brdf.is_delta()
    }

    /// `a(wo)` for `wo` in the scratch frame (0 below the surface): the nearest `phi_o` bin
    /// (the BRDF is piecewise constant in `phi_o`) and linear interpolation in `|theta_o|`.
    ///
    /// This sums a table *column* (fixed `phi_o`, over `phi_i`), while eq. (1') bounds the
    /// *rows* (fixed `phi_i`) by 1: a lossless diffuse table is reciprocal only up to its Monte
    /// Carlo noise, so `a` may exceed 1 by that noise (a few per cent for small tables). The
    /// BSDF then scales the lobe by `1 / a` ([`ScratchLobeTable::scaled_albedo`]).
    #[inline]
    pub fn albedo(&self, wo: Vec3) -> f32 {
        if wo.z <= 0.0 {
            return 0.0;
        }
        self.albedo_at(&self.brdf.wo_terms(wo))
    }

    /// [`Self::albedo`] from the table's `wo` terms (`phi_o` bin, `t = 2 |theta_o| / pi`).
    #[inline]
    fn albedo_at(&self, wt: &WoTerms) -> f32 {
        let o = wt.o;
        let x = wt.t as f32 * (ALBEDO_THETA_POINTS - 1) as f32;
        let i = (x as usize).min(ALBEDO_THETA_POINTS - 2);
        let f = (x - i as f32).clamp(0.0, 1.0);
        let row = &self.albedo[o * ALBEDO_THETA_POINTS..(o + 1) * ALBEDO_THETA_POINTS];
        row[i] * (1.0 - f) + row[i + 1] * f
    }

    /// `(min(a, 1), s)` with `s = min(1, 1 / a)` the factor applied to the lobe at `wo` so that
    /// it never reflects more than it receives (departure: noise of the table, see `albedo`).
    #[inline]
    pub fn scaled_albedo(&self, wo: Vec3) -> (f32, f32) {
        Self::scale_albedo(self.albedo(wo))
    }

    #[inline]
    fn scale_albedo(a: f32) -> (f32, f32) {
        if a > 1.0 {
            (1.0, 1.0 / a)
        } else {
            (a, 1.0)
        }
    }
}

/// The smooth base under the scratches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ScratchedBase {
    /// A smooth dielectric with relative index `eta = n_inside / n_outside`.
    Glass { eta: f32 },
    /// A smooth conductor.
    Metal { ior: super::ConductorIor },
}

/// One scratch lobe at a hit: its coverage `c` of the footprint and the rotation of its scratch
/// frame, `(cos beta, sin beta)` with `t = cos beta s + sin beta t_shading`, and the frame's
/// lean along the scratch (`lean = true`, METHOD.md 8.3): its normal tilted toward `t` by an
/// angle `alpha`, as `sin alpha` (0 without one); and where the hit lies where two scratches
/// cross (traced glass walls, METHOD.md 8.3), the other scratch's across axis `b` in this
/// lobe's scratch frame, `(x, y)` (zero without one); and, for traced glass walls seen from
/// inside, where the hit lies across the groove ([`GroovePlace`]); and, for glass walls, where
/// a path its groove sends on goes on from: `spawn`, an offset from the hit in the shading
/// plane (world units along the frame's `s` and `t`; zero: the hit itself).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ScratchLobe {
    pub coverage: f32,
    pub cos: f32,
    pub sin: f32,
    pub lean: f32,
    pub cross: [f32; 2],
    pub place: Option<GroovePlace>,
    pub spawn: [f32; 2],
}

/// Where a hit lies across the groove of its lobe: `at` its offset from the axis along the
/// scratch frame's `x` in opening widths, `width` the opening's width there (world units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroovePlace {
    pub at: f32,
    pub width: f32,
}

impl Default for ScratchLobe {
    fn default() -> Self {
        ScratchLobe::new(0.0, 0.0, 0.0)
    }
}

impl ScratchLobe {
    /// A lobe of coverage `c` along `(cos beta, sin beta)`, without a lean.
    pub fn new(coverage: f32, cos: f32, sin: f32) -> Self {
        ScratchLobe {
            coverage,
            cos,
            sin,
            lean: 0.0,
            cross: [0.0; 2],
            place: None,
            spawn: [0.0; 2],
        }
    }

    /// The same lobe with its paths going on from `spawn` (see the type).
    pub fn spawned_at(self, spawn: [f32; 2]) -> Self {
        ScratchLobe { spawn, ..self }
    }

    /// Where a sample of this lobe goes on from ([`crate::render::bsdf::BsdfSample::from`]):
    /// `from` (below a groove's wall) shifted to the lobe's spawn point, or that point on the
    /// surface, or (neither) the hit.
    #[inline]
    pub fn going_on_from(&self, from: Option<Vec3>) -> Option<Vec3> {
        let spawn = Vec3::new(self.spawn[0], self.spawn[1], 0.0);
        match from {
            Some(v) => Some(self.from_scratch(v) + spawn),
            None => (self.spawn != [0.0; 2]).then_some(spawn),
        }
    }

    /// The same lobe at a crossing with the scratch of `other`'s direction: `other`'s across
    /// axis `b' = (sin beta', -cos beta')` in this lobe's scratch frame (the lean left out).
    pub fn crossed_by(self, other: &ScratchLobe) -> Self {
        let along = self.cos * other.cos + self.sin * other.sin;
        let across = self.sin * other.cos - self.cos * other.sin;
        ScratchLobe {
            cross: [along, -across],
            ..self
        }
    }

    /// The same lobe at `place` across its groove.
    pub fn at_place(self, place: Option<GroovePlace>) -> Self {
        ScratchLobe { place, ..self }
    }

    /// The same lobe with its normal tilted toward `t` by the angle whose tangent is `tan`.
    pub fn leaned(self, tan: f32) -> Self {
        ScratchLobe {
            lean: tan / (1.0 + tan * tan).sqrt(),
            ..self
        }
    }

    /// The same lobe without its lean: its frame the extruded groove's.
    pub fn unleaned(self) -> Self {
        ScratchLobe { lean: 0.0, ..self }
    }

    /// `tan alpha` of the lean (0 without one).
    pub fn lean_tan(&self) -> f32 {
        let (c, s) = self.lean_cos_sin();
        s / c
    }

    #[inline]
    fn has_lean(&self) -> bool {
        self.lean != 0.0
    }

    /// `(cos alpha, sin alpha)` of the lean.
    #[inline]
    fn lean_cos_sin(&self) -> (f32, f32) {
        ((1.0 - self.lean * self.lean).sqrt(), self.lean)
    }

    /// Shading frame to scratch frame: `x = w . b`, `b = t x n = (sin beta, -cos beta, 0)`;
    /// `y = w . t`; then the lean, `n' = cos alpha n + sin alpha t`, `t' = cos alpha t - sin
    /// alpha n`.
    #[inline]
    pub fn to_scratch(&self, w: Vec3) -> Vec3 {
        let v = Vec3::new(
            self.sin * w.x - self.cos * w.y,
            self.cos * w.x + self.sin * w.y,
            w.z,
        );
        if !self.has_lean() {
            return v;
        }
        let (c, s) = self.lean_cos_sin();
        Vec3::new(v.x, c * v.y - s * v.z, c * v.z + s * v.y)
    }

    #[inline]
    pub fn from_scratch(&self, v: Vec3) -> Vec3 {
        let v = if self.has_lean() {
            let (c, s) = self.lean_cos_sin();
            Vec3::new(v.x, c * v.y + s * v.z, c * v.z - s * v.y)
        } else {
            v
        };
        Vec3::new(
            self.sin * v.x + self.cos * v.y,
            -self.cos * v.x + self.sin * v.y,
            v.z,
        )
    }

    /// `wo` in the scratch frame, kept on its side of the surface: a leaned frame takes a
    /// grazing `wo` across its horizon, and there it is held just on its own side.
    #[inline]
    pub fn wo_to_scratch(&self, wo: Vec3) -> Vec3 {
        let v = self.to_scratch(wo);
        if !self.has_lean() || v.z * wo.z > 0.0 || wo.z == 0.0 {
            return v;
        }
        const HORIZON: f32 = 1e-4;
        let xy = (v.x * v.x + v.y * v.y).sqrt().max(f32::MIN_POSITIVE);
        let k = (1.0 - HORIZON * HORIZON).sqrt() / xy;
        Vec3::new(v.x * k, v.y * k, HORIZON.copysign(wo.z))
    }

    /// `wi` in the scratch frame, and the factor taking the lobe's value there (a BSDF for the
    /// cosine `wi_s.z`) to the shading frame's (for `wi.z`): `wi_s.z / wi.z`, so that a leaned
    /// lobe scatters the energy it does unleaned (1 without a lean). `None` where the lean puts
    /// `wi` on the other side of the frame's horizon than the surface's: not in the lobe
    /// ([`Self::wi_from_scratch`] fails there too).
    #[inline]
    pub fn wi_to_scratch(&self, wi: Vec3) -> Option<(Vec3, f32)> {
        let wi_s = self.to_scratch(wi);
        if !self.has_lean() {
            return Some((wi_s, 1.0));
        }
        (wi.z * wi_s.z > 0.0).then(|| (wi_s, wi_s.z / wi.z))
    }

    /// A direction sampled in the scratch frame, in the shading frame; `None` where it is not
    /// in the lobe, judged on its own image in the scratch frame as `eval` and `pdf` see it
    /// ([`Self::wi_to_scratch`]).
    #[inline]
    pub fn wi_from_scratch(&self, v: Vec3) -> Option<Vec3> {
        let wi = self.from_scratch(v);
        (!self.has_lean() || self.wi_to_scratch(wi).is_some()).then_some(wi)
    }
}

/// Where a hit's one lobe lies within the bounce's BSDF-lobe number under `layer_mix =
/// "stochastic"`: the material picked the lobe by that number (`u` in `[start, start + len)`),
/// and the BSDF's sampling reads its place within the share, `(u - start) / len`, uniform in
/// `[0, 1)` and independent of the pick, so one stratified number chooses both
/// (`render::scratched::ScratchedMaterial::bsdf`). The whole of `[0, 1)` elsewhere.
#[derive(Clone, Copy, Debug)]
pub struct LobeShare {
    start: f32,
    inv_len: f32,
}

impl Default for LobeShare {
    fn default() -> Self {
        LobeShare {
            start: 0.0,
            inv_len: 1.0,
        }
    }
}

impl LobeShare {
    /// The share `[start, start + len)`; the whole of `[0, 1)` unless `len > 0`.
    pub fn new(start: f32, len: f32) -> Self {
        if len.is_nan() || len <= 0.0 {
            return Self::default();
        }
        LobeShare {
            start,
            inv_len: 1.0 / len,
        }
    }

    /// `u`'s place within the share, in `[0, 1)` (`u` itself for the whole of `[0, 1)`).
    #[inline(always)]
    pub fn place(&self, u: f32) -> f32 {
        ((u - self.start) * self.inv_len).clamp(0.0, 1.0 - f32::EPSILON / 2.0)
    }
}

/// The scratch lobes of one hit, shared by the scratched BSDFs: those with coverage `c_k > 0`,
/// at most [`MAX_SCRATCH_LOBES`] (extra ones ignored), each `c_k` clamped to 1 and all rescaled
/// so that `C = sum c_k <= 1` (the `sum` mode's normalisation).
#[derive(Clone, Copy, Debug, Default)]
pub struct CoveredLobes {
    lobes: [ScratchLobe; MAX_SCRATCH_LOBES],
    count: u8,
    /// `C = sum_k c_k <= 1`.
    total: f32,
    /// Where the sampling's lobe number lies ([`LobeShare`]).
    share: LobeShare,
}

impl CoveredLobes {
    pub fn new(lobes: &[ScratchLobe]) -> Self {
        let mut out = CoveredLobes::default();
        let mut count = 0;
        for l in lobes
            .iter()
            .filter(|l| l.coverage > 0.0)
            .take(MAX_SCRATCH_LOBES)
        {
            out.lobes[count] = ScratchLobe {
                coverage: l.coverage.min(1.0),
                ..*l
            };
            out.total += out.lobes[count].coverage;
            count += 1;
        }
        out.count = count as u8;
        if out.total > 1.0 {
            for l in &mut out.lobes[..count] {
                l.coverage /= out.total;
            }
            out.total = 1.0;
        }
        out
    }

    #[inline]
    pub fn as_slice(&self) -> &[ScratchLobe] {
        &self.lobes[..self.count as usize]
    }

    /// These lobes with the sampling's lobe number read within `share`.
    #[inline(always)]
    pub fn in_share(self, share: LobeShare) -> Self {
        CoveredLobes { share, ..self }
    }

    /// The sampling's lobe number `u_lobe`, read within the share ([`LobeShare::place`]).
    #[inline(always)]
    pub fn lobe_number(&self, u_lobe: f32) -> f32 {
        self.share.place(u_lobe)
    }

    /// `C = sum_k c_k`.
    #[inline]
    pub fn total(&self) -> f32 {
        self.total
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// The lobe a uniform `u` picks when lobe `k` spans `c_k` of `[start, start + C)` in order
    /// (the last lobe takes what rounding leaves), and `u`'s place within its span in `[0, 1]`.
    /// At least one lobe.
    #[inline]
    pub fn pick(&self, u: f32, start: f32) -> (usize, f32) {
        let lobes = self.as_slice();
        let (mut k, mut acc) = (0, start);
        while k + 1 < lobes.len() && u >= acc + lobes[k].coverage {
            acc += lobes[k].coverage;
            k += 1;
        }
        (k, ((u - acc) / lobes[k].coverage).clamp(0.0, 1.0))
    }
}

/// What one lobe's lookups need of `wo`: the table's `wo` terms in the lobe's scratch frame
/// (`phi_o` bin, `theta_o`, eq. (4)'s common `R`) and [`ScratchLobeTable::scaled_albedo`].
#[derive(Clone, Copy, Debug, Default)]
struct LobeWo {
    terms: WoTerms,
    /// `min(a(wo), 1)` and the lobe's scale `min(1, 1 / a(wo))`.
    a: f32,
    scale: f32,
}

/// The scratched BSDF at one hit (see the module notes). Built by the `scratched` material.
#[derive(Clone, Copy, Debug)]
pub struct ScratchedBsdf<'a> {
    pub base: ScratchedBase,
    pub table: &'a ScratchLobeTable,
    /// RGB factor on the scratch lobe (metal: the base's colour; glass: 1).
    pub tint: Rgb,
    lobes: CoveredLobes,
    /// The first lobe's `wo` terms for the `wo` of [`ScratchedBsdf::at_wo`].
    wo_cache: WoCache,
}

/// The first lobe's [`LobeWo`] for one `wo`, keyed on the bits of `wo`. A hit evaluates,
/// light-samples and samples one `wo`, so its `phi_o` bin, `theta_o`, albedo and eq. (4)'s
/// `R` are computed once instead of in each of those lookups (4-8 times); another `wo`, and
/// the other lobes of `sum` mode, are computed afresh, to the same bits (the test
/// `wo_cache_changes_no_result` holds it to that). One lobe only: the BSDF is returned and moved
/// by value at every hit, so it is kept small; `max` mode has one lobe.
#[derive(Clone, Copy, Debug, Default)]
struct WoCache {
    key: Option<[u32; 3]>,
    terms: LobeWo,
}

impl WoCache {
    #[inline]
    fn key(wo: Vec3) -> [u32; 3] {
        wo.to_array().map(f32::to_bits)
    }

    #[inline]
    fn get(&self, wo: Vec3) -> Option<LobeWo> {
        (self.key == Some(Self::key(wo))).then_some(self.terms)
    }
}

impl<'a> ScratchedBsdf<'a> {
    /// This BSDF with its sampling's lobe number read within `share` ([`LobeShare`]).
    #[inline(always)]
    pub fn in_share(mut self, share: LobeShare) -> Self {
        self.lobes = self.lobes.in_share(share);
        self
    }

    /// `lobes` with coverages `c_k >= 0`; at most [`MAX_SCRATCH_LOBES`] (extra ones are
    /// ignored), rescaled so that `sum c_k <= 1` (the `sum` mode's normalisation).
    pub fn new(
        base: ScratchedBase,
        table: &'a ScratchLobeTable,
        tint: Rgb,
        lobes: &[ScratchLobe],
    ) -> Self {
        ScratchedBsdf {
            base,
            table,
            tint,
            lobes: CoveredLobes::new(lobes),
            wo_cache: WoCache::default(),
        }
    }

    /// The same BSDF with the `wo`-dependent terms of its lobes precomputed for `wo` (the
    /// direction the integrator will evaluate and sample it with). Changes no result: a call
    /// with another `wo` computes them afresh.
    #[inline]
    pub fn at_wo(mut self, wo: Vec3) -> Self {
        if wo.z > 0.0 && !self.lobes.is_empty() {
            self.wo_cache = WoCache {
                key: Some(WoCache::key(wo)),
                terms: self.lobe_wo(&self.lobes()[0], wo),
            };
        }
        self
    }

    /// [`LobeWo`] of lobe `l` for `wo.z > 0`.
    #[inline]
    fn lobe_wo(&self, l: &ScratchLobe, wo: Vec3) -> LobeWo {
        let wo_s = l.wo_to_scratch(wo);
        let terms = self.table.brdf().wo_terms(wo_s);
        let (a, scale) = ScratchLobeTable::scale_albedo(self.table.albedo_at(&terms));
        LobeWo { terms, a, scale }
    }

    /// [`LobeWo`] of lobe `k` for `wo.z > 0`: the cached one for lobe 0 and the cached `wo`.
    #[inline]
    fn terms(&self, k: usize, wo: Vec3) -> LobeWo {
        match self.wo_cache.get(wo) {
            Some(terms) if k == 0 => terms,
            _ => self.lobe_wo(&self.lobes()[k], wo),
        }
    }

    pub fn lobes(&self) -> &[ScratchLobe] {
        self.lobes.as_slice()
    }

    /// `C = sum_k c_k`.
    pub fn total_coverage(&self) -> f32 {
        self.lobes.total()
    }

    #[inline]
    fn is_glass(&self) -> bool {
        matches!(self.base, ScratchedBase::Glass { .. })
    }

    /// Probability of choosing the scratch lobe `l` (before its own sampling): `c a(wo)` for
    /// glass, `c` for metal.
    #[inline]
    fn lobe_probability(&self, l: &ScratchLobe, c: &LobeWo) -> f32 {
        if self.is_glass() {
            l.coverage * c.a
        } else {
            l.coverage
        }
    }

    /// `sum_k c_k f_s,k(wo, wi)` times the tint (0 for delta tables, for `wo` inside glass and
    /// for any pair not both above the surface).
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if self.table.is_delta() || wo.z <= 0.0 || wi.z <= 0.0 {
            return Rgb::ZERO;
        }
        let mut f = 0.0f64;
        for (k, l) in self.lobes().iter().enumerate() {
            let Some((wi_s, lean)) = l.wi_to_scratch(wi) else {
                continue;
            };
            let c = self.terms(k, wo);
            let fk = self.table.brdf().eval_at(&c.terms, wi_s);
            f += (l.coverage * c.scale * lean) as f64 * fk;
        }
        self.tint * f as f32
    }

    /// `sum_k P_k pdf_k(wi)`: the probability of each lobe times its solid-angle density.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if self.table.is_delta() || wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let mut p = 0.0f64;
        for (k, l) in self.lobes().iter().enumerate() {
            let Some((wi_s, _)) = l.wi_to_scratch(wi) else {
                continue;
            };
            let c = self.terms(k, wo);
            let pk = self.lobe_probability(l, &c);
            if pk > 0.0 {
                p += pk as f64 * self.table.brdf().eval_pdf_at(&c.terms, wi_s).1;
            }
        }
        p as f32
    }

    /// `(eval, pdf)` in one pass over the lobes (shared scratch-frame transforms and albedo).
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        if self.table.is_delta() || wo.z <= 0.0 || wi.z <= 0.0 {
            return (Rgb::ZERO, 0.0);
        }
        let (mut f, mut p) = (0.0f64, 0.0f64);
        for (k, l) in self.lobes().iter().enumerate() {
            let Some((wi_s, lean)) = l.wi_to_scratch(wi) else {
                continue;
            };
            let c = self.terms(k, wo);
            let (fk, pdf_k) = self.table.brdf().eval_pdf_at(&c.terms, wi_s);
            f += (l.coverage * c.scale * lean) as f64 * fk;
            let pk = self.lobe_probability(l, &c);
            if pk > 0.0 {
                p += pk as f64 * pdf_k;
            }
        }
        (self.tint * f as f32, p as f32)
    }

    /// See the module notes for the component probabilities. `u_lobe` picks the component,
    /// `u` drives the scratch lobe's sampler.
    #[inline]
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let u_lobe = self.lobes.lobe_number(u_lobe);
        match self.base {
            ScratchedBase::Glass { eta } => {
                if wo.z <= 0.0 {
                    return super::Dielectric::new(eta).sample(wo, u_lobe);
                }
                // The smooth base's own Fresnel (`Dielectric::sample`'s, in `f32`).
                let (fr, cos_t, eta_it) = fresnel_f32::dielectric(wo.z, eta);
                let base = 1.0 - self.lobes.total();
                let p_reflect = base * fr;
                if u_lobe < p_reflect {
                    return Some(mirror_sample(wo, p_reflect));
                }
                let mut p_scatter = [0.0f32; MAX_SCRATCH_LOBES];
                let mut p_transmit = base * (1.0 - fr);
                for (k, l) in self.lobes().iter().enumerate() {
                    let pk = self.lobe_probability(l, &self.terms(k, wo));
                    p_scatter[k] = pk;
                    p_transmit += l.coverage - pk;
                }
                let mut acc = p_reflect + p_transmit;
                if u_lobe < acc || self.lobes.is_empty() {
                    return Some(refraction_sample(wo, cos_t, eta_it, p_transmit));
                }
                let count = self.lobes().len();
                for (k, &pk) in p_scatter[..count].iter().enumerate() {
                    acc += pk;
                    if u_lobe < acc || k + 1 == count {
                        return self.sample_lobe(k, wo, pk, u);
                    }
                }
                None
            }
            ScratchedBase::Metal { ior } => {
                if wo.z <= 0.0 {
                    return None;
                }
                let base = 1.0 - self.lobes.total();
                if u_lobe < base || self.lobes.is_empty() {
                    return Some(BsdfSample {
                        wi: reflect_z(wo),
                        weight: ior.fresnel(wo.z),
                        pdf: base,
                        delta: true,
                        eta: 1.0,
                        from: None,
                    });
                }
                let (k, _) = self.lobes.pick(u_lobe, base);
                self.sample_lobe(k, wo, self.lobes()[k].coverage, u)
            }
        }
    }

    /// Sample scratch lobe `k`, chosen with probability `pk`.
    #[inline]
    fn sample_lobe(&self, k: usize, wo: Vec3, pk: f32, u: Vec2) -> Option<BsdfSample> {
        if !(pk > 0.0) {
            return None;
        }
        let l = &self.lobes()[k];
        let c = self.terms(k, wo);
        let s = self
            .table
            .brdf()
            .sample_at(&c.terms, [u.x as f64, u.y as f64])?;
        let wi = l.wi_from_scratch(s.wi)?;
        if s.delta || self.lobes().len() == 1 {
            // The delta lobe (coefficient c_k s value over P_k pmf), or one smooth lobe (the
            // `max` mode: the mixture's pdf is P_k times the lobe's, its value c_k s f): the
            // lobe's own weight times c_k s / P_k, with P_k = c_k a_k for glass, c_k for metal.
            let w = (s.weight * (l.coverage * c.scale / pk) as f64) as f32;
            return Some(BsdfSample {
                wi,
                weight: self.tint * w,
                pdf: pk * s.pdf as f32,
                delta: s.delta,
                eta: 1.0,
                from: None,
            });
        }
        let (f, pdf) = self.eval_pdf(wo, wi);
        if !(pdf > 0.0) || wi.z <= 0.0 {
            return None;
        }
        Some(BsdfSample {
            wi,
            weight: f * (wi.z / pdf),
            pdf,
            delta: false,
            eta: 1.0,
            from: None,
        })
    }

    #[inline]
    pub fn has_transmission(&self) -> bool {
        self.is_glass()
    }

    /// Every lobe is a delta when the table is a mirror-wall one.
    #[inline]
    pub fn is_delta(&self) -> bool {
        self.table.is_delta()
    }
}
