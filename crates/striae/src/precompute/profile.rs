//! Scratch cross-section profiles (METHOD.md section 2).
//!
//! A profile is a polyline in the cross-section plane `(x, z)` from `(-1/2, 0)` to `(1/2, 0)`
//! with `z <= 0` in between: a groove below the flat surface `z = 0`, normalised to width 1
//! (geometric optics is scale-free). Shapes: V-groove (by depth or opening angle), rounded
//! groove (a circular arc), trapezoid, flat (for analytic tests) and a custom polyline read
//! from a text file. Every profile is validated: finite, at least two segments, never above the
//! surface, no zero-length segment and no self-intersection.
//!
//! Spec syntax (the CLI's `--profile`), documented in `docs/table-format.md`:
//! `v:depth=D`, `v:angle=DEG`, `round:depth=D[,segments=K]`, `trapezoid:depth=D,bottom=B`,
//! `flat`, `file:PATH`.

use std::path::{Path, PathBuf};

/// Why a profile or its specification was rejected.
#[derive(Debug, thiserror::Error)]
pub enum ProfileError {
    #[error("unknown profile kind `{0}` (expected v, round, trapezoid, flat or file:PATH)")]
    UnknownKind(String),
    #[error("profile `{spec}`: unknown parameter `{key}` (expected {expected})")]
    UnknownParameter {
        spec: String,
        key: String,
        expected: &'static str,
    },
    #[error("profile `{spec}`: missing parameter `{key}`")]
    MissingParameter { spec: String, key: &'static str },
    #[error("profile `{spec}`: parameter `{key}` given twice")]
    DuplicateParameter { spec: String, key: String },
    #[error("profile `{spec}`: parameter `{key}` = `{value}` is invalid: {why}")]
    BadParameter {
        spec: String,
        key: String,
        value: String,
        why: String,
    },
    #[error("profile `{spec}`: `{item}` is not of the form key=value")]
    Malformed { spec: String, item: String },
    #[error("cannot read profile file {path}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("profile file {path}, line {line}: cannot read `{text}` as two numbers `x z`")]
    BadLine {
        path: PathBuf,
        line: usize,
        text: String,
    },
    #[error("profile file {path}, line {line}: `{text}` {why}")]
    BadPoint {
        path: PathBuf,
        line: usize,
        text: String,
        why: String,
    },
    #[error("profile {what}: point {index} ({x}, {z}) lies more than {MAX_EXTENT} opening widths from the opening's centre")]
    TooFar {
        what: String,
        index: usize,
        x: f64,
        z: f64,
    },
    #[error("profile {what}: has {segments} segment(s), at least 2 are needed")]
    TooFewSegments { what: String, segments: usize },
    #[error("profile {what}: has more than {MAX_SEGMENTS} segments (the most a profile may have)")]
    TooManySegments { what: String },
    #[error("profile {what}: point {index} ({x}, {z}) is not finite")]
    NonFinite {
        what: String,
        index: usize,
        x: f64,
        z: f64,
    },
    #[error("profile {what}: point {index} ({x}, {z}) lies above the surface z = 0")]
    AboveSurface {
        what: String,
        index: usize,
        x: f64,
        z: f64,
    },
    #[error("profile {what}: endpoints must lie on the surface z = 0 with x increasing, got ({x0}, {z0}) and ({x1}, {z1})")]
    BadEndpoints {
        what: String,
        x0: f64,
        z0: f64,
        x1: f64,
        z1: f64,
    },
    #[error("profile {what}: segment {index} has zero length")]
    ZeroLength { what: String, index: usize },
    #[error("profile {what}: segments {a} and {b} intersect")]
    SelfIntersecting { what: String, a: usize, b: usize },
}

/// A validated profile: `points[0] = (-1/2, 0)`, `points[last] = (1/2, 0)`, `z <= 0`.
#[derive(Clone, Debug, PartialEq)]
pub struct Profile {
    /// The specification it came from (e.g. `v:depth=0.5`), for records and plots.
    pub spec: String,
    /// Polyline vertices `[x, z]`.
    pub points: Vec<[f64; 2]>,
}

const Z_TOL: f64 = 1e-12;

impl Profile {
    /// A profile from explicit vertices, validated. `what` names it in errors.
    pub fn from_points(
        spec: impl Into<String>,
        points: Vec<[f64; 2]>,
    ) -> Result<Self, ProfileError> {
        let spec = spec.into();
        validate(&spec, &points)?;
        Ok(Profile { spec, points })
    }

    /// The profile worn to the depth ratio `d` in `(0, 1]` (METHOD.md 9.2): every depth times
    /// `d`, the width kept.
    pub fn worn(&self, d: f64) -> Result<Self, ProfileError> {
        let points = self.points.iter().map(|&[x, z]| [x, z * d]).collect();
        Self::from_points(format!("{} worn to {d}", self.spec), points)
    }

    /// V-groove of depth `d` (bottom at `(0, -d)`).
    pub fn v_depth(depth: f64) -> Result<Self, ProfileError> {
        let spec = format!("v:depth={depth}");
        depth_in_range(&spec, depth)?;
        Profile::from_points(spec, vec![[-0.5, 0.0], [0.0, -depth], [0.5, 0.0]])
    }

    /// V-groove with full opening angle `deg` degrees at the bottom: depth `1/2 / tan(deg/2)`.
    pub fn v_angle(deg: f64) -> Result<Self, ProfileError> {
        let spec = format!("v:angle={deg}");
        if !(deg.is_finite() && deg > 0.0 && deg < 180.0) {
            return Err(bad(&spec, "angle", deg, "must be in (0, 180) degrees"));
        }
        let depth = 0.5 / (deg.to_radians() / 2.0).tan();
        if depth > MAX_EXTENT {
            return Err(bad(
                &spec,
                "angle",
                deg,
                "makes a groove deeper than 1000 opening widths (profile::MAX_EXTENT)",
            ));
        }
        Profile::from_points(spec, vec![[-0.5, 0.0], [0.0, -depth], [0.5, 0.0]])
    }

    /// Rounded groove: the circular arc through `(-1/2, 0)`, `(0, -d)`, `(1/2, 0)` as a polyline
    /// of `segments` equal-angle chords. `d <= 1/2` (at most a half circle).
    pub fn round(depth: f64, segments: usize) -> Result<Self, ProfileError> {
        let spec = format!("round:depth={depth},segments={segments}");
        positive(&spec, "depth", depth)?;
        if depth > 0.5 {
            return Err(bad(
                &spec,
                "depth",
                depth,
                "must be at most 0.5 (a half circle)",
            ));
        }
        if !(2..=MAX_SEGMENTS).contains(&segments) {
            return Err(bad(
                &spec,
                "segments",
                segments as f64,
                "must be in 2..=4096 (profile::MAX_SEGMENTS)",
            ));
        }
        // Radius r and centre (0, c) with r^2 = 1/4 + c^2 and c - r = -d.
        let r = (0.25 + depth * depth) / (2.0 * depth);
        let c = r - depth;
        let half = (0.5 / r).clamp(-1.0, 1.0).asin(); // half-angle of the arc seen from the centre
        let mut points = Vec::with_capacity(segments + 1);
        for k in 0..=segments {
            // From angle -pi/2 - half (left end) to -pi/2 + half (right end), measured from +x.
            let a = -std::f64::consts::FRAC_PI_2 - half + 2.0 * half * k as f64 / segments as f64;
            let (x, z) = if k == 0 {
                (-0.5, 0.0)
            } else if k == segments {
                (0.5, 0.0)
            } else {
                (r * a.cos(), (c + r * a.sin()).min(0.0))
            };
            points.push([x, z]);
        }
        Profile::from_points(spec, points)
    }

    /// Trapezoid of depth `d` with a flat bottom of width `b` in (0, 1).
    pub fn trapezoid(depth: f64, bottom: f64) -> Result<Self, ProfileError> {
        let spec = format!("trapezoid:depth={depth},bottom={bottom}");
        depth_in_range(&spec, depth)?;
        if !(bottom.is_finite() && bottom > 0.0 && bottom < 1.0) {
            return Err(bad(
                &spec,
                "bottom",
                bottom,
                "must be in (0, 1) (use v: for a V-groove)",
            ));
        }
        let h = bottom / 2.0;
        Profile::from_points(
            spec,
            vec![[-0.5, 0.0], [-h, -depth], [h, -depth], [0.5, 0.0]],
        )
    }

    /// The flat surface as two collinear segments: every ray hits at its entry point.
    pub fn flat() -> Self {
        Profile {
            spec: "flat".into(),
            points: vec![[-0.5, 0.0], [0.0, 0.0], [0.5, 0.0]],
        }
    }

    /// A non-convex W groove (two V's either side of a raised middle), named `w`: rays
    /// leaving one half meet the other, the case the convex tracers refuse.
    #[cfg(test)]
    pub(crate) fn w_groove() -> Self {
        Profile::from_points(
            "w",
            vec![
                [-0.5, 0.0],
                [-0.25, -0.5],
                [0.0, -0.1],
                [0.25, -0.5],
                [0.5, 0.0],
            ],
        )
        .unwrap()
    }

    /// Read a polyline file (format in `docs/table-format.md`): one vertex `x z` per line
    /// (whitespace or comma separated), `#` starts a comment, blank lines are skipped. The
    /// endpoints must have `z = 0` and `x0 < x_last`; the polyline is translated and scaled
    /// uniformly so that they land on `(-1/2, 0)` and `(1/2, 0)`.
    pub fn from_file(path: &Path) -> Result<Self, ProfileError> {
        let text = crate::io::read_text(path).map_err(|source| ProfileError::Io {
            path: path.into(),
            source,
        })?;
        let mut raw = Vec::new();
        // Where each vertex was written (line number and text), for errors.
        let mut written: Vec<(usize, &str)> = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let body = line.split('#').next().unwrap_or("").trim();
            if body.is_empty() {
                continue;
            }
            let nums: Vec<&str> = body
                .split(|c: char| c == ',' || c.is_whitespace())
                .filter(|s| !s.is_empty())
                .collect();
            let parsed: Option<Vec<f64>> = nums.iter().map(|s| s.parse::<f64>().ok()).collect();
            if raw.len() > MAX_SEGMENTS {
                return Err(ProfileError::TooManySegments {
                    what: format!("file {}", path.display()),
                });
            }
            match parsed {
                Some(v) if v.len() == 2 => {
                    raw.push([v[0], v[1]]);
                    written.push((i + 1, line));
                }
                _ => {
                    return Err(ProfileError::BadLine {
                        path: path.into(),
                        line: i + 1,
                        text: line.to_string(),
                    })
                }
            }
        }
        let what = format!("file {}", path.display());
        let spec = format!("file:{}", path.display());
        if raw.len() < 3 {
            return Err(ProfileError::TooFewSegments {
                what,
                segments: raw.len().saturating_sub(1),
            });
        }
        let bad_point = |index: usize, why: String| {
            let (line, text) = written[index];
            ProfileError::BadPoint {
                path: path.into(),
                line,
                text: text.to_string(),
                why,
            }
        };
        if let Some(index) = raw
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(bad_point(index, "is not two finite numbers".into()));
        }
        let (a, b) = (raw[0], raw[raw.len() - 1]);
        if a[1].abs() > Z_TOL || b[1].abs() > Z_TOL || b[0] <= a[0] {
            return Err(ProfileError::BadEndpoints {
                what,
                x0: a[0],
                z0: a[1],
                x1: b[0],
                z1: b[1],
            });
        }
        if !(b[0] - a[0]).is_finite() {
            return Err(bad_point(
                raw.len() - 1,
                "is further from the first point than a number can hold".into(),
            ));
        }
        let s = 1.0 / (b[0] - a[0]);
        let mut points: Vec<[f64; 2]> = raw
            .iter()
            .map(|p| [(p[0] - a[0]) * s - 0.5, p[1] * s])
            .collect();
        if let Some(index) = points.iter().position(|p| !within_extent(*p)) {
            return Err(bad_point(
                index,
                format!(
                    "lies more than {MAX_EXTENT} opening widths from the opening's centre \
                     (the first and last points are the opening)"
                ),
            ));
        }
        let last = points.len() - 1;
        points[0] = [-0.5, 0.0];
        points[last] = [0.5, 0.0];
        validate(&what, &points)?;
        Ok(Profile { spec, points })
    }

    /// Parse a `--profile` specification.
    pub fn parse(spec: &str) -> Result<Self, ProfileError> {
        let spec = spec.trim();
        if let Some(path) = spec.strip_prefix("file:") {
            return Profile::from_file(Path::new(path));
        }
        let (kind, rest) = spec.split_once(':').unwrap_or((spec, ""));
        let allowed: (&[&str], &'static str) = match kind {
            "v" => (&["depth", "angle"], "depth or angle"),
            "round" => (&["depth", "segments"], "depth, segments"),
            "trapezoid" => (&["depth", "bottom"], "depth, bottom"),
            "flat" => (&[], "no parameters"),
            _ => return Err(ProfileError::UnknownKind(kind.to_string())),
        };
        let mut params: Vec<(String, f64)> = Vec::new();
        let mut written: Vec<(String, &str)> = Vec::new();
        for item in rest.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (k, v) = item
                .split_once('=')
                .ok_or_else(|| ProfileError::Malformed {
                    spec: spec.into(),
                    item: item.into(),
                })?;
            let (k, v) = (k.trim(), v.trim());
            if !allowed.0.contains(&k) {
                return Err(ProfileError::UnknownParameter {
                    spec: spec.into(),
                    key: k.into(),
                    expected: allowed.1,
                });
            }
            if params.iter().any(|(p, _)| p == k) {
                return Err(ProfileError::DuplicateParameter {
                    spec: spec.into(),
                    key: k.into(),
                });
            }
            let x: f64 = v.parse().map_err(|_| ProfileError::BadParameter {
                spec: spec.into(),
                key: k.into(),
                value: v.into(),
                why: "not a number".into(),
            })?;
            params.push((k.to_string(), x));
            written.push((k.to_string(), v));
        }
        let w = |e| as_written(e, spec, &written);
        let get = |k: &str| params.iter().find(|(p, _)| p == k).map(|(_, v)| *v);
        let need = |k: &'static str| {
            get(k).ok_or_else(|| ProfileError::MissingParameter {
                spec: spec.into(),
                key: k,
            })
        };
        let mut profile = match kind {
            "v" => match (get("depth"), get("angle")) {
                (Some(d), None) => Profile::v_depth(d).map_err(w)?,
                (None, Some(a)) => Profile::v_angle(a).map_err(w)?,
                (Some(_), Some(_)) => {
                    return Err(ProfileError::BadParameter {
                        spec: spec.into(),
                        key: "angle".into(),
                        value: rest.into(),
                        why: "give depth or angle, not both".into(),
                    })
                }
                (None, None) => {
                    return Err(ProfileError::MissingParameter {
                        spec: spec.into(),
                        key: "depth or angle",
                    })
                }
            },
            "round" => {
                let segs = get("segments").unwrap_or(64.0);
                if segs.fract() != 0.0 || !(2.0..=MAX_SEGMENTS as f64).contains(&segs) {
                    return Err(w(bad(
                        spec,
                        "segments",
                        segs,
                        "must be an integer in 2..=4096 (profile::MAX_SEGMENTS)",
                    )));
                }
                Profile::round(need("depth")?, segs as usize).map_err(w)?
            }
            "trapezoid" => Profile::trapezoid(need("depth")?, need("bottom")?).map_err(w)?,
            _ => Profile::flat(),
        };
        profile.spec = spec.to_string();
        Ok(profile)
    }

    /// Number of segments.
    pub fn segments(&self) -> usize {
        self.points.len() - 1
    }

    /// The groove's depth below the surface, in units of its opening's width.
    pub fn depth(&self) -> f64 {
        -self.points.iter().map(|p| p[1]).fold(0.0, f64::min)
    }

    /// The groove's cross-section area below the opening, in units of the opening's width
    /// squared (the shoelace formula over the polyline closed along the opening): `d / 2` for a
    /// V of depth `d`. Scaled about the opening's centre, a groove whose width changes at the
    /// rate `W'` along its axis tilts its walls' normals along the axis, toward its wider part,
    /// by `tan = 2 area |W'|` on average over the opening, and exactly so at every wall point of a
    /// V (`lean = true`, [`crate::render::scratched::ScratchedMaterial::with_lean`]).
    pub fn area(&self) -> f64 {
        let twice: f64 = self
            .points
            .windows(2)
            .map(|w| w[0][0] * w[1][1] - w[1][0] * w[0][1])
            .sum();
        0.5 * twice.abs()
    }

    /// Below this `tan theta` from the normal (in the cross-section) no light from inside meets
    /// the groove beside its opening ([`Self::ray_meets_ridge`]): a ray from beside the left
    /// rim reaches the point `(x, z)` only if it leans at least `(x + 1/2) / |z|` (the right
    /// rim mirrored), so the least such slope over the points below the surface.
    pub fn ridge_tan(&self) -> f64 {
        self.points
            .iter()
            .filter(|p| p[1] < 0.0)
            .map(|p| (p[0] + 0.5).min(0.5 - p[0]) / -p[1])
            .fold(f64::INFINITY, f64::min)
    }

    /// Whether the line from the surface point `(x, 0)` going down along `(dx, dz)` (`dz <
    /// 0`) meets the groove's walls. Seen from inside the object a groove is a ridge of air
    /// below the surface, so light arriving along `-(dx, dz)` at a point beside the opening
    /// has met the groove first when this holds (METHOD.md 8.1; the light beside the opening
    /// of [`crate::precompute::groove::GonioSettings::beside`]).
    pub fn ray_meets_ridge(&self, x: f64, dx: f64, dz: f64) -> bool {
        self.ray_meets_ridge_between(x, dx, dz, 0.0, f64::INFINITY)
    }

    /// [`Self::ray_meets_ridge`] for the stretch of the line between `min_depth` and
    /// `max_depth` below the surface: light that began `max_depth` deep (met shallower than
    /// that on its way up), or light that left a wall `min_depth` deep on its way down (met
    /// deeper than that; a line that is below the opening there, in the groove or under it,
    /// meets no wall beside it).
    pub fn ray_meets_ridge_between(
        &self,
        x: f64,
        dx: f64,
        dz: f64,
        min_depth: f64,
        max_depth: f64,
    ) -> bool {
        let down = dz < 0.0;
        if !down || (x + dx * min_depth / -dz).abs() < 0.5 {
            return false;
        }
        let o = [x, 0.0];
        let d = [dx, dz];
        self.points.windows(2).any(|w| {
            // `o + t d = w0 + u (w1 - w0)`, `t > 0`, `u` in `[0, 1]`.
            let e = sub(w[1], w[0]);
            let den = cross(d, e);
            if den == 0.0 {
                return false;
            }
            let r = sub(w[0], o);
            let t = cross(r, e) / den;
            let u = cross(r, d) / den;
            t > 1e-12 && (0.0..=1.0).contains(&u) && (min_depth..max_depth).contains(&(-t * dz))
        })
    }
}

fn bad(spec: &str, key: &str, value: f64, why: &str) -> ProfileError {
    ProfileError::BadParameter {
        spec: spec.into(),
        key: key.into(),
        value: value.to_string(),
        why: why.into(),
    }
}

fn positive(spec: &str, key: &str, v: f64) -> Result<(), ProfileError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(bad(spec, key, v, "must be a finite number > 0"))
    }
}

/// A groove's `depth`: positive and at most [`MAX_EXTENT`].
fn depth_in_range(spec: &str, depth: f64) -> Result<(), ProfileError> {
    positive(spec, "depth", depth)?;
    if depth > MAX_EXTENT {
        return Err(bad(
            spec,
            "depth",
            depth,
            "must be at most 1000 opening widths (profile::MAX_EXTENT)",
        ));
    }
    Ok(())
}

/// A constructor's error with the specification and the parameter's value as the user wrote
/// them (`written`: key and text); a number printed back can differ from its text (`1e308`
/// prints as 309 digits).
fn as_written(e: ProfileError, spec: &str, written: &[(String, &str)]) -> ProfileError {
    match e {
        ProfileError::BadParameter {
            key, value, why, ..
        } => ProfileError::BadParameter {
            spec: spec.into(),
            value: written
                .iter()
                .find(|(k, _)| *k == key)
                .map_or(value, |(_, text)| text.to_string()),
            key,
            why,
        },
        other => other,
    }
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

/// Closed segments `p1 p2` and `q1 q2` share a point.
fn segments_touch(p1: [f64; 2], p2: [f64; 2], q1: [f64; 2], q2: [f64; 2]) -> bool {
    let d1 = cross(sub(q2, q1), sub(p1, q1));
    let d2 = cross(sub(q2, q1), sub(p2, q1));
    let d3 = cross(sub(p2, p1), sub(q1, p1));
    let d4 = cross(sub(p2, p1), sub(q2, p1));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    let on = |a: [f64; 2], b: [f64; 2], p: [f64; 2], d: f64| {
        d == 0.0
            && p[0] >= a[0].min(b[0])
            && p[0] <= a[0].max(b[0])
            && p[1] >= a[1].min(b[1])
            && p[1] <= a[1].max(b[1])
    };
    on(q1, q2, p1, d1) || on(q1, q2, p2, d2) || on(p1, p2, q1, d3) || on(p1, p2, q2, d4)
}

/// The most segments a profile may have: 4096. Every bounce of the 2D and 2.5D tracers tests
/// all walls and the self-intersection check tests all pairs (8 million at the limit, about
/// 30 ms), so a 200,000-vertex file would take minutes to validate and hours to trace; a real
/// scratch profile needs tens.
pub const MAX_SEGMENTS: usize = 4096;

/// The farthest a vertex may lie from the opening's centre, in opening widths: 1000. A deeper
/// or wider groove is no scratch, and beyond it the tracers' absolute tolerances (`1e-10`
/// along a ray) approach the spacing of `f64` values at such coordinates.
pub const MAX_EXTENT: f64 = 1000.0;

/// `|x|` and `|z|` at most [`MAX_EXTENT`].
fn within_extent(p: [f64; 2]) -> bool {
    p[0].abs() <= MAX_EXTENT && p[1].abs() <= MAX_EXTENT
}

fn validate(what: &str, points: &[[f64; 2]]) -> Result<(), ProfileError> {
    let what = what.to_string();
    let segs = points.len().saturating_sub(1);
    if segs > MAX_SEGMENTS {
        return Err(ProfileError::TooManySegments { what });
    }
    if segs < 2 {
        return Err(ProfileError::TooFewSegments {
            what,
            segments: segs,
        });
    }
    for (index, p) in points.iter().enumerate() {
        if !(p[0].is_finite() && p[1].is_finite()) {
            return Err(ProfileError::NonFinite {
                what,
                index,
                x: p[0],
                z: p[1],
            });
        }
        if p[1] > Z_TOL {
            return Err(ProfileError::AboveSurface {
                what,
                index,
                x: p[0],
                z: p[1],
            });
        }
        if !within_extent(*p) {
            return Err(ProfileError::TooFar {
                what,
                index,
                x: p[0],
                z: p[1],
            });
        }
    }
    let (a, b) = (points[0], points[segs]);
    if a != [-0.5, 0.0] || b != [0.5, 0.0] {
        return Err(ProfileError::BadEndpoints {
            what,
            x0: a[0],
            z0: a[1],
            x1: b[0],
            z1: b[1],
        });
    }
    for i in 0..segs {
        let e = sub(points[i + 1], points[i]);
        if e[0] * e[0] + e[1] * e[1] < 1e-24 {
            return Err(ProfileError::ZeroLength { what, index: i });
        }
    }
    for i in 0..segs {
        for j in i + 1..segs {
            let (p1, p2, q1, q2) = (points[i], points[i + 1], points[j], points[j + 1]);
            if j == i + 1 {
                // Adjacent: they share p2 == q1; they intersect elsewhere only if they fold back
                // onto each other (collinear, opposite directions).
                let e1 = sub(p2, p1);
                let e2 = sub(q2, q1);
                let dot = e1[0] * e2[0] + e1[1] * e2[1];
                if cross(e1, e2).abs() <= 1e-12 * (dot.abs() + 1e-300) && dot < 0.0 {
                    return Err(ProfileError::SelfIntersecting { what, a: i, b: j });
                }
            } else if segments_touch(p1, p2, q1, q2) {
                return Err(ProfileError::SelfIntersecting { what, a: i, b: j });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Cross-section areas in closed form: a V of depth `d` (`d / 2`), a trapezoid (`d (1 +
    /// b) / 2`) and a half circle of diameter 1 (`pi / 8`, as a fine polyline, whose inscribed
    /// polygon falls short by about `pi^3 / (24 n^2)` of it).
    #[test]
    fn areas_in_closed_form() {
        let close = |p: &str, want: f64, tol: f64| {
            let a = Profile::parse(p).unwrap().area();
            assert!((a - want).abs() <= tol, "{p}: {a} against {want}");
        };
        close("v:depth=0.5", 0.25, 1e-15);
        close("v:angle=60", 0.5 * 0.5 / 30f64.to_radians().tan(), 1e-15);
        close("trapezoid:depth=0.3,bottom=0.4", 0.3 * 1.4 / 2.0, 1e-15);
        close(
            "round:depth=0.5,segments=512",
            std::f64::consts::PI / 8.0,
            1e-5,
        );
    }

    /// The ridge a round groove shows from inside (a circular segment of chord 1 and sagitta
    /// `s`, radius `R = (1/4 + s^2) / 2s`, centre `c = R - s` above the surface) meets light at
    /// the angle `a` from the normal over a surface band beyond the opening of `k - 1`, with
    /// `k` the closed form of `groove`'s `beside_light_meets_the_ridge_over_its_projected_width`
    /// (1 while the arc's end tangent hides the ridge, `a <= 90 deg - alpha`, `sin alpha =
    /// 1 / 2R`; then `(cos a / 2 + R - c sin a) / cos a`); and nothing on the far side.
    #[test]
    fn ridge_band_of_a_round_groove() {
        let p = Profile::parse("round:depth=0.3,segments=1024").unwrap();
        assert!((p.depth() - 0.3).abs() < 1e-9);
        let sag = 0.3f64;
        let r = (0.25 + sag * sag) / (2.0 * sag);
        let c = r - sag;
        let alpha = (0.5 / r).asin();
        for deg in [20.0f64, 60.0, 75.0, 85.0] {
            let a = deg.to_radians();
            let k = if a <= std::f64::consts::FRAC_PI_2 - alpha {
                1.0
            } else {
                (0.5 * a.cos() + r - c * a.sin()) / a.cos()
            };
            // Light going up and to `-x` arrives from `(sin a, -cos a)`: the band lies at
            // `x < -1/2`, where the ray back towards the light passes under the groove.
            let n = 50_000;
            let span = 4.0;
            let hits = (0..n)
                .filter(|&i| {
                    let x = -0.5 - span * (i as f64 + 0.5) / n as f64;
                    p.ray_meets_ridge(x, a.sin(), -a.cos())
                })
                .count();
            let band = span * hits as f64 / n as f64;
            assert!(
                (band - (k - 1.0)).abs() < 1e-3,
                "{deg} degrees: band {band} against {}",
                k - 1.0
            );
            let far = (0..1000)
                .any(|i| p.ray_meets_ridge(0.5 + 0.004 * (i as f64 + 0.5), a.sin(), -a.cos()));
            assert!(!far, "{deg} degrees: the far side");
        }
    }

    /// A line down through a V of depth 1/2 crosses its walls where the geometry puts them:
    /// from `(-3/2, 0)` along `(1, -1/4)` into the left wall at depth 1/3 and out through the
    /// right one at depth 2/5. Only a stretch of the line holding one of them meets it, and a
    /// stretch that begins below the opening (from depth 1/4 on, past `x = -1/2`: in the
    /// groove or under it) meets neither, whatever lies deeper.
    #[test]
    fn ridge_met_over_a_stretch_of_the_line() {
        let p = Profile::parse("v:depth=0.5").unwrap();
        let (x, dx, dz) = (-1.5, 1.0, -0.25);
        for (min, max, meets) in [
            (0.0, f64::INFINITY, true),
            (0.0, 0.33, false),
            (0.0, 0.34, true),
            (0.2, 0.34, true),
            (0.2, 0.3, false),
            (0.24, 0.34, true),
            (0.26, f64::INFINITY, false),
        ] {
            assert_eq!(
                p.ray_meets_ridge_between(x, dx, dz, min, max),
                meets,
                "{min}..{max}"
            );
        }
        assert!(
            !p.ray_meets_ridge_between(x, dx, -dz, 0.0, f64::INFINITY),
            "going up"
        );
    }

    #[test]
    fn shapes_are_valid_and_parsed() {
        let v = Profile::parse("v:depth=0.5").unwrap();
        assert_eq!(v.points, vec![[-0.5, 0.0], [0.0, -0.5], [0.5, 0.0]]);
        let a = Profile::parse("v:angle=90").unwrap();
        assert!(
            (a.points[1][1] + 0.5).abs() < 1e-12,
            "90 degrees is depth 1/2"
        );
        let r = Profile::parse("round:depth=0.3").unwrap();
        assert_eq!(r.segments(), 64);
        assert!(r.points.iter().all(|p| p[1] <= 0.0));
        let zmin = r.points.iter().map(|p| p[1]).fold(0.0, f64::min);
        assert!((zmin + 0.3).abs() < 1e-3, "{zmin}");
        // Every vertex on the circle.
        let rad = (0.25 + 0.09) / 0.6;
        for p in &r.points {
            assert!((p[0].hypot(p[1] - (rad - 0.3)) - rad).abs() < 1e-9);
        }
        let t = Profile::parse("trapezoid:depth=0.2,bottom=0.4").unwrap();
        assert_eq!(t.points[1], [-0.2, -0.2]);
        assert_eq!(Profile::parse("flat").unwrap().segments(), 2);
        assert_eq!(
            Profile::parse("round:depth=0.5,segments=8")
                .unwrap()
                .segments(),
            8
        );
    }

    #[test]
    fn invalid_specs_are_rejected() {
        for bad in [
            "u:depth=1",
            "v",
            "v:depth=0",
            "v:depth=-1",
            "v:depth=nan",
            "v:depth=inf",
            "v:depth=abc",
            "v:depth=0.5,angle=90",
            "v:depth=0.5,depth=0.4",
            "v:width=1",
            "v:depth",
            "v:angle=180",
            "v:angle=0",
            "round:depth=0.7",
            "round:depth=0.3,segments=1",
            "round:depth=0.3,segments=2.5",
            "trapezoid:depth=0.2",
            "trapezoid:depth=0.2,bottom=1",
            "trapezoid:depth=0.2,bottom=0",
            "flat:depth=1",
            "file:/nonexistent/profile.txt",
        ] {
            let e = Profile::parse(bad);
            assert!(e.is_err(), "{bad} accepted");
            assert!(!e.unwrap_err().to_string().is_empty());
        }
    }

    #[test]
    fn invalid_polylines_are_rejected() {
        let p = |pts: Vec<[f64; 2]>| Profile::from_points("test", pts);
        assert!(matches!(
            p(vec![[-0.5, 0.0], [0.5, 0.0]]),
            Err(ProfileError::TooFewSegments { .. })
        ));
        assert!(matches!(
            p(vec![[-0.5, 0.0], [0.0, 0.1], [0.5, 0.0]]),
            Err(ProfileError::AboveSurface { .. })
        ));
        assert!(matches!(
            p(vec![[-0.5, 0.0], [0.0, f64::NAN], [0.5, 0.0]]),
            Err(ProfileError::NonFinite { .. })
        ));
        assert!(matches!(
            p(vec![[-0.5, 0.0], [0.0, -0.5], [0.0, -0.5], [0.5, 0.0]]),
            Err(ProfileError::ZeroLength { .. })
        ));
        // A bow tie: the walls cross.
        assert!(matches!(
            p(vec![[-0.5, 0.0], [0.3, -0.5], [-0.3, -0.5], [0.5, 0.0]]),
            Err(ProfileError::SelfIntersecting { .. })
        ));
        // Folding back on itself.
        assert!(matches!(
            p(vec![[-0.5, 0.0], [0.0, -0.5], [-0.2, -0.3], [0.5, 0.0]]),
            Err(ProfileError::SelfIntersecting { .. })
        ));
        assert!(matches!(
            p(vec![
                [-0.5, 0.0],
                [0.0, -0.5],
                [0.0, -0.2],
                [0.0, -0.7],
                [0.5, 0.0]
            ]),
            Err(ProfileError::SelfIntersecting { .. })
        ));
        // Right shape accepted.
        assert!(p(vec![[-0.5, 0.0], [-0.1, -0.5], [0.2, -0.3], [0.5, 0.0]]).is_ok());
    }

    #[test]
    fn profiles_over_the_segment_limit_are_refused_at_once() {
        // 200,000 vertices: the pairwise self-intersection check once took minutes on this.
        let dir = std::env::temp_dir().join(format!("striae-profile-big-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("big.txt");
        let n = 200_000;
        let text: String = (0..n)
            .map(|i| {
                let x = -0.5 + i as f64 / (n - 1) as f64;
                let z = if i == 0 || i == n - 1 {
                    0.0
                } else {
                    -0.1 - 0.01 * (i % 2) as f64
                };
                format!("{x} {z}\n")
            })
            .collect();
        std::fs::write(&path, text).unwrap();
        let start = std::time::Instant::now();
        let e = Profile::from_file(&path).unwrap_err().to_string();
        assert!(e.contains("more than 4096 segments"), "{e}");
        assert!(start.elapsed().as_secs_f64() < 1.0);
        let e = Profile::parse("round:depth=0.3,segments=100000")
            .unwrap_err()
            .to_string();
        assert!(e.contains("segments"), "{e}");
        assert!(Profile::parse("round:depth=0.3,segments=4096").is_ok());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn profile_files() {
        let dir = std::env::temp_dir().join(format!("striae-profile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("ok.txt");
        std::fs::write(&f, "# measured\n0 0\n1, -1\n\n2 0  # end\n").unwrap();
        let p = Profile::parse(&format!("file:{}", f.display())).unwrap();
        assert_eq!(p.points, vec![[-0.5, 0.0], [0.0, -0.5], [0.5, 0.0]]);
        for (name, text) in [
            ("bad_line.txt", "0 0\n1 x\n2 0\n"),
            ("three_numbers.txt", "0 0\n1 -1 3\n2 0\n"),
            ("short.txt", "0 0\n2 0\n"),
            ("above.txt", "0 0\n1 1\n2 0\n"),
            ("endpoint.txt", "0 -1\n1 -1\n2 0\n"),
            ("reversed.txt", "2 0\n1 -1\n0 0\n"),
            ("nan.txt", "0 0\n1 NaN\n2 0\n"),
            ("cross.txt", "0 0\n1.6 -1\n0.4 -1\n2 0\n"),
        ] {
            let f = dir.join(name);
            std::fs::write(&f, text).unwrap();
            assert!(
                Profile::parse(&format!("file:{}", f.display())).is_err(),
                "{name} accepted"
            );
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Absurd numbers are refused with the value as the user wrote it (`1e308` printed back
    /// is 309 digits long): parameters of a specification, and the line of a profile file.
    #[test]
    fn absurd_coordinates_are_refused_as_written() {
        for (spec, key, text) in [
            ("v:depth=1e308", "depth", "1e308"),
            ("v:angle=1e-300", "angle", "1e-300"),
            ("trapezoid:depth=2e3,bottom=0.5", "depth", "2e3"),
            ("round:depth=1e308", "depth", "1e308"),
            ("round:depth=0.3,segments=1e308", "segments", "1e308"),
        ] {
            let e = Profile::parse(spec).unwrap_err();
            let message = e.to_string();
            assert!(
                matches!(&e, ProfileError::BadParameter { key: k, value, spec: s, .. }
                    if k == key && value == text && s == spec),
                "{spec}: {message}"
            );
            assert!(message.len() < 200, "{message}");
        }
        assert!(Profile::parse("v:depth=1000").is_ok());
        assert!(matches!(
            Profile::from_points("p", vec![[-0.5, 0.0], [0.0, -1000.5], [0.5, 0.0]]),
            Err(ProfileError::TooFar { index: 1, .. })
        ));
        let dir = std::env::temp_dir().join(format!("striae-profile-far-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        for (name, text, line, why) in [
            (
                "deep.txt",
                "0 0\n1 -1e308\n2 0\n",
                "1 -1e308",
                "more than 1000",
            ),
            (
                "wide.txt",
                "-1e308 0\n0 -1\n1e308 0\n",
                "1e308 0",
                "further",
            ),
            ("overflow.txt", "0 0\n1 -1e400\n2 0\n", "1 -1e400", "finite"),
            (
                "far.txt",
                "0 0\n0.5 -2000 # too deep\n1 0\n",
                "0.5 -2000 # too deep",
                "more than 1000",
            ),
        ] {
            let f = dir.join(name);
            std::fs::write(&f, text).unwrap();
            let e = Profile::from_file(&f).unwrap_err();
            let message = e.to_string();
            assert!(
                matches!(&e, ProfileError::BadPoint { text: t, .. } if t == line)
                    && message.contains(&f.display().to_string())
                    && message.contains(why),
                "{name}: {message}"
            );
            assert!(message.len() < 300, "{message}");
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
