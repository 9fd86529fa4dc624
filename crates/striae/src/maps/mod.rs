//! Painted scratch maps (METHOD.md 9.5): an image laid on uv as image textures are (row 0 at
//! `v = 0`, texel centres at `(i + 1/2) / size`, repeating), each texel the scratched fraction in
//! `[0, 1]`, with a scratch direction per texel from a flow map (glTF's
//! `KHR_materials_anisotropy` convention: `direction = 2 rg - 1`, `x` along `dP/du`, `y` along
//! `dP/dv`) or, without one, from the map's own structure (the minor eigenvector of its smoothed
//! structure tensor: the direction along which the map varies least, along the painted stroke).
//!
//! Prefiltered: a MIP pyramid ([`ScratchMap::levels`]) of the coverage `c` and of the
//! direction as a doubled-angle orientation vector weighted by coverage, `c (cos 2 theta, sin 2
//! theta)`, so that a scratch and its reverse (the same groove) add up and perpendicular ones
//! cancel; each texel of a level is the mean of its four children. A lookup over a pixel
//! footprint ([`ScratchMap::filtered`]) is trilinear: bilinear in the two levels around `log2`
//! of the footprint's longer edge in texels, interpolated between them. A map knows no
//! crossings (METHOD.md 9.5): at a hit it is one source of one lobe, whose coverage is the
//! filtered fraction and whose direction the filtered orientation ([`MapSample`]).
//!
//! This module takes decoded pixels; `render::scene::scratches` reads the files (8- and 16-bit
//! PNG read linear, not sRGB-decoded, or EXR) and names them in errors.

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use crate::math::Vec2;

/// The structure tensor's smoothing at the finest level: a Gaussian of this standard deviation
/// (texels), cut at 3 of them, in each direction; coarser scales come from the tensor's own
/// pyramid ([`structure_orientations`]).
const TENSOR_SIGMA: f32 = 2.0;
const TENSOR_RADIUS: usize = 6;

/// A tensor whose trace is below this fraction of the finest level's largest trace carries no
/// direction: the texel takes the next coarser level's tensor ([`structure_orientations`]).
const TENSOR_FLOOR: f32 = 1e-4;

/// Errors of a scratch map's pixels: each names the image (`map` or `direction`) and the pixel.
#[derive(Debug, thiserror::Error)]
pub enum MapError {
    #[error("{image}: pixel ({x}, {y}) holds {value:?}: {why}")]
    Pixel {
        image: &'static str,
        x: usize,
        y: usize,
        value: f32,
        why: &'static str,
    },
    #[error("{image}: {width} x {height} pixels: {why}")]
    Size {
        image: &'static str,
        width: usize,
        height: usize,
        why: String,
    },
    #[error("map_scale = {0:?}: must be finite and > 0")]
    Scale(f64),
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
}

/// In which frame a map's directions are given, which decides how a lobe carries them to 3D.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DirectionFrame {
    /// Texture space `(u, v)`, carried by `d.x dP/du + d.y dP/dv` (the structure tensor's
    /// directions, the level sets of the map on uv).
    Uv,
    /// The unit tangents: `d.x dP/du / |dP/du| + d.y dP/dv / |dP/dv|` (a flow map, as glTF's
    /// `KHR_materials_anisotropy` reads its direction in the tangent frame).
    Tangent,
}

/// One level of the pyramid: per texel `[c, c cos 2 theta, c sin 2 theta]`, row-major, row 0
/// at `v = 0`.
#[derive(Clone, Debug, PartialEq)]
pub struct Level {
    pub width: usize,
    pub height: usize,
    pub texels: Vec<[f32; 3]>,
}

impl Level {
    /// Texel `(x, y)`, both indices wrapped (the map repeats, as image textures do).
    #[inline]
    pub fn texel(&self, x: i64, y: i64) -> [f32; 3] {
        let x = x.rem_euclid(self.width as i64) as usize;
        let y = y.rem_euclid(self.height as i64) as usize;
        self.texels[y * self.width + x]
    }

    /// Bilinear lookup at `uv` (texel centres at `(i + 1/2) / size`, wrapping), as
    /// `render::texture`'s images.
    #[inline]
    fn bilinear(&self, uv: Vec2) -> [f32; 3] {
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        if !(x.is_finite() && y.is_finite()) {
            return [0.0; 3];
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let lerp = |a: [f32; 3], b: [f32; 3], t: f32| {
            [
                a[0] + (b[0] - a[0]) * t,
                a[1] + (b[1] - a[1]) * t,
                a[2] + (b[2] - a[2]) * t,
            ]
        };
        let a = lerp(self.texel(x0, y0), self.texel(x0 + 1, y0), fx);
        let b = lerp(self.texel(x0, y0 + 1), self.texel(x0 + 1, y0 + 1), fx);
        lerp(a, b, fy)
    }

    /// The next coarser level: each texel the mean of its four children `(2i + {0, 1}, 2j +
    /// {0, 1})`; an odd size rounds up, its last column (row) of children clamped to the edge
    /// (so that texel is the mean of two, or one, distinct children).
    fn coarser(&self) -> Result<Level, MapError> {
        let (w, h) = (self.width.div_ceil(2), self.height.div_ceil(2));
        let mut texels = crate::memory::try_alloc_vec(w * h, [0.0f32; 3], "a scratch map level")?;
        for j in 0..h {
            for i in 0..w {
                let mut sum = [0.0f32; 3];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let x = (2 * i + dx).min(self.width - 1);
                    let y = (2 * j + dy).min(self.height - 1);
                    let t = self.texels[y * self.width + x];
                    for k in 0..3 {
                        sum[k] += t[k];
                    }
                }
                texels[j * w + i] = sum.map(|s| 0.25 * s);
            }
        }
        Ok(Level {
            width: w,
            height: h,
            texels,
        })
    }
}

/// A map's value over a footprint: the scratched fraction and the orientation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapSample {
    /// The filtered scratched fraction, in `[0, 1]`.
    pub coverage: f32,
    /// The filtered doubled-angle orientation per unit coverage, `mean(c (cos 2 theta, sin 2
    /// theta)) / mean(c)`: its length is the anisotropy (1 where every scratch of the footprint
    /// runs one way, 0 where they cancel), its angle `2 theta` of the mean direction.
    pub orientation: Vec2,
}

impl MapSample {
    /// From a pyramid value `[c, c cos 2 theta, c sin 2 theta]`.
    #[inline]
    fn from_texel(t: [f32; 3]) -> MapSample {
        let c = t[0];
        if !(c > 0.0) {
            return MapSample {
                coverage: 0.0,
                orientation: Vec2::ZERO,
            };
        }
        let o = Vec2::new(t[1], t[2]) / c;
        let len = o.length();
        MapSample {
            coverage: c.min(1.0),
            // (Rounding may take it a hair past 1.)
            orientation: if len > 1.0 { o / len } else { o },
        }
    }

    /// Between 0 (isotropic: directions cancel) and 1 (one direction).
    #[inline]
    pub fn anisotropy(&self) -> f32 {
        self.orientation.length()
    }

    /// The mean direction, `(cos theta, sin theta)` with `theta = atan2(o.y, o.x) / 2` in
    /// `(-pi/2, pi/2]` (a scratch has no sign); `(1, 0)` where the orientation is zero.
    #[inline]
    pub fn direction(&self) -> Vec2 {
        direction_of(self.orientation)
    }

    /// A direction for one hit, drawn by `u` in `[0, 1)`: the mean direction with probability
    /// [`Self::anisotropy`] `a`, else a uniformly random one. Over hits, the drawn directions'
    /// doubled-angle mean is the filtered orientation: a footprint whose scratches run every
    /// way renders as scratches of every direction, not as one.
    #[inline]
    pub fn draw_direction(&self, u: f32) -> Vec2 {
        let a = self.anisotropy();
        if u < a {
            return self.direction();
        }
        // `u` uniform in `[a, 1)`: rescaled to an angle in `[0, pi)`.
        let t = ((u - a) / (1.0 - a)).clamp(0.0, 1.0);
        let (s, c) = (std::f32::consts::PI * t).sin_cos();
        Vec2::new(c, s)
    }
}

/// The direction of the doubled-angle vector `o`: `(cos theta, sin theta)`, `2 theta = atan2(o.y,
/// o.x)`; `(1, 0)` for a zero (or non-finite) vector.
#[inline]
pub fn direction_of(o: Vec2) -> Vec2 {
    if !(o.length_squared() > 0.0) || !o.is_finite() {
        return Vec2::X;
    }
    let (s, c) = (0.5 * o.y.atan2(o.x)).sin_cos();
    Vec2::new(c, s)
}

/// The doubled-angle unit vector `(cos 2 theta, sin 2 theta)` of the direction `d`; zero for a
/// zero (or non-finite) `d`.
#[inline]
pub fn doubled(d: Vec2) -> Vec2 {
    let l2 = d.length_squared();
    if !(l2 > 0.0) || !l2.is_finite() {
        return Vec2::ZERO;
    }
    Vec2::new(d.x * d.x - d.y * d.y, 2.0 * d.x * d.y) / l2
}

/// A flow map texel's direction: `2 rg - 1` (glTF `KHR_materials_anisotropy`), in the tangent
/// frame ([`DirectionFrame::Tangent`]).
#[inline]
pub fn flow_direction(rg: [f32; 2]) -> Vec2 {
    Vec2::new(2.0 * rg[0] - 1.0, 2.0 * rg[1] - 1.0)
}

/// A prefiltered scratch map (see the module notes).
#[derive(Clone, Debug)]
pub struct ScratchMap {
    /// Finest first; the last is 1 x 1.
    levels: Vec<Level>,
    frame: DirectionFrame,
    /// uv tiling: the map is read at `uv * scale`.
    scale: f32,
}

impl ScratchMap {
    /// The map of `coverage` (`width x height` values, row-major, row 0 at `v = 0`, each in
    /// `[0, 1]`) with the directions of the flow map `flow` (`2 rg - 1` per texel, `r` and `g` in
    /// `[0, 1]`, the same size) or, without one, of the map's structure tensor
    /// ([`structure_orientations`]), tiled `scale` times over uv. Errors name the image and
    /// pixel of a value out of range or not finite, a size that is zero or over
    /// [`crate::io::MAX_IMAGE_PIXELS`], a flow map of another size, a bad scale.
    pub fn new(
        width: usize,
        height: usize,
        coverage: &[f32],
        flow: Option<&[[f32; 2]]>,
        scale: f64,
    ) -> Result<ScratchMap, MapError> {
        let size_error = |image, why: String| MapError::Size {
            image,
            width,
            height,
            why,
        };
        if width == 0 || height == 0 {
            return Err(size_error("map", "empty".into()));
        }
        if width as u64 * height as u64 > crate::io::MAX_IMAGE_PIXELS {
            return Err(size_error(
                "map",
                format!("over the limit of {} pixels", crate::io::MAX_IMAGE_PIXELS),
            ));
        }
        if coverage.len() != width * height {
            return Err(size_error(
                "map",
                format!("{} values given", coverage.len()),
            ));
        }
        if !(scale.is_finite() && scale > 0.0 && (scale as f32).is_normal()) {
            return Err(MapError::Scale(scale));
        }
        for (i, &c) in coverage.iter().enumerate() {
            if !(c.is_finite() && (0.0..=1.0).contains(&c)) {
                return Err(MapError::Pixel {
                    image: "map",
                    x: i % width,
                    y: i / width,
                    value: c,
                    why: "a scratched fraction must be finite and in [0, 1]",
                });
            }
        }
        let (orientations, frame) = match flow {
            Some(flow) => {
                if flow.len() != width * height {
                    return Err(MapError::Size {
                        image: "direction",
                        width,
                        height,
                        why: format!(
                            "{} values given: a flow map must have the map's size",
                            flow.len()
                        ),
                    });
                }
                let mut o = crate::memory::try_alloc_vec(
                    width * height,
                    Vec2::ZERO,
                    "a scratch map's orientations",
                )?;
                for (i, rg) in flow.iter().enumerate() {
                    if let Some(&v) = rg
                        .iter()
                        .find(|v| !(v.is_finite() && (0.0..=1.0).contains(*v)))
                    {
                        return Err(MapError::Pixel {
                            image: "direction",
                            x: i % width,
                            y: i / width,
                            value: v,
                            why: "a flow map's R and G must be finite and in [0, 1]",
                        });
                    }
                    o[i] = doubled(flow_direction(*rg));
                }
                (o, DirectionFrame::Tangent)
            }
            None => (
                structure_orientations(width, height, coverage)?,
                DirectionFrame::Uv,
            ),
        };
        let mut texels =
            crate::memory::try_alloc_vec(width * height, [0.0f32; 3], "a scratch map")?;
        for ((t, &c), o) in texels.iter_mut().zip(coverage).zip(&orientations) {
            *t = [c, c * o.x, c * o.y];
        }
        drop(orientations);
        let mut levels = vec![Level {
            width,
            height,
            texels,
        }];
        while let Some(l) = levels.last().filter(|l| l.width > 1 || l.height > 1) {
            let next = l.coarser()?;
            levels.push(next);
        }
        Ok(ScratchMap {
            levels,
            frame,
            scale: scale as f32,
        })
    }

    /// The pyramid, finest first.
    pub fn levels(&self) -> &[Level] {
        &self.levels
    }

    /// The frame its directions are given in.
    pub fn frame(&self) -> DirectionFrame {
        self.frame
    }

    /// The value at `uv` without a footprint: the finest level, bilinear.
    #[inline]
    pub fn at_point(&self, uv: Vec2) -> MapSample {
        MapSample::from_texel(self.levels[0].bilinear(uv * self.scale))
    }

    /// The level a footprint of edges `a`, `b` (uv, one pixel step each) reads, fractional:
    /// `log2` of the longer edge in finest-level texels, clamped to the pyramid.
    #[inline]
    pub fn level_of(&self, a: Vec2, b: Vec2) -> f32 {
        let l0 = &self.levels[0];
        let texels = Vec2::new(l0.width as f32, l0.height as f32) * self.scale;
        let w = (a * texels).length().max((b * texels).length());
        let level = w.log2();
        if !(level > 0.0) {
            return 0.0;
        }
        level.min((self.levels.len() - 1) as f32)
    }

    /// The value over the footprint of edges `a`, `b` centred on `uv`: trilinear, at
    /// [`Self::level_of`] (bilinear in the two levels around it, interpolated).
    #[inline]
    pub fn filtered(&self, uv: Vec2, a: Vec2, b: Vec2) -> MapSample {
        let level = self.level_of(a, b);
        let p = uv * self.scale;
        let i = level.floor() as usize;
        let t = level - i as f32;
        let lo = self.levels[i].bilinear(p);
        if t <= 0.0 || i + 1 >= self.levels.len() {
            return MapSample::from_texel(lo);
        }
        let hi = self.levels[i + 1].bilinear(p);
        MapSample::from_texel([
            lo[0] + (hi[0] - lo[0]) * t,
            lo[1] + (hi[1] - lo[1]) * t,
            lo[2] + (hi[2] - lo[2]) * t,
        ])
    }

    /// Bytes held by the pyramid.
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.texels.len() * 12).sum()
    }
}

/// Each texel's orientation from the map's structure: the doubled-angle unit vector of the
/// minor eigenvector of the structure tensor `J = sum g g^T` of the map's gradient `g` on uv
/// (Scharr's 3 x 3 operator, wrapping), smoothed by a Gaussian of [`TENSOR_SIGMA`] texels. `J`'s anisotropic part
/// `(J_uu - J_vv, 2 J_uv)` is the doubled-angle vector of the major eigenvector (across the
/// stroke); the minor one, along it, is its opposite. Where the smoothed tensor is too weak
/// (its trace below [`TENSOR_FLOOR`] of the largest: inside a stroke wider than the kernel,
/// or in a flat region), the texel takes the tensor of the next coarser level of the tensor's
/// own pyramid (means of four, as the map's), bilinear at its centre, and so on; where every
/// level is too weak, zero (no direction).
pub fn structure_orientations(
    width: usize,
    height: usize,
    coverage: &[f32],
) -> Result<Vec<Vec2>, MapError> {
    let at = |x: i64, y: i64| {
        coverage[y.rem_euclid(height as i64) as usize * width + x.rem_euclid(width as i64) as usize]
    };
    // The gradient on uv, in units of the finest texel of the longer side: `(W df/dx, H df/dy) /
    // max(W, H)`, so that level sets keep their direction on a non-square map.
    let n = width.max(height) as f32;
    let (sx, sy) = (width as f32 / n, height as f32 / n);
    let mut tensor =
        crate::memory::try_alloc_vec(width * height, [0.0f32; 3], "a scratch map's tensor")?;
    for y in 0..height as i64 {
        for x in 0..width as i64 {
            // Scharr's operator: central differences smoothed across by `[3 10 3] / 16`,
            // the 3 x 3 derivative of least directional error.
            let dx = |yy: i64| 0.5 * (at(x + 1, yy) - at(x - 1, yy));
            let dy = |xx: i64| 0.5 * (at(xx, y + 1) - at(xx, y - 1));
            let gx = (3.0 * dx(y - 1) + 10.0 * dx(y) + 3.0 * dx(y + 1)) / 16.0 * sx;
            let gy = (3.0 * dy(x - 1) + 10.0 * dy(x) + 3.0 * dy(x + 1)) / 16.0 * sy;
            tensor[y as usize * width + x as usize] = [gx * gx, gy * gy, gx * gy];
        }
    }
    // Separable smoothing, wrapping: rows, then columns.
    let mut tmp =
        crate::memory::try_alloc_vec(width * height, [0.0f32; 3], "a scratch map's tensor")?;
    smooth_wrapping(&tensor, &mut tmp, width, height, (1, 0));
    smooth_wrapping(&tmp, &mut tensor, width, height, (0, 1));
    drop(tmp);
    let floor = TENSOR_FLOOR * tensor.iter().map(|t| t[0] + t[1]).fold(0.0f32, f32::max);
    let mut pyramid = vec![Level {
        width,
        height,
        texels: tensor,
    }];
    while let Some(l) = pyramid.last().filter(|l| l.width > 1 || l.height > 1) {
        let next = l.coarser()?;
        pyramid.push(next);
    }
    let mut out = crate::memory::try_alloc_vec(width * height, Vec2::ZERO, "a scratch map")?;
    for y in 0..height {
        for x in 0..width {
            let uv = Vec2::new(
                (x as f32 + 0.5) / width as f32,
                (y as f32 + 0.5) / height as f32,
            );
            let strong = |t: &[f32; 3]| floor > 0.0 && t[0] + t[1] > floor;
            let t0 = pyramid[0].texels[y * width + x];
            let t = if strong(&t0) {
                Some(t0)
            } else {
                pyramid[1..]
                    .iter()
                    .map(|l| l.bilinear(uv))
                    .find(|t| strong(t))
            };
            out[y * width + x] = match t {
                Some([juu, jvv, juv]) => -doubled_of_tensor(juu, jvv, juv),
                None => Vec2::ZERO,
            };
        }
    }
    Ok(out)
}

/// `src` convolved with the tensor's Gaussian along `step` (`(1, 0)`: rows, `(0, 1)`: columns),
/// wrapping at the image's edges, into `dst`.
fn smooth_wrapping(
    src: &[[f32; 3]],
    dst: &mut [[f32; 3]],
    width: usize,
    height: usize,
    step: (i64, i64),
) {
    let kernel = tensor_kernel();
    let r = TENSOR_RADIUS as i64;
    for y in 0..height {
        for x in 0..width {
            let mut s = [0.0f32; 3];
            for (k, w) in kernel.iter().enumerate() {
                let d = k as i64 - r;
                let xx = (x as i64 + d * step.0).rem_euclid(width as i64) as usize;
                let yy = (y as i64 + d * step.1).rem_euclid(height as i64) as usize;
                let t = src[yy * width + xx];
                for c in 0..3 {
                    s[c] += w * t[c];
                }
            }
            dst[y * width + x] = s;
        }
    }
}

/// The normalised Gaussian weights of [`TENSOR_SIGMA`], `2 TENSOR_RADIUS + 1` taps.
fn tensor_kernel() -> [f32; 2 * TENSOR_RADIUS + 1] {
    let mut k = [0.0f32; 2 * TENSOR_RADIUS + 1];
    for (i, w) in k.iter_mut().enumerate() {
        let x = i as f32 - TENSOR_RADIUS as f32;
        *w = (-0.5 * x * x / (TENSOR_SIGMA * TENSOR_SIGMA)).exp();
    }
    let sum: f32 = k.iter().sum();
    k.map(|w| w / sum)
}

/// The unit doubled-angle vector of a symmetric tensor's major eigenvector, `(J_uu - J_vv, 2
/// J_uv)` normalised; zero for an isotropic tensor.
#[inline]
fn doubled_of_tensor(juu: f32, jvv: f32, juv: f32) -> Vec2 {
    let v = Vec2::new(juu - jvv, 2.0 * juv);
    let l = v.length();
    if l > 0.0 && l.is_finite() {
        v / l
    } else {
        Vec2::ZERO
    }
}

#[cfg(test)]
mod tests;
