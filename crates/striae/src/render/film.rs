//! The film: a linear RGB image accumulated with a box filter (each sample lands at a random
//! position inside its pixel and counts only there, Mitsuba's `box` rfilter), written as a
//! linear OpenEXR file (`exr` crate) and as an 8-bit sRGB PNG preview with an exposure in
//! stops. Both are written atomically (`io::write_atomically`).

use crate::math::Rgb;
use std::path::{Path, PathBuf};

/// Memory a render takes per pixel of its film: the tiles' results (12 bytes), the image
/// (12) and, after both, the encoders' buffers. Measured as the peak resident size (`/usr/bin/time
/// -f %M`) of `striae render --spp 1` of the default scene: 38 MB at 1024 x 1024, 113 MB at
/// 2048 x 2048, 24.2 bytes a pixel between them. A part (`--tile`) or a merge holds as much.
pub const BYTES_PER_PIXEL: u64 = 24;

/// The largest PNG preview exposure, in stops either way: the preview's scale `2^exposure`
/// stays a normal 32-bit float (at 128 it is infinite).
pub const MAX_EXPOSURE: f32 = 126.0;

/// Whether `exposure` (stops) lies within [`MAX_EXPOSURE`] (NaN does not).
pub fn exposure_in_range(exposure: f32) -> bool {
    exposure.abs() <= MAX_EXPOSURE
}

/// A finished image: `width x height` linear RGB pixels, row 0 on top.
#[derive(Clone, Debug, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub pixels: Vec<Rgb>,
}

/// Why an image could not be written.
#[derive(Debug, thiserror::Error)]
pub enum FilmError {
    #[error("cannot write {path}: {message}")]
    Write { path: PathBuf, message: String },
    /// A failure of the outputs as a whole in [`crate::io::write_all_atomically`] (a
    /// destination that is a folder, a rename); its message names the file.
    #[error("{0}")]
    Outputs(String),
    /// Finite inputs whose light overflowed 32-bit floats: an error, not an image of `inf`.
    #[error("the render overflowed: pixel ({x}, {y}) is not finite; the scene's emission, irradiance or environment radiance is too large for 32-bit floats")]
    Overflow { x: u32, y: u32 },
    #[error("exposure {0:?} stops: must lie within +-{MAX_EXPOSURE}")]
    Exposure(f32),
}

impl From<std::io::Error> for FilmError {
    fn from(e: std::io::Error) -> Self {
        FilmError::Outputs(e.to_string())
    }
}

/// The sRGB transfer function (IEC 61966-2-1) of a linear value in `[0, 1]`.
#[inline]
pub fn linear_to_srgb(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

impl Image {
    pub fn new(width: u32, height: u32) -> Self {
        Image {
            width,
            height,
            pixels: vec![Rgb::ZERO; (width * height) as usize],
        }
    }

    /// [`Image::new`], or an error naming `what` (the flag that set the size) where the
    /// allocator refuses the pixels.
    pub fn try_new(
        width: u32,
        height: u32,
        what: &str,
    ) -> Result<Self, crate::memory::MemoryError> {
        let n = width as usize * height as usize;
        Ok(Image {
            width,
            height,
            pixels: crate::memory::try_alloc_vec(n, Rgb::ZERO, what)?,
        })
    }

    pub fn get(&self, x: u32, y: u32) -> Rgb {
        self.pixels[(y * self.width + x) as usize]
    }

    /// Mean of all pixels.
    pub fn mean(&self) -> Rgb {
        self.pixels.iter().fold(Rgb::ZERO, |a, &p| a + p) / self.pixels.len().max(1) as f32
    }

    /// Write a linear (scene-referred) RGB OpenEXR file, 32-bit float channels. The blocks are
    /// compressed and written in order on the calling thread, so the same image always gives
    /// the same bytes (the crate's parallel writer stores them in the order they finish).
    pub fn write_exr(&self, path: &Path) -> Result<(), FilmError> {
        crate::io::write_atomically(path, |tmp| self.exr_into(tmp, path))
    }

    /// Write the EXR and the PNG preview together: both or neither
    /// ([`crate::io::write_all_atomically`]).
    pub fn write_exr_and_png(
        &self,
        exr: &Path,
        png: &Path,
        exposure: f32,
    ) -> Result<(), FilmError> {
        if !exposure_in_range(exposure) {
            return Err(FilmError::Exposure(exposure));
        }
        if let Some(i) = self.pixels.iter().position(|p| !p.is_finite()) {
            let w = self.width.max(1) as usize;
            return Err(FilmError::Overflow {
                x: (i % w) as u32,
                y: (i / w) as u32,
            });
        }
        crate::io::write_all_atomically(vec![
            (exr, Box::new(|tmp: &Path| self.exr_into(tmp, exr))),
            (
                png,
                Box::new(|tmp: &Path| self.png_into(tmp, png, exposure)),
            ),
        ])
    }

    /// The EXR of [`Self::write_exr`] into `tmp`, errors naming `path`.
    fn exr_into(&self, tmp: &Path, path: &Path) -> Result<(), FilmError> {
        use exr::prelude::{Image, SpecificChannels, WritableImage};
        let channels = SpecificChannels::rgb(|pos: exr::math::Vec2<usize>| {
            let p = self.pixels[pos.1 * self.width as usize + pos.0];
            (p.x, p.y, p.z)
        });
        Image::from_channels((self.width as usize, self.height as usize), channels)
            .write()
            .non_parallel()
            .to_file(tmp)
            .map_err(|e| FilmError::Write {
                path: path.to_path_buf(),
                message: e.to_string(),
            })
    }

    /// The 8-bit sRGB preview: scaled by `2^exposure`, clamped, sRGB-encoded, rounded.
    pub fn to_srgb8(&self, exposure: f32) -> Vec<u8> {
        let scale = exposure.exp2();
        let mut out = Vec::with_capacity(self.pixels.len() * 3);
        for p in &self.pixels {
            for c in [p.x, p.y, p.z] {
                let c = if c.is_finite() { c * scale } else { 0.0 };
                out.push((linear_to_srgb(c) * 255.0 + 0.5) as u8);
            }
        }
        out
    }

    /// Write the PNG preview (see [`Image::to_srgb8`]).
    pub fn write_png(&self, path: &Path, exposure: f32) -> Result<(), FilmError> {
        if !exposure_in_range(exposure) {
            return Err(FilmError::Exposure(exposure));
        }
        crate::io::write_atomically(path, |tmp| self.png_into(tmp, path, exposure))
    }

    /// The PNG of [`Self::write_png`] into `tmp`, errors naming `path`.
    fn png_into(&self, tmp: &Path, path: &Path, exposure: f32) -> Result<(), FilmError> {
        let img = image::RgbImage::from_raw(self.width, self.height, self.to_srgb8(exposure))
            .ok_or_else(|| FilmError::Write {
                path: path.to_path_buf(),
                message: "image buffer size mismatch".into(),
            })?;
        img.save_with_format(tmp, image::ImageFormat::Png)
            .map_err(|e| FilmError::Write {
                path: path.to_path_buf(),
                message: e.to_string(),
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_film_the_allocator_refuses_is_an_error_naming_the_flag() {
        let e = Image::try_new(u32::MAX, u32::MAX, "--res 4294967295x4294967295").unwrap_err();
        assert!(
            e.to_string()
                .starts_with("--res 4294967295x4294967295: could not allocate"),
            "{e}"
        );
        assert_eq!(Image::try_new(3, 2, "--res 3x2").unwrap(), Image::new(3, 2));
    }

    #[test]
    fn srgb_curve_endpoints_and_midpoint() {
        assert_eq!(linear_to_srgb(0.0), 0.0);
        assert!((linear_to_srgb(1.0) - 1.0).abs() < 1e-6);
        // 18% grey encodes to about 0.46.
        assert!((linear_to_srgb(0.18) - 0.4614).abs() < 1e-3);
        assert!((linear_to_srgb(7.0) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn exr_and_png_round_trip() {
        let dir = std::env::temp_dir().join(format!("striae-film-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut img = Image::new(3, 2);
        img.pixels[4] = Rgb::new(0.25, 2.0, 0.0);
        img.write_exr(&dir.join("a.exr")).unwrap();
        img.write_png(&dir.join("a.png"), 0.0).unwrap();
        let back = exr::prelude::read_first_rgba_layer_from_file(
            dir.join("a.exr"),
            |res, _| vec![Rgb::ZERO; res.width() * res.height()],
            |px: &mut Vec<Rgb>, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                px[pos.y() * 3 + pos.x()] = Rgb::new(r, g, b)
            },
        )
        .unwrap();
        assert_eq!(back.layer_data.channel_data.pixels, img.pixels);
        let png = image::open(dir.join("a.png")).unwrap().to_rgb8();
        assert_eq!(png.get_pixel(1, 1).0, [137, 255, 0]);
        // A write into a missing folder fails cleanly, naming the file.
        let err = img
            .write_png(&dir.join("missing/b.png"), 0.0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("b.png"), "{err}");
        // The pair: a PNG that cannot be written leaves no EXR either.
        std::fs::create_dir(dir.join("c.png")).unwrap();
        let err = img
            .write_exr_and_png(&dir.join("c.exr"), &dir.join("c.png"), 0.0)
            .unwrap_err()
            .to_string();
        assert!(err.contains("c.png"), "{err}");
        assert!(!dir.join("c.exr").exists());
        img.write_exr_and_png(&dir.join("d.exr"), &dir.join("d.png"), 0.0)
            .unwrap();
        assert!(dir.join("d.exr").is_file() && dir.join("d.png").is_file());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// The same image gives the same EXR bytes, write after write (many compressed blocks: a
    /// parallel writer would store them in the order its threads finish).
    #[test]
    fn exr_bytes_are_reproducible() {
        let dir = std::env::temp_dir().join(format!("striae-film-bytes-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut img = Image::new(256, 192);
        for (i, p) in img.pixels.iter_mut().enumerate() {
            let f = (i as f32 * 0.618_034).fract();
            *p = Rgb::new(f, 1.0 - f, f * f);
        }
        let bytes: Vec<Vec<u8>> = (0..4)
            .map(|k| {
                let path = dir.join(format!("{k}.exr"));
                img.write_exr(&path).unwrap();
                std::fs::read(&path).unwrap()
            })
            .collect();
        assert!(bytes.iter().all(|b| *b == bytes[0]));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
