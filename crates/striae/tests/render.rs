//! Scene tests of the path tracer: white furnaces, analytic scenes with known pixel values,
//! determinism across thread counts, and clear errors for bad scene files. Small images and
//! few samples: the whole file runs in a few seconds.

use std::path::Path;
use striae::render::film::Image;
use striae::render::geometry::TriangleTest;
use striae::render::integrator::{render_with, LoopCopy, Simd};
use striae::render::scene::{Overrides, Scene, SceneError};
use striae::testing::MeanEstimate;

mod common;
use common::{assert_bit_identical_across_thread_counts, render_with_threads, scene};

/// Mean over the pixels inside a centred square of side `frac` of the image (each pixel is an
/// independent estimate), per channel.
fn centre_mean(img: &Image, frac: f32, channel: usize) -> MeanEstimate {
    let mut m = MeanEstimate::default();
    let (w, h) = (img.width as f32, img.height as f32);
    for y in 0..img.height {
        for x in 0..img.width {
            let (dx, dy) = ((x as f32 + 0.5) / w - 0.5, (y as f32 + 0.5) / h - 0.5);
            if dx.abs() < frac / 2.0 && dy.abs() < frac / 2.0 {
                m.push(img.get(x, y)[channel] as f64);
            }
        }
    }
    m
}

/// A camera filling its view with a unit sphere of the given material in a uniform white
/// environment: every pixel's expectation is exactly 1 for a lossless material.
fn furnace(material: &str) -> Scene {
    scene(&furnace_text(material))
}

/// The text of [`furnace`]'s scene.
fn furnace_text(material: &str) -> String {
    format!(
        r#"
[render]
width = 24
height = 24
spp = 64
max_depth = 0
[camera]
position = [0, 0, 4]
look_at = [0, 0, 0]
fov = 28
[materials.m]
{material}
[[shapes]]
type = "sphere"
material = "m"
[environment]
type = "constant"
radiance = 1
"#
    )
}

fn assert_furnace(s: &Scene, what: &str) {
    let (img, _) = render_with_threads(s, 2);
    for c in 0..3 {
        let m = centre_mean(&img, 0.5, c);
        assert!(m.count() > 100);
        assert!(
            m.agrees_with(1.0, 4.0, 1e-3),
            "{what}: channel {c} mean {} +- {}",
            m.mean(),
            m.std_error()
        );
    }
}

#[test]
fn white_furnace_glass_sphere() {
    assert_furnace(&furnace("type = \"dielectric\"\nior = 1.5"), "glass sphere");
}

#[test]
fn white_furnace_perfect_conductor_sphere() {
    // A purely imaginary index (eta = 0, k > 0) reflects everything: F = 1 at every angle.
    assert_furnace(
        &furnace("type = \"conductor\"\neta = [0, 0, 0]\nk = [1, 1, 1]"),
        "F = 1 conductor",
    );
}

#[test]
fn white_furnace_fails_for_a_lossy_material() {
    // The furnace test can fail: an absorbing material is caught.
    let s = furnace("type = \"conductor\"\neta = [0.2, 0.2, 0.2]\nk = [3, 3, 3]");
    let (img, _) = render_with_threads(&s, 2);
    let m = centre_mean(&img, 0.5, 0);
    assert!(!m.agrees_with(1.0, 4.0, 1e-3), "mean {}", m.mean());
}

/// The white furnace of a rough sphere with and without `multiscatter = true`, 32 x 32 pixels
/// at 64 spp: with it, the mean over a centred square of 0.6 of the image (inside the
/// sphere) is 1 within noise per channel, and so is each of its 4 x 4 blocks; without it the
/// sphere is darker (single scattering loses energy), by more than `min_loss`. Both images
/// are written as PNGs (exposure -1: 1 is mid grey) to the test's temporary folder. Returns
/// the two means (red channel).
fn assert_multiscatter_furnace(material: &str, name: &str, min_loss: f64) -> (f64, f64) {
    let text = |ms: bool| {
        furnace_text(&format!("{material}\nmultiscatter = {ms}"))
            .replace("width = 24", "width = 32")
            .replace("height = 24", "height = 32")
    };
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let mut means = [0.0; 2];
    for (i, ms) in [true, false].into_iter().enumerate() {
        let (img, _) = render_with_threads(&scene(&text(ms)), 2);
        img.write_png(&dir.join(format!("furnace-{name}-ms-{ms}.png")), -1.0)
            .unwrap();
        for c in 0..3 {
            let m = centre_mean(&img, 0.6, c);
            assert!(m.count() > 300);
            if c == 0 {
                means[i] = m.mean();
            }
            if ms {
                assert!(
                    m.agrees_with(1.0, 4.0, 2e-3),
                    "{name} multiscatter: channel {c} mean {} +- {}",
                    m.mean(),
                    m.std_error()
                );
                for (b, block) in square_blocks(&img, 0.6, 4, c).iter().enumerate() {
                    assert!(
                        block.agrees_with(1.0, 4.5, 2e-3),
                        "{name} multiscatter: channel {c} block {b} mean {} +- {}",
                        block.mean(),
                        block.std_error()
                    );
                }
            } else {
                assert!(
                    m.mean() + 4.0 * m.std_error() < 1.0 - min_loss,
                    "{name} single scattering: channel {c} mean {} +- {}",
                    m.mean(),
                    m.std_error()
                );
            }
        }
    }
    eprintln!(
        "{name}: furnace {:.4} with multiscatter, {:.4} without",
        means[0], means[1]
    );
    (means[0], means[1])
}

/// The pixel means of the `n x n` blocks of the centred square of side `frac`, per channel.
fn square_blocks(img: &Image, frac: f32, n: usize, channel: usize) -> Vec<MeanEstimate> {
    let mut blocks = vec![MeanEstimate::default(); n * n];
    let (w, h) = (img.width as f32, img.height as f32);
    for y in 0..img.height {
        for x in 0..img.width {
            let (dx, dy) = ((x as f32 + 0.5) / w - 0.5, (y as f32 + 0.5) / h - 0.5);
            if dx.abs() < frac / 2.0 && dy.abs() < frac / 2.0 {
                let bx = (((dx / frac + 0.5) * n as f32) as usize).min(n - 1);
                let by = (((dy / frac + 0.5) * n as f32) as usize).min(n - 1);
                blocks[by * n + bx].push(img.get(x, y)[channel] as f64);
            }
        }
    }
    blocks
}

#[test]
fn white_furnace_rough_glass_sphere_with_multiscatter() {
    assert_multiscatter_furnace(
        "type = \"dielectric\"\nior = 1.5\nroughness = 0.8",
        "rough-glass",
        0.02,
    );
}

#[test]
fn white_furnace_rough_perfect_conductor_sphere_with_multiscatter() {
    assert_multiscatter_furnace(
        "type = \"conductor\"\npreset = \"none\"\nroughness = 0.8",
        "rough-mirror",
        0.03,
    );
}

#[test]
fn diffuse_plane_under_constant_sky_is_albedo_times_radiance() {
    assert_diffuse_plane_under_constant_sky("sobol");
}

#[test]
fn independent_sampler_gives_the_same_expectation() {
    assert_diffuse_plane_under_constant_sky("independent");
}

/// A Lambertian plane of albedo (0.5, 0.25, 0.8) filling the view under a constant sky of
/// radiance (2, 2, 1), with the given `render.sampler` and `[[lights]]` tables.
fn plane_under_constant_sky(sampler: &str, lights: &str) -> Scene {
    scene(&format!(
        r#"
[render]
width = 32
height = 32
spp = 16
max_depth = 2
sampler = "{sampler}"
[camera]
position = [0, 3, 1]
look_at = [0, 0, 0]
fov = 30
[materials.plane]
type = "diffuse"
reflectance = [0.5, 0.25, 0.8]
[[shapes]]
type = "rectangle"
material = "plane"
transform = [{{ scale = 50 }}, {{ rotate = {{ axis = [1, 0, 0], angle = -90 }} }}]
{lights}
[environment]
type = "constant"
radiance = [2, 2, 1]
"#
    ))
}

/// pixel = a L for a Lambertian plane of albedo a seeing only a sky of radiance L (reached by
/// BSDF sampling; a constant sky is not light-sampled), with the given `render.sampler`.
fn assert_diffuse_plane_under_constant_sky(sampler: &str) {
    let s = plane_under_constant_sky(sampler, "");
    let (img, stats) = render_with_threads(&s, 2);
    assert_eq!(stats.samples, 32 * 32 * 16);
    for (c, expected) in [(0, 1.0), (1, 0.5), (2, 0.8)] {
        let m = centre_mean(&img, 1.0, c);
        assert!(
            m.agrees_with(expected, 4.0, 1e-3),
            "{sampler}, channel {c}: {} +- {} vs {expected}",
            m.mean(),
            m.std_error()
        );
        assert!(m.std_error() < 0.01);
    }
}

#[test]
fn diffuse_plane_under_constant_sky_and_sun_counts_each_light_once() {
    // pixel = a (L + E cos(theta_sun) / pi). The sky reaches the plane by BSDF sampling only
    // (a constant environment gives next-event estimation no sample), so its escaping rays
    // must weigh 1; the sun is light-sampled when chosen (one of two lights, weight 2).
    let (e, cos_sun) = (3.0f64, 0.8f64);
    let s = plane_under_constant_sky(
        "sobol",
        "[[lights]]\ntype = \"sun\"\ndirection = [0.6, 0.8, 0]\nirradiance = 3",
    );
    let (img, _) = render_with_threads(&s, 2);
    let sun = e * cos_sun / std::f64::consts::PI;
    for (c, a, sky) in [(0, 0.5, 2.0), (1, 0.25, 2.0), (2, 0.8, 1.0)] {
        let expected = a * (sky + sun);
        let m = centre_mean(&img, 1.0, c);
        assert!(
            m.agrees_with(expected, 4.0, 1e-3),
            "channel {c}: {} +- {} vs {expected}",
            m.mean(),
            m.std_error()
        );
    }
}

#[test]
fn diffuse_plane_under_a_sphere_light_matches_the_analytic_irradiance() {
    // A sphere light of radius R and radiance Le centred at height d above a Lambertian plane
    // gives irradiance E = pi Le (R/d)^2 at the foot point, so the pixel there is a Le (R/d)^2.
    // The camera sees a tiny patch around the foot point (1 degree field of view).
    let (r, d, le, a) = (0.5f64, 2.0f64, 10.0f64, 0.6f64);
    let s = scene(&format!(
        r#"
[render]
width = 8
height = 8
spp = 256
max_depth = 2
[camera]
position = [3, 2, 0]
look_at = [0, 0, 0]
fov = 1
[materials.plane]
type = "diffuse"
reflectance = [{a}, {a}, {a}]
[[shapes]]
type = "rectangle"
material = "plane"
transform = [{{ scale = 10 }}, {{ rotate = {{ axis = [1, 0, 0], angle = -90 }} }}]
[[shapes]]
type = "sphere"
center = [0, {d}, 0]
radius = {r}
emission = {le}
"#
    ));
    let (img, _) = render_with_threads(&s, 2);
    let expected = a * le * (r / d).powi(2);
    let m = centre_mean(&img, 1.0, 1);
    // The patch is ~0.06 wide: the irradiance varies by well under 0.5% across it.
    assert!(
        m.agrees_with(expected, 4.0, 0.005 * expected),
        "{} +- {} vs {expected}",
        m.mean(),
        m.std_error()
    );
}

#[test]
fn emitter_seen_directly_has_its_radiance() {
    let s = scene(
        r#"
[render]
width = 8
height = 8
spp = 4
[camera]
position = [0, 0, 3]
look_at = [0, 0, 0]
fov = 10
[[shapes]]
type = "rectangle"
emission = [1, 2, 3]
"#,
    );
    let (img, _) = render_with_threads(&s, 1);
    for p in &img.pixels {
        assert_eq!(*p, striae::math::Rgb::new(1.0, 2.0, 3.0));
    }
}

#[test]
fn image_is_bit_identical_across_thread_counts() {
    let text = striae::render::scene::DEFAULT_SCENE;
    let o = Overrides {
        spp: Some(4),
        resolution: Some((40, 30)),
        seed: Some(7),
        max_depth: None,
        sampler: None,
        lanes: None,
    };
    let s = Scene::parse(text, Path::new("default.toml"), Path::new("."), &o).unwrap();
    let a = assert_bit_identical_across_thread_counts(&s);
    // And the seed matters.
    let o2 = Overrides { seed: Some(8), ..o };
    let s2 = Scene::parse(text, Path::new("default.toml"), Path::new("."), &o2).unwrap();
    let (c, _) = render_with_threads(&s2, 2);
    assert_ne!(a.pixels, c.pixels);
    // The independent sampler too, and its image is not the Sobol one.
    let o3 = Overrides {
        sampler: Some(striae::render::sampler::SamplerKind::Independent),
        ..o
    };
    let s3 = Scene::parse(text, Path::new("default.toml"), Path::new("."), &o3).unwrap();
    let d = assert_bit_identical_across_thread_counts(&s3);
    assert_ne!(a.pixels, d.pixels);
}

#[test]
fn fast_and_watertight_triangle_tests_render_the_glass_teapot_alike() {
    // The same samples through both forms of the triangle test (`render.watertight`): they
    // differ only for rays within rounding of a triangle's edge, so nearly every pixel is the
    // same and the image means agree far below the noise.
    let smooth = include_str!("../scenes/glass-teapot.toml");
    let o = Overrides {
        spp: Some(16),
        resolution: Some((64, 48)),
        ..Overrides::default()
    };
    let scene = |text: &str| Scene::parse(text, Path::new("t.toml"), Path::new("."), &o).unwrap();
    let (fast, watertight) = (
        scene(smooth),
        scene(&smooth.replace("[render]\n", "[render]\nwatertight = true\n")),
    );
    assert_eq!(fast.settings.triangles, TriangleTest::Fast);
    assert_eq!(watertight.settings.triangles, TriangleTest::Watertight);
    let (fast, watertight) = (
        render_with_threads(&fast, 2).0,
        render_with_threads(&watertight, 2).0,
    );
    let same = fast
        .pixels
        .iter()
        .zip(&watertight.pixels)
        .filter(|(a, b)| (**a - **b).abs().max_element() <= 1e-4 * (1.0 + a.max_element()))
        .count();
    assert!(
        same * 100 >= fast.pixels.len() * 99,
        "{same} of {} pixels agree",
        fast.pixels.len()
    );
    let mean = |img: &Image| {
        img.pixels
            .iter()
            .map(|p| p.element_sum() as f64)
            .sum::<f64>()
    };
    let (a, b) = (mean(&fast), mean(&watertight));
    assert!((a / b - 1.0).abs() < 1e-3, "means {a} and {b}");
}

#[test]
fn simd_and_portable_render_loops_give_the_same_image() {
    // The render loop is compiled three times (AVX-512 and AVX2 + FMA where the CPU has them,
    // portable everywhere); all must give the same image bit for bit (on a CPU without
    // AVX-512 or AVX2, `Auto` and `Avx2` fall back to a narrower copy). The default scene
    // (scratched glass under a sun: the loop that carries ray differentials), the smooth glass
    // teapot (a textured diffuse floor, an area light, the sky) and one with rough and smooth
    // metal, rough glass and a sphere light cover both loops, the BVH, both triangle tests,
    // the sphere test and the BSDFs.
    let rough = r#"
        [render]
        width = 24
        height = 18
        spp = 4
        max_depth = 8
        [camera]
        position = [0.0, 1.0, 4.0]
        look_at = [0.0, 0.5, 0.0]
        fov = 40.0
        [materials.gold]
        type = "conductor"
        preset = "Au"
        roughness = 0.2
        [materials.frosted]
        type = "dielectric"
        ior = 1.5
        roughness = 0.3
        [materials.chrome]
        type = "conductor"
        preset = "Cr"
        [[shapes]]
        type = "teapot"
        material = "gold"
        subdivisions = 3
        transform = [{ scale = 0.3 }]
        [[shapes]]
        type = "sphere"
        material = "frosted"
        center = [1.0, 0.4, 0.0]
        radius = 0.4
        [[shapes]]
        type = "rectangle"
        material = "chrome"
        transform = [{ scale = 3.0 }, { rotate = { axis = [1, 0, 0], angle = -90 } }]
        [[shapes]]
        type = "sphere"
        center = [0.0, 3.0, 1.0]
        radius = 0.3
        emission = [20.0, 20.0, 20.0]
        [environment]
        type = "constant"
        radiance = [0.2, 0.2, 0.3]
    "#;
    let o = Overrides {
        spp: Some(4),
        resolution: Some((32, 24)),
        seed: Some(3),
        max_depth: None,
        sampler: None,
        lanes: None,
    };
    let smooth = include_str!("../scenes/glass-teapot.toml");
    let watertight = smooth.replace("[render]\n", "[render]\nwatertight = true\n");
    for text in [
        striae::render::scene::DEFAULT_SCENE,
        smooth,
        rough,
        &watertight,
    ] {
        let s = Scene::parse(text, Path::new("t.toml"), Path::new("."), &o).unwrap();
        let (a, _) = render_with(&s, &|_| {}, Simd::Auto);
        let (b, _) = render_with(&s, &|_| {}, Simd::Avx2);
        let (c, stats) = render_with(&s, &|_| {}, Simd::Portable);
        assert_eq!(stats.copy, LoopCopy::Portable);
        assert!(a.pixels.iter().any(|p| p.max_element() > 0.0));
        assert_eq!(a.pixels, b.pixels);
        assert_eq!(a.pixels, c.pixels);
    }
}

fn parse_err(text: &str) -> String {
    match Scene::parse(
        text,
        Path::new("scenes/broken.toml"),
        Path::new("."),
        &Overrides::default(),
    ) {
        Ok(_) => panic!("scene accepted:\n{text}"),
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.contains("scenes/broken.toml"),
                "message does not name the file: {msg}"
            );
            msg
        }
    }
}

const CAMERA: &str = "[camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 40\n";

#[test]
fn bad_scene_files_give_clear_errors() {
    // Unknown key, named with its line.
    let msg = parse_err(&format!("{CAMERA}[render]\nsspp = 4\n"));
    assert!(msg.contains("sspp") && msg.contains("line"), "{msg}");
    // Bad value type.
    let msg = parse_err(&format!("{CAMERA}[render]\nspp = \"many\"\n"));
    assert!(msg.contains("spp") && msg.contains("many"), "{msg}");
    // Out-of-range value.
    let msg = parse_err(&format!("{CAMERA}[render]\nspp = 0\n"));
    assert!(msg.contains("render.spp") && msg.contains('0'), "{msg}");
    // Unknown sampler.
    let msg = parse_err(&format!("{CAMERA}[render]\nsampler = \"halton\"\n"));
    assert!(
        msg.contains("render.sampler") && msg.contains("halton") && msg.contains("independent"),
        "{msg}"
    );
    // Unknown shape type.
    let msg = parse_err(&format!(
        "{CAMERA}[[shapes]]\ntype = \"torus\"\nemission = 1\n"
    ));
    assert!(msg.contains("torus") && msg.contains("type"), "{msg}");
    // Missing mesh file, with the key path.
    let msg = parse_err(&format!("{CAMERA}[materials.m]\ntype = \"dielectric\"\nior = 1.5\n[[shapes]]\ntype = \"mesh\"\npath = \"nowhere.obj\"\nmaterial = \"m\"\n"));
    assert!(
        msg.contains("shapes[0].path") && msg.contains("nowhere.obj"),
        "{msg}"
    );
    // Unknown material name.
    let msg = parse_err(&format!(
        "{CAMERA}[[shapes]]\ntype = \"sphere\"\nmaterial = \"glas\"\n"
    ));
    assert!(
        msg.contains("shapes[0].material") && msg.contains("glas"),
        "{msg}"
    );
    // Degenerate camera: the message names the key at fault, not the whole section.
    let msg = parse_err("[camera]\nposition = [0, 0, 0]\nlook_at = [0, 0, 0]\nfov = 40\n");
    assert!(msg.contains("`camera.look_at`"), "{msg}");
    let msg = parse_err("[camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 180\n");
    assert!(msg.contains("`camera.fov` = 180"), "{msg}");
    let msg = parse_err(
        "[camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nup = [0, 0, 1]\nfov = 40\n",
    );
    assert!(msg.contains("`camera.up`"), "{msg}");
    let msg = parse_err(&format!("{CAMERA}aperture_radius = -0.1\n"));
    assert!(msg.contains("`camera.aperture_radius` = -0.1"), "{msg}");
    // A material's key under its full name; a colour quoted as written.
    let msg = parse_err(&format!(
        "{CAMERA}[materials.g]\ntype = \"scratched\"\nbase = \"glass\"\n[materials.g.scratches]\nm = 0\n"
    ));
    assert!(msg.contains("`materials.g.scratches.m` = 0"), "{msg}");
    let msg = parse_err(&format!(
        "{CAMERA}[materials.g]\ntype = \"scratched\"\nbase = \"glass\"\n[materials.g.scratches]\nwalls = \"rough\"\n"
    ));
    assert!(
        msg.contains("[materials.g]") && msg.contains("`materials.g.scratches.walls`"),
        "{msg}"
    );
    let msg = parse_err(&format!(
        "{CAMERA}[materials.g]\ntype = \"scratched\"\nbase = \"glass\"\n[materials.g.scratches]\ntable = \"nowhere.npz\"\n"
    ));
    assert!(
        msg.contains("`materials.g.scratches.table`")
            && msg.contains("nowhere.npz")
            && msg.contains("os error"),
        "{msg}"
    );
    let msg = parse_err(&format!(
        "{CAMERA}[environment]\ntype = \"constant\"\nradiance = [-1, 0, 0]\n"
    ));
    assert!(
        msg.contains("`environment.radiance` = [-1.0, 0.0, 0.0]"),
        "{msg}"
    );
    // Negative emission.
    let msg = parse_err(&format!(
        "{CAMERA}[[shapes]]\ntype = \"rectangle\"\nemission = -1\n"
    ));
    assert!(
        msg.contains("shapes[0].emission") && msg.contains("-1"),
        "{msg}"
    );
    // Bad value inside a shape: the message names the key.
    let msg = parse_err(&format!(
        "{CAMERA}[[shapes]]\ntype = \"sphere\"\nradius = \"big\"\nemission = 1\n"
    ));
    assert!(msg.contains("radius") && msg.contains("big"), "{msg}");
    // An index of refraction below 1, named with its material.
    let msg = parse_err(&format!(
        "{CAMERA}[materials.glass]\ntype = \"dielectric\"\nior = 0.9\n"
    ));
    assert!(msg.contains("`materials.glass.ior` = 0.9"), "{msg}");
    // A key that does not belong to the shape's type.
    let msg = parse_err(&format!(
        "{CAMERA}[[shapes]]\ntype = \"rectangle\"\nradius = 2\nemission = 1\n"
    ));
    assert!(msg.contains("shapes[0].radius"), "{msg}");
    // Transforms that leave the finite floats: a non-finite translation, and regular
    // operations whose product overflows (a panic while transforming the mesh, before).
    let msg = parse_err(&format!(
        "{CAMERA}[[shapes]]\ntype = \"rectangle\"\nemission = 1\ntransform = [{{ translate = [0, nan, 0] }}]\n"
    ));
    assert!(
        msg.contains("transform = [{ translate") && msg.contains("not finite"),
        "{msg}"
    );
    let msg = parse_err(&format!(
        "{CAMERA}[[shapes]]\ntype = \"box\"\nemission = 1\ntransform = [{{ translate = [3e38, 0, 0] }}, {{ scale = 10 }}]\n"
    ));
    assert!(
        msg.contains("transform = [{ translate") && msg.contains("overflows"),
        "{msg}"
    );
    let msg = parse_err(&format!(
        "{CAMERA}[[shapes]]\ntype = \"box\"\nemission = 1\ntransform = {{ scale = 1e30 }}\n"
    ));
    assert!(msg.contains("single precision"), "{msg}");
    // Missing file.
    let err = Scene::load(Path::new("no/such/scene.toml"), &Overrides::default()).unwrap_err();
    assert!(
        matches!(err, SceneError::Read { .. }) && err.to_string().contains("no/such/scene.toml"),
        "{err}"
    );
}

/// The footprint a pixel of a `height`-pixel image with vertical fov `fov_deg` has on a plane
/// facing the camera at distance `dist`: its width in world units.
fn pixel_width(dist: f64, fov_deg: f64, height: f64) -> f64 {
    2.0 * dist * (fov_deg.to_radians() / 2.0).tan() / height
}

const FOOTPRINT_CAMERA: &str = "[render]\nwidth = 64\nheight = 64\n[camera]\nposition = [0, 0, 4]\nlook_at = [0, 0, 0]\nfov = 30\n";

fn assert_footprint(ctx: &striae::render::shading::ShadingContext, expected_du: f64, what: &str) {
    let (duvdx, duvdy) = ctx.footprint_uv();
    for (name, d) in [("duvdx", duvdx), ("duvdy", duvdy)] {
        let got = d.length() as f64;
        assert!(
            (got / expected_du - 1.0).abs() < 0.01,
            "{what}: |{name}| = {got}, expected {expected_du}"
        );
    }
    let cos = duvdx.dot(duvdy) / (duvdx.length() * duvdy.length());
    assert!(
        cos.abs() < 0.01,
        "{what}: square pixels stay square ({duvdx:?}, {duvdy:?})"
    );
}

#[test]
fn footprint_of_a_plane_seen_head_on() {
    // A rectangle scaled by 2 maps world x in [-2, 2] to u in [0, 1]: du = dx / 4.
    let s = scene(&format!("{FOOTPRINT_CAMERA}[materials.d]\ntype = \"diffuse\"\n[[shapes]]\ntype = \"rectangle\"\nmaterial = \"d\"\ntransform = {{ scale = 2 }}\n"));
    let ctx =
        striae::render::integrator::trace_contexts(&s, striae::math::Vec2::new(32.0, 32.0), 4);
    assert_eq!(ctx.len(), 1);
    assert_footprint(&ctx[0], pixel_width(4.0, 30.0, 64.0) / 4.0, "head-on plane");
    assert!(
        ctx[0].footprint_uv().1.y < 0.0,
        "v grows upward, image rows downward"
    );
}

#[test]
fn footprint_after_a_mirror_grows_with_the_unfolded_distance() {
    // Mirror at the origin turned 45 degrees sends the view to +x, onto a plane at x = 3:
    // the footprint there is that of a plane at distance 4 + 3 seen head-on.
    let s = scene(&format!(
        "{FOOTPRINT_CAMERA}[materials.d]\ntype = \"diffuse\"\n[materials.m]\ntype = \"conductor\"\npreset = \"none\"\n\
         [[shapes]]\ntype = \"rectangle\"\nmaterial = \"m\"\ntransform = [{{ scale = 3 }}, {{ rotate = {{ axis = [0, 1, 0], angle = 45 }} }}]\n\
         [[shapes]]\ntype = \"rectangle\"\nmaterial = \"d\"\ntransform = [{{ scale = 2 }}, {{ rotate = {{ axis = [0, 1, 0], angle = -90 }} }}, {{ translate = [3, 0, 0] }}]\n"
    ));
    let ctx =
        striae::render::integrator::trace_contexts(&s, striae::math::Vec2::new(32.0, 32.0), 4);
    assert_eq!(ctx.len(), 2, "mirror, then the plane");
    assert_footprint(
        &ctx[1],
        pixel_width(7.0, 30.0, 64.0) / 4.0,
        "plane seen in a mirror",
    );
}

#[test]
fn footprint_behind_a_glass_slab_uses_the_reduced_distance() {
    // A slab of thickness 1 and IOR 1.5 (faces at z = +-0.5) in front of a plane at z = -2:
    // paraxially the beam spreads as over 3.5 + 1 / 1.5 + 1.5 in air.
    let s = scene(&format!(
        "{FOOTPRINT_CAMERA}[materials.d]\ntype = \"diffuse\"\n[materials.g]\ntype = \"dielectric\"\nior = 1.5\n\
         [[shapes]]\ntype = \"box\"\nmaterial = \"g\"\ntransform = {{ scale = [3, 3, 0.5] }}\n\
         [[shapes]]\ntype = \"rectangle\"\nmaterial = \"d\"\ntransform = [{{ scale = 2 }}, {{ translate = [0, 0, -2] }}]\n"
    ));
    let ctx =
        striae::render::integrator::trace_contexts(&s, striae::math::Vec2::new(32.0, 32.0), 4);
    assert_eq!(ctx.len(), 3, "front face, back face, plane");
    assert_footprint(
        &ctx[2],
        pixel_width(3.5 + 1.0 / 1.5 + 1.5, 30.0, 64.0) / 4.0,
        "plane behind glass",
    );
}

#[test]
fn diffuse_plane_under_a_half_sky_map() {
    // An equirectangular EXR bright (2) over the upper hemisphere and black below (65 rows:
    // row 32 is the horizon). A Lambertian plane facing up sees only the bright half:
    // pixel = a * 2. Exercises the map's importance sampling under MIS with the BSDF.
    let dir = std::env::temp_dir().join(format!("striae-envtest-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (w, h) = (32u32, 65u32);
    let mut sky = Image::new(w, h);
    for y in 0..=32 {
        for x in 0..w {
            sky.pixels[(y * w + x) as usize] = striae::math::Rgb::new(2.0, 2.0, 2.0);
        }
    }
    sky.write_exr(&dir.join("sky.exr")).unwrap();
    let text = r#"
[render]
width = 16
height = 16
spp = 64
max_depth = 2
[camera]
position = [0, 3, 1]
look_at = [0, 0, 0]
fov = 20
[materials.plane]
type = "diffuse"
reflectance = 0.5
[[shapes]]
type = "rectangle"
material = "plane"
transform = [{ scale = 50 }, { rotate = { axis = [1, 0, 0], angle = -90 } }]
[environment]
type = "map"
path = "sky.exr"
transform = { rotate = { axis = [0, 1, 0], angle = 30 } }
"#;
    let s = Scene::parse(text, Path::new("env.toml"), &dir, &Overrides::default()).unwrap();
    let (img, _) = render_with_threads(&s, 2);
    let m = centre_mean(&img, 1.0, 0);
    assert!(
        m.agrees_with(1.0, 4.0, 2e-3),
        "{} +- {}",
        m.mean(),
        m.std_error()
    );
    // A non-rotation transform and a missing file are rejected with the key named.
    let bad = text.replace(
        "transform = { rotate = { axis = [0, 1, 0], angle = 30 } }",
        "transform = { scale = 2 }",
    );
    let err = Scene::parse(&bad, Path::new("env.toml"), &dir, &Overrides::default())
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("environment") && err.contains("rotation"),
        "{err}"
    );
    let err = Scene::parse(
        &text.replace("sky.exr", "nosky.exr"),
        Path::new("env.toml"),
        &dir,
        &Overrides::default(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("environment.path") && err.contains("nosky.exr"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn diffuse_plane_under_a_sun_is_albedo_times_irradiance_cosine_over_pi() {
    // A sun at 60 degrees from the zenith with irradiance E: pixel = a E cos(60) / pi.
    let s = scene(
        r#"
[render]
width = 8
height = 8
spp = 4
[camera]
position = [0, 3, 1]
look_at = [0, 0, 0]
fov = 20
[materials.plane]
type = "diffuse"
reflectance = 0.5
[[shapes]]
type = "rectangle"
material = "plane"
transform = [{ scale = 50 }, { rotate = { axis = [1, 0, 0], angle = -90 } }]
[[lights]]
type = "sun"
direction = [0.8660254, 0.5, 0]
irradiance = 4
"#,
    );
    let (img, _) = render_with_threads(&s, 1);
    let expected = 0.5 * 4.0 * 0.5 / std::f32::consts::PI;
    for p in &img.pixels {
        assert!(
            (p.x - expected).abs() < 1e-4 * expected,
            "{p} vs {expected}"
        );
    }
}

#[test]
fn shading_frame_always_faces_the_viewer_on_a_coarse_smooth_mesh() {
    // A teapot of 2 x 2 quads per patch: interpolated normals differ a lot from the facets, so
    // near silhouettes the viewer falls behind the interpolated normal, and an opaque BSDF
    // would return black there. The integrator's guard bends the shading normal so the
    // viewer is always in front of it (checked at every pixel centre of a 160 x 120 view).
    let s = scene(
        r#"
[render]
width = 160
height = 120
[camera]
position = [0, 2, 9]
look_at = [0, 1.3, 0]
fov = 30
[materials.d]
type = "diffuse"
reflectance = 0.8
[[shapes]]
type = "teapot"
subdivisions = 2
material = "d"
"#,
    );
    let eye = striae::math::Vec3::new(0.0, 2.0, 9.0);
    let mut hits = 0;
    for y in 0..120 {
        for x in 0..160 {
            let film = striae::math::Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
            let Some(ctx) = striae::render::integrator::trace_contexts(&s, film, 1).pop() else {
                continue;
            };
            let wo = (eye - ctx.p).normalize();
            hits += 1;
            assert!(
                ctx.frame.n.dot(wo) > 0.0,
                "viewer behind the shading normal at pixel ({x}, {y})"
            );
        }
    }
    assert!(hits > 3000, "{hits}");
}

#[test]
fn obj_mesh_path_is_relative_to_the_scene_file() {
    // An OBJ written next to the scene file and referenced by a relative path, with a
    // transform, renders like the built-in rectangle under the same transform.
    let dir = std::env::temp_dir().join(format!("striae-objtest-{}", std::process::id()));
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    striae::render::geometry::TriangleMesh::rectangle()
        .write_obj(dir.join("meshes/quad.obj"))
        .unwrap();
    let make = |shape: &str| {
        format!(
            "[render]\nwidth = 16\nheight = 16\nspp = 4\n[camera]\nposition = [0, 0, 4]\nlook_at = [0, 0, 0]\nfov = 40\n\
             [materials.d]\ntype = \"diffuse\"\nreflectance = 0.5\n[[shapes]]\n{shape}\nmaterial = \"d\"\n\
             transform = [{{ rotate = {{ axis = [0, 1, 0], angle = 20 }} }}]\n[environment]\ntype = \"constant\"\nradiance = 1\n"
        )
    };
    let from_obj = Scene::parse(
        &make("type = \"mesh\"\npath = \"meshes/quad.obj\""),
        &dir.join("s.toml"),
        &dir,
        &Overrides::default(),
    )
    .unwrap();
    let built_in = Scene::parse(
        &make("type = \"rectangle\""),
        &dir.join("s.toml"),
        &dir,
        &Overrides::default(),
    )
    .unwrap();
    let (a, _) = render_with_threads(&from_obj, 1);
    let (b, _) = render_with_threads(&built_in, 1);
    assert_eq!(a.pixels, b.pixels);
    assert!(
        a.pixels.iter().any(|p| (p.x - 0.5).abs() < 1e-3),
        "the quad is in view"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
