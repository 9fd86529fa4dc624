//! `striae render --preview`: a fake tev (a TCP server that parses every packet and checks its
//! framing and type) receives the tiles and then the final image, which equals the EXR; the
//! outputs are byte for byte those of a render without preview; a tev that closes its socket
//! mid-render costs a warning, not the render; `every=SECONDS` leaves valid outputs; a bad
//! value names the flag.

use std::io::Read;
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Run `striae ARGS`: whether it succeeded, and its standard error.
fn striae(args: &[&str]) -> (bool, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_striae"))
        .args(args)
        .output()
        .unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("striae-preview-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A glass sphere under a constant sky, `width x height` at `spp`, as `dir/s.toml`.
fn glass_sphere(dir: &Path, width: u32, height: u32, spp: u32) -> String {
    let scene = dir.join("s.toml");
    let text = format!(
        "[render]\nwidth = {width}\nheight = {height}\nspp = {spp}\n[camera]\nposition = [0, 1, 4]\n\
         look_at = [0, 0.5, 0]\nfov = 40\n[materials.glass]\ntype = \"dielectric\"\n[[shapes]]\n\
         type = \"sphere\"\nmaterial = \"glass\"\ncenter = [0, 0.6, 0]\nradius = 0.6\n\
         [environment]\ntype = \"constant\"\nradiance = [0.8, 0.9, 1.0]\n"
    );
    std::fs::write(&scene, text).unwrap();
    scene.display().to_string()
}

/// The pixels of an RGB EXR file, row by row.
fn read_exr(path: &Path) -> (usize, usize, Vec<[f32; 3]>) {
    let img = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |res, _| (res.width(), vec![[0.0f32; 3]; res.width() * res.height()]),
        |(w, px): &mut (usize, Vec<[f32; 3]>), pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            px[pos.y() * *w + pos.x()] = [r, g, b]
        },
    )
    .unwrap();
    let size = img.layer_data.size;
    (size.0, size.1, img.layer_data.channel_data.pixels.1)
}

/// A cursor over one packet's payload that panics on a short read.
struct Fields<'a>(&'a [u8]);

impl Fields<'_> {
    fn bytes(&mut self, n: usize) -> &[u8] {
        assert!(self.0.len() >= n, "packet too short");
        let (a, b) = self.0.split_at(n);
        self.0 = b;
        a
    }
    fn u8(&mut self) -> u8 {
        self.bytes(1)[0]
    }
    fn i32(&mut self) -> i32 {
        i32::from_le_bytes(self.bytes(4).try_into().unwrap())
    }
    fn i64(&mut self) -> i64 {
        i64::from_le_bytes(self.bytes(8).try_into().unwrap())
    }
    fn str(&mut self) -> String {
        let end = self
            .0
            .iter()
            .position(|&b| b == 0)
            .expect("a NUL-terminated string");
        let s = String::from_utf8(self.0[..end].to_vec()).unwrap();
        self.0 = &self.0[end + 1..];
        s
    }
}

/// What a fake tev saw: the image name, its size, the rectangles of the updates in order, and
/// the image they left.
#[derive(Debug, Default)]
struct Seen {
    name: String,
    width: usize,
    height: usize,
    updates: Vec<[usize; 4]>,
    image: Vec<[f32; 3]>,
}

/// Reads tev packets from `conn` until the other end closes, checking each one's framing: its
/// length covers exactly its fields, a `CreateImage` (type 4) of RGB first, then only
/// `UpdateImageV3` (type 6) of that image with RGB interleaved, within it.
fn fake_tev(mut conn: TcpStream) -> Seen {
    let mut seen = Seen::default();
    let mut first = true;
    loop {
        let mut len = [0u8; 4];
        match conn.read_exact(&mut len) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return seen,
            Err(e) => panic!("{e}"),
        }
        let len = u32::from_le_bytes(len) as usize;
        assert!(len >= 5, "packet length {len}");
        let mut body = vec![0u8; len - 4];
        conn.read_exact(&mut body).expect("a whole packet");
        let mut f = Fields(&body);
        let kind = f.u8();
        if first {
            assert_eq!(kind, 4, "the first packet creates the image");
            assert_eq!(f.u8(), 1, "grab focus");
            seen.name = f.str();
            seen.width = f.i32() as usize;
            seen.height = f.i32() as usize;
            assert_eq!(f.i32(), 3);
            assert_eq!([f.str(), f.str(), f.str()], ["R", "G", "B"]);
            seen.image = vec![[f32::NAN; 3]; seen.width * seen.height];
            first = false;
        } else {
            assert_eq!(kind, 6, "then only UpdateImageV3");
            assert!(f.u8() <= 1);
            assert_eq!(f.str(), seen.name);
            assert_eq!(f.i32(), 3);
            assert_eq!([f.str(), f.str(), f.str()], ["R", "G", "B"]);
            let [x, y, w, h] = [f.i32(), f.i32(), f.i32(), f.i32()].map(|v| v as usize);
            assert!(w > 0 && h > 0 && x + w <= seen.width && y + h <= seen.height);
            assert_eq!([f.i64(), f.i64(), f.i64()], [0, 1, 2], "offsets");
            assert_eq!([f.i64(), f.i64(), f.i64()], [3, 3, 3], "strides");
            assert_eq!(
                f.0.len(),
                w * h * 12,
                "the data is the rectangle's, exactly"
            );
            let floats: Vec<f32> =
                f.0.chunks(4)
                    .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                    .collect();
            for (i, px) in floats.chunks(3).enumerate() {
                seen.image[(y + i / w) * seen.width + x + i % w] = [px[0], px[1], px[2]];
            }
            seen.updates.push([x, y, w, h]);
            f.0 = &[];
        }
        assert!(
            f.0.is_empty(),
            "{} bytes left over in a type {kind} packet",
            f.0.len()
        );
    }
}

/// A fake tev on 127.0.0.1: its `tev:HOST:PORT` flag value and the thread that serves one
/// connection with `serve`.
fn server<T: Send + 'static>(
    serve: impl FnOnce(TcpStream) -> T + Send + 'static,
) -> (String, std::thread::JoinHandle<T>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = listener.local_addr().unwrap();
    let thread = std::thread::spawn(move || serve(listener.accept().unwrap().0));
    (format!("tev:{addr}"), thread)
}

fn bits(px: &[[f32; 3]]) -> Vec<u32> {
    px.iter().flatten().map(|v| v.to_bits()).collect()
}

/// tev gets the image created, then each finished tile and last the whole image, all with the
/// EXR's pixels bit for bit; the EXR and PNG are byte for byte those of a render without
/// preview (and of one with `every=`), at 1 and at 2 threads.
#[test]
fn tev_gets_the_final_image_and_the_outputs_are_unchanged() {
    let dir = temp_dir("tev");
    let scene = glass_sphere(&dir, 37, 21, 4);
    let out = |name: &str| dir.join(name).display().to_string();
    let (ok, err) = striae(&[
        "render",
        &scene,
        "-q",
        "--threads",
        "2",
        "-o",
        &out("plain"),
    ]);
    assert!(ok, "{err}");
    for threads in ["1", "2"] {
        let (flag, tev) = server(fake_tev);
        let name = format!("tev{threads}");
        let (ok, err) = striae(&[
            "render",
            &scene,
            "-q",
            "--threads",
            threads,
            "--preview",
            &flag,
            "-o",
            &out(&name),
        ]);
        assert!(ok, "{err}");
        assert!(!err.contains("warning"), "{err}");
        let seen = tev.join().unwrap();
        let (w, h, exr) = read_exr(&dir.join(format!("{name}.exr")));
        assert_eq!((seen.width, seen.height), (w, h));
        assert!(seen.name.ends_with(&format!("{name}.exr")), "{}", seen.name);
        assert_eq!(bits(&seen.image), bits(&exr), "tev's image is not the EXR");
        // 6 tiles, then the final image in strips of 16 rows.
        assert_eq!(seen.updates.len(), 6 + 2, "{:?}", seen.updates);
        assert_eq!(
            &seen.updates[6..],
            &[[0, 0, 37, 16], [0, 16, 37, 5]],
            "the final image comes last"
        );
        for ext in ["exr", "png"] {
            let a = std::fs::read(dir.join(format!("plain.{ext}"))).unwrap();
            let b = std::fs::read(dir.join(format!("{name}.{ext}"))).unwrap();
            assert!(a == b, "{ext} with --preview differs from without");
        }
    }
    let (ok, err) = striae(&[
        "render",
        &scene,
        "-q",
        "--preview",
        "every=0.1",
        "-o",
        &out("every"),
    ]);
    assert!(ok, "{err}");
    for ext in ["exr", "png"] {
        let a = std::fs::read(dir.join(format!("plain.{ext}"))).unwrap();
        let b = std::fs::read(dir.join(format!("every.{ext}"))).unwrap();
        assert!(a == b, "{ext} with --preview every= differs from without");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A tev that closes its socket after the first packet, one that is not there at all: the
/// render finishes with a warning naming `--preview`, and its outputs are unchanged.
#[test]
fn a_tev_that_closes_or_is_absent_costs_a_warning_not_the_render() {
    let dir = temp_dir("closed");
    // Long enough (a few tenths of a second) that tiles are sent after the socket closed.
    let scene = glass_sphere(&dir, 96, 64, 256);
    let out = |name: &str| dir.join(name).display().to_string();
    let (ok, err) = striae(&["render", &scene, "-q", "-o", &out("plain")]);
    assert!(ok, "{err}");
    let (flag, tev) = server(|mut conn| {
        let mut len = [0u8; 4];
        conn.read_exact(&mut len).unwrap();
        let mut body = vec![0u8; u32::from_le_bytes(len) as usize - 4];
        conn.read_exact(&mut body).unwrap();
        assert_eq!(body[0], 4);
    });
    let (ok, err) = striae(&[
        "render",
        &scene,
        "-q",
        "--preview",
        &flag,
        "-o",
        &out("closed"),
    ]);
    tev.join().unwrap();
    assert!(ok, "{err}");
    assert!(
        err.contains(&format!("warning: --preview {flag}")) && err.contains("goes on"),
        "{err}"
    );
    // Nothing listens on a port just freed.
    let port = TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let absent = format!("tev:127.0.0.1:{port}");
    let (ok, err) = striae(&[
        "render",
        &scene,
        "-q",
        "--preview",
        &absent,
        "-o",
        &out("absent"),
    ]);
    assert!(ok, "{err}");
    assert!(
        err.contains("warning: --preview tev:") && err.contains("connect"),
        "{err}"
    );
    for name in ["closed", "absent"] {
        for ext in ["exr", "png"] {
            let a = std::fs::read(dir.join(format!("plain.{ext}"))).unwrap();
            let b = std::fs::read(dir.join(format!("{name}.{ext}"))).unwrap();
            assert!(
                a == b,
                "{name}.{ext} differs from the render without preview"
            );
        }
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `every=0.1` rewrites the outputs while the render runs (about a second): an EXR and a PNG
/// appear before it ends, each whole (written atomically), and those there after it are the
/// image. A bad value names the flag and renders nothing.
#[test]
fn every_leaves_valid_outputs_and_bad_values_name_the_flag() {
    let dir = temp_dir("every");
    let scene = glass_sphere(&dir, 96, 64, 1024);
    let out = dir.join("e").display().to_string();
    let mut child = Command::new(env!("CARGO_BIN_EXE_striae"))
        .args([
            "render",
            &scene,
            "-q",
            "--threads",
            "2",
            "--preview",
            "every=0.1",
            "-o",
            &out,
        ])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut seen_while_running = false;
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break status;
        }
        if !seen_while_running && dir.join("e.png").exists() {
            let (w, h, _) = read_exr(&dir.join("e.exr"));
            assert_eq!((w, h), (96, 64));
            let png = image::open(dir.join("e.png")).unwrap().to_rgb8();
            assert_eq!(png.dimensions(), (96, 64));
            seen_while_running = true;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    };
    let mut err = String::new();
    child
        .stderr
        .take()
        .unwrap()
        .read_to_string(&mut err)
        .unwrap();
    assert!(status.success(), "{err}");
    assert!(
        seen_while_running,
        "no preview was written while the render ran"
    );
    let (w, h, px) = read_exr(&dir.join("e.exr"));
    assert_eq!((w, h), (96, 64));
    assert!(px.iter().flatten().all(|v| v.is_finite() && *v > 0.0));
    let png = image::open(dir.join("e.png")).unwrap().to_rgb8();
    assert_eq!(png.dimensions(), (96, 64));
    for bad in [
        "nonsense",
        "every=0",
        "every=x",
        "tev:nohost",
        "tev:h:70000",
    ] {
        let (ok, err) = striae(&[
            "render",
            &scene,
            "-q",
            "--preview",
            bad,
            "-o",
            &dir.join("bad").display().to_string(),
        ]);
        assert!(
            !ok && err.contains("--preview") && err.contains(bad),
            "{bad}: {err}"
        );
        assert!(!dir.join("bad.exr").exists() && !dir.join("bad.png").exists());
    }
    let (ok, err) = striae(&["render", &scene, "-q", "--preview", "tev", "--tile", "0/2"]);
    assert!(
        !ok && err.contains("--preview") && err.contains("--tile"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
