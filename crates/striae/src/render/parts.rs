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
//!
//! A part can also hold only the samples `A..B` of its pixels (`striae render --samples A..B`,
//! [`PartHeader::samples`]); its pixels are then the sums of those samples. [`merge`] takes, for
//! every part index, either one part of all the samples or parts whose sample ranges tile
//! `0..spp` exactly (no overlap, no gap), adds their sums in `f64`, in range order, and divides
//! by the spp. That is not the whole render bit for bit: the whole render adds a pixel's samples
//! in `f32`, one after another, and a range that starts after sample 0 takes its pixels'
//! scratch-coverage footprints (`layers::CoverageCache::of_pixel`) from its own first samples,
//! not from the pixel's first. Both differences are far below the Monte Carlo noise
//! (`tests::merged_sample_ranges_match_the_whole_render_within_noise`, `docs/distributed.md`).

use crate::math::Rgb;
use crate::render::film::Image;
use crate::render::integrator::{self, Cancelled, RenderStats, Simd};
use crate::render::scene::Scene;
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
/// The largest part file a reader opens: the magic line, the longest header, the pixels of
/// the largest image the renderer makes and the checksum (its header then says how large it
/// must be).
const MAX_PART_BYTES: u64 = MAGIC.len() as u64
    + 4
    + MAX_HEADER as u64
    + crate::render::scene::MAX_RESOLUTION as u64
        * crate::render::scene::MAX_RESOLUTION as u64
        * 12
    + 32;
/// The most parts [`PartError::Missing`] lists before it counts the rest.
const LISTED: usize = 10;

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
    /// The samples of each pixel this part holds, `[A, B)` within `0..spp`, where it holds
    /// fewer than all of them; its pixels are then the sums of those samples, not the means.
    /// Absent for a part of all the samples.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub samples: Option<[u32; 2]>,
}

impl PartHeader {
    /// The samples `[A, B)` this part holds (`[0, spp)` for all of them).
    pub fn sample_range(&self) -> [u32; 2] {
        self.samples.unwrap_or([0, self.render.spp])
    }

    /// The number of pixels of the part the header describes, after checking it against what
    /// a render can be: the format, an image within the renderer's size limit, a part index
    /// and count within its tiles, an spp within the sampler's, a sample range within it and
    /// a finite exposure. The reason, as a phrase about the header, where it cannot be.
    fn pixel_count(&self) -> Result<usize, String> {
        if self.format != FORMAT {
            return Err(format!(
                "format {} (this striae reads format {FORMAT})",
                self.format
            ));
        }
        let r = &self.render;
        if !crate::render::scene::resolution_in_range(r.width, r.height) {
            return Err(format!(
                "its header's image size {}x{} is beyond the renderer's (each side 1 to {})",
                r.width,
                r.height,
                crate::render::scene::MAX_RESOLUTION
            ));
        }
        let max_spp = crate::render::sampler::MAX_SPP;
        if !(1..=max_spp).contains(&r.spp) {
            return Err(format!(
                "its header's spp {} is beyond the sampler's (1 to {max_spp})",
                r.spp
            ));
        }
        if let Some(range) = self.samples {
            check_samples(range, r.spp).map_err(|e| format!("its header's {e}"))?;
        }
        if !crate::render::film::exposure_in_range(self.exposure) {
            return Err(format!(
                "its header's exposure {:?} is beyond +-{} stops",
                self.exposure,
                crate::render::film::MAX_EXPOSURE
            ));
        }
        part_pixel_count((r.width, r.height), self.index, self.count)
            .map_err(|e| format!("its header's {e}"))
    }
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
    #[error(
        "parts missing: {} of 0..{count} (no part file given for them)",
        listed(.missing)
    )]
    Missing { missing: Vec<u32>, count: u32 },
    #[error("samples {first}..{end}: {reason}")]
    Samples {
        first: u32,
        end: u32,
        reason: String,
    },
    #[error(
        "part files {} (samples {}..{}) and {} (samples {}..{}) overlap: both hold samples {}..{} of part {index} of {count}",
        .first.display(), .a[0], .a[1], .file.display(), .b[0], .b[1], .both[0], .both[1]
    )]
    Overlap {
        index: u32,
        count: u32,
        first: PathBuf,
        a: [u32; 2],
        file: PathBuf,
        b: [u32; 2],
        both: [u32; 2],
    },
    #[error("samples missing: no part file holds samples {missing} of part {index} of {count} (the render has {spp} spp; given for it: {given})")]
    SamplesMissing {
        index: u32,
        count: u32,
        missing: String,
        spp: u32,
        given: String,
    },
    #[error("no part files given")]
    Empty,
    #[error(transparent)]
    Cancelled(#[from] Cancelled),
    /// An image the allocator refused.
    #[error(transparent)]
    Memory(#[from] crate::memory::MemoryError),
}

/// The first [`LISTED`] of `items`, and how many more there are: a render of 10,000 parts
/// merged from one file does not print 9,999 numbers.
fn listed(items: &[u32]) -> String {
    let shown: Vec<String> = items.iter().take(LISTED).map(u32::to_string).collect();
    match items.len().saturating_sub(LISTED) {
        0 => format!("[{}]", shown.join(", ")),
        more => format!(
            "[{}, ...] ({more} more, {} in all)",
            shown.join(", "),
            items.len()
        ),
    }
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

/// `A..B` (sample indices, counting from 0, `B` excluded): the text of `--samples`.
pub fn parse_samples(text: &str) -> Result<[u32; 2], String> {
    let bad = || format!("`{text}` is not A..B (the samples A to B-1 of every pixel, e.g. 0..64)");
    let (a, b) = text.split_once("..").ok_or_else(bad)?;
    let a: u32 = a.trim().parse().map_err(|_| bad())?;
    let b: u32 = b.trim().parse().map_err(|_| bad())?;
    Ok([a, b])
}

/// Check the sample range `[first, end)` of a render of `spp` samples per pixel: not empty and
/// within `0..spp`.
pub fn check_samples([first, end]: [u32; 2], spp: u32) -> Result<(), PartError> {
    let bad = |reason: String| Err(PartError::Samples { first, end, reason });
    if first >= end {
        return bad("A must be less than B (the range A..B excludes B)".into());
    }
    if end > spp {
        return bad(format!(
            "B must be at most the samples per pixel ({spp}): the range lies in 0..{spp}"
        ));
    }
    Ok(())
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
    /// Render part `index` of `count` of `scene` (loaded from `scene_text`), of the samples
    /// `samples` of each pixel (`[A, B)`; `None`, or all of `0..spp`: every sample, the
    /// pixels' means); `progress` and `cancel` as in [`integrator::render_tiles`].
    pub fn render(
        scene: &Scene,
        scene_text: &str,
        (index, count): (u32, u32),
        samples: Option<[u32; 2]>,
        progress: &(dyn Fn(u64) + Sync),
        cancel: &AtomicBool,
    ) -> Result<(Part, RenderStats), PartError> {
        let render = RenderId::new(scene_text, scene);
        let tiles = part_tiles(index, count, render.tile_count())?;
        let samples = samples.filter(|&s| s != [0, render.spp]);
        let (pixels, stats) = match samples {
            None => integrator::render_tiles(scene, &tiles, progress, cancel, Simd::Auto)?,
            Some(range @ [a, b]) => {
                check_samples(range, render.spp)?;
                integrator::render_tile_sums(scene, &tiles, a..b, progress, cancel, Simd::Auto)?
            }
        };
        let header = PartHeader {
            format: FORMAT,
            render,
            index,
            count,
            exposure: scene.settings.exposure,
            samples,
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
        if !bytes.starts_with(MAGIC) {
            return Err(corrupt("it does not start with the part files' magic line"));
        }
        if bytes.len() < MAGIC.len() + 4 + 32 {
            return Err(corrupt("it is cut short"));
        }
        let (content, digest) = bytes.split_at(bytes.len() - 32);
        if Sha256::digest(content).as_slice() != digest {
            return Err(corrupt(
                "its checksum does not match (the file is damaged or cut short)",
            ));
        }
        let (header, pixels_at, n) = Part::head(content, file)?;
        let data = &content[pixels_at..];
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
        let pixels: Vec<Rgb> = data
            .chunks_exact(12)
            .map(|c| {
                let f = |i: usize| f32::from_le_bytes(c[i..i + 4].try_into().expect("4 bytes"));
                Rgb::new(f(0), f(4), f(8))
            })
            .collect();
        // A render drops non-finite samples, so only a damaged or forged file holds one (the
        // image's writer would blame the scene for it).
        if let Some(k) = pixels.iter().position(|p| !p.is_finite()) {
            let (x, y) = pixel_position(&header, k);
            return Err(corrupt(&format!(
                "its pixel ({x}, {y}) is {}, not finite",
                pixels[k]
            )));
        }
        Ok(Part { header, pixels })
    }

    /// The header at the start of a part file's `bytes` (at least the magic line), checked
    /// ([`PartHeader::pixel_count`]), with where its pixels start and how many there are.
    fn head(bytes: &[u8], file: &Path) -> Result<(PartHeader, usize, usize), PartError> {
        let corrupt = |reason: String| PartError::Corrupt {
            file: file.to_path_buf(),
            reason,
        };
        let body = bytes
            .strip_prefix(MAGIC)
            .ok_or_else(|| corrupt("it does not start with the part files' magic line".into()))?;
        let len = body
            .get(..4)
            .map(|b| u32::from_le_bytes(b.try_into().expect("4 bytes")))
            .ok_or_else(|| corrupt("it is cut short".into()))?;
        let rest = &body[4..];
        if len > MAX_HEADER || len as usize > rest.len() {
            return Err(corrupt("its header length is out of range".into()));
        }
        let header: PartHeader = serde_json::from_slice(&rest[..len as usize])
            .map_err(|e| corrupt(format!("its header does not parse: {e}")))?;
        let n = header.pixel_count().map_err(corrupt)?;
        Ok((header, MAGIC.len() + 4 + len as usize, n))
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

    /// Read the part file `path`: a regular file only, whose size is checked against its
    /// header before its pixels are read (a header cannot make the reader take more than the
    /// pixels it describes, and a device or FIFO is refused unopened).
    pub fn read(path: &Path) -> Result<Part, PartError> {
        use std::io::Read;
        let read_error = |e: std::io::Error| PartError::Read {
            file: path.to_path_buf(),
            message: e.to_string(),
        };
        let file = crate::io::open_regular(path, MAX_PART_BYTES).map_err(read_error)?;
        let size = file.metadata().map_err(read_error)?.len();
        let mut bytes = Vec::new();
        let mut file = file.take(MAGIC.len() as u64 + 4 + MAX_HEADER as u64);
        file.read_to_end(&mut bytes).map_err(read_error)?;
        let (header, pixels_at, n) = Part::head(&bytes, path)?;
        let expected = (pixels_at + n * 12 + 32) as u64;
        if size != expected {
            return Err(PartError::Corrupt {
                file: path.to_path_buf(),
                reason: format!(
                    "it is {size} bytes, part {}/{} of a {}x{} image is {expected} (the file is damaged or cut short)",
                    header.index, header.count, header.render.width, header.render.height
                ),
            });
        }
        // Read on to exactly the expected size; a file that grew meanwhile fails the checksum.
        let mut file = file.into_inner().take(expected - bytes.len() as u64);
        bytes.reserve_exact(expected as usize - bytes.len());
        file.read_to_end(&mut bytes).map_err(read_error)?;
        Part::from_bytes(&bytes, path)
    }
}

/// The image position of pixel `k` of the part `header` describes.
fn pixel_position(header: &PartHeader, k: usize) -> (u32, u32) {
    let (w, h) = (header.render.width, header.render.height);
    let tiles = part_tiles(header.index, header.count, integrator::tile_count(w, h))
        .expect("a checked header");
    let mut k = k as u32;
    for t in tiles {
        let [x0, y0, x1, y1] = integrator::tile_rect(w, h, t);
        let tw = x1 - x0;
        if k < tw * (y1 - y0) {
            return (x0 + k % tw, y0 + k / tw);
        }
        k -= tw * (y1 - y0);
    }
    unreachable!("pixel {k} beyond the part")
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
/// exposure they carry: every part of one render, each with all its samples once (in one file,
/// or in files whose sample ranges tile `0..spp`).
pub fn merge(parts: &[(PathBuf, Part)]) -> Result<(Image, f32), PartError> {
    let (first_file, first) = parts.first().ok_or(PartError::Empty)?;
    let (id, count) = (&first.header.render, first.header.count);
    let checked = |file: &PathBuf, header: &PartHeader| {
        header.pixel_count().map_err(|reason| PartError::Corrupt {
            file: file.clone(),
            reason,
        })
    };
    // Before anything is sized by the first part's count and image.
    checked(first_file, &first.header)?;
    let mut by_index: Vec<Vec<usize>> = vec![Vec::new(); count as usize];
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
        let n = checked(file, h)?;
        if part.pixels.len() != n {
            return Err(PartError::Corrupt {
                file: file.clone(),
                reason: format!("it holds {} pixels, its part needs {n}", part.pixels.len()),
            });
        }
        by_index[h.index as usize].push(i);
    }
    let missing: Vec<u32> = (0..count)
        .filter(|&i| by_index[i as usize].is_empty())
        .collect();
    if !missing.is_empty() {
        return Err(PartError::Missing { missing, count });
    }
    for (index, files) in by_index.iter_mut().enumerate() {
        order_samples(parts, files, (index as u32, count), id.spp)?;
    }
    let size = format!("the merged {}x{} image", id.width, id.height);
    let mut image = Image::try_new(id.width, id.height, &size)?;
    for (index, files) in by_index.iter().enumerate() {
        let pixels = match files.as_slice() {
            // All the samples in one part: its pixels as they are (bit for bit).
            &[i] if parts[i].1.header.samples.is_none() => parts[i].1.pixels.clone(),
            _ => mean_of_sums(files.iter().map(|&i| &parts[i].1.pixels[..]), id.spp),
        };
        place_part(&mut image, (index as u32, count), &pixels)?;
    }
    Ok((image, first.header.exposure))
}

/// The memory [`merge`] and writing its image take beyond the parts themselves: the image and
/// its encoders ([`crate::render::film::BYTES_PER_PIXEL`] a pixel of the first part's render),
/// and, for the largest part, its pixels' sums in `f64` and their means (36 bytes a pixel).
pub fn merge_memory_estimate(parts: &[(PathBuf, Part)]) -> u64 {
    let Some((_, first)) = parts.first() else {
        return 0;
    };
    let id = &first.header.render;
    let largest = parts.iter().map(|(_, p)| p.pixels.len() as u64).max();
    (id.width as u64 * id.height as u64 * crate::render::film::BYTES_PER_PIXEL)
        .saturating_add(largest.unwrap_or(0).saturating_mul(36))
}

/// Sort the parts `files` (indices into `parts`) of part `index` of `count` by their sample
/// ranges, and check that these tile `0..spp`: one part given twice, two ranges that overlap
/// or samples that no range holds are errors naming them.
fn order_samples(
    parts: &[(PathBuf, Part)],
    files: &mut [usize],
    (index, count): (u32, u32),
    spp: u32,
) -> Result<(), PartError> {
    let range = |i: usize| parts[i].1.header.sample_range();
    files.sort_by_key(|&i| range(i));
    let mut gaps = Vec::new();
    let mut next = 0;
    for (k, &i) in files.iter().enumerate() {
        let [a, b] = range(i);
        if k > 0 && a < next {
            let j = files[k - 1];
            if range(j) == range(i) && parts[i].1.header.samples.is_none() {
                return Err(PartError::Duplicate {
                    index,
                    count,
                    first: parts[j].0.clone(),
                    file: parts[i].0.clone(),
                });
            }
            return Err(PartError::Overlap {
                index,
                count,
                first: parts[j].0.clone(),
                a: range(j),
                file: parts[i].0.clone(),
                b: range(i),
                both: [a, next.min(b)],
            });
        }
        if a > next {
            gaps.push(format!("{next}..{a}"));
        }
        next = b;
    }
    if next < spp {
        gaps.push(format!("{next}..{spp}"));
    }
    if gaps.is_empty() {
        return Ok(());
    }
    let given = files.iter().map(|&i| {
        let [a, b] = range(i);
        format!("{} ({a}..{b})", parts[i].0.display())
    });
    Err(PartError::SamplesMissing {
        index,
        count,
        missing: gaps.join(", "),
        spp,
        given: given.collect::<Vec<_>>().join(", "),
    })
}

/// The pixels' means of `spp` samples from their sums over sample ranges (`sums`, in range
/// order): added in `f64`, divided by `spp`, rounded to `f32` once.
fn mean_of_sums<'a>(mut sums: impl Iterator<Item = &'a [Rgb]>, spp: u32) -> Vec<Rgb> {
    let mut total: Vec<glam::DVec3> = match sums.next() {
        Some(first) => first.iter().map(|p| p.as_dvec3()).collect(),
        None => return Vec::new(),
    };
    for part in sums {
        for (t, p) in total.iter_mut().zip(part) {
            *t += p.as_dvec3();
        }
    }
    total.iter().map(|t| (*t / spp as f64).as_vec3()).collect()
}

/// Copy the pixels of part `index` of `count` ([`part_tiles`]' tiles, each row by row) into
/// `image`.
fn place_part(
    image: &mut Image,
    (index, count): (u32, u32),
    pixels: &[Rgb],
) -> Result<(), PartError> {
    let (w, h) = (image.width, image.height);
    let mut pixels = pixels;
    for tile in part_tiles(index, count, integrator::tile_count(w, h))? {
        let [x0, y0, x1, y1] = integrator::tile_rect(w, h, tile);
        let (now, rest) = pixels.split_at(((x1 - x0) * (y1 - y0)) as usize);
        integrator::place_tile(image, tile, now);
        pixels = rest;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::scene::{Overrides, Scene};

    /// Scratched glass over a diffuse floor (also the Python tests' scene), 70 x 40 pixels:
    /// 5 x 3 = 15 tiles, the last column and row cut short.
    const SCENE: &str = include_str!("../../tests/data/scratched-sphere.toml");

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
                let (part, _) = Part::render(
                    scene,
                    SCENE,
                    (i, count),
                    None,
                    &|_| {},
                    &AtomicBool::new(false),
                )
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

    /// The scene at `spp` samples per pixel and seed `seed`.
    fn scene_at(spp: u32, seed: u64) -> Scene {
        let overrides = Overrides {
            spp: Some(spp),
            seed: Some(seed),
            ..Overrides::default()
        };
        Scene::parse(SCENE, Path::new("test.toml"), Path::new("."), &overrides).unwrap()
    }

    /// Parts `(index, count)` of the sample ranges `ranges`, through the file format.
    fn sample_parts(scene: &Scene, tile: (u32, u32), ranges: &[[u32; 2]]) -> Vec<(PathBuf, Part)> {
        ranges
            .iter()
            .map(|&r| {
                let samples = Some(r);
                let (part, _) = Part::render(
                    scene,
                    SCENE,
                    tile,
                    samples,
                    &|_| {},
                    &AtomicBool::new(false),
                )
                .unwrap();
                let name = PathBuf::from(format!("part-{}-{}-{}..{}", tile.0, tile.1, r[0], r[1]));
                (
                    name.clone(),
                    Part::from_bytes(&part.to_bytes(), &name).unwrap(),
                )
            })
            .collect()
    }

    /// The largest absolute difference of two images' channels, and the root mean square.
    fn difference_of(a: &Image, b: &Image) -> (f32, f64) {
        let d: Vec<f32> = a
            .pixels
            .iter()
            .zip(&b.pixels)
            .flat_map(|(p, q)| (*p - *q).abs().to_array())
            .collect();
        let rms = (d.iter().map(|&x| x as f64 * x as f64).sum::<f64>() / d.len() as f64).sqrt();
        (d.iter().fold(0.0f32, |m, &x| m.max(x)), rms)
    }

    /// 8 and 64 spp split into 2 and 3 sample ranges, and `0..1, 1..spp` (whose pixel
    /// footprints start at sample 1): every pixel the whole render's up to `f32` rounding, but
    /// for a few whose samples see the scratched glass, and those by less than the noise
    /// between two seeds (the measured values, printed with `--nocapture`, are the table of
    /// `docs/distributed.md`).
    #[test]
    fn merged_sample_ranges_match_the_whole_render_within_noise() {
        for spp in [8, 64] {
            let scene = scene_at(spp, 5);
            let (whole, _) = integrator::render(&scene, &|_| {});
            let (other_seed, _) = integrator::render(&scene_at(spp, 6), &|_| {});
            let (noise_max, noise_rms) = difference_of(&whole, &other_seed);
            eprintln!("{spp} spp, seed 5 against 6: max {noise_max:.4}, rms {noise_rms:.5}");
            let (h, t) = (spp / 2, spp / 3);
            for ranges in [
                vec![[0, h], [h, spp]],
                vec![[0, t], [t, 2 * t], [2 * t, spp]],
                vec![[0, 1], [1, spp]],
            ] {
                let mut parts = sample_parts(&scene, (0, 1), &ranges);
                parts.reverse(); // any order
                let (merged, _) = merge(&parts).unwrap();
                let (max, rms) = difference_of(&merged, &whole);
                let beyond_rounding = merged
                    .pixels
                    .iter()
                    .zip(&whole.pixels)
                    .filter(|(p, q)| {
                        (**p - **q).abs().max_element() > 1e-5 * q.max_element().max(1e-3)
                    })
                    .count();
                eprintln!("{ranges:?}: max {max:.4}, rms {rms:.5}, {beyond_rounding} pixels beyond rounding");
                assert!(
                    max < 0.5 * noise_max,
                    "{ranges:?}: max {max} vs {noise_max}"
                );
                assert!(
                    rms < 0.25 * noise_rms,
                    "{ranges:?}: rms {rms} vs {noise_rms}"
                );
                assert!(
                    beyond_rounding <= 84,
                    "{ranges:?}: {beyond_rounding} pixels"
                ); // 3 %
            }
        }
    }

    /// Tiles times samples: 2 parts of tiles, the first split 0..4, 4..8 and the second whole,
    /// are the sample merge's pixels in the first part's tiles and the whole render's, bit for
    /// bit, in the second's.
    #[test]
    fn tiles_and_sample_ranges_merge_together() {
        let scene = scene_at(8, 5);
        let (whole, _) = integrator::render(&scene, &|_| {});
        let halves = [[0, 4], [4, 8]];
        let (by_samples, _) = merge(&sample_parts(&scene, (0, 1), &halves)).unwrap();
        let mut parts = sample_parts(&scene, (0, 2), &halves);
        parts.extend(sample_parts(&scene, (1, 2), &[[0, 8]]));
        let (merged, _) = merge(&parts).unwrap();
        let tiles_of_0 = part_tiles(0, 2, integrator::tile_count(70, 40)).unwrap();
        let mut expected = whole.clone();
        for t in tiles_of_0 {
            let [x0, y0, x1, y1] = integrator::tile_rect(70, 40, t);
            for y in y0..y1 {
                for x in x0..x1 {
                    let i = (y * 70 + x) as usize;
                    expected.pixels[i] = by_samples.pixels[i];
                }
            }
        }
        assert_eq!(bits(&merged), bits(&expected));
        assert_ne!(bits(&merged), bits(&whole), "the split changes some pixel");
    }

    #[test]
    fn bad_sample_ranges_are_refused() {
        let scene = scene_at(8, 5);
        let err = |p: &[(PathBuf, Part)]| merge(p).unwrap_err().to_string();
        let overlap = sample_parts(&scene, (0, 1), &[[0, 5], [4, 8]]);
        let e = err(&overlap);
        assert!(
            e.contains("part-0-1-0..5 (samples 0..5) and part-0-1-4..8 (samples 4..8) overlap")
                && e.contains("both hold samples 4..5 of part 0 of 1"),
            "{e}"
        );
        let mut same = sample_parts(&scene, (0, 1), &[[0, 4], [4, 8]]);
        same.push(same[1].clone());
        assert!(
            err(&same).contains("both hold samples 4..8"),
            "{}",
            err(&same)
        );
        let mut with_whole = same[..2].to_vec();
        with_whole.extend(parts(&scene, 1));
        assert!(err(&with_whole).contains("overlap"), "{}", err(&with_whole));
        let gaps = sample_parts(&scene, (0, 1), &[[1, 3], [4, 6]]);
        let e = err(&gaps);
        assert!(
            e.contains("no part file holds samples 0..1, 3..4, 6..8 of part 0 of 1")
                && e.contains("given for it: part-0-1-1..3 (1..3), part-0-1-4..6 (4..6)"),
            "{e}"
        );
        let mut foreign = sample_parts(&scene, (0, 1), &[[0, 4]]);
        foreign.extend(sample_parts(&scene_at(8, 6), (0, 1), &[[4, 8]]));
        assert!(
            err(&foreign).contains("seed is 5 in one and 6"),
            "{}",
            err(&foreign)
        );
        let check = |r: [u32; 2]| check_samples(r, 8).unwrap_err().to_string();
        assert!(check([4, 4]).contains("A must be less than B"));
        assert!(check([0, 9]).contains("at most the samples per pixel (8)"));
        assert_eq!(parse_samples(" 2..7"), Ok([2, 7]));
        for bad in ["2-7", "..7", "a..b", "-1..4", "0..4..8"] {
            assert!(
                parse_samples(bad).unwrap_err().contains("is not A..B"),
                "{bad}"
            );
        }
        let mut part = same[0].1.clone();
        part.header.samples = Some([0, 9]);
        let e = Part::from_bytes(&part.to_bytes(), Path::new("p.part")).unwrap_err();
        assert!(
            e.to_string().contains("p.part") && e.to_string().contains("samples 0..9"),
            "{e}"
        );
    }
}
