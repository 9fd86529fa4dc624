//! Jobs under a limit the machine sets besides `MemAvailable` (here `ulimit -v`, as in a batch
//! job or a container): refused up front with the estimate, the limit that binds and the flag
//! to change; never an abort or a panic, and nothing written.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// About 3.8 GiB of address space, as `ulimit -v 4000000` (KiB).
const LIMIT_KIB: &str = "4000000";

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("striae-resources-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `striae ARGS` in `dir` under `ulimit -v`, its table cache in `dir` too.
fn limited(dir: &Path, args: &[&str]) -> Output {
    Command::new("bash")
        .arg("-c")
        .arg(format!("ulimit -v {LIMIT_KIB}; exec \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_striae"))
        .args(args)
        .current_dir(dir)
        .env("STRIAE_CACHE", dir.join("cache"))
        .output()
        .unwrap()
}

/// The command failed with exit code 1 and a message naming `flag` and `ulimit -v`: not killed
/// by a signal (an abort is 134 from a shell, `None` here), no panic (101).
fn refused(o: &Output, flag: &str) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert_eq!(o.status.code(), Some(1), "{:?}: {err}", o.status);
    assert!(
        !err.contains("panicked") && !err.contains("memory allocation"),
        "{err}"
    );
    assert!(err.contains(flag), "no {flag}: {err}");
    assert!(err.contains("GiB") && binds(&err), "{err}");
    err
}

/// The message names `ulimit -v` as the limit, or, on a machine with less than that free, the
/// tighter limit (`MemAvailable`, a cgroup's).
fn binds(err: &str) -> bool {
    let meminfo = std::fs::read_to_string("/proc/meminfo").unwrap_or_default();
    let available_kib: u64 = meminfo
        .lines()
        .find_map(|l| l.strip_prefix("MemAvailable:"))
        .and_then(|v| v.split_whitespace().next()?.parse().ok())
        .unwrap_or(u64::MAX);
    err.contains("ulimit -v")
        || (available_kib < LIMIT_KIB.parse::<u64>().unwrap()
            && (err.contains("MemAvailable") || err.contains("cgroup")))
}

/// The files in `dir` other than the table cache.
fn written(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n != "cache")
        .collect()
}

#[test]
fn layers_too_large_for_the_address_space_are_refused() {
    let dir = tmp("layers");
    let o = limited(
        &dir,
        &[
            "layers",
            "--setting",
            "1",
            "--layers",
            "1",
            "--res",
            "16384",
            "-o",
            "out",
        ],
    );
    let err = refused(&o, "--res 16384");
    assert!(err.contains("Lower --res or "), "{err}");
    assert!(written(&dir).is_empty(), "{:?}", written(&dir));

    // A small job under the same limit runs.
    let o = limited(
        &dir,
        &[
            "layers",
            "--setting",
            "1",
            "--layers",
            "2",
            "--res",
            "64",
            "-o",
            "out",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join("out/layers.png").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_film_too_large_for_the_address_space_is_refused() {
    const SCENE: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../striae/scenes/glass-teapot.toml"
    );
    let dir = tmp("render");
    let o = limited(
        &dir,
        &["render", SCENE, "--res", "20000x20000", "-q", "-o", "big"],
    );
    let err = refused(&o, "--res 20000x20000");
    assert!(err.contains("Lower --res or "), "{err}");
    assert!(written(&dir).is_empty(), "{:?}", written(&dir));

    // The size set by the scene's keys names them, and --res that replaces them.
    let scene = std::fs::read_to_string(SCENE).unwrap();
    let scene = scene
        .lines()
        .map(|l| match l.split('=').next().map(str::trim) {
            Some("width") | Some("height") => l.split('=').next().unwrap().to_string() + "= 20000",
            _ => l.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(dir.join("big.toml"), scene).unwrap();
    let o = limited(&dir, &["render", "big.toml", "-q", "-o", "big"]);
    let err = refused(&o, "render.width x render.height, 20000x20000");
    assert!(err.contains("Lower --res"), "{err}");
    assert_eq!(written(&dir), ["big.toml"]);

    // A part of the same image is sized by its own pixels: 1/4096 of it fits.
    let o = limited(
        &dir,
        &[
            "render",
            "big.toml",
            "-q",
            "--tile",
            "0/4096",
            "--spp",
            "1",
            "--max-depth",
            "1",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(dir.join("big-0-of-4096.part").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

/// The explicit grooves are estimated before they are carved: the BVH builder would panic in
/// an `unwrap` where an allocation fails.
#[test]
fn explicit_grooves_too_large_for_the_address_space_are_refused() {
    let dir = tmp("explicit");
    std::fs::write(
        dir.join("grooves.toml"),
        "[render]\nwidth = 8\nheight = 8\nspp = 1\n\
         [camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 30\n\
         [materials.plate]\ntype = \"scratched\"\nbase = \"metal\"\npreset = \"gold\"\n\
         [materials.plate.scratches]\nexplicit = true\nsetting = 2\nlayers = 64\nstations = 200\n\
         [[shapes]]\nmaterial = \"plate\"\ntype = \"rectangle\"\n",
    )
    .unwrap();
    let o = limited(&dir, &["render", "grooves.toml", "-q", "-o", "g"]);
    let err = refused(&o, "materials.plate.scratches.explicit");
    assert!(err.contains("explicit grooves"), "{err}");
    assert_eq!(written(&dir), ["grooves.toml"]);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn histograms_tables_and_merges_too_large_are_refused() {
    let dir = tmp("lab");
    // 4096 x 4096 bins: 16 bytes each for every accumulator, up to 5 on each of 4 threads.
    let o = limited(
        &dir,
        &[
            "gonio",
            "--bins",
            "4096",
            "--threads",
            "4",
            "--paths",
            "100000",
            "-o",
            "g.npz",
        ],
    );
    refused(&o, "--bins 4096");
    let o = limited(
        &dir,
        &[
            "fidelity",
            "--bins",
            "4096",
            "--threads",
            "2",
            "--runs",
            "2",
            "-o",
            "study",
        ],
    );
    refused(&o, "--bins 4096");
    let o = limited(&dir, &["precompute", "--m", "8192", "-o", "t.npz"]);
    refused(&o, "--m 8192");
    assert!(written(&dir).is_empty(), "{:?}", written(&dir));

    // A part file of 5 GB (sparse): refused before it is read.
    let part = dir.join("huge.part");
    std::fs::File::create(&part)
        .unwrap()
        .set_len(5 << 30)
        .unwrap();
    let o = limited(&dir, &["merge", "huge.part", "-o", "merged"]);
    refused(&o, "reading the part files");
    assert_eq!(written(&dir), ["huge.part"]);
    let _ = std::fs::remove_dir_all(&dir);
}
