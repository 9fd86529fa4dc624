//! `striae hologram`: the arcs of a scratch hologram (METHOD.md 9.3-9.4) for the points of an
//! OBJ or CSV file, written as an SVG drawing (`striae::lab::hologram`, docs/hologram.md).
//!
//! Everything is read, checked and drawn in memory first; the SVG is then written atomically,
//! so a bad input leaves no file behind.

use anyhow::{bail, Context, Result};
use std::path::PathBuf;
use striae::lab::hologram::{self, HologramError, HologramParams, Plate};

#[derive(clap::Args)]
pub struct Args {
    /// The points: a .obj file (its `v` lines) or a .csv file (columns x,y,z, an optional
    /// header line). The plate is z = 0; z > 0 is in front of it (toward the viewer), z < 0
    /// behind.
    points: PathBuf,
    /// Output SVG: one arc per point; its viewBox (the plate) maps onto texture space,
    /// u = (x - X0) / SX, v = (y - Y0) / SY.
    #[arg(short, long)]
    output: PathBuf,
    /// The drawing's rectangle X0,Y0,SX,SY in the points' units (default: the box of the
    /// points and their arcs, with a margin of 5% of its larger side).
    #[arg(long, value_parser = parse_plate, allow_hyphen_values = true)]
    plate: Option<Plate>,
    /// The design view angle from the plate's normal, in (0, 90) degrees, with the light at
    /// the normal: each arc's radius is tan(angle) times its point's distance from the plate.
    #[arg(long, default_value_t = hologram::DEFAULT_VIEW_ANGLE, conflicts_with = "scale")]
    view_angle: f64,
    /// The arcs' radius over their points' distance from the plate, instead of
    /// tan(--view-angle).
    #[arg(long)]
    scale: Option<f64>,
    /// The range of view azimuths, in (0, 360] degrees, over which each point is seen: the
    /// angle each arc covers.
    #[arg(long, default_value_t = hologram::DEFAULT_SPAN)]
    span: f64,
    /// The design azimuth: the direction on the plate toward the viewer, in degrees from +x
    /// toward +y (90: +y, the bottom of the drawing as an image shows it).
    #[arg(long, default_value_t = hologram::DEFAULT_AZIMUTH)]
    azimuth: f64,
    /// Stroke width in drawing units (default: 1/400 of the larger side of the box of the
    /// points and their arcs).
    #[arg(long)]
    width: Option<f64>,
}

/// `X0,Y0,SX,SY`: four numbers; their ranges are checked with the other parameters.
fn parse_plate(text: &str) -> Result<Plate, String> {
    let bad = || format!("`{text}`: expected X0,Y0,SX,SY (four numbers), e.g. 0,0,10,10");
    let v: Vec<f64> = text
        .split(',')
        .map(|w| w.trim().parse::<f64>().map_err(|_| bad()))
        .collect::<Result<_, _>>()?;
    match v[..] {
        [x0, y0, size_x, size_y] => Ok(Plate {
            x0,
            y0,
            size_x,
            size_y,
        }),
        _ => Err(bad()),
    }
}

/// A bad parameter named by its flag: `--view-angle 95: ...`, `--plate: plate size_x = 0: ...`.
fn flag_error(e: HologramError) -> anyhow::Error {
    match e {
        HologramError::Param { name, value, why } => match name {
            "view_angle" | "scale" | "span" | "azimuth" | "width" => {
                anyhow::anyhow!("--{} {value}: {why}", name.replace('_', "-"))
            }
            _ => anyhow::anyhow!("--plate: {name} = {value}: {why}"),
        },
        e => e.into(),
    }
}

pub fn run(a: Args) -> Result<()> {
    let params = HologramParams {
        plate: a.plate,
        view_angle: a.view_angle,
        scale: a.scale,
        span: a.span,
        azimuth: a.azimuth,
        width: a.width,
    };
    params.validate().map_err(flag_error)?;
    super::check_output_file("-o", &a.output)?;
    if striae::io::same_file(&a.points, &a.output) {
        bail!(
            "-o {} is the points file itself; refusing to overwrite it",
            a.output.display()
        );
    }
    let points = hologram::read_points(&a.points)?;
    let h = hologram::hologram(&points, &params)?;
    let svg = h.to_svg();
    striae::io::write_atomically(&a.output, |tmp| std::fs::write(tmp, &svg))
        .with_context(|| format!("could not write {}", a.output.display()))?;
    if h.outside > 0 {
        eprintln!(
            "striae: warning: {} of {} arcs reach outside the plate --plate {},{},{},{}",
            h.outside,
            h.arcs.len(),
            h.plate.x0,
            h.plate.y0,
            h.plate.size_x,
            h.plate.size_y
        );
    }
    let p = h.plate;
    println!(
        "wrote {} arcs to {}: plate {},{},{},{} (X0,Y0,SX,SY), scale {}, stroke width {}",
        h.arcs.len(),
        a.output.display(),
        p.x0,
        p.y0,
        p.size_x,
        p.size_y,
        h.scale,
        h.width
    );
    Ok(())
}
