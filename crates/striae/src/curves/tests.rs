//! Tests of the curve set: coverage against closed forms and a brute-force count, the point
//! test, the SVG mapping, taper, dashes and wear, and bad input.

use super::stroke::StrokeStyle;
use super::*;

fn set(lines: &[Polyline]) -> CurveSet {
    CurveSet::new(lines, DVec2::ONE).expect("valid set")
}

/// The fraction of the footprint covered, counted on a fine grid of point tests (an
/// estimate independent of the clipping).
fn brute_coverage(s: &CurveSet, uv: DVec2, a: DVec2, b: DVec2, n: usize) -> f64 {
    let mut hit = 0;
    for i in 0..n {
        for j in 0..n {
            let x = (i as f64 + 0.5) / n as f64 - 0.5;
            let y = (j as f64 + 0.5) / n as f64 - 0.5;
            if !s.at_point(uv + a * x + b * y).is_empty() {
                hit += 1;
            }
        }
    }
    hit as f64 / (n * n) as f64
}

#[test]
fn a_straight_scratch_covers_its_rectangle() {
    let s = set(&[Polyline::uniform(
        vec![DVec2::new(0.2, 0.5), DVec2::new(0.8, 0.5)],
        0.01,
    )]);
    // A footprint 0.1 x 0.1 centred on the scratch: 0.02 / 0.1 of it.
    let h = s.footprint(
        DVec2::new(0.5, 0.5),
        DVec2::new(0.1, 0.0),
        DVec2::new(0.0, 0.1),
        0.3,
    );
    assert_eq!(h.len(), 1);
    assert!((h[0].coverage - 0.2).abs() < 1e-12, "{}", h[0].coverage);
    assert!((h[0].direction - DVec2::X).length() < 1e-12);
    // Off the scratch: nothing.
    assert!(s
        .footprint(
            DVec2::new(0.5, 0.7),
            DVec2::new(0.1, 0.0),
            DVec2::new(0.0, 0.1),
            0.3
        )
        .is_empty());
}

#[test]
fn circle_coverage_matches_the_annulus_and_a_brute_force_count() {
    // A circle of radius 0.3, width 0.02, flattened finely: the annulus' area over a
    // footprint holding the whole circle, and a brute-force count over a smaller footprint.
    let (r, hw) = (0.3, 0.01);
    let pts = stroke::arc_points(DVec2::splat(0.5), r, 0.0, std::f64::consts::TAU, 1e-6);
    let s = set(&[Polyline::uniform(pts, hw)]);
    let a = DVec2::new(1.0, 0.0);
    let b = DVec2::new(0.0, 1.0);
    let h = s.footprint_within(DVec2::splat(0.5), a, b, 0.5, usize::MAX);
    assert_eq!(h.len(), 1);
    let annulus = std::f64::consts::PI * ((r + hw).powi(2) - (r - hw).powi(2));
    assert!(
        (h[0].coverage - annulus).abs() < 1e-4 * annulus,
        "{} vs {annulus}",
        h[0].coverage
    );
    // A skewed footprint across the ring.
    let (uv, a, b) = (
        DVec2::new(0.8, 0.52),
        DVec2::new(0.03, 0.01),
        DVec2::new(-0.005, 0.04),
    );
    let exact = s.footprint(uv, a, b, 0.5)[0].coverage;
    let brute = brute_coverage(&s, uv, a, b, 400);
    assert!((exact - brute).abs() < 5e-3, "{exact} vs {brute}");
}

#[test]
fn overlapping_curves_are_reported_each_and_the_largest_first() {
    let s = set(&[
        Polyline::uniform(vec![DVec2::new(0.0, 0.5), DVec2::new(1.0, 0.5)], 0.01),
        Polyline::uniform(vec![DVec2::new(0.5, 0.0), DVec2::new(0.5, 1.0)], 0.02),
    ]);
    let h = s.footprint(
        DVec2::splat(0.5),
        DVec2::new(0.1, 0.0),
        DVec2::new(0.0, 0.1),
        0.0,
    );
    assert_eq!(h.len(), 2);
    assert_eq!(h[0].curve, 1);
    assert!((h[0].coverage - 0.4).abs() < 1e-12);
    assert!((h[1].coverage - 0.2).abs() < 1e-12);
    assert!((h[0].direction.y.abs() - 1.0).abs() < 1e-12);
    let p = s.at_point(DVec2::splat(0.5));
    assert_eq!(p.len(), 2);
}

#[test]
fn the_segment_direction_is_drawn_in_proportion_to_its_share() {
    // An L: 3/4 of the covered area horizontal, 1/4 vertical, inside one footprint.
    let s = set(&[Polyline::uniform(
        vec![
            DVec2::new(0.2, 0.5),
            DVec2::new(0.5, 0.5),
            DVec2::new(0.5, 0.6),
        ],
        0.001,
    )]);
    let n = 4000;
    let mut horizontal = 0;
    for k in 0..n {
        let u = (k as f64 + 0.5) / n as f64;
        let h = s.footprint(
            DVec2::new(0.4, 0.5),
            DVec2::new(0.6, 0.0),
            DVec2::new(0.0, 0.6),
            u,
        );
        if h[0].direction.x.abs() > 0.5 {
            horizontal += 1;
        }
    }
    let share = horizontal as f64 / n as f64;
    assert!((share - 0.75).abs() < 0.01, "{share}");
}

#[test]
fn a_tapered_scratch_covers_its_closed_form() {
    let (l, hw, taper) = (0.6, 0.01, 0.1);
    let style = StrokeStyle {
        taper,
        ..StrokeStyle::default()
    };
    let lines = style.apply(&[DVec2::new(0.2, 0.5), DVec2::new(0.2 + l, 0.5)], hw, 0);
    let s = set(&lines);
    let h = s.footprint_within(DVec2::splat(0.5), DVec2::X, DVec2::Y, 0.5, usize::MAX);
    let closed = 2.0 * hw * (l - 2.0 * taper + std::f64::consts::PI * taper / 2.0);
    // The tips are polygons through TAPER_STATIONS stations: within 0.5 % of the ellipse.
    assert!(
        (h[0].coverage - closed).abs() < 5e-3 * closed,
        "{} vs {closed}",
        h[0].coverage
    );
    // The tips are thin: at 1 % of the taper from the end, 14 % of the width.
    let tip = s.at_point(DVec2::new(0.2 + 0.001, 0.5 + 0.2 * hw));
    assert!(tip.is_empty());
}

#[test]
fn dashes_cut_a_scratch_into_pieces() {
    let style = StrokeStyle {
        dashes: vec![0.1, 0.05],
        ..StrokeStyle::default()
    };
    let lines = style.apply(&[DVec2::new(0.0, 0.5), DVec2::new(1.0, 0.5)], 0.005, 0);
    // 1 / 0.15 periods: 7 dashes (the last cut at the end).
    assert_eq!(lines.len(), 7);
    let s = set(&lines);
    assert!(!s.at_point(DVec2::new(0.05, 0.5)).is_empty());
    assert!(s.at_point(DVec2::new(0.125, 0.5)).is_empty());
    let h = s.footprint_within(DVec2::splat(0.5), DVec2::X, DVec2::Y, 0.5, usize::MAX);
    let on = 6.0 * 0.1 + 0.1;
    let total: f64 = h.iter().map(|h| h.coverage).sum();
    assert!((total - on * 0.01).abs() < 1e-9, "{total}");
}

#[test]
fn wear_stays_within_its_range_and_depends_on_the_seed_only() {
    let style = StrokeStyle {
        depth: 0.8,
        wear: 0.5,
        wear_length: 0.05,
        seed: 7,
        ..StrokeStyle::default()
    };
    let pts = [DVec2::new(0.0, 0.5), DVec2::new(1.0, 0.5)];
    let a = style.apply(&pts, 0.005, 3);
    let b = style.apply(&pts, 0.005, 3);
    assert_eq!(a, b);
    let d = &a[0].depths;
    assert!(d.len() > 70);
    assert!(d.iter().all(|&x| (0.4 - 1e-12..=0.8).contains(&x)));
    let (lo, hi) = d
        .iter()
        .fold((1.0f64, 0.0f64), |m, &x| (m.0.min(x), m.1.max(x)));
    assert!(hi - lo > 0.1, "the wear varies: {lo}..{hi}");
}

#[test]
fn a_drawing_maps_its_canvas_onto_uv() {
    let svg = br#"<svg xmlns="http://www.w3.org/2000/svg" width="200" height="100" viewBox="0 0 200 100">
        <g transform="translate(10 0)"><line id="a" x1="10" y1="25" x2="90" y2="25" stroke="black" stroke-width="4"/></g>
        <circle id="c" cx="150" cy="50" r="30" fill="none" stroke="black" stroke-width="2" stroke-opacity="0.5"/>
    </svg>"#;
    let d = svg::parse(svg, "test.svg", &StrokeStyle::default()).unwrap();
    assert_eq!(d.paths, 2);
    assert_eq!(
        d.segments,
        d.polylines
            .iter()
            .map(|l| l.points.len() - 1)
            .sum::<usize>()
    );
    assert_eq!(d.size, DVec2::new(200.0, 100.0));
    let s = CurveSet::new(&d.polylines, d.to_uv()).unwrap();
    // The line runs from x 20 to 100 at y 25: u 0.1..0.5, v 0.25, 4 units wide (0.04 in v).
    let on = s.at_point(DVec2::new(0.3, 0.25 + 0.015));
    assert_eq!(on.len(), 1);
    assert!((on[0].direction - DVec2::X).length() < 1e-9);
    assert!(s.at_point(DVec2::new(0.3, 0.25 + 0.025)).is_empty());
    assert!(s.at_point(DVec2::new(0.55, 0.25)).is_empty());
    // The circle: centre (0.75, 0.5), radius 0.15 in u and 0.3 in v; half as deep.
    let top = s.at_point(DVec2::new(0.75, 0.2));
    assert_eq!(top.len(), 1);
    assert!((top[0].depth - 0.5).abs() < 1e-6);
    // (Chords within 2 % of the width: the tangent within a few degrees, stretched by the
    // non-square canvas.)
    assert!(top[0].direction.x.abs() > 0.99);
    let right = s.at_point(DVec2::new(0.9, 0.5));
    assert_eq!(right.len(), 1);
    assert!(right[0].direction.y.abs() > 0.99);
}

#[test]
fn bad_drawings_are_errors_naming_the_element() {
    let style = StrokeStyle::default();
    let err = |svg: &str| {
        svg::parse(svg.as_bytes(), "bad.svg", &style)
            .unwrap_err()
            .to_string()
    };
    let e = err("not svg at all");
    assert!(
        e.contains("bad.svg") && e.contains("not a valid SVG"),
        "{e}"
    );
    let e = err(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><path id="p1" d="M0 0 L5 5" stroke="black" stroke-width="0"/></svg>"#,
    );
    assert!(e.contains("id=\"p1\"") && e.contains("stroke-width"), "{e}");
    let e = err(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><path d="M0 0 L5 5" style="stroke:black; stroke-width:-2"/></svg>"#,
    );
    assert!(e.contains("line 1") && e.contains("-2"), "{e}");
    let e = err(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><rect id="r" x="1" y="1" width="5" height="5" fill="red"/></svg>"#,
    );
    assert!(e.contains("id=\"r\"") && e.contains("no stroke"), "{e}");
    let e = err(r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"></svg>"#);
    assert!(e.contains("no stroked path"), "{e}");
}

#[test]
fn bad_curves_and_styles_name_the_key() {
    let e = Polyline::uniform(vec![DVec2::ZERO], 0.1)
        .validate("3")
        .unwrap_err();
    assert!(e.to_string().contains("curve 3"), "{e}");
    let mut p = Polyline::uniform(vec![DVec2::ZERO, DVec2::ONE], 0.1);
    p.half_widths[1] = -1.0;
    assert!(CurveSet::new(&[p], DVec2::ONE).is_err());
    let bad = StrokeStyle {
        wear: 0.5,
        ..StrokeStyle::default()
    };
    assert!(bad
        .validate()
        .unwrap_err()
        .to_string()
        .contains("wear_length"));
    let bad = StrokeStyle {
        depth: 0.0,
        ..StrokeStyle::default()
    };
    assert!(bad.validate().unwrap_err().to_string().contains("depth"));
}

#[test]
fn patterns_are_seeded_and_circles_are_concentric() {
    let swirl = patterns::Pattern::Swirl {
        count: 50,
        radius: [0.05, 0.2],
        arc: [20.0, 90.0],
        width: 0.002,
        seed: 4,
    };
    let a = swirl.polylines(&StrokeStyle::default()).unwrap();
    assert_eq!(a, swirl.polylines(&StrokeStyle::default()).unwrap());
    assert_eq!(a.len(), 50);
    let circles = patterns::Pattern::Circles {
        centre: [0.5, 0.5],
        radius: [0.1, 0.4],
        count: 4,
        width: 0.002,
        jitter: 0.0,
        seed: 0,
    };
    let c = circles.polylines(&StrokeStyle::default()).unwrap();
    for (i, line) in c.iter().enumerate() {
        let r = 0.1 + 0.1 * i as f64;
        for p in &line.points {
            assert!(((*p - DVec2::splat(0.5)).length() - r).abs() < 1e-12);
        }
    }
    // The tangent at the circle's top is along u.
    let s = set(&c);
    let h = s.at_point(DVec2::new(0.5, 0.8));
    assert_eq!(h.len(), 1);
    assert!(h[0].direction.x.abs() > 0.999);
}

#[test]
fn too_many_segments_are_refused_up_front() {
    let pts: Vec<DVec2> = (0..MAX_SEGMENTS + 2)
        .map(|i| DVec2::new(i as f64, 0.0))
        .collect();
    let e = CurveSet::new(&[Polyline::uniform(pts, 0.1)], DVec2::ONE).unwrap_err();
    assert!(
        e.to_string().contains(&format!("{}", MAX_SEGMENTS + 1)),
        "{e}"
    );
}

#[test]
fn long_crossing_strokes_keep_the_grid_small_and_the_answers_exact() {
    // 2000 strokes across the whole square: a fine grid would list each in every cell of its
    // bounds (millions of entries); the coarsened one stays within 16 entries a segment.
    let lines: Vec<Polyline> = (0..2000)
        .map(|i| {
            let t = i as f64 / 2000.0;
            Polyline::uniform(vec![DVec2::new(0.0, t), DVec2::new(1.0, 1.0 - t)], 1e-5)
        })
        .collect();
    let s = set(&lines);
    assert!(s.bytes() < 2000 * 200, "{} bytes", s.bytes());
    let uv = DVec2::new(0.5, 0.5);
    let hits = s.at_point(uv);
    // Every stroke passes through the centre.
    assert_eq!(hits.len(), MAX_CURVE_HITS);
}

#[test]
fn tight_turns_are_found_by_radius_over_width() {
    // A circle of radius 0.1 flattened finely: R / w = 0.1 / w.
    let ring = |w: f64| {
        Polyline::uniform(
            stroke::arc_points(DVec2::splat(0.5), 0.1, 0.0, 3.0, 1e-5),
            0.5 * w,
        )
    };
    assert!((ring(0.01).min_radius_over_width() - 10.0).abs() < 0.01);
    let (tight, min) = CurveSet::tight_turns(&[ring(0.01), ring(0.1), ring(0.05)]);
    assert_eq!(tight, vec![1]);
    assert!((min - 1.0).abs() < 1e-3, "{min}");
    // A straight line never turns.
    let line = Polyline::uniform(vec![DVec2::ZERO, DVec2::X, DVec2::new(2.0, 0.0)], 0.1);
    assert_eq!(line.min_radius_over_width(), f64::INFINITY);
}

#[test]
fn patterns_and_drawings_past_the_segment_limit_are_refused_up_front() {
    // 10^6 circles of radius 0.4 and width 1e-4: about 10^9 segments, refused before drawing.
    let p = patterns::Pattern::Circles {
        centre: [0.5, 0.5],
        radius: [0.1, 0.4],
        count: 1_000_000,
        width: 1e-4,
        jitter: 0.0,
        seed: 0,
    };
    let e = p
        .polylines(&StrokeStyle::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("segments"), "{e}");
    // An SVG of fine circles: refused at the path that passes the limit.
    let mut svg =
        String::from(r#"<svg xmlns="http://www.w3.org/2000/svg" width="1000" height="1000">"#);
    for i in 0..400 {
        svg.push_str(&format!(
            r#"<circle id="c{i}" cx="500" cy="500" r="400" fill="none" stroke="black" stroke-width="0.0001"/>"#
        ));
    }
    svg.push_str("</svg>");
    let e = svg::parse(svg.as_bytes(), "fine.svg", &StrokeStyle::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("fine.svg") && e.contains("segments") && e.contains("id=\"c"),
        "{e}"
    );
}
