//! The hash functions every random stream of the crate derives from (one home, so two
//! functions never share a name).
//!
//! Both are Steele, Lea and Flood's SplitMix64 (2014): [`mix64`] is its bijective finaliser,
//! [`splitmix64`] one full step of the generator (the golden-ratio increment, then the
//! finaliser). Streams keyed with one must keep it: switching changes every image and table.

/// The SplitMix64 increment, `2^64 / phi` rounded to odd.
pub const GOLDEN: u64 = 0x9E37_79B9_7F4A_7C15;

/// SplitMix64's finaliser: a bijective 64-bit mixer.
#[inline(always)]
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// `x / 2^32` for `x < 2^32`, exactly `x as f64 / 2^32`: the 32 bits set as the high mantissa
/// bits of a number in `[1, 2)`, then 1 taken away (exact). A shift, an or and a subtraction,
/// where AVX2 has no conversion from 64-bit integers, lane-wise or unsigned.
#[inline(always)]
pub fn unit_from_u32(x: u64) -> f64 {
    debug_assert!(x >> 32 == 0);
    f64::from_bits(0x3FF0_0000_0000_0000 | (x << 20)) - 1.0
}

/// The top 24 bits of a hash `h` as a number in `[0, 1)`, exactly representable in `f32`.
#[inline(always)]
pub fn unit_f32(h: u64) -> f32 {
    (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

/// One SplitMix64 step from state `x`: `mix64(x + GOLDEN)`.
#[inline(always)]
pub fn splitmix64(x: u64) -> u64 {
    mix64(x.wrapping_add(GOLDEN))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix64_matches_the_reference_sequence() {
        // The first outputs of the reference generator seeded with 0 (Vigna's splitmix64.c):
        // state advances by GOLDEN, output is the finaliser of the new state.
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
        assert_eq!(splitmix64(GOLDEN), 0x6E78_9E6A_A1B9_65F4);
        assert_eq!(mix64(0), 0);
    }

    #[test]
    fn unit_from_u32_is_the_exact_quotient() {
        let mut x = 0;
        let edges = [
            0,
            1,
            2,
            3,
            (1 << 31) - 1,
            1 << 31,
            (1 << 32) - 2,
            (1 << 32) - 1,
        ];
        let hashed = (0..100_000).map(|_| {
            x = splitmix64(x);
            x >> 32
        });
        for v in edges.into_iter().chain(hashed) {
            let want = v as f64 / 4_294_967_296.0;
            assert_eq!(unit_from_u32(v).to_bits(), want.to_bits(), "{v}");
        }
    }
}
