//! An image rendered in parts, on several machines or processes, and merged bit for bit.
//!
//! Part `I` of `N` holds the film's tiles `t` ([`integrator::tile_rect`], numbered row by row)
//! with `t % N == I`: interleaved, so that every part gets a share of the busy and the empty
//! regions of the image. Its pixels come from [`integrator::render_tiles`], the render loop of
//! whole renders, and a pixel's value does not depend on which tiles are rendered with it, so
//! [`merge`] of all `N` parts is the whole render's image, bit for bit.
//!
//! A part file (`striae render --tile I/N`) holds, in order: the magic line [`MAGIC`]; the
//! length of the header (`u32`, little-endian); the header, JSON ([`PartHeader`]: which
//! render, [`RenderId`], which part, the preview's exposure); the part's pixels, linear RGB
//! `f32` little-endian, tile after tile in increasing tile order, each tile row by row; the
//! SHA-256 of everything before it. [`merge`] refuses parts of different renders, a missing or
//! repeated part, and a file whose size or checksum is wrong.

use crate::film::Image;
use crate::integrator::{self, Cancelled, RenderStats, Simd};
use crate::math::Rgb;
use crate::scene::Scene;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// The first bytes of every part file.
pub const MAGIC: &[u8] = b"striae part file\n";
/// The format of the header and the pixels; a reader refuses any other.
pub const FORMAT: u32 = 1;
/// The longest header a reader accepts, in bytes.
const MAX_HEADER: u32 = 1 << 16;

/// What makes two renders the same image: the scene description, the settings that change
/// pixels and the crate version.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderId {
    /// SHA-256 of the scene file's text, hexadecimal (files it names are not hashed).
    pub scene_hash: String,
    pub width: u32,
    pub height: u32,
    pub spp: u32,
    pub seed: u64,
    pub max_depth: u32,
    pub rr_depth: u32,
    pub sampler: String,
    pub version: String,
}

impl RenderId {
    /// The render of `scene`, loaded from the scene text `scene_text`.
    pub fn new(scene_text: &str, scene: &Scene) -> RenderId {
        let s = &scene.settings;
        RenderId {
            scene_hash: hex(&Sha256::digest(scene_text.as_bytes())),
            width: s.width,
            height: s.height,
            spp: s.spp,
            seed: s.seed,
            max_depth: s.max_depth,
            rr_depth: s.rr_depth,
            sampler: s.sampler.name().to_string(),
            version: crate::VERSION.to_string(),
        }
    }

    /// The film's tile count ([`integrator::tile_count`]).
    pub fn tile_count(&self) -> u32 {
        integrator::tile_count(self.width, self.height)
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The header of a part file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PartHeader {
    pub format: u32,
    pub render: RenderId,
    /// This part, `0..count`.
    pub index: u32,
    pub count: u32,
    /// The PNG preview's exposure in stops (`render.exposure`), for `merge`.
    pub exposure: f32,
}

/// One part of an image: its header and pixels ([`part_tiles`]' tiles, each row by row).
#[derive(Clone, Debug, PartialEq)]
pub struct Part {
    pub header: PartHeader,
    pub pixels: Vec<Rgb>,
}

/// What can be wrong with a part, a part file or a set of parts.
#[derive(Debug, thiserror::Error)]
pub enum PartError {
    #[error("part {index}/{count}: {reason}")]
    Index {
        index: u32,
        count: u32,
        reason: String,
    },
    #[error("cannot read part file {file}: {message}")]
    Read { file: PathBuf, message: String },
    #[error("cannot write part file {file}: {message}")]
    Write { file: PathBuf, message: String },
    #[error("part file {file} is not a valid striae part: {reason}")]
    Corrupt { file: PathBuf, reason: String },
    #[error("part files {first} and {file} are of different renders: {key} is {a} in one and {b} in the other")]
    Mismatch {
        first: PathBuf,
        file: PathBuf,
        key: String,
        a: String,
        b: String,
    },
    #[error("part {index} of {count} is given twice: {first} and {file}")]
    Duplicate {
        index: u32,
        count: u32,
        first: PathBuf,
        file: PathBuf,
    },
    #[error("parts missing: {missing:?} of 0..{count} (no part file given for them)")]
    Missing { missing: Vec<u32>, count: u32 },
    #[error("no part files given")]
    Empty,
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
}

/// The tiles of part `index` of `count` of a film of `tiles` tiles, in increasing order. An
/// error if `index >= count` or there are fewer tiles than parts (a part would be empty).
pub fn part_tiles(index: u32, count: u32, tiles: u32) -> Result<Vec<u32>, PartError> {
    let bad = |reason: String| PartError::Index {
        index,
        count,
        reason,
    };
    if count == 0 {
        return Err(bad("the part count must be at least 1".into()));
    }
    if index >= count {
        return Err(bad(format!(
            "the part index must lie in 0..{count} (0 to {})",
            count - 1
        )));
    }
    if count > tiles {
        return Err(bad(format!(
            "the image has only {tiles} tiles of {t}x{t} pixels: at most {tiles} parts",
            t = integrator::TILE
        )));
    }
    Ok((index..tiles).step_by(count as usize).collect())
}

/// The number of pixels of part `index` of `count` of a `width x height` image (an error as
/// [`part_tiles`]').
pub fn part_pixel_count(
    (width, height): (u32, u32),
    index: u32,
    count: u32,
) -> Result<usize, PartError> {
    let tiles = part_tiles(index, count, integrator::tile_count(width, height))?;
    Ok(tiles
        .iter()
        .map(|&t| {
            let [x0, y0, x1, y1] = integrator::tile_rect(width, height, t);
            ((x1 - x0) * (y1 - y0)) as usize
        })
        .sum())
}

impl Part {
    /// Render part `index` of `count` of `scene` (loaded from `scene_text`); `progress` and
    /// `cancel` as in [`integrator::render_tiles`].
    pub fn render(
        scene: &Scene,
        scene_text: &str,
        (index, count): (u32, u32),
        progress: &(dyn Fn(u64) + Sync),
        cancel: &AtomicBool,
    ) -> Result<(Part, RenderStats), PartError> {
        let render = RenderId::new(scene_text, scene);
        let tiles = part_tiles(index, count, render.tile_count())?;
        let (pixels, stats) =
            integrator::render_tiles(scene, &tiles, progress, cancel, Simd::Auto)?;
        let header = PartHeader {
            format: FORMAT,
            render,
            index,
            count,
            exposure: scene.settings.exposure,
        };
        let pixels = pixels.into_iter().flatten().collect();
        Ok((Part { header, pixels }, stats))
    }

    /// The part file's bytes (see the module notes).
    pub fn to_bytes(&self) -> Vec<u8> {
        let header = serde_json::to_vec(&self.header).expect("a header serialises");
        let mut out = Vec::with_capacity(MAGIC.len() + 4 + header.len() + self.pixels.len() * 12);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(header.len() as u32).to_le_bytes());
        out.extend_from_slice(&header);
        for p in &self.pixels {
            for c in [p.x, p.y, p.z] {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
        let digest = Sha256::digest(&out);
        out.extend_from_slice(&digest);
        out
    }

    /// The part held by `bytes` (a part file's, named `file` in errors).
    pub fn from_bytes(bytes: &[u8], file: &Path) -> Result<Part, PartError> {
        let corrupt = |reason: &str| PartError::Corrupt {
            file: file.to_path_buf(),
            reason: reason.to_string(),
        };
        let body = bytes
            .strip_prefix(MAGIC)
            .ok_or_else(|| corrupt("it does not start with the part files' magic line"))?;
        if bytes.len() < MAGIC.len() + 4 + 32 {
            return Err(corrupt("it is cut short"));
        }
        let (content, digest) = bytes.split_at(bytes.len() - 32);
        if Sha256::digest(content).as_slice() != digest {
            return Err(corrupt(
                "its checksum does not match (the file is damaged or cut short)",
            ));
        }
        let len = u32::from_le_bytes(body[..4].try_into().expect("4 bytes"));
        let rest = &content[MAGIC.len() + 4..];
        if len > MAX_HEADER || len as usize > rest.len() {
            return Err(corrupt("its header length is out of range"));
        }
        let (header, data) = rest.split_at(len as usize);
        let header: PartHeader = serde_json::from_slice(header)
            .map_err(|e| corrupt(&format!("its header does not parse: {e}")))?;
        if header.format != FORMAT {
            return Err(corrupt(&format!(
                "format {} (this striae reads format {FORMAT})",
                header.format
            )));
        }
        let size = (header.render.width, header.render.height);
        let n = part_pixel_count(size, header.index, header.count)?;
        if data.len() != n * 12 {
            return Err(corrupt(&format!(
                "it holds {} bytes of pixels, part {}/{} of a {}x{} image needs {}",
                data.len(),
                header.index,
                header.count,
                header.render.width,
                header.render.height,
                n * 12
            )));
        }
        let pixels = data
            .chunks_exact(12)
            .map(|c| {
                let f = |i: usize| f32::from_le_bytes(c[i..i + 4].try_into().expect("4 bytes"));
                Rgb::new(f(0), f(4), f(8))
            })
            .collect();
        Ok(Part { header, pixels })
    }

    /// Write the part file `path` atomically.
    pub fn write(&self, path: &Path) -> Result<(), PartError> {
        let bytes = self.to_bytes();
        crate::io::write_atomically(path, |tmp| std::fs::write(tmp, &bytes)).map_err(|e| {
            PartError::Write {
                file: path.to_path_buf(),
                message: e.to_string(),
            }
        })
    }

    /// Read the part file `path`.
    pub fn read(path: &Path) -> Result<Part, PartError> {
        let bytes = std::fs::read(path).map_err(|e| PartError::Read {
            file: path.to_path_buf(),
            message: e.to_string(),
        })?;
        Part::from_bytes(&bytes, path)
    }
}

/// The first key on which two renders differ, with both values.
fn difference(a: &RenderId, b: &RenderId) -> Option<(String, String, String)> {
    let (a, b) = (
        serde_json::to_value(a).expect("serialises"),
        serde_json::to_value(b).expect("serialises"),
    );
    let (a, b) = (a.as_object()?, b.as_object()?);
    a.iter()
        .find(|(k, v)| b.get(*k) != Some(v))
        .map(|(k, v)| (k.clone(), v.to_string(), b[k].to_string()))
}

/// The image of a complete set of parts (each named by its file in errors), with the preview
/// exposure they carry: every part of one render, each once.
pub fn merge(parts: &[(PathBuf, Part)]) -> Result<(Image, f32), PartError> {
    let (first_file, first) = parts.first().ok_or(PartError::Empty)?;
    let (id, count) = (&first.header.render, first.header.count);
    let mut by_index: Vec<Option<usize>> = vec![None; count as usize];
    for (i, (file, part)) in parts.iter().enumerate() {
        let h = &part.header;
        let mismatch = |key: &str, a: String, b: String| PartError::Mismatch {
            first: first_file.clone(),
            file: file.clone(),
            key: key.to_string(),
            a,
            b,
        };
        if let Some((key, a, b)) = difference(id, &h.render) {
            return Err(mismatch(&key, a, b));
        }
        if h.count != count {
            return Err(mismatch(
                "part count",
                count.to_string(),
                h.count.to_string(),
            ));
        }
        let n = part_pixel_count((id.width, id.height), h.index, count)?;
        if part.pixels.len() != n {
            return Err(PartError::Corrupt {
                file: file.clone(),
                reason: format!("it holds {} pixels, its part needs {n}", part.pixels.len()),
            });
        }
        let slot = &mut by_index[h.index as usize];
        if let Some(j) = *slot {
            return Err(PartError::Duplicate {
                index: h.index,
                count,
                first: parts[j].0.clone(),
                file: file.clone(),
            });
        }
        *slot = Some(i);
    }
    let missing: Vec<u32> = (0..count)
        .filter(|&i| by_index[i as usize].is_none())
        .collect();
    if !missing.is_empty() {
        return Err(PartError::Missing { missing, count });
    }
    let mut image = Image::new(id.width, id.height);
    for (_, part) in parts {
        let tiles = part_tiles(part.header.index, count, id.tile_count())?;
        let mut pixels = part.pixels.as_slice();
        for tile in tiles {
            let [x0, y0, x1, y1] = integrator::tile_rect(id.width, id.height, tile);
            let (now, rest) = pixels.split_at(((x1 - x0) * (y1 - y0)) as usize);
            integrator::place_tile(&mut image, tile, now);
            pixels = rest;
        }
    }
    Ok((image, first.header.exposure))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Overrides, Scene};

    /// Scratched glass over a diffuse floor (also the Python tests' scene), 70 x 40 pixels:
    /// 5 x 3 = 15 tiles, the last column and row cut short.
    const SCENE: &str = include_str!("../tests/data/scratched-sphere.toml");

    fn scene() -> Scene {
        Scene::parse(
            SCENE,
            Path::new("test.toml"),
            Path::new("."),
            &Overrides::default(),
        )
        .unwrap()
    }

    fn parts(scene: &Scene, count: u32) -> Vec<(PathBuf, Part)> {
        (0..count)
            .map(|i| {
                let (part, _) =
                    Part::render(scene, SCENE, (i, count), &|_| {}, &AtomicBool::new(false))
                        .unwrap();
                // Through the file format, as `striae merge` reads them.
                let name = PathBuf::from(format!("part-{i}"));
                (
                    name.clone(),
                    Part::from_bytes(&part.to_bytes(), &name).unwrap(),
                )
            })
            .collect()
    }

    fn bits(image: &Image) -> Vec<u32> {
        image
            .pixels
            .iter()
            .flat_map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
            .collect()
    }

    /// 15 tiles in 1, 2, 7 (which does not divide them: parts of 3 and 2 tiles) and 15 parts;
    /// 16 parts are more than the tiles (a clear error).
    #[test]
    fn merged_parts_equal_the_whole_render_bit_for_bit() {
        let scene = scene();
        let (whole, _) = integrator::render(&scene, &|_| {});
        assert!(whole.mean().max_element() > 0.0);
        for count in [1, 2, 7, 15] {
            let (merged, exposure) = merge(&parts(&scene, count)).unwrap();
            assert_eq!(bits(&merged), bits(&whole), "{count} parts");
            assert_eq!(exposure, scene.settings.exposure);
        }
        let err = part_tiles(0, 16, 15).unwrap_err().to_string();
        assert!(err.contains("only 15 tiles"), "{err}");
    }

    #[test]
    fn bad_part_sets_and_files_are_refused() {
        let scene = scene();
        let two = parts(&scene, 2);
        let err = |p: &[(PathBuf, Part)]| merge(p).unwrap_err().to_string();
        assert!(
            err(&two[..1]).contains("parts missing: [1]"),
            "{}",
            err(&two[..1])
        );
        let dup = vec![two[0].clone(), two[1].clone(), two[0].clone()];
        assert!(
            err(&dup).contains("part 0 of 2 is given twice"),
            "{}",
            err(&dup)
        );
        let mut other = two.clone();
        other[1].1.header.render.seed = 6;
        assert!(
            err(&other).contains("seed is 5 in one and 6"),
            "{}",
            err(&other)
        );
        let mut other = two.clone();
        other[1].1.header.render.scene_hash = "0".into();
        assert!(err(&other).contains("scene_hash"), "{}", err(&other));
        assert!(err(&[]).contains("no part files"));
        let bytes = two[0].1.to_bytes();
        let file = Path::new("p.part");
        let corrupt = |b: &[u8]| Part::from_bytes(b, file).unwrap_err().to_string();
        let mut flipped = bytes.clone();
        flipped[bytes.len() / 2] ^= 1;
        assert!(
            corrupt(&flipped).contains("checksum"),
            "{}",
            corrupt(&flipped)
        );
        assert!(corrupt(&bytes[..bytes.len() - 5]).contains("checksum"));
        assert!(corrupt(b"hello").contains("magic"));
        assert!(corrupt(MAGIC).contains("cut short"));
        let err = part_tiles(2, 2, 6).unwrap_err().to_string();
        assert!(
            err.contains("part 2/2: the part index must lie in 0..2"),
            "{err}"
        );
    }
}
