//! The memory a job needs, estimated from its parameters before anything is allocated, and
//! refused with the figure when it exceeds what the machine has available (`MemAvailable`) or
//! what `--max-memory` allows. The per-unit costs are peak resident sizes measured with
//! `/usr/bin/time -f %M` at two sizes (the difference over the difference in size):
//!
//! * `render`: 24 bytes a pixel (the film, the tiles' results and the EXR and PNG encoders);
//!   `--res 1024x1024` peaks at 31 MB, `2048x2048` at 106 MB.
//! * `precompute`: 80 bytes per `M^2` (the histograms, the four `M x M` arrays and their copies
//!   in the `.npz` writer), whatever the thread count; `--m 1024` peaks at 89 MB.
//! * `layers`: `14 + K` bytes a texel (one layer's coverage and mip chain, the combined image,
//!   the encoded PNGs held until all are written), 6 more with `--stages`; `--res 4096`, 8
//!   layers, peaks at 395 MB.

use anyhow::bail;

/// What every job needs beside its arrays (the binary, the thread pool, the scene): 32 MiB.
pub const BASE_BYTES: u64 = 32 << 20;

/// Available memory from /proc/meminfo (Linux), if readable.
fn mem_available() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = s.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// `--max-memory`: bytes, or a number with `K`, `M`, `G` or `T` (powers of 1024).
pub fn parse_size(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (digits, unit) = match t.char_indices().find(|(_, c)| c.is_ascii_alphabetic()) {
        Some((i, _)) => (&t[..i], &t[i..]),
        None => (t, ""),
    };
    let scale: u64 = match unit.to_ascii_uppercase().trim_end_matches(['B', 'I']) {
        "" => 1,
        "K" => 1 << 10,
        "M" => 1 << 20,
        "G" => 1 << 30,
        "T" => 1 << 40,
        _ => {
            return Err(format!(
                "`{s}`: expected bytes or a number with K, M, G or T"
            ))
        }
    };
    let n: f64 = digits
        .trim()
        .parse()
        .map_err(|_| format!("`{s}`: expected bytes or a number with K, M, G or T"))?;
    if !(n.is_finite() && n > 0.0 && n * scale as f64 <= u64::MAX as f64) {
        return Err(format!("`{s}`: must be a positive size"));
    }
    Ok((n * scale as f64) as u64)
}

fn gib(bytes: u64) -> f64 {
    bytes as f64 / (1u64 << 30) as f64
}

/// Refuses a job whose estimate `need` (bytes, [`BASE_BYTES`] added here) exceeds
/// `--max-memory` or the memory available; `what` names the flag and value that set the size.
pub fn check(what: &str, need: u64, max_memory: Option<u64>) -> anyhow::Result<()> {
    let need = need.saturating_add(BASE_BYTES);
    if let Some(limit) = max_memory {
        if need > limit {
            bail!(
                "{what}: the job would need about {:.2} GiB of memory, over --max-memory ({:.2} GiB)",
                gib(need),
                gib(limit)
            );
        }
    }
    if let Some(avail) = mem_available() {
        if need > avail {
            bail!(
                "{what}: the job would need about {:.2} GiB of memory, {:.2} GiB is available",
                gib(need),
                gib(avail)
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_estimates_refuse() {
        assert_eq!(parse_size("4096"), Ok(4096));
        assert_eq!(parse_size("2K"), Ok(2048));
        assert_eq!(parse_size("1.5G"), Ok(3 << 29));
        assert_eq!(parse_size("8GiB"), Ok(8 << 30));
        assert!(parse_size("-1G").is_err() && parse_size("3X").is_err() && parse_size("").is_err());
        assert!(check("--res 8x8", 1000, Some(1 << 30)).is_ok());
        let e = check("--res 9999x9999", 24 * 9999 * 9999, Some(1 << 30)).unwrap_err();
        assert!(
            e.to_string().contains("--res 9999x9999") && e.to_string().contains("2.27 GiB"),
            "{e}"
        );
    }
}
