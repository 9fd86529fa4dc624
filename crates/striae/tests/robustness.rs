//! Bad values never panic: every number of two scene files (`data/every-kind.toml`, with
//! every shape, material, light, transform and input-file kind, and a scratched plate) is
//! replaced in turn by NaN, infinities, zero, -1 and extremes, and every quoted value by an
//! empty, an unknown and a missing-file one; each variant must load and render, or fail with
//! an error naming the file. (A random fuzzer over the shipped scenes found non-finite
//! translations panicking at load; this sweep covers that class systematically.) Tiny images,
//! about a second in all.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use striae::math::Rgb;
use striae::precompute::profile::Profile;
use striae::precompute::table::{ScratchTable, TableParams};
use striae::precompute::trace2d::TraceSettings;
use striae::render::film::Image;
use striae::render::integrator::render;
use striae::render::scene::{Overrides, Scene};

/// Every kind of shape, material, light, transform and input file.
const EVERYTHING: &str = include_str!("data/every-kind.toml");

const SCRATCHED: &str = r#"
[render]
width = 4
height = 3
spp = 2

[camera]
position = [0.3, 1.15, 1.2]
look_at = [0.0, 1.0, 0.0]
fov = 20.0

[materials.glass]
type = "scratched"
base = "glass"
ior = 1.5

[materials.glass.scratches]
table = "t.npz"
length = 0.3
width = 0.001
threshold = 0.1
layers = 3
seed = 1
layer_mix = "sum"

[[shapes]]
type = "box"
material = "glass"
transform = [{ scale = [1.5, 1.0, 0.02] }, { rotate = { axis = [0.0, 1.0, 0.0], angle = 25.0 } }, { translate = [0.0, 1.0, 0.0] }]

[[lights]]
type = "sun"
direction = [-0.2, 0.6, 0.8]
irradiance = 60.0
"#;

const REPLACEMENTS: [&str; 8] = ["nan", "inf", "-inf", "0", "-1", "1e30", "-1e-30", "4e9"];

/// Byte ranges of the numbers in `text` (outside strings and comments).
fn numbers(text: &str) -> Vec<(usize, usize)> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let (mut i, mut in_string) = (0, false);
    while i < b.len() {
        let c = b[i];
        if c == b'"' {
            in_string = !in_string;
        } else if c == b'#' && !in_string {
            // A comment: to the end of its line.
            i += text[i..].find('\n').unwrap_or(text.len() - i);
            continue;
        } else if !in_string
            && (c.is_ascii_digit() || c == b'-')
            && (i == 0 || b" =[,{".contains(&b[i - 1]))
        {
            let start = i;
            while i < b.len() && (b[i].is_ascii_alphanumeric() || b"-+.".contains(&b[i])) {
                i += 1;
            }
            out.push((start, i));
            continue;
        }
        i += 1;
    }
    out
}

/// Byte ranges of the quoted values in `text` (quotes included): the strings after a `=`,
/// outside comment lines.
fn strings(text: &str) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(k) = text[from..].find("= \"") {
        let start = from + k + 2;
        let end = start + 1 + text[start + 1..].find('"').unwrap() + 1;
        let line = text[..start].rfind('\n').map_or(0, |n| n + 1);
        if !text[line..start].trim_start().starts_with('#') {
            out.push((start, end));
        }
        from = end;
    }
    out
}

/// Each span of `text` replaced in turn by each of `replacements`: every variant must load and
/// render, or fail with an error naming the file. Returns how many loaded.
fn sweep(
    name: &str,
    text: &str,
    dir: &Path,
    spans: &[(usize, usize)],
    replacements: &[&str],
) -> usize {
    let file = dir.join(name);
    let mut loaded = 0;
    for &(a, b) in spans {
        for r in replacements {
            let variant = format!("{}{r}{}", &text[..a], &text[b..]);
            let outcome = catch_unwind(AssertUnwindSafe(|| {
                match Scene::parse(&variant, &file, dir, &Overrides::default()) {
                    Ok(scene) => {
                        render(&scene, &|_| {});
                        Ok(())
                    }
                    Err(e) => Err(e.to_string()),
                }
            }));
            let at = format!("{name}: `{}` -> `{r}`", &text[a..b]);
            match outcome {
                Err(_) => panic!("{at}: panicked"),
                Ok(Err(msg)) => assert!(msg.contains(name), "{at}: error without the file: {msg}"),
                Ok(Ok(())) => loaded += 1,
            }
        }
    }
    loaded
}

/// A fresh folder holding the files the two scenes name: a mesh, an environment map, an image
/// texture and a small scratch table.
fn input_files(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("striae-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("tet.obj"), include_str!("data/tet.obj")).unwrap();
    let mut image = Image::new(8, 4);
    for (i, p) in image.pixels.iter_mut().enumerate() {
        *p = Rgb::splat(0.1 + 0.05 * (i % 7) as f32);
    }
    image.write_exr(&dir.join("sky.exr")).unwrap();
    image.write_png(&dir.join("wood.png"), 0.0).unwrap();
    let trace = TraceSettings {
        m: 8,
        n: 40,
        nr: 2,
        ..TraceSettings::default()
    };
    let params = TableParams::new(Profile::parse("v:angle=90").unwrap(), trace);
    ScratchTable::compute(&params, &|_| {})
        .unwrap()
        .save(&dir.join("t.npz"))
        .unwrap();
    dir
}

#[test]
fn every_value_of_a_scene_replaced_by_a_bad_one_loads_or_errors_without_panicking() {
    let dir = input_files("robustness");
    // Both files load as written.
    for (name, text) in [
        ("everything.toml", EVERYTHING),
        ("scratched.toml", SCRATCHED),
    ] {
        Scene::parse(text, &dir.join(name), &dir, &Overrides::default())
            .unwrap_or_else(|e| panic!("{e}"));
    }
    let mut loaded = 0;
    for (name, text) in [
        ("everything.toml", EVERYTHING),
        ("scratched.toml", SCRATCHED),
    ] {
        let spans = numbers(text);
        assert!(spans.len() > 20, "{name}: only {} numbers", spans.len());
        loaded += sweep(name, text, &dir, &spans, &REPLACEMENTS);
        // Every quoted value (a type, a material name, a path, a preset, a profile) empty,
        // unknown, or a file that does not exist.
        let spans = strings(text);
        assert!(spans.len() > 5, "{name}: only {} strings", spans.len());
        loaded += sweep(
            name,
            text,
            &dir,
            &spans,
            &["\"\"", "\"x\"", "\"missing.obj\""],
        );
    }
    // Many replacements are legal (0 seed, 1e30 radiance...) and rendered: the sweep reached
    // the render loop, not only the parser.
    assert!(loaded > 50, "only {loaded} variants loaded");
    let _ = std::fs::remove_dir_all(&dir);
}

/// An error and its causes, as the CLI prints them.
fn chain(e: &dyn std::error::Error) -> String {
    let mut text = e.to_string();
    let mut cause = e.source();
    while let Some(c) = cause {
        text = format!("{text}: {c}");
        cause = c.source();
    }
    text
}

/// A valid 8 x 4 EXR whose header is patched to claim a 100000 x 100000 data window: 470 bytes
/// that would ask the decoder for 120 GB.
fn exr_bomb(path: &Path) {
    Image::new(8, 4).write_exr(path).unwrap();
    let mut bytes = std::fs::read(path).unwrap();
    let key = b"dataWindow\0box2i\0";
    let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4;
    for (k, v) in [0i32, 0, 99_999, 99_999].into_iter().enumerate() {
        bytes[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    std::fs::write(path, bytes).unwrap();
}

/// Header-size bombs and special files: every input (scene, mesh, image texture, environment
/// map, profile, table) is refused with what is wrong, before anything large is allocated and
/// without blocking on a FIFO.
#[test]
fn header_bombs_and_special_files_are_refused_up_front() {
    let dir = input_files("bombs");
    exr_bomb(&dir.join("bomb.exr"));
    let fifo = dir.join("fifo");
    let fifo_made = std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success());
    let file = dir.join("everything.toml");
    let load = |text: &str| {
        Scene::parse(text, &file, &dir, &Overrides::default())
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    let mut cases = vec![
        ("\"sky.exr\"", "\"bomb.exr\"", "100000 x 100000"),
        ("\"wood.png\"", "\"bomb.exr\"", "100000 x 100000"),
        ("\"tet.obj\"", "\"/dev/zero\"", "a device"),
        ("\"tet.obj\"", "\".\"", "a folder"),
        ("\"sky.exr\"", "\"/dev/urandom\"", "a device"),
    ];
    if fifo_made {
        cases.push(("\"tet.obj\"", "\"fifo\"", "a FIFO"));
        cases.push(("\"wood.png\"", "\"fifo\"", "a FIFO"));
    }
    for (from, to, expect) in cases {
        assert!(EVERYTHING.contains(from));
        let msg = load(&EVERYTHING.replacen(from, to, 1));
        assert!(msg.contains(expect), "{from} -> {to}: {msg}");
    }
    for path in [Path::new("/dev/zero"), fifo.as_path(), dir.as_path()] {
        if path == fifo && !fifo_made {
            continue;
        }
        let msg = Scene::load(path, &Overrides::default())
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("not a regular file"), "{msg}");
        let msg = chain(&Profile::parse(&format!("file:{}", path.display())).unwrap_err());
        assert!(msg.contains("not a regular file"), "{msg}");
        let msg = chain(&ScratchTable::load(path).unwrap_err());
        assert!(msg.contains("not a regular file"), "{msg}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Over-long and short arrays: every numeric array of the scene format (positions, axes,
/// colours, matrix rows, conductor indices) given one element more or one fewer is refused
/// with the file named, never trimmed or padded.
#[test]
fn arrays_of_the_wrong_length_are_refused() {
    let dir = input_files("arrays");
    let file = dir.join("everything.toml");
    let mut arrays = 0;
    let mut from = 0;
    while let Some(k) = EVERYTHING[from..].find('[') {
        let start = from + k;
        let end = start + EVERYTHING[start..].find(']').unwrap();
        from = start + 1;
        let body = &EVERYTHING[start + 1..end];
        let line = EVERYTHING[..start].rfind('\n').map_or(0, |n| n + 1);
        let numeric = !body.is_empty()
            && body.split(',').all(|x| x.trim().parse::<f32>().is_ok())
            && !EVERYTHING[line..start].trim_start().starts_with('#');
        if !numeric {
            continue;
        }
        arrays += 1;
        let shorter = body.rsplit_once(',').map_or("", |(head, _)| head);
        for changed in [format!("{body}, 0.5"), shorter.to_string()] {
            let variant = format!(
                "{}[{changed}]{}",
                &EVERYTHING[..start],
                &EVERYTHING[end + 1..]
            );
            let msg = Scene::parse(&variant, &file, &dir, &Overrides::default())
                .map(|_| ())
                .expect_err(&format!("[{body}] -> [{changed}] accepted"))
                .to_string();
            assert!(
                msg.contains("everything.toml")
                    && (msg.contains("expected an array of exactly")
                        || msg.contains("a number or an [r, g, b] array")
                        || msg.contains("a number or an [x, y, z] array")),
                "[{body}] -> [{changed}]: {msg}"
            );
        }
    }
    assert!(arrays >= 10, "only {arrays} arrays");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every rejection names the key or flag that was wrong, with the value as written: a bad
/// key is checked on its own before any check that combines keys.
#[test]
fn errors_blame_the_key_or_flag_with_the_value_as_written() {
    let dir = input_files("blame");
    let file = dir.join("everything.toml");
    let load = |text: &str, o: &Overrides| {
        Scene::parse(text, &file, &dir, o)
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    let none = Overrides::default();
    for (from, to, expect) in [
        (
            "position = [0.0, 2.6, 6.0]",
            "position = [nan, 2.6, 6.0]",
            "`camera.position`",
        ),
        (
            "position = [0.0, 2.6, 6.0]",
            "position = [0.0, 0.7, 1e30]",
            "`camera.position`",
        ),
        (
            "center = [-1.0, 1.0, 0.0]",
            "center = [-1.0, 1e30, 0.0]",
            "`shapes[3].center`",
        ),
        ("fov = ", "fov = 1e39 #", "`camera.fov` = 1e39"),
        (
            "\nradius = ",
            "\nradius = -1e39 #",
            "`shapes[3].radius` = -1e39",
        ),
    ] {
        assert!(EVERYTHING.contains(from), "{from}");
        let msg = load(&EVERYTHING.replacen(from, to, 1), &none);
        assert!(msg.contains(expect), "{to}: {msg}");
        assert!(!msg.contains("inf"), "{to}: {msg}");
    }
    // A flag's value is blamed on the flag, not on the scene file.
    let res = Overrides {
        resolution: Some((100_000, 100_000)),
        ..Overrides::default()
    };
    let msg = load(EVERYTHING, &res);
    assert!(msg.contains("`--res` = 100000x100000"), "{msg}");
    assert!(!msg.contains("everything.toml"), "{msg}");
    // An OBJ face of two vertices is not a triangle.
    std::fs::write(dir.join("tet.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n").unwrap();
    let msg = load(EVERYTHING, &none);
    assert!(msg.contains("line 4 has 2 vertices"), "{msg}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Part files (`striae merge`, Python's `merge`) are read as strictly as the scene's inputs:
/// a regular file only, its size checked against its header before its pixels are read, a
/// header within what a render can be (the renderer's largest image, a part count within the
/// tiles, an spp and an exposure in range), finite pixels; every refusal names the file. A set
/// missing many parts lists the first few and counts the rest.
#[test]
fn part_files_are_refused_naming_the_file_before_anything_large_is_read() {
    use striae::render::parts::{merge, part_pixel_count, Part, PartHeader, RenderId, FORMAT};
    let dir = std::env::temp_dir().join(format!("striae-parts-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Part `index` of `count` of a `width x height` image, its pixels 0.5.
    let part = |(width, height): (u32, u32), index: u32, count: u32| {
        let render = RenderId {
            scene_hash: "0".repeat(64),
            width,
            height,
            spp: 4,
            seed: 1,
            max_depth: 8,
            rr_depth: 5,
            sampler: "sobol".into(),
            version: striae::VERSION.into(),
        };
        let n = part_pixel_count((width, height), index, count).unwrap();
        let header = PartHeader {
            format: FORMAT,
            render,
            index,
            count,
            exposure: 0.0,
            samples: None,
        };
        Part {
            header,
            pixels: vec![Rgb::splat(0.5); n],
        }
    };
    // 64 x 48 pixels: 4 x 3 = 12 tiles.
    let small = (64, 48);
    let write = |name: &str, bytes: &[u8]| {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        path
    };
    let refused = |path: &Path, expect: &str| {
        let e = Part::read(path).unwrap_err().to_string();
        assert!(
            e.contains(expect) && e.contains(&path.display().to_string()),
            "{}: {e}",
            path.display()
        );
    };
    let good = write("good.part", &part(small, 0, 1).to_bytes());
    assert_eq!(Part::read(&good).unwrap(), part(small, 0, 1));

    // Special files, refused unopened (a folder first: without the check it fails at once,
    // where /dev/zero would be read until memory runs out).
    refused(&dir, "a folder");
    refused(Path::new("/dev/zero"), "a device");
    let fifo = dir.join("fifo");
    if std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success())
    {
        refused(&fifo, "a FIFO");
    }
    // Cut short on disk: its size against its header, before the pixels are read.
    let bytes = part(small, 0, 1).to_bytes();
    let short = write("short.part", &bytes[..bytes.len() - 5]);
    refused(&short, &format!("is {} bytes", bytes.len() - 5));
    // A header of the largest image in a file of a few hundred bytes.
    let mut claim = part(small, 0, 1);
    (claim.header.render.width, claim.header.render.height) = (32768, 32768);
    let claim = write("claim.part", &claim.to_bytes());
    refused(&claim, "part 0/1 of a 32768x32768 image is 128849");

    // Headers beyond what a render can be, and pixels no render writes: through the file
    // (read) and through the bytes (Python's parts) alike.
    let forged = |edit: &dyn Fn(&mut Part), expect: &str| {
        let mut p = part(small, 0, 2);
        edit(&mut p);
        let path = write("forged.part", &p.to_bytes());
        refused(&path, expect);
        let e = Part::from_bytes(&p.to_bytes(), &path)
            .unwrap_err()
            .to_string();
        assert!(e.contains(expect) && e.contains("forged.part"), "{e}");
    };
    forged(
        &|p| p.header.render.width = 100_000,
        "image size 100000x48 is beyond the renderer's",
    );
    forged(&|p| p.header.count = 13, "only 12 tiles");
    forged(&|p| p.header.index = 2, "must lie in 0..2");
    forged(&|p| p.header.render.spp = 0, "spp 0");
    forged(&|p| p.header.exposure = 1e30, "exposure 1e30 is beyond");
    // Part 0 of 2 holds tiles 0, 2, 4, ...: its pixel 17 is (1, 1) of tile 0.
    forged(
        &|p| p.pixels[17].y = f32::NAN,
        "pixel (1, 1) is [0.5, NaN, 0.5]",
    );
    forged(&|p| p.pixels[40].x = f32::INFINITY, "pixel (8, 2)");

    // A part built in memory with a count beyond the tiles: refused, naming it, before the
    // merge sizes anything by that count.
    let mut many = part(small, 0, 12);
    many.header.count = 4_000_000_000;
    let e = merge(&[(dir.join("many.part"), many)])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("many.part") && e.contains("only 12 tiles"),
        "{e}"
    );
    // 256 x 256 pixels in 256 parts, one given: the first ten missing, and a count.
    let one = part((256, 256), 0, 256);
    let e = merge(&[(dir.join("one.part"), one)])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("parts missing: [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, ...] (245 more, 255 in all)"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// A value of the wrong type names its full key, inside a material too (where serde reads a
/// buffered table that `toml` cannot point into); keys that apply to nothing are refused by
/// name; values beyond what the renderer takes (an OBJ vertex beyond the bound of the scene's
/// points, an exposure, a scratch length) are refused with the value as written.
#[test]
fn mistyped_foreign_and_absurd_values_name_their_key() {
    let dir = input_files("keys");
    let file = dir.join("everything.toml");
    let load = |text: &str| {
        Scene::parse(text, &file, &dir, &Overrides::default())
            .map(|_| ())
            .unwrap_err()
            .to_string()
    };
    let mix = "layer_mix = \"sum\"";
    let with = |key: &str| format!("{mix}\n{key}");
    for (from, to, expect) in [
        (
            mix,
            with("explicit = \"yes\""),
            "key `materials.scratched.scratches.explicit`: invalid type: string \"yes\", expected a boolean",
        ),
        (
            mix,
            with("lean = \"true\""),
            "`materials.scratched.scratches.lean`",
        ),
        (
            mix,
            "layer_mix = \"avg\"".into(),
            "`materials.scratched.scratches.layer_mix`: unknown variant `avg`",
        ),
        (
            mix,
            with("model = \"exact\""),
            "`materials.scratched.scratches.model`: unknown variant `exact`, expected `default` or `seed`",
        ),
        (
            mix,
            with("bogus = 1"),
            "`materials.scratched.scratches.bogus`: unknown field",
        ),
        (
            "scale = 8.0 }",
            "scale = \"x\" }".into(),
            "`materials.floor.reflectance",
        ),
        (
            "eta = [0.143, 0.375, 1.442]",
            "eta = [0.143, 0.375, \"x\"]".into(),
            "`materials.metal.eta[2]`",
        ),
        (
            "type = \"dielectric\"",
            "type = 7".into(),
            "`materials.rough.type`",
        ),
        (
            "type = \"dielectric\"",
            "type = \"glas\"".into(),
            "`materials.rough.type`: unknown variant `glas`",
        ),
        (
            "preset = \"gold\"\nroughness = 0.1",
            "preset = \"gold\"\nroughness = \"0.1\"".into(),
            "`materials.gold.roughness`",
        ),
        // Keys that apply to nothing.
        (
            mix,
            with("stations = 16"),
            "`materials.scratched.scratches.stations` = 16: applies to explicit grooves only",
        ),
        (
            "type = \"map\"\npath = \"sky.exr\"",
            "type = \"constant\"\nradiance = 1.0".into(),
            "`environment.scale` = 1.0: `scale` does not apply to a constant environment",
        ),
        // Absurd values, as written.
        (
            "exposure = 0.5",
            "exposure = 1e30".into(),
            "`render.exposure` = 1e30",
        ),
        (
            "setting = 1",
            "length = 1e30\nwidth = 0.01\nthreshold = 0.1".into(),
            "`materials.scratched.scratches.length` = 1e30",
        ),
    ] {
        assert!(EVERYTHING.contains(from), "{from}");
        let msg = load(&EVERYTHING.replacen(from, &to, 1));
        assert!(msg.contains(expect), "{to}: {msg}");
    }
    // An OBJ vertex beyond the bound of sphere centres (`MAX_COORDINATE`).
    for v in ["v 1e20 0 0", "v 0 0 -1e39"] {
        let obj = format!("v 0 0 0\nv 1 0 0\n{v}\nf 1 2 3\n");
        std::fs::write(dir.join("tet.obj"), obj).unwrap();
        let msg = load(EVERYTHING);
        assert!(
            msg.contains("tet.obj") && msg.contains(&format!("line 3 (`{v}`)")),
            "{v}: {msg}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
