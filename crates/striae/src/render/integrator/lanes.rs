//! The lane render loop (`render.lanes = true`): [`LANES`] paths of a tile in flight at once,
//! advanced stage by stage, as Mitsuba 3's wavefront and pbrt-v4's `WavefrontPathIntegrator` do
//! over whole images. A step traces every path's ray (new paths' camera rays together, in packets
//! where they share the pinhole), lands every path on its hit (the vertices `lane_vertex` takes in
//! SIMD lanes, the others by [`Path::land`], the one-path loop's own vertex), then tests every
//! deferred shadow ray; a path that ends makes room for the tile's next sample (path regeneration),
//! so the lanes stay full until the tile runs out.
//!
//! Each path runs the same operations as in the one-path loop, and the samples of a pixel are
//! summed in sample order (a short reorder queue holds samples that finish early), so the image
//! is the one-path loop's bit for bit where no material reads the pixel's footprint. Where one
//! does (the scratched material seen from outside), a pixel's samples share its cached
//! footprints (`layers::CoverageCache::of_pixel`) in the order they reach them, which here is
//! not sample order: the lanes then hold one pixel's samples at a time, and the image agrees
//! with the one-path loop's within noise (`tests/lanes.rs`).

use super::lane_vertex::{self, LaneTables, Lanes};
use super::path::{
    camera_packet, camera_sample, traces_camera_packets, CameraHit, CameraSample, Path, ShadowTest,
};
use super::Worker;
use crate::math::Rgb;
use crate::render::geometry::{SurfaceHit, PACKET};
use crate::render::scene::Scene;
use arrayvec::ArrayVec;
use std::collections::VecDeque;

/// Paths in flight at once.
pub const LANES: usize = 16;

/// Every lane's bit.
const ALL_LANES: u32 = (1 << LANES) - 1;

/// The lanes whose bits are set in `mask`, lowest first.
#[inline(always)]
fn lanes_of(mut mask: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        let i = mask.trailing_zeros() as usize;
        mask &= mask.wrapping_sub(1);
        (i < 32).then_some(i)
    })
}

/// The samples of a tile, numbered pixel by pixel (row by row), samples in order within a
/// pixel: the order the one-path loop runs them in.
struct Work {
    x0: u32,
    y0: u32,
    width: u32,
    /// The film's width.
    film_width: u32,
    /// Samples per pixel in this pass, and the first one's index.
    n: u32,
    first: u32,
    total: u64,
}

impl Work {
    /// The pixel `(x, y)` (its index on the film) and the sample index of item `item`.
    fn sample(&self, item: u64) -> ((u32, u32), u64, u32) {
        let pixel = (item / self.n as u64) as u32;
        let s = self.first + (item % self.n as u64) as u32;
        let (x, y) = (self.x0 + pixel % self.width, self.y0 + pixel / self.width);
        ((x, y), y as u64 * self.film_width as u64 + x as u64, s)
    }

    /// The tile's pixel (row by row) of item `item`.
    fn pixel(&self, item: u64) -> usize {
        (item / self.n as u64) as usize
    }
}

/// The tile's camera samples in order, with their closest hits traced as the one-path loop
/// traces them: in packets of up to [`PACKET`] of a pixel's samples where the pass does
/// (`traces_camera_packets`), else by their paths' first step.
struct CameraQueue {
    samples: ArrayVec<CameraSample, PACKET>,
    hits: ArrayVec<Option<SurfaceHit>, PACKET>,
    /// The item of `samples[0]`, and how many were taken.
    first: u64,
    taken: usize,
    packets: bool,
}

impl CameraQueue {
    /// Item `item`'s camera sample and, where it was traced in a packet, its closest hit.
    #[inline(always)]
    fn take<const DIFFERENTIALS: bool>(
        &mut self,
        scene: &Scene,
        work: &Work,
        item: u64,
    ) -> (CameraSample, CameraHit) {
        if !self.packets {
            let ((x, y), pixel_index, s) = work.sample(item);
            let sample = camera_sample::<DIFFERENTIALS>(scene, (x, y), pixel_index, s);
            return (sample, CameraHit::Untraced);
        }
        if self.taken == self.samples.len() {
            // The next chunk: up to `PACKET` samples, not past the pixel's last.
            let ((x, y), pixel_index, s) = work.sample(item);
            let n = (work.first + work.n - s).min(PACKET as u32) as usize;
            let chunk = (s, n);
            camera_packet::<DIFFERENTIALS>(
                scene,
                (x, y),
                pixel_index,
                chunk,
                &mut self.samples,
                &mut self.hits,
            );
            self.first = item;
            self.taken = 0;
        }
        debug_assert_eq!(item, self.first + self.taken as u64);
        let k = self.taken;
        self.taken += 1;
        // (The chunk's samples are taken once each, in order: a copy, then never read again.)
        (self.samples[k].clone(), CameraHit::Traced(self.hits[k]))
    }
}

/// The per-pixel sums of the tile's samples, each pixel's added in sample order as in the
/// one-path loop: a sample that finishes before an earlier one waits in a queue.
struct Sums {
    sums: Vec<Rgb>,
    /// The samples from item `base` on: `None` while running.
    waiting: VecDeque<Option<Rgb>>,
    base: u64,
    /// Item `base`'s pixel (row by row in the tile) and its place among the pixel's `n`
    /// samples, counted rather than divided out of `base` ([`Work::pixel`]).
    base_pixel: usize,
    base_sample: u32,
    n: u32,
}

impl Sums {
    /// Item `item` started (items start in order).
    fn start(&mut self, item: u64) {
        debug_assert_eq!(item, self.base + self.waiting.len() as u64);
        self.waiting.push_back(None);
    }

    /// Item `item` finished with radiance `l`; the finished run at the front is summed.
    #[inline(always)]
    fn finish(&mut self, item: u64, l: Rgb, worker: &mut Worker) {
        self.waiting[(item - self.base) as usize] = Some(l);
        while let Some(Some(l)) = self.waiting.front().copied() {
            self.waiting.pop_front();
            if l.is_finite() {
                self.sums[self.base_pixel] += l;
            } else {
                worker.nonfinite += 1;
            }
            self.base += 1;
            self.base_sample += 1;
            if self.base_sample == self.n {
                self.base_sample = 0;
                self.base_pixel += 1;
            }
        }
    }
}

/// The sums of the samples `first..end` of the tile `[x0, y0, x1, y1)`'s pixels (row by row),
/// as [`super::render_pixel`] gives them; `SIMD_GGX` as [`Lanes::run`] takes it.
#[inline(always)]
pub(super) fn render_tile<const DIFFERENTIALS: bool, const SIMD_GGX: u32>(
    scene: &Scene,
    [x0, y0, x1, y1]: [u32; 4],
    (first, end): (u32, u32),
    worker: &mut Worker,
) -> Vec<Rgb> {
    let pixels = ((x1 - x0) * (y1 - y0)) as usize;
    let work = Work {
        x0,
        y0,
        width: x1 - x0,
        film_width: scene.camera.resolution().0,
        n: end - first,
        first,
        total: pixels as u64 * (end - first) as u64,
    };
    let mut sums = Sums {
        sums: vec![Rgb::ZERO; pixels],
        waiting: VecDeque::with_capacity(4 * LANES),
        base: 0,
        base_pixel: 0,
        base_sample: 0,
        n: end - first,
    };
    let mut cameras = CameraQueue {
        samples: ArrayVec::new(),
        hits: ArrayVec::new(),
        first: 0,
        taken: 0,
        packets: traces_camera_packets(scene, end - first),
    };
    let mut lanes = ArrayVec::<Path, LANES>::new();
    let mut items = [0u64; LANES];
    let mut next = 0u64;
    // The pixel whose footprints the coverage cache holds (with `DIFFERENTIALS`).
    let mut pixel = usize::MAX;
    let mut hits: [Option<SurfaceHit>; LANES] = [None; LANES];
    let mut shadows: [Option<ShadowTest>; LANES] = [None; LANES];
    // Lanes as bits: running a path; whose hit came with the camera ray's packet.
    let (mut running, mut traced) = (0u32, 0u32);
    // Two `let`s, not one of a pair: made as a pair, the AVX2 copy's cost model keeps the
    // dielectrics' GGX loops scalar (`objdump -d` shows no `vsqrtps ymm` of theirs).
    let mut vertices = Lanes::new();
    let mut tables = LaneTables::new();
    loop {
        // Regeneration: each free lane takes the tile's next sample. With differentials, a
        // pixel's samples share its footprints: the next pixel starts once the lanes are empty.
        // (The lowest free lane is at most the number of lanes made so far.)
        for i in lanes_of(!running & ALL_LANES) {
            if next == work.total {
                break;
            }
            if DIFFERENTIALS && work.pixel(next) != pixel {
                if running != 0 {
                    break;
                }
                pixel = work.pixel(next);
                worker.coverage.start_pixel();
            }
            let (sample, camera_hit) = cameras.take::<DIFFERENTIALS>(scene, &work, next);
            if let CameraHit::Traced(hit) = camera_hit {
                hits[i] = hit;
                traced |= 1 << i;
            }
            match lanes.get_mut(i) {
                Some(path) => path.restart(sample),
                None => lanes.push(Path::new(sample)),
            }
            items[i] = next;
            running |= 1 << i;
            sums.start(next);
            next += 1;
        }
        if running == 0 {
            break;
        }

        // Closest hits of the rays not traced yet.
        for i in lanes_of(running & !traced) {
            hits[i] = scene.geometry.intersect(&lanes[i].ray);
        }
        traced = 0;

        // Every path's vertex: those of plain materials in lanes (`lane_vertex`), the others
        // one by one; the shadow rays they leave; the light of those unoccluded; the paths
        // that ended.
        let (mut shadowed, mut ended, mut plain) = (0u32, 0u32, 0u32);
        for i in lanes_of(running) {
            if let Some(hit) = hits[i].as_ref() {
                let path = &mut lanes[i];
                if let Some(kind) =
                    lane_vertex::takes::<SIMD_GGX>(scene, hit, path.depth, path.ray.d)
                {
                    vertices.gather(i, scene, path, hit, kind, &mut tables);
                    plain |= 1 << i;
                    continue;
                }
            }
            let landing = lanes[i].land::<DIFFERENTIALS, true>(scene, hits[i], worker);
            if landing.shadow.is_some() {
                shadows[i] = landing.shadow;
                shadowed |= 1 << i;
            }
            ended |= (!landing.goes_on as u32) << i;
        }
        if plain != 0 {
            vertices.run::<SIMD_GGX>(&tables);
            for i in lanes_of(plain) {
                let hit = hits[i].as_ref().expect("a plain vertex has a hit");
                let path = &mut lanes[i];
                let goes_on =
                    vertices.scatter::<DIFFERENTIALS>(i, scene, path, hit, worker, &mut shadows[i]);
                shadowed |= (shadows[i].is_some() as u32) << i;
                ended |= (!goes_on as u32) << i;
            }
        }
        for i in lanes_of(shadowed) {
            if let Some(test) = shadows[i].take() {
                if !scene.geometry.occluded(&test.ray) {
                    lanes[i].l += test.radiance;
                }
            }
        }
        for i in lanes_of(ended) {
            sums.finish(items[i], lanes[i].l, worker);
        }
        running &= !ended;
    }
    debug_assert!(sums.waiting.is_empty());
    sums.sums
}
