//! Bad values never panic: every number of two scene files (one with every shape, material,
//! light and transform kind, one scratched) is replaced in turn by NaN, infinities, zero, -1 and
//! extremes, and every quoted value by an empty, an unknown and a missing-file one; each variant
//! must load and render, or fail with an error naming the file. (A
//! random fuzzer over the shipped scenes found non-finite translations panicking at load;
//! this sweep covers that class systematically.) Tiny images, about a second in all.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use striae::integrator::render;
use striae::profile::Profile;
use striae::scene::{Overrides, Scene};
use striae::table::{ScratchTable, TableParams};
use striae::trace2d::TraceSettings;

const EVERYTHING: &str = r#"
[render]
width = 4
height = 3
spp = 1
max_depth = 6
rr_depth = 2
seed = 3
exposure = 0.5

[camera]
position = [0.0, 2.6, 6.0]
look_at = [0.0, 0.7, 0.0]
up = [0.0, 1.0, 0.0]
fov = 30.0
aperture_radius = 0.05
focus_distance = 6.2

[materials.floor]
type = "diffuse"
reflectance = { type = "checkerboard", color0 = [0.8, 0.8, 0.8], color1 = [0.1, 0.1, 0.1], scale = 8.0 }

[materials.rough]
type = "dielectric"
ior = 1.5
ext_ior = 1.0
roughness = 0.2

[materials.gold]
type = "conductor"
preset = "gold"
roughness = 0.1

[materials.metal]
type = "conductor"
eta = [0.143, 0.375, 1.442]
k = [3.983, 2.386, 1.603]

[[shapes]]
type = "mesh"
path = "tet.obj"
material = "floor"
transform = [{ scale = 0.5 }, { translate = [1.0, 0.0, 0.0] }]

[[shapes]]
type = "rectangle"
material = "floor"
transform = [{ scale = 6.0 }, { rotate = { axis = [1.0, 0.0, 0.0], angle = -90.0 } }]

[[shapes]]
type = "box"
material = "rough"
transform = { scale = [0.5, 0.5, 0.1] }

[[shapes]]
type = "sphere"
center = [-1.0, 1.0, 0.0]
radius = 0.5
material = "gold"

[[shapes]]
type = "teapot"
subdivisions = 2
material = "metal"
transform = { matrix = [[0.2, 0.0, 0.0, 0.0], [0.0, 0.2, 0.0, 0.0], [0.0, 0.0, 0.2, 1.0], [0.0, 0.0, 0.0, 1.0]] }

[[shapes]]
type = "rectangle"
emission = [12.0, 11.0, 10.0]
transform = [{ look_at = { origin = [-1.5, 4.0, 1.5], target = [0.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] } }]

[[shapes]]
type = "sphere"
center = [2.0, 3.0, 0.0]
radius = 0.3
emission = 5.0

[environment]
type = "constant"
radiance = [0.25, 0.3, 0.4]

[[lights]]
type = "sun"
direction = [0.3, 1.0, 0.2]
irradiance = [3.0, 3.0, 3.0]
"#;

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

/// Byte ranges of the quoted values in `text` (quotes included): the strings after a `=`.
fn strings(text: &str) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut from = 0;
    while let Some(k) = text[from..].find("= \"") {
        let start = from + k + 2;
        let end = start + 1 + text[start + 1..].find('"').unwrap() + 1;
        out.push((start, end));
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
    std::fs::write(
        dir.join("tet.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    )
    .unwrap();
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
