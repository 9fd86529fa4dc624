//! The scratch hologram of `scenes/hologram.toml` rendered (METHOD.md 9.4): each arc glints
//! where `(l + v) . t = 0` (solved along the arc for the scene's near lamp and eye), and the
//! glints seen from two eyes triangulate to the depths of the points the arcs were drawn for.

mod common;

use glam::{DVec3, Vec2};
use std::path::Path;
use striae::lab::hologram::{hologram, read_points, HologramParams, Plate};
use striae::render::scene::{Overrides, Scene};

const SCENES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes");
const LAMP: DVec3 = DVec3::new(0.0, 0.0, 8.0);

/// `scenes/hologram.toml` seen from `eye`, smaller and with more samples.
fn scene(eye: DVec3) -> Scene {
    let text = std::fs::read_to_string(Path::new(SCENES).join("hologram.toml")).unwrap();
    let text = text
        .replace(
            "position = [0.0, 5.66, 5.66]",
            &format!("position = [{}, {}, {}]", eye.x, eye.y, eye.z),
        )
        .replace("width = 400", "width = 240")
        .replace("height = 300", "height = 180")
        .replace("spp = 64", "spp = 256");
    Scene::parse(
        &text,
        &Path::new(SCENES).join("hologram.toml"),
        Path::new(SCENES),
        &Overrides::default(),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// The glints of one arc for the lamp and `eye`: roots of `(l + v) . t` along it.
fn arc_glints(arc: &striae::lab::hologram::HologramArc, eye: DVec3) -> Vec<DVec3> {
    let p = |a: f64| {
        let q = arc.at(a);
        DVec3::new(q.x, q.y, 0.0)
    };
    let f = |a: f64| {
        let t = DVec3::new(-a.sin(), a.cos(), 0.0);
        ((LAMP - p(a)).normalize() + (eye - p(a)).normalize()).dot(t)
    };
    common::roots(f, arc.start, arc.end, 2000)
        .into_iter()
        .map(p)
        .collect()
}

/// Render from `eye`; per arc the luminance-weighted centroid of the lit pixels within 3 pixels
/// of its predicted glint, met with the plate through the camera (`None` where none is lit),
/// after checking that every lit pixel lies near some predicted glint.
fn rendered_glints(eye: DVec3, arcs: &[striae::lab::hologram::HologramArc]) -> Vec<Option<DVec3>> {
    let s = scene(eye);
    let img = common::assert_bit_identical_across_thread_counts(&s);
    let w = img.width as usize;
    let lum: Vec<f32> = img
        .pixels
        .iter()
        .map(|c| striae::math::luminance(*c))
        .collect();
    let max = lum.iter().copied().fold(0.0f32, f32::max);
    // The environment's own light on the plate is far below a glint.
    let lit: Vec<(Vec2, f32)> = (0..lum.len())
        .filter(|&i| lum[i] > 0.01 * max)
        .map(|i| {
            (
                Vec2::new((i % w) as f32 + 0.5, (i / w) as f32 + 0.5),
                lum[i],
            )
        })
        .collect();
    let project = |p: DVec3| s.camera.project((p - eye).as_vec3()).expect("in front");
    let predicted: Vec<Vec<Vec2>> = arcs
        .iter()
        .map(|a| arc_glints(a, eye).into_iter().map(project).collect())
        .collect();
    let near = |p: Vec2, q: Vec2, tol: f32| (p - q).abs().max_element() <= tol;
    let stray = lit
        .iter()
        .filter(|(p, _)| !predicted.iter().flatten().any(|q| near(*p, *q, 3.0)))
        .count();
    assert!(
        stray * 50 <= lit.len(),
        "{stray} of {} lit pixels far from every predicted glint",
        lit.len()
    );
    predicted
        .iter()
        .map(|qs| {
            let (mut sum, mut wsum) = (Vec2::ZERO, 0.0f32);
            for (p, l) in &lit {
                if qs.iter().any(|q| near(*p, *q, 3.0)) {
                    sum += *p * *l;
                    wsum += l;
                }
            }
            (wsum > 0.0).then(|| {
                let ray = s.camera.generate_ray_only(sum / wsum, Vec2::splat(0.5));
                let t = -ray.o.z / ray.d.z;
                (ray.o + ray.d * t).as_dvec3()
            })
        })
        .collect()
}

/// The point nearest both lines of sight `e1 -> a` and `e2 -> b`.
fn triangulate(e1: DVec3, a: DVec3, e2: DVec3, b: DVec3) -> DVec3 {
    let (d1, d2) = ((a - e1).normalize(), (b - e2).normalize());
    let w0 = e1 - e2;
    let (bb, d, e) = (d1.dot(d2), d1.dot(w0), d2.dot(w0));
    let den = 1.0 - bb * bb;
    let (s, t) = ((bb * e - d) / den, (e - bb * d) / den);
    0.5 * ((e1 + d1 * s) + (e2 + d2 * t))
}

#[test]
fn hologram_glints_triangulate_to_the_points_depths() {
    let points = read_points(&Path::new(SCENES).join("hologram-points.csv")).unwrap();
    let params = HologramParams {
        plate: Some(Plate {
            x0: -1.0,
            y0: -1.0,
            size_x: 2.0,
            size_y: 2.0,
        }),
        width: Some(0.006),
        ..HologramParams::default()
    };
    let holo = hologram(&points, &params).unwrap();
    // The shipped drawing is this one.
    let shipped = std::fs::read_to_string(Path::new(SCENES).join("hologram.svg")).unwrap();
    assert_eq!(shipped, holo.to_svg());
    // Two eyes 8 from the plate's centre at the design view angle (45 degrees), 15 degrees
    // either side of the design azimuth (+y).
    let eye = |az: f64| {
        let a = az.to_radians();
        8.0 * DVec3::new(
            a.cos() * std::f64::consts::FRAC_1_SQRT_2,
            a.sin() * std::f64::consts::FRAC_1_SQRT_2,
            std::f64::consts::FRAC_1_SQRT_2,
        )
    };
    let (e1, e2) = (eye(65.0), eye(115.0));
    let g1 = rendered_glints(e1, &holo.arcs);
    let g2 = rendered_glints(e2, &holo.arcs);
    // Per arc glinting in both views: the depth triangulated from the rendered glints, and
    // from the glints the exact condition predicts for this near lamp and these near eyes.
    let mut rows = Vec::new();
    for (i, arc) in holo.arcs.iter().enumerate() {
        let (Some(a), Some(b)) = (g1[i], g2[i]) else {
            continue;
        };
        let (pa, pb) = (arc_glints(arc, e1), arc_glints(arc, e2));
        let exact = triangulate(e1, pa[0], e2, pb[0]);
        rows.push((arc.z, triangulate(e1, a, e2, b), exact));
    }
    assert!(
        rows.len() * 3 >= holo.arcs.len() * 2,
        "{} of {} arcs glint in both views",
        rows.len(),
        holo.arcs.len()
    );
    // The renderer: rendered glints triangulate where the exact roots of the lamp's centre do,
    // within 0.06 (the lamp, 0.35 across at 8, spreads each glint along its arc by a few
    // pixels, not symmetrically).
    let render_error = rows
        .iter()
        .map(|(_, p, q)| (*p - *q).length())
        .fold(0.0, f64::max);
    // The construction (exact for a distant lamp and eye, `lab::hologram`'s tests): with the
    // lamp and the eyes 8 plate half-widths away, the points float within 30 % of their depth
    // (median within 10 %).
    let mut rel: Vec<f64> = rows.iter().map(|(z, p, _)| ((p.z - z) / z).abs()).collect();
    rel.sort_by(f64::total_cmp);
    let (median, worst) = (rel[rel.len() / 2], rel[rel.len() - 1]);
    eprintln!(
        "{} arcs: rendered vs exact-root triangulation within {render_error:.3}; depth within {:.0} % (median {:.0} %)",
        rows.len(),
        100.0 * worst,
        100.0 * median
    );
    assert!(render_error < 0.06, "rendered glints off by {render_error}");
    assert!(
        worst < 0.3 && median < 0.1,
        "depth off by {worst} (median {median})"
    );
}
