//! Anti-aliased rasters of a scratch layer, for people and other tools (METHOD.md section 5,
//! the seed's Fig. 4): texel value = the exact fraction of the texel the layer's scratches
//! cover, so scratches thinner than a texel still show, plus a box-filtered mip chain of that
//! coverage, PNG encoding, the combined direction-tinted picture and the stages of Fig. 4.
//!
//! Pixel mapping (the same everywhere): texel `(x, y)` of an `R x R` raster, column `x`, row `y`
//! with row 0 at the top, covers `u in [x/R, (x+1)/R]`, `v in [1 - (y+1)/R, 1 - y/R]`.
//!
//! The rasteriser scatters: it lists the scratches (feature points) whose ellipse reaches
//! `[0, 1]^2`, then for each band of rows, in parallel, adds every scratch's exact disc-texel
//! overlap (in noise space, [`super::footprint`]) to the texels its ellipse can touch. Texels
//! touched by a scratch that overlaps another scratch are recomputed as an exact union. Each
//! texel's value depends only on the layer, never on the thread count.

use super::footprint::union_discs_polygon_area;
use super::layer::ScratchLayer;
use super::LayerError;
use glam::DVec2;
use rayon::prelude::*;

/// Largest raster side the library accepts.
pub const MAX_RESOLUTION: usize = 16384;
/// Most noise cells a rasteriser will enumerate (about twice the number of scratches).
pub const MAX_RASTER_CELLS: f64 = 2.0e8;
/// Rows per parallel work item.
const BAND: usize = 16;

/// The memory `striae layers` takes for `layers` rasters of side `res` (with `stages`, the
/// stages of Fig. 4 too): per texel, one layer's coverage and mip chain (5.3 bytes), the
/// combined image (12), the PNG being encoded (2) and, per layer, its encoded PNG held until
/// all are written (up to 1); 6 more with the stages. Measured as the peak resident size
/// (`/usr/bin/time -f %M`) of `striae layers --setting 1`: 317 MB at `--res 4096`, 1231 MB at
/// `--res 8192` (18.6 bytes a texel between them), 395 MB at `--res 4096 --layers 8`.
pub fn images_bytes(res: usize, layers: usize, stages: bool) -> u64 {
    let per_texel = 19 + layers as u64 + if stages { 6 } else { 0 };
    (res as u64 * res as u64).saturating_mul(per_texel)
}

/// The memory of `layers` coverage masks of side `res` as one `(K, R, R)` float array (the
/// Python bindings' `LayerSet.masks`): 4 bytes a texel a layer, and one layer's raster and
/// mip chain being computed (6).
pub fn masks_bytes(res: usize, layers: usize) -> u64 {
    (res as u64 * res as u64).saturating_mul(4 * layers as u64 + 6)
}

/// The centre of texel `(x, y)` of an `res x res` raster, in texture space.
#[inline]
pub fn texel_centre(res: usize, x: usize, y: usize) -> DVec2 {
    let r = res as f64;
    DVec2::new((x as f64 + 0.5) / r, 1.0 - (y as f64 + 0.5) / r)
}

/// Check a raster side: at least 1 and at most [`MAX_RESOLUTION`].
pub fn check_resolution(res: usize) -> Result<(), LayerError> {
    if res == 0 {
        return Err(LayerError::Resolution {
            res,
            reason: "it must be at least 1".into(),
        });
    }
    if res > MAX_RESOLUTION {
        let gib = (res as f64).powi(2) * 4.0 * 4.0 / 3.0 / (1u64 << 30) as f64;
        return Err(LayerError::Resolution {
            res,
            reason: format!("the largest is {MAX_RESOLUTION} (one layer's coverage and mips alone would take {gib:.1} GiB)"),
        });
    }
    Ok(())
}

/// A layer's coverage raster and its mip chain. Level 0 is `res x res`; level `l + 1` has side
/// `ceil(side_l / 2)` and averages the (up to four) texels below each of its texels; the last
/// level is `1 x 1`. Rows are stored top (v = 1) first.
#[derive(Clone, Debug, PartialEq)]
pub struct CoverageRaster {
    levels: Vec<(usize, Vec<f32>)>,
}

impl CoverageRaster {
    /// Build from a level-0 coverage image (row-major, `res * res` values in `[0, 1]`).
    pub fn from_coverage(res: usize, data: Vec<f32>) -> Self {
        assert_eq!(data.len(), res * res);
        let mut levels = vec![(res, data)];
        while levels.last().unwrap().0 > 1 {
            let (n, src) = levels.last().unwrap();
            let n = *n;
            let m = n.div_ceil(2);
            let mut dst = vec![0.0f32; m * m];
            for y in 0..m {
                for x in 0..m {
                    let (mut s, mut c) = (0.0f32, 0.0f32);
                    for (yy, xx) in [
                        (2 * y, 2 * x),
                        (2 * y, 2 * x + 1),
                        (2 * y + 1, 2 * x),
                        (2 * y + 1, 2 * x + 1),
                    ] {
                        if yy < n && xx < n {
                            s += src[yy * n + xx];
                            c += 1.0;
                        }
                    }
                    dst[y * m + x] = s / c;
                }
            }
            levels.push((m, dst));
        }
        CoverageRaster { levels }
    }

    /// Side of level 0.
    pub fn res(&self) -> usize {
        self.levels[0].0
    }

    /// Number of mip levels (down to 1 x 1).
    pub fn level_count(&self) -> usize {
        self.levels.len()
    }

    /// Mip level `l`: its side and its row-major coverage.
    pub fn level(&self, l: usize) -> (usize, &[f32]) {
        let (n, d) = &self.levels[l];
        (*n, d)
    }

    /// Coverage of texel `(x, y)` of level 0.
    pub fn get(&self, x: usize, y: usize) -> f32 {
        self.levels[0].1[y * self.res() + x]
    }

    /// Mean coverage of the texture (the measured coverage), summed in `f64`.
    pub fn mean(&self) -> f64 {
        let d = &self.levels[0].1;
        d.iter().map(|&c| c as f64).sum::<f64>() / d.len() as f64
    }

    /// Level 0 as an 8-bit grey PNG (white = scratch, value `round(255 c)`, linear).
    pub fn to_png(&self) -> Result<Vec<u8>, LayerError> {
        let (n, d) = self.level(0);
        encode_png(n, &to_u8(d), 1, "a coverage raster")
    }
}

/// `[0, 1]` values to bytes.
pub fn to_u8(d: &[f32]) -> Vec<u8> {
    d.iter()
        .map(|&c| (c.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect()
}

/// Encode a square 8-bit image with 1 (grey) or 3 (RGB) channels as PNG bytes.
pub fn encode_png(
    n: usize,
    bytes: &[u8],
    channels: usize,
    what: &str,
) -> Result<Vec<u8>, LayerError> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    let ty = if channels == 3 {
        image::ExtendedColorType::Rgb8
    } else {
        image::ExtendedColorType::L8
    };
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(bytes, n as u32, n as u32, ty)
        .map_err(|e| LayerError::Png {
            what: what.into(),
            msg: e.to_string(),
        })?;
    Ok(out)
}

/// The tint of a direction: fully saturated hue `alpha / 2 pi` (red at 0, green at 2 pi/3, ...).
pub fn direction_tint(alpha: f64) -> [f32; 3] {
    let h = (alpha.rem_euclid(std::f64::consts::TAU) / std::f64::consts::TAU * 6.0) as f32;
    let f = |n: f32| {
        let k = (n + h) % 6.0;
        1.0 - (k.min(4.0 - k).clamp(0.0, 1.0))
    };
    [f(5.0), f(3.0), f(1.0)]
}

/// Accumulates the combined picture: every layer tinted by its direction, composited with a
/// "screen" blend, `rgb = 1 - prod_k (1 - c_k tint_k)`, so crossings brighten and nothing clips.
pub struct CombinedImage {
    res: usize,
    /// `prod_k (1 - c_k tint_k)` per texel and channel.
    dark: Vec<f32>,
}

impl CombinedImage {
    /// An image of side `res`, or an error where the allocator refuses it.
    pub fn new(res: usize) -> Result<Self, LayerError> {
        Ok(CombinedImage {
            res,
            dark: crate::memory::try_alloc_vec(3 * res * res, 1.0, "the combined layers image")?,
        })
    }

    pub fn add(&mut self, raster: &CoverageRaster, alpha: f64) {
        assert_eq!(raster.res(), self.res);
        let t = direction_tint(alpha);
        let (_, d) = raster.level(0);
        self.dark
            .par_chunks_mut(3)
            .zip(d.par_iter())
            .for_each(|(px, &c)| {
                for ch in 0..3 {
                    px[ch] *= 1.0 - c * t[ch];
                }
            });
    }

    pub fn to_png(&self) -> Result<Vec<u8>, LayerError> {
        let bytes: Vec<u8> = self
            .dark
            .iter()
            .map(|&d| ((1.0 - d).clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        encode_png(self.res, &bytes, 3, "the combined layers image")
    }
}

/// Stage (a) of Fig. 4: the layer's cell noise before rotation and stretch, shown at the same
/// density of feature points as the final layer (`q = (p - c) / sqrt(L W)`). Grey level
/// `1 - min(F1, 1)`: feature points bright, cell borders dark.
pub fn stage_noise(layer: &ScratchLayer, res: usize) -> Result<Vec<f32>, LayerError> {
    check_resolution(res)?;
    let (hl, hw) = layer.half_axes();
    let scale = 1.0 / (hl * hw / (layer.threshold() * layer.threshold())).sqrt();
    per_texel(res, |p| {
        1.0 - layer
            .noise()
            .eval((p - super::layer::CENTRE) * scale)
            .f1
            .min(1.0)
    })
}

/// Stage (b) of Fig. 4: the same noise after rotation by `alpha` and stretch by `(L, W)`, i.e.
/// `1 - min(F1(q(p)), 1)` sampled at texel centres. Stage (c) is its threshold `F1 < tau`,
/// which is the anti-aliased coverage raster ([`rasterize`]).
pub fn stage_stretched(layer: &ScratchLayer, res: usize) -> Result<Vec<f32>, LayerError> {
    check_resolution(res)?;
    per_texel(res, |p| 1.0 - layer.noise_at(p).f1.min(1.0))
}

/// A raster of side `res`, or an error where the allocator refuses it.
fn raster_of(res: usize) -> Result<Vec<f32>, LayerError> {
    let what = format!("a {res} x {res} layer raster");
    Ok(crate::memory::try_alloc_vec(res * res, 0.0f32, &what)?)
}

fn per_texel(res: usize, f: impl Fn(DVec2) -> f64 + Sync) -> Result<Vec<f32>, LayerError> {
    let mut out = raster_of(res)?;
    out.par_chunks_mut(res).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            *o = f(texel_centre(res, x, y)) as f32;
        }
    });
    Ok(out)
}

/// One scratch that reaches the texture: its feature point in noise and texture space.
struct Scratch {
    q: DVec2,
    p: DVec2,
    /// Overlaps another scratch (their union needs the exact treatment).
    clustered: bool,
}

/// Rasterise `layer` at `res x res` with exact per-texel coverage (see the module doc). Where a
/// texel holds more overlapping scratches than the exact union takes (only at tiny resolutions),
/// it keeps the sum of their areas, clamped to 1.
pub fn rasterize(layer: &ScratchLayer, res: usize) -> Result<CoverageRaster, LayerError> {
    check_resolution(res)?;
    if let Some(r) = layer.random() {
        // Randomly oriented scratches: each texel's exact coverage.
        let t = 1.0 / res as f64;
        let (a, b) = (DVec2::new(t, 0.0), DVec2::new(0.0, t));
        let data = per_texel(res, |p| {
            r.coverage(p, a, b, usize::MAX)
                .unwrap_or_else(|| r.is_scratched(p) as u8 as f64)
        })?;
        return Ok(CoverageRaster::from_coverage(res, data));
    }
    let shape = EllipseShape::of(layer);
    let scratches = reaching_scratches(layer, res, &shape)?;
    let r = res as f64;
    let bands = res.div_ceil(BAND);
    let mut lists: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (k, s) in scratches.iter().enumerate() {
        let (y0, y1) = shape.row_range(s, res);
        if y0 > y1 {
            continue;
        }
        for list in &mut lists[y0 / BAND..=y1 / BAND] {
            list.push(k as u32);
        }
    }
    let texel = TexelShape::of(layer, r);
    let mut data = raster_of(res)?;
    data.par_chunks_mut(BAND * res)
        .enumerate()
        .for_each(|(b, chunk)| {
            let band = Band {
                layer,
                res,
                first_row: b * BAND,
                shape: &shape,
                texel: &texel,
            };
            band.rasterize(&lists[b], &scratches, chunk);
        });
    Ok(CoverageRaster::from_coverage(res, data))
}

/// A layer's scratch ellipse in texture space: its extents, and its horizontal chords (with
/// the quadratic form `Q = M^T M / tau^2`, the chord at height `dv` is centred at
/// `du = k_chord dv`, half-width at most `h0`).
struct EllipseShape {
    ex: f64,
    ey: f64,
    k_chord: f64,
    h0: f64,
}

impl EllipseShape {
    fn of(layer: &ScratchLayer) -> Self {
        let tau = layer.threshold();
        let (hl, hw) = layer.half_axes();
        let [du, dv] = layer.direction();
        let mx = layer.vector_to_noise(DVec2::X);
        let my = layer.vector_to_noise(DVec2::Y);
        let (q11, q12) = (mx.length_squared() / (tau * tau), mx.dot(my) / (tau * tau));
        EllipseShape {
            ex: ((hl * du).powi(2) + (hw * dv).powi(2)).sqrt(),
            ey: ((hl * dv).powi(2) + (hw * du).powi(2)).sqrt(),
            k_chord: -q12 / q11,
            h0: 1.0 / q11.sqrt(),
        }
    }

    /// The texel rows `y0..=y1` that scratch `s` can touch (empty when `y0 > y1`).
    fn row_range(&self, s: &Scratch, res: usize) -> (usize, usize) {
        let r = res as f64;
        let y0 = ((1.0 - (s.p.y + self.ey)) * r).floor().max(0.0) as usize;
        let y1 = (((1.0 - (s.p.y - self.ey)) * r).floor().max(0.0) as usize).min(res - 1);
        (y0, y1)
    }
}

/// The scratches of `layer` whose ellipse reaches the texture square, each marked when it
/// overlaps another. Refuses layers with more than [`MAX_RASTER_CELLS`] cells to enumerate.
fn reaching_scratches(
    layer: &ScratchLayer,
    res: usize,
    shape: &EllipseShape,
) -> Result<Vec<Scratch>, LayerError> {
    let tau = layer.threshold();
    let noise = layer.noise();
    // Cells whose disc can reach the texture square: its noise-space bounding box plus tau.
    let corners = [DVec2::ZERO, DVec2::X, DVec2::ONE, DVec2::Y].map(|p| layer.to_noise(p));
    let lo = corners
        .iter()
        .fold(DVec2::splat(f64::INFINITY), |m, c| m.min(*c))
        - tau;
    let hi = corners
        .iter()
        .fold(DVec2::splat(f64::NEG_INFINITY), |m, c| m.max(*c))
        + tau;
    let (i0, i1, j0, j1) = (lo.x.floor(), hi.x.floor(), lo.y.floor(), hi.y.floor());
    let cells = (i1 - i0 + 1.0) * (j1 - j0 + 1.0);
    if cells > MAX_RASTER_CELLS {
        return Err(LayerError::Resolution {
            res,
            reason: format!("the layer has about {cells:.2e} noise cells to enumerate (scratches too small for a raster; the most is {MAX_RASTER_CELLS:.0e})"),
        });
    }
    let (ex, ey) = (shape.ex, shape.ey);
    let reach = (2.0 * tau).ceil() as i64;
    let mut scratches = Vec::new();
    for j in j0 as i64..=j1 as i64 {
        for i in i0 as i64..=i1 as i64 {
            let q = noise.feature_point(i, j);
            let p = layer.to_texture(q);
            if p.x + ex < 0.0 || p.x - ex > 1.0 || p.y + ey < 0.0 || p.y - ey > 1.0 {
                continue;
            }
            let mut clustered = false;
            'n: for dj in -reach..=reach {
                for di in -reach..=reach {
                    if (di, dj) != (0, 0)
                        && (noise.feature_point(i + di, j + dj) - q).length_squared()
                            < 4.0 * tau * tau
                    {
                        clustered = true;
                        break 'n;
                    }
                }
            }
            scratches.push(Scratch { q, p, clustered });
        }
    }
    Ok(scratches)
}

/// One texel in noise space: a parallelogram around its centre, its edges' half-planes
/// `(n, d)` (`n . x <= d` inside) and its area.
struct TexelShape {
    poly: [DVec2; 4],
    planes: [(DVec2, f64); 4],
    area: f64,
}

impl TexelShape {
    fn of(layer: &ScratchLayer, r: f64) -> Self {
        let (ta, tb) = (
            layer.vector_to_noise(DVec2::X) / r,
            layer.vector_to_noise(DVec2::Y) / r,
        );
        let poly = [
            (-ta - tb) * 0.5,
            (ta - tb) * 0.5,
            (ta + tb) * 0.5,
            (tb - ta) * 0.5,
        ];
        let mut planes = [(DVec2::ZERO, 0.0f64); 4];
        for e in 0..4 {
            let d = poly[(e + 1) % 4] - poly[e];
            let n = DVec2::new(d.y, -d.x).normalize();
            planes[e] = (n, n.dot(poly[e]));
        }
        TexelShape {
            poly,
            planes,
            area: ta.perp_dot(tb),
        }
    }

    /// The area of the disc of radius `tau` about `c` (relative to the texel's centre) inside
    /// the texel: the whole disc or the exact clipped area; `None` where the disc stays clear
    /// of the texel's edges' half-planes.
    fn disc_area(&self, c: DVec2, tau: f64) -> Option<f64> {
        let mut inside = true;
        for &(n, d) in &self.planes {
            let sd = d - n.dot(c);
            if sd <= -tau {
                return None;
            }
            inside &= sd >= tau;
        }
        Some(if inside {
            std::f64::consts::PI * tau * tau
        } else {
            union_discs_polygon_area(&[c], tau, &self.poly)
        })
    }
}

/// The rows of one band of the raster and what rasterising them needs.
struct Band<'a> {
    layer: &'a ScratchLayer,
    res: usize,
    first_row: usize,
    shape: &'a EllipseShape,
    texel: &'a TexelShape,
}

impl Band<'_> {
    /// Coverage of the band's texels (`chunk`, rows of `res`) by the scratches `list` of
    /// `scratches`: the sum of each disc's exact area in a texel, replaced by the exact union
    /// where overlapping scratches meet.
    fn rasterize(&self, list: &[u32], scratches: &[Scratch], chunk: &mut [f32]) {
        let (res, r, tau) = (self.res, self.res as f64, self.layer.threshold());
        let rows = chunk.len() / res;
        let mut acc = vec![0.0f64; chunk.len()];
        let mut needs_union = vec![false; chunk.len()];
        for &k in list {
            let s = &scratches[k as usize];
            let (y0, y1) = self.shape.row_range(s, res);
            for y in y0.max(self.first_row)..=y1.min(self.first_row + rows - 1) {
                // The slab of this row, clipped to the ellipse's v-range, gives the chord centres.
                let (vb, vt) = (1.0 - (y + 1) as f64 / r, 1.0 - y as f64 / r);
                let dv0 = (vb - s.p.y).max(-self.shape.ey);
                let dv1 = (vt - s.p.y).min(self.shape.ey);
                let (ca, cb) = (self.shape.k_chord * dv0, self.shape.k_chord * dv1);
                let u0 = s.p.x + ca.min(cb) - self.shape.h0;
                let u1 = s.p.x + ca.max(cb) + self.shape.h0;
                if u1 < 0.0 || u0 > 1.0 {
                    continue;
                }
                let x0 = (u0 * r).floor().max(0.0) as usize;
                let x1 = ((u1 * r).floor() as usize).min(res - 1);
                let row = (y - self.first_row) * res;
                for x in x0..=x1 {
                    let c = s.q - self.layer.to_noise(texel_centre(res, x, y));
                    if let Some(a) = self.texel.disc_area(c, tau) {
                        acc[row + x] += a;
                        needs_union[row + x] |= s.clustered;
                    }
                }
            }
        }
        for (k, (o, &a)) in chunk.iter_mut().zip(&acc).enumerate() {
            let mut v = a / self.texel.area;
            if needs_union[k] {
                let (x, y) = (k % res, self.first_row + k / res);
                if let Some(exact) = self.layer.footprint_coverage(
                    texel_centre(res, x, y),
                    DVec2::X / r,
                    DVec2::Y / r,
                    usize::MAX,
                ) {
                    v = exact;
                }
            }
            *o = v.clamp(0.0, 1.0) as f32;
        }
    }
}
