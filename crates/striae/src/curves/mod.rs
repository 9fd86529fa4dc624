//! Scratches as curves (METHOD.md section 9): strokes of an SVG drawing ([`svg`]), polishing
//! swirls and turned circles ([`patterns`]), each flattened to a [`Polyline`] in texture space
//! with a half-width and a depth ratio at every vertex, and the set of them the renderer
//! queries ([`CurveSet`]).
//!
//! A polyline's opening is the union of its *thick segments*: the quadrilateral between two
//! consecutive vertices whose sides run at the vertices' half-widths from the centre line and
//! whose ends are the joints' mitre lines ([`Polyline::mitres`]), so that consecutive quads
//! share their joint edge and tile the stroke without overlap (METHOD.md 9.1: "the footprint
//! coverage is the area of the footprint inside the union of the polyline's thick segments").
//! The explicit grooves carve the same outline (`render::geometry::carve`).
//!
//! Conventions: texture space `(u, v)` as everywhere (`lib.rs`); a curve's direction at a point
//! is its segment's unit tangent in texture space, carried to 3D through `dP/du`, `dP/dv` as a
//! layer's direction is (METHOD.md 9.1). Queries take `f32` texture coordinates and work in `f64`.

pub mod clip;
pub mod patterns;
pub mod stroke;
pub mod svg;

use glam::DVec2;

/// Most segments a curve set may hold (about 9 MB of segments and grid): an SVG or a pattern
/// that flattens to more is refused up front with the figure.
pub const MAX_SEGMENTS: usize = 1 << 20;
/// The largest mitre a joint may take, in half-widths: a joint that turns by more than about
/// 151 degrees is clipped to it (its quads then overlap or leave a notch at the outer corner).
pub const MITRE_LIMIT: f64 = 4.0;
/// The smallest radius of curvature over width measured against explicit curved grooves
/// (METHOD.md 9.1, 9.6; docs/scratched.md, "Curves": full circles of `R / w` 1.5 to 20 on a
/// plate with diffuse walls render within 0.4-0.7 % of their carved grooves): tighter turns
/// are rendered all the same, with a warning naming the curves ([`CurveSet::tight_turns`]).
pub const MIN_RADIUS_OVER_WIDTH: f64 = 1.5;
/// Most curves one footprint query reports ([`CurveHits`]); the smallest are dropped beyond.
pub const MAX_CURVE_HITS: usize = 8;
/// Most grid cells a footprint query visits; a larger footprint takes the point test at the
/// hit (unbiased over the pixel's samples in `sum` and `union` mode, as `coverage = "point"`).
pub const MAX_QUERY_CELLS: usize = 1024;

/// Errors of curve sets: each names the curve (its index in the set, or the SVG element) and
/// the bad value.
#[derive(Debug, thiserror::Error)]
pub enum CurveError {
    #[error("curve {curve}: {why}")]
    Curve { curve: String, why: String },
    #[error("the curves flatten to {0} segments, more than the {MAX_SEGMENTS} a set may hold")]
    TooManySegments(usize),
    #[error("{key} = {value}: {why}")]
    Param {
        key: &'static str,
        value: String,
        why: String,
    },
    #[error("{path}: {why}")]
    File { path: String, why: String },
}

/// One scratch as a polyline in texture space (METHOD.md 9.1-9.2): vertices, the half-width
/// and the depth ratio (the groove's depth over the profile's, 1 = unworn) at each; both vary
/// linearly along each segment.
#[derive(Clone, Debug, PartialEq)]
pub struct Polyline {
    pub points: Vec<DVec2>,
    pub half_widths: Vec<f64>,
    pub depths: Vec<f64>,
}

impl Polyline {
    /// A polyline of constant half-width `hw` and depth ratio 1.
    pub fn uniform(points: Vec<DVec2>, hw: f64) -> Polyline {
        let n = points.len();
        Polyline {
            points,
            half_widths: vec![hw; n],
            depths: vec![1.0; n],
        }
    }

    /// Check it: at least 2 vertices, finite coordinates, half-widths `>= 0` and finite, depth
    /// ratios in `(0, 1]`, the arrays of one length; `name` names it in the error.
    pub fn validate(&self, name: &str) -> Result<(), CurveError> {
        let bad = |why: String| CurveError::Curve {
            curve: name.to_string(),
            why,
        };
        let n = self.points.len();
        if n < 2 {
            return Err(bad(format!("needs at least 2 points, has {n}")));
        }
        if self.half_widths.len() != n || self.depths.len() != n {
            return Err(bad(format!(
                "{n} points but {} half-widths and {} depths",
                self.half_widths.len(),
                self.depths.len()
            )));
        }
        if let Some(p) = self.points.iter().find(|p| !p.is_finite()) {
            return Err(bad(format!("a point is not finite: {p:?}")));
        }
        if let Some(w) = self
            .half_widths
            .iter()
            .find(|w| !(w.is_finite() && **w >= 0.0))
        {
            return Err(bad(format!(
                "widths must be finite and >= 0, got half-width {w:?}"
            )));
        }
        if self.half_widths.iter().all(|&w| w == 0.0) {
            return Err(bad("has zero width everywhere".into()));
        }
        if let Some(d) = self.depths.iter().find(|d| !(**d > 0.0 && **d <= 1.0)) {
            return Err(bad(format!("depth ratios must lie in (0, 1], got {d:?}")));
        }
        Ok(())
    }

    /// The smallest radius of curvature over the local width along the polyline: at each
    /// joint, the radius of the circle through a chord of the mean length of its two segments
    /// turning by the joint's angle, `c / (2 sin(turn / 2))`, over the joint's width (infinite
    /// for a straight line).
    pub fn min_radius_over_width(&self) -> f64 {
        let p = &self.points;
        let mut out = f64::INFINITY;
        for i in 1..p.len().saturating_sub(1) {
            let (a, b) = (p[i] - p[i - 1], p[i + 1] - p[i]);
            let (la, lb) = (a.length(), b.length());
            if la == 0.0 || lb == 0.0 {
                continue;
            }
            let turn = (a.dot(b) / (la * lb)).clamp(-1.0, 1.0).acos();
            let w = 2.0 * self.half_widths[i];
            if turn > 0.0 && w > 0.0 {
                out = out.min(0.5 * (la + lb) / (2.0 * (0.5 * turn).sin()) / w);
            }
        }
        out
    }

    /// Arc length along the polyline at each vertex (0 at the first).
    pub fn arc_lengths(&self) -> Vec<f64> {
        let mut s = Vec::with_capacity(self.points.len());
        let mut acc = 0.0;
        s.push(0.0);
        for w in self.points.windows(2) {
            acc += (w[1] - w[0]).length();
            s.push(acc);
        }
        s
    }

    /// The mitre vector at each vertex: the offset of the opening's outline per unit of
    /// half-width, on the left of the direction of travel (`perp`, counter-clockwise in uv).
    /// At the ends the segment's normal (a closed curve, whose last point is its first, has a
    /// joint there); at a joint the bisector of the two normals scaled by
    /// `1 / cos(turn / 2)`, so that the outline runs at the half-width from both segments,
    /// at most [`MITRE_LIMIT`]. Consecutive duplicate points must have been removed.
    pub fn mitres(&self) -> Vec<DVec2> {
        let p = &self.points;
        let n = p.len();
        let normal = |i: usize| (p[i + 1] - p[i]).normalize_or_zero().perp();
        let joint = |a: DVec2, b: DVec2| {
            let m = (a + b).normalize_or_zero();
            let c = m.dot(a);
            if m == DVec2::ZERO || c < 1.0 / MITRE_LIMIT {
                // Turning back on itself: the limit along the bisector (or the normal).
                let m = if m == DVec2::ZERO { a } else { m };
                m * MITRE_LIMIT
            } else {
                m / c
            }
        };
        // A closed curve (a circle, SVG's `Z`) joins its last segment to its first.
        let closed = n >= 3 && p[0] == p[n - 1];
        (0..n)
            .map(|i| {
                if i == 0 || i == n - 1 {
                    if closed {
                        joint(normal(n - 2), normal(0))
                    } else if i == 0 {
                        normal(0)
                    } else {
                        normal(n - 2)
                    }
                } else {
                    joint(normal(i - 1), normal(i))
                }
            })
            .collect()
    }

    /// The same polyline without consecutive duplicate points (a zero-length segment has no
    /// direction); `None` where fewer than 2 distinct points remain.
    pub fn deduplicated(mut self) -> Option<Polyline> {
        let mut keep = 0;
        for i in 0..self.points.len() {
            if keep > 0 && self.points[i] == self.points[keep - 1] {
                // Keep the wider end.
                self.half_widths[keep - 1] = self.half_widths[keep - 1].max(self.half_widths[i]);
                continue;
            }
            self.points[keep] = self.points[i];
            self.half_widths[keep] = self.half_widths[i];
            self.depths[keep] = self.depths[i];
            keep += 1;
        }
        self.points.truncate(keep);
        self.half_widths.truncate(keep);
        self.depths.truncate(keep);
        (keep >= 2).then_some(self)
    }
}

/// One thick segment: its quad (counter-clockwise), unit tangent and curve.
#[derive(Clone, Copy, Debug)]
struct Segment {
    quad: [DVec2; 4],
    tangent: DVec2,
    lo: DVec2,
    hi: DVec2,
    curve: u32,
    /// The depth ratio at its middle (METHOD.md 9.2).
    depth: f32,
}

impl Segment {
    /// Its groove's axis, the half-widths at its ends and its depth ratio.
    fn axis(&self) -> SegmentAxis {
        let q = &self.quad;
        // The quad's sides are the mitred ends: their part across the axis is the width.
        let across = self.tangent.perp();
        SegmentAxis {
            start: 0.5 * (q[0] + q[3]),
            end: 0.5 * (q[1] + q[2]),
            half_widths: [
                0.5 * (q[3] - q[0]).dot(across).abs(),
                0.5 * (q[2] - q[1]).dot(across).abs(),
            ],
            depth: self.depth,
        }
    }
}

/// One curve's part of a footprint ([`CurveSet::footprint`]): its coverage and the direction
/// of one of its segments, chosen in proportion to the segment's share of the footprint.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CurveHit {
    pub curve: u32,
    pub coverage: f64,
    pub direction: DVec2,
    pub depth: f32,
    /// The point test's segment ([`CurveSet::at_point`]): where the hit lies across it.
    pub axis: Option<SegmentAxis>,
}

/// The curves a footprint meets, at most [`MAX_CURVE_HITS`].
pub type CurveHits = arrayvec::ArrayVec<CurveHit, MAX_CURVE_HITS>;

/// One thick segment's groove as the ridge search of dielectric-walled glass reads it
/// ([`CurveSet::for_segments_along`]): its axis from `start` to `end` (texture space), the
/// half-width across the axis at either end and the depth ratio (METHOD.md 9.1-9.2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SegmentAxis {
    pub start: DVec2,
    pub end: DVec2,
    pub half_widths: [f64; 2],
    pub depth: f32,
}

impl SegmentAxis {
    /// The half-width across the axis at `s` in `[0, 1]` along it (linear between its ends;
    /// texture space).
    #[inline(always)]
    pub fn half_width_at(&self, s: f64) -> f64 {
        let [w0, w1] = self.half_widths;
        w0 + (w1 - w0) * s
    }
}

/// A set of scratch curves with a uniform grid over their segments in texture space.
#[derive(Clone, Debug)]
pub struct CurveSet {
    segments: Vec<Segment>,
    curves: usize,
    /// The largest half-width over the set (uv units, the larger axis of the drawing's map).
    max_half_width: f64,
    grid_lo: DVec2,
    cell: DVec2,
    dims: [usize; 2],
    cell_start: Vec<u32>,
    cell_segments: Vec<u32>,
    /// Names the set in the render workers' caches (`layers::CoverageCache`); unique per
    /// process, from 1.
    id: u64,
}

/// The next [`CurveSet`] id.
static NEXT_SET_ID: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

impl CurveSet {
    /// Build the set from polylines in drawing units (each checked with
    /// [`Polyline::validate`], named by its index) and the map to uv, `uv = p * to_uv` (one
    /// for curves given in uv; an SVG's [`svg::Drawing::to_uv`]). The outline is built in
    /// drawing units, where widths are isotropic, then mapped: an affine map keeps the
    /// quads' areas in proportion, so coverage stays exact.
    pub fn new(polylines: &[Polyline], to_uv: DVec2) -> Result<CurveSet, CurveError> {
        if !(to_uv.is_finite() && to_uv.x > 0.0 && to_uv.y > 0.0) {
            return Err(CurveError::Param {
                key: "to_uv",
                value: format!("{to_uv:?}"),
                why: "the drawing's scale onto uv must be finite and positive".into(),
            });
        }
        let total: usize = polylines
            .iter()
            .map(|p| p.points.len().saturating_sub(1))
            .sum();
        if total > MAX_SEGMENTS {
            return Err(CurveError::TooManySegments(total));
        }
        let mut segments = Vec::with_capacity(total);
        let mut max_half_width = 0.0f64;
        let mut curves = 0;
        for (c, line) in polylines.iter().enumerate() {
            line.validate(&format!("{c}"))?;
            let Some(line) = line.clone().deduplicated() else {
                continue;
            };
            let m = line.mitres();
            let (p, w) = (&line.points, &line.half_widths);
            for i in 0..p.len() - 1 {
                let j = i + 1;
                let quad = [
                    p[i] - m[i] * w[i],
                    p[j] - m[j] * w[j],
                    p[j] + m[j] * w[j],
                    p[i] + m[i] * w[i],
                ]
                .map(|q| q * to_uv);
                let lo = quad.iter().fold(DVec2::INFINITY, |a, &q| a.min(q));
                let hi = quad.iter().fold(DVec2::NEG_INFINITY, |a, &q| a.max(q));
                max_half_width = max_half_width.max(w[i].max(w[j]) * to_uv.max_element());
                segments.push(Segment {
                    quad,
                    tangent: ((p[j] - p[i]) * to_uv).normalize(),
                    lo,
                    hi,
                    curve: curves as u32,
                    depth: (0.5 * (line.depths[i] + line.depths[j])) as f32,
                });
            }
            curves += 1;
        }
        if segments.is_empty() {
            return Err(CurveError::Curve {
                curve: "(all)".into(),
                why: "no curve has two distinct points".into(),
            });
        }
        let (grid_lo, cell, dims, cell_start, cell_segments) = build_grid(&segments);
        Ok(CurveSet {
            segments,
            curves,
            max_half_width,
            grid_lo,
            cell,
            dims,
            cell_start,
            cell_segments,
            id: NEXT_SET_ID.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
        })
    }

    /// A process-unique id (clones share it).
    pub fn id(&self) -> u64 {
        self.id
    }

    /// `hits` with each curve that holds `uv` taking the direction (and depth) of its segment
    /// there (the render workers' caches, `layers::CoverageCache`).
    pub fn directed_at(&self, mut hits: CurveHits, uv: DVec2) -> CurveHits {
        if hits.is_empty() {
            return hits;
        }
        for p in self.at_point(uv) {
            if let Some(h) = hits.iter_mut().find(|h| h.curve == p.curve) {
                h.direction = p.direction;
                h.depth = p.depth;
            }
        }
        hits
    }

    /// The indices of `polylines` that turn tighter than [`MIN_RADIUS_OVER_WIDTH`], and the
    /// smallest radius over width among them.
    pub fn tight_turns(polylines: &[Polyline]) -> (Vec<usize>, f64) {
        let mut tight = Vec::new();
        let mut min = f64::INFINITY;
        for (i, l) in polylines.iter().enumerate() {
            let r = l.min_radius_over_width();
            if r < MIN_RADIUS_OVER_WIDTH {
                tight.push(i);
                min = min.min(r);
            }
        }
        (tight, min)
    }

    /// Number of curves (polylines with at least one segment).
    pub fn len(&self) -> usize {
        self.curves
    }

    pub fn is_empty(&self) -> bool {
        self.curves == 0
    }

    /// Number of thick segments.
    pub fn segments(&self) -> usize {
        self.segments.len()
    }

    /// The largest half-width over the set (uv units).
    pub fn max_half_width(&self) -> f64 {
        self.max_half_width
    }

    /// Bytes the set holds (segments and grid).
    pub fn bytes(&self) -> usize {
        self.segments.len() * std::mem::size_of::<Segment>()
            + (self.cell_start.len() + self.cell_segments.len()) * 4
    }

    /// The cell range `[i0, i1) x [j0, j1)` of the texture box `[lo, hi]`, clamped to the grid.
    fn cells_of(&self, lo: DVec2, hi: DVec2) -> ([usize; 2], [usize; 2]) {
        let f = |x: f64, k: usize| {
            let c = ((x - self.grid_lo[k]) / self.cell[k]).floor();
            c.clamp(0.0, (self.dims[k] - 1) as f64) as usize
        };
        let (i0, i1) = (f(lo.x, 0), f(hi.x, 0) + 1);
        let (j0, j1) = (f(lo.y, 1), f(hi.y, 1) + 1);
        ([i0, j0], [i1, j1])
    }

    /// Whether the box `[lo, hi]` misses the grid's bounds.
    fn outside(&self, lo: DVec2, hi: DVec2) -> bool {
        let ghi = self.grid_lo + self.cell * DVec2::new(self.dims[0] as f64, self.dims[1] as f64);
        hi.x < self.grid_lo.x || hi.y < self.grid_lo.y || lo.x > ghi.x || lo.y > ghi.y
    }

    /// Calls `f` with every segment whose bounds meet the box `[lo, hi]`, each once (a segment
    /// is visited from the first cell of the box and its own bounds that it lies in).
    fn for_segments_in(
        &self,
        lo: DVec2,
        hi: DVec2,
        (c0, c1): ([usize; 2], [usize; 2]),
        mut f: impl FnMut(&Segment),
    ) {
        let misses = |seg: &Segment| {
            seg.hi.x < lo.x || seg.hi.y < lo.y || seg.lo.x > hi.x || seg.lo.y > hi.y
        };
        if c1[0] - c0[0] == 1 && c1[1] - c0[1] == 1 {
            // One cell (every point query): its list holds each segment once.
            let cell = c0[1] * self.dims[0] + c0[0];
            let range = self.cell_start[cell] as usize..self.cell_start[cell + 1] as usize;
            for &s in &self.cell_segments[range] {
                let seg = &self.segments[s as usize];
                if !misses(seg) {
                    f(seg);
                }
            }
            return;
        }
        for j in c0[1]..c1[1] {
            for i in c0[0]..c1[0] {
                let cell = j * self.dims[0] + i;
                let range = self.cell_start[cell] as usize..self.cell_start[cell + 1] as usize;
                for &s in &self.cell_segments[range] {
                    let seg = &self.segments[s as usize];
                    if misses(seg) {
                        continue;
                    }
                    // Deduplicate: visit from the first cell of the overlap only.
                    let (o0, _) = self.cells_of(seg.lo.max(lo), seg.lo.max(lo));
                    if o0 != [i, j] {
                        continue;
                    }
                    f(seg);
                }
            }
        }
    }

    /// Calls `f` with the axis of every thick segment whose bounds meet the texture segment
    /// from `from` to `to`'s box, until `f` returns `true`; whether one did. A groove that a
    /// ray passing under the surface along that segment meets lies among them: its walls lie
    /// under its opening, which the segment's projection must enter.
    pub fn for_segments_along(
        &self,
        from: DVec2,
        to: DVec2,
        mut f: impl FnMut(&SegmentAxis) -> bool,
    ) -> bool {
        let (lo, hi) = (from.min(to), from.max(to));
        if self.outside(lo, hi) {
            return false;
        }
        let mut found = false;
        self.for_segments_in(lo, hi, self.cells_of(lo, hi), |seg| {
            if found {
                return;
            }
            found = f(&seg.axis());
        });
        found
    }

    /// The point of curve `curve` nearest to `uv` among its segments whose bounds meet the box
    /// `uv +- reach`, moved across the axis by `across` (in `[-1, 1]`) of the half-width there:
    /// where a footprint's path goes on from (`render::scratched`, METHOD.md section 6). `None`
    /// where no segment of the curve comes within the box.
    pub fn nearest_point(&self, curve: u32, uv: DVec2, reach: DVec2, across: f64) -> Option<DVec2> {
        let (lo, hi) = (uv - reach, uv + reach);
        if self.outside(lo, hi) {
            return None;
        }
        let mut best: Option<(f64, DVec2)> = None;
        self.for_segments_in(lo, hi, self.cells_of(lo, hi), |seg| {
            if seg.curve != curve {
                return;
            }
            let axis = seg.axis();
            let d = axis.end - axis.start;
            let len2 = d.length_squared();
            let t = if len2 > 0.0 {
                ((uv - axis.start).dot(d) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let p = axis.start + t * d + seg.tangent.perp() * (across * axis.half_width_at(t));
            let dist = p.distance_squared(uv);
            if best.is_none_or(|(b, _)| dist < b) {
                best = Some((dist, p));
            }
        });
        best.map(|(_, p)| p)
    }

    /// The curves whose opening holds texture point `uv` (coverage 1 each, the direction of the
    /// segment holding it): `coverage = "point"`, and the point test behind a too-large
    /// footprint.
    pub fn at_point(&self, uv: DVec2) -> CurveHits {
        let mut hits = CurveHits::new();
        if self.outside(uv, uv) {
            return hits;
        }
        let cells = self.cells_of(uv, uv);
        self.for_segments_in(uv, uv, cells, |seg| {
            if clip::convex_contains(&seg.quad, uv) && !hits.iter().any(|h| h.curve == seg.curve) {
                let hit = CurveHit {
                    curve: seg.curve,
                    coverage: 1.0,
                    direction: seg.tangent,
                    depth: seg.depth,
                    axis: Some(seg.axis()),
                };
                let _ = hits.try_push(hit);
            }
        });
        hits
    }

    /// The share of the footprint `{uv + s a + t b : s, t in [-1/2, 1/2]}` each curve's opening
    /// covers (exact: the footprint clipped by every thick segment, METHOD.md 9.1), with one
    /// segment's direction per curve drawn in proportion to its share by `u` in `[0, 1)`. A
    /// degenerate footprint, or one spanning more than [`MAX_QUERY_CELLS`] grid cells, takes
    /// the point test ([`Self::at_point`]). Beyond [`MAX_CURVE_HITS`] curves the smallest are
    /// dropped.
    pub fn footprint(&self, uv: DVec2, a: DVec2, b: DVec2, u: f64) -> CurveHits {
        self.footprint_within(uv, a, b, u, MAX_QUERY_CELLS)
    }

    /// [`Self::footprint`] with footprints spanning more than `max_cells` grid cells taking
    /// the point test.
    pub fn footprint_within(
        &self,
        uv: DVec2,
        a: DVec2,
        b: DVec2,
        u: f64,
        max_cells: usize,
    ) -> CurveHits {
        let area = a.perp_dot(b).abs();
        let corners = [
            uv - 0.5 * a - 0.5 * b,
            uv + 0.5 * a - 0.5 * b,
            uv + 0.5 * a + 0.5 * b,
            uv - 0.5 * a + 0.5 * b,
        ];
        let lo = corners.iter().fold(DVec2::INFINITY, |m, &q| m.min(q));
        let hi = corners.iter().fold(DVec2::NEG_INFINITY, |m, &q| m.max(q));
        if !(area > 0.0 && area.is_finite()) {
            return self.at_point(uv);
        }
        if self.outside(lo, hi) {
            return CurveHits::new();
        }
        let cells = self.cells_of(lo, hi);
        let count = (cells.1[0] - cells.0[0]) * (cells.1[1] - cells.0[1]);
        if count > max_cells {
            return self.at_point(uv);
        }
        // Counter-clockwise corners for the clip.
        let poly = if a.perp_dot(b) > 0.0 {
            corners
        } else {
            [corners[0], corners[3], corners[2], corners[1]]
        };
        // Per curve: covered area, and a reservoir of one segment weighted by its area.
        struct Acc {
            hit: CurveHit,
            u: f64,
        }
        let mut acc: arrayvec::ArrayVec<Acc, { 4 * MAX_CURVE_HITS }> = arrayvec::ArrayVec::new();
        self.for_segments_in(lo, hi, cells, |seg| {
            let s = clip::clipped_area(&poly, &seg.quad);
            if s <= 0.0 {
                return;
            }
            let entry = match acc.iter().rposition(|e| e.hit.curve == seg.curve) {
                Some(i) => &mut acc[i],
                None => {
                    if acc.is_full() {
                        // Drop the smallest so far (its area is lost to the footprint).
                        let (i, _) = acc
                            .iter()
                            .enumerate()
                            .min_by(|x, y| x.1.hit.coverage.total_cmp(&y.1.hit.coverage))
                            .expect("full");
                        acc.swap_remove(i);
                    }
                    acc.push(Acc {
                        hit: CurveHit {
                            curve: seg.curve,
                            ..CurveHit::default()
                        },
                        u,
                    });
                    acc.last_mut().expect("pushed")
                }
            };
            // One uniform, rescaled, picks the segment in proportion to its area.
            entry.hit.coverage += s;
            let p = s / entry.hit.coverage;
            if entry.u < p {
                entry.u /= p;
                entry.hit.direction = seg.tangent;
                entry.hit.depth = seg.depth;
            } else {
                entry.u = (entry.u - p) / (1.0 - p);
            }
        });
        acc.sort_by(|x, y| {
            y.hit
                .coverage
                .total_cmp(&x.hit.coverage)
                .then(x.hit.curve.cmp(&y.hit.curve))
        });
        acc.iter()
            .take(MAX_CURVE_HITS)
            .map(|e| CurveHit {
                coverage: (e.hit.coverage / area).min(1.0),
                ..e.hit
            })
            .collect()
    }
}

/// Most grid entries a segment may make on average ([`build_grid`]).
const MAX_CELL_ENTRIES_PER_SEGMENT: usize = 16;

/// A uniform grid over the segments' bounds, about two cells a segment (at most 2048 a side,
/// coarser where long segments would list themselves in too many cells),
/// each cell listing the segments whose bounds reach it (compressed rows).
#[allow(clippy::type_complexity)]
fn build_grid(segments: &[Segment]) -> (DVec2, DVec2, [usize; 2], Vec<u32>, Vec<u32>) {
    let lo = segments.iter().fold(DVec2::INFINITY, |m, s| m.min(s.lo));
    let hi = segments
        .iter()
        .fold(DVec2::NEG_INFINITY, |m, s| m.max(s.hi));
    let ext = (hi - lo).max(DVec2::splat(1e-12));
    let target = (2 * segments.len()).max(1) as f64;
    let mut side = (ext.x * ext.y / target).sqrt();
    let dim = |e: f64, side: f64| ((e / side).ceil() as usize).clamp(1, 2048);
    // Long segments reach many cells: coarsen until the lists hold at most
    // [`MAX_CELL_ENTRIES_PER_SEGMENT`] entries a segment (a long straight stroke across a fine
    // grid would otherwise list itself in every cell of its bounds).
    let entries = |side: f64| -> usize {
        let (nx, ny) = (dim(ext.x, side), dim(ext.y, side));
        let reach = |a: f64, b: f64, e: f64, n: usize| ((b - a) / e * n as f64) as usize + 2;
        segments
            .iter()
            .map(|s| reach(s.lo.x, s.hi.x, ext.x, nx) * reach(s.lo.y, s.hi.y, ext.y, ny))
            .sum()
    };
    while entries(side) > MAX_CELL_ENTRIES_PER_SEGMENT * segments.len()
        && (dim(ext.x, side) > 1 || dim(ext.y, side) > 1)
    {
        side *= 2.0;
    }
    let dims = [dim(ext.x, side), dim(ext.y, side)];
    let cell = ext / DVec2::new(dims[0] as f64, dims[1] as f64);
    let cell_of = |x: f64, k: usize| {
        (((x - lo[k]) / cell[k]).floor()).clamp(0.0, (dims[k] - 1) as f64) as usize
    };
    let range = |s: &Segment| {
        (
            cell_of(s.lo.x, 0)..cell_of(s.hi.x, 0) + 1,
            cell_of(s.lo.y, 1)..cell_of(s.hi.y, 1) + 1,
        )
    };
    let mut count = vec![0u32; dims[0] * dims[1] + 1];
    for s in segments {
        let (ri, rj) = range(s);
        for j in rj {
            for i in ri.clone() {
                count[j * dims[0] + i + 1] += 1;
            }
        }
    }
    for c in 1..count.len() {
        count[c] += count[c - 1];
    }
    let mut fill = count.clone();
    let mut items = vec![0u32; count[count.len() - 1] as usize];
    for (k, s) in segments.iter().enumerate() {
        let (ri, rj) = range(s);
        for j in rj {
            for i in ri.clone() {
                let c = j * dims[0] + i;
                items[fill[c] as usize] = k as u32;
                fill[c] += 1;
            }
        }
    }
    (lo, cell, dims, count, items)
}

#[cfg(test)]
mod tests;
