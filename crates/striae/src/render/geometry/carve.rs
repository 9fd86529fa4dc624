//! Explicit scratch geometry (METHOD.md 8.3, 9.6): the scratches of a layer set and the
//! material's curves built as real grooves carved into the planar faces of a shape.
//!
//! Each scratch (one ellipse of [`LayerSet::scratches`]) becomes a groove along its long axis:
//! at `N` stations `s = -l cos theta` (`theta` uniform, so the stations crowd at the tapered
//! ends) the cross-section is the profile scaled to the local width `2 w(s)`, `w(s) = w_0
//! sqrt(1 - (s/l)^2)`, depth in proportion; between stations the width is linear in `s`, so every
//! wall quad is planar and the groove is exactly the triangles [`Carving::walls`] builds. The
//! void a groove cuts is analytic ([`Carving::in_void`]): the flat face is not a surface inside
//! a groove's opening, and a wall is not a surface inside another groove's void (their union is
//! the void), so [`crate::render::geometry::Geometry`] drops such hits (a hit filter), with a margin at
//! the seams that keeps surfaces, never leaks: [`MARGIN_ROUND_OFFS`] times the round-off of a
//! hit position on the face. The face is cut away over the opening less that margin; another
//! groove's wall is cut away inside the void farther than it from the void's walls.
//!
//! A face is the parallelogram `P(u, v) = o + u dP/du + v dP/dv`, `(u, v)` in `[0, 1]^2`. The
//! texture-space ellipse maps to a face ellipse by that affine map `A`; for thin scratches
//! (`W << L`) its image is the thin ellipse along `A d` of half-length `|A d| l` and half-width
//! `w_0 det A / |A d|` (area preserved), which is what the groove takes (exact for a similarity).
//! A groove is cut where its centre line leaves the face (open at the face's edge).
//!
//! **Curves** (METHOD.md 9.6): a curve's groove is the profile swept along its polyline
//! ([`crate::curves::Polyline`], drawing units, `uv = p * to_uv`). At vertex `i` the
//! cross-section lies along the joint's mitre `m_i` ([`crate::curves::Polyline::mitres`]): its
//! profile point `x` sits at `p_i + 2 x m_i w_i` (on the side of `b = t x n` for `x > 0`, as a
//! straight groove's), mapped to uv and onto the face, and `2 w_i' z d_i` below it, `w_i'` the
//! half-width in world units by the same area-preserving rule along the vertex's tangent and
//! `d_i` the depth ratio (wear, METHOD.md 9.2). Consecutive segments share the joint's
//! cross-section, and the opening is exactly the SV-BRDF's thick segments
//! ([`crate::curves::CurveSet`]) mapped onto the face. Between two joints every cross-section
//! interpolates theirs linearly (a ruled surface over each profile segment, built as two
//! triangles: exact where the quad is planar, as on a straight segment or a circle of constant
//! width and depth; elsewhere off by its twist, where the width or the depth changes along a
//! turn), and the void of a segment is the set of points under its opening, between its two
//! mitre lines, inside the cross-section through them. Below the face its margin grows by the
//! segment's twist, so that the void stays inside the triangles' walls by the margin. A curve is cut where its centre line leaves the face, open
//! there as a straight groove is; its own ends, where wider than zero, are closed by the
//! profile's polygon (a cap).

use crate::curves::Polyline;
use crate::layers::{LayerSet, Scratch};
use crate::math::{Vec2, Vec3};
use glam::{DVec2, DVec3};

/// Stations along each groove (ends included) unless the scene says otherwise
/// (`scratches.stations`): the opening is the polygon through them, which falls short of the
/// ellipse's area by `1 - sin(x) / x`, `x = pi / (stations - 1)` (0.7 % at 16, 0.04 % at 64).
pub const DEFAULT_STATIONS: usize = 16;
/// The fewest and the most stations a groove may have.
pub const STATIONS_RANGE: std::ops::RangeInclusive<usize> = 3..=1024;
/// Margin of the void test, in units of the round-off of a world-space hit position (`f32`) on
/// the face: relative to a groove's local width, 1.2e-3 on a setting-1 groove 4e-4 wide on a
/// face at distance 1 from the origin, 1.2e-4 at setting 2. The face kept over that band of the
/// opening is the reference's own error in the opening's area (`docs/fidelity.md`).
pub const MARGIN_ROUND_OFFS: f64 = 8.0;
/// The largest margin, in units of the local width (a groove narrower than the round-off
/// toward its tips).
const MAX_MARGIN: f32 = 0.25;
/// A curve segment whose walls twist off the ruled surface by more than this fraction of its
/// width is split into as many pieces as bring each under it ([`MAX_SPLIT`] at most): the void
/// keeps that much more margin from its walls there.
pub const TWIST_TOLERANCE: f64 = 2e-3;
/// The most pieces a twisted curve segment is split into.
pub const MAX_SPLIT: usize = 16;

/// A planar face: `P(u, v) = origin + u dpdu + v dpdv`, outward unit normal `n`.
#[derive(Clone, Copy, Debug)]
pub struct Face {
    pub origin: Vec3,
    pub dpdu: Vec3,
    pub dpdv: Vec3,
    pub n: Vec3,
}

/// One straight groove in the face's orthonormal frame `(e1, e2)` (world units).
#[derive(Clone, Debug)]
struct Groove {
    centre: Vec2,
    dir: Vec2,
    /// Station positions along `dir` (increasing) and half-widths there.
    s: Box<[f32]>,
    hw: Box<[f32]>,
}

impl Groove {
    /// The first and the last station's positions along `dir`.
    fn ends(&self) -> (f32, f32) {
        (self.s[0], self.s[self.s.len() - 1])
    }

    /// Its cross-sections, one a station: the profile across `b = t x n`, scaled to the width.
    fn sections(&self) -> Vec<Section> {
        let across = across(self.dir).as_dvec2();
        (0..self.s.len())
            .map(|k| {
                let width = 2.0 * self.hw[k] as f64;
                Section {
                    centre: (self.centre + self.s[k] * self.dir).as_dvec2(),
                    across: width * across,
                    depth: width,
                }
            })
            .collect()
    }
}

/// A cross-section of a groove in the face frame: the profile's point `(x, z)` lies at
/// `centre + x across` on the face, `z depth` above it (`z <= 0`: below).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Section {
    centre: DVec2,
    across: DVec2,
    depth: f64,
}

impl Section {
    /// Profile point `p` on the section, in the face frame `(x1, x2, height)`.
    fn at(&self, p: [f32; 2]) -> DVec3 {
        let x = self.centre + p[0] as f64 * self.across;
        DVec3::new(x.x, x.y, p[1] as f64 * self.depth)
    }

    fn lerp(&self, o: &Section, t: f64) -> Section {
        Section {
            centre: self.centre.lerp(o.centre, t),
            across: self.across.lerp(o.across, t),
            depth: self.depth + t * (o.depth - self.depth),
        }
    }
}

/// A curve's groove in the face frame (METHOD.md 9.6): the cross-sections at its polyline's
/// vertices (clipped to the face), along the joints' mitres.
#[derive(Clone, Debug)]
struct CurvedGroove {
    sections: Vec<Section>,
    /// The groove's full width at each vertex across its tangent (world units, `2 w_i'`).
    width: Vec<f64>,
    /// Whether its first and its last end are the curve's own, closed by a cap (rather than a
    /// cut where the curve leaves the face, or a tip of zero width).
    caps: [bool; 2],
    /// The void piece of its first segment (the others follow).
    first_piece: u32,
}

/// A curved groove's segment, one piece of the void.
#[derive(Clone, Copy, Debug)]
struct CurveSegment {
    curve: u32,
    /// Its first vertex.
    vertex: u32,
    /// How far its wall triangles may lie from the ruled surface between its sections (world
    /// units): the margin below the face grows by it.
    twist: f64,
}

/// A polyline's vertex on its way to the face: its uv, cross-section and width.
#[derive(Clone, Copy, Debug)]
struct CurveVertex {
    uv: DVec2,
    section: Section,
    width: f64,
}

impl CurveVertex {
    fn lerp(&self, o: &CurveVertex, t: f64) -> CurveVertex {
        CurveVertex {
            uv: self.uv.lerp(o.uv, t),
            section: self.section.lerp(&o.section, t),
            width: self.width + t * (o.width - self.width),
        }
    }
}

/// The grooves of one face, their walls and a grid to find the grooves near a point.
///
/// The void is made of *pieces*, each tested on its own: piece `k < grooves` is straight
/// groove `k`, the next ones the curved grooves' segments in order.
#[derive(Clone, Debug)]
pub struct Carving {
    origin: Vec3,
    e1: Vec3,
    e2: Vec3,
    n: Vec3,
    /// The profile's points, `x` in `[-1/2, 1/2]`, `z <= 0`, width 1.
    profile: Vec<[f32; 2]>,
    /// The profile's polygon closed by its opening, as triangles of its points: a curve's cap.
    cap: Vec<[u32; 3]>,
    grooves: Vec<Groove>,
    curves: Vec<CurvedGroove>,
    /// The curve segment pieces.
    segments: Vec<CurveSegment>,
    /// Uniform grid over the face: lower corner, cell size, cells per row and column, and per
    /// cell the pieces that reach it (compressed rows).
    grid_lo: Vec2,
    cell: f32,
    dims: [usize; 2],
    cell_start: Vec<u32>,
    cell_pieces: Vec<u32>,
    /// The piece of each wall triangle of [`Carving::walls`].
    tri_piece: Vec<u32>,
    /// The void test's margin in world units ([`MARGIN_ROUND_OFFS`]).
    margin: f64,
}

/// Wall triangles per groove of a profile of `segments` segments with `stations` stations
/// (upper bound: the degenerate triangles at the pointed ends are dropped).
pub fn triangles_per_groove(segments: usize, stations: usize) -> usize {
    2 * segments * (stations - 1)
}

/// Wall triangles of a curve's groove (METHOD.md 9.6) of a profile of `segments` segments
/// along a polyline of `vertices` vertices: two per profile segment and polyline segment, and
/// the caps at its two ends (clipped to the face, it holds no more; a segment split for its
/// twist, [`TWIST_TOLERANCE`], where a taper or wear changes the width or depth along a turn,
/// adds its pieces).
pub fn triangles_per_curve(segments: usize, vertices: usize) -> usize {
    2 * segments * vertices.saturating_sub(1) + 2 * segments.saturating_sub(1)
}

impl Face {
    /// The face's orthonormal frame `(e1 along dP/du, e2, n)`.
    fn frame(&self) -> (Vec3, Vec3) {
        let e1 = self.dpdu.normalize();
        (e1, self.n.cross(e1))
    }

    /// The scratches of `layers` on this face.
    pub fn scratches(layers: &LayerSet) -> Vec<Scratch> {
        layers.scratches(DVec2::ZERO, DVec2::ONE)
    }

    /// The largest coordinate of a point of the face, which bounds the round-off of a hit
    /// position on it.
    fn extent(&self) -> f64 {
        [Vec3::ZERO, self.dpdu, self.dpdv, self.dpdu + self.dpdv]
            .map(|c| (self.origin + c).abs().max_element() as f64)
            .into_iter()
            .fold(0.0, f64::max)
    }

    /// `A`: texture-space vectors to the face frame (columns `A u`, `A v`).
    fn affine(&self) -> [Vec2; 2] {
        let (e1, e2) = self.frame();
        [
            Vec2::new(self.dpdu.dot(e1), self.dpdu.dot(e2)),
            Vec2::new(self.dpdv.dot(e1), self.dpdv.dot(e2)),
        ]
    }
}

/// The image `A d` of a texture-space direction `d` and `|det A|`: a scratch along `d` of
/// half-width `w` maps to one along `A d` of half-width `w |det A| / |A d|`, the thin shape of
/// the same area ([`Scratch::mapped_half_axes`]), the rule straight and curved grooves share.
fn image(a: &[DVec2; 2], d: DVec2) -> (DVec2, f64) {
    (a[0] * d.x + a[1] * d.y, a[0].perp_dot(a[1]).abs())
}

/// The image of a texture-space scratch on the face: `(unit direction, half-width w_0, length
/// scale |A d|)` of the thin-ellipse approximation (module docs).
fn map_scratch(a: &[Vec2; 2], s: &Scratch) -> (Vec2, f32, f32) {
    let (d, det) = image(&a.map(Vec2::as_dvec2), s.direction);
    let len = d.length();
    let (_, half_width) = s.mapped_half_axes(len, det);
    ((d / len).as_vec2(), half_width as f32, len as f32)
}

/// The interval of `t` in `[lo, hi]` where `p + t d` lies in `[0, 1]^2`, if any.
fn clip_to_unit_square(p: DVec2, d: DVec2, lo: f64, hi: f64) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (lo, hi);
    for k in 0..2 {
        if d[k].abs() < 1e-300 {
            if !(0.0..=1.0).contains(&p[k]) {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((0.0 - p[k]) / d[k], (1.0 - p[k]) / d[k]);
        lo = lo.max(t0.min(t1));
        hi = hi.min(t0.max(t1));
    }
    (hi > lo).then_some((lo, hi))
}

/// The point `(t, x)` of the ruled patch between cross-sections `a` (`t = 0`) and `b`
/// (`t = 1`) whose opening holds `q`: `q = (1 - t)(a.centre + x a.across) + t (b.centre + x
/// b.across)` with `t` in `[0, 1]`, `x` in `[-1/2, 1/2]` (the inverse of the bilinear map of the
/// segment's quad), if any.
fn bilinear_inverse(a: &Section, b: &Section, q: DVec2) -> Option<(f64, f64)> {
    let (r, e, c, d) = (
        q - a.centre,
        a.across,
        b.across - a.across,
        b.centre - a.centre,
    );
    // r - x e = t (d + x c): the two sides parallel, x^2 (e ^ c) + x (e ^ d - r ^ c) - r ^ d = 0.
    let (qa, qb, qc) = (e.perp_dot(c), e.perp_dot(d) - r.perp_dot(c), -r.perp_dot(d));
    let roots = if qa == 0.0 {
        [-qc / qb, f64::NAN]
    } else {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc < 0.0 {
            return None;
        }
        // The stable pair: the small root stays exact as the sides turn parallel (qa -> 0).
        let k = -0.5 * (qb + disc.sqrt().copysign(qb));
        [qc / k, k / qa]
    };
    roots.into_iter().find_map(|x| {
        if !(x.abs() <= 0.5) {
            return None;
        }
        let side = d + x * c;
        let t = (r - x * e).dot(side) / side.length_squared();
        (0.0..=1.0).contains(&t).then_some((t, x))
    })
}

/// The distance from `q` to the line of cross-section `s` (a cap's trace on the face).
fn distance_to_section(s: &Section, q: DVec2) -> f64 {
    (q - s.centre).perp_dot(s.across).abs() / s.across.length()
}

/// Wall triangles under construction, with each one's void piece.
#[derive(Default)]
struct Walls {
    positions: Vec<Vec3>,
    indices: Vec<[u32; 3]>,
    pieces: Vec<u32>,
}

impl Walls {
    /// Adds triangle `tri` of piece `piece` wound so that its normal faces `want` (into the
    /// void); a degenerate one is dropped.
    fn push(&mut self, tri: [u32; 3], want: Vec3, piece: u32) {
        let [a, b, c] = tri.map(|i| self.positions[i as usize]);
        let nrm: Vec3 = (b - a).cross(c - a);
        if !(nrm.length_squared() > 0.0) {
            return;
        }
        self.indices.push(if nrm.dot(want) >= 0.0 {
            tri
        } else {
            [tri[0], tri[2], tri[1]]
        });
        self.pieces.push(piece);
    }
}

impl Carving {
    /// The grooves of `scratches` (texture space, [`Face::scratches`]) and of `curves`
    /// (polylines in drawing units, `uv = p * to_uv`, each valid by
    /// [`Polyline::validate`]; METHOD.md 9.6) carved into `face` with `profile` (points of width
    /// 1, [`crate::precompute::profile::Profile::points`]), `stations` stations along each
    /// straight groove (within [`STATIONS_RANGE`]).
    pub fn new(
        face: &Face,
        scratches: &[Scratch],
        curves: &[Polyline],
        to_uv: DVec2,
        profile: &[[f64; 2]],
        stations: usize,
    ) -> Carving {
        let (e1, e2) = face.frame();
        let a = face.affine();
        let stations = stations.clamp(*STATIONS_RANGE.start(), *STATIONS_RANGE.end());
        let grooves: Vec<Groove> = scratches
            .iter()
            .filter_map(|s| Self::groove(&a, s, stations))
            .collect();
        let profile: Vec<[f32; 2]> = profile.iter().map(|p| [p[0] as f32, p[1] as f32]).collect();
        let mut c = Carving {
            origin: face.origin,
            e1,
            e2,
            n: face.n,
            cap: triangulate(&profile),
            profile,
            grooves,
            curves: Vec::new(),
            segments: Vec::new(),
            grid_lo: Vec2::ZERO,
            cell: 1.0,
            dims: [1, 1],
            cell_start: Vec::new(),
            cell_pieces: Vec::new(),
            tri_piece: Vec::new(),
            margin: MARGIN_ROUND_OFFS * f32::EPSILON as f64 / 2.0 * face.extent(),
        };
        let a64 = a.map(Vec2::as_dvec2);
        for line in curves {
            c.add_curve(&a64, line, to_uv);
        }
        c.build_grid(&a);
        c
    }

    /// One groove: the scratch's centre line clipped to the face, `stations` stations on it,
    /// evenly spaced in the ellipse's angle (so closer together toward its tips).
    fn groove(a: &[Vec2; 2], s: &Scratch, stations: usize) -> Option<Groove> {
        let (dir, w0, scale) = map_scratch(a, s);
        let l = s.half_length;
        let (lo, hi) = clip_to_unit_square(s.centre, s.direction, -l, l)?;
        let (th_lo, th_hi) = (
            (-lo / l).clamp(-1.0, 1.0).acos(),
            (-hi / l).clamp(-1.0, 1.0).acos(),
        );
        let th = |k: usize| th_lo + (th_hi - th_lo) * k as f64 / (stations - 1) as f64;
        let st: Box<[f32]> = (0..stations)
            .map(|k| (-l * th(k).cos()) as f32 * scale)
            .collect();
        let hw = (0..stations)
            .map(|k| w0 * th(k).sin().max(0.0) as f32)
            .collect();
        let c = a[0] * s.centre.x as f32 + a[1] * s.centre.y as f32;
        (st[stations - 1] > st[0]).then_some(Groove {
            centre: c,
            dir,
            s: st,
            hw,
        })
    }

    /// The grooves of one curve (METHOD.md 9.6): its vertices' cross-sections on the face
    /// (under `a`, uv to the face frame), then its runs inside the face, each a
    /// [`CurvedGroove`]. A cut at the face's edge interpolates the segment's cross-sections, so
    /// the pieces keep the segment's opening and walls.
    fn add_curve(&mut self, a: &[DVec2; 2], line: &Polyline, to_uv: DVec2) {
        let Some(line) = line.clone().deduplicated() else {
            return;
        };
        let mitres = line.mitres();
        let n = line.points.len();
        // The mitres lie left of the direction of travel in the drawing; `b = t x n` lies
        // right of it on the face where the map keeps orientation.
        let side = if a[0].perp_dot(a[1]) >= 0.0 {
            -2.0
        } else {
            2.0
        };
        let verts: Vec<CurveVertex> = (0..n)
            .map(|i| {
                let uv = line.points[i] * to_uv;
                // The tangent at the vertex: across its mitre (the segment's at an open end).
                let tangent = -mitres[i].perp().normalize_or_zero();
                let (along, det) = image(a, tangent * to_uv);
                let width = 2.0 * line.half_widths[i] * det * to_uv.x * to_uv.y / along.length();
                let width = if width.is_finite() { width } else { 0.0 };
                let (across, _) = image(a, mitres[i] * line.half_widths[i] * to_uv);
                CurveVertex {
                    uv,
                    section: Section {
                        centre: image(a, uv).0,
                        across: side * across,
                        depth: width * line.depths[i],
                    },
                    width,
                }
            })
            .collect();
        // A closed curve (a circle, SVG's `Z`) that leaves the face starts and ends outside it.
        let closed = n >= 3 && line.points[0] == line.points[n - 1];
        let outside =
            |v: &CurveVertex| !(v.uv.cmpge(DVec2::ZERO).all() && v.uv.cmple(DVec2::ONE).all());
        let order: Vec<usize> = match (closed, verts.iter().position(outside)) {
            (true, Some(k)) => (k..n - 1).chain(0..=k).collect(),
            _ => (0..n).collect(),
        };
        let own_ends = !closed;
        let mut run: Vec<CurveVertex> = Vec::new();
        let mut start_cap = false;
        for k in 0..order.len() - 1 {
            let (v0, v1) = (&verts[order[k]], &verts[order[k + 1]]);
            let Some((t0, t1)) = clip_to_unit_square(v0.uv, v1.uv - v0.uv, 0.0, 1.0) else {
                self.finish_curve(std::mem::take(&mut run), [start_cap, false]);
                continue;
            };
            if run.is_empty() {
                start_cap = own_ends && k == 0 && t0 == 0.0;
                run.push(if t0 > 0.0 { v0.lerp(v1, t0) } else { *v0 });
            }
            if t1 < 1.0 {
                run.push(v0.lerp(v1, t1));
                self.finish_curve(std::mem::take(&mut run), [start_cap, false]);
            } else {
                run.push(*v1);
            }
        }
        self.finish_curve(run, [start_cap, own_ends]);
    }

    /// Adds the curved groove through `run` (nothing under 2 vertices), closed by caps at the
    /// ends `caps` names that are wider than zero. A segment that twists by more than
    /// [`TWIST_TOLERANCE`] of its width is split along its ruled surface (the pieces keep its
    /// opening; the twist falls as their number).
    fn finish_curve(&mut self, coarse: Vec<CurveVertex>, caps: [bool; 2]) {
        if coarse.len() < 2 {
            return;
        }
        let mut run = Vec::with_capacity(coarse.len());
        run.push(coarse[0]);
        for w in coarse.windows(2) {
            let width = w[0].width.max(w[1].width);
            let pieces = self.twist(&w[0].section, &w[1].section) / (TWIST_TOLERANCE * width);
            let n = if pieces.is_finite() {
                (pieces.ceil() as usize).clamp(1, MAX_SPLIT)
            } else {
                1
            };
            run.extend((1..n).map(|k| w[0].lerp(&w[1], k as f64 / n as f64)));
            run.push(w[1]);
        }
        let curve = self.curves.len() as u32;
        let first_piece = (self.grooves.len() + self.segments.len()) as u32;
        for (i, w) in run.windows(2).enumerate() {
            self.segments.push(CurveSegment {
                curve,
                vertex: i as u32,
                twist: self.twist(&w[0].section, &w[1].section),
            });
        }
        let wide = |v: &CurveVertex| v.section.across != DVec2::ZERO;
        self.curves.push(CurvedGroove {
            caps: [
                caps[0] && wide(&run[0]),
                caps[1] && wide(&run[run.len() - 1]),
            ],
            sections: run.iter().map(|v| v.section).collect(),
            width: run.iter().map(|v| v.width).collect(),
            first_piece,
        });
    }

    /// How far the two triangles of each profile segment between sections `a` and `b` may lie
    /// from the ruled surface through them: half the twist `P00 + P11 - P01 - P10` across the
    /// plane of the quad's diagonals (a quarter is the bilinear patch's largest distance to
    /// first order; zero for a planar quad).
    fn twist(&self, a: &Section, b: &Section) -> f64 {
        self.profile
            .windows(2)
            .map(|p| {
                let (p00, p01, p10, p11) = (a.at(p[0]), a.at(p[1]), b.at(p[0]), b.at(p[1]));
                let normal = (p11 - p00).cross(p01 - p10).normalize_or_zero();
                0.5 * (p00 + p11 - p01 - p10).dot(normal).abs()
            })
            .fold(0.0, f64::max)
    }

    /// Number of grooves (straight and curved; a curve leaving and entering the face makes a
    /// groove of each run inside it).
    pub fn len(&self) -> usize {
        self.grooves.len() + self.curves.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The deepest point of any groove below the face (world units).
    pub fn max_depth(&self) -> f32 {
        let z_min = self.profile.iter().map(|p| p[1]).fold(0.0, f32::min).abs() as f64;
        let straight = self
            .grooves
            .iter()
            .flat_map(|g| g.hw.iter().map(|&h| 2.0 * h as f64));
        let curved = self
            .curves
            .iter()
            .flat_map(|c| c.sections.iter().map(|s| s.depth));
        (straight.chain(curved).fold(0.0, f64::max) * z_min) as f32
    }

    /// The face-frame coordinates `(x1, x2)` and height above the face of world point `p`, in
    /// `f64`: in `f32` the subtraction of the face's origin alone would cost 3e-4 of a
    /// setting-1 groove's width on a face of size 2.
    #[inline]
    fn local(&self, p: Vec3) -> (DVec2, f64) {
        let r = p.as_dvec3() - self.origin.as_dvec3();
        let (e1, e2, n) = (self.e1.as_dvec3(), self.e2.as_dvec3(), self.n.as_dvec3());
        (DVec2::new(r.dot(e1), r.dot(e2)), r.dot(n))
    }

    /// The world point of profile point `p` on cross-section `s`.
    fn point(&self, s: &Section, p: [f32; 2]) -> Vec3 {
        let l = s.at(p);
        (self.origin.as_dvec3() + self.world(l.truncate()) + l.z * self.n.as_dvec3()).as_vec3()
    }

    /// A face-frame direction in the world.
    fn world(&self, v: DVec2) -> DVec3 {
        v.x * self.e1.as_dvec3() + v.y * self.e2.as_dvec3()
    }

    /// Registers every piece in the grid cells its bounding rectangle along it reaches (a
    /// straight groove's along its axis, a curve segment's along its chord). The cells are
    /// about an eighth of the longest straight groove or a quarter of a curve segment's mean
    /// length, at most 1024 a side.
    fn build_grid(&mut self, a: &[Vec2; 2]) {
        let corners = [Vec2::ZERO, a[0], a[1], a[0] + a[1]];
        let lo = corners.iter().fold(Vec2::INFINITY, |m, &c| m.min(c));
        let hi = corners.iter().fold(Vec2::NEG_INFINITY, |m, &c| m.max(c));
        // Each piece's rectangle: a point, a unit direction, the range along it and the
        // half-width across it.
        let mut rects: Vec<(Vec2, Vec2, [f32; 2], f32)> = self
            .grooves
            .iter()
            .map(|g| {
                let w = g.hw.iter().fold(0.0f32, |m, &h| m.max(h));
                let (s0, s1) = g.ends();
                (g.centre, g.dir, [s0, s1], w)
            })
            .collect();
        for seg in &self.segments {
            let (s0, s1) = self.segment(seg);
            let dir = (s1.centre - s0.centre).normalize_or(s0.across.perp().normalize_or_zero());
            let rims = [s0, s1].map(|s| [s.centre - 0.5 * s.across, s.centre + 0.5 * s.across]);
            let along = rims
                .as_flattened()
                .iter()
                .map(|&p| (p - s0.centre).dot(dir));
            let across = rims
                .as_flattened()
                .iter()
                .map(|&p| (p - s0.centre).perp_dot(dir).abs());
            let range = along.fold([f64::INFINITY, f64::NEG_INFINITY], |m, x| {
                [m[0].min(x), m[1].max(x)]
            });
            // Widened by the margin: no cast to `f32` drops a point of the void.
            let slack = self.margin;
            rects.push((
                s0.centre.as_vec2(),
                dir.as_vec2(),
                [(range[0] - slack) as f32, (range[1] + slack) as f32],
                (across.fold(0.0, f64::max) + slack) as f32,
            ));
        }
        let longest = self
            .grooves
            .iter()
            .map(|g| g.ends().1 - g.ends().0)
            .fold(0.0, f32::max);
        let mean_segment = rects[self.grooves.len()..]
            .iter()
            .map(|r| r.2[1] - r.2[0])
            .sum::<f32>()
            / self.segments.len().max(1) as f32;
        let extent = (hi - lo).max_element().max(1e-20);
        let wanted = match (self.grooves.is_empty(), self.segments.is_empty()) {
            (false, false) => (longest / 8.0).min(mean_segment / 4.0),
            (false, true) => longest / 8.0,
            (true, false) => mean_segment / 4.0,
            (true, true) => extent,
        };
        let cell = wanted.max(extent / 1024.0);
        let dims = [
            ((hi.x - lo.x) / cell).ceil().max(1.0) as usize,
            ((hi.y - lo.y) / cell).ceil().max(1.0) as usize,
        ];
        let mut lists = vec![Vec::<u32>::new(); dims[0] * dims[1]];
        let r = cell * std::f32::consts::FRAC_1_SQRT_2;
        for (piece, &(c, dir, [s0, s1], w)) in rects.iter().enumerate() {
            if !(w > 0.0) {
                continue;
            }
            let perp = across(dir);
            let ends = [c + s0 * dir, c + s1 * dir];
            let (glo, ghi) = (
                ends[0].min(ends[1]) - Vec2::splat(w) - lo,
                ends[0].max(ends[1]) + Vec2::splat(w) - lo,
            );
            let (i0, j0) = (
                (glo.x / cell).floor().max(0.0) as usize,
                (glo.y / cell).floor().max(0.0) as usize,
            );
            let i1 = ((ghi.x / cell).floor().max(0.0) as usize).min(dims[0] - 1);
            let j1 = ((ghi.y / cell).floor().max(0.0) as usize).min(dims[1] - 1);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let q = lo + Vec2::new((i as f32 + 0.5) * cell, (j as f32 + 0.5) * cell);
                    let rel = q - c;
                    let s = rel.dot(dir);
                    if s >= s0 - r && s <= s1 + r && rel.dot(perp).abs() <= w + r {
                        lists[j * dims[0] + i].push(piece as u32);
                    }
                }
            }
        }
        self.cell_start = Vec::with_capacity(lists.len() + 1);
        self.cell_start.push(0);
        for l in &lists {
            self.cell_pieces.extend_from_slice(l);
            self.cell_start.push(self.cell_pieces.len() as u32);
        }
        (self.grid_lo, self.cell, self.dims) = (lo, cell, dims);
    }

    /// The cross-sections at the ends of a curve segment.
    #[inline]
    fn segment(&self, seg: &CurveSegment) -> (&Section, &Section) {
        let s = &self.curves[seg.curve as usize].sections;
        (&s[seg.vertex as usize], &s[seg.vertex as usize + 1])
    }

    /// Whether world point `p` lies inside the void of a piece other than `except` (by more
    /// than the margin, [`MARGIN_ROUND_OFFS`]); `on_face`: `p` lies on the face itself, and the
    /// test is whether it lies in a groove's opening.
    pub fn in_void(&self, p: Vec3, except: Option<u32>, on_face: bool) -> bool {
        let (x, h) = self.local(p);
        let c = (x - self.grid_lo.as_dvec2()) / self.cell as f64;
        if !(c.x >= 0.0 && c.y >= 0.0) {
            return false;
        }
        let (i, j) = (c.x as usize, c.y as usize);
        if i >= self.dims[0] || j >= self.dims[1] {
            return false;
        }
        let cell = j * self.dims[0] + i;
        let range = self.cell_start[cell] as usize..self.cell_start[cell + 1] as usize;
        self.cell_pieces[range]
            .iter()
            .any(|&g| Some(g) != except && self.in_piece(g, x, h, on_face))
    }

    /// Whether the face-frame point `(x, h)` lies inside piece `g`'s void (`on_face`: in its
    /// opening, `h` not read).
    fn in_piece(&self, g: u32, x: DVec2, h: f64, on_face: bool) -> bool {
        let g = g as usize;
        if g < self.grooves.len() {
            return self.in_groove(&self.grooves[g], x, h, on_face);
        }
        self.in_segment(&self.segments[g - self.grooves.len()], x, h, on_face)
    }

    /// Whether the face-frame point `(x, h)` lies inside straight groove `g`'s void.
    fn in_groove(&self, g: &Groove, x: DVec2, h: f64, on_face: bool) -> bool {
        let rel = x - g.centre.as_dvec2();
        let s = rel.dot(g.dir.as_dvec2()) as f32;
        let (s0, s1) = g.ends();
        if !(s > s0 && s < s1) {
            return false;
        }
        let k = g.s.partition_point(|&t| t <= s).clamp(1, g.s.len() - 1) - 1;
        let f = (s - g.s[k]) / (g.s[k + 1] - g.s[k]);
        let width = 2.0 * (g.hw[k] + f * (g.hw[k + 1] - g.hw[k])) as f64;
        let across = rel.dot(across(g.dir).as_dvec2()) / width;
        self.in_cross_section(across, h, width, width, self.margin, on_face)
    }

    /// Whether the face-frame point `(x, h)` lies inside curve segment `seg`: between its
    /// mitre lines, at `(t, x)` of [`bilinear_inverse`], inside the cross-section interpolated
    /// there (METHOD.md 9.6) farther than the margin and the twist from its walls, and farther
    /// than the margin from a cap.
    fn in_segment(&self, seg: &CurveSegment, x: DVec2, h: f64, on_face: bool) -> bool {
        let (g, i) = (&self.curves[seg.curve as usize], seg.vertex as usize);
        let (s0, s1) = (&g.sections[i], &g.sections[i + 1]);
        let Some((t, across)) = bilinear_inverse(s0, s1, x) else {
            return false;
        };
        let capped =
            |end: usize, s: &Section| g.caps[end] && distance_to_section(s, x) <= self.margin;
        if (i == 0 && capped(0, s0)) || (i + 2 == g.sections.len() && capped(1, s1)) {
            return false;
        }
        let width = g.width[i] + t * (g.width[i + 1] - g.width[i]);
        let depth = s0.depth + t * (s1.depth - s0.depth);
        let below = self.margin + seg.twist;
        self.in_cross_section(across, h, width, depth, below, on_face)
    }

    /// Whether a point at `across` (the profile's `x`, in widths) and height `h` lies in a
    /// cross-section of full width `width` and depth scale `depth` (world units: `z = h /
    /// depth`) farther than `below` (world units) from its walls (`on_face`: whether `across`
    /// lies in the opening less the margin).
    fn in_cross_section(
        &self,
        across: f64,
        h: f64,
        width: f64,
        depth: f64,
        below: f64,
        on_face: bool,
    ) -> bool {
        if !(width > 0.0 && depth > 0.0) {
            return false;
        }
        let across = across as f32;
        if on_face {
            return across.abs() < 0.5 - ((self.margin / width) as f32).min(MAX_MARGIN);
        }
        // Widths are at least the depth scale (depth ratios <= 1): the margin in `z` units
        // is at least `below` in world units along both axes.
        let margin = ((below / depth.min(width)) as f32).min(MAX_MARGIN);
        across.abs() < 0.5 && in_profile(&self.profile, across, (h / depth) as f32, margin)
    }

    /// The wall triangles of every groove (normals into the void, out of the object), and the
    /// void piece of each triangle (kept for [`Carving::wall_piece`]).
    pub fn walls(&mut self) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let mut w = Walls::default();
        for (gi, g) in self.grooves.iter().enumerate() {
            self.sweep(&g.sections(), |_| gi as u32, &mut w);
        }
        for g in &self.curves {
            let base = self.sweep(&g.sections, |k| g.first_piece + k as u32, &mut w);
            let last = g.sections.len() - 1;
            // Each end's section, its neighbour and its segment's piece.
            let ends = [
                (0, 1, g.first_piece),
                (last, last - 1, g.first_piece + last as u32 - 1),
            ];
            for (end, &(k, next, piece)) in ends.iter().enumerate() {
                if !g.caps[end] {
                    continue;
                }
                // Into the groove: along its centre line from the end.
                let inward = g.sections[next].centre - g.sections[k].centre;
                let inward = self.world(inward).as_vec3();
                let ring = base + (k * self.profile.len()) as u32;
                for tri in &self.cap {
                    w.push(tri.map(|v| ring + v), inward, piece);
                }
            }
        }
        self.tri_piece = w.pieces;
        (w.positions, w.indices)
    }

    /// Appends the walls swept through `sections`: each profile point's vertex on every
    /// section, two triangles a profile segment between consecutive sections (quad `k` of
    /// piece `piece(k)`), normals into the void. Returns the first vertex's index.
    fn sweep(&self, sections: &[Section], piece: impl Fn(usize) -> u32, w: &mut Walls) -> u32 {
        let np = self.profile.len();
        let base = w.positions.len() as u32;
        for s in sections {
            w.positions
                .extend(self.profile.iter().map(|&p| self.point(s, p)));
        }
        let v = |kk: usize, jj: usize| base + (kk * np + jj) as u32;
        for k in 0..sections.len() - 1 {
            let x_axis =
                self.world((sections[k].across + sections[k + 1].across).normalize_or_zero());
            for j in 0..np - 1 {
                let (p, q) = (self.profile[j], self.profile[j + 1]);
                // The profile normal (left of its direction: into the void) in 3D.
                let want = (-(q[1] - p[1]) as f64 * x_axis
                    + (q[0] - p[0]) as f64 * self.n.as_dvec3())
                .as_vec3();
                for tri in [
                    [v(k, j), v(k, j + 1), v(k + 1, j + 1)],
                    [v(k, j), v(k + 1, j + 1), v(k + 1, j)],
                ] {
                    w.push(tri, want, piece(k));
                }
            }
        }
        base
    }

    /// The void piece wall triangle `tri` belongs to.
    #[inline]
    pub fn wall_piece(&self, tri: u32) -> u32 {
        self.tri_piece[tri as usize]
    }
}

/// The profile's `x` axis for a groove along the unit `dir`, in the face's frame `(e1, e2, n)`:
/// `b = t x n` (METHOD.md section 1), the scratch frame's `x` that the model's lobes are read in,
/// so that an asymmetric profile is cut facing the way its lobes face.
fn across(dir: Vec2) -> Vec2 {
    Vec2::new(dir.y, -dir.x)
}

/// The profile's polygon (its points, closed by the opening from the last to the first) as
/// triangles of its points, by ear clipping (a valid profile is a simple polygon).
fn triangulate(profile: &[[f32; 2]]) -> Vec<[u32; 3]> {
    let p = |i: usize| DVec2::new(profile[i][0] as f64, profile[i][1] as f64);
    let twice_area: f64 = (0..profile.len())
        .map(|i| p(i).perp_dot(p((i + 1) % profile.len())))
        .sum();
    let orient = twice_area.signum();
    let mut left: Vec<usize> = (0..profile.len()).collect();
    let mut out = Vec::with_capacity(profile.len().saturating_sub(2));
    while left.len() > 3 {
        let m = left.len();
        let ear = (0..m).find(|&k| {
            let (a, b, c) = (left[(k + m - 1) % m], left[k], left[(k + 1) % m]);
            let turn = orient * (p(b) - p(a)).perp_dot(p(c) - p(b));
            // Convex (or straight) at `b`, and no other vertex in the triangle.
            turn >= 0.0
                && !left.iter().any(|&o| {
                    o != a
                        && o != b
                        && o != c
                        && [(a, b), (b, c), (c, a)]
                            .iter()
                            .all(|&(u, v)| orient * (p(v) - p(u)).perp_dot(p(o) - p(u)) >= 0.0)
                })
        });
        // Only a self-intersecting polygon has no ear: fan what is left.
        let k = ear.unwrap_or(1);
        out.push([left[(k + m - 1) % m], left[k], left[(k + 1) % m]].map(|i| i as u32));
        left.remove(k);
    }
    if left.len() == 3 {
        out.push([left[0], left[1], left[2]].map(|i| i as u32));
    }
    out
}

/// Whether `(x, z)` (width-1 units, `|x| < 1/2`) lies inside the profile polygon closed by its
/// opening, farther than `margin` from every profile segment; points on or just above the
/// opening count as just below it.
fn in_profile(profile: &[[f32; 2]], x: f32, z: f32, margin: f32) -> bool {
    if z > margin {
        return false;
    }
    let z = z.min(-margin);
    let mut inside = false;
    for w in profile.windows(2) {
        let ([x0, z0], [x1, z1]) = (w[0], w[1]);
        if (z0 > z) != (z1 > z) && x < x0 + (z - z0) / (z1 - z0) * (x1 - x0) {
            inside = !inside;
        }
        let (ex, ez) = (x1 - x0, z1 - z0);
        let t = (((x - x0) * ex + (z - z0) * ez) / (ex * ex + ez * ez)).clamp(0.0, 1.0);
        let (dx, dz) = (x - x0 - t * ex, z - z0 - t * ez);
        if dx * dx + dz * dz <= margin * margin {
            return false;
        }
    }
    // The opening (z = 0 between the profile's ends) crosses no horizontal ray below z = 0.
    inside
}

/// What a shape is to the carvings.
#[derive(Clone, Copy, Debug)]
pub enum CarveRole {
    /// A rectangle or box whose face `f` (triangles `2f`, `2f + 1`) is carving `first + f`.
    Faces { first: u32 },
    /// The wall triangles of carving `carving` ([`Carving::walls`]).
    Walls { carving: u32 },
}

/// The carvings of a scene and each shape's role: the hit filter of
/// [`crate::render::geometry::Geometry`].
#[derive(Clone, Debug, Default)]
pub struct Carve {
    pub carvings: Vec<Carving>,
    /// Per shape (indexed like the scene's shapes; shorter when the last shapes are not carved).
    pub roles: Vec<Option<CarveRole>>,
}

impl Carve {
    /// Whether shape `shape` takes part in the carving (its hits are filtered).
    #[inline]
    pub fn is_carved(&self, shape: u32) -> bool {
        matches!(self.roles.get(shape as usize), Some(Some(_)))
    }

    /// Whether the hit at `p` on triangle `prim` of shape `shape` is no surface: a face point
    /// inside a groove's opening, a wall point inside the void of another groove or of another
    /// segment of its curve.
    #[inline]
    pub fn rejects(&self, shape: u32, prim: u32, p: Vec3) -> bool {
        match self.roles.get(shape as usize) {
            Some(Some(CarveRole::Faces { first })) => {
                self.carvings[(first + prim / 2) as usize].in_void(p, None, true)
            }
            Some(Some(CarveRole::Walls { carving })) => {
                let c = &self.carvings[*carving as usize];
                c.in_void(p, Some(c.wall_piece(prim)), false)
            }
            _ => false,
        }
    }

    /// Number of grooves over all carvings.
    pub fn grooves(&self) -> usize {
        self.carvings.iter().map(Carving::len).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::curves::stroke::{arc_points, StrokeStyle};
    use crate::curves::CurveSet;
    use crate::layers::LayerParams;
    use crate::math::Ray;
    use crate::precompute::profile::Profile;
    use crate::render::geometry::{Geometry, Shape, ShapeGeometry, Transform, TriangleMesh};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;
    use std::f64::consts::TAU;

    /// The face `[0, 1]^2` of the plane `z = 0`, normal `+z`, uv = `(x, y)`.
    fn unit_face() -> Face {
        Face {
            origin: Vec3::ZERO,
            dpdu: Vec3::X,
            dpdv: Vec3::Y,
            n: Vec3::Z,
        }
    }

    fn scratch(centre: [f64; 2], angle: f64, half_length: f64, half_width: f64) -> Scratch {
        Scratch {
            layer: 0,
            centre: DVec2::from(centre),
            direction: DVec2::new(angle.cos(), angle.sin()),
            half_length,
            half_width,
        }
    }

    /// The unit face (shape 0) carved by `scratches` with a 90-degree V (depth = half-width),
    /// walls as shape 1.
    fn carved(scratches: &[Scratch]) -> Geometry {
        let profile = Profile::parse("v:angle=90").unwrap();
        let c = Carving::new(
            &unit_face(),
            scratches,
            &[],
            DVec2::ONE,
            &profile.points,
            DEFAULT_STATIONS,
        );
        geometry(c)
    }

    /// The unit face (shape 0) carved by `carving`, walls as shape 1.
    fn geometry(mut carving: Carving) -> Geometry {
        let (positions, indices) = carving.walls();
        let to_unit = Transform::translate(Vec3::new(0.5, 0.5, 0.0))
            .unwrap()
            .compose(&Transform::scale(Vec3::new(0.5, 0.5, 1.0)).unwrap());
        let face = TriangleMesh::rectangle().transformed(&to_unit).unwrap();
        let walls = TriangleMesh::new(positions, indices, None, None, None).unwrap();
        let shapes = [face, walls].map(|m| Shape {
            geometry: ShapeGeometry::Mesh(m),
            material: 0,
            area_light: None,
        });
        Geometry::with_carve(
            shapes.to_vec(),
            Carve {
                carvings: vec![carving],
                roles: vec![
                    Some(CarveRole::Faces { first: 0 }),
                    Some(CarveRole::Walls { carving: 0 }),
                ],
            },
        )
    }

    fn down(x: f32, y: f32) -> Ray {
        Ray::new(Vec3::new(x, y, 1.0), -Vec3::Z)
    }

    #[test]
    fn rays_hit_the_groove_bottom_the_flat_face_and_skip_walls_in_other_voids() {
        // Groove A along x (half-width 0.1), groove B along y (half-width 0.05), long enough
        // that their taper is negligible where they cross at (0.5, 0.5).
        let g = carved(&[
            scratch([0.5, 0.5], 0.0, 2.0, 0.1),
            scratch([0.5, 0.5], std::f64::consts::FRAC_PI_2, 2.0, 0.05),
        ]);
        // Down A's axis away from B: the V's bottom, one half-width deep.
        let h = g.intersect(&down(0.3, 0.5)).expect("groove bottom");
        assert_eq!(h.shape, 1);
        let w = 0.1 * (1.0 - (0.2f32 / 2.0).powi(2)).sqrt();
        assert!(
            (h.p.z + w).abs() < 1e-3 * w,
            "bottom at {} not {}",
            h.p.z,
            -w
        );
        // On the flat face, outside both grooves.
        let h = g.intersect(&down(0.3, 0.8)).expect("flat face");
        assert_eq!((h.shape, h.p.z), (0, 0.0));
        // Inside both openings: B's wall at (0.53, 0.51) lies 0.02 deep, inside A's void
        // (0.09 deep there), so the ray goes on to A's wall.
        let h = g.intersect(&down(0.53, 0.51)).expect("A's wall");
        assert!((h.p.z + 0.09).abs() < 1e-3, "hit at depth {}", h.p.z);
        // B alone (outside A): B's wall 0.02 deep.
        let h = g.intersect(&down(0.53, 0.7)).expect("B's wall");
        assert!((h.p.z + 0.02).abs() < 1e-3, "hit at depth {}", h.p.z);
        // Shadow rays see the same surfaces.
        let shadow = |x, y, t_max| {
            let mut r = down(x, y);
            r.t_max = t_max;
            g.occluded(&r)
        };
        assert!(!shadow(0.53, 0.51, 1.05));
        assert!(shadow(0.53, 0.51, 1.1));
    }

    #[test]
    fn grooves_cover_the_face_as_the_layers_do() {
        let params = LayerParams {
            length: 0.3,
            width: 0.02,
            threshold: 0.1,
            layers: 3,
        };
        let layers = LayerSet::new(params, 7).unwrap();
        let profile = Profile::parse("v:angle=90").unwrap();
        let carving = |stations| {
            let scratches = Face::scratches(&layers);
            Carving::new(
                &unit_face(),
                &scratches,
                &[],
                DVec2::ONE,
                &profile.points,
                stations,
            )
        };
        let (carving, fine) = (carving(DEFAULT_STATIONS), carving(512));
        let mut rng = Pcg64::seed_from_u64(3);
        let n = 200_000;
        let (mut grooves, mut scratched, mut differ, mut differ_fine) = (0, 0, 0, 0);
        for _ in 0..n {
            let uv = crate::math::Vec2::new(rng.random(), rng.random());
            let g = carving.in_void(uv.extend(0.0), None, true);
            let s = layers.scratched_mask(uv) != 0;
            grooves += g as usize;
            scratched += s as usize;
            differ += (g != s) as usize;
            differ_fine += (fine.in_void(uv.extend(0.0), None, true) != s) as usize;
        }
        let (fg, fs) = (grooves as f64 / n as f64, scratched as f64 / n as f64);
        // The layers' own expectation for K independent layers.
        let c = layers.expected_coverage();
        let expected = 1.0 - (1.0 - c).powi(3);
        let sigma = (expected * (1.0 - expected) / n as f64).sqrt();
        assert!(
            (fs - expected).abs() < 4.0 * sigma + 0.01 * expected,
            "{fs} vs {expected}"
        );
        // The grooves' openings are polygons inscribed in the ellipses (30 sides: 0.7 % less
        // area); the same points agree but for that sliver.
        assert!(
            (fg - fs).abs() < 4.0 * sigma + 0.012 * fs,
            "grooves {fg}, layers {fs}"
        );
        assert!(
            (differ as f64) < 0.015 * scratched as f64,
            "{differ} of {scratched} differ"
        );
        // With 512 stations (polygons 0.002 % short) what remains is the face's edges, where a
        // groove ends with its centre line, and the margin at the seams, 2.4e-4 of the 4e-3
        // wide grooves' width (0.17 % differ; a margin of 1e-3 of the width, 2.4 times that
        // kept of the face along a 90-degree V's rims, made it 0.7 %).
        assert!(
            (differ_fine as f64) < 0.003 * scratched as f64,
            "{differ_fine} of {scratched} differ"
        );
    }

    #[test]
    fn openings_fall_short_of_the_ellipse_by_the_closed_form() {
        // The polygon through the stations, evenly spaced in the ellipse's angle, is the affine
        // image of a regular polygon of 2 (stations - 1) sides inscribed in a circle.
        let profile = Profile::parse("v:angle=90").unwrap();
        let (l, w) = (0.2, 0.01);
        let sc = scratch([0.5, 0.5], 0.3, l, w);
        for stations in [3, 16, 64, 1024] {
            let c = Carving::new(
                &unit_face(),
                &[sc],
                &[],
                DVec2::ONE,
                &profile.points,
                stations,
            );
            let g = &c.grooves[0];
            assert_eq!(g.s.len(), stations);
            let area: f64 = (1..stations)
                .map(|k| (g.hw[k - 1] + g.hw[k]) as f64 * (g.s[k] - g.s[k - 1]) as f64)
                .sum();
            let x = std::f64::consts::PI / (stations - 1) as f64;
            let want = std::f64::consts::PI * l * w * x.sin() / x;
            assert!(
                (area / want - 1.0).abs() < 1e-4,
                "{stations} stations: {area} against {want}"
            );
        }
    }

    #[test]
    fn no_ray_leaks_through_the_seams() {
        // Narrow crossing grooves (setting-1 widths, 4e-4 and 6e-4) and rays from above aimed at
        // their rims, steep and grazing: every ray meets the face or a wall. A margin too small
        // for the hit positions' round-off drops both the face and the wall at a seam.
        let (wa, wb) = (2e-4, 3e-4);
        let g = carved(&[
            scratch([0.5, 0.5], 0.3, 0.4, wa),
            scratch([0.5, 0.5], 1.9, 0.4, wb),
        ]);
        let mut rng = Pcg64::seed_from_u64(11);
        let (dir_a, dir_b) = (
            DVec2::new(0.3f64.cos(), 0.3f64.sin()),
            DVec2::new(1.9f64.cos(), 1.9f64.sin()),
        );
        let mut misses = 0;
        for i in 0..200_000 {
            // A point on a rim of either groove, within 0.3 of its centre along it.
            let (d, w) = if i % 2 == 0 { (dir_a, wa) } else { (dir_b, wb) };
            let t: f64 = rng.random_range(-0.3..0.3);
            let side = if rng.random::<bool>() { 1.0 } else { -1.0 };
            let width_here = w * (1.0 - (t / 0.4f64).powi(2)).sqrt();
            let jitter: f64 = rng.random_range(-1e-6..1e-6);
            let at = DVec2::new(0.5, 0.5) + t * d + (side * width_here + jitter) * d.perp();
            let target = Vec3::new(at.x as f32, at.y as f32, 0.0);
            let theta: f32 = rng.random_range(0.0..1.5);
            let phi: f32 = rng.random_range(0.0..std::f32::consts::TAU);
            let dir = -Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            let ray = Ray::new(target - dir, dir);
            misses += g.intersect(&ray).is_none() as usize;
        }
        assert_eq!(misses, 0, "rays through the seams");
    }

    /// A sawtooth: asymmetric, its deepest point right of the centre (on `b = t x n`).
    const SAWTOOTH: [[f64; 2]; 3] = [[-0.5, 0.0], [0.3, -0.4], [0.5, 0.0]];

    /// The unit face carved by `curves` (uv) with `profile`.
    fn carve_curves(curves: &[Polyline], profile: &[[f64; 2]]) -> Carving {
        Carving::new(
            &unit_face(),
            &[],
            curves,
            DVec2::ONE,
            profile,
            DEFAULT_STATIONS,
        )
    }

    /// A circle about `centre` of `radius` and half-width `hw`, flattened as patterns are.
    fn circle(centre: [f64; 2], radius: f64, hw: f64) -> Polyline {
        let tol = crate::curves::stroke::FLATTEN_TOLERANCE * 2.0 * hw;
        let points = arc_points(DVec2::from(centre), radius, 0.3, 0.3 + TAU, tol);
        Polyline::uniform(points, hw)
    }

    /// An open arc tapered at both ends and worn (METHOD.md 9.2).
    fn worn_arc() -> Polyline {
        let style = StrokeStyle {
            taper: 0.05,
            wear: 0.5,
            wear_length: 0.05,
            seed: 4,
            ..StrokeStyle::default()
        };
        let points = arc_points(DVec2::new(0.45, 0.4), 0.25, -0.5, 2.0, 4e-4);
        let mut lines = style.apply(&points, 0.01, 0);
        assert_eq!(lines.len(), 1);
        lines.pop().unwrap()
    }

    /// A bent open stroke of constant width: its ends are capped.
    fn bent() -> Polyline {
        let points = [[0.2, 0.8], [0.5, 0.9], [0.7, 0.75]]
            .map(DVec2::from)
            .to_vec();
        Polyline::uniform(points, 0.008)
    }

    #[test]
    fn a_straight_polyline_carves_the_straight_groove() {
        // A scratch far longer than the face (its width constant to 3e-9 across it) and the
        // polyline through its three stations, both leaving the face at its edges: the same
        // opening, the same walls (the asymmetric profile facing the same way), the same void.
        let (angle, hw) = (0.3f64, 0.01);
        let sc = scratch([0.5, 0.5], angle, 1e4, hw);
        let straight = Carving::new(&unit_face(), &[sc], &[], DVec2::ONE, &SAWTOOTH, 3);
        let g = &straight.grooves[0];
        let d = DVec2::new(angle.cos(), angle.sin());
        let mid = (g.centre + g.s[1] * g.dir).as_dvec2();
        let c = DVec2::splat(0.5);
        let line = Polyline::uniform(vec![c - 2.0 * d, mid, c + 2.0 * d], hw);
        let curved = carve_curves(&[line], &SAWTOOTH);
        assert_eq!(curved.len(), 1);
        assert_eq!(curved.curves[0].sections.len(), 3);
        assert_eq!(curved.curves[0].caps, [false, false]);
        let ((pa, ia), (pb, ib)) = (straight.clone().walls(), curved.clone().walls());
        assert_eq!(ia.len(), 8);
        assert_eq!(ia, ib, "the same triangles, wound the same way");
        let worst = pa
            .iter()
            .zip(&pb)
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f32::max);
        assert!(worst < 1e-6, "vertices {worst} apart");
        let mut rng = Pcg64::seed_from_u64(5);
        let (n, mut inside, mut differ) = (200_000, 0, 0);
        for _ in 0..n {
            let along: f64 = rng.random_range(-0.4..0.4);
            let off: f64 = rng.random_range(-1.2..1.2) * hw;
            let q = c + along * d + off * d.perp();
            let on_face = rng.random::<bool>();
            let h = if on_face {
                0.0
            } else {
                rng.random_range(-0.01..0.001)
            };
            let p = Vec3::new(q.x as f32, q.y as f32, h as f32);
            let a = straight.in_void(p, None, on_face);
            inside += a as usize;
            differ += (a != curved.in_void(p, None, on_face)) as usize;
        }
        assert!(inside > n / 4, "{inside} of {n} inside");
        assert!(differ <= 2, "{differ} of {n} differ");
    }

    /// The outline's edges: the SV-BRDF's thick segments ([`CurveSet::new`]).
    fn outline(lines: &[Polyline]) -> Vec<[DVec2; 2]> {
        let mut edges = Vec::new();
        for line in lines {
            let line = line.clone().deduplicated().unwrap();
            let (p, w, m) = (&line.points, &line.half_widths, line.mitres());
            for i in 0..p.len() - 1 {
                let j = i + 1;
                let q = [
                    p[i] - m[i] * w[i],
                    p[j] - m[j] * w[j],
                    p[j] + m[j] * w[j],
                    p[i] + m[i] * w[i],
                ];
                edges.extend((0..4).map(|k| [q[k], q[(k + 1) % 4]]));
            }
        }
        edges
    }

    fn distance_to_edges(edges: &[[DVec2; 2]], p: DVec2) -> f64 {
        edges
            .iter()
            .map(|&[a, b]| {
                let e = b - a;
                let t = ((p - a).dot(e) / e.length_squared().max(1e-300)).clamp(0.0, 1.0);
                (p - a - t * e).length()
            })
            .fold(f64::INFINITY, f64::min)
    }

    #[test]
    fn a_carved_circle_cuts_the_sv_brdfs_outline() {
        // A circle, a tapered worn arc and a bent capped stroke, on a dense grid: the opening
        // (on the face) agrees with the SV-BRDF's point test but within the margin of the
        // outline; just below the face the void does too, but where a segment's twist widens
        // the margin (the worn arc's turns).
        let v = Profile::parse("v:angle=90").unwrap().points;
        let n = 1000;
        let compare = |lines: &[Polyline], h: f32| {
            let set = CurveSet::new(lines, DVec2::ONE).unwrap();
            let carving = carve_curves(lines, &v);
            let edges = outline(lines);
            let (mut scratched, mut differ, mut far) = (0, 0, 0.0f64);
            for j in 0..n {
                for i in 0..n {
                    let uv = DVec2::new((i as f64 + 0.5) / n as f64, (j as f64 + 0.5) / n as f64);
                    let p = Vec3::new(uv.x as f32, uv.y as f32, h);
                    let cut = carving.in_void(p, None, h == 0.0);
                    let modelled = !set.at_point(p.truncate().as_dvec2()).is_empty();
                    scratched += modelled as usize;
                    if cut != modelled {
                        differ += 1;
                        far = far.max(distance_to_edges(&edges, p.truncate().as_dvec2()));
                    }
                }
            }
            eprintln!(
                "{} curves, h = {h}: {differ} of {} points differ ({scratched} scratched), at most {far:.2e} from the outline",
                lines.len(),
                n * n
            );
            assert!(scratched > 15_000, "{scratched}");
            (differ as f64 / scratched as f64, far)
        };
        let all = [circle([0.5, 0.5], 0.3, 0.01), bent(), worn_arc()];
        let (_, far) = compare(&all, 0.0);
        assert!(far <= 2e-6, "a point {far} from the outline differs");
        // Below the face, 1e-6 deep: a 90-degree V narrows by as much on each side.
        let (_, far) = compare(&all[..2], -1e-6);
        assert!(far <= 4e-6, "a point {far} from the outline differs");
        let (fraction, _) = compare(&all, -1e-6);
        assert!(fraction < 0.005, "{fraction}");
    }

    #[test]
    fn wall_normals_point_into_the_void() {
        // Every wall triangle, straight or curved (caps included), each groove alone: a step
        // along its normal from its centroid (a tenth of its shortest edge) enters the void, a
        // step against it does not.
        let v = Profile::parse("v:angle=90").unwrap().points;
        let round = Profile::parse("round:depth=0.3").unwrap().points;
        for profile in [&v[..], &round, &SAWTOOTH] {
            let straight = Carving::new(
                &unit_face(),
                &[scratch([0.5, 0.2], 0.4, 0.3, 0.01)],
                &[],
                DVec2::ONE,
                profile,
                DEFAULT_STATIONS,
            );
            let curved = [circle([0.5, 0.5], 0.3, 0.01), worn_arc(), bent()]
                .map(|l| carve_curves(&[l], profile));
            assert_eq!(
                curved[2].curves[0].caps,
                [true, true],
                "a stroke's ends are capped"
            );
            for mut c in [straight].into_iter().chain(curved) {
                let (positions, indices) = c.walls();
                let (mut wrong, mut small) = (0, 0);
                for (k, tri) in indices.iter().enumerate() {
                    let [a, b, p] = tri.map(|i| positions[i as usize]);
                    let nrm = (b - a).cross(p - a).normalize();
                    let centre = (a + b + p) / 3.0;
                    let edges = [b - a, p - b, a - p].map(Vec3::length);
                    let eps = 0.1 * edges.into_iter().fold(f32::MAX, f32::min);
                    // A sliver at a straight groove's pointed tip, or a triangle of a twisted
                    // segment (a taper's turns), smaller than the margin and the twist.
                    let piece = c.wall_piece(k as u32) as usize;
                    let twist = match piece.checked_sub(c.grooves.len()) {
                        Some(seg) => c.segments[seg].twist,
                        None => 0.0,
                    };
                    if (eps as f64) < 2.0 * (c.margin + twist) {
                        small += 1;
                        continue;
                    }
                    if !c.in_void(centre + eps * nrm, None, false)
                        || c.in_void(centre - eps * nrm, None, false)
                    {
                        wrong += 1;
                    }
                }
                assert_eq!(wrong, 0, "{wrong} of {} triangles face away", indices.len());
                assert!(small * 20 < indices.len(), "{small} of {}", indices.len());
            }
        }
    }

    #[test]
    fn walls_twist_only_where_width_or_depth_change_along_a_turn() {
        // The largest twist of a segment's wall quads, over the groove's width there: none on
        // a circle or a stroke of constant width; where a tapered and worn arc turns (a
        // taper's first stations, where the width doubles from one to the next: 2.4 % of the
        // width unsplit), under the tolerance once split (over the pieces' own widths, at
        // most twice that where the width doubles along a segment).
        let v = Profile::parse("v:angle=90").unwrap().points;
        let twist = |line: Polyline| {
            let c = carve_curves(&[line], &v);
            c.segments
                .iter()
                .map(|seg| {
                    let g = &c.curves[seg.curve as usize];
                    let i = seg.vertex as usize;
                    seg.twist / g.width[i].max(g.width[i + 1])
                })
                .fold(0.0, f64::max)
        };
        let (circle, bent, worn) = (
            twist(circle([0.5, 0.5], 0.3, 0.01)),
            twist(bent()),
            twist(worn_arc()),
        );
        eprintln!("twist over width: circle {circle:.1e}, bent {bent:.1e}, worn arc {worn:.1e}");
        assert!(circle < 1e-6 && bent < 1e-6, "{circle}, {bent}");
        assert!(worn <= 2.0 * TWIST_TOLERANCE, "{worn}");
    }

    #[test]
    fn rays_meet_curved_grooves_and_never_leak_where_they_cross() {
        // Two crossing circles and a straight groove across them (setting-1 widths, 4e-4 to
        // 6e-4), rays from above aimed at their rims, steep and grazing: every ray meets the
        // face or a wall.
        let lines = [
            circle([0.5, 0.5], 0.3, 2e-4),
            circle([0.6, 0.45], 0.2, 3e-4),
        ];
        let profile = Profile::parse("v:angle=90").unwrap();
        let carving = Carving::new(
            &unit_face(),
            &[scratch([0.5, 0.5], 0.3, 0.4, 2e-4)],
            &lines,
            DVec2::ONE,
            &profile.points,
            DEFAULT_STATIONS,
        );
        let rims: Vec<(Section, Section)> = carving
            .segments
            .iter()
            .map(|seg| {
                let (a, b) = carving.segment(seg);
                (*a, *b)
            })
            .collect();
        let g = geometry(carving);
        // Down the first circle's first vertex: the V's bottom, one half-width deep.
        let h = g
            .intersect(&down(0.5 + 0.3 * 0.3f32.cos(), 0.5 + 0.3 * 0.3f32.sin()))
            .expect("groove bottom");
        assert_eq!(h.shape, 1);
        assert!((h.p.z + 2e-4).abs() < 1e-6, "bottom at {}", h.p.z);
        let h = g.intersect(&down(0.5, 0.3)).expect("flat face");
        assert_eq!((h.shape, h.p.z), (0, 0.0));
        let mut rng = Pcg64::seed_from_u64(12);
        let mut misses = 0;
        for _ in 0..200_000 {
            let (a, b) = rims[rng.random_range(0..rims.len())];
            let s = a.lerp(&b, rng.random());
            let side = if rng.random::<bool>() { 0.5 } else { -0.5 };
            let jitter = DVec2::new(rng.random_range(-1e-6..1e-6), rng.random_range(-1e-6..1e-6));
            let at = s.centre + side * s.across + jitter;
            let target = Vec3::new(at.x as f32, at.y as f32, 0.0);
            let theta: f32 = rng.random_range(0.0..1.5);
            let phi: f32 = rng.random_range(0.0..std::f32::consts::TAU);
            let dir = -Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            misses += g.intersect(&Ray::new(target - dir, dir)).is_none() as usize;
        }
        assert_eq!(misses, 0, "rays through the seams");
    }

    #[test]
    fn curves_are_cut_at_the_faces_edge_and_keep_their_outline() {
        // A circle half off the face: one open groove (no caps: open at the face's edge, as a
        // straight groove), its opening the SV-BRDF's inside the face.
        let lines = [circle([0.9, 0.5], 0.3, 0.01)];
        let c = carve_curves(&lines, &SAWTOOTH);
        assert_eq!(c.len(), 1);
        assert_eq!(c.curves[0].caps, [false, false]);
        let ends = [
            &c.curves[0].sections[0],
            c.curves[0].sections.last().unwrap(),
        ];
        for s in ends {
            assert!((s.centre.x - 1.0).abs() < 1e-12, "cut at {:?}", s.centre);
        }
        let set = CurveSet::new(&lines, DVec2::ONE).unwrap();
        let edges = outline(&lines);
        let mut rng = Pcg64::seed_from_u64(2);
        for _ in 0..100_000 {
            let uv = DVec2::new(rng.random_range(0.55..1.0), rng.random_range(0.15..0.85));
            let p = Vec3::new(uv.x as f32, uv.y as f32, 0.0);
            let modelled = !set.at_point(p.truncate().as_dvec2()).is_empty();
            if c.in_void(p, None, true) != modelled {
                let d = distance_to_edges(&edges, p.truncate().as_dvec2());
                assert!(d < 2e-6 || p.x > 0.99, "{p} differs, {d} from the outline");
            }
        }
    }
}
