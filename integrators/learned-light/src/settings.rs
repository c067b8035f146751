//! What the learning integrators share around their settings: range checks, and what was
//! learned for the film last rendered, and how it is prepared for a film.

use crate::{blocks_of, FilmKey};
use std::ops::Range;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex};
use tress_core::film::FilmSettings;
use tress_core::integrator::FilmIntegrator;
use tress_core::{Integrator, Scene};

/// A setting outside its range.
#[derive(Debug, thiserror::Error)]
#[error("{integrator} settings: {field} = {value}: {why}")]
pub struct OutOfRange {
    /// The integrator's name.
    pub integrator: &'static str,
    /// The setting.
    pub field: &'static str,
    /// Its value.
    pub value: f64,
    /// The range it must lie in.
    pub why: &'static str,
}

/// One range check: the setting, its value, whether it is in range, and the range.
pub type RangeCheck = (&'static str, f64, bool, &'static str);

/// The first of `checks` that fails, as an error of `integrator`'s settings.
pub fn check_ranges(integrator: &'static str, checks: &[RangeCheck]) -> Result<(), OutOfRange> {
    match checks.iter().find(|(_, _, ok, _)| !ok) {
        Some(&(field, value, _, why)) => Err(OutOfRange {
            integrator,
            field,
            value,
            why,
        }),
        None => Ok(()),
    }
}

/// What an integrator learned for the film it rendered last, kept so that the waves and sample
/// ranges of one image train once, and handed to the next training for the same film when it
/// does not serve, so that training can go on from it instead of starting again.
#[derive(Debug)]
pub struct LastFilm<T> {
    last: Mutex<Option<(FilmKey, Arc<T>)>>,
}

impl<T> Default for LastFilm<T> {
    fn default() -> Self {
        LastFilm {
            last: Mutex::new(None),
        }
    }
}

impl<T> LastFilm<T> {
    /// What was learned for `film`, if it `serves` the request, else what `train` learns
    /// (kept for the next request); `None` when training was stopped. `train` is given what was
    /// learned for the same film before (no longer kept here, so that it is freed as soon as
    /// its last user lets go of it), to go on from.
    pub fn get_or_train(
        &self,
        film: FilmKey,
        serves: impl Fn(&T) -> bool,
        train: impl FnOnce(Option<Arc<T>>) -> Option<T>,
    ) -> Option<Arc<T>> {
        let mut last = self.last.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((key, learned)) = last.as_ref() {
            if *key == film && serves(learned) {
                return Some(learned.clone());
            }
        }
        let before = last.take().filter(|(key, _)| *key == film).map(|(_, l)| l);
        let learned = Arc::new(train(before)?);
        *last = Some((film, learned.clone()));
        Some(learned)
    }
}

/// What a learning integrator learns for some sample blocks of one film, trained block after
/// block, so that [`LastFilm::for_film`] prepares either integrator alike.
pub trait BlockLearning: Integrator + Sized + 'static {
    /// The integrator's settings.
    type Settings;

    /// What is learned for sample blocks `blocks` of `film`, going on from `before` (what was
    /// learned for earlier blocks of the same film) where it serves; `None` when cancelled.
    fn train(
        settings: &Self::Settings,
        scene: &Scene,
        film: FilmKey,
        blocks: Range<u32>,
        before: Option<Arc<Self>>,
        cancel: &AtomicBool,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Option<Self>;

    /// Whether it has learned for every block of `blocks`.
    fn covers(&self, blocks: &Range<u32>) -> bool;

    /// What was learned and what it cost, one line for logs.
    fn description(&self) -> &str;
}

impl<T: BlockLearning> LastFilm<T> {
    /// [`Integrator::for_film`] of an integrator whose samples come in blocks starting at
    /// `block_spp`: what was learned for the blocks `samples` fall in, trained when it is not
    /// kept already.
    #[allow(clippy::too_many_arguments)]
    pub fn for_film(
        &self,
        settings: &T::Settings,
        block_spp: u32,
        scene: &Scene,
        film: &FilmSettings,
        samples: Range<u64>,
        cancel: &AtomicBool,
        progress: &(dyn Fn(f64) + Sync),
    ) -> Option<FilmIntegrator> {
        let key = FilmKey::of(film);
        let blocks = blocks_of(block_spp, samples);
        let learned = self.get_or_train(
            key,
            |t| t.covers(&blocks),
            |before| {
                T::train(
                    settings,
                    scene,
                    key,
                    blocks.clone(),
                    before,
                    cancel,
                    progress,
                )
            },
        )?;
        Some(FilmIntegrator {
            note: learned.description().to_owned(),
            integrator: learned,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    #[test]
    fn the_first_failing_check_names_its_setting() {
        let checks = [
            ("a", 1.0, true, "fine"),
            ("b", 7.0, false, "must lie in 0..=4"),
        ];
        let e = check_ranges("cache", &checks).unwrap_err();
        assert_eq!(e.to_string(), "cache settings: b = 7: must lie in 0..=4");
        assert!(check_ranges("cache", &checks[..1]).is_ok());
    }

    #[test]
    fn what_was_learned_is_kept_for_its_film_while_it_serves() {
        let film = |seed| FilmKey {
            width: 4,
            height: 4,
            seed,
            window: [0, 0, 4, 4],
        };
        let trained = Cell::new(0);
        let learned: LastFilm<u32> = LastFilm::default();
        // What training was handed, for the checks below.
        let handed = Cell::new(None);
        let get = |key, wanted: u32| {
            learned.get_or_train(
                key,
                |&have| have >= wanted,
                |before: Option<Arc<u32>>| {
                    handed.set(before.map(|b| *b));
                    trained.set(trained.get() + 1);
                    Some(wanted)
                },
            )
        };
        assert_eq!(*get(film(1), 2).unwrap(), 2);
        assert_eq!(handed.get(), None);
        assert_eq!(*get(film(1), 1).unwrap(), 2, "kept: it serves");
        assert_eq!(trained.get(), 1);
        assert_eq!(
            *get(film(1), 3).unwrap(),
            3,
            "trained again: it does not serve"
        );
        assert_eq!(handed.get(), Some(2), "handed what the same film learned");
        assert_eq!(*get(film(2), 1).unwrap(), 1, "trained again: another film");
        assert_eq!(
            handed.get(),
            None,
            "another film's learning is not handed on"
        );
        assert_eq!(trained.get(), 3);
        // A stopped training keeps nothing and returns nothing.
        assert!(learned.get_or_train(film(3), |_| true, |_| None).is_none());
    }
}
