//! Every TOML example of docs/scenes.md and docs/scratched.md is loaded and rendered, so the docs
//! cannot drift from what the scene parser accepts (a renamed or misspelt key fails here).
//!
//! Each ```` ```toml ```` block must be preceded (blank lines allowed in between) by an HTML
//! comment, invisible in the rendered Markdown, that says how the block is checked:
//!
//! * `<!-- example: scene -->`: a whole scene file, rendered as written.
//! * `<!-- example: fragment -->`: tables of a scene (`[render]`, `[materials.NAME]`,
//!   `[[shapes]]`, ...), spliced into [`BASE`], a minimal scene: the base's own `[render]`,
//!   `[camera]` and `[environment]` give way to the fragment's; every material the fragment
//!   defines is put on a rectangle of its own, so that it is used; every material its shapes
//!   name without defining it is added as a plain diffuse one; and every file it names
//!   (`path = "..."`, `curves = "..."`, `map = "..."` or `direction = "..."`, outside comments)
//!   is created beside the scene (an OBJ mesh: a tetrahedron; an SVG drawing: one stroke; a
//!   glTF: one triangle; a PNG: a 4 x 4 grey image holding one line, which serves as a painted
//!   scratch map and as its flow map alike). A fragment with neither materials nor shapes gets a
//!   grey rectangle.
//! * `<!-- example: transforms -->`: each non-empty line is one `transform = ...` alternative,
//!   given in turn to a rectangle of [`BASE`].
//!
//! A block without a marker, or a marker without a block, fails the test. Lines commented out
//! inside a block (alternatives such as `# lobes = "table"`) are documentation, not checked.
//!
//! Each scene is rendered by `striae render FILE --spp 1 --res 8x8 -q` and must exit 0 and write
//! its EXR. The table cache (`STRIAE_CACHE`) is a fresh folder for each run, shared by both docs:
//! their scratched examples ask for the seed's full table (`M = 256`, `N = 10000`, `N_r = 100`),
//! the one slow step (a few seconds on 2 cores), computed once.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The minimal scene a fragment is spliced into, by part: `(top-level table, text)`.
const BASE: &[(&str, &str)] = &[
    (
        "render",
        "[render]\nwidth = 8\nheight = 8\nspp = 1\nmax_depth = 4\n",
    ),
    (
        "camera",
        "[camera]\nposition = [0.0, 0.0, 5.0]\nlook_at = [0.0, 0.0, 0.0]\nfov = 40.0\n",
    ),
    (
        "environment",
        "[environment]\ntype = \"constant\"\nradiance = 0.5\n",
    ),
];

/// The material of the base's own rectangle (transform examples, fragments with no material).
const BASE_MATERIAL: &str = "[materials.doc_example_base]\ntype = \"diffuse\"\nreflectance = 0.5\n";

/// The mesh written for an OBJ file a fragment names.
const TETRAHEDRON_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\n\
    f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

/// The glTF written for a glTF file a fragment names (`.gltf` or `.glb`; the importer tells a
/// GLB by its magic bytes, so JSON serves both): one triangle, its buffer a data URI.
const TRIANGLE_GLTF: &str = r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],"meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}],"bufferViews":[{"buffer":0,"byteLength":36}],"buffers":[{"byteLength":36,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]}"#;
/// The drawing written for an SVG file a fragment names (`curves = "..."`): one stroke.
const STROKE_SVG: &str = r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100"><path d="M 10 80 C 30 60, 60 70, 90 20" fill="none" stroke="black" stroke-width="1"/></svg>"#;

#[derive(Debug, PartialEq)]
enum Kind {
    Scene,
    Fragment,
    Transforms,
}

/// One ```` ```toml ```` block of a doc: where it starts (1-based line of the fence), its marker
/// and its text.
struct Block {
    line: usize,
    kind: Kind,
    text: String,
}

/// The TOML blocks of `doc`, each with its marker; panics naming the line of a block without a
/// marker, an unknown marker or a marker without a block.
fn blocks(doc: &str, name: &str) -> Vec<Block> {
    let mut out = Vec::new();
    let mut marker: Option<(usize, Kind)> = None;
    let mut lines = doc.lines().enumerate();
    while let Some((i, line)) = lines.next() {
        let t = line.trim();
        if let Some(rest) = t.strip_prefix("<!-- example:") {
            assert!(
                marker.is_none(),
                "{name}:{}: two example markers in a row",
                i + 1
            );
            let rest = rest.trim_end_matches("-->").trim();
            let word = rest.split_whitespace().next().unwrap_or("");
            let kind = match word {
                "scene" => Kind::Scene,
                "fragment" => Kind::Fragment,
                "transforms" => Kind::Transforms,
                _ => panic!(
                    "{name}:{}: unknown example marker `{rest}` (scene, fragment or transforms)",
                    i + 1
                ),
            };
            marker = Some((i + 1, kind));
        } else if t.starts_with("```") {
            let fence = i + 1;
            let is_toml = t == "```toml";
            let mut text = String::new();
            for (_, l) in lines.by_ref() {
                if l.trim_start().starts_with("```") {
                    break;
                }
                text.push_str(l);
                text.push('\n');
            }
            if is_toml {
                let (_, kind) = marker.take().unwrap_or_else(|| {
                    panic!(
                        "{name}:{fence}: a ```toml block without an example marker \
                         (`<!-- example: scene|fragment|transforms -->` before it; \
                         see crates/striae-cli/tests/doc_examples.rs)"
                    )
                });
                out.push(Block {
                    line: fence,
                    kind,
                    text,
                });
            } else if let Some((at, _)) = marker {
                panic!("{name}:{at}: an example marker before a block that is not ```toml");
            }
        } else if !t.is_empty() {
            if let Some((at, _)) = marker {
                panic!("{name}:{at}: an example marker not followed by a ```toml block");
            }
        }
    }
    assert!(marker.is_none(), "{name}: an example marker at the end");
    out
}

/// The lines of `text` outside comments (a line whose first non-blank character is `#`).
fn code_lines(text: &str) -> impl Iterator<Item = &str> {
    text.lines().filter(|l| !l.trim_start().starts_with('#'))
}

/// The first quoted string after `key = ` in `line`.
fn quoted_value<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    let at = line.find(&format!("{key} = \""))? + key.len() + 4;
    let rest = &line[at..];
    Some(&rest[..rest.find('"')?])
}

/// `[NAME]` or `[NAME.sub]` or `[[NAME]]`: the top-level table `NAME` of a header line.
fn top_table(line: &str) -> Option<&str> {
    let t = line.trim();
    let inner = t.strip_prefix("[[").or_else(|| t.strip_prefix('['))?;
    let end = inner.find([']', '.'])?;
    Some(inner[..end].trim())
}

/// `[materials.NAME]` (one level): `NAME`.
fn material_defined(line: &str) -> Option<&str> {
    let inner = line.trim().strip_prefix("[materials.")?.strip_suffix(']')?;
    (!inner.contains('.')).then_some(inner)
}

/// A fragment spliced into [`BASE`], and the files it names (relative paths) to create.
fn splice(fragment: &str) -> (String, Vec<String>) {
    let first = code_lines(fragment).find(|l| !l.trim().is_empty());
    assert!(
        first.is_some_and(|l| l.trim_start().starts_with('[')),
        "a fragment must start with a table header"
    );
    let tables: Vec<&str> = code_lines(fragment).filter_map(top_table).collect();
    let defined: Vec<&str> = code_lines(fragment).filter_map(material_defined).collect();
    let mut named: Vec<&str> = code_lines(fragment)
        .filter_map(|l| quoted_value(l, "material"))
        .filter(|m| !defined.contains(m))
        .collect();
    named.sort_unstable();
    named.dedup();
    let files: Vec<String> = code_lines(fragment)
        .filter_map(|l| {
            quoted_value(l, "path")
                .or_else(|| quoted_value(l, "curves"))
                .or_else(|| quoted_value(l, "map"))
                .or_else(|| quoted_value(l, "direction"))
        })
        .map(str::to_owned)
        .collect();

    let mut scene = String::from(fragment);
    for (table, text) in BASE {
        if !tables.contains(table) {
            scene.push('\n');
            scene.push_str(text);
        }
    }
    for m in &named {
        scene.push_str(&format!(
            "\n[materials.{m}]\ntype = \"diffuse\"\nreflectance = 0.5\n"
        ));
    }
    let on_rectangles: Vec<&str> = if defined.is_empty() && !tables.contains(&"shapes") {
        scene.push('\n');
        scene.push_str(BASE_MATERIAL);
        vec!["doc_example_base"]
    } else {
        defined
    };
    for (k, m) in on_rectangles.iter().enumerate() {
        scene.push_str(&format!(
            "\n[[shapes]]\ntype = \"rectangle\"\nmaterial = \"{m}\"\n\
             transform = {{ translate = [{}, 0.0, 0.0] }}\n",
            k as f32 * 0.5
        ));
    }
    (scene, files)
}

/// A rectangle of [`BASE`] with `transform_line` (`transform = ...`).
fn with_transform(transform_line: &str) -> String {
    let mut scene = String::new();
    for (_, text) in BASE {
        scene.push_str(text);
        scene.push('\n');
    }
    scene.push_str(BASE_MATERIAL);
    scene.push_str(&format!(
        "\n[[shapes]]\ntype = \"rectangle\"\nmaterial = \"doc_example_base\"\n{transform_line}\n"
    ));
    scene
}

/// Writes `scene` (and `files`) into a folder of its own under `dir` and renders it: `Err` with
/// the command's standard error when it fails.
fn render(dir: &Path, label: &str, scene: &str, files: &[String]) -> Result<(), String> {
    let folder = dir.join(label);
    std::fs::create_dir_all(&folder).unwrap();
    for f in files {
        let path = folder.join(f);
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        if f.ends_with(".png") {
            // A painted scratch map (and a flow map): one line down column 1.
            image::GrayImage::from_fn(4, 4, |x, _| image::Luma([if x == 1 { 255 } else { 0 }]))
                .save(&path)
                .unwrap();
            continue;
        }
        let contents = if f.ends_with(".obj") {
            TETRAHEDRON_OBJ
        } else if f.ends_with(".svg") {
            STROKE_SVG
        } else if f.ends_with(".gltf") || f.ends_with(".glb") {
            TRIANGLE_GLTF
        } else {
            panic!(
                "{label}: names `{f}`; only OBJ, SVG, glTF and PNG files are made for examples \
                 (add the file type to crates/striae-cli/tests/doc_examples.rs)"
            )
        };
        std::fs::write(&path, contents).unwrap();
    }
    let file = folder.join("scene.toml");
    std::fs::write(&file, scene).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_striae"))
        .env("STRIAE_CACHE", dir.join("cache"))
        .arg("render")
        .arg(&file)
        .args(["--spp", "1", "--res", "8x8", "-q", "-o"])
        .arg(folder.join("out"))
        .output()
        .unwrap();
    if o.status.success() && folder.join("out.exr").is_file() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&o.stderr).into_owned())
    }
}

/// Checks every TOML block of `doc` (`docs/NAME`), rendering into folders under `dir`: the
/// failures, one message each.
fn check_doc(dir: &Path, name: &str, doc: &str) -> Vec<String> {
    let blocks = blocks(doc, name);
    assert!(!blocks.is_empty(), "{name}: no ```toml block found");
    let mut failures = Vec::new();
    for b in &blocks {
        let mut cases: Vec<(String, String, Vec<String>)> = Vec::new();
        let label = format!("{}-{}", name.trim_end_matches(".md"), b.line);
        match b.kind {
            Kind::Scene => cases.push((label, b.text.clone(), Vec::new())),
            Kind::Fragment => {
                let (scene, files) = splice(&b.text);
                cases.push((label, scene, files));
            }
            Kind::Transforms => {
                let lines: Vec<&str> = code_lines(&b.text)
                    .filter(|l| !l.trim().is_empty())
                    .collect();
                assert!(!lines.is_empty(), "{name}:{}: no transform", b.line);
                for (k, l) in lines.iter().enumerate() {
                    assert!(
                        l.trim_start().starts_with("transform ="),
                        "{name}:{}: `{l}` is not a `transform = ...` line",
                        b.line
                    );
                    cases.push((format!("{label}-{k}"), with_transform(l), Vec::new()));
                }
            }
        }
        for (label, scene, files) in cases {
            if let Err(err) = render(dir, &label, &scene, &files) {
                failures.push(format!(
                    "docs/{name}:{} ({:?}) failed to render:\n{err}\n--- the scene ---\n{scene}",
                    b.line, b.kind
                ));
            }
        }
    }
    failures
}

/// Both docs in one test, so that their scratched examples, which ask for the same table (the
/// seed's sizes), share one cache and compute it once.
#[test]
fn toml_examples_of_the_docs_render() {
    let dir: PathBuf =
        std::env::temp_dir().join(format!("striae-doc-examples-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mut failures = Vec::new();
    for (name, path) in [
        (
            "scenes.md",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/scenes.md"),
        ),
        (
            "scratched.md",
            concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/scratched.md"),
        ),
    ] {
        let doc =
            std::fs::read_to_string(path).unwrap_or_else(|e| panic!("cannot read {path}: {e}"));
        failures.extend(check_doc(&dir, name, &doc));
    }
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        failures.is_empty(),
        "{} TOML examples of the docs fail:\n\n{}",
        failures.len(),
        failures.join("\n\n")
    );
}

#[test]
fn markers_are_required_and_fragments_are_spliced() {
    let doc =
        "text\n\n<!-- example: fragment -->\n\n```toml\n[materials.a]\ntype = \"diffuse\"\n```\n";
    let b = blocks(doc, "t");
    assert_eq!(b.len(), 1);
    assert_eq!(b[0].kind, Kind::Fragment);
    assert_eq!(b[0].line, 5);
    let (scene, files) = splice(&b[0].text);
    assert!(scene.contains("material = \"a\"") && scene.contains("[camera]"));
    assert!(files.is_empty());
    let (scene, files) =
        splice("[[shapes]]\ntype = \"mesh\"\npath = \"m/x.obj\"\nmaterial = \"g\"\n");
    assert!(scene.contains("[materials.g]") && !scene.contains("doc_example_base"));
    assert_eq!(files, ["m/x.obj"]);
    let unmarked = std::panic::catch_unwind(|| blocks("```toml\n[render]\n```\n", "t"));
    assert!(unmarked.is_err());
}
