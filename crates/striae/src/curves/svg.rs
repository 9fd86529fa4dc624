//! Scratches drawn in SVG (METHOD.md 9.1): every stroked path of the drawing is a scratch.
//!
//! `usvg` resolves the document (groups, transforms, CSS, `circle`, `ellipse`, `rect`,
//! `line`, `polyline`, `polygon` and every path command, arcs included, into absolute
//! Béziers); this module flattens them ([`super::stroke`]) in the drawing's canvas units.
//!
//! Mapping, exactly: the drawing lies on uv as an image texture of the same drawing would,
//! its canvas (the viewBox, mapped to the document's size) onto `[0, 1]^2`, SVG `x` to `u`,
//! SVG `y` to `v` ([`Drawing::to_uv`]). `stroke-width` is the scratch's width in canvas units
//! (under a transform, times the square root of its determinant). Per path, SVG carries:
//! `stroke-dasharray` and `stroke-dashoffset` (the dashes, replacing the set's), and
//! `stroke-opacity` (the depth ratio, times the set's `depth`: a fainter stroke is a
//! shallower scratch). A path without a stroke is an error naming it (a scratch is a stroke),
//! as is a `stroke-width` of zero or below, which usvg would drop silently.

use super::stroke::{self, StrokeStyle, FLATTEN_TOLERANCE};
use super::{CurveError, Polyline};
use glam::DVec2;
use std::path::Path;

/// Most bytes an SVG file may have (64 MiB): checked before it is read.
pub const MAX_SVG_BYTES: u64 = 64 << 20;

/// The scratches of a drawing, in its canvas units, and the map onto uv.
#[derive(Clone, Debug)]
pub struct Drawing {
    pub polylines: Vec<Polyline>,
    /// The canvas size (the document's width and height, in user units).
    pub size: DVec2,
    /// Stroked paths read.
    pub paths: usize,
    /// Segments of `polylines` in all.
    pub segments: usize,
}

impl Drawing {
    /// Canvas units to uv: `uv = p * to_uv`, component by component.
    pub fn to_uv(&self) -> DVec2 {
        DVec2::ONE / self.size
    }
}

fn file_error(path: &str, why: impl Into<String>) -> CurveError {
    CurveError::File {
        path: path.to_string(),
        why: why.into(),
    }
}

/// Read the SVG file at `path` (see the module notes); `style` supplies what a path does not.
pub fn load(path: &Path, style: &StrokeStyle) -> Result<Drawing, CurveError> {
    let name = path.display().to_string();
    let meta = std::fs::metadata(path).map_err(|e| file_error(&name, e.to_string()))?;
    if meta.len() > MAX_SVG_BYTES {
        return Err(file_error(
            &name,
            format!(
                "{} bytes, more than the {MAX_SVG_BYTES} an SVG drawing may have",
                meta.len()
            ),
        ));
    }
    let data = std::fs::read(path).map_err(|e| file_error(&name, e.to_string()))?;
    parse(&data, &name, style)
}

/// Parse SVG `data`; `name` names it in errors.
pub fn parse(data: &[u8], name: &str, style: &StrokeStyle) -> Result<Drawing, CurveError> {
    style.validate()?;
    let text = std::str::from_utf8(data)
        .map_err(|_| file_error(name, "is not SVG: not UTF-8 text (svgz is not read)"))?;
    check_stroke_widths(text, name)?;
    let tree = usvg::Tree::from_str(text, &usvg::Options::default())
        .map_err(|e| file_error(name, format!("is not a valid SVG document: {e}")))?;
    let size = DVec2::new(tree.size().width() as f64, tree.size().height() as f64);
    let mut out = Drawing {
        polylines: Vec::new(),
        size,
        paths: 0,
        segments: 0,
    };
    let mut count = 0usize;
    walk(tree.root(), name, style, &mut out, &mut count)?;
    if out.paths == 0 {
        return Err(file_error(
            name,
            "holds no stroked path: no scratch to draw",
        ));
    }
    Ok(out)
}

/// How a path is named in errors: its `id`, or its place among the paths.
fn path_name(p: &usvg::Path, index: usize) -> String {
    if p.id().is_empty() {
        format!("path #{index} (no id)")
    } else {
        format!("path id=\"{}\"", p.id())
    }
}

fn walk(
    g: &usvg::Group,
    name: &str,
    style: &StrokeStyle,
    out: &mut Drawing,
    count: &mut usize,
) -> Result<(), CurveError> {
    for node in g.children() {
        match node {
            usvg::Node::Group(g) => walk(g, name, style, out, count)?,
            usvg::Node::Path(p) => {
                *count += 1;
                if !p.is_visible() {
                    continue;
                }
                let Some(stroke) = p.stroke() else {
                    return Err(file_error(
                        name,
                        format!(
                            "{} has no stroke: a scratch is a stroked path (give it `stroke` and `stroke-width`, or remove it)",
                            path_name(p, *count)
                        ),
                    ));
                };
                if !add_path(p, stroke, style, *count, out) {
                    return Err(file_error(
                        name,
                        format!(
                            "{} alone flattens to more than {} segments: thinner strokes flatten finer; widen it",
                            path_name(p, *count),
                            super::MAX_SEGMENTS
                        ),
                    ));
                }
                out.paths += 1;
                // Refused as soon as the budget is passed, before the rest is flattened.
                if out.segments > super::MAX_SEGMENTS {
                    return Err(file_error(
                        name,
                        format!(
                            "flattens to more than {} segments by {} (of {} paths read): thinner strokes flatten finer; widen them or split the drawing",
                            super::MAX_SEGMENTS,
                            path_name(p, *count),
                            out.paths
                        ),
                    ));
                }
            }
            usvg::Node::Image(_) | usvg::Node::Text(_) => {}
        }
    }
    Ok(())
}

/// Flatten one stroked path into `out`; `false` (and `out` unchanged) where its polyline
/// alone passes [`super::MAX_SEGMENTS`].
fn add_path(
    p: &usvg::Path,
    s: &usvg::Stroke,
    style: &StrokeStyle,
    index: usize,
    out: &mut Drawing,
) -> bool {
    let before = (out.polylines.len(), out.segments);
    let t = p.abs_transform();
    let scale = ((t.sx * t.sy - t.kx * t.ky).abs() as f64).sqrt();
    let map = |q: usvg::tiny_skia_path::Point| {
        DVec2::new(
            (q.x * t.sx + q.y * t.kx + t.tx) as f64,
            (q.x * t.ky + q.y * t.sy + t.ty) as f64,
        )
    };
    let hw = 0.5 * s.width().get() as f64 * scale;
    let tol = FLATTEN_TOLERANCE * 2.0 * hw;
    let mut own = style.clone();
    if let Some(d) = s.dasharray() {
        own.dashes = d.iter().map(|&x| x as f64 * scale).collect();
        own.dash_offset = s.dashoffset() as f64 * scale;
    }
    own.depth = (style.depth * s.opacity().get() as f64).clamp(1e-3, 1.0);
    let mut line: Vec<DVec2> = Vec::new();
    let mut start = DVec2::ZERO;
    let flush = |line: &mut Vec<DVec2>, out: &mut Drawing| {
        if line.len() >= 2 {
            let id = (index as u64) << 20 | out.polylines.len() as u64 & 0xfffff;
            for l in own.apply(line, hw, id) {
                out.segments += l.points.len() - 1;
                out.polylines.push(l);
            }
        }
        line.clear();
    };
    for seg in p.data().segments() {
        if line.len() > super::MAX_SEGMENTS {
            out.polylines.truncate(before.0);
            out.segments = before.1;
            return false;
        }
        use usvg::tiny_skia_path::PathSegment as S;
        let last = line.last().copied().unwrap_or(start);
        match seg {
            S::MoveTo(q) => {
                flush(&mut line, out);
                start = map(q);
                line.push(start);
            }
            S::LineTo(q) => {
                if line.is_empty() {
                    line.push(last);
                }
                line.push(map(q));
            }
            S::QuadTo(a, b) => {
                if line.is_empty() {
                    line.push(last);
                }
                let c = [last, map(a), map(b)];
                let n = stroke::quad_steps(c, tol);
                line.extend((1..=n).map(|k| stroke::quad_at(c, k as f64 / n as f64)));
            }
            S::CubicTo(a, b, e) => {
                if line.is_empty() {
                    line.push(last);
                }
                let c = [last, map(a), map(b), map(e)];
                let n = stroke::cubic_steps(c, tol);
                line.extend((1..=n).map(|k| stroke::cubic_at(c, k as f64 / n as f64)));
            }
            S::Close => {
                if !line.is_empty() {
                    line.push(start);
                }
                flush(&mut line, out);
            }
        }
    }
    if line.len() > super::MAX_SEGMENTS {
        out.polylines.truncate(before.0);
        out.segments = before.1;
        return false;
    }
    flush(&mut line, out);
    true
}

/// A `stroke-width` of zero or below (an attribute or a `style` declaration), which usvg drops
/// silently: an error naming the element (its tag and `id`, or its line).
fn check_stroke_widths(text: &str, name: &str) -> Result<(), CurveError> {
    let doc = usvg::roxmltree::Document::parse_with_options(
        text,
        usvg::roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        },
    )
    .map_err(|e| file_error(name, format!("is not a valid SVG document: {e}")))?;
    for node in doc.descendants().filter(|n| n.is_element()) {
        let mut widths: Vec<&str> = node.attribute("stroke-width").into_iter().collect();
        if let Some(style) = node.attribute("style") {
            widths.extend(style.split(';').filter_map(|decl| {
                let (k, v) = decl.split_once(':')?;
                (k.trim() == "stroke-width").then_some(v.trim())
            }));
        }
        for w in widths {
            let number: String = w
                .trim()
                .chars()
                .take_while(|c| c.is_ascii_digit() || matches!(c, '.' | '-' | '+' | 'e' | 'E'))
                .collect();
            if let Ok(x) = number.parse::<f64>() {
                if x <= 0.0 {
                    let what = match node.attribute("id") {
                        Some(id) => format!("<{} id=\"{id}\">", node.tag_name().name()),
                        None => format!(
                            "<{}> at line {}",
                            node.tag_name().name(),
                            doc.text_pos_at(node.range().start).row
                        ),
                    };
                    return Err(file_error(
                        name,
                        format!("{what} has stroke-width {w:?}: a scratch's width must be > 0"),
                    ));
                }
            }
        }
    }
    Ok(())
}
