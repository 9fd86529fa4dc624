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
            "base = \"glass\"\n[scratches]\nmodel = \"exact\"",
            &["`scratches.model`", "exact", "seed", "default"],
        ),
        (
            "base = \"glass\"\n[scratches]\nmodel = 1",
            &["`scratches.model`"],
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

/// The resolved settings of a material's text (`[scratches]` body after `base`).
fn resolved(base: &str, scratches: &str) -> Resolved {
    parse(&format!(
        "type = \"scratched\"\n{base}\n[scratches]\n{scratches}"
    ))
    .unwrap()
    .resolve(Path::new("."))
    .unwrap()
}

fn trace_of(r: &Resolved) -> &TraceSettings {
    match &r.table {
        TableSource::Compute(p) => &p.trace,
        other => panic!("{other:?}"),
    }
}

/// `model = "seed"` is the seed's model, key by key as METHOD.md sections 3-6 state it (not as
/// the code's defaults say): a 90-degree V groove, Lambertian walls (section 3, the seed's
/// glass), M 256, N 10000, N_r 100 (section 3), facet albedo 1, one Schlick factor a path
/// with n 1.50 (eq. 2) on three theta slices blended by eq. (3)-(4) (no exact-groove
/// slices), Table 1's setting 1 (L 0.3, W 0.001, tau 0.1) in 8 layers of one direction each
/// (section 5), the largest layer (section 6), the footprint's coverage (section 6) and the
/// extruded groove (no lean, 8.3). A metal base: [Raymond16]'s mirror walls, Fresnel at every
/// hit.
#[test]
fn model_seed_is_the_seeds_model() {
    let glass = "base = \"glass\"";
    for model in [
        "model = \"seed\"",
        "model = \"seed\"\nsetting = 1\nlayers = 8",
    ] {
        let r = resolved(glass, model);
        assert_eq!(r.model, ModelKey::Seed);
        let TableSource::Compute(p) = &r.table else {
            panic!("{:?}", r.table)
        };
        assert_eq!(p.profile.spec, "v:angle=90");
        let t = &p.trace;
        assert_eq!(t.walls, Walls::Diffuse);
        assert_eq!((t.m, t.n, t.nr), (256, 10_000, 100));
        assert_eq!(t.albedo, 1.0);
        assert_eq!(t.fresnel_mode, FresnelMode::Seed);
        assert_eq!(t.fresnel_law, FresnelLaw::Schlick { n: 1.5 });
        assert_eq!(t.groove_slices, 0);
        assert_eq!(
            (
                r.layers.length,
                r.layers.width,
                r.layers.threshold,
                r.layers.layers
            ),
            (0.3, 0.001, 0.1, 8)
        );
        assert_eq!(r.orientation, Orientation::Layer);
        assert_eq!(r.mix, LayerMix::Max);
        assert_eq!(r.coverage, CoverageMode::Footprint);
        assert_eq!(r.base, ScratchedBase::Glass { eta: 1.5 });
        let m = parse(&format!("type = \"scratched\"\n{glass}\n[scratches]\nmodel = \"seed\"\nlayers = 1\nm = 8\nn = 50\nnr = 2"))
            .unwrap()
            .prepare(Path::new("."))
            .unwrap();
        assert!(!m.has_lean());
    }
    // Setting 2 of Table 1: L 0.6, W 0.010, tau 0.1.
    let r = resolved(glass, "model = \"seed\"\nsetting = 2");
    assert_eq!(
        (r.layers.length, r.layers.width, r.layers.threshold),
        (0.6, 0.010, 0.1)
    );
    let r = resolved("base = \"metal\"\npreset = \"gold\"", "model = \"seed\"");
    let t = trace_of(&r);
    assert_eq!(
        (t.walls, t.fresnel_mode, t.groove_slices, t.m, t.n),
        (Walls::Specular, FresnelMode::Walls, 0, 256, 10_000)
    );
    assert_eq!(r.mix, LayerMix::Max);
    // The seed's model is what a shipped seed scene spells out key by key.
    let spelt = "profile = \"v:angle=90\"\nwalls = \"diffuse\"\nfresnel = \"seed\"\nfresnel_law = \"schlick\"\nm = 256\nn = 10000\nnr = 100\nsetting = 1\nlayers = 8\nseed = 1\nlayer_mix = \"max\"";
    let (a, b) = (resolved(glass, "model = \"seed\""), resolved(glass, spelt));
    assert_eq!(trace_of(&a), trace_of(&b));
    assert_eq!(
        (a.mix, a.layers, a.layer_seed),
        (b.mix, b.layers, b.layer_seed)
    );
}

/// The defaults (`model` left out, or `"default"`) are docs/fidelity.md's "The defaults":
/// glass with diffuse walls and a Fresnel law takes 6 exact-groove slices, `fresnel =
/// "walls"`, M 64, N 50000, N_r 1; layers combine by `layer_mix = "stochastic"`; everything
/// else is the seed's (the footprint, a direction per layer, a metal's mirror walls).
#[test]
fn the_defaults_are_the_documented_ones() {
    let glass = "base = \"glass\"";
    for model in ["", "model = \"default\""] {
        let r = resolved(glass, model);
        assert_eq!(r.model, ModelKey::Default);
        let t = trace_of(&r);
        assert_eq!(
            (t.walls, t.fresnel_mode, t.fresnel_law, t.groove_slices),
            (
                Walls::Diffuse,
                FresnelMode::Walls,
                FresnelLaw::Schlick { n: 1.5 },
                6
            )
        );
        assert_eq!((t.m, t.n, t.nr, t.albedo), (64, 50_000, 1, 1.0));
        assert_eq!(
            (r.mix, r.coverage, r.orientation),
            (
                LayerMix::Stochastic,
                CoverageMode::Footprint,
                Orientation::Layer
            )
        );
        assert_eq!(r.layers, LayerParams::setting(1).unwrap());
        let m = parse(&format!("type = \"scratched\"\n{glass}\n[scratches]\n{model}\nlayers = 1\nm = 8\nn = 50\nnr = 2"))
            .unwrap()
            .prepare(Path::new("."))
            .unwrap();
        assert!(!m.has_lean());
    }
    // Metal: [Raymond16]'s mirror walls (exact with Fresnel at every hit), as the seed's.
    let gold = "base = \"metal\"\npreset = \"gold\"";
    let r = resolved(gold, "");
    let t = trace_of(&r);
    assert_eq!(
        (t.walls, t.fresnel_mode, t.groove_slices, t.m, t.n, t.nr),
        (Walls::Specular, FresnelMode::Walls, 0, 256, 10_000, 100)
    );
    assert_eq!(r.mix, LayerMix::Stochastic);
    // A metal's Lambertian walls keep the seed's table (Fresnel at every hit, eq. (3)).
    let t = trace_of(&resolved(gold, "walls = \"diffuse\"")).clone();
    assert_eq!(
        (t.groove_slices, t.fresnel_mode, t.m, t.n, t.nr),
        (0, FresnelMode::Walls, 256, 10_000, 100)
    );
    assert!(matches!(t.fresnel_law, FresnelLaw::Conductor { .. }));
    // Glass: lossless walls (the seed's table is exact), mirror walls, a facet albedo: the
    // seed's table, as under `model = "seed"`.
    for keys in [
        "fresnel_law = \"none\"",
        "walls = \"specular\"",
        "albedo = 0.5",
    ] {
        let a = trace_of(&resolved(glass, keys)).clone();
        let b = trace_of(&resolved(glass, &format!("{keys}\nmodel = \"seed\""))).clone();
        assert_eq!(a, b, "{keys}");
        assert_eq!((a.groove_slices, a.m, a.n, a.nr), (0, 256, 10_000, 100));
    }
    // Dielectric walls: no 2D table; the default layer choice.
    let r = resolved(glass, "walls = \"dielectric\"");
    assert!(matches!(r.table, TableSource::Traced(_)), "{:?}", r.table);
    assert_eq!(r.mix, LayerMix::Stochastic);
}

/// A key given explicitly wins over either model's default.
#[test]
fn explicit_keys_override_the_model() {
    let glass = "base = \"glass\"";
    let r = resolved(glass, "model = \"seed\"\nlayer_mix = \"union\"");
    assert_eq!(r.mix, LayerMix::Union);
    assert_eq!(trace_of(&r).groove_slices, 0);
    let r = resolved(glass, "model = \"default\"\nlayer_mix = \"union\"");
    assert_eq!(r.mix, LayerMix::Union);
    assert_eq!(trace_of(&r).groove_slices, 6);
    // The seed's model with slices asked for: the seed's sizes, Fresnel at every hit.
    let t = trace_of(&resolved(glass, "model = \"seed\"\ngroove_slices = 6")).clone();
    assert_eq!(
        (t.groove_slices, t.fresnel_mode, t.m, t.n, t.nr),
        (6, FresnelMode::Walls, 256, 10_000, 100)
    );
    let t = trace_of(&resolved(glass, "model = \"seed\"\nfresnel = \"walls\"")).clone();
    assert_eq!((t.groove_slices, t.fresnel_mode), (0, FresnelMode::Walls));
    // The defaults with the seed's Fresnel: no slices (they need Fresnel at every hit).
    let t = trace_of(&resolved(glass, "fresnel = \"seed\"")).clone();
    assert_eq!(
        (t.groove_slices, t.fresnel_mode, t.m, t.n, t.nr),
        (0, FresnelMode::Seed, 256, 10_000, 100)
    );
    let t = trace_of(&resolved(glass, "groove_slices = 3\nm = 32\nnr = 2")).clone();
    assert_eq!((t.groove_slices, t.m, t.n, t.nr), (3, 32, 50_000, 2));
    let t = trace_of(&resolved(glass, "fresnel_law = \"dielectric\"")).clone();
    assert_eq!(
        (t.groove_slices, t.fresnel_law),
        (6, FresnelLaw::Dielectric { n: 1.5 })
    );
    // A table file: the model still picks the layer mix.
    let r = parse(
        "type = \"scratched\"\nbase = \"glass\"\n[scratches]\nmodel = \"seed\"\ntable = \"t.npz\"",
    )
    .unwrap()
    .resolve(Path::new("."))
    .unwrap();
    assert_eq!(r.mix, LayerMix::Max);
}

#[test]
fn curves_alone_or_beside_layers() {
    let dir = std::env::temp_dir().join(format!("striae-curves-keys-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("marks.svg"),
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><path d="M1 1 L9 9" stroke="black" stroke-width="0.1"/></svg>"#,
    )
    .unwrap();
    let prepare = |scratches: &str| -> Result<ScratchedMaterial, String> {
        let text = format!(
            "type = \"scratched\"\nbase = \"metal\"\npreset = \"gold\"\n[scratches]\nm = 16\nn = 200\n{scratches}"
        );
        let m: MaterialDesc = toml::from_str(&text).map_err(|e| e.to_string())?;
        let MaterialDesc::Scratched(s) = m else {
            return Err("not scratched".into());
        };
        s.prepare(&dir).map_err(|e| e.to_string())
    };
    // The SVG, relative to the scene's folder, alone: no layers.
    let m = prepare("curves = \"marks.svg\"\ntaper = 0.5").unwrap();
    assert_eq!(m.layers.len(), 0);
    // Curves alone default to `union` (closest to explicit grooves), under the seed's model
    // to `max`, beside layers to `stochastic`.
    assert_eq!(m.mix, LayerMix::Union);
    let seed = prepare("curves = \"marks.svg\"\nmodel = \"seed\"").unwrap();
    assert_eq!(seed.mix, LayerMix::Max);
    assert_eq!(m.curves.as_ref().unwrap().len(), 1);
    // With a layer key: both.
    let m = prepare("curves = \"marks.svg\"\nsetting = 2\nlayers = 2").unwrap();
    assert_eq!(m.layers.len(), 2);
    assert_eq!(m.mix, LayerMix::Stochastic);
    assert!(m.curves.is_some());
    // A pattern.
    let m =
        prepare("pattern = { kind = \"circles\", radius = [0.1, 0.4], count = 5, width = 0.01 }")
            .unwrap();
    assert_eq!(m.curves.as_ref().unwrap().len(), 5);
    // Errors name the key (and the file).
    let err = |s: &str| prepare(s).unwrap_err();
    let e = err("curves = \"missing.svg\"");
    assert!(
        e.contains("scratches.curves") && e.contains("missing.svg"),
        "{e}"
    );
    let e = err("curves = \"marks.svg\"\npattern = { kind = \"swirl\", count = 3, radius = [0.1, 0.2], width = 0.01 }");
    assert!(
        e.contains("scratches.pattern") && e.contains("exclude"),
        "{e}"
    );
    let e = err("taper = 0.1");
    assert!(
        e.contains("scratches.taper") && e.contains("curves only"),
        "{e}"
    );
    let e = err("curves = \"marks.svg\"\nwear = 0.5");
    assert!(e.contains("scratches.wear_length"), "{e}");
    let e = err("pattern = { kind = \"circles\", radius = [0.4, 0.1], count = 5, width = 0.01 }");
    assert!(e.contains("scratches.pattern.radius"), "{e}");
    let e = err("pattern = { kind = \"swirl\", count = 0, radius = [0.1, 0.2], width = 0.01 }");
    assert!(e.contains("scratches.pattern.count"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
    // Unknown pattern keys and kinds are parse errors naming them.
    let e = parse("type = \"scratched\"\nbase = \"metal\"\n[scratches]\npattern = { kind = \"swirl\", count = 3, radius = [0.1, 0.2], width = 0.01, colour = 1 }").unwrap_err();
    assert!(e.contains("colour"), "{e}");
    let e = parse(
        "type = \"scratched\"\nbase = \"metal\"\n[scratches]\npattern = { kind = \"spiral\" }",
    )
    .unwrap_err();
    assert!(e.contains("spiral"), "{e}");
}

/// A painted map (METHOD.md 9.5) alone (no layers, `union`) or beside layers (`max`), and its
/// errors, each naming the key and the file (and the pixel).
#[test]
fn maps_alone_or_beside_layers_and_their_errors() {
    let dir = std::env::temp_dir().join(format!("striae-map-keys-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let grey = |name: &str, w: u32, h: u32, v: u8| {
        image::GrayImage::from_pixel(w, h, image::Luma([v]))
            .save(dir.join(name))
            .unwrap();
    };
    grey("wear.png", 8, 8, 128);
    grey("flow.png", 8, 8, 255);
    grey("small.png", 4, 8, 255);
    // An EXR holding 1.5 at pixel (2, 1).
    let mut px = vec![crate::math::Rgb::splat(0.5); 4 * 3];
    px[4 + 2] = crate::math::Rgb::splat(1.5);
    crate::render::film::Image {
        width: 4,
        height: 3,
        pixels: px,
    }
    .write_exr(&dir.join("over.exr"))
    .unwrap();
    let prepare = |scratches: &str| -> Result<ScratchedMaterial, String> {
        let text = format!(
            "type = \"scratched\"\nbase = \"metal\"\npreset = \"gold\"\n[scratches]\nm = 16\nn = 200\n{scratches}"
        );
        let m: MaterialDesc = toml::from_str(&text).map_err(|e| e.to_string())?;
        let MaterialDesc::Scratched(s) = m else {
            return Err("not scratched".into());
        };
        s.prepare(&dir).map_err(|e| e.to_string())
    };
    let m = prepare("map = \"wear.png\"").unwrap();
    assert_eq!(m.layers.len(), 0);
    assert_eq!(m.mix, LayerMix::Union);
    // Read linear: 128 / 255, not sRGB-decoded (0.216).
    let s = m
        .map
        .as_ref()
        .unwrap()
        .at_point(crate::math::Vec2::splat(0.5));
    assert!((s.coverage - 128.0 / 255.0).abs() < 1e-6, "{}", s.coverage);
    let m =
        prepare("map = \"wear.png\"\ndirection = \"flow.png\"\nsetting = 2\nlayers = 2").unwrap();
    assert_eq!((m.layers.len(), m.mix), (2, LayerMix::Stochastic));
    assert!(m.curves.is_none() && m.map.is_some());
    let err = |s: &str| prepare(s).unwrap_err();
    let e = err("map = \"missing.png\"");
    assert!(
        e.contains("scratches.map") && e.contains("missing.png"),
        "{e}"
    );
    let e = err("map = \"over.exr\"");
    assert!(
        e.contains("scratches.map") && e.contains("over.exr") && e.contains("(2, 1)"),
        "{e}"
    );
    let e = err("direction = \"flow.png\"");
    assert!(
        e.contains("scratches.direction") && e.contains("scratches.map"),
        "{e}"
    );
    let e = err("map = \"wear.png\"\ndirection = \"small.png\"");
    assert!(
        e.contains("scratches.direction") && e.contains("map's size"),
        "{e}"
    );
    let e = err("map = \"wear.png\"\nmap_scale = 0.0");
    assert!(e.contains("scratches.map_scale"), "{e}");
    let e = err("map_scale = 2.0");
    assert!(e.contains("scratches.map_scale"), "{e}");
    let e = err("map = \"wear.png\"\ndepth = 1.5");
    assert!(e.contains("scratches.depth"), "{e}");
    let e = err("map = \"wear.png\"\ntaper = 0.1");
    assert!(e.contains("scratches.taper"), "{e}");
    // A map cannot be carved.
    let text = "type = \"scratched\"\nbase = \"metal\"\npreset = \"gold\"\n[scratches]\nmap = \"wear.png\"\nexplicit = true";
    let MaterialDesc::Scratched(s) = toml::from_str::<MaterialDesc>(text).unwrap() else {
        panic!("not scratched")
    };
    let e = s.explicit(&dir).unwrap_err().to_string();
    assert!(e.contains("scratches.map") && e.contains("carved"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}
