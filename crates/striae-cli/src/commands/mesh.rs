//! `striae mesh teapot -o teapot.obj`: write a built-in mesh as Wavefront OBJ, exactly as a
//! scene tessellates it (same `subdivisions`, same z-up to y-up turn), so another renderer
//! (Mitsuba 3 in `validation/`) can load the very triangles striae renders.

use anyhow::Context;
use std::fmt::Write as _;
use std::path::PathBuf;
use striae::geometry::{Transform, TriangleMesh};
use striae::math::Vec3;

#[derive(clap::Args)]
pub struct Args {
    /// Which built-in mesh: `teapot`.
    pub mesh: String,
    /// Segments per Bezier patch side (as the scene key `subdivisions`).
    #[arg(long, default_value_t = 8)]
    pub subdivisions: u32,
    /// Leave out vertex normals (flat shading in both renderers).
    #[arg(long)]
    pub flat: bool,
    /// Output OBJ file.
    #[arg(short = 'o', long)]
    pub output: PathBuf,
}

pub fn run(args: Args) -> anyhow::Result<()> {
    let mesh = match args.mesh.as_str() {
        "teapot" => {
            if !(1..=64).contains(&args.subdivisions) {
                anyhow::bail!("--subdivisions {} must lie in 1..=64", args.subdivisions);
            }
            let z_up_to_y_up = Transform::rotate(Vec3::X, -90.0)?;
            TriangleMesh::teapot(args.subdivisions).transformed(&z_up_to_y_up)
        }
        other => anyhow::bail!("unknown built-in mesh `{other}` (known: teapot)"),
    };
    let text = to_obj(&mesh, !args.flat);
    striae::io::write_atomically(&args.output, |p| std::fs::write(p, &text))
        .with_context(|| format!("writing {}", args.output.display()))?;
    println!("wrote {} ({} triangles)", args.output.display(), mesh.triangle_count());
    Ok(())
}

/// OBJ text with positions, uvs and (optionally) normals; indices are 1-based.
fn to_obj(mesh: &TriangleMesh, normals: bool) -> String {
    let mut s = String::from("# written by striae mesh\n");
    for p in mesh.positions() {
        let _ = writeln!(s, "v {:.9} {:.9} {:.9}", p.x, p.y, p.z);
    }
    let uvs = mesh.uvs();
    if let Some(uvs) = uvs {
        for t in uvs {
            let _ = writeln!(s, "vt {:.9} {:.9}", t.x, t.y);
        }
    }
    let ns = if normals { mesh.normals() } else { None };
    if let Some(ns) = ns {
        for n in ns {
            let _ = writeln!(s, "vn {:.9} {:.9} {:.9}", n.x, n.y, n.z);
        }
    }
    for f in mesh.indices() {
        let [a, b, c] = f.map(|i| i + 1);
        let _ = match (uvs.is_some(), ns.is_some()) {
            (true, true) => writeln!(s, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}"),
            (true, false) => writeln!(s, "f {a}/{a} {b}/{b} {c}/{c}"),
            (false, true) => writeln!(s, "f {a}//{a} {b}//{b} {c}//{c}"),
            (false, false) => writeln!(s, "f {a} {b} {c}"),
        };
    }
    s
}
