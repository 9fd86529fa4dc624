//! `striae hologram` end to end: the SVG it writes for a points file, and clear errors that
//! leave no file for bad input.

use std::path::PathBuf;
use std::process::Command;

/// A fresh folder for one test.
fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("striae-hologram-cli-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn striae(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_striae"))
        .arg("hologram")
        .args(args)
        .output()
        .unwrap()
}

/// The value of attribute `name` in `element`.
fn attribute<'a>(element: &'a str, name: &str) -> &'a str {
    let key = format!(" {name}=\"");
    let from = element.find(&key).unwrap() + key.len();
    &element[from..from + element[from..].find('"').unwrap()]
}

#[test]
fn writes_one_arc_per_point() {
    let dir = tmp("ok");
    let csv = dir.join("points.csv");
    std::fs::write(&csv, "x,y,z\n0,0,-1\n1,0.5,0.5\n-1,1,2\n").unwrap();
    let out = dir.join("arcs.svg");
    let o = striae(&[csv.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(stdout.starts_with("wrote 3 arcs to "), "{stdout}");
    assert!(stdout.contains("scale 1,"), "{stdout}");
    let svg = std::fs::read_to_string(&out).unwrap();
    let paths: Vec<&str> = svg.split("<path").skip(1).collect();
    assert_eq!(paths.len(), 3);
    // The point behind (0, 0, -1), default view angle 45 and azimuth 90 (+y) and span 90: the
    // arc of radius 1 from 45 to 135 degrees, on the viewer's side.
    let d = attribute(paths[0], "d");
    let w: Vec<f64> = d
        .split_whitespace()
        .filter_map(|x| x.parse().ok())
        .collect();
    let h = 0.5f64.sqrt();
    let expected = [h, h, 1.0, 1.0, 0.0, 0.0, 1.0, -h, h];
    assert_eq!(w.len(), expected.len(), "{d}");
    for (a, b) in w.iter().zip(expected) {
        assert!((a - b).abs() < 1e-15, "{d}");
    }
    // The fitted plate holds the arcs; the viewBox is the SVG's size.
    let tag = &svg[svg.find("<svg").unwrap()..];
    let vb: Vec<f64> = attribute(tag, "viewBox")
        .split(' ')
        .map(|x| x.parse().unwrap())
        .collect();
    assert_eq!(attribute(tag, "width").parse::<f64>().unwrap(), vb[2]);
    assert_eq!(attribute(tag, "height").parse::<f64>().unwrap(), vb[3]);
    assert!(vb[0] < -2.41 && vb[0] + vb[2] > 1.35 && vb[1] < -0.41 && vb[1] + vb[3] > 1.0);

    // An OBJ of the same points with a given plate, span, azimuth and width: the same count,
    // and the plate and width as given.
    let obj = dir.join("points.obj");
    std::fs::write(&obj, "o p\nv 0 0 -1\nv 1 0.5 0.5\nv -1 1 2\n").unwrap();
    let out2 = dir.join("obj.svg");
    let o = striae(&[
        obj.to_str().unwrap(),
        "-o",
        out2.to_str().unwrap(),
        "--plate",
        "-4,-4,8,8",
        "--span",
        "120",
        "--azimuth",
        "-90",
        "--scale",
        "0.5",
        "--width",
        "0.02",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let svg = std::fs::read_to_string(&out2).unwrap();
    assert!(svg.contains(r#"viewBox="-4 -4 8 8""#), "{svg}");
    assert_eq!(svg.matches(r#"stroke-width="0.02""#).count(), 3);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_input_is_a_clear_error_and_writes_nothing() {
    let dir = tmp("bad");
    let good = dir.join("good.csv");
    std::fs::write(&good, "0,0,1\n").unwrap();
    let bad_line = dir.join("bad.csv");
    std::fs::write(&bad_line, "x,y,z\n0,0,1\n0,oops,1\n").unwrap();
    let on_plate = dir.join("flat.obj");
    std::fs::write(&on_plate, "v 0 0 1\nv 1 1 0\n").unwrap();
    let missing = dir.join("missing.csv");
    let g = good.to_str().unwrap();
    let cases: Vec<(Vec<&str>, String)> = vec![
        (vec![missing.to_str().unwrap()], "missing.csv".to_string()),
        (
            vec![bad_line.to_str().unwrap()],
            "bad.csv, line 3: `oops` is not a number".to_string(),
        ),
        (
            vec![on_plate.to_str().unwrap()],
            "point 1 (1, 1, 0): lies on the plate".to_string(),
        ),
        (vec![g, "--view-angle", "90"], "--view-angle 90".to_string()),
        (vec![g, "--scale", "-1"], "--scale -1".to_string()),
        (vec![g, "--span", "0"], "--span 0".to_string()),
        (vec![g, "--span", "400"], "--span 400".to_string()),
        (vec![g, "--width", "0"], "--width 0".to_string()),
        (vec![g, "--plate", "0,0,-1,1"], "plate size_x".to_string()),
        (vec![g, "--plate", "0,0,1"], "X0,Y0,SX,SY".to_string()),
    ];
    let out = dir.join("out.svg");
    for (args, want) in cases {
        let mut a = args.clone();
        a.extend(["-o", out.to_str().unwrap()]);
        let o = striae(&a);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?} should fail");
        assert!(err.contains(&want), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote {out:?}");
    }
    // Nothing else was left in the folder (no temporary file).
    let mut left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    left.sort();
    assert_eq!(left, ["bad.csv", "flat.obj", "good.csv"]);
    // The output may not overwrite the points file.
    let o = striae(&[g, "-o", g]);
    assert!(!o.status.success());
    assert_eq!(std::fs::read_to_string(&good).unwrap(), "0,0,1\n");
    let _ = std::fs::remove_dir_all(&dir);
}
