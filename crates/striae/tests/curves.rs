//! Scratches as curves, rendered (METHOD.md 9.1, 9.3): the floating stripe of concentric
//! circles on mirror-walled metal glints exactly where `(l + v) . t = 0`, solved along each
//! circle with the camera's own projection, from two camera positions (the parallax).

mod common;

use striae::math::Vec3;

/// Circles of the test plate: centre (0.5, 0.5) in uv, radii 0.1..0.45 (8 circles).
const RADII: [f64; 8] = [0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45];
/// The lamp: above and behind the eyes, so that its mirror image falls off the plate and the
/// lamp itself out of view: only the scratches' glints are lit.
const LAMP: [f32; 3] = [0.0, -3.5, 4.0];
const LAMP_RADIUS: f32 = 0.25;

fn stripe_scene(eye: [f32; 3]) -> String {
    format!(
        r#"
[render]
width = 160
height = 120
spp = 256
max_depth = 4
seed = 1

[camera]
position = [{}, {}, {}]
look_at = [0.0, 0.2, 0.0]
up = [0.0, 0.0, 1.0]
fov = 45.0

[materials.steel]
type = "scratched"
base = "metal"
preset = "steel"

[materials.steel.scratches]
profile = "round:depth=0.3"
m = 64
n = 2000
pattern = {{ kind = "circles", centre = [0.5, 0.5], radius = [0.1, 0.45], count = 8, width = 0.004 }}

[[shapes]]
type = "rectangle"
material = "steel"

[[shapes]]
type = "sphere"
center = [{}, {}, {}]
radius = {LAMP_RADIUS}
emission = [3000.0, 3000.0, 3000.0]

[environment]
type = "constant"
radiance = [0.0, 0.0, 0.0]
"#,
        eye[0], eye[1], eye[2], LAMP[0], LAMP[1], LAMP[2]
    )
}

/// Where circle `r` glints for a lamp at `lamp` and the eye at `eye`: the roots of
/// `(l + v) . t` along it (METHOD.md 9.3), as world points on the plate (the rectangle maps
/// uv to `x = 2u - 1`, `y = 2v - 1`).
fn glints(r: f64, lamp: Vec3, eye: Vec3) -> Vec<Vec3> {
    let point = |a: f64| {
        let (u, v) = (0.5 + r * a.cos(), 0.5 + r * a.sin());
        Vec3::new((2.0 * u - 1.0) as f32, (2.0 * v - 1.0) as f32, 0.0)
    };
    let f = |a: f64| {
        let p = point(a);
        let t = Vec3::new(-a.sin() as f32, a.cos() as f32, 0.0);
        ((lamp - p).normalize() + (eye - p).normalize()).dot(t) as f64
    };
    common::roots(f, 0.0, std::f64::consts::TAU, 3600)
        .into_iter()
        .map(point)
        .collect()
}

/// Render the stripe from `eye` and compare its lit pixels with the predicted glints: every
/// lit pixel within 2 pixels of a glint predicted for some point of the lamp, and 80 % of the
/// glints predicted for the lamp's centre lit within 2 pixels (27 of 32 over the two views: the
/// mirror walls' delta lobe is found by BSDF sampling alone, so a glint is a few hits). Returns
/// the lit pixels' count.
fn check_stripe(eye: [f32; 3]) -> usize {
    let scene = common::scene(&stripe_scene(eye));
    // (Curves keep the render deterministic whatever the thread count.)
    let img = common::assert_bit_identical_across_thread_counts(&scene);
    let (w, h) = (img.width as usize, img.height as usize);
    let eye_v = Vec3::from(eye);
    let lamp = Vec3::from(LAMP);
    let pixel_of = |p: Vec3| scene.camera.project(p - eye_v);
    // The glints of the lamp's centre, and of points on its rim facing the plate.
    let mut lamp_points = vec![lamp];
    for k in 0..8 {
        let a = std::f32::consts::TAU * k as f32 / 8.0;
        lamp_points.push(lamp + LAMP_RADIUS * Vec3::new(a.cos(), 0.0, a.sin()));
        lamp_points.push(lamp + LAMP_RADIUS * Vec3::new(a.cos(), a.sin(), 0.0));
    }
    let mut predicted = Vec::new();
    let mut centre_glints = Vec::new();
    for (i, l) in lamp_points.iter().enumerate() {
        for &r in &RADII {
            for g in glints(r, *l, eye_v) {
                if let Some(px) = pixel_of(g) {
                    predicted.push(px);
                    if i == 0 {
                        centre_glints.push(px);
                    }
                }
            }
        }
    }
    assert!(
        centre_glints.len() >= 8,
        "{} glints predicted",
        centre_glints.len()
    );
    let lum: Vec<f32> = img
        .pixels
        .iter()
        .map(|c| striae::math::luminance(*c))
        .collect();
    let max = lum.iter().copied().fold(0.0f32, f32::max);
    assert!(max > 0.0, "nothing is lit");
    let lit: Vec<(f32, f32)> = (0..w * h)
        .filter(|&i| lum[i] > 1e-4 * max)
        .map(|i| ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5))
        .collect();
    let near = |p: (f32, f32), q: striae::math::Vec2, tol: f32| {
        (p.0 - q.x).abs() <= tol && (p.1 - q.y).abs() <= tol
    };
    let stray: Vec<_> = lit
        .iter()
        .filter(|p| !predicted.iter().any(|q| near(**p, *q, 2.0)))
        .collect();
    assert!(
        stray.is_empty(),
        "{} of {} lit pixels away from every predicted glint, e.g. {:?}",
        stray.len(),
        lit.len(),
        &stray[..stray.len().min(5)]
    );
    let inside =
        |q: &striae::math::Vec2| q.x >= 0.0 && q.y >= 0.0 && q.x < w as f32 && q.y < h as f32;
    let visible: Vec<_> = centre_glints.iter().filter(|q| inside(q)).collect();
    let found = visible
        .iter()
        .filter(|q| lit.iter().any(|p| near(*p, ***q, 2.0)))
        .count();
    eprintln!(
        "{} lit, {found} of {} predicted glints lit",
        lit.len(),
        visible.len()
    );
    assert!(
        found as f64 >= 0.8 * visible.len() as f64,
        "{found} of {} predicted glints lit",
        visible.len()
    );
    lit.len()
}

#[test]
fn concentric_circles_glint_where_l_plus_v_is_normal_to_the_tangent() {
    let a = check_stripe([0.0, -2.2, 2.6]);
    // A second eye, to the side: the stripe turns with h_p (the parallax).
    let b = check_stripe([1.3, -1.9, 2.6]);
    assert!(a > 10 && b > 10, "lit pixels: {a}, {b}");
}

/// The pixel footprint shared by a pixel's samples (`CoverageCache::curves_of_pixel`) renders what each
/// sample's own footprint renders (`coverage = "sample"`), within noise, image mean and
/// blocks of pixels alike.
#[test]
fn the_curves_pixel_cache_renders_what_each_samples_footprint_renders() {
    let text = |coverage: &str| {
        format!(
            r#"
[render]
width = 96
height = 72
spp = 32
max_depth = 3
seed = 2
[camera]
position = [0.0, -2.4, 2.4]
look_at = [0.0, 0.0, 0.0]
up = [0.0, 0.0, 1.0]
fov = 40.0
[materials.al]
type = "scratched"
base = "metal"
preset = "aluminium"
[materials.al.scratches]
profile = "v:angle=90"
walls = "diffuse"
m = 32
n = 2000
coverage = "{coverage}"
pattern = {{ kind = "swirl", count = 600, radius = [0.1, 0.4], arc = [20.0, 90.0], width = 0.004, seed = 5 }}
[[shapes]]
type = "rectangle"
material = "al"
[environment]
type = "constant"
radiance = 1.0
"#
        )
    };
    let (a, _) = common::render_with_threads(&common::scene(&text("footprint")), 2);
    let (b, _) = common::render_with_threads(&common::scene(&text("sample")), 2);
    let mean = |img: &striae::render::film::Image| {
        img.pixels
            .iter()
            .map(|p| striae::math::luminance(*p) as f64)
            .sum::<f64>()
            / img.pixels.len() as f64
    };
    let (ma, mb) = (mean(&a), mean(&b));
    // The scratches darken the plate where they lie (diffuse walls): the mean differs from
    // the plain base's, and agrees between the two coverage modes within 0.5 %.
    assert!((ma - mb).abs() < 5e-3 * mb, "{ma} vs {mb}");
    // 12 x 12-pixel blocks agree within 3 %.
    let block = |img: &striae::render::film::Image, bx: usize, by: usize| {
        let w = img.width as usize;
        (0..12)
            .flat_map(|y| (0..12).map(move |x| (x, y)))
            .map(|(x, y)| {
                striae::math::luminance(img.pixels[(by * 12 + y) * w + bx * 12 + x]) as f64
            })
            .sum::<f64>()
    };
    for by in 0..6 {
        for bx in 0..8 {
            let (x, y) = (block(&a, bx, by), block(&b, bx, by));
            assert!(
                (x - y).abs() <= 0.03 * y.max(1.0),
                "block ({bx}, {by}): {x} vs {y}"
            );
        }
    }
}

/// The floating stripe in transmission (METHOD.md 9.3): concentric circles on a glass surface
/// with smooth glass walls (`walls = "dielectric"`), a small lamp behind it, seen through it.
/// A smooth-walled groove conserves `beta = n w . t` (8.1): light going from the lamp through
/// the glass (index 1.5) at `d` leaves toward the eye at `v` where `1.5 d . t = v . t`. The
/// surface is one rectangle, the boundary of the glass behind it, so the lamp lies in the
/// glass and its light runs straight to the surface.
#[test]
fn backlit_circles_glint_on_the_refracted_cone() {
    let eye = Vec3::new(0.0, -2.0, 2.6);
    let lamp = Vec3::new(0.0, 1.2, -2.0);
    let lamp_radius = 0.2f32;
    let text = format!(
        r#"
[render]
width = 160
height = 120
spp = 256
max_depth = 4
seed = 3
[camera]
position = [{}, {}, {}]
look_at = [0.0, 0.2, 0.0]
up = [0.0, 0.0, 1.0]
fov = 45.0
[materials.pane]
type = "scratched"
base = "glass"
ior = 1.5
[materials.pane.scratches]
profile = "round:depth=0.3"
walls = "dielectric"
pattern = {{ kind = "circles", centre = [0.5, 0.5], radius = [0.1, 0.45], count = 8, width = 0.004 }}
[[shapes]]
type = "rectangle"
material = "pane"
[[shapes]]
type = "sphere"
center = [{}, {}, {}]
radius = {lamp_radius}
emission = [3000.0, 3000.0, 3000.0]
[environment]
type = "constant"
radiance = [0.0, 0.0, 0.0]
"#,
        eye.x, eye.y, eye.z, lamp.x, lamp.y, lamp.z
    );
    let scene = common::scene(&text);
    let (img, _) = common::render_with_threads(&scene, 2);
    let (w, h) = (img.width as usize, img.height as usize);
    // Where each circle can glint: the point P whose groove sends some light of the lamp to
    // the eye, i.e. `v . t / 1.5` lies in the range of `d . t` over the directions `d` from the
    // lamp's sphere to P (a cone of half-angle asin(R / |P - L|) about P - L); and where the
    // lamp's centre alone glints (the sign changes of `1.5 d . t - v . t`).
    let mut predicted = Vec::new();
    let mut centre = Vec::new();
    for &r in &RADII {
        let n = 7200;
        let mut last = None;
        for k in 0..=n {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            let (u, v) = (0.5 + r * a.cos(), 0.5 + r * a.sin());
            let p = Vec3::new((2.0 * u - 1.0) as f32, (2.0 * v - 1.0) as f32, 0.0);
            let t = Vec3::new(-a.sin() as f32, a.cos() as f32, 0.0);
            let axis = (p - lamp).normalize();
            let vt = (eye - p).normalize().dot(t) / 1.5;
            let theta = axis.dot(t).clamp(-1.0, 1.0).acos();
            let rho = (lamp_radius / (p - lamp).length()).asin();
            let (lo, hi) = (
                (theta + rho).min(std::f32::consts::PI).cos(),
                (theta - rho).max(0.0).cos(),
            );
            let Some(px) = scene.camera.project(p - eye) else {
                continue;
            };
            if (lo..=hi).contains(&vt) {
                predicted.push(px);
            }
            let f = axis.dot(t) - vt;
            if let Some(prev) = last {
                if f32::signum(prev) != f32::signum(f) {
                    centre.push(px);
                }
            }
            last = Some(f);
        }
    }
    // The lamp seen through the flat glass (the camera ray refracted into the glass meets
    // its sphere, grown by 2 pixels' worth): not a glint, left out.
    let lamp_image = |x: usize, y: usize| {
        let ray = scene.camera.generate_ray_only(
            striae::math::Vec2::new(x as f32 + 0.5, y as f32 + 0.5),
            striae::math::Vec2::splat(0.5),
        );
        let t = -ray.o.z / ray.d.z;
        let p = ray.o + ray.d * t;
        let (cos_i, eta) = (-ray.d.z, 1.0 / 1.5f32);
        let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
        let d = ray.d * eta + Vec3::Z * (eta * cos_i - k.sqrt());
        let oc = p - lamp;
        let b = oc.dot(d);
        let grown = lamp_radius * 1.2;
        b * b - (oc.length_squared() - grown * grown) >= 0.0
    };
    let lum: Vec<f32> = img
        .pixels
        .iter()
        .map(|c| striae::math::luminance(*c))
        .collect();
    let max = lum.iter().copied().fold(0.0f32, f32::max);
    assert!(max > 0.0, "nothing is lit");
    let lit: Vec<(f32, f32)> = (0..w * h)
        .filter(|&i| lum[i] > 1e-4 * max && !lamp_image(i % w, i / w))
        .map(|i| ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5))
        .collect();
    let near = |p: (f32, f32), q: striae::math::Vec2, tol: f32| {
        (p.0 - q.x).abs() <= tol && (p.1 - q.y).abs() <= tol
    };
    let stray = lit
        .iter()
        .filter(|p| !predicted.iter().any(|q| near(**p, *q, 2.0)))
        .count();
    eprintln!(
        "{} lit, {stray} stray, {} lamp-centre glints",
        lit.len(),
        centre.len()
    );
    assert!(
        stray * 50 <= lit.len(),
        "{stray} of {} lit pixels away from every glint",
        lit.len()
    );
    let inside = |q: &&striae::math::Vec2| {
        q.x >= 0.0
            && q.y >= 0.0
            && q.x < w as f32
            && q.y < h as f32
            && !lamp_image(q.x as usize, q.y as usize)
    };
    let visible: Vec<_> = centre.iter().filter(inside).collect();
    let found = visible
        .iter()
        .filter(|q| lit.iter().any(|p| near(*p, ***q, 2.0)))
        .count();
    assert!(
        found * 10 >= visible.len() * 8 && visible.len() >= 8,
        "{found} of {} predicted glints lit",
        visible.len()
    );
}
