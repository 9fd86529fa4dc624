//! The point test of METHOD.md section 5 (`F1(q) < tau`) for every layer of a set at once,
//! the layers laid out lane by lane: the same arithmetic as [`super::Worley::any_within`],
//! but branch-free (each lane tests its own cell and the nearer neighbouring column, row and
//! corner, which for `tau <= 1/2` are all the cells the disc can touch), so that the compiler
//! runs eight layers in one vector. Hits from inside glass with dielectric walls make this
//! test at every bounce (`scratched`), where it is most of what scratches cost.
//!
//! The capsule test ([`PointLanes::capsule_mask`]) asks the same of a segment: whether some
//! scratch of the layer comes within `tau` of it in noise space (a feature point within the
//! capsule), for segments short enough that the capsule's box spans at most two cells per
//! axis (longer ones are split): the four cells from the box's lower corner.

use super::layer::{ScratchLayer, CENTRE};
use super::worley::{cell_offset, floor_pair};
use glam::DVec2;

/// Layers a group tests together.
const LANES: usize = 8;

/// The most pieces [`PointLanes::capsule_mask`] splits a segment into.
const MAX_PIECES: usize = 64;

/// Eight layers' noise maps and hash keys; a lane that is not tested here has `r2 = -1`.
#[derive(Clone, Debug)]
struct Group {
    /// Rows of each layer's `M` ([`ScratchLayer::to_noise`]): `m00, m01, m10, m11`.
    m: [[f64; LANES]; 4],
    key: [u64; LANES],
    mask: [i64; LANES],
    r2: [f64; LANES],
    tau: [f64; LANES],
}

/// The lane-wise point test of a set's layers (see the module notes).
#[derive(Clone, Debug)]
pub struct PointLanes {
    groups: Vec<Group>,
    /// Layers the lanes do not take (a direction per scratch, or `tau > 1/2`): tested one by
    /// one.
    others: Vec<usize>,
}

impl PointLanes {
    pub fn new(layers: &[ScratchLayer]) -> Self {
        let mut groups = vec![
            Group {
                m: [[0.0; LANES]; 4],
                key: [0; LANES],
                mask: [0; LANES],
                r2: [-1.0; LANES],
                tau: [0.0; LANES],
            };
            layers.len().div_ceil(LANES)
        ];
        let mut others = Vec::new();
        for (k, layer) in layers.iter().enumerate() {
            let tau = layer.threshold();
            if layer.random().is_some() || tau > 0.5 {
                others.push(k);
                continue;
            }
            let (g, lane) = (&mut groups[k / LANES], k % LANES);
            let m = layer.noise_matrix();
            for (row, v) in [m[0].x, m[0].y, m[1].x, m[1].y].into_iter().enumerate() {
                g.m[row][lane] = v;
            }
            (g.key[lane], g.mask[lane]) = layer.noise().hash_key();
            g.r2[lane] = tau * tau;
            g.tau[lane] = tau;
        }
        PointLanes { groups, others }
    }

    /// Bit `k` set where layer `k` is scratched at `uv` ([`ScratchLayer::is_scratched`], the
    /// same answer).
    #[inline(always)]
    pub fn mask(&self, uv: DVec2, layers: &[ScratchLayer]) -> u64 {
        let d = uv - CENTRE;
        let mut out = 0u64;
        for (g, group) in self.groups.iter().enumerate() {
            let mut hit = [false; LANES];
            for (lane, h) in hit.iter_mut().enumerate() {
                *h = group.lane_hit(lane, d);
            }
            for (lane, &h) in hit.iter().enumerate() {
                out |= (h as u64) << (g * LANES + lane);
            }
        }
        for &k in &self.others {
            out |= (layers[k].is_scratched_at(uv) as u64) << k;
        }
        out
    }

    /// Bit `k` set where a scratch of layer `k` may come within reach of the texture segment
    /// from `uv` to `uv + v`: exactly (a feature point within `tau` of it in noise space) for
    /// the lanes' layers and segments within [`MAX_PIECES`] pieces, always for the others.
    #[inline(always)]
    pub fn capsule_mask(&self, uv: DVec2, v: DVec2) -> u64 {
        let d = uv - CENTRE;
        let mut out = 0u64;
        for (g, group) in self.groups.iter().enumerate() {
            // Pieces short enough that each capsule's box spans at most two cells per axis;
            // a lane that would need more than `MAX_PIECES` (a segment across many cells, or
            // `tau` near 1/2) may be reached.
            let mut need = [0.0f64; LANES];
            for (lane, n) in need.iter_mut().enumerate() {
                let (qx, qy) = group.to_noise(lane, v);
                *n = qx.abs().max(qy.abs()) / (0.999 - 2.0 * group.tau[lane]);
            }
            let most = need
                .iter()
                .filter(|&&n| n <= MAX_PIECES as f64)
                .fold(1.0f64, |m, &n| m.max(n));
            let pieces = most.ceil() as usize;
            let step = v / pieces as f64;
            let mut hit = [false; LANES];
            for piece in 0..pieces {
                let start = d + step * piece as f64;
                for (lane, h) in hit.iter_mut().enumerate() {
                    *h |= group.lane_capsule(lane, start, step);
                }
            }
            for (lane, &h) in hit.iter().enumerate() {
                let split = need[lane] <= MAX_PIECES as f64;
                let maybe = !split && group.r2[lane] >= 0.0;
                out |= ((h || maybe) as u64) << (g * LANES + lane);
            }
        }
        for &k in &self.others {
            out |= 1 << k;
        }
        out
    }
}

impl Group {
    /// The offset of lane `lane`'s feature point inside cell `(i, j)`, in `[0, 1)^2`.
    #[inline(always)]
    fn offset(&self, lane: usize, i: i64, j: i64) -> (f64, f64) {
        cell_offset(self.key[lane], self.mask[lane], i, j)
    }

    /// Lane `lane`'s linear map to noise space (`M v`).
    #[inline(always)]
    fn to_noise(&self, lane: usize, v: DVec2) -> (f64, f64) {
        (
            self.m[0][lane] * v.x + self.m[1][lane] * v.y,
            self.m[2][lane] * v.x + self.m[3][lane] * v.y,
        )
    }

    /// Whether a feature point of lane `lane`'s layer lies within `tau` of the segment from
    /// texture offset `d` (`uv - CENTRE`) along `v`, whose capsule's box spans at most two
    /// cells per axis.
    #[inline(always)]
    fn lane_capsule(&self, lane: usize, d: DVec2, v: DVec2) -> bool {
        let (ax, ay) = self.to_noise(lane, d);
        let (vx, vy) = self.to_noise(lane, v);
        let tau = self.tau[lane];
        let ((fi, i), (fj, j)) = (
            floor_pair(ax.min(ax + vx) - tau),
            floor_pair(ay.min(ay + vy) - tau),
        );
        let (fx, fy) = (ax - fi, ay - fj);
        let vv = vx * vx + vy * vy;
        let inv = if vv > 0.0 { 1.0 / vv } else { 0.0 };
        let r2 = self.r2[lane];
        let near = |a: i64, b: i64| {
            // The feature point relative to the segment's start, then its nearest point.
            let (ox, oy) = self.offset(lane, i + a, j + b);
            let (px, py) = (a as f64 + ox - fx, b as f64 + oy - fy);
            let t = ((px * vx + py * vy) * inv).clamp(0.0, 1.0);
            let (ex, ey) = (px - t * vx, py - t * vy);
            ex * ex + ey * ey < r2
        };
        near(0, 0) | near(1, 0) | near(0, 1) | near(1, 1)
    }

    /// Whether lane `lane`'s layer is scratched at texture offset `d = uv - CENTRE`.
    #[inline(always)]
    fn lane_hit(&self, lane: usize, d: DVec2) -> bool {
        let (qx, qy) = self.to_noise(lane, d);
        let ((fi, i), (fj, j)) = (floor_pair(qx), floor_pair(qy));
        let (fx, fy) = (qx - fi, qy - fj);
        // The nearer neighbouring column and row, as integers and as floats.
        let side = |f: f64| if f < 0.5 { (-1, -1.0) } else { (1, 1.0) };
        let ((di, dfi), (dj, dfj)) = (side(fx), side(fy));
        let r2 = self.r2[lane];
        let near = |(a, af): (i64, f64), (b, bf): (i64, f64)| {
            let (ox, oy) = self.offset(lane, i + a, j + b);
            let (px, py) = (af + ox - fx, bf + oy - fy);
            px * px + py * py < r2
        };
        let (o, x, y) = ((0, 0.0), (di, dfi), (dj, dfj));
        near(o, o) | near(x, o) | near(o, y) | near(x, y)
    }
}
