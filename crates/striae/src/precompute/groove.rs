//! The exact BSDF of an extruded groove by 2.5D tracing (METHOD.md 8.1): a virtual
//! gonioreflectometer.
//!
//! The groove is the profile in the `(x, z)` plane extruded to infinity along `y`; the flat
//! surface continues the rims to `x = +-inf` at `z = 0`; air above, the object below. Paths carry
//! full 3D unit directions, but an intersection needs only their `(x, z)` part (the position
//! along `y` never matters), so the geometry is the 2D precompute's ([`CrossSection`]) and a
//! path costs what a 2D path costs. At a wall of normal `n = (n_x, 0, n_z)`:
//!
//! * `Diffuse` walls reflect into a cosine-weighted 3D direction about `n`, `Specular` walls
//!   mirror; both multiply the path's weight by the Fresnel law at the true 3D cosine `|w . n|`
//!   at every hit (opaque walls: the object is never entered).
//! * `Dielectric` walls are smooth glass of index `ior`: the exact Fresnel reflectance picks
//!   reflection or refraction (Snell's law in 3D keeps `n w.y`), lossless. Inside the object a
//!   path ends when it heads down with no wall ahead (transmitted into the bulk); heading up it
//!   meets the groove from below (the same split) or the flat surface beside it (smooth
//!   Fresnel: total internal reflection, reflection back down, or exit into the air).
//! * `roughness > 0` makes the walls GGX microsurfaces of `alpha = roughness`: a rough
//!   conductor (the Fresnel law per microfacet) or a rough dielectric, scattering as the
//!   random walk on the microsurface of [`Microsurface`] (Heitz16; METHOD.md 9.7), lossless
//!   where the facets are. `single_scatter` takes one microfacet event instead ([`Ggx`],
//!   sampled by visible normals, separable Smith masking), absorbing a direction below the
//!   wall: the light that would meet a second microfacet is lost.
//!
//! Light arrives from outside (`Outside`, through the opening) or from inside the object
//! (`Inside`, dielectric walls only: the ray reaches the profile from below on its way to the
//! opening). The results are fractions of the energy incident on the opening per exit bin:
//! `reflected` leaves on the incident side, `transmitted` on the other, each binned by the
//! `theta`, `phi` of METHOD.md section 1 of its direction, a direction inside the object
//! mirrored to point up first (`(x, y, -z)`). The incident angles of an `Inside` source are
//! those of its direction mirrored the same way.
//!
//! Determinism: path `k` draws from a counter-based stream keyed by `(seed, k)` (entry jitter,
//! then three numbers per bounce) and the weights are summed in 2^-40 fixed point (integer
//! sums are associative), so the output is bit-identical for any thread count.

use crate::hash::{mix64, GOLDEN};
use crate::math::{Vec2, Vec3};
use crate::optics::fresnel::{dielectric, FresnelLaw};
use crate::optics::microfacet::Ggx;
use crate::optics::microsurface::Microsurface;
use crate::precompute::angle_bins::AngleBins;
use crate::precompute::cross_section::{CrossSection, T_EPS};
use crate::precompute::crossing::{Crossing, CrossingEnd, Partner};
use crate::precompute::profile::Profile;
use rayon::prelude::*;
use std::f64::consts::PI;

/// The walls' BSDF.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GrooveWalls {
    /// Lambertian (3D cosine lobe about the wall normal) times the Fresnel law per hit.
    Diffuse,
    /// Mirror (or rough conductor) times the Fresnel law per hit.
    Specular,
    /// Smooth (or rough) glass of index `ior`: reflection and refraction into the object.
    Dielectric,
}

/// Where the light comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightSide {
    /// From the air above the surface.
    Outside,
    /// From inside the object (dielectric walls only).
    Inside,
}

/// The settings of one goniometer run.
#[derive(Clone, Debug, PartialEq)]
pub struct GonioSettings {
    pub walls: GrooveWalls,
    /// GGX `alpha` of the walls, in `[0, 1]`; 0: smooth.
    pub roughness: f64,
    /// Rough walls scatter once (the single-scattering GGX BSDF, losing the light that would
    /// meet a second microfacet) instead of walking the microsurface (METHOD.md 9.7).
    pub single_scatter: bool,
    /// The Fresnel law of opaque (diffuse, specular) walls.
    pub fresnel_law: FresnelLaw,
    /// The object's index of refraction (dielectric walls and the flat surface).
    pub ior: f64,
    /// Incident `theta_i`, `phi_i` (radians, METHOD.md section 1), each in `(-pi/2, pi/2)`.
    pub theta_i: f64,
    pub phi_i: f64,
    pub side: LightSide,
    /// `Inside` only: also trace the light aimed at the flat surface beside the opening that
    /// meets the groove first, or, totally reflected there, right after. Seen from inside, a
    /// groove is a ridge of air below the surface, and at grazing incidence it intercepts more
    /// light than crosses its opening: the ridge's projected width over the opening's on the
    /// way to the surface, and under total internal reflection as much again on the way back
    /// from it ([`GonioOutput::intercept`]). The fractions stay per unit opening, so a lossless
    /// groove's `albedo_r + albedo_t` is the intercept.
    pub beside: bool,
    /// Paths traced (entry points, stratified over the opening, or the band of `beside`).
    pub paths: u64,
    /// Bins `B` per angle.
    pub bins: usize,
    /// Surface interactions per path before it is dropped (and its energy reported).
    pub max_bounces: usize,
    pub seed: u64,
}

impl Default for GonioSettings {
    fn default() -> Self {
        GonioSettings {
            walls: GrooveWalls::Diffuse,
            roughness: 0.0,
            single_scatter: false,
            fresnel_law: FresnelLaw::Schlick { n: 1.5 },
            ior: 1.5,
            theta_i: 0.0,
            phi_i: 0.0,
            side: LightSide::Outside,
            beside: false,
            paths: 200_000,
            bins: 32,
            max_bounces: 256,
            seed: 0,
        }
    }
}

/// Why a run was refused; `key` is the command-line flag.
#[derive(Debug, thiserror::Error, PartialEq)]
#[error("invalid gonio parameter `--{key}` = {value}: {why}")]
pub struct GonioError {
    pub key: &'static str,
    pub value: String,
    pub why: &'static str,
}

impl GonioSettings {
    /// Reject settings the tracer cannot honour.
    pub fn validate(&self) -> Result<(), GonioError> {
        let bad = |key, value: String, why| Err(GonioError { key, value, why });
        let deg = |a: f64| format!("{} degrees", a.to_degrees());
        let open = |a: f64| a.is_finite() && a.abs() < PI / 2.0;
        if !open(self.theta_i) {
            return bad("theta-i", deg(self.theta_i), "must be in (-90, 90)");
        }
        if !open(self.phi_i) {
            return bad("phi-i", deg(self.phi_i), "must be in (-90, 90)");
        }
        if !(self.roughness.is_finite() && (0.0..=1.0).contains(&self.roughness)) {
            return bad("roughness", self.roughness.to_string(), "must be in [0, 1]");
        }
        if self.roughness > 0.0 && self.walls == GrooveWalls::Diffuse {
            return bad(
                "roughness",
                self.roughness.to_string(),
                "applies to specular (rough conductor) and dielectric walls, not diffuse ones",
            );
        }
        if self.single_scatter && self.roughness == 0.0 {
            return bad(
                "single-scatter",
                "true".into(),
                "applies to rough walls (roughness > 0)",
            );
        }
        if !(self.ior.is_finite() && self.ior >= 1.0) {
            return bad("ior", self.ior.to_string(), "must be finite and >= 1");
        }
        if self.side == LightSide::Inside && self.walls != GrooveWalls::Dielectric {
            return bad(
                "side",
                "inside".into(),
                "light from inside the object needs dielectric walls (opaque walls have no inside)",
            );
        }
        if self.beside && self.side != LightSide::Inside {
            return bad(
                "beside",
                "outside".into(),
                "light from outside meets a groove only through its opening",
            );
        }
        if !(1..=4096).contains(&self.bins) {
            return bad("bins", self.bins.to_string(), "must be in 1..=4096");
        }
        if self.paths == 0 || self.paths > MAX_PATHS {
            return bad(
                "paths",
                self.paths.to_string(),
                "must be in 1..=2^24 (a bin's fixed-point sum holds 2^24 paths' weight; average \
                 runs of other seeds for more)",
            );
        }
        if !(1..=100_000).contains(&self.max_bounces) {
            return bad(
                "max-bounces",
                self.max_bounces.to_string(),
                "must be in 1..=100000",
            );
        }
        match self.fresnel_law {
            FresnelLaw::Schlick { n } | FresnelLaw::Dielectric { n }
                if !(n.is_finite() && n >= 1.0) =>
            {
                bad("ior", n.to_string(), "must be finite and >= 1")
            }
            FresnelLaw::Conductor { eta, k }
                if !(eta.is_finite() && k.is_finite() && eta > 0.0 && k >= 0.0) =>
            {
                bad(
                    "fresnel-law",
                    format!("conductor:{eta},{k}"),
                    "a conductor needs finite ETA > 0 and K >= 0",
                )
            }
            _ => Ok(()),
        }
    }

    /// The direction the incident light travels (unit, 3D).
    pub fn incident_travel(&self) -> [f64; 3] {
        let (st, ct) = self.theta_i.sin_cos();
        let (sp, cp) = self.phi_i.sin_cos();
        // w_i points away from the surface, towards the light (mirrored for `Inside`).
        let z = match self.side {
            LightSide::Outside => ct * cp,
            LightSide::Inside => -ct * cp,
        };
        [-ct * sp, -st, -z]
    }
}

/// The result of a run: fractions of the incident energy, `[theta bin][phi bin]` row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct GonioOutput {
    pub bins: usize,
    /// Bin centres (radians) of both axes, over `[-pi/2, pi/2]`.
    pub centres: Vec<f64>,
    pub reflected: Vec<f64>,
    pub transmitted: Vec<f64>,
    pub albedo_r: f64,
    pub albedo_t: f64,
    /// With [`GonioSettings::beside`], the light meeting the groove per unit of light crossing
    /// its opening (the share of the band's paths that meet the groove times the band's
    /// width); `None` for light through the opening alone.
    pub intercept: Option<f64>,
    /// Fraction dropped by the bounce cap.
    pub dropped: f64,
    /// Fraction lost to round-off (a ray with no surface ahead and nowhere to leave); 0.
    pub lost: f64,
}

/// Fixed-point scale of the accumulated weights (`w <= 1`).
const FIXED: f64 = (1u64 << 40) as f64;

/// The most paths one trace takes: every one of them may land in one bin, whose `u64` sum of
/// weights at [`FIXED`] scale holds `2^64 / 2^40` of them.
pub const MAX_PATHS: u64 = 1 << 24;

/// Integer accumulators of a set of paths.
#[derive(Clone)]
struct Acc {
    reflected: Vec<u64>,
    transmitted: Vec<u64>,
    dropped: u64,
    lost: u64,
    /// Paths of the `beside` band that pass the groove (before and after the flat surface).
    missed: u64,
}

impl Acc {
    fn new(bins: usize) -> Self {
        Acc {
            reflected: vec![0; bins * bins],
            transmitted: vec![0; bins * bins],
            dropped: 0,
            lost: 0,
            missed: 0,
        }
    }

    fn merge(mut self, o: Acc) -> Acc {
        for (a, b) in self.reflected.iter_mut().zip(&o.reflected) {
            *a += b;
        }
        for (a, b) in self.transmitted.iter_mut().zip(&o.transmitted) {
            *a += b;
        }
        self.dropped += o.dropped;
        self.lost += o.lost;
        self.missed += o.missed;
        self
    }
}

#[inline(always)]
fn fixed(w: f64) -> u64 {
    (w * FIXED).round() as u64
}

/// Paths per work item.
const BLOCK: u64 = 4096;

/// Salt of the goniometer's random streams.
const GONIO_SALT: u64 = 0x474F_4E49_4F00_0001;
/// Salt of the microsurface walks' streams (a stream per path and bounce).
const WALK_SALT: u64 = 0x5741_4C4B_0000_0001;

/// Run the goniometer. `progress` is called from worker threads with the number of paths just
/// finished. Runs on the current rayon pool.
pub fn trace_groove(
    profile: &Profile,
    s: &GonioSettings,
    progress: &(dyn Fn(u64) + Sync),
) -> Result<GonioOutput, GonioError> {
    s.validate()?;
    let tracer = Tracer::new(profile, s);
    let blocks = s.paths.div_ceil(BLOCK);
    // At most about 4 work items a thread, so that at most 5 accumulators a thread are alive
    // (`lab::gonio::memory_estimate`); the sums are integers, the same however split.
    let min_len = blocks
        .div_ceil(4 * rayon::current_num_threads() as u64)
        .max(1);
    let acc = (0..blocks as usize)
        .into_par_iter()
        .with_min_len(min_len as usize)
        .map(|b| b as u64)
        .fold(
            || Acc::new(s.bins),
            |mut acc, b| {
                let (lo, hi) = (b * BLOCK, ((b + 1) * BLOCK).min(s.paths));
                for k in lo..hi {
                    tracer.path(k, &mut acc);
                }
                progress(hi - lo);
                acc
            },
        )
        .reduce(|| Acc::new(s.bins), Acc::merge);
    // Every path stands for `band_width / paths` of the opening's light.
    let norm = tracer.band_width / (FIXED * s.paths as f64);
    let reflected: Vec<f64> = acc.reflected.iter().map(|&v| v as f64 * norm).collect();
    let transmitted: Vec<f64> = acc.transmitted.iter().map(|&v| v as f64 * norm).collect();
    let albedo_r = acc.reflected.iter().sum::<u64>() as f64 * norm;
    let albedo_t = acc.transmitted.iter().sum::<u64>() as f64 * norm;
    Ok(GonioOutput {
        bins: s.bins,
        centres: tracer.bins.centres(),
        reflected,
        transmitted,
        albedo_r,
        albedo_t,
        intercept: s
            .beside
            .then(|| tracer.band_width * (1.0 - acc.missed as f64 / s.paths as f64)),
        dropped: acc.dropped as f64 * norm,
        lost: acc.lost as f64 * norm,
    })
}

/// Uniform in `[0, 1)` from the top 53 bits.
#[inline(always)]
fn unit(x: u64) -> f64 {
    (x >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

#[inline(always)]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `-d` in the frame `(x, y = (0, 1, 0), z)`: the direction back along a ray travelling `d`.
#[inline(always)]
fn back_in_frame(x: [f64; 3], z: [f64; 3], d: [f64; 3]) -> [f64; 3] {
    [-dot(d, x), -d[1], -dot(d, z)]
}

/// [`from_frame`] normalised.
#[inline(always)]
fn unit_from_frame(x: [f64; 3], z: [f64; 3], l: [f64; 3]) -> [f64; 3] {
    let d = from_frame(x, z, l);
    let len = dot(d, d).sqrt();
    [d[0] / len, d[1] / len, d[2] / len]
}

/// `a x + b y + c z` for the frame `(x, y = (0, 1, 0), z)`.
#[inline(always)]
fn from_frame(x: [f64; 3], z: [f64; 3], l: [f64; 3]) -> [f64; 3] {
    [l[0] * x[0] + l[2] * z[0], l[1], l[0] * x[2] + l[2] * z[2]]
}

/// The three random numbers of one bounce of one path (counters `base .. base + 3` of the
/// path's stream), each computed on demand.
#[derive(Clone, Copy)]
struct Draws {
    key: u64,
    base: u64,
}

impl Draws {
    #[inline(always)]
    fn get(self, i: u64) -> f64 {
        unit(mix64(
            self.key.wrapping_add((self.base + i).wrapping_mul(GOLDEN)),
        ))
    }
}

/// Where a path is and what it carries.
#[derive(Clone, Copy, Debug)]
struct Ray {
    pos: [f64; 2],
    /// Unit travel direction.
    d: [f64; 3],
    in_object: bool,
    /// The segment last hit (skipped by the next query), `usize::MAX` for none.
    skip: usize,
    w: f64,
    /// The rate `W'` at which the groove's width changes along its axis (`y`), where the path
    /// runs: 0 for the extruded groove ([`Tracer::wall_normal`]).
    taper: f64,
}

/// Where entry points start on the line `z = 0` and the width they cover, for light along
/// `d`: the opening `[-1/2, 1/2]`, or with `beside` every line through the groove's bounding
/// box before it reaches the surface (a line reaches `z = cs.z_min` at `dx` from where it
/// crosses `z = 0`), and under total internal reflection ([`totally_reflected`]) after it
/// too, the surface beside the opening reflecting the light into the groove.
fn entry_band(cs: &CrossSection, d: [f64; 3], beside: bool, ior: f64) -> (f64, f64) {
    if !beside {
        return (-0.5, 1.0);
    }
    let dx = cs.z_min * d[0] / d[2];
    if totally_reflected(d, ior) {
        (-0.5 - dx.abs(), 1.0 + 2.0 * dx.abs())
    } else {
        (-0.5 - dx.max(0.0), 1.0 + dx.abs())
    }
}

/// Whether light inside the object along the unit `d` is totally reflected at the flat
/// surface: `n^2 (1 - d_z^2) > 1`.
pub fn totally_reflected(d: [f64; 3], ior: f64) -> bool {
    ior * ior * (1.0 - d[2] * d[2]) > 1.0
}

/// How a path ended ([`Tracer::run`]).
enum Outcome {
    /// With nothing ahead: into the air or the bulk.
    Left(Ray),
    /// From inside, beside the groove without meeting it.
    Missed,
    Absorbed,
    /// Out of bounces, with its weight.
    Dropped(f64),
    /// From inside, after meeting the groove, on its way up to the flat surface beside the
    /// opening, where another groove may lie ([`GroovePaths::trace`] with `at`): the ray as it
    /// left the last wall.
    Surfaced(Ray),
}

/// What a surface interaction did to a path.
enum Scatter {
    /// The path goes on (its direction, medium and weight updated).
    On,
    /// The path is absorbed (a microfacet sample below the wall).
    Absorbed,
    /// A microsurface walk past [`crate::optics::microsurface::MAX_ORDER`] events.
    Dropped,
}

#[derive(Debug)]
struct Tracer {
    cs: CrossSection,
    bins: AngleBins,
    s: GonioSettings,
    ggx: Option<Ggx>,
    key: u64,
    d0: [f64; 3],
    /// Where entry points start on the line `z = 0` and the width they cover (the opening
    /// `[-1/2, 1/2]`, or with `beside` every line through the groove's bounding box).
    band_start: f64,
    band_width: f64,
}

impl Tracer {
    fn new(profile: &Profile, s: &GonioSettings) -> Self {
        let cs = CrossSection::new(profile);
        let d0 = s.incident_travel();
        let (band_start, band_width) = entry_band(&cs, d0, s.beside, s.ior);
        Tracer {
            band_start,
            band_width,
            cs,
            bins: AngleBins::new(s.bins),
            s: s.clone(),
            ggx: (s.roughness > 0.0).then(|| Ggx::isotropic(s.roughness as f32)),
            key: mix64(mix64(s.seed.wrapping_add(GOLDEN)) ^ GONIO_SALT),
            d0,
        }
    }

    /// Draw `counter` of path `path`'s stream (counter 0: the entry jitter; bounce `k` uses
    /// `1 + 3k .. 4 + 3k`).
    #[inline(always)]
    fn draw(&self, path_key: u64, counter: u64) -> f64 {
        unit(mix64(path_key.wrapping_add(counter.wrapping_mul(GOLDEN))))
    }

    /// The starting ray of path `k`: its entry point stratified over the opening (or the
    /// band of `beside`).
    fn start(&self, k: u64, path_key: u64) -> Ray {
        let x0 = self.band_start
            + self.band_width * (k as f64 + self.draw(path_key, 0)) / self.s.paths as f64;
        self.entry(x0, self.d0, self.s.side == LightSide::Inside)
    }

    /// A ray along `d` entering at `x0` on the line `z = 0`: there from the air, or from
    /// inside the object (`inside`), below the deepest point on the line through `(x0, 0)`.
    fn entry(&self, x0: f64, d: [f64; 3], inside: bool) -> Ray {
        let (pos, in_object) = if inside {
            let z = self.cs.z_min - 1.0;
            ([x0 + z / d[2] * d[0], z], true)
        } else {
            ([x0, 0.0], false)
        };
        Ray {
            pos,
            d,
            in_object,
            skip: usize::MAX,
            w: 1.0,
            taper: 0.0,
        }
    }

    /// Trace path `k` into `acc`.
    fn path(&self, k: u64, acc: &mut Acc) {
        let path_key = mix64(self.key.wrapping_add(k.wrapping_mul(GOLDEN)));
        match self.run(self.start(k, path_key), path_key, self.s.beside, false) {
            Outcome::Left(ray) => self.leave(&ray, acc),
            Outcome::Missed => acc.missed += 1,
            Outcome::Absorbed => {}
            Outcome::Dropped(w) | Outcome::Surfaced(Ray { w, .. }) => acc.dropped += fixed(w),
        }
    }

    /// Follow `ray` until it leaves the groove (`beside`: a path from inside that does not meet
    /// the groove before it reaches the flat surface, or, totally reflected there, right
    /// after, is `Missed`; `surfacing`: one that met it and heads up to the flat surface from
    /// below the surface, is `Surfaced`).
    fn run(&self, mut ray: Ray, path_key: u64, beside: bool, surfacing: bool) -> Outcome {
        // Aimed beside the groove and not yet in it.
        let mut aimed = beside;
        for bounce in 0..self.s.max_bounces {
            // This bounce's random numbers, drawn only where needed.
            let u = Draws {
                key: path_key,
                base: 1 + 3 * bounce as u64,
            };
            let d2 = [ray.d[0], ray.d[2]];
            let t_min = if bounce == 0 { -1e-12 } else { T_EPS };
            if !ray.in_object {
                let Some((seg, t)) = self.cs.nearest(ray.pos, d2, ray.skip, t_min) else {
                    return Outcome::Left(ray);
                };
                ray.pos = [ray.pos[0] + t * d2[0], ray.pos[1] + t * d2[1]];
                ray.skip = seg;
                match self.wall(&mut ray, seg, u) {
                    Scatter::On => {}
                    Scatter::Absorbed => return Outcome::Absorbed,
                    Scatter::Dropped => return Outcome::Dropped(ray.w),
                }
                continue;
            }
            let hit = self.cs.nearest_either_side(ray.pos, d2, ray.skip, t_min);
            // The flat surface z = 0 beside the groove, reached from below.
            let t_flat = if ray.d[2] > 0.0 {
                -ray.pos[1] / ray.d[2]
            } else {
                f64::INFINITY
            };
            match hit {
                Some((seg, t, _)) if t < t_flat => {
                    aimed = false;
                    ray.pos = [ray.pos[0] + t * d2[0], ray.pos[1] + t * d2[1]];
                    ray.skip = seg;
                    match self.wall(&mut ray, seg, u) {
                        Scatter::On => {}
                        Scatter::Absorbed => return Outcome::Absorbed,
                        Scatter::Dropped => return Outcome::Dropped(ray.w),
                    }
                }
                _ if aimed && !(t_flat.is_finite() && totally_reflected(ray.d, self.s.ior)) => {
                    // Aimed beside the groove and passing it (before the flat surface, or
                    // after reflecting there): the flat surface's light.
                    return Outcome::Missed;
                }
                _ if t_flat.is_finite() => {
                    if surfacing && !aimed && ray.pos[1] < -SURFACING_DEPTH {
                        return Outcome::Surfaced(ray);
                    }
                    ray.pos = [ray.pos[0] + t_flat * d2[0], 0.0];
                    ray.skip = usize::MAX;
                    self.flat(&mut ray, u.get(2));
                }
                _ => return Outcome::Left(ray),
            }
        }
        Outcome::Dropped(ray.w)
    }

    /// A path with nothing ahead: it leaves upward into the air or downward into the bulk.
    fn leave(&self, ray: &Ray, acc: &mut Acc) {
        let d = ray.d;
        let (up, into_air) = if ray.in_object {
            (-d[2], false)
        } else {
            (d[2], true)
        };
        if up <= 0.0 {
            acc.lost += fixed(ray.w);
            return;
        }
        let j = self.bins.bin_sin(d[1]) * self.s.bins + self.bins.bin_xz(d[0], up);
        let incident_side = into_air == (self.s.side == LightSide::Outside);
        let hist = if incident_side {
            &mut acc.reflected
        } else {
            &mut acc.transmitted
        };
        hist[j] += fixed(ray.w);
    }

    /// A wall hit at `ray.pos` on segment `seg`.
    fn wall(&self, ray: &mut Ray, seg: usize, u: Draws) -> Scatter {
        let mut n = self.wall_normal(seg, ray.taper);
        // The media follow the path's state; `n` is turned to face the ray.
        let from_air = !ray.in_object;
        if dot(ray.d, n) > 0.0 {
            n = [-n[0], -n[1], -n[2]];
        }
        // `n` faces the incoming ray; `x` completes the frame (x, y, n).
        let x = [n[2], 0.0, -n[0]];
        let cos_i = -dot(ray.d, n);
        match (self.s.walls, self.ggx) {
            (GrooveWalls::Diffuse, _) => {
                ray.w *= self.s.fresnel_law.reflectance(cos_i);
                let (u0, u1) = (u.get(0), u.get(1));
                let r = u0.sqrt();
                let (sp, cp) = (2.0 * PI * u1).sin_cos();
                let l = [r * cp, r * sp, (1.0 - u0).max(0.0).sqrt()];
                ray.d = from_frame(x, n, l);
            }
            (GrooveWalls::Specular, None) => {
                ray.w *= self.s.fresnel_law.reflectance(cos_i);
                let c = 2.0 * cos_i;
                ray.d = [
                    ray.d[0] + c * n[0],
                    ray.d[1] + c * n[1],
                    ray.d[2] + c * n[2],
                ];
            }
            (GrooveWalls::Dielectric, None) => {
                let (n1, n2) = if from_air {
                    (1.0, self.s.ior)
                } else {
                    (self.s.ior, 1.0)
                };
                self.smooth_dielectric(ray, n, cos_i, n2 / n1, u.get(2));
            }
            (walls, Some(_)) if !self.s.single_scatter => {
                return self.walk(ray, walls, x, n, from_air, u)
            }
            (walls, Some(ggx)) => return self.rough(ray, &ggx, walls, x, n, from_air, u),
        }
        Scatter::On
    }

    /// The unit normal of wall segment `seg` (the segment's side) where the groove's width
    /// changes at the rate `taper` (`W'`, opening widths per unit length along `y`; the
    /// groove scaled about the opening's centre, its depth in proportion): the wall `n . p =
    /// c` of the cross-section at width 1 is `n . p = c W(y)` along the groove, whose normal
    /// tilts along the axis by `-c W'` (METHOD.md 8.3, tapered ends; `lean = true`): for a V of
    /// depth `d` every wall point alike (`tan = d W'` off the surface's normal), for other
    /// profiles more where the wall lies farther from the centre. To first order in `W'`: the
    /// path's few widths along the groove leave its width as it was. Only smooth walls, which
    /// need no frame about `n`, are traced with a taper ([`GroovePaths`]).
    #[inline]
    fn wall_normal(&self, seg: usize, taper: f64) -> [f64; 3] {
        let sg = &self.cs.segs[seg];
        if taper == 0.0 {
            return [sg.n[0], 0.0, sg.n[1]];
        }
        let c = sg.n[0] * sg.p[0] + sg.n[1] * sg.p[1];
        let n = [sg.n[0], -taper * c, sg.n[1]];
        let len = dot(n, n).sqrt();
        [n[0] / len, n[1] / len, n[2] / len]
    }

    /// Smooth dielectric interface of normal `n` (facing the ray), relative index
    /// `eta = n_t / n_i`: reflect with the Fresnel reflectance, else refract.
    fn smooth_dielectric(&self, ray: &mut Ray, n: [f64; 3], cos_i: f64, eta: f64, u: f64) {
        smooth_interface(&mut ray.d, &mut ray.in_object, n, cos_i, eta, u);
    }

    /// The flat surface `z = 0` hit from inside the object.
    fn flat(&self, ray: &mut Ray, u: f64) {
        let n = [0.0, 0.0, -1.0];
        let cos_i = ray.d[2];
        self.smooth_dielectric(ray, n, cos_i, 1.0 / self.s.ior, u);
    }

    /// A rough wall (conductor or dielectric) in the frame `(x, y, n)`, `n` facing the ray:
    /// the random walk on its microsurface (METHOD.md 9.7), drawing from a stream of its own
    /// keyed by the path and the bounce.
    fn walk(
        &self,
        ray: &mut Ray,
        walls: GrooveWalls,
        x: [f64; 3],
        n: [f64; 3],
        from_air: bool,
        u: Draws,
    ) -> Scatter {
        let surface = Microsurface::new(self.s.roughness);
        let wo = back_in_frame(x, n, ray.d);
        let stream = Draws {
            key: mix64(u.key ^ mix64(u.base.wrapping_add(WALK_SALT))),
            base: 0,
        };
        let mut k = 0u64;
        let mut rng = || {
            k += 1;
            stream.get(k)
        };
        let exit = if walls == GrooveWalls::Dielectric {
            let eta = if from_air {
                self.s.ior
            } else {
                1.0 / self.s.ior
            };
            surface.walk_dielectric(wo, eta, &mut rng)
        } else {
            let law = self.s.fresnel_law;
            surface.walk_conductor(wo, |c| law.reflectance(c), &mut rng)
        };
        let Some(exit) = exit else {
            return Scatter::Dropped;
        };
        ray.in_object ^= exit.w[2] < 0.0;
        ray.w *= exit.weight;
        ray.d = unit_from_frame(x, n, exit.w);
        Scatter::On
    }

    /// A GGX wall (rough conductor or rough dielectric) scattering once, in the frame `(x, y,
    /// n)`, `n` facing the ray.
    #[allow(clippy::too_many_arguments)]
    fn rough(
        &self,
        ray: &mut Ray,
        ggx: &Ggx,
        walls: GrooveWalls,
        x: [f64; 3],
        n: [f64; 3],
        from_air: bool,
        u: Draws,
    ) -> Scatter {
        let wo = back_in_frame(x, n, ray.d);
        let wo32 = Vec3::new(wo[0] as f32, wo[1] as f32, wo[2] as f32);
        let m32 = ggx.sample_visible(wo32, Vec2::new(u.get(0) as f32, u.get(1) as f32));
        let m = [m32.x as f64, m32.y as f64, m32.z as f64];
        let c = dot(wo, m).max(0.0);
        let reflected = [
            2.0 * c * m[0] - wo[0],
            2.0 * c * m[1] - wo[1],
            2.0 * c * m[2] - wo[2],
        ];
        // (direction in the frame, weight, refracted?)
        let (wi, weight, refracted) = if walls == GrooveWalls::Dielectric {
            let eta = if from_air {
                self.s.ior
            } else {
                1.0 / self.s.ior
            };
            let f = dielectric(c, eta);
            if u.get(2) < f.r {
                (reflected, 1.0, false)
            } else {
                let e = 1.0 / eta;
                let k = e * c + f.cos_theta_t; // e c - cos_t
                let wi = [
                    k * m[0] - e * wo[0],
                    k * m[1] - e * wo[1],
                    k * m[2] - e * wo[2],
                ];
                (wi, 1.0, true)
            }
        } else {
            (reflected, self.s.fresnel_law.reflectance(c), false)
        };
        // A sample on the wrong side of the wall (single scattering: absorbed).
        if (wi[2] <= 0.0 && !refracted) || (wi[2] >= 0.0 && refracted) {
            return Scatter::Absorbed;
        }
        ray.in_object ^= refracted;
        let wi32 = Vec3::new(wi[0] as f32, wi[1] as f32, wi[2] as f32);
        ray.w *= weight * ggx.g1(wi32, m32) as f64;
        ray.d = unit_from_frame(x, n, wi);
        Scatter::On
    }
}

/// A smooth interface of unit normal `n` facing the ray (`cos_i = -d . n`) and relative index
/// `eta = n_t / n_i`: reflect `d` with the exact Fresnel reflectance (`u` below it), else refract
/// it to the other side (`in_object` flips). Both tracers' walls and flat surface.
pub(crate) fn smooth_interface(
    d: &mut [f64; 3],
    in_object: &mut bool,
    n: [f64; 3],
    cos_i: f64,
    eta: f64,
    u: f64,
) {
    let f = dielectric(cos_i, eta);
    if u < f.r {
        let c = 2.0 * cos_i;
        *d = [d[0] + c * n[0], d[1] + c * n[1], d[2] + c * n[2]];
    } else {
        let e = 1.0 / eta;
        let k = e * cos_i + f.cos_theta_t; // cos_theta_t < 0 from the incident side
        *d = [
            e * d[0] + k * n[0],
            e * d[1] + k * n[1],
            e * d[2] + k * n[2],
        ];
        *in_object = !*in_object;
    }
}

/// Single paths through a groove with smooth dielectric walls, for the renderer
/// (`lobes = "traced"`): the exact groove sampled where a table would be read, one path of
/// the goniometer's tracer at a time.
#[derive(Debug)]
pub struct GroovePaths {
    tracer: Tracer,
}

/// Where a traced path left the groove: its travel direction (unit, the groove's frame),
/// whether it went into the object, and its weight (1: smooth walls are lossless); `from`, for
/// a path traced at a place ([`GroovePaths::trace`] with `at`, [`GroovePaths::trace_from`])
/// that left the last wall inside the object, the point `(x, z)` of the cross-section (`z <
/// 0`) where it left it: heading up (`d.z > 0`) for the flat surface beside the opening (it
/// surfaced), or down (`d.z < 0`) into the bulk, passing under the surface within reach of
/// other grooves (METHOD.md 8.1, "Ours": light between grooves).
#[derive(Clone, Copy, Debug)]
pub struct GrooveExit {
    pub d: [f64; 3],
    pub in_object: bool,
    pub w: f64,
    pub from: Option<[f64; 2]>,
}

/// The least depth below the surface (in opening widths) from which a path that met the
/// groove surfaces ([`GroovePaths::trace`] with `at`); one leaving a wall closer to the rim
/// meets the flat surface there in the tracer, too close to the opening to hold another.
const SURFACING_DEPTH: f64 = 0.02;

/// Entry points a path from inside tries before it is given up: light aimed beside the
/// opening misses the groove with probability below 1/2 wherever the band is wider than the
/// opening, so 32 tries all miss with probability below 2^-32.
const ENTRY_TRIES: u64 = 32;

impl GroovePaths {
    /// Smooth glass walls of index `ior` in the groove `profile`.
    pub fn new(profile: &Profile, ior: f64) -> Self {
        let s = GonioSettings {
            walls: GrooveWalls::Dielectric,
            ior,
            fresnel_law: FresnelLaw::None,
            ..GonioSettings::default()
        };
        GroovePaths {
            tracer: Tracer::new(profile, &s),
        }
    }

    /// One path of light travelling along `d0` (unit, 3D, the groove's frame; `d0.z < 0`:
    /// from the air through the opening; `d0.z > 0`: from inside, through the opening or
    /// meeting the ridge beside it, uniformly over the light the groove intercepts, as the
    /// goniometer's `beside`), entering at `x` in `[0, 1)` across the opening (or the band),
    /// its bounces (and further entry points, from inside) drawn from the stream `key`; with a
    /// `partner`, through the union of this groove and the partner crossing it
    /// ([`crate::precompute::crossing`]). `None` for a path that runs out of bounces or leaves
    /// along the surface.
    ///
    /// `at`, from inside and without a partner: the light crosses the surface's plane `at`
    /// across the groove (in opening widths from its axis) rather than at a drawn place, and a
    /// path that met the groove and heads up for the flat surface beside it stops there
    /// ([`GrooveExit::from`]): the renderer looks the scratches up again where it surfaces
    /// (METHOD.md 8.1, "Ours": light between grooves). The tracer's flat surface would hold
    /// no other groove. Should the light miss the groove there, the path enters at drawn
    /// places as without `at`.
    pub fn trace(
        &self,
        d0: [f64; 3],
        x: f64,
        at: Option<f64>,
        key: u64,
        partner: Option<Partner>,
        taper: f64,
    ) -> Option<GrooveExit> {
        let t = &self.tracer;
        let inside = d0[2] > 0.0;
        let (start, width) = entry_band(&t.cs, d0, inside, t.s.ior);
        let at = at.filter(|a| inside && partner.is_none() && a.is_finite());
        for attempt in 0..ENTRY_TRIES {
            let path_key = mix64(key.wrapping_add(attempt.wrapping_mul(GOLDEN)));
            let u = if attempt == 0 { x } else { t.draw(path_key, 0) };
            let placed = at.filter(|_| attempt == 0);
            let x0 = placed.unwrap_or(start + width * u);
            let end = match partner {
                Some(p) => Crossing::new(&t.cs, t.s.ior, x0, p).run(
                    x0,
                    d0,
                    inside,
                    PathDraws::new(path_key),
                    t.s.max_bounces,
                ),
                None => self.run_2d(x0, d0, inside, path_key, placed.is_some(), taper),
            };
            match end {
                CrossingEnd::Left(e)
                    if e.from.is_some() || (e.d[2] != 0.0 && (e.d[2] < 0.0) == e.in_object) =>
                {
                    return Some(e)
                }
                CrossingEnd::Missed => continue,
                _ => return None,
            }
        }
        None
    }

    /// One path of the 2.5D tracer entering on the line through `(x0, 0)` (`surfacing`: see
    /// [`Tracer::run`]).
    fn run_2d(
        &self,
        x0: f64,
        d0: [f64; 3],
        inside: bool,
        path_key: u64,
        surfacing: bool,
        taper: f64,
    ) -> CrossingEnd {
        let t = &self.tracer;
        let ray = Ray {
            taper,
            ..t.entry(x0, d0, inside)
        };
        end_of(t.run(ray, path_key, inside, surfacing), surfacing)
    }

    /// One path of light inside the object travelling down along `d0` (unit, 3D, the
    /// groove's frame, `d0.z < 0`) from the point `start` (`(x, z)`, `z <= 0`, beside the
    /// groove, in opening widths from its axis), its bounces drawn from the stream `key`: light
    /// another groove sent down under this one ([`GrooveExit::from`]). `Missed` where the line
    /// passes the groove. With `surfacing` (the renderer's), a path that meets it and heads up
    /// for the flat surface beside it stops there, and one that leaves down into the bulk gives
    /// where it left, as [`Self::trace`] with `at`; without, the tracer's flat surface, which
    /// holds no other groove, turns it back.
    pub fn trace_from(
        &self,
        start: [f64; 2],
        d0: [f64; 3],
        key: u64,
        taper: f64,
        surfacing: bool,
    ) -> CrossingEnd {
        let ray = Ray {
            pos: start,
            d: d0,
            in_object: true,
            skip: usize::MAX,
            w: 1.0,
            taper,
        };
        end_of(self.tracer.run(ray, mix64(key), true, surfacing), surfacing)
    }

    /// [`Self::run_2d`] for the crossing tracer's tests: `Some(Some(exit))`, `Some(None)`
    /// missed, `None` lost.
    #[cfg(test)]
    pub(crate) fn run_from(
        &self,
        x0: f64,
        d0: [f64; 3],
        inside: bool,
        path_key: u64,
    ) -> Option<Option<GrooveExit>> {
        match self.run_2d(x0, d0, inside, path_key, false, 0.0) {
            CrossingEnd::Left(e) => Some(Some(e)),
            CrossingEnd::Missed => Some(None),
            CrossingEnd::Lost => None,
        }
    }
}

/// How a path of [`GroovePaths`] ended, from the tracer's outcome (`placed`: traced at a
/// place, where [`GrooveExit::from`] says where it left the last wall).
fn end_of(outcome: Outcome, placed: bool) -> CrossingEnd {
    let exit = |r: Ray, from| {
        CrossingEnd::Left(GrooveExit {
            d: r.d,
            in_object: r.in_object,
            w: r.w,
            from,
        })
    };
    match outcome {
        // Down into the bulk from a wall below the surface.
        Outcome::Left(r) if placed && r.in_object && r.d[2] < 0.0 && r.pos[1] < 0.0 => {
            exit(r, Some(r.pos))
        }
        Outcome::Left(r) => exit(r, None),
        Outcome::Surfaced(r) => exit(r, Some(r.pos)),
        Outcome::Missed => CrossingEnd::Missed,
        Outcome::Absorbed | Outcome::Dropped(_) => CrossingEnd::Lost,
    }
}

/// The random numbers the tracers draw for one path, from its counter-based stream: the
/// Fresnel choice of bounce `k` is counter `3 + 3k` ([`Tracer::draw`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct PathDraws {
    key: u64,
}

impl PathDraws {
    pub fn new(path_key: u64) -> Self {
        PathDraws { key: path_key }
    }

    /// The number that picks reflection or refraction at bounce `k`.
    #[inline]
    pub fn fresnel(self, k: usize) -> f64 {
        Draws {
            key: self.key,
            base: 1 + 3 * k as u64,
        }
        .get(2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::precompute::angle_bins::{bin_centre, bin_of};
    use crate::precompute::trace2d::{trace, TraceSettings, Walls};
    use std::f64::consts::FRAC_PI_2;

    fn run(spec: &str, s: &GonioSettings) -> GonioOutput {
        trace_groove(&Profile::parse(spec).unwrap(), s, &|_| {}).unwrap()
    }

    /// A tapered groove's walls ([`Tracer::wall_normal`]) are unit normals that tilt along the
    /// axis as the scaled cross-section has them: for a V every wall by `tan = d W'` (twice
    /// its area times `W'`, the lean the renderer's lobes carry,
    /// [`crate::render::bsdf::scratched_glass::TracedGroove`]), toward the wider end for the
    /// side facing the air; for a round groove more toward the rims; none without a taper.
    #[test]
    fn tapered_walls_tilt_as_the_scaled_cross_section() {
        let taper = 0.07;
        for spec in ["v:depth=0.3", "v:depth=1.2", "round:depth=0.3,segments=8"] {
            let p = profile(spec);
            let t = Tracer::new(&p, &GonioSettings::default());
            let mut tilts = Vec::new();
            for seg in 0..t.cs.segs.len() {
                assert_eq!(t.wall_normal(seg, 0.0)[1], 0.0, "{spec}");
                let n = t.wall_normal(seg, taper);
                assert!((dot(n, n) - 1.0).abs() < 1e-12, "{spec}: {n:?}");
                // The normal facing the air (up), its tilt along the axis against the surface.
                let n = if n[2] < 0.0 { n.map(|x| -x) } else { n };
                tilts.push(n[1] / n[2]);
                // The wall of the cross-section scaled by 1 + taper dy, finite differences.
                let sg = &t.cs.segs[seg];
                let mid = [sg.p[0] + 0.5 * sg.e[0], sg.p[1] + 0.5 * sg.e[1]];
                let dy = 1e-6;
                let moved = [mid[0] * (1.0 + taper * dy), mid[1] * (1.0 + taper * dy)];
                // The point `mid` moved along y lies on the wall: the normal is orthogonal to the
                // step from `mid` to it.
                let step = [moved[0] - mid[0], dy, moved[1] - mid[1]];
                assert!(dot(n, step).abs() < 1e-9, "{spec}: {n:?}");
            }
            if spec.starts_with('v') {
                for tilt in &tilts {
                    assert!(
                        (tilt - 2.0 * p.area() * taper).abs() < 1e-12,
                        "{spec}: {tilts:?}"
                    );
                }
            } else {
                let (lo, hi) = tilts
                    .iter()
                    .fold((f64::MAX, f64::MIN), |(a, b), &x| (a.min(x), b.max(x)));
                assert!(lo > 0.0 && hi > 1.5 * lo, "{spec}: {tilts:?}");
            }
        }
    }

    /// A path from inside that enters `at` a drawn entry's place is the drawn path until it
    /// surfaces: heading up for the flat surface beside the opening, it stops on the wall it
    /// left, below the surface, and the drawn path goes on from there through the flat
    /// surface alone: mirrored, or refracted into the air. Elsewhere the two are one path,
    /// and one that leaves down into the glass gives the wall it left (below the surface).
    #[test]
    fn surfacing_paths_stop_on_the_wall_they_leave() {
        let ior = 1.5;
        for spec in [
            "round:depth=0.3,segments=8",
            "v:depth=0.3",
            "round:depth=0.1,segments=8",
        ] {
            let profile = Profile::parse(spec).unwrap();
            let paths = GroovePaths::new(&profile, ior);
            let cs = CrossSection::new(&profile);
            let (mut surfaced, mut departed) = (0, 0);
            for k in 0..20_000u64 {
                let h = |i: u64| unit(mix64(k * 8 + i));
                let theta = (42.0 + 47.0 * h(0)).to_radians();
                let phi = 2.0 * PI * h(1);
                let d0 = [
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                ];
                let (u, key) = (h(2), mix64(k));
                let (start, width) = entry_band(&cs, d0, true, ior);
                let drawn = paths.trace(d0, u, None, key, None, 0.0);
                let placed = paths.trace(d0, u, Some(start + width * u), key, None, 0.0);
                let (a, b) = match (drawn, placed) {
                    (Some(a), Some(b)) => (a, b),
                    (None, None) => continue,
                    other => panic!("{spec}: {other:?}"),
                };
                let Some([x, z]) = b.from else {
                    assert_eq!((a.d, a.in_object), (b.d, b.in_object), "{spec}");
                    continue;
                };
                // On the profile's walls.
                let gap = profile
                    .points
                    .windows(2)
                    .map(|w| {
                        let (e, r) = (
                            [w[1][0] - w[0][0], w[1][1] - w[0][1]],
                            [x - w[0][0], z - w[0][1]],
                        );
                        let t = ((r[0] * e[0] + r[1] * e[1]) / (e[0] * e[0] + e[1] * e[1]))
                            .clamp(0.0, 1.0);
                        (r[0] - t * e[0]).hypot(r[1] - t * e[1])
                    })
                    .fold(f64::INFINITY, f64::min);
                assert!(gap < 1e-9, "{spec}: ({x}, {z}) is {gap} off the walls");
                if b.d[2] < 0.0 {
                    departed += 1;
                    assert_eq!((a.d, a.in_object), (b.d, b.in_object), "{spec}");
                    assert!(b.in_object && z < 0.0, "{spec}: {b:?}");
                    continue;
                }
                surfaced += 1;
                assert!(b.in_object && z < -SURFACING_DEPTH, "{spec}: {b:?}");
                // It surfaces beside the opening.
                let xs = x - z * b.d[0] / b.d[2];
                assert!(xs.abs() > 0.5, "{spec}: surfaces at {xs}");
                let want = if a.in_object {
                    [b.d[0], b.d[1], -b.d[2]]
                } else {
                    let t = [ior * b.d[0], ior * b.d[1]];
                    [t[0], t[1], (1.0 - t[0] * t[0] - t[1] * t[1]).sqrt()]
                };
                let off = a.d.iter().zip(want).map(|(x, y)| (x - y).abs());
                assert!(off.fold(0.0, f64::max) < 1e-9, "{spec}: {a:?} from {b:?}");
            }
            assert!(surfaced > 200, "{spec}: {surfaced} paths surfaced");
            assert!(departed > 200, "{spec}: {departed} paths left down");
        }
    }

    fn theta_marginal(h: &[f64], b: usize) -> Vec<f64> {
        (0..b).map(|i| h[i * b..(i + 1) * b].iter().sum()).collect()
    }

    fn phi_marginal(h: &[f64], b: usize) -> Vec<f64> {
        (0..b).map(|j| (0..b).map(|i| h[i * b + j]).sum()).collect()
    }

    /// `integral over the bin of cos(theta)^2 cos(phi) dtheta dphi`: the projected solid
    /// angle of bin `(i, j)` (`w.z dw`, METHOD.md section 1).
    fn projected_solid_angle(i: usize, j: usize, b: usize) -> f64 {
        let edge = |k: usize| -FRAC_PI_2 + k as f64 * PI / b as f64;
        let cos2 = |t: f64| t / 2.0 + (2.0 * t).sin() / 4.0;
        (cos2(edge(i + 1)) - cos2(edge(i))) * (edge(j + 1).sin() - edge(j).sin())
    }

    const PROFILES: [&str; 5] = [
        "v:angle=90",
        "v:angle=60",
        "round:depth=0.4",
        "trapezoid:depth=0.3,bottom=0.2",
        "file-w",
    ];

    fn profile(spec: &str) -> Profile {
        if spec == "file-w" {
            // A non-convex W: paths refracted into the object meet the groove again.
            return Profile::w_groove();
        }
        Profile::parse(spec).unwrap()
    }

    /// Smooth glass walls and the smooth flat surface lose nothing: R + T = 1 (up to what the
    /// bounce cap drops), from either side; F = 1 mirrors and Lambertian walls reflect all.
    #[test]
    fn lossless_walls_conserve_energy() {
        for spec in PROFILES {
            let p = profile(spec);
            for (walls, side, law) in [
                (
                    GrooveWalls::Dielectric,
                    LightSide::Outside,
                    FresnelLaw::None,
                ),
                (GrooveWalls::Dielectric, LightSide::Inside, FresnelLaw::None),
                (GrooveWalls::Specular, LightSide::Outside, FresnelLaw::None),
                (GrooveWalls::Diffuse, LightSide::Outside, FresnelLaw::None),
            ] {
                for (ti, pi) in [(0.0f64, 0.0f64), (25.0, -40.0), (-70.0, 60.0)] {
                    let s = GonioSettings {
                        walls,
                        side,
                        fresnel_law: law,
                        theta_i: ti.to_radians(),
                        phi_i: pi.to_radians(),
                        paths: 20_000,
                        bins: 8,
                        seed: 5,
                        ..GonioSettings::default()
                    };
                    let o = trace_groove(&p, &s, &|_| {}).unwrap();
                    let total = o.albedo_r + o.albedo_t + o.dropped;
                    let what = format!("{spec} {walls:?} {side:?} ({ti}, {pi})");
                    assert!((total - 1.0).abs() < 1e-9, "{what}: {total}");
                    assert_eq!(o.lost, 0.0, "{what}");
                    assert!(o.dropped < 1e-3, "{what}: dropped {}", o.dropped);
                    if walls != GrooveWalls::Dielectric {
                        assert_eq!(o.albedo_t, 0.0, "{what}");
                    } else if side == LightSide::Outside {
                        // (From inside, walls steeper than the critical angle reflect all.)
                        assert!(o.albedo_t > 0.5, "{what}: T = {}", o.albedo_t);
                    }
                }
            }
        }
    }

    /// A 90-degree mirror V: the cross-section retroreflects the two-wall fraction
    /// `max(0, 1 - tan |phi_i|)` (derived in `trace2d`'s test of the same name), and every
    /// path keeps `w.y`, so all light leaves at `theta_o = -theta_i`.
    #[test]
    fn mirror_v90_retroreflects_in_the_cross_section() {
        let b = 18;
        for (ti, pj) in [(5usize, 11usize), (13, 7), (9, 9)] {
            let (theta_i, phi_i) = (bin_centre(ti, b), bin_centre(pj, b));
            let s = GonioSettings {
                walls: GrooveWalls::Specular,
                fresnel_law: FresnelLaw::None,
                theta_i,
                phi_i,
                paths: 50_000,
                bins: b,
                ..GonioSettings::default()
            };
            let o = run("v:angle=90", &s);
            let rows = theta_marginal(&o.reflected, b);
            let mirror_row = bin_of(-theta_i, b);
            assert!((rows[mirror_row] - 1.0).abs() < 1e-9, "{rows:?}");
            let retro = o.reflected[mirror_row * b + pj];
            let expect = (1.0 - phi_i.abs().tan()).max(0.0);
            assert!(
                (retro - expect).abs() < 3.0 / s.paths as f64,
                "phi_i {phi_i}: {retro} vs {expect}"
            );
        }
    }

    /// Smooth glass walls conserve `beta = n w.y`: from outside, reflected light leaves at
    /// `theta_o = -theta_i` and transmitted light at `sin theta_t = -sin theta_i / n`; from
    /// inside, reflected at `-theta_i` and transmitted at `sin theta_t = -n sin theta_i`.
    #[test]
    fn smooth_dielectric_walls_conserve_beta() {
        let b = 30;
        let n = 1.5;
        for spec in ["round:depth=0.4", "v:angle=60", "file-w"] {
            for (side, ti_deg) in [(LightSide::Outside, 32.0f64), (LightSide::Inside, 17.0)] {
                let theta_i = ti_deg.to_radians();
                let s = GonioSettings {
                    walls: GrooveWalls::Dielectric,
                    side,
                    ior: n,
                    theta_i,
                    phi_i: 0.3,
                    paths: 20_000,
                    bins: b,
                    ..GonioSettings::default()
                };
                let o = trace_groove(&profile(spec), &s, &|_| {}).unwrap();
                let sin_t = match side {
                    LightSide::Outside => -theta_i.sin() / n,
                    LightSide::Inside => -theta_i.sin() * n,
                };
                let r_rows = theta_marginal(&o.reflected, b);
                let t_rows = theta_marginal(&o.transmitted, b);
                let (r_row, t_row) = (bin_of(-theta_i, b), bin_of(sin_t.asin(), b));
                let what = format!("{spec} {side:?}");
                assert!(
                    (r_rows[r_row] - o.albedo_r).abs() < 1e-12,
                    "{what}: {r_rows:?}"
                );
                assert!(
                    (t_rows[t_row] - o.albedo_t).abs() < 1e-12,
                    "{what}: {t_rows:?}"
                );
                // Both lobes are populated, except from inside a steep V (total internal
                // reflection at every wall).
                let steep_inside = side == LightSide::Inside && spec != "round:depth=0.4";
                assert!(
                    o.albedo_r > 1e-3 && (o.albedo_t > 0.1 || steep_inside),
                    "{what}: R {} T {}",
                    o.albedo_r,
                    o.albedo_t
                );
            }
        }
    }

    /// Lossless Lambertian walls (METHOD.md section 4): the `phi_o` marginal is the 2D
    /// table's row for `phi_i` whatever `theta_i`, and `theta_o` follows `cos^2` independently.
    #[test]
    fn lossless_lambertian_walls_match_the_2d_table_and_cos2_law() {
        let b = 16;
        for spec in ["v:depth=0.5", "round:depth=0.4"] {
            let p = Profile::parse(spec).unwrap();
            let t2 = trace(
                &p,
                &TraceSettings {
                    walls: Walls::Diffuse,
                    m: b,
                    n: 4000,
                    nr: 50,
                    seed: 1,
                    ..TraceSettings::default()
                },
                &|_| {},
            )
            .unwrap();
            let n2 = 4000.0 * 50.0;
            for (row, theta_deg) in [(11usize, 40.0f64), (4, -65.0)] {
                let s = GonioSettings {
                    walls: GrooveWalls::Diffuse,
                    fresnel_law: FresnelLaw::None,
                    theta_i: theta_deg.to_radians(),
                    phi_i: bin_centre(row, b),
                    paths: 200_000,
                    bins: b,
                    seed: 2,
                    ..GonioSettings::default()
                };
                let o = trace_groove(&p, &s, &|_| {}).unwrap();
                let ng = s.paths as f64;
                let phi_m = phi_marginal(&o.reflected, b);
                let mut z2 = 0.0;
                for (j, g) in phi_m.iter().enumerate() {
                    let f2 = t2.rho_m[row * b + j] * bin_centre(j, b).cos() * PI / b as f64;
                    let f = 0.5 * (g + f2);
                    let sigma = (f * (1.0 - f) * (1.0 / ng + 1.0 / n2)).sqrt().max(1e-9);
                    let z = (g - f2) / sigma;
                    assert!(z.abs() < 5.0, "{spec} row {row} bin {j}: {g} vs {f2}");
                    z2 += z * z;
                }
                assert!(
                    z2 / (b as f64) < 2.5,
                    "{spec} row {row}: mean z^2 {}",
                    z2 / b as f64
                );
                // cos^2 theta: the exact bin probabilities, chi-square on the path counts
                // (weights are 1, so fractions times paths are counts).
                let counts: Vec<u64> = theta_marginal(&o.reflected, b)
                    .iter()
                    .map(|f| (f * ng).round() as u64)
                    .collect();
                let expected: Vec<f64> = (0..b)
                    .map(|i| (0..b).map(|j| projected_solid_angle(i, j, b)).sum::<f64>())
                    .map(|p| p / PI * ng)
                    .collect();
                let chi = crate::testing::chi2_discrete(&counts, &expected);
                assert!(chi.p_value > 1e-3, "{spec} row {row}: {chi:?}");
            }
        }
    }

    /// Helmholtz reciprocity of the reflected lobe, `f_r(a -> b) = f_r(b -> a)`, for walls
    /// whose own BSDF is reciprocal (lossless Lambert, a rough conductor, rough glass): the
    /// BRDF estimated per bin as fraction / projected solid angle, within noise and the bin
    /// averaging. (Lambert times the Fresnel factor of the incident cosine, the seed's walls,
    /// is not reciprocal, nor is a groove of such walls.)
    #[test]
    fn reflected_lobe_is_reciprocal() {
        let b = 12;
        // Pairs in mirrored theta bins (`11 - i`), where every lobe here has most of its light.
        let pairs = [
            ((3usize, 8usize), (8usize, 2usize)),
            ((5, 5), (6, 7)),
            ((7, 3), (4, 9)),
            ((2, 4), (9, 6)),
        ];
        let gold = FresnelLaw::Conductor { eta: 0.2, k: 3.9 };
        for (spec, walls, rough, law) in [
            (
                "trapezoid:depth=0.3,bottom=0.2",
                GrooveWalls::Diffuse,
                0.0,
                FresnelLaw::None,
            ),
            ("round:depth=0.4", GrooveWalls::Specular, 0.5, gold),
            ("v:angle=90", GrooveWalls::Dielectric, 0.4, FresnelLaw::None),
        ] {
            let base = GonioSettings {
                walls,
                roughness: rough,
                fresnel_law: law,
                paths: 400_000,
                bins: b,
                ..GonioSettings::default()
            };
            let brdf = |from: (usize, usize), to: (usize, usize)| {
                let s = GonioSettings {
                    theta_i: bin_centre(from.0, b),
                    phi_i: bin_centre(from.1, b),
                    ..base.clone()
                };
                let o = run(spec, &s);
                let frac = o.reflected[to.0 * b + to.1];
                let psa = projected_solid_angle(to.0, to.1, b);
                (frac / psa, (frac / s.paths as f64).sqrt() / psa)
            };
            for (a, c) in pairs {
                let (f_ac, s_ac) = brdf(a, c);
                let (f_ca, s_ca) = brdf(c, a);
                let tol = 4.0 * s_ac.hypot(s_ca) + 0.06 * (f_ac + f_ca) / 2.0;
                assert!(
                    (f_ac - f_ca).abs() < tol && f_ac + f_ca > 0.0,
                    "{spec} {a:?} <-> {c:?}: {f_ac} vs {f_ca} (tol {tol})"
                );
            }
        }
    }

    /// Generalised reciprocity of the transmitted lobes (METHOD.md 8.1):
    /// `f_t(a -> b) / n_b^2 = f_t(b -> a) / n_a^2` between outside (air, `n = 1`) and inside
    /// (`n = 1.5`) directions, for rough glass walls scattering once (Walter's BTDF, reciprocal
    /// in closed form): the tracer's paths keep what the walls' BSDF keeps. The test compares one
    /// incident direction with one exit bin each way, which holds only as far as the lobe is
    /// flat over a bin; the microsurface walk's own reciprocity is tested exactly, as fluxes
    /// between cones (`optics::microsurface::tests`).
    #[test]
    fn transmitted_lobes_obey_generalised_reciprocity() {
        let b = 12;
        let n = 1.5;
        for spec in ["v:angle=90", "round:depth=0.4"] {
            let base = GonioSettings {
                walls: GrooveWalls::Dielectric,
                roughness: 0.4,
                single_scatter: true,
                ior: n,
                paths: 400_000,
                bins: b,
                ..GonioSettings::default()
            };
            let btdf = |side, from: (usize, usize), to: (usize, usize)| {
                let s = GonioSettings {
                    side,
                    theta_i: bin_centre(from.0, b),
                    phi_i: bin_centre(from.1, b),
                    ..base.clone()
                };
                let o = run(spec, &s);
                let frac = o.transmitted[to.0 * b + to.1];
                let psa = projected_solid_angle(to.0, to.1, b);
                (frac / psa, (frac / s.paths as f64).sqrt() / psa)
            };
            for (air, glass) in [((6usize, 7usize), (5usize, 5usize)), ((4, 8), (6, 4))] {
                let (f_out, s_out) = btdf(LightSide::Outside, air, glass);
                let (f_in, s_in) = btdf(LightSide::Inside, glass, air);
                // f_t(air -> glass) / n^2 = f_t(glass -> air) / 1.
                let (lhs, rhs) = (f_out / (n * n), f_in);
                let tol = 4.0 * (s_out / (n * n)).hypot(s_in) + 0.08 * (lhs + rhs) / 2.0;
                assert!(
                    (lhs - rhs).abs() < tol && lhs > 0.0,
                    "{spec} {air:?} <-> {glass:?}: {lhs} vs {rhs} (tol {tol})"
                );
            }
        }
    }

    /// Single-scattering rough walls: a rough conductor with `F = 1` on a flat profile reflects
    /// the GGX single-scattering albedo: for `alpha = 0.5`, 0.6875 at normal incidence and
    /// 0.6785 at 45 degrees (by quadrature of `D G1 G1 / (4 cos_o cos_i)` and by an independent
    /// Monte Carlo with Walter's sampling of `D cos`, both in Python, agreeing to 1e-3). Nearly
    /// smooth walls (`alpha = 0.01`) give the smooth walls' albedo, scattering once or walking
    /// the microsurface; neither gains energy (R + T <= 1).
    #[test]
    fn rough_walls_match_ggx_albedo_and_approach_smooth() {
        for (phi_deg, expect) in [(0.0f64, 0.6875), (45.0, 0.6785)] {
            let s = GonioSettings {
                walls: GrooveWalls::Specular,
                fresnel_law: FresnelLaw::None,
                roughness: 0.5,
                single_scatter: true,
                phi_i: phi_deg.to_radians(),
                paths: 200_000,
                bins: 8,
                ..GonioSettings::default()
            };
            let o = trace_groove(&Profile::flat(), &s, &|_| {}).unwrap();
            assert!(
                (o.albedo_r - expect).abs() < 0.006,
                "{phi_deg}: {}",
                o.albedo_r
            );
        }
        for walls in [GrooveWalls::Specular, GrooveWalls::Dielectric] {
            let s = GonioSettings {
                walls,
                fresnel_law: FresnelLaw::None,
                theta_i: 0.2,
                phi_i: -0.4,
                paths: 50_000,
                bins: 16,
                ..GonioSettings::default()
            };
            let smooth = run("v:angle=90", &s);
            for (alpha, single_scatter) in [(0.01, true), (0.01, false), (0.5, true), (0.5, false)]
            {
                let o = run(
                    "v:angle=90",
                    &GonioSettings {
                        roughness: alpha,
                        single_scatter,
                        ..s.clone()
                    },
                );
                let total = o.albedo_r + o.albedo_t + o.dropped;
                assert!(total <= 1.0 + 1e-9, "{walls:?} {alpha}: {total}");
                if alpha == 0.01 {
                    assert!(total > 0.99, "{walls:?} {alpha}: {total}");
                    assert!((o.albedo_r - smooth.albedo_r).abs() < 0.02, "{walls:?}");
                }
            }
        }
    }

    /// Rough walls that lose nothing make a groove that loses nothing (METHOD.md 9.7): with
    /// the microsurface walk, glass walls (light from outside, and from inside with the light
    /// beside the opening: R + T is then the intercept) and mirror-metal walls (`F = 1`) give
    /// `R + T = 1` within 1e-3 for `alpha` 0.05 to 1 and `theta_i` 0 to 85 degrees, on a V and
    /// a round groove; scattering once, the same grooves lose up to a fifth.
    #[test]
    fn rough_walls_lose_nothing_where_their_material_does_not() {
        let mut worst_single = 1.0f64;
        for profile in ["v:angle=90", "round:depth=0.5"] {
            for alpha in [0.05, 0.2, 0.5, 1.0] {
                for theta in [0.0f64, 30.0, 60.0, 85.0] {
                    for (walls, side) in [
                        (GrooveWalls::Dielectric, LightSide::Outside),
                        (GrooveWalls::Dielectric, LightSide::Inside),
                        (GrooveWalls::Specular, LightSide::Outside),
                    ] {
                        let s = GonioSettings {
                            walls,
                            side,
                            beside: side == LightSide::Inside,
                            fresnel_law: FresnelLaw::None,
                            roughness: alpha,
                            theta_i: theta.to_radians(),
                            phi_i: 0.5,
                            paths: 10_000,
                            bins: 8,
                            ..GonioSettings::default()
                        };
                        let o = run(profile, &s);
                        let total = (o.albedo_r + o.albedo_t) / o.intercept.unwrap_or(1.0);
                        assert!(
                            (total - 1.0).abs() < 1e-3,
                            "{profile} {walls:?} {side:?} alpha {alpha} theta {theta}: {total}"
                        );
                        let single = run(
                            profile,
                            &GonioSettings {
                                single_scatter: true,
                                ..s
                            },
                        );
                        let single_total =
                            (single.albedo_r + single.albedo_t) / single.intercept.unwrap_or(1.0);
                        worst_single = worst_single.min(single_total);
                    }
                }
            }
        }
        assert!(worst_single < 0.85, "single scattering: {worst_single}");
    }

    #[test]
    fn deterministic_across_thread_counts() {
        let s = GonioSettings {
            walls: GrooveWalls::Dielectric,
            roughness: 0.3,
            theta_i: 0.5,
            phi_i: 0.2,
            paths: 30_000,
            bins: 8,
            seed: 9,
            ..GonioSettings::default()
        };
        let on = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| run("round:depth=0.4", &s))
        };
        let a = on(1);
        assert_eq!(a, on(3));
        let c = run("round:depth=0.4", &GonioSettings { seed: 10, ..s });
        assert_ne!(a.reflected, c.reflected);
    }

    /// Seen from inside, a round groove (a circular segment of chord 1 and sagitta `s`, radius
    /// `R = (1/4 + s^2) / 2s`, centre `c = R - s` above the surface) is a ridge of air. Light
    /// at the angle `a` from the normal in the cross-section (`phi_i`; `theta_i` only tilts it
    /// along the groove) meets it over the ridge's projected width `cos a` while the arc's end
    /// tangent hides it (`a <= 90 deg - alpha`, `sin alpha = 1 / 2R`), then `cos a / 2 + R -
    /// c sin a` (the rim on one side, the arc's far point on the other), so the intercept is
    /// that over `cos a`: 1.171 at 60 degrees for `s = 0.3`. Under total internal reflection
    /// the flat surface beside the opening mirrors the light into the groove from the other
    /// side, a second band as wide as the first beyond the opening (the groove being
    /// symmetric): the intercept is `(2 width - cos a) / cos a`, 1.341 there. With lossless
    /// walls what the band meets all leaves: `albedo_r + albedo_t` is the intercept.
    #[test]
    fn beside_light_meets_the_ridge_over_its_projected_width() {
        let sag = 0.3f64;
        let r = (0.25 + sag * sag) / (2.0 * sag);
        let c = r - sag;
        let alpha = (0.5 / r).asin();
        for (theta_deg, phi_deg) in [
            (0.0f64, 60.0f64),
            (40.0, -60.0),
            (-20.0, 75.0),
            (10.0, 20.0),
            (5.0, 38.0),
        ] {
            let a = phi_deg.abs().to_radians();
            let width = if a <= FRAC_PI_2 - alpha {
                a.cos()
            } else {
                0.5 * a.cos() + r - c * a.sin()
            };
            let s = GonioSettings {
                walls: GrooveWalls::Dielectric,
                fresnel_law: FresnelLaw::None,
                side: LightSide::Inside,
                beside: true,
                theta_i: theta_deg.to_radians(),
                phi_i: phi_deg.to_radians(),
                paths: 40_000,
                bins: 8,
                ..GonioSettings::default()
            };
            let tir = totally_reflected(s.incident_travel(), s.ior);
            let expect = if tir { 2.0 * width - a.cos() } else { width } / a.cos();
            let o = run("round:depth=0.3,segments=1024", &s);
            let what = format!("theta_i {theta_deg}, phi_i {phi_deg}, tir {tir}");
            let k = o.intercept.unwrap();
            assert!(
                (k - expect).abs() < 1e-3 * expect,
                "{what}: intercept {k} against {expect}"
            );
            let total = o.albedo_r + o.albedo_t + o.dropped;
            assert!((total - k).abs() < 1e-9, "{what}: {total}");
            // Through the opening alone the same light counts 1.
            let opening = run(
                "round:depth=0.3,segments=1024",
                &GonioSettings { beside: false, ..s },
            );
            let total = opening.albedo_r + opening.albedo_t + opening.dropped;
            assert!(
                opening.intercept.is_none() && (total - 1.0).abs() < 1e-9,
                "{what}"
            );
        }
    }

    #[test]
    fn bad_settings_name_their_flag() {
        let base = GonioSettings::default();
        for (s, key) in [
            (
                GonioSettings {
                    walls: GrooveWalls::Dielectric,
                    beside: true,
                    ..base.clone()
                },
                "beside",
            ),
            (
                GonioSettings {
                    side: LightSide::Inside,
                    ..base.clone()
                },
                "side",
            ),
            (
                GonioSettings {
                    walls: GrooveWalls::Specular,
                    roughness: 1.5,
                    ..base.clone()
                },
                "roughness",
            ),
            (
                GonioSettings {
                    roughness: 0.2,
                    ..base.clone()
                },
                "roughness",
            ),
            (
                GonioSettings {
                    ior: 0.9,
                    ..base.clone()
                },
                "ior",
            ),
            (
                GonioSettings {
                    theta_i: FRAC_PI_2,
                    ..base.clone()
                },
                "theta-i",
            ),
            (
                GonioSettings {
                    paths: MAX_PATHS + 1,
                    ..base.clone()
                },
                "paths",
            ),
            (
                GonioSettings {
                    bins: 0,
                    ..base.clone()
                },
                "bins",
            ),
        ] {
            let e = trace_groove(&Profile::flat(), &s, &|_| {}).unwrap_err();
            assert_eq!(e.key, key, "{e}");
            assert!(e.to_string().contains(&format!("--{key}")), "{e}");
        }
    }

    /// Single traced paths ([`GroovePaths`], the renderer's `lobes = "traced"`) leave as the
    /// goniometer's histograms say, from outside and from inside (beside the opening
    /// included): a chi-square of their exit bins against `trace_groove`'s fractions, each
    /// normalised to its total; every path lossless.
    #[test]
    fn single_paths_follow_the_goniometer() {
        let profile = Profile::parse("round:depth=0.3,segments=8").unwrap();
        let paths = GroovePaths::new(&profile, 1.5);
        let b = 12;
        let bins = AngleBins::new(b);
        for (i, (theta, phi, side)) in [
            (20.0f64, 10.0f64, LightSide::Outside),
            (-50.0, 60.0, LightSide::Outside),
            (30.0, -40.0, LightSide::Inside),
            (10.0, 75.0, LightSide::Inside),
        ]
        .into_iter()
        .enumerate()
        {
            let s = GonioSettings {
                walls: GrooveWalls::Dielectric,
                fresnel_law: FresnelLaw::None,
                theta_i: theta.to_radians(),
                phi_i: phi.to_radians(),
                side,
                beside: side == LightSide::Inside,
                paths: 400_000,
                bins: b,
                ..GonioSettings::default()
            };
            let g = trace_groove(&profile, &s, &|_| {}).unwrap();
            let d0 = s.incident_travel();
            let n = 40_000u64;
            let mut counts = vec![0u64; 2 * b * b];
            for k in 0..n {
                let key = mix64(k ^ (i as u64) << 40);
                let x = (k as f64 + 0.5) / n as f64;
                let e = paths
                    .trace(d0, x, None, key, None, 0.0)
                    .expect("a lossless path leaves");
                assert_eq!(e.w, 1.0);
                let up = if e.in_object { -e.d[2] } else { e.d[2] };
                let reflected = e.in_object == (side == LightSide::Inside);
                let j = bins.bin_sin(e.d[1]) * b + bins.bin_xz(e.d[0], up);
                counts[j + if reflected { 0 } else { b * b }] += 1;
            }
            let total: f64 = g.reflected.iter().chain(&g.transmitted).sum();
            let expected: Vec<f64> = g
                .reflected
                .iter()
                .chain(&g.transmitted)
                .map(|f| f / total * n as f64)
                .collect();
            let r = crate::testing::chi2_discrete(&counts, &expected);
            assert!(r.p_value > 1e-3, "{theta} {phi} {side:?}: {r:?}");
        }
    }
}
