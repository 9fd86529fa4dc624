//! Scratch holograms (METHOD.md 9.3-9.4): the arcs that, scratched into a smooth plate and lit
//! by one distant light, show a set of 3D points floating in front of and behind the plate.
//!
//! # The plate and its frame
//!
//! The points are given in the hologram's frame: the plate is the plane `z = 0`, `x` and `y`
//! are coordinates on it and `z` is a point's signed distance from it, `z > 0` in front (on the
//! side of the plate's normal, toward the viewer), `z < 0` behind. The plate point `(x, y)` is
//! the SVG point `(x, y)`, with no flip, so that the drawing's user units are the points'
//! units. The drawing's rectangle `[x0, x0 + size_x] x [y0, y0 + size_y]` ([`Plate`]) is its
//! `viewBox`, and it lies on a surface's texture space as an image texture of the same drawing
//! does (`render::texture`: the image's top row at `v = 0`):
//!
//! ```text
//! u = (x - x0) / size_x,    v = (y - y0) / size_y
//! ```
//!
//! so `x` runs along `dP/du`, `y` along `dP/dv` and `z` along the shading normal. SVG's `y`
//! runs down the page, and so does `v` down an image. The arcs are right when the surface maps
//! the drawing without stretching (`|dP/du| / size_x = |dP/dv| / size_y`, `dP/du` orthogonal to
//! `dP/dv`); a depth `z` is then `z |dP/du| / size_x` in the scene's units. The construction
//! commutes with mirror images of the plate, so the frame `(dP/du, dP/dv, n)` need not be
//! right-handed (an OBJ mesh's flipped `v` makes it left-handed).
//!
//! # The physics (METHOD.md 9.3)
//!
//! A groove with smooth walls along the unit tangent `t` keeps the component of a direction
//! along `t` (8.1), so light from direction `l` leaves only into directions `v` with
//! `(l + v) . t = 0` (`l` and `v` unit, pointing away from the plate). On a circle of radius
//! `r` around `c`, the point at angle `phi`, `c + r (cos phi, sin phi)`, has the tangent
//! `(-sin phi, cos phi)`; with `h = l + v` and `h_p` its projection on the plate, the
//! condition `h_p . t = 0` holds where `(cos phi, sin phi)` is parallel to `h_p`: a distant
//! light seen by a distant eye makes the circle glint at the two points `c +- r h_p / |h_p|`.
//!
//! # The hologram (METHOD.md 9.4)
//!
//! Take the light at the plate's normal (`l = n`, so `h_p = v_p`) and the eye in the unit
//! direction `v` at the angle `theta` from the normal and the azimuth `alpha` on the plate,
//! `v = (sin theta cos alpha, sin theta sin alpha, cos theta)`; `a = (cos alpha, sin alpha)` is
//! the direction on the plate toward the viewer. The eye sees a point `(c, z)` where the ray
//! toward it along `-v` meets the plate: `c - z tan(theta) a`. The circle's glints are at
//! `c + r a` and `c - r a`. So, with `r = tan(theta) |z|`:
//!
//! * a point behind the plate (`z < 0`) is seen at `c + r a`, the glint of the half of the
//!   circle toward the viewer: it moves with the viewer under parallax;
//! * a point in front (`z > 0`) is seen at `c - r a`, the glint of the half away from the
//!   viewer: it moves against the viewer.
//!
//! The two halves are concave opposite ways: with the viewer at the bottom of the drawing, an
//! arc behind is a smile (its centre above it), an arc in front a frown. The radius is
//! `r = k |z|` with the *scale* `k`, by default `tan(view_angle)` for the design view angle
//! from the normal ([`HologramParams::scale`]). Each arc covers the directions `a` takes while
//! the eye's azimuth sweeps `span` degrees centred on the design azimuth: from `alpha0 - span/2`
//! to `alpha0 + span/2` around `c` for a point behind, the same plus 180 degrees for a point in
//! front. As the eye circles the plate at the design elevation, every glint is exactly where
//! its point projects, so rays from two views' glints along the two eye directions meet at the
//! point: exact parallax ([`glint`], the tests).
//!
//! Away from the design:
//!
//! * an eye at another angle `theta` from the normal (light still at the normal) sees every
//!   point at the same `c` but at the depth `z k / tan(theta)`: rays from its glints along `v`
//!   meet at `(c, z k / tan(theta))` for every azimuth, so the shape stays a rigid set of points,
//!   flattened when seen more obliquely and deepened when seen more steeply (at the normal
//!   itself `h_p = 0` and the whole circle glints);
//! * a distant light off the normal turns `h_p = l_p + v_p` away from `v_p`: the glints no
//!   longer follow one point, and the shape distorts, little while `|l_p|` is small against
//!   `sin(theta)`;
//! * a near light or eye makes `h` change along the arc: the glint is the root of
//!   `(l(s) + v(s)) . t(s) = 0` (METHOD.md 9.3), not computed here;
//! * with `span` over 180 degrees an arc also holds, for some views, its circle's other glint,
//!   which shows the point mirrored through the plate (`-z`); a full circle (360) shows both
//!   for every view.
//!
//! Whether a glint is bright depends on the groove's profile (how much of the light its walls
//! send into the eye's direction on the cone), not on where it is: this module places the
//! arcs, the renderer's scratch BRDF lights them.

use glam::{DVec2, DVec3};
use std::f64::consts::{PI, TAU};
use std::fmt::Write as _;
use std::path::Path;

/// Most points a hologram may hold (an SVG of about 100 MB); more is refused with the count.
pub const MAX_POINTS: usize = 1 << 20;
/// Largest magnitude of a point's coordinate, a radius or a plate's corner: beyond, the
/// drawing's numbers lose the precision an SVG reader (single precision in usvg) keeps.
pub const MAX_COORDINATE: f64 = 1e15;
/// The default design view angle from the plate's normal, in degrees: `k = tan 45 = 1`, each
/// arc's radius equals its point's distance from the plate.
pub const DEFAULT_VIEW_ANGLE: f64 = 45.0;
/// The default range of view azimuths an arc covers, in degrees.
pub const DEFAULT_SPAN: f64 = 90.0;
/// The default design azimuth, in degrees from `+x` toward `+y`: `+y`, the bottom of the
/// drawing as an image shows it, where a viewer stands who sees the drawing upright.
pub const DEFAULT_AZIMUTH: f64 = 90.0;
/// The default stroke width, as a fraction of the larger side of the box of the points and
/// their arcs.
pub const DEFAULT_WIDTH_FRACTION: f64 = 1.0 / 400.0;
/// The fitted plate's margin on each side, as a fraction of the larger side of the box of the
/// points and their stroked arcs.
pub const MARGIN_FRACTION: f64 = 0.05;

/// Errors of holograms: a bad parameter (named, with its value), a bad point (its index, from
/// 0, and its coordinates), or a points file (its path and the line, from 1).
#[derive(Debug, thiserror::Error)]
pub enum HologramError {
    #[error("{name} = {value}: {why}")]
    Param {
        name: &'static str,
        value: String,
        why: String,
    },
    #[error("point {index} ({x}, {y}, {z}): {why}")]
    Point {
        index: usize,
        x: f64,
        y: f64,
        z: f64,
        why: String,
    },
    #[error("no points: a hologram needs at least one")]
    NoPoints,
    #[error("{0} points, more than the {MAX_POINTS} a hologram may hold")]
    TooManyPoints(usize),
    #[error("{path}: {why}")]
    File { path: String, why: String },
    #[error("{path}, line {line}: {why}")]
    Line {
        path: String,
        line: usize,
        why: String,
    },
}

fn param(name: &'static str, value: f64, why: &str) -> HologramError {
    HologramError::Param {
        name,
        value: value.to_string(),
        why: why.to_string(),
    }
}

/// The drawing's rectangle on the plate, `[x0, x0 + size_x] x [y0, y0 + size_y]` in the
/// points' units: the SVG's `viewBox`, mapped onto texture space `[0, 1]^2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plate {
    pub x0: f64,
    pub y0: f64,
    pub size_x: f64,
    pub size_y: f64,
}

impl Plate {
    /// Check it: finite corners within [`MAX_COORDINATE`], sizes positive.
    pub fn validate(&self) -> Result<(), HologramError> {
        for (name, value) in [("plate x0", self.x0), ("plate y0", self.y0)] {
            if !(value.is_finite() && value.abs() <= MAX_COORDINATE) {
                return Err(param(
                    name,
                    value,
                    &format!("must be a finite number within +-{MAX_COORDINATE:e}"),
                ));
            }
        }
        for (name, value) in [("plate size_x", self.size_x), ("plate size_y", self.size_y)] {
            if !(value > 0.0 && value <= MAX_COORDINATE) {
                return Err(param(
                    name,
                    value,
                    &format!("must be positive and at most {MAX_COORDINATE:e}"),
                ));
            }
        }
        Ok(())
    }

    /// The texture coordinates of plate point `p`: `((x - x0) / size_x, (y - y0) / size_y)`.
    pub fn to_uv(&self, p: DVec2) -> DVec2 {
        DVec2::new((p.x - self.x0) / self.size_x, (p.y - self.y0) / self.size_y)
    }

    /// Whether the box `[lo, hi]` lies inside the plate.
    pub fn holds(&self, lo: DVec2, hi: DVec2) -> bool {
        lo.x >= self.x0
            && lo.y >= self.y0
            && hi.x <= self.x0 + self.size_x
            && hi.y <= self.y0 + self.size_y
    }
}

/// How a hologram is drawn. Angles are in degrees.
#[derive(Clone, Debug, PartialEq)]
pub struct HologramParams {
    /// The drawing's rectangle; `None` fits one around the points and their arcs with a margin
    /// of [`MARGIN_FRACTION`] on each side.
    pub plate: Option<Plate>,
    /// The design view angle from the plate's normal, in `(0, 90)`: the scale is its tangent
    /// unless [`HologramParams::scale`] is given.
    pub view_angle: f64,
    /// The scale `k` (radius over distance from the plate), replacing `tan(view_angle)`.
    pub scale: Option<f64>,
    /// The range of view azimuths each arc covers, in `(0, 360]`.
    pub span: f64,
    /// The design azimuth, the direction on the plate toward the viewer, from `+x` toward `+y`.
    pub azimuth: f64,
    /// The stroke width in drawing units; `None` takes [`DEFAULT_WIDTH_FRACTION`] of the larger
    /// side of the box of the points and their arcs.
    pub width: Option<f64>,
}

impl Default for HologramParams {
    fn default() -> Self {
        HologramParams {
            plate: None,
            view_angle: DEFAULT_VIEW_ANGLE,
            scale: None,
            span: DEFAULT_SPAN,
            azimuth: DEFAULT_AZIMUTH,
            width: None,
        }
    }
}

impl HologramParams {
    /// Check every parameter; the error names the first bad one.
    pub fn validate(&self) -> Result<(), HologramError> {
        if !(self.view_angle > 0.0 && self.view_angle < 90.0) {
            return Err(param(
                "view_angle",
                self.view_angle,
                "must be in (0, 90) degrees from the plate's normal",
            ));
        }
        if let Some(k) = self.scale {
            if !(k > 0.0 && k.is_finite()) {
                return Err(param("scale", k, "must be a positive finite number"));
            }
        }
        if !(self.span > 0.0 && self.span <= 360.0) {
            return Err(param("span", self.span, "must be in (0, 360] degrees"));
        }
        if !self.azimuth.is_finite() {
            return Err(param("azimuth", self.azimuth, "must be a finite angle"));
        }
        if let Some(w) = self.width {
            if !(w > 0.0 && w <= MAX_COORDINATE) {
                return Err(param(
                    "width",
                    w,
                    &format!("must be positive and at most {MAX_COORDINATE:e}"),
                ));
            }
        }
        if let Some(plate) = &self.plate {
            plate.validate()?;
        }
        Ok(())
    }

    /// The scale `k`: [`HologramParams::scale`] if given, else `tan(view_angle)` (exactly 1 at
    /// 45 degrees, where `tan` of the rounded radian angle gives `1 - 2^-53`).
    pub fn scale(&self) -> f64 {
        self.scale.unwrap_or_else(|| {
            if self.view_angle == 45.0 {
                1.0
            } else {
                self.view_angle.to_radians().tan()
            }
        })
    }

    /// The design eye direction (unit, away from the plate): at the azimuth
    /// [`HologramParams::azimuth`] and the angle `atan(k)` from the normal, where the light at
    /// the normal shows every point at its depth.
    pub fn design_eye(&self) -> DVec3 {
        eye_direction(self.scale().atan(), self.azimuth.to_radians())
    }
}

/// The unit direction at `theta` from the plate's normal and the azimuth `alpha` (radians, from
/// `+x` toward `+y`): `(sin theta cos alpha, sin theta sin alpha, cos theta)`.
pub fn eye_direction(theta: f64, alpha: f64) -> DVec3 {
    DVec3::new(
        theta.sin() * alpha.cos(),
        theta.sin() * alpha.sin(),
        theta.cos(),
    )
}

/// The arc of one point: the points `centre + radius (cos phi, sin phi)` for `phi` from `start`
/// to `end` (radians, from `+x` toward `+y`; `start` in `[-pi, pi]`, `end = start + span`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HologramArc {
    /// The point's projection `(x, y)` on the plate.
    pub centre: DVec2,
    /// `k |z|`.
    pub radius: f64,
    pub start: f64,
    pub end: f64,
    /// The point's signed distance from the plate (`> 0` in front).
    pub z: f64,
}

impl HologramArc {
    /// The point of the circle at angle `phi`.
    pub fn at(&self, phi: f64) -> DVec2 {
        self.centre + self.radius * DVec2::new(phi.cos(), phi.sin())
    }

    /// Whether the angle `phi` (any turn) lies on the arc, up to `1e-12` radians at its ends.
    pub fn holds_angle(&self, phi: f64) -> bool {
        (phi - self.start).rem_euclid(TAU) <= self.end - self.start + 1e-12
            || (self.start - phi).rem_euclid(TAU) <= 1e-12
    }

    /// The arc's bounding box `(lo, hi)`: its ends and the axis extremes it passes.
    pub fn bounds(&self) -> (DVec2, DVec2) {
        let (mut lo, mut hi) = (self.at(self.start), self.at(self.start));
        let mut add = |p: DVec2| {
            lo = lo.min(p);
            hi = hi.max(p);
        };
        add(self.at(self.end));
        for quarter in 0..4 {
            let phi = quarter as f64 * PI / 2.0;
            if self.holds_angle(phi) {
                add(self.at(phi));
            }
        }
        (lo, hi)
    }
}

/// Where a distant light in direction `light_dir` and a distant eye in direction `eye_dir`
/// (both away from the plate, on its front; any length) make the arc glint (METHOD.md 9.3):
/// the point of the arc's circle where `(l + v) . t = 0` on the arc's designed side,
/// `c - sign(z) r h_p / |h_p|` (`c + r h_p / |h_p|` for a point behind the plate), if the
/// arc holds it. `None` when it lies off the arc, when the light or the eye is not in front
/// of the plate, or when `h_p = 0` (the light mirrored into the eye by the plate itself: every
/// point of the circle glints).
pub fn glint(arc: &HologramArc, light_dir: DVec3, eye_dir: DVec3) -> Option<DVec2> {
    let (l, v) = (light_dir.try_normalize()?, eye_dir.try_normalize()?);
    if l.z <= 0.0 || v.z <= 0.0 {
        return None;
    }
    let h = l + v;
    let hp = DVec2::new(h.x, h.y);
    if hp.length() <= 1e-12 * h.length() {
        return None;
    }
    let dir = -arc.z.signum() * hp.normalize();
    let phi = dir.y.atan2(dir.x);
    arc.holds_angle(phi).then(|| arc.centre + arc.radius * dir)
}

/// Check the points and the parameters, returning the scale.
fn check(points: &[DVec3], params: &HologramParams) -> Result<f64, HologramError> {
    params.validate()?;
    if points.is_empty() {
        return Err(HologramError::NoPoints);
    }
    if points.len() > MAX_POINTS {
        return Err(HologramError::TooManyPoints(points.len()));
    }
    Ok(params.scale())
}

/// The arc of every point (METHOD.md 9.4), in the points' order: centred on `(x, y)`, of radius
/// `k |z|`, covering `span` degrees centred on the design azimuth for a point behind the plate
/// and on the opposite direction for a point in front. A point with a coordinate that is not
/// finite or beyond [`MAX_COORDINATE`], on the plate (`z = 0`), or whose radius leaves
/// `(0, MAX_COORDINATE]`, is an error naming its index.
pub fn arcs(points: &[DVec3], params: &HologramParams) -> Result<Vec<HologramArc>, HologramError> {
    let k = check(points, params)?;
    let half = params.span.to_radians() / 2.0;
    let span = params.span.to_radians();
    let azimuth = params.azimuth.to_radians();
    points
        .iter()
        .enumerate()
        .map(|(index, p)| {
            let bad = |why: String| HologramError::Point {
                index,
                x: p.x,
                y: p.y,
                z: p.z,
                why,
            };
            if !(p.is_finite() && p.abs().max_element() <= MAX_COORDINATE) {
                return Err(bad(format!(
                    "a coordinate is not a finite number within +-{MAX_COORDINATE:e}"
                )));
            }
            if p.z == 0.0 {
                return Err(bad(
                    "lies on the plate (z = 0): it is neither in front nor behind, and has no arc"
                        .into(),
                ));
            }
            let radius = k * p.z.abs();
            if !(radius > 0.0 && radius <= MAX_COORDINATE) {
                return Err(bad(format!(
                    "its arc's radius k |z| = {radius} is outside (0, {MAX_COORDINATE:e}]"
                )));
            }
            let middle = if p.z < 0.0 { azimuth } else { azimuth + PI };
            let start = (middle - half + PI).rem_euclid(TAU) - PI;
            Ok(HologramArc {
                centre: DVec2::new(p.x, p.y),
                radius,
                start,
                end: start + span,
                z: p.z,
            })
        })
        .collect()
}

/// A drawn hologram: the arcs, the plate they are drawn on and the stroke width.
#[derive(Clone, Debug, PartialEq)]
pub struct Hologram {
    pub arcs: Vec<HologramArc>,
    pub plate: Plate,
    /// The stroke width in drawing units.
    pub width: f64,
    /// The scale `k`.
    pub scale: f64,
    /// How many stroked arcs reach outside a given plate (0 for a fitted one).
    pub outside: usize,
}

/// The arcs of the points ([`arcs`]) on the plate of `params` or a fitted one, with the stroke
/// width.
pub fn hologram(points: &[DVec3], params: &HologramParams) -> Result<Hologram, HologramError> {
    let arcs = arcs(points, params)?;
    let (mut lo, mut hi) = (DVec2::INFINITY, DVec2::NEG_INFINITY);
    for arc in &arcs {
        let (a, b) = arc.bounds();
        lo = lo.min(a.min(arc.centre));
        hi = hi.max(b.max(arc.centre));
    }
    let width = params
        .width
        .unwrap_or_else(|| (hi - lo).max_element() * DEFAULT_WIDTH_FRACTION);
    let half = width / 2.0;
    let (plate, outside) = match params.plate {
        Some(plate) => {
            let outside = arcs
                .iter()
                .filter(|arc| {
                    let (a, b) = arc.bounds();
                    !plate.holds(a - half, b + half)
                })
                .count();
            (plate, outside)
        }
        None => {
            let (lo, hi) = (lo - half, hi + half);
            let margin = (hi - lo).max_element() * MARGIN_FRACTION;
            let plate = Plate {
                x0: lo.x - margin,
                y0: lo.y - margin,
                size_x: hi.x - lo.x + 2.0 * margin,
                size_y: hi.y - lo.y + 2.0 * margin,
            };
            plate.validate()?;
            (plate, 0)
        }
    };
    Ok(Hologram {
        arcs,
        plate,
        width,
        scale: params.scale(),
        outside,
    })
}

impl Hologram {
    /// The SVG document: `width` and `height` equal to the `viewBox` (the plate), and one
    /// `<path>` per arc, `fill="none" stroke="black" stroke-width="W"`, whose `d` moves to the
    /// arc's start and draws it with elliptical arc commands (`A r r 0 0 1 x y`, each at most
    /// 90 degrees; sweep flag 1 is SVG's direction of increasing angle, from `+x` toward `+y`).
    /// Numbers are written in the shortest form that reads back to the same `f64`.
    pub fn to_svg(&self) -> String {
        let p = &self.plate;
        let mut svg = String::with_capacity(200 + 120 * self.arcs.len());
        let _ = writeln!(svg, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
        let _ = writeln!(
            svg,
            r#"<svg xmlns="http://www.w3.org/2000/svg" version="1.1" width="{}" height="{}" viewBox="{} {} {} {}">"#,
            p.size_x, p.size_y, p.x0, p.y0, p.size_x, p.size_y
        );
        let _ = writeln!(
            svg,
            "<!-- striae hologram (METHOD.md 9.4): {} arcs, scale k = {}; plate point (x, y) = SVG (x, y) -->",
            self.arcs.len(),
            self.scale
        );
        for arc in &self.arcs {
            let _ = writeln!(
                svg,
                r#"<path d="{}" fill="none" stroke="black" stroke-width="{}"/>"#,
                path_data(arc),
                self.width
            );
        }
        svg.push_str("</svg>\n");
        svg
    }
}

/// The `d` attribute of one arc: `M` to its start, then `ceil(span / 90 degrees)` equal arc
/// commands (short, so every reader places their centre well).
fn path_data(arc: &HologramArc) -> String {
    let span = arc.end - arc.start;
    let pieces = ((span / (PI / 2.0)) - 1e-9).ceil().max(1.0) as usize;
    let s = arc.at(arc.start);
    let mut d = format!("M {} {}", s.x, s.y);
    for i in 1..=pieces {
        let phi = if i == pieces {
            arc.end
        } else {
            arc.start + span * i as f64 / pieces as f64
        };
        let e = arc.at(phi);
        let _ = write!(d, " A {} {} 0 0 1 {} {}", arc.radius, arc.radius, e.x, e.y);
    }
    d
}

/// The points of a `.obj` file (its `v` lines: `x y z`, with an optional `w` that divides them
/// or an ignored colour `r g b`) or a `.csv` file (three columns x, y, z separated by commas,
/// an optional header line first, blank lines and lines starting with `#` skipped). The
/// OBJ's vertices are read directly rather than with `tobj`, which keeps only the vertices a
/// face uses, reads them in single precision, and names no line. Errors name the file and,
/// for a bad line, its number.
pub fn read_points(path: &Path) -> Result<Vec<DVec3>, HologramError> {
    let name = path.display().to_string();
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let kind = match ext.as_deref() {
        Some("obj") => PointsFormat::Obj,
        Some("csv") => PointsFormat::Csv,
        _ => {
            return Err(HologramError::File {
                path: name,
                why: "expected a .obj or .csv file of points".into(),
            })
        }
    };
    let text = crate::io::read_text(path).map_err(|e| HologramError::File {
        path: name.clone(),
        why: e.to_string(),
    })?;
    parse_points(&text, kind, &name)
}

/// The formats [`read_points`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PointsFormat {
    Obj,
    Csv,
}

/// The points of `text` in `format` ([`read_points`]); `name` names it in errors.
pub fn parse_points(
    text: &str,
    format: PointsFormat,
    name: &str,
) -> Result<Vec<DVec3>, HologramError> {
    let line_err = |line: usize, why: String| HologramError::Line {
        path: name.to_string(),
        line,
        why,
    };
    let number = |line: usize, word: &str| -> Result<f64, HologramError> {
        match word.trim().parse::<f64>() {
            Ok(x) if x.abs() <= MAX_COORDINATE => Ok(x),
            Ok(_) => Err(line_err(
                line,
                format!("`{word}` is not a finite number within +-{MAX_COORDINATE:e}"),
            )),
            Err(_) => Err(line_err(line, format!("`{word}` is not a number"))),
        }
    };
    let shown = |s: &str| s.trim().chars().take(80).collect::<String>();
    let mut points = Vec::new();
    let mut first = true;
    for (i, raw) in text.lines().enumerate() {
        let line = i + 1;
        match format {
            PointsFormat::Obj => {
                let mut words = raw.split('#').next().unwrap_or("").split_whitespace();
                if words.next() != Some("v") {
                    continue;
                }
                let words: Vec<&str> = words.collect();
                if !matches!(words.len(), 3 | 4 | 6) {
                    return Err(line_err(
                        line,
                        format!(
                            "`{}`: a vertex is `v x y z`, with an optional w or colour r g b",
                            shown(raw)
                        ),
                    ));
                }
                let mut p = DVec3::new(
                    number(line, words[0])?,
                    number(line, words[1])?,
                    number(line, words[2])?,
                );
                if words.len() == 4 {
                    let w = number(line, words[3])?;
                    if w == 0.0 {
                        return Err(line_err(line, format!("`{}`: w is 0", shown(raw))));
                    }
                    p /= w;
                    if !(p.is_finite() && p.abs().max_element() <= MAX_COORDINATE) {
                        return Err(line_err(
                            line,
                            format!(
                                "`{}`: x/w, y/w or z/w is beyond +-{MAX_COORDINATE:e}",
                                shown(raw)
                            ),
                        ));
                    }
                }
                points.push(p);
            }
            PointsFormat::Csv => {
                let trimmed = raw.trim();
                if trimmed.is_empty() || trimmed.starts_with('#') {
                    continue;
                }
                let fields: Vec<&str> = trimmed.split(',').collect();
                let header = first && fields.iter().all(|f| f.trim().parse::<f64>().is_err());
                first = false;
                if header {
                    continue;
                }
                if fields.len() != 3 {
                    return Err(line_err(
                        line,
                        format!(
                            "`{}`: expected three numbers x,y,z, found {} fields",
                            shown(raw),
                            fields.len()
                        ),
                    ));
                }
                points.push(DVec3::new(
                    number(line, fields[0])?,
                    number(line, fields[1])?,
                    number(line, fields[2])?,
                ));
            }
        }
        if points.len() > MAX_POINTS {
            return Err(HologramError::File {
                path: name.to_string(),
                why: format!("more than the {MAX_POINTS} points a hologram may hold"),
            });
        }
    }
    if points.is_empty() {
        return Err(HologramError::File {
            path: name.to_string(),
            why: match format {
                PointsFormat::Obj => "no vertices (`v` lines)".into(),
                PointsFormat::Csv => "no points (lines x,y,z)".into(),
            },
        });
    }
    Ok(points)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points in front and behind, near and far, at several scales.
    fn points() -> Vec<DVec3> {
        vec![
            DVec3::new(0.3, -0.2, -0.5),
            DVec3::new(1.0, 2.0, 0.25),
            DVec3::new(-1.5, 0.5, 1.5),
            DVec3::new(0.0, 0.0, -2.0),
            DVec3::new(10.0, -3.0, 0.01),
            DVec3::new(-4.0, 7.5, -30.0),
        ]
    }

    /// Parameter sets: the default, a wide span seen from the side, a given scale with a full
    /// circle, a narrow span at a grazing design angle.
    fn param_sets() -> Vec<HologramParams> {
        vec![
            HologramParams::default(),
            HologramParams {
                view_angle: 60.0,
                span: 200.0,
                azimuth: -30.0,
                ..Default::default()
            },
            HologramParams {
                scale: Some(0.3),
                span: 360.0,
                azimuth: 180.0,
                ..Default::default()
            },
            HologramParams {
                view_angle: 75.0,
                span: 20.0,
                azimuth: 725.0,
                ..Default::default()
            },
        ]
    }

    /// SplitMix64: uniform numbers in [0, 1) for the random views.
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f64 {
            self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = self.0;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// The test's own parametrisation of the arc's circle (not `HologramArc::at`).
    fn circle(arc: &HologramArc, phi: f64) -> DVec2 {
        DVec2::new(
            arc.centre.x + arc.radius * phi.cos(),
            arc.centre.y + arc.radius * phi.sin(),
        )
    }

    /// `(l + v) . t` at angle `phi`, `t` the unit tangent by a central finite difference of
    /// the arc (taken about its centre, so that the centre's rounding stays out of it).
    fn cone_condition(arc: &HologramArc, phi: f64, l: DVec3, v: DVec3) -> f64 {
        let eps = 1e-6;
        let offset = |phi: f64| arc.radius * DVec2::new(phi.cos(), phi.sin());
        let t = (offset(phi + eps) - offset(phi - eps)).normalize();
        let h = l.normalize() + v.normalize();
        h.x * t.x + h.y * t.y
    }

    /// The angle of `p` around the arc's centre and whether it lies on the arc (checked with
    /// the test's own angle arithmetic).
    fn on_arc(arc: &HologramArc, p: DVec2) -> (f64, bool) {
        let d = p - arc.centre;
        let phi = d.y.atan2(d.x);
        let from_start = (phi - arc.start).rem_euclid(2.0 * PI);
        let inside = from_start <= arc.end - arc.start + 1e-9 || from_start >= 2.0 * PI - 1e-9;
        (phi, inside)
    }

    /// The roots of `(l + v) . t = 0` along the arc, by scanning and bisection.
    fn roots(arc: &HologramArc, l: DVec3, v: DVec3) -> Vec<f64> {
        let n = 4000;
        let f = |phi: f64| cone_condition(arc, phi, l, v);
        let at = |i: usize| arc.start + (arc.end - arc.start) * i as f64 / n as f64;
        let mut out = Vec::new();
        for i in 0..n {
            let (mut a, mut b) = (at(i), at(i + 1));
            let (fa, fb) = (f(a), f(b));
            if fa == 0.0 {
                out.push(a);
                continue;
            }
            if fa * fb > 0.0 {
                continue;
            }
            for _ in 0..100 {
                let m = 0.5 * (a + b);
                if f(a) * f(m) <= 0.0 {
                    b = m;
                } else {
                    a = m;
                }
            }
            out.push(0.5 * (a + b));
        }
        out
    }

    /// (a) Every design view inside the span (light at the normal, eye at the design elevation)
    /// makes each arc glint on the arc, at the radius, where the finite-difference tangent
    /// meets `(l + v) . t = 0`; and for random distant lights and eyes, a glint the function
    /// reports is one of the roots found by scanning the arc, while the roots it leaves out lie
    /// on the circle's other side.
    #[test]
    fn glints_lie_on_the_arc_where_the_cone_condition_holds() {
        let mut rng = Rng(7);
        let n = DVec3::Z;
        for params in param_sets() {
            let arcs = arcs(&points(), &params).unwrap();
            let theta = params.scale().atan();
            for arc in &arcs {
                for i in 0..=20 {
                    let alpha = params.azimuth.to_radians()
                        + params.span.to_radians() * (i as f64 / 20.0 - 0.5) * 0.999;
                    let v = eye_direction(theta, alpha);
                    let g = glint(arc, n, v).expect("a design view inside the span glints");
                    let (phi, inside) = on_arc(arc, g);
                    assert!(inside, "{arc:?}: glint angle {phi} off the arc");
                    let off = ((g - arc.centre).length() - arc.radius).abs();
                    assert!(off <= 1e-12 * (arc.radius + arc.centre.length()), "{off}");
                    let c = cone_condition(arc, phi, n, v);
                    assert!(c.abs() < 1e-8, "{arc:?} alpha {alpha}: (l + v) . t = {c}");
                }
                // A view outside the span (for a span under 360) leaves the arc dark.
                if params.span < 359.0 {
                    let alpha = params.azimuth.to_radians()
                        + (params.span.to_radians() / 2.0
                            + 0.6 * (PI - params.span.to_radians() / 2.0));
                    assert_eq!(glint(arc, n, eye_direction(theta, alpha)), None);
                }
                // Random distant lights and eyes in front of the plate.
                for _ in 0..40 {
                    let dir = |rng: &mut Rng| {
                        eye_direction((0.05 + 0.9 * rng.next()) * PI / 2.0, 2.0 * PI * rng.next())
                    };
                    let (l, v) = (dir(&mut rng), dir(&mut rng));
                    let found = roots(arc, l, v);
                    let h = l + v;
                    match glint(arc, l, v) {
                        Some(g) => {
                            let (phi, inside) = on_arc(arc, g);
                            assert!(inside);
                            assert!(cone_condition(arc, phi, l, v).abs() < 1e-8);
                            assert!(
                                found
                                    .iter()
                                    .any(|&r| (circle(arc, r) - g).length() < 1e-7 * arc.radius),
                                "{arc:?}: glint {g} not among the roots {found:?}"
                            );
                        }
                        None => {
                            // Every root on the arc is the circle's other glint: on the side
                            // of h_p that shows the point mirrored through the plate.
                            for r in found {
                                let side = (circle(arc, r) - arc.centre).dot(DVec2::new(h.x, h.y));
                                assert!(side * arc.z > 0.0, "{arc:?}: missed root {r}");
                            }
                        }
                    }
                }
            }
        }
    }

    /// The nearest points of the lines `p + s d` and `q + t e`: their midpoint and distance.
    fn triangulate(p: DVec3, d: DVec3, q: DVec3, e: DVec3) -> (DVec3, f64) {
        let w = p - q;
        let (a, b, c) = (d.dot(d), d.dot(e), e.dot(e));
        let (dd, ee) = (d.dot(w), e.dot(w));
        let den = a * c - b * b;
        let s = (b * ee - c * dd) / den;
        let t = (a * ee - b * dd) / den;
        let (x, y) = (p + s * d, q + t * e);
        (0.5 * (x + y), (x - y).length())
    }

    /// (b) Parallax: the rays from two views' glints along the two eye directions (light at
    /// the normal, two azimuths inside the span) meet at the point itself at the design
    /// elevation; at another elevation `theta` they meet at the same `(x, y)` and at the depth
    /// `z k / tan(theta)`. The depth comes back to 1e-9 of itself, the position on the plate to
    /// 1e-9 of `|c| + |z|`, and the rays meet to 1e-9 of `|c| + |z|` (measured: at most 3e-13,
    /// 9e-14 and 8e-15, the rounding of the glints' coordinates).
    #[test]
    fn two_views_triangulate_the_point() {
        let (mut worst_z, mut worst_xy, mut worst_miss) = (0.0f64, 0.0f64, 0.0f64);
        for params in param_sets() {
            let pts = points();
            let arcs = arcs(&pts, &params).unwrap();
            let k = params.scale();
            let a0 = params.azimuth.to_radians();
            let half = params.span.to_radians() / 2.0;
            for theta in [k.atan(), 0.4, 1.2] {
                for (p, arc) in pts.iter().zip(&arcs) {
                    for (f1, f2) in [(-0.9, 0.9), (-0.5, 0.1), (0.2, 0.7)] {
                        let v1 = eye_direction(theta, a0 + f1 * half);
                        let v2 = eye_direction(theta, a0 + f2 * half);
                        let g1 = glint(arc, DVec3::Z, v1).unwrap();
                        let g2 = glint(arc, DVec3::Z, v2).unwrap();
                        let (seen, miss) = triangulate(g1.extend(0.0), v1, g2.extend(0.0), v2);
                        let depth = if theta == k.atan() {
                            p.z
                        } else {
                            p.z * k / theta.tan()
                        };
                        let size = DVec2::new(p.x, p.y).length() + depth.abs();
                        let z_err = (seen.z - depth).abs() / depth.abs();
                        let xy_err = (DVec2::new(seen.x - p.x, seen.y - p.y)).length() / size;
                        assert!(
                            z_err <= 1e-9 && xy_err <= 1e-9 && miss <= 1e-9 * size,
                            "{p} theta {theta}: seen at {seen}, expected depth {depth}, miss {miss}"
                        );
                        worst_z = worst_z.max(z_err);
                        worst_xy = worst_xy.max(xy_err);
                        worst_miss = worst_miss.max(miss / size);
                    }
                }
            }
        }
        eprintln!(
            "parallax: relative depth error {worst_z:e}, plate position {worst_xy:e}, miss {worst_miss:e}"
        );
    }

    /// The arcs of points behind are on the viewer's side of their centres, moving with the
    /// viewer; the arcs of points in front on the far side, moving against the viewer.
    #[test]
    fn behind_moves_with_the_viewer_in_front_against() {
        let params = HologramParams::default();
        let pts = [DVec3::new(0.0, 0.0, -1.0), DVec3::new(0.0, 0.0, 1.0)];
        let a = arcs(&pts, &params).unwrap();
        let mid = |arc: &HologramArc| arc.at(0.5 * (arc.start + arc.end));
        // The viewer is toward +y (azimuth 90): behind on the +y side, in front on the -y side.
        assert!((mid(&a[0]) - DVec2::new(0.0, 1.0)).length() < 1e-12);
        assert!((mid(&a[1]) - DVec2::new(0.0, -1.0)).length() < 1e-12);
        // The viewer moves toward +x (azimuth from 90 to 70 degrees).
        let theta = params.scale().atan();
        let at = |arc, deg: f64| glint(arc, DVec3::Z, eye_direction(theta, deg.to_radians()));
        assert!(at(&a[0], 70.0).unwrap().x > at(&a[0], 90.0).unwrap().x);
        assert!(at(&a[1], 70.0).unwrap().x < at(&a[1], 90.0).unwrap().x);
        // k = tan 45 degrees: radius = |z|; the design eye at 45 degrees toward +y.
        assert_eq!(a[0].radius, 1.0);
        let eye = params.design_eye();
        assert!((eye - DVec3::new(0.0, 0.5f64.sqrt(), 0.5f64.sqrt())).length() < 1e-15);
    }

    /// Reads the `d` attribute written by `to_svg`: `M x y` then `A rx ry rot large sweep x y`.
    fn parse_d(d: &str) -> (DVec2, Vec<[f64; 7]>) {
        let words: Vec<&str> = d.split_whitespace().collect();
        assert_eq!(words[0], "M");
        let num = |w: &str| w.parse::<f64>().unwrap();
        let start = DVec2::new(num(words[1]), num(words[2]));
        let mut arcs = Vec::new();
        let mut i = 3;
        while i < words.len() {
            assert_eq!(words[i], "A", "{d}");
            let mut a = [0.0; 7];
            for (j, x) in a.iter_mut().enumerate() {
                *x = num(words[i + 1 + j]);
            }
            arcs.push(a);
            i += 8;
        }
        (start, arcs)
    }

    fn attribute<'a>(element: &'a str, name: &str) -> &'a str {
        let key = format!(" {name}=\"");
        let from = element.find(&key).unwrap() + key.len();
        &element[from..from + element[from..].find('"').unwrap()]
    }

    /// (c) The SVG reads back: its own `d` attributes hold exactly the arcs (start, radius,
    /// flags, pieces of at most 90 degrees ending on the circle at the arc's end), and usvg reads
    /// the document with the plate's size, one stroked path per arc, the stroke width, and every
    /// path's vertices on its circle (to usvg's single precision).
    #[test]
    fn the_svg_reads_back() {
        for params in param_sets() {
            let h = hologram(&points(), &params).unwrap();
            assert_eq!(h.outside, 0, "a fitted plate holds every arc");
            let svg = h.to_svg();
            let svg_tag = &svg[svg.find("<svg").unwrap()..];
            let p = h.plate;
            assert_eq!(
                attribute(svg_tag, "viewBox"),
                format!("{} {} {} {}", p.x0, p.y0, p.size_x, p.size_y)
            );
            assert_eq!(
                attribute(svg_tag, "width").parse::<f64>().unwrap(),
                p.size_x
            );
            assert_eq!(
                attribute(svg_tag, "height").parse::<f64>().unwrap(),
                p.size_y
            );
            let paths: Vec<&str> = svg.split("<path").skip(1).collect();
            assert_eq!(paths.len(), h.arcs.len());
            for (element, arc) in paths.iter().zip(&h.arcs) {
                assert_eq!(attribute(element, "fill"), "none");
                assert_eq!(attribute(element, "stroke"), "black");
                assert_eq!(
                    attribute(element, "stroke-width").parse::<f64>().unwrap(),
                    h.width
                );
                let (start, pieces) = parse_d(attribute(element, "d"));
                assert_eq!(start, arc.at(arc.start));
                let span = arc.end - arc.start;
                assert_eq!(pieces.len(), (span / (PI / 2.0) - 1e-9).ceil() as usize);
                let mut from = start;
                for a in &pieces {
                    assert_eq!(
                        (a[0], a[1], a[2], a[3], a[4]),
                        (arc.radius, arc.radius, 0.0, 0.0, 1.0)
                    );
                    let to = DVec2::new(a[5], a[6]);
                    // Each piece turns counter-clockwise (from +x toward +y) by at most 90
                    // degrees about the centre.
                    let (u, w) = (from - arc.centre, to - arc.centre);
                    let turn = u.perp_dot(w).atan2(u.dot(w));
                    assert!(turn > 0.0 && turn <= PI / 2.0 + 1e-9, "turn {turn}");
                    assert!(
                        ((to - arc.centre).length() - arc.radius).abs()
                            < 1e-12 * (1.0 + arc.radius + arc.centre.length())
                    );
                    from = to;
                }
                assert!(
                    (from - arc.at(arc.end)).length()
                        < 1e-12 * (1.0 + arc.radius + arc.centre.length())
                );
            }

            let tree = usvg::Tree::from_str(&svg, &usvg::Options::default()).unwrap();
            assert!((tree.size().width() as f64 - p.size_x).abs() <= 1e-6 * p.size_x);
            assert!((tree.size().height() as f64 - p.size_y).abs() <= 1e-6 * p.size_y);
            let mut read = Vec::new();
            collect_paths(tree.root(), &mut read);
            assert_eq!(read.len(), h.arcs.len());
            let scale = p.size_x.max(p.size_y);
            for (path, arc) in read.iter().zip(&h.arcs) {
                assert!(path.fill().is_none());
                let stroke = path.stroke().unwrap();
                assert!((stroke.width().get() as f64 - h.width).abs() <= 1e-6 * h.width);
                let t = path.abs_transform();
                let mut ends = Vec::new();
                for seg in path.data().segments() {
                    use usvg::tiny_skia_path::PathSegment as S;
                    let q = match seg {
                        S::MoveTo(q) | S::LineTo(q) | S::QuadTo(_, q) | S::CubicTo(_, _, q) => q,
                        S::Close => continue,
                    };
                    let mut q = q;
                    t.map_point(&mut q);
                    // Canvas coordinates are the viewBox's less its corner: u = X / size_x.
                    ends.push(DVec2::new(q.x as f64 + p.x0, q.y as f64 + p.y0));
                }
                assert!(ends.len() >= 2);
                for q in &ends {
                    let off = ((*q - arc.centre).length() - arc.radius).abs();
                    assert!(
                        off <= 1e-5 * scale,
                        "{arc:?}: vertex {q} off the circle by {off}"
                    );
                }
                assert!((ends[0] - arc.at(arc.start)).length() <= 1e-5 * scale);
                assert!((ends[ends.len() - 1] - arc.at(arc.end)).length() <= 1e-5 * scale);
            }
        }
    }

    fn collect_paths<'a>(group: &'a usvg::Group, out: &mut Vec<&'a usvg::Path>) {
        for node in group.children() {
            match node {
                usvg::Node::Path(p) => out.push(p),
                usvg::Node::Group(g) => collect_paths(g, out),
                _ => {}
            }
        }
    }

    /// A fitted plate holds every stroked arc with its margin; a given plate is kept and the
    /// arcs reaching out of it counted; the uv mapping has no flip.
    #[test]
    fn plates_fit_and_map_to_uv() {
        let h = hologram(&points(), &HologramParams::default()).unwrap();
        for arc in &h.arcs {
            let (lo, hi) = arc.bounds();
            let m = MARGIN_FRACTION * 0.9 * h.plate.size_x.max(h.plate.size_y)
                / (1.0 + 2.0 * MARGIN_FRACTION);
            assert!(h
                .plate
                .holds(lo - h.width / 2.0 - m, hi + h.width / 2.0 + m));
        }
        let plate = Plate {
            x0: -1.0,
            y0: -1.0,
            size_x: 2.0,
            size_y: 4.0,
        };
        let given = hologram(
            &points(),
            &HologramParams {
                plate: Some(plate),
                width: Some(0.01),
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(given.plate, plate);
        assert_eq!(given.width, 0.01);
        // Only the arc of (0.3, -0.2, -0.5) fits (radius 0.5, x in [-0.06, 0.66], y in
        // [0.15, 0.3]).
        assert_eq!(given.outside, 5);
        assert_eq!(plate.to_uv(DVec2::new(0.0, 2.0)), DVec2::new(0.5, 0.75));
        assert_eq!(plate.to_uv(DVec2::new(-1.0, -1.0)), DVec2::ZERO);
    }

    /// (d) Bad points and bad parameters are errors that name them.
    #[test]
    fn bad_input_is_refused_by_name() {
        let message =
            |pts: &[DVec3], params: HologramParams| hologram(pts, &params).unwrap_err().to_string();
        let ok = points();
        let mut on_plate = ok.clone();
        on_plate[3].z = 0.0;
        let e = message(&on_plate, HologramParams::default());
        assert!(e.starts_with("point 3 (0, 0, 0): lies on the plate"), "{e}");
        let mut nan = ok.clone();
        nan[2].x = f64::NAN;
        assert!(message(&nan, HologramParams::default()).starts_with("point 2 (NaN"));
        let mut far = ok.clone();
        far[1].z = 1e300;
        assert!(message(&far, HologramParams::default()).starts_with("point 1 "));
        let tiny = [DVec3::new(0.0, 0.0, 1e-320)];
        let e = message(
            &tiny,
            HologramParams {
                scale: Some(1e-10),
                ..Default::default()
            },
        );
        assert!(e.contains("radius"), "{e}");
        assert_eq!(
            message(&[], HologramParams::default()),
            "no points: a hologram needs at least one"
        );
        let many = vec![DVec3::new(0.0, 0.0, 1.0); MAX_POINTS + 1];
        assert!(message(&many, HologramParams::default()).contains("more than the"));

        let bad = |params: HologramParams, name: &str| {
            let e = message(&ok, params);
            assert!(e.starts_with(&format!("{name} = ")), "{name}: {e}");
        };
        for v in [0.0, 90.0, -10.0, f64::NAN] {
            bad(
                HologramParams {
                    view_angle: v,
                    ..Default::default()
                },
                "view_angle",
            );
        }
        for v in [0.0, -1.0, f64::INFINITY] {
            bad(
                HologramParams {
                    scale: Some(v),
                    ..Default::default()
                },
                "scale",
            );
        }
        for v in [0.0, -5.0, 360.5, f64::NAN] {
            bad(
                HologramParams {
                    span: v,
                    ..Default::default()
                },
                "span",
            );
        }
        bad(
            HologramParams {
                azimuth: f64::INFINITY,
                ..Default::default()
            },
            "azimuth",
        );
        for v in [0.0, -0.1, f64::NAN] {
            bad(
                HologramParams {
                    width: Some(v),
                    ..Default::default()
                },
                "width",
            );
        }
        let plate = Plate {
            x0: 0.0,
            y0: 0.0,
            size_x: 1.0,
            size_y: 1.0,
        };
        for (p, name) in [
            (
                Plate {
                    x0: f64::NAN,
                    ..plate
                },
                "plate x0",
            ),
            (
                Plate {
                    y0: f64::INFINITY,
                    ..plate
                },
                "plate y0",
            ),
            (
                Plate {
                    size_x: 0.0,
                    ..plate
                },
                "plate size_x",
            ),
            (
                Plate {
                    size_y: -2.0,
                    ..plate
                },
                "plate size_y",
            ),
        ] {
            bad(
                HologramParams {
                    plate: Some(p),
                    ..Default::default()
                },
                name,
            );
        }
        // A full circle is allowed; the glint of a view at the normal is everywhere.
        let arc = arcs(
            &ok,
            &HologramParams {
                span: 360.0,
                ..Default::default()
            },
        )
        .unwrap()[0];
        assert_eq!(glint(&arc, DVec3::Z, DVec3::Z), None);
        assert_eq!(glint(&arc, DVec3::Z, DVec3::new(1.0, 0.0, -0.5)), None);
    }

    /// Points files: OBJ vertices (w divides, colours ignored, other lines skipped), CSV with
    /// and without a header; bad lines and files named with their line numbers.
    #[test]
    fn points_files_parse_or_name_the_line() {
        let obj = "# a shape\nmtllib x.mtl\nv 1 2 3\nvt 0.5 0.5\nv 2 4 6 2\nv 0.5 0.5 -1 1 0 0 # red\nf 1 2 3\n";
        assert_eq!(
            parse_points(obj, PointsFormat::Obj, "a.obj").unwrap(),
            vec![
                DVec3::new(1.0, 2.0, 3.0),
                DVec3::new(1.0, 2.0, 3.0),
                DVec3::new(0.5, 0.5, -1.0)
            ]
        );
        let csv = "x, y, z\n\n1,2,3\r\n# note\n -1.5 , 0, 2e-1\n";
        assert_eq!(
            parse_points(csv, PointsFormat::Csv, "a.csv").unwrap(),
            vec![DVec3::new(1.0, 2.0, 3.0), DVec3::new(-1.5, 0.0, 0.2)]
        );
        assert_eq!(
            parse_points("1,2,3\n", PointsFormat::Csv, "b.csv")
                .unwrap()
                .len(),
            1
        );
        let err = |text: &str, format| parse_points(text, format, "p").unwrap_err().to_string();
        assert_eq!(
            err("x,y,z\n1,2,3\n4,five,6\n", PointsFormat::Csv),
            "p, line 3: `five` is not a number"
        );
        assert!(err("1,2,3\n1,2\n", PointsFormat::Csv)
            .starts_with("p, line 2: `1,2`: expected three numbers"));
        assert!(
            err("1,2,3\nx,y,z\n", PointsFormat::Csv).starts_with("p, line 2: `x` is not a number")
        );
        assert!(err("1,2,inf\n", PointsFormat::Csv)
            .starts_with("p, line 1: `inf` is not a finite number"));
        assert_eq!(
            err("x,y,z\n", PointsFormat::Csv),
            "p: no points (lines x,y,z)"
        );
        assert!(err("v 1 2\n", PointsFormat::Obj).starts_with("p, line 1: `v 1 2`: a vertex is"));
        assert_eq!(
            err("\nv 1 2 3 0\n", PointsFormat::Obj),
            "p, line 2: `v 1 2 3 0`: w is 0"
        );
        assert!(
            err("v 1 nan 3\n", PointsFormat::Obj).starts_with("p, line 1: `nan` is not a finite")
        );
        assert_eq!(
            err("f 1 2 3\n", PointsFormat::Obj),
            "p: no vertices (`v` lines)"
        );

        let dir = std::env::temp_dir().join(format!("striae-hologram-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("shape.CSV");
        std::fs::write(&file, "0,0,1\n0,1,-1\n").unwrap();
        assert_eq!(read_points(&file).unwrap().len(), 2);
        let missing = dir.join("none.obj");
        let e = read_points(&missing).unwrap_err().to_string();
        assert!(e.starts_with(&missing.display().to_string()), "{e}");
        let e = read_points(&dir.join("p.txt")).unwrap_err().to_string();
        assert!(e.ends_with("expected a .obj or .csv file of points"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
