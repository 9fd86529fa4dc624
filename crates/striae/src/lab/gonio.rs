//! The goniometer's output (`striae gonio`, METHOD.md 8.1): the `.npz` file (its plot is
//! [`crate::lab::plot::plot_gonio`]).
//!
//! The `.npz` holds exactly `theta[B]`, `phi[B]` (bin centres, radians, over `[-pi/2, pi/2]`),
//! `reflected[B, B]` and `transmitted[B, B]` (fractions of the incident energy per
//! `[theta bin, phi bin]`, see [`crate::precompute::groove`]) and the scalars `albedo_r`, `albedo_t`.

use crate::precompute::groove::GonioOutput;
use ndarray::{arr0, Array1, Array2};
use ndarray_npy::NpzWriter;
use std::path::Path;

/// The memory a goniometer run of `paths` paths with `bins` bins per angle takes on `threads`
/// threads, per bin of the `bins x bins` grid: up to 5 accumulators a busy thread alive at
/// once (16 bytes each: a reflected and a transmitted count; `trace_groove` makes at most
/// about 4 work items a thread, of 4096 paths or more), the output's fractions (16) and their
/// copies for the `.npz` (16). The bound, not a fit: `striae gonio --bins 2048 --paths 2000000`
/// peaks at 167 MB resident, 344 MB of address space (`VmPeak`) on 1 thread, 263 and 608 MB
/// on 2 (the estimate: 470 and 805 MB).
pub fn memory_estimate(bins: usize, threads: usize, paths: u64) -> u64 {
    let busy = (threads as u64).min(paths.div_ceil(4096)).max(1);
    let cells = bins as u64 * bins as u64;
    cells.saturating_mul(32 + 80 * busy)
}

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
        if let Some(k) = out.intercept {
            w.add_array("intercept", &arr0(k)).map_err(err)?;
        }
        w.finish().map_err(err)?;
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::precompute::groove::{trace_groove, GonioSettings, GrooveWalls};
    use crate::precompute::profile::Profile;
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
        crate::lab::plot::plot_gonio(&out, "test", &png).unwrap();
        let img = image::open(&png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (1500, 720));
        std::fs::remove_dir_all(&dir).ok();
    }
}
