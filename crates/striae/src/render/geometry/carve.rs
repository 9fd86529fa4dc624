//! Explicit scratch geometry (METHOD.md 8.3): the scratches of a layer set built as real
//! grooves carved into the planar faces of a shape.
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

use crate::layers::{LayerSet, Scratch};
use crate::math::{Vec2, Vec3};
use glam::DVec2;

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

/// A planar face: `P(u, v) = origin + u dpdu + v dpdv`, outward unit normal `n`.
#[derive(Clone, Copy, Debug)]
pub struct Face {
    pub origin: Vec3,
    pub dpdu: Vec3,
    pub dpdv: Vec3,
    pub n: Vec3,
}

/// One groove in the face's orthonormal frame `(e1, e2)` (world units).
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
}

/// The grooves of one face, their walls and a grid to find the grooves near a point.
#[derive(Clone, Debug)]
pub struct Carving {
    origin: Vec3,
    e1: Vec3,
    e2: Vec3,
    n: Vec3,
    /// The profile's points, `x` in `[-1/2, 1/2]`, `z <= 0`, width 1.
    profile: Vec<[f32; 2]>,
    grooves: Vec<Groove>,
    /// Uniform grid over the face: lower corner, cell size, cells per row and column, and per
    /// cell the grooves that reach it (compressed rows).
    grid_lo: Vec2,
    cell: f32,
    dims: [usize; 2],
    cell_start: Vec<u32>,
    cell_grooves: Vec<u32>,
    /// The groove of each wall triangle of [`Carving::walls`].
    tri_groove: Vec<u32>,
    /// The void test's margin in world units ([`MARGIN_ROUND_OFFS`]).
    margin: f64,
}

/// Wall triangles per groove of a profile of `segments` segments with `stations` stations
/// (upper bound: the degenerate triangles at the pointed ends are dropped).
pub fn triangles_per_groove(segments: usize, stations: usize) -> usize {
    2 * segments * (stations - 1)
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

    /// The largest groove depth (world units) `layers` carve into this face with a profile
    /// whose deepest point is `z_min` (width 1): `2 w_0 |z_min|` at the widest scratch.
    pub fn max_depth(&self, scratches: &[Scratch], z_min: f32) -> f32 {
        let a = self.affine();
        scratches
            .iter()
            .map(|s| 2.0 * map_scratch(&a, s).1 * z_min.abs())
            .fold(0.0, f32::max)
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

/// The image of a texture-space scratch on the face: `(unit direction, half-width w_0, length
/// scale |A d|)` of the thin-ellipse approximation (module docs).
fn map_scratch(a: &[Vec2; 2], s: &Scratch) -> (Vec2, f32, f32) {
    let d = a[0] * s.direction.x as f32 + a[1] * s.direction.y as f32;
    let det = (a[0].x * a[1].y - a[0].y * a[1].x).abs();
    let len = d.length();
    let (_, half_width) = s.mapped_half_axes(len as f64, det as f64);
    (d / len, half_width as f32, len)
}

/// The interval of `t` in `[-a, a]` where `p + t d` lies in `[0, 1]^2`, if any.
fn clip_to_unit_square(p: DVec2, d: DVec2, a: f64) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (-a, a);
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

impl Carving {
    /// The grooves of `scratches` (texture space, [`Face::scratches`]) carved into `face` with
    /// `profile` (points of width 1, [`crate::precompute::profile::Profile::points`]), `stations` stations
    /// each (within [`STATIONS_RANGE`]).
    pub fn new(
        face: &Face,
        scratches: &[Scratch],
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
        let mut c = Carving {
            origin: face.origin,
            e1,
            e2,
            n: face.n,
            profile: profile.iter().map(|p| [p[0] as f32, p[1] as f32]).collect(),
            grooves,
            grid_lo: Vec2::ZERO,
            cell: 1.0,
            dims: [1, 1],
            cell_start: Vec::new(),
            cell_grooves: Vec::new(),
            tri_groove: Vec::new(),
            margin: MARGIN_ROUND_OFFS * f32::EPSILON as f64 / 2.0 * face.extent(),
        };
        c.build_grid(&a);
        c
    }

    /// One groove: the scratch's centre line clipped to the face, `stations` stations on it,
    /// evenly spaced in the ellipse's angle (so closer together toward its tips).
    fn groove(a: &[Vec2; 2], s: &Scratch, stations: usize) -> Option<Groove> {
        let (dir, w0, scale) = map_scratch(a, s);
        let l = s.half_length;
        let (lo, hi) = clip_to_unit_square(s.centre, s.direction, l)?;
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

    /// Number of grooves.
    pub fn len(&self) -> usize {
        self.grooves.len()
    }

    pub fn is_empty(&self) -> bool {
        self.grooves.is_empty()
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

    /// Registers every groove in the grid cells its bounding rectangle reaches.
    fn build_grid(&mut self, a: &[Vec2; 2]) {
        let corners = [Vec2::ZERO, a[0], a[1], a[0] + a[1]];
        let lo = corners.iter().fold(Vec2::INFINITY, |m, &c| m.min(c));
        let hi = corners.iter().fold(Vec2::NEG_INFINITY, |m, &c| m.max(c));
        let longest = self
            .grooves
            .iter()
            .map(|g| g.ends().1 - g.ends().0)
            .fold(0.0, f32::max);
        let extent = (hi - lo).max_element().max(1e-20);
        let cell = (longest / 8.0).max(extent / 1024.0);
        let dims = [
            ((hi.x - lo.x) / cell).ceil().max(1.0) as usize,
            ((hi.y - lo.y) / cell).ceil().max(1.0) as usize,
        ];
        let mut lists = vec![Vec::<u32>::new(); dims[0] * dims[1]];
        let r = cell * std::f32::consts::FRAC_1_SQRT_2;
        for (gi, g) in self.grooves.iter().enumerate() {
            let (s0, s1) = g.ends();
            let w = g.hw.iter().fold(0.0f32, |m, &h| m.max(h));
            let perp = across(g.dir);
            let ends = [g.centre + s0 * g.dir, g.centre + s1 * g.dir];
            let glo = ends[0].min(ends[1]) - Vec2::splat(w) - lo;
            let ghi = ends[0].max(ends[1]) + Vec2::splat(w) - lo;
            let (i0, j0) = (
                (glo.x / cell).floor().max(0.0) as usize,
                (glo.y / cell).floor().max(0.0) as usize,
            );
            let i1 = ((ghi.x / cell).floor().max(0.0) as usize).min(dims[0] - 1);
            let j1 = ((ghi.y / cell).floor().max(0.0) as usize).min(dims[1] - 1);
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let q = lo + Vec2::new((i as f32 + 0.5) * cell, (j as f32 + 0.5) * cell);
                    let rel = q - g.centre;
                    let s = rel.dot(g.dir);
                    if s >= s0 - r && s <= s1 + r && rel.dot(perp).abs() <= w + r {
                        lists[j * dims[0] + i].push(gi as u32);
                    }
                }
            }
        }
        self.cell_start = Vec::with_capacity(lists.len() + 1);
        self.cell_start.push(0);
        for l in &lists {
            self.cell_grooves.extend_from_slice(l);
            self.cell_start.push(self.cell_grooves.len() as u32);
        }
        (self.grid_lo, self.cell, self.dims) = (lo, cell, dims);
    }

    /// Whether world point `p` lies inside the void of a groove other than `except` (by more
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
        self.cell_grooves[range]
            .iter()
            .any(|&g| Some(g) != except && self.in_groove(&self.grooves[g as usize], x, h, on_face))
    }

    /// Whether the face-frame point `(x, h)` lies inside groove `g`'s void (`on_face`: in its
    /// opening, `h` not read).
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
        if !(width > 0.0) {
            return false;
        }
        let across = (rel.dot(across(g.dir).as_dvec2()) / width) as f32;
        let margin = ((self.margin / width) as f32).min(MAX_MARGIN);
        if on_face {
            return across.abs() < 0.5 - margin;
        }
        let z = (h / width) as f32;
        across.abs() < 0.5 && in_profile(&self.profile, across, z, margin)
    }

    /// The wall triangles of every groove (normals into the void, out of the object), and the
    /// groove of each triangle (kept for [`Carving::wall_groove`]).
    pub fn walls(&mut self) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let np = self.profile.len();
        let stations: usize = self.grooves.iter().map(|g| g.s.len()).sum();
        let mut positions = Vec::with_capacity(stations * np);
        let mut indices = Vec::new();
        self.tri_groove.clear();
        for (gi, g) in self.grooves.iter().enumerate() {
            let base = positions.len() as u32;
            let perp = across(g.dir);
            for k in 0..g.s.len() {
                let width = 2.0 * g.hw[k];
                for p in &self.profile {
                    let x = g.centre + g.s[k] * g.dir + p[0] * width * perp;
                    positions
                        .push(self.origin + x.x * self.e1 + x.y * self.e2 + p[1] * width * self.n);
                }
            }
            for j in 0..np - 1 {
                let e = [
                    self.profile[j + 1][0] - self.profile[j][0],
                    self.profile[j + 1][1] - self.profile[j][1],
                ];
                // The profile normal (left of its direction: into the void) in 3D.
                let want = -e[1] * perp.x * self.e1 - e[1] * perp.y * self.e2 + e[0] * self.n;
                for k in 0..g.s.len() - 1 {
                    let v = |kk: usize, jj: usize| base + (kk * np + jj) as u32;
                    for tri in [
                        [v(k, j), v(k, j + 1), v(k + 1, j + 1)],
                        [v(k, j), v(k + 1, j + 1), v(k + 1, j)],
                    ] {
                        let [a, b, c] = tri.map(|i| positions[i as usize]);
                        let nrm: Vec3 = (b - a).cross(c - a);
                        if !(nrm.length_squared() > 0.0) {
                            continue;
                        }
                        indices.push(if nrm.dot(want) >= 0.0 {
                            tri
                        } else {
                            [tri[0], tri[2], tri[1]]
                        });
                        self.tri_groove.push(gi as u32);
                    }
                }
            }
        }
        (positions, indices)
    }

    /// The groove wall triangle `tri` belongs to.
    #[inline]
    pub fn wall_groove(&self, tri: u32) -> u32 {
        self.tri_groove[tri as usize]
    }
}

/// The profile's `x` axis for a groove along the unit `dir`, in the face's frame `(e1, e2, n)`:
/// `b = t x n` (METHOD.md section 1), the scratch frame's `x` that the model's lobes are read in,
/// so that an asymmetric profile is cut facing the way its lobes face.
fn across(dir: Vec2) -> Vec2 {
    Vec2::new(dir.y, -dir.x)
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
    /// inside a groove's opening, a wall point inside another groove's void.
    #[inline]
    pub fn rejects(&self, shape: u32, prim: u32, p: Vec3) -> bool {
        match self.roles.get(shape as usize) {
            Some(Some(CarveRole::Faces { first })) => {
                self.carvings[(first + prim / 2) as usize].in_void(p, None, true)
            }
            Some(Some(CarveRole::Walls { carving })) => {
                let c = &self.carvings[*carving as usize];
                c.in_void(p, Some(c.wall_groove(prim)), false)
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
    use crate::layers::LayerParams;
    use crate::math::Ray;
    use crate::precompute::profile::Profile;
    use crate::render::geometry::{Geometry, Shape, ShapeGeometry, Transform, TriangleMesh};
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

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
        let mut carving = Carving::new(&unit_face(), scratches, &profile.points, DEFAULT_STATIONS);
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
            Carving::new(&unit_face(), &scratches, &profile.points, stations)
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
            let c = Carving::new(&unit_face(), &[sc], &profile.points, stations);
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
}
