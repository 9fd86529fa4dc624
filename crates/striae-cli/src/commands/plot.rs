//! `striae plot`: a polar lobe for one incident angle (the seed's Fig. 2) or a heat map of a
//! scratch BRDF table.

use anyhow::Context;
use std::path::PathBuf;
use striae::precompute::table::ScratchTable;

#[derive(clap::Args)]
pub struct Args {
    /// The table (.npz) written by `striae precompute`.
    table: PathBuf,
    /// Incident angle phi_i in degrees for the polar lobe plot.
    #[arg(long, default_value_t = 30.0, allow_hyphen_values = true)]
    phi_i: f64,
    /// Incident angle theta_i in degrees (dielectric-wall tables: their R and T lobes at
    /// (theta_i, phi_i)).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    theta_i: f64,
    /// Plot the whole rho_m table as a heat map instead of one lobe.
    #[arg(long)]
    heatmap: bool,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(a: Args) -> anyhow::Result<()> {
    striae::lab::plot::check_png_name(&a.output).map_err(|e| anyhow::anyhow!("-o {e}"))?;
    super::check_output_file("-o", &a.output)?;
    if striae::io::same_file(&a.table, &a.output) {
        anyhow::bail!(
            "-o {} would overwrite the table it plots",
            a.output.display()
        );
    }
    let walls = striae::precompute::wall_table::WallTable::load(&a.table)
        .with_context(|| format!("loading {}", a.table.display()))?;
    if let Some(walls) = walls {
        striae::lab::plot::plot_wall_table(
            &walls,
            a.theta_i.to_radians(),
            a.phi_i.to_radians(),
            &a.output,
        )?;
        println!("wrote {}", a.output.display());
        return Ok(());
    }
    let table =
        ScratchTable::load(&a.table).with_context(|| format!("loading {}", a.table.display()))?;
    if a.heatmap {
        striae::lab::plot::plot_heatmap(&table, &a.output)?;
    } else {
        striae::lab::plot::plot_lobe(&table, a.phi_i, &a.output)?;
    }
    println!("wrote {}", a.output.display());
    Ok(())
}
