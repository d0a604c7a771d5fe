//! The thread pool of the batch calls, one per process.
//!
//! Rayon's global pool does not survive `fork`: the child inherits the pool's bookkeeping but
//! not its threads, so its first parallel call waits for workers that do not exist, forever
//! (Gymnasium's `AsyncVectorEnv` and `multiprocessing` fork by default on Linux). The batch
//! calls therefore run on a pool tagged with the id of the process that built it; a forked
//! child sees a different id and builds a fresh pool on its first batch call.

use std::sync::{Arc, Mutex};

use rayon::{ThreadPool, ThreadPoolBuilder};

/// Batches under this many rows run on the calling thread: waking the pool costs more than a few
/// microsecond-sized rows.
pub const MIN_ROWS: usize = 32;

/// The pool and the id of the process whose threads it owns.
static POOL: Mutex<Option<(u32, Arc<ThreadPool>)>> = Mutex::new(None);

/// This process's pool, built on first use (again after a fork); `None` if threads cannot be
/// started, in which case the caller runs serially.
fn pool() -> Option<Arc<ThreadPool>> {
    let pid = std::process::id();
    let mut slot = POOL.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
    if let Some((owner, pool)) = slot.as_ref() {
        if *owner == pid {
            return Some(pool.clone());
        }
    }
    // A pool inherited through fork: its worker threads do not exist here, so dropping it
    // would wait on them. Leak it (one allocation per fork) and build this process's own.
    if let Some(inherited) = slot.take() {
        std::mem::forget(inherited);
    }
    let pool = Arc::new(ThreadPoolBuilder::new().build().ok()?);
    *slot = Some((pid, pool.clone()));
    Some(pool)
}

/// Runs `op` inside this process's pool, so that rayon's parallel iterators in it use
/// threads that exist (see the module docs); serially if no pool can be had.
pub fn install<R: Send>(op: impl FnOnce() -> R + Send) -> R {
    match pool() {
        Some(pool) => pool.install(op),
        None => op(),
    }
}

/// Runs `op` with a scope of this process's pool in which the calling thread works too: tasks
/// spawned on the scope run on the pool's threads while `op` goes on with its own share on the
/// caller's (nothing is handed off and waited for, which costs a thread wake-up when the
/// caller has been doing other work, as a PyTorch layer's caller has). `None`: no pool, serial.
pub fn in_place_scope<'scope, R>(op: impl FnOnce(Option<&rayon::Scope<'scope>>) -> R) -> R {
    match pool() {
        Some(pool) => pool.in_place_scope(|scope| op(Some(scope))),
        None => op(None),
    }
}

/// Threads of this process's pool (1 without one).
pub fn threads() -> usize {
    pool().map_or(1, |pool| pool.current_num_threads())
}
