//! `striae render` flags: bad values are usage errors that name the flag, and nothing is written.

use std::process::Command;

#[test]
fn bad_render_flags_name_the_flag_and_write_nothing() {
    let dir = std::env::temp_dir().join(format!("striae-render-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("out");
    for (flag, value) in [
        ("--spp", "0"),
        ("--spp", "70000"),
        ("--threads", "0"),
        ("--res", "0x5"),
        ("--sampler", "halton"),
        ("--exposure", "NaN"),
    ] {
        let o = Command::new(env!("CARGO_BIN_EXE_striae"))
            .args(["render", flag, value, "-q", "-o"])
            .arg(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{flag} {value} should fail");
        assert!(
            err.contains(flag) && err.contains(value),
            "{flag} {value}: {err}"
        );
        assert!(
            !out.with_extension("exr").exists() && !out.with_extension("png").exists(),
            "{flag} {value} wrote an image"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
