//! `striae layers` end to end: the files it writes, and clear errors with no output for bad input.

use std::path::PathBuf;
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("striae-layers-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn striae(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_striae"))
        .arg("layers")
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn writes_layers_combined_json_and_stages() {
    let out = tmp("ok");
    let o = striae(&[
        "--setting",
        "2",
        "--layers",
        "3",
        "--res",
        "96",
        "--seed",
        "5",
        "--stages",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "layer-0.png",
            "layer-1.png",
            "layer-2.png",
            "layers.json",
            "layers.png",
            "stage-a-noise.png",
            "stage-b-stretched.png",
            "stage-c-threshold.png"
        ]
    );
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("layers.json")).unwrap()).unwrap();
    assert_eq!(json["params"]["length"], 0.6);
    assert_eq!(json["params"]["width"], 0.01);
    assert_eq!(json["params"]["layers"], 3);
    let layers = json["layers"].as_array().unwrap();
    assert_eq!(layers.len(), 3);
    for l in layers {
        let a = l["angle_rad"].as_f64().unwrap();
        let d = l["direction"].as_array().unwrap();
        assert!(
            (d[0].as_f64().unwrap() - a.cos()).abs() < 1e-12
                && (d[1].as_f64().unwrap() - a.sin()).abs() < 1e-12
        );
        let c = l["coverage"].as_f64().unwrap();
        assert!(c > 0.005 && c < 0.1, "coverage {c}");
    }
    // Same seed, same bytes.
    let again = tmp("again");
    assert!(striae(&[
        "--setting",
        "2",
        "--layers",
        "3",
        "--res",
        "96",
        "--seed",
        "5",
        "-o",
        again.to_str().unwrap()
    ])
    .status
    .success());
    assert_eq!(
        std::fs::read(out.join("layer-1.png")).unwrap(),
        std::fs::read(again.join("layer-1.png")).unwrap()
    );
    std::fs::remove_dir_all(&out).unwrap();
    std::fs::remove_dir_all(&again).unwrap();
}

#[test]
fn bad_input_is_a_clear_error_and_leaves_nothing() {
    for (args, want) in [
        (
            vec!["--length", "0", "--width", "0.01", "--threshold", "0.1"],
            "length",
        ),
        (
            vec!["--length", "-0.3", "--width", "0.01", "--threshold", "0.1"],
            "length",
        ),
        (
            vec!["--length", "0.3", "--width", "0", "--threshold", "0.1"],
            "width",
        ),
        (
            vec!["--length", "0.3", "--width", "0.01", "--threshold", "1.5"],
            "threshold",
        ),
        (
            vec!["--length", "0.3", "--width", "0.01", "--threshold", "0"],
            "threshold",
        ),
        (vec!["--layers", "0"], "layers"),
        (vec!["--setting", "3"], "setting"),
        (vec!["--res", "0"], "res"),
        (vec!["--res", "1000000"], "res"),
    ] {
        let out = tmp("bad");
        let mut a = args.clone();
        a.extend(["-o", out.to_str().unwrap()]);
        let o = striae(&a);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} should fail");
        assert!(err.contains(want), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} left {out:?} behind");
    }
    // Only part of the custom triple, or a setting with a custom value: usage errors.
    let out = tmp("partial");
    assert!(!striae(&["--length", "0.3", "-o", out.to_str().unwrap()])
        .status
        .success());
    assert!(!striae(&[
        "--setting",
        "1",
        "--width",
        "0.1",
        "-o",
        out.to_str().unwrap()
    ])
    .status
    .success());
    assert!(!out.exists());
}

#[test]
fn a_file_that_cannot_be_written_leaves_the_folder_as_it_was() {
    // `layer-3.png` is a folder and `layer-1.png` an old file: the run fails naming the
    // folder, the old file keeps its content, and nothing else is written.
    let out = tmp("partial-write");
    std::fs::create_dir_all(out.join("layer-3.png")).unwrap();
    std::fs::write(out.join("layer-1.png"), b"old").unwrap();
    let o = striae(&["--res", "32", "-o", out.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("layer-3.png is a folder"), "{err}");
    assert_eq!(std::fs::read(out.join("layer-1.png")).unwrap(), b"old");
    let mut left: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    left.sort();
    assert_eq!(left, ["layer-1.png", "layer-3.png"]);
    let _ = std::fs::remove_dir_all(&out);
}
