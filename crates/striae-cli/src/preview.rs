//! `striae render --preview`: a live view of the film while it renders, to tev over TCP
//! (`tev[:HOST:PORT]`, [`crate::tev`]) or as the output PNG and EXR rewritten every few seconds
//! (`every=SECONDS`).
//!
//! The render loop hands each finished tile's final pixels to [`Preview::on_tile`]
//! (`integrator::try_render_observed`), which copies them into a preview film under a lock held
//! for that copy only; the render's arithmetic is untouched, so its image is bit for bit the
//! image of a render without preview. A background thread reads the preview film: it never
//! holds the lock while it writes to a socket or a file, so the workers never wait on tev or
//! on the disk. A tev that is absent, closes its socket or stops reading costs a warning and
//! no more preview: sockets connect and write with a timeout of [`WRITE_TIMEOUT`], and at the
//! end the command waits at most [`FINAL_WAIT`] for tev to take the final image.

use std::net::{TcpStream, ToSocketAddrs};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc, Condvar, Mutex};
use std::time::{Duration, Instant};
use striae::math::Rgb;
use striae::render::film::Image;
use striae::render::integrator::{place_tile, tile_rect, TILE};

/// The longest a connect or a single socket write to tev may take before the preview gives up.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(2);
/// The longest the command waits, after the render, for tev to take the final image.
pub const FINAL_WAIT: Duration = Duration::from_secs(3);
/// How often the tev sender sends the tiles finished since its last send.
const TEV_PERIOD: Duration = Duration::from_millis(200);
/// The longest `every=SECONDS`: about a week, far beyond any render.
const MAX_EVERY: f64 = 1e6;

/// Where `--preview` sends the film.
#[derive(Clone, Debug, PartialEq)]
pub enum PreviewSpec {
    /// tev listening at `HOST:PORT`.
    Tev(String),
    /// The PNG and EXR outputs rewritten (atomically) at this period.
    Every(Duration),
}

/// `--preview`: `tev` (tev's default address, 127.0.0.1:14158), `tev:HOST:PORT` or
/// `every=SECONDS` (a period above 0).
pub fn parse_preview(s: &str) -> Result<PreviewSpec, String> {
    let bad = || {
        format!(
            "`{s}` is not a preview: give tev (tev at 127.0.0.1:{}), tev:HOST:PORT, or every=SECONDS (rewrite the PNG and EXR)",
            crate::tev::DEFAULT_PORT
        )
    };
    if s == "tev" {
        return Ok(PreviewSpec::Tev(format!(
            "127.0.0.1:{}",
            crate::tev::DEFAULT_PORT
        )));
    }
    if let Some(addr) = s.strip_prefix("tev:") {
        let (host, port) = addr.rsplit_once(':').ok_or_else(bad)?;
        if host.is_empty() || port.parse::<u16>().is_err() {
            return Err(format!(
                "`{s}`: give tev:HOST:PORT, a host name or address and a port (0 to 65535)"
            ));
        }
        return Ok(PreviewSpec::Tev(addr.to_string()));
    }
    if let Some(secs) = s.strip_prefix("every=") {
        return match secs.parse::<f64>() {
            Ok(t) if t > 0.0 && t <= MAX_EVERY => {
                Ok(PreviewSpec::Every(Duration::from_secs_f64(t)))
            }
            _ => Err(format!(
                "`{s}`: every=SECONDS takes a period in seconds above 0 and at most {MAX_EVERY}"
            )),
        };
    }
    Err(bad())
}

/// How a preview warns: on standard error, around the progress bar.
pub type Warn = Arc<dyn Fn(String) + Send + Sync>;

/// The state the render's workers and the preview thread share.
struct State {
    /// The film so far: finished tiles hold their final pixels, the rest are black.
    film: Image,
    /// Tiles finished since the preview thread last read the film.
    fresh: Vec<u32>,
    /// The final image, once the render is done (tev only).
    last: Option<Arc<Image>>,
    /// Set when the command is done with the preview.
    stop: bool,
}

struct Shared {
    state: Mutex<State>,
    wake: Condvar,
    /// Set when the preview has given up (a warning was printed): tiles are no longer copied.
    dead: AtomicBool,
}

/// A running preview: [`Preview::on_tile`] from the render's workers, then
/// [`Preview::finish`].
pub struct Preview {
    shared: Arc<Shared>,
    thread: Option<std::thread::JoinHandle<()>>,
    /// Disconnected when the preview thread ends (in a mutex: the workers share the preview).
    ended: Mutex<mpsc::Receiver<()>>,
    spec: PreviewSpec,
    warn: Warn,
}

impl Preview {
    /// Starts the preview of a `width x height` film: the thread that connects to tev (the
    /// image named `name`) or rewrites `exr` and `png` (PNG at `exposure`).
    pub fn start(
        spec: PreviewSpec,
        (width, height): (u32, u32),
        name: String,
        (exr, png): (PathBuf, PathBuf),
        exposure: f32,
        warn: Warn,
    ) -> anyhow::Result<Preview> {
        let film = Image::try_new(width, height, "--preview (a copy of the film)")?;
        let shared = Arc::new(Shared {
            state: Mutex::new(State {
                film,
                fresh: Vec::new(),
                last: None,
                stop: false,
            }),
            wake: Condvar::new(),
            dead: AtomicBool::new(false),
        });
        let (tx, ended) = mpsc::channel::<()>();
        let thread = {
            let shared = Arc::clone(&shared);
            let spec = spec.clone();
            let warn = Arc::clone(&warn);
            std::thread::Builder::new()
                .name("striae-preview".into())
                .spawn(move || {
                    let _ended = tx;
                    let result = match &spec {
                        PreviewSpec::Tev(addr) => send_to_tev(&shared, addr, &name),
                        PreviewSpec::Every(period) => {
                            rewrite_outputs(&shared, *period, &exr, &png, exposure)
                        }
                    };
                    if let Err(e) = result {
                        shared.dead.store(true, Ordering::Relaxed);
                        warn(format!(
                            "striae: warning: --preview {}: {e}; the render goes on without the preview",
                            describe(&spec)
                        ));
                    }
                })?
        };
        Ok(Preview {
            shared,
            thread: Some(thread),
            ended: Mutex::new(ended),
            spec,
            warn,
        })
    }

    /// A finished tile's final pixels (row by row), from the worker that rendered it: copied
    /// into the preview film under the lock, nothing else.
    pub fn on_tile(&self, tile: u32, pixels: &[Rgb]) {
        if self.shared.dead.load(Ordering::Relaxed) {
            return;
        }
        let mut state = self.shared.state.lock().unwrap_or_else(|e| e.into_inner());
        place_tile(&mut state.film, tile, pixels);
        state.fresh.push(tile);
    }

    /// Stops the preview once the render is done. With tev, `image` (the render's final image)
    /// is sent last, and this waits at most [`FINAL_WAIT`] for it (a warning where it takes
    /// longer; the thread is left to end with the process). With `every=`, the thread is
    /// stopped and joined (after at most the write it is in) so that the final outputs, written
    /// after this, are never replaced by a preview.
    pub fn finish(mut self, image: Arc<Image>) {
        {
            let mut state = self.shared.state.lock().unwrap_or_else(|e| e.into_inner());
            if matches!(self.spec, PreviewSpec::Tev(_)) {
                state.last = Some(image);
            }
            state.stop = true;
        }
        self.shared.wake.notify_all();
        match self.spec {
            PreviewSpec::Tev(_) => {
                let ended = self.ended.lock().unwrap_or_else(|e| e.into_inner());
                if let Err(mpsc::RecvTimeoutError::Timeout) = ended.recv_timeout(FINAL_WAIT) {
                    (self.warn)(format!(
                        "striae: warning: --preview {}: tev did not take the final image within {} s; it may show an unfinished one",
                        describe(&self.spec),
                        FINAL_WAIT.as_secs()
                    ));
                    // Detached: the process ends without waiting for it.
                    self.thread = None;
                }
            }
            PreviewSpec::Every(_) => {
                if let Some(t) = self.thread.take() {
                    let _ = t.join();
                }
            }
        }
    }
}

/// The flag's value as the user gives it, for warnings.
fn describe(spec: &PreviewSpec) -> String {
    match spec {
        PreviewSpec::Tev(addr) => format!("tev:{addr}"),
        PreviewSpec::Every(p) => format!("every={}", p.as_secs_f64()),
    }
}

/// What the preview thread takes from the shared state at a wake-up.
struct Batch {
    tiles: Vec<([u32; 4], Vec<[f32; 3]>)>,
    last: Option<Arc<Image>>,
    stop: bool,
}

/// Waits until `deadline` or [`State::stop`], then takes the fresh tiles' pixels (copies,
/// so that nothing is held while they are sent) and the final image.
fn take(shared: &Shared, deadline: Instant) -> Batch {
    let mut state = shared.state.lock().unwrap_or_else(|e| e.into_inner());
    while !state.stop {
        let now = Instant::now();
        if now >= deadline {
            break;
        }
        state = shared
            .wake
            .wait_timeout(state, deadline - now)
            .unwrap_or_else(|e| e.into_inner())
            .0;
    }
    let fresh = std::mem::take(&mut state.fresh);
    let film = &state.film;
    let tiles = fresh
        .into_iter()
        .map(|t| {
            let [x0, y0, x1, y1] = tile_rect(film.width, film.height, t);
            let px = (y0..y1)
                .flat_map(|y| (x0..x1).map(move |x| (x, y)))
                .map(|(x, y)| film.get(x, y).to_array())
                .collect();
            ([x0, y0, x1 - x0, y1 - y0], px)
        })
        .collect();
    Batch {
        tiles,
        last: state.last.take(),
        stop: state.stop,
    }
}

/// The tev preview: connect, create the image, send finished tiles every [`TEV_PERIOD`], and
/// at the end the final image in strips of [`TILE`] rows.
fn send_to_tev(shared: &Shared, addr: &str, name: &str) -> Result<(), String> {
    let mut stream = connect(addr)?;
    let (w, h) = {
        let state = shared.state.lock().unwrap_or_else(|e| e.into_inner());
        (state.film.width, state.film.height)
    };
    send(&mut stream, &crate::tev::create_image(name, w, h))?;
    loop {
        let batch = take(shared, Instant::now() + TEV_PERIOD);
        for (rect, px) in &batch.tiles {
            send(&mut stream, &crate::tev::update_image(name, *rect, px))?;
        }
        if let Some(image) = batch.last {
            for y0 in (0..h).step_by(TILE as usize) {
                let y1 = (y0 + TILE).min(h);
                let start = (y0 * w) as usize;
                let px: Vec<[f32; 3]> = image.pixels[start..(y1 * w) as usize]
                    .iter()
                    .map(|p| p.to_array())
                    .collect();
                send(
                    &mut stream,
                    &crate::tev::update_image(name, [0, y0, w, y1 - y0], &px),
                )?;
            }
            return Ok(());
        }
        if batch.stop {
            return Ok(());
        }
    }
}

/// A connection to tev at `addr`, each address tried with [`WRITE_TIMEOUT`], writes bounded
/// by it.
fn connect(addr: &str) -> Result<TcpStream, String> {
    let addrs = addr
        .to_socket_addrs()
        .map_err(|e| format!("cannot resolve {addr}: {e}"))?;
    let mut last = format!("{addr} has no address");
    for a in addrs {
        match TcpStream::connect_timeout(&a, WRITE_TIMEOUT) {
            Ok(stream) => {
                stream
                    .set_write_timeout(Some(WRITE_TIMEOUT))
                    .and_then(|()| stream.set_nodelay(true))
                    .map_err(|e| format!("cannot set up the connection to {a}: {e}"))?;
                return Ok(stream);
            }
            Err(e) => last = format!("cannot connect to tev at {a}: {e}"),
        }
    }
    Err(last)
}

fn send(stream: &mut TcpStream, packet: &[u8]) -> Result<(), String> {
    use std::io::Write;
    stream.write_all(packet).map_err(|e| match e.kind() {
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut => {
            format!("tev took no data for {} s", WRITE_TIMEOUT.as_secs())
        }
        _ => format!("sending to tev failed: {e}"),
    })
}

/// The `every=` preview: the film so far written to the outputs (atomically, both or neither)
/// every `period` where a tile finished since the last write.
fn rewrite_outputs(
    shared: &Shared,
    period: Duration,
    exr: &std::path::Path,
    png: &std::path::Path,
    exposure: f32,
) -> Result<(), String> {
    loop {
        let batch = take(shared, Instant::now() + period);
        if batch.stop {
            return Ok(());
        }
        if batch.tiles.is_empty() {
            continue;
        }
        let film = {
            let state = shared.state.lock().unwrap_or_else(|e| e.into_inner());
            state.film.clone()
        };
        film.write_exr_and_png(exr, png, exposure)
            .map_err(|e| e.to_string())?;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_the_flag() {
        assert_eq!(
            parse_preview("tev"),
            Ok(PreviewSpec::Tev("127.0.0.1:14158".into()))
        );
        assert_eq!(
            parse_preview("tev:localhost:1234"),
            Ok(PreviewSpec::Tev("localhost:1234".into()))
        );
        assert_eq!(
            parse_preview("tev:[::1]:1234"),
            Ok(PreviewSpec::Tev("[::1]:1234".into()))
        );
        assert_eq!(
            parse_preview("every=0.5"),
            Ok(PreviewSpec::Every(Duration::from_millis(500)))
        );
        for bad in [
            "nonsense",
            "tev:",
            "tev:host",
            "tev::80",
            "tev:h:99999",
            "every=0",
            "every=-1",
            "every=nan",
            "every=inf",
            "every=",
        ] {
            assert!(parse_preview(bad).is_err(), "{bad}");
        }
    }

    /// A tev that accepts the connection but never reads: the final wait ends within
    /// [`FINAL_WAIT`] (plus a margin), with a warning.
    #[test]
    fn a_tev_that_never_reads_bounds_the_final_wait() {
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap().to_string();
        let warnings = Arc::new(Mutex::new(Vec::<String>::new()));
        let w = Arc::clone(&warnings);
        let (width, height) = (1024, 1024);
        let dir = std::env::temp_dir();
        let preview = Preview::start(
            PreviewSpec::Tev(addr),
            (width, height),
            "t".into(),
            (dir.join("unused.exr"), dir.join("unused.png")),
            0.0,
            Arc::new(move |m| w.lock().unwrap().push(m)),
        )
        .unwrap();
        let (_conn, _) = listener.accept().unwrap();
        // 12 MiB of final image: far beyond what the socket buffers hold.
        let start = Instant::now();
        preview.finish(Arc::new(Image::new(width, height)));
        let waited = start.elapsed();
        assert!(waited < FINAL_WAIT + Duration::from_secs(1), "{waited:?}");
        let warnings = warnings.lock().unwrap();
        assert!(
            warnings.iter().any(|m| m.contains("--preview tev:")),
            "{warnings:?}"
        );
    }
}
