//! One scratch layer (METHOD.md section 5): the affine map from texture space to noise space,
//! `q = S^-1 R(-alpha) (p - c)`, and the procedural queries on it: is a point scratched, and
//! what fraction of a footprint do the scratches cover.

use super::footprint::{union_discs_polygon_area, MAX_DISCS};
use super::random::RandomScratches;
use super::worley::{floor_i64, Worley, WorleySample};
use super::{LayerError, LayerParams, LAYER_NOISE_PERIOD};
use crate::math::Vec2;
use glam::DVec2;

/// Footprints whose noise-space bounding box spans more cells than this use the layer's
/// expected coverage (the prefiltered limit) instead of enumerating scratches.
pub const MAX_FOOTPRINT_CELLS: usize = 256;

/// The size of a buffer that holds every candidate disc of a footprint
/// ([`ScratchLayer::footprint_candidates`]): [`MAX_DISCS`] and one slot that the enumeration
/// writes rejected cells to (it stores every cell and advances only past the kept ones, so
/// that the test costs no branch).
pub const CANDIDATE_ROOM: usize = MAX_DISCS + 1;

/// The texture centre `c` about which the noise is rotated.
pub const CENTRE: DVec2 = DVec2::new(0.5, 0.5);

#[inline]
fn cross(a: DVec2, b: DVec2) -> f64 {
    a.x * b.y - a.y * b.x
}

/// Scratch layer `k` of a [`super::LayerSet`].
#[derive(Clone, Debug)]
pub struct ScratchLayer {
    index: usize,
    alpha: f64,
    /// `(cos alpha, sin alpha)`, kept: the scratches built at every ridge search read it.
    direction: [f64; 2],
    noise: Worley,
    tau: f64,
    length: f64,
    width: f64,
    /// Rows of `M = S^-1 R(-alpha)`.
    m: [DVec2; 2],
    /// Rows of `M^-1 = R(alpha) S`.
    m_inv: [DVec2; 2],
    /// `orientation = "random"`: the scratches, each with its own direction; the queries
    /// below then answer for them.
    random: Option<RandomScratches>,
}

impl ScratchLayer {
    /// Layer `index` with angle `alpha` and noise seed `noise_seed` (parameters already valid).
    pub fn new(
        index: usize,
        alpha: f64,
        noise_seed: u64,
        params: &LayerParams,
    ) -> Result<Self, LayerError> {
        params.validate()?;
        let (s, c) = alpha.sin_cos();
        let (l, w) = (params.length, params.width);
        Ok(ScratchLayer {
            index,
            alpha,
            direction: [c, s],
            noise: Worley::new(noise_seed, LAYER_NOISE_PERIOD)?,
            tau: params.threshold,
            length: l,
            width: w,
            m: [DVec2::new(c / l, s / l), DVec2::new(-s / w, c / w)],
            m_inv: [DVec2::new(c * l, -s * w), DVec2::new(s * l, c * w)],
            random: None,
        })
    }

    /// The same layer with a direction per scratch ([`RandomScratches`], same noise seed).
    pub fn into_random(
        mut self,
        noise_seed: u64,
        params: &LayerParams,
    ) -> Result<Self, LayerError> {
        self.random = Some(RandomScratches::new(noise_seed, params)?);
        Ok(self)
    }

    /// The randomly oriented scratches, where the layer has them.
    pub fn random(&self) -> Option<&RandomScratches> {
        self.random.as_ref()
    }

    pub fn index(&self) -> usize {
        self.index
    }

    /// The rotation angle `alpha` (radians, from the `u` axis towards `v`), in `[0, 2 pi)`.
    pub fn angle(&self) -> f64 {
        self.alpha
    }

    /// The scratch direction `d = (cos alpha, sin alpha)` in texture space.
    pub fn direction(&self) -> [f64; 2] {
        self.direction
    }

    pub fn noise(&self) -> &Worley {
        &self.noise
    }

    /// Rows of `M = S^-1 R(-alpha)`, the linear part of [`Self::to_noise`].
    pub fn noise_matrix(&self) -> [DVec2; 2] {
        self.m
    }

    pub fn threshold(&self) -> f64 {
        self.tau
    }

    /// Half-axes `(tau L, tau W)` of every scratch ellipse, along `d` and across it.
    pub fn half_axes(&self) -> (f64, f64) {
        (self.tau * self.length, self.tau * self.width)
    }

    /// The scratch of the feature point `q` (noise space): the ellipse of [`Self::half_axes`]
    /// along the layer's direction about `q`'s texture point ([`super::LayerSet::scratches`]).
    pub fn scratch(&self, q: DVec2) -> super::Scratch {
        let (half_length, half_width) = self.half_axes();
        super::Scratch {
            layer: self.index,
            centre: self.to_texture(q),
            direction: DVec2::from(self.direction()),
            half_length,
            half_width,
        }
    }

    /// `q = S^-1 R(-alpha) (p - c)`, METHOD.md section 5.
    #[inline]
    pub fn to_noise(&self, p: DVec2) -> DVec2 {
        let d = p - CENTRE;
        DVec2::new(self.m[0].dot(d), self.m[1].dot(d))
    }

    /// A texture-space vector to noise space (the linear part of [`Self::to_noise`]).
    #[inline]
    pub fn vector_to_noise(&self, v: DVec2) -> DVec2 {
        DVec2::new(self.m[0].dot(v), self.m[1].dot(v))
    }

    /// The inverse map, `p = c + R(alpha) S q`.
    #[inline]
    pub fn to_texture(&self, q: DVec2) -> DVec2 {
        CENTRE + DVec2::new(self.m_inv[0].dot(q), self.m_inv[1].dot(q))
    }

    /// The noise (F1, F2, nearest feature point) behind texture point `p` (stage b of Fig. 4).
    pub fn noise_at(&self, p: DVec2) -> WorleySample {
        self.noise.eval(self.to_noise(p))
    }

    /// The feature point nearest to texture point `p`, in noise space (`noise_at(p).nearest`,
    /// at half the cost).
    #[inline]
    pub fn nearest_at(&self, p: DVec2) -> DVec2 {
        self.noise.nearest(self.to_noise(p))
    }

    /// The scratch covering texture point `p`, if one does (the seed's layers: a feature point
    /// within `tau` in noise space; randomly oriented ones: the nearest in its own metric,
    /// where it covers `p`).
    #[inline]
    pub fn scratch_covering(&self, p: DVec2) -> Option<super::Scratch> {
        if let Some(r) = &self.random {
            return r
                .nearest_scratch(p, self.index)
                .filter(|_| r.is_scratched(p));
        }
        let q = self.noise.feature_within(self.to_noise(p), self.tau)?;
        Some(self.scratch(q))
    }

    /// `F1(q(p)) < tau` at an `f64` texture point.
    #[inline]
    pub fn is_scratched_at(&self, p: DVec2) -> bool {
        if let Some(r) = &self.random {
            return r.is_scratched(p);
        }
        self.noise.any_within(self.to_noise(p), self.tau)
    }

    /// Whether texture point `uv` is scratched (`F1(q) < tau`), evaluated in `f64`.
    #[inline]
    pub fn is_scratched(&self, uv: Vec2) -> bool {
        self.is_scratched_at(uv.as_dvec2())
    }

    /// Coverage of the footprint `{uv + s duvdx + t duvdy : s, t in [-1/2, 1/2]}` by this
    /// layer's scratches, in `[0, 1]`; `expected` is the value for footprints too large to
    /// enumerate (the set's [`super::LayerSet::expected_coverage`]).
    pub fn coverage(&self, uv: Vec2, duvdx: Vec2, duvdy: Vec2, expected: f64) -> f32 {
        self.coverage_at(uv.as_dvec2(), duvdx.as_dvec2(), duvdy.as_dvec2(), expected) as f32
    }

    /// [`Self::coverage`] in `f64`. Exact (area of the union of scratch ellipses clipped to the
    /// parallelogram, [`super::footprint`]) when the footprint's noise-space bounding box spans
    /// at most [`MAX_FOOTPRINT_CELLS`] cells and touches at most `MAX_DISCS` scratches;
    /// otherwise `expected`. A degenerate footprint (zero area) is a point query; non-finite
    /// input gives 0.
    pub fn coverage_at(&self, p: DVec2, a: DVec2, b: DVec2, expected: f64) -> f64 {
        self.footprint_coverage(p, a, b, MAX_FOOTPRINT_CELLS)
            .unwrap_or(expected)
    }

    /// The footprint `{p + s a + t b : s, t in [-1/2, 1/2]}` carried to noise space, shared by
    /// [`Self::footprint_coverage`] and its reference; `Err(coverage)` when no area work is
    /// needed (non-finite input: 0; a degenerate footprint: the point query at its centre).
    fn noise_footprint(&self, p: DVec2, a: DVec2, b: DVec2) -> Result<NoiseFootprint, f64> {
        let q0 = self.to_noise(p);
        let (qa, qb) = (self.vector_to_noise(a), self.vector_to_noise(b));
        let cr = cross(qa, qb);
        if !(q0.is_finite() && cr.is_finite()) {
            return Err(0.0);
        }
        if cr.abs() < 1e-12 {
            return Err(self.noise.any_within(q0, self.tau) as u8 as f64);
        }
        // Counter-clockwise edges, so the corners below run counter-clockwise too.
        let (qa, qb) = if cr > 0.0 { (qa, qb) } else { (qb, qa) };
        Ok(NoiseFootprint {
            q0,
            qa,
            qb,
            cr: cr.abs(),
            poly: [
                (-qa - qb) * 0.5,
                (qa - qb) * 0.5,
                (qa + qb) * 0.5,
                (qb - qa) * 0.5,
            ],
            ext: (qa.abs() + qb.abs()) * 0.5 + DVec2::splat(self.tau),
        })
    }

    /// The exact coverage of the footprint `{p + s a + t b : s, t in [-1/2, 1/2]}`, or `None`
    /// when its noise-space bounding box spans more than `max_cells` cells or it touches more
    /// than `MAX_DISCS` scratches.
    ///
    /// The fast path of [`Self::footprint_coverage_reference`] (same value up to rounding):
    /// the candidate discs ([`Self::footprint_candidates`]) and their clipped area
    /// ([`FootprintCandidates::coverage`]).
    pub fn footprint_coverage(
        &self,
        p: DVec2,
        a: DVec2,
        b: DVec2,
        max_cells: usize,
    ) -> Option<f64> {
        self.footprint_coverage_in(p, a, b, max_cells, &mut [DVec2::ZERO; CANDIDATE_ROOM])
    }

    /// [`Self::footprint_coverage`] with the caller's buffer for the candidate discs (so that a
    /// query over several layers clears one buffer, not one per layer).
    #[inline]
    pub fn footprint_coverage_in(
        &self,
        p: DVec2,
        a: DVec2,
        b: DVec2,
        max_cells: usize,
        centres: &mut [DVec2; CANDIDATE_ROOM],
    ) -> Option<f64> {
        if let Some(r) = &self.random {
            return r.coverage(p, a, b, max_cells);
        }
        match self.footprint_candidates(p, a, b, max_cells, centres) {
            Candidates::Done(c) => c,
            Candidates::Discs(f) => Some(f.coverage(&centres[..f.n])),
            Candidates::Overflow => unreachable!("a buffer of CANDIDATE_ROOM never overflows"),
        }
    }

    /// The scratch discs that may touch the footprint `{p + s a + t b : s, t in [-1/2, 1/2]}`
    /// in noise space (their centres go to `centres`), or the answer itself where no area work
    /// is needed (no disc, a degenerate or non-finite footprint, one too large: see
    /// [`Self::footprint_coverage`]).
    ///
    /// `centres` (at least one slot) holds `centres.len() - 1` discs; it may be shorter than
    /// [`CANDIDATE_ROOM`] (a share of a larger buffer, as [`super::LayerSet::coverage_max`]
    /// keeps every layer's candidates): when more discs than it holds touch the footprint, the
    /// answer is [`Candidates::Overflow`] and the call must be repeated with a buffer of
    /// [`CANDIDATE_ROOM`] (which answers `Done(None)` where more than [`MAX_DISCS`] touch it).
    ///
    /// Cells are enumerated over the noise-space bounding box as in the reference (a
    /// row-by-row enumeration over the parallelogram's extent is slower, 1.25 s against 1.0 s
    /// on the close-up: footprints span few cells per row); a disc is kept when its centre lies within `tau` of
    /// both slabs of the parallelogram.
    pub fn footprint_candidates(
        &self,
        p: DVec2,
        a: DVec2,
        b: DVec2,
        max_cells: usize,
        centres: &mut [DVec2],
    ) -> Candidates {
        let (q0, ext, mut found) = match self.candidate_geometry(p, a, b) {
            Ok(g) => g,
            Err(c) => return Candidates::Done(Some(c)),
        };
        let tau = self.tau;
        // Far more than max_cells: leave before the integer conversion (floor_i64 needs
        // |x| < 2^62).
        if !(ext.x < 1e12 && ext.y < 1e12) {
            return Candidates::Done(None);
        }
        let (i0, i1) = (floor_i64(q0.x - ext.x), floor_i64(q0.x + ext.x));
        let (j0, j1) = (floor_i64(q0.y - ext.y), floor_i64(q0.y + ext.y));
        let cells = (i1 - i0 + 1) as f64 * (j1 - j0 + 1) as f64;
        if cells > max_cells as f64 {
            return Candidates::Done(None);
        }
        let [(na, ha), (nb, hb), ..] = found.shape.planes;
        // Kept discs go to centres[..room]; the slot after them takes the rejected cells. No
        // branch on the test (a short-circuit `||` mispredicted often: a quarter of the cells
        // are kept; without it the enumeration costs 45 % less).
        let room = (centres.len() - 1).min(MAX_DISCS);
        let mut n = 0;
        for j in j0..=j1 {
            for i in i0..=i1 {
                let o = self.noise.offset(i, j);
                let f = DVec2::new((i as f64 - q0.x) + o.x, (j as f64 - q0.y) + o.y);
                // (`<` keeps what `!(.. >= tau)` kept: the values are finite here.)
                let keep = (na.dot(f).abs() - ha < tau) & (nb.dot(f).abs() - hb < tau);
                centres[n] = f;
                n += keep as usize;
                if n > room {
                    return if room == MAX_DISCS {
                        Candidates::Done(None)
                    } else {
                        Candidates::Overflow
                    };
                }
            }
        }
        if n == 0 {
            return Candidates::Done(Some(0.0));
        }
        found.n = n;
        Candidates::Discs(found)
    }

    /// The footprint `{p + s a + t b : s, t in [-1/2, 1/2]}` in noise space: its centre, the
    /// half-extent of its bounding box grown by `tau`, and what the areas need (no discs yet);
    /// `Err(coverage)` as [`Self::noise_footprint`].
    #[inline]
    fn candidate_geometry(
        &self,
        p: DVec2,
        a: DVec2,
        b: DVec2,
    ) -> Result<(DVec2, DVec2, FootprintCandidates), f64> {
        let NoiseFootprint {
            q0, qa, qb, ext, ..
        } = self.noise_footprint(p, a, b)?;
        let found = FootprintCandidates {
            n: 0,
            tau: self.tau,
            shape: Parallelogram::new(qa, qb),
        };
        Ok((q0, ext, found))
    }

    /// The exact coverage of the footprint `{p + s a + t b : s, t in [-1/2, 1/2]}` from its
    /// candidate discs `centres`, as [`Self::footprint_candidates`] found them (so the same
    /// value as [`Self::footprint_coverage`], without enumerating the cells again), where it
    /// may reach `floor`, else `None` ([`FootprintCandidates::coverage_reaching`]: layers that
    /// cannot be the largest are given up part way).
    pub fn coverage_reaching(
        &self,
        p: DVec2,
        a: DVec2,
        b: DVec2,
        centres: &[DVec2],
        bound_area: f64,
        floor: f64,
    ) -> Option<f64> {
        match self.candidate_geometry(p, a, b) {
            Ok((_, _, f)) => f.coverage_reaching(centres, bound_area, floor),
            Err(c) => (c >= floor).then_some(c),
        }
    }

    /// The reference for [`Self::footprint_coverage`]: every cell of the noise-space bounding
    /// box, and the exact union area of all candidate discs (kept for the tests).
    pub fn footprint_coverage_reference(
        &self,
        p: DVec2,
        a: DVec2,
        b: DVec2,
        max_cells: usize,
    ) -> Option<f64> {
        let NoiseFootprint {
            q0, cr, poly, ext, ..
        } = match self.noise_footprint(p, a, b) {
            Ok(f) => f,
            Err(c) => return Some(c),
        };
        let tau = self.tau;
        let (i0, i1) = ((q0.x - ext.x).floor(), (q0.x + ext.x).floor());
        let (j0, j1) = ((q0.y - ext.y).floor(), (q0.y + ext.y).floor());
        let cells = (i1 - i0 + 1.0) * (j1 - j0 + 1.0);
        if cells > max_cells as f64 {
            return None;
        }
        // Outward edge normals for the quick rejection of discs that cannot touch the polygon.
        let mut planes = [(DVec2::ZERO, 0.0f64); 4];
        for e in 0..4 {
            let d = poly[(e + 1) % 4] - poly[e];
            let n = DVec2::new(d.y, -d.x).normalize_or_zero();
            planes[e] = (n, n.dot(poly[e]));
        }
        let mut centres = [DVec2::ZERO; MAX_DISCS];
        let mut n = 0;
        let (i0, i1, j0, j1) = (i0 as i64, i1 as i64, j0 as i64, j1 as i64);
        for j in j0..=j1 {
            for i in i0..=i1 {
                let o = self.noise.offset(i, j);
                let f = DVec2::new((i as f64 - q0.x) + o.x, (j as f64 - q0.y) + o.y);
                if planes.iter().any(|&(nrm, d)| nrm.dot(f) - d >= tau) {
                    continue;
                }
                if n == MAX_DISCS {
                    return None;
                }
                centres[n] = f;
                n += 1;
            }
        }
        if n == 0 {
            return Some(0.0);
        }
        Some((union_discs_polygon_area(&centres[..n], tau, &poly) / cr).clamp(0.0, 1.0))
    }
}

/// Whether two of the discs of radius `r` around `centres` overlap.
#[inline]
fn any_overlap(centres: &[DVec2], r: f64) -> bool {
    let d2 = 4.0 * r * r;
    for (k, &c) in centres.iter().enumerate() {
        for &o in &centres[k + 1..] {
            if (o - c).length_squared() < d2 {
                return true;
            }
        }
    }
    false
}

/// Area of a disc of radius `r` outside a line at signed distance `s` (positive: the centre is
/// on the inner side) from its centre: the circular segment `r^2 acos(s/r) - s sqrt(r^2 - s^2)`.
#[inline]
fn segment_outside(s: f64, r: f64) -> f64 {
    let x = (s / r).clamp(-1.0, 1.0);
    r * r * x.acos() - s * (r * r - s * s).max(0.0).sqrt()
}

/// A footprint parallelogram in noise space, centred on the origin, with what the per-disc
/// areas ([`disc_parallelogram_area`]) need.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Parallelogram {
    /// Corners `(-qa - qb) / 2, (qa - qb) / 2, (qa + qb) / 2, (qb - qa) / 2`, counter-clockwise.
    pub(crate) poly: [DVec2; 4],
    /// Outward unit normals and offsets of its edges `qa, qb, -qa, -qb` (edges 0 and 2
    /// parallel, 1 and 3 parallel); the offsets are the half-widths across each pair.
    pub(crate) planes: [(DVec2, f64); 4],
    /// Area, `cross(qa, qb)`.
    pub(crate) area: f64,
    /// Unit directions of edges 0 and 1 (edges 2 and 3 run the other way).
    tangents: [DVec2; 2],
    /// Where each edge starts along its own unit direction `t_e`: `poly[e] . t_e`.
    start: [f64; 4],
    /// Lengths of edges 0 and 1 (those of 2 and 3).
    len: [f64; 2],
}

impl Parallelogram {
    /// The parallelogram `{s qa + t qb : s, t in [-1/2, 1/2]}` for counter-clockwise edge
    /// vectors (`cross(qa, qb) > 0`).
    #[inline]
    pub(crate) fn new(qa: DVec2, qb: DVec2) -> Self {
        let cr = cross(qa, qb);
        let (la, lb) = (qa.length(), qb.length());
        let (na, nb) = (DVec2::new(qa.y, -qa.x) / la, DVec2::new(qb.y, -qb.x) / lb);
        let (ha, hb) = (0.5 * cr / la, 0.5 * cr / lb);
        let poly = [
            (-qa - qb) * 0.5,
            (qa - qb) * 0.5,
            (qa + qb) * 0.5,
            (qb - qa) * 0.5,
        ];
        // The unit directions, na and nb turned back a quarter (exactly qa / la, qb / lb).
        let (ta, tb) = (DVec2::new(-na.y, na.x), DVec2::new(-nb.y, nb.x));
        Parallelogram {
            poly,
            planes: [(na, ha), (nb, hb), (-na, ha), (-nb, hb)],
            area: cr,
            tangents: [ta, tb],
            start: [
                poly[0].dot(ta),
                poly[1].dot(tb),
                -poly[2].dot(ta),
                -poly[3].dot(tb),
            ],
            len: [la, lb],
        }
    }
}

/// The upper bound of [`FootprintCandidates::disc_bound`] on the area of
/// `disc(c, r) ∩ parallelogram`.
#[inline]
pub(crate) fn disc_parallelogram_area_bound(c: DVec2, r: f64, shape: &Parallelogram) -> f64 {
    let mut b = (std::f64::consts::PI * r * r).min(shape.area);
    for &(nrm, h) in &shape.planes[..2] {
        let xc = nrm.dot(c);
        let (x0, x1) = ((xc - r).max(-h), (xc + r).min(h));
        let m = 0.5 * (x0 + x1) - xc;
        b = b.min((x1 - x0).max(0.0) * 2.0 * (r * r - m * m).max(0.0).sqrt());
    }
    b
}

/// Area of `disc(c, r) ∩ parallelogram`. Closed form when the circle crosses at most one pair
/// of parallel edge lines (the two segments cut off are disjoint) or holds all four corners
/// (the whole parallelogram: small footprints); otherwise
/// [`disc_parallelogram_crossing_area`].
#[inline]
pub(crate) fn disc_parallelogram_area(c: DVec2, r: f64, shape: &Parallelogram) -> f64 {
    let mut s = [0.0f64; 4];
    let mut active = 0u32;
    for (e, &(nrm, d)) in shape.planes.iter().enumerate() {
        s[e] = d - nrm.dot(c);
        if s[e] <= -r {
            return 0.0;
        }
        if s[e] < r {
            active |= 1 << e;
        }
    }
    let full = std::f64::consts::PI * r * r;
    if active & 0b1010 == 0 || active & 0b0101 == 0 {
        let mut area = full;
        for (e, &se) in s.iter().enumerate() {
            if active & (1 << e) != 0 {
                area -= segment_outside(se, r);
            }
        }
        area.max(0.0)
    } else if shape
        .poly
        .iter()
        .all(|&v| (v - c).length_squared() <= r * r)
    {
        shape.area
    } else {
        disc_parallelogram_crossing_area(c, r, &s, shape)
    }
}

/// Area of `disc(c, r) ∩ parallelogram` by Green's theorem, given the signed distances `s[e]`
/// of the centre inside each edge line (the case where lines of both pairs cross the circle).
/// Twice the area is the sum over the boundary of `(x dy - y dx)` about `c`: along each edge,
/// the piece inside the disc (its chord clipped to the edge, `[u0, u1]` along the edge from the
/// foot of the perpendicular, at distance `s`) gives `s (u1 - u0)`; the arcs inside the
/// parallelogram give `r^2 theta`, `theta` the angle of the circle inside. The edges' angles
/// about `c` add up to `W` = 2 pi (`c` inside) or 0, so `theta = W - sum phi_e` over the
/// pieces, `phi_e` the angle of piece `e` seen from `c`, whose rotation is
/// `(s^2 + u0 u1, s (u1 - u0))`. The conjugate rotations are multiplied as complex numbers and
/// `theta` (in `(0, 2 pi)` here: the circle crosses the boundary) taken with one `atan2`;
/// within 1e-6 of 0 or 2 pi (ambiguous) the angles are summed piece by piece instead. The
/// same area as [`disc_convex_polygon_area`] (the triangle decomposition it replaced, kept for
/// the tests) up to rounding, without divisions and half its cost.
#[inline]
fn disc_parallelogram_crossing_area(c: DVec2, r: f64, s: &[f64; 4], shape: &Parallelogram) -> f64 {
    let r2 = r * r;
    let (ca, cb) = (c.dot(shape.tangents[0]), c.dot(shape.tangents[1]));
    // The centre's coordinate along each edge's direction (edges 2 and 3 run backwards).
    let along = [ca, cb, -ca, -cb];
    let mut twice = 0.0;
    let mut z = DVec2::X;
    let mut rot = [DVec2::X; 4];
    let mut pieces = 0;
    for e in 0..4 {
        let se = s[e];
        if se * se >= r2 {
            continue;
        }
        let h = (r2 - se * se).sqrt();
        // The edge spans [start, start + len] from the foot of the perpendicular from c; the
        // chord spans [-h, h].
        let start = shape.start[e] - along[e];
        let (u0, u1) = (start.max(-h), (start + shape.len[e & 1]).min(h));
        if u0 >= u1 {
            continue;
        }
        pieces += 1;
        twice += se * (u1 - u0);
        let w = DVec2::new(se * se + u0 * u1, -se * (u1 - u0)); // conjugate rotation
        rot[e] = w;
        z = DVec2::new(z.x * w.x - z.y * w.y, z.x * w.y + z.y * w.x);
    }
    let winding = if s.iter().all(|&x| x >= 0.0) {
        std::f64::consts::TAU
    } else {
        0.0
    };
    let theta = if pieces == 0 {
        winding
    } else {
        let mut theta = z.y.atan2(z.x);
        if theta < 0.0 {
            theta += std::f64::consts::TAU;
        }
        if !(theta > 1e-6 && theta < std::f64::consts::TAU - 1e-6) {
            theta = winding + rot.iter().map(|w| w.y.atan2(w.x)).sum::<f64>();
        }
        theta
    };
    (0.5 * (twice + r2 * theta)).max(0.0)
}

/// Area of `disc(c, r) ∩ polygon` for a convex counter-clockwise polygon, as the sum over its
/// edges of the signed areas of `disc ∩ triangle(c, a, b)`: triangle parts plus circular
/// sectors whose angles add up to the measure `theta` in `[0, 2 pi]` of the circle inside the
/// polygon (Green's theorem). The sector rotations are composed as complex numbers and `theta`
/// taken with one `atan2` per disc; where `theta` is within 1e-6 of 0 or 2 pi (ambiguous
/// modulo 2 pi) the angles are summed edge by edge instead. The tests' reference for
/// [`disc_parallelogram_crossing_area`].
#[cfg(test)]
pub(crate) fn disc_convex_polygon_area(c: DVec2, r: f64, poly: &[DVec2; 4]) -> f64 {
    let r2 = r * r;
    let mut twice = 0.0;
    let mut z = DVec2::X; // product of the unit-free sector rotations
    let mut rot = [DVec2::X; 4];
    #[inline]
    fn mul(p: DVec2, q: DVec2) -> DVec2 {
        DVec2::new(p.x * q.x - p.y * q.y, p.x * q.y + p.y * q.x)
    }
    for e in 0..4 {
        let (a, b) = (poly[e] - c, poly[(e + 1) % 4] - c);
        let (da, db) = (a.length_squared(), b.length_squared());
        if da <= r2 && db <= r2 {
            twice += cross(a, b);
            continue;
        }
        let d = b - a;
        let dd = d.length_squared();
        if dd == 0.0 {
            continue;
        }
        let hb = a.dot(d) / dd;
        let disc = hb * hb - (da - r2) / dd;
        let (t0, t1) = if disc > 0.0 {
            let s = disc.sqrt();
            (-hb - s, -hb + s)
        } else {
            (1.0, 0.0)
        };
        let w = if disc <= 0.0 || t1 <= 0.0 || t0 >= 1.0 {
            // The edge stays outside the circle: a sector from a to b.
            DVec2::new(a.dot(b), cross(a, b))
        } else {
            let p0 = if t0 > 0.0 { a + d * t0 } else { a };
            let p1 = if t1 < 1.0 { a + d * t1 } else { b };
            twice += cross(p0, p1);
            // Sectors from a to p0 and from p1 to b.
            mul(
                DVec2::new(a.dot(p0), cross(a, p0)),
                DVec2::new(p1.dot(b), cross(p1, b)),
            )
        };
        // Keep the product in range: only the direction matters.
        let w = w / w.x.abs().max(w.y.abs()).max(f64::MIN_POSITIVE);
        rot[e] = w;
        z = mul(z, w);
        z /= z.x.abs().max(z.y.abs()).max(f64::MIN_POSITIVE);
    }
    let mut theta = z.y.atan2(z.x);
    if theta.abs() < 1e-6 || !theta.is_finite() {
        theta = rot.iter().map(|w| w.y.atan2(w.x)).sum();
    } else if theta < 0.0 {
        theta += std::f64::consts::TAU;
    }
    (0.5 * (twice + r2 * theta)).max(0.0)
}

/// A pixel footprint in a layer's noise space (see [`ScratchLayer::footprint_coverage`]).
struct NoiseFootprint {
    /// Centre.
    q0: DVec2,
    /// Edge vectors, counter-clockwise (`cross(qa, qb) > 0`).
    qa: DVec2,
    qb: DVec2,
    /// Area, `cross(qa, qb)`.
    cr: f64,
    /// Corners relative to `q0`, counter-clockwise.
    poly: [DVec2; 4],
    /// Half-extent of the bounding box, grown by the disc radius `tau`.
    ext: DVec2,
}

/// What [`ScratchLayer::footprint_candidates`] found.
#[allow(clippy::large_enum_variant)] // returned once per layer and query: no allocation
pub enum Candidates {
    /// The coverage needs no area work (`None`: too large a footprint, see
    /// [`ScratchLayer::footprint_coverage`]).
    Done(Option<f64>),
    /// Discs to clip against the footprint.
    Discs(FootprintCandidates),
    /// More discs than the caller's buffer (shorter than [`CANDIDATE_ROOM`]) holds: ask again
    /// with a buffer of [`CANDIDATE_ROOM`].
    Overflow,
}

/// How many scratch discs (radius `tau`, centres relative to the footprint's centre, in noise
/// space, held by the caller) may touch a footprint parallelogram, with what the area needs.
#[derive(Clone, Copy, Debug)]
pub struct FootprintCandidates {
    /// Number of candidate discs.
    pub n: usize,
    tau: f64,
    /// The footprint.
    shape: Parallelogram,
}

impl FootprintCandidates {
    /// The exact coverage: when no two candidate discs overlap (the common case: a layer covers
    /// about pi tau^2), the discs' areas are summed one by one, each in closed form
    /// ([`disc_parallelogram_area`]); only footprints with overlapping discs pay for the exact
    /// union ([`union_discs_polygon_area`]). Below 1e-12 the closed forms' value is rounding
    /// noise (a disc grazing the footprint: pi tau^2 less segments that nearly cancel), so it
    /// reports no coverage, as the union does.
    pub fn coverage(&self, centres: &[DVec2]) -> f64 {
        let area = if any_overlap(centres, self.tau) {
            union_discs_polygon_area(centres, self.tau, &self.shape.poly)
        } else {
            centres
                .iter()
                .map(|&c| disc_parallelogram_area(c, self.tau, &self.shape))
                .sum()
        };
        self.coverage_of_area(area)
    }

    /// [`Self::coverage`] where it may reach `floor`, else `None`: where no two discs overlap,
    /// the discs' exact areas replace their bounds ([`Self::disc_bound`]) one by one, and the
    /// layer is given up as soon as the exact areas so far and the bounds of the rest, padded as
    /// in [`Self::coverage_bound`], fall below `floor`. `bound_area` is the sum of the discs'
    /// bounds, [`Self::bound_area`] (the caller has it from choosing the layer). The value, when
    /// there is one, is the same as [`Self::coverage`]'s bit for bit (the same sum in the same
    /// order).
    pub fn coverage_reaching(&self, centres: &[DVec2], bound_area: f64, floor: f64) -> Option<f64> {
        if centres.len() < 2 {
            return Some(self.coverage(centres)); // no cheaper way to know
        }
        if any_overlap(centres, self.tau) {
            let c = self.coverage(centres);
            return (c >= floor).then_some(c);
        }
        let (mut area, mut bounded) = (0.0, 0.0);
        for &c in centres {
            area += disc_parallelogram_area(c, self.tau, &self.shape);
            bounded += self.disc_bound(c);
            if self.coverage_bound_of_area(area + (bound_area - bounded).max(0.0)) < floor {
                return None;
            }
        }
        Some(self.coverage_of_area(area))
    }

    /// The coverage of a scratched area: below 1e-12 it is rounding noise (see
    /// [`Self::coverage`]).
    #[inline]
    fn coverage_of_area(&self, area: f64) -> f64 {
        let c = area / self.shape.area;
        if c < 1e-12 {
            0.0
        } else {
            c.min(1.0)
        }
    }

    /// An upper bound on [`Self::coverage`] at a fraction of its cost: the sum of the discs'
    /// bounds ([`Self::bound_area`]), which bounds their union too, as a coverage
    /// ([`Self::coverage_bound_of_area`]).
    pub fn coverage_bound(&self, centres: &[DVec2]) -> f64 {
        self.coverage_bound_of_area(self.bound_area(centres))
    }

    /// The sum of the discs' area bounds ([`Self::disc_bound`]).
    #[inline]
    pub fn bound_area(&self, centres: &[DVec2]) -> f64 {
        centres.iter().map(|&c| self.disc_bound(c)).sum()
    }

    /// A bound on the scratched area `area` as a coverage, padded by a relative 1e-9 (and
    /// 1e-12) so that rounding in [`Self::coverage`] never exceeds it.
    #[inline]
    pub fn coverage_bound_of_area(&self, area: f64) -> f64 {
        (area / self.shape.area * (1.0 + 1e-9) + 1e-12).min(1.0)
    }

    /// An upper bound on the area of `disc(c, tau) ∩ parallelogram`: at most `pi tau^2`, the
    /// parallelogram's area, and for each pair of parallel edges the area of the disc inside
    /// their slab, `integral over x in [x0, x1] of chord(x)` (`x` across the slab, `[x0, x1]`
    /// the part of the slab the disc spans, `chord(x) = 2 sqrt(tau^2 - (x - x_c)^2)`), which is
    /// at most `(x1 - x0) chord((x0 + x1) / 2)` since the chord is concave in `x` (Jensen).
    /// (Before: `2 h` times the longest chord in the slab, `h` its half-width; twice the exact
    /// area on average for the teapot's footprints after the glass, 1.45 times with this one.)
    #[inline]
    pub fn disc_bound(&self, c: DVec2) -> f64 {
        disc_parallelogram_area_bound(c, self.tau, &self.shape)
    }
}
