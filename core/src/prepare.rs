//! The preparation context of a run: what integrators derive from a scene before rendering
//! (dual-scattering tables, the scene's density grids, …), built once and shared by every
//! integrator the run builds, and dropped with the run (Tungsten's `prepareForRender`). Scenes
//! know nothing of integrators: an integrator asks for what it needs while it is built. It replaces process-wide caches: two runs in one process (a study's
//! jobs share one; separate renders or tests do not) never see each other's data, and a cache
//! entry is found by the value of its key, never by a description of it. It also carries the
//! run's [`Limits`], which what is built is checked against.

use crate::limits::Limits;
use std::any::{Any, TypeId};
use std::collections::HashMap;
use std::hash::Hash;
use std::sync::{Arc, Mutex};

/// Derived data of a run, by key, built on first request (see the module docs).
#[derive(Default)]
pub struct Preparation {
    /// Per (key type, value type): a `HashMap<K, Arc<T>>`.
    caches: Mutex<HashMap<TypeId, Box<dyn Any + Send + Sync>>>,
    /// What was built, one line each, for the caller to log.
    notes: Mutex<Vec<String>>,
    /// What building may spend.
    limits: Limits,
}

impl std::fmt::Debug for Preparation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Preparation")
            .field("kinds", &self.lock().len())
            .field("limits", &self.limits)
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

    /// The limits builds are held to.
    pub fn limits(&self) -> &Limits {
        &self.limits
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
}
