//! `striae`: the command line. Each subcommand lives in `commands/`; this file only parses.

mod commands;
mod preview;
mod tev;

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(
    name = "striae",
    version,
    about = "Scratched glass and metal: scratch BRDF precompute, scratch layers and a path tracer"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// Every subcommand takes negative numbers as values, not flags: `--spp -1` is reported as a
/// bad `--spp`, not as an unexpected argument `-1`.
#[derive(Subcommand)]
enum Command {
    /// Precompute the BRDF table of one scratch profile by 2D ray tracing (METHOD.md 2-4).
    #[command(allow_negative_numbers = true)]
    Precompute(commands::precompute::Args),
    /// Plot a scratch BRDF table: a polar lobe for one incident angle, or a heat map.
    #[command(allow_negative_numbers = true)]
    Plot(commands::plot::Args),
    /// Generate scratch layers from Worley cell noise and write them as images (METHOD.md 5).
    #[command(allow_negative_numbers = true)]
    Layers(commands::layers::Args),
    /// Render a scene file (or the built-in default scene) to EXR and PNG.
    #[command(allow_negative_numbers = true)]
    Render(commands::render::Args),
    /// Merge the part files of one render (`render --tile I/N`, `--samples A..B`) into its EXR and PNG.
    Merge(commands::merge::Args),
    /// Regenerate the seed's figures (Fig. 2, 4, 6, 7, 8a) as PNGs plus an index.html.
    #[command(allow_negative_numbers = true)]
    Figures(commands::figures::Args),
    /// The exact BSDF of an extruded groove by 2.5D tracing: a virtual gonioreflectometer
    /// (METHOD.md 8.1).
    #[command(allow_negative_numbers = true)]
    Gonio(commands::gonio::Args),
    /// The scratch model's 3D BRDF against the exact groove: L1 and albedo errors, noise,
    /// heat maps (docs/fidelity.md).
    Fidelity(commands::fidelity::Args),
    /// The arcs of a scratch hologram for the points of an OBJ or CSV file, as an SVG
    /// (METHOD.md 9.4, docs/hologram.md).
    #[command(allow_negative_numbers = true)]
    Hologram(commands::hologram::Args),
}

fn main() {
    let cli = Cli::parse();
    // Ctrl-C or SIGTERM: remove the temporary files and folders being written, so an
    // interrupted command leaves nothing behind, then exit as interrupted (128 + SIGINT).
    if let Err(e) = ctrlc::set_handler(|| {
        striae::io::remove_temporaries();
        std::process::exit(130);
    }) {
        eprintln!(
            "warning: no signal handler ({e}); an interrupted command may leave temporary files"
        );
    }
    commands::print_library_messages(false);
    let result = match cli.command {
        Command::Precompute(a) => commands::precompute::run(a),
        Command::Plot(a) => commands::plot::run(a),
        Command::Layers(a) => commands::layers::run(a),
        Command::Render(a) => commands::render::run(a),
        Command::Merge(a) => commands::merge::run(a),
        Command::Figures(a) => commands::figures::run(a),
        Command::Gonio(a) => commands::gonio::run(a),
        Command::Fidelity(a) => commands::fidelity::run(a),
        Command::Hologram(a) => commands::hologram::run(a),
    };
    if let Err(e) = result {
        eprintln!("error: {e:#}");
        std::process::exit(1);
    }
}
