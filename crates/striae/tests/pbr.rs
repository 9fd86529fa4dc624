//! Scene tests of the glTF material and lights: point and spot lights against the analytic
//! irradiance of a diffuse plane, Beer-Lambert absorption in a glass slab against its
//! closed-form transmission, a neutral normal map leaving the image bit-identical, and errors
//! naming `materials.NAME.key` / `lights[i].key`.

use std::path::Path;
use striae::math::{Vec2, Vec3};
use striae::render::film::Image;
use striae::render::lights::spot_falloff;
use striae::render::scene::{Overrides, Scene};
use striae::testing::MeanEstimate;

mod common;
use common::{render_with_threads, scene};

/// A 50 x 50 diffuse plane (`y = 0`, albedo 0.5) seen from above, lit by `light` only.
fn lit_plane(light: &str) -> Scene {
    scene(&format!(
        r#"
[render]
width = 32
height = 32
spp = 16
max_depth = 2
[camera]
position = [0, 3, 0.5]
look_at = [0, 0, 0]
fov = 40
[materials.plane]
type = "diffuse"
reflectance = 0.5
[[shapes]]
type = "rectangle"
material = "plane"
transform = [{{ scale = 50 }}, {{ rotate = {{ axis = [1, 0, 0], angle = -90 }} }}]
[[lights]]
{light}
"#
    ))
}

/// Per pixel: the plane point the pixel centre sees, the points an 8 x 8 grid over the pixel
/// sees, and the rendered value (red channel).
fn plane_points(s: &Scene, img: &Image) -> Vec<(Vec3, Vec<Vec3>, f32)> {
    let see = |film: Vec2| {
        let ray = s.camera.generate_ray_only(film, Vec2::splat(0.5));
        s.geometry
            .intersect(&ray)
            .expect("the plane fills the view")
            .p
    };
    let mut out = Vec::new();
    for y in 0..img.height {
        for x in 0..img.width {
            let corner = Vec2::new(x as f32, y as f32);
            let grid = (0..64)
                .map(|k| see(corner + (Vec2::new((k % 8) as f32, (k / 8) as f32) + 0.5) / 8.0))
                .collect();
            out.push((see(corner + 0.5), grid, img.get(x, y).x));
        }
    }
    out
}

/// Irradiance of a point light of intensity `i` at `light` on the plane `y = 0` at `p`, times
/// the diffuse BRDF `0.5 / pi`: `rho / pi * I cos / d^2`.
fn point_expected(light: Vec3, i: f32, p: Vec3) -> f32 {
    let d = light - p;
    let cos = d.y / d.length();
    0.5 / std::f32::consts::PI * i * cos / d.length_squared()
}

#[test]
fn diffuse_plane_under_a_point_light_is_rho_over_pi_i_cos_over_d2() {
    let light = Vec3::new(0.3, 1.0, -0.2);
    let s = lit_plane("type = \"point\"\nposition = [0.3, 1.0, -0.2]\nintensity = [4, 2, 1]");
    let (img, _) = render_with_threads(&s, 2);
    let mut ratio = MeanEstimate::default();
    for (p, _, v) in plane_points(&s, &img) {
        let e = point_expected(light, 4.0, p);
        // Each pixel averages its area; its centre's value is within 1 % of that.
        assert!((v - e).abs() < 0.01 * e, "at {p}: {v} vs {e}");
        ratio.push((v / e) as f64);
    }
    assert!((ratio.mean() - 1.0).abs() < 1e-3, "{}", ratio.mean());
    // The colour is the intensity's: green and blue are 1/2 and 1/4 of red.
    let c = img.get(16, 16);
    assert!((c.y - 0.5 * c.x).abs() < 1e-5 * c.x && (c.z - 0.25 * c.x).abs() < 1e-5 * c.x);
}

#[test]
fn spot_light_falls_off_between_its_cones_and_is_dark_outside() {
    // Straight down from 1 above the origin; inner 20, outer 35 degrees: the lit disc has a
    // radius tan(35) = 0.7, the plane seen spans about +-1.1.
    let light = Vec3::new(0.0, 1.0, 0.0);
    let s = lit_plane(
        "type = \"spot\"\nposition = [0, 1, 0]\ndirection = [0, -2, 0]\nintensity = 3\ninner_angle = 20\nouter_angle = 35",
    );
    let (img, _) = render_with_threads(&s, 2);
    let (cos_inner, cos_outer) = (20f32.to_radians().cos(), 35f32.to_radians().cos());
    let (mut full, mut fading, mut dark) = (0, 0, 0);
    let spot = |p: Vec3| {
        let cos = (light - p).normalize().y;
        point_expected(light, 3.0, p) * spot_falloff(cos, cos_inner, cos_outer)
    };
    for (p, grid, v) in plane_points(&s, &img) {
        let cos = (light - p).normalize().y;
        // The pixel's mean over its area (the falloff bends within a pixel).
        let e = grid.iter().map(|&q| spot(q)).sum::<f32>() / grid.len() as f32;
        if cos < cos_outer - 0.03 {
            // Every sample of the pixel outside the outer cone.
            assert_eq!(v, 0.0, "at {p} (cos {cos})");
            dark += 1;
        } else if cos > cos_inner + 0.015 {
            assert!((v - e).abs() < 0.01 * e, "at {p}: {v} vs {e}");
            full += 1;
        } else if cos > cos_outer + 0.01 && cos < cos_inner - 0.01 {
            // Between the cones: 16 samples against the falloff's curve over the pixel.
            assert!((v - e).abs() < 0.03 * e + 1e-4, "at {p}: {v} vs {e}");
            fading += 1;
        }
    }
    assert!(
        full > 10 && fading > 50 && dark > 50,
        "{full} {fading} {dark}"
    );
    // The falloff itself: glTF's t^2 with t linear in the cosine.
    assert_eq!(spot_falloff(1.0, cos_inner, cos_outer), 1.0);
    assert_eq!(spot_falloff(cos_outer - 1e-3, cos_inner, cos_outer), 0.0);
    let mid = 0.5 * (cos_inner + cos_outer);
    assert!((spot_falloff(mid, cos_inner, cos_outer) - 0.25).abs() < 1e-5);
}

/// A smooth glass slab of thickness `d` (IOR 1.5, absorbing) seen head-on against a white
/// environment: the light that reaches the camera along the normal is the front face's
/// reflection `R` plus what crosses the slab after `k` round trips inside,
/// `(1 - R)^2 a (R a)^(2k)`, and what is reflected back after crossing it twice, so that in
/// all `R + (1 - R)^2 a / (1 - R a)`, `a = exp(-sigma_a d)` (`a = 1`: a lossless 1).
#[test]
fn absorbing_glass_slab_transmits_fresnel_times_beer_lambert() {
    let colour = [0.5f32, 0.25, 0.8];
    let s = scene(&format!(
        r#"
[render]
width = 8
height = 8
spp = 512
max_depth = 40
[camera]
position = [0, 0, 5]
look_at = [0, 0, 0]
fov = 1
[materials.glass]
type = "pbr"
metallic = 0
roughness = 0
transmission = 1
ior = 1.5
attenuation_color = {colour:?}
attenuation_distance = 0.1
[[shapes]]
type = "box"
material = "glass"
transform = [{{ scale = [3, 3, 0.05] }}]
[environment]
type = "constant"
radiance = 1
"#
    ));
    assert!(s.has_absorption());
    let (img, _) = render_with_threads(&s, 2);
    let r = ((1.5f64 - 1.0) / 2.5).powi(2);
    for (c, colour) in colour.iter().enumerate() {
        // Thickness 0.1 = attenuation_distance: a = attenuation_color.
        let a = *colour as f64;
        let expected = r + (1.0 - r).powi(2) * a / (1.0 - r * a);
        let mut m = MeanEstimate::default();
        for p in &img.pixels {
            m.push(p[c] as f64);
        }
        assert!(
            m.agrees_with(expected, 4.0, 1e-3),
            "channel {c}: {} +- {} vs {expected}",
            m.mean(),
            m.std_error()
        );
        // Far from the lossless slab's 1.
        assert!(expected < 0.9);
    }
}

/// The same scene without `attenuation_distance` renders bit-identically whether or not
/// the test for absorption would run: a scene without absorbing materials skips it.
#[test]
fn no_attenuation_distance_means_no_absorption() {
    let text = |extra: &str| {
        format!(
            r#"
[render]
width = 8
height = 8
spp = 16
[camera]
position = [0, 0, 5]
look_at = [0, 0, 0]
fov = 10
[materials.glass]
type = "pbr"
metallic = 0
roughness = 0.3
transmission = 1
{extra}
[[shapes]]
type = "sphere"
material = "glass"
[environment]
type = "constant"
radiance = 1
"#
        )
    };
    let plain = scene(&text(""));
    assert!(!plain.has_absorption());
    let white = scene(&text(
        "attenuation_color = [1, 1, 1]\nattenuation_distance = 1",
    ));
    assert!(white.has_absorption());
    let (a, _) = render_with_threads(&plain, 1);
    let (b, _) = render_with_threads(&white, 1);
    // exp(-0 t) = 1: the same image, bit for bit, through the absorption code.
    assert!(a.pixels.iter().zip(&b.pixels).all(|(x, y)| x == y));
}

/// A normal map of the constant flat normal (0.5, 0.5, 1) leaves every pixel bit-identical.
#[test]
fn neutral_normal_map_leaves_the_image_bit_identical() {
    let text = |extra: &str| {
        format!(
            r#"
[render]
width = 16
height = 16
spp = 8
[camera]
position = [0, 1, 4]
look_at = [0, 0, 0]
fov = 30
[materials.m]
type = "pbr"
base_color = [0.8, 0.3, 0.2]
metallic = 0.3
roughness = 0.4
{extra}
[[shapes]]
type = "sphere"
material = "m"
[[lights]]
type = "point"
position = [2, 3, 2]
intensity = 20
[environment]
type = "constant"
radiance = 0.2
"#
        )
    };
    let (a, _) = render_with_threads(&scene(&text("")), 1);
    let (b, _) = render_with_threads(&scene(&text("normal_map = [0.5, 0.5, 1.0]")), 1);
    assert!(a.pixels.iter().zip(&b.pixels).all(|(x, y)| x == y));
    // A tilted normal does change it.
    let (c, _) = render_with_threads(&scene(&text("normal_map = [0.8, 0.5, 0.9]")), 1);
    assert!(a.pixels.iter().zip(&c.pixels).any(|(x, y)| x != y));
}

fn parse_err(text: &str) -> String {
    match Scene::parse(
        text,
        Path::new("scenes/broken.toml"),
        Path::new("."),
        &Overrides::default(),
    ) {
        Ok(_) => panic!("scene accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

const CAMERA: &str = "[camera]\nposition = [0, 0, 3]\nlook_at = [0, 0, 0]\nfov = 40\n";

#[test]
fn bad_pbr_materials_and_lights_name_the_key() {
    let material_cases: &[(&str, &str)] = &[
        ("metallic = 1.5", "materials.m.metallic"),
        ("metallic = -0.1", "materials.m.metallic"),
        ("roughness = 2", "materials.m.roughness"),
        ("transmission = -1", "materials.m.transmission"),
        ("anisotropy = 1.1", "materials.m.anisotropy"),
        (
            "anisotropy_rotation = nan",
            "materials.m.anisotropy_rotation",
        ),
        ("ior = 0.9", "materials.m.ior"),
        ("normal_scale = inf", "materials.m.normal_scale"),
        ("base_color = [1.2, 0, 0]", "materials.m.base_color"),
        ("base_color = -1", "materials.m.base_color"),
        (
            "metallic_roughness = [0, 2, 0]",
            "materials.m.metallic_roughness",
        ),
        ("normal_map = [0.5, 0.5, 1.5]", "materials.m.normal_map"),
        (
            "attenuation_color = [0, 1, 1]",
            "materials.m.attenuation_color",
        ),
        (
            "attenuation_color = [1, 1]",
            "materials.m.attenuation_color",
        ),
        (
            "attenuation_distance = 0",
            "materials.m.attenuation_distance",
        ),
        (
            "attenuation_distance = -2",
            "materials.m.attenuation_distance",
        ),
        ("roughnes = 0.5", "roughnes"),
        (
            "base_color = { type = \"image\", path = \"missing.png\" }",
            "materials.m.base_color",
        ),
    ];
    for (line, key) in material_cases {
        let msg = parse_err(&format!(
            "{CAMERA}[materials.m]\ntype = \"pbr\"\n{line}\n[[shapes]]\ntype = \"sphere\"\nmaterial = \"m\"\n"
        ));
        assert!(msg.contains(key), "{line}: {msg}");
    }
    let light_cases: &[(&str, &str)] = &[
        ("type = \"point\"\nintensity = 1", "lights[0].position"),
        ("type = \"point\"\nposition = [0, 1, 0]", "lights[0].intensity"),
        ("type = \"point\"\nposition = [0, 1, 0]\nintensity = -1", "lights[0].intensity"),
        ("type = \"point\"\nposition = [0, 1, 0]\nintensity = [1, nan, 1]", "lights[0].intensity"),
        ("type = \"point\"\nposition = [0, 1]\nintensity = 1", "position"),
        ("type = \"point\"\nposition = [0, 1e30, 0]\nintensity = 1", "lights[0].position"),
        ("type = \"point\"\nposition = [0, 1, 0]\nintensity = 1\ndirection = [0, -1, 0]", "lights[0].direction"),
        ("type = \"point\"\nposition = [0, 1, 0]\nintensity = 1\nouter_angle = 20", "lights[0].outer_angle"),
        ("type = \"spot\"\nposition = [0, 1, 0]\nintensity = 1", "lights[0].direction"),
        ("type = \"spot\"\nposition = [0, 1, 0]\nintensity = 1\ndirection = [0, 0, 0]", "lights[0].direction"),
        ("type = \"spot\"\nposition = [0, 1, 0]\nintensity = 1\ndirection = [0, -1, 0]\ninner_angle = -1", "lights[0].inner_angle"),
        ("type = \"spot\"\nposition = [0, 1, 0]\nintensity = 1\ndirection = [0, -1, 0]\ninner_angle = 30\nouter_angle = 20", "lights[0].outer_angle"),
        ("type = \"spot\"\nposition = [0, 1, 0]\nintensity = 1\ndirection = [0, -1, 0]\nouter_angle = 91", "lights[0].outer_angle"),
        ("type = \"spot\"\nposition = [0, 1, 0]\nintensity = 1\ndirection = [0, -1, 0]\nirradiance = 1", "lights[0].irradiance"),
        ("type = \"sun\"\ndirection = [0, 1, 0]\nirradiance = 1\nposition = [0, 1, 0]", "lights[0].position"),
        ("type = \"sun\"\nirradiance = 1", "lights[0].direction"),
        ("type = \"lamp\"", "lamp"),
    ];
    for (body, key) in light_cases {
        let msg = parse_err(&format!("{CAMERA}[[lights]]\n{body}\n"));
        assert!(msg.contains(key), "{body}: {msg}");
    }
}

/// White furnace: a unit sphere in a white environment renders 1 wherever the material is
/// lossless: smooth white `pbr` glass (`metallic = 0, transmission = 1`) and smooth white
/// metal; rough white metal loses what single-scattering GGX loses (below 1, above 0.8).
#[test]
fn white_furnace_pbr_glass_and_metal_spheres() {
    let furnace = |material: &str| {
        scene(&format!(
            r#"
[render]
width = 16
height = 16
spp = 64
max_depth = 0
[camera]
position = [0, 0, 4]
look_at = [0, 0, 0]
fov = 20
[materials.m]
type = "pbr"
{material}
[[shapes]]
type = "sphere"
material = "m"
[environment]
type = "constant"
radiance = 1
"#
        ))
    };
    for (material, lossless) in [
        ("metallic = 0\nroughness = 0\ntransmission = 1", true),
        ("metallic = 1\nroughness = 0", true),
        ("metallic = 1\nroughness = 0.6", false),
    ] {
        let (img, _) = render_with_threads(&furnace(material), 2);
        let mut m = MeanEstimate::default();
        for p in &img.pixels {
            m.push(p.x as f64);
        }
        if lossless {
            assert!(
                m.agrees_with(1.0, 4.0, 1e-3),
                "{material}: {} +- {}",
                m.mean(),
                m.std_error()
            );
        } else {
            assert!(
                m.mean() < 0.99 && m.mean() > 0.8,
                "{material}: {}",
                m.mean()
            );
        }
    }
}
