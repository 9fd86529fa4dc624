//! Bad values never panic: every number of two scene files (`data/every-kind.toml`, with
//! every shape, material, light, transform and input-file kind, and a scratched plate) is
//! replaced in turn by NaN, infinities, zero, -1 and extremes, and every quoted value by an
//! empty, an unknown and a missing-file one; each variant must load and render, or fail with
//! an error naming the file. (A random fuzzer over the shipped scenes found non-finite
//! translations panicking at load; this sweep covers that class systematically.) Tiny images,
//! about a second in all.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use striae::film::Image;
use striae::integrator::render;
use striae::math::Rgb;
use striae::profile::Profile;
use striae::scene::{Overrides, Scene};
use striae::table::{ScratchTable, TableParams};
use striae::trace2d::TraceSettings;

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

#[test]
fn every_value_of_a_scene_replaced_by_a_bad_one_loads_or_errors_without_panicking() {
    let dir = std::env::temp_dir().join(format!("striae-robustness-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // The files the scenes name.
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
