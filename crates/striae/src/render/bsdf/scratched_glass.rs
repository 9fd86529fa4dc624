//! The complete scratched-glass BSDF (METHOD.md 8.1-8.2, `walls = "dielectric"`): a smooth
//! dielectric mixed with the four lobes of a groove cut into glass, from either side,
//! `f = (1 - C) f_smooth + sum_k c_k f_groove,k` (`C = sum_k c_k`, the footprint coverages).
//!
//! **The groove lobes from the table.** [`WallLobeTable`] is the render form of a
//! [`WallTable`]: for each incident grid point and side, the fractions `m_b` of the energy that
//! leaves through each exit bin `b` of `(theta, phi)` (METHOD.md section 1 angles, a direction
//! inside the glass mirrored up), reflected then transmitted. The BSDF at `(wo, wi)` reads the
//! table with `wo` as the incident direction and `wi` as the exit, which physics allows:
//! reflection is reciprocal, and transmission obeys the generalised reciprocity of 8.1,
//! `f(wi -> wo) = (n_o / n_i)^2 f(wo -> wi)` (`n_o`, `n_i`: the indices on `wo`'s and `wi`'s
//! sides), the factor that makes light entering glass `1 / n^2` as bright per solid angle
//! (radiance transport, as [`super::Dielectric`]). Within a bin the exit density is uniform
//! in `(theta, phi)`, so with `dw = cos(theta) dtheta dphi`
//!
//! `f(wo, wi) = s m_b / (J dtheta dphi cos(theta_i) |wi.z|)`,  `s = 1` (R), `(n_o / n_i)^2` (T).
//!
//! **Smooth walls** conserve `beta = n w.y` at every hit (METHOD.md 8.1): each lobe leaves at
//! one exact `theta`, a delta that exit bins would smear over their width (5.6 degrees at 32
//! bins: against explicit grooves lit from behind, 11 % too much light, docs/fidelity.md). Their
//! tables hold only the `phi_o` marginals ([`crate::precompute::wall_table`]), and the exit `theta` is
//! `wo`'s own smooth-wall exit angle, spread uniformly over a box [`SMOOTH_BOX`] wide
//! (`dtheta` above, `J = 1`): narrow enough to be exact at any scale a scene resolves, and
//! still a density, so `eval` and `pdf` stay defined (light sampling leaves it to BSDF
//! sampling, below).
//!
//! **The walls' two render forms** ([`GlassWalls`]): a table ([`WallLobeTable`], below: rough
//! walls, and smooth ones with `lobes = "table"`), or, for smooth walls by default, the exact
//! groove traced ([`TracedGroove`], `lobes = "traced"`): a groove sample is one path of
//! [`GroovePaths`] through the groove, entering at `u.x` across the opening (or the band
//! beside it, from inside), its bounces drawn from a stream keyed by the sample's other
//! numbers; its weight is `s` times the path's (1: lossless), its `pdf` the lobe's probability
//! `c_k` (there is no density to give: `eval` and `pdf` are 0 for these lobes, which only BSDF
//! sampling reaches, as for smooth walls' boxes).
//!
//! **Between grid points** the four nearest incident slices are blended bilinearly in
//! `(theta_o, phi_o)` of `wo`; for rough walls each is first warped along `theta`: the
//! piecewise-linear map of `(-pi/2, pi/2)` onto itself that carries the slice's smooth-wall
//! exit angle ([`crate::precompute::wall_table::exit_theta`]) to `wo`'s, with slope `J`, so that the peak
//! of a nearly smooth wall's lobe lands where it belongs wherever `wo` lies between the grid's
//! points (beyond the grid's last `theta` centres the warp extrapolates).
//!
//! **Sampling.** One component with the probability of its energy: the smooth reflection
//! `(1 - C) F`, the smooth refraction `(1 - C)(1 - F)` (both deltas, weight 1 and `1 / eta^2`),
//! groove lobe `k` with `c_k`; within a groove lobe, a grid slice with its bilinear weight, an
//! exit bin in proportion to `m_b` (reflected and transmitted together, one CDF per slice,
//! searched through a one-line guide of it), a point uniform in the bin, warped (rough walls)
//! or in the box (smooth walls). The density of the non-delta part is `sum_k c_k pdf_k`, the
//! value `pdf` returns, so MIS with light sampling is consistent (rough walls: the weight is
//! `f cos / pdf` of the whole blend). Smooth walls' boxes are too narrow for light sampling
//! to land in: the integrator skips it there ([`super::Bsdf::is_delta`]) and counts what BSDF
//! sampling finds, as for a specular surface, so no other density is weighed against
//! theirs, and their weight is the **one-slice estimate** `f_q cos / pdf_q = s E_q` of the
//! chosen slice `q` alone (`E_q` its energy, 1 for a lossless groove): the blend's expected
//! value, since slice `q` is chosen with its weight, with no lookup of the other slices (the
//! table is the size of a large cache; BENCHMARKS.md).

use super::dielectric::{mirror_sample, refraction_sample};
use super::scratched::CoveredLobes;
use super::{BsdfSample, GroovePlace, ScratchLobe};
use crate::hash::{mix64, unit_from_u32};
use crate::math::{Rgb, Vec2, Vec3};
use crate::optics::fresnel_f32;
use crate::precompute::crossing::{CrossingEnd, Partner};
use crate::precompute::groove::{GrooveExit, GroovePaths};
use crate::precompute::profile::Profile;
use crate::precompute::wall_table::{self, WallTable, WallTableParams};
use std::f32::consts::{FRAC_PI_2, PI};
use std::sync::Arc;

/// How far from `+-pi/2` the warp's fixed points are kept (radians), so that its slopes stay
/// finite where an exit angle grazes (total internal reflection clamps it to `+-pi/2`).
const WARP_MARGIN: f32 = 1e-3;

/// The `theta_o` extent of a smooth wall's exit box (radians): 0.35 degrees.
pub(crate) const SMOOTH_BOX: f32 = PI / 512.0;

/// A dielectric-wall table ready for rendering (see the module notes).
#[derive(Debug)]
pub struct WallLobeTable {
    /// Incident grid sizes and the exit bins per angle.
    nt: usize,
    np: usize,
    b: usize,
    /// `theta_o` rows per lobe: `b` bins (rough walls) or one box at the exact exit angle
    /// (smooth walls).
    rows: usize,
    /// A smooth wall's box (radians).
    smooth_box: f32,
    /// The glass's index `n`.
    n: f32,
    /// `[t][p][side][lobe][theta row][phi bin]`, side 0: from outside, 1: from inside; lobe 0
    /// reflected, 1 transmitted.
    mass: Vec<f32>,
    /// Inclusive prefix sums of `mass` within each `[t][p][side]` slice.
    cdf: Vec<f32>,
    /// Each slice's energy, its CDF's last entry, `[t][p][side]`: a few kilobytes the
    /// lookups read before the slice itself.
    totals: Vec<f32>,
    /// Each slice's CDF at the ends of its [`GUIDE`] equal groups, `[t][p][side][group]`:
    /// one cache line per slice, a sixteenth of the CDF's size, that takes a sample to its
    /// group before it reads the CDF itself (one line of it for smooth walls).
    guide: Vec<[f32; GUIDE]>,
    /// The smooth-wall exit angles of the `theta` grid's centres, `[t][side][lobe]`.
    grid_exit: Vec<[[f32; 2]; 2]>,
    /// The groove's cross-section, and the least `tan theta` (in the cross-section) at which
    /// light from inside meets it beside its opening ([`GlassWalls::ridge_tan`]).
    profile: Profile,
    ridge_tan: f64,
    hash: String,
}

impl WallLobeTable {
    pub fn new(table: &WallTable) -> Self {
        Self::with_smooth_box(table, SMOOTH_BOX)
    }

    /// [`Self::new`] with smooth walls' boxes `smooth_box` radians wide (tests integrate the
    /// density over wider boxes).
    pub(crate) fn with_smooth_box(table: &WallTable, smooth_box: f32) -> Self {
        let (nt, np, b) = (table.theta_i.len(), table.phi_i.len(), table.params.bins);
        // Smooth walls: one row, the `phi_o` marginal; the exit `theta` is exact.
        let rows = table.params.exit_rows();
        let mut mass = Vec::with_capacity(nt * np * 4 * rows * b);
        for t in 0..nt {
            for p in 0..np {
                for l in 0..4 {
                    mass.extend(table.slice(l, t, p).iter().map(|&m| m.max(0.0) as f32));
                }
            }
        }
        let mut cdf = Vec::with_capacity(mass.len());
        for slice in mass.chunks_exact(2 * rows * b) {
            let mut acc = 0.0f64;
            cdf.extend(slice.iter().map(|&m| {
                acc += m as f64;
                acc as f32
            }));
        }
        let len = 2 * rows * b;
        let totals = cdf.chunks_exact(len).map(|c| c[len - 1]).collect();
        let guide = cdf
            .chunks_exact(len)
            .map(|c| {
                std::array::from_fn(|g| group_end(g, len).checked_sub(1).map_or(0.0, |e| c[e]))
            })
            .collect();
        let mut t = WallLobeTable {
            nt,
            np,
            b,
            rows,
            smooth_box,
            n: table.params.ior as f32,
            mass,
            cdf,
            totals,
            guide,
            grid_exit: Vec::new(),
            profile: table.params.profile.clone(),
            ridge_tan: table.params.profile.ridge_tan(),
            hash: table.params.hash(),
        };
        t.grid_exit = (0..nt)
            .map(|i| {
                let centre = -FRAC_PI_2 + (i as f32 + 0.5) * PI / nt as f32;
                std::array::from_fn(|side| std::array::from_fn(|l| t.exit_theta(side, l, centre)))
            })
            .collect();
        t
    }

    /// The table's parameter hash (`WallTableParams::hash`).
    pub fn hash(&self) -> &str {
        &self.hash
    }

    #[inline]
    fn slice_len(&self) -> usize {
        2 * self.rows * self.b
    }

    #[inline]
    fn bin_width(&self) -> f32 {
        PI / self.b as f32
    }

    /// Whether the walls are smooth: each lobe's exit `theta` is exact (a box of
    /// [`Self::row_width`] around it) and only `phi_o` is binned.
    #[inline]
    pub fn smooth(&self) -> bool {
        self.rows == 1
    }

    /// The groove's cross-section.
    pub fn profile(&self) -> &Profile {
        &self.profile
    }

    /// The `theta_o` extent of one row: an exit bin, or a smooth wall's box.
    #[inline]
    pub fn row_width(&self) -> f32 {
        if self.smooth() {
            self.smooth_box
        } else {
            self.bin_width()
        }
    }

    /// The first entry of slice `slice`'s CDF above `x` (the last where none is): its
    /// group from the guide, then the entry within the group.
    #[inline]
    fn search(&self, slice: usize, x: f32) -> usize {
        let len = self.slice_len();
        let g = self.guide[slice]
            .partition_point(|&v| v <= x)
            .min(GUIDE - 1);
        let (start, end) = (group_end(g.wrapping_sub(1), len), group_end(g, len));
        let cdf = &self.cdf[slice * len + start..slice * len + end];
        (start + cdf.partition_point(|&v| v <= x)).min(len - 1)
    }

    /// The exit bin of an angle in `(-pi/2, pi/2)`.
    #[inline]
    fn bin(&self, a: f32) -> usize {
        (((a + FRAC_PI_2) / self.bin_width()) as usize).min(self.b - 1)
    }

    /// The smooth-wall exit `theta` of lobe `l` (0: R, 1: T) for incident `theta` from
    /// `side` (METHOD.md 8.1, [`crate::precompute::wall_table::exit_theta`]), kept off `+-pi/2`.
    #[inline]
    fn exit_theta(&self, side: usize, l: usize, theta: f32) -> f32 {
        let e = wall_table::exit_theta(2 * side + l, theta as f64, self.n as f64) as f32;
        e.clamp(-FRAC_PI_2 + WARP_MARGIN, FRAC_PI_2 - WARP_MARGIN)
    }

    /// The slices around `wo` (scratch frame, `wo.z != 0`) and their warps ([`Corners`]).
    pub(super) fn corners(&self, wo: Vec3) -> Corners {
        let side = (wo.z < 0.0) as usize;
        let theta = wo.y.clamp(-1.0, 1.0).asin();
        let phi = wo.x.atan2(wo.z.abs());
        let wt = wall_table::grid_weights(self.nt, theta as f64);
        let wp = wall_table::grid_weights(self.np, phi as f64);
        let mut e_o = [
            self.exit_theta(side, 0, theta),
            self.exit_theta(side, 1, theta),
        ];
        if self.smooth() {
            // The box stays inside `(-pi/2, pi/2)`.
            let edge = FRAC_PI_2 - 0.5 * self.row_width();
            e_o = e_o.map(|e| e.clamp(-edge, edge));
        }
        let mut c = Corners {
            side,
            count: 0,
            slice: [0; 4],
            weight: [0.0; 4],
            total: [0.0; 4],
            e_c: [[0.0; 2]; 4],
            e_o,
        };
        let len = self.slice_len();
        for &(t, a) in &wt {
            let e_c = self.grid_exit[t][side];
            for &(p, bw) in &wp {
                let w = (a * bw) as f32;
                if !(w > 0.0) {
                    continue;
                }
                let k = c.count;
                let slice = (t * self.np + p) * 2 + side;
                c.slice[k] = (slice * len) as u32;
                c.weight[k] = w;
                c.total[k] = self.totals[slice];
                c.e_c[k] = e_c;
                c.count += 1;
            }
        }
        c
    }

    /// `(f, pdf)` of one groove lobe at `wi` (scratch frame), the pdf as the lobe's sampler's
    /// ([`Self::sample`]) given the corners of `wo`.
    #[inline]
    pub(super) fn eval_pdf(&self, c: &Corners, wi: Vec3) -> (f32, f32) {
        let below = wi.z < 0.0;
        if wi.z == 0.0 {
            return (0.0, 0.0);
        }
        let l = (below != (c.side == 1)) as usize;
        let theta = wi.y.clamp(-1.0, 1.0).asin();
        let cos_theta = theta.cos();
        if !(cos_theta > 0.0) {
            return (0.0, 0.0);
        }
        let smooth = self.smooth();
        if smooth && (theta - c.e_o[l]).abs() > 0.5 * self.row_width() {
            return (0.0, 0.0);
        }
        let col = self.bin(wi.x.atan2(wi.z.abs()));
        let lobe_len = self.rows * self.b;
        let (mut f, mut p) = (0.0f32, 0.0f32);
        for k in 0..c.count {
            let (row, slope) = if smooth {
                (0, 1.0)
            } else {
                let (src, slope) = unwarp(theta, c.e_c[k][l], c.e_o[l]);
                (self.bin(src), slope)
            };
            let m = self.mass[c.slice[k] as usize + l * lobe_len + row * self.b + col];
            if m > 0.0 && c.total[k] > 0.0 {
                let m = c.weight[k] * m / slope;
                f += m;
                p += m / c.total[k];
            }
        }
        let area = self.row_width() * self.bin_width() * cos_theta;
        let s = radiance_factor(self.n, c.side, l);
        (s * f / (area * wi.z.abs()), p / area)
    }

    /// Smooth walls: a direction from the groove lobes of `wo` (scratch frame, `wo.z != 0`),
    /// the one-slice estimate of the module notes. `u0` picks a grid slice with its bilinear
    /// weight (the `theta` neighbour, then the `phi` one), `u.x` an exit bin of the slice's
    /// CDF and the point in the box, `u.y` the point in the bin. The directions are
    /// distributed as [`Self::eval_pdf`]'s density; the weight is the chosen slice's own
    /// `f |cos| / pdf`. `None` where the slice holds no energy.
    #[inline]
    pub(super) fn sample_smooth(&self, wo: Vec3, u0: f32, u: Vec2) -> Option<SmoothSample> {
        let side = (wo.z < 0.0) as usize;
        let theta = wo.y.clamp(-1.0, 1.0).asin();
        let phi = wo.x.atan2(wo.z.abs());
        let (t, v) = pick_neighbour(wall_table::grid_weights(self.nt, theta as f64), u0);
        let (p, _) = pick_neighbour(wall_table::grid_weights(self.np, phi as f64), v);
        let slice = (t * self.np + p) * 2 + side;
        let total = self.totals[slice];
        if !(total > 0.0) {
            return None;
        }
        let x = u.x * total;
        let j = self.search(slice, x);
        let cdf = &self.cdf[slice * self.slice_len()..];
        let lo = if j == 0 { 0.0 } else { cdf[j - 1] };
        let m = cdf[j] - lo;
        if !(m > 0.0) {
            return None;
        }
        let frac = ((x - lo) / m).clamp(0.0, 1.0);
        let (l, col) = (j / self.b, j % self.b);
        let edge = FRAC_PI_2 - 0.5 * self.smooth_box;
        let exit = self.exit_theta(side, l, theta).clamp(-edge, edge);
        let theta_o = exit + (frac - 0.5) * self.smooth_box;
        let h = self.bin_width();
        let phi_o = -FRAC_PI_2 + (col as f32 + u.y) * h;
        let (st, ct) = theta_o.sin_cos();
        let (sp, cp) = phi_o.sin_cos();
        let up = (side == 0) == (l == 0);
        let z = if up { ct * cp } else { -ct * cp };
        Some(SmoothSample {
            wi: Vec3::new(ct * sp, st, z),
            lobe: l,
            weight: radiance_factor(self.n, side, l) * total,
            pdf: m / (total * self.smooth_box * h * ct),
            from: None,
        })
    }

    /// A direction from one groove lobe (see the module notes): `u0` picks the slice, `u` the
    /// bin and the point in it. `None` where the chosen slice holds no energy.
    #[inline]
    pub(super) fn sample(&self, c: &Corners, u0: f32, u: Vec2) -> Option<(Vec3, usize)> {
        let mut k = 0;
        let mut acc = c.weight[0];
        while u0 >= acc && k + 1 < c.count {
            k += 1;
            acc += c.weight[k];
        }
        if !(c.total[k] > 0.0) {
            return None;
        }
        let start = c.slice[k] as usize;
        let cdf = &self.cdf[start..start + self.slice_len()];
        let x = u.x * c.total[k];
        let j = self.search(start / self.slice_len(), x);
        let lo = if j == 0 { 0.0 } else { cdf[j - 1] };
        let frac = if cdf[j] > lo {
            ((x - lo) / (cdf[j] - lo)).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let lobe_len = self.rows * self.b;
        let (l, row, col) = (j / lobe_len, (j % lobe_len) / self.b, j % self.b);
        let h = self.bin_width();
        let theta = if self.smooth() {
            c.e_o[l] + (frac - 0.5) * self.row_width()
        } else {
            warp(-FRAC_PI_2 + (row as f32 + frac) * h, c.e_c[k][l], c.e_o[l])
        };
        let phi = -FRAC_PI_2 + (col as f32 + u.y) * h;
        let (st, ct) = theta.sin_cos();
        let (sp, cp) = phi.sin_cos();
        let up = (c.side == 0) == (l == 0);
        let z = if up { ct * cp } else { -ct * cp };
        Some((Vec3::new(ct * sp, st, z), l))
    }
}

/// The factor `s` of lobe `l` (0: R, 1: T) for light from `side` (module notes) through
/// walls of index `n`: 1 for reflection, `(n_o / n_i)^2` for transmission.
#[inline]
fn radiance_factor(n: f32, side: usize, l: usize) -> f32 {
    match (l, side) {
        (0, _) => 1.0,
        (_, 0) => 1.0 / (n * n),
        _ => n * n,
    }
}

/// Groups of a slice's CDF in the guide ([`WallLobeTable::search`]).
const GUIDE: usize = 16;

/// The end (exclusive) of group `g` of a CDF of `len` entries; `g = -1` (wrapped) ends at 0.
/// The groups split the entries evenly, and some are empty where `len < GUIDE`.
#[inline]
fn group_end(g: usize, len: usize) -> usize {
    g.wrapping_add(1) * len / GUIDE
}

/// One grid neighbour of a pair `[(i, 1 - w), (i + 1, w)]` ([`wall_table::grid_weights`]),
/// picked by `u` with its weight, and `u` rescaled within its share.
#[inline]
fn pick_neighbour(pair: [(usize, f64); 2], u: f32) -> (usize, f32) {
    let [(i, a), (j, b)] = pair.map(|(i, w)| (i, w as f32));
    let (k, rest) = if u < a || !(b > 0.0) {
        (i, u / a)
    } else {
        (j, (u - a) / b)
    };
    (k, rest.clamp(0.0, ONE_BELOW))
}

/// The largest `f32` below 1.
const ONE_BELOW: f32 = 1.0 - f32::EPSILON / 2.0;

/// Keys the place across a crossing groove's opening ([`TracedGroove::sample`]).
const CROSSING_SALT: u64 = 0x6372_6f73_7369_6e67;

/// A smooth-wall groove sample ([`WallLobeTable::sample_smooth`], [`TracedGroove::sample`]),
/// scratch frame.
#[derive(Clone, Copy, Debug)]
pub(super) struct SmoothSample {
    pub wi: Vec3,
    /// 0: reflected, 1: transmitted.
    pub lobe: usize,
    /// `f |cos| / pdf` of the chosen slice: `s` times its energy, or `s` times the traced
    /// path's weight (module notes).
    pub weight: f32,
    /// The density of `wi` from the chosen slice; 1 for a traced path, which has none.
    pub pdf: f32,
    /// A traced path that surfaced ([`GrooveExit::from`]): where it goes on from, relative to
    /// the hit (scratch frame, world units, below the surface), heading up inside the object.
    pub from: Option<Vec3>,
}

/// The groove crossing a traced one along `cross` ([`ScratchLobe::cross`]), placed from the
/// path's stream `key` as a covered point of two independent scratches lies (METHOD.md 8.3):
/// the entry line uniformly across its opening, and its width over the traced groove's that of
/// two tapered scratches (`w(s) = w_0 sqrt(1 - (s/l)^2)`, each at a point drawn in proportion
/// to its width: `s/l` the `x` of a uniform point of the unit disc; the ratio kept within 1/20
/// and 20, where a tip is narrower).
fn crossing_groove(cross: [f32; 2], key: u64) -> Partner {
    let mut h = mix64(key ^ CROSSING_SALT);
    let mut next = || {
        h = mix64(h);
        unit_from_u32(h >> 32)
    };
    let at = next() - 0.5;
    let mut width = || {
        let x = next().sqrt() * (std::f64::consts::TAU * next()).cos();
        (1.0 - x * x).sqrt()
    };
    let ratio = width() / width();
    Partner {
        across: [cross[0] as f64, cross[1] as f64],
        at,
        width: ratio.clamp(0.05, 20.0),
    }
}

/// How far up its ray a path that surfaced goes on from the wall it left, at most (in opening
/// widths of depth; half the wall's depth there where that is less).
const SURFACING_STEP: f64 = 0.01;

/// Smooth glass walls with no table (`lobes = "traced"`, see the module notes): the groove
/// sampled by tracing it, one path a sample.
#[derive(Debug)]
pub struct TracedGroove {
    paths: GroovePaths,
    /// The glass's index `n`.
    n: f32,
    profile: Profile,
    ridge_tan: f64,
    hash: String,
}

impl TracedGroove {
    /// The rate `W'` at which `lobe`'s groove widens along its axis, from the lean its frame
    /// was given (`tan alpha = 2 A W'`, [`crate::render::scratched::ScratchedMaterial::with_lean`]):
    /// the tracer leans each wall by it ([`GroovePaths::trace`]).
    fn taper(&self, lobe: &ScratchLobe) -> f64 {
        let tan = lobe.lean_tan() as f64;
        if tan == 0.0 {
            0.0
        } else {
            tan / (2.0 * self.profile.area())
        }
    }

    /// The groove of `params` (smooth dielectric walls).
    pub fn new(params: &WallTableParams) -> Self {
        let profile = params.profile.clone();
        TracedGroove {
            paths: GroovePaths::new(&profile, params.ior),
            n: params.ior as f32,
            ridge_tan: profile.ridge_tan(),
            hash: format!("{}-traced", params.hash()),
            profile,
        }
    }

    /// One path through the groove for light arriving along `-w` (`w` toward the viewer,
    /// scratch frame, as a table is read): `u.x` the entry point, the bounces from a stream
    /// keyed by `u0` and `u.y`; at a crossing (`lobe`'s [`ScratchLobe::cross`], not zero)
    /// through the union with the other groove, its entry line at a uniform place across that
    /// groove's opening, drawn from the same stream (METHOD.md 8.3). `None` where the path is
    /// lost. With the hit's place (`lobe`'s [`ScratchLobe::place`]), light from inside enters
    /// there and a path that surfaces beside the opening goes on from where it left the groove
    /// ([`GroovePaths::trace`], [`SmoothSample::from`]). The walls lean by `taper`
    /// ([`Self::taper`]; `lobe` and `w` in the unleaned frame).
    #[inline]
    fn sample(
        &self,
        w: Vec3,
        u0: f32,
        u: Vec2,
        lobe: &ScratchLobe,
        taper: f64,
    ) -> Option<SmoothSample> {
        let (cross, place) = (lobe.cross, lobe.place);
        let key = mix64((u0.to_bits() as u64) << 32 | u.y.to_bits() as u64);
        let d0 = [-w.x as f64, -w.y as f64, -w.z as f64];
        let partner = (cross != [0.0; 2]).then(|| crossing_groove(cross, key));
        let at = place.map(|p| p.at as f64);
        let e = self.paths.trace(d0, u.x as f64, at, key, partner, taper)?;
        let wi = Vec3::new(e.d[0] as f32, e.d[1] as f32, e.d[2] as f32);
        let side = (w.z < 0.0) as usize;
        // Transmitted where it ends in the other medium (one that surfaced has not).
        let lobe = (e.in_object != (side == 1)) as usize;
        Some(SmoothSample {
            wi,
            lobe,
            weight: radiance_factor(self.n, side, lobe) * e.w as f32,
            pdf: 1.0,
            from: place.and_then(|p| going_on(&e, p)),
        })
    }
}

/// Where a path traced at `place` ([`GroovePaths::trace`] with `at`) goes on from, where not
/// from the hit ([`SmoothSample::from`], scratch frame, relative to the point of the surface at
/// `place`): where it left the groove's wall inside the object, going down, or, going up for
/// the surface beside the opening, a step up its ray, off the wall: the hit where it surfaces
/// searches for grooves met beside their openings no deeper than that (`origin_depth`), which
/// leaves out the wall it left, whatever the rounding of world positions.
fn going_on(e: &GrooveExit, place: GroovePlace) -> Option<Vec3> {
    let [x, z] = e.from?;
    let step = if e.d[2] > 0.0 {
        (0.5 * -z).min(SURFACING_STEP)
    } else {
        0.0
    };
    let (x, z) = (x + step * e.d[0] / e.d[2], z + step);
    Some(Vec3::new(x as f32 - place.at, 0.0, z as f32) * place.width)
}

/// The groove that light another groove sent down into the glass meets below the surface
/// (METHOD.md 8.1, "Ours": light between grooves; [`crate::render::scratched::ScratchedMaterial::groove_below`]):
/// its traced walls, its frame and the place across it where the light's line crosses the
/// surface (`lobe`), how far below the surface the light began (`depth`, world units) and
/// where the line crosses the surface (`surface`, shading frame, relative to the hit).
#[derive(Clone, Copy, Debug)]
pub struct GrooveBelow<'a> {
    pub groove: &'a TracedGroove,
    pub lobe: ScratchLobe,
    pub depth: f32,
    pub surface: Vec3,
}

impl GrooveBelow<'_> {
    /// One path of the light along `wi` (shading frame, down into the glass) through the
    /// groove, its bounces drawn from a stream keyed by `key`: where it goes on, as a sample
    /// whose weight multiplies the one that sent it (a transmission's into the air, the
    /// path's); the light unchanged where the exact trace finds the line passing the groove;
    /// `None` where the path is lost. It goes on from where it leaves the groove's wall below
    /// the surface, as [`TracedGroove`]'s placed samples do ([`BsdfSample::from`]).
    pub fn sample(&self, wi: Vec3, key: u64) -> Option<BsdfSample> {
        let place = self.lobe.place?;
        let frame = self.lobe.unleaned();
        let d = frame.to_scratch(wi);
        if !(d.z < 0.0 && place.width > 0.0) {
            return None;
        }
        let g = self.groove;
        let depth = (self.depth / place.width) as f64;
        let d = [d.x as f64, d.y as f64, d.z as f64];
        let start = [place.at as f64 + depth * d[0] / -d[2], -depth];
        let e = match g.paths.trace_from(start, d, key, g.taper(&self.lobe), true) {
            CrossingEnd::Left(e) => e,
            CrossingEnd::Missed => {
                return Some(BsdfSample {
                    wi,
                    weight: Rgb::ONE,
                    pdf: 1.0,
                    delta: true,
                    eta: 1.0,
                    from: None,
                })
            }
            CrossingEnd::Lost => return None,
        };
        let into_air = !e.in_object;
        let out = Vec3::new(e.d[0] as f32, e.d[1] as f32, e.d[2] as f32);
        let from = going_on(&e, place).map(|v| frame.from_scratch(v) + self.surface);
        Some(BsdfSample {
            wi: frame.wi_from_scratch(out)?,
            weight: Rgb::splat(radiance_factor(g.n, 1, into_air as usize) * e.w as f32),
            pdf: 1.0,
            delta: true,
            eta: if into_air { 1.0 / g.n } else { 1.0 },
            from,
        })
    }
}

/// The render form of glass scratch walls (see the module notes), shared by the materials
/// that use it.
#[derive(Clone, Debug)]
pub enum GlassWalls {
    /// Read from a wall table: rough walls, and smooth ones with `lobes = "table"`.
    Table(Arc<WallLobeTable>),
    /// Smooth walls traced (`lobes = "traced"`, their default).
    Traced(Arc<TracedGroove>),
}

impl GlassWalls {
    /// The groove's cross-section.
    pub fn profile(&self) -> &Profile {
        match self {
            GlassWalls::Table(t) => &t.profile,
            GlassWalls::Traced(g) => &g.profile,
        }
    }

    /// The profile's [`Profile::ridge_tan`], kept for the hits from inside that ask it.
    pub fn ridge_tan(&self) -> f64 {
        match self {
            GlassWalls::Table(t) => t.ridge_tan,
            GlassWalls::Traced(g) => g.ridge_tan,
        }
    }

    /// The walls' parameter hash (`WallTableParams::hash`; `-traced` appended for traced
    /// walls).
    pub fn hash(&self) -> &str {
        match self {
            GlassWalls::Table(t) => &t.hash,
            GlassWalls::Traced(g) => &g.hash,
        }
    }

    /// The glass's index.
    pub fn ior(&self) -> f32 {
        match self {
            GlassWalls::Table(t) => t.n,
            GlassWalls::Traced(g) => g.n,
        }
    }

    /// Whether the walls are smooth (their lobes are reached by BSDF sampling only).
    pub fn smooth(&self) -> bool {
        match self {
            GlassWalls::Table(t) => t.smooth(),
            GlassWalls::Traced(_) => true,
        }
    }
}

/// The slices a `wo` reads: up to four, with bilinear weights, each slice's total energy and
/// the warp's fixed points (`e_c` the slice's smooth exit angle per lobe, `e_o` `wo`'s).
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Corners {
    side: usize,
    count: usize,
    slice: [u32; 4],
    weight: [f32; 4],
    total: [f32; 4],
    e_c: [[f32; 2]; 4],
    e_o: [f32; 2],
}

/// The piecewise-linear map of `(-pi/2, pi/2)` onto itself carrying `from` to `to`.
#[inline]
fn warp(x: f32, from: f32, to: f32) -> f32 {
    if x <= from {
        -FRAC_PI_2 + (x + FRAC_PI_2) * (to + FRAC_PI_2) / (from + FRAC_PI_2)
    } else {
        FRAC_PI_2 - (FRAC_PI_2 - x) * (FRAC_PI_2 - to) / (FRAC_PI_2 - from)
    }
}

/// The inverse of [`warp`] at `y` and the warp's slope there.
#[inline]
fn unwarp(y: f32, from: f32, to: f32) -> (f32, f32) {
    if y <= to {
        let slope = (to + FRAC_PI_2) / (from + FRAC_PI_2);
        (-FRAC_PI_2 + (y + FRAC_PI_2) / slope, slope)
    } else {
        let slope = (FRAC_PI_2 - to) / (FRAC_PI_2 - from);
        (FRAC_PI_2 - (FRAC_PI_2 - y) / slope, slope)
    }
}

/// The scratched-glass BSDF at one hit (see the module notes).
#[derive(Clone, Copy, Debug)]
pub struct ScratchedGlassBsdf<'a> {
    /// Relative index of the smooth base, inside over outside.
    pub eta: f32,
    pub walls: &'a GlassWalls,
    lobes: CoveredLobes,
}

impl<'a> ScratchedGlassBsdf<'a> {
    /// The lobes at the hit.
    pub fn lobes(&self) -> &[ScratchLobe] {
        self.lobes.as_slice()
    }

    /// This BSDF with its sampling's lobe number read within `share` ([`super::LobeShare`]).
    #[inline(always)]
    pub fn in_share(mut self, share: super::LobeShare) -> Self {
        self.lobes = self.lobes.in_share(share);
        self
    }

    /// `lobes` with coverages `c_k >= 0` ([`CoveredLobes`]).
    pub fn new(eta: f32, walls: &'a GlassWalls, lobes: &[ScratchLobe]) -> Self {
        ScratchedGlassBsdf {
            eta,
            walls,
            lobes: CoveredLobes::new(lobes),
        }
    }

    /// `(sum_k c_k f_k, sum_k c_k pdf_k)`: the groove lobes' value and the density of the
    /// sampler's non-delta part.
    #[inline]
    pub fn eval_pdf(&self, wo: Vec3, wi: Vec3) -> (Rgb, f32) {
        let GlassWalls::Table(table) = self.walls else {
            return (Rgb::ZERO, 0.0);
        };
        if wo.z == 0.0 {
            return (Rgb::ZERO, 0.0);
        }
        let (mut f, mut p) = (0.0f32, 0.0f32);
        for l in self.lobes.as_slice() {
            let Some((wi_s, lean)) = l.wi_to_scratch(wi) else {
                continue;
            };
            let c = table.corners(l.wo_to_scratch(wo));
            let (fk, pk) = table.eval_pdf(&c, wi_s);
            f += l.coverage * fk * lean;
            p += l.coverage * pk;
        }
        (Rgb::splat(f), p)
    }

    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        self.eval_pdf(wo, wi).0
    }

    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        self.eval_pdf(wo, wi).1
    }

    /// `u_lobe` picks the component (module notes) and, rescaled, a groove lobe's slice; `u`
    /// the direction.
    #[inline]
    pub fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        let u_lobe = self.lobes.lobe_number(u_lobe);
        if wo.z == 0.0 {
            return None;
        }
        let (fr, cos_t, eta_it) = fresnel_f32::dielectric(wo.z, self.eta);
        let base = 1.0 - self.lobes.total();
        let p_reflect = base * fr;
        if u_lobe < p_reflect {
            return Some(mirror_sample(wo, p_reflect));
        }
        let p_transmit = base * (1.0 - fr);
        let acc = p_reflect + p_transmit;
        if u_lobe < acc || self.lobes.is_empty() {
            if !(p_transmit > 0.0) {
                return None;
            }
            return Some(refraction_sample(wo, cos_t, eta_it, p_transmit));
        }
        let (k, u0) = self.lobes.pick(u_lobe, acc);
        let l = &self.lobes.as_slice()[k];
        let n = self.walls.ior();
        let eta = |lobe: usize| {
            if lobe == 0 {
                1.0
            } else if wo.z > 0.0 {
                n
            } else {
                1.0 / n
            }
        };
        let table = match self.walls {
            GlassWalls::Table(t) if !t.smooth() => t,
            walls => {
                // Smooth walls: a traced path, or the one-slice estimate (module notes); no
                // light sampling to weigh against.
                let (l, s) = match walls {
                    GlassWalls::Traced(g) => {
                        // A traced groove leans its walls, not its frame.
                        let frame = l.unleaned();
                        let w = frame.wo_to_scratch(wo);
                        (frame, g.sample(w, u0, u, &frame, g.taper(l)))
                    }
                    GlassWalls::Table(t) => (*l, t.sample_smooth(l.wo_to_scratch(wo), u0, u)),
                };
                let s = s?;
                return Some(BsdfSample {
                    wi: l.wi_from_scratch(s.wi)?,
                    weight: Rgb::splat(s.weight),
                    pdf: l.coverage * s.pdf,
                    delta: false,
                    eta: eta(s.lobe),
                    from: l.going_on_from(s.from),
                });
            }
        };
        let corners = table.corners(l.wo_to_scratch(wo));
        let (wi_s, lobe) = table.sample(&corners, u0, u)?;
        let wi = l.wi_from_scratch(wi_s)?;
        let (f, pdf) = self.eval_pdf(wo, wi);
        if !(pdf > 0.0) {
            return None;
        }
        Some(BsdfSample {
            wi,
            weight: f * (wi.z.abs() / pdf),
            pdf,
            delta: false,
            eta: eta(lobe),
            from: l.going_on_from(None),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::precompute::wall_table::WallTableParams;
    use crate::render::bsdf::GroovePlace;

    /// Light from inside sampled at a placed hit ([`ScratchLobe::place`]) that surfaces goes
    /// on from a point beside the groove's walls below the surface (the scratch's
    /// frame turned and its width scaled into the shading frame's world units), up through the
    /// glass to the surface beside the opening, with a reflection's weight; some of the light
    /// does. Light it sends down into the glass gives the wall it left there, below the
    /// surface, no deeper than the groove.
    #[test]
    fn surfaced_samples_go_on_from_inside_the_groove_to_beside_it() {
        let profile = Profile::parse("round:depth=0.3,segments=8").unwrap();
        let walls = GlassWalls::Traced(Arc::new(TracedGroove::new(&WallTableParams::new(
            profile, 1.5, 0.0,
        ))));
        let (beta, width) = (0.7f32, 0.004f32);
        let (mut surfaced, mut departed) = (0, 0);
        for k in 0..4000 {
            let h = |i: u64| crate::hash::unit_f32(mix64(k * 8 + i));
            let at = h(0) - 0.5;
            let lobe = ScratchLobe::new(1.0, beta.cos(), beta.sin())
                .at_place(Some(GroovePlace { at, width }));
            let bsdf = ScratchedGlassBsdf::new(1.5, &walls, &[lobe]);
            let (t, p) = (0.75 + 0.8 * h(1), 6.3 * h(2));
            let wo = Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), -t.cos());
            let Some(bs) = bsdf.sample(wo, 0.999, Vec2::new(h(3), h(4))) else {
                continue;
            };
            let Some(from) = bs.from else {
                continue;
            };
            let s = lobe.to_scratch(from) / width;
            if bs.wi.z < 0.0 {
                departed += 1;
                assert!(bs.eta == 1.0 && bs.weight == Rgb::ONE, "{bs:?}");
                assert!(s.z < 0.0 && s.z >= -0.3 - 1e-6, "from {s:?}, at {at}");
                continue;
            }
            surfaced += 1;
            assert!(bs.eta == 1.0 && bs.weight == Rgb::ONE, "{bs:?}");
            // Just off the wall it left (a step up its ray), below the surface, no deeper
            // than the groove.
            assert!(s.z < 0.0 && s.z > -0.3, "from {s:?}, at {at}");
            let up = lobe.to_scratch(from + bs.wi * (-from.z / bs.wi.z)) / width;
            assert!(
                (up.x + at).abs() > 0.5 && up.z.abs() < 1e-4,
                "surfaces at {up:?}"
            );
        }
        assert!(surfaced > 40, "{surfaced} samples surfaced");
        assert!(departed > 40, "{departed} samples sent down");
    }

    /// The guided search ([`WallLobeTable::search`]) finds the entry a binary search of the
    /// whole slice finds, at every CDF value (ties and empty bins included) and between them,
    /// for slices longer than the guide, as long and shorter (empty groups).
    #[test]
    fn guided_search_is_the_whole_search() {
        for (roughness, bins) in [(0.0, 2), (0.0, 8), (0.0, 12), (0.3, 3)] {
            let p = WallTableParams {
                theta_bins: 2,
                phi_bins: 2,
                bins,
                paths: 300,
                ..WallTableParams::new(Profile::parse("v:angle=90").unwrap(), 1.5, roughness)
            };
            let t = WallLobeTable::new(&WallTable::compute(&p).unwrap());
            let len = t.slice_len();
            for slice in 0..t.totals.len() {
                let cdf = &t.cdf[slice * len..(slice + 1) * len];
                let mut xs: Vec<f32> = cdf
                    .iter()
                    .flat_map(|&v| [v, v * 0.999, v * 1.001])
                    .collect();
                xs.extend([-1.0, 0.0, 2.0 * t.totals[slice]]);
                for x in xs {
                    let whole = cdf.partition_point(|&v| v <= x).min(len - 1);
                    assert_eq!(t.search(slice, x), whole, "bins {bins} slice {slice} x {x}");
                }
            }
        }
    }
}
