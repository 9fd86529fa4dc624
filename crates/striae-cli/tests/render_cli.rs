//! `striae render` flags: bad values are usage errors that name the flag, and nothing is written.
//! `--threads` means the same in every subcommand: 1 to 4096, all cores when left out.

use std::path::Path;
use std::process::Command;

/// Run `striae ARGS -o OUT`: whether it succeeded, and its standard error.
fn striae(args: &[&str], out: &Path) -> (bool, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_striae"))
        .args(args)
        .arg("-o")
        .arg(out)
        .output()
        .unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn bad_render_flags_name_the_flag_and_write_nothing() {
    let dir = std::env::temp_dir().join(format!("striae-render-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("out");
    for (flag, value) in [
        ("--spp", "0"),
        ("--spp", "70000"),
        ("--threads", "0"),
        ("--res", "0x5"),
        ("--sampler", "halton"),
        ("--exposure", "NaN"),
        ("--spp", "-1"),
        ("--seed", "-1"),
        ("--threads", "-2"),
        ("--res", "100000x100000"),
        ("--exposure", "1e30"),
    ] {
        let (ok, err) = striae(&["render", flag, value, "-q"], &out);
        assert!(!ok, "{flag} {value} should fail");
        assert!(
            err.contains(flag) && err.contains(value),
            "{flag} {value}: {err}"
        );
        assert!(
            !out.with_extension("exr").exists() && !out.with_extension("png").exists(),
            "{flag} {value} wrote an image"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn thread_counts_out_of_range_are_refused_by_every_subcommand() {
    let dir = std::env::temp_dir().join(format!("striae-threads-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("out");
    // (A million threads took minutes to start before they were refused.)
    for (command, n) in [
        ("render", "0"),
        ("figures", "0"),
        ("precompute", "0"),
        ("render", "1000000"),
        ("figures", "4097"),
        ("precompute", "1000000"),
    ] {
        let (ok, err) = striae(&[command, "--threads", n], &out);
        assert!(!ok, "{command} --threads {n} should fail");
        assert!(
            err.contains("--threads") && err.contains(n) && err.contains("1 to 4096"),
            "{command}: {err}"
        );
        assert!(
            std::fs::read_dir(&dir).unwrap().next().is_none(),
            "{command} wrote"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn striae_simd_caps_the_render_loop_and_a_bad_value_is_named() {
    const SCENE: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../striae/scenes/glass-teapot.toml"
    );
    let dir = std::env::temp_dir().join(format!("striae-simd-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("out");
    let run = |value: &str| {
        let o = Command::new(env!("CARGO_BIN_EXE_striae"))
            .args(["render", SCENE, "--res", "16x12"])
            .args(["--spp", "1", "-q", "-o"])
            .arg(&out)
            .env("STRIAE_SIMD", value)
            .env_remove("STRIAE_PORTABLE")
            .output()
            .unwrap();
        (
            o.status.success(),
            String::from_utf8_lossy(&o.stderr).into_owned(),
        )
    };
    let (ok, err) = run("avx3");
    assert!(
        !ok && err.contains("STRIAE_SIMD") && err.contains("avx3"),
        "{err}"
    );
    assert!(
        !out.with_extension("exr").exists(),
        "a bad STRIAE_SIMD wrote an image"
    );
    let (ok, err) = run("portable");
    assert!(ok && err.contains("portable render loop"), "{err}");
    // `striae figures` renders too, and refuses the bad value before writing anything.
    let figs = dir.join("figs");
    let o = Command::new(env!("CARGO_BIN_EXE_striae"))
        .args(["figures", "-o"])
        .arg(&figs)
        .env("STRIAE_SIMD", "avx3")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("STRIAE_SIMD") && err.contains("avx3"),
        "{err}"
    );
    assert!(!figs.exists(), "a bad STRIAE_SIMD wrote figures");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn outputs_that_would_be_wrong_or_would_replace_what_is_not_a_file_are_refused() {
    let dir = std::env::temp_dir().join(format!("striae-outputs-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // A `.jpg` name would get PNG bytes.
    let (ok, err) = striae(
        &["render", "--spp", "1", "--res", "8x6", "-q"],
        &dir.join("a.jpg"),
    );
    assert!(!ok && err.contains("not .jpg"), "{err}");
    // A folder that does not exist is named before anything is rendered.
    let (ok, err) = striae(
        &["render", "--spp", "1", "--res", "8x6", "-q"],
        &dir.join("missing/a.exr"),
    );
    assert!(!ok && err.contains("missing does not exist"), "{err}");
    assert_eq!(
        std::fs::read_dir(&dir).unwrap().count(),
        0,
        "something written"
    );
    // A FIFO (or a device) at the output's name is not replaced by the rename.
    let fifo = dir.join("t.npz");
    if std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success())
    {
        let (ok, err) = striae(&["precompute", "--m", "4", "--n", "20", "--nr", "2"], &fifo);
        assert!(!ok && err.contains("not a regular file"), "{err}");
        use std::os::unix::fs::FileTypeExt;
        assert!(std::fs::symlink_metadata(&fifo)
            .unwrap()
            .file_type()
            .is_fifo());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A glass sphere under a constant sky, 37 x 21 pixels (6 tiles) at `spp`, as `dir/s.toml`.
fn glass_sphere(dir: &Path, spp: u32) -> std::path::PathBuf {
    let scene = dir.join("s.toml");
    let text = format!(
        "[render]\nwidth = 37\nheight = 21\nspp = {spp}\n[camera]\nposition = [0, 1, 4]\n\
         look_at = [0, 0.5, 0]\nfov = 40\n[materials.glass]\ntype = \"dielectric\"\n[[shapes]]\n\
         type = \"sphere\"\nmaterial = \"glass\"\ncenter = [0, 0.6, 0]\nradius = 0.6\n\
         [environment]\ntype = \"constant\"\nradiance = [0.8, 0.9, 1.0]\n"
    );
    std::fs::write(&scene, text).unwrap();
    scene
}

/// `--lanes` and `--lanes=true` (the lane loop), `--lanes=false` and no flag (the one-path
/// loop) write the same image byte for byte; `--lanes` before the scene leaves it the scene.
#[test]
fn either_render_loop_writes_the_same_image() {
    let dir = std::env::temp_dir().join(format!("striae-lanes-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = glass_sphere(&dir, 5);
    let scene = scene.to_str().unwrap();
    let mut images = Vec::new();
    for (i, args) in [
        ["--lanes", scene],
        [scene, "--lanes=false"],
        [scene, "--lanes=true"],
        [scene, "--spp=5"],
    ]
    .into_iter()
    .enumerate()
    {
        let out = dir.join(format!("l{i}"));
        let (ok, err) = striae(&[&["render", "-q"][..], &args].concat(), &out);
        assert!(ok, "{args:?}: {err}");
        images.push(std::fs::read(out.with_extension("exr")).unwrap());
    }
    assert!(images.iter().all(|x| *x == images[0]));
    let out = dir.join("bad");
    let (ok, err) = striae(&["render", scene, "--lanes=maybe", "-q"], &out);
    assert!(
        !ok && err.contains("--lanes") && err.contains("maybe"),
        "{err}"
    );
    assert!(!out.with_extension("exr").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `striae render --tile I/N` for I in 0..3 and `striae merge` give the EXR of the whole
/// render byte for byte (37 x 21 pixels: 6 tiles, 3 parts of 2); an index out of range, and a
/// missing or foreign part, are errors that say so.
#[test]
fn tiles_merge_to_the_whole_render_and_bad_parts_are_refused() {
    let dir = std::env::temp_dir().join(format!("striae-tiles-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = glass_sphere(&dir, 2);
    let s = scene.to_str().unwrap();
    let (ok, err) = striae(&["render", s, "-q"], &dir.join("whole"));
    assert!(ok, "{err}");
    let part = |i: u32| dir.join(format!("p{i}.part"));
    for i in 0..3 {
        let (ok, err) = striae(&["render", s, "-q", "--tile", &format!("{i}/3")], &part(i));
        assert!(ok, "{err}");
    }
    let p: Vec<String> = (0..3).map(|i| part(i).display().to_string()).collect();
    let (ok, err) = striae(&["merge", &p[2], &p[0], &p[1]], &dir.join("merged"));
    assert!(ok, "{err}");
    let read = |name: &str| std::fs::read(dir.join(name)).unwrap();
    assert!(
        read("merged.exr") == read("whole.exr"),
        "merged EXR differs"
    );
    assert!(
        read("merged.png") == read("whole.png"),
        "merged PNG differs"
    );

    let (ok, err) = striae(&["merge", &p[0], &p[1]], &dir.join("bad"));
    assert!(!ok && err.contains("parts missing: [2]"), "{err}");
    let (ok, err) = striae(
        &["render", s, "-q", "--seed", "2", "--tile", "2/3"],
        &part(2),
    );
    assert!(ok, "{err}");
    let (ok, err) = striae(&["merge", &p[0], &p[1], &p[2]], &dir.join("bad"));
    assert!(!ok && err.contains("different renders: seed"), "{err}");
    let (ok, err) = striae(&["render", s, "-q", "--tile", "3/3"], &part(3));
    assert!(
        !ok && err.contains("--tile") && err.contains("0..N"),
        "{err}"
    );
    let (ok, err) = striae(&["render", s, "-q", "--tile", "0/7"], &part(3));
    assert!(!ok && err.contains("only 6 tiles"), "{err}");
    assert!(!dir.join("bad.exr").exists() && !part(3).exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `striae render --samples A..B` (alone and with `--tile`) and `striae merge`: the merged
/// pixels are the whole render's within `f32` rounding (a dielectric scene: no scratch
/// footprints); bad ranges name `--samples`, overlaps and gaps name the files and samples.
#[test]
fn sample_ranges_merge_and_bad_ranges_are_refused() {
    let dir = std::env::temp_dir().join(format!("striae-samples-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = glass_sphere(&dir, 5);
    let s = scene.to_str().unwrap();
    let path = |name: &str| dir.join(name).display().to_string();
    let render = |extra: &[&str], name: &str| {
        let (ok, err) = striae(&[&["render", s, "-q"], extra].concat(), &dir.join(name));
        assert!(ok, "{err}");
    };
    render(&["--tile", "0/1"], "whole.part");
    render(&["--samples", "0..2"], "a.part");
    render(&["--samples", "2..5"], "b.part");
    render(&["--tile", "0/2", "--samples", "0..4"], "t0a.part");
    render(&["--tile", "0/2", "--samples", "4..5"], "t0b.part");
    render(&["--tile", "1/2"], "t1.part");
    let read = |name: &str| {
        (
            dir.join(name),
            striae::render::parts::Part::read(&dir.join(name)).unwrap(),
        )
    };
    let (whole, _) = striae::render::parts::merge(&[read("whole.part")]).unwrap();
    for set in [
        vec!["b.part", "a.part"],
        vec!["t0b.part", "t1.part", "t0a.part"],
    ] {
        let parts: Vec<_> = set.iter().map(|n| read(n)).collect();
        let (merged, _) = striae::render::parts::merge(&parts).unwrap();
        for (p, q) in merged.pixels.iter().zip(&whole.pixels) {
            assert!(
                (*p - *q).abs().max_element() <= 1e-5 * q.max_element(),
                "{set:?}: {p} {q}"
            );
        }
        let files: Vec<String> = set.iter().map(|n| path(n)).collect();
        let files: Vec<&str> = files.iter().map(String::as_str).collect();
        let (ok, err) = striae(&[&["merge"], &files[..]].concat(), &dir.join("merged"));
        assert!(ok && dir.join("merged.exr").exists(), "{err}");
    }

    let (ok, err) = striae(&["merge", &path("a.part")], &dir.join("bad"));
    assert!(
        !ok && err.contains("no part file holds samples 2..5") && err.contains("a.part (0..2)"),
        "{err}"
    );
    render(&["--samples", "1..3"], "c.part");
    let (ok, err) = striae(
        &["merge", &path("a.part"), &path("c.part"), &path("b.part")],
        &dir.join("bad"),
    );
    assert!(
        !ok && err.contains("c.part (samples 1..3) overlap"),
        "{err}"
    );
    for bad in ["3..2", "2..2", "0..6", "1-2", "x"] {
        let (ok, err) = striae(
            &["render", s, "-q", "--samples", bad],
            &dir.join("bad.part"),
        );
        assert!(!ok && err.contains("--samples"), "{bad}: {err}");
    }
    assert!(!dir.join("bad.exr").exists() && !dir.join("bad.part").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// Jobs larger than memory allows are refused up front with the estimate and the flag that set
/// the size, before anything is allocated or written.
#[test]
fn jobs_over_the_memory_limit_are_refused_with_the_estimate() {
    let dir = std::env::temp_dir().join(format!("striae-memory-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("out");
    for (args, expect) in [
        (&["layers", "--res", "16384"][..], "--res 16384"),
        (&["precompute", "--m", "8192"][..], "--m 8192"),
        (
            &["render", "--res", "8192x8192", "-q"][..],
            "--res 8192x8192",
        ),
    ] {
        let mut all = args.to_vec();
        all.extend(["--max-memory", "1G"]);
        let start = std::time::Instant::now();
        let (ok, err) = striae(&all, &out);
        assert!(
            !ok && err.contains(expect) && err.contains("GiB"),
            "{args:?}: {err}"
        );
        assert!(
            start.elapsed().as_secs_f64() < 30.0,
            "{args:?} ran before refusing"
        );
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            0,
            "{args:?} wrote"
        );
    }
    // A command's output never replaces its own input.
    let profile = dir.join("p.txt");
    std::fs::write(&profile, "-1 0\n0 -0.5\n1 0\n").unwrap();
    let spec = format!("file:{}", profile.display());
    let (ok, err) = striae(&["precompute", "--profile", &spec, "--m", "4"], &profile);
    assert!(!ok && err.contains("would overwrite"), "{err}");
    assert_eq!(
        std::fs::read_to_string(&profile).unwrap(),
        "-1 0\n0 -0.5\n1 0\n"
    );
    std::fs::remove_file(&profile).unwrap();
    let (ok, err) = striae(&["layers", "--res", "64", "--max-memory", "3X"], &out);
    assert!(!ok && err.contains("--max-memory"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Finite inputs whose light overflows 32-bit floats are an error, not an image of `inf`.
#[test]
fn radiance_that_overflows_is_an_error() {
    let dir = std::env::temp_dir().join(format!("striae-overflow-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("hot.toml");
    std::fs::write(
        &scene,
        "[render]\nwidth = 8\nheight = 6\nspp = 16\n[camera]\nposition = [0, 1, 3]\n\
         look_at = [0, 0, 0]\nfov = 40\n[materials.white]\ntype = \"diffuse\"\nreflectance = 1.0\n\
         [[shapes]]\ntype = \"rectangle\"\nmaterial = \"white\"\n\
         transform = { rotate = { axis = [1, 0, 0], angle = -90 } }\n\
         [[lights]]\ntype = \"sun\"\ndirection = [0, 1, 0]\nirradiance = 3e38\n",
    )
    .unwrap();
    let out = dir.join("hot");
    let (ok, err) = striae(&["render", scene.to_str().unwrap(), "-q"], &out);
    assert!(!ok && err.contains("overflowed"), "{err}");
    assert!(!out.with_extension("exr").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `precompute --walls dielectric` takes the table's sizes from `--incident`, `--exit-bins`
/// and `--wall-paths`; the flags are refused for other walls and out of range, naming them.
#[test]
fn dielectric_wall_table_sizes_come_from_their_flags() {
    let dir = std::env::temp_dir().join(format!("striae-walls-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("w.npz");
    let sizes = [
        "--incident",
        "2x3",
        "--exit-bins",
        "6",
        "--wall-paths",
        "50",
    ];
    let mut args = vec!["precompute", "--walls", "dielectric"];
    args.extend(sizes);
    let (ok, err) = striae(&args, &out);
    assert!(ok, "{err}");
    let t = striae::precompute::wall_table::WallTable::load(&out)
        .unwrap()
        .unwrap();
    assert_eq!((t.theta_i.len(), t.phi_i.len()), (2, 3));
    assert_eq!((t.params.bins, t.params.paths), (6, 50));
    std::fs::remove_file(&out).unwrap();
    for (args, flag) in [
        (&["precompute", "--exit-bins", "6"][..], "--exit-bins"),
        (
            &["precompute", "--walls", "dielectric", "--incident", "0x4"][..],
            "--incident",
        ),
        (
            &["precompute", "--walls", "dielectric", "--incident", "4by4"][..],
            "--incident",
        ),
        (
            &["precompute", "--walls", "dielectric", "--wall-paths", "0"][..],
            "--wall-paths",
        ),
    ] {
        let (ok, err) = striae(args, &out);
        assert!(!ok && err.contains(flag), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A wall table refuses the 2D table's options it would ignore, naming the option; one of
/// more than 10^11 paths (hours to days) or over the memory limit is refused before it starts,
/// naming the flags that size it; a 2D table refuses `--check`, which only wall tables read.
#[test]
fn wall_tables_refuse_what_they_would_ignore_or_could_not_finish() {
    let dir = std::env::temp_dir().join(format!("striae-walls-ignored-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("w.npz");
    let small = [
        "--incident",
        "2x2",
        "--exit-bins",
        "4",
        "--wall-paths",
        "10",
    ];
    let dielectric = ["precompute", "--walls", "dielectric"];
    let specular = ["precompute", "--walls", "specular", "--roughness", "0.3"];
    let wall = |walls: &[&'static str]| -> Vec<&'static str> {
        walls.iter().chain(&small).copied().collect()
    };
    for (base, extra, flag) in [
        (
            wall(&dielectric),
            &["--groove-slices", "4"][..],
            "--groove-slices",
        ),
        (
            wall(&dielectric),
            &["--estimator", "kernel"],
            "--estimator kernel",
        ),
        (
            wall(&dielectric),
            &["--fresnel-law", "none"],
            "--fresnel-law",
        ),
        (wall(&dielectric), &["--fresnel", "walls"], "--fresnel"),
        (wall(&dielectric), &["--m", "64"], "--m"),
        (wall(&dielectric), &["--nr", "4"], "--nr"),
        (
            wall(&specular),
            &["--groove-slices", "2"],
            "--groove-slices",
        ),
        (wall(&specular), &["--max-bounces", "8"], "--max-bounces"),
        (vec!["precompute", "--m", "4"], &["--check", "3"], "--check"),
    ] {
        let args = [&base[..], extra].concat();
        let (ok, err) = striae(&args, &out);
        let named = err.contains(&format!("{flag}:")) || err.contains(&format!("{flag} applies"));
        assert!(!ok && named, "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote");
    }
    // Rough specular walls read `--fresnel-law`.
    let args: Vec<&str> = specular
        .iter()
        .chain(&small)
        .chain(&["--fresnel-law", "none"])
        .copied()
        .collect();
    let (ok, err) = striae(&args, &out);
    assert!(ok, "{err}");
    std::fs::remove_file(&out).unwrap();
    for (args, expect) in [
        (
            &["--incident", "256x256", "--wall-paths", "16777216"][..],
            &["--wall-paths 16777216", "--incident 256x256"][..],
        ),
        (
            &[
                "--incident",
                "16x16",
                "--exit-bins",
                "256",
                "--roughness",
                "0.3",
                "--wall-paths",
                "10",
            ],
            &["--exit-bins 256", "GiB"],
        ),
    ] {
        let args: Vec<&str> = dielectric
            .iter()
            .chain(args)
            .chain(&["--max-memory", "1G"])
            .copied()
            .collect();
        let start = std::time::Instant::now();
        let (ok, err) = striae(&args, &out);
        assert!(
            !ok && expect.iter().all(|e| err.contains(e)),
            "{args:?}: {err}"
        );
        assert!(start.elapsed().as_secs_f64() < 30.0, "{args:?} ran");
        assert!(!out.exists(), "{args:?} wrote");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `gonio`, `fidelity`, `plot` and `layers` check every flag and output before anything is
/// computed or written: a plot name of another format, a folder that does not exist, a
/// `fidelity --plot` case or `--plot-models` model the study does not have, `--bins` and
/// `--slice-m` out of range, an absurd `--length` (quoted as written).
#[test]
fn lab_commands_check_flags_and_outputs_before_any_work() {
    let dir = std::env::temp_dir().join(format!("striae-lab-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let empty = |what: &str| {
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().flatten().collect();
        assert!(left.is_empty(), "{what} wrote {left:?}");
    };
    let gonio = ["gonio", "--paths", "2000", "--bins", "8"];
    let missing = dir.join("missing").join("g.png");
    for (plot, out, expect) in [
        ("g.jpg", "g.npz", "not .jpg"),
        (missing.to_str().unwrap(), "g.npz", "does not exist"),
        ("g.png", "missing/g.npz", "does not exist"),
    ] {
        let plot = dir.join(plot).display().to_string();
        let mut args = gonio.to_vec();
        args.extend(["--plot", &plot]);
        let (ok, err) = striae(&args, &dir.join(out));
        assert!(!ok && err.contains(expect), "--plot {plot}: {err}");
        empty(&format!("gonio --plot {plot} -o {out}"));
    }
    let fid = dir.join("fid");
    let small = [
        "fidelity",
        "--profiles",
        "v90=v:angle=90",
        "--theta-i",
        "0",
        "--phi-i",
        "0",
        "--paths",
        "2000",
        "--runs",
        "2",
        "--table",
        "8,200,2",
        "--slices",
        "1",
        "--slice-paths",
        "200",
    ];
    for (extra, expect) in [
        (&["--plot", "v60@0,0"][..], "no profile `v60`"),
        (&["--plot", "v90@45,0"], "theta 45 is not one of --theta-i"),
        (&["--plot", "v90@0,30"], "phi 30 is not one of --phi-i"),
        (
            &["--plot-models", "seed,groove_slices6"],
            "`groove_slices6`",
        ),
        (&["--bins", "0"], "`--bins` = 0"),
        (&["--slice-m", "0"], "slice_m 0"),
    ] {
        let mut args = small.to_vec();
        args.extend(extra);
        let (ok, err) = striae(&args, &fid);
        assert!(!ok && err.contains(expect), "{extra:?}: {err}");
        empty(&format!("fidelity {extra:?}"));
    }
    let table = dir.join("t.npz");
    let (ok, err) = striae(
        &["precompute", "--m", "4", "--n", "20", "--nr", "2"],
        &table,
    );
    assert!(ok, "{err}");
    let (ok, err) = striae(&["plot", table.to_str().unwrap()], &dir.join("lobe.jpg"));
    assert!(!ok && err.contains("not .jpg"), "{err}");
    assert!(!dir.join("lobe.jpg").exists(), "a .jpg plot was written");
    std::fs::remove_file(&table).unwrap();
    let layers = [
        "layers",
        "--width",
        "0.01",
        "--threshold",
        "0.1",
        "--length",
    ];
    let (ok, err) = striae(&[&layers[..], &["1e308"]].concat(), &dir.join("l"));
    assert!(
        !ok && err.contains("`length`") && err.contains("1e308"),
        "{err}"
    );
    empty("layers --length 1e308");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `striae merge` refuses an output that would replace one of its part files, before reading
/// them.
#[test]
fn merge_refuses_to_overwrite_its_parts() {
    let dir = std::env::temp_dir().join(format!("striae-merge-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = glass_sphere(&dir, 1);
    // A part file named like the merge's EXR.
    let part = dir.join("m.exr");
    let (ok, err) = striae(
        &["render", scene.to_str().unwrap(), "-q", "--tile", "0/1"],
        &part,
    );
    assert!(ok, "{err}");
    let before = std::fs::read(&part).unwrap();
    let (ok, err) = striae(&["merge", part.to_str().unwrap()], &dir.join("m"));
    assert!(
        !ok && err.contains("would overwrite the part file"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(&part).unwrap(),
        before,
        "the part was replaced"
    );
    assert!(!dir.join("m.png").exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// A scene whose curves are a bad SVG (not SVG, a path with no stroke, a zero stroke width)
/// fails naming the file and the element, and writes nothing.
#[test]
fn bad_curve_drawings_name_the_file_and_the_element_and_write_nothing() {
    let dir = std::env::temp_dir().join(format!("striae-cli-curves-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let scene = dir.join("s.toml");
    std::fs::write(
        &scene,
        r#"
[render]
width = 8
height = 8
spp = 1
[camera]
position = [0.0, 0.0, 3.0]
look_at = [0.0, 0.0, 0.0]
fov = 40.0
[materials.m]
type = "scratched"
base = "metal"
preset = "gold"
[materials.m.scratches]
m = 16
n = 200
curves = "marks.svg"
[[shapes]]
type = "rectangle"
material = "m"
"#,
    )
    .unwrap();
    let out = dir.join("out");
    for (svg, expect) in [
        ("this is not a drawing", "not a valid SVG"),
        (
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><rect id="fill" width="5" height="5" fill="red"/></svg>"#,
            "id=\"fill\"",
        ),
        (
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><line id="zero" x2="9" y2="9" stroke="black" stroke-width="0"/></svg>"#,
            "id=\"zero\"",
        ),
    ] {
        std::fs::write(dir.join("marks.svg"), svg).unwrap();
        let (ok, err) = striae(&["render", scene.to_str().unwrap()], &out);
        assert!(!ok, "{svg}");
        assert!(
            err.contains("marks.svg") && err.contains("scratches.curves") && err.contains(expect),
            "{err}"
        );
        assert!(!out.with_extension("exr").exists() && !out.with_extension("png").exists());
    }
    std::fs::remove_dir_all(&dir).ok();
}
