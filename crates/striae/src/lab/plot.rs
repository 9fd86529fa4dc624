//! Plots of a scratch BRDF table: the polar lobe for one incident angle (the seed's Fig. 2:
//! lobe radius = `rho_m(phi_o, phi_i)` over the upper half plane, incident direction marked)
//! and a heat map of the whole `rho_m` table with labelled axes and a colour bar.
//!
//! Text uses DejaVu Sans, embedded with `include_bytes!` (licence in
//! `crates/striae/assets/DejaVuSans-LICENSE.txt`) and registered with plotters' ab_glyph backend.

use crate::lab::fidelity::study::{Case, ModelResult};
use crate::precompute::groove::GonioOutput;
use crate::precompute::table::ScratchTable;
use crate::precompute::wall_table::{WallKind, WallTable};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

static FONT: &[u8] = include_bytes!("../../assets/DejaVuSans.ttf");

/// A plot could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error("plot {path}: {why}")]
    Draw { path: PathBuf, why: String },
    #[error("plot: --phi-i {0} degrees is outside (-90, 90)")]
    BadAngle(f64),
    #[error("{}: plots are PNG files; give NAME.png or NAME, not .{ext}", .path.display())]
    NotPng { path: PathBuf, ext: String },
}

/// A plot's name: `NAME.png` or `NAME`; another extension (`.jpg`) is refused, as
/// `striae render -o` refuses it, instead of PNG bytes written under a JPEG's name.
pub fn check_png_name(path: &Path) -> Result<(), PlotError> {
    match path.extension() {
        Some(e) if !e.eq_ignore_ascii_case("png") => Err(PlotError::NotPng {
            path: path.to_path_buf(),
            ext: e.to_string_lossy().into_owned(),
        }),
        _ => Ok(()),
    }
}

fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The font is embedded and known to parse; a failure would only lose the text.
        let _ = plotters::style::register_font("sans-serif", FontStyle::Normal, FONT);
    });
}

fn draw_err(path: &Path) -> impl Fn(String) -> PlotError + '_ {
    move |why| PlotError::Draw {
        path: path.to_path_buf(),
        why,
    }
}

/// Render to a temporary PNG and rename it into place (no half-written file).
pub(crate) fn render(
    path: &Path,
    size: (u32, u32),
    draw: impl FnOnce(&Path) -> Result<(), String>,
) -> Result<(), PlotError> {
    register_font();
    let _ = size;
    let err = draw_err(path);
    check_png_name(path)?;
    crate::io::check_destination(path).map_err(|e| err(e.to_string()))?;
    // plotters picks the encoder from the extension: keep `.png` on the temporary name.
    let tmp = crate::io::TempFile::new(path, ".png");
    draw(tmp.path()).map_err(&err)?;
    tmp.persist(path).map_err(|e| err(e.to_string()))
}

/// The seed's Fig. 2: polar plot of `rho_m(phi_o, phi_i)` over `phi_o` for the incident bin
/// nearest `phi_i_deg`, with the incident direction drawn as an arrow from the origin.
pub fn plot_lobe(table: &ScratchTable, phi_i_deg: f64, path: &Path) -> Result<(), PlotError> {
    if !(phi_i_deg.is_finite() && phi_i_deg > -90.0 && phi_i_deg < 90.0) {
        return Err(PlotError::BadAngle(phi_i_deg));
    }
    let m = table.m;
    let i = crate::precompute::trace2d::bin_of(phi_i_deg.to_radians(), m);
    let phi_i = table.phi[i];
    let row: Vec<f64> = (0..m).map(|j| table.rho_m[i * m + j]).collect();
    let rmax = row.iter().cloned().fold(0.0, f64::max).max(1e-9) * 1.1;
    let albedo = table.albedo_2d()[i];
    let (w, h) = (900u32, 520u32);
    render(path, (w, h), |tmp| {
        let root = BitMapBackend::new(tmp, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let caption = format!(
            "rho_m lobe, phi_i = {:.1} deg  ({}, {:?} walls, 2D albedo {:.3})",
            phi_i.to_degrees(),
            table.params.profile.spec,
            table.params.trace.walls,
            albedo
        );
        let mut chart = ChartBuilder::on(&root)
            .caption(caption, ("sans-serif", 20))
            .margin(15)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(-rmax..rmax, 0.0..rmax)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("rho sin(phi_o)")
            .y_desc("rho cos(phi_o)")
            .disable_mesh()
            .draw()
            .map_err(|e| e.to_string())?;
        // Reference half circles.
        let step = nice_step(rmax / 4.0);
        let mut r = step;
        while r < rmax {
            let arc: Vec<(f64, f64)> = (0..=180)
                .map(|k| (k as f64).to_radians())
                .map(|a| (r * a.cos(), r * a.sin()))
                .collect();
            chart
                .draw_series(LineSeries::new(arc, RGBColor(210, 210, 210)))
                .map_err(|e| e.to_string())?;
            chart
                .draw_series(std::iter::once(Text::new(
                    format!("{r:.3}"),
                    (-0.259 * r, 0.966 * r),
                    ("sans-serif", 13)
                        .into_font()
                        .color(&RGBColor(120, 120, 120)),
                )))
                .map_err(|e| e.to_string())?;
            r += step;
        }
        // The lobe: one vertex per phi_o bin centre, closed through the origin.
        let mut pts = vec![(0.0, 0.0)];
        pts.extend((0..m).map(|j| {
            let (s, c) = table.phi[j].sin_cos();
            (row[j] * s, row[j] * c)
        }));
        pts.push((0.0, 0.0));
        // Separate 2-point segments: a thick polyline's miter joins overshoot at the sharp
        // turns of mirror spikes.
        chart
            .draw_series(
                pts.windows(2)
                    .map(|w| PathElement::new(vec![w[0], w[1]], BLUE.stroke_width(2))),
            )
            .map_err(|e| e.to_string())?
            .label("rho_m(phi_o, phi_i)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE.stroke_width(2)));
        // Incident direction: w_i points away from the surface at phi_i; light travels inward.
        let (s, c) = phi_i.sin_cos();
        let tip = (0.95 * rmax * s, 0.95 * rmax * c);
        chart
            .draw_series(LineSeries::new(vec![tip, (0.0, 0.0)], RED.stroke_width(2)))
            .map_err(|e| e.to_string())?
            .label("incident direction")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED.stroke_width(2)));
        chart
            .draw_series(std::iter::once(Circle::new(tip, 6, RED.filled())))
            .map_err(|e| e.to_string())?;
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .label_font(("sans-serif", 14))
            .draw()
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())
    })
}

fn nice_step(x: f64) -> f64 {
    let p = 10f64.powf(x.log10().floor());
    let f = x / p;
    p * if f < 1.5 {
        1.0
    } else if f < 3.5 {
        2.0
    } else if f < 7.5 {
        5.0
    } else {
        10.0
    }
}

/// A viridis-like colour map on `[0, 1]` (piecewise linear through 5 of viridis' colours).
pub(crate) fn colour(t: f64) -> RGBColor {
    const STOPS: [(f64, f64, f64); 5] = [
        (68.0, 1.0, 84.0),
        (59.0, 82.0, 139.0),
        (33.0, 145.0, 140.0),
        (94.0, 201.0, 98.0),
        (253.0, 231.0, 37.0),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    } * 4.0;
    let k = (t as usize).min(3);
    let f = t - k as f64;
    let (a, b) = (STOPS[k], STOPS[k + 1]);
    let l = |x: f64, y: f64| (x + (y - x) * f).round() as u8;
    RGBColor(l(a.0, b.0), l(a.1, b.1), l(a.2, b.2))
}

/// Heat map of `rho_m[phi_i][phi_o]` (x: `phi_o`, y: `phi_i`, degrees) with a colour bar.
/// The colour scale saturates at the 99th percentile (stated in the caption) so that mirror
/// spikes do not hide the rest.
pub fn plot_heatmap(table: &ScratchTable, path: &Path) -> Result<(), PlotError> {
    let m = table.m;
    let mut sorted = table.rho_m.clone();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let vmax = sorted[((sorted.len() - 1) as f64 * 0.99) as usize]
        .max(sorted[sorted.len() - 1] * 1e-3)
        .max(1e-12);
    let (w, h) = (900u32, 760u32);
    render(path, (w, h), |tmp| {
        let root = BitMapBackend::new(tmp, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let map = HeatMap {
            values: &table.rho_m,
            n: m,
            vmax,
            caption: format!(
                "rho_m: {}, {:?} walls, M = {} (colour saturates at {:.3})",
                table.params.profile.spec, table.params.trace.walls, m, vmax
            ),
            y_desc: "phi_i (degrees)",
            bar_desc: "rho_m",
        };
        heat_panel(&root, &map)?;
        root.present().map_err(|e| e.to_string())
    })
}

/// An `n x n` grid of values over `[-90, 90]` degrees in both axes, row-major with rows along
/// y (x is always `phi_o`), drawn with colours saturating at `vmax`.
pub(crate) struct HeatMap<'a> {
    pub values: &'a [f64],
    pub n: usize,
    pub vmax: f64,
    pub caption: String,
    pub y_desc: &'a str,
    pub bar_desc: &'a str,
}

/// Draws `map` into `area` with its colour bar on the right.
pub(crate) fn heat_panel(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    map: &HeatMap,
) -> Result<(), String> {
    let (n, vmax) = (map.n, map.vmax);
    let (pw, _) = area.dim_in_pixel();
    let (left, bar_area) = area.split_horizontally(pw - 150);
    let mut chart = ChartBuilder::on(&left)
        .caption(&map.caption, ("sans-serif", 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(-90.0..90.0f64, -90.0..90.0f64)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("phi_o (degrees)")
        .y_desc(map.y_desc)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .draw()
        .map_err(|e| e.to_string())?;
    let bw = 180.0 / n as f64;
    chart
        .draw_series((0..n * n).map(|k| {
            let (i, j) = (k / n, k % n);
            let (x0, y0) = (-90.0 + j as f64 * bw, -90.0 + i as f64 * bw);
            Rectangle::new(
                [(x0, y0), (x0 + bw, y0 + bw)],
                colour(map.values[k] / vmax).filled(),
            )
        }))
        .map_err(|e| e.to_string())?;
    let mut bar = ChartBuilder::on(&bar_area)
        .margin_top(50)
        .margin_bottom(60)
        .margin_right(10)
        .y_label_area_size(90)
        .build_cartesian_2d(0.0..1.0f64, 0.0..vmax)
        .map_err(|e| e.to_string())?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_label_formatter(&|v| format!("{v:.1e}"))
        .y_desc(map.bar_desc)
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .draw()
        .map_err(|e| e.to_string())?;
    let steps = 200;
    bar.draw_series((0..steps).map(|k| {
        let (a, c) = (
            vmax * k as f64 / steps as f64,
            vmax * (k + 1) as f64 / steps as f64,
        );
        Rectangle::new(
            [(0.0, a), (1.0, c)],
            colour((k as f64 + 0.5) / steps as f64).filled(),
        )
    }))
    .map_err(|e| e.to_string())?;
    Ok(())
}

/// A dielectric-wall table's heat maps: the lobes at incident `(theta_i, phi_i)` (interpolated), 2 x 2: R and T
/// from outside above, from inside below; specular walls: R from outside alone (x:
/// `phi_o`, y: `theta_o`, degrees).
pub fn plot_wall_table(
    table: &WallTable,
    theta_i: f64,
    phi_i: f64,
    path: &Path,
) -> Result<(), PlotError> {
    let mut lobes = std::array::from_fn(|_| Vec::new());
    table.lobes_at(theta_i, phi_i, &mut lobes);
    let p = &table.params;
    let ((w, h), grid) = match p.walls {
        WallKind::Dielectric => ((1500u32, 1400u32), (2, 2)),
        WallKind::Specular { .. } => ((1100, 900), (1, 1)),
    };
    let walls = p.walls_label();
    let title = format!(
        "{}, {walls}, roughness {}: theta_i {:.1}, phi_i {:.1} degrees",
        p.profile.spec,
        p.roughness,
        theta_i.to_degrees(),
        phi_i.to_degrees()
    );
    let names = [
        "R from outside",
        "T outside to inside (mirrored up)",
        "R from inside (mirrored up)",
        "T inside to outside",
    ];
    render(path, (w, h), |tmp| {
        let root = BitMapBackend::new(tmp, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let root = root
            .titled(&title, ("sans-serif", 20))
            .map_err(|e| e.to_string())?;
        for (l, area) in root.split_evenly(grid).iter().enumerate() {
            let hist = &lobes[l];
            let vmax = hist.iter().cloned().fold(0.0, f64::max);
            let albedo: f64 = hist.iter().sum();
            let map = HeatMap {
                values: hist,
                n: table.params.bins,
                vmax: if vmax > 0.0 { vmax } else { 1.0 },
                caption: format!("{}: albedo {albedo:.4}", names[l]),
                y_desc: "theta_o (degrees)",
                bar_desc: "fraction per bin",
            };
            heat_panel(area, &map)?;
        }
        root.present().map_err(|e| e.to_string())
    })
}

/// The goniometer's two histograms (`striae gonio --plot`) as heat maps side by side (x: `phi_o`, y: `theta_o`, degrees), each
/// with its own colour bar saturating at its maximum; `title` heads the figure.
pub fn plot_gonio(out: &GonioOutput, title: &str, path: &Path) -> Result<(), PlotError> {
    let (w, h) = (1500u32, 720u32);
    render(path, (w, h), |tmp| {
        let root = BitMapBackend::new(tmp, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let root = root
            .titled(title, ("sans-serif", 20))
            .map_err(|e| e.to_string())?;
        let (left, right) = root.split_horizontally(w / 2);
        let panels = [
            (&left, &out.reflected, "reflected", out.albedo_r),
            (
                &right,
                &out.transmitted,
                "transmitted (inside mirrored up)",
                out.albedo_t,
            ),
        ];
        for (area, hist, name, albedo) in panels {
            let vmax = hist.iter().cloned().fold(0.0, f64::max);
            let caption = format!("{name}: albedo {albedo:.4}");
            let map = HeatMap {
                values: hist,
                n: out.bins,
                vmax: if vmax > 0.0 { vmax } else { 1.0 },
                caption: if vmax > 0.0 {
                    caption
                } else {
                    format!("{caption} (empty)")
                },
                y_desc: "theta_o (degrees)",
                bar_desc: "fraction per bin",
            };
            heat_panel(area, &map)?;
        }
        root.present().map_err(|e| e.to_string())
    })
}

/// `striae fidelity --plot`: one row of heat maps per model of `case` named in `models`: the model's lobe, the exact
/// lobe (both on the same colour scale) and `|model - exact|` (its own scale).
pub fn plot_fidelity_case(case: &Case, models: &[&str], path: &Path) -> Result<(), PlotError> {
    let rows: Vec<&ModelResult> = case
        .models
        .iter()
        .filter(|m| models.contains(&m.name.as_str()))
        .collect();
    let (pw, ph) = (560u32, 420u32);
    let (w, h) = (3 * pw, rows.len().max(1) as u32 * ph + 40);
    let title = format!(
        "{}: theta_i {} deg, phi_i {} deg (fraction of the incident energy per bin)",
        case.profile, case.theta_i_deg, case.phi_i_deg
    );
    render(path, (w, h), |tmp| {
        let root = BitMapBackend::new(tmp, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let root = root
            .titled(&title, ("sans-serif", 22))
            .map_err(|e| e.to_string())?;
        let areas = root.split_evenly((rows.len().max(1), 3));
        for (k, m) in rows.iter().enumerate() {
            let exact = if m.lossless {
                case.exact_lossless.as_ref().expect("lossless")
            } else {
                &case.exact
            };
            let diff: Vec<f64> = m
                .hist
                .iter()
                .zip(&exact.mean)
                .map(|(a, b)| (a - b).abs())
                .collect();
            let max = |v: &[f64]| v.iter().cloned().fold(1e-300, f64::max);
            let vmax = max(&m.hist).max(max(&exact.mean));
            let c = &m.cmp;
            let panels = [
                (
                    &m.hist,
                    vmax,
                    format!("{}: albedo {:.4}", m.name, c.albedo_model),
                ),
                (
                    &exact.mean,
                    vmax,
                    format!("exact: albedo {:.4}", c.albedo_exact),
                ),
                (
                    &diff,
                    max(&diff),
                    format!("|diff|: L1 {:.4}, noise {:.4}", c.l1, c.noise_l1),
                ),
            ];
            for (j, (values, vmax, caption)) in panels.into_iter().enumerate() {
                let map = HeatMap {
                    values,
                    n: exact.bins,
                    vmax,
                    caption,
                    y_desc: "theta_o (degrees)",
                    bar_desc: "fraction per bin",
                };
                heat_panel(&areas[3 * k + j], &map)?;
            }
        }
        root.present().map_err(|e| e.to_string())
    })?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::precompute::profile::Profile;
    use crate::precompute::table::TableParams;
    use crate::precompute::trace2d::{TraceSettings, Walls};

    #[test]
    fn plots_are_written_and_bad_angles_rejected() {
        let s = TraceSettings {
            walls: Walls::Diffuse,
            m: 16,
            n: 200,
            nr: 4,
            ..TraceSettings::default()
        };
        let t = ScratchTable::compute(
            &TableParams::new(Profile::parse("v:angle=90").unwrap(), s),
            &|_| {},
        )
        .unwrap();
        let dir = std::env::temp_dir().join(format!("striae-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let lobe = dir.join("lobe.png");
        plot_lobe(&t, 30.0, &lobe).unwrap();
        let img = image::open(&lobe).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (900, 520));
        // Blue lobe and red incident line are drawn.
        assert!(img.pixels().any(|p| p.0 == [0, 0, 255]));
        assert!(img.pixels().any(|p| p.0 == [255, 0, 0]));
        let heat = dir.join("heat.png");
        plot_heatmap(&t, &heat).unwrap();
        assert!(image::open(&heat).is_ok());
        assert!(matches!(
            plot_lobe(&t, 90.0, &dir.join("x.png")),
            Err(PlotError::BadAngle(_))
        ));
        assert!(!dir.join("x.png").exists());
        std::fs::remove_dir_all(&dir).ok();
    }
}
