//! The scratched material's scene keys: defaults, and errors naming the key and the value.

use super::*;
use crate::render::scene::materials::MaterialDesc;

fn parse(text: &str) -> Result<ScratchedDesc, String> {
    let m: MaterialDesc = toml::from_str(text).map_err(|e| e.to_string())?;
    m.validate(std::path::Path::new("."))
        .map_err(|e| e.to_string())?;
    match m {
        MaterialDesc::Scratched(s) => Ok(s),
        _ => Err("not scratched".into()),
    }
}

/// The parameters of the table a valid material computes.
fn computed(text: &str) -> TableParams {
    match parse(text).unwrap().resolve(Path::new(".")).unwrap().table {
        TableSource::Compute(p) => p,
        other => panic!("{other:?}"),
    }
}

#[test]
fn keys_are_validated() {
    let ok = parse("type = \"scratched\"\nbase = \"glass\"\nior = 1.5\n[scratches]\nsetting = 2\nlayers = 3\nlayer_mix = \"sum\"\nm = 16").unwrap();
    let r = ok.resolve(Path::new(".")).unwrap();
    assert_eq!(
        r.layers,
        LayerParams {
            layers: 3,
            ..LayerParams::setting(2).unwrap()
        }
    );
    assert_eq!(
        (r.mix, r.coverage, r.orientation),
        (LayerMix::Sum, CoverageMode::Footprint, Orientation::Layer)
    );
    let random =
        parse("type = \"scratched\"\nbase = \"glass\"\n[scratches]\norientation = \"random\"")
            .unwrap()
            .resolve(Path::new("."))
            .unwrap();
    assert_eq!(random.orientation, Orientation::Random);
    // Dielectric walls: the glass's index, the walls' roughness, the trace seed.
    let walls = parse("type = \"scratched\"\nbase = \"glass\"\nior = 1.4\n[scratches]\nwalls = \"dielectric\"\nroughness = 0.25\ntrace_seed = 7")
        .unwrap()
        .resolve(Path::new("."))
        .unwrap();
    let TableSource::Walls(w) = walls.table else {
        panic!("{:?}", walls.table)
    };
    assert_eq!((w.ior, w.roughness, w.seed), (1.4f32 as f64, 0.25, 7));
    // Smooth walls: traced with no table, by default or asked for; a table where asked for.
    let smooth = |lobes: &str| {
        parse(&format!(
            "type = \"scratched\"\nbase = \"glass\"\n[scratches]\nwalls = \"dielectric\"\n{lobes}"
        ))
        .unwrap()
        .resolve(Path::new("."))
        .unwrap()
        .table
    };
    for lobes in ["", "lobes = \"traced\""] {
        let TableSource::Traced(w) = smooth(lobes) else {
            panic!("{lobes}: {:?}", smooth(lobes))
        };
        assert_eq!((w.ior, w.roughness), (1.5, 0.0));
    }
    let TableSource::Walls(w) = smooth("lobes = \"table\"") else {
        panic!("{:?}", smooth("lobes = \"table\""))
    };
    assert_eq!((w.ior, w.roughness), (1.5, 0.0));
    let TableSource::Compute(p) = r.table else {
        panic!()
    };
    assert_eq!(
        (p.trace.m, p.trace.walls, p.trace.fresnel_law),
        (16, Walls::Diffuse, FresnelLaw::Schlick { n: 1.5 })
    );
    // A metal's rough walls: a specular-wall table with the law its mirror walls take, the
    // trace seed; roughness 0 leaves the seed's mirror-wall table exactly as without the key.
    let metal = "type = \"scratched\"\nbase = \"metal\"\npreset = \"gold\"\n[scratches]\nprofile = \"round:depth=0.3\"";
    let mirror = computed(metal);
    assert_eq!(computed(&format!("{metal}\nroughness = 0.0")), mirror);
    assert_eq!(
        computed(&format!("{metal}\nwalls = \"specular\"\nroughness = 0")).hash(),
        mirror.hash()
    );
    let rough = parse(&format!("{metal}\nroughness = 0.3\ntrace_seed = 4"))
        .unwrap()
        .resolve(Path::new("."))
        .unwrap();
    let TableSource::Walls(w) = rough.table else {
        panic!("{:?}", rough.table)
    };
    assert_eq!(
        (w.walls, w.roughness, w.seed),
        (
            crate::precompute::wall_table::WallKind::Specular {
                law: mirror.trace.fresnel_law
            },
            0.3,
            4
        )
    );
    assert!(matches!(
        mirror.trace.fresnel_law,
        FresnelLaw::Conductor { .. }
    ));
    // Metal defaults: mirror walls, Fresnel at the walls, the base's law; `none` for F = 1.
    let r = parse("type = \"scratched\"\nbase = \"metal\"\npreset = \"none\"")
        .unwrap()
        .resolve(Path::new("."))
        .unwrap();
    let TableSource::Compute(p) = r.table else {
        panic!()
    };
    assert_eq!(
        (p.trace.walls, p.trace.fresnel_mode, p.trace.fresnel_law),
        (Walls::Specular, FresnelMode::Walls, FresnelLaw::None)
    );
    assert_eq!(r.tint, Rgb::ONE);
    let r = parse("type = \"scratched\"\nbase = \"metal\"\npreset = \"gold\"")
        .unwrap()
        .resolve(Path::new("."))
        .unwrap();
    assert!(r.tint.x == 1.0 && r.tint.z < 0.6, "{:?}", r.tint);
    // Exact-groove slices: `fresnel` defaults to `walls`; explicit grooves refuse them.
    let p = computed("type = \"scratched\"\nbase = \"glass\"\n[scratches]\ngroove_slices = 6");
    assert_eq!(
        (p.trace.groove_slices, p.trace.fresnel_mode),
        (6, FresnelMode::Walls)
    );
    let e = parse("type = \"scratched\"\nbase = \"metal\"\npreset = \"gold\"\n[scratches]\nwalls = \"diffuse\"\ngroove_slices = 4\nexplicit = true")
        .unwrap()
        .explicit(Path::new("."))
        .unwrap_err()
        .to_string();
    assert!(e.contains("`scratches.groove_slices`"), "{e}");
    let e = parse("type = \"scratched\"\nbase = \"metal\"\npreset = \"gold\"\n[scratches]\nroughness = 0.2\nexplicit = true")
        .unwrap()
        .explicit(Path::new("."))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("`scratches.explicit`") && e.contains("roughness"),
        "{e}"
    );
    let cases: &[(&str, &[&str])] = &[
        ("base = \"wood\"", &["`base`", "wood"]),
        ("base = \"glass\"\nior = 0.5", &["`ior`", "0.5"]),
        (
            "base = \"glass\"\npreset = \"gold\"",
            &["`preset`", "metal"],
        ),
        (
            "base = \"metal\"\nior = 1.5\npreset = \"gold\"",
            &["`ior`", "glass"],
        ),
        (
            "base = \"metal\"\npreset = \"unobtainium\"",
            &["unobtainium"],
        ),
        (
            "base = \"glass\"\n[scratches]\nm = 0",
            &["`scratches.m`", "0"],
        ),
        (
            "base = \"glass\"\n[scratches]\nsetting = 3",
            &["`scratches.setting`", "3"],
        ),
        (
            "base = \"glass\"\n[scratches]\nsetting = 1\nwidth = 0.1",
            &["`scratches.setting`", "excludes"],
        ),
        (
            "base = \"glass\"\n[scratches]\nlength = 0.1",
            &["`scratches.length`"],
        ),
        (
            "base = \"glass\"\n[scratches]\nlength = 0.1\nwidth = -1\nthreshold = 0.1",
            &["`scratches.width`", "-1"],
        ),
        (
            "base = \"glass\"\n[scratches]\nlayers = 0",
            &["`scratches.layers`"],
        ),
        (
            "base = \"glass\"\n[scratches]\nlayers = 65",
            &["`scratches.layers`", "65"],
        ),
        (
            "base = \"glass\"\n[scratches]\nprofile = \"zigzag\"",
            &["`scratches.profile`", "zigzag"],
        ),
        (
            "base = \"glass\"\n[scratches]\nior = 0.5",
            &["`scratches.ior`", "0.5", ">= 1"],
        ),
        (
            "base = \"glass\"\n[scratches]\nfresnel_law = \"fancy\"",
            &["`scratches.fresnel_law`", "fancy"],
        ),
        (
            "base = \"glass\"\n[scratches]\ntable = \"t.npz\"\nm = 64",
            &["`scratches.m`", "table"],
        ),
        (
            "base = \"glass\"\n[scratches]\nlayer_mix = \"avg\"",
            &["`scratches.layer_mix`", "avg"],
        ),
        (
            "base = \"glass\"\n[scratches]\nwalls = \"rough\"",
            &["`scratches.walls`", "rough"],
        ),
        (
            "base = \"glass\"\n[scratches]\nwalls = \"dielectric\"\nlobes = \"exact\"",
            &["`scratches.lobes`", "exact"],
        ),
        (
            "base = \"glass\"\n[scratches]\nwalls = \"dielectric\"\nroughness = 0.2\nlobes = \"traced\"",
            &["`scratches.lobes`", "smooth walls"],
        ),
        (
            "base = \"glass\"\n[scratches]\nlobes = \"traced\"",
            &["`scratches.lobes`", "dielectric"],
        ),
        (
            "base = \"glass\"\n[scratches]\ntable = \"t.npz\"\nlobes = \"table\"",
            &["`scratches.lobes`", "table"],
        ),
        (
            "base = \"glass\"\n[scratches]\nfresnel = \"exact\"",
            &["`scratches.fresnel`", "exact"],
        ),
        (
            "base = \"glass\"\n[scratches]\ncoverage = \"pixel\"",
            &["`scratches.coverage`", "pixel"],
        ),
        (
            "base = \"glass\"\n[scratches]\norientation = \"spiral\"",
            &["`scratches.orientation`", "spiral"],
        ),
        (
            "base = \"glass\"\n[scratches]\ngroove_slices = 0",
            &["`scratches.groove_slices`", "0", "1..=32"],
        ),
        (
            "base = \"glass\"\n[scratches]\ngroove_slices = 33",
            &["`scratches.groove_slices`", "33", "0..=32"],
        ),
        (
            "base = \"metal\"\npreset = \"gold\"\n[scratches]\ngroove_slices = 6",
            &["`scratches.groove_slices`", "6", "diffuse walls"],
        ),
        (
            "base = \"glass\"\n[scratches]\ngroove_slices = 6\nfresnel = \"seed\"",
            &["`scratches.fresnel`", "seed", "fresnel = walls"],
        ),
        (
            "base = \"glass\"\n[scratches]\ngroove_slices = 6\nalbedo = 0.5",
            &["`scratches.albedo`", "0.5"],
        ),
        (
            "base = \"glass\"\n[scratches]\ngroove_slices = 6\nm = 2048",
            &["`scratches.m`", "2048", "groove_slices"],
        ),
        (
            "base = \"glass\"\n[scratches]\nwalls = \"dielectric\"\ngroove_slices = 6",
            &["`scratches.groove_slices`", "dielectric"],
        ),
        (
            "base = \"glass\"\n[scratches]\ntable = \"t.npz\"\ngroove_slices = 6",
            &["`scratches.groove_slices`", "table"],
        ),
        ("base = \"glass\"\n[scratches]\nfoo = 1", &["foo"]),
        (
            "base = \"metal\"\npreset = \"gold\"\n[scratches]\nwalls = \"dielectric\"",
            &["`scratches.walls`", "glass"],
        ),
        (
            "base = \"glass\"\n[scratches]\nwalls = \"dielectric\"\nroughness = 1.5",
            &["`scratches.roughness`", "1.5"],
        ),
        (
            "base = \"glass\"\n[scratches]\nwalls = \"dielectric\"\nroughness = -0.1",
            &["`scratches.roughness`", "-0.1"],
        ),
        (
            "base = \"glass\"\n[scratches]\nroughness = 0.2",
            &["`scratches.roughness`", "dielectric"],
        ),
        (
            "base = \"glass\"\n[scratches]\nwalls = \"dielectric\"\nm = 64",
            &["`scratches.m`", "dielectric"],
        ),
        (
            "base = \"glass\"\n[scratches]\nwalls = \"dielectric\"\nfresnel_law = \"schlick\"",
            &["`scratches.fresnel_law`", "dielectric"],
        ),
        ("base = \"glass\"\nroughness = 0.1", &["roughness"]),
        // A metal's rough walls: specular walls only, in [0, 1], no 2D-table keys, no carving.
        (
            "base = \"metal\"\npreset = \"gold\"\n[scratches]\nwalls = \"diffuse\"\nroughness = 0.2",
            &["`scratches.roughness`", "0.2", "specular"],
        ),
        (
            "base = \"metal\"\npreset = \"gold\"\n[scratches]\nwalls = \"diffuse\"\nroughness = 0",
            &["`scratches.roughness`", "specular"],
        ),
        (
            "base = \"glass\"\n[scratches]\nwalls = \"specular\"\nroughness = 0.2",
            &["`scratches.roughness`", "metal"],
        ),
        (
            "base = \"metal\"\npreset = \"gold\"\n[scratches]\nwalls = \"specular\"\nroughness = 1.5",
            &["`scratches.roughness`", "1.5", "[0, 1]"],
        ),
        (
            "base = \"metal\"\npreset = \"gold\"\n[scratches]\nroughness = -0.1",
            &["`scratches.roughness`", "-0.1"],
        ),
        (
            "base = \"metal\"\npreset = \"gold\"\n[scratches]\nroughness = nan",
            &["`scratches.roughness`", "NaN"],
        ),
        (
            "base = \"metal\"\npreset = \"gold\"\n[scratches]\nroughness = 0.2\nm = 64",
            &["`scratches.m`", "rough specular walls"],
        ),
        (
            "base = \"metal\"\npreset = \"gold\"\n[scratches]\nroughness = 0.2\nfresnel = \"seed\"",
            &["`scratches.fresnel`", "rough specular walls"],
        ),
        (
            "base = \"metal\"\npreset = \"gold\"\n[scratches]\nroughness = 0.2\nfresnel_law = \"bogus\"",
            &["`scratches.fresnel_law`", "bogus"],
        ),
    ];
    for (body, needles) in cases {
        let src = format!("type = \"scratched\"\n{body}");
        let e = parse(&src).expect_err(&src);
        for n in *needles {
            assert!(e.contains(n), "error for {src:?} should mention {n:?}: {e}");
        }
    }
}

/// A specular-wall table file (rough metal walls) fits a metal base, not glass.
#[test]
fn specular_wall_table_files_need_a_metal_base() {
    use crate::precompute::wall_table::WallTable;
    let dir = std::env::temp_dir().join(format!("striae-spec-file-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let params = WallTableParams {
        theta_bins: 2,
        phi_bins: 2,
        bins: 4,
        paths: 200,
        ..WallTableParams::specular(Profile::parse("v:angle=90").unwrap(), FresnelLaw::None, 0.2)
    };
    WallTable::compute(&params)
        .unwrap()
        .save(&dir.join("s.npz"))
        .unwrap();
    let material = |base: &str| {
        parse(&format!(
            "type = \"scratched\"\n{base}\n[scratches]\ntable = \"s.npz\"\nlayers = 1"
        ))
        .unwrap()
        .prepare(&dir)
    };
    let m = material("base = \"metal\"\npreset = \"gold\"").unwrap();
    assert!(matches!(m.model, ScratchModel::SpecularWalls(_)));
    let e = material("base = \"glass\"").unwrap_err().to_string();
    assert!(
        e.contains("`scratches.table`") && e.contains("metal"),
        "{e}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
