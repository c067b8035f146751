//! The preparation context of a run: what integrators derive from a scene before rendering
//! (dual-scattering tables, the scene's density grids, …), built once and shared by every
//! integrator the run builds, and dropped with the run (Tungsten's `prepareForRender`). Scenes
//! know nothing of integrators: an integrator asks for what it needs while it is built. It replaces process-wide caches: two runs in one process (a study's
//! jobs share one; separate renders or tests do not) never see each other's data, and a cache
//! entry is found by the value of its key, never by a description of it. It also carries the
//! run's [`Limits`], which what is built is checked against, and the folder, if the front end
//! chose one, where tables are kept between runs ([`Preparation::get_or_build_stored`],
//! [`crate::stored_table`]).

use crate::limits::Limits;
use crate::stored_table::{self, Loaded, StoredTable};
use std::any::{Any, TypeId};
use std::collections::HashMap;
use std::hash::Hash;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// Derived data of a run, by key, built on first request (see the module docs).
#[derive(Default)]
pub struct Preparation {
    /// Per (key type, value type): a `HashMap<K, Arc<T>>`.
    caches: Mutex<HashMap<TypeId, Box<dyn Any + Send + Sync>>>,
    /// What was built, one line each, for the caller to log.
    notes: Mutex<Vec<String>>,
    /// What building may spend.
    limits: Limits,
    /// Where tables are kept between runs; `None`: nowhere.
    table_dir: Option<PathBuf>,
}

impl std::fmt::Debug for Preparation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Preparation")
            .field("kinds", &self.lock().len())
            .field("limits", &self.limits)
            .field("table_dir", &self.table_dir)
            .finish()
    }
}

impl Preparation {
    /// An empty context with the default [`Limits`].
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty context whose builds are held to `limits`.
    pub fn with_limits(limits: Limits) -> Self {
        Preparation {
            limits,
            ..Self::default()
        }
    }

    /// The same context, keeping the tables that can be stored ([`StoredTable`]) in `dir`
    /// between runs (`None`: nowhere). The front ends choose the folder; the library reads no
    /// environment.
    pub fn with_table_dir(self, dir: Option<PathBuf>) -> Self {
        Preparation {
            table_dir: dir,
            ..self
        }
    }

    /// The limits builds are held to.
    pub fn limits(&self) -> &Limits {
        &self.limits
    }

    /// The folder where tables are kept between runs, if any.
    pub fn table_dir(&self) -> Option<&Path> {
        self.table_dir.as_deref()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<TypeId, Box<dyn Any + Send + Sync>>> {
        // A panic while building leaves no entry behind, so a poisoned map is still valid.
        self.caches.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The `T` for `key`, built by `build` on first request. Builds are serialised (the lock is
    /// held while building), so concurrent requests never build the same data twice; a failed
    /// build leaves nothing behind.
    pub fn get_or_build<K, T, E>(
        &self,
        key: K,
        build: impl FnOnce() -> Result<T, E>,
    ) -> Result<Arc<T>, E>
    where
        K: Hash + Eq + Send + Sync + 'static,
        T: Send + Sync + 'static,
    {
        let mut caches = self.lock();
        let cache = caches
            .entry(TypeId::of::<(K, T)>())
            .or_insert_with(|| Box::new(HashMap::<K, Arc<T>>::new()))
            .downcast_mut::<HashMap<K, Arc<T>>>()
            .expect("the map under (K, T)'s type id holds K → Arc<T>");
        if let Some(t) = cache.get(&key) {
            return Ok(Arc::clone(t));
        }
        let t = Arc::new(build()?);
        cache.insert(key, Arc::clone(&t));
        Ok(t)
    }

    /// [`Preparation::get_or_build`] for a table that can be kept on disk: on first request in
    /// the run it is read from the table folder if that holds it for `key`, otherwise built and
    /// stored there. A file that is not the table asked for (truncated, corrupt, of another
    /// version or key) is ignored with a warning note and replaced; a table that cannot be
    /// stored is kept for the run with a warning note. Reading back gives the built table bit
    /// for bit, so images do not depend on the folder. Each read and build is noted.
    pub fn get_or_build_stored<T, E>(
        &self,
        key: T::Key,
        build: impl FnOnce() -> Result<T, E>,
    ) -> Result<Arc<T>, E>
    where
        T: StoredTable,
    {
        let stored = self.table_dir.as_deref().map(|dir| {
            let key_bytes = T::key_bytes(&key);
            (stored_table::path::<T>(dir, &key_bytes), key_bytes)
        });
        // get_or_build holds the cache's lock while this runs: one read or build per key.
        self.get_or_build(key, || {
            if let Some((path, key_bytes)) = &stored {
                match stored_table::load::<T>(path, key_bytes) {
                    Loaded::Table(t) => {
                        self.note(format!("{} table read from {}", T::KIND, path.display()));
                        return Ok(t);
                    }
                    Loaded::Absent => {}
                    Loaded::Rejected(why) => self.note(format!(
                        "warning: ignoring {}: {why}; building the {} table again",
                        path.display(),
                        T::KIND
                    )),
                }
            }
            let start = Instant::now();
            let t = build()?;
            let seconds = start.elapsed().as_secs_f64();
            let kept = match &stored {
                None => String::new(),
                Some((path, key_bytes)) => match stored_table::store(path, key_bytes, &t) {
                    Ok(()) => format!(", stored in {}", path.display()),
                    Err(why) => {
                        self.note(format!(
                            "warning: the {} table is kept for this run only: {why}",
                            T::KIND
                        ));
                        String::new()
                    }
                },
            };
            self.note(format!("{} table built in {seconds:.2} s{kept}", T::KIND));
            Ok(t)
        })
    }

    /// Records one line about something built (what, how large, how long), for the caller to
    /// log when it chooses ([`Preparation::take_notes`]).
    pub fn note(&self, line: String) {
        self.notes
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(line);
    }

    /// The lines recorded since the last call, oldest first.
    pub fn take_notes(&self) -> Vec<String> {
        std::mem::take(&mut *self.notes.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// How many `T`s are held under keys of type `K`.
    pub fn count<K: 'static, T: 'static>(&self) -> usize {
        self.lock()
            .get(&TypeId::of::<(K, T)>())
            .and_then(|c| c.downcast_ref::<HashMap<K, Arc<T>>>())
            .map_or(0, HashMap::len)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builds_once_per_key_and_type_and_keeps_no_failure() {
        let prep = Preparation::new();
        let mut builds = 0;
        let mut get = |key: u32| {
            prep.get_or_build(key, || {
                builds += 1;
                Ok::<_, ()>(format!("table {key}"))
            })
            .unwrap()
        };
        let a = get(1);
        let b = get(1);
        assert!(Arc::ptr_eq(&a, &b));
        get(2);
        assert_eq!(builds, 2);
        // Another value type under the same key is another entry.
        let n = prep.get_or_build(1u32, || Ok::<_, ()>(7u64)).unwrap();
        assert_eq!(*n, 7);
        assert_eq!(prep.count::<u32, String>(), 2);
        assert_eq!(prep.count::<u32, u64>(), 1);
        // A failed build is not kept.
        assert!(prep.get_or_build(3u32, || Err::<String, _>("no")).is_err());
        assert_eq!(prep.count::<u32, String>(), 2);
        prep.note("grid".into());
        prep.note("tables".into());
        assert_eq!(prep.take_notes(), ["grid", "tables"]);
        assert!(prep.take_notes().is_empty());
    }

    #[test]
    fn stored_tables_are_read_back_and_bad_files_rebuilt() {
        use crate::stored_table::tests::Squares;
        let dir = tempfile::tempdir().unwrap();
        let builds = std::cell::Cell::new(0);
        let build = |seed: u32| {
            builds.set(builds.get() + 1);
            Ok::<_, ()>(Squares((0..4).map(|i| (seed + i) * (seed + i)).collect()))
        };
        let run = || Preparation::new().with_table_dir(Some(dir.path().join("tables")));
        // A first run builds and stores; within it, the same key is built once.
        let first = run();
        let a = first.get_or_build_stored(2, || build(2)).unwrap();
        let b = first.get_or_build_stored(2, || build(2)).unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        assert_eq!(builds.get(), 1);
        let notes = first.take_notes();
        assert!(
            notes.len() == 1 && notes[0].contains("squares table built in"),
            "{notes:?}"
        );
        assert!(notes[0].contains("stored in"), "{notes:?}");
        // A second run reads it.
        let second = run();
        assert_eq!(*second.get_or_build_stored(2, || build(2)).unwrap(), *a);
        assert_eq!(builds.get(), 1);
        assert!(second.take_notes()[0].starts_with("squares table read from"));
        // A damaged file is rebuilt, with a warning, and replaced.
        let path =
            crate::stored_table::path::<Squares>(&dir.path().join("tables"), &2u32.to_le_bytes());
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 3]).unwrap();
        let third = run();
        assert_eq!(*third.get_or_build_stored(2, || build(2)).unwrap(), *a);
        assert_eq!(builds.get(), 2);
        let notes = third.take_notes();
        assert!(
            notes[0].starts_with("warning: ignoring") && notes[0].contains("truncated"),
            "{notes:?}"
        );
        assert_eq!(std::fs::read(&path).unwrap(), bytes);
        // Without a folder nothing is read or written.
        let plain = Preparation::new();
        plain.get_or_build_stored(2, || build(2)).unwrap();
        assert_eq!(builds.get(), 3);
        assert!(plain.table_dir().is_none());
    }
}
