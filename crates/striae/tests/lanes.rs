//! The lane render loop (`render.lanes`, `integrator::lanes`) against the one-path loop, the
//! reference: on every shipped scene, the same image bit for bit where no material reads the
//! pixel's footprint, and the same mean within noise where one does; the same image for any
//! thread count and in every compiled copy of the loop.

mod common;

use common::{assert_bit_identical_across_thread_counts, render_with_threads};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use striae::render::film::Image;
use striae::render::integrator::{render_tile_sums, render_with, tile_count, Simd};
use striae::render::material::Material;
use striae::render::scene::{Overrides, Scene};

const SCENES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes");

/// The shipped scene files: the TOML scenes, and the glTF scene Blender's exporter wrote
/// (its materials glTF's metallic-roughness BSDF).
fn shipped_scenes() -> Vec<PathBuf> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(SCENES)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    paths.sort();
    paths.push(Path::new(SCENES).join("blender/blender-scene.glb"));
    paths
}

/// The scene at `path` at `res`, `spp`, in the lane loop or the one-path loop.
fn load(path: &Path, res: (u32, u32), spp: u32, lanes: bool) -> Scene {
    let o = Overrides {
        spp: Some(spp),
        resolution: Some(res),
        lanes: Some(lanes),
        ..Overrides::default()
    };
    Scene::load(path, &o).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn bits(img: &Image) -> Vec<[u32; 3]> {
    img.pixels
        .iter()
        .map(|p| p.to_array().map(f32::to_bits))
        .collect()
}

/// How many standard errors the mean of `a - b` over pixels and channels lies from 0.
fn mean_difference_in_sigmas(a: &Image, b: &Image) -> f64 {
    let d: Vec<f64> = a
        .pixels
        .iter()
        .zip(&b.pixels)
        .flat_map(|(x, y)| (*x - *y).to_array().map(f64::from))
        .collect();
    let n = d.len() as f64;
    let mean = d.iter().sum::<f64>() / n;
    let var = d.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    if var == 0.0 {
        return 0.0;
    }
    mean / (var / n).sqrt()
}

#[test]
fn lane_loop_renders_every_shipped_scene_as_the_one_path_loop() {
    let (mut identical, mut within_noise, mut lit, mut pbr) = (0, 0, 0, 0);
    for path in shipped_scenes() {
        // A full tile and a cut one with packets of camera rays (8 spp), and odd sizes below
        // the packet threshold (3 spp), where every path traces its own camera ray.
        for (res, spp) in [((40, 24), 8), ((19, 13), 3)] {
            let (one, lanes) = (load(&path, res, spp, false), load(&path, res, spp, true));
            let (a, sa) = render_with_threads(&one, 2);
            let (b, sb) = render_with_threads(&lanes, 2);
            let name = path.file_name().unwrap().to_string_lossy();
            lit += a.pixels.iter().any(|p| p.max_element() > 0.0) as usize;
            pbr += one.materials.iter().any(|m| matches!(m, Material::Pbr(_))) as usize;
            if one.materials.iter().any(Material::reads_footprint) {
                // A pixel's samples share its cached footprints in the order they reach
                // them: not sample order in the lanes, so the images differ within noise.
                let z = mean_difference_in_sigmas(&a, &b);
                assert!(
                    z.abs() < 4.0,
                    "{name} at {spp} spp: means {z:.2} sigma apart"
                );
                within_noise += 1;
            } else {
                assert!(bits(&a) == bits(&b), "{name} at {spp} spp: images differ");
                assert_eq!(sa.rays, sb.rays, "{name}: ray counts");
                assert_eq!(sa.nonfinite, sb.nonfinite, "{name}: non-finite samples");
                identical += 1;
            }
        }
    }
    // Both kinds of scene are among the shipped ones, and nearly every image shows something
    // (a black image proves nothing; a halo can miss every pixel of the smallest film).
    assert!(
        identical >= 10 && within_noise >= 4,
        "{identical} and {within_noise}"
    );
    assert!(
        lit + 2 >= identical + within_noise,
        "{lit} images not black"
    );
    // glTF's BSDF among them: `pbr.toml` and Blender's scene, at both sizes.
    assert!(pbr >= 4, "{pbr} renders of glTF materials");
}

/// The scene `text` at 40 x 24, 8 spp, in the lane loop or the one-path loop.
fn parse_small(text: &str, lanes: bool) -> Scene {
    let o = Overrides {
        spp: Some(8),
        resolution: Some((40, 24)),
        lanes: Some(lanes),
        ..Overrides::default()
    };
    Scene::parse(text, Path::new("small.toml"), Path::new(SCENES), &o).unwrap()
}

/// `one` (the one-path loop) and its lane-loop twin `lanes` render the same image bit for bit
/// with the same rays, and it is not black.
fn assert_lanes_bit_for_bit(one: &Scene, lanes: &Scene) {
    let (a, sa) = render_with_threads(one, 2);
    let (b, sb) = render_with_threads(lanes, 2);
    assert!(a.pixels.iter().any(|p| p.max_element() > 0.0));
    assert!(bits(&a) == bits(&b) && sa.rays == sb.rays);
}

#[test]
fn scratched_glass_seen_from_inside_runs_in_lanes_bit_for_bit() {
    // With point coverage no material reads the footprint, so the loops must agree bit for
    // bit; the lane vertex takes the glass's hits from inside (its smooth base).
    let text = include_str!("../scenes/glass-teapot-setting1.toml").replace(
        "layer_mix = \"max\"",
        "layer_mix = \"max\"\ncoverage = \"point\"",
    );
    let one = parse_small(&text, false);
    assert!(!one.materials.iter().any(Material::reads_footprint));
    assert_lanes_bit_for_bit(&one, &parse_small(&text, true));
}

#[test]
fn rough_glass_and_metal_run_in_lanes_bit_for_bit() {
    // GGX glass and gold, plain and compensated, rough glTF glass, smooth glTF metal and
    // plastic on a shape that glows (the lane vertex's GGX and glTF loops), each scene with
    // and without the lanes, and the lanes in every compiled copy (each runs the GGX vertices
    // it vectorises in SIMD lanes and leaves the others to the one-path vertex).
    let frosted = include_str!("../scenes/glass-teapot.toml")
        .replace("ior = 1.5", "ior = 1.5\nroughness = 0.25");
    let brushed = include_str!("../scenes/metal-teapot.toml")
        .replace("preset = \"gold\"", "preset = \"gold\"\nroughness = 0.2");
    // And compensated (`multiscatter = true`): the same BSDFs with their albedo tables.
    let compensated = |text: &str| text.replace("roughness", "multiscatter = true\nroughness");
    let (milky, worn) = (compensated(&frosted), compensated(&brushed));
    // And glTF's BSDF with rough absorbing glass (`pbr.toml`'s, made rough).
    let smooth_gltf = include_str!("../scenes/pbr.toml");
    let frosted_gltf = smooth_gltf.replace(
        "roughness = 0.0\ntransmission = 1.0",
        "roughness = 0.3\ntransmission = 1.0",
    );
    assert_ne!(smooth_gltf, frosted_gltf);
    // And smooth glTF metal (a delta BSDF) and plastic (delta lobes beside a diffuse one), the
    // plastic box glowing.
    let glowing_gltf = smooth_gltf
        .replace(
            "metallic = 1.0\nroughness = 0.35",
            "metallic = 1.0\nroughness = 0.0",
        )
        .replace(
            "metallic = 0.0\nroughness = 0.3\n",
            "metallic = 0.0\nroughness = 0.0\n",
        )
        .replace(
            "material = \"plastic\"",
            "material = \"plastic\"\nemission = [0.4, 0.1, 0.1]",
        );
    assert_eq!(glowing_gltf.matches("roughness = 0.0").count(), 3);
    assert!(glowing_gltf.contains("emission"));
    for text in [frosted, brushed, milky, worn, frosted_gltf, glowing_gltf] {
        assert!(text.contains("roughness"));
        let lanes = parse_small(&text, true);
        assert_lanes_bit_for_bit(&parse_small(&text, false), &lanes);
        let (a, _) = render_with(&lanes, &|_| {}, Simd::Auto);
        let (b, _) = render_with(&lanes, &|_| {}, Simd::Avx2);
        let (c, _) = render_with(&lanes, &|_| {}, Simd::Portable);
        assert!(bits(&a) == bits(&b) && bits(&a) == bits(&c));
    }
}

#[test]
fn lane_loop_follows_a_thin_lens_and_sample_ranges_as_the_one_path_loop() {
    // A thin lens's camera rays share no origin (no packets); one sample a pixel leaves lanes
    // idle at a tile's end.
    let teapot = include_str!("../scenes/glass-teapot.toml").replace(
        "fov = 30.0",
        "fov = 30.0\naperture_radius = 0.05\nfocus_distance = 6.0",
    );
    for spp in [1, 6] {
        let scene = |lanes| {
            let o = Overrides {
                spp: Some(spp),
                resolution: Some((36, 20)),
                lanes: Some(lanes),
                ..Overrides::default()
            };
            Scene::parse(&teapot, Path::new("lens.toml"), Path::new("."), &o).unwrap()
        };
        let (a, _) = render_with_threads(&scene(false), 2);
        let (b, _) = render_with_threads(&scene(true), 2);
        assert!(bits(&a) == bits(&b), "thin lens at {spp} spp");
    }
    // A part of the samples (`render_tile_sums`, as `parts` renders them): samples 3..40 of
    // every tile, through the pinhole (packets of camera rays that start mid-pixel).
    let o = |lanes| Overrides {
        spp: Some(40),
        resolution: Some((36, 20)),
        lanes: Some(lanes),
        ..Overrides::default()
    };
    let pinhole = include_str!("../scenes/glass-teapot.toml");
    let sums = |lanes| {
        let s = Scene::parse(pinhole, Path::new("t.toml"), Path::new("."), &o(lanes)).unwrap();
        let tiles: Vec<u32> = (0..tile_count(36, 20)).collect();
        let never = AtomicBool::new(false);
        let (sums, _) = render_tile_sums(&s, &tiles, 3..40, &|_| {}, &never, Simd::Auto).unwrap();
        sums.concat()
    };
    let (a, b) = (sums(false), sums(true));
    assert!(a.iter().any(|p| p.max_element() > 0.0));
    assert!(a
        .iter()
        .zip(&b)
        .all(|(x, y)| x.to_array().map(f32::to_bits) == y.to_array().map(f32::to_bits)));
}

#[test]
fn lane_loop_images_do_not_depend_on_threads_or_the_compiled_copy() {
    // The built-in scene reads footprints (scratched glass seen from outside): the lanes hold
    // one pixel's samples at a time there; the glass teapot does not.
    let o = Overrides {
        spp: Some(6),
        resolution: Some((40, 30)),
        seed: Some(5),
        lanes: Some(true),
        ..Overrides::default()
    };
    let teapot = include_str!("../scenes/glass-teapot.toml");
    for text in [striae::render::scene::DEFAULT_SCENE, teapot] {
        let s = Scene::parse(text, Path::new("t.toml"), Path::new("."), &o).unwrap();
        assert!(s.settings.lanes);
        let a = assert_bit_identical_across_thread_counts(&s);
        let (b, _) = render_with(&s, &|_| {}, Simd::Avx2);
        let (c, _) = render_with(&s, &|_| {}, Simd::Portable);
        assert!(bits(&a) == bits(&b) && bits(&a) == bits(&c));
    }
}
