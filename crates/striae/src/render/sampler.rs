//! Per-pixel sample streams for the path tracer, of two kinds ([`SamplerKind`]):
//!
//! * **`sobol`** (the default): Owen-scrambled Sobol points (Burley 2020, "Practical Hash-based
//!   Owen Scrambling", via the `sobol_burley` crate), pbrt-v4's `PaddedSobolSampler` /
//!   `ZSobolSampler` family: stratified in every 4-dimension set, so a pixel converges faster
//!   than with independent numbers.
//! * **`independent`**: uniform numbers with no stratification (pbrt-v4's `IndependentSampler`,
//!   Mitsuba 3's `independent`, the sampler Mitsuba's renders in `validation/` and
//!   `scripts/bench_render.py` use). Each number is a hash of `(pixel seed, sample, dimension)`
//!   (SplitMix64's finaliser): counter-based, so the dimension layout below and the seeks work
//!   unchanged, and cheaper than a Sobol set where a bounce reads only one or two of its
//!   numbers.
//!
//! Every pixel gets its own stream, seeded by a hash of the pixel index and the render seed, so
//! a pixel's samples do not depend on which thread renders it or in which order: the image is
//! bit-identical whatever the thread count. Within a sample, dimensions are laid out by
//! purpose: the camera uses dimensions `0..CAMERA_DIMS`, and bounce `k` uses the block
//! `CAMERA_DIMS + k * BOUNCE_DIMS ..`, so the same random number drives the same decision on
//! every sample (pbrt-v4's `Sampler` discipline). Past the 256 dimensions `sobol_burley`
//! provides, the dimension wraps and the seed is re-hashed, which gives an independent (still
//! Owen-scrambled, no longer stratified against the earlier dimensions) stream. A bounce's
//! Sobol numbers (its block: two 4-dimension sets) are worked out together once the first is
//! read ([`sobol_block`]): the sets share the sample's index, so its bits are walked once for
//! both, and their scrambles run 8 wide in the render loop's SIMD copies.

use crate::hash::splitmix64;
use crate::math::Vec2;

/// Dimensions used by the camera ray: pixel position (2) and lens position (2).
pub const CAMERA_DIMS: u32 = 4;
/// Dimensions reserved per bounce: BSDF lobe (1) and direction (2), light choice (1) and
/// position (2), Russian roulette (1), and one for the material's layer choice (1, drawn by
/// [`PixelSampler::next_1d_hashed`]; `layer_mix = "stochastic"` reads the BSDF lobe's instead).
pub const BOUNCE_DIMS: u32 = 8;
/// The BSDF lobe's dimension within a bounce's block ([`PixelSampler::seek`]).
pub const LOBE_DIM: u32 = 4;
/// The most samples per pixel one sequence supports (a limit of `sobol_burley`).
pub const MAX_SPP: u32 = 1 << 16;

/// Which numbers a [`PixelSampler`] draws (scene key `render.sampler`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SamplerKind {
    /// Owen-scrambled Sobol points.
    #[default]
    Sobol,
    /// Independent uniform numbers (hashed counters).
    Independent,
}

impl SamplerKind {
    /// Every kind, in the order messages list them.
    pub const ALL: [SamplerKind; 2] = [SamplerKind::Sobol, SamplerKind::Independent];

    /// The name used in scene files and on the command line (the one place it is spelled).
    pub fn name(self) -> &'static str {
        match self {
            SamplerKind::Sobol => "sobol",
            SamplerKind::Independent => "independent",
        }
    }

    /// The kind called `name` (one of [`SamplerKind::name`]'s).
    pub fn from_name(name: &str) -> Option<SamplerKind> {
        Self::ALL.into_iter().find(|kind| kind.name() == name)
    }

    /// The allowed names for error messages: `"sobol" or "independent"`.
    pub fn allowed_names() -> String {
        let quoted: Vec<String> = Self::ALL
            .iter()
            .map(|k| format!("\"{}\"", k.name()))
            .collect();
        quoted.join(" or ")
    }
}

/// The random numbers of one sample of one pixel.
#[derive(Clone, Debug)]
pub struct PixelSampler {
    kind: SamplerKind,
    seed: u32,
    /// The independent sampler's key of this pixel and sample (dimension 0).
    key: u64,
    /// The Sobol sampler's shuffled (Owen-scrambled, bit-reversed) sample index: the first step
    /// of `sobol_burley::sample_4d`, which depends on the seed and the sample only, so it is
    /// computed once per sample instead of once per 4-dimension set (0 for the independent
    /// kind, which does not read it).
    shuffled_rev_index: u32,
    sample_index: u32,
    dimension: u32,
    /// The numbers last worked out and which: bounce `k`'s block ([`sobol_block`], all 8
    /// values), or one 4-dimension set `s` (`SINGLE | s`, its values first: the camera's, and
    /// sets past the blocks; `sobol_burley::sample_4d` computes four dimensions for about the
    /// cost of one, and gives exactly what four calls of `sample` would); `u32::MAX` for
    /// none.
    cached_key: u32,
    cached: [f32; BLOCK_DIMS],
}

impl PixelSampler {
    /// The Sobol stream of sample `sample_index` (< [`MAX_SPP`]) of pixel `pixel_index` under
    /// `seed`.
    pub fn new(pixel_index: u64, sample_index: u32, seed: u64) -> Self {
        Self::with_kind(SamplerKind::Sobol, pixel_index, sample_index, seed)
    }

    /// The stream of sample `sample_index` (< [`MAX_SPP`]) of pixel `pixel_index` under `seed`,
    /// of the given kind.
    pub fn with_kind(kind: SamplerKind, pixel_index: u64, sample_index: u32, seed: u64) -> Self {
        let pixel_seed = splitmix64(splitmix64(seed) ^ pixel_index);
        let sample_index = sample_index.min(MAX_SPP - 1);
        PixelSampler {
            kind,
            seed: pixel_seed as u32,
            // Sample `i`'s dimensions are the keys `key + d`: distinct samples of a pixel
            // start 2^32 apart, far beyond any dimension a path reads.
            key: pixel_seed.wrapping_add((sample_index as u64) << 32),
            shuffled_rev_index: match kind {
                SamplerKind::Sobol => shuffle_rev_index(sample_index, pixel_seed as u32),
                SamplerKind::Independent => 0,
            },
            sample_index,
            dimension: 0,
            cached_key: u32::MAX,
            cached: [0.0; BLOCK_DIMS],
        }
    }

    /// Jump to the dimension block of bounce `depth` (0 = the first hit).
    pub fn start_bounce(&mut self, depth: u32) {
        self.dimension = CAMERA_DIMS + depth * BOUNCE_DIMS;
    }

    /// Jump to dimension `offset` within the block of bounce `depth` (the layout of a block:
    /// 0 layer choice (hashed), 1 light choice, 2-3 light position, 4 BSDF lobe, 5-6 BSDF direction,
    /// 7 Russian roulette), so a decision keeps its dimension whether or not earlier ones ran.
    pub fn seek(&mut self, depth: u32, offset: u32) {
        self.dimension = CAMERA_DIMS + depth * BOUNCE_DIMS + offset;
    }

    /// The number of dimension `offset` within the block of bounce `depth`, without moving
    /// the stream: the value a later [`Self::seek`] there then draws again.
    #[inline(always)]
    pub fn peek(&mut self, depth: u32, offset: u32) -> f32 {
        let d = self.dimension;
        self.seek(depth, offset);
        let u = self.next_1d();
        self.dimension = d;
        u
    }

    /// The next number in `[0, 1)`. (Forced inline: the render loop's copies must hold it.)
    #[inline(always)]
    pub fn next_1d(&mut self) -> f32 {
        if self.kind == SamplerKind::Independent {
            return self.next_1d_hashed();
        }
        let d = self.dimension;
        self.dimension += 1;
        let set = d / 4;
        let (key, at) = if (1..=2 * BLOCKS).contains(&set) {
            (
                (d - CAMERA_DIMS) / BOUNCE_DIMS,
                (d - CAMERA_DIMS) % BOUNCE_DIMS,
            )
        } else {
            (SINGLE | set, d % 4)
        };
        if key & SINGLE == 0 {
            return self.block(key)[at as usize];
        }
        if key != self.cached_key {
            // `NUM_DIMENSIONS` is a multiple of 4, so a set never straddles the wrap.
            let n = sobol_burley::NUM_DIMENSIONS;
            let values = if d < n {
                sobol_set(self.shuffled_rev_index, set, self.seed)
            } else {
                let seed = splitmix64(self.seed as u64 ^ ((d / n) as u64) << 32) as u32;
                sobol_burley::sample_4d(self.sample_index, (d % n) / 4, seed)
            };
            self.cached[..4].copy_from_slice(&values);
            self.cached_key = key;
        }
        self.cached[at as usize]
    }

    /// Bounce `k`'s block (`k < BLOCKS`), worked out unless the cache holds it.
    #[inline(always)]
    fn block(&mut self, k: u32) -> &[f32; BLOCK_DIMS] {
        if self.cached_key != k {
            self.cached = sobol_block(self.shuffled_rev_index, k, self.seed);
            self.cached_key = k;
        }
        &self.cached
    }

    /// The numbers of dimensions `1..BOUNCE_DIMS` of bounce `depth`'s block, each what
    /// [`Self::seek`]`(depth, 1)` and [`Self::next_1d`] in turn give (test
    /// `bounce_numbers_equal_one_at_a_time`), from one look at the block where it is Sobol's;
    /// the stream is left past the block.
    #[inline(always)]
    pub fn bounce_numbers(&mut self, depth: u32) -> [f32; BOUNCE_DIMS as usize - 1] {
        let mut u = [0.0; BOUNCE_DIMS as usize - 1];
        if self.kind == SamplerKind::Sobol && depth < BLOCKS {
            u.copy_from_slice(&self.block(depth)[1..]);
            self.seek(depth + 1, 0);
            return u;
        }
        self.seek(depth, 1);
        for x in &mut u {
            *x = self.next_1d();
        }
        u
    }

    /// The next number in `[0, 1)`, hashed from the pixel, the sample and the dimension
    /// whatever the kind (what [`Self::next_1d`] gives for the independent kind): for a choice
    /// that gains nothing from stratification, such as breaking a rare tie, at the cost of one
    /// hash instead of a Sobol set (a 4-dimension set costs about as much as a BSDF lookup).
    #[inline]
    pub fn next_1d_hashed(&mut self) -> f32 {
        let d = self.dimension;
        self.dimension += 1;
        crate::hash::unit_f32(splitmix64(self.key.wrapping_add(d as u64)))
    }

    /// The next two numbers in `[0, 1)^2`.
    #[inline(always)]
    pub fn next_2d(&mut self) -> Vec2 {
        let x = self.next_1d();
        let y = self.next_1d();
        Vec2::new(x, y)
    }
}

/// Samples a pixel's camera numbers are drawn for at once ([`PixelSampler::sobol_camera_lanes`]).
pub const CAMERA_LANES: usize = 32;

impl PixelSampler {
    /// The lane form of a pixel's camera numbers: the Sobol streams of samples
    /// `first..first + CAMERA_LANES` of pixel `pixel_index` under `seed` (each index clamped
    /// as [`Self::with_kind`] clamps it), each past its [`CAMERA_DIMS`] camera dimensions, and
    /// those numbers. Bit for bit what `with_kind(SamplerKind::Sobol, ..)` and four
    /// [`Self::next_1d`] give (test `camera_lanes_equal_one_sample_at_a_time`): each stream is
    /// `with_kind`'s, and the numbers are worked out as one operation over all the samples at
    /// each step, which the render loop's SIMD copies run 8 or 16 samples at a time: the Sobol
    /// point of the first set (every direction row masked by its bit of the index, as
    /// `sobol_int4_rev` XORs the rows of the set bits) and its Owen scramble.
    #[inline(always)]
    pub fn sobol_camera_lanes(
        pixel_index: u64,
        first: u32,
        seed: u64,
    ) -> ([PixelSampler; CAMERA_LANES], [[f32; CAMERA_LANES]; 4]) {
        use sobol_burley::parts::{owen_scramble_rev, sobol_int4_rev, u32_to_f32_norm};
        const L: usize = CAMERA_LANES;
        let mut samplers: [PixelSampler; L] = std::array::from_fn(|k| {
            PixelSampler::with_kind(SamplerKind::Sobol, pixel_index, first + k as u32, seed)
        });
        // (A loop here and a written-out array below, not `[T; N]::map`: that stays an
        // out-of-line call compiled for baseline x86-64, outside the render loop's SIMD copies.)
        let mut index = [0u32; L];
        for (i, sampler) in index.iter_mut().zip(&samplers) {
            *i = sampler.shuffled_rev_index;
        }
        // Set 0's direction rows (of the index's top 16 bits) and scrambles, as `sobol_set`.
        let rows: [[u32; 4]; 16] = std::array::from_fn(|b| sobol_int4_rev(1 << (31 - b), 0).into());
        let scramble: [u32; 4] = set_scramble(samplers[0].seed, 0).into();
        let mut numbers = [[0.0f32; L]; 4];
        for (d, out) in numbers.iter_mut().enumerate() {
            let mut point = [0u32; L];
            for (b, row) in rows.iter().enumerate() {
                for (p, i) in point.iter_mut().zip(&index) {
                    *p ^= row[d] & ((i >> (31 - b)) & 1).wrapping_neg();
                }
            }
            for (o, p) in out.iter_mut().zip(&point) {
                *o = u32_to_f32_norm(owen_scramble_rev(*p, scramble[d]).reverse_bits());
            }
        }
        for (k, sampler) in samplers.iter_mut().enumerate() {
            sampler.dimension = CAMERA_DIMS;
            sampler.cached_key = SINGLE;
            sampler.cached[..4].copy_from_slice(&[
                numbers[0][k],
                numbers[1][k],
                numbers[2][k],
                numbers[3][k],
            ]);
        }
        (samplers, numbers)
    }
}

/// The index shuffle of `sobol_burley::sample_4d` (its first step, verbatim).
#[inline]
fn shuffle_rev_index(sample_index: u32, seed: u32) -> u32 {
    use sobol_burley::parts::{hash, owen_scramble_rev};
    owen_scramble_rev(sample_index.reverse_bits(), hash(seed ^ 0x79c68e4a))
}

/// The rest of `sobol_burley::sample_4d(sample_index, set, seed)` given
/// `shuffle_rev_index(sample_index, seed)`: the same operations, so the same bits (test
/// `cached_4d_sets_equal_single_dimensions`).
#[inline]
fn sobol_set(shuffled_rev_index: u32, set: u32, seed: u32) -> [f32; 4] {
    use sobol_burley::parts::{owen_scramble_int4_rev, sobol_int4_rev};
    let sobol = sobol_int4_rev(shuffled_rev_index, set);
    owen_scramble_int4_rev(sobol, set_scramble(seed, set))
        .reverse_bits()
        .to_f32_norm()
}

/// The key bit of a single set's numbers in [`PixelSampler`]'s cache.
const SINGLE: u32 = 1 << 31;
/// The bounces whose blocks [`sobol_block`] works out: those within `sobol_burley`'s
/// dimensions (sets `1..=2 * BLOCKS`).
const BLOCKS: u32 = (sobol_burley::NUM_DIMENSION_SETS_4D - 1) / 2;
/// The numbers in a block.
const BLOCK_DIMS: usize = BOUNCE_DIMS as usize;

/// Every block's direction rows, `[bounce][bit][dimension]`: row `b` of a dimension is what
/// `sobol_int4_rev` XORs in for bit `31 - b` of the (reversed) index.
static BLOCK_ROWS: std::sync::LazyLock<Vec<[[u32; BLOCK_DIMS]; 16]>> =
    std::sync::LazyLock::new(|| {
        use sobol_burley::parts::sobol_int4_rev;
        (0..BLOCKS)
            .map(|k| {
                std::array::from_fn(|b| {
                    let a: [u32; 4] = sobol_int4_rev(1 << (31 - b), 1 + 2 * k).into();
                    let c: [u32; 4] = sobol_int4_rev(1 << (31 - b), 2 + 2 * k).into();
                    [a[0], a[1], a[2], a[3], c[0], c[1], c[2], c[3]]
                })
            })
            .collect()
    });

/// The Sobol numbers of bounce `k`'s block (sets `1 + 2k` and `2 + 2k`), each what
/// [`sobol_set`] gives, worked out together: the index's bits are walked once for both sets,
/// and the scrambles run 8 wide (in the render loop's SIMD copies).
#[inline(always)]
fn sobol_block(shuffled_rev_index: u32, k: u32, seed: u32) -> [f32; BLOCK_DIMS] {
    use sobol_burley::parts::{hash, owen_scramble_rev, u32_to_f32_norm};
    let rows = &BLOCK_ROWS[k as usize];
    let mut point = [0u32; BLOCK_DIMS];
    // (The index's top 16 bits, as `sobol_int4_rev`: row `b` for each set bit `31 - b`.)
    let mut index = shuffled_rev_index & 0xffff_0000;
    while index != 0 {
        let b = index.leading_zeros();
        for (p, r) in point.iter_mut().zip(&rows[b as usize]) {
            *p ^= r;
        }
        index &= !(0x8000_0000 >> b);
    }
    let seed = seed.wrapping_mul(0x9c8f2d3b);
    let mut out = [0.0f32; BLOCK_DIMS];
    for (i, (o, p)) in out.iter_mut().zip(&point).enumerate() {
        // (`set_scramble`'s key of the lane's set and dimension.)
        let set = 1 + 2 * k + (i / 4) as u32;
        let scramble = hash(seed ^ set ^ LANE_SALT[i]);
        *o = u32_to_f32_norm(reverse_bits(owen_scramble_rev(*p, scramble)));
    }
    out
}

/// `u32::reverse_bits` by shifts and masks (as `sobol_burley`'s `Int4::reverse_bits`), which
/// the render loop's copies run 8 or 16 wide: the instruction x86 lacks would leave a scalar
/// loop.
#[inline(always)]
fn reverse_bits(mut n: u32) -> u32 {
    n = ((n >> 1) & 0x5555_5555) | ((n & 0x5555_5555) << 1);
    n = ((n >> 2) & 0x3333_3333) | ((n & 0x3333_3333) << 2);
    n = ((n >> 4) & 0x0f0f_0f0f) | ((n & 0x0f0f_0f0f) << 4);
    n = ((n >> 8) & 0x00ff_00ff) | ((n & 0x00ff_00ff) << 8);
    n.rotate_left(16)
}

/// `sobol_burley::sample_4d`'s salts of a set's four dimensions.
const SET_SALT: [u32; 4] = [0x912f69ba, 0x174f18ab, 0x691e72ca, 0xb40cc1b8];

/// [`SET_SALT`] for each dimension of a block (a table: indexed `i % 4`, the loop over a
/// block's dimensions does not run 8 wide).
const LANE_SALT: [u32; BLOCK_DIMS] = {
    let mut salt = [0u32; BLOCK_DIMS];
    let mut i = 0;
    while i < BLOCK_DIMS {
        salt[i] = SET_SALT[i % 4];
        i += 1;
    }
    salt
};

/// The Owen scrambles of the four dimensions of set `set` under `seed` (of
/// `sobol_burley::sample_4d`, verbatim).
#[inline(always)]
fn set_scramble(seed: u32, set: u32) -> sobol_burley::parts::Int4 {
    use sobol_burley::parts::{hash_int4, Int4};
    let seed: Int4 = [seed.wrapping_mul(0x9c8f2d3b); 4].into();
    let set: Int4 = [set; 4].into();
    hash_int4(seed ^ set ^ SET_SALT.into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_are_uniform_and_pixel_dependent() {
        // Mean of a 1D projection over 1024 samples is close to 1/2, and two pixels differ.
        let mut sum = 0.0f64;
        let mut differ = 0;
        for i in 0..1024 {
            let mut a = PixelSampler::new(7, i, 3);
            let mut b = PixelSampler::new(8, i, 3);
            a.start_bounce(40); // past 256 dimensions: the wrap path
            b.start_bounce(40);
            let x = a.next_1d();
            assert!((0.0..1.0).contains(&x));
            sum += x as f64;
            if x != b.next_1d() {
                differ += 1;
            }
        }
        assert!((sum / 1024.0 - 0.5).abs() < 0.02, "mean {}", sum / 1024.0);
        assert!(differ > 1000);
        // Same inputs, same numbers.
        let mut a = PixelSampler::new(5, 9, 1);
        let mut b = PixelSampler::new(5, 9, 1);
        assert_eq!(a.next_2d(), b.next_2d());
    }

    #[test]
    fn every_kind_is_found_by_its_name_and_listed() {
        for kind in SamplerKind::ALL {
            assert_eq!(SamplerKind::from_name(kind.name()), Some(kind));
            assert!(SamplerKind::allowed_names().contains(&format!("\"{}\"", kind.name())));
        }
        assert_eq!(SamplerKind::from_name("halton"), None);
        assert_eq!(SamplerKind::from_name("Sobol"), None);
    }

    #[test]
    fn camera_lanes_equal_one_sample_at_a_time() {
        // Every lane's numbers and stream, then the stream's next numbers, as one sample's
        // `with_kind` and `next_1d`; also where the lanes run past `MAX_SPP` (clamped).
        for (pixel, first, seed) in [(0u64, 0u32, 0u64), (777, 96, 5), (1 << 40, MAX_SPP - 20, 9)] {
            let (samplers, numbers) = PixelSampler::sobol_camera_lanes(pixel, first, seed);
            for (k, lane) in samplers.iter().enumerate() {
                let mut one =
                    PixelSampler::with_kind(SamplerKind::Sobol, pixel, first + k as u32, seed);
                assert_eq!(numbers.len(), CAMERA_DIMS as usize);
                for (d, dim) in numbers.iter().enumerate() {
                    let u = one.next_1d();
                    assert_eq!(u.to_bits(), dim[k].to_bits(), "lane {k} dim {d}");
                }
                let (mut a, mut b) = (one, lane.clone());
                for depth in [0, 3] {
                    a.start_bounce(depth);
                    b.start_bounce(depth);
                    for _ in 0..BOUNCE_DIMS {
                        assert_eq!(a.next_1d().to_bits(), b.next_1d().to_bits());
                    }
                }
                assert_eq!(a.next_1d_hashed().to_bits(), b.next_1d_hashed().to_bits());
            }
        }
    }

    #[test]
    fn cached_4d_sets_equal_single_dimensions() {
        // The 4-dimension cache returns exactly `sobol_burley::sample` of each dimension, in any
        // access order (seeks back and forth), also past the wrap at NUM_DIMENSIONS.
        let n = sobol_burley::NUM_DIMENSIONS;
        for i in [0u32, 1, 17, 1000] {
            let mut s = PixelSampler::new(123, i, 9);
            let seed = s.seed;
            // (Across bounces' blocks and out of the last one: bounce 0's holds dimensions
            // 4-11, bounce 30's ends at 251, set 63 is single.)
            for &d in &[
                0u32, 1, 2, 3, 4, 9, 5, 6, 2, 11, 12, 36, 251, 252, 255, 256, 257, 300, 4, 1000,
            ] {
                s.dimension = d;
                let got = s.next_1d();
                let seed_d = if d < n {
                    seed
                } else {
                    splitmix64(seed as u64 ^ ((d / n) as u64) << 32) as u32
                };
                assert_eq!(
                    got,
                    sobol_burley::sample(i, d % n, seed_d),
                    "sample {i} dim {d}"
                );
            }
        }
    }

    #[test]
    fn blocks_equal_their_sets() {
        // Each bounce's block holds its two sets' numbers (`sobol_burley::sample_4d`'s
        // operations, as `sobol_set`), bit for bit, for indices with few and many bits set and
        // several seeds.
        for (i, seed) in [(0u32, 0u32), (1, 7), (MAX_SPP - 1, 3), (12345, 0xdead_beef)] {
            let index = shuffle_rev_index(i, seed);
            for k in 0..BLOCKS {
                let block = sobol_block(index, k, seed);
                for (h, set) in [1 + 2 * k, 2 + 2 * k].into_iter().enumerate() {
                    let values = sobol_set(index, set, seed);
                    assert_eq!(values, sobol_burley::sample_4d(i, set, seed));
                    for (j, u) in values.iter().enumerate() {
                        let v = block[4 * h + j];
                        assert_eq!(u.to_bits(), v.to_bits(), "sample {i}, set {set}, dim {j}");
                    }
                }
            }
        }
        for n in [0u32, 1, 0x8000_0000, 0x1234_5678, 0xdead_beef, u32::MAX] {
            assert_eq!(reverse_bits(n), n.reverse_bits());
        }
    }

    #[test]
    fn bounce_numbers_equal_one_at_a_time() {
        // Both kinds, in and past the blocks, with the cache holding another block, the same
        // block or a single set, and the stream left where the single draws leave it.
        for kind in [SamplerKind::Sobol, SamplerKind::Independent] {
            for (pixel, sample) in [(0u64, 0u32), (17, 5), (40_000, MAX_SPP - 1)] {
                let mut a = PixelSampler::with_kind(kind, pixel, sample, 9);
                let mut b = a.clone();
                for depth in [0, 1, 1, 5, BLOCKS - 1, BLOCKS, BLOCKS + 4, 2] {
                    let lanes = a.bounce_numbers(depth);
                    b.seek(depth, 1);
                    for (j, u) in lanes.iter().enumerate() {
                        assert_eq!(u.to_bits(), b.next_1d().to_bits(), "{kind:?} {depth} {j}");
                    }
                    assert_eq!(a.next_1d().to_bits(), b.next_1d().to_bits());
                    // (Leaves a single set or another block in the cache.)
                    a.seek(depth + 3, 2);
                    b.seek(depth + 3, 2);
                    assert_eq!(a.next_1d().to_bits(), b.next_1d().to_bits());
                }
            }
        }
    }

    /// Counts of `(x, y)` pairs in a 16 x 16 grid, drawn by `pair(pixel, sample)` over 256
    /// pixels and 64 samples each, against the uniform expectation.
    fn chi2_pairs(mut pair: impl FnMut(u64, u32) -> (f32, f32)) -> f64 {
        const G: usize = 16;
        let mut counts = vec![0u64; G * G];
        let mut n = 0u64;
        for pixel in 0..256u64 {
            for sample in 0..64u32 {
                let (x, y) = pair(pixel, sample);
                assert!((0.0..1.0).contains(&x) && (0.0..1.0).contains(&y));
                counts[(y * G as f32) as usize * G + (x * G as f32) as usize] += 1;
                n += 1;
            }
        }
        let expected = vec![n as f64 / (G * G) as f64; G * G];
        crate::testing::chi2_discrete(&counts, &expected).p_value
    }

    #[test]
    fn both_kinds_give_uniform_pairs_chi2() {
        // Pairs within a bounce, across bounces and past the 256-dimension wrap: uniform in the
        // unit square for both kinds (Sobol sets are more even than chance, which only raises
        // the p-value). For the independent kind also two consecutive samples of a pixel (Sobol
        // points 2i and 2i + 1 are stratified against each other by design).
        for kind in [SamplerKind::Sobol, SamplerKind::Independent] {
            for (da, db) in [(5u32, 6u32), (4, 12), (7, 300), (290, 291)] {
                let p = chi2_pairs(|pixel, sample| {
                    let mut s = PixelSampler::with_kind(kind, pixel, sample, 11);
                    s.dimension = da;
                    let x = s.next_1d();
                    s.dimension = db;
                    (x, s.next_1d())
                });
                assert!(p > 1e-3, "{kind:?} dims ({da}, {db}): p = {p:.2e}");
            }
            if kind == SamplerKind::Sobol {
                continue;
            }
            let p = chi2_pairs(|pixel, sample| {
                let mut a = PixelSampler::with_kind(kind, pixel, 2 * sample, 3);
                let mut b = PixelSampler::with_kind(kind, pixel, 2 * sample + 1, 3);
                a.start_bounce(1);
                b.start_bounce(1);
                (a.next_1d(), b.next_1d())
            });
            assert!(p > 1e-3, "{kind:?} consecutive samples: p = {p:.2e}");
        }
        // The test can fail: a stream that repeats its first number is caught.
        let p = chi2_pairs(|pixel, sample| {
            let mut s = PixelSampler::with_kind(SamplerKind::Independent, pixel, sample, 11);
            let x = s.next_1d();
            (x, x)
        });
        assert!(p < 1e-6, "a degenerate pair passed: p = {p:.2e}");
    }

    #[test]
    fn independent_numbers_depend_only_on_pixel_sample_and_dimension() {
        // Seeking back returns the same number; another pixel, sample, seed or dimension a
        // different one.
        let draw = |pixel, sample, seed, d| {
            let mut s = PixelSampler::with_kind(SamplerKind::Independent, pixel, sample, seed);
            s.dimension = d;
            s.next_1d()
        };
        let mut s = PixelSampler::with_kind(SamplerKind::Independent, 9, 4, 2);
        s.seek(3, 5);
        let x = s.next_1d();
        s.seek(0, 0);
        s.next_2d();
        s.seek(3, 5);
        assert_eq!(s.next_1d(), x);
        let d = CAMERA_DIMS + 3 * BOUNCE_DIMS + 5;
        assert_eq!(draw(9, 4, 2, d), x);
        for other in [
            draw(10, 4, 2, d),
            draw(9, 5, 2, d),
            draw(9, 4, 3, d),
            draw(9, 4, 2, d + 1),
        ] {
            assert_ne!(other, x);
        }
        // And it is not the Sobol stream.
        let mut sobol = PixelSampler::new(9, 4, 2);
        sobol.seek(3, 5);
        assert_ne!(sobol.next_1d(), x);
    }
}
