//! Training paths through a film's pixels, traced in parallel and merged in a fixed order.

use rayon::prelude::*;
use std::ops::Range;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use tress_core::film::FilmSettings;
use tress_core::rng::hash_words;
use tress_core::{Ray, Sampler, Scene};

/// What training depends on besides the scene: the film's size, seed and crop window (never
/// its spp or sample range, so that every pass of one image learns the same). Training paths
/// start through the window's pixels alone, so that a crop — a preview, a farm's tile — costs
/// training in proportion to its own pixels; a crop's image therefore equals the same window of
/// the whole film's in expectation, not bit for bit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FilmKey {
    /// Film width, in pixels.
    pub width: u32,
    /// Film height, in pixels.
    pub height: u32,
    /// The film's seed.
    pub seed: u64,
    /// The pixels rendered, `[x0, y0, x1, y1)`: the crop, or the whole film.
    pub window: [u32; 4],
}

impl FilmKey {
    /// The key of `film`.
    pub fn of(film: &FilmSettings) -> Self {
        FilmKey {
            width: film.width,
            height: film.height,
            seed: film.seed,
            window: film.window(),
        }
    }

    /// Pixels of the window that training paths start through.
    pub fn pixels(&self) -> u64 {
        let [x0, y0, x1, y1] = self.window;
        (x1 - x0) as u64 * (y1 - y0) as u64
    }
}

/// Paths traced per task: fixed, so that what each task records — and so what is learned — is
/// the same for any number of threads.
const CHUNK: u64 = 256;
/// Chunks traced in parallel before their records are merged, so that only one batch's
/// unmerged records are held at once.
const BATCH: u64 = 64;

/// Traces the training paths numbered `paths`: path `i` starts through pixel `i mod pixels`
/// of the film's window at a uniformly jittered position, with random numbers seeded by the film's
/// seed, `stream` and `i` alone. `trace` follows one path and records what it learns into its
/// chunk's records `R`; the chunks' records are handed to `merge` in index order, so the result
/// does not depend on how threads shared the work. `progress` gets the number of paths done.
/// Returns `None`, having merged only part, as soon as `cancel` is set (checked per chunk).
#[allow(clippy::too_many_arguments)]
pub fn train<R: Default + Send>(
    scene: &Scene,
    film: FilmKey,
    stream: u64,
    paths: Range<u64>,
    cancel: &AtomicBool,
    progress: &(dyn Fn(u64) + Sync),
    trace: impl Fn(&Ray, &mut Sampler, &mut R) + Sync,
    mut merge: impl FnMut(R),
) -> Option<()> {
    let pixels = film.pixels();
    let [x0, y0, x1, _] = film.window;
    let window_width = (x1 - x0) as u64;
    let done = AtomicU64::new(0);
    let chunks = (paths.end - paths.start).div_ceil(CHUNK);
    for batch in (0..chunks).step_by(BATCH as usize) {
        let batch_records: Vec<Option<R>> = (batch..(batch + BATCH).min(chunks))
            .into_par_iter()
            .map(|chunk| {
                if cancel.load(Ordering::Relaxed) {
                    return None;
                }
                let mut records = R::default();
                let first = paths.start + chunk * CHUNK;
                let range = first..(first + CHUNK).min(paths.end);
                let n = range.end - range.start;
                for i in range {
                    let pixel = i % pixels;
                    let x = x0 as u64 + pixel % window_width;
                    let y = y0 as u64 + pixel / window_width;
                    let mut sampler = Sampler::from_seed(hash_words(&[film.seed, stream, i]));
                    let jitter = sampler.next_2d();
                    let lens = sampler.next_2d();
                    let ray = scene.camera.generate_ray(
                        x as f32 + jitter.x,
                        y as f32 + jitter.y,
                        film.width,
                        film.height,
                        lens,
                    );
                    trace(&ray, &mut sampler, &mut records);
                }
                progress(done.fetch_add(n, Ordering::Relaxed) + n);
                Some(records)
            })
            .collect();
        for records in batch_records {
            merge(records?);
        }
    }
    Some(())
}
