//! Interrupted and refused work leaves nothing behind: `figures` checks every option before
//! its first write and publishes its folder whole, and SIGTERM (as Ctrl-C) removes what was
//! being written.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn entries(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .map(|d| {
            d.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn figures_validate_first_and_leave_nothing_when_interrupted() {
    let dir = std::env::temp_dir().join(format!("striae-interrupt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let figs = dir.join("figs");
    let striae = || {
        let mut c = Command::new(env!("CARGO_BIN_EXE_striae"));
        c.env("STRIAE_CACHE", dir.join("cache"));
        c
    };
    // A bad option after the ones that make the first figures: refused before any write.
    for (flag, value) in [("--layer-res", "0"), ("--res", "100000x10")] {
        let o = striae()
            .args(["figures", flag, value, "-o"])
            .arg(&figs)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains(flag),
            "{flag} {value}: {err}"
        );
        assert!(!figs.exists(), "{flag} {value}: the folder was made");
    }
    // SIGTERM in the middle of the renders: no folder, no temporary left.
    let mut child = striae()
        .args([
            "figures",
            "--spp",
            "256",
            "--res",
            "320x240",
            "--threads",
            "1",
            "-o",
        ])
        .arg(&figs)
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while !entries(&dir).iter().any(|e| e.starts_with(".figs.tmp-")) {
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no temporary folder appeared"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(500));
    let killed = Command::new("kill")
        .args(["-TERM", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    let status = child.wait().unwrap();
    assert!(!status.success());
    let left: Vec<_> = entries(&dir).into_iter().filter(|e| e != "cache").collect();
    assert!(left.is_empty(), "left behind: {left:?}");
    let _ = std::fs::remove_dir_all(&dir);
}
