//! Textures evaluated at a surface point's `(u, v)`: a constant, a checkerboard and an image
//! (PNG decoded from sRGB to linear, or a linear EXR), bilinearly filtered with wrapping.
//!
//! ## Conventions (matching Mitsuba 3, which the renderer is validated against)
//!
//! * Image row 0 (the top row of the file) is at `v = 0`, column 0 at `u = 0`; pixel centres
//!   are at `((i + 0.5) / width, (j + 0.5) / height)` (Mitsuba's `bitmap`). Like Mitsuba's, the
//!   OBJ loader flips `v` (`1 - v`) so that OBJ files' bottom-left texture origin maps
//!   correctly (`geometry/obj.rs`).
//! * The checkerboard is Mitsuba's `checkerboard`: `color0` where `frac(u s) < 1/2` and
//!   `frac(v s) < 1/2` agree, `color1` elsewhere, so one unit of scaled uv holds 2 x 2 checks.
//!
//! In scene files a texture is written as an RGB triple (`[0.8, 0.8, 0.8]`), a single grey
//! number, or a table with a `type` key (see [`Texture`]'s `Deserialize`).

use crate::math::{Rgb, Vec2};
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};
use serde::Deserialize;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Errors loading an image file, each naming the file.
#[derive(Debug, thiserror::Error)]
pub enum TextureError {
    #[error("cannot read image `{path}`: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("cannot decode image `{path}`: {message}")]
    Decode { path: PathBuf, message: String },
    #[error("unsupported image format `{path}`: expected a .png or .exr file")]
    Unsupported { path: PathBuf },
    #[error("image `{path}` holds a non-finite or negative value at pixel ({x}, {y})")]
    BadPixel { path: PathBuf, x: usize, y: usize },
}

/// Refuses an image whose header claims more than [`crate::io::MAX_IMAGE_PIXELS`], before a
/// pixel is allocated.
fn check_image_size(path: &Path, width: usize, height: usize) -> Result<(), TextureError> {
    let pixels = width as u64 * height as u64;
    if pixels > crate::io::MAX_IMAGE_PIXELS {
        return Err(TextureError::Decode {
            path: path.to_path_buf(),
            message: format!(
                "its header claims {width} x {height} pixels, over the limit of {} million",
                crate::io::MAX_IMAGE_PIXELS / 1_000_000
            ),
        });
    }
    Ok(())
}

/// The sRGB transfer function inverted (IEC 61966-2-1): an 8-bit-style encoded value in
/// `[0, 1]` to linear.
#[inline]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// A linear RGB image, row-major, row 0 at the top.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbImage {
    pub width: usize,
    pub height: usize,
    pub pixels: Vec<Rgb>,
}

impl RgbImage {
    /// # Panics
    /// If `pixels.len() != width * height` or either size is 0.
    pub fn new(width: usize, height: usize, pixels: Vec<Rgb>) -> Self {
        assert!(
            width > 0 && height > 0 && pixels.len() == width * height,
            "RgbImage size mismatch"
        );
        RgbImage {
            width,
            height,
            pixels,
        }
    }

    /// Load a PNG (decoded from sRGB to linear unless `srgb` is `Some(false)`) or an EXR
    /// (linear; `srgb` ignored), choosing by the file extension.
    pub fn load(path: &Path, srgb: Option<bool>) -> Result<Self, TextureError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        crate::io::open_regular(path, crate::io::MAX_BINARY_BYTES).map_err(|source| {
            TextureError::Io {
                path: path.to_path_buf(),
                source,
            }
        })?;
        let img = match ext.as_deref() {
            Some("png") => Self::load_png(path, srgb.unwrap_or(true))?,
            Some("exr") => Self::load_exr(path)?,
            _ => {
                return Err(TextureError::Unsupported {
                    path: path.to_path_buf(),
                })
            }
        };
        for (i, p) in img.pixels.iter().enumerate() {
            if !p.is_finite() || p.min_element() < 0.0 {
                return Err(TextureError::BadPixel {
                    path: path.to_path_buf(),
                    x: i % img.width,
                    y: i / img.width,
                });
            }
        }
        Ok(img)
    }

    fn load_png(path: &Path, srgb: bool) -> Result<Self, TextureError> {
        let bytes =
            crate::io::read_bounded(path, crate::io::MAX_BINARY_BYTES).map_err(|source| {
                TextureError::Io {
                    path: path.to_path_buf(),
                    source,
                }
            })?;
        Self::from_png_bytes(&bytes, path, srgb)
    }

    /// Decode a PNG held in memory (an image inside a glTF), from sRGB to linear where `srgb`;
    /// `path` names it in errors. The header's size is checked before the pixels are decoded.
    pub fn from_png_bytes(bytes: &[u8], path: &Path, srgb: bool) -> Result<Self, TextureError> {
        let decode_error = |e: image::ImageError| TextureError::Decode {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        let reader = || {
            image::ImageReader::with_format(std::io::Cursor::new(&bytes), image::ImageFormat::Png)
        };
        let (w, h) = reader().into_dimensions().map_err(decode_error)?;
        check_image_size(path, w as usize, h as usize)?;
        let decoded = reader().decode().map_err(decode_error)?;
        let rgb = decoded.to_rgb32f();
        let (w, h) = (rgb.width() as usize, rgb.height() as usize);
        if w == 0 || h == 0 {
            return Err(TextureError::Decode {
                path: path.to_path_buf(),
                message: "empty image".into(),
            });
        }
        let f = |c: f32| if srgb { srgb_to_linear(c) } else { c };
        let pixels = rgb
            .pixels()
            .map(|p| Rgb::new(f(p[0]), f(p[1]), f(p[2])))
            .collect();
        Ok(RgbImage::new(w, h, pixels))
    }

    fn load_exr(path: &Path) -> Result<Self, TextureError> {
        use exr::prelude::*;
        let decode_error = |e: exr::error::Error| TextureError::Decode {
            path: path.to_path_buf(),
            message: e.to_string(),
        };
        let file =
            crate::io::open_regular(path, crate::io::MAX_BINARY_BYTES).map_err(|source| {
                TextureError::Io {
                    path: path.to_path_buf(),
                    source,
                }
            })?;
        let meta = exr::meta::MetaData::read_from_buffered(std::io::BufReader::new(file), false)
            .map_err(decode_error)?;
        for header in &meta.headers {
            check_image_size(path, header.layer_size.width(), header.layer_size.height())?;
        }
        let image = read_first_rgba_layer_from_file(
            path,
            |resolution, _| {
                (
                    resolution.width(),
                    vec![Rgb::ZERO; resolution.width() * resolution.height()],
                )
            },
            |(w, px): &mut (usize, Vec<Rgb>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                px[pos.y() * *w + pos.x()] = Rgb::new(r, g, b);
            },
        )
        .map_err(decode_error)?;
        let (w, pixels) = image.layer_data.channel_data.pixels;
        if w == 0 || pixels.is_empty() {
            return Err(TextureError::Decode {
                path: path.to_path_buf(),
                message: "empty image".into(),
            });
        }
        Ok(RgbImage::new(w, pixels.len() / w, pixels))
    }

    /// Pixel `(x, y)` with both indices wrapped (repeat).
    #[inline]
    pub fn texel(&self, x: i64, y: i64) -> Rgb {
        let x = x.rem_euclid(self.width as i64) as usize;
        let y = y.rem_euclid(self.height as i64) as usize;
        self.pixels[y * self.width + x]
    }

    /// Bilinear lookup at `uv` with wrapping; pixel centres at `(i + 0.5) / size`.
    #[inline]
    pub fn bilinear(&self, uv: Vec2) -> Rgb {
        let x = uv.x * self.width as f32 - 0.5;
        let y = uv.y * self.height as f32 - 0.5;
        if !(x.is_finite() && y.is_finite()) {
            return Rgb::ZERO;
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as i64, y0 as i64);
        let a = self.texel(x0, y0).lerp(self.texel(x0 + 1, y0), fx);
        let b = self.texel(x0, y0 + 1).lerp(self.texel(x0 + 1, y0 + 1), fx);
        a.lerp(b, fy)
    }
}

/// A colour varying over texture space.
#[derive(Clone, Debug, PartialEq)]
pub enum Texture {
    Constant(Rgb),
    /// Mitsuba's checkerboard (see the module comment); `scale` multiplies uv first.
    Checkerboard {
        color0: Rgb,
        color1: Rgb,
        scale: f32,
    },
    /// An image file, loaded by [`Texture::load_images`] (relative paths resolved against the
    /// scene file's folder); `scale` multiplies uv (tiling).
    Image {
        path: PathBuf,
        srgb: Option<bool>,
        scale: f32,
        image: Option<Arc<RgbImage>>,
    },
}

impl Texture {
    /// The texture's value at `uv`. An image texture not yet loaded evaluates to 0.5 grey
    /// (callers load images when they load the scene).
    #[inline(always)]
    pub fn eval(&self, uv: Vec2) -> Rgb {
        match self {
            Texture::Constant(c) => *c,
            Texture::Checkerboard {
                color0,
                color1,
                scale,
            } => {
                let p = uv * *scale;
                let mx = p.x - p.x.floor() > 0.5;
                let my = p.y - p.y.floor() > 0.5;
                if mx == my {
                    *color0
                } else {
                    *color1
                }
            }
            Texture::Image { scale, image, .. } => match image {
                Some(img) => img.bilinear(uv * *scale),
                None => Rgb::splat(0.5),
            },
        }
    }

    /// Load image files (once; already loaded images are kept), resolving relative paths
    /// against `base_dir`.
    pub fn load_images(&mut self, base_dir: &Path) -> Result<(), TextureError> {
        if let Texture::Image {
            path, srgb, image, ..
        } = self
        {
            if image.is_none() {
                let full = if path.is_absolute() {
                    path.clone()
                } else {
                    base_dir.join(&path)
                };
                *image = Some(Arc::new(RgbImage::load(&full, *srgb)?));
            }
        }
        Ok(())
    }

    /// Smallest and largest channel value the texture can return (for loaded images: over
    /// all pixels; unloaded images: `None`).
    pub fn range(&self) -> Option<(f32, f32)> {
        match self {
            Texture::Constant(c) => Some((c.min_element(), c.max_element())),
            Texture::Checkerboard { color0, color1, .. } => Some((
                color0.min(*color1).min_element(),
                color0.max(*color1).max_element(),
            )),
            Texture::Image { image, .. } => image.as_ref().map(|img| {
                img.pixels
                    .iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| {
                        (lo.min(p.min_element()), hi.max(p.max_element()))
                    })
            }),
        }
    }
}

/// A colour: one number (grey) or `[r, g, b]`, linear.
#[derive(Clone, Copy, Deserialize, PartialEq)]
#[serde(untagged, expecting = "a number or an [r, g, b] array")]
pub enum Colour {
    Grey(f32),
    Rgb([f32; 3]),
}

impl std::fmt::Debug for Colour {
    /// As written in the file (`-1.0`, `[1.0, 0.5, 0.0]`): scene errors quote it.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Colour::Grey(g) => write!(f, "{g:?}"),
            Colour::Rgb(c) => write!(f, "{c:?}"),
        }
    }
}

impl Colour {
    pub fn rgb(self) -> Rgb {
        match self {
            Colour::Grey(g) => Rgb::splat(g),
            Colour::Rgb(c) => Rgb::from_array(c),
        }
    }
}

/// The table form of a texture in a scene file.
#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
enum TextureTable {
    Constant {
        value: Colour,
    },
    Checkerboard {
        color0: Colour,
        color1: Colour,
        #[serde(default = "one")]
        scale: f32,
    },
    Image {
        path: PathBuf,
        /// Decode a PNG from sRGB (default true); ignored for EXR (always linear).
        #[serde(default)]
        srgb: Option<bool>,
        #[serde(default = "one")]
        scale: f32,
    },
}

fn one() -> f32 {
    1.0
}

impl From<TextureTable> for Texture {
    fn from(t: TextureTable) -> Self {
        match t {
            TextureTable::Constant { value } => Texture::Constant(value.rgb()),
            TextureTable::Checkerboard {
                color0,
                color1,
                scale,
            } => Texture::Checkerboard {
                color0: color0.rgb(),
                color1: color1.rgb(),
                scale,
            },
            TextureTable::Image { path, srgb, scale } => Texture::Image {
                path,
                srgb,
                scale,
                image: None,
            },
        }
    }
}

/// Accepts `0.5` (grey), `[r, g, b]`, or a table `{ type = "constant" | "checkerboard" |
/// "image", ... }`:
///
/// ```toml
/// reflectance = [0.8, 0.8, 0.8]
/// reflectance = { type = "checkerboard", color0 = [0.9, 0.9, 0.9], color1 = [0.1, 0.1, 0.1], scale = 4 }
/// reflectance = { type = "image", path = "textures/wood.png", scale = 1 }
/// ```
impl<'de> Deserialize<'de> for Texture {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = Texture;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str(
                    "a grey value, an [r, g, b] array, or a texture table with a `type` key",
                )
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Texture, E> {
                Ok(Texture::Constant(Rgb::splat(v as f32)))
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Texture, E> {
                Ok(Texture::Constant(Rgb::splat(v as f32)))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Texture, E> {
                Ok(Texture::Constant(Rgb::splat(v as f32)))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Texture, A::Error> {
                let rgb = <[f32; 3]>::deserialize(de::value::SeqAccessDeserializer::new(seq))?;
                Ok(Texture::Constant(Rgb::from(rgb)))
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Texture, A::Error> {
                Ok(TextureTable::deserialize(de::value::MapAccessDeserializer::new(map))?.into())
            }
        }
        d.deserialize_any(V)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checkerboard_matches_mitsuba_layout() {
        let t = Texture::Checkerboard {
            color0: Rgb::ONE,
            color1: Rgb::ZERO,
            scale: 2.0,
        };
        // scale 2: checks of side 1/4 in uv.
        assert_eq!(t.eval(Vec2::new(0.1, 0.1)), Rgb::ONE);
        assert_eq!(t.eval(Vec2::new(0.3, 0.1)), Rgb::ZERO);
        assert_eq!(t.eval(Vec2::new(0.3, 0.3)), Rgb::ONE);
        assert_eq!(t.eval(Vec2::new(0.1, 0.3)), Rgb::ZERO);
        assert_eq!(t.eval(Vec2::new(-0.1, 0.1)), Rgb::ZERO, "wraps below 0");
        // Half the area of each colour.
        let n = 100;
        let s: f32 = (0..n * n)
            .map(|i| {
                t.eval(Vec2::new(
                    (i % n) as f32 / n as f32 + 0.003,
                    (i / n) as f32 / n as f32 + 0.003,
                ))
                .x
            })
            .sum();
        assert_eq!(s as usize, n * n / 2);
    }

    #[test]
    fn srgb_decoding() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        assert!((srgb_to_linear(0.5) - 0.214_041).abs() < 1e-5);
        // Continuous at the knee.
        assert!((srgb_to_linear(0.04045) - srgb_to_linear(0.04046)).abs() < 1e-5);
    }

    fn tmp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("striae-texture-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// A 2 x 2 PNG written here, loaded through the scene-file path: decoded to linear,
    /// row 0 at v = 0, bilinear between pixel centres, wrapping at the edges.
    #[test]
    fn image_texture_png_and_exr() {
        let dir = tmp_dir("img");
        let png = dir.join("tiny.png");
        let mut img = image::RgbImage::new(2, 2);
        img.put_pixel(0, 0, image::Rgb([255, 0, 0]));
        img.put_pixel(1, 0, image::Rgb([0, 255, 0]));
        img.put_pixel(0, 1, image::Rgb([0, 0, 255]));
        img.put_pixel(1, 1, image::Rgb([128, 128, 128]));
        img.save(&png).unwrap();

        let mut t: Texture =
            toml::from_str::<toml::Table>("t = { type = \"image\", path = \"tiny.png\" }").unwrap()
                ["t"]
                .clone()
                .try_into()
                .unwrap();
        assert_eq!(t.eval(Vec2::splat(0.25)), Rgb::splat(0.5), "unloaded: grey");
        t.load_images(&dir).unwrap();
        // Pixel centres.
        assert!((t.eval(Vec2::new(0.25, 0.25)) - Rgb::new(1.0, 0.0, 0.0)).length() < 1e-6);
        assert!((t.eval(Vec2::new(0.75, 0.25)) - Rgb::new(0.0, 1.0, 0.0)).length() < 1e-6);
        assert!((t.eval(Vec2::new(0.25, 0.75)) - Rgb::new(0.0, 0.0, 1.0)).length() < 1e-6);
        let grey = srgb_to_linear(128.0 / 255.0);
        assert!((t.eval(Vec2::new(0.75, 0.75)) - Rgb::splat(grey)).length() < 1e-6);
        // Midway between the two top pixels, and wrapping: u = 0 is midway between columns 1 and 0.
        assert!((t.eval(Vec2::new(0.5, 0.25)) - Rgb::new(0.5, 0.5, 0.0)).length() < 1e-6);
        assert!((t.eval(Vec2::new(0.0, 0.25)) - Rgb::new(0.5, 0.5, 0.0)).length() < 1e-6);
        assert!((t.eval(Vec2::new(1.25, -0.75)) - t.eval(Vec2::new(0.25, 0.25))).length() < 1e-6);

        // EXR: linear values come back unchanged.
        let exr_path = dir.join("tiny.exr");
        let vals = [[0.1f32, 2.0, 0.3], [4.0, 0.5, 0.6], [0.7, 0.8, 9.0]];
        exr::prelude::write_rgb_file(&exr_path, 3, 1, |x, _| (vals[x][0], vals[x][1], vals[x][2]))
            .unwrap();
        let img = RgbImage::load(&exr_path, None).unwrap();
        assert_eq!((img.width, img.height), (3, 1));
        for (p, v) in img.pixels.iter().zip(vals) {
            assert_eq!(*p, Rgb::from(v));
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn missing_or_corrupt_images_name_the_path() {
        let dir = tmp_dir("bad");
        let mut t = Texture::Image {
            path: "nope.png".into(),
            srgb: None,
            scale: 1.0,
            image: None,
        };
        let e = t.load_images(&dir).unwrap_err().to_string();
        assert!(e.contains("nope.png") && e.contains("cannot read"), "{e}");
        let bad = dir.join("corrupt.png");
        std::fs::write(&bad, b"this is not a png").unwrap();
        let e = RgbImage::load(&bad, None).unwrap_err().to_string();
        assert!(e.contains("corrupt.png") && e.contains("decode"), "{e}");
        let bad = dir.join("corrupt.exr");
        std::fs::write(&bad, b"this is not an exr").unwrap();
        let e = RgbImage::load(&bad, None).unwrap_err().to_string();
        assert!(e.contains("corrupt.exr"), "{e}");
        std::fs::write(dir.join("x.jpg"), b"").unwrap();
        let e = RgbImage::load(&dir.join("x.jpg"), None)
            .unwrap_err()
            .to_string();
        assert!(e.contains("x.jpg") && e.contains("unsupported"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn texture_syntax() {
        #[derive(Deserialize)]
        struct T {
            t: Texture,
        }
        let p = |s: &str| toml::from_str::<T>(s).map(|t| t.t);
        assert_eq!(p("t = 0.25").unwrap(), Texture::Constant(Rgb::splat(0.25)));
        assert_eq!(p("t = 1").unwrap(), Texture::Constant(Rgb::ONE));
        assert_eq!(
            p("t = [0.1, 0.2, 0.3]").unwrap(),
            Texture::Constant(Rgb::new(0.1, 0.2, 0.3))
        );
        assert_eq!(
            p("t = { type = \"checkerboard\", color0 = [1, 1, 1], color1 = [0, 0, 0], scale = 4 }").unwrap(),
            Texture::Checkerboard { color0: Rgb::ONE, color1: Rgb::ZERO, scale: 4.0 }
        );
        // A colour inside a table may be a grey number too, as everywhere else.
        assert_eq!(
            p("t = { type = \"checkerboard\", color0 = 0.5, color1 = [0, 0, 1] }").unwrap(),
            Texture::Checkerboard {
                color0: Rgb::splat(0.5),
                color1: Rgb::Z,
                scale: 1.0
            }
        );
        assert_eq!(
            p("t = { type = \"constant\", value = 0.25 }").unwrap(),
            Texture::Constant(Rgb::splat(0.25))
        );
        let e = p(
            "t = { type = \"checkerboard\", color0 = [1, 1, 1], color1 = [0, 0, 0], scael = 4 }",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("scael"), "{e}");
        let e = p("t = { type = \"marble\" }").unwrap_err().to_string();
        assert!(e.contains("marble"), "{e}");
        let e = p("t = [0.1, 0.2]").unwrap_err().to_string();
        assert!(e.contains("3"), "{e}");
        assert!(p("t = \"red\"").is_err());
    }
}
