//! The scene's acceleration structure: every triangle and sphere of every shape in one BVH,
//! traversed for the closest hit and for any hit (shadow rays, early exit). The default
//! ([`BvhKind::Bvh8`]) is an 8-wide BVH with SSE box tests (`geometry::bvh8`) collapsed from
//! obvhs' binary BVH (PLOC with reinsertion), whose leaves are blocks of four triangles tested
//! at once (`Tri4`); obvhs' binary BVH itself is the reference it is tested against
//! ([`BvhKind::Bvh2`]) and the fallback for trees too deep for the 8-wide traversal's stack.
//!
//! The leaves' triangles take Moeller and Trumbore's test (1997, "Fast, Minimum Storage
//! Ray/Triangle Intersection") in the form of Embree's `Triangle4` leaves: each block stores
//! `v0`, both edges from it and their cross product, so a ray needs one cross product per
//! triangle (`FastTri4`), in one of two forms ([`TriangleTest`]):
//!
//! * **Fast** (the default), as Embree's default mode: two triangles sharing an edge compute
//!   their edge values with different rounding, so a ray aimed at the edge itself can pass
//!   between them (`closed_mesh_leaks_only_where_aimed_at_its_edges` states how often).
//! * **Watertight** (`render.watertight = true`, and always for explicit scratch geometry): the
//!   same test guarded by a bound on its rounding. Its three edge values are, in exact
//!   arithmetic, the Pluecker values `d . ((p - o) x (q - o))` of the edges `p q`, which two
//!   triangles sharing an edge have with opposite signs; where one lies within its bound of
//!   zero the block is decided by those values in `f64`, taken from each edge's endpoints in
//!   one fixed order ([`exact_hit`]), so that both triangles see one value. Every sign either
//!   path takes is then the exact one, and a ray never slips between triangles.
//!
//! The glass teapot renders in 11 % less CPU time with the fast form than with Woop, Benthin and
//! Wald's watertight test (2013, JCGT 2(1)), 8 % less with the watertight form (one thread,
//! `BENCHMARKS.md`). Woop's test, in the form of pbrt-v4's `Triangle::Intersect`
//! ([`WatertightRay`]), remains for the binary BVH, the scalar leaves (carved faces) and the
//! brute-force oracle of the tests.

use std::time::Duration;

use glam::{Vec3A, Vec4};
use obvhs::aabb::Aabb;
use obvhs::bvh2::builder::build_bvh2;
use obvhs::bvh2::Bvh2;
use obvhs::ploc::PlocSearchDistance;
use obvhs::BvhBuildParams;

use super::bvh8::{AnyLeaf, Bvh8, ClosestLeaf, Leaf, BLOCK, PACKET};
use super::carve::Carve;
use super::sphere::{intersect_sphere, sphere_surface};
use super::{Shape, ShapeGeometry, SurfaceHit};
use crate::math::{Ray, Vec3};
use arrayvec::ArrayVec;

/// One BVH primitive, stored in BVH order (no index indirection at traversal).
#[derive(Clone, Copy, Debug)]
struct Prim {
    /// Triangle vertices; for a sphere `v[0]` is the centre and `v[1].x` the radius.
    v: [Vec3; 3],
    shape: u32,
    /// Triangle index within the shape, or [`SPHERE`].
    prim: u32,
}

const SPHERE: u32 = u32::MAX;

/// Per-ray constants of Woop, Benthin and Wald's watertight test (the binary BVH's, the scalar
/// leaves' and the oracle's): the ray's dominant axis `kz` (with `kx`, `ky` the next two axes
/// cyclically) and the shear.
///
/// Departure from pbrt-v4: pbrt swaps `kx` and `ky` when `d[kz] < 0` to keep the determinant's
/// sign; the test is two-sided, and swapping only negates every edge function, `det` and the
/// scaled `t` exactly (IEEE negation is exact), so `t`, `b1`, `b2` and every accept/reject
/// decision are bit-for-bit the same without it. Without the swap the permutation is one of
/// three cyclic ones, which [`WatertightRay::intersect_axis`] takes as a constant.
#[derive(Clone, Copy, Debug)]
pub(crate) struct WatertightRay {
    o: Vec3,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl WatertightRay {
    #[inline(always)]
    pub(crate) fn new(ray: &Ray) -> Self {
        let d = ray.d;
        let kz = d.abs().max_position();
        let kx = (kz + 1) % 3;
        let ky = (kx + 1) % 3;
        WatertightRay {
            o: ray.o,
            kz,
            sx: -d[kx] / d[kz],
            sy: -d[ky] / d[kz],
            sz: 1.0 / d[kz],
        }
    }

    /// `(t, b1, b2)` of the hit with triangle `(p0, p1, p2)` for `t` in `(0, t_max)`;
    /// `b1`, `b2` weight `p1`, `p2`.
    #[inline]
    pub(crate) fn intersect(
        &self,
        p0: Vec3,
        p1: Vec3,
        p2: Vec3,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        match self.kz {
            0 => self.intersect_axis::<0>(p0, p1, p2, t_max),
            1 => self.intersect_axis::<1>(p0, p1, p2, t_max),
            _ => self.intersect_axis::<2>(p0, p1, p2, t_max),
        }
    }

    /// [`WatertightRay::intersect`] for a ray whose dominant axis is `KZ` (`== self.kz`).
    #[inline(always)]
    pub(crate) fn intersect_axis<const KZ: usize>(
        &self,
        p0: Vec3,
        p1: Vec3,
        p2: Vec3,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        debug_assert_eq!(KZ, self.kz);
        let (kx, ky) = ((KZ + 1) % 3, (KZ + 2) % 3);
        let (a, b, c) = (p0 - self.o, p1 - self.o, p2 - self.o);
        let ax = a[kx] + self.sx * a[KZ];
        let ay = a[ky] + self.sy * a[KZ];
        let bx = b[kx] + self.sx * b[KZ];
        let by = b[ky] + self.sy * b[KZ];
        let cx = c[kx] + self.sx * c[KZ];
        let cy = c[ky] + self.sy * c[KZ];
        let mut e0 = bx * cy - by * cx;
        let mut e1 = cx * ay - cy * ax;
        let mut e2 = ax * by - ay * bx;
        if e0 == 0.0 || e1 == 0.0 || e2 == 0.0 {
            // Exactly on an edge in f32: decide in f64 (pbrt-v4, Woop et al. section 3.3).
            let (bxd, byd, cxd, cyd, axd, ayd) = (
                bx as f64, by as f64, cx as f64, cy as f64, ax as f64, ay as f64,
            );
            e0 = (bxd * cyd - byd * cxd) as f32;
            e1 = (cxd * ayd - cyd * axd) as f32;
            e2 = (axd * byd - ayd * bxd) as f32;
        }
        if (e0 < 0.0 || e1 < 0.0 || e2 < 0.0) && (e0 > 0.0 || e1 > 0.0 || e2 > 0.0) {
            return None;
        }
        let det = e0 + e1 + e2;
        if det == 0.0 {
            return None;
        }
        let az = self.sz * a[KZ];
        let bz = self.sz * b[KZ];
        let cz = self.sz * c[KZ];
        let t_scaled = e0 * az + e1 * bz + e2 * cz;
        if det < 0.0 && (t_scaled >= 0.0 || t_scaled < t_max * det) {
            return None;
        }
        if det > 0.0 && (t_scaled <= 0.0 || t_scaled > t_max * det) {
            return None;
        }
        let inv_det = 1.0 / det;
        let t = t_scaled * inv_det;
        if !(t > 0.0 && t < t_max) {
            return None;
        }
        Some((t, e1 * inv_det, e2 * inv_det))
    }
}

/// The vertices of a [`Bvh8`] leaf block's four triangles as structure of arrays:
/// `v[vertex][axis]` holds that coordinate of the four triangles (what [`exact_hit`] decides
/// from where the guarded fast test is not sure).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct Tri4 {
    v: [[Vec4; 3]; 3],
}

/// Four triangles of a [`Bvh8`] leaf block for the fast test in either form ([`TriangleTest`]), as
/// structure of arrays (`[axis]` rows of four lanes): the first vertex `v0`, the edges
/// `a = v1 - v0`, `b = v2 - v0`, the unnormalised normal `n = a x b` (Embree's `Triangle4`) and
/// each lane's largest edge component (for the rounding bound). A padded lane or a sphere's lane
/// holds zeros: `n = 0` is never hit.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
struct FastTri4 {
    v0: [Vec4; 3],
    a: [Vec4; 3],
    b: [Vec4; 3],
    n: [Vec4; 3],
    size: Vec4,
}

/// What [`FastTri4::hits`] found.
enum FastHits {
    None,
    /// A lane's edge value lies within its rounding bound of zero: the exact test decides.
    Uncertain,
    /// The lanes hit, with each lane's `t`, `b1`, `b2`.
    Some(glam::BVec4A, Vec4, Vec4, Vec4),
}

/// Bound on the fast test's rounding of an edge value, in units of `eps |d| |o - v0| size`
/// (largest components; for the third edge twice this, plus this with `size` for `|o - v0|`).
/// A first-order count of the operations' errors, the stored edges' and normal's rounding
/// included, gives about 42 units for an edge and 96 for the third; 64 leaves a margin.
const EDGE_ROUNDING: f32 = 64.0 * f32::EPSILON;

impl FastTri4 {
    /// The block holding the triangles `tris` (at most [`BLOCK`]; `None` for a lane without one).
    fn new(tris: impl Iterator<Item = Option<[Vec3; 3]>>) -> Self {
        let mut block = FastTri4 {
            v0: [Vec4::ZERO; 3],
            a: [Vec4::ZERO; 3],
            b: [Vec4::ZERO; 3],
            n: [Vec4::ZERO; 3],
            size: Vec4::ZERO,
        };
        for (lane, tri) in tris.enumerate() {
            let Some([p0, p1, p2]) = tri else { continue };
            let (a, b) = (p1 - p0, p2 - p0);
            let n = a.cross(b);
            for axis in 0..3 {
                block.v0[axis][lane] = p0[axis];
                block.a[axis][lane] = a[axis];
                block.b[axis][lane] = b[axis];
                block.n[axis][lane] = n[axis];
            }
            block.size[lane] = a.abs().max(b.abs()).max_element();
        }
        block
    }

    /// `(lane, t, b1, b2)` of the closest hit along `o + t d` with `t` in `(0, t_max)`, the
    /// lowest lane on a tie; `b1`, `b2` weight `v1`, `v2`. With `GUARD` (the watertight test)
    /// a block the fast test is not sure of is decided by `exact` ([`Tri4::closest_exact`]).
    #[inline(always)]
    fn closest<const GUARD: bool>(
        &self,
        o: Vec3,
        d: Vec3,
        t_max: f32,
        exact: impl FnOnce() -> Option<(usize, f32, f32, f32)>,
    ) -> Option<(usize, f32, f32, f32)> {
        let (valid, t, b1, b2) = match self.hits::<GUARD>(o, d, t_max) {
            FastHits::None => return None,
            FastHits::Uncertain => return exact(),
            FastHits::Some(valid, t, b1, b2) => (valid, t, b1, b2),
        };
        let tm = Vec4::select(valid, t, Vec4::INFINITY);
        let t_min = tm.min_element();
        let lane = tm.cmpeq(Vec4::splat(t_min)).bitmask().trailing_zeros() as usize;
        Some((lane, t[lane], b1[lane], b2[lane]))
    }

    /// Whether any triangle of the block is hit with `t` in `(0, t_max)`; `exact` as in
    /// [`Self::closest`].
    #[inline(always)]
    fn any<const GUARD: bool>(
        &self,
        o: Vec3,
        d: Vec3,
        t_max: f32,
        exact: impl FnOnce() -> bool,
    ) -> bool {
        match self.hits::<GUARD>(o, d, t_max) {
            FastHits::None => false,
            FastHits::Uncertain => exact(),
            FastHits::Some(..) => true,
        }
    }

    /// Moeller-Trumbore on the four lanes. With `O = o - v0`, `R = d x O` and `den = d . n`,
    /// Cramer's rule gives `t = -(O . n) / den`, `b1 = (b . R) / den`, `b2 = -(a . R) / den`;
    /// all are taken with the sign of `den` (a two-sided test) and compared before the one
    /// division. In exact arithmetic `b . R`, `-(a . R)` and `den - b . R + a . R` are the
    /// Pluecker values of the edges `v2 v0`, `v0 v1` and `v1 v2` ([`edge_value`]), which a
    /// neighbour sharing the edge computes with the opposite sign; where one lies within its
    /// rounding bound ([`EDGE_ROUNDING`]) of zero on a lane that may be hit, the block is
    /// `Uncertain` (with `GUARD`). Every sign the test then decides is the exact one, so it never
    /// disagrees with a neighbour's decision, exact or fast: no ray slips between them. Without
    /// `GUARD` the signs are taken as computed, and a ray through an edge may find neither.
    #[inline(always)]
    fn hits<const GUARD: bool>(&self, o: Vec3, d: Vec3, t_max: f32) -> FastHits {
        let [ox, oy, oz] = [0, 1, 2].map(|k| Vec4::splat(o[k]) - self.v0[k]);
        let [dx, dy, dz] = [0, 1, 2].map(|k| Vec4::splat(d[k]));
        let (rx, ry, rz) = (dy * oz - dz * oy, dz * ox - dx * oz, dx * oy - dy * ox);
        let [a, b, n] = [&self.a, &self.b, &self.n];
        let den = dx * n[0] + dy * n[1] + dz * n[2];
        let zero = Vec4::ZERO;
        let sign = Vec4::select(den.cmplt(zero), Vec4::NEG_ONE, Vec4::ONE);
        let abs_den = den * sign;
        let u = (b[0] * rx + b[1] * ry + b[2] * rz) * sign;
        let v = -(a[0] * rx + a[1] * ry + a[2] * rz) * sign;
        let w = abs_den - (u + v);
        let t_den = -(ox * n[0] + oy * n[1] + oz * n[2]) * sign;
        let ahead = t_den.cmpgt(zero) & t_den.cmplt(abs_den * Vec4::splat(t_max));
        if GUARD {
            let scale = Vec4::splat(EDGE_ROUNDING * d.abs().max_element()) * self.size;
            let bound = scale * ox.abs().max(oy.abs()).max(oz.abs());
            let bound_w = bound + bound + scale * self.size;
            let near = u.abs().cmplt(bound) | v.abs().cmplt(bound) | w.abs().cmplt(bound_w);
            if (near & ahead).any() {
                return FastHits::Uncertain;
            }
        }
        let valid = ahead & den.cmpne(zero) & u.cmpge(zero) & v.cmpge(zero) & w.cmpge(zero);
        if !valid.any() {
            return FastHits::None;
        }
        let inv_den = Vec4::ONE / abs_den;
        let t = t_den * inv_den;
        let valid = valid & t.cmpgt(zero) & t.cmplt(Vec4::splat(t_max));
        if !valid.any() {
            return FastHits::None;
        }
        FastHits::Some(valid, t, u * inv_den, v * inv_den)
    }
}

impl Tri4 {
    /// The block holding the triangles `tris` (at most [`BLOCK`]; `None` for a lane without one).
    fn new(tris: impl Iterator<Item = Option<[Vec3; 3]>>) -> Self {
        let mut block = Tri4 {
            v: [[Vec4::ZERO; 3]; 3],
        };
        for (lane, tri) in tris.enumerate() {
            for (k, p) in tri.into_iter().flatten().enumerate() {
                for axis in 0..3 {
                    block.v[k][axis][lane] = p[axis];
                }
            }
        }
        block
    }

    /// Lane `lane`'s vertices.
    fn vertices(&self, lane: usize) -> [Vec3; 3] {
        [0, 1, 2].map(|k| Vec3::new(self.v[k][0][lane], self.v[k][1][lane], self.v[k][2][lane]))
    }

    /// The closest hit of the block's lanes by [`exact_hit`] (the fast test's fallback, out of
    /// line: it runs for a few blocks in ten thousand).
    #[inline(never)]
    fn closest_exact(&self, o: Vec3, d: Vec3, mut t_max: f32) -> Option<(usize, f32, f32, f32)> {
        let mut best = None;
        for lane in 0..BLOCK {
            if let Some((t, b1, b2)) = exact_hit(o, d, self.vertices(lane), t_max) {
                t_max = t;
                best = Some((lane, t, b1, b2));
            }
        }
        best
    }
}

/// The Pluecker value `d . ((p - o) x (q - o))` of the edge `p q` for the ray `o + t d`, in
/// `f64` (the differences of `f32` coordinates and their products are exact there) and from the
/// endpoints in one fixed order, so that the two triangles sharing the edge get the same
/// magnitude with opposite signs, bit for bit.
fn edge_value(o: Vec3, d: Vec3, p: Vec3, q: Vec3) -> f64 {
    let key = |v: Vec3| {
        v.to_array()
            .map(|x| x.to_bits() as i32 ^ ((x.to_bits() as i32 >> 31) & 0x7fff_ffff))
    };
    let (x, y, sign) = if key(p) <= key(q) {
        (p, q, 1.0)
    } else {
        (q, p, -1.0)
    };
    let (o, d) = (o.as_dvec3(), d.as_dvec3());
    sign * d.dot((x.as_dvec3() - o).cross(y.as_dvec3() - o))
}

/// `(t, b1, b2)` of the hit of `o + t d` with the triangle `(p0, p1, p2)` for `t` in
/// `(0, t_max)`, decided by the signs of its three edges' exact values ([`edge_value`]): a ray
/// on an edge hits both triangles that share it, never neither.
fn exact_hit(o: Vec3, d: Vec3, [p0, p1, p2]: [Vec3; 3], t_max: f32) -> Option<(f32, f32, f32)> {
    let (e01, e12, e20) = (
        edge_value(o, d, p0, p1),
        edge_value(o, d, p1, p2),
        edge_value(o, d, p2, p0),
    );
    if (e01 < 0.0 || e12 < 0.0 || e20 < 0.0) && (e01 > 0.0 || e12 > 0.0 || e20 > 0.0) {
        return None;
    }
    let den = e01 + e12 + e20;
    if den == 0.0 {
        return None;
    }
    let n = (p1 - p0).as_dvec3().cross((p2 - p0).as_dvec3());
    let t = ((p0.as_dvec3() - o.as_dvec3()).dot(n) / d.as_dvec3().dot(n)) as f32;
    (t > 0.0 && t < t_max).then(|| (t, (e20 / den) as f32, (e01 / den) as f32))
}

/// Which form of the ray/triangle test a [`Geometry`]'s 8-wide BVH runs at its triangle leaves
/// (module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum TriangleTest {
    /// Moeller-Trumbore on precomputed edges (Embree's default mode): may let a ray aimed at a
    /// shared edge or vertex through.
    #[default]
    Fast,
    /// The same, with the blocks near an edge decided exactly: no ray slips between triangles
    /// that share an edge.
    Watertight,
}

/// Which hierarchy [`Geometry`] traverses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum BvhKind {
    /// 8-wide BVH with SSE box tests and 4-triangle SIMD leaves, collapsed from obvhs' binary
    /// BVH (`geometry::bvh8`).
    #[default]
    Bvh8,
    /// obvhs' binary BVH with collapsed leaves: the reference the 8-wide one is tested against,
    /// and its fallback for trees too deep for its traversal stack.
    Bvh2,
}

enum Accel {
    None,
    Bvh2(Bvh2),
    Bvh8(Bvh8),
}

/// Most primitives per leaf of the binary BVH that [`BvhKind::Bvh8`] collapses (its leaf
/// blocks hold up to [`BLOCK`]).
const BVH8_LEAF_PRIMS: u32 = 2;

/// Scenes of at most this many primitives get the slower, better binary BVH build before the
/// collapse to [`Bvh8`] (see [`Geometry::with_bvh`]).
const SLOW_BUILD_PRIMS: usize = 1 << 17;

/// Shapes with the BVH over their primitives.
pub struct Geometry {
    shapes: Vec<Shape>,
    /// Primitives in BVH order; for [`BvhKind::Bvh8`] `BLOCK` per leaf block (padded).
    prims: Vec<Prim>,
    /// The triangles of `prims` as blocks of four for the fast test ([`BvhKind::Bvh8`] only).
    fast4: Vec<FastTri4>,
    /// Their vertices, where the watertight test decides from them ([`TriangleTest::Watertight`]).
    tri4: Vec<Tri4>,
    triangles: TriangleTest,
    /// Number of distinct primitives.
    prim_count: usize,
    accel: Accel,
    /// Explicit scratch geometry's hit filter (METHOD.md 8.3); `None` in other scenes.
    carve: Option<Box<Carve>>,
}

impl std::fmt::Debug for Geometry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Geometry")
            .field("shapes", &self.shapes.len())
            .field("primitives", &self.prim_count)
            .finish()
    }
}

fn prim_aabb(p: &Prim) -> Aabb {
    let (lo, hi) = if p.prim == SPHERE {
        let r = Vec3::splat(p.v[1].x);
        (p.v[0] - r, p.v[0] + r)
    } else {
        (
            p.v[0].min(p.v[1]).min(p.v[2]),
            p.v[0].max(p.v[1]).max(p.v[2]),
        )
    };
    // A little padding keeps flat (axis-aligned) boxes robust in the slab test.
    let pad = Vec3::splat(1e-6 * lo.abs().max(hi.abs()).max_element() + 1e-20);
    Aabb::new(Vec3A::from(lo - pad), Vec3A::from(hi + pad))
}

impl Geometry {
    /// Builds the BVH (the default [`BvhKind`] and [`TriangleTest`]) over all triangles and
    /// spheres of `shapes`.
    pub fn new(shapes: Vec<Shape>) -> Geometry {
        Geometry::with_triangles(shapes, TriangleTest::default())
    }

    /// Builds the default BVH with the chosen triangle test.
    pub fn with_triangles(shapes: Vec<Shape>, triangles: TriangleTest) -> Geometry {
        Geometry::with_bvh(shapes, BvhKind::default(), triangles)
    }

    /// Builds the chosen kind of BVH with the chosen triangle test (for benchmarks and tests).
    pub fn with_bvh(shapes: Vec<Shape>, kind: BvhKind, triangles: TriangleTest) -> Geometry {
        Geometry::build(shapes, kind, triangles, None)
    }

    /// Builds the BVH over `shapes`, some of them carved by explicit scratch grooves whose
    /// hits `carve` filters ([`Carve::rejects`]). Their triangles go to scalar leaves, where
    /// each hit is tested before it counts (Woop's test); the rest take the watertight form of
    /// the fast test ([`TriangleTest::Watertight`]), since the grooves' walls are the reference
    /// the scratch model is measured against.
    pub fn with_carve(shapes: Vec<Shape>, carve: Carve) -> Geometry {
        Geometry::build(
            shapes,
            BvhKind::default(),
            TriangleTest::Watertight,
            Some(Box::new(carve)),
        )
    }

    fn build(
        shapes: Vec<Shape>,
        kind: BvhKind,
        triangles: TriangleTest,
        carve: Option<Box<Carve>>,
    ) -> Geometry {
        let mut prims = Vec::new();
        for (s, shape) in shapes.iter().enumerate() {
            match &shape.geometry {
                ShapeGeometry::Mesh(mesh) => {
                    for i in 0..mesh.triangle_count() {
                        prims.push(Prim {
                            v: mesh.triangle(i),
                            shape: s as u32,
                            prim: i as u32,
                        });
                    }
                }
                ShapeGeometry::Sphere { centre, radius } => {
                    prims.push(Prim {
                        v: [*centre, Vec3::new(*radius, 0.0, 0.0), Vec3::ZERO],
                        shape: s as u32,
                        prim: SPHERE,
                    });
                }
            }
        }
        let prim_count = prims.len();
        if prims.is_empty() {
            return Geometry {
                shapes,
                prims,
                fast4: Vec::new(),
                tri4: Vec::new(),
                triangles,
                prim_count,
                accel: Accel::None,
                carve,
            };
        }
        let aabbs: Vec<Aabb> = prims.iter().map(prim_aabb).collect();
        let params = BvhBuildParams::medium_build();
        let (accel, order) = match kind {
            BvhKind::Bvh2 => {
                let bvh = build_bvh2(&aabbs, params, &mut Duration::default());
                let order = bvh.primitive_indices.clone();
                (Accel::Bvh2(bvh), order)
            }
            BvhKind::Bvh8 => {
                // Up to SLOW_BUILD_PRIMS primitives: obvhs' `very_slow_build` without its
                // triangle pre-splitting (the BVH is built over boxes) and with the widest PLOC
                // search: 2.6 % fewer instructions and 3.6 % less time per render than
                // `medium_build` on the glass teapot, for a build 6x as long (~30 ms for its
                // 4096 triangles). Larger meshes keep `medium_build`.
                let base = if prims.len() <= SLOW_BUILD_PRIMS {
                    BvhBuildParams {
                        pre_split: false,
                        ploc_search_distance: PlocSearchDistance::VeryHigh,
                        ..BvhBuildParams::very_slow_build()
                    }
                } else {
                    params
                };
                let params = BvhBuildParams {
                    max_prims_per_leaf: BVH8_LEAF_PRIMS,
                    ..base
                };
                let bvh = build_bvh2(&aabbs, params, &mut Duration::default());
                let order = bvh.primitive_indices.clone();
                let scalar = |i: u32| {
                    let p = &prims[i as usize];
                    p.prim == SPHERE || carve.as_ref().is_some_and(|c| c.is_carved(p.shape))
                };
                match Bvh8::from_bvh2(&bvh, scalar) {
                    Some((bvh8, order)) => (Accel::Bvh8(bvh8), order),
                    // Too deep for the BVH8's fixed stack: keep the binary BVH.
                    None => (Accel::Bvh2(bvh), order),
                }
            }
        };
        // Primitives in BVH order: traversal indexes them directly.
        let prims: Vec<Prim> = order.iter().map(|&i| prims[i as usize]).collect();
        // Leaf blocks of four for the 8-wide BVH, a sphere's lane left empty (zero).
        let bvh8 = matches!(accel, Accel::Bvh8(_));
        let blocks = || {
            let triangle = |p: &Prim| (p.prim != SPHERE).then_some(p.v);
            prims.chunks(BLOCK).map(move |b| b.iter().map(triangle))
        };
        let fast4 = match bvh8 {
            true => blocks().map(FastTri4::new).collect(),
            false => Vec::new(),
        };
        let tri4 = match (bvh8, triangles) {
            (true, TriangleTest::Watertight) => blocks().map(Tri4::new).collect(),
            _ => Vec::new(),
        };
        Geometry {
            shapes,
            prims,
            fast4,
            tri4,
            triangles,
            prim_count,
            accel,
            carve,
        }
    }

    /// Whether the triangle hit of primitive `p` at ray parameter `t` is dropped by the
    /// explicit scratch geometry's filter.
    #[inline(always)]
    fn carved_away(&self, p: &Prim, ray: &Ray, t: f32) -> bool {
        self.carve
            .as_ref()
            .is_some_and(|c| c.rejects(p.shape, p.prim, ray.at(t)))
    }

    /// The origin of a ray leaving a hit at `p` (geometric normal `ng`) on shape `shape`
    /// toward `dir`: moved off the surface by [`super::OFFSET`], or by
    /// [`super::CARVED_OFFSET`] on explicit scratch geometry.
    #[inline(always)]
    pub fn spawn_origin(&self, p: Vec3, ng: Vec3, shape: u32, dir: Vec3) -> Vec3 {
        super::offset_origin_by(p, ng, dir, self.spawn_offset(shape))
    }

    /// The relative offset [`Self::spawn_origin`] gives rays leaving `shape`.
    #[inline(always)]
    pub fn spawn_offset(&self, shape: u32) -> f32 {
        match &self.carve {
            Some(c) if c.is_carved(shape) => super::CARVED_OFFSET,
            _ => super::OFFSET,
        }
    }

    /// The explicit scratch geometry, if the scene has any.
    pub fn carve(&self) -> Option<&Carve> {
        self.carve.as_deref()
    }

    pub fn shapes(&self) -> &[Shape] {
        &self.shapes
    }

    /// Number of BVH primitives (triangles plus spheres).
    pub fn primitive_count(&self) -> usize {
        self.prim_count
    }

    #[inline]
    fn obvhs_ray(ray: &Ray) -> obvhs::ray::Ray {
        // `+ 0.0` turns -0.0 into +0.0: obvhs picks the slab order from `d < 0` but inverts
        // -0.0 to -huge, so a -0.0 component would swap the slabs and miss every box.
        let d = Vec3A::from(ray.d) + Vec3A::ZERO;
        obvhs::ray::Ray::new(Vec3A::from(ray.o), d, 0.0, ray.t_max)
    }

    #[inline(always)]
    fn hit_prim(
        &self,
        wray: &WatertightRay,
        ray: &Ray,
        id: usize,
        t_max: f32,
    ) -> Option<(f32, f32, f32)> {
        let p = &self.prims[id];
        if p.prim == SPHERE {
            intersect_sphere(p.v[0], p.v[1].x, ray, t_max).map(|t| (t, 0.0, 0.0))
        } else {
            wray.intersect(p.v[0], p.v[1], p.v[2], t_max)
                .filter(|h| !self.carved_away(p, ray, h.0))
        }
    }

    /// Closest hit in the [`Bvh8`]: `(primitive, t, b1, b2)`.
    #[inline(always)]
    fn closest_bvh8(&self, bvh: &Bvh8, ray: &Ray) -> Option<(usize, f32, f32, f32)> {
        let mut test = Bvh8Leaves::new(self, ray);
        bvh.closest(ray.o, ray.d, ray.t_max, &mut test);
        test.best
    }

    /// Any hit in the [`Bvh8`].
    #[inline(always)]
    fn occluded_bvh8(&self, bvh: &Bvh8, ray: &Ray) -> bool {
        bvh.any(ray.o, ray.d, ray.t_max, &mut Bvh8Leaves::new(self, ray))
    }

    /// Closest hit with `t` in `(0, ray.t_max)`. Inlined into the caller (the render loop is
    /// compiled once per instruction set, `integrator::render`): the default BVH is traversed
    /// inline, obvhs' hierarchies out of line.
    #[inline(always)]
    pub fn intersect(&self, ray: &Ray) -> Option<SurfaceHit> {
        let Accel::Bvh8(bvh) = &self.accel else {
            return self.intersect_obvhs(ray);
        };
        self.intersect_bvh8(bvh, ray)
    }

    /// [`Geometry::intersect`] in the [`Bvh8`].
    #[inline(always)]
    fn intersect_bvh8(&self, bvh: &Bvh8, ray: &Ray) -> Option<SurfaceHit> {
        let (id, t, b1, b2) = self.closest_bvh8(bvh, ray)?;
        Some(self.surface_hit(ray, id, t, b1, b2))
    }

    /// The closest hits of `rays` (at most [`PACKET`]) into `hits` (cleared first), as
    /// [`Geometry::intersect`] finds them (but for exact ties in `t`, see `bvh8`). Rays that
    /// share their origin and the signs of their directions (a pixel's
    /// camera rays through a pinhole) are traversed as one packet ([`Bvh8::closest_packet`]),
    /// other rays one by one. (The hits go to the caller's array rather than being returned:
    /// a returned array of 32 hits, 2.7 KB, is copied several times on its way out; in place,
    /// an 8-spp glass-teapot render is 6 % faster.)
    /// # Panics
    /// If there are more than [`PACKET`] rays.
    #[inline(always)]
    pub fn intersect_coherent(
        &self,
        rays: &[Ray],
        hits: &mut ArrayVec<Option<SurfaceHit>, PACKET>,
    ) {
        self.intersect_coherent_counted(rays, hits);
    }

    /// [`Geometry::intersect_coherent`]; whether the rays were traced as a packet.
    #[inline(always)]
    pub(crate) fn intersect_coherent_counted(
        &self,
        rays: &[Ray],
        hits: &mut ArrayVec<Option<SurfaceHit>, PACKET>,
    ) -> bool {
        assert!(rays.len() <= PACKET);
        hits.clear();
        if let (Accel::Bvh8(bvh), 2..) = (&self.accel, rays.len()) {
            let origin = rays[0].o.to_array().map(f32::to_bits);
            let shared = rays
                .iter()
                .all(|r| r.o.to_array().map(f32::to_bits) == origin);
            let traced = shared && self.closest_packet(bvh, rays, hits);
            if !traced {
                self.intersect_each(rays, hits);
            }
            return traced;
        }
        self.intersect_each(rays, hits);
        false
    }

    /// [`Geometry::intersect`] of each ray (out of line: [`Geometry::intersect_coherent`]'s
    /// fallback, for rays that are no packet).
    #[inline(never)]
    fn intersect_each(&self, rays: &[Ray], hits: &mut ArrayVec<Option<SurfaceHit>, PACKET>) {
        // (A loop of `push` rather than `extend`: that is compiled out of line, where the
        // render loop's copy loses its target features.)
        for ray in rays {
            hits.push(self.intersect(ray));
        }
    }

    /// [`Geometry::intersect_coherent`]'s packet of rays with one origin, into `hits`; false
    /// (and `hits` left empty) when their directions' signs differ.
    #[inline(always)]
    fn closest_packet(
        &self,
        bvh: &Bvh8,
        rays: &[Ray],
        hits: &mut ArrayVec<Option<SurfaceHit>, PACKET>,
    ) -> bool {
        let mut packet = PacketLeaves {
            rays: ArrayVec::new(),
        };
        let mut dirs = ArrayVec::<Vec3, PACKET>::new();
        let mut largest = f32::NEG_INFINITY;
        for ray in rays {
            packet.rays.push((Bvh8Leaves::new(self, ray), ray.t_max));
            dirs.push(ray.d);
            largest = largest.max(ray.t_max);
        }
        if !bvh.closest_packet(rays[0].o, &dirs, largest, &mut packet) {
            return false;
        }
        for (leaves, _) in &packet.rays {
            let ray = leaves.ray;
            hits.push(
                leaves
                    .best
                    .map(|(id, t, b1, b2)| self.surface_hit(ray, id, t, b1, b2)),
            );
        }
        true
    }

    /// [`Geometry::intersect`] for both kinds of hierarchy.
    #[inline(never)]
    fn intersect_obvhs(&self, ray: &Ray) -> Option<SurfaceHit> {
        let wray = WatertightRay::new(ray);
        let mut best: Option<(usize, f32, f32, f32)> = None;
        let mut t_max = ray.t_max;
        let mut hit = obvhs::ray::RayHit::none();
        match &self.accel {
            Accel::None => return None,
            Accel::Bvh8(bvh) => best = self.closest_bvh8(bvh, ray),
            Accel::Bvh2(bvh) => {
                bvh.ray_traverse(Self::obvhs_ray(ray), &mut hit, |_, id| {
                    match self.hit_prim(&wray, ray, id, t_max) {
                        Some((t, b1, b2)) => {
                            best = Some((id, t, b1, b2));
                            t_max = t;
                            t
                        }
                        None => f32::INFINITY,
                    }
                });
            }
        }
        let (id, t, b1, b2) = best?;
        Some(self.surface_hit(ray, id, t, b1, b2))
    }

    /// Whether anything lies along the ray in `(0, ray.t_max)` (any hit, early exit). Inlined
    /// like [`Geometry::intersect`].
    #[inline(always)]
    pub fn occluded(&self, ray: &Ray) -> bool {
        let Accel::Bvh8(bvh) = &self.accel else {
            return self.occluded_obvhs(ray);
        };
        self.occluded_bvh8(bvh, ray)
    }

    /// [`Geometry::occluded`] for both kinds of hierarchy.
    #[inline(never)]
    fn occluded_obvhs(&self, ray: &Ray) -> bool {
        let wray = WatertightRay::new(ray);
        let test = |id: usize| {
            if self.hit_prim(&wray, ray, id, ray.t_max).is_some() {
                0.0
            } else {
                f32::INFINITY
            }
        };
        match &self.accel {
            Accel::None => false,
            Accel::Bvh2(bvh) => !bvh.ray_traverse_miss(Self::obvhs_ray(ray), |_, id| test(id)),
            Accel::Bvh8(bvh) => self.occluded_bvh8(bvh, ray),
        }
    }

    /// Whether the shading normal of shape `shape` varies over its surface (a sphere, a mesh
    /// with [`TriangleMesh::has_curved_normals`]), so that [`Self::shading_normal_steps`] may
    /// be non-zero.
    #[inline]
    pub fn has_curved_normals(&self, shape: u32) -> bool {
        match &self.shapes[shape as usize].geometry {
            ShapeGeometry::Mesh(mesh) => mesh.has_curved_normals(),
            ShapeGeometry::Sphere { .. } => true,
        }
    }

    /// The change of the shading normal of the surface `hit` lies on, for each step `dp` of
    /// `steps` in the tangent plane (e.g. a ray differential's `dP/dx`, `dP/dy`): `dp / r` on a
    /// sphere of radius `r`, [`TriangleMesh::shading_normal_steps`] on a mesh with vertex
    /// normals (zero on its flat triangles); `None` on a mesh whose shading normal never varies
    /// (no vertex normals, or equal ones on every triangle: boxes, rectangles, flat OBJ files).
    #[inline]
    pub fn shading_normal_steps(&self, hit: &SurfaceHit, steps: [Vec3; 2]) -> Option<[Vec3; 2]> {
        match &self.shapes[hit.shape as usize].geometry {
            ShapeGeometry::Mesh(mesh) => mesh.shading_normal_steps(hit.prim as usize, steps),
            ShapeGeometry::Sphere { radius, .. } => Some(steps.map(|dp| dp / *radius)),
        }
    }

    #[inline(always)]
    fn surface_hit(&self, ray: &Ray, id: usize, t: f32, b1: f32, b2: f32) -> SurfaceHit {
        let prim = &self.prims[id];
        let shape = &self.shapes[prim.shape as usize];
        match &shape.geometry {
            ShapeGeometry::Mesh(mesh) => {
                let (p, ng, ns, uv, dpdu, dpdv) = mesh.surface(prim.prim as usize, b1, b2);
                SurfaceHit {
                    t,
                    p,
                    ng,
                    ns,
                    uv,
                    dpdu,
                    dpdv,
                    shape: prim.shape,
                    prim: prim.prim,
                }
            }
            ShapeGeometry::Sphere { centre, radius } => {
                let (p, n, uv, dpdu, dpdv) = sphere_surface(*centre, *radius, ray.at(t));
                SurfaceHit {
                    t,
                    p,
                    ng: n,
                    ns: n,
                    uv,
                    dpdu,
                    dpdv,
                    shape: prim.shape,
                    prim: 0,
                }
            }
        }
    }
}

/// The primitive tests of [`Geometry`]'s [`Bvh8`] for a ray, with the closest hit so far
/// `(primitive, t, b1, b2)`.
struct Bvh8Leaves<'a> {
    geometry: &'a Geometry,
    ray: &'a Ray,
    /// The ray's constants for Woop's test, made at its first scalar leaf (spheres, carved
    /// faces).
    wray: Option<WatertightRay>,
    best: Option<(usize, f32, f32, f32)>,
}

impl<'a> Bvh8Leaves<'a> {
    #[inline(always)]
    fn new(geometry: &'a Geometry, ray: &'a Ray) -> Self {
        Bvh8Leaves {
            geometry,
            ray,
            wray: None,
            best: None,
        }
    }

    /// Primitive `id` of a scalar leaf, before `t_max`.
    #[inline(always)]
    fn scalar(&mut self, id: usize, t_max: f32) -> Option<(f32, f32, f32)> {
        let ray = self.ray;
        let wray = self.wray.get_or_insert_with(|| WatertightRay::new(ray));
        self.geometry.hit_prim(wray, ray, id, t_max)
    }
}

impl ClosestLeaf for Bvh8Leaves<'_> {
    #[inline(always)]
    fn closest(&mut self, leaf: Leaf, t_max: &mut f32) {
        let first = BLOCK * leaf.block;
        if leaf.scalar {
            for id in first..first + leaf.count {
                if let Some((t, b1, b2)) = self.scalar(id, *t_max) {
                    self.best = Some((id, t, b1, b2));
                    *t_max = t;
                }
            }
        } else if let Some((lane, t, b1, b2)) = {
            let (o, d, g) = (self.ray.o, self.ray.d, self.geometry);
            let (fast, block) = (&g.fast4[leaf.block], leaf.block);
            match g.triangles {
                TriangleTest::Fast => fast.closest::<false>(o, d, *t_max, || None),
                TriangleTest::Watertight => {
                    fast.closest::<true>(o, d, *t_max, || g.tri4[block].closest_exact(o, d, *t_max))
                }
            }
        } {
            self.best = Some((first + lane, t, b1, b2));
            *t_max = t;
        }
    }
}

impl AnyLeaf for Bvh8Leaves<'_> {
    #[inline(always)]
    fn any(&mut self, leaf: Leaf, t_max: f32) -> bool {
        let first = BLOCK * leaf.block;
        if leaf.scalar {
            (first..first + leaf.count).any(|id| self.scalar(id, t_max).is_some())
        } else {
            let (o, d, g) = (self.ray.o, self.ray.d, self.geometry);
            let (fast, block) = (&g.fast4[leaf.block], leaf.block);
            match g.triangles {
                TriangleTest::Fast => fast.any::<false>(o, d, t_max, || false),
                TriangleTest::Watertight => fast.any::<true>(o, d, t_max, || {
                    g.tri4[block].closest_exact(o, d, t_max).is_some()
                }),
            }
        }
    }
}

/// The primitive tests of a packet ([`Bvh8::closest_packet`]): each ray's own
/// [`Bvh8Leaves`], with its own closest `t`.
struct PacketLeaves<'a> {
    rays: ArrayVec<(Bvh8Leaves<'a>, f32), PACKET>,
}

impl ClosestLeaf for PacketLeaves<'_> {
    /// Every ray tests the leaf against its own closest `t`; `t_max` becomes the largest.
    #[inline(always)]
    fn closest(&mut self, leaf: Leaf, t_max: &mut f32) {
        let mut largest = f32::NEG_INFINITY;
        for (ray, t) in &mut self.rays {
            ray.closest(leaf, t);
            largest = largest.max(*t);
        }
        *t_max = largest;
    }
}

/// Brute-force closest hit over every primitive (the test oracle for the BVH).
pub fn intersect_brute_force(shapes: &[Shape], ray: &Ray) -> Option<(f32, u32, u32)> {
    let wray = WatertightRay::new(ray);
    let mut best: Option<(f32, u32, u32)> = None;
    let mut t_max = ray.t_max;
    for (s, shape) in shapes.iter().enumerate() {
        match &shape.geometry {
            ShapeGeometry::Mesh(mesh) => {
                for i in 0..mesh.triangle_count() {
                    let [a, b, c] = mesh.triangle(i);
                    if let Some((t, ..)) = wray.intersect(a, b, c, t_max) {
                        t_max = t;
                        best = Some((t, s as u32, i as u32));
                    }
                }
            }
            ShapeGeometry::Sphere { centre, radius } => {
                if let Some(t) = intersect_sphere(*centre, *radius, ray, t_max) {
                    t_max = t;
                    best = Some((t, s as u32, 0));
                }
            }
        }
    }
    best
}

#[cfg(test)]
mod tri4_tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64;

    /// `(t, b1, b2)` of the ray `o + t d` in the plane of triangle `(p0, p1, p2)` by Cramer's
    /// rule in `f64` (the barycentrics may be negative: the point may lie outside).
    fn plane_hit_f64(o: Vec3, d: Vec3, [p0, p1, p2]: [Vec3; 3]) -> Option<(f64, f64, f64)> {
        let (o, d) = (o.as_dvec3(), d.as_dvec3());
        let (a, b) = ((p1 - p0).as_dvec3(), (p2 - p0).as_dvec3());
        let q = o - p0.as_dvec3();
        // o + t d = p0 + b1 a + b2 b  <=>  [-d a b] (t b1 b2) = q.
        let det = (-d).dot(a.cross(b));
        (det != 0.0).then(|| {
            (
                q.dot(a.cross(b)) / det,
                (-d).dot(q.cross(b)) / det,
                (-d).dot(a.cross(q)) / det,
            )
        })
    }

    #[test]
    fn fast_test_finds_the_exact_hit_away_from_the_edges() {
        // Random blocks of four triangles and random rays, both forms of the test (unguarded,
        // and guarded with its exact fallback): every lane whose exact (f64) hit lies inside its
        // triangle and inside (0, t_max) by a margin of 1e-4 must be found, the closest with the
        // exact t and barycentrics to 1e-5; a block whose lanes all miss by that margin must be
        // missed. Lanes within the margin of an edge may go either way.
        let mut rng = Pcg64::seed_from_u64(17);
        let (mut hits, mut misses) = (0, 0);
        for k in 0..40_000 {
            let point =
                |rng: &mut Pcg64| Vec3::new(rng.random(), rng.random(), rng.random()) * 4.0 - 2.0;
            let mut tris = [None; BLOCK];
            let lanes = 1 + k % BLOCK;
            for tri in tris.iter_mut().take(lanes) {
                *tri = Some([point(&mut rng), point(&mut rng), point(&mut rng)]);
            }
            let block = FastTri4::new(tris.iter().copied());
            let exact = Tri4::new(tris.iter().copied());
            let o = point(&mut rng) * 2.0;
            let d = (point(&mut rng) - o).normalize();
            let t_max = if k % 5 == 0 { 3.0 } else { f32::INFINITY };
            let margin = 1e-4;
            let mut expected: Option<(usize, f64, f64, f64)> = None;
            let mut ambiguous = false;
            for (lane, tri) in tris.iter().enumerate() {
                let Some(exact) = tri.and_then(|tri| plane_hit_f64(o, d, tri)) else {
                    continue;
                };
                let (t, b1, b2) = exact;
                let inside = b1.min(b2).min(1.0 - b1 - b2);
                let within = t.min(t_max as f64 - t);
                if inside.abs() < margin || within.abs() < margin {
                    ambiguous = true;
                } else if inside > 0.0 && within > 0.0 && expected.is_none_or(|e| t < e.1) {
                    expected = Some((lane, t, b1, b2));
                }
            }
            let fast = block.closest::<false>(o, d, t_max, || None);
            assert_eq!(block.any::<false>(o, d, t_max, || false), fast.is_some());
            let fallback = || exact.closest_exact(o, d, t_max);
            let guarded = block.closest::<true>(o, d, t_max, fallback);
            let any = block.any::<true>(o, d, t_max, || fallback().is_some());
            assert_eq!(any, guarded.is_some());
            if ambiguous {
                continue;
            }
            for got in [fast, guarded] {
                match (got, expected) {
                    (None, None) => misses += 1,
                    (Some((lane, t, b1, b2)), Some((l, te, b1e, b2e))) => {
                        hits += 1;
                        assert_eq!(lane, l, "{tris:?} {o} {d}");
                        let close = |x: f32, e: f64| (x as f64 - e).abs() < 1e-5 * (1.0 + e.abs());
                        assert!(
                            close(t, te) && close(b1, b1e) && close(b2, b2e),
                            "{tris:?} {o} {d}"
                        );
                    }
                    (got, expected) => panic!("{got:?} against {expected:?}: {tris:?} {o} {d}"),
                }
            }
        }
        assert!(
            hits > 10_000 && misses > 10_000,
            "{hits} hits, {misses} misses"
        );
    }
}
