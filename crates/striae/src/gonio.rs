//! The goniometer's outputs (`striae gonio`, METHOD.md 8.1): the `.npz` file and the plot.
//!
//! The `.npz` holds exactly `theta[B]`, `phi[B]` (bin centres, radians, over `[-pi/2, pi/2]`),
//! `reflected[B, B]` and `transmitted[B, B]` (fractions of the incident energy per
//! `[theta bin, phi bin]`, see [`crate::groove`]) and the scalars `albedo_r`, `albedo_t`.

use crate::groove::GonioOutput;
use crate::plot::{colour, render, PlotError};
use ndarray::{arr0, Array1, Array2};
use ndarray_npy::NpzWriter;
use plotters::prelude::*;
use std::path::Path;

/// Write `out` as `.npz` (atomically).
pub fn save_npz(out: &GonioOutput, path: &Path) -> std::io::Result<()> {
    let b = out.bins;
    let err = |e: ndarray_npy::WriteNpzError| std::io::Error::other(e.to_string());
    let shape =
        |v: &[f64]| Array2::from_shape_vec((b, b), v.to_vec()).map_err(std::io::Error::other);
    let (r, t) = (shape(&out.reflected)?, shape(&out.transmitted)?);
    crate::io::write_atomically(path, |tmp| {
        let file = std::fs::File::create(tmp)?;
        let mut w = NpzWriter::new(std::io::BufWriter::new(file));
        let centres = Array1::from(out.centres.clone());
        w.add_array("theta", &centres).map_err(err)?;
        w.add_array("phi", &centres).map_err(err)?;
        w.add_array("reflected", &r).map_err(err)?;
        w.add_array("transmitted", &t).map_err(err)?;
        w.add_array("albedo_r", &arr0(out.albedo_r)).map_err(err)?;
        w.add_array("albedo_t", &arr0(out.albedo_t)).map_err(err)?;
        w.finish().map_err(err)?;
        Ok(())
    })
}

/// Heat maps of the two histograms side by side (x: `phi_o`, y: `theta_o`, degrees), each
/// with its own colour bar saturating at its maximum; `title` heads the figure.
pub fn plot(out: &GonioOutput, title: &str, path: &Path) -> Result<(), PlotError> {
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
            heat_panel(area, out.bins, hist, &format!("{name}: albedo {albedo:.4}"))?;
        }
        root.present().map_err(|e| e.to_string())
    })
}

fn heat_panel(
    area: &DrawingArea<BitMapBackend, plotters::coord::Shift>,
    b: usize,
    hist: &[f64],
    caption: &str,
) -> Result<(), String> {
    let vmax = hist.iter().cloned().fold(0.0, f64::max);
    let (vmax, caption) = if vmax > 0.0 {
        (vmax, caption.to_string())
    } else {
        (1.0, format!("{caption} (empty)"))
    };
    let (pw, _) = area.dim_in_pixel();
    let (map, bar_area) = area.split_horizontally(pw - 120);
    let mut chart = ChartBuilder::on(&map)
        .caption(&caption, ("sans-serif", 18))
        .margin(15)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(-90.0..90.0f64, -90.0..90.0f64)
        .map_err(|e| e.to_string())?;
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc("phi_o (degrees)")
        .y_desc("theta_o (degrees)")
        .label_style(("sans-serif", 14))
        .axis_desc_style(("sans-serif", 16))
        .draw()
        .map_err(|e| e.to_string())?;
    let bw = 180.0 / b as f64;
    chart
        .draw_series((0..b * b).map(|k| {
            let (i, j) = (k / b, k % b);
            let (x0, y0) = (-90.0 + j as f64 * bw, -90.0 + i as f64 * bw);
            Rectangle::new(
                [(x0, y0), (x0 + bw, y0 + bw)],
                colour(hist[k] / vmax).filled(),
            )
        }))
        .map_err(|e| e.to_string())?;
    let mut bar = ChartBuilder::on(&bar_area)
        .margin_top(50)
        .margin_bottom(60)
        .margin_right(10)
        .y_label_area_size(85)
        .build_cartesian_2d(0.0..1.0f64, 0.0..vmax)
        .map_err(|e| e.to_string())?;
    bar.configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_label_formatter(&|v| format!("{v:.2e}"))
        .y_desc("fraction per bin")
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::groove::{trace_groove, GonioSettings, GrooveWalls};
    use crate::profile::Profile;
    use ndarray::{Array0, Ix0};
    use ndarray_npy::NpzReader;

    #[test]
    fn npz_holds_exactly_the_documented_arrays_and_the_plot_is_drawn() {
        let s = GonioSettings {
            walls: GrooveWalls::Dielectric,
            theta_i: 0.3,
            phi_i: 0.2,
            paths: 5000,
            bins: 6,
            ..GonioSettings::default()
        };
        let out = trace_groove(&Profile::parse("v:angle=90").unwrap(), &s, &|_| {}).unwrap();
        let dir = std::env::temp_dir().join(format!("striae-gonio-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("g.npz");
        save_npz(&out, &path).unwrap();
        let mut r = NpzReader::new(std::fs::File::open(&path).unwrap()).unwrap();
        let mut names = r.names().unwrap();
        names.sort();
        assert_eq!(
            names,
            [
                "albedo_r",
                "albedo_t",
                "phi",
                "reflected",
                "theta",
                "transmitted"
            ]
        );
        let theta: Array1<f64> = r.by_name("theta").unwrap();
        assert_eq!(theta.to_vec(), out.centres);
        let refl: Array2<f64> = r.by_name("reflected").unwrap();
        assert_eq!(refl.dim(), (6, 6));
        assert_eq!(refl.iter().cloned().collect::<Vec<_>>(), out.reflected);
        let a: Array0<f64> = r
            .by_name::<ndarray::OwnedRepr<f64>, Ix0>("albedo_t")
            .unwrap();
        assert_eq!(a.into_scalar(), out.albedo_t);
        let png = dir.join("g.png");
        plot(&out, "test", &png).unwrap();
        let img = image::open(&png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (1500, 720));
        std::fs::remove_dir_all(&dir).ok();
    }
}
